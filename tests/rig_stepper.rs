//! Full sessions against the simulated stepper bench (the real firmware core behind a real
//! pseudo-terminal), driven through the ordinary stepper backend: a clean run, a run with
//! link and mechanism faults, a brief unplug that must be survived, a permanent unplug
//! that must leave an incomplete recording, and a firmware with another protocol version.

use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;
use std::sync::Arc;

use crate::support::serial_group;
use mpc_rig::motion::Motion;
use mpc_rig::rig::backend::stepper::StepperBench;
use mpc_rig::rig::config::RigConfig;
use mpc_rig::rig::recording::{flags, Phase, Recording};
use mpc_rig::rig::session::{measure, EndReason, MeasureOptions, MeasureOutcome, TargetSpec};
use mpc_rig::rig::sim::plant::PlantConfig;
use mpc_rig::rig::sim::stepper::{self, Mechanics, SimHandle, SimStatus, SimStepperOptions};
use mpc_rig::rig::RigError;

fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

fn motion_path() -> PathBuf {
    root().join("data/motions/half-turn-2to1.toml")
}

fn sim(faults: &[&str]) -> SimHandle {
    stepper::spawn(SimStepperOptions {
        target: Motion::from_file(&motion_path()).unwrap(),
        plant: PlantConfig::from_faults(faults).unwrap(),
        mechanics: Mechanics::default(),
        link: None,
        driver: None,
    })
    .unwrap()
}

fn session(sim: &SimHandle, out: &Path, cycles: u32, reverse: bool) -> MeasureOutcome {
    let mut opts = MeasureOptions {
        rig_path: root().join("rigs/sim-stepper.toml"),
        ports: vec![sim.path().display().to_string()],
        target: TargetSpec::Motion(motion_path()),
        speed_rpm: 90.0,
        cycles,
        settle_cycles: 1,
        reverse,
        out_dir: Some(out.to_path_buf()),
        replace: false,
        cancel: Arc::new(AtomicBool::new(false)),
        progress: None,
        live: None,
    };
    measure(&mut opts).unwrap()
}

/// The simulator's state once the host is done: the motor must be de-energized and still.
fn assert_motor_stopped(status: &SimStatus) {
    assert!(!status.enabled, "driver still enabled: {status:?}");
    assert!(!status.moving, "motor still stepping: {status:?}");
}

/// Guards: a clean forward+reverse session at 1 kHz records every sample (no gaps, no
/// missing samples), follows the target law to within the encoder's quantization (so each
/// sensor reading and step count belong to the same instant), and ends with the motor
/// stopped.
#[test]
fn full_session_against_simulated_stepper_bench() {
    let _serial = serial_group::real_time();
    let dir = tempfile::tempdir().unwrap();
    let sim = sim(&[]);
    let out = session(&sim, dir.path(), 1, true);
    std::thread::sleep(std::time::Duration::from_millis(100));
    let status = sim.stop().unwrap();
    assert!(out.complete, "{:?}", out.end);
    let rec = Recording::load(dir.path()).unwrap();
    let c = rec.meta.counts;
    assert_eq!(
        (c.gaps, c.missing_samples, c.crc_errors),
        (0, 0, 0),
        "{c:?}"
    );
    assert_eq!(c.samples as usize, rec.len());
    // 1 kHz of device time, every sample present.
    let span_s = (rec.device_time_us[rec.len() - 1] - rec.device_time_us[0]) as f64 / 1e6;
    assert!(
        ((rec.len() - 1) as f64 - span_s * 1000.0).abs() < 1.5,
        "{} in {span_s}",
        rec.len()
    );
    assert!(rec.phase.contains(&Phase::Forward) && rec.phase.contains(&Phase::Reverse));
    assert_eq!(rec.meta.device.board.as_deref(), Some("sim-stepper"));
    // The follower reading tracks the target law (up to a constant offset).
    let motion = Motion::from_file(&motion_path()).unwrap();
    let enc = rec.sensor("follower_rz_counts").unwrap();
    let errs: Vec<f64> = (0..rec.len())
        .filter(|&i| rec.phase[i] == Phase::Forward)
        .map(|i| {
            let target = motion.angle_z(rec.driver_angle_deg[i] / 360.0).unwrap()[0].to_degrees();
            let measured = enc[i] * 360.0 / 4096.0;
            (measured - target + 540.0).rem_euclid(360.0) - 180.0
        })
        .collect();
    let mean = errs.iter().sum::<f64>() / errs.len() as f64;
    let worst = errs.iter().map(|e| (e - mean).abs()).fold(0.0, f64::max);
    // An ideal plant leaves only the AS5600's quantization (360°/4096 = 0.088°, ±0.044°
    // about the mean): a reading taken right after a step in the same poll must see the
    // shaft after that step (one microstep is 0.11° of driver, up to 0.17° of follower).
    assert!(
        worst < 0.06,
        "follower deviates {worst}° from the target law"
    );
    assert_motor_stopped(&status);
}

