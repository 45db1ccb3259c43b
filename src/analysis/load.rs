//! From files to the analysis' inputs: a recording directory plus its rig calibration
//! becomes a [`MeasuredRun`]; a mechanism or motion file becomes a [`TargetLaw`].
//!
//! The recording is stream-parsed row by row through [`crate::rig::recording`]'s reader (no
//! per-row allocation), raw sensor values are converted with the rig's own calibration
//! ([`crate::rig::config::SensorConfig::to_physical`], IMU mounting), rotary encoders are
//! unwrapped as they arrive, and samples whose sensor value the device marked as repeated
//! (stale IMU, failed read) or whose driver angle was held rather than measured at their
//! instant (`DRIVER_HELD`, a mixed bench's bus behind its board) are left out and counted,
//! as are rows the device sampled late (kept). It does not compute any figure.

use std::path::{Path, PathBuf};

use nalgebra::{Quaternion, UnitQuaternion};

use super::run::{unwrap_in_place, MeasuredRun, Phase, Resolution};
use super::target::TargetLaw;
use super::AnalysisError;
use crate::rig::config::{Dof as RigDof, SensorConfig};
use crate::rig::recording::{flags, RecordingMeta, RecordingReader, RowBuf};

/// An IMU quaternion whose norm is further than this from 1 is rejected as garbage rather
/// than normalized: the rig's [`crate::rig::config::IMU_NORM_TOLERANCE`].
pub use crate::rig::config::IMU_NORM_TOLERANCE as QUATERNION_NORM_TOLERANCE;

/// What loading found besides the samples.
#[derive(Debug, Clone)]
pub struct LoadedRecording {
    /// The recording directory.
    pub dir: PathBuf,
    /// The sidecar.
    pub meta: RecordingMeta,
    /// Samples in physical units.
    pub run: MeasuredRun,
    /// Rows read from the CSV.
    pub rows: usize,
    /// Rows left out because the device flagged their follower value as repeated or failed.
    pub stale_rows: usize,
    /// Rows left out because their driver angle was held, not measured at their instant
    /// (flag `DRIVER_HELD`: on a mixed bench the Dynamixel bus fell behind the board).
    pub held_rows: usize,
    /// Rows the device sampled late (flag `LATE`: it missed sampling ticks before them);
    /// kept, since their time stamps are their own.
    pub late_rows: usize,
    /// The CSV ended in a partial line (crash, unplug or Ctrl-C) that was dropped.
    pub truncated_last_line: bool,
    /// Names of the sensors used: (rz, tz, imu).
    pub sensors_used: (Option<String>, Option<String>, Option<String>),
}

fn recording_err(dir: &Path, e: impl std::fmt::Display) -> AnalysisError {
    AnalysisError::Recording {
        path: dir.to_path_buf(),
        message: e.to_string(),
    }
}

