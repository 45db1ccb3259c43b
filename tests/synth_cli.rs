//! End-to-end tests of `mpc-rig synth` and `mpc-rig synth --check` on the paper's 1R
//! example with reduced settings (fewer samples, candidates and generations; the same code
//! path as the defaults).

use crate::support::serial_group;
use assert_cmd::Command;
use predicates::prelude::*;

const MOTION: &str = "data/motions/half-turn-2to1.toml";

/// The reduced 1R run: K searched from 2 (so the gap-filling bands take part; a fixed
/// `--k 4` closed or not depending on round-off in the candidates), d_x fixed.
fn synth_small(out: &std::path::Path) -> assert_cmd::assert::Assert {
    synth_reduced(MOTION, out, &["--dx", "6", "--seed", "1"])
}

/// `synth` with reduced settings (90 samples, 16 candidates per band, 100 generations) plus
/// `extra` arguments.
fn synth_reduced(
    motion: &str,
    out: &std::path::Path,
    extra: &[&str],
) -> assert_cmd::assert::Assert {
    Command::cargo_bin("mpc-rig")
        .unwrap()
        .args([
            "synth",
            motion,
            "-o",
            out.to_str().unwrap(),
            "--samples",
            "90",
            "--candidates",
            "16",
            "--generations",
            "100",
        ])
        .args(extra)
        .assert()
}

