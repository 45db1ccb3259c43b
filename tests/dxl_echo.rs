//! Nothing on a Dynamixel serial line panics the host (issue 16: a port that echoes every
//! byte made `dynamixel2` 0.9.1 panic in its bus thread, `bus.rs:302`). An echoing adapter
//! is recognised before the library sees a byte and refused with a message that says so,
//! on a Dynamixel bench and on a mixed one; and a reply the library cannot parse, should one
//! get through anyway, ends the run with an error instead of a dead thread.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Duration;

use mpc_rig::rig::backend::dynamixel::echo::crc16;
use mpc_rig::rig::backend::dynamixel::DynamixelBench;
use mpc_rig::rig::config::RigConfig;
use mpc_rig::rig::sim::pty::Pty;
use mpc_rig::rig::RigError;

use crate::support::serial_group;
use crate::support::SimChild;

fn repo(p: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join(p)
}

/// `measure` with `ports` on `rig`; its exit status and standard error.
fn measure(rig: &str, ports: &[&str], motion: &str, out: &Path) -> (bool, String) {
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_mpc-rig"));
    cmd.args(["measure", "--rig"]).arg(repo(rig));
    for p in ports {
        cmd.args(["--port", p]);
    }
    let o = cmd
        .arg("--motion")
        .arg(repo(motion))
        .args(["--speed", "30", "--cycles", "1", "-o"])
        .arg(out)
        .output()
        .unwrap();
    (
        o.status.success(),
        String::from_utf8_lossy(&o.stderr).into_owned(),
    )
}

/// Guards the echo check on a Dynamixel bench and on a mixed bench's bus: `measure` fails
/// with a message naming the echo and the port, and nothing panics.
#[test]
fn an_echoing_adapter_is_refused_without_a_panic() {
    let _serial = serial_group::real_time();
    let tmp = tempfile::tempdir().unwrap();
    let dxl = SimChild::spawn([
        "sim-device",
        "dynamixel",
        "--motion",
        repo("data/motions/half-turn-2to1.toml").to_str().unwrap(),
        "--fault",
        "echo=1",
    ]);
    let (ok, stderr) = measure(
        "rigs/sim-dynamixel.toml",
        &[&dxl.first_line],
        "data/motions/half-turn-2to1.toml",
        &tmp.path().join("dxl"),
    );
    assert!(!ok);
    assert!(stderr.contains("sends back every byte"), "{stderr}");
    assert!(stderr.contains(&dxl.first_line), "{stderr}");
    assert!(!stderr.contains("panicked"), "{stderr}");

    let mixed = SimChild::spawn([
        "sim-device",
        "mixed",
        "--rig",
        repo("rigs/sim-dynamixel-imu.toml").to_str().unwrap(),
        "--motion",
        repo("data/motions/cone-sweep.toml").to_str().unwrap(),
        "--fault",
        "echo=1",
    ]);
    let ports: Vec<&str> = mixed.first_line.split_whitespace().collect();
    let (ok, stderr) = measure(
        "rigs/sim-dynamixel-imu.toml",
        &ports,
        "data/motions/cone-sweep.toml",
        &tmp.path().join("mixed"),
    );
    assert!(!ok);
    assert!(stderr.contains("sends back every byte"), "{stderr}");
    assert!(!stderr.contains("panicked"), "{stderr}");
}

/// A status packet `dynamixel2` 0.9.1 accepts (its CRC is right) and then panics on: length
/// field 3, so the parameters would be `buffer[9..8]`.
fn short_status(id: u8) -> Vec<u8> {
    let mut p = vec![0xFF, 0xFF, 0xFD, 0x00, id, 0x03, 0x00, 0x55];
    let crc = crc16(&p).to_le_bytes();
    p.extend_from_slice(&crc);
    p
}

/// Guards the last resort: a device answering every instruction with a status packet
/// `dynamixel2` cannot parse (no echo, so the probe lets it through; line noise damaging a
/// length byte does the same once in a while) makes opening the bench fail with an error
/// that names the library's panic after the usual retries, and the process goes on.
#[test]
fn a_reply_the_library_cannot_parse_is_an_error_not_a_dead_thread() {
    let _serial = serial_group::real_time();
    let mut pty = Pty::open().unwrap();
    let path = pty.path().to_path_buf();
    let stop = Arc::new(AtomicBool::new(false));
    let device = {
        let stop = stop.clone();
        std::thread::spawn(move || {
            let mut buf = [0u8; 256];
            while !stop.load(Ordering::Relaxed) {
                if pty.wait_readable(Duration::from_millis(10)) {
                    if let Ok(n) = pty.read_available(&mut buf) {
                        // Answer anything that looks like an instruction to servo 1.
                        if buf[..n]
                            .windows(5)
                            .any(|w| w == [0xFF, 0xFF, 0xFD, 0x00, 0x01])
                        {
                            std::thread::sleep(Duration::from_millis(1));
                            let _ = pty.write_lossy(&short_status(1));
                        }
                    }
                }
            }
        })
    };
    let mut rig = RigConfig::load(&repo("rigs/sim-dynamixel.toml")).unwrap();
    rig.apply_port_overrides(&[path.display().to_string()])
        .unwrap();
    let err = DynamixelBench::from_rig(&rig).expect_err("the bench cannot be used");
    let text = err.to_string();
    assert!(matches!(err, RigError::WrongDevice { .. }), "{text}");
    assert!(text.contains("panicked reading a reply"), "{text}");
    stop.store(true, Ordering::Relaxed);
    device.join().unwrap();
}
