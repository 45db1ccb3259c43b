//! The report: pictures for people, numbers for scripts, and a verdict.
//!
//! [`write_report`] writes into one directory: PNG + SVG charts ([`plots`]), `report.md`,
//! a self-contained `report.html` (charts embedded; one document model, [`doc`], renders
//! both) and `summary.json` ([`Summary`]: every metric, units in the field names, and the
//! pass/fail [`Check`]s against the tolerances of [`ReportOptions`]). It computes nothing
//! itself: the figures come from [`crate::analysis::analyze`].

pub mod doc;
pub mod plots;

use std::path::{Path, PathBuf};

use serde::Serialize;

use super::align::Dof;
use super::metrics::{ChannelMetrics, Hysteresis};
use super::run::MeasuredRun;
use super::sampling::SamplingStats;
use super::target::TargetLaw;
use super::timing::TimingReport;
use super::{Analysis, AnalysisError, KeyPoseError};
use crate::motion::units::fixed;
use doc::Block;

/// Cycles covering less of the revolution than this are left out of the per-cycle table
/// of `report.md`/`report.html` (they stay in `summary.json`). Default 0.05: the few
/// samples a run ends with past its last whole cycle say nothing about that cycle.
pub const REPORT_MIN_COVERAGE: f64 = 0.05;

/// Format tag of `summary.json`.
pub const SUMMARY_FORMAT: &str = "mpcrig-summary/1";

/// How to analyse and what to judge.
#[derive(Debug, Clone, Default)]
pub struct ReportOptions {
    /// Where to write the report; `<recording>/report` when `None`.
    pub out_dir: Option<PathBuf>,
    /// Analyse against this mechanism (file or directory) instead of the recording's target.
    pub mechanism: Option<PathBuf>,
    /// Analyse against this motion file instead of the recording's target.
    pub motion: Option<PathBuf>,
    /// Follower crossing angles for timing ratios (`--timing 0,180,360`).
    pub timing_levels: Option<Vec<f64>>,
    /// Tolerance on the RMS rotation error, degrees.
    pub tol_deg: Option<f64>,
    /// Tolerance on the RMS height error, millimetres.
    pub tol_mm: Option<f64>,
    /// Tolerance on |measured − target| of every timing ratio.
    pub tol_ratio: Option<f64>,
    /// Also compare with this prediction of `mpc-rig simulate` (prediction.json).
    pub prediction: Option<PathBuf>,
    /// The folder `mpc-rig build` wrote the measured mechanism's parts into: the report
    /// shows their pictures and figures.
    pub parts: Option<PathBuf>,
}

/// One pass/fail check against a tolerance.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Check {
    /// What is checked, e.g. `rms_error_rz_deg`.
    pub name: String,
    /// The measured figure (`None` when it could not be measured: the check fails).
    pub measured: Option<f64>,
    /// The target value it is compared with (0 for errors).
    pub target: f64,
    /// The allowed |measured − target|.
    pub tolerance: f64,
    /// Whether it passed.
    pub pass: bool,
}

/// Where the data came from.
#[derive(Debug, Clone, Serialize)]
pub struct SourceInfo {
    /// Recording directory.
    pub recording_dir: PathBuf,
    /// Whether the session ended normally (sidecar `complete`).
    pub complete: Option<bool>,
    /// Why it ended.
    pub end_reason: Option<String>,
    /// CSV rows read.
    pub rows: usize,
    /// Rows left out as stale (device-flagged repeated values).
    pub stale_rows: usize,
    /// Rows left out because their driver angle was held rather than measured at their
    /// instant (a mixed bench whose Dynamixel bus fell behind the board).
    pub held_rows: usize,
    /// Rows the device sampled late (missed sampling ticks before them); kept.
    pub late_rows: usize,
    /// The CSV ended in a cut-off line that was dropped.
    pub truncated_last_line: bool,
    /// Why the session marked the recording degraded (sidecar `degraded`), if it did.
    pub degraded: Option<String>,
    /// The recording's own counters (gaps, CRC errors, reconnects …), as written by the rig.
    pub device_counts: serde_json::Value,
    /// Target kind (`mechanism` or `motion`).
    pub target_kind: String,
    /// Target file.
    pub target_path: PathBuf,
}

/// The headline figures.
#[derive(Debug, Clone, Serialize)]
pub struct Headline {
    /// Motion class.
    pub class: String,
    /// Motion name.
    pub motion: String,
    /// RMS rotation error (rz for 1R/1R1T, geodesic for 3R), after alignment.
    pub rms_error_deg: Option<f64>,
    /// Largest rotation error.
    pub max_error_deg: Option<f64>,
    /// RMS height error (1R1T).
    pub rms_error_mm: Option<f64>,
    /// First timing ratio (e.g. first half-turn over second half-turn).
    pub timing_ratio_measured: Option<f64>,
    /// Its expanded uncertainty (k = 2).
    pub timing_ratio_u95: Option<f64>,
    /// The target's ratio (2.0 for half-turn-2to1).
    pub timing_ratio_target: Option<f64>,
    /// Phase lag in driver degrees.
    pub phase_lag_deg: f64,
    /// Driver-side backlash, when both directions were run.
    pub backlash_driver_deg: Option<f64>,
    /// Follower-side dead band about z (its play: printed parts' clearance shows here, not
    /// in the driver-side figure), when both directions were run.
    pub backlash_follower_deg: Option<f64>,
    /// The free fit's negative dead band about z, when it was held at 0 (see
    /// `align::DofOffsets::backlash`); `backlash_follower_deg` is then 0.
    pub backlash_follower_free_deg: Option<f64>,
    /// Complete forward/reverse cycles analysed.
    pub cycles: usize,
    /// Mean sample rate.
    pub sample_rate_hz: f64,
    /// Why the error and timing figures above are absent although samples were analysed
    /// ([`not_enough_data`]); `None` when they rest on whole cycles.
    pub not_enough_data: Option<String>,
}

