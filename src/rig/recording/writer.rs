//! Writing a recording: one row at a time, flushed at least every [`FLUSH_INTERVAL`], the
//! sidecar refreshed at every flush and rewritten at the end.
//!
//! The writer owns the folder while it records: it holds an exclusive lock on
//! [`LOCK_FILE`] (a second session into the same folder is refused, and a finished
//! recording is not overwritten unless asked, [`Existing`]), and it makes the sidecar true
//! to what is on disk: rows are written by the writer's own buffer, which knows how many
//! whole rows each write put on disk, so `counts` and the [`CsvFingerprint`] never describe
//! a row that is not there. When the disk fills, the CSV is cut back to its last whole row
//! and the space reserved in the lock file ([`DISK_RESERVE_BYTES`]) is given up so the
//! final sidecar can still be written, saying "disk full".

use std::fmt::Write as _;
use std::fs::{File, OpenOptions};
use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::{Instant, SystemTime};

use nix::fcntl::{Flock, FlockArg};
use sha2::{Digest, Sha256};

use super::{
    io_err, missing_before, utc_rfc3339, CsvFingerprint, Phase, RecordingError, RecordingMeta,
    CSV_FILE, FLUSH_INTERVAL, SIDECAR_FILE,
};

/// Lock file inside a recording folder, held (flock, exclusive) by the writer while it
/// records and removed when it finishes. It also holds the disk-space reserve.
pub const LOCK_FILE: &str = "recording.lock";

/// Bytes kept in the lock file while recording and released when the disk fills, so the
/// final sidecar (a few kB: rig, device, counts) and its temporary copy can still be
/// written. 64 KiB is sixteen 4 KiB blocks, several times what the two need.
pub const DISK_RESERVE_BYTES: u64 = 64 * 1024;

/// Rows are written to the file when this many bytes are buffered (or at a flush): about
/// 1.3 s of 1 kHz rows of one sensor, so a flush normally does the writing.
const WRITE_CHUNK: usize = 64 * 1024;

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
    /// [`super::flags`] bits.
    pub flags: u32,
}

/// What to do when the folder already holds a recording (a CSV or a sidecar).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub enum Existing {
    /// Refuse with [`RecordingError::Exists`].
    #[default]
    Refuse,
    /// Delete it (CSV, sidecar, and the `report/` made from it) and record anew.
    Replace,
}

/// A buffered row: where it ends in the buffer and the samples missing before it.
#[derive(Debug, Clone, Copy)]
struct Pending {
    end: usize,
    missing: u64,
}

/// A recording folder claimed for one session: it exists, this process holds the
/// exclusive lock on its [`LOCK_FILE`] (with the disk reserve in it), and it holds no
/// other recording. Claimed before the bench is opened, so a busy or taken folder is
/// refused before any hardware is touched.
#[derive(Debug)]
pub struct Claim {
    dir: PathBuf,
    lock: Flock<File>,
}

impl Claim {
    /// Claim `dir` (created with its parents if needed), dealing with a recording already
    /// there as `existing` says.
    pub fn folder(dir: &Path, existing: Existing) -> Result<Claim, RecordingError> {
        std::fs::create_dir_all(dir).map_err(io_err(dir))?;
        Self::take(dir, existing)
    }

    /// Claim a new folder under `parent` named `stem`, or `stem-2`, `stem-3`, … when that
    /// exists: the name is taken by creating the folder, so two sessions started in the
    /// same second never share one.
    pub fn unique(parent: &Path, stem: &str) -> Result<Claim, RecordingError> {
        std::fs::create_dir_all(parent).map_err(io_err(parent))?;
        for n in 1u32.. {
            let name = if n == 1 {
                stem.to_string()
            } else {
                format!("{stem}-{n}")
            };
            let dir = parent.join(name);
            match std::fs::create_dir(&dir) {
                Ok(()) => return Self::take(&dir, Existing::Refuse),
                Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => continue,
                Err(e) => return Err(io_err(&dir)(e)),
            }
        }
        unreachable!("u32 folder suffixes exhausted")
    }

    fn take(dir: &Path, existing: Existing) -> Result<Claim, RecordingError> {
        let lock_path = dir.join(LOCK_FILE);
        let lock_file = OpenOptions::new()
            .create(true)
            .truncate(false)
            .write(true)
            .open(&lock_path)
            .map_err(io_err(&lock_path))?;
        let lock = Flock::lock(lock_file, FlockArg::LockExclusiveNonblock).map_err(|_| {
            RecordingError::Locked {
                dir: dir.to_path_buf(),
            }
        })?;
        let csv_path = dir.join(CSV_FILE);
        let sidecar = dir.join(SIDECAR_FILE);
        if csv_path.exists() || sidecar.exists() {
            if existing == Existing::Refuse {
                return Err(RecordingError::Exists {
                    dir: dir.to_path_buf(),
                });
            }
            for f in [&csv_path, &sidecar] {
                if f.exists() {
                    std::fs::remove_file(f).map_err(io_err(f))?;
                }
            }
            let report = dir.join("report");
            if report.is_dir() {
                std::fs::remove_dir_all(&report).map_err(io_err(&report))?;
            }
        }
        reserve(&lock, DISK_RESERVE_BYTES).map_err(io_err(&lock_path))?;
        Ok(Claim {
            dir: dir.to_path_buf(),
            lock,
        })
    }