/// Load a recording directory into physical units with its own rig calibration.
pub fn load_run(dir: &Path) -> Result<LoadedRecording, AnalysisError> {
    let (meta, mut reader) = RecordingReader::open(dir).map_err(|e| recording_err(dir, e))?;
    let columns: Vec<String> = reader.columns().to_vec();
    let lead = crate::rig::recording::LEADING_COLUMNS.len();
    // A sensor's first column: the sidecar says which columns belong to which sensor (the
    // header names carry units since issue 20: `follower_rz_counts`), in the header's
    // order (the reader checked that the two agree); a sidecar that does not say finds it
    // by the name recordings used before (`follower_rz`, `imu_qw`).
    let col_of = |sensor: &str, legacy: &str| -> Result<usize, AnalysisError> {
        meta.columns
            .iter()
            .position(|c| c.sensor.as_deref() == Some(sensor))
            .or_else(|| columns.iter().position(|c| c == legacy))
            .and_then(|i| i.checked_sub(lead))
            .ok_or_else(|| {
                recording_err(
                    dir,
                    format!("the CSV header has no column for the rig's sensor `{sensor}`"),
                )
            })
    };
    // Pick one sensor per DOF (the first the rig lists).
    let mut rz: Option<(&SensorConfig, usize)> = None;
    let mut tz: Option<(&SensorConfig, usize)> = None;
    let mut imu: Option<(&crate::rig::config::ImuConfig, usize)> = None;
    for s in &meta.rig.sensors {
        match (s, s.dof()) {
            (SensorConfig::Imu(i), _) if imu.is_none() => {
                imu = Some((i, col_of(&i.name, &format!("{}_qw", i.name))?));
            }
            (_, Some(RigDof::Rz)) if rz.is_none() => rz = Some((s, col_of(s.name(), s.name())?)),
            (_, Some(RigDof::Tz)) if tz.is_none() => tz = Some((s, col_of(s.name(), s.name())?)),
            _ => {}
        }
    }
    if rz.is_none() && tz.is_none() && imu.is_none() {
        return Err(recording_err(
            dir,
            format!("rig `{}` has no follower sensor", meta.rig.name),
        ));
    }
    let guess = std::fs::metadata(dir.join(crate::rig::recording::CSV_FILE))
        .map(|m| (m.len() / 40) as usize)
        .unwrap_or(0)
        .min(50_000_000);
    let mut run = MeasuredRun {
        time_s: Vec::with_capacity(guess),
        phase: Vec::with_capacity(guess),
        driver_deg: Vec::with_capacity(guess),
        rz_deg: rz.map(|_| Vec::with_capacity(guess)),
        tz_mm: tz.map(|_| Vec::with_capacity(guess)),
        rotation: imu.map(|_| Vec::with_capacity(guess)),
        ramping: Vec::new(),
        resolution: Resolution {
            rz_deg: rz
                .and_then(|(s, _)| s.counts_per_rev())
                .map_or(0.0, |c| 360.0 / c),
            tz_mm: tz
                .and_then(|(s, _)| match s {
                    SensorConfig::As5600(e) | SensorConfig::Quadrature(e) => e.mm_per_count,
                    _ => None,
                })
                .unwrap_or(0.0),
        },
    };
    let mut row = RowBuf::default();
    let (mut rows, mut stale, mut held, mut late) = (0usize, 0usize, 0usize, 0usize);
    // Incremental unwrap of the rotary encoder.
    let mut rz_prev_raw: Option<f64> = None;
    let mut rz_turns = 0.0;
    let stale_mask = |s: Option<&SensorConfig>| match s {
        Some(SensorConfig::Dynamixel(_)) => flags::FOLLOWER_STALE | flags::SENSOR_ERROR,
        _ => flags::SENSOR_ERROR,
    };
    let rz_mask = stale_mask(rz.map(|r| r.0));
    let imu_mask = flags::IMU_STALE | flags::SENSOR_ERROR;
    while reader
        .next_row(&mut row)
        .map_err(|e| recording_err(dir, e))?
    {
        rows += 1;
        let line = rows + 1;
        let mask = if imu.is_some() { imu_mask } else { rz_mask };
        if row.flags & mask != 0 {
            stale += 1;
            continue;
        }
        if row.flags & flags::DRIVER_HELD != 0 {
            held += 1;
            continue;
        }
        if row.flags & flags::LATE != 0 {
            late += 1;
        }
        let bad = |what: String| AnalysisError::Recording {
            path: dir.join(crate::rig::recording::CSV_FILE),
            message: format!("line {line}: {what}"),
        };
        if let Some((s, c)) = rz {
            let v = s
                .to_physical(row.values[c])
                .filter(|v| v.is_finite())
                .ok_or_else(|| {
                    bad(format!(
                        "sensor `{}`: value {} is not usable",
                        s.name(),
                        row.values[c]
                    ))
                })?;
            if let Some(prev) = rz_prev_raw {
                rz_turns -= 360.0 * ((v - prev) / 360.0).round();
            }
            rz_prev_raw = Some(v);
            run.rz_deg
                .as_mut()
                .expect("allocated with the sensor")
                .push(v + rz_turns);
        }
        if let Some((s, c)) = tz {
            let v = s
                .to_physical(row.values[c])
                .filter(|v| v.is_finite())
                .ok_or_else(|| {
                    bad(format!(
                        "sensor `{}`: value {} is not usable",
                        s.name(),
                        row.values[c]
                    ))
                })?;
            run.tz_mm
                .as_mut()
                .expect("allocated with the sensor")
                .push(v);
        }
        if let Some((i, c)) = imu {
            let q = Quaternion::new(
                row.values[c],
                row.values[c + 1],
                row.values[c + 2],
                row.values[c + 3],
            );
            let norm = q.norm();
            if !norm.is_finite() || (norm - 1.0).abs() > QUATERNION_NORM_TOLERANCE {
                return Err(bad(format!(
                    "IMU `{}`: quaternion norm {norm} is not 1 (±{QUATERNION_NORM_TOLERANCE})",
                    i.name
                )));
            }
            run.rotation
                .as_mut()
                .expect("allocated with the sensor")
                .push(i.follower_rotation(UnitQuaternion::from_quaternion(q)));
        }
        if !row.driver_angle_deg.is_finite() {
            return Err(bad(format!(
                "driver_angle_deg {} is not finite",
                row.driver_angle_deg
            )));
        }
        run.time_s.push(row.device_time_us as f64 * 1e-6);
        run.phase.push(match row.phase {
            Some(crate::rig::recording::Phase::Forward) => Phase::Forward,
            Some(crate::rig::recording::Phase::Reverse) => Phase::Reverse,
            _ => Phase::Settle,
        });
        run.driver_deg.push(row.driver_angle_deg);
    }
    if let Some(v) = &mut run.rz_deg {
        // The incremental unwrap above is exact; this is a no-op guard for stale-row skips.
        unwrap_in_place(v, 360.0);
    }
    let sensors_used = (
        rz.map(|r| r.0.name().to_string()),
        tz.map(|r| r.0.name().to_string()),
        imu.map(|r| r.0.name.clone()),
    );
    Ok(LoadedRecording {
        dir: dir.to_path_buf(),
        truncated_last_line: reader.truncated_last_line(),
        meta,
        run,
        rows,
        stale_rows: stale,
        held_rows: held,
        late_rows: late,
        sensors_used,
    })
}

