//! The recording a measurement session leaves behind, and its reader.
//!
//! A recording is a directory holding `recording.csv` (one row per device sample, written
//! incrementally and flushed at least every [`FLUSH_INTERVAL`]) and `recording.json` (the
//! [`RecordingMeta`] sidecar: rig, device, target, session, counts, columns). The sidecar is
//! written with `"complete": false` when the recording starts, refreshed at every flush (so
//! a crash leaves counts no older than a flush), and rewritten at the end.
//!
//! CSV columns: `device_time_us, host_time_s, phase, driver_angle_deg`, then one column per
//! sensor channel of the rig ([`crate::rig::config::SensorConfig::columns`]), then `flags`
//! (bits in [`flags`]). A crash, unplug or Ctrl-C leaves a CSV whose last line may be cut
//! short: [`RecordingReader`] drops such a line and reports it
//! ([`Recording::truncated_last_line`]).
//!
//! This module owns the format only. It does not decide what goes into a row (the session
//! does) and does not interpret sensor values (analysis does, with the rig calibration).

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::fs::File;
use std::io::{BufRead, BufReader, BufWriter, Write};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use serde::{Deserialize, Serialize};

use crate::rig::config::{ColumnSpec, RigConfig};

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
    /// A row pushed to the writer has the wrong number of sensor values.
    #[error("row has {got} sensor values, the recording has {expected} sensor columns")]
    RowWidth {
        /// Sensor columns of the recording.
        expected: usize,
        /// Values given.
        got: usize,
    },
}

fn io_err(path: &Path) -> impl FnOnce(std::io::Error) -> RecordingError + '_ {
    move |source| RecordingError::Io {
        path: path.to_path_buf(),
        source,
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

/// Link and sample counts.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Counts {
    /// Rows written.
    pub samples: u64,
    /// Sequence gaps seen (each may cover several samples).
    pub gaps: u64,
    /// Samples lost in gaps.
    pub missing_samples: u64,
    /// Frames rejected for a bad CRC.
    pub crc_errors: u64,
    /// Times the link was re-established.
    pub reconnects: u64,
    /// Bytes or frames that could not be decoded for other reasons.
    #[serde(default)]
    pub decode_errors: u64,
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

/// One CSV row to write.
#[derive(Debug, Clone, Copy)]
pub struct Row<'a> {
    /// Device clock, unwrapped, µs since stream start.
    pub device_time_us: u64,
    /// Host clock, s since session start.
    pub host_time_s: f64,
    /// Phase.
    pub phase: Phase,
    /// Driver angle, deg, unwrapped, 0 at home.
    pub driver_angle_deg: f64,
    /// One value per sensor column.
    pub values: &'a [f64],
    /// [`flags`] bits.
    pub flags: u32,
}

/// Writes a recording incrementally.
pub struct RecordingWriter {
    dir: PathBuf,
    csv_path: PathBuf,
    csv: BufWriter<File>,
    meta: RecordingMeta,
    line: String,
    last_flush: Instant,
    finished: bool,
}

impl RecordingWriter {
    /// Create the directory (and parents), write the CSV header and an incomplete sidecar.
    pub fn create(dir: &Path, meta: RecordingMeta) -> Result<RecordingWriter, RecordingError> {
        std::fs::create_dir_all(dir).map_err(io_err(dir))?;
        let csv_path = dir.join(CSV_FILE);
        let file = File::create(&csv_path).map_err(io_err(&csv_path))?;
        let mut csv = BufWriter::with_capacity(1 << 16, file);
        let header: Vec<&str> = meta.columns.iter().map(|c| c.name.as_str()).collect();
        writeln!(csv, "{}", header.join(",")).map_err(io_err(&csv_path))?;
        csv.flush().map_err(io_err(&csv_path))?;
        let w = RecordingWriter {
            dir: dir.to_path_buf(),
            csv_path,
            csv,
            meta,
            line: String::with_capacity(256),
            last_flush: Instant::now(),
            finished: false,
        };
        w.write_sidecar()?;
        Ok(w)
    }

    /// The recording directory.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// The sidecar as it stands.
    pub fn meta(&self) -> &RecordingMeta {
        &self.meta
    }