    /// The folder.
    pub fn dir(&self) -> &Path {
        &self.dir
    }
}

/// Writes a recording incrementally.
pub struct RecordingWriter {
    dir: PathBuf,
    csv_path: PathBuf,
    file: File,
    /// Rows not yet written to the file.
    buf: Vec<u8>,
    pending: Vec<Pending>,
    /// Bytes of the CSV on disk (header and whole rows) and their hash.
    on_disk: u64,
    hasher: Sha256,
    lock: Flock<File>,
    meta: RecordingMeta,
    /// Nominal sample period (µs) that holes are measured against.
    period_us: f64,
    last_device_us: Option<u64>,
    line: String,
    last_flush: Instant,
    /// The disk filled: nothing more is written to the CSV.
    disk_full: bool,
    finished: bool,
}

impl RecordingWriter {
    /// Start the recording in a claimed folder: write the CSV header and an incomplete
    /// sidecar.
    pub fn create(claim: Claim, meta: RecordingMeta) -> Result<RecordingWriter, RecordingError> {
        let Claim { dir, lock } = claim;
        let csv_path = dir.join(CSV_FILE);
        let mut file = File::create(&csv_path).map_err(io_err(&csv_path))?;
        let header: Vec<&str> = meta.columns.iter().map(|c| c.name.as_str()).collect();
        let header = format!("{}\n", header.join(","));
        file.write_all(header.as_bytes())
            .map_err(io_err(&csv_path))?;
        let mut hasher = Sha256::new();
        hasher.update(header.as_bytes());
        let period_us = 1e6 / meta.session.sample_rate_hz;
        let mut w = RecordingWriter {
            dir,
            csv_path,
            file,
            buf: Vec::with_capacity(WRITE_CHUNK + 4096),
            pending: Vec::new(),
            on_disk: header.len() as u64,
            hasher,
            lock,
            meta,
            period_us,
            last_device_us: None,
            line: String::with_capacity(256),
            last_flush: Instant::now(),
            disk_full: false,
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

    /// Mutable access to the sidecar (device info, link counts, degraded); written at the
    /// next flush. `counts.samples`, `gaps`, `missing_samples` and `csv` are the writer's
    /// and are set from what is on disk at every flush.
    pub fn meta_mut(&mut self) -> &mut RecordingMeta {
        &mut self.meta
    }

    /// Rows pushed so far, written or still buffered (for progress displays).
    pub fn rows_pushed(&self) -> u64 {
        self.meta.counts.samples + self.pending.len() as u64
    }

    /// Append one row; writes and flushes when [`FLUSH_INTERVAL`] has passed since the last
    /// flush. After the disk filled, every push fails with [`RecordingError::DiskFull`].
    pub fn push(&mut self, row: &Row<'_>) -> Result<(), RecordingError> {
        if self.disk_full {
            return Err(RecordingError::DiskFull {
                path: self.csv_path.clone(),
            });
        }
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
        let missing = self.last_device_us.map_or(0, |prev| {
            missing_before(row.device_time_us.saturating_sub(prev), self.period_us)
        });
        self.last_device_us = Some(row.device_time_us);
        self.buf.extend_from_slice(self.line.as_bytes());
        self.pending.push(Pending {
            end: self.buf.len(),
            missing,
        });
        if self.last_flush.elapsed() >= FLUSH_INTERVAL {
            self.flush()?;
        } else if self.buf.len() >= WRITE_CHUNK {
            self.write_buffer()?;
        }
        Ok(())
    }

    /// Write the buffered rows to the file and refresh the sidecar (still incomplete).
    pub fn flush(&mut self) -> Result<(), RecordingError> {
        self.last_flush = Instant::now();
        self.write_buffer()?;
        self.write_sidecar()
    }

    /// Whether a flush is due (for callers that push rarely).
    pub fn flush_due(&self) -> bool {
        self.last_flush.elapsed() >= FLUSH_INTERVAL
    }

    /// End the recording: write what is buffered, fsync, and write the final sidecar (with
    /// `complete` false if that write failed). After a full disk nothing more is written to
    /// the CSV, the reserve has been given up, and the sidecar describes the rows on disk,
    /// with `end_reason` as given: a caller that wants the write's failure in the end reason
    /// calls [`RecordingWriter::flush`] first.
    pub fn finish(
        mut self,
        complete: bool,
        end_reason: &str,
    ) -> Result<RecordingMeta, RecordingError> {
        let written = if self.disk_full {
            Ok(())
        } else {
            self.write_buffer()
        };
        let synced = self.file.sync_all().map_err(io_err(&self.csv_path));
        self.meta.complete = complete && written.is_ok();
        self.meta.end_reason = Some(end_reason.to_string());
        self.meta.finished_at = Some(utc_rfc3339(SystemTime::now()));
        self.write_sidecar()?;
        self.finished = true;
        // Unlink while still holding the lock, so no one sees an unlocked stale file.
        let _ = std::fs::remove_file(self.dir.join(LOCK_FILE));
        written?;
        synced?;
        Ok(self.meta.clone())
    }

    /// Write the buffer to the file. Rows count as written only once whole on disk; on a
    /// write error the file is cut back to its last whole row, the rest of the buffer is
    /// dropped, and (disk full) the writer stops writing rows and frees the reserve.
    fn write_buffer(&mut self) -> Result<(), RecordingError> {
        if self.buf.is_empty() {
            return Ok(());
        }
        let mut written = 0;
        let mut failure = None;
        while written < self.buf.len() {
            match self.file.write(&self.buf[written..]) {
                Ok(0) => {
                    failure = Some(std::io::Error::from(std::io::ErrorKind::WriteZero));
                    break;
                }
                Ok(n) => written += n,
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
                Err(e) => {
                    failure = Some(e);
                    break;
                }
            }
        }
        // Whole rows that made it.
        let done = self.pending.partition_point(|p| p.end <= written);
        let whole = if done > 0 {
            self.pending[done - 1].end
        } else {
            0
        };
        self.hasher.update(&self.buf[..whole]);
        self.on_disk += whole as u64;
        let c = &mut self.meta.counts;
        c.samples += done as u64;
        for p in &self.pending[..done] {
            if p.missing > 0 {
                c.gaps += 1;
                c.missing_samples += p.missing;
            }
        }
        self.buf.clear();
        self.pending.clear();
        let Some(e) = failure else {
            return Ok(());
        };
        // Cut a partial row away so the CSV ends where the sidecar says.
        let _ = self.file.set_len(self.on_disk);
        let err = io_err(&self.csv_path)(e);
        self.note_failure(&err);
        Err(err)
    }

    /// After a failed write: on a full disk, stop writing rows and give up the reserve so
    /// the final sidecar fits.
    fn note_failure(&mut self, err: &RecordingError) {
        if matches!(err, RecordingError::DiskFull { .. }) && !self.disk_full {
            self.disk_full = true;
            let _ = self.lock.set_len(0);
        }
    }

    fn write_sidecar(&mut self) -> Result<(), RecordingError> {
        self.meta.csv = Some(CsvFingerprint {
            bytes: self.on_disk,
            sha256: self
                .hasher
                .clone()
                .finalize()
                .iter()
                .map(|b| format!("{b:02x}"))
                .collect(),
        });
        let path = self.dir.join(SIDECAR_FILE);
        let tmp = self.dir.join(format!("{SIDECAR_FILE}.tmp"));
        let json =
            serde_json::to_vec_pretty(&self.meta).map_err(|source| RecordingError::Sidecar {
                path: path.clone(),
                source,
            })?;
        let written = std::fs::write(&tmp, json)
            .map_err(io_err(&tmp))
            .and_then(|()| std::fs::rename(&tmp, &path).map_err(io_err(&path)));
        if let Err(e) = &written {
            // Never leave a half-written temporary behind; the previous sidecar stays.
            let _ = std::fs::remove_file(&tmp);
            self.note_failure(e);
        }
        written
    }
}

/// Allocate `bytes` of real disk space in `file` (not a sparse hole): `posix_fallocate`,
/// or zeros written where the file system does not support it.
fn reserve(file: &File, bytes: u64) -> std::io::Result<()> {
    use std::os::fd::AsRawFd;
    let len = i64::try_from(bytes).unwrap_or(i64::MAX);
    match nix::fcntl::posix_fallocate(file.as_raw_fd(), 0, len) {
        Ok(()) => Ok(()),
        Err(nix::errno::Errno::EOPNOTSUPP | nix::errno::Errno::EINVAL) => {
            let mut f = file;
            f.write_all(&vec![0u8; bytes as usize])?;
            f.sync_all()
        }
        Err(e) => Err(std::io::Error::from(e)),
    }
}

impl Drop for RecordingWriter {
    fn drop(&mut self) {
        if !self.finished {
            // Best effort: keep what we have; the sidecar stays `complete: false`.
            if !self.disk_full {
                let _ = self.write_buffer();
            }
            if self.meta.end_reason.is_none() {
                self.meta.end_reason = Some("aborted: writer dropped before finish".into());
            }
            let _ = self.write_sidecar();
            let _ = std::fs::remove_file(self.dir.join(LOCK_FILE));
        }
    }
}
