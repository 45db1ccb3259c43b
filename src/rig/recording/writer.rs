//! Writing a recording: one row at a time, flushed at least every [`FLUSH_INTERVAL`], the
//! sidecar refreshed at every flush and rewritten at the end.

use std::fmt::Write as _;
use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
use std::time::{Instant, SystemTime};

use super::{
    io_err, utc_rfc3339, Phase, RecordingError, RecordingMeta, CSV_FILE, FLUSH_INTERVAL,
    SIDECAR_FILE,
};

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
