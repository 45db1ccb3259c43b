//! Recordings on disk through the real loader: calibration and unwrapping of raw AS5600
//! counts and IMU quaternions, the target named in the sidecar, garbage and cut-off lines,
//! and the `analyze` command's exit codes.

use std::io::Write as _;
use std::path::{Path, PathBuf};

use mpc_rig::analysis::synthetic::{write_recording, SyntheticBench};
use mpc_rig::analysis::{analyze_and_report, load_run, load_target, ReportOptions, TargetSource};
use mpc_rig::rig::config::RigConfig;
use mpc_rig::rig::recording::TargetRef;
use nalgebra::UnitQuaternion;

fn repo(p: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join(p)
}

fn target_ref(kind: &str, path: &Path, class: &str, name: &str) -> TargetRef {
    TargetRef {
        kind: kind.into(),
        path: path.to_path_buf(),
        sha256: String::new(),
        class: class.into(),
        name: name.into(),
    }
}

/// Writes a half-turn-2to1 recording from the sim-stepper rig (AS5600 raw counts, wrapped)
/// with a 3° sensor zero error and 1.5° phase lag.
fn half_turn_recording(dir: &Path, bench: &SyntheticBench) -> PathBuf {
    let motion = repo("data/motions/half-turn-2to1.toml");
    let law = load_target(&TargetSource::Motion(motion.clone())).unwrap();
    let run = bench.generate(&law);
    let rig = RigConfig::load(&repo("rigs/sim-stepper.toml")).unwrap();
    let rec = dir.join("rec");
    write_recording(
        &run,
        rig,
        target_ref("motion", &motion, "1R", "half-turn-2to1"),
        &rec,
    )
    .unwrap();
    rec
}

fn bench() -> SyntheticBench {
    SyntheticBench {
        driver_offset_deg: 1.5,
        rz_offset_deg: 3.0,
        noise: 0.03,
        forward_cycles: 3.0,
        rate_hz: 500.0,
        seed: 21,
        ..Default::default()
    }
}

/// Guards the loader and the sidecar's target: raw wrapped AS5600 counts are unwrapped into
/// a follower turning 4 turns, the half-turn ratio is 2 within its U95 (and within 0.01), the
/// phase lag and sensor offset are recovered within 0.1°, and the report lands in
/// `<recording>/report/`.
#[test]
fn analyzes_recording_named_target() {
    let tmp = tempfile::tempdir().unwrap();
    let rec = half_turn_recording(tmp.path(), &bench());
    let loaded = load_run(&rec).unwrap();
    let rz = loaded.run.rz_deg.as_ref().unwrap();
    let span = rz.last().unwrap() - rz.first().unwrap();
    assert!((span - 4.0 * 360.0).abs() < 5.0, "unwrapped span {span}");
    assert!((loaded.run.resolution.rz_deg - 360.0 / 4096.0).abs() < 1e-12);
    let s = analyze_and_report(&rec, &ReportOptions::default()).unwrap();
    let t = s.timing.as_ref().unwrap();
    let r = t.ratios[0];
    assert!((r.target - 2.0).abs() < 1e-6, "target {}", r.target);
    assert!((r.measured - 2.0).abs() <= r.u95.max(0.01), "{r:?}");
    assert!(
        (s.alignment.driver_offset_deg - 1.5).abs() < 0.1,
        "{:?}",
        s.alignment
    );
    assert!((s.alignment.sensor_offset_rz_deg.unwrap() - 3.0).abs() < 0.1);
    assert!(rec.join("report/report.html").exists());
    assert!(rec.join("report/summary.json").exists());
}

/// Guards garbage handling: a non-numeric driver angle is an error naming the CSV line and
/// column; a cut-off last line (crash) is dropped, reported, and the rest still analysed.
#[test]
fn garbage_is_located_and_cut_off_line_tolerated() {
    let tmp = tempfile::tempdir().unwrap();
    let rec = half_turn_recording(tmp.path(), &bench());
    let csv = rec.join("recording.csv");
    let clean = std::fs::read(&csv).unwrap();
    let lines = clean.iter().filter(|b| **b == b'\n').count();
    // A cut-off last line.
    std::fs::OpenOptions::new()
        .append(true)
        .open(&csv)
        .unwrap()
        .write_all(b"99999999,1.0,forw")
        .unwrap();
    let s = analyze_and_report(&rec, &ReportOptions::default()).unwrap();
    assert!(s.source.truncated_last_line);
    // Garbage in a full line.
    let mut bad = clean.clone();
    bad.extend_from_slice(b"99999999,1.0,forward,abc,17,0\n");
    std::fs::write(&csv, bad).unwrap();
    let e = analyze_and_report(&rec, &ReportOptions::default())
        .unwrap_err()
        .to_string();
    assert_eq!(
        e.replace(&rec.display().to_string(), "REC"),
        format!(
            "cannot load recording REC: REC/recording.csv:{}: column `driver_angle_deg`: `abc` \
             is not a number",
            lines + 1
        )
    );
}