/// Why a run with no complete cycle gets no error or timing figures: over part of a
/// revolution the alignment fits offsets that absorb most of any error (issue 20: a run
/// that disconnected got "error RMS 0.025°" after a −41° driver offset was fitted on
/// 0 cycles), so such an RMS says nothing about the mechanism. `None` with a whole cycle.
pub fn not_enough_data(cycles: usize) -> Option<String> {
    (cycles == 0).then(|| {
        format!(
            "not enough data: no complete driver revolution was recorded (a cycle counts \
             when {:.0} % of it is covered), so no error or timing figures are given; the \
             offsets were fitted on part of a revolution",
            super::metrics::FULL_CYCLE_COVERAGE * 100.0
        )
    })
}

/// The offsets, with units in the field names.
#[derive(Debug, Clone, Serialize)]
pub struct AlignmentSummary {
    /// Constant driver-angle offset δ₀ (positive: follower behind).
    pub driver_offset_deg: f64,
    /// Its standard error.
    pub driver_offset_std_err_deg: f64,
    /// False when the law cannot separate it from the sensor offset (uniform laws).
    pub driver_offset_determined: bool,
    /// Sensor offset of rz, degrees.
    pub sensor_offset_rz_deg: Option<f64>,
    /// Its standard error.
    pub sensor_offset_rz_std_err_deg: Option<f64>,
    /// Sensor offset of tz, millimetres.
    pub sensor_offset_tz_mm: Option<f64>,
    /// Its standard error.
    pub sensor_offset_tz_std_err_mm: Option<f64>,
    /// 3R: angle of the world-frame (IMU heading) offset.
    pub world_offset_deg: Option<f64>,
    /// 3R: its axis.
    pub world_offset_axis: Option<[f64; 3]>,
    /// 3R: angle of the mounting offset.
    pub mount_offset_deg: Option<f64>,
    /// 3R: its axis.
    pub mount_offset_axis: Option<[f64; 3]>,
    /// Non-settle samples used.
    pub samples: usize,
}

/// Lag and backlash, with units in the field names.
#[derive(Debug, Clone, Serialize)]
pub struct LagSummary {
    /// Phase lag (= the driver offset; a homing error looks the same).
    pub phase_lag_driver_deg: f64,
    /// As a time at the forward speed.
    pub phase_lag_ms: Option<f64>,
    /// Driver-side backlash 2λ (forward and reverse runs only).
    pub backlash_driver_deg: Option<f64>,
    /// Its standard error.
    pub backlash_driver_std_err_deg: Option<f64>,
    /// Follower-side dead band in rz.
    pub backlash_follower_rz_deg: Option<f64>,
    /// Follower-side dead band in tz.
    pub backlash_follower_tz_mm: Option<f64>,
    /// The free fit's negative dead band in rz, when it was held at 0.
    pub backlash_follower_rz_free_deg: Option<f64>,
    /// The free fit's negative dead band in tz, when it was held at 0.
    pub backlash_follower_tz_free_mm: Option<f64>,
    /// 3R forward/reverse difference of the error rotation.
    pub rotation_hysteresis: Option<Hysteresis>,
}

/// `summary.json`: every figure of the analysis for scripts.
#[derive(Debug, Clone, Serialize)]
pub struct Summary {
    /// [`SUMMARY_FORMAT`].
    pub format: String,
    /// `None` without tolerances; otherwise whether every check passed.
    pub pass: Option<bool>,
    /// The checks.
    pub checks: Vec<Check>,
    /// Headline figures.
    pub headline: Headline,
    /// Offsets.
    pub alignment: AlignmentSummary,
    /// Lag and backlash.
    pub lag: LagSummary,
    /// Error statistics per channel.
    pub errors: Vec<ChannelMetrics>,
    /// Timing ratios.
    pub timing: Option<TimingReport>,
    /// 3R key poses.
    pub key_poses: Vec<KeyPoseError>,
    /// Sampling figures.
    pub sampling: SamplingStats,
    /// Data sources.
    pub source: SourceInfo,
    /// The measurement against the parts' predicted law (`--prediction`).
    pub prediction: Option<super::prediction::PredictionComparison>,
    /// The printed parts the measurement was made with (`--parts`).
    pub parts: Option<PartsSummary>,
    /// Files written (relative to the report directory).
    pub files: Vec<String>,
}

/// ` The prediction says the parts lose the drive at driver a–b°, …: there the follower
/// is not held.` or nothing when they never do.
pub fn drive_lost_sentence(windows: &[[f64; 2]]) -> String {
    if windows.is_empty() {
        return String::new();
    }
    format!(
        " The prediction says the parts lose the drive at driver {}: there the follower is \
         not held.",
        crate::predict::lost_windows_text(windows)
    )
}

/// The parts `mpc-rig build` made of the measured mechanism, as the report shows them.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct PartsSummary {
    /// The folder the build wrote.
    pub dir: PathBuf,
    /// Whether the build found them printable.
    pub printable: bool,
    /// Why not, when they are not.
    pub problems: Vec<String>,
    /// Print clearance, mm.
    pub clearance_mm: f64,
    /// Deepest point of one part inside another over the period (a vertex or a point of a
    /// ridge), mm.
    pub worst_penetration_mm: f64,
    /// Smallest gap at a design contact over the period, mm (`None` without pairs).
    pub smallest_gap_mm: Option<f64>,
    /// Per part: name, triangles, volume (mm³) and bounding box size (mm).
    pub parts: Vec<(String, usize, f64, [f64; 3])>,
    /// Per part, in the order of `parts`: what the build measured of its walls and mesh.
    pub quality: Vec<PartQuality>,
}

/// What the build measured of one part's walls and mesh; `None` where a build made before
/// 2026-12-06 did not measure it.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct PartQuality {
    /// Share of the surface over walls thinner than `thin_below_mm`.
    pub thin_share: Option<f64>,
    /// The bound, mm.
    pub thin_below_mm: Option<f64>,
    /// 99th percentile of the mesh error, mm.
    pub mesh_error_p99_mm: Option<f64>,
}

/// The assembly pictures of the build shown in the report, copied beside it as
/// `parts-<name>` so the report stays whole when moved.
const PARTS_PICTURES: [(&str, &str); 2] = [
    (
        "assembly-isometric.png",
        "The printed parts, assembled (isometric view).",
    ),
    ("assembly-front.png", "The printed parts, from the front."),
];

