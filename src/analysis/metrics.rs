//! Error metrics: per-sample errors after alignment, and their statistics per channel,
//! per direction, per cycle and across cycles.
//!
//! A *channel* is one error signal: `rz` (degrees) and `tz` (millimetres) for 1R/1R1T; for 3R
//! the geodesic angle `rotation` between measured and target orientation (degrees) and the
//! components `rx`, `ry`, `rz` of the error rotation vector in the reference frame. Only the
//! static offsets of the [`Alignment`] (driver offset δ₀, sensor offsets, 3R frame offsets)
//! are removed; lag and backlash stay in the errors, where they belong. Cycles are whole
//! driver revolutions, numbered by ⌊φ/360°⌋ of the measured driver angle; the profile over one
//! revolution uses [`PROFILE_BINS`] bins of driver angle. This module does not fit anything.

use std::collections::BTreeMap;

use nalgebra::UnitQuaternion;

use super::align::Alignment;
use super::run::{MeasuredRun, Phase};
use super::sampling::median;
use super::target::TargetLaw;

/// Bins of driver angle per revolution for profiles, repeatability and hysteresis. Default
/// 360 (1° of driver angle): fine enough to resolve the shape of a law synthesized from 360
/// samples, coarse enough that every bin holds several samples at 10 rpm and 100 Hz.
pub const PROFILE_BINS: usize = 360;

/// A cycle counts as complete when at least this fraction of its revolution is covered
/// (see [`cycle_coverage`]). Default 0.9: tolerates short gaps while excluding the partial
/// first and last cycles.
pub const FULL_CYCLE_COVERAGE: f64 = 0.9;

/// A run of empty bins counts as a gap (not covered) when it is wider than this many times
/// the median spacing between occupied bins. Default 3: a sensor slower than one sample per
/// bin (a BNO055 fusing at 100 Hz gives one per 1.8° at 30 rpm) still covers its cycle,
/// while a dropout of a few samples does not.
pub const GAP_SPACINGS: usize = 3;

/// Runs of empty bins longer than 1/this of a revolution are always gaps, however sparse
/// the sampling. Default 36 (10° of driver angle): a 100 Hz IMU still covers its cycles up
/// to about 160 rpm, and a cycle with a handful of samples is never called complete.
pub const MAX_GAP_DIVISOR: usize = 36;

/// Fraction of a revolution covered by the occupied bins of one cycle. Every bin counts as
/// covered except those in runs of empty bins longer than [`GAP_SPACINGS`] times the median
/// spacing of the occupied bins (at least 2 bins, at most 1/[`MAX_GAP_DIVISOR`] of a
/// revolution): so the figure is the same for a 1 kHz encoder and a 100 Hz IMU, and is low
/// only where data is really missing.
pub fn cycle_coverage(occupied: &[bool]) -> f64 {
    let n = occupied.len();
    let hits: Vec<usize> = (0..n).filter(|&b| occupied[b]).collect();
    if hits.is_empty() {
        return 0.0;
    }
    // Circular spacings between consecutive occupied bins.
    let gaps: Vec<usize> = hits
        .iter()
        .enumerate()
        .map(|(i, &b)| {
            let next = hits[(i + 1) % hits.len()];
            (next + n - b - 1) % n + 1
        })
        .collect();
    let mut sorted = gaps.clone();
    sorted.sort_unstable();
    let median = sorted[sorted.len() / 2];
    let limit = (GAP_SPACINGS * median).clamp(2, (n / MAX_GAP_DIVISOR).max(2));
    // A gap of g bins between two occupied bins leaves g − 1 empty bins.
    let uncovered: usize = gaps.iter().filter(|&&g| g > limit).map(|&g| g - 1).sum();
    1.0 - uncovered as f64 / n as f64
}

/// Statistics of one error signal. Serialized with the unit appended to every field name.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ErrorStats {
    /// Unit of the values (`deg` or `mm`).
    pub unit: &'static str,
    /// Number of samples.
    pub samples: usize,
    /// Root mean square.
    pub rms: f64,
    /// Mean (signed).
    pub mean: f64,
    /// Largest magnitude.
    pub max_abs: f64,
    /// 95th percentile of the magnitude.
    pub p95_abs: f64,
}