/// Guards: with dropped and corrupted bytes, missed steps, backlash and noise injected,
/// the session still completes, counts the gaps and CRC errors it saw, keeps a readable
/// recording, and ends with the motor stopped.
#[test]
fn faulty_link_session_survives_and_counts() {
    let _serial = serial_group::real_time();
    let dir = tempfile::tempdir().unwrap();
    let sim = sim(&[
        "drop_prob=0.0005",
        "corrupt_prob=0.0005",
        "missed_step_prob=0.001",
        "backlash_deg=1",
        "encoder_noise_counts=1",
        "seed=7",
    ]);
    let out = session(&sim, dir.path(), 2, false);
    std::thread::sleep(std::time::Duration::from_millis(100));
    let status = sim.stop().unwrap();
    assert!(out.complete, "{:?}", out.end);
    let rec = Recording::load(dir.path()).unwrap();
    let c = rec.meta.counts;
    assert!(status.bytes_dropped + status.bytes_corrupted > 0);
    assert!(c.gaps > 0 && c.missing_samples > 0, "{c:?}");
    assert!(c.crc_errors + c.decode_errors > 0, "{c:?}");
    assert!(status.missed_steps > 0);
    assert!(rec.flags.iter().any(|f| f & flags::GAP_BEFORE != 0));
    assert_motor_stopped(&status);
}

/// Guards: a brief unplug (the device disappears for 0.4 s and comes back on the same
/// path) is survived: one reconnect, the recording is complete and continuous, and the
/// first sample after it is flagged.
#[test]
fn brief_unplug_reconnects_without_losing_recording() {
    let _serial = serial_group::real_time();
    let dir = tempfile::tempdir().unwrap();
    let sim = sim(&["dropout_at_s=1.5", "dropout_s=0.4"]);
    let out = session(&sim, dir.path(), 2, false);
    let status = sim.stop().unwrap();
    assert!(out.complete, "{:?}", out.end);
    assert_eq!(status.dropouts, 1);
    let rec = Recording::load(dir.path()).unwrap();
    assert_eq!(rec.meta.counts.reconnects, 1);
    assert!(rec.flags.iter().any(|f| f & flags::RECONNECTED != 0));
    assert!(rec.device_time_us.windows(2).all(|w| w[1] > w[0]));
    assert_motor_stopped(&status);
}

/// Guards: a permanent unplug mid-run ends the session with `Disconnected`, keeps the
/// samples recorded so far in a valid recording marked incomplete, and does not panic.
#[test]
fn unplug_mid_run_keeps_incomplete_recording() {
    let _serial = serial_group::real_time();
    let dir = tempfile::tempdir().unwrap();
    let sim = sim(&["disconnect_at_s=1.5"]);
    let out = session(&sim, dir.path(), 3, false);
    let status = sim.stop().unwrap();
    assert!(status.disconnected);
    assert!(!out.complete);
    assert!(
        matches!(out.end, EndReason::Disconnected(_)),
        "{:?}",
        out.end
    );
    let rec = Recording::load(dir.path()).unwrap();
    assert!(!rec.meta.complete);
    assert!(rec
        .meta
        .end_reason
        .as_deref()
        .unwrap()
        .contains("disconnected"));
    assert!(rec.len() > 500, "{}", rec.len());
}

