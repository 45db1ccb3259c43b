//! End-to-end tests of `mpc-rig build` that stop early: the refusals a user meets first (the
//! refused build plans the parts before it refuses, 10–20 s). A full build of a printable design
//! takes many minutes; see docs/build.md for its figures.

use crate::support::serial_group;
use assert_cmd::Command;

const TEST_MECHANISM: &str = "tests/data/mechanism/half-turn-2to1";

/// Guards what a user sees when the design leaves no room for a part: the whole message
/// (which plate, why, whose bands' sweep stops its struts, and which synthesis options
/// make room), exit 1, and no output folder.
/// The test mechanism was synthesized with the default band gap, whose follower cannot be
/// joined (docs/build.md, "Printable designs").
#[test]
fn a_design_without_room_is_refused_whole_and_writes_nothing() {
    let _serial = serial_group::alone();
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("parts");
    let assert = Command::cargo_bin("mpc-rig")
        .unwrap()
        .args(["build", TEST_MECHANISM, "-o", out.to_str().unwrap()])
        .assert()
        .code(1);
    let stderr = String::from_utf8_lossy(&assert.get_output().stderr).to_string();
    let tail: Vec<&str> = stderr.lines().rev().take(2).collect();
    assert_eq!(
        tail,
        vec![
            "  caused by: cannot join plate 2 (curve pair 2): of the 225 rays leaving it, 220 \
             come within 1.9 mm of the other part's moving contact surfaces and 5 reach no \
             point 3.4 mm clear of the other part's swept volume within 12 mm, so no strut can \
             start there (rays stopped by the sweep of pair 2's band (187), pair 1's band \
             (34)). The design leaves no room for it: synthesize with `mpc-rig synth \
             --printable` (docs/build.md, \"Printable designs\")",
            "error: building tests/data/mechanism/half-turn-2to1/mechanism.json",
        ],
        "stderr:\n{stderr}"
    );
    assert!(!out.exists(), "nothing is written for a refused build");
}

/// Guards the option errors at the command line: the option as typed, its range, exit 1,
/// before any work.
#[test]
fn out_of_range_options_are_refused() {
    let assert = Command::cargo_bin("mpc-rig")
        .unwrap()
        .args(["build", TEST_MECHANISM, "--clearance", "3"])
        .assert()
        .code(1);
    let stderr = String::from_utf8_lossy(&assert.get_output().stderr).to_string();
    assert!(
        stderr.ends_with("  caused by: --clearance: 3 is outside 0–2\n"),
        "stderr:\n{stderr}"
    );
}