impl serde::Serialize for ErrorStats {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        use serde::ser::SerializeMap;
        let mut m = s.serialize_map(Some(5))?;
        m.serialize_entry("samples", &self.samples)?;
        m.serialize_entry(&format!("rms_{}", self.unit), &self.rms)?;
        m.serialize_entry(&format!("mean_{}", self.unit), &self.mean)?;
        m.serialize_entry(&format!("max_abs_{}", self.unit), &self.max_abs)?;
        m.serialize_entry(&format!("p95_abs_{}", self.unit), &self.p95_abs)?;
        m.end()
    }
}

#[derive(Debug, Clone, Copy, Default)]
struct Accum {
    n: usize,
    s: f64,
    s2: f64,
    max_abs: f64,
}

impl Accum {
    fn push(&mut self, e: f64) {
        self.n += 1;
        self.s += e;
        self.s2 += e * e;
        self.max_abs = self.max_abs.max(e.abs());
    }

    fn stats(&self, unit: &'static str, p95: f64) -> ErrorStats {
        let n = self.n.max(1) as f64;
        ErrorStats {
            unit,
            samples: self.n,
            rms: (self.s2 / n).sqrt(),
            mean: self.s / n,
            max_abs: self.max_abs,
            p95_abs: p95,
        }
    }
}

/// Statistics of one cycle.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct CycleStats {
    /// Run direction.
    pub direction: Phase,
    /// Cycle number ⌊φ/360°⌋.
    pub cycle: i64,
    /// Fraction of profile bins holding samples.
    pub coverage: f64,
    /// Error statistics over the cycle (`p95` over the cycle too).
    pub stats: ErrorStats,
}

/// Cycle-to-cycle repeatability: for each driver-angle bin, the standard deviation of the
/// per-cycle mean error across complete cycles of the same direction.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Repeatability {
    /// Unit.
    pub unit: &'static str,
    /// Complete cycles compared.
    pub cycles: usize,
    /// RMS over bins of the across-cycle standard deviation.
    pub rms_std: f64,
    /// Largest across-cycle standard deviation of any bin.
    pub max_std: f64,
}

impl serde::Serialize for Repeatability {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        use serde::ser::SerializeMap;
        let mut m = s.serialize_map(Some(3))?;
        m.serialize_entry("cycles", &self.cycles)?;
        m.serialize_entry(&format!("rms_std_{}", self.unit), &self.rms_std)?;
        m.serialize_entry(&format!("max_std_{}", self.unit), &self.max_std)?;
        m.end()
    }
}

/// Forward-versus-reverse difference (hysteresis) over the driver revolution.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Hysteresis {
    /// Unit.
    pub unit: &'static str,
    /// Bins with data in both directions.
    pub bins: usize,
    /// Mean over bins. Scalar DOFs: of s·(e_rev − e_fwd) with s the sign of the target's
    /// motion, so a dead band of width β gives +β. 3R: of |ē_fwd − ē_rev| (rotation vectors).
    pub mean: f64,
    /// Largest magnitude over bins.
    pub max_abs: f64,
}

impl serde::Serialize for Hysteresis {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        use serde::ser::SerializeMap;
        let mut m = s.serialize_map(Some(3))?;
        m.serialize_entry("bins", &self.bins)?;
        m.serialize_entry(&format!("mean_{}", self.unit), &self.mean)?;
        m.serialize_entry(&format!("max_abs_{}", self.unit), &self.max_abs)?;
        m.end()
    }
}

/// Mean error per driver-angle bin (NaN where a bin is empty), for plots.
#[derive(Debug, Clone, Default)]
pub struct Profile {
    /// Mean over all forward samples per bin.
    pub forward: Vec<f64>,
    /// Mean over all reverse samples per bin.
    pub reverse: Vec<f64>,
    /// Per cycle (direction, number, mean per bin).
    pub cycles: Vec<(Phase, i64, Vec<f64>)>,
}

/// Everything measured about one error channel.
#[derive(Debug, Clone, serde::Serialize)]
pub struct ChannelMetrics {
    /// Channel name (`rz`, `tz`, `rotation`, `rx`, `ry`).
    pub name: String,
    /// Unit (`deg`, `mm`).
    pub unit: &'static str,
    /// All measured samples.
    pub overall: ErrorStats,
    /// Forward samples.
    pub forward: Option<ErrorStats>,
    /// Reverse samples.
    pub reverse: Option<ErrorStats>,
    /// Before alignment (only whole turns removed); shows what the offsets hid.
    pub unaligned: Option<ErrorStats>,
    /// Every cycle, complete or not.
    pub per_cycle: Vec<CycleStats>,
    /// Cycle-to-cycle repeatability over complete cycles.
    pub repeatability: Option<Repeatability>,
    /// Forward versus reverse.
    pub hysteresis: Option<Hysteresis>,
    /// Binned profile for plots (not serialized).
    #[serde(skip)]
    pub profile: Profile,
}