    /// Mutable access to the sidecar (device info, counts); written at the next flush.
    pub fn meta_mut(&mut self) -> &mut RecordingMeta {
        &mut self.meta
    }

    /// Append one row; flushes when [`FLUSH_INTERVAL`] has passed since the last flush.
    pub fn push(&mut self, row: &Row<'_>) -> Result<(), RecordingError> {
        let expected = self.meta.sensor_column_count();
        if row.values.len() != expected {
            return Err(RecordingError::RowWidth {
                expected,
                got: row.values.len(),
            });
        }
        self.line.clear();
        // Writing to a String cannot fail.
        let _ = write!(
            self.line,
            "{},{:.6},{},{}",
            row.device_time_us,
            row.host_time_s,
            row.phase.as_str(),
            row.driver_angle_deg
        );
        for v in row.values {
            let _ = write!(self.line, ",{v}");
        }
        let _ = writeln!(self.line, ",{}", row.flags);
        self.csv
            .write_all(self.line.as_bytes())
            .map_err(io_err(&self.csv_path))?;
        self.meta.counts.samples += 1;
        if self.last_flush.elapsed() >= FLUSH_INTERVAL {
            self.flush()?;
        }
        Ok(())
    }

    /// Flush the CSV to the OS and refresh the sidecar (still incomplete).
    pub fn flush(&mut self) -> Result<(), RecordingError> {
        self.csv.flush().map_err(io_err(&self.csv_path))?;
        self.last_flush = Instant::now();
        self.write_sidecar()
    }

    /// Whether a flush is due (for callers that push rarely).
    pub fn flush_due(&self) -> bool {
        self.last_flush.elapsed() >= FLUSH_INTERVAL
    }

    /// End the recording: flush, fsync, and write the final sidecar.
    pub fn finish(
        mut self,
        complete: bool,
        end_reason: &str,
    ) -> Result<RecordingMeta, RecordingError> {
        self.csv.flush().map_err(io_err(&self.csv_path))?;
        self.csv
            .get_ref()
            .sync_all()
            .map_err(io_err(&self.csv_path))?;
        self.meta.complete = complete;
        self.meta.end_reason = Some(end_reason.to_string());
        self.meta.finished_at = Some(utc_rfc3339(SystemTime::now()));
        self.write_sidecar()?;
        self.finished = true;
        Ok(self.meta.clone())
    }

    fn write_sidecar(&self) -> Result<(), RecordingError> {
        let path = self.dir.join(SIDECAR_FILE);
        let tmp = self.dir.join(format!("{SIDECAR_FILE}.tmp"));
        let json =
            serde_json::to_vec_pretty(&self.meta).map_err(|source| RecordingError::Sidecar {
                path: path.clone(),
                source,
            })?;
        std::fs::write(&tmp, json).map_err(io_err(&tmp))?;
        std::fs::rename(&tmp, &path).map_err(io_err(&path))
    }
}

impl Drop for RecordingWriter {
    fn drop(&mut self) {
        if !self.finished {
            // Best effort: keep what we have; the sidecar stays `complete: false`.
            let _ = self.csv.flush();
            if self.meta.end_reason.is_none() {
                self.meta.end_reason = Some("aborted: writer dropped before finish".into());
            }
            let _ = self.write_sidecar();
        }
    }
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

/// One parsed CSV row, reused between calls to [`RecordingReader::next_row`].
#[derive(Debug, Clone, Default, PartialEq)]
pub struct RowBuf {
    /// Device clock, µs.
    pub device_time_us: u64,
    /// Host clock, s.
    pub host_time_s: f64,
    /// Phase (`None` only before the first row).
    pub phase: Option<Phase>,
    /// Driver angle, deg.
    pub driver_angle_deg: f64,
    /// Sensor values in column order.
    pub values: Vec<f64>,
    /// Flags.
    pub flags: u32,
}

/// Streams rows of a recording without per-row allocation.
pub struct RecordingReader {
    path: PathBuf,
    reader: BufReader<File>,
    buf: Vec<u8>,
    line: usize,
    columns: Vec<String>,
    sensor_columns: usize,
    truncated: bool,
}

impl RecordingReader {
    /// Open `dir/recording.csv` and check its header against the sidecar.
    pub fn open(dir: &Path) -> Result<(RecordingMeta, RecordingReader), RecordingError> {
        let meta = load_meta(dir)?;
        let path = dir.join(CSV_FILE);
        let file = File::open(&path).map_err(io_err(&path))?;
        let mut reader = BufReader::with_capacity(1 << 20, file);
        let mut header = String::new();
        reader.read_line(&mut header).map_err(io_err(&path))?;
        let columns: Vec<String> = header.trim_end().split(',').map(str::to_string).collect();
        let expected: Vec<&str> = meta.columns.iter().map(|c| c.name.as_str()).collect();
        if columns != expected {
            return Err(RecordingError::Csv {
                path,
                line: 1,
                column: "-".into(),
                message: format!(
                    "header `{}` does not match the sidecar's columns `{}`",
                    columns.join(","),
                    expected.join(",")
                ),
            });
        }
        let sensor_columns = meta.sensor_column_count();
        Ok((
            meta,
            RecordingReader {
                path,
                reader,
                buf: Vec::with_capacity(256),
                line: 1,
                columns,
                sensor_columns,
                truncated: false,
            },
        ))
    }

