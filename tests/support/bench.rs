//! Simulated benches and session options shared by the integration tests of the bench's
//! safety and data integrity; each uses the part it needs.

use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;
use std::sync::Arc;

use mpc_rig::motion::Motion;
use mpc_rig::rig::session::{MeasureOptions, TargetSpec};
use mpc_rig::rig::sim::dynamixel::{self, MotionTarget, SimDynamixelHandle, SimDynamixelOptions};
use mpc_rig::rig::sim::plant::PlantConfig;
use mpc_rig::rig::sim::stepper::{self, Mechanics, SimHandle, SimStepperOptions};

/// A path in the repository.
pub fn repo(p: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join(p)
}

/// The motion file `data/motions/<name>.toml`, loaded.
pub fn motion(name: &str) -> Motion {
    Motion::from_file(&repo(&format!("data/motions/{name}.toml"))).unwrap()
}

/// A simulated stepper bench (the mechanics of `rigs/sim-stepper.toml`) following `motion`
/// with `faults` (`key=value`).
pub fn stepper_sim<S: AsRef<str>>(motion_name: &str, faults: &[S]) -> SimHandle {
    stepper::spawn(SimStepperOptions {
        target: motion(motion_name),
        plant: PlantConfig::from_faults(faults).unwrap(),
        mechanics: Mechanics::default(),
        link: None,
        driver: None,
    })
    .unwrap()
}

/// A simulated Dynamixel bus (driver ID 1, follower ID 2) following `motion` with `faults`.
pub fn dxl_sim<S: AsRef<str>>(motion_name: &str, faults: &[S]) -> SimDynamixelHandle {
    let mut o = SimDynamixelOptions::new(Arc::new(MotionTarget::new(motion(motion_name)).unwrap()));
    o.plant = PlantConfig::from_faults(faults).unwrap();
    dynamixel::spawn(o).unwrap()
}

/// Options of a session on `rig` (a path in the repository) through `ports` towards the
/// motion file `data/motions/<motion>.toml`, recording into `out`: 40 rpm, one settle and
/// one measured cycle forward; tests change what they need.
pub fn options(rig: &str, ports: Vec<String>, motion_name: &str, out: &Path) -> MeasureOptions {
    MeasureOptions {
        rig_path: repo(rig),
        ports,
        target: TargetSpec::Motion(repo(&format!("data/motions/{motion_name}.toml"))),
        speed_rpm: 40.0,
        cycles: 1,
        settle_cycles: 1,
        reverse: false,
        out_dir: Some(out.to_path_buf()),
        replace: false,
        cancel: Arc::new(AtomicBool::new(false)),
        progress: None,
        live: None,
    }
}