/// Per-sample errors of one channel (NaN for settle samples).
#[derive(Debug, Clone)]
pub struct ChannelErrors {
    /// Channel name.
    pub name: String,
    /// Unit.
    pub unit: &'static str,
    /// Aligned errors.
    pub values: Vec<f64>,
    /// Errors before alignment, when meaningful.
    pub unaligned: Option<Vec<f64>>,
    /// Sign of the target's motion per profile bin (scalar channels), for hysteresis.
    pub bin_sign: Option<Vec<f64>>,
}

/// Bin of a driver angle.
#[inline]
pub fn bin_of(phi_deg: f64) -> usize {
    let u = phi_deg / 360.0;
    (((u - u.floor()) * PROFILE_BINS as f64) as usize).min(PROFILE_BINS - 1)
}

/// The aligned target orientation at driver angle `phi_deg` (3R).
pub fn aligned_rotation(
    law: &TargetLaw,
    al: &Alignment,
    phi_deg: f64,
) -> Option<UnitQuaternion<f64>> {
    let (r, off) = (law.rotation.as_ref()?, al.rotation?);
    Some(off.world * r.eval(phi_deg - al.driver_offset_deg.value) * off.mount)
}

/// Per-sample errors of every channel.
pub fn channel_errors(run: &MeasuredRun, law: &TargetLaw, al: &Alignment) -> Vec<ChannelErrors> {
    let n = run.len();
    let d0 = al.driver_offset_deg.value;
    let mut out = Vec::new();
    for off in &al.dofs {
        let (y, table, name) = match off.dof {
            super::align::Dof::Rz => (run.rz_deg.as_ref(), law.rz_deg.as_ref(), "rz"),
            super::align::Dof::Tz => (run.tz_mm.as_ref(), law.tz_mm.as_ref(), "tz"),
        };
        let (Some(y), Some(table)) = (y, table) else {
            continue;
        };
        let c = off.total_offset();
        let mut values = vec![f64::NAN; n];
        let mut unaligned = vec![f64::NAN; n];
        for i in run.measured_indices() {
            let phi = run.driver_deg[i];
            values[i] = y[i] - table.value(phi - d0) - c;
            unaligned[i] = y[i] - table.value(phi) - off.turn_shift;
        }
        let bin_sign = (0..PROFILE_BINS)
            .map(|b| {
                let phi = (b as f64 + 0.5) * 360.0 / PROFILE_BINS as f64 - d0;
                let (_, s) = table.eval(phi);
                if s.abs() <= super::target::DWELL_SLOPE {
                    0.0
                } else {
                    s.signum()
                }
            })
            .collect();
        out.push(ChannelErrors {
            name: name.into(),
            unit: off.dof.unit(),
            values,
            unaligned: Some(unaligned),
            bin_sign: Some(bin_sign),
        });
    }
    if let (Some(meas), Some(_)) = (&run.rotation, &law.rotation) {
        let mut geo = vec![f64::NAN; n];
        let mut comp = [vec![f64::NAN; n], vec![f64::NAN; n], vec![f64::NAN; n]];
        for i in run.measured_indices() {
            let Some(target) = aligned_rotation(law, al, run.driver_deg[i]) else {
                continue;
            };
            let err = meas[i] * target.inverse();
            let v = err.scaled_axis();
            geo[i] = v.norm().to_degrees();
            for k in 0..3 {
                comp[k][i] = v[k].to_degrees();
            }
        }
        out.push(ChannelErrors {
            name: "rotation".into(),
            unit: "deg",
            values: geo,
            unaligned: None,
            bin_sign: None,
        });
        for (k, v) in comp.into_iter().enumerate() {
            out.push(ChannelErrors {
                name: ["rx", "ry", "rz"][k].into(),
                unit: "deg",
                values: v,
                unaligned: None,
                bin_sign: None,
            });
        }
    }
    out
}