use crate::motion::DEFAULT_SCALE_MM;

/// Where the target law comes from.
#[derive(Debug, Clone, PartialEq)]
pub enum TargetSource {
    /// A `mechanism.json` (or the directory holding it).
    Mechanism(PathBuf),
    /// A motion file (`.toml` keyframes or `.csv` dense).
    Motion(PathBuf),
}

impl TargetSource {
    /// `mechanism` or `motion`.
    pub fn kind(&self) -> &'static str {
        match self {
            TargetSource::Mechanism(_) => "mechanism",
            TargetSource::Motion(_) => "motion",
        }
    }

    /// The path.
    pub fn path(&self) -> &Path {
        match self {
            TargetSource::Mechanism(p) | TargetSource::Motion(p) => p,
        }
    }
}

/// Load the target law. A mechanism file is validated as `mpc-rig synth --check` does
/// ([`crate::rig::target::load_mechanism`]) before its follower motion is compared with
/// anything, and its own `scale_mm` converts heights.
pub fn load_target(src: &TargetSource) -> Result<TargetLaw, AnalysisError> {
    let err = |e: crate::rig::RigError| AnalysisError::Target {
        path: src.path().to_path_buf(),
        message: match e {
            crate::rig::RigError::Target { message, .. } => message,
            other => other.to_string(),
        },
    };
    match src {
        TargetSource::Mechanism(p) => {
            let (mechanism, motion) = crate::rig::target::load_mechanism(p).map_err(err)?;
            Ok(TargetLaw {
                mechanism_digest: Some(mechanism.digest()),
                ..TargetLaw::from_motion(&motion, mechanism.scale_mm)
            })
        }
        TargetSource::Motion(p) => {
            let motion = crate::rig::target::load_motion(p).map_err(err)?;
            Ok(TargetLaw::from_motion(&motion, DEFAULT_SCALE_MM))
        }
    }
}

/// The target a recording names in its sidecar (relative paths are tried as given, then
/// relative to the recording directory's parents).
pub fn recorded_target(loaded: &LoadedRecording) -> Result<TargetSource, AnalysisError> {
    let t = &loaded.meta.target;
    let mut candidates = vec![t.path.clone()];
    if t.path.is_relative() {
        let mut d = Some(loaded.dir.as_path());
        while let Some(dir) = d {
            candidates.push(dir.join(&t.path));
            d = dir.parent();
        }
    }
    let path =
        candidates
            .into_iter()
            .find(|p| p.exists())
            .ok_or_else(|| AnalysisError::Target {
                path: t.path.clone(),
                message:
                    "the recording's target file does not exist here; pass --mechanism or --motion"
                        .into(),
            })?;
    match t.kind.as_str() {
        "mechanism" => Ok(TargetSource::Mechanism(path)),
        "motion" => Ok(TargetSource::Motion(path)),
        other => Err(AnalysisError::Target {
            path,
            message: format!("unknown target kind `{other}` in the sidecar (mechanism or motion)"),
        }),
    }
}

/// Analyse a recording directory and write its report into `<recording_dir>/report/` (or
/// `opts.out_dir`). The target is the one the sidecar names unless `opts` overrides it.
pub fn analyze_and_report(
    recording_dir: &Path,
    opts: &super::ReportOptions,
) -> Result<super::Summary, AnalysisError> {
    let loaded = load_run(recording_dir)?;
    let src = match (&opts.mechanism, &opts.motion) {
        (Some(_), Some(_)) => {
            return Err(AnalysisError::BadOption {
                option: "--mechanism/--motion".into(),
                message: "give one target, not both".into(),
            })
        }
        (Some(m), None) => TargetSource::Mechanism(m.clone()),
        (None, Some(m)) => TargetSource::Motion(m.clone()),
        (None, None) => recorded_target(&loaded)?,
    };
    let law = load_target(&src)?;
    if loaded.truncated_last_line {
        tracing::warn!(
            "{}: the last CSV line was cut off (crash or unplug) and was dropped",
            recording_dir.display()
        );
    }
    let analysis = super::analyze(
        &loaded.run,
        &law,
        &super::AnalysisOptions {
            timing_levels: opts.timing_levels.clone(),
        },
    )?;
    let out_dir = opts
        .out_dir
        .clone()
        .unwrap_or_else(|| recording_dir.join("report"));
    let source = super::report::SourceInfo {
        recording_dir: recording_dir.to_path_buf(),
        complete: Some(loaded.meta.complete),
        end_reason: loaded.meta.end_reason.clone(),
        rows: loaded.rows,
        stale_rows: loaded.stale_rows,
        held_rows: loaded.held_rows,
        late_rows: loaded.late_rows,
        truncated_last_line: loaded.truncated_last_line,
        degraded: loaded.meta.degraded.clone(),
        device_counts: serde_json::to_value(loaded.meta.counts).unwrap_or_default(),
        target_kind: src.kind().into(),
        target_path: src.path().to_path_buf(),
    };
    super::report::write_report(&out_dir, &analysis, &loaded.run, &law, source, opts)
}
