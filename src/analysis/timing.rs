//! Timing ratios (1R, 1R1T): when does the follower pass chosen angles, and how do the
//! durations between those crossings compare with the target?
//!
//! For each complete forward cycle k the levels are `θ_T(360°·k) + a_j` (the target's
//! follower angle at the cycle start plus the user's crossing angles a_j, e.g. 0, 180, 360),
//! compared with the measured angle after removing the sensor offset. Each crossing time is
//! found by interpolation: a least-squares line is fitted to the samples on each side of the
//! bracketing pair; if the two slopes agree (within their uncertainty) one joint line is
//! used, otherwise the law has a kink between the two samples and the crossing lies on
//! whichever line reaches the level before the kink. This is exact on a noiseless
//! piecewise-linear law with at most one kink per sample interval, and second-order accurate
//! on smooth laws. The crossing's standard uncertainty combines the line fit's (residual
//! noise, floored at the encoder's quantization step q/√12), the quantization step seen
//! through the slope, and the device clock's resolution; durations, driver-angle spans and
//! ratios carry it by first-order propagation. Across cycles, the mean ratio's uncertainty
//! is the larger of the propagated one and the observed scatter, divided by √cycles, and is
//! reported expanded (k = 2, ≈95 %).
//!
//! It does not align anything; it takes the sensor offset from [`mod@super::align`].

use super::metrics::{cycle_coverage, FULL_CYCLE_COVERAGE, PROFILE_BINS};
use super::run::{MeasuredRun, Phase};
use super::target::PeriodicTable;
use super::AnalysisError;

/// Fewest samples in each side's line fit. Default 2: two samples define a line, which is
/// what makes the estimator exact on noiseless piecewise-linear laws.
pub const TIMING_MIN_HALF_WINDOW: usize = 2;

/// Most samples in each side's line fit. Default 64: at 1 kHz that is 64 ms of data, enough
/// to average quantization and noise without bending around the law's curvature.
pub const TIMING_MAX_HALF_WINDOW: usize = 64;

/// Each side's fit window grows until the follower moves by at least this many noise steps
/// (the larger of the quantization step and three noise standard deviations). Default 4:
/// below that a line through a staircase or noise is ill-determined.
pub const TIMING_WINDOW_STEPS: f64 = 4.0;

/// Resolution of the device clock, seconds. Default 1 µs (the recording's `device_time_us`).
pub const CLOCK_RESOLUTION_S: f64 = 1e-6;

/// A cycle is used for timing only when the driver speed over each of its durations
/// (span / duration) stays within this fraction of the cycle's mean speed. Default 0.02: a
/// stepper at constant commanded speed holds it to far better than 0.1 %; a cycle that
/// includes an acceleration ramp or a stall would bias the time ratio and is left out.
pub const TIMING_STEADY_SPEED: f64 = 0.02;

/// Coverage factor for reported expanded uncertainties. Default 2 (≈95 % for normal errors).
pub const COVERAGE_FACTOR: f64 = 2.0;

/// One crossing of a level.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Crossing {
    /// Device time of the crossing.
    pub time_s: f64,
    /// Standard uncertainty of the time.
    pub time_u_s: f64,
    /// Driver angle at the crossing.
    pub driver_deg: f64,
    /// Standard uncertainty of the driver angle (time uncertainty times driver speed).
    pub driver_u_deg: f64,
}

/// Timing of one forward cycle.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct CycleTiming {
    /// Cycle number ⌊φ/360°⌋.
    pub cycle: i64,
    /// One crossing per level.
    pub crossings: Vec<Crossing>,
    /// Durations between consecutive crossings.
    pub durations_s: Vec<f64>,
    /// Driver-angle spans between consecutive crossings.
    pub spans_deg: Vec<f64>,
    /// duration_j / duration_{j+1}.
    pub ratios: Vec<f64>,
    /// Expanded uncertainty (k = 2) of each ratio.
    pub ratios_u95: Vec<f64>,
}