fn p95_abs(values: impl Iterator<Item = f64>) -> f64 {
    let mut v: Vec<f64> = values.filter(|x| x.is_finite()).map(f64::abs).collect();
    if v.is_empty() {
        return 0.0;
    }
    let k = ((v.len() as f64 * 0.95).ceil() as usize).clamp(1, v.len()) - 1;
    let (_, m, _) = v.select_nth_unstable_by(k, f64::total_cmp);
    *m
}

struct CycleAcc {
    acc: Accum,
    bins: Vec<(f64, u32)>,
    abs: Vec<f64>,
}

/// Statistics of one channel.
pub fn channel_metrics(run: &MeasuredRun, ch: &ChannelErrors) -> ChannelMetrics {
    let unit = ch.unit;
    let (mut all, mut fwd, mut rev) = (Accum::default(), Accum::default(), Accum::default());
    let mut cycles: BTreeMap<(i8, i64), CycleAcc> = BTreeMap::new();
    let mut last_key = None;
    let mut cur: Option<CycleAcc> = None;
    for i in run.measured_indices() {
        let e = ch.values[i];
        if !e.is_finite() {
            continue;
        }
        let phase = run.phase[i];
        all.push(e);
        if phase == Phase::Forward {
            fwd.push(e);
        } else {
            rev.push(e);
        }
        let phi = run.driver_deg[i];
        let key = (phase.direction() as i8, (phi / 360.0).floor() as i64);
        if last_key != Some(key) {
            if let (Some(k), Some(c)) = (last_key, cur.take()) {
                merge(&mut cycles, k, c);
            }
            cur = Some(cycles.remove(&key).unwrap_or_else(|| CycleAcc {
                acc: Accum::default(),
                bins: vec![(0.0, 0); PROFILE_BINS],
                abs: Vec::new(),
            }));
            last_key = Some(key);
        }
        let c = cur.as_mut().expect("current cycle set above");
        c.acc.push(e);
        c.abs.push(e.abs());
        let b = &mut c.bins[bin_of(phi)];
        b.0 += e;
        b.1 += 1;
    }
    if let (Some(k), Some(c)) = (last_key, cur.take()) {
        merge(&mut cycles, k, c);
    }
    let p95_all = p95_abs(run.measured_indices().map(|i| ch.values[i]));
    let p95_dir = |ph: Phase| {
        p95_abs(
            run.measured_indices()
                .filter(|&i| run.phase[i] == ph)
                .map(|i| ch.values[i]),
        )
    };
    let mut profile = Profile {
        forward: vec![0.0; PROFILE_BINS],
        reverse: vec![0.0; PROFILE_BINS],
        cycles: Vec::new(),
    };
    let mut dir_bins = [
        vec![(0.0, 0u32); PROFILE_BINS],
        vec![(0.0, 0u32); PROFILE_BINS],
    ];
    let mut per_cycle = Vec::new();
    // Complete cycles' bin means, per direction, for repeatability.
    let mut complete: [Vec<Vec<f64>>; 2] = [Vec::new(), Vec::new()];
    for (&(dir, cycle), c) in cycles.iter_mut() {
        let direction = if dir > 0 {
            Phase::Forward
        } else {
            Phase::Reverse
        };
        let di = usize::from(dir < 0);
        let occupied: Vec<bool> = c.bins.iter().map(|b| b.1 > 0).collect();
        let coverage = cycle_coverage(&occupied);
        let means: Vec<f64> = c
            .bins
            .iter()
            .map(|&(s, k)| if k > 0 { s / f64::from(k) } else { f64::NAN })
            .collect();
        for (b, &(s, k)) in c.bins.iter().enumerate() {
            dir_bins[di][b].0 += s;
            dir_bins[di][b].1 += k;
        }
        if coverage >= FULL_CYCLE_COVERAGE {
            complete[di].push(means.clone());
        }
        let p95 = {
            let k = ((c.abs.len() as f64 * 0.95).ceil() as usize).clamp(1, c.abs.len().max(1)) - 1;
            if c.abs.is_empty() {
                0.0
            } else {
                *c.abs.select_nth_unstable_by(k, f64::total_cmp).1
            }
        };
        per_cycle.push(CycleStats {
            direction,
            cycle,
            coverage,
            stats: c.acc.stats(unit, p95),
        });
        profile.cycles.push((direction, cycle, means));
    }
    // Forward cycles first, then reverse, each in cycle order.
    per_cycle.sort_by_key(|c: &CycleStats| (c.direction != Phase::Forward, c.cycle));
    profile.cycles.sort_by_key(|c| (c.0 != Phase::Forward, c.1));
    for (di, target) in [&mut profile.forward, &mut profile.reverse]
        .into_iter()
        .enumerate()
    {
        for (b, v) in target.iter_mut().enumerate() {
            let (s, k) = dir_bins[di][b];
            *v = if k > 0 { s / f64::from(k) } else { f64::NAN };
        }
    }
    let repeatability = {
        let mut stds = Vec::new();
        let mut n_cycles = 0;
        for set in &complete {
            if set.len() < 2 {
                continue;
            }
            n_cycles += set.len();
            for b in 0..PROFILE_BINS {
                let vals: Vec<f64> = set.iter().map(|m| m[b]).filter(|v| v.is_finite()).collect();
                if vals.len() < 2 {
                    continue;
                }
                let m = vals.iter().sum::<f64>() / vals.len() as f64;
                let var =
                    vals.iter().map(|v| (v - m).powi(2)).sum::<f64>() / (vals.len() - 1) as f64;
                stds.push(var.sqrt());
            }
        }
        (!stds.is_empty()).then(|| Repeatability {
            unit,
            cycles: n_cycles,
            rms_std: (stds.iter().map(|s| s * s).sum::<f64>() / stds.len() as f64).sqrt(),
            max_std: stds.iter().fold(0.0, |m: f64, &s| m.max(s)),
        })
    };
    let hysteresis = ch.bin_sign.as_ref().and_then(|sign| {
        let vals: Vec<f64> = (0..PROFILE_BINS)
            .filter(|&b| {
                profile.forward[b].is_finite() && profile.reverse[b].is_finite() && sign[b] != 0.0
            })
            .map(|b| sign[b] * (profile.reverse[b] - profile.forward[b]))
            .collect();
        hysteresis_of(unit, &vals)
    });
    let unaligned = ch.unaligned.as_ref().map(|u| {
        let mut a = Accum::default();
        run.measured_indices()
            .map(|i| u[i])
            .filter(|v| v.is_finite())
            .for_each(|v| a.push(v));
        a.stats(unit, p95_abs(run.measured_indices().map(|i| u[i])))
    });
    ChannelMetrics {
        name: ch.name.clone(),
        unit,
        overall: all.stats(unit, p95_all),
        forward: (fwd.n > 0).then(|| fwd.stats(unit, p95_dir(Phase::Forward))),
        reverse: (rev.n > 0).then(|| rev.stats(unit, p95_dir(Phase::Reverse))),
        unaligned,
        per_cycle,
        repeatability,
        hysteresis,
        profile,
    }
}

