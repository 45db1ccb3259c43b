//! End-to-end tests of `mpc-rig simulate` (the virtual prototype, docs/simulate.md).

use assert_cmd::Command;

const TEST_MECHANISM: &str = "tests/data/mechanism/half-turn-2to1";

/// `simulate` of the test mechanism with the parts in `parts`, writing into `out`.
fn simulate_args<'a>(parts: &'a str, out: &'a str) -> [&'a str; 6] {
    ["simulate", TEST_MECHANISM, "--parts", parts, "-o", out]
}

/// Run `mpc-rig ARGS`, which must exit 1; its (stdout, stderr).
fn refused(args: &[&str]) -> (String, String) {
    let assert = Command::cargo_bin("mpc-rig")
        .unwrap()
        .args(args)
        .assert()
        .code(1);
    let out = assert.get_output();
    (
        String::from_utf8_lossy(&out.stdout).to_string(),
        String::from_utf8_lossy(&out.stderr).to_string(),
    )
}

/// Guards what a user who has not built the parts yet sees: the file that is missing, and
/// the command that makes it, exit 1, nothing written.
#[test]
fn simulating_without_built_parts_says_to_build_them() {
    let dir = tempfile::tempdir().unwrap();
    let parts = dir.path().join("no-parts");
    let out = dir.path().join("prediction");
    let (_, stderr) = refused(&simulate_args(
        parts.to_str().unwrap(),
        out.to_str().unwrap(),
    ));
    assert_eq!(
        stderr,
        format!(
            "error: simulating the parts in {p}\n  caused by: {p}/build.json: No such file or \
             directory (os error 2). Build the parts first: mpc-rig build MECHANISM\n",
            p = parts.display()
        )
    );
    assert!(!out.exists());
}

/// Guards the floor on driver angles: fewer than the file's 360 samples is refused with
/// the option as typed.
#[test]
fn too_few_driver_angles_are_refused() {
    let (_, stderr) = refused(&["simulate", TEST_MECHANISM, "--samples", "100"]);
    assert!(
        stderr.ends_with("  caused by: --samples 100: at least 360 driver angles per period\n"),
        "stderr:\n{stderr}"
    );
}

/// Guards the geometry plant's refusal of a prediction it cannot read: what it was
/// reading for, the file and why, exit 1, before any device is served.
#[test]
fn a_bench_with_a_missing_prediction_is_refused_before_it_starts() {
    let dir = tempfile::tempdir().unwrap();
    let missing = dir.path().join("prediction.json");
    let (stdout, stderr) = refused(&[
        "sim-device",
        "stepper",
        "--mechanism",
        TEST_MECHANISM,
        "--prediction",
        missing.to_str().unwrap(),
    ]);
    assert_eq!(
        stderr,
        format!(
            "error: reading the prediction for the geometry plant\n  caused by: {}: No such \
             file or directory (os error 2)\n",
            missing.display()
        )
    );
    assert!(stdout.is_empty(), "no device path printed");
}

/// Guards the whole command on parts that never meet (a small block on each part's axis,
/// 60 mm apart): the follower is free both ways at every driver angle up to the 10° cap,
/// so the drive is lost at all 1 440 angles, in one window; every file is written and
/// `prediction.json` has the documented shape.
#[test]
fn parts_that_never_meet_lose_the_drive_everywhere() {
    let dir = tempfile::tempdir().unwrap();
    let parts = dir.path().join("parts");
    blocks_that_never_meet(&parts);
    let out = dir.path().join("prediction");
    let assert = Command::cargo_bin("mpc-rig")
        .unwrap()
        .args(simulate_args(
            parts.to_str().unwrap(),
            out.to_str().unwrap(),
        ))
        .assert()
        .success();
    let stdout = String::from_utf8_lossy(&assert.get_output().stdout).to_string();
    assert!(
        stdout.contains("drive lost at 1440 of 1440 angles (play > 5°): driver 0–359.75°"),
        "stdout:\n{stdout}"
    );
    let doc = written(
        &out,
        &[
            "prediction.json",
            "law.png",
            "law.svg",
            "deviation.png",
            "deviation.svg",
            "play.png",
            "play.svg",
            "prediction.md",
        ],
    );
    assert_eq!(doc["format"], "mpcmech-prediction/1");
    let p = &doc["prediction"];
    let samples = p["samples"].as_array().unwrap();
    assert_eq!(samples.len(), 1440);
    for s in samples {
        assert_eq!(s["free_plus_deg"].as_f64().unwrap(), 10.0);
        assert_eq!(s["free_minus_deg"].as_f64().unwrap(), 10.0);
        assert_eq!(s["drive_lost"], true);
    }
    assert_eq!(p["worst_play"]["deg"].as_f64().unwrap(), 20.0);
    assert_eq!(p["drive_lost_windows"].as_array().unwrap().len(), 1);
    // The file's contacts hold the follower at each of its 90 samples; the parts nowhere.
    assert_eq!(p["closure"]["lost_by_parts_only"], 90);
    assert_eq!(p["closure"]["held_both"], 0);
}

