//! The bench commands as a user runs them: `mpc-rig sim-device stepper` in its own process
//! (path on the first stdout line), `mpc-rig measure` against it, and the exit codes and
//! messages of an unplug and a version mismatch.

use std::path::Path;
use std::process::{Command, Stdio};

use crate::support::serial_group;
use crate::support::SimChild;

fn bin() -> &'static str {
    env!("CARGO_BIN_EXE_mpc-rig")
}

fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

/// `sim-device stepper` for half-turn-2to1 with `faults` (killed when dropped).
fn start_sim(faults: &[&str]) -> SimChild {
    let mut args = vec![
        "sim-device".into(),
        "stepper".into(),
        "--motion".into(),
        root()
            .join("data/motions/half-turn-2to1.toml")
            .into_os_string(),
    ];
    for f in faults {
        args.extend(["--fault".into(), (*f).into()]);
    }
    SimChild::spawn::<_, std::ffi::OsString>(args)
}

fn measure(sim: &SimChild, out: &Path) -> std::process::Output {
    measure_with(sim, out, &["--cycles", "3", "--no-analysis"])
}

/// `measure` at 90 rpm on the simulator towards half-turn-2to1 into `out`, with `args`.
fn measure_with(sim: &SimChild, out: &Path, args: &[&str]) -> std::process::Output {
    Command::new(bin())
        .arg("measure")
        .arg("--rig")
        .arg(root().join("rigs/sim-stepper.toml"))
        .args(["--port", &sim.first_line])
        .arg("--motion")
        .arg(root().join("data/motions/half-turn-2to1.toml"))
        .args(["--speed", "90"])
        .args(args)
        .arg("-o")
        .arg(out)
        .stdin(Stdio::null())
        .output()
        .unwrap()
}

/// Guards: the simulator prints a usable pseudo-terminal path on its first line.
#[test]
fn sim_device_prints_pty_path_first() {
    let _serial = serial_group::real_time();
    let sim = start_sim(&[]);
    assert!(
        sim.first_line.starts_with("/dev/pts/"),
        "{}",
        sim.first_line
    );
    assert!(Path::new(&sim.first_line).exists());
}

/// Guards: an unplug mid-run (the simulator closes its end for good) ends `measure` with
/// exit code 5, a message saying the device disconnected and that the recording is kept
/// (each said once: it used to read "device disconnected (disconnected: PORT: …"), and an
/// incomplete but readable recording.
#[test]
fn measure_reports_unplug_with_exit_code_and_kept_recording() {
    let _serial = serial_group::real_time();
    let dir = tempfile::tempdir().unwrap();
    let rec = dir.path().join("rec");
    let sim = start_sim(&["disconnect_at_s=1.5"]);
    let out = measure(&sim, &rec);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(5), "{stderr}");
    assert!(stderr.contains("device disconnected"), "{stderr}");
    assert!(stderr.contains("kept and marked incomplete"), "{stderr}");
    let last = stderr
        .lines()
        .rfind(|l| l.starts_with("error:"))
        .unwrap_or_else(|| panic!("no final error line: {stderr}"));
    assert_eq!(last.matches("disconnected").count(), 1, "{last}");
    assert_eq!(last.matches(sim.first_line.as_str()).count(), 1, "{last}");
    let r = mpc_rig::rig::recording::Recording::load(&rec).unwrap();
    assert!(!r.meta.complete && !r.is_empty());
}

/// Guards: a version mismatch stops `measure` before anything moves, with exit code 1 and
/// a message naming both protocol versions.
#[test]
fn measure_reports_version_mismatch() {
    let _serial = serial_group::real_time();
    let dir = tempfile::tempdir().unwrap();
    let sim = start_sim(&["protocol_version=7"]);
    let out = measure(&sim, &dir.path().join("rec"));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert!(
        stderr.contains("speaks wire protocol version 7, this host speaks 1"),
        "{stderr}"
    );
}

