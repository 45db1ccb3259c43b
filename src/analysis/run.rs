//! The measured run as the analysis sees it: one array per quantity, in physical units.
//!
//! A [`MeasuredRun`] is what a recording becomes after calibration (see [`super::load`]):
//! device time in seconds, the session phase, the driver angle in degrees and the follower's
//! measured pose per degree of freedom (unwrapped rotation about z in degrees, height in
//! millimetres, or an orientation). It owns validation of those arrays and angle unwrapping;
//! it does not know about files or targets.

use nalgebra::UnitQuaternion;

use super::AnalysisError;

/// The session phase a sample belongs to.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Phase {
    /// Run-in before measuring; excluded from every metric.
    Settle,
    /// Driver turning forward (driver angle increasing).
    Forward,
    /// Driver turning in reverse (driver angle decreasing).
    Reverse,
}

impl Phase {
    /// +1 forward, −1 reverse, 0 settle.
    pub fn direction(self) -> f64 {
        match self {
            Phase::Forward => 1.0,
            Phase::Reverse => -1.0,
            Phase::Settle => 0.0,
        }
    }

    /// Parse the recording's spelling (`settle`, `forward`, `reverse`).
    pub fn parse(s: &str) -> Option<Phase> {
        match s {
            "settle" => Some(Phase::Settle),
            "forward" => Some(Phase::Forward),
            "reverse" => Some(Phase::Reverse),
            _ => None,
        }
    }

    /// The recording's spelling.
    pub fn as_str(self) -> &'static str {
        match self {
            Phase::Settle => "settle",
            Phase::Forward => "forward",
            Phase::Reverse => "reverse",
        }
    }
}

/// Smallest representable change of each measured quantity (the sensor's quantization step),
/// used for timing uncertainties. Zero means "continuous" (unknown or simulated without
/// quantization).
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize)]
pub struct Resolution {
    /// Rotation sensor step in degrees (e.g. 360/4096 for an AS5600).
    pub rz_deg: f64,
    /// Height sensor step in millimetres.
    pub tz_mm: f64,
}

/// Measured samples in physical units, one entry per sample in every array.
#[derive(Debug, Clone, Default)]
pub struct MeasuredRun {
    /// Device time in seconds since the stream started.
    pub time_s: Vec<f64>,
    /// Session phase per sample.
    pub phase: Vec<Phase>,
    /// Driver angle in degrees (after gear ratio and direction, unwrapped, 0 at home).
    pub driver_deg: Vec<f64>,
    /// Follower rotation about z in degrees, unwrapped (1R, 1R1T).
    pub rz_deg: Option<Vec<f64>>,
    /// Follower height along z in millimetres (1R1T).
    pub tz_mm: Option<Vec<f64>>,
    /// Follower orientation (3R).
    pub rotation: Option<Vec<UnitQuaternion<f64>>>,
    /// Per sample: the driver was still accelerating (excluded from timing). Empty means
    /// never.
    pub ramping: Vec<bool>,
    /// Sensor quantization steps.
    pub resolution: Resolution,
}

impl MeasuredRun {
    /// Number of samples.
    pub fn len(&self) -> usize {
        self.time_s.len()
    }

    /// True when there are no samples.
    pub fn is_empty(&self) -> bool {
        self.time_s.is_empty()
    }

