//! The recording a measurement session leaves behind, and its reader.
//!
//! A recording is a directory holding `recording.csv` (one row per device sample, written
//! incrementally and flushed at least every [`FLUSH_INTERVAL`]) and `recording.json` (the
//! [`RecordingMeta`] sidecar: rig, device, target, session, counts, columns). The sidecar is
//! written with `"complete": false` when the recording starts, refreshed at every flush (so
//! a crash leaves counts no older than a flush), and rewritten at the end.
//!
//! CSV columns: `device_time_us, host_time_s, phase, driver_angle_deg`, then one column per
//! sensor channel of the rig ([`crate::rig::config::SensorConfig::columns`]; each header
//! ends in its unit, `follower_rz_counts`, except dimensionless ones, `imu_qw`), then
//! `flags` (bits in [`flags`]). The sidecar's `columns` give each column's unit and sensor. A crash, unplug or Ctrl-C leaves a CSV whose last line may be cut
//! short: [`RecordingReader`] drops such a line and reports it
//! ([`Recording::truncated_last_line`]).
//!
//! The sidecar is true to what is on disk: `counts.samples`, `gaps` and `missing_samples`
//! are counted by the writer from the rows it has written ([`missing_before`] at the
//! session's nominal rate, the same for every backend), and [`CsvFingerprint`] (`csv`) holds
//! the length and SHA-256 of the CSV it describes, which the reader checks. While a session
//! records, the folder holds `recording.lock` (locked, with a disk-space reserve; removed at
//! the end). A finished run whose data cannot support every figure carries `degraded`.
//!
//! This module owns the format only. It does not decide what goes into a row (the session
//! does) and does not interpret sensor values (analysis does, with the rig calibration).

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::time::{Duration, SystemTime, UNIX_EPOCH};

use serde::{Deserialize, Serialize};

use crate::rig::config::{ColumnSpec, RigConfig};

mod reader;
mod writer;

pub use reader::{Recording, RecordingReader, RowBuf};
pub use writer::{Claim, Existing, RecordingWriter, Row, DISK_RESERVE_BYTES, LOCK_FILE};

/// The `format` field of every sidecar this version writes.
pub const RECORDING_FORMAT: &str = "mpcrig-recording/1";
/// CSV file name inside a recording directory.
pub const CSV_FILE: &str = "recording.csv";
/// Sidecar file name inside a recording directory.
pub const SIDECAR_FILE: &str = "recording.json";
/// Longest time rows stay in the write buffer: 0.5 s, half the one second the format
/// promises, so a crash loses at most half a second of samples.
pub const FLUSH_INTERVAL: Duration = Duration::from_millis(500);
/// The fixed leading columns.
pub const LEADING_COLUMNS: [&str; 4] =
    ["device_time_us", "host_time_s", "phase", "driver_angle_deg"];
/// The trailing column.
pub const FLAGS_COLUMN: &str = "flags";

/// Bits of the `flags` column.
pub mod flags {
    /// The IMU value is repeated from an earlier sample (the IMU runs slower than sampling).
    pub const IMU_STALE: u32 = 1 << 0;
    /// One or more samples were lost on the link just before this one.
    pub const GAP_BEFORE: u32 = 1 << 1;
    /// A sensor read failed on the device; its value is repeated from the previous sample.
    pub const SENSOR_ERROR: u32 = 1 << 2;
    /// First sample after the link was re-established.
    pub const RECONNECTED: u32 = 1 << 3;
    /// The device reports its emergency stop latched.
    pub const ESTOP: u32 = 1 << 4;
    /// The device took this sample late (it missed at least one sampling tick before it).
    pub const LATE: u32 = 1 << 5;
    /// The Dynamixel follower read failed; the value is repeated.
    pub const FOLLOWER_STALE: u32 = 1 << 6;
    /// Mixed bench: no two bus samples close in time bracket this row, so its driver angle
    /// (and any follower servo values) are the nearest bus sample's, not interpolated.
    pub const DRIVER_HELD: u32 = 1 << 7;
    /// The driver reports a hardware fault at this sample: a Dynamixel driver's alert bit
    /// (a latched Hardware Error Status such as an overload), our firmware's emergency stop
    /// on the board that turns the driver. The session stops on it.
    pub const DRIVER_FAULT: u32 = 1 << 8;
}

