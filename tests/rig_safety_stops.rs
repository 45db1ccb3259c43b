//! The session stops the motor when the driver does not follow its command or the
//! mechanism jams (issue 16: an overloaded Dynamixel driver froze and the run went on to
//! `max_run_s` with the overload unnamed). Over the simulated stepper, Dynamixel and mixed
//! benches, a driver hardware fault, a blocked driver shaft and a follower that binds each
//! end the run within 0.5 s with the reason named, the driver angle recorded in the
//! sidecar's `safety_stop`, the recording kept, and the motor stopped.

use std::path::Path;

use mpc_rig::rig::config::RigConfig;
use mpc_rig::rig::recording::{flags, Recording, SafetyStop};
use mpc_rig::rig::session::{measure, EndReason};
use mpc_rig::rig::sim::mixed;
use mpc_rig::rig::sim::plant::PlantConfig;

use crate::support::bench::{self, motion, options, repo};
use crate::support::serial_group;

/// The fault injected 2 s after the simulator starts: well into the run (setup takes a
/// fraction of a second, the plan several seconds).
const AT: &str = "2.0";

/// How soon after its onset a problem must have stopped the run, device time.
const STOP_WITHIN_US: u64 = 500_000;

/// A session of three cycles at 40 rpm; how it ended.
fn session(rig: &str, ports: Vec<String>, motion_name: &str, out: &Path) -> EndReason {
    let mut o = options(rig, ports, motion_name, out);
    o.cycles = 3;
    measure(&mut o).expect("the session runs").end
}

/// The recording of a run the session stopped: incomplete, its `safety_stop` of `kind`,
/// decided within [`STOP_WITHIN_US`] of where the problem shows in the rows.
fn stopped_recording(dir: &Path, kind: &str) -> (Recording, SafetyStop) {
    let rec = Recording::load(dir).unwrap();
    assert!(!rec.meta.complete);
    let stop = rec
        .meta
        .safety_stop
        .clone()
        .expect("the sidecar records the stop");
    assert_eq!(stop.kind, kind, "{stop:?}");
    assert!(stop.onset_device_time_us <= stop.detected_device_time_us);
    (rec, stop)
}

/// Device time from which the driver angle no longer advanced (within 0.5°).
fn driver_stopped_at(rec: &Recording) -> u64 {
    let last = *rec.driver_angle_deg.last().unwrap();
    let i = rec
        .driver_angle_deg
        .iter()
        .position(|a| (last - a).abs() < 0.5)
        .unwrap();
    rec.device_time_us[i]
}

/// `fault` at [`AT`].
fn at(fault: &str) -> [String; 1] {
    [format!("{fault}={AT}")]
}

/// A session on a simulated stepper bench with `fault`: how it ended, and the folder
/// holding its recording. Checks that the motor ended disabled and still.
fn stepper_run(fault: &str) -> (EndReason, tempfile::TempDir) {
    let sim = bench::stepper_sim("half-turn-2to1", &at(fault));
    let tmp = tempfile::tempdir().unwrap();
    let end = session(
        "rigs/sim-stepper.toml",
        vec![sim.path().display().to_string()],
        "half-turn-2to1",
        tmp.path(),
    );
    std::thread::sleep(std::time::Duration::from_millis(100));
    let status = sim.stop().unwrap();
    assert!(!status.enabled && !status.moving, "{fault}: {status:?}");
    (end, tmp)
}

fn dxl_sim(fault: &str) -> mpc_rig::rig::sim::dynamixel::SimDynamixelHandle {
    bench::dxl_sim("half-turn-2to1", &at(fault))
}

fn mixed_sim(fault: &str) -> mixed::SimMixedHandle {
    let rig = RigConfig::load(&repo("rigs/sim-dynamixel-imu.toml")).unwrap();
    mixed::spawn(
        &rig,
        motion("cone-sweep"),
        PlantConfig::from_faults(&at(fault)).unwrap(),
    )
    .unwrap()
}

/// Guards the stepper bench: a failed STEP output makes the firmware latch its emergency
/// stop, which the session names at once; the motor ends disabled and still.
#[test]
fn stepper_driver_fault_is_named_and_stops_the_run() {
    let _serial = serial_group::real_time();
    let (end, tmp) = stepper_run("driver_fault_at_s");
    assert!(
        matches!(&end, EndReason::DriverStalled(m) if m.contains("emergency stop")),
        "{end}"
    );
    let (rec, stop) = stopped_recording(tmp.path(), "driver fault");
    let first = rec
        .flags
        .iter()
        .position(|f| f & flags::DRIVER_FAULT != 0)
        .expect("the fault is flagged in the rows");
    assert_eq!(stop.onset_device_time_us, rec.device_time_us[first]);
}