/// Guards the whole pipeline: synth writes an accepted mechanism.json and the report plots,
/// prints the best figures every K tried reached, `--check` re-verifies the file from its
/// samples, and a tampered or malformed file is rejected with a message naming what is
/// wrong.
#[test]
fn synth_end_to_end_then_check_and_reject_tampering() {
    let _serial = serial_group::alone();
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("ht");
    synth_small(&out)
        .success()
        .stdout(predicate::str::contains("1R"))
        .stdout(predicate::str::contains(
            "best reached per K tried (closure margin asked: E_maxDist ≤ −0.02):\n  K = 3, d_x = 6:",
        ))
        .stdout(predicate::str::contains("(accepted)"))
        .stdout(predicate::str::contains(
            "lengths in model units, 10 mm each (scale_mm): d_x 6 = 60 mm, band gap 0.5 = 5 mm, \
             axis room none",
        ));
    let file = out.join("mechanism.json");
    assert!(file.exists());
    for plot in [
        "dist.png",
        "dist.svg",
        "curves-follower-top.png",
        "curves-driver-top.svg",
        "normals-worst.png",
    ] {
        assert!(out.join("report").join(plot).exists(), "missing {plot}");
    }
    let text = std::fs::read_to_string(&file).unwrap();
    let json: serde_json::Value = serde_json::from_str(&text).unwrap();
    assert_eq!(json["format"], "mpcmech-mechanism/1");
    assert_eq!(json["class"], "1R");
    // K is what the search accepted, and at least the 1R minimum.
    let pairs = json["curve_pairs"].as_array().unwrap().len();
    let accepted: Vec<&serde_json::Value> = json["solve"]["attempts"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|a| a["accepted"] == true)
        .collect();
    assert_eq!(accepted.len(), 1);
    assert_eq!(accepted[0]["k"].as_u64(), Some(pairs as u64));
    assert!(pairs >= 2);
    assert_eq!(json["closure"]["vali_time"], 1.0);
    assert_eq!(json["closure"]["max_dist"], -1.0);
    assert_eq!(json["closure"]["robust_vali_time"], 1.0);
    assert_eq!(json["solve"]["band_gap"], 0.5);
    assert!(json["solve"]["axis_room"].is_null());
    Command::cargo_bin("mpc-rig")
        .unwrap()
        .args(["synth", "--check", out.to_str().unwrap()])
        .assert()
        .success()
        .stdout(predicate::str::contains("passes every check"))
        .stdout(predicate::str::contains("axis room").not());

    // Claimed layout options the curves do not keep: a wider band gap than the slabs
    // leave, and an axis room the curves reach into.
    for (field, value, fails) in [
        ("band_gap", 1.0, "FAIL band separation"),
        ("axis_room", 4.0, "FAIL axis room"),
    ] {
        let mut claimed = json.clone();
        claimed["solve"][field] = serde_json::json!(value);
        let f = dir.path().join(format!("claimed-{field}.json"));
        std::fs::write(&f, serde_json::to_string(&claimed).unwrap()).unwrap();
        Command::cargo_bin("mpc-rig")
            .unwrap()
            .args(["synth", "--check", f.to_str().unwrap()])
            .assert()
            .code(2)
            .stdout(predicate::str::contains(fails));
    }

    // Tamper: move one contact point of pair 0.
    let mut bad = json.clone();
    bad["curve_pairs"][0]["samples"]["p"][5][0] = serde_json::json!(9.0);
    let bad_file = dir.path().join("bad.json");
    std::fs::write(&bad_file, serde_json::to_string(&bad).unwrap()).unwrap();
    // The same verdicts as JSON for scripts: the file, the verdict, every check.
    for (file, passed, code) in [(&out, true, 0), (&bad_file, false, 2)] {
        let run = Command::cargo_bin("mpc-rig")
            .unwrap()
            .args(["synth", "--check", file.to_str().unwrap(), "--json"])
            .output()
            .unwrap();
        assert_eq!(run.status.code(), Some(code));
        let v: serde_json::Value = serde_json::from_slice(&run.stdout).unwrap();
        assert_eq!(v["file"], file.to_str().unwrap());
        assert_eq!(v["passed"], passed);
        let items = v["items"].as_array().unwrap();
        assert!(items.len() >= 5, "{v}");
        assert_eq!(items[0]["name"], "coincident points");
        assert_eq!(items[0]["passed"], passed);
        assert!(
            items[0]["detail"].as_str().unwrap().contains("max |R2"),
            "{v}"
        );
    }
    Command::cargo_bin("mpc-rig")
        .unwrap()
        .args(["synth", "--check", bad_file.to_str().unwrap()])
        .assert()
        .code(2)
        .stdout(predicate::str::contains("FAIL coincident points"));

    // Malformed: truncated JSON gives file:line:column and the field it stopped in. Cut from
    // the committed fixture, so the place does not move with the synthesis.
    let fixture = std::fs::read_to_string(
        std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("tests/data/mechanism/half-turn-2to1/mechanism.json"),
    )
    .unwrap();
    let trunc = dir.path().join("trunc.json");
    std::fs::write(&trunc, &fixture[..fixture.len() / 2]).unwrap();
    let in_dir = |out: std::process::Output| {
        assert_eq!(out.status.code(), Some(1));
        String::from_utf8_lossy(&out.stderr).replace(&dir.path().display().to_string(), "DIR")
    };
    let check = |file: &std::path::Path| {
        Command::cargo_bin("mpc-rig")
            .unwrap()
            .args(["synth", "--check"])
            .arg(file)
            .output()
            .unwrap()
    };
    assert_eq!(
        in_dir(check(&trunc)),
        "error: DIR/trunc.json:1:73488: field `curve_pairs[1].samples.n2[22]`: EOF while parsing \
         a list\n"
    );

    // Wrong array length names the field.
    let mut short = json;
    short["curve_pairs"][1]["samples"]["n"]
        .as_array_mut()
        .unwrap()
        .pop();
    let short_file = dir.path().join("short.json");
    std::fs::write(&short_file, serde_json::to_string(&short).unwrap()).unwrap();
    assert_eq!(in_dir(check(&short_file)), "error: DIR/short.json: field `curve_pairs[1].samples.n`: 89 entries, expected samples = 90\n");
}

/// Guards request validation at the command line: a closure margin below ε is refused with
/// a message saying why, before any work.
#[test]
fn synth_refuses_a_margin_below_epsilon() {
    let dir = tempfile::tempdir().unwrap();
    Command::cargo_bin("mpc-rig")
        .unwrap()
        .args([
            "synth",
            MOTION,
            "-o",
            dir.path().to_str().unwrap(),
            "--min-margin",
            "0.01",
        ])
        .assert()
        .code(1)
        .stderr(
            "error: bad synthesis request: --min-margin 0.01 must lie between ε = 0.02 (a sample \
             is closed when its dist < −ε) and 1 (dist of unit vectors never goes below −1)\n",
        );
}