/// A ratio of consecutive durations, measured over all cycles against the target.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct RatioEstimate {
    /// Which durations: `j` means duration j / duration j+1.
    pub index: usize,
    /// Level at the start of the first duration, the shared level, and the end (degrees).
    pub levels_deg: [f64; 3],
    /// Mean measured ratio of durations (time).
    pub measured: f64,
    /// Expanded uncertainty (k = 2) of the mean.
    pub u95: f64,
    /// Mean measured ratio of driver-angle spans.
    pub measured_span_ratio: f64,
    /// The target's ratio (driver-angle spans of the target law; equal to the time ratio at
    /// constant driver speed).
    pub target: f64,
    /// Standard deviation of the per-cycle ratios.
    pub cycle_std: f64,
}

/// All timing figures.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct TimingReport {
    /// Crossing angles relative to the cycle start (degrees of follower rotation).
    pub levels_deg: Vec<f64>,
    /// The target's driver-angle spans between consecutive levels.
    pub target_spans_deg: Vec<f64>,
    /// Mean measured durations between consecutive levels.
    pub mean_durations_s: Vec<f64>,
    /// Mean measured driver-angle spans.
    pub mean_spans_deg: Vec<f64>,
    /// Ratios of consecutive durations.
    pub ratios: Vec<RatioEstimate>,
    /// Per complete forward cycle.
    pub cycles: Vec<CycleTiming>,
    /// Complete cycles left out because the driver speed was not steady
    /// ([`TIMING_STEADY_SPEED`]).
    pub cycles_rejected_unsteady: usize,
    /// Cycles whose crossings were all found but whose samples cover less than
    /// [`FULL_CYCLE_COVERAGE`] of the revolution (gaps): left out, since a crossing fitted
    /// across a gap is a guess, and the headline counts only covered cycles.
    pub cycles_rejected_gaps: usize,
}

/// Parse `--timing 0,180,360`: at least two strictly monotone, finite angles.
pub fn parse_levels(text: &str) -> Result<Vec<f64>, AnalysisError> {
    let bad = |m: String| AnalysisError::BadOption {
        option: "--timing".into(),
        message: m,
    };
    let levels = text
        .split(',')
        .map(|s| {
            s.trim()
                .parse::<f64>()
                .ok()
                .filter(|v| v.is_finite())
                .ok_or_else(|| bad(format!("{:?} is not a finite angle in degrees", s.trim())))
        })
        .collect::<Result<Vec<f64>, _>>()?;
    check_levels(&levels).map_err(bad)?;
    Ok(levels)
}

fn check_levels(levels: &[f64]) -> Result<(), String> {
    if levels.len() < 2 {
        return Err("give at least two crossing angles, e.g. 0,180,360".into());
    }
    let up = levels[1] > levels[0];
    if levels
        .windows(2)
        .any(|w| (w[1] > w[0]) != up || w[1] == w[0])
    {
        return Err(format!(
            "crossing angles must be strictly monotone, got {levels:?}"
        ));
    }
    Ok(())
}

/// Inputs of [`timing`].
#[derive(Debug, Clone, Copy)]
pub struct TimingInput<'a> {
    /// The run (time, phase, driver angle).
    pub run: &'a MeasuredRun,
    /// Measured follower angle with the sensor offset removed (degrees), one per sample.
    pub follower_deg: &'a [f64],
    /// The target rotation law.
    pub target: &'a PeriodicTable,
    /// Encoder quantization step in degrees (0 when continuous).
    pub quantum_deg: f64,
    /// Crossing angles relative to the cycle start.
    pub levels_deg: &'a [f64],
}

