//! The report's charts, drawn through [`crate::plot`]: follower over driver angle (measured
//! against target), error over driver angle, per-cycle overlay, error histogram, timing
//! ratios per cycle and, for 3R, the end-effector axis path.

use std::path::{Path, PathBuf};

use nalgebra::Vector3;

use crate::analysis::align::Dof;
use crate::analysis::metrics::{ChannelErrors, ChannelMetrics, PROFILE_BINS};
use crate::analysis::run::{MeasuredRun, Phase};
use crate::analysis::target::TargetLaw;
use crate::analysis::timing::TimingReport;
use crate::analysis::{Analysis, AnalysisError};
use crate::plot::{Chart, Series};
use crate::predict::table::PredictedDeviation;

/// Most points drawn per scatter series. Default 4000: a 1000-pixel-wide chart cannot show
/// more, and SVG files stay below a megabyte.
pub const MAX_PLOT_POINTS: usize = 4000;

/// Bars in the error histogram. Default 41 (odd, so zero error sits in the middle of a bar).
pub const HISTOGRAM_BINS: usize = 41;

/// A written chart: caption and PNG path (the SVG sits beside it).
pub type Picture = (String, PathBuf);

fn stride(n: usize) -> usize {
    n.div_ceil(MAX_PLOT_POINTS).max(1)
}

fn by_phase(run: &MeasuredRun, ph: Phase) -> Vec<usize> {
    let idx: Vec<usize> = (0..run.len()).filter(|&i| run.phase[i] == ph).collect();
    let s = stride(idx.len());
    idx.into_iter().step_by(s).collect()
}

fn unit_label(unit: &str) -> &str {
    if unit == "deg" {
        "°"
    } else {
        " mm"
    }
}

/// Follower DOF over one driver revolution: measured (the fitted driver and sensor offsets
/// removed, as for the error; folded into one cycle) on the target law, which is drawn as a
/// broad pale band under the points so neither hides the other (issue 20: the measured
/// curve was hidden under the target, or shifted off it by an offset the error does not
/// count).
pub fn follower_chart(
    dir: &Path,
    run: &MeasuredRun,
    law: &TargetLaw,
    a: &Analysis,
    dof: Dof,
) -> Result<Picture, AnalysisError> {
    let (y, table) = match dof {
        Dof::Rz => (run.rz_deg.as_ref(), law.rz_deg.as_ref()),
        Dof::Tz => (run.tz_mm.as_ref(), law.tz_mm.as_ref()),
    };
    let (Some(y), Some(table)) = (y, table) else {
        return Err(AnalysisError::Mismatch(format!(
            "no {} data to plot",
            dof.name()
        )));
    };
    let off = a
        .alignment
        .dofs
        .iter()
        .find(|d| d.dof == dof)
        .map_or(0.0, |d| d.total_offset());
    let adv = table.advance();
    let driver_off = a.alignment.driver_offset_deg.value;
    let fold = |i: usize| {
        let phi = run.driver_deg[i] - driver_off;
        let k = (phi / 360.0).floor();
        (phi - 360.0 * k, y[i] - off - k * adv)
    };
    let target: Vec<(f64, f64)> = (0..=720)
        .map(|k| {
            let phi = k as f64 * 0.5;
            (phi, table.value(phi))
        })
        .collect();
    let mut chart = Chart::new(
        format!(
            "{}: follower {} over one driver revolution — measured vs target",
            law.name,
            if dof == Dof::Rz { "angle" } else { "height" }
        ),
        "driver angle within the cycle [°]",
        format!(
            "follower {} [{}]",
            if dof == Dof::Rz {
                "angle θ"
            } else {
                "height h"
            },
            if dof == Dof::Rz { "°" } else { "mm" }
        ),
    );
    chart.x_range = Some((0.0, 360.0));
    chart = chart.with(Series::band("target law", target, 2, 9));
    for (ph, label, color) in [
        (Phase::Forward, "measured, forward", 0),
        (Phase::Reverse, "measured, reverse", 1),
    ] {
        let pts: Vec<(f64, f64)> = by_phase(run, ph).into_iter().map(fold).collect();
        if !pts.is_empty() {
            chart = chart.with(Series::points(label, pts, 2, color));
        }
    }
    let stem = dir.join(format!("follower_{}", dof.name()));
    chart.write(&stem)?;
    Ok((
        format!(
            "Follower {} on the target (pale band) over one driver revolution, all cycles \
             folded, the fitted offsets removed.",
            dof.name()
        ),
        stem.with_extension("png"),
    ))
}