/// Read what `mpc-rig build` wrote into `dir` and copy its assembly pictures into
/// `out_dir`; the summary and the pictures' (caption, copied path).
fn parts_summary(
    dir: &Path,
    out_dir: &Path,
) -> Result<(PartsSummary, Vec<plots::Picture>), AnalysisError> {
    let built = crate::predict::BuiltParts::load(dir).map_err(|e| AnalysisError::BadOption {
        option: "--parts".into(),
        message: e.to_string(),
    })?;
    let mut pics = Vec::new();
    for (name, caption) in PARTS_PICTURES {
        let from = dir.join(name);
        if !from.exists() {
            continue;
        }
        let to = out_dir.join(format!("parts-{name}"));
        std::fs::copy(&from, &to).map_err(|e| AnalysisError::io(&from, e))?;
        pics.push((caption.to_string(), to));
    }
    let summary = PartsSummary {
        dir: dir.to_path_buf(),
        printable: built.printable,
        problems: built.problems.clone(),
        clearance_mm: built.clearance_mm,
        worst_penetration_mm: built
            .check
            .penetrations
            .iter()
            .map(|p| p.depth_mm)
            .fold(0.0, f64::max),
        smallest_gap_mm: built
            .check
            .gaps
            .iter()
            .map(|g| g.min_mm)
            .min_by(f64::total_cmp),
        parts: built
            .parts
            .iter()
            .map(|p| {
                let size = std::array::from_fn(|i| p.bbox_max_mm[i] - p.bbox_min_mm[i]);
                (p.name.clone(), p.triangles, p.volume_mm3, size)
            })
            .collect(),
        quality: built
            .parts
            .iter()
            .map(|p| PartQuality {
                thin_share: p
                    .walls
                    .as_ref()
                    .filter(|w| w.area_mm2 > 0.0)
                    .map(|w| w.thin_area_mm2 / w.area_mm2),
                thin_below_mm: p.walls.as_ref().map(|w| w.thin_below_mm),
                mesh_error_p99_mm: p.mesh_error.as_ref().map(|e| e.p99_mm),
            })
            .collect(),
    };
    Ok((summary, pics))
}

/// The tolerance checks; with `enough` false (no complete cycle) every figure counts as
/// not measured, so a tolerance given is missed.
fn checks(a: &Analysis, opts: &ReportOptions, enough: bool) -> Vec<Check> {
    let mut out = Vec::new();
    let rot = a
        .channels
        .iter()
        .find(|c| c.name == "rz" || c.name == "rotation")
        .filter(|_| enough);
    if let Some(tol) = opts.tol_deg {
        let m = rot.map(|c| c.overall.rms);
        out.push(Check {
            name: format!(
                "rms_error_{}_deg",
                rot.map_or("rotation", |c| c.name.as_str())
            ),
            measured: m,
            target: 0.0,
            tolerance: tol,
            pass: m.is_some_and(|m| m <= tol),
        });
    }
    if let Some(tol) = opts.tol_mm {
        let m = a
            .channels
            .iter()
            .find(|c| c.name == "tz")
            .filter(|_| enough)
            .map(|c| c.overall.rms);
        out.push(Check {
            name: "rms_error_tz_mm".into(),
            measured: m,
            target: 0.0,
            tolerance: tol,
            pass: m.is_some_and(|m| m <= tol),
        });
    }
    if let Some(tol) = opts.tol_ratio {
        match a.timing.as_ref().filter(|_| enough) {
            Some(t) if !t.ratios.is_empty() => {
                for r in &t.ratios {
                    out.push(Check {
                        name: format!(
                            "timing_ratio_{}_{}_{}",
                            r.levels_deg[0], r.levels_deg[1], r.levels_deg[2]
                        ),
                        measured: Some(r.measured),
                        target: r.target,
                        tolerance: tol,
                        pass: (r.measured - r.target).abs() <= tol,
                    });
                }
            }
            _ => out.push(Check {
                name: "timing_ratio".into(),
                measured: None,
                target: f64::NAN,
                tolerance: tol,
                pass: false,
            }),
        }
    }
    out
}

