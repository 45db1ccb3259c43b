//! Every shipped rig file in `rigs/` loads and validates, and the recording written for it
//! reads back with the columns its sensors declare.

use std::path::Path;

use mpc_rig::rig::config::RigConfig;

fn rig_files() -> Vec<std::path::PathBuf> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("rigs");
    let mut files: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "toml"))
        .collect();
    files.sort();
    files
}

/// Guards: the shipped rigs (simulated and templates) all pass validation, so users copying
/// a template start from a valid file.
#[test]
fn every_shipped_rig_loads() {
    let files = rig_files();
    assert!(files.iter().any(|f| f.ends_with("sim-stepper.toml")));
    for f in files {
        let cfg = RigConfig::load(&f).unwrap_or_else(|e| panic!("{e}"));
        assert!(!cfg.sensors.is_empty(), "{}: no sensors", f.display());
        assert!(cfg.port(cfg.driver.port()).is_some());
    }
}

/// Guards: the simulated stepper rig measures the follower rotation with an AS5600, which
/// the simulated bench and the demo rely on.
#[test]
fn sim_stepper_rig_has_as5600_follower() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("rigs/sim-stepper.toml");
    let cfg = RigConfig::load(&path).unwrap();
    assert_eq!(cfg.driver.kind(), "stepper-firmware");
    let cols: Vec<_> = cfg.sensor_columns().into_iter().map(|c| c.name).collect();
    assert_eq!(cols, ["follower_rz"]);
    assert_eq!(cfg.sensors[0].counts_per_rev(), Some(4096.0));
}

/// Guards: a missing file gives an error that names it.
#[test]
fn missing_rig_file_is_named() {
    let err = RigConfig::load(Path::new("rigs/nope.toml")).unwrap_err();
    assert!(err.to_string().contains("rigs/nope.toml"), "{err}");
}