/// Compute the timing figures over all complete forward cycles.
pub fn timing(input: &TimingInput<'_>) -> Result<TimingReport, AnalysisError> {
    let levels = input.levels_deg;
    check_levels(levels).map_err(|m| AnalysisError::BadOption {
        option: "--timing".into(),
        message: m,
    })?;
    let target = input.target;
    let base0 = target.value(0.0);
    // Target crossings within one revolution starting at φ = 0.
    let mut target_phi = Vec::with_capacity(levels.len());
    let mut from = 0.0;
    for &a in levels {
        let phi = target.first_crossing(base0 + a, from, 2.0).ok_or_else(|| {
            AnalysisError::BadOption {
                option: "--timing".into(),
                message: format!(
                    "the target law never reaches {a}° (relative to its start) within two revolutions"
                ),
            }
        })?;
        target_phi.push(phi);
        from = phi;
    }
    let target_spans: Vec<f64> = target_phi.windows(2).map(|w| w[1] - w[0]).collect();
    let noise = noise_std(input.follower_deg, input.run);
    let step = input.quantum_deg.max(3.0 * noise);
    let mut cycles = Vec::new();
    let mut rejected = 0;
    let mut rejected_gaps = 0;
    for (s, e) in forward_segments(input.run) {
        let phi = &input.run.driver_deg;
        let coverage = coverage_by_cycle(&phi[s..e]);
        let k0 = (phi[s] / 360.0).floor() as i64;
        let k1 = (phi[e - 1] / 360.0).floor() as i64;
        let mut start = s;
        for k in k0..=k1 {
            let base = target.value(360.0 * k as f64);
            let mut crossings = Vec::with_capacity(levels.len());
            let mut i = start;
            for (j, &a) in levels.iter().enumerate() {
                let limit_phi = 360.0 * k as f64 + target_phi[j] + 180.0;
                let earliest_phi = 360.0 * k as f64 + target_phi[j] - 180.0;
                while i < e && phi[i] < earliest_phi {
                    i += 1;
                }
                match find_crossing(input, base + a, i.max(s + 1), e, limit_phi, step) {
                    Some((c, next)) => {
                        crossings.push(c);
                        i = next;
                    }
                    None => break,
                }
            }
            if crossings.len() == levels.len() {
                start = i.saturating_sub(1).max(s);
                let c = cycle_timing(k, crossings);
                if coverage.get(&k).copied().unwrap_or(0.0) < FULL_CYCLE_COVERAGE {
                    rejected_gaps += 1;
                } else if steady(&c) {
                    cycles.push(c);
                } else {
                    rejected += 1;
                }
            }
        }
    }
    if cycles.is_empty() {
        return Err(AnalysisError::NotEnoughData(format!(
            "no complete forward cycle at steady speed passes all timing angles {levels:?} \
             ({rejected} complete cycles had an unsteady driver speed, {rejected_gaps} too \
             many missing samples)"
        )));
    }
    let nl = levels.len();
    let kc = cycles.len() as f64;
    let mean_of = |f: &dyn Fn(&CycleTiming) -> f64| cycles.iter().map(f).sum::<f64>() / kc;
    let mean_durations: Vec<f64> = (0..nl - 1)
        .map(|j| mean_of(&|c| c.durations_s[j]))
        .collect();
    let mean_spans: Vec<f64> = (0..nl - 1).map(|j| mean_of(&|c| c.spans_deg[j])).collect();
    let ratios = (0..nl.saturating_sub(2))
        .map(|j| {
            let m = mean_of(&|c| c.ratios[j]);
            let var = if cycles.len() > 1 {
                cycles
                    .iter()
                    .map(|c| (c.ratios[j] - m).powi(2))
                    .sum::<f64>()
                    / (kc - 1.0)
            } else {
                0.0
            };
            let prop = (cycles
                .iter()
                .map(|c| (c.ratios_u95[j] / COVERAGE_FACTOR).powi(2))
                .sum::<f64>()
                / kc)
                .sqrt();
            let u = prop.max(var.sqrt()) / kc.sqrt();
            RatioEstimate {
                index: j,
                levels_deg: [levels[j], levels[j + 1], levels[j + 2]],
                measured: m,
                u95: COVERAGE_FACTOR * u,
                measured_span_ratio: mean_of(&|c| c.spans_deg[j] / c.spans_deg[j + 1]),
                target: target_spans[j] / target_spans[j + 1],
                cycle_std: var.sqrt(),
            }
        })
        .collect();
    Ok(TimingReport {
        levels_deg: levels.to_vec(),
        target_spans_deg: target_spans,
        mean_durations_s: mean_durations,
        mean_spans_deg: mean_spans,
        ratios,
        cycles,
        cycles_rejected_unsteady: rejected,
        cycles_rejected_gaps: rejected_gaps,
    })
}

