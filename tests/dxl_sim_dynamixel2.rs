//! The simulated Dynamixel bus, driven through a real pseudo-terminal by the `dynamixel2`
//! crate (an independent Protocol 2.0 host implementation): ping/scan, reads and writes with
//! error replies, sync read/write, reboot, and the follower tracking the plant model.

use std::sync::Arc;
use std::time::Duration;

use crate::support::serial_group;
use mpc_rig::rig::sim::dynamixel::control_table::{addr, mode};
use mpc_rig::rig::sim::dynamixel::{spawn, SimDynamixelOptions};
use mpc_rig::rig::sim::plant::WobbleTurn;

/// Repeat a transaction that timed out (up to 5 attempts): on a busy machine the simulator
/// thread may get the CPU later than `dynamixel2`'s fixed 34 ms reply timeout.
macro_rules! retry {
    ($e:expr) => {{
        let mut attempts = 1;
        loop {
            match $e {
                Err(dynamixel2::TransferError::ReadError(dynamixel2::ReadError::Io(ref io)))
                    if io.kind() == std::io::ErrorKind::TimedOut && attempts < 5 =>
                {
                    attempts += 1
                }
                r => break r,
            }
        }
    }};
}

fn sim() -> mpc_rig::rig::sim::dynamixel::SimDynamixelHandle {
    let opts = SimDynamixelOptions::new(Arc::new(WobbleTurn { amplitude: 0.0 }));
    spawn(opts).expect("simulator starts")
}

fn open(path: &std::path::Path) -> dynamixel2::Bus<Vec<u8>, Vec<u8>> {
    dynamixel2::Bus::open(path, 57_600).expect("pty opens as a serial port")
}

/// Guards that a host scanning the bus finds exactly the driver (1) and follower (2), both
/// reporting the XL430-W250 model number 1060.
#[test]
fn dynamixel2_scan_and_ping_find_two_xl430() {
    let _serial = serial_group::real_time();
    let sim = sim();
    let mut bus = open(sim.path());
    // A scan waits a fixed time for all replies; on a busy machine repeat it.
    let mut found: Vec<(u8, u16)> = Vec::new();
    for _ in 0..3 {
        found = bus
            .scan()
            .expect("scan sent")
            .into_iter()
            .filter_map(|r| r.ok().map(|r| (r.motor_id, r.data.model)))
            .collect();
        if found.len() == 2 {
            break;
        }
    }
    assert_eq!(found, vec![(1, 1060), (2, 1060)]);
    let ping = retry!(bus.ping(2)).expect("ping 2");
    assert_eq!(ping.data.model, 1060);
    assert!(retry!(bus.ping(3)).is_err(), "no servo 3");
}

/// Guards reads, writes and their error replies as a host library sees them: factory baud
/// index 1, an EEPROM write refused while torque is on (Access error 7), a write to a
/// read-only item refused.
#[test]
fn dynamixel2_read_write_and_errors() {
    let _serial = serial_group::real_time();
    let sim = sim();
    let mut bus = open(sim.path());
    assert_eq!(retry!(bus.read_u8(1, addr::BAUD_RATE)).unwrap().data, 1);
    assert_eq!(
        retry!(bus.read_u16(1, addr::MODEL_NUMBER)).unwrap().data,
        1060
    );
    retry!(bus.write_u8(1, addr::TORQUE_ENABLE, 1)).unwrap();
    match retry!(bus.write_u8(1, addr::OPERATING_MODE, mode::VELOCITY)) {
        Err(dynamixel2::TransferError::ReadError(dynamixel2::ReadError::MotorError(e))) => {
            assert_eq!(e.raw & 0x7F, 7)
        }
        other => panic!("expected an access error, got {other:?}"),
    }
    assert!(retry!(bus.write_u32(1, addr::PRESENT_POSITION, 5)).is_err());
    retry!(bus.write_u8(1, addr::TORQUE_ENABLE, 0)).unwrap();
    retry!(bus.write_u8(1, addr::OPERATING_MODE, mode::VELOCITY)).unwrap();
    assert_eq!(
        retry!(bus.read_u8(1, addr::OPERATING_MODE)).unwrap().data,
        mode::VELOCITY
    );
    // Reboot: RAM back to defaults, EEPROM kept.
    retry!(bus.write_u8(1, addr::LED, 1)).unwrap();
    retry!(bus.reboot(1)).unwrap();
    assert_eq!(retry!(bus.read_u8(1, addr::LED)).unwrap().data, 0);
    assert_eq!(
        retry!(bus.read_u8(1, addr::OPERATING_MODE)).unwrap().data,
        mode::VELOCITY
    );
}