/// Build the summary (no files written).
pub fn summarize(
    a: &Analysis,
    law: &TargetLaw,
    source: SourceInfo,
    opts: &ReportOptions,
) -> Summary {
    let rot = a
        .channels
        .iter()
        .find(|c| c.name == "rz" || c.name == "rotation");
    let cycles = rot.map_or(0, |c| {
        c.per_cycle
            .iter()
            .filter(|k| k.coverage >= super::metrics::FULL_CYCLE_COVERAGE)
            .count()
    });
    let not_enough_data = not_enough_data(cycles);
    let enough = not_enough_data.is_none();
    let checks = checks(a, opts, enough);
    let pass = (!checks.is_empty()).then(|| checks.iter().all(|c| c.pass));
    // Without a whole cycle the figures are withheld (see [`not_enough_data`]).
    let rot = rot.filter(|_| enough);
    let tz = a
        .channels
        .iter()
        .find(|c| c.name == "tz")
        .filter(|_| enough);
    let ratio = a
        .timing
        .as_ref()
        .and_then(|t| t.ratios.first())
        .filter(|_| enough);
    let off = |d: Dof| a.alignment.dofs.iter().find(|o| o.dof == d);
    let rot_off = a.alignment.rotation;
    let axis = |q: nalgebra::UnitQuaternion<f64>| {
        q.axis().map_or([0.0, 0.0, 1.0], |ax| [ax.x, ax.y, ax.z])
    };
    let bl = a.backlash.as_ref();
    let follower_bl = |d: Dof| {
        bl.and_then(|b| {
            b.follower
                .iter()
                .find(|(x, _)| *x == d)
                .map(|(_, e)| e.value)
        })
    };
    let follower_free = |d: Dof| off(d).and_then(|o| o.backlash_free);
    Summary {
        format: SUMMARY_FORMAT.into(),
        pass,
        checks,
        headline: Headline {
            class: a.class.into(),
            motion: law.name.clone(),
            rms_error_deg: rot.map(|c| c.overall.rms),
            max_error_deg: rot.map(|c| c.overall.max_abs),
            rms_error_mm: tz.map(|c| c.overall.rms),
            timing_ratio_measured: ratio.map(|r| r.measured),
            timing_ratio_u95: ratio.map(|r| r.u95),
            timing_ratio_target: ratio.map(|r| r.target),
            phase_lag_deg: a.phase_lag.driver_deg.value,
            backlash_driver_deg: bl.map(|b| b.driver_deg.value),
            backlash_follower_deg: follower_bl(Dof::Rz),
            backlash_follower_free_deg: follower_free(Dof::Rz),
            cycles,
            sample_rate_hz: a.sampling.mean_rate_hz,
            not_enough_data,
        },
        alignment: AlignmentSummary {
            driver_offset_deg: a.alignment.driver_offset_deg.value,
            driver_offset_std_err_deg: a.alignment.driver_offset_deg.std_err,
            driver_offset_determined: a.alignment.driver_offset_deg.determined,
            sensor_offset_rz_deg: off(Dof::Rz).map(|o| o.sensor_offset.value),
            sensor_offset_rz_std_err_deg: off(Dof::Rz).map(|o| o.sensor_offset.std_err),
            sensor_offset_tz_mm: off(Dof::Tz).map(|o| o.sensor_offset.value),
            sensor_offset_tz_std_err_mm: off(Dof::Tz).map(|o| o.sensor_offset.std_err),
            world_offset_deg: rot_off.map(|r| r.world.angle().to_degrees()),
            world_offset_axis: rot_off.map(|r| axis(r.world)),
            mount_offset_deg: rot_off.map(|r| r.mount.angle().to_degrees()),
            mount_offset_axis: rot_off.map(|r| axis(r.mount)),
            samples: a.alignment.samples,
        },
        lag: LagSummary {
            phase_lag_driver_deg: a.phase_lag.driver_deg.value,
            phase_lag_ms: a.phase_lag.ms,
            backlash_driver_deg: bl.map(|b| b.driver_deg.value),
            backlash_driver_std_err_deg: bl.map(|b| b.driver_deg.std_err),
            backlash_follower_rz_deg: follower_bl(Dof::Rz),
            backlash_follower_tz_mm: follower_bl(Dof::Tz),
            backlash_follower_rz_free_deg: follower_free(Dof::Rz),
            backlash_follower_tz_free_mm: follower_free(Dof::Tz),
            rotation_hysteresis: a.rotation_hysteresis,
        },
        errors: a.channels.clone(),
        timing: a.timing.clone(),
        key_poses: a.key_poses.clone(),
        sampling: a.sampling.clone(),
        source,
        prediction: None,
        parts: None,
        files: Vec::new(),
    }
}

/// What the sample counts leave unsaid about a side falling behind, for the headline and
/// the command's summary line: rows whose driver angle was held (left out) and rows the
/// device sampled late; empty when there are none.
pub fn behind(src: &SourceInfo) -> String {
    let mut out = String::new();
    if src.held_rows > 0 {
        out += &format!(
            ", {} rows left out whose driver angle was held (the Dynamixel bus fell behind \
             the board)",
            src.held_rows
        );
    }
    if src.late_rows > 0 {
        out += &format!(", {} samples taken late by the device", src.late_rows);
    }
    out
}

/// The recording's counters as words ("crc errors 0, gaps 2, …") rather than raw JSON
/// (issue 20).
fn counters_text(counts: &serde_json::Value) -> String {
    match counts.as_object() {
        Some(map) => map
            .iter()
            .map(|(k, v)| format!("{} {v}", k.replace('_', " ")))
            .collect::<Vec<_>>()
            .join(", "),
        None => counts.to_string(),
    }
}

/// The follower-side dead band after the driver-side backlash, when it was fitted; one the
/// free fit put below zero reads as none, with that value.
pub fn follower_play(dead_band_deg: Option<f64>, free_deg: Option<f64>) -> String {
    match (dead_band_deg, free_deg) {
        (Some(_), Some(free)) => format!(
            " and no follower-side dead band (the free fit's {}° held at 0)",
            f3(free)
        ),
        (Some(f), None) => format!(" and {}° of follower (its dead band)", f3(f)),
        (None, _) => String::new(),
    }
}

/// The note beside a follower-side dead band in the offsets table: where a free fit's
/// negative width was held at 0, that width.
fn held_note(free: Option<f64>, unit: &str) -> String {
    free.map_or(String::new(), |v| {
        format!(
            "held at 0: the free fit gave {} {unit} (a width cannot be negative; the \
             directions' gap is the driver side's)",
            f3(v)
        )
    })
}

/// The driver-side backlash with its standard error, "2.013 ± 0.004": a figure near zero
/// reads as zero within its error rather than as a negative backlash ("-0.001" alone did).
pub fn backlash_with_error(value: f64, std_err: Option<f64>) -> String {
    match std_err {
        Some(e) if e.is_finite() => format!("{} ± {}", f3(value), f3(e)),
        _ => f3(value),
    }
}

/// `v` with three decimals, without the sign of a value that rounds to zero ("-0.000"
/// reads as a negative figure; issue 20).
pub fn f3(v: f64) -> String {
    fixed(v, 3)
}

fn opt3(v: Option<f64>) -> String {
    v.map_or_else(|| "–".into(), f3)
}

/// The verdict sentence.
fn verdict(s: &Summary) -> (Option<bool>, String) {
    let failed: Vec<&str> = s
        .checks
        .iter()
        .filter(|c| !c.pass)
        .map(|c| c.name.as_str())
        .collect();
    match s.pass {
        Some(true) => (
            Some(true),
            format!("PASS — all {} tolerance checks met", s.checks.len()),
        ),
        Some(false) => (Some(false), format!("FAIL — missed: {}", failed.join(", "))),
        None => (
            None,
            "No tolerances given (use --tol-deg, --tol-mm, --tol-ratio for a verdict)".into(),
        ),
    }
}