/// Guards: a firmware speaking another protocol version is refused at the handshake with
/// a message naming both versions and what to do.
#[test]
fn version_mismatch_is_reported_clearly() {
    let _serial = serial_group::real_time();
    let sim = sim(&["protocol_version=9"]);
    let mut rig = RigConfig::load(&root().join("rigs/sim-stepper.toml")).unwrap();
    rig.apply_port_overrides(&[sim.path().display().to_string()])
        .unwrap();
    let err = StepperBench::open(&rig).err().unwrap();
    assert!(
        matches!(err, RigError::VersionMismatch { device: 9, .. }),
        "{err}"
    );
    let msg = err
        .to_string()
        .replace(&sim.path().display().to_string(), "PORT");
    assert_eq!(
        msg,
        "PORT: firmware 0.1.0 speaks wire protocol version 9, this host speaks 1; flash a \
         matching firmware (see firmware/README.md) or use a matching mpc-rig"
    );
    drop(sim);
}

/// Guards: the 3R path — a BNO055 bench (rigs/pico-bno055.toml) on the simulated stepper
/// bench records unit quaternions that follow the target orientation (up to the constant
/// IMU world frame, measured at home), with repeated IMU values flagged stale.
#[test]
fn imu_bench_records_follower_orientation() {
    let _serial = serial_group::real_time();
    let dir = tempfile::tempdir().unwrap();
    let rig_path = root().join("rigs/pico-bno055.toml");
    let motion_file = root().join("data/motions/figure-eight.toml");
    let rig = RigConfig::load(&rig_path).unwrap();
    let sim = stepper::spawn(SimStepperOptions {
        target: Motion::from_file(&motion_file).unwrap(),
        plant: PlantConfig::default(),
        mechanics: Mechanics::from_rig(&rig).unwrap(),
        link: None,
        driver: None,
    })
    .unwrap();
    let mut opts = MeasureOptions {
        rig_path,
        ports: vec![format!("firmware={}", sim.path().display())],
        target: TargetSpec::Motion(motion_file.clone()),
        speed_rpm: 30.0,
        cycles: 1,
        settle_cycles: 0,
        reverse: false,
        out_dir: Some(dir.path().to_path_buf()),
        replace: false,
        cancel: Arc::new(AtomicBool::new(false)),
        progress: None,
        live: None,
    };
    let out = measure(&mut opts).unwrap();
    let status = sim.stop().unwrap();
    assert!(out.complete, "{:?}", out.end);
    let rec = Recording::load(dir.path()).unwrap();
    let imu = match &rec.meta.rig.sensors[0] {
        mpc_rig::rig::config::SensorConfig::Imu(i) => i.clone(),
        other => panic!("{other:?}"),
    };
    let col = |n: &str| rec.sensor(n).unwrap();
    let (w, x, y, z) = (col("imu_qw"), col("imu_qx"), col("imu_qy"), col("imu_qz"));
    let motion = Motion::from_file(&motion_file).unwrap();
    let q_at = |i: usize| {
        imu.follower_rotation(nalgebra::UnitQuaternion::from_quaternion(
            nalgebra::Quaternion::new(w[i], x[i], y[i], z[i]),
        ))
    };
    // The IMU's world frame at home, then the error along the run.
    let world = motion.sample(0.0).rotation * q_at(0).inverse();
    let mut worst: f64 = 0.0;
    for i in (0..rec.len()).step_by(25) {
        let n = (w[i] * w[i] + x[i] * x[i] + y[i] * y[i] + z[i] * z[i]).sqrt();
        assert!((n - 1.0).abs() < 2e-3, "quaternion norm {n}");
        let target = motion.sample(rec.driver_angle_deg[i] / 360.0).rotation;
        worst = worst.max((world * q_at(i)).angle_to(&target).to_degrees());
    }
    // 100 Hz IMU at 30 rpm: the held value lags up to 10 ms = 1.8° of driver angle.
    assert!(worst < 3.0, "orientation error up to {worst}°");
    let stale = rec
        .flags
        .iter()
        .filter(|f| *f & flags::IMU_STALE != 0)
        .count();
    let frac = stale as f64 / rec.len() as f64;
    assert!((0.6..0.95).contains(&frac), "stale fraction {frac}");
    assert_motor_stopped(&status);
}