fn merge(cycles: &mut BTreeMap<(i8, i64), CycleAcc>, key: (i8, i64), c: CycleAcc) {
    cycles.insert(key, c);
}

fn hysteresis_of(unit: &'static str, vals: &[f64]) -> Option<Hysteresis> {
    (!vals.is_empty()).then(|| Hysteresis {
        unit,
        bins: vals.len(),
        mean: vals.iter().sum::<f64>() / vals.len() as f64,
        max_abs: vals.iter().fold(0.0, |m: f64, v| m.max(v.abs())),
    })
}

/// 3R hysteresis from the profiles of the three rotation-vector components: per bin the
/// length of the difference between the forward and reverse mean error vectors.
pub fn vector_hysteresis(components: [&ChannelMetrics; 3]) -> Option<Hysteresis> {
    let vals: Vec<f64> = (0..PROFILE_BINS)
        .filter_map(|b| {
            let mut d2 = 0.0;
            for c in components {
                let (f, r) = (c.profile.forward[b], c.profile.reverse[b]);
                if !(f.is_finite() && r.is_finite()) {
                    return None;
                }
                d2 += (f - r) * (f - r);
            }
            Some(d2.sqrt())
        })
        .collect();
    hysteresis_of("deg", &vals)
}

/// Median absolute error of a channel, used as a robust noise figure.
pub fn median_abs(values: &[f64]) -> f64 {
    let v: Vec<f64> = values
        .iter()
        .filter(|x| x.is_finite())
        .map(|x| x.abs())
        .collect();
    median(&v).unwrap_or(0.0)
}

#[cfg(test)]
mod tests {