/// The report as blocks, section by section.
fn blocks(
    s: &Summary,
    a: &Analysis,
    pictures: &[plots::Picture],
    parts_pictures: &[plots::Picture],
) -> Vec<Block> {
    let mut b = Vec::new();
    headline_blocks(s, pictures, &mut b);
    parts_blocks(s, parts_pictures, &mut b);
    alignment_blocks(s, &mut b);
    error_blocks(s, a, &mut b);
    timing_blocks(s, &mut b);
    key_pose_blocks(s, &mut b);
    sampling_blocks(s, &mut b);
    b
}

/// The top of the report: title, verdict, the headline sentences, the checks and the
/// pictures, so a person understands the result at a glance.
fn headline_blocks(s: &Summary, pictures: &[plots::Picture], b: &mut Vec<Block>) {
    let h = &s.headline;
    b.push(Block::Heading(
        1,
        format!("Bench report: {} ({})", h.motion, h.class),
    ));
    let (v, text) = verdict(s);
    b.push(Block::Verdict(v, text));
    let mut lines = Vec::new();
    if let (Some(m), Some(u), Some(t)) = (
        h.timing_ratio_measured,
        h.timing_ratio_u95,
        h.timing_ratio_target,
    ) {
        let lv = s
            .timing
            .as_ref()
            .map(|t| t.ratios[0].levels_deg)
            .unwrap_or_default();
        lines.push(format!(
            "Timing: the follower's {}°→{}° took **{m:.3} ± {u:.3}** times as long as {}°→{}° (target **{t:.3}**).",
            lv[0], lv[1], lv[1], lv[2]
        ));
    }
    if let Some(why) = &h.not_enough_data {
        lines.push(format!("**{}{}.**", why[..1].to_uppercase(), &why[1..]));
    }
    if let Some(r) = h.rms_error_deg {
        lines.push(format!(
            "Rotation error after alignment: RMS **{r:.3}°**, max {:.3}°.",
            h.max_error_deg.unwrap_or(f64::NAN)
        ));
    }
    if let Some(p) = &s.prediction {
        lines.push(format!(
            "Against the law predicted for the built parts (`{}`): RMS **{:.3}°**, max {:.3}° \
             (against the target on the same samples: RMS {:.3}°).{}",
            p.file.display(),
            p.rms_deg,
            p.max_deg,
            p.rms_vs_target_deg,
            drive_lost_sentence(&p.drive_lost_deg)
        ));
    }
    if let Some(r) = h.rms_error_mm {
        lines.push(format!("Height error after alignment: RMS **{r:.3} mm**."));
    }
    if let Some(p) = s.prediction.as_ref().and_then(|p| p.height) {
        lines.push(format!(
            "Height against the predicted law: RMS **{:.3} mm**, max {:.3} mm (against the \
             target on the same samples: RMS {:.3} mm).",
            p.rms_mm, p.max_mm, p.rms_vs_target_mm
        ));
    }
    lines.push(format!(
        "Phase lag {}° of driver angle{}; {}.",
        f3(h.phase_lag_deg),
        s.lag
            .phase_lag_ms
            .map_or(String::new(), |ms| format!(" ({} ms)", fixed(ms, 1))),
        h.backlash_driver_deg
            .map_or("backlash not measured (no reverse run)".to_string(), |v| {
                format!(
                    "backlash {}° of driver angle{}",
                    backlash_with_error(v, s.lag.backlash_driver_std_err_deg),
                    follower_play(h.backlash_follower_deg, h.backlash_follower_free_deg)
                )
            })
    ));
    lines.push(format!(
        "{} complete cycles, {} samples at {:.1} Hz, {} gaps{}.",
        h.cycles,
        s.sampling.samples,
        s.sampling.mean_rate_hz,
        s.sampling.gaps,
        behind(&s.source)
    ));
    if let Some(why) = &s.source.degraded {
        lines.push(format!(
            "**Degraded recording:** {why}. Figures that need whole cycles (timing ratios, \
             per-cycle statistics) are given only for cycles the samples cover."
        ));
    }
    for l in lines {
        b.push(Block::Para(l));
    }
    if !s.checks.is_empty() {
        b.push(Block::Table(
            vec![
                "check".into(),
                "measured".into(),
                "target".into(),
                "tolerance".into(),
                "result".into(),
            ],
            s.checks
                .iter()
                .map(|c| {
                    vec![
                        c.name.clone(),
                        opt3(c.measured),
                        f3(c.target),
                        format!("±{}", c.tolerance),
                        if c.pass {
                            "pass".into()
                        } else {
                            "**FAIL**".into()
                        },
                    ]
                })
                .collect(),
        ));
    }
    // Pictures early: a person should understand the result at a glance.
    for (cap, path) in pictures {
        b.push(Block::Image(cap.clone(), path.clone()));
    }
}

/// The printed parts the mechanism was measured with: their pictures and figures.
fn parts_blocks(s: &Summary, pictures: &[plots::Picture], b: &mut Vec<Block>) {
    let Some(p) = &s.parts else {
        return;
    };
    b.push(Block::Heading(2, "The printed parts".into()));
    let verdict = if p.printable {
        "printable".to_string()
    } else {
        format!("**not printable**: {}", p.problems.join("; "))
    };
    b.push(Block::Para(format!(
        "Built by `mpc-rig build` into `{}` ({verdict}); its `build.md` has every figure. \
         Clearance {} mm; over the period no part enters another by more than {} mm, and \
         the smallest gap at a design contact is {} mm. The simulated follower is moved as \
         these parts move it (the prediction above).",
        p.dir.display(),
        f3(p.clearance_mm),
        f3(p.worst_penetration_mm),
        opt3(p.smallest_gap_mm),
    )));
    b.push(Block::Table(
        vec![
            "part".into(),
            "triangles".into(),
            "volume [mm³]".into(),
            "size [mm]".into(),
            "thin walls".into(),
            "mesh error, 99 % [mm]".into(),
        ],
        p.parts
            .iter()
            .enumerate()
            .map(|(i, (name, tri, vol, size))| {
                let q = p.quality.get(i);
                let thin = match q.and_then(|q| q.thin_share.zip(q.thin_below_mm)) {
                    Some((share, below)) => {
                        format!("{:.1} % of the surface under {below} mm", 100.0 * share)
                    }
                    None => "–".into(),
                };
                vec![
                    name.clone(),
                    tri.to_string(),
                    format!("{vol:.0}"),
                    format!("{:.0} × {:.0} × {:.0}", size[0], size[1], size[2]),
                    thin,
                    q.and_then(|q| q.mesh_error_p99_mm)
                        .map_or("–".into(), |e| format!("{e:.3}")),
                ]
            })
            .collect(),
    ));
    for (cap, path) in pictures {
        b.push(Block::Image(cap.clone(), path.clone()));
    }
}