/// Guards the command line: `analyze` exits 0 with loose tolerances, 3 when the RMS
/// tolerance is missed, and prints the report location and the timing ratio.
#[test]
fn analyze_command_exit_codes() {
    let tmp = tempfile::tempdir().unwrap();
    let rec = half_turn_recording(tmp.path(), &bench());
    let out = assert_cmd::Command::cargo_bin("mpc-rig")
        .unwrap()
        .args([
            "analyze",
            rec.to_str().unwrap(),
            "--tol-deg",
            "5",
            "--tol-ratio",
            "0.05",
        ])
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert_eq!(
        out.status.code(),
        Some(0),
        "{stdout}{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(
        stdout.contains("report.html")
            && stdout.contains("vs target 2.000")
            && stdout.contains("PASS"),
        "{stdout}"
    );
    let out = assert_cmd::Command::cargo_bin("mpc-rig")
        .unwrap()
        .args([
            "analyze",
            rec.to_str().unwrap(),
            "--tol-deg",
            "0.0001",
            "-o",
        ])
        .arg(tmp.path().join("r2"))
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(3));
    assert!(String::from_utf8_lossy(&out.stdout).contains("FAIL"));
    assert!(tmp.path().join("r2/summary.json").exists());
}

/// Guards the IMU path: figure-eight recorded through the Pico + BNO055 rig (90° mounting
/// rotation, a 20° IMU heading offset) analyses with a sub-0.3° RMS geodesic error and an
/// axis-path chart.
#[test]
fn analyzes_imu_recording() {
    let tmp = tempfile::tempdir().unwrap();
    let motion = repo("data/motions/figure-eight.toml");
    let law = load_target(&TargetSource::Motion(motion.clone())).unwrap();
    let run = SyntheticBench {
        noise: 0.1,
        world_offset: UnitQuaternion::from_euler_angles(0.0, 0.0, 20f64.to_radians()),
        forward_cycles: 2.0,
        rate_hz: 100.0,
        seed: 4,
        ..Default::default()
    }
    .generate(&law);
    let rig = RigConfig::load(&repo("rigs/pico-bno055.toml")).unwrap();
    let rec = tmp.path().join("rec");
    write_recording(
        &run,
        rig,
        target_ref("motion", &motion, "3R", "figure-eight"),
        &rec,
    )
    .unwrap();
    let s = analyze_and_report(&rec, &ReportOptions::default()).unwrap();
    assert_eq!(s.headline.class, "3R");
    assert!(s.headline.rms_error_deg.unwrap() < 0.3, "{:?}", s.headline);
    assert!((s.alignment.world_offset_deg.unwrap() - 20.0).abs() < 0.5);
    assert!(!s.key_poses.is_empty());
    assert!(rec.join("report/axis_path.png").exists());
}

/// Guards `analyze --json` for scripts: standard output is exactly the summary.json the
/// command wrote (no file list, no text), and the exit code is unchanged by it.
#[test]
fn analyze_json_prints_the_summary_alone() {
    let tmp = tempfile::tempdir().unwrap();
    let rec = half_turn_recording(tmp.path(), &bench());
    for (tol, code) in [("5", 0), ("0.0001", 3)] {
        let report = tmp.path().join(format!("report-{code}"));
        let out = assert_cmd::Command::cargo_bin("mpc-rig")
            .unwrap()
            .args([
                "analyze",
                rec.to_str().unwrap(),
                "--json",
                "--tol-deg",
                tol,
                "-o",
            ])
            .arg(&report)
            .output()
            .unwrap();
        assert_eq!(out.status.code(), Some(code));
        let printed: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
        let written: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(report.join("summary.json")).unwrap())
                .unwrap();
        assert_eq!(printed, written);
        assert_eq!(printed["pass"], code == 0);
    }
}