/// A 1R1T mechanism: screw-bob synthesized at 90 samples per period (`mpc-rig synth
/// data/motions/screw-bob.toml --samples 90`: K = 4, d_x = 6), small enough to keep here.
const SCREW_MECHANISM: &str = "tests/data/mechanism/screw-bob";

/// Asserts that `simulate` wrote each of `files` into `out`, and returns its
/// `prediction.json`.
fn written(out: &std::path::Path, files: &[&str]) -> serde_json::Value {
    for f in files {
        assert!(out.join(f).is_file(), "{f} written");
    }
    serde_json::from_str(&std::fs::read_to_string(out.join("prediction.json")).unwrap()).unwrap()
}

/// Two blocks as the parts of either test mechanism (a small one on each part's axis, 60 mm
/// apart, which never meet), with the `build.json` fields `simulate` reads, in `parts`.
fn blocks_that_never_meet(parts: &std::path::Path) {
    use mpc_rig::geometry::io::stl::write_stl;
    use mpc_rig::geometry::primitive_meshes::cuboid;
    std::fs::create_dir_all(parts).unwrap();
    let block = cuboid([-2.0, -2.0, -2.0], [2.0, 2.0, 2.0]);
    write_stl(&parts.join("driver.stl"), &block, "driver").unwrap();
    write_stl(&parts.join("follower.stl"), &block, "follower").unwrap();
    std::fs::write(
        parts.join("build.json"),
        r#"{"scale_mm": 10.0, "clearance_mm": 0.2, "cell_mm": 0.4, "without_pair": null,
            "check": {"gaps": []}}"#,
    )
    .unwrap();
}

/// Guards the 1R1T prediction end to end on parts that never meet: every ray of the free
/// region (turn, slide and both screws, each way) reaches the cap (5.24 mm in the plane of
/// the 30 mm lever), so the drive is lost at every angle, and the stdout line says so in
/// the region's terms. `prediction.json` carries each sample's heights, slides and region,
/// and the slide's figures; the height and slide charts are written. A torque is refused
/// for 1R1T with the reason, before anything is traced.
#[test]
fn a_1r1t_follower_on_parts_that_never_meet_is_free_along_every_ray() {
    use mpc_rig::predict::{FREE_CAP_MM, SCREW_LEVER_MM};
    let dir = tempfile::tempdir().unwrap();
    let parts = dir.path().join("parts");
    blocks_that_never_meet(&parts);
    let out = dir.path().join("prediction");
    let (parts_arg, out_arg) = (parts.to_str().unwrap(), out.to_str().unwrap());
    let assert = Command::cargo_bin("mpc-rig")
        .unwrap()
        .args([
            "simulate",
            SCREW_MECHANISM,
            "--parts",
            parts_arg,
            "-o",
            out_arg,
        ])
        .assert()
        .success();
    let stdout = String::from_utf8_lossy(&assert.get_output().stdout).to_string();
    assert!(
        stdout.contains(
            "drive lost at 1440 of 1440 angles (play along a line > 2.62 mm): driver 0–359.75°"
        ),
        "stdout:\n{stdout}"
    );
    let doc = written(
        &out,
        &[
            "height.png",
            "height.svg",
            "play-slide.png",
            "play-slide.svg",
        ],
    );
    let p = &doc["prediction"];
    assert_eq!(p["class"], "1R1T");
    assert_eq!(p["slide"]["lever_mm"].as_f64().unwrap(), SCREW_LEVER_MM);
    let samples = p["samples"].as_array().unwrap();
    assert_eq!(samples.len(), 1440);
    for s in samples {
        let region = s["region_mm"].as_array().unwrap();
        assert_eq!(region.len(), 8);
        for r in region {
            assert!((r.as_f64().unwrap() - FREE_CAP_MM).abs() < 1e-9, "{s}");
        }
        assert_eq!(s["free_up_mm"].as_f64().unwrap(), FREE_CAP_MM);
        assert_eq!(s["slide_play_mm"].as_f64().unwrap(), 2.0 * FREE_CAP_MM);
        assert_eq!(s["drive_lost"], true);
        // The dragged heights stay within the region's reach of the target.
        let target = s["target_mm"].as_f64().unwrap();
        for side in ["forward_mm", "reverse_mm"] {
            let dev = s[side].as_f64().unwrap() - target;
            assert!(dev.abs() <= FREE_CAP_MM + 1e-9, "{side}: {s}");
        }
    }
    let (_, stderr) = refused(&[
        "simulate",
        SCREW_MECHANISM,
        "--parts",
        parts_arg,
        "-o",
        out_arg,
        "--load",
        "torque+",
    ]);
    assert_eq!(
        stderr,
        format!(
            "error: simulating the parts in {parts_arg}\n  caused by: --load torque+: a 1R1T \
             follower takes the drag only so far: a torque or a spring about its axis leaves \
             its height to friction alone, which is not modelled\n"
        )
    );
}

