//! Broken or unmeasurable targets never move a motor (issue 16): every reader of
//! `mechanism.json` — `measure`, `sim-device` and `analyze` — validates it as `mpc-rig synth
//! --check` does before anything moves, and a target class the rig's sensors cannot measure
//! is refused before the bench is opened. Checked against live simulated stepper, Dynamixel
//! and mixed benches, which must see no motion at all.

use std::path::{Path, PathBuf};

use serde_json::{json, Value};

use mpc_rig::analysis::{load_target, TargetSource};
use mpc_rig::rig::config::RigConfig;
use mpc_rig::rig::session::{measure, MeasureOptions, TargetSpec};
use mpc_rig::rig::sim::mixed;
use mpc_rig::rig::sim::plant::PlantConfig;
use mpc_rig::rig::RigError;

use crate::support::bench::{self, dxl_sim, motion, repo, stepper_sim};
use crate::support::serial_group;

/// The accepted half-turn mechanism (N = 90, K = 4) the broken variants are made from.
fn good_mechanism() -> Value {
    let text = std::fs::read_to_string(repo("tests/data/mechanism/half-turn-2to1/mechanism.json"))
        .unwrap();
    serde_json::from_str(&text).unwrap()
}

/// One edit of the good mechanism: name, its whole refusal (`FILE` for the file's path),
/// the edit.
type Edit = (&'static str, &'static str, Box<dyn Fn(&mut Value)>);

/// The broken variants of the issue, each with its whole refusal, which names the file and
/// what `synth --check` names (issue 18: whole texts, so a change of wording shows).
fn broken_variants(dir: &Path) -> Vec<(PathBuf, &'static str)> {
    let edits: Vec<Edit> = vec![
        (
            "format-2",
            "field `format`: expected \"mpcmech-mechanism/1\", found \"mpcmech-mechanism/2\"",
            Box::new(|m| m["format"] = json!("mpcmech-mechanism/2")),
        ),
        (
            "null-sample",
            "field `curve_pairs[0].samples.p[3]`: invalid type: null, expected an array of length 3",
            Box::new(|m| m["curve_pairs"][0]["samples"]["p"][3] = Value::Null),
        ),
        (
            "no-pairs",
            "field `curve_pairs`: no curve pairs",
            Box::new(|m| m["curve_pairs"] = json!([])),
        ),
        (
            "short-array",
            "field `curve_pairs[1].samples.n`: 89 entries, expected samples = 90",
            Box::new(|m| {
                m["curve_pairs"][1]["samples"]["n"]
                    .as_array_mut()
                    .unwrap()
                    .pop();
            }),
        ),
        (
            "short-follower-motion",
            "field `follower_motion`: 25 entries, expected samples = 90",
            Box::new(|m| {
                m["follower_motion"].as_array_mut().unwrap().truncate(25);
            }),
        ),
        (
            "zero-samples",
            "field `samples`: 0 samples is too few (≥ 8)",
            Box::new(|m| m["samples"] = json!(0)),
        ),
        (
            "zero-normal",
            "field `curve_pairs[2].samples.n[7]`: a normal must be a unit vector, found length \
             0.0000",
            Box::new(|m| m["curve_pairs"][2]["samples"]["n"][7] = json!([0.0, 0.0, 0.0])),
        ),
        (
            "class-3r",
            "fails the mechanism check (`mpc-rig synth --check` shows it): stored dist(t) \
             reproduced: max |Δdist| = 1.88e0; dynamic form closure: E_valiTime = 0.0889, \
             E_maxDist = 0.8835 (worst at t = 0.5778; need 1 and ≤ −0.02); robust closure: \
             robust E_valiTime = 0.0000, robust E_maxDist = 1000.0000; 3R normal cone: max \
             |n·p̂| = 0.9928 ≤ sin 10° = 0.1736 (tangent cone)",
            Box::new(|m| m["class"] = json!("3R")),
        ),
        (
            "partial",
            "a partial design (written after a cancelled or failed synthesis, not accepted); run \
             `mpc-rig synth` to the end and measure its mechanism.json",
            Box::new(|m| m["solve"]["partial"] = json!(true)),
        ),
    ];
    edits
        .into_iter()
        .map(|(name, fragment, edit)| {
            let mut m = good_mechanism();
            edit(&mut m);
            let sub = dir.join(name);
            std::fs::create_dir_all(&sub).unwrap();
            let file = if name == "partial" {
                sub.join("mechanism.partial.json")
            } else {
                sub.join("mechanism.json")
            };
            std::fs::write(&file, serde_json::to_string(&m).unwrap()).unwrap();
            (file, fragment)
        })
        .collect()
}