/// The offsets the alignment fitted and the play it found (reported, not hidden).
fn alignment_blocks(s: &Summary, b: &mut Vec<Block>) {
    b.push(Block::Heading(2, "Alignment (reported, not hidden)".into()));
    let al = &s.alignment;
    let mut rows = vec![vec![
        "driver-angle offset δ₀ (phase lag)".into(),
        format!(
            "{} ± {} °",
            f3(al.driver_offset_deg),
            f3(al.driver_offset_std_err_deg)
        ),
        if al.driver_offset_determined {
            "".into()
        } else {
            "not separable from the sensor offset".into()
        },
    ]];
    if let Some(v) = al.sensor_offset_rz_deg {
        rows.push(vec![
            "sensor offset rz".into(),
            format!("{} ± {} °", f3(v), opt3(al.sensor_offset_rz_std_err_deg)),
            String::new(),
        ]);
    }
    if let Some(v) = al.sensor_offset_tz_mm {
        rows.push(vec![
            "sensor offset tz".into(),
            format!("{} ± {} mm", f3(v), opt3(al.sensor_offset_tz_std_err_mm)),
            String::new(),
        ]);
    }
    if let (Some(w), Some(ax)) = (al.world_offset_deg, al.world_offset_axis) {
        rows.push(vec![
            "IMU world-frame offset".into(),
            format!("{w:.3}° about [{:.2}, {:.2}, {:.2}]", ax[0], ax[1], ax[2]),
            String::new(),
        ]);
    }
    if let (Some(w), Some(ax)) = (al.mount_offset_deg, al.mount_offset_axis) {
        rows.push(vec![
            "mounting offset".into(),
            format!("{w:.3}° about [{:.2}, {:.2}, {:.2}]", ax[0], ax[1], ax[2]),
            String::new(),
        ]);
    }
    if let Some(v) = s.lag.backlash_driver_deg {
        rows.push(vec![
            "driver-side backlash (2λ)".into(),
            format!("{} ± {} °", f3(v), opt3(s.lag.backlash_driver_std_err_deg)),
            "includes 2 × time lag × speed".into(),
        ]);
    }
    if let Some(v) = s.lag.backlash_follower_rz_deg {
        rows.push(vec![
            "follower-side dead band rz".into(),
            format!("{} °", f3(v)),
            held_note(s.lag.backlash_follower_rz_free_deg, "°"),
        ]);
    }
    if let Some(v) = s.lag.backlash_follower_tz_mm {
        rows.push(vec![
            "follower-side dead band tz".into(),
            format!("{} mm", f3(v)),
            held_note(s.lag.backlash_follower_tz_free_mm, "mm"),
        ]);
    }
    b.push(Block::Table(
        vec!["offset".into(), "value".into(), "note".into()],
        rows,
    ));
}

/// The error statistics per channel and direction, repeatability, hysteresis and the
/// first channel's cycles.
fn error_blocks(s: &Summary, a: &Analysis, b: &mut Vec<Block>) {
    b.push(Block::Heading(2, "Errors".into()));
    let mut rows = Vec::new();
    for c in &a.channels {
        let u = c.unit;
        for (label, st) in [
            ("all", Some(c.overall)),
            ("forward", c.forward),
            ("reverse", c.reverse),
            ("unaligned", c.unaligned),
        ] {
            if let Some(st) = st {
                rows.push(vec![
                    format!("{} ({label})", c.name),
                    st.samples.to_string(),
                    format!("{} {u}", f3(st.rms)),
                    format!("{} {u}", f3(st.mean)),
                    format!("{} {u}", f3(st.max_abs)),
                    format!("{} {u}", f3(st.p95_abs)),
                ]);
            }
        }
    }
    b.push(Block::Table(
        [
            "channel",
            "samples",
            "RMS",
            "mean",
            "largest",
            "95 % within",
        ]
        .map(String::from)
        .to_vec(),
        rows,
    ));
    let mut rows = Vec::new();
    for c in &a.channels {
        if let Some(r) = c.repeatability {
            rows.push(vec![
                format!("{} repeatability ({} cycles)", c.name, r.cycles),
                format!("RMS σ {} {}", f3(r.rms_std), c.unit),
                format!("max σ {} {}", f3(r.max_std), c.unit),
            ]);
        }
        if let Some(hy) = c.hysteresis {
            rows.push(vec![
                format!("{} hysteresis (reverse − forward)", c.name),
                format!("mean {} {}", f3(hy.mean), c.unit),
                format!("max {} {}", f3(hy.max_abs), c.unit),
            ]);
        }
    }
    if let Some(hy) = s.lag.rotation_hysteresis {
        rows.push(vec![
            "rotation hysteresis (forward vs reverse)".into(),
            format!("mean {} deg", f3(hy.mean)),
            format!("max {} deg", f3(hy.max_abs)),
        ]);
    }
    if !rows.is_empty() {
        b.push(Block::Table(
            vec!["figure".into(), "".into(), "".into()],
            rows,
        ));
    }
    if let Some(c) = a.channels.first() {
        b.push(Block::Heading(3, format!("Per cycle ({})", c.name)));
        let rows = c
            .per_cycle
            .iter()
            .filter(|k| k.coverage >= REPORT_MIN_COVERAGE)
            .map(|k| {
                vec![
                    format!("{} {}", k.direction.as_str(), k.cycle),
                    format!("{:.0} %", 100.0 * k.coverage),
                    format!("{} {}", f3(k.stats.rms), c.unit),
                    format!("{} {}", f3(k.stats.mean), c.unit),
                    format!("{} {}", f3(k.stats.max_abs), c.unit),
                ]
            })
            .collect();
        b.push(Block::Table(
            ["cycle", "coverage", "RMS", "mean", "largest"]
                .map(String::from)
                .to_vec(),
            rows,
        ));
    }
}