/// Guards the geometry plant's class check: a 1R prediction given for a 1R1T target is
/// refused, naming both classes, before any device is served.
#[test]
fn a_bench_refuses_a_prediction_of_another_class() {
    let dir = tempfile::tempdir().unwrap();
    let parts = dir.path().join("parts");
    blocks_that_never_meet(&parts);
    let out = dir.path().join("prediction");
    Command::cargo_bin("mpc-rig")
        .unwrap()
        .args(simulate_args(
            parts.to_str().unwrap(),
            out.to_str().unwrap(),
        ))
        .assert()
        .success();
    let file = out.join("prediction.json");
    let (stdout, stderr) = refused(&[
        "sim-device",
        "stepper",
        "--mechanism",
        SCREW_MECHANISM,
        "--prediction",
        file.to_str().unwrap(),
    ]);
    assert_eq!(
        stderr,
        format!(
            "error: --prediction {}: a prediction of a 1R mechanism, but this target is 1R1T\n",
            file.display()
        )
    );
    assert!(stdout.is_empty(), "no device path printed");
}

/// Another 1R mechanism than [`TEST_MECHANISM`]: the demo's printable design.
const OTHER_MECHANISM: &str = "tests/data/mechanism/half-turn-2to1-printable";

/// Guards the refusal of what was made for another mechanism, each before anything is
/// traced or served: parts whose `build.json` records another mechanism's digest (both
/// digests named, the command that mends it), and a prediction given to a bench whose
/// target is another mechanism (the same words, from the bench's side).
#[test]
fn parts_and_predictions_of_another_mechanism_are_refused() {
    use mpc_rig::synth::mechanism::Mechanism;
    let digest = |m: &str| Mechanism::load(std::path::Path::new(m)).unwrap().digest();
    let (this, other) = (digest(TEST_MECHANISM), digest(OTHER_MECHANISM));
    assert_ne!(this, other);
    let dir = tempfile::tempdir().unwrap();
    let parts = dir.path().join("parts");
    blocks_that_never_meet(&parts);
    let build_json = parts.join("build.json");
    let mut build: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&build_json).unwrap()).unwrap();
    build["mechanism_digest"] = other.clone().into();
    std::fs::write(&build_json, build.to_string()).unwrap();
    let out = dir.path().join("prediction");
    let (parts_arg, out_arg) = (parts.to_str().unwrap(), out.to_str().unwrap());
    let (_, stderr) = refused(&simulate_args(parts_arg, out_arg));
    assert_eq!(
        stderr,
        format!(
            "error: simulating the parts in {parts_arg}\n  caused by: {parts_arg}: these parts \
             were built from another mechanism than the one given (build.json records the \
             mechanism digest {}…, the mechanism's is {}…), perhaps one synthesized into the \
             same folder since. Build them again: mpc-rig build MECHANISM\n",
            &other[..12],
            &this[..12]
        )
    );
    assert!(!out.exists(), "nothing written");

    // Built from this mechanism: predicted, and the prediction says for which.
    build["mechanism_digest"] = this.clone().into();
    std::fs::write(&build_json, build.to_string()).unwrap();
    Command::cargo_bin("mpc-rig")
        .unwrap()
        .args(simulate_args(parts_arg, out_arg))
        .assert()
        .success();
    let file = out.join("prediction.json");
    let doc = written(&out, &["prediction.json"]);
    assert_eq!(doc["prediction"]["mechanism_digest"], this.as_str());
    let (stdout, stderr) = refused(&[
        "sim-device",
        "stepper",
        "--mechanism",
        OTHER_MECHANISM,
        "--prediction",
        file.to_str().unwrap(),
    ]);
    assert_eq!(
        stderr,
        format!(
            "error: --prediction {f}: a prediction for another mechanism than {OTHER_MECHANISM} \
             (its mechanism digest is {}…, this one's {}…). Predict this one: mpc-rig simulate \
             {OTHER_MECHANISM}\n",
            &this[..12],
            &other[..12],
            f = file.display()
        )
    );
    assert!(stdout.is_empty(), "no device path printed");
}