/// Part of the run a sample belongs to.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Phase {
    /// Settle cycle(s) before the measured ones.
    Settle,
    /// Measured cycles, driver turning in the positive direction.
    Forward,
    /// Measured cycles, driver turning backwards.
    Reverse,
}

impl Phase {
    /// The CSV spelling.
    pub fn as_str(self) -> &'static str {
        match self {
            Phase::Settle => "settle",
            Phase::Forward => "forward",
            Phase::Reverse => "reverse",
        }
    }

    fn parse(s: &str) -> Option<Phase> {
        match s {
            "settle" => Some(Phase::Settle),
            "forward" => Some(Phase::Forward),
            "reverse" => Some(Phase::Reverse),
            _ => None,
        }
    }
}

/// Error while writing or reading a recording.
#[derive(Debug, thiserror::Error)]
pub enum RecordingError {
    /// File system error.
    #[error("{path}: {source}")]
    Io {
        /// The file or directory.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// The sidecar is not valid JSON of the expected shape.
    #[error("{path}: invalid sidecar: {source}")]
    Sidecar {
        /// The sidecar file.
        path: PathBuf,
        /// The JSON error.
        source: serde_json::Error,
    },
    /// The sidecar announces a format this reader does not know.
    #[error("{path}: format `{found}` is not {RECORDING_FORMAT}")]
    UnknownFormat {
        /// The sidecar file.
        path: PathBuf,
        /// The format found.
        found: String,
    },
    /// A CSV line is malformed.
    #[error("{path}:{line}: column `{column}`: {message}")]
    Csv {
        /// The CSV file.
        path: PathBuf,
        /// 1-based line.
        line: usize,
        /// The column (or `-` for the whole line).
        column: String,
        /// What is wrong.
        message: String,
    },
    /// The file system is full (or the user's quota is used up): the rows written before
    /// are on disk, the sidecar says how many.
    #[error("{path}: disk full")]
    DiskFull {
        /// The file being written.
        path: PathBuf,
    },
    /// Another session holds the recording folder's lock.
    #[error("{dir}: another session is recording into this folder")]
    Locked {
        /// The recording folder.
        dir: PathBuf,
    },
    /// The folder already holds a recording.
    #[error("{dir} already holds a recording; choose another folder, or replace it explicitly (measure --replace)")]
    Exists {
        /// The recording folder.
        dir: PathBuf,
    },
    /// The CSV is not the one the sidecar describes.
    #[error("{dir}: {CSV_FILE} does not belong to {SIDECAR_FILE}: {message}")]
    Mismatch {
        /// The recording folder.
        dir: PathBuf,
        /// What differs.
        message: String,
    },
    /// A row pushed to the writer has the wrong number of sensor values.
    #[error("row has {got} sensor values, the recording has {expected} sensor columns")]
    RowWidth {
        /// Sensor columns of the recording.
        expected: usize,
        /// Values given.
        got: usize,
    },
}

/// An I/O error on `path`; a full file system (or quota) is [`RecordingError::DiskFull`].
fn io_err(path: &Path) -> impl FnOnce(std::io::Error) -> RecordingError + '_ {
    move |source| {
        if matches!(
            source.kind(),
            std::io::ErrorKind::StorageFull | std::io::ErrorKind::QuotaExceeded
        ) {
            RecordingError::DiskFull {
                path: path.to_path_buf(),
            }
        } else {
            RecordingError::Io {
                path: path.to_path_buf(),
                source,
            }
        }
    }
}

/// What the session measured against.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TargetRef {
    /// "mechanism" or "motion".
    pub kind: String,
    /// Path as given by the user.
    pub path: PathBuf,
    /// SHA-256 of the file read (hex).
    pub sha256: String,
    /// Motion class ("1R", "1R1T", "3R").
    pub class: String,
    /// Motion name.
    pub name: String,
}

/// Session parameters.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SessionInfo {
    /// Commanded driver speed, rpm.
    pub speed_rpm: f64,
    /// Measured cycles (driver revolutions) per direction.
    pub cycles: u32,
    /// Settle cycles before the measured ones.
    pub settle_cycles: u32,
    /// Whether reverse cycles follow the forward ones.
    pub reverse: bool,
    /// Requested sample rate, Hz.
    pub sample_rate_hz: f64,
}