/// Whether the driver speed was steady over the cycle's durations.
fn steady(c: &CycleTiming) -> bool {
    let total_t: f64 = c.durations_s.iter().sum();
    let total_phi: f64 = c.spans_deg.iter().sum();
    if total_t <= 0.0 || total_phi == 0.0 {
        return false;
    }
    let mean = total_phi / total_t;
    c.durations_s
        .iter()
        .zip(&c.spans_deg)
        .all(|(d, s)| *d > 0.0 && ((s / d) / mean - 1.0).abs() <= TIMING_STEADY_SPEED)
}

fn cycle_timing(cycle: i64, crossings: Vec<Crossing>) -> CycleTiming {
    let durations: Vec<f64> = crossings
        .windows(2)
        .map(|w| w[1].time_s - w[0].time_s)
        .collect();
    let spans: Vec<f64> = crossings
        .windows(2)
        .map(|w| w[1].driver_deg - w[0].driver_deg)
        .collect();
    let mut ratios = Vec::new();
    let mut u95 = Vec::new();
    for j in 0..durations.len().saturating_sub(1) {
        let (d0, d1) = (durations[j], durations[j + 1]);
        let r = d0 / d1;
        // r = (t1 − t0)/(t2 − t1): exact first-order propagation with the shared t1.
        let g = [-1.0 / d1, 1.0 / d1 + d0 / (d1 * d1), -d0 / (d1 * d1)];
        let var: f64 = (0..3)
            .map(|m| (g[m] * crossings[j + m].time_u_s).powi(2))
            .sum();
        ratios.push(r);
        u95.push(COVERAGE_FACTOR * var.sqrt());
    }
    CycleTiming {
        cycle,
        crossings,
        durations_s: durations,
        spans_deg: spans,
        ratios,
        ratios_u95: u95,
    }
}

/// Contiguous runs of forward samples, as [start, end).
/// Coverage ([`cycle_coverage`] over [`PROFILE_BINS`] bins) of each driver revolution k
/// (φ in [360k, 360k + 360)) by the samples of one forward segment.
fn coverage_by_cycle(phi: &[f64]) -> std::collections::BTreeMap<i64, f64> {
    let mut occupied: std::collections::BTreeMap<i64, Vec<bool>> = Default::default();
    for &p in phi {
        let k = (p / 360.0).floor();
        let bin = (((p - 360.0 * k) / 360.0 * PROFILE_BINS as f64) as usize).min(PROFILE_BINS - 1);
        occupied
            .entry(k as i64)
            .or_insert_with(|| vec![false; PROFILE_BINS])[bin] = true;
    }
    occupied
        .into_iter()
        .map(|(k, o)| (k, cycle_coverage(&o)))
        .collect()
}

fn forward_segments(run: &MeasuredRun) -> Vec<(usize, usize)> {
    let mut out = Vec::new();
    let mut i = 0;
    while i < run.len() {
        if run.phase[i] == Phase::Forward && !run.is_ramping(i) {
            let s = i;
            while i < run.len() && run.phase[i] == Phase::Forward && !run.is_ramping(i) {
                i += 1;
            }
            if i - s >= 2 {
                out.push((s, i));
            }
        } else {
            i += 1;
        }
    }
    out
}