    /// Column names from the header.
    pub fn columns(&self) -> &[String] {
        &self.columns
    }

    /// Whether the file ended in a partial line (dropped).
    pub fn truncated_last_line(&self) -> bool {
        self.truncated
    }

    /// Read the next row into `row`; `Ok(false)` at the end of the file.
    pub fn next_row(&mut self, row: &mut RowBuf) -> Result<bool, RecordingError> {
        loop {
            self.buf.clear();
            let n = self
                .reader
                .read_until(b'\n', &mut self.buf)
                .map_err(io_err(&self.path))?;
            if n == 0 {
                return Ok(false);
            }
            self.line += 1;
            if self.buf.last() != Some(&b'\n') {
                // Cut short by a crash or unplug: drop it and say so.
                self.truncated = true;
                return Ok(false);
            }
            self.buf.pop();
            if self.buf.last() == Some(&b'\r') {
                self.buf.pop();
            }
            if self.buf.is_empty() {
                continue;
            }
            self.parse_line(row)?;
            return Ok(true);
        }
    }

    fn parse_line(&self, row: &mut RowBuf) -> Result<(), RecordingError> {
        let err = |column: &str, message: String| RecordingError::Csv {
            path: self.path.clone(),
            line: self.line,
            column: column.to_string(),
            message,
        };
        let text = std::str::from_utf8(&self.buf).map_err(|_| err("-", "not UTF-8".into()))?;
        let mut fields = text.split(',');
        let mut next = |col: usize| {
            fields.next().ok_or_else(|| {
                err(
                    &self.columns[col],
                    format!(
                        "missing (row has fewer than {} columns)",
                        self.columns.len()
                    ),
                )
            })
        };
        let num = |col: usize, s: &str| -> Result<f64, RecordingError> {
            s.parse::<f64>()
                .map_err(|_| err(&self.columns[col], format!("`{s}` is not a number")))
        };
        let f = next(0)?;
        row.device_time_us = f.parse().map_err(|_| {
            err(
                "device_time_us",
                format!("`{f}` is not an unsigned integer"),
            )
        })?;
        let f = next(1)?;
        row.host_time_s = num(1, f)?;
        let f = next(2)?;
        row.phase = Some(
            Phase::parse(f)
                .ok_or_else(|| err("phase", format!("`{f}` is not settle, forward or reverse")))?,
        );
        let f = next(3)?;
        row.driver_angle_deg = num(3, f)?;
        row.values.clear();
        for i in 0..self.sensor_columns {
            let col = LEADING_COLUMNS.len() + i;
            let f = next(col)?;
            row.values.push(num(col, f)?);
        }
        let col = self.columns.len() - 1;
        let f = next(col)?;
        row.flags = f
            .parse()
            .map_err(|_| err(FLAGS_COLUMN, format!("`{f}` is not an unsigned integer")))?;
        if fields.next().is_some() {
            return Err(err(
                "-",
                format!("more than {} columns", self.columns.len()),
            ));
        }
        Ok(())
    }
}

/// A whole recording in memory, column by column.
#[derive(Debug, Clone)]
pub struct Recording {
    /// The directory it was loaded from.
    pub dir: PathBuf,
    /// The sidecar.
    pub meta: RecordingMeta,
    /// Column names from the CSV header.
    pub columns: Vec<String>,
    /// Device clock, µs.
    pub device_time_us: Vec<u64>,
    /// Host clock, s.
    pub host_time_s: Vec<f64>,
    /// Phase per row.
    pub phase: Vec<Phase>,
    /// Driver angle, deg.
    pub driver_angle_deg: Vec<f64>,
    /// One vector per sensor column, in header order.
    pub sensors: Vec<Vec<f64>>,
    /// Flags per row.
    pub flags: Vec<u32>,
    /// The CSV ended in a partial line that was dropped (crash or unplug).
    pub truncated_last_line: bool,
}

impl Recording {
    /// Load a recording directory (sidecar and all rows).
    pub fn load(dir: &Path) -> Result<Recording, RecordingError> {
        let (meta, mut reader) = RecordingReader::open(dir)?;
        // Preallocate from the file size (~ 40 bytes per row at least).
        let guess = std::fs::metadata(dir.join(CSV_FILE))
            .map(|m| (m.len() / 48) as usize)
            .unwrap_or(0);
        let ns = meta.sensor_column_count();
        let mut rec = Recording {
            dir: dir.to_path_buf(),
            columns: reader.columns().to_vec(),
            device_time_us: Vec::with_capacity(guess),
            host_time_s: Vec::with_capacity(guess),
            phase: Vec::with_capacity(guess),
            driver_angle_deg: Vec::with_capacity(guess),
            sensors: (0..ns).map(|_| Vec::with_capacity(guess)).collect(),
            flags: Vec::with_capacity(guess),
            truncated_last_line: false,
            meta,
        };
        let mut row = RowBuf::default();
        while reader.next_row(&mut row)? {
            rec.device_time_us.push(row.device_time_us);
            rec.host_time_s.push(row.host_time_s);
            rec.phase.push(row.phase.unwrap_or(Phase::Settle));
            rec.driver_angle_deg.push(row.driver_angle_deg);
            for (col, v) in rec.sensors.iter_mut().zip(&row.values) {
                col.push(*v);
            }
            rec.flags.push(row.flags);
        }
        rec.truncated_last_line = reader.truncated_last_line();
        Ok(rec)
    }