/// Guards the bench behaviour end to end: the driver spun in velocity mode through a sync
/// write, the follower read by sync read follows the target law (one follower turn per
/// driver turn for this law), and the realtime tick advances in milliseconds.
#[test]
fn dynamixel2_sync_read_follower_tracks_driver() {
    let _serial = serial_group::real_time();
    let sim = sim();
    let mut bus = open(sim.path());
    retry!(bus.write_u8(1, addr::OPERATING_MODE, mode::VELOCITY)).unwrap();
    retry!(bus.write_u8(1, addr::TORQUE_ENABLE, 1)).unwrap();
    let start = retry!(bus.sync_read_u32(&[1, 2], addr::PRESENT_POSITION)).unwrap();
    assert_eq!(start.len(), 2);
    // 131 × 0.229 rpm ≈ 30 rpm.
    bus.sync_write_u32(
        addr::GOAL_VELOCITY,
        &[dynamixel2::instructions::SyncWriteData {
            motor_id: 1,
            data: 131u32,
        }],
    )
    .unwrap();
    // One read of Realtime Tick (120) through Present Position (132) is a consistent
    // snapshot of the servo; motion is checked against the servo's own clock, which a busy
    // machine cannot skew.
    let snapshot = |bus: &mut dynamixel2::Bus<Vec<u8>, Vec<u8>>| {
        let d = retry!(bus.read(1, addr::REALTIME_TICK, 16)).unwrap().data;
        let tick = u16::from_le_bytes([d[0], d[1]]);
        let vel = i32::from_le_bytes([d[8], d[9], d[10], d[11]]);
        let pos = i32::from_le_bytes([d[12], d[13], d[14], d[15]]);
        (tick, vel, pos)
    };
    std::thread::sleep(Duration::from_millis(100));
    let (tick_a, vel_a, pos_a) = snapshot(&mut bus);
    assert_eq!(vel_a, 131, "running at the goal velocity");
    std::thread::sleep(Duration::from_millis(300));
    let (tick_b, _, pos_b) = snapshot(&mut bus);
    let dt_s = f64::from((i32::from(tick_b) - i32::from(tick_a)).rem_euclid(32768)) / 1000.0;
    let expected = 131.0 * 0.229 / 60.0 * 4096.0 * dt_s;
    assert!(
        dt_s >= 0.29,
        "servo clock advanced {dt_s} s in a 0.3 s sleep"
    );
    assert!(
        (f64::from(pos_b - pos_a) - expected).abs() < 4.0 + 0.01 * expected,
        "driver moved {} in {dt_s} s of servo time, expected ≈{expected}",
        pos_b - pos_a
    );
    let now = retry!(bus.sync_read_u32(&[1, 2], addr::PRESENT_POSITION)).unwrap();
    let driver_moved = now[0].data as i32 - start[0].data as i32;
    let follower_moved = now[1].data as i32 - start[1].data as i32;
    // This test's law is θ = φ; both positions come from one sync read.
    assert!(driver_moved > 0);
    assert!(
        (follower_moved - driver_moved).abs() <= 8,
        "follower {follower_moved} vs driver {driver_moved}"
    );
    retry!(bus.write_u8(1, addr::TORQUE_ENABLE, 0)).unwrap();
    assert_eq!(sim.bus().driver().present_velocity(), 0);
}
