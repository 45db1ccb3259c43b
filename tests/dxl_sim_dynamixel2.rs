//! The simulated Dynamixel bus, driven through a real pseudo-terminal by the `dynamixel2`
//! crate (an independent Protocol 2.0 host implementation): ping/scan, reads and writes with
//! error replies, sync read/write, reboot, and the follower tracking the plant model.

use std::sync::Arc;
use std::time::{Duration, Instant};

use mpc_rig::rig::sim::dynamixel::control_table::{addr, mode};
use mpc_rig::rig::sim::dynamixel::{spawn, SimDynamixelOptions};
use mpc_rig::rig::sim::plant::WobbleTurn;

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
    let sim = sim();
    let mut bus = open(sim.path());
    let found: Vec<(u8, u16)> = bus
        .scan()
        .expect("scan sent")
        .into_iter()
        .map(|r| {
            let r = r.expect("valid reply");
            (r.motor_id, r.data.model)
        })
        .collect();
    assert_eq!(found, vec![(1, 1060), (2, 1060)]);
    let ping = bus.ping(2).expect("ping 2");
    assert_eq!(ping.data.model, 1060);
    assert!(bus.ping(3).is_err(), "no servo 3");
}

/// Guards reads, writes and their error replies as a host library sees them: factory baud
/// index 1, an EEPROM write refused while torque is on (Access error 7), a write to a
/// read-only item refused.
#[test]
fn dynamixel2_read_write_and_errors() {
    let sim = sim();
    let mut bus = open(sim.path());
    assert_eq!(bus.read_u8(1, addr::BAUD_RATE).unwrap().data, 1);
    assert_eq!(bus.read_u16(1, addr::MODEL_NUMBER).unwrap().data, 1060);
    bus.write_u8(1, addr::TORQUE_ENABLE, 1).unwrap();
    match bus.write_u8(1, addr::OPERATING_MODE, mode::VELOCITY) {
        Err(dynamixel2::TransferError::ReadError(dynamixel2::ReadError::MotorError(e))) => {
            assert_eq!(e.raw & 0x7F, 7)
        }
        other => panic!("expected an access error, got {other:?}"),
    }
    assert!(bus.write_u32(1, addr::PRESENT_POSITION, 5).is_err());
    bus.write_u8(1, addr::TORQUE_ENABLE, 0).unwrap();
    bus.write_u8(1, addr::OPERATING_MODE, mode::VELOCITY)
        .unwrap();
    assert_eq!(
        bus.read_u8(1, addr::OPERATING_MODE).unwrap().data,
        mode::VELOCITY
    );
    // Reboot: RAM back to defaults, EEPROM kept.
    bus.write_u8(1, addr::LED, 1).unwrap();
    bus.reboot(1).unwrap();
    assert_eq!(bus.read_u8(1, addr::LED).unwrap().data, 0);
    assert_eq!(
        bus.read_u8(1, addr::OPERATING_MODE).unwrap().data,
        mode::VELOCITY
    );
}

/// Guards the bench behaviour end to end: the driver spun in velocity mode through a sync
/// write, the follower read by sync read follows the target law (one follower turn per
/// driver turn for this law), and the realtime tick advances in milliseconds.
#[test]
fn dynamixel2_sync_read_follower_tracks_driver() {
    let sim = sim();
    let mut bus = open(sim.path());
    bus.write_u8(1, addr::OPERATING_MODE, mode::VELOCITY)
        .unwrap();
    bus.write_u8(1, addr::TORQUE_ENABLE, 1).unwrap();
    let start = bus.sync_read_u32(&[1, 2], addr::PRESENT_POSITION).unwrap();
    assert_eq!(start.len(), 2);
    let tick0 = bus.read_u16(1, addr::REALTIME_TICK).unwrap().data;
    // 131 × 0.229 rpm ≈ 30 rpm.
    bus.sync_write_u32(
        addr::GOAL_VELOCITY,
        &[dynamixel2::instructions::SyncWriteData {
            motor_id: 1,
            data: 131u32,
        }],
    )
    .unwrap();
    let t0 = Instant::now();
    std::thread::sleep(Duration::from_millis(400));
    let now = bus.sync_read_u32(&[1, 2], addr::PRESENT_POSITION).unwrap();
    let elapsed = t0.elapsed().as_secs_f64();
    let driver_moved = now[0].data as i32 - start[0].data as i32;
    let follower_moved = now[1].data as i32 - start[1].data as i32;
    let expected = 131.0 * 0.229 / 60.0 * 4096.0 * elapsed;
    assert!(
        (f64::from(driver_moved) - expected).abs() < 0.1 * expected,
        "driver moved {driver_moved}, expected ≈{expected}"
    );
    assert!(
        (follower_moved - driver_moved).abs() <= 8,
        "follower {follower_moved} vs driver {driver_moved}"
    );
    let tick1 = bus.read_u16(1, addr::REALTIME_TICK).unwrap().data;
    let dt_ms = (i32::from(tick1) - i32::from(tick0)).rem_euclid(32768);
    assert!((380..=1000).contains(&dt_ms), "tick advanced {dt_ms} ms");
    bus.write_u8(1, addr::TORQUE_ENABLE, 0).unwrap();
    assert_eq!(sim.bus().driver().present_velocity(), 0);
}