/// Sample and link counts.
///
/// `samples`, `gaps` and `missing_samples` describe the CSV as it is on disk (the writer
/// counts them from the rows it has written, [`missing_before`]), for every backend; the
/// others are the backend's view of its link.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Counts {
    /// Rows in the CSV.
    pub samples: u64,
    /// Holes in the CSV's device time: steps longer than [`GAP_FACTOR`] sample periods.
    pub gaps: u64,
    /// Samples missing in those holes: round(step / period) − 1 each.
    pub missing_samples: u64,
    /// Frames rejected for a bad CRC.
    pub crc_errors: u64,
    /// Times the link was re-established.
    pub reconnects: u64,
    /// Bytes or frames that could not be decoded for other reasons.
    #[serde(default)]
    pub decode_errors: u64,
    /// Losses the backend saw on its link (frame sequence gaps, failed bus transactions).
    /// Not the same as `gaps`: a mixed bench bridges a bus gap by interpolation (no hole),
    /// and a sample never taken (a late bus) is a hole but no link loss. Absent (0) in
    /// recordings made before it was added.
    #[serde(default)]
    pub link_gaps: u64,
    /// Samples the backend counted lost on its link.
    #[serde(default)]
    pub link_missing_samples: u64,
}

/// A step between consecutive rows' device times longer than this many sample periods is
/// a hole (a gap) in the recording. Default 1.5: one lost sample doubles the step, while
/// the jitter of a device clock read over USB or a 1 ms servo tick stays well below half a
/// period.
pub const GAP_FACTOR: f64 = 1.5;

/// Samples missing between two rows `dt_us` apart at the nominal period `period_us`: 0 for
/// a step up to [`GAP_FACTOR`] periods, else round(step / period) − 1. The one rule the
/// writer's counts and the analysis' gap figures share.
pub fn missing_before(dt_us: u64, period_us: f64) -> u64 {
    let dt = dt_us as f64;
    if period_us.is_nan() || period_us <= 0.0 || dt <= GAP_FACTOR * period_us {
        0
    } else {
        ((dt / period_us).round() as u64).saturating_sub(1)
    }
}

/// What the sidecar knew of the CSV when it was written: its first `bytes` bytes (always
/// whole rows) and their SHA-256. The reader checks a CSV against it, so a sidecar is never
/// read with another run's CSV.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct CsvFingerprint {
    /// Bytes of the CSV (header and whole rows) on disk when the sidecar was written.
    pub bytes: u64,
    /// SHA-256 of those bytes, hex.
    pub sha256: String,
}

/// Identity of the device(s) measured with.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct DeviceInfo {
    /// Backend ("stepper-firmware", "dynamixel").
    pub backend: String,
    /// Port path(s) used.
    #[serde(default)]
    pub ports: Vec<String>,
    /// Firmware version string, when the device reports one.
    #[serde(default)]
    pub firmware_version: Option<String>,
    /// Wire protocol version, when the device reports one.
    #[serde(default)]
    pub protocol_version: Option<u32>,
    /// Board or model name.
    #[serde(default)]
    pub board: Option<String>,
    /// Device clock rate, Hz.
    #[serde(default)]
    pub clock_hz: Option<u64>,
    /// Anything else a backend wants to record.
    #[serde(flatten)]
    pub extra: BTreeMap<String, serde_json::Value>,
}

/// The sidecar `recording.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RecordingMeta {
    /// Always [`RECORDING_FORMAT`].
    pub format: String,
    /// True only when the session ended as planned.
    pub complete: bool,
    /// Why the recording ended ("finished", "cancelled", "disconnected: ...", ...).
    #[serde(default)]
    pub end_reason: Option<String>,
    /// UTC start time, RFC 3339.
    pub started_at: String,
    /// UTC end time, RFC 3339.
    #[serde(default)]
    pub finished_at: Option<String>,
    /// The rig configuration as loaded (with calibrations).
    pub rig: RigConfig,
    /// The device(s).
    pub device: DeviceInfo,
    /// What the run is measured against.
    pub target: TargetRef,
    /// Session parameters.
    pub session: SessionInfo,
    /// Counts.
    pub counts: Counts,
    /// Every CSV column in order, with unit and sensor.
    pub columns: Vec<ColumnSpec>,
    /// The CSV this sidecar belongs to (absent in recordings made before it was added).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub csv: Option<CsvFingerprint>,
    /// Set when the session ran to the end but the data cannot support every figure (e.g.
    /// most samples missing): why. Absent when the data is sound.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub degraded: Option<String>,
    /// Set when the session stopped the motor because the driver or the mechanism did not
    /// do what it should (a driver fault or stall, a jammed follower): where and why.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub safety_stop: Option<SafetyStop>,
}

