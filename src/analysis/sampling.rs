//! Sample-rate statistics and gaps, from the device timestamps alone.
//!
//! Owns the figures that say whether the recording itself can be trusted: rate, period
//! spread, gaps and an estimate of the samples lost in them, plus the driver speed per
//! direction (used to turn driver-angle lags into milliseconds). It does not look at the
//! follower. Gaps follow the recording's own rule ([`crate::rig::recording::missing_before`])
//! measured against the median period of the samples used (rows the device flagged stale,
//! such as repeated IMU values, are not samples here), not the nominal rate the sidecar's
//! counts use.

use super::run::{MeasuredRun, Phase};
use crate::rig::recording::missing_before;

/// Sampling figures of a run.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct SamplingStats {
    /// Samples in the run (all phases).
    pub samples: usize,
    /// Time from first to last sample.
    pub duration_s: f64,
    /// (samples − 1) / duration.
    pub mean_rate_hz: f64,
    /// Median sample period.
    pub median_period_ms: f64,
    /// Shortest period.
    pub min_period_ms: f64,
    /// Longest period.
    pub max_period_ms: f64,
    /// Standard deviation of the periods that are not gaps.
    pub period_jitter_ms: f64,
    /// Periods longer than [`crate::rig::recording::GAP_FACTOR`] × median.
    pub gaps: usize,
    /// Samples missing in the gaps, estimated as round(period / median) − 1 per gap.
    pub missing_samples_estimate: u64,
    /// Median driver speed while running forward (degrees of driver angle per second), from
    /// line fits over [`SPEED_WINDOW_S`] windows (see [`driver_speed`]).
    pub driver_speed_forward_deg_per_s: Option<f64>,
    /// Median driver speed while running in reverse (magnitude).
    pub driver_speed_reverse_deg_per_s: Option<f64>,
}

/// Median of a slice (copied; NaN-free input). `None` when empty.
pub fn median(values: &[f64]) -> Option<f64> {
    if values.is_empty() {
        return None;
    }
    let mut v = values.to_vec();
    let mid = v.len() / 2;
    let (_, m, _) = v.select_nth_unstable_by(mid, f64::total_cmp);
    Some(*m)
}

/// Length of the windows over which the driver speed is fitted. A stepper's driver angle
/// moves in whole (micro)steps, so one sample period holds 1 or 2 steps at 30 rpm and
/// 1 kHz and a per-sample difference is 112.5 or 225 °/s, never 180; a line fitted
/// through a quarter second of samples averages the steps out.
pub const SPEED_WINDOW_S: f64 = 0.25;

/// Median driver speed (magnitude, °/s) in phase `ph`: the samples of each stretch of that
/// phase are cut into windows of [`SPEED_WINDOW_S`] (at least 3 samples), a least-squares
/// line is fitted to driver angle over time in each, and the median of the slopes is
/// returned (ramps at a stretch's ends are outvoted by the cruise). `None` without a
/// window of 3 samples.
pub fn driver_speed(run: &MeasuredRun, ph: Phase) -> Option<f64> {
    let t = &run.time_s;
    let d = &run.driver_deg;
    let mut slopes = Vec::new();
    let fit = |lo: usize, hi: usize| -> Option<f64> {
        let n = (hi - lo) as f64;
        let mt = t[lo..hi].iter().sum::<f64>() / n;
        let md = d[lo..hi].iter().sum::<f64>() / n;
        let (mut sxy, mut sxx) = (0.0, 0.0);
        for i in lo..hi {
            sxy += (t[i] - mt) * (d[i] - md);
            sxx += (t[i] - mt) * (t[i] - mt);
        }
        (sxx > 0.0).then(|| (sxy / sxx).abs())
    };
    let mut i = 0;
    while i < t.len() {
        if run.phase[i] != ph {
            i += 1;
            continue;
        }
        // One stretch of the phase: [i, end).
        let mut end = i;
        while end < t.len() && run.phase[end] == ph {
            end += 1;
        }
        let mut lo = i;
        while lo < end {
            let mut hi = lo + 1;
            while hi < end && (t[hi] - t[lo] < SPEED_WINDOW_S || hi - lo < 3) {
                hi += 1;
            }
            // A short tail joins the window before it rather than standing alone.
            if end - hi < 3 || t[end - 1] - t[hi.min(end - 1)] < SPEED_WINDOW_S / 2.0 {
                hi = end;
            }
            if hi - lo >= 3 {
                slopes.extend(fit(lo, hi));
            }
            lo = hi;
        }
        i = end;
    }
    median(&slopes)
}

