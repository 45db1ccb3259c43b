//! The main job end to end, the code path of `cargo run --release -- demo` on the target
//! plant: synthesis (reduced effort with `--quick`), the simulated stepper bench on a
//! pseudo-terminal, the real session, analysis and report; then the cached mechanism is
//! reused and an injected backlash shows up in the report. The default geometry plant adds
//! a synthesis with the printable layout and a build of the parts (minutes at the default
//! cell, measured by hand: docs/simulate.md); here it runs on a given printable mechanism
//! (`--mechanism`) at coarse cells, and its refusals run.

use crate::support::serial_group;
use std::path::{Path, PathBuf};

fn demo(out: &Path, extra: &[&str]) -> (std::process::Output, String) {
    let out = assert_cmd::Command::cargo_bin("mpc-rig")
        .unwrap()
        .args([
            "demo", "--quick", "--plant", "target", "--cycles", "2", "--speed", "60", "-o",
        ])
        .arg(out)
        .args(extra)
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
    (out, stdout)
}

fn summary_of(stdout: &str) -> serde_json::Value {
    let line = stdout
        .lines()
        .find(|l| l.starts_with("summary:"))
        .expect("summary path printed");
    let path = PathBuf::from(line.trim_start_matches("summary:").trim());
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

/// Guards the demo: it prints the mechanism, recording and report locations and the
/// half-turn ratio against 2.0 (measured within 0.05 of 2 on the simulated bench), writes
/// summary.json inside the output directory, reuses the cached mechanism on the second
/// run, and `--fault backlash=2` yields a driver-side backlash of 2° ± 0.5°.
#[test]
fn demo_end_to_end_with_cache_and_backlash() {
    let _serial = serial_group::alone();
    let tmp = tempfile::tempdir().unwrap();
    let (out, stdout) = demo(tmp.path(), &[]);
    assert!(
        out.status.success(),
        "{stdout}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(
        stdout.contains("mechanism:") && stdout.contains("report.html"),
        "{stdout}"
    );
    assert!(stdout.contains("vs target 2.000"), "{stdout}");
    let s = summary_of(&stdout);
    let r = s["headline"]["timing_ratio_measured"].as_f64().unwrap();
    assert!((r - 2.0).abs() < 0.05, "ratio {r}");
    assert!(s["headline"]["rms_error_deg"].as_f64().unwrap() < 2.0);
    // The synthesis charts beside the mechanism, as `synth` writes them.
    let mechanism = stdout
        .lines()
        .find_map(|l| l.strip_prefix("mechanism:"))
        .map(|p| PathBuf::from(p.trim()))
        .expect("mechanism path printed");
    let charts = mechanism.parent().unwrap().join("report");
    for chart in ["dist.png", "torque-arm.svg", "normals-worst.png"] {
        assert!(
            charts.join(chart).exists(),
            "no {chart} in {}",
            charts.display()
        );
    }

    let (out, stdout) = demo(tmp.path(), &["--fault", "backlash=2"]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(stdout.contains("(cached)"), "{stdout}");
    let s = summary_of(&stdout);
    let b = s["headline"]["backlash_driver_deg"].as_f64().unwrap();
    assert!((b - 2.0).abs() < 0.5, "backlash {b}");
    // The printed figure carries its standard error, as summary.json has it.
    let e = s["lag"]["backlash_driver_std_err_deg"].as_f64().unwrap();
    let line = format!(
        "backlash: {} ± {}° of driver angle",
        mpc_rig::analysis::report::f3(b),
        mpc_rig::analysis::report::f3(e)
    );
    assert!(stdout.contains(&line), "no `{line}` in {stdout}");
}

/// Guards the demo's argument checks (issue 20: `demo --cycles 0` or `--speed 500` ran the
/// synthesis before refusing): a plan the bench would refuse is refused before step 1, and
/// nothing is written.
#[test]
fn a_plan_the_bench_refuses_is_refused_before_the_synthesis() {
    let tmp = tempfile::tempdir().unwrap();
    for (args, why) in [
        (
            ["--cycles", "0"],
            "refused: at least one measured cycle is needed",
        ),
        (
            ["--speed", "500"],
            "refused: 500 rpm exceeds safety.max_speed_rpm = 120 of rig `sim-stepper`",
        ),
    ] {
        // Whole: no "[1/4]" step line, so nothing ran before the refusal.
        assert_eq!(
            refused_demo(tmp.path(), &args),
            format!("error: the demo's run on rig rigs/sim-stepper.toml\n  caused by: {why}\n")
        );
    }
}

/// Run `mpc-rig demo -o OUT ARGS`, which must exit 1 having written nothing into `out`;
/// its standard error.
fn refused_demo(out: &Path, args: &[&str]) -> String {
    let run = assert_cmd::Command::cargo_bin("mpc-rig")
        .unwrap()
        .args(["demo", "-o"])
        .arg(out)
        .args(args)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&run.stderr).into_owned();
    assert_eq!(run.status.code(), Some(1), "{stderr}");
    assert_eq!(std::fs::read_dir(out).unwrap().count(), 0);
    stderr
}

/// Guards the plant's refusals before step 1, writing nothing: `--plant geometry` on a 3R
/// example (the parts' prediction does not handle it) says why and what measures it
/// instead; a build option out of range is refused before minutes of synthesis.
#[test]
fn the_geometry_plant_is_refused_for_a_class_it_cannot_predict() {
    let tmp = tempfile::tempdir().unwrap();
    assert_eq!(
        refused_demo(
            tmp.path(),
            &["--example", "spherical-four-bar", "--plant", "geometry"]
        ),
        "error: --plant geometry: the parts' prediction (`mpc-rig simulate`) handles 1R and \
         1R1T mechanisms; this motion is 3R. `--plant target` measures it on the target law\n"
    );
    // A build option out of range is refused before the synthesis, in the build's words.
    assert_eq!(
        refused_demo(tmp.path(), &["--cell-mm", "5"]),
        "error: --cell-mm: 5 is outside 0.1–1\n"
    );
}

/// Guards the demo's geometry path on a given mechanism (the printable half-turn-2to1 of
/// tests/data): its parts are built (at 1 mm cells, a preview whose mesh error the build's
/// check fails, so they are reported not printable and used all the same), their motion
/// predicted, the bench's follower moved by that prediction, and the summary compares the
/// measurement with target and prediction and carries the parts' verdict. The parts are
/// cached under OUT/mechanisms/, not beside the given file, and a second run reuses them.
#[test]
fn demo_measures_the_parts_of_a_given_mechanism() {
    let _serial = serial_group::alone();
    let tmp = tempfile::tempdir().unwrap();
    let given =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/mechanism/half-turn-2to1-printable");
    let run = || {
        let out = assert_cmd::Command::cargo_bin("mpc-rig")
            .unwrap()
            .args(["demo", "--mechanism"])
            .arg(&given)
            .args(["--cell-mm", "1", "--cycles", "1", "--speed", "60", "-o"])
            .arg(tmp.path())
            .output()
            .unwrap();
        let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
        let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
        assert!(out.status.success(), "{stdout}\n{stderr}");
        (stdout, stderr)
    };
    let (stdout, stderr) = run();
    assert!(
        stdout.contains(&format!(
            "mechanism: {} (given)",
            given.join("mechanism.json").display()
        )),
        "{stdout}"
    );
    assert!(
        stderr.contains("[2/6] printable parts at 1 mm cells"),
        "{stderr}"
    );
    // The coarse preview fails the build's check, which says so; the demo goes on.
    let parts = line_of(&stdout, "parts:").trim();
    assert!(parts.contains("NOT printable"), "{parts}");
    let parts_dir = PathBuf::from(parts.split(" (").next().unwrap());
    assert!(
        parts_dir.starts_with(tmp.path().join("mechanisms")),
        "{}",
        parts_dir.display()
    );
    for f in [
        "build.json",
        "driver.stl",
        "follower.stl",
        "support.stl",
        "assembly.glb",
    ] {
        assert!(
            parts_dir.join(f).exists(),
            "no {f} in {}",
            parts_dir.display()
        );
    }
    // Every part's walls and mesh error are measured (the figures themselves are the unit
    // tests' and docs/build.md's).
    let build: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(parts_dir.join("build.json")).unwrap())
            .unwrap();
    for part in build["parts"].as_array().unwrap() {
        let w = &part["walls"];
        let (area, thin) = (
            w["area_mm2"].as_f64().unwrap(),
            w["thin_area_mm2"].as_f64().unwrap(),
        );
        assert!(area > 0.0 && (0.0..=area).contains(&thin), "{part}");
        assert_eq!(w["thin_below_mm"], serde_json::json!(0.8), "{part}");
        let e = &part["mesh_error"];
        let [mean, p99, max] = ["mean_mm", "p99_mm", "max_mm"].map(|k| e[k].as_f64().unwrap());
        assert!(e["samples"].as_u64().unwrap() > 0, "{part}");
        assert!(0.0 <= mean && mean <= p99 && p99 <= max, "{part}");
    }
    let md = std::fs::read_to_string(parts_dir.join("build.md")).unwrap();
    assert!(md.contains("\n- support: "), "{md}");
    let predicted = PathBuf::from(line_of(&stdout, "predicted:").trim());
    assert_eq!(predicted, parts_dir.join("prediction/prediction.json"));
    assert!(predicted.exists());
    // The bench's follower moved as the parts move it: the measurement is nearer the
    // prediction than the target.
    let s = summary_of(&stdout);
    let p = &s["prediction"];
    let (rms_pred, rms_target) = (
        p["rms_deg"].as_f64().unwrap(),
        p["rms_vs_target_deg"].as_f64().unwrap(),
    );
    assert!(
        rms_pred < 0.5 * rms_target,
        "vs prediction {rms_pred}°, vs target {rms_target}°"
    );
    assert_eq!(s["parts"]["printable"], serde_json::json!(false));
    assert!(stdout.contains("predict:"), "{stdout}");

    let (stdout, stderr) = run();
    assert!(
        line_of(&stdout, "parts:").contains("(cached, NOT printable"),
        "{stdout}"
    );
    assert!(stderr.contains("reusing"), "{stderr}");
}

/// The rest of the headline line that starts with `prefix`.
fn line_of<'a>(stdout: &'a str, prefix: &str) -> &'a str {
    stdout
        .lines()
        .find_map(|l| l.strip_prefix(prefix))
        .unwrap_or_else(|| panic!("no `{prefix}` line in {stdout}"))
}
