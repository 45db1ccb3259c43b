//! SIGTERM and SIGHUP stop a run like Ctrl-C (issue 16: SIGTERM, what `timeout` and service
//! managers send, ended `measure` at once with exit 143: no stop command, `end_reason`
//! null, the last half second of rows lost). Over the simulated stepper, Dynamixel and
//! mixed benches: the motor ends stopped, the recording is finished as `cancelled` with
//! every row flushed (down to the driver at rest), and the exit code is 128 + the signal.

use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use nix::sys::signal::{kill, Signal};
use nix::unistd::Pid;

use mpc_rig::rig::config::RigConfig;
use mpc_rig::rig::recording::{load_meta, Recording};
use mpc_rig::rig::sim::mixed;
use mpc_rig::rig::sim::plant::PlantConfig;

use crate::support::bench::{dxl_sim, motion, repo, stepper_sim};
use crate::support::serial_group;

/// Run `measure` with `rig`, `ports` and `motion` into `dir`, send `signal` once a second of
/// rows is on disk, and return the exit code and standard error.
fn measure_then_signal(
    rig: &str,
    ports: &[String],
    motion: &str,
    dir: &Path,
    signal: Signal,
) -> (Option<i32>, String) {
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_mpc-rig"));
    cmd.args(["measure", "--rig"]).arg(repo(rig));
    for p in ports {
        cmd.args(["--port", p]);
    }
    let child = cmd
        .arg("--motion")
        .arg(repo(motion))
        .args(["--speed", "30", "--cycles", "4", "--no-analysis", "-o"])
        .arg(dir)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let rate = RigConfig::load(&repo(rig)).unwrap().sampling.rate_hz;
    let deadline = Instant::now() + Duration::from_secs(30);
    loop {
        let rows = load_meta(dir).map_or(0, |m| m.counts.samples);
        if rows as f64 >= rate {
            break;
        }
        assert!(Instant::now() < deadline, "the run never got going");
        std::thread::sleep(Duration::from_millis(50));
    }
    kill(Pid::from_raw(child.id() as i32), signal).unwrap();
    let out = child.wait_with_output().unwrap();
    (
        out.status.code(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// The recording a signal ended: cancelled, every row counted, and the driver at rest in
/// its last rows (the stop ramp was recorded and flushed).
fn assert_cancelled_recording(dir: &Path) {
    let rec = Recording::load(dir).unwrap();
    assert!(!rec.meta.complete);
    assert_eq!(rec.meta.end_reason.as_deref(), Some("cancelled"));
    assert_eq!(rec.meta.counts.samples as usize, rec.len());
    let n = rec.len();
    let tail = (n - 5..n).map(|i| rec.driver_angle_deg[i]);
    let (lo, hi) = tail.fold((f64::MAX, f64::MIN), |(l, h), a| (l.min(a), h.max(a)));
    assert!(
        hi - lo < 0.5,
        "the driver was still turning in the last rows"
    );
}

/// Guards SIGTERM on the stepper bench: exit 143, recording cancelled and flushed, the
/// simulated motor disabled and still.
#[test]
fn sigterm_stops_a_stepper_run_like_ctrl_c() {
    let _serial = serial_group::real_time();
    let sim = stepper_sim::<&str>("half-turn-2to1", &[]);
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("rec");
    let (code, stderr) = measure_then_signal(
        "rigs/sim-stepper.toml",
        &[sim.path().display().to_string()],
        "data/motions/half-turn-2to1.toml",
        &dir,
        Signal::SIGTERM,
    );
    assert_eq!(code, Some(143), "{stderr}");
    assert!(stderr.contains("cancelled by SIGTERM"), "{stderr}");
    assert_cancelled_recording(&dir);
    std::thread::sleep(Duration::from_millis(100));
    let status = sim.stop().unwrap();
    assert!(!status.enabled && !status.moving, "{status:?}");
}

/// Guards SIGHUP (a closed terminal) on the Dynamixel bench: exit 129, recording cancelled
/// and flushed, the driver servo's torque off and its velocity 0.
#[test]
fn sighup_stops_a_dynamixel_run_like_ctrl_c() {
    let _serial = serial_group::real_time();
    let sim = dxl_sim::<&str>("half-turn-2to1", &[]);
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("rec");
    let (code, stderr) = measure_then_signal(
        "rigs/sim-dynamixel.toml",
        &[sim.path().display().to_string()],
        "data/motions/half-turn-2to1.toml",
        &dir,
        Signal::SIGHUP,
    );
    assert_eq!(code, Some(129), "{stderr}");
    assert!(stderr.contains("cancelled by SIGHUP"), "{stderr}");
    assert_cancelled_recording(&dir);
    let bus = sim.bus();
    assert!(!bus.driver().torque_enabled());
    assert_eq!(bus.driver().present_velocity(), 0);
}

/// Guards SIGTERM on the mixed bench (servo driver, firmware sensor board): exit 143,
/// recording cancelled and flushed, the driver servo stopped with its torque off.
#[test]
fn sigterm_stops_a_mixed_run_like_ctrl_c() {
    let _serial = serial_group::real_time();
    let rig = RigConfig::load(&repo("rigs/sim-dynamixel-imu.toml")).unwrap();
    let sim = mixed::spawn(&rig, motion("cone-sweep"), PlantConfig::default()).unwrap();
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("rec");
    let (code, stderr) = measure_then_signal(
        "rigs/sim-dynamixel-imu.toml",
        &sim.port_overrides(),
        "data/motions/cone-sweep.toml",
        &dir,
        Signal::SIGTERM,
    );
    assert_eq!(code, Some(143), "{stderr}");
    assert_cancelled_recording(&dir);
    let bus = sim.bus().bus();
    assert!(!bus.driver().torque_enabled());
    assert_eq!(bus.driver().present_velocity(), 0);
}