/// Compute the sampling statistics of `run`.
pub fn sampling_stats(run: &MeasuredRun) -> SamplingStats {
    let t = &run.time_s;
    let periods: Vec<f64> = t.windows(2).map(|w| w[1] - w[0]).collect();
    let med = median(&periods).unwrap_or(0.0);
    let duration = match (t.first(), t.last()) {
        (Some(a), Some(b)) => b - a,
        _ => 0.0,
    };
    let mut gaps = 0;
    let mut missing = 0u64;
    let (mut s, mut s2, mut n) = (0.0, 0.0, 0usize);
    let (mut lo, mut hi) = (f64::INFINITY, 0.0f64);
    for &p in &periods {
        lo = lo.min(p);
        hi = hi.max(p);
        // Both in µs, as the rule is written for device times.
        let m = missing_before((p * 1e6).round() as u64, med * 1e6);
        if m > 0 {
            gaps += 1;
            missing += m;
        } else {
            s += p;
            s2 += p * p;
            n += 1;
        }
    }
    let jitter = if n > 1 {
        let m = s / n as f64;
        ((s2 / n as f64 - m * m).max(0.0)).sqrt()
    } else {
        0.0
    };
    let speed = |ph: Phase| driver_speed(run, ph);
    SamplingStats {
        samples: t.len(),
        duration_s: duration,
        mean_rate_hz: if duration > 0.0 {
            (t.len() - 1) as f64 / duration
        } else {
            0.0
        },
        median_period_ms: med * 1e3,
        min_period_ms: if lo.is_finite() { lo * 1e3 } else { 0.0 },
        max_period_ms: hi * 1e3,
        period_jitter_ms: jitter * 1e3,
        gaps,
        missing_samples_estimate: missing,
        driver_speed_forward_deg_per_s: speed(Phase::Forward),
        driver_speed_reverse_deg_per_s: speed(Phase::Reverse),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Guards gap detection: a 1 kHz stream with 3 samples dropped in one place and 1 in
    /// another reports 2 gaps, 4 missing samples and the true rate.
    #[test]
    fn gaps_and_missing_samples_are_counted() {
        let mut t: Vec<f64> = (0..10_000).map(|i| i as f64 * 1e-3).collect();
        t.drain(5000..5003);
        t.remove(8000);
        let n = t.len();
        let run = MeasuredRun {
            driver_deg: t.iter().map(|x| x * 36.0).collect(),
            phase: vec![Phase::Forward; n],
            time_s: t,
            rz_deg: Some(vec![0.0; n]),
            ..Default::default()
        };
        let s = sampling_stats(&run);
        assert_eq!(s.gaps, 2);
        assert_eq!(s.missing_samples_estimate, 4);
        assert!((s.median_period_ms - 1.0).abs() < 1e-9);
        assert!((s.max_period_ms - 4.0).abs() < 1e-9);
        assert!((s.driver_speed_forward_deg_per_s.unwrap() - 36.0).abs() < 1e-6);
        assert!(s.driver_speed_reverse_deg_per_s.is_none());
    }

    /// Guards the driver speed of a stepper bench (issue 20: 225 °/s reported at 30 rpm,
    /// 337.5 at 60): a driver angle in whole 1/16 microsteps of 1.8° sampled at 1 kHz, with
    /// a ramp at each end of the phase, reads as its true cruise speed, not as the most
    /// common number of steps per sample period.
    #[test]
    fn quantized_stepper_angle_gives_the_true_speed() {
        let step = 1.8 / 16.0;
        for (rpm, reverse) in [(30.0, false), (60.0, true), (5.0, false)] {
            let v: f64 = rpm * 6.0;
            let accel = 720.0;
            let ramp = v / accel;
            let total = 3.0;
            let angle = |t: f64| {
                // Trapezoid: ramp up, cruise, ramp down.
                if t < ramp {
                    0.5 * accel * t * t
                } else if t < total - ramp {
                    0.5 * accel * ramp * ramp + v * (t - ramp)
                } else {
                    let r = total - t;
                    v * (total - ramp) - 0.5 * accel * r * r
                }
            };
            let sign = if reverse { -1.0 } else { 1.0 };
            let t: Vec<f64> = (0..3000).map(|i| i as f64 * 1e-3).collect();
            let n = t.len();
            let run = MeasuredRun {
                driver_deg: t
                    .iter()
                    .map(|&x| sign * (angle(x) / step).floor() * step)
                    .collect(),
                phase: vec![
                    if reverse {
                        Phase::Reverse
                    } else {
                        Phase::Forward
                    };
                    n
                ],
                time_s: t,
                rz_deg: Some(vec![0.0; n]),
                ..Default::default()
            };
            let s = sampling_stats(&run);
            let got = if reverse {
                s.driver_speed_reverse_deg_per_s
            } else {
                s.driver_speed_forward_deg_per_s
            }
            .unwrap();
            assert!((got - v).abs() < 0.05, "{rpm} rpm: {got} °/s, want {v}");
        }
    }
}