/// Robust high-frequency noise estimate from second differences (MAD of y_{i+1} − 2y_i +
/// y_{i−1}, whose standard deviation is √6·σ for white noise).
fn noise_std(y: &[f64], run: &MeasuredRun) -> f64 {
    let stride = (y.len() / 50_000).max(1);
    let d: Vec<f64> = (1..y.len().saturating_sub(1))
        .step_by(stride)
        .filter(|&i| run.phase[i] == Phase::Forward)
        .map(|i| (y[i + 1] - 2.0 * y[i] + y[i - 1]).abs())
        .filter(|v| v.is_finite())
        .collect();
    super::sampling::median(&d).map_or(0.0, |m| m / 0.6745 / 6f64.sqrt())
}

struct Line {
    /// Value at t = t_ref.
    y0: f64,
    slope: f64,
    t_mean: f64,
    stt: f64,
    n: usize,
    ssr: f64,
}

impl Line {
    fn fit(t: &[f64], y: &[f64], t_ref: f64) -> Option<Line> {
        let n = t.len();
        if n < 2 {
            return None;
        }
        let tm = t.iter().map(|v| v - t_ref).sum::<f64>() / n as f64;
        let ym = y.iter().sum::<f64>() / n as f64;
        let (mut stt, mut sty) = (0.0, 0.0);
        for (a, b) in t.iter().zip(y) {
            let dt = a - t_ref - tm;
            stt += dt * dt;
            sty += dt * (b - ym);
        }
        if stt <= 0.0 {
            return None;
        }
        let slope = sty / stt;
        let y0 = ym - slope * tm;
        let ssr = t
            .iter()
            .zip(y)
            .map(|(a, b)| (b - (y0 + slope * (a - t_ref))).powi(2))
            .sum();
        Some(Line {
            y0,
            slope,
            t_mean: tm,
            stt,
            n,
            ssr,
        })
    }

    /// Local time (relative to t_ref) where the line reaches `level`.
    fn cross(&self, level: f64) -> f64 {
        (level - self.y0) / self.slope
    }

    /// Standard uncertainty of the crossing time for value noise σ.
    fn cross_u(&self, level: f64, sigma: f64) -> f64 {
        let tc = self.cross(level);
        sigma / self.slope.abs()
            * (1.0 / self.n as f64 + (tc - self.t_mean).powi(2) / self.stt).sqrt()
    }
}

/// Find the first crossing of `level` at or after sample `from` (needs a sample before it),
/// before the driver passes `limit_phi` or the segment ends. Returns the crossing and the
/// index to continue from.
fn good(l: &Option<Line>) -> Option<&Line> {
    l.as_ref().filter(|l| l.slope.is_finite() && l.slope != 0.0)
}

