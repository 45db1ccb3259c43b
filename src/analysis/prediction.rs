//! A measurement against the virtual prototype's prediction (`analyze --prediction`).
//!
//! Owns [`compare`] and [`PredictionComparison`]: the rotation error about z (measured −
//! target, after the alignment's offsets) less the deviation `mpc-rig simulate` predicted
//! for the printed parts at that driver angle and direction. Small against the prediction
//! while large against the target means the parts move as predicted and the design (or
//! its print) is what differs from the target; large against both means something the
//! prediction does not model (the bench, the print, the load). It reads no files itself.

use std::path::PathBuf;

use serde::Serialize;

use super::run::{MeasuredRun, Phase};
use super::Analysis;
use crate::predict::table::PredictedDeviation;

/// The measurement against the prediction, 1R.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct PredictionComparison {
    /// The prediction file.
    pub file: PathBuf,
    /// RMS of measured − predicted, degrees.
    pub rms_deg: f64,
    /// Largest |measured − predicted|, degrees.
    pub max_deg: f64,
    /// RMS of measured − target over the same samples, degrees.
    pub rms_vs_target_deg: f64,
    /// Measured samples compared.
    pub samples: usize,
    /// Driver angles (first and last sample, degrees) where the prediction says the parts
    /// lose the drive: where a large error is the parts' doing.
    pub drive_lost_deg: Vec<[f64; 2]>,
}

/// Compare the rz errors of `a` (from `run`) with `predicted`; `None` when the analysis
/// has no rz channel (1R1T heights and 3R are not predicted yet).
pub fn compare(
    a: &Analysis,
    run: &MeasuredRun,
    predicted: &PredictedDeviation,
    file: PathBuf,
) -> Option<PredictionComparison> {
    let ch = a.errors.iter().find(|c| c.name == "rz")?;
    if a.class != "1R" {
        return None;
    }
    let d0 = a.alignment.driver_offset_deg.value;
    let (mut sq, mut sq_target, mut max, mut n) = (0.0, 0.0, 0.0f64, 0usize);
    for i in run.measured_indices() {
        let e = ch.values[i];
        if !e.is_finite() {
            continue;
        }
        let forward = run.phase[i] != Phase::Reverse;
        let r = e - predicted.at(run.driver_deg[i] - d0, forward);
        sq += r * r;
        sq_target += e * e;
        max = max.max(r.abs());
        n += 1;
    }
    (n > 0).then(|| PredictionComparison {
        file,
        rms_deg: (sq / n as f64).sqrt(),
        max_deg: max,
        rms_vs_target_deg: (sq_target / n as f64).sqrt(),
        samples: n,
        drive_lost_deg: predicted.lost_windows_deg().to_vec(),
    })
}
