//! Measured versus target: turns a recording into follower poses, aligns it with the target
//! law, computes error metrics and timing ratios, and writes the report.
//!
//! The pipeline, one file per step:
//! - [`run`]: the measured run in physical units (time, phase, driver angle, follower pose)
//!   and angle unwrapping;
//! - [`load`]: a recording directory plus its rig calibration → [`MeasuredRun`], and a
//!   mechanism or motion file → [`TargetLaw`];
//! - [`target`]: the target law tabulated over the driver angle (follower at φ is M²(φ/2π));
//! - [`mod@align`]: constant driver-angle and sensor offsets (3R: frame offsets), lag and
//!   backlash when both directions were run, all reported with standard errors;
//! - [`metrics`]: per-sample errors and their statistics per channel, direction and cycle;
//!   repeatability and hysteresis;
//! - [`sampling`]: sample rate, jitter and gaps;
//! - [`timing`]: follower-angle crossings, durations and their ratios with uncertainty;
//! - [`report`]: plots, `report.md`, `report.html` and `summary.json`, pass/fail against
//!   tolerances.
//!
//! It does not talk to devices; it reads recordings (see [`crate::rig`] for how they are made).

pub mod align;
mod error;
pub mod load;
pub mod metrics;
pub mod prediction;
pub mod report;
pub mod run;
pub mod sampling;
pub mod synthetic;
pub mod target;
pub mod timing;

use nalgebra::UnitQuaternion;

pub use align::{align, Alignment, Dof, Estimate};
pub use error::AnalysisError;
pub use load::{analyze_and_report, load_run, load_target, TargetSource};
pub use metrics::{ChannelErrors, ChannelMetrics, ErrorStats};
pub use report::{ReportOptions, Summary};
pub use run::{MeasuredRun, Phase, Resolution};
pub use sampling::SamplingStats;
pub use target::TargetLaw;
pub use timing::TimingReport;

/// What to compute beyond the always-on metrics.
#[derive(Debug, Clone, Default)]
pub struct AnalysisOptions {
    /// Follower crossing angles for timing ratios (1R/1R1T), relative to the cycle start.
    /// `None` uses [`default_timing_levels`].
    pub timing_levels: Option<Vec<f64>>,
}

/// The default crossing angles: 0, 180°, 360° in the direction of the follower's net
/// rotation (the paper's half-turn timing), or none for an oscillating follower.
pub fn default_timing_levels(law: &TargetLaw) -> Option<Vec<f64>> {
    match law.net_turns() {
        0 => None,
        n => {
            let s = n.signum() as f64;
            Some(vec![0.0, 180.0 * s, 360.0 * s])
        }
    }
}

/// Phase lag of the follower behind the driver: the constant driver-angle offset δ₀ (a
/// homing error looks the same and cannot be told apart), and as a time at the forward speed.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct PhaseLag {
    /// Lag in degrees of driver angle.
    pub driver_deg: Estimate,
    /// The same as a time at the median forward driver speed, when the driver moved.
    pub ms: Option<f64>,
}

/// Backlash seen between the two run directions (only with forward and reverse runs).
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Backlash {
    /// Driver-side dead band 2λ in driver degrees (includes 2 × any time lag × speed).
    pub driver_deg: Estimate,
    /// Follower-side dead band per scalar DOF, in the DOF's unit (`rz` deg, `tz` mm).
    pub follower: Vec<(Dof, Estimate)>,
}

/// Orientation error at one key pose of a 3R motion, over the cycles that pass it.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct KeyPoseError {
    /// Key pose index (0-based, in the motion's order).
    pub index: usize,
    /// Fraction of the period.
    pub t: f64,
    /// Cycles (and directions) that passed it.
    pub passes: usize,
    /// Mean geodesic error.
    pub mean_deg: f64,
    /// Largest geodesic error.
    pub max_deg: f64,
}

/// The complete in-memory analysis of a run.
#[derive(Debug, Clone)]
pub struct Analysis {
    /// "1R", "1R1T" or "3R".
    pub class: &'static str,
    /// Fitted offsets.
    pub alignment: Alignment,
    /// Phase lag.
    pub phase_lag: PhaseLag,
    /// Backlash, when both directions were run.
    pub backlash: Option<Backlash>,
    /// Sampling figures.
    pub sampling: SamplingStats,
    /// Per channel statistics (first the headline channel: rz or rotation).
    pub channels: Vec<ChannelMetrics>,
    /// Per-sample errors (same order as `channels`).
    pub errors: Vec<ChannelErrors>,
    /// Timing ratios (1R/1R1T with a turning follower or explicit levels).
    pub timing: Option<TimingReport>,
    /// 3R key pose errors.
    pub key_poses: Vec<KeyPoseError>,
    /// 3R forward/reverse difference of the error rotation vectors.
    pub rotation_hysteresis: Option<metrics::Hysteresis>,
}