/// Driver angles at which a predicted deviation is drawn per revolution: every 0.25°, the
/// prediction's own default spacing.
const PREDICTED_POINTS: usize = 1440;

/// Error over the driver angle within the cycle, every cycle of both directions folded
/// onto one revolution (issue 20: over the cumulative angle the reverse run retraced the
/// forward one's x range backwards, and a cycle's features were spread over the run).
/// With `predicted` (the deviation `mpc-rig simulate` predicts for the parts, and the
/// alignment's driver offset in degrees) the predicted error of each direction is drawn
/// over the measured one: target (zero), prediction and measurement on one chart.
pub fn error_chart(
    dir: &Path,
    run: &MeasuredRun,
    ch: &ChannelErrors,
    m: &ChannelMetrics,
    tol: Option<f64>,
    predicted: Option<(&PredictedDeviation, f64)>,
) -> Result<Picture, AnalysisError> {
    let u = unit_label(ch.unit);
    let mut chart = Chart::new(
        format!(
            "{} error over the driver angle in the cycle — RMS {}{u}, largest {}{u}",
            ch.name,
            super::f3(m.overall.rms),
            super::f3(m.overall.max_abs)
        ),
        "driver angle within the cycle [°]",
        format!("error [{}]", ch.unit),
    );
    chart.x_range = Some((0.0, 360.0));
    for (ph, label, color) in [
        (Phase::Forward, "forward", 0),
        (Phase::Reverse, "reverse", 1),
    ] {
        let pts: Vec<(f64, f64)> = by_phase(run, ph)
            .into_iter()
            .map(|i| (run.driver_deg[i].rem_euclid(360.0), ch.values[i]))
            .collect();
        if !pts.is_empty() {
            chart = chart.with(Series::points(label, pts, 2, color));
        }
    }
    if let Some((p, offset_deg)) = predicted {
        for (forward, label, color) in [
            (true, "predicted forward", 2),
            (false, "predicted reverse", 3),
        ] {
            // The measured x is the recorded driver angle; the prediction's is the
            // mechanism's, `offset_deg` behind it (as `prediction::compare` reads it).
            let pts: Vec<(f64, f64)> = (0..=PREDICTED_POINTS)
                .filter_map(|i| {
                    let x = 360.0 * i as f64 / PREDICTED_POINTS as f64;
                    Some((x, p.of(&ch.name, x - offset_deg, forward)?))
                })
                .collect();
            chart = chart.with(Series::line(label, pts, color));
        }
    }
    if let Some(t) = tol {
        chart.h_lines.push((t, format!("±{t}{u} (RMS tolerance)")));
        chart.h_lines.push((-t, String::new()));
    }
    chart.h_lines.push((0.0, String::new()));
    // Room above the data for the legend: both directions' errors fill the plot's height
    // at both ends of the cycle, so no corner of it is free otherwise (the legend hid the
    // reverse run's peak near 355°).
    let ys = chart
        .series
        .iter()
        .flat_map(|s| s.points.iter().map(|p| p.1))
        .chain(chart.h_lines.iter().map(|l| l.0))
        .filter(|y| y.is_finite());
    let (lo, hi) = ys.fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), y| {
        (l.min(y), h.max(y))
    });
    if lo < hi {
        chart.y_range = Some(crate::plot::legend_room_y_range(lo, hi - lo));
    }
    let stem = dir.join(format!("error_{}", ch.name));
    chart.write(&stem)?;
    Ok((
        format!(
            "{} error over the driver angle within the cycle, all cycles folded{}.",
            ch.name,
            if predicted.is_some() {
                "; lines: the error the parts' prediction gives each direction"
            } else {
                ""
            }
        ),
        stem.with_extension("png"),
    ))
}

/// Longest run of empty bins a cycle's line is drawn across: 4 (4° at 1° bins). A 100 Hz
/// IMU at 30 rpm fills every other 1° bin, and its line must not break at each (issue 20:
/// the 3R chart looked broken); a longer hole is data missing, and shows as a break.
const BRIDGED_EMPTY_BINS: usize = 4;

