//! Round trips through the writer and the reader.

use super::*;
use crate::rig::config::RigConfig;
use std::io::Write;
use std::time::Duration;

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
    let mut w =
        RecordingWriter::create(Claim::folder(dir, Existing::Refuse).unwrap(), meta()).unwrap();
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
    assert_eq!(rec.sensor("enc_counts").unwrap()[9], 9.0);
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
    let mut w =
        RecordingWriter::create(Claim::folder(dir.path(), Existing::Refuse).unwrap(), meta())
            .unwrap();
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