    /// Number of rows.
    pub fn len(&self) -> usize {
        self.device_time_us.len()
    }

    /// Whether there are no rows.
    pub fn is_empty(&self) -> bool {
        self.device_time_us.is_empty()
    }

    /// The values of a sensor column by name.
    pub fn sensor(&self, column: &str) -> Option<&[f64]> {
        let i = self
            .columns
            .iter()
            .position(|c| c == column)?
            .checked_sub(LEADING_COLUMNS.len())?;
        self.sensors.get(i).map(Vec::as_slice)
    }
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
mod tests {
    use super::*;
    use crate::rig::config::RigConfig;

    pub(crate) fn test_rig() -> RigConfig {
        RigConfig::from_toml_str(
            r#"
name = "t"
[[ports]]
name = "fw"
[driver]
kind = "stepper-firmware"
port = "fw"
steps_per_rev = 200
microsteps = 16
max_speed_rpm = 60
max_accel = 720
[[sensors]]
kind = "as5600"
name = "enc"
dof = "rz"
[[sensors]]
kind = "imu"
name = "imu"
"#,
            Path::new("t.toml"),
        )
        .unwrap()
    }

    fn meta() -> RecordingMeta {
        RecordingMeta::new(
            test_rig(),
            DeviceInfo {
                backend: "test".into(),
                ..Default::default()
            },
            TargetRef {
                kind: "motion".into(),
                path: "m.toml".into(),
                sha256: "00".into(),
                class: "1R".into(),
                name: "m".into(),
            },
            SessionInfo {
                speed_rpm: 10.0,
                cycles: 2,
                settle_cycles: 1,
                reverse: false,
                sample_rate_hz: 1000.0,
            },
        )
    }

    fn write_rows(dir: &Path, n: u64) -> RecordingWriter {
        let mut w = RecordingWriter::create(dir, meta()).unwrap();
        for i in 0..n {
            let values = [i as f64 % 4096.0, 1.0, 0.0, 0.0, 0.0];
            w.push(&Row {
                device_time_us: i * 1000,
                host_time_s: i as f64 * 1e-3,
                phase: if i < 3 { Phase::Settle } else { Phase::Forward },
                driver_angle_deg: i as f64 * 0.1,
                values: &values,
                flags: (i % 2) as u32 * flags::IMU_STALE,
            })
            .unwrap();
        }
        w
    }

