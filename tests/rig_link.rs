//! The stepper-firmware backend's first contact through real pseudo-terminals: a silent
//! port and a port with a foreign device each give a clear message naming the port.

use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Duration;

use crate::support::serial_group;
use mpc_rig::rig::backend::stepper::StepperBench;
use mpc_rig::rig::config::RigConfig;
use mpc_rig::rig::sim::pty::Pty;
use mpc_rig::rig::RigError;

fn rig_on(path: &Path) -> RigConfig {
    let mut rig =
        RigConfig::load(&Path::new(env!("CARGO_MANIFEST_DIR")).join("rigs/sim-stepper.toml"))
            .unwrap();
    rig.apply_port_overrides(&[path.display().to_string()])
        .unwrap();
    rig
}

/// Guards: a port where nothing answers yields "no answer to the handshake", naming it
/// (the whole message).
#[test]
fn silent_port_is_reported_as_no_answer() {
    let pty = Pty::open().unwrap();
    let err = StepperBench::open(&rig_on(pty.path())).err().unwrap();
    assert!(matches!(err, RigError::NoAnswer { .. }), "{err}");
    let msg = err
        .to_string()
        .replace(&pty.path().display().to_string(), "PORT");
    assert_eq!(
        msg,
        "PORT: no answer to the handshake within 1500 ms (is the firmware flashed and running? \
         is this the right port?)"
    );
}

/// Guards: a port with another device talking (here a GPS-like NMEA text stream) is
/// reported as the wrong device, with what was seen, not as a hang or a panic.
#[test]
fn foreign_device_is_reported_as_wrong_device() {
    let _serial = serial_group::real_time();
    let mut pty = Pty::open().unwrap();
    let path = pty.path().to_path_buf();
    let stop = Arc::new(AtomicBool::new(false));
    let stop2 = stop.clone();
    let talker = std::thread::spawn(move || {
        let mut buf = [0u8; 256];
        while !stop2.load(Ordering::Relaxed) {
            let _ = pty.read_available(&mut buf);
            let _ = pty.write_lossy(
                b"$GPGGA,123519,4807.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,*47\r\n",
            );
            std::thread::sleep(Duration::from_millis(20));
        }
    });
    let err = StepperBench::open(&rig_on(&path)).err().unwrap();
    stop.store(true, Ordering::Relaxed);
    talker.join().unwrap();
    assert!(matches!(err, RigError::WrongDevice { .. }), "{err}");
    let msg = err.to_string();
    assert!(
        msg.contains("does not speak the mpc-rig firmware protocol"),
        "{msg}"
    );
    assert!(msg.contains("bytes arrived"), "{msg}");
}

/// Guards: a path that does not exist is an open error that names it and says what to
/// check (the whole message).
#[test]
fn missing_port_is_an_open_error() {
    let err = StepperBench::open(&rig_on(Path::new("/dev/mpc-rig-no-such-port")))
        .err()
        .unwrap();
    assert_eq!(
        err.to_string(),
        "cannot open serial port /dev/mpc-rig-no-such-port: No such file or directory (is the \
         device plugged in, and is the path right? `mpc-rig ports` lists ports)"
    );
}

/// Guards: pointing the stepper rig at a Dynamixel bus (the simulated one, which ignores
/// frames that are not Protocol 2.0 packets) fails the handshake with a message that asks
/// whether this is the right port, instead of hanging.
#[test]
fn dynamixel_bus_on_the_port_is_reported() {
    let _serial = serial_group::real_time();
    use mpc_rig::rig::sim::dynamixel::{self, MotionTarget, SimDynamixelOptions};
    let motion = mpc_rig::motion::Motion::from_file(
        &Path::new(env!("CARGO_MANIFEST_DIR")).join("data/motions/half-turn-2to1.toml"),
    )
    .unwrap();
    let sim = dynamixel::spawn(SimDynamixelOptions::new(Arc::new(
        MotionTarget::new(motion).unwrap(),
    )))
    .unwrap();
    let err = StepperBench::open(&rig_on(sim.path())).err().unwrap();
    let msg = err.to_string();
    assert!(
        matches!(
            err,
            RigError::NoAnswer { .. } | RigError::WrongDevice { .. }
        ),
        "{msg}"
    );
    assert!(msg.contains("right port"), "{msg}");
}
