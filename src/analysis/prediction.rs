//! A measurement against the virtual prototype's prediction (`analyze --prediction`).
//!
//! Owns [`compare`] and [`PredictionComparison`]: the rotation error about z (measured −
//! target, after the alignment's offsets) less the deviation `mpc-rig simulate` predicted
//! for the printed parts at that driver angle and direction, and for a 1R1T follower the
//! height error likewise. Small against the prediction
//! while large against the target means the parts move as predicted and the design (or
//! its print) is what differs from the target; large against both means something the
//! prediction does not model (the bench, the print, the load). It reads no files itself.

use std::path::PathBuf;

use serde::Serialize;

use super::run::{MeasuredRun, Phase};
use super::Analysis;
use crate::predict::table::PredictedDeviation;

/// The measurement against the prediction: the turn's errors (1R, 1R1T), and a 1R1T
/// follower's heights.
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
    /// 1R1T: the same for the height along the axis.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub height: Option<HeightComparison>,
}

/// A 1R1T follower's measured heights against the prediction.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct HeightComparison {
    /// RMS of measured − predicted, mm.
    pub rms_mm: f64,
    /// Largest |measured − predicted|, mm.
    pub max_mm: f64,
    /// RMS of measured − target over the same samples, mm.
    pub rms_vs_target_mm: f64,
    /// Measured samples compared.
    pub samples: usize,
}

/// RMS and largest |error − predicted| of channel `name`, the RMS of the error alone, and
/// the samples compared; `None` without the channel, its prediction or any finite sample.
fn residuals(
    a: &Analysis,
    run: &MeasuredRun,
    name: &str,
    predicted: &PredictedDeviation,
) -> Option<(f64, f64, f64, usize)> {
    let ch = a.errors.iter().find(|c| c.name == name)?;
    let d0 = a.alignment.driver_offset_deg.value;
    let (mut sq, mut sq_target, mut max, mut n) = (0.0, 0.0, 0.0f64, 0usize);
    for i in run.measured_indices() {
        let e = ch.values[i];
        if !e.is_finite() {
            continue;
        }
        let forward = run.phase[i] != Phase::Reverse;
        let r = e - predicted.of(name, run.driver_deg[i] - d0, forward)?;
        sq += r * r;
        sq_target += e * e;
        max = max.max(r.abs());
        n += 1;
    }
    (n > 0).then(|| {
        (
            (sq / n as f64).sqrt(),
            max,
            (sq_target / n as f64).sqrt(),
            n,
        )
    })
}

/// Compare the errors of `a` (from `run`) with `predicted`: rz, and tz for 1R1T; `None`
/// when the analysis is of another class or has no rz channel.
pub fn compare(
    a: &Analysis,
    run: &MeasuredRun,
    predicted: &PredictedDeviation,
    file: PathBuf,
) -> Option<PredictionComparison> {
    if a.class != "1R" && a.class != "1R1T" {
        return None;
    }
    let (rms_deg, max_deg, rms_vs_target_deg, samples) = residuals(a, run, "rz", predicted)?;
    let height =
        residuals(a, run, "tz", predicted).map(|(rms_mm, max_mm, rms_vs_target_mm, samples)| {
            HeightComparison {
                rms_mm,
                max_mm,
                rms_vs_target_mm,
                samples,
            }
        });
    Some(PredictionComparison {
        file,
        rms_deg,
        max_deg,
        rms_vs_target_deg,
        samples,
        drive_lost_deg: predicted.lost_windows_deg().to_vec(),
        height,
    })
}