/// Analyse `run` against `law`.
pub fn analyze(
    run: &MeasuredRun,
    law: &TargetLaw,
    opts: &AnalysisOptions,
) -> Result<Analysis, AnalysisError> {
    run.validate()?;
    let alignment = align(run, law)?;
    let sampling = sampling::sampling_stats(run);
    let errors = metrics::channel_errors(run, law, &alignment);
    let channels: Vec<ChannelMetrics> = errors
        .iter()
        .map(|e| metrics::channel_metrics(run, e))
        .collect();
    let phase_lag = {
        let driver = alignment.driver_offset_deg;
        PhaseLag {
            driver_deg: driver,
            ms: sampling
                .driver_speed_forward_deg_per_s
                .filter(|s| *s > 0.0)
                .map(|s| driver.value / s * 1e3),
        }
    };
    let backlash = alignment.lag_driver_deg.map(|l| Backlash {
        driver_deg: Estimate {
            value: 2.0 * l.value,
            std_err: 2.0 * l.std_err,
            determined: l.determined,
        },
        follower: alignment
            .dofs
            .iter()
            .filter_map(|d| d.backlash.map(|b| (d.dof, b)))
            .collect(),
    });
    let levels = match &opts.timing_levels {
        Some(l) => Some(l.clone()),
        None => default_timing_levels(law),
    };
    let timing = match (&law.rz_deg, &run.rz_deg, levels) {
        (Some(table), Some(y), Some(levels)) => {
            if law.rotation.is_some() {
                None
            } else {
                let off = alignment
                    .dofs
                    .iter()
                    .find(|d| d.dof == Dof::Rz)
                    .map_or(0.0, |d| d.total_offset());
                let follower: Vec<f64> = y.iter().map(|v| v - off).collect();
                let input = timing::TimingInput {
                    run,
                    follower_deg: &follower,
                    target: table,
                    quantum_deg: run.resolution.rz_deg,
                    levels_deg: &levels,
                };
                match timing::timing(&input) {
                    Ok(t) => Some(t),
                    Err(AnalysisError::NotEnoughData(m)) if opts.timing_levels.is_none() => {
                        tracing::warn!("no timing ratios: {m}");
                        None
                    }
                    Err(e) => return Err(e),
                }
            }
        }
        (None, _, Some(_)) if opts.timing_levels.is_some() => {
            return Err(AnalysisError::BadOption {
                option: "--timing".into(),
                message: format!(
                    "timing ratios need a follower turning about z (1R or 1R1T); this target is {}",
                    law.class_name()
                ),
            })
        }
        _ => None,
    };
    let key_poses = key_pose_errors(run, law, &alignment);
    let rotation_hysteresis = match channels.iter().position(|c| c.name == "rx") {
        Some(k) if channels.len() >= k + 3 => {
            metrics::vector_hysteresis([&channels[k], &channels[k + 1], &channels[k + 2]])
        }
        _ => None,
    };
    Ok(Analysis {
        class: law.class_name(),
        alignment,
        phase_lag,
        backlash,
        sampling,
        channels,
        errors,
        timing,
        key_poses,
        rotation_hysteresis,
    })
}

/// For each key pose and each (direction, cycle) that passes it, the geodesic error of the
/// sample nearest to the key pose's driver angle (within one profile bin).
fn key_pose_errors(run: &MeasuredRun, law: &TargetLaw, al: &Alignment) -> Vec<KeyPoseError> {
    let (Some(meas), Some(_)) = (&run.rotation, &law.rotation) else {
        return Vec::new();
    };
    let d0 = al.driver_offset_deg.value;
    let tol = 360.0 / metrics::PROFILE_BINS as f64;
    law.key_poses
        .iter()
        .enumerate()
        .map(|(index, kp)| {
            // Best sample per (direction, cycle): (distance, error).
            let mut best: std::collections::BTreeMap<(i8, i64), (f64, f64)> = Default::default();
            for i in run.measured_indices() {
                let phi = run.driver_deg[i] - d0;
                let cycle = ((phi - 360.0 * kp.t) / 360.0).round();
                let dist = (phi - 360.0 * (cycle + kp.t)).abs();
                if dist > tol {
                    continue;
                }
                let key = (run.phase[i].direction() as i8, cycle as i64);
                let target: UnitQuaternion<f64> =
                    match metrics::aligned_rotation(law, al, run.driver_deg[i]) {
                        Some(t) => t,
                        None => continue,
                    };
                let err = meas[i].angle_to(&target).to_degrees();
                let e = best.entry(key).or_insert((f64::INFINITY, 0.0));
                if dist < e.0 {
                    *e = (dist, err);
                }
            }
            let errs: Vec<f64> = best.values().map(|v| v.1).collect();
            KeyPoseError {
                index,
                t: kp.t,
                passes: errs.len(),
                mean_deg: if errs.is_empty() {
                    f64::NAN
                } else {
                    errs.iter().sum::<f64>() / errs.len() as f64
                },
                max_deg: errs.iter().fold(0.0, |m: f64, v| m.max(*v)),
            }
        })
        .collect()
}