/// Guards request validation of the layout options at the command line: a band gap outside
/// 0–5 and an axis room that is not positive or leaves the curves no room between it and the
/// shafts' minimum radius (d_x − 0.8) are refused with a message saying why.
#[test]
fn synth_refuses_bad_layout_options() {
    let dir = tempfile::tempdir().unwrap();
    for (args, says) in [
        (
            &["--band-gap", "-1"][..],
            "--band-gap -1 must lie between 0 (bands touching) and 5 model units (wider only \
             makes the stack taller); it is the free height between neighbouring bands of \
             height 1 (default 0.5)",
        ),
        (
            &["--band-gap", "6"],
            "--band-gap 6 must lie between 0 (bands touching) and 5 model units (wider only \
             makes the stack taller); it is the free height between neighbouring bands of \
             height 1 (default 0.5)",
        ),
        (
            &["--axis-room", "-1"],
            "--axis-room -1 must be positive and below 5.2 model units: the curves must stay \
             within d_x − A of their axes (d_x = 6 is the smallest tried) but at least 0.8 away \
             from them (the minimum radius kept for the shafts), which leaves no room when \
             A ≥ d_x − 0.8",
        ),
        (
            &["--axis-room", "5.5", "--dx", "6"],
            "--axis-room 5.5 must be positive and below 5.2 model units: the curves must stay \
             within d_x − A of their axes (d_x = 6 is the smallest tried) but at least 0.8 away \
             from them (the minimum radius kept for the shafts), which leaves no room when \
             A ≥ d_x − 0.8",
        ),
    ] {
        Command::cargo_bin("mpc-rig")
            .unwrap()
            .args(["synth", MOTION, "-o", dir.path().to_str().unwrap()])
            .args(args)
            .assert()
            .code(1)
            .stderr(format!("error: bad synthesis request: {says}\n"));
    }
}

/// Guards request validation at the command line: K below dof + 1 is refused with a clear
/// message and a non-zero exit, not a panic.
#[test]
fn synth_refuses_k_below_minimum() {
    let dir = tempfile::tempdir().unwrap();
    Command::cargo_bin("mpc-rig")
        .unwrap()
        .args([
            "synth",
            MOTION,
            "-o",
            dir.path().to_str().unwrap(),
            "--k",
            "1",
        ])
        .assert()
        .code(1)
        .stderr(
            "error: bad synthesis request: --k 1 is below the minimum 2 for class 1R (dof + 1)\n",
        );
}

/// Guards 3R end to end with the `arm` reading of Eq. 30 (`--normal-cone arm`): the
/// cone-sweep example closes (E_valiTime = 1, E_maxDist ≤ −ε) with reduced settings, the
/// file records the cone it was designed with, `--check` passes, and the same file claimed
/// to use the printed cone (|n·p̂| ≤ sin 10°) fails the cone check.
#[test]
fn synth_3r_with_arm_cone_closes_and_check_knows_the_cone() {
    let _serial = serial_group::alone();
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("cs");
    synth_reduced(
        "data/motions/cone-sweep.toml",
        &out,
        &["--k", "6", "--dx", "6", "--normal-cone", "arm"],
    )
    .success()
    .stdout(predicate::str::contains("3R"));
    let file = out.join("mechanism.json");
    let text = std::fs::read_to_string(&file).unwrap();
    let json: serde_json::Value = serde_json::from_str(&text).unwrap();
    assert_eq!(json["class"], "3R");
    assert_eq!(json["solve"]["normal_cone"], "arm");
    assert_eq!(json["closure"]["vali_time"], 1.0);
    assert!(json["closure"]["max_dist"].as_f64().unwrap() <= -0.02);
    Command::cargo_bin("mpc-rig")
        .unwrap()
        .args(["synth", "--check", file.to_str().unwrap()])
        .assert()
        .success()
        .stdout(predicate::str::contains("arm cone"));
    let mut claimed = json;
    claimed["solve"]["normal_cone"] = serde_json::json!("tangent");
    let bad = dir.path().join("claimed-tangent.json");
    std::fs::write(&bad, serde_json::to_string(&claimed).unwrap()).unwrap();
    Command::cargo_bin("mpc-rig")
        .unwrap()
        .args(["synth", "--check", bad.to_str().unwrap()])
        .assert()
        .code(2)
        .stdout(predicate::str::contains("FAIL 3R normal cone"));
}