    /// Check that all arrays have the same length, every value is finite and time does not
    /// go backwards; the error names the column and the first bad sample.
    pub fn validate(&self) -> Result<(), AnalysisError> {
        let n = self.time_s.len();
        let bad_len = |name: &str, len: usize| AnalysisError::BadSample {
            what: format!("column {name} has {len} samples, time has {n}"),
            index: len.min(n),
        };
        if self.phase.len() != n {
            return Err(bad_len("phase", self.phase.len()));
        }
        if self.driver_deg.len() != n {
            return Err(bad_len("driver_angle_deg", self.driver_deg.len()));
        }
        if !self.ramping.is_empty() && self.ramping.len() != n {
            return Err(bad_len("ramping", self.ramping.len()));
        }
        check_finite("device_time", &self.time_s)?;
        check_finite("driver_angle_deg", &self.driver_deg)?;
        if let Some(i) = self.time_s.windows(2).position(|w| w[1] < w[0]) {
            return Err(AnalysisError::BadSample {
                what: format!(
                    "device time goes backwards ({} s after {} s)",
                    self.time_s[i + 1],
                    self.time_s[i]
                ),
                index: i + 1,
            });
        }
        if let Some(v) = &self.rz_deg {
            if v.len() != n {
                return Err(bad_len("rz", v.len()));
            }
            check_finite("rz", v)?;
        }
        if let Some(v) = &self.tz_mm {
            if v.len() != n {
                return Err(bad_len("tz", v.len()));
            }
            check_finite("tz", v)?;
        }
        if let Some(v) = &self.rotation {
            if v.len() != n {
                return Err(bad_len("rotation", v.len()));
            }
            if let Some(i) = v
                .iter()
                .position(|q| !q.coords.iter().all(|c| c.is_finite()))
            {
                return Err(AnalysisError::BadSample {
                    what: "rotation quaternion is not finite".into(),
                    index: i,
                });
            }
        }
        if self.rz_deg.is_none() && self.tz_mm.is_none() && self.rotation.is_none() {
            return Err(AnalysisError::Mismatch(
                "the recording has no follower sensor".into(),
            ));
        }
        Ok(())
    }

    /// Whether sample `i` was taken while the driver was ramping.
    pub fn is_ramping(&self, i: usize) -> bool {
        self.ramping.get(i).copied().unwrap_or(false)
    }

    /// Indices of the samples that count (not settle).
    pub fn measured_indices(&self) -> impl Iterator<Item = usize> + '_ {
        self.phase
            .iter()
            .enumerate()
            .filter(|(_, p)| **p != Phase::Settle)
            .map(|(i, _)| i)
    }
}

fn check_finite(name: &str, v: &[f64]) -> Result<(), AnalysisError> {
    match v.iter().position(|x| !x.is_finite()) {
        Some(i) => Err(AnalysisError::BadSample {
            what: format!("{name} is not a finite number"),
            index: i,
        }),
        None => Ok(()),
    }
}

/// Unwrap an angle sequence in place: whenever consecutive values jump by more than half a
/// `period`, add the multiple of `period` that makes the step smallest. Values that were
/// already continuous are unchanged. Correct as long as the true motion between two samples
/// is less than half a period (180° for an angle; at 1 kHz that allows 500 rev/s).
pub fn unwrap_in_place(values: &mut [f64], period: f64) {
    let mut offset = 0.0;
    let mut prev_raw = match values.first() {
        Some(v) => *v,
        None => return,
    };
    for v in values.iter_mut().skip(1) {
        let raw = *v;
        let d = raw - prev_raw;
        offset -= period * (d / period).round();
        prev_raw = raw;
        *v = raw + offset;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Guards unwrapping of raw encoder angles: a follower turning 2.5 turns forward then
    /// back, seen through a 0..360 wrap, is recovered exactly.
    #[test]
    fn unwrap_recovers_multi_turn_motion() {
        let truth: Vec<f64> = (0..2000)
            .map(|i| {
                let x = i as f64;
                if i < 1000 {
                    0.9 * x
                } else {
                    900.0 - 0.9 * (x - 1000.0)
                }
            })
            .collect();
        let mut wrapped: Vec<f64> = truth.iter().map(|v| v.rem_euclid(360.0)).collect();
        unwrap_in_place(&mut wrapped, 360.0);
        for (a, b) in wrapped.iter().zip(&truth) {
            assert!((a - b).abs() < 1e-9);
        }
    }

    /// Guards validation messages: a NaN in the follower column is reported with its column
    /// name and index, and time going backwards with its index.
    #[test]
    fn validation_names_column_and_sample() {
        let mut run = MeasuredRun {
            time_s: vec![0.0, 0.001, 0.002],
            phase: vec![Phase::Forward; 3],
            driver_deg: vec![0.0, 0.1, 0.2],
            rz_deg: Some(vec![0.0, f64::NAN, 0.2]),
            ..Default::default()
        };
        let e = run.validate().unwrap_err().to_string();
        assert!(e.contains("rz") && e.contains("sample 1"), "{e}");
        run.rz_deg = Some(vec![0.0; 3]);
        run.time_s[2] = 0.0;
        let e = run.validate().unwrap_err().to_string();
        assert!(e.contains("backwards") && e.contains("sample 2"), "{e}");
    }
}