fn find_crossing(
    input: &TimingInput<'_>,
    level: f64,
    from: usize,
    end: usize,
    limit_phi: f64,
    step: f64,
) -> Option<(Crossing, usize)> {
    let (t, y, phi) = (&input.run.time_s, input.follower_deg, &input.run.driver_deg);
    let mut b = from;
    while b < end {
        if phi[b] > limit_phi {
            return None;
        }
        let (da, db) = (y[b - 1] - level, y[b] - level);
        if (da < 0.0 && db >= 0.0) || (da > 0.0 && db <= 0.0) {
            break;
        }
        b += 1;
    }
    if b >= end {
        return None;
    }
    let a = b - 1;
    let seg_start = {
        let mut s = a;
        while s > 0 && input.run.phase[s - 1] == Phase::Forward && !input.run.is_ramping(s - 1) {
            s -= 1;
        }
        s
    };
    // Grow each side's window until it spans TIMING_WINDOW_STEPS noise steps.
    let need = TIMING_WINDOW_STEPS * step;
    let mut ml = TIMING_MIN_HALF_WINDOW;
    while ml < TIMING_MAX_HALF_WINDOW
        && a + 1 > ml
        && a + 1 - ml > seg_start
        && (y[a] - y[a + 1 - ml]).abs() < need
    {
        ml += 1;
    }
    let mut mr = TIMING_MIN_HALF_WINDOW;
    while mr < TIMING_MAX_HALF_WINDOW && b + mr < end && (y[b + mr - 1] - y[b]).abs() < need {
        mr += 1;
    }
    let l0 = (a + 1).saturating_sub(ml).max(seg_start);
    let r1 = (b + mr).min(end);
    let t_ref = t[a];
    let q = input.quantum_deg;
    let left = Line::fit(&t[l0..=a], &y[l0..=a], t_ref);
    let right = Line::fit(&t[b..r1], &y[b..r1], t_ref);
    let joint = Line::fit(&t[l0..r1], &y[l0..r1], t_ref);
    let interp = || {
        let w = (level - y[a]) / (y[b] - y[a]);
        let tc = w * (t[b] - t[a]);
        let slope = (y[b] - y[a]) / (t[b] - t[a]);
        (tc, q / 12f64.sqrt() / slope.abs())
    };
    let (tc_local, u_fit, slope) = match (good(&left), good(&right), good(&joint)) {
        (Some(l), Some(r), Some(j)) => {
            let dof = (l.n + r.n).saturating_sub(4).max(1) as f64;
            let sigma = ((l.ssr + r.ssr) / dof).sqrt().max(q / 12f64.sqrt());
            let sd = sigma * (1.0 / l.stt + 1.0 / r.stt).sqrt();
            let tol = 1e-9 * l.slope.abs().max(r.slope.abs());
            if (l.slope - r.slope).abs() <= (3.0 * sd).max(tol) {
                let dofj = (j.n.saturating_sub(2)).max(1) as f64;
                let sj = (j.ssr / dofj).sqrt().max(q / 12f64.sqrt());
                (j.cross(level), j.cross_u(level, sj), j.slope)
            } else {
                // Kink between the lines: the crossing is on the line that gets there first.
                let t_kink = (r.y0 - l.y0) / (l.slope - r.slope);
                let tl = l.cross(level);
                if tl <= t_kink {
                    (tl, l.cross_u(level, sigma), l.slope)
                } else {
                    (r.cross(level), r.cross_u(level, sigma), r.slope)
                }
            }
        }
        _ => {
            let (tc, u) = interp();
            (tc, u, (y[b] - y[a]) / (t[b] - t[a]))
        }
    };
    // Sanity: a crossing must lie within the bracketing interval (± one sample); otherwise
    // the lines were bent by something else and plain interpolation is the honest answer.
    let (tc_local, u_fit, slope) =
        if tc_local.is_finite() && tc_local >= -(t[b] - t[a]) && tc_local <= 2.0 * (t[b] - t[a]) {
            (tc_local, u_fit, slope)
        } else {
            let (tc, u) = interp();
            (tc, u, (y[b] - y[a]) / (t[b] - t[a]))
        };
    let u_q = q / 12f64.sqrt() / slope.abs();
    let u_clock = CLOCK_RESOLUTION_S / 12f64.sqrt();
    let time_u = (u_fit * u_fit + u_q * u_q + u_clock * u_clock).sqrt();
    let time = t_ref + tc_local;
    // Driver angle at the crossing, by interpolation on the driver's own samples.
    let mut k = a;
    while k + 1 < end && t[k + 1] < time {
        k += 1;
    }
    while k > seg_start && t[k] > time {
        k -= 1;
    }
    let k1 = (k + 1).min(end - 1);
    let driver = if t[k1] > t[k] {
        phi[k] + (phi[k1] - phi[k]) * (time - t[k]) / (t[k1] - t[k])
    } else {
        phi[k]
    };
    let speed = if t[b] > t[a] {
        (phi[b] - phi[a]) / (t[b] - t[a])
    } else {
        0.0
    };
    Some((
        Crossing {
            time_s: time,
            time_u_s: time_u,
            driver_deg: driver,
            driver_u_deg: time_u * speed.abs(),
        },
        b,
    ))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::analysis::synthetic::{piecewise_half_turn, SyntheticBench};

    /// Guards the steady-speed rule: a cycle whose second half runs 5 % faster (a speed
    /// change, not the mechanism) is rejected rather than reported as a ratio change.
    #[test]
    fn unsteady_cycle_is_rejected() {
        let law = piecewise_half_turn(2.0 / 3.0);
        let mut run = SyntheticBench::default().generate(&law);
        // Compress time after driver angle 1000° by 5 %: the driver sped up there.
        let i0 = run.driver_deg.iter().position(|p| *p > 1000.0).unwrap();
        let t0 = run.time_s[i0];
        for t in &mut run.time_s[i0..] {
            *t = t0 + (*t - t0) / 1.05;
        }
        let table = law.rz_deg.as_ref().unwrap();
        let follower = run.rz_deg.clone().unwrap();
        let r = timing(&TimingInput {
            run: &run,
            follower_deg: &follower,
            target: table,
            quantum_deg: 0.0,
            levels_deg: &[0.0, 180.0, 360.0],
        })
        .unwrap();
        assert_eq!(
            r.cycles_rejected_unsteady,
            1,
            "{:?}",
            r.cycles.iter().map(|c| c.cycle).collect::<Vec<_>>()
        );
        assert!((r.ratios[0].measured - 2.0).abs() < 1e-9);
    }

    /// Guards the coverage rule (issue 16: a stepper run with 72 % of its samples missing
    /// still gave a timing ratio from cycles the headline counted as incomplete): a forward
    /// cycle missing a 60° stretch of driver angle away from every crossing is left out of
    /// the timing (counted in `cycles_rejected_gaps`), the fully covered ones are used.
    #[test]
    fn cycle_with_a_gap_is_left_out_of_timing() {
        let law = piecewise_half_turn(2.0 / 3.0);
        let full = SyntheticBench::default().generate(&law);
        let table = law.rz_deg.as_ref().unwrap();
        let input = |run: &MeasuredRun| {
            let follower = run.rz_deg.clone().unwrap();
            timing(&TimingInput {
                run,
                follower_deg: &follower,
                target: table,
                quantum_deg: 0.0,
                levels_deg: &[0.0, 180.0, 360.0],
            })
            .unwrap()
        };
        let before = input(&full);
        assert_eq!(before.cycles_rejected_gaps, 0);
        // Drop the samples between 60° and 120° of driver angle in the second forward
        // cycle (crossings of this law lie at 0°, 240° and 360°).
        let first = before.cycles[0].cycle;
        let lo = 360.0 * (first + 1) as f64 + 60.0;
        let keep: Vec<usize> = (0..full.len())
            .filter(|&i| !(lo..lo + 60.0).contains(&full.driver_deg[i]))
            .collect();
        let pick = |v: &[f64]| keep.iter().map(|&i| v[i]).collect::<Vec<f64>>();
        let gappy = MeasuredRun {
            time_s: pick(&full.time_s),
            phase: keep.iter().map(|&i| full.phase[i]).collect(),
            driver_deg: pick(&full.driver_deg),
            rz_deg: full.rz_deg.as_deref().map(pick),
            ..Default::default()
        };
        let after = input(&gappy);
        assert_eq!(after.cycles_rejected_gaps, 1);
        assert_eq!(after.cycles.len(), before.cycles.len() - 1);
        assert!(after.cycles.iter().all(|c| c.cycle != first + 1));
    }

    /// Guards option parsing messages.
    #[test]
    fn level_parsing_rejects_bad_lists() {
        assert_eq!(parse_levels("0,180,360").unwrap(), vec![0.0, 180.0, 360.0]);
        assert_eq!(parse_levels("0,-180").unwrap(), vec![0.0, -180.0]);
        assert!(parse_levels("90")
            .unwrap_err()
            .to_string()
            .contains("at least two"));
        assert!(parse_levels("0,180,90")
            .unwrap_err()
            .to_string()
            .contains("monotone"));
        assert!(parse_levels("0,nan").is_err());
    }
}