/// Guards the stepper bench's blind spot and its cover: a blocked shaft loses every step
/// while the firmware goes on counting them, so the driver angle keeps advancing; the
/// follower stops, and the jam watch stops the run within 0.5 s of the follower leaving the
/// target, recording the driver angle there.
#[test]
fn stepper_blocked_shaft_is_caught_by_the_follower() {
    let _serial = serial_group::real_time();
    let (end, tmp) = stepper_run("driver_stall_at_s");
    assert!(matches!(end, EndReason::Jammed { .. }), "{end}");
    let (_, stop) = stopped_recording(tmp.path(), "jam");
    assert!(stop.detected_device_time_us - stop.onset_device_time_us <= STOP_WITHIN_US);
}

/// Guards the jam on the stepper bench: the follower binds while the driver turns on; the
/// run stops with the driver angle where the follower left the target.
#[test]
fn stepper_jam_stops_the_run_at_its_driver_angle() {
    let _serial = serial_group::real_time();
    let (end, tmp) = stepper_run("jam_at_s");
    let EndReason::Jammed {
        driver_angle_deg, ..
    } = end
    else {
        panic!("expected a jam, got {end}");
    };
    let (rec, stop) = stopped_recording(tmp.path(), "jam");
    assert!((stop.driver_angle_deg - driver_angle_deg).abs() < 1e-9);
    assert!(stop.detected_device_time_us - stop.onset_device_time_us <= STOP_WITHIN_US);
    // The motor was stopped right after: it was at rest within 0.5 s (plus its ramp down).
    assert!(driver_stopped_at(&rec) - stop.detected_device_time_us <= STOP_WITHIN_US);
}

/// Guards the Dynamixel bench, each fault on a bench of its own: an overload (the issue's
/// case) is named from the driver's Hardware Error Status; a blocked shaft with no error
/// is caught within 0.5 s of the driver stopping; a follower that binds is a jam. The
/// driver servo ends with its torque off.
#[test]
fn dynamixel_faults_stalls_and_jams_stop_the_run() {
    let _serial = serial_group::real_time();
    for (fault, check) in [
        (
            "driver_fault_at_s",
            &(|e: &EndReason| matches!(e, EndReason::DriverStalled(m) if m.contains("overload")))
                as &dyn Fn(&EndReason) -> bool,
        ),
        (
            "driver_stall_at_s",
            &|e: &EndReason| matches!(e, EndReason::DriverStalled(m) if m.contains("moved")),
        ),
        ("jam_at_s", &|e: &EndReason| {
            matches!(e, EndReason::Jammed { .. })
        }),
    ] {
        let sim = dxl_sim(fault);
        let tmp = tempfile::tempdir().unwrap();
        let end = session(
            "rigs/sim-dynamixel.toml",
            vec![sim.path().display().to_string()],
            "half-turn-2to1",
            tmp.path(),
        );
        assert!(check(&end), "{fault}: {end}");
        let kind = match fault {
            "driver_fault_at_s" => "driver fault",
            "driver_stall_at_s" => "driver stall",
            _ => "jam",
        };
        let (rec, stop) = stopped_recording(tmp.path(), kind);
        if fault == "driver_stall_at_s" {
            let stalled = driver_stopped_at(&rec);
            assert!(
                stop.detected_device_time_us - stalled <= STOP_WITHIN_US,
                "stalled at {stalled} µs, stopped at {} µs",
                stop.detected_device_time_us
            );
        }
        let bus = sim.bus();
        assert!(!bus.driver().torque_enabled(), "{fault}: torque on");
        assert_eq!(bus.driver().present_velocity(), 0, "{fault}: still turning");
    }
}

/// Guards the mixed bench (servo driver, IMU on a firmware board, 3R): the bus's driver
/// overload is named, a blocked driver is caught by the driver angle interpolated onto the
/// board's timeline, and a 3R follower that binds is a jam by its geodesic error.
#[test]
fn mixed_faults_stalls_and_jams_stop_the_run() {
    let _serial = serial_group::real_time();
    for (fault, kind) in [
        ("driver_fault_at_s", "driver fault"),
        ("driver_stall_at_s", "driver stall"),
        ("jam_at_s", "jam"),
    ] {
        let sim = mixed_sim(fault);
        let tmp = tempfile::tempdir().unwrap();
        let end = session(
            "rigs/sim-dynamixel-imu.toml",
            sim.port_overrides(),
            "cone-sweep",
            tmp.path(),
        );
        let (rec, stop) = stopped_recording(tmp.path(), kind);
        match kind {
            "jam" => assert!(matches!(end, EndReason::Jammed { .. }), "{end}"),
            "driver fault" => assert!(
                matches!(&end, EndReason::DriverStalled(m) if m.contains("overload")),
                "{end}"
            ),
            _ => assert!(matches!(end, EndReason::DriverStalled(_)), "{end}"),
        }
        if kind == "driver stall" {
            assert!(stop.detected_device_time_us - driver_stopped_at(&rec) <= STOP_WITHIN_US);
        }
        let bus = sim.bus().bus();
        assert!(!bus.driver().torque_enabled(), "{fault}: torque on");
        assert_eq!(bus.driver().present_velocity(), 0, "{fault}: still turning");
    }
}
