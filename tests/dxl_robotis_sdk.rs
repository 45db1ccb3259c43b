//! Faithfulness check: ROBOTIS's own Python SDK (`pip install dynamixel-sdk`) talks to the
//! simulated bus through a real pseudo-terminal — ping, broadcast ping, reads and writes
//! (with an error reply and byte stuffing both ways), group sync read/write, bulk read,
//! reboot. Skipped, with a message saying why, when python3 or the SDK is missing.

use std::process::Command;
use std::sync::Arc;

use crate::support::serial_group;
use mpc_rig::rig::sim::dynamixel::{spawn, SimDynamixelOptions};
use mpc_rig::rig::sim::plant::WobbleTurn;

fn sdk_available() -> Result<(), String> {
    match Command::new("python3")
        .args(["-c", "import dynamixel_sdk"])
        .output()
    {
        Err(e) => Err(format!("python3 is not runnable ({e})")),
        Ok(o) if !o.status.success() => {
            Err("the ROBOTIS SDK is not installed (pip install dynamixel-sdk)".into())
        }
        Ok(_) => Ok(()),
    }
}

/// Guards that the simulator is faithful enough for ROBOTIS's reference host
/// implementation: the script exits 0 only if every step behaves like a real XL430 pair.
#[test]
fn robotis_python_sdk_talks_to_the_simulator() {
    let _serial = serial_group::real_time();
    if let Err(why) = sdk_available() {
        eprintln!("SKIPPED robotis_python_sdk_talks_to_the_simulator: {why}");
        return;
    }
    let sim = spawn(SimDynamixelOptions::new(Arc::new(WobbleTurn {
        amplitude: 0.0,
    })))
    .expect("simulator starts");
    let script = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/tests/support/dxl_robotis_sdk_check.py"
    );
    let out = Command::new("python3")
        .arg(script)
        .arg(sim.path())
        .output()
        .expect("python3 runs");
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        out.status.success() && stdout.contains("SDK-CHECK OK"),
        "SDK check failed:\n{stdout}\n{stderr}"
    );
}