/// The timing ratios and each cycle's durations.
fn timing_blocks(s: &Summary, b: &mut Vec<Block>) {
    if let Some(t) = &s.timing {
        b.push(Block::Heading(2, "Timing".into()));
        b.push(Block::Para(format!(
            "Crossings of the follower angles {:?}° (relative to each cycle's start), found by interpolation; uncertainties from sample period, encoder resolution and noise, expanded k = 2.",
            t.levels_deg
        )));
        let rows = t
            .ratios
            .iter()
            .map(|r| {
                vec![
                    format!(
                        "({}→{}) / ({}→{})",
                        r.levels_deg[0], r.levels_deg[1], r.levels_deg[1], r.levels_deg[2]
                    ),
                    format!("**{:.4}** ± {:.4}", r.measured, r.u95),
                    format!("{:.4}", r.measured_span_ratio),
                    format!("{:.4}", r.target),
                    format!("{:.4}", r.cycle_std),
                ]
            })
            .collect();
        b.push(Block::Table(
            [
                "ratio",
                "measured (time)",
                "measured (driver angle)",
                "target",
                "σ across cycles",
            ]
            .map(String::from)
            .to_vec(),
            rows,
        ));
        let rows = t
            .cycles
            .iter()
            .map(|c| {
                let mut r = vec![c.cycle.to_string()];
                r.extend(c.durations_s.iter().map(|d| format!("{d:.4} s")));
                r.extend(
                    c.ratios
                        .iter()
                        .zip(&c.ratios_u95)
                        .map(|(x, u)| format!("{x:.4} ± {u:.4}")),
                );
                r
            })
            .collect();
        let mut head = vec!["cycle".to_string()];
        head.extend(
            (0..t.levels_deg.len() - 1)
                .map(|j| format!("{}→{}°", t.levels_deg[j], t.levels_deg[j + 1])),
        );
        head.extend((0..t.ratios.len()).map(|j| format!("ratio {j}")));
        b.push(Block::Table(head, rows));
    }
}

/// The error at each key pose.
fn key_pose_blocks(s: &Summary, b: &mut Vec<Block>) {
    if !s.key_poses.is_empty() {
        b.push(Block::Heading(2, "Key poses".into()));
        let rows = s
            .key_poses
            .iter()
            .map(|k| {
                vec![
                    k.index.to_string(),
                    format!("{:.3}", k.t),
                    k.passes.to_string(),
                    format!("{} °", f3(k.mean_deg)),
                    format!("{} °", f3(k.max_deg)),
                ]
            })
            .collect();
        b.push(Block::Table(
            ["key pose", "t", "passes", "mean error", "max error"]
                .map(String::from)
                .to_vec(),
            rows,
        ));
    }
}

/// How the samples were taken and what the recording holds.
fn sampling_blocks(s: &Summary, b: &mut Vec<Block>) {
    b.push(Block::Heading(2, "Sampling and recording".into()));
    let sm = &s.sampling;
    let src = &s.source;
    b.push(Block::Table(
        vec!["figure".into(), "value".into()],
        vec![
            vec!["samples".into(), sm.samples.to_string()],
            vec!["duration".into(), format!("{:.3} s", sm.duration_s)],
            vec!["mean rate".into(), format!("{:.2} Hz", sm.mean_rate_hz)],
            vec![
                "period median / min / max".into(),
                format!(
                    "{:.3} / {:.3} / {:.3} ms",
                    sm.median_period_ms, sm.min_period_ms, sm.max_period_ms
                ),
            ],
            vec![
                "period jitter (σ)".into(),
                format!("{:.4} ms", sm.period_jitter_ms),
            ],
            vec![
                "gaps / missing samples (est.)".into(),
                format!("{} / {}", sm.gaps, sm.missing_samples_estimate),
            ],
            vec![
                "driver speed forward / reverse".into(),
                format!(
                    "{} / {} °/s",
                    opt3(sm.driver_speed_forward_deg_per_s),
                    opt3(sm.driver_speed_reverse_deg_per_s)
                ),
            ],
            vec!["recording".into(), src.recording_dir.display().to_string()],
            vec![
                "complete".into(),
                src.complete.map_or("unknown".into(), |c| {
                    if c {
                        "yes".into()
                    } else {
                        format!("no ({})", src.end_reason.clone().unwrap_or_default())
                    }
                }),
            ],
            vec![
                "degraded".into(),
                src.degraded.clone().unwrap_or_else(|| "no".into()),
            ],
            vec![
                "rows / left out: stale / driver held".into(),
                format!("{} / {} / {}", src.rows, src.stale_rows, src.held_rows),
            ],
            vec!["rows sampled late".into(), src.late_rows.to_string()],
            vec![
                "truncated last line".into(),
                if src.truncated_last_line {
                    "yes (dropped)".into()
                } else {
                    "no".into()
                },
            ],
            vec!["device counters".into(), counters_text(&src.device_counts)],
            vec![
                "target".into(),
                format!("{} {}", src.target_kind, src.target_path.display()),
            ],
        ],
    ));
}