    /// Guards: what the writer writes, the reader reads back exactly, with a complete sidecar.
    #[test]
    fn write_then_load_round_trip() {
        let dir = tempfile::tempdir().unwrap();
        let w = write_rows(dir.path(), 10);
        let meta = w.finish(true, "finished").unwrap();
        assert_eq!(meta.counts.samples, 10);
        let rec = Recording::load(dir.path()).unwrap();
        assert!(rec.meta.complete);
        assert_eq!(rec.len(), 10);
        assert!(!rec.truncated_last_line);
        assert_eq!(rec.phase[2], Phase::Settle);
        assert_eq!(rec.phase[3], Phase::Forward);
        assert_eq!(rec.driver_angle_deg[7], 7.0 * 0.1);
        assert_eq!(rec.sensor("enc").unwrap()[9], 9.0);
        assert_eq!(rec.sensor("imu_qw").unwrap()[9], 1.0);
        assert_eq!(rec.flags[1], flags::IMU_STALE);
        assert_eq!(rec.meta.columns.len(), 4 + 5 + 1);
    }

    /// Guards: a writer dropped without `finish` (crash path) leaves an analyzable recording
    /// marked incomplete; a cut-off last line is dropped and reported.
    #[test]
    fn crash_leaves_incomplete_readable_recording() {
        let dir = tempfile::tempdir().unwrap();
        drop(write_rows(dir.path(), 5));
        // Simulate a line cut mid-write.
        let csv = dir.path().join(CSV_FILE);
        let mut f = std::fs::OpenOptions::new().append(true).open(&csv).unwrap();
        f.write_all(b"5000,0.005000,forw").unwrap();
        let rec = Recording::load(dir.path()).unwrap();
        assert!(!rec.meta.complete);
        assert!(rec.meta.end_reason.as_deref().unwrap().contains("aborted"));
        assert_eq!(rec.len(), 5);
        assert!(rec.truncated_last_line);
    }

    /// Guards: a malformed middle line is an error naming line and column.
    #[test]
    fn malformed_line_names_line_and_column() {
        let dir = tempfile::tempdir().unwrap();
        write_rows(dir.path(), 3).finish(true, "finished").unwrap();
        let csv = dir.path().join(CSV_FILE);
        let text = std::fs::read_to_string(&csv).unwrap();
        let bad = text.replacen(",settle,", ",sideways,", 2);
        std::fs::write(&csv, bad).unwrap();
        let err = Recording::load(dir.path()).unwrap_err().to_string();
        assert!(
            err.ends_with(":2: column `phase`: `sideways` is not settle, forward or reverse"),
            "{err}"
        );
    }

    /// Guards: a row with the wrong number of values is refused by the writer.
    #[test]
    fn writer_rejects_wrong_width() {
        let dir = tempfile::tempdir().unwrap();
        let mut w = RecordingWriter::create(dir.path(), meta()).unwrap();
        let e = w.push(&Row {
            device_time_us: 0,
            host_time_s: 0.0,
            phase: Phase::Forward,
            driver_angle_deg: 0.0,
            values: &[1.0],
            flags: 0,
        });
        assert!(matches!(
            e,
            Err(RecordingError::RowWidth {
                expected: 5,
                got: 1
            })
        ));
    }

    /// Guards: the civil-date conversion (used for directory names and sidecar times).
    #[test]
    fn utc_formatting() {
        let t = UNIX_EPOCH + Duration::from_millis(1_795_413_541_123);
        assert_eq!(utc_rfc3339(t), "2026-11-23T05:59:01.123Z");
        assert_eq!(utc_dir_stamp(t), "20261123T055901Z");
        assert_eq!(utc_rfc3339(UNIX_EPOCH), "1970-01-01T00:00:00.000Z");
        let leap = UNIX_EPOCH + Duration::from_secs(951_782_400); // 2000-02-29
        assert_eq!(&utc_rfc3339(leap)[..10], "2000-02-29");
    }
}