/// Binned values as line points: empty bins skipped, a break (NaN) across a run of more
/// than [`BRIDGED_EMPTY_BINS`].
fn bridged(values: &[f64], x: impl Fn(usize) -> f64) -> Vec<(f64, f64)> {
    let mut pts = Vec::with_capacity(values.len());
    let mut last: Option<usize> = None;
    for (b, &v) in values.iter().enumerate().filter(|(_, v)| v.is_finite()) {
        if last.is_some_and(|l| b - l > BRIDGED_EMPTY_BINS + 1) {
            pts.push((f64::NAN, f64::NAN));
        }
        pts.push((x(b), v));
        last = Some(b);
    }
    pts
}

/// Per-cycle overlay of the binned error over one revolution, with the mean per direction:
/// the cycles as pale bands, the means as solid lines on them, and headroom for the legend
/// (issue 20: the dashed mean covered every cycle, and the legend a peak).
pub fn cycles_chart(dir: &Path, ch: &ChannelMetrics) -> Result<Picture, AnalysisError> {
    let mut chart = Chart::new(
        format!("{} error per cycle (1° bins), overlaid", ch.name),
        "driver angle within the cycle [°]",
        format!("error [{}]", ch.unit),
    );
    chart.x_range = Some((0.0, 360.0));
    let x = |b: usize| (b as f64 + 0.5) * 360.0 / PROFILE_BINS as f64;
    let (mut fwd_labelled, mut rev_labelled) = (false, false);
    for (ph, _, means) in &ch.profile.cycles {
        let forward = *ph == Phase::Forward;
        let label = match (forward, fwd_labelled, rev_labelled) {
            (true, false, _) => {
                fwd_labelled = true;
                "forward cycles"
            }
            (false, _, false) => {
                rev_labelled = true;
                "reverse cycles"
            }
            _ => "",
        };
        let pts = bridged(means, x);
        chart = chart.with(Series::band(label, pts, if forward { 0 } else { 1 }, 5));
    }
    for (prof, label, color) in [
        (&ch.profile.forward, "forward mean", 0),
        (&ch.profile.reverse, "reverse mean", 1),
    ] {
        if prof.iter().any(|v| v.is_finite()) {
            let pts = bridged(prof, x);
            chart = chart.with(Series::line(label, pts, color));
        }
    }
    let all = ch
        .profile
        .cycles
        .iter()
        .flat_map(|c| c.2.iter())
        .copied()
        .filter(|v| v.is_finite());
    let (lo, hi) = all.fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), v| {
        (l.min(v), h.max(v))
    });
    if lo < hi {
        chart.y_range = Some(crate::plot::legend_room_y_range(lo, hi - lo));
    }
    let stem = dir.join(format!("cycles_{}", ch.name));
    chart.write(&stem)?;
    Ok((
        format!(
            "{} error of every cycle over one driver revolution (pale), and the mean per \
             direction (solid).",
            ch.name
        ),
        stem.with_extension("png"),
    ))
}

/// Histogram of the error (percent of samples per bin).
pub fn histogram_chart(
    dir: &Path,
    run: &MeasuredRun,
    ch: &ChannelErrors,
    m: &ChannelMetrics,
) -> Result<Picture, AnalysisError> {
    let vals: Vec<f64> = run
        .measured_indices()
        .map(|i| ch.values[i])
        .filter(|v| v.is_finite())
        .collect();
    let non_negative = vals.iter().all(|v| *v >= 0.0);
    let hi = m.overall.max_abs.max(1e-9);
    let lo = if non_negative { 0.0 } else { -hi };
    let w = (hi - lo) / HISTOGRAM_BINS as f64;
    let mut counts = vec![0usize; HISTOGRAM_BINS];
    for v in &vals {
        let b = (((v - lo) / w) as usize).min(HISTOGRAM_BINS - 1);
        counts[b] += 1;
    }
    let total = vals.len().max(1) as f64;
    let pts = counts
        .iter()
        .enumerate()
        .map(|(b, &c)| (lo + (b as f64 + 0.5) * w, 100.0 * c as f64 / total))
        .collect();
    let u = unit_label(ch.unit);
    let chart = Chart::new(
        format!(
            "{} error distribution — mean {:.3}{u}, RMS {:.3}{u}, 95 % within {:.3}{u}",
            ch.name, m.overall.mean, m.overall.rms, m.overall.p95_abs
        ),
        format!("error [{}]", ch.unit),
        "samples [%]",
    )
    .with(Series::bars("", pts, 0));
    let stem = dir.join(format!("histogram_{}", ch.name));
    chart.write(&stem)?;
    Ok((
        format!(
            "Distribution of the {} error over all measured samples.",
            ch.name
        ),
        stem.with_extension("png"),
    ))
}

