//! Reading a recording back: streaming row by row without per-row allocation
//! ([`RecordingReader`]), or whole into memory column by column ([`Recording`]).

use std::fs::File;
use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};

use super::{
    io_err, load_meta, Phase, RecordingError, RecordingMeta, CSV_FILE, FLAGS_COLUMN,
    LEADING_COLUMNS,
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
