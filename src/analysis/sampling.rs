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
    /// Median driver speed while running forward (degrees of driver angle per second).
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
    let speed = |ph: Phase| {
        let v: Vec<f64> = (1..t.len())
            .filter(|&i| run.phase[i] == ph && run.phase[i - 1] == ph && t[i] > t[i - 1])
            .map(|i| ((run.driver_deg[i] - run.driver_deg[i - 1]) / (t[i] - t[i - 1])).abs())
            .collect();
        median(&v)
    };
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
}