/// The message with the mechanism file's path written `FILE`.
fn with_file(text: &str, file: &Path) -> String {
    text.replace(&file.display().to_string(), "FILE")
}

/// Compare every refusal of a table with its whole expected text and report all the
/// differences at once.
#[track_caller]
fn assert_all_match(found: Vec<(String, String, String)>) {
    let wrong: Vec<String> = found
        .iter()
        .filter(|(_, got, want)| got != want)
        .map(|(what, got, want)| format!("{what}:\n  got:  {got}\n  want: {want}"))
        .collect();
    assert!(wrong.is_empty(), "{}", wrong.join("\n"));
}

/// Options of a session on `rig` towards `target` (30 rpm, one cycle).
fn options(rig: &str, ports: Vec<String>, target: TargetSpec, out: &Path) -> MeasureOptions {
    let mut o = bench::options(rig, ports, "half-turn-2to1", out);
    o.target = target;
    o.speed_rpm = 30.0;
    o
}

/// Guards the good fixture itself: it loads as a target, so the refusals below are the
/// edits' doing.
#[test]
fn the_accepted_mechanism_is_a_target() {
    let t = TargetSpec::Mechanism(repo("tests/data/mechanism/half-turn-2to1"))
        .load()
        .unwrap();
    assert_eq!(t.motion.class().to_string(), "1R");
    load_target(&TargetSource::Mechanism(repo(
        "tests/data/mechanism/half-turn-2to1/mechanism.json",
    )))
    .unwrap();
}

/// Guards the broken mechanism files of the issue (format version 2, a `null` sample, K = 0,
/// an array one entry short, a short `follower_motion`, `samples = 0`, a zero normal, a
/// class changed to 3R, a `mechanism.partial.json`): `measure` refuses each with the file
/// and the problem named, against a live simulated stepper bench, Dynamixel bench and mixed
/// bench, none of which sees a byte or moves; `analyze`'s target loader refuses each too.
#[test]
fn broken_mechanisms_never_move_a_motor() {
    let _serial = serial_group::real_time();
    let tmp = tempfile::tempdir().unwrap();
    let variants = broken_variants(tmp.path());
    let stepper_sim = stepper_sim::<&str>("half-turn-2to1", &[]);
    let dxl_sim = dxl_sim::<&str>("half-turn-2to1", &[]);
    let mixed_rig = RigConfig::load(&repo("rigs/sim-dynamixel-1r1t.toml")).unwrap();
    let screw = motion("screw-bob");
    let mixed_sim = mixed::spawn(&mixed_rig, screw, PlantConfig::default()).unwrap();
    let benches = [
        (
            "rigs/sim-stepper.toml",
            vec![stepper_sim.path().display().to_string()],
        ),
        (
            "rigs/sim-dynamixel.toml",
            vec![dxl_sim.path().display().to_string()],
        ),
        ("rigs/sim-dynamixel-1r1t.toml", mixed_sim.port_overrides()),
    ];
    let mut found = Vec::new();
    for (file, expected) in &variants {
        for (rig, ports) in &benches {
            let out = tmp.path().join("rec");
            let mut opts = options(
                rig,
                ports.clone(),
                TargetSpec::Mechanism(file.clone()),
                &out,
            );
            let err = measure(&mut opts).expect_err("a broken mechanism is refused");
            let text = err.to_string();
            assert!(matches!(err, RigError::Target { .. }), "{text}");
            assert!(!out.exists(), "no recording is started for {text}");
            found.push((
                format!("measure on {rig}, {}", file.display()),
                with_file(&text, file),
                format!("target FILE: {expected}"),
            ));
        }
        let err = load_target(&TargetSource::Mechanism(file.clone()))
            .expect_err("analysis refuses it too")
            .to_string();
        found.push((
            format!("analysis, {}", file.display()),
            with_file(&err, file),
            format!("cannot load target FILE: {expected}"),
        ));
    }
    assert_all_match(found);
    let status = stepper_sim.stop().unwrap();
    assert_eq!(
        (status.bytes_in, status.steps),
        (0, 0),
        "the stepper bench was used: {status:?}"
    );
    for bus in [dxl_sim.bus(), mixed_sim.bus().bus()] {
        assert!(!bus.driver().torque_enabled());
        assert_eq!(bus.driver().present_velocity(), 0);
    }
    assert_eq!(mixed_sim.board().status().bytes_in, 0);
}