/// Write every chart, `report.md`, `report.html` and `summary.json` into `out_dir`.
pub fn write_report(
    out_dir: &Path,
    a: &Analysis,
    run: &MeasuredRun,
    law: &TargetLaw,
    source: SourceInfo,
    opts: &ReportOptions,
) -> Result<Summary, AnalysisError> {
    std::fs::create_dir_all(out_dir).map_err(|e| AnalysisError::io(out_dir, e))?;
    let mut s = summarize(a, law, source, opts);
    let mut predicted_deviation = None;
    if let Some(path) = &opts.prediction {
        let predicted = crate::predict::table::PredictedDeviation::load(path).map_err(|e| {
            AnalysisError::BadOption {
                option: "--prediction".into(),
                message: e.to_string(),
            }
        })?;
        use crate::synth::mechanism::Mechanism;
        if let Some((made_for, target)) = Mechanism::other_than(
            predicted.mechanism_digest(),
            law.mechanism_digest.as_deref(),
        ) {
            return Err(AnalysisError::BadOption {
                option: "--prediction".into(),
                message: format!(
                    "{}: a prediction for another mechanism than the target (its \
                     mechanism digest is {}…, the target's {}…). Predict the target: \
                     mpc-rig simulate MECHANISM",
                    path.display(),
                    Mechanism::short_digest(made_for),
                    Mechanism::short_digest(target)
                ),
            });
        }
        s.prediction = super::prediction::compare(a, run, &predicted, path.clone());
        predicted_deviation = Some(predicted);
    }
    let mut parts_pics = Vec::new();
    if let Some(dir) = &opts.parts {
        let (summary, pics) = parts_summary(dir, out_dir)?;
        s.parts = Some(summary);
        parts_pics = pics;
    }
    let mut pics: Vec<plots::Picture> = Vec::new();
    if let Some(t) = &a.timing {
        if !t.ratios.is_empty() {
            pics.push(plots::timing_chart(out_dir, t, opts.tol_ratio)?);
        }
    }
    if law.rotation.is_some() {
        pics.push(plots::axis_chart(out_dir, run, law, a)?);
        pics.push(plots::axis_over_driver_chart(out_dir, run, law, a)?);
    }
    for dof in [Dof::Rz, Dof::Tz] {
        if a.alignment.dofs.iter().any(|d| d.dof == dof) {
            pics.push(plots::follower_chart(out_dir, run, law, a, dof)?);
        }
    }
    for (ch, m) in a.errors.iter().zip(&a.channels) {
        if matches!(ch.name.as_str(), "rx" | "ry") || (law.rotation.is_some() && ch.name == "rz") {
            continue;
        }
        let tol = if ch.unit == "deg" {
            opts.tol_deg
        } else {
            opts.tol_mm
        };
        let predicted = predicted_deviation
            .as_ref()
            .filter(|p| (a.class == "1R" || a.class == "1R1T") && p.predicts(&ch.name))
            .map(|p| (p, a.alignment.driver_offset_deg.value));
        pics.push(plots::error_chart(out_dir, run, ch, m, tol, predicted)?);
        pics.push(plots::cycles_chart(out_dir, m)?);
        pics.push(plots::histogram_chart(out_dir, run, ch, m)?);
    }
    let mut files: Vec<String> = Vec::new();
    for (_, p) in &pics {
        for ext in ["png", "svg"] {
            files.push(
                p.with_extension(ext)
                    .file_name()
                    .map(|n| n.to_string_lossy().into_owned())
                    .unwrap_or_default(),
            );
        }
    }
    for (_, p) in &parts_pics {
        files.push(
            p.file_name()
                .map(|n| n.to_string_lossy().into_owned())
                .unwrap_or_default(),
        );
    }
    files.extend(["report.md", "report.html", "summary.json"].map(String::from));
    s.files = files;
    let blocks = blocks(&s, a, &pics, &parts_pics);
    doc::write(&out_dir.join("report.md"), &doc::markdown(&blocks))?;
    let title = format!("Bench report: {}", law.name);
    doc::write(&out_dir.join("report.html"), &doc::html(&title, &blocks)?)?;
    let json_path = out_dir.join("summary.json");
    let json = serde_json::to_string_pretty(&s).map_err(|source| AnalysisError::Json {
        path: json_path.clone(),
        source,
    })?;
    doc::write(&json_path, &json)?;
    Ok(s)
}

#[cfg(test)]
mod tests {
    use super::{backlash_with_error, f3, follower_play, held_note};

    /// Guards the sentence the report and `analyze` give the prediction's loss of drive:
    /// every window, in driver degrees to the samples' 0.25° (as `simulate` writes them),
    /// and nothing at all when the parts never lose it.
    #[test]
    fn the_drive_lost_windows_are_named_or_nothing_is_said() {
        assert_eq!(
            super::drive_lost_sentence(&[[290.5, 292.25], [359.75, 0.25]]),
            " The prediction says the parts lose the drive at driver 290.5–292.25°, \
             359.75–0.25°: there the follower is not held."
        );
        assert_eq!(super::drive_lost_sentence(&[]), "");
    }

    /// Guards figures without a negative zero: what rounds to zero prints unsigned, the
    /// rest keeps its sign.
    #[test]
    fn no_negative_zero() {
        assert_eq!(f3(-0.0002), "0.000");
        assert_eq!(f3(-0.0), "0.000");
        assert_eq!(f3(-0.0006), "-0.001");
        assert_eq!(f3(1.23449), "1.234");
    }

    /// Guards the backlash figure: with its standard error when the fit gave one, so a
    /// value near zero is read against its error; alone when it did not.
    #[test]
    fn backlash_carries_its_error() {
        assert_eq!(backlash_with_error(-0.0014, Some(0.0011)), "-0.001 ± 0.001");
        assert_eq!(backlash_with_error(2.0134, Some(0.0042)), "2.013 ± 0.004");
        assert_eq!(backlash_with_error(2.0134, None), "2.013");
        assert_eq!(backlash_with_error(2.0134, Some(f64::NAN)), "2.013");
    }

    /// Guards the follower-side dead band's words: a fitted width reads as such; one the
    /// free fit put below zero reads as none, with the value that was held, in the
    /// sentence and in the table's note.
    #[test]
    fn a_held_dead_band_reads_as_none() {
        assert_eq!(
            follower_play(Some(0.5004), None),
            " and 0.500° of follower (its dead band)"
        );
        assert_eq!(
            follower_play(Some(0.0), Some(-0.0861)),
            " and no follower-side dead band (the free fit's -0.086° held at 0)"
        );
        assert_eq!(follower_play(None, None), "");
        assert_eq!(held_note(None, "mm"), "");
        assert_eq!(
            held_note(Some(-0.0581), "mm"),
            "held at 0: the free fit gave -0.058 mm (a width cannot be negative; the \
             directions' gap is the driver side's)"
        );
    }
}
