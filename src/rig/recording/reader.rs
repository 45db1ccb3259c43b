//! Reading a recording back: streaming row by row without per-row allocation
//! ([`RecordingReader`]), or whole into memory column by column ([`Recording`]).
//!
//! Reading to the end also checks that the CSV belongs to its sidecar: the bytes the
//! sidecar's [`super::CsvFingerprint`] describes must be there with that SHA-256, and a
//! finished recording may have no rows beyond them (a crashed one may: they were written
//! after its last sidecar). Sidecars from before the fingerprint are checked by their row
//! count. So another run's sidecar, or an edited CSV, is an error, not a silent analysis.

use std::fs::File;
use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};

use sha2::{Digest, Sha256};

use super::{
    io_err, load_meta, CsvFingerprint, Phase, RecordingError, RecordingMeta, CSV_FILE,
    FLAGS_COLUMN, LEADING_COLUMNS,
};

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
    dir: PathBuf,
    reader: BufReader<File>,
    buf: Vec<u8>,
    line: usize,
    columns: Vec<String>,
    sensor_columns: usize,
    truncated: bool,
    /// What the sidecar says of the CSV: its fingerprint, row count and completeness.
    expect: (Option<CsvFingerprint>, u64, bool),
    /// Hash of the bytes read so far, up to the fingerprint's length.
    hasher: Sha256,
    /// Bytes of whole lines read (header included).
    read_bytes: u64,
    /// Rows read, and rows read past the fingerprint's bytes.
    rows: u64,
    rows_beyond: u64,
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
        let mut hasher = Sha256::new();
        hasher.update(header.as_bytes());
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
        let expect = (meta.csv.clone(), meta.counts.samples, meta.complete);
        Ok((
            meta,
            RecordingReader {
                path,
                dir: dir.to_path_buf(),
                reader,
                buf: Vec::with_capacity(256),
                line: 1,
                columns,
                sensor_columns,
                truncated: false,
                expect,
                hasher,
                read_bytes: header.len() as u64,
                rows: 0,
                rows_beyond: 0,
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

    /// Read the next row into `row`; `Ok(false)` at the end of the file, once the CSV has
    /// been found to belong to the sidecar ([`RecordingError::Mismatch`] otherwise).
    pub fn next_row(&mut self, row: &mut RowBuf) -> Result<bool, RecordingError> {
        loop {
            self.buf.clear();
            let n = self
                .reader
                .read_until(b'\n', &mut self.buf)
                .map_err(io_err(&self.path))?;
            if n == 0 {
                self.check_belongs()?;
                return Ok(false);
            }
            self.line += 1;
            if self.buf.last() != Some(&b'\n') {
                // Cut short by a crash or unplug: drop it and say so.
                self.truncated = true;
                self.check_belongs()?;
                return Ok(false);
            }
            self.account_line();
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

    /// Hash a whole line read (up to the fingerprint's length) and count it.
    fn account_line(&mut self) {
        let limit = self.expect.0.as_ref().map_or(0, |f| f.bytes);
        let before = self.read_bytes;
        self.read_bytes += self.buf.len() as u64;
        if before < limit {
            let take = (limit - before).min(self.buf.len() as u64) as usize;
            self.hasher.update(&self.buf[..take]);
        } else {
            self.rows_beyond += 1;
        }
        // Blank lines are skipped by the parser and are no rows.
        if self.buf.iter().any(|&b| b != b'\n' && b != b'\r') {
            self.rows += 1;
        }
    }

    /// At the end of the file: does this CSV belong to the sidecar?
    fn check_belongs(&self) -> Result<(), RecordingError> {
        let mismatch = |message: String| {
            Err(RecordingError::Mismatch {
                dir: self.dir.clone(),
                message,
            })
        };
        let (fingerprint, counted, complete) = &self.expect;
        match fingerprint {
            Some(f) => {
                if self.read_bytes < f.bytes {
                    return mismatch(format!(
                        "it holds {} bytes of whole rows, the sidecar describes {} (rows are \
                         missing, or it is another run's CSV)",
                        self.read_bytes, f.bytes
                    ));
                }
                let hash: String = self
                    .hasher
                    .clone()
                    .finalize()
                    .iter()
                    .map(|b| format!("{b:02x}"))
                    .collect();
                if hash != f.sha256 {
                    return mismatch(format!(
                        "its first {} bytes are not the ones the sidecar recorded (another \
                         run's CSV, or an edited one)",
                        f.bytes
                    ));
                }
                if *complete && self.rows_beyond > 0 {
                    return mismatch(format!(
                        "{} rows follow the ones the finished recording's sidecar describes",
                        self.rows_beyond
                    ));
                }
            }
            // A sidecar from before the fingerprint: the row count must fit.
            None if (*complete && self.rows != *counted) || self.rows < *counted => {
                return mismatch(format!(
                    "it holds {} rows, the {} sidecar counts {counted}",
                    self.rows,
                    if *complete { "finished" } else { "unfinished" }
                ));
            }
            None => {}
        }
        Ok(())
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
