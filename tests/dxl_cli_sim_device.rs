//! `mpc-rig sim-device dynamixel` as a user runs it: the pseudo-terminal path on the first
//! line of stdout, a bus a host can talk to, clear errors for bad arguments, and the
//! configured unplug.

use std::process::Command;
use std::time::{Duration, Instant};

use crate::support::serial_group;
use crate::support::SimChild;

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

fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_mpc-rig"))
}

fn motion() -> String {
    format!(
        "{}/data/motions/half-turn-2to1.toml",
        env!("CARGO_MANIFEST_DIR")
    )
}

fn serve(extra: &[&str]) -> SimChild {
    let motion = motion();
    let mut args = vec!["sim-device", "dynamixel", "--motion", motion.as_str()];
    args.extend_from_slice(extra);
    SimChild::spawn(args)
}

/// Guards the user-facing contract: the first stdout line is a pseudo-terminal path and a
/// Protocol 2.0 host finds the XL430 driver and follower on it.
#[test]
fn prints_pty_path_and_serves_the_bus() {
    let _serial = serial_group::real_time();
    let served = serve(&[]);
    assert!(
        served.first_line.starts_with("/dev/"),
        "first line: {}",
        served.first_line
    );
    let mut bus = dynamixel2::Bus::open(&served.first_line, 57_600).expect("opens");
    assert_eq!(retry!(bus.ping(1)).unwrap().data.model, 1060);
    assert_eq!(retry!(bus.ping(2)).unwrap().data.model, 1060);
}

/// Guards custom IDs and the configured unplug: the process ends by itself after
/// `disconnect_at_s` and the port stops answering.
#[test]
fn custom_ids_and_configured_disconnect() {
    let _serial = serial_group::real_time();
    let mut served = serve(&[
        "--driver-id",
        "5",
        "--follower-id",
        "6",
        "--fault",
        "disconnect_at_s=0.8",
    ]);
    let mut bus = dynamixel2::Bus::open(&served.first_line, 1_000_000).expect("opens at any baud");
    assert_eq!(retry!(bus.ping(5)).unwrap().data.model, 1060);
    assert!(retry!(bus.ping(1)).is_err());
    let t0 = Instant::now();
    let status = loop {
        if let Some(s) = served.child.try_wait().unwrap() {
            break s;
        }
        assert!(
            t0.elapsed() < Duration::from_secs(5),
            "simulator did not end after its disconnect"
        );
        std::thread::sleep(Duration::from_millis(50));
    };
    assert!(status.success());
    assert!(
        retry!(bus.ping(5)).is_err(),
        "nothing answers after the unplug"
    );
}

/// Guards the argument errors: no target, both targets, a bad fault key, a 3R target.
#[test]
fn bad_arguments_are_refused_clearly() {
    let out = bin().args(["sim-device", "dynamixel"]).output().unwrap();
    assert!(!out.status.success());
    let out = bin()
        .args([
            "sim-device",
            "dynamixel",
            "--motion",
            &motion(),
            "--fault",
            "wobble=3",
        ])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert_eq!(
        err,
        "error: --fault `wobble=3`: unknown key `wobble`; known: backlash_deg, phase_lag_deg, \
         gain_error, encoder_noise_counts, encoder_resolution, imu_noise_deg, imu_bias_deg, \
         missed_step_prob, scale_mm, drop_prob, corrupt_prob, disconnect_at_s, dropout_at_s, \
         dropout_s, stall_at_s, stall_s, reboot_at_s, driver_fault_at_s, driver_stall_at_s, \
         jam_at_s, echo, protocol_version, seed\n"
    );
    let fig8 = format!(
        "{}/data/motions/figure-eight.toml",
        env!("CARGO_MANIFEST_DIR")
    );
    let out = bin()
        .args(["sim-device", "dynamixel", "--motion", &fig8])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert_eq!(
        err.replace(env!("CARGO_MANIFEST_DIR"), "REPO"),
        "error: motion `figure-eight` is 3R: a Dynamixel follower encoder measures one rotation \
         about z; use a 1R or 1R1T target, or measure 3R with an IMU on a firmware board \
         (`sim-device mixed --rig rigs/sim-dynamixel-imu.toml`, or the stepper bench)\n"
    );
}