/// Timing ratio of every cycle with its U95, against the target and the tolerance.
pub fn timing_chart(
    dir: &Path,
    t: &TimingReport,
    tol: Option<f64>,
) -> Result<Picture, AnalysisError> {
    let r = &t.ratios[0];
    let mut chart = Chart::new(
        format!(
            "duration ratio ({}°→{}°) / ({}°→{}°): measured {:.3} ± {:.3} vs target {:.3}",
            r.levels_deg[0],
            r.levels_deg[1],
            r.levels_deg[1],
            r.levels_deg[2],
            r.measured,
            r.u95,
            r.target
        ),
        "cycle",
        "ratio of durations [-]",
    );
    let pts: Vec<(f64, f64)> = t
        .cycles
        .iter()
        .map(|c| (c.cycle as f64, c.ratios[0]))
        .collect();
    // Error bars as short vertical lines (NaN-separated segments of one line series).
    let mut bars = Vec::new();
    for c in &t.cycles {
        let (x, y, u) = (c.cycle as f64, c.ratios[0], c.ratios_u95[0]);
        bars.extend([(x, y - u), (x, y + u), (f64::NAN, f64::NAN)]);
    }
    chart
        .h_lines
        .push((r.target, format!("target {:.3}", r.target)));
    if let Some(tol) = tol {
        chart
            .h_lines
            .push((r.target + tol, format!("tolerance ±{tol}")));
        chart.h_lines.push((r.target - tol, String::new()));
    }
    chart = chart
        .with(Series::line("U95 per cycle", bars, 0))
        .with(Series::points("measured per cycle", pts, 5, 0));
    let (lo, hi) = t
        .cycles
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), c| {
            (a.min(c.cycle as f64), b.max(c.cycle as f64))
        });
    chart.x_range = Some((lo - 0.5, hi + 0.5));
    chart.whole_x = true;
    let stem = dir.join("timing");
    chart.write(&stem)?;
    Ok((
        "Timing ratio per forward cycle with its expanded uncertainty; red: target (and tolerance).".into(),
        stem.with_extension("png"),
    ))
}

/// The projection `motion show` uses for the end-effector axis: azimuthal equidistant
/// around the rest direction +z (tilt towards +x, tilt towards +y, degrees).
fn project(v: Vector3<f64>) -> (f64, f64) {
    let tilt = v.z.clamp(-1.0, 1.0).acos().to_degrees();
    let az = v.y.atan2(v.x);
    (tilt * az.cos(), tilt * az.sin())
}

/// 3R: the end-effector axis (follower +z) path, measured (frame offsets removed) on the
/// same plot as `motion show` draws the target (its projection, tilt circle and keyframes).
pub fn axis_chart(
    dir: &Path,
    run: &MeasuredRun,
    law: &TargetLaw,
    a: &Analysis,
) -> Result<Picture, AnalysisError> {
    let (Some(meas), Some(rot), Some(off)) = (&run.rotation, &law.rotation, a.alignment.rotation)
    else {
        return Err(AnalysisError::Mismatch(
            "no orientation data to plot".into(),
        ));
    };
    let measured: Vec<(f64, f64)> = run
        .measured_indices()
        .step_by(stride(run.len()))
        .map(|i| project(off.world.inverse() * meas[i] * off.mount.inverse() * Vector3::z()))
        .collect();
    let base = law.motion.as_ref().and_then(|m| {
        crate::motion::figures::charts(m, 360, &crate::motion::BenchScale::default())
            .into_iter()
            .find(|(name, _)| name == "axis-path")
            .map(|(_, c)| c)
    });
    let mut chart = match base {
        Some(mut c) => {
            c.title = format!(
                "{}: end-effector axis, measured vs target (seen from above)",
                law.name
            );
            c
        }
        None => {
            let target: Vec<(f64, f64)> = (0..=720)
                .map(|k| project(rot.eval(k as f64 * 0.5) * Vector3::z()))
                .collect();
            let keys: Vec<(f64, f64)> = law
                .key_poses
                .iter()
                .map(|k| project(k.rotation * Vector3::z()))
                .collect();
            let mut c = Chart::new(
                format!(
                    "{}: end-effector axis, measured vs target (seen from above)",
                    law.name
                ),
                "tilt towards +x [deg]",
                "tilt towards +y [deg]",
            )
            .with(Series::line("target axis path", target, 0))
            .with(Series::points("keyframes", keys, 5, 1));
            c.equal_aspect = true;
            c.size = (900, 900);
            c
        }
    };
    // Measured first in the legend order does not matter; draw it under the target line.
    chart
        .series
        .insert(0, Series::points("measured axis", measured, 2, 4));
    let stem = dir.join("axis_path");
    chart.write(&stem)?;
    Ok((
        "End-effector axis (follower +z) seen from above (tilt from +z towards x and y): measured against the target path, key poses marked.".into(),
        stem.with_extension("png"),
    ))
}

