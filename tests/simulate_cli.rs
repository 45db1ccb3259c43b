//! End-to-end tests of `mpc-rig simulate` (the virtual prototype, docs/simulate.md).

use assert_cmd::Command;

const TEST_MECHANISM: &str = "tests/data/mechanism/half-turn-2to1";

/// Guards what a user who has not built the parts yet sees: the file that is missing, and
/// the command that makes it, exit 1, nothing written.
#[test]
fn simulating_without_built_parts_says_to_build_them() {
    let dir = tempfile::tempdir().unwrap();
    let parts = dir.path().join("no-parts");
    let out = dir.path().join("prediction");
    let assert = Command::cargo_bin("mpc-rig")
        .unwrap()
        .args([
            "simulate",
            TEST_MECHANISM,
            "--parts",
            parts.to_str().unwrap(),
            "-o",
            out.to_str().unwrap(),
        ])
        .assert()
        .code(1);
    let stderr = String::from_utf8_lossy(&assert.get_output().stderr).to_string();
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
    let assert = Command::cargo_bin("mpc-rig")
        .unwrap()
        .args(["simulate", TEST_MECHANISM, "--samples", "100"])
        .assert()
        .code(1);
    let stderr = String::from_utf8_lossy(&assert.get_output().stderr).to_string();
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
    let assert = Command::cargo_bin("mpc-rig")
        .unwrap()
        .args([
            "sim-device",
            "stepper",
            "--mechanism",
            TEST_MECHANISM,
            "--prediction",
            missing.to_str().unwrap(),
        ])
        .assert()
        .code(1);
    let stderr = String::from_utf8_lossy(&assert.get_output().stderr).to_string();
    assert_eq!(
        stderr,
        format!(
            "error: reading the prediction for the geometry plant\n  caused by: {}: No such \
             file or directory (os error 2)\n",
            missing.display()
        )
    );
    assert!(
        assert.get_output().stdout.is_empty(),
        "no device path printed"
    );
}