/// Guards: when the host process dies mid-run (SIGKILL, no cleanup at all), the firmware's
/// dead-man watchdog stops the motor, and the recording on disk is still valid and
/// analyzable, marked incomplete.
#[test]
fn host_crash_leaves_valid_recording_and_watchdog_stops_motor() {
    let _serial = serial_group::real_time();
    use mpc_rig::motion::Motion;
    use mpc_rig::rig::sim::plant::PlantConfig;
    use mpc_rig::rig::sim::stepper::{self, Mechanics, SimStepperOptions};
    let dir = tempfile::tempdir().unwrap();
    let rec = dir.path().join("rec");
    let sim = stepper::spawn(SimStepperOptions {
        target: Motion::from_file(&root().join("data/motions/half-turn-2to1.toml")).unwrap(),
        plant: PlantConfig::default(),
        mechanics: Mechanics::default(),
        link: None,
        driver: None,
    })
    .unwrap();
    let mut child = Command::new(bin())
        .arg("measure")
        .arg("--rig")
        .arg(root().join("rigs/sim-stepper.toml"))
        .args(["--port", &sim.path().display().to_string()])
        .arg("--motion")
        .arg(root().join("data/motions/half-turn-2to1.toml"))
        .args(["--speed", "60", "--cycles", "5", "--no-analysis", "-o"])
        .arg(&rec)
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    // Kill it while the motor runs.
    let t0 = std::time::Instant::now();
    while !sim.status().moving && t0.elapsed().as_secs() < 10 {
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
    std::thread::sleep(std::time::Duration::from_millis(1500));
    assert!(sim.status().moving, "the motor should run before the crash");
    child.kill().unwrap(); // SIGKILL: no handler, no shutdown
    child.wait().unwrap();
    // Watchdog 250 ms + deceleration from 1 rev/s at 1440 °/s² (0.25 s).
    std::thread::sleep(std::time::Duration::from_millis(1200));
    let status = sim.stop().unwrap();
    assert!(
        !status.moving,
        "watchdog did not stop the motor: {status:?}"
    );
    let r = mpc_rig::rig::recording::Recording::load(&rec).unwrap();
    assert!(!r.meta.complete);
    assert!(r.len() > 500, "{} rows survived", r.len());
}

/// Guards `measure --json` for scripts: standard output is one JSON object and nothing else
/// (no progress, no file list), with the recording, how the run ended, its counts, the
/// analysis (the summary.json the run wrote) and the exit code the program ends with; and
/// the same object when the run fails a tolerance (exit 3).
#[test]
fn measure_json_is_one_object_with_the_outcome_and_the_summary() {
    let _serial = serial_group::real_time();
    let sim = start_sim(&[]);
    let dir = tempfile::tempdir().unwrap();
    for (tol, code) in [("5", 0), ("0.000001", 3)] {
        let rec = dir.path().join(format!("rec-{code}"));
        let out = measure_with(&sim, &rec, &["--cycles", "1", "--json", "--tol-deg", tol]);
        let stdout = String::from_utf8_lossy(&out.stdout);
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(code), "{stdout}{stderr}");
        let json: serde_json::Value = serde_json::from_str(&stdout)
            .unwrap_or_else(|e| panic!("stdout is not one JSON object ({e}): {stdout}"));
        assert_eq!(json["recording"], rec.to_str().unwrap());
        assert_eq!(json["end_reason"], "finished");
        assert_eq!(json["complete"], true);
        assert_eq!(json["degraded"], serde_json::Value::Null);
        assert_eq!(json["exit_code"], code);
        assert!(json["counts"]["samples"].as_u64().unwrap() > 500, "{json}");
        let written: serde_json::Value = serde_json::from_str(
            &std::fs::read_to_string(rec.join("report/summary.json")).unwrap(),
        )
        .unwrap();
        assert_eq!(
            json["summary"], written,
            "the summary is summary.json's content"
        );
        assert_eq!(json["summary"]["pass"], code == 0);
    }
}