/// 3R: the end-effector axis projection coordinates (tilt towards +x and +y) over one
/// driver revolution, measured (frame offsets removed, cycles folded) against target.
pub fn axis_over_driver_chart(
    dir: &Path,
    run: &MeasuredRun,
    law: &TargetLaw,
    a: &Analysis,
) -> Result<Picture, AnalysisError> {
    let (Some(meas), Some(rot), Some(off)) = (&run.rotation, &law.rotation, a.alignment.rotation)
    else {
        return Err(AnalysisError::Mismatch(
            "no orientation data to plot".into(),
        ));
    };
    let mut chart = Chart::new(
        format!(
            "{}: end-effector axis over one driver revolution — measured vs target",
            law.name
        ),
        "driver angle within the cycle [°]",
        "axis tilt towards +x / +y [°]",
    );
    chart.x_range = Some((0.0, 360.0));
    let idx: Vec<usize> = run.measured_indices().step_by(stride(run.len())).collect();
    let folded = |i: usize| run.driver_deg[i].rem_euclid(360.0);
    let m: Vec<(f64, (f64, f64))> = idx
        .iter()
        .map(|&i| {
            (
                folded(i),
                project(off.world.inverse() * meas[i] * off.mount.inverse() * Vector3::z()),
            )
        })
        .collect();
    let t: Vec<(f64, (f64, f64))> = (0..=720)
        .map(|k| {
            let phi = k as f64 * 0.5;
            (phi, project(rot.eval(phi) * Vector3::z()))
        })
        .collect();
    chart = chart
        .with(Series::points(
            "measured, towards +x",
            m.iter().map(|p| (p.0, p.1 .0)).collect(),
            2,
            0,
        ))
        .with(Series::points(
            "measured, towards +y",
            m.iter().map(|p| (p.0, p.1 .1)).collect(),
            2,
            1,
        ))
        .with(Series::dashed(
            "target, towards +x",
            t.iter().map(|p| (p.0, p.1 .0)).collect(),
            6,
        ))
        .with(Series::dashed(
            "target, towards +y",
            t.iter().map(|p| (p.0, p.1 .1)).collect(),
            3,
        ));
    let stem = dir.join("follower_axis");
    chart.write(&stem)?;
    Ok((
        "End-effector axis tilt over one driver revolution (all cycles folded): measured against target.".into(),
        stem.with_extension("png"),
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Guards the per-cycle lines: a sparse sensor's every-other empty bin is drawn
    /// across, a hole longer than [`BRIDGED_EMPTY_BINS`] bins breaks the line.
    #[test]
    fn empty_bins_are_bridged_up_to_a_limit() {
        let n = f64::NAN;
        let v = [1.0, n, 2.0, n, n, n, n, 3.0, n, n, n, n, n, 4.0];
        let pts = bridged(&v, |b| b as f64);
        assert_eq!(pts.len(), 5, "{pts:?}");
        // One empty bin and a 4-bin hole are drawn across.
        assert_eq!(pts[..3], [(0.0, 1.0), (2.0, 2.0), (7.0, 3.0)]);
        assert!(pts[3].0.is_nan(), "a 5-bin hole breaks the line: {pts:?}");
        assert_eq!(pts[4], (13.0, 4.0));
    }
}