/// Why and where the session stopped the motor on its own.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SafetyStop {
    /// `driver fault`, `driver stall` or `jam`.
    pub kind: String,
    /// Device time of the first sample of the problem (the fault reported, the start of
    /// the window in which the driver did not advance, the first row beyond the follower
    /// limit), µs.
    pub onset_device_time_us: u64,
    /// Device time of the sample that decided the stop, µs.
    pub detected_device_time_us: u64,
    /// Driver angle at the onset, deg.
    pub driver_angle_deg: f64,
    /// What was seen, in words.
    pub detail: String,
}

impl RecordingMeta {
    /// A fresh, incomplete sidecar; `columns` is filled from the rig's sensors.
    pub fn new(
        rig: RigConfig,
        device: DeviceInfo,
        target: TargetRef,
        session: SessionInfo,
    ) -> RecordingMeta {
        let columns = all_columns(&rig);
        RecordingMeta {
            format: RECORDING_FORMAT.into(),
            complete: false,
            end_reason: None,
            started_at: utc_rfc3339(SystemTime::now()),
            finished_at: None,
            rig,
            device,
            target,
            session,
            counts: Counts::default(),
            columns,
            csv: None,
            degraded: None,
            safety_stop: None,
        }
    }

    /// Number of sensor columns (between `driver_angle_deg` and `flags`).
    pub fn sensor_column_count(&self) -> usize {
        self.columns.len().saturating_sub(LEADING_COLUMNS.len() + 1)
    }
}

/// All CSV columns of a rig, in order.
pub fn all_columns(rig: &RigConfig) -> Vec<ColumnSpec> {
    let fixed = |name: &str, unit: &str| ColumnSpec {
        name: name.into(),
        unit: unit.into(),
        sensor: None,
    };
    let mut cols = vec![
        fixed("device_time_us", "us"),
        fixed("host_time_s", "s"),
        fixed("phase", "-"),
        fixed("driver_angle_deg", "deg"),
    ];
    cols.extend(rig.sensor_columns());
    cols.push(fixed(FLAGS_COLUMN, "bits"));
    cols
}

/// Read the sidecar of a recording directory.
pub fn load_meta(dir: &Path) -> Result<RecordingMeta, RecordingError> {
    let path = dir.join(SIDECAR_FILE);
    let text = std::fs::read(&path).map_err(io_err(&path))?;
    #[derive(Deserialize)]
    struct Probe {
        format: String,
    }
    let probe: Probe = serde_json::from_slice(&text).map_err(|source| RecordingError::Sidecar {
        path: path.clone(),
        source,
    })?;
    if probe.format != RECORDING_FORMAT {
        return Err(RecordingError::UnknownFormat {
            path,
            found: probe.format,
        });
    }
    serde_json::from_slice(&text).map_err(|source| RecordingError::Sidecar { path, source })
}

/// UTC time as RFC 3339 with milliseconds, e.g. `2026-11-22T05:59:01.123Z`.
pub fn utc_rfc3339(t: SystemTime) -> String {
    let (date, hms, ms) = civil(t);
    format!("{date}T{hms}.{ms:03}Z")
}

/// UTC time as a directory name, e.g. `20261122T055901Z`.
pub fn utc_dir_stamp(t: SystemTime) -> String {
    let (date, hms, _) = civil(t);
    format!("{}T{}Z", date.replace('-', ""), hms.replace(':', ""))
}

/// (YYYY-MM-DD, HH:MM:SS, milliseconds) in UTC, by the days-from-civil inverse
/// (proleptic Gregorian calendar).
fn civil(t: SystemTime) -> (String, String, u32) {
    let d = t.duration_since(UNIX_EPOCH).unwrap_or_default();
    let secs = d.as_secs() as i64;
    let days = secs.div_euclid(86_400);
    let sod = secs.rem_euclid(86_400);
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let day = doy - (153 * mp + 2) / 5 + 1;
    let month = if mp < 10 { mp + 3 } else { mp - 9 };
    let year = yoe + era * 400 + i64::from(month <= 2);
    (
        format!("{year:04}-{month:02}-{day:02}"),
        format!("{:02}:{:02}:{:02}", sod / 3600, sod / 60 % 60, sod % 60),
        d.subsec_millis(),
    )
}

#[cfg(test)]
mod tests;