    /// Guards the cycle coverage: a 100 Hz IMU at 30 rpm (one sample per 1.8 bins) covers
    /// its cycle fully, a dropout of 20° is counted as missing, a partial last cycle is
    /// partial, and one lone sample or none covers nothing useful.
    #[test]
    fn coverage_counts_gaps_relative_to_the_sampling_density() {
        let n = PROFILE_BINS;
        let sparse: Vec<bool> = (0..n).map(|b| (b * 5) % 9 < 5).collect();
        assert!((cycle_coverage(&sparse) - 1.0).abs() < 1e-12);
        let mut dropout = vec![true; n];
        for b in dropout.iter_mut().skip(100).take(20) {
            *b = false;
        }
        assert!((cycle_coverage(&dropout) - 340.0 / 360.0).abs() < 1e-12);
        let partial: Vec<bool> = (0..n).map(|b| b < 18).collect();
        assert!((cycle_coverage(&partial) - 18.0 / 360.0).abs() < 1e-12);
        let mut one = vec![false; n];
        one[7] = true;
        assert!((cycle_coverage(&one) - 1.0 / 360.0).abs() < 1e-12);
        assert_eq!(cycle_coverage(&vec![false; n]), 0.0);
    }

    use super::*;
    use crate::analysis::run::MeasuredRun;

    fn run_with_errors(errors: &[f64], phase: Phase) -> (MeasuredRun, ChannelErrors) {
        let n = errors.len();
        let run = MeasuredRun {
            time_s: (0..n).map(|i| i as f64 * 1e-3).collect(),
            phase: vec![phase; n],
            driver_deg: (0..n).map(|i| i as f64 * 720.0 / n as f64).collect(),
            rz_deg: Some(vec![0.0; n]),
            ..Default::default()
        };
        let ch = ChannelErrors {
            name: "rz".into(),
            unit: "deg",
            values: errors.to_vec(),
            unaligned: None,
            bin_sign: None,
        };
        (run, ch)
    }

    /// Guards the statistics: RMS, mean, max and p95 of a known error sequence.
    #[test]
    fn statistics_of_known_errors() {
        let errors: Vec<f64> = (0..7200)
            .map(|i| if i % 2 == 0 { 1.0 } else { -1.0 })
            .collect();
        let (run, ch) = run_with_errors(&errors, Phase::Forward);
        let m = channel_metrics(&run, &ch);
        assert!((m.overall.rms - 1.0).abs() < 1e-12);
        assert!(m.overall.mean.abs() < 1e-12);
        assert!((m.overall.max_abs - 1.0).abs() < 1e-12);
        assert!((m.overall.p95_abs - 1.0).abs() < 1e-12);
        assert_eq!(m.per_cycle.len(), 2);
        assert!(m.reverse.is_none() && m.hysteresis.is_none());
    }

    /// Guards repeatability: two cycles with the same error pattern over the driver angle
    /// have (almost) no spread; adding 0.5° to the second cycle gives a spread of 0.354°
    /// (the sample standard deviation of two values 0.5 apart) in every bin.
    #[test]
    fn repeatability_measures_cycle_to_cycle_spread() {
        let pattern = |phi: f64| (phi.rem_euclid(360.0)).to_radians().sin();
        let (run, mut ch) = run_with_errors(&[0.0; 7200], Phase::Forward);
        ch.values = run.driver_deg.iter().map(|&p| pattern(p)).collect();
        let r = channel_metrics(&run, &ch).repeatability.unwrap();
        assert_eq!(r.cycles, 2);
        assert!(r.max_std < 0.01, "{r:?}");
        ch.values = run
            .driver_deg
            .iter()
            .map(|&p| pattern(p) + if p >= 360.0 { 0.5 } else { 0.0 })
            .collect();
        let r = channel_metrics(&run, &ch).repeatability.unwrap();
        assert!((r.rms_std - 0.5 / 2f64.sqrt()).abs() < 0.01, "{r:?}");
    }

    /// Guards the field names scripts read: units are appended to every statistic.
    #[test]
    fn serialized_statistics_carry_units() {
        let (run, ch) = run_with_errors(&[0.5; 100], Phase::Forward);
        let m = channel_metrics(&run, &ch);
        let v = serde_json::to_value(m.overall).unwrap();
        for k in [
            "rms_deg",
            "mean_deg",
            "max_abs_deg",
            "p95_abs_deg",
            "samples",
        ] {
            assert!(v.get(k).is_some(), "{k} missing in {v}");
        }
    }
}
