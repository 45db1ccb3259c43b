//! `measure --port P` without `--rig`, as users will type it (issue 20): the port is probed,
//! the shipped rig for what answered is chosen and said, the run measures with it, and
//! `--save-rig` writes it for next time. On the simulated stepper (our firmware) and
//! Dynamixel benches, and on a port where nothing answers.

use std::path::Path;
use std::process::Command;

use mpc_rig::rig::config::RigConfig;
use mpc_rig::rig::recording::load_meta;
use mpc_rig::rig::sim::pty::Pty;

use crate::support::bench::{dxl_sim, repo, stepper_sim};
use crate::support::serial_group;

/// `measure --port PORT` towards half-turn-2to1, one cycle, no analysis, into `out`, with
/// `extra` arguments; the exit code and standard error.
fn measure_on(port: &Path, out: &Path, extra: &[&str]) -> (Option<i32>, String) {
    let run = Command::new(env!("CARGO_BIN_EXE_mpc-rig"))
        .arg("measure")
        .arg("--port")
        .arg(port)
        .arg("--motion")
        .arg(repo("data/motions/half-turn-2to1.toml"))
        .args(["--cycles", "1", "--no-analysis", "-o"])
        .arg(out)
        .args(extra)
        .output()
        .unwrap();
    (
        run.status.code(),
        String::from_utf8_lossy(&run.stderr).into_owned(),
    )
}

/// Guards the firmware case: the board's handshake picks `sim-stepper`, the choice is
/// printed, the run records with it, and the saved rig file loads with the port set.
#[test]
fn our_firmware_on_a_port_picks_its_shipped_rig() {
    let _serial = serial_group::real_time();
    let sim = stepper_sim::<&str>("half-turn-2to1", &[]);
    let tmp = tempfile::tempdir().unwrap();
    let saved = tmp.path().join("bench.toml");
    let (code, stderr) = measure_on(
        sim.path(),
        &tmp.path().join("rec"),
        &["--save-rig", saved.to_str().unwrap()],
    );
    assert_eq!(code, Some(0), "{stderr}");
    let port = sim.path().display();
    let expected = format!(
        "no --rig: identifying what is on {port} …\n\
         found our firmware 0.1.0 on board `sim-stepper` with sensors AS5600 (channel 0)\n\
         using the shipped rig `sim-stepper` (rigs/sim-stepper.toml: Simulated Pico + stepper \
         + AS5600 bench (firmware core on a pseudo-terminal)) on {port}\n\
         saved it as {}: edit it (rigs/README.md) and pass it with --rig {} next time\n",
        saved.display(),
        saved.display()
    );
    assert!(stderr.starts_with(&expected), "{stderr}");
    let meta = load_meta(&tmp.path().join("rec")).unwrap();
    assert_eq!(meta.rig.name, "sim-stepper");
    assert_eq!(meta.end_reason.as_deref(), Some("finished"));
    let rig = RigConfig::load(&saved).unwrap();
    assert_eq!(rig.ports[0].path.as_deref(), Some(sim.path()));
}

/// Guards the Dynamixel case: after our firmware's handshake gets no answer, the ping scan
/// finds the two servos at 57 600 baud and `sim-dynamixel` (a pseudo-terminal) is used.
#[test]
fn a_dynamixel_bus_on_a_port_is_found_by_its_ping_scan() {
    let _serial = serial_group::real_time();
    let sim = dxl_sim::<&str>("half-turn-2to1", &[]);
    let tmp = tempfile::tempdir().unwrap();
    let (code, stderr) = measure_on(sim.path(), &tmp.path().join("rec"), &[]);
    assert_eq!(code, Some(0), "{stderr}");
    assert!(
        stderr.contains(
            "found a Dynamixel bus at 57600 baud with ID 1 (XL430-W250), ID 2 (XL430-W250)\n\
             using the shipped rig `sim-dynamixel` (rigs/sim-dynamixel.toml:"
        ),
        "{stderr}"
    );
    assert!(stderr.contains("save it with --save-rig FILE"), "{stderr}");
    let meta = load_meta(&tmp.path().join("rec")).unwrap();
    assert_eq!(meta.rig.name, "sim-dynamixel");
    assert!(meta.counts.samples > 0);
}

/// Guards a port where nothing answers: one error that says what was tried, and nothing
/// recorded; and a second port given without a rig is refused before anything is opened.
#[test]
fn a_silent_port_is_an_error_that_says_what_was_tried() {
    let _serial = serial_group::real_time();
    let pty = Pty::open().unwrap();
    let tmp = tempfile::tempdir().unwrap();
    let out = tmp.path().join("rec");
    let (code, stderr) = measure_on(pty.path(), &out, &[]);
    assert_eq!(code, Some(1), "{stderr}");
    let port = pty.path().display();
    assert!(
        stderr.starts_with(&format!(
            "no --rig: identifying what is on {port} …\n\
             error: {port}: the device on this port answers neither as our firmware nor as a \
             Dynamixel bus: the firmware handshake said: {port}: no answer to the handshake \
             within 1500 ms (is the firmware flashed and running? is this the right port?); \
             no Dynamixel answered a broadcast ping at 57600, 1000000, 115200, 2000000, \
             3000000, 4000000 baud. Is this the right port (`mpc-rig ports`)?\n"
        )),
        "{stderr}"
    );
    assert!(!out.exists(), "nothing recorded");

    let run = Command::new(env!("CARGO_BIN_EXE_mpc-rig"))
        .args([
            "measure", "--port", "a=/dev/x", "--port", "b=/dev/y", "--motion",
        ])
        .arg(repo("data/motions/half-turn-2to1.toml"))
        .output()
        .unwrap();
    assert_eq!(run.status.code(), Some(1));
    assert_eq!(
        String::from_utf8_lossy(&run.stderr),
        "error: without --rig, give the one port the bench is on: --port PATH or --port \
         USB_SERIAL (`mpc-rig ports` lists them); a bench on several ports needs a rig file \
         (rigs/README.md)\n"
    );
    // The usage line says what is needed: a rig or a port, and a target.
    let run = Command::new(env!("CARGO_BIN_EXE_mpc-rig"))
        .arg("measure")
        .output()
        .unwrap();
    assert_eq!(run.status.code(), Some(2));
    assert!(
        String::from_utf8_lossy(&run.stderr).contains(
            "Usage: mpc-rig measure <--rig <FILE>|--port <PORT>> <--mechanism <PATH>|--motion <FILE>>"
        ),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
}