/// Guards `sim-device --mechanism` (it served broken files before): it exits with an error
/// naming the file and the problem and never prints a port to connect to.
#[test]
fn sim_device_refuses_broken_mechanisms() {
    let tmp = tempfile::tempdir().unwrap();
    let mut found = Vec::new();
    for (file, expected) in broken_variants(tmp.path()) {
        for device in ["stepper", "dynamixel"] {
            let out = std::process::Command::new(env!("CARGO_BIN_EXE_mpc-rig"))
                .args(["sim-device", device, "--mechanism"])
                .arg(&file)
                .output()
                .unwrap();
            let stderr = String::from_utf8_lossy(&out.stderr);
            assert!(!out.status.success(), "{device} served {}", file.display());
            assert!(out.stdout.is_empty(), "printed a port: {:?}", out.stdout);
            found.push((
                format!("sim-device {device}, {}", file.display()),
                with_file(&stderr, &file),
                format!("error: target FILE: {expected}\n"),
            ));
        }
    }
    assert_all_match(found);
}

/// Guards the class check (issue 16: a 3R motion on a rig without an IMU ran the whole
/// motor run, then "analysis failed", exit 0): a 3R target on the stepper rig with only an
/// AS5600, a 1R1T target on the Dynamixel rig (no height sensor) and a 1R target on the
/// mixed IMU rig (no rotary sensor) are each refused before the bench is opened, naming the
/// missing sensor; the live simulators see nothing.
#[test]
fn targets_the_rig_cannot_measure_are_refused_before_moving() {
    let _serial = serial_group::real_time();
    let tmp = tempfile::tempdir().unwrap();
    let stepper_sim = stepper_sim::<&str>("half-turn-2to1", &[]);
    let dxl_sim = dxl_sim::<&str>("half-turn-2to1", &[]);
    let imu_rig = RigConfig::load(&repo("rigs/sim-dynamixel-imu.toml")).unwrap();
    let mixed_sim =
        mixed::spawn(&imu_rig, motion("half-turn-2to1"), PlantConfig::default()).unwrap();
    let cases = [
        (
            "rigs/sim-stepper.toml",
            vec![stepper_sim.path().display().to_string()],
            "data/motions/figure-eight.toml",
            "refused: rig `sim-stepper` cannot measure a 3R target: it has no orientation sensor \
             (`kind = \"imu\"`) on the follower (rigs/README.md lists the sensors each class needs)",
        ),
        (
            "rigs/sim-dynamixel.toml",
            vec![dxl_sim.path().display().to_string()],
            "data/motions/screw-bob.toml",
            "refused: rig `sim-dynamixel` cannot measure a 1R1T target: it has no linear sensor \
             (`dof = \"tz\"`) for the height (rigs/README.md lists the sensors each class needs)",
        ),
        (
            "rigs/sim-dynamixel-imu.toml",
            mixed_sim.port_overrides(),
            "data/motions/half-turn-2to1.toml",
            "refused: rig `sim-dynamixel-imu` cannot measure a 1R target: it has no rotary sensor \
             (`dof = \"rz\"` or a follower servo) (rigs/README.md lists the sensors each class \
             needs)",
        ),
    ];
    for (rig, ports, motion, missing) in cases {
        let out = tmp.path().join("rec");
        let mut opts = options(rig, ports, TargetSpec::Motion(repo(motion)), &out);
        let err = measure(&mut opts).expect_err("refused");
        assert!(matches!(err, RigError::CannotMeasure { .. }), "{err}");
        assert_eq!(err.to_string(), missing);
        assert!(!out.exists());
    }
    assert_eq!(stepper_sim.stop().unwrap().bytes_in, 0);
    assert!(!dxl_sim.bus().driver().torque_enabled());
    assert_eq!(dxl_sim.bus().driver().present_velocity(), 0);
    assert_eq!(mixed_sim.board().status().bytes_in, 0);
}