/// Guards rows whose driver angle was held (issue 20: a loaded mixed bench showed spike
/// columns in the error while the report said "0 gaps"): a stretch of rows flagged
/// `DRIVER_HELD`, their driver angle frozen as the merge leaves it, is left out of the
/// figures, counted, and said in the report and the summary line.
#[test]
fn rows_with_a_held_driver_angle_are_left_out_and_said() {
    let tmp = tempfile::tempdir().unwrap();
    let rec = half_turn_recording(tmp.path(), &bench());
    let clean = analyze_and_report(&rec, &ReportOptions::default()).unwrap();
    let csv = rec.join("recording.csv");
    let text = std::fs::read_to_string(&csv).unwrap();
    let mut lines: Vec<String> = text.lines().map(str::to_string).collect();
    // 0.2 s at 500 Hz in the middle of the run: the driver angle frozen at the first
    // row's, as a bus that fell behind leaves it (tens of degrees stale by the end).
    let from = lines.len() / 2;
    let to = from + 100;
    let frozen = lines[from].split(',').nth(3).unwrap().to_string();
    for line in &mut lines[from..to] {
        let mut cells: Vec<String> = line.split(',').map(str::to_string).collect();
        cells[3] = frozen.clone();
        let last = cells.len() - 1;
        let flags: u32 = cells[last].parse().unwrap();
        cells[last] = (flags | mpc_rig::rig::recording::flags::DRIVER_HELD).to_string();
        *line = cells.join(",");
    }
    std::fs::write(&csv, lines.join("\n") + "\n").unwrap();
    // The sidecar's fingerprint of the CSV is for the rows as written; drop it, as a
    // sidecar from before fingerprints has none.
    let sidecar = rec.join("recording.json");
    let mut meta: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&sidecar).unwrap()).unwrap();
    meta["csv"] = serde_json::Value::Null;
    std::fs::write(&sidecar, meta.to_string()).unwrap();
    let held = analyze_and_report(&rec, &ReportOptions::default()).unwrap();
    assert_eq!(held.source.held_rows, to - from);
    assert_eq!(clean.source.held_rows, 0);
    let (a, b) = (
        clean.headline.max_error_deg.unwrap(),
        held.headline.max_error_deg.unwrap(),
    );
    assert!(
        b <= a + 0.05,
        "held rows entered the figures: max {b}° against {a}°"
    );
    let report = std::fs::read_to_string(rec.join("report/report.md")).unwrap();
    assert!(
        report.contains(
            "100 rows left out whose driver angle was held (the Dynamixel bus fell behind \
             the board)."
        ),
        "{report}"
    );
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(rec.join("report/summary.json")).unwrap())
            .unwrap();
    assert_eq!(summary["source"]["held_rows"], 100);
}

/// Guards the units in the CSV header (issue 20) and the reading of older recordings: the
/// header names each sensor column with its unit, and a recording from before that (the
/// column named by the sensor alone), with or without the sidecar's `sensor` field, gives
/// the same figures.
#[test]
fn the_header_carries_units_and_older_headers_still_read() {
    let tmp = tempfile::tempdir().unwrap();
    let rec = half_turn_recording(tmp.path(), &bench());
    let csv = rec.join("recording.csv");
    let text = std::fs::read_to_string(&csv).unwrap();
    let (header, rows) = text.split_once('\n').unwrap();
    assert_eq!(
        header,
        "device_time_us,host_time_s,phase,driver_angle_deg,follower_rz_counts,flags"
    );
    let now = analyze_and_report(&rec, &ReportOptions::default()).unwrap();

    let legacy = header.replace("follower_rz_counts", "follower_rz");
    std::fs::write(&csv, format!("{legacy}\n{rows}")).unwrap();
    let sidecar = rec.join("recording.json");
    let mut meta: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&sidecar).unwrap()).unwrap();
    // The fingerprint is of the CSV as written; an older sidecar has none.
    meta["csv"] = serde_json::Value::Null;
    assert_eq!(meta["columns"][4]["name"], "follower_rz_counts");
    meta["columns"][4]["name"] = "follower_rz".into();
    for with_sensor_field in [true, false] {
        if !with_sensor_field {
            for c in meta["columns"].as_array_mut().unwrap() {
                c.as_object_mut().unwrap().remove("sensor");
            }
        }
        std::fs::write(&sidecar, meta.to_string()).unwrap();
        let before = analyze_and_report(&rec, &ReportOptions::default()).unwrap();
        assert_eq!(
            before.headline.rms_error_deg, now.headline.rms_error_deg,
            "sensor field: {with_sensor_field}"
        );
        assert_eq!(before.source.rows, now.source.rows);
    }
}
