//! The main job end to end, the code path of `cargo run --release -- demo` on the target
//! plant: synthesis (reduced effort with `--quick`), the simulated stepper bench on a
//! pseudo-terminal, the real session, analysis and report; then the cached mechanism is
//! reused and an injected backlash shows up in the report. The default geometry plant adds
//! a build of the parts (minutes at the default cell) and is measured by hand
//! (docs/simulate.md); here only its refusals run.

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
    let _serial = serial_group::lock();
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

/// Guards the plant's refusals before step 1, writing nothing: `--plant geometry` on a
/// 1R1T example (the parts' prediction does not handle it) says why and what measures it
/// instead; a build option out of range is refused before minutes of synthesis.
#[test]
fn the_geometry_plant_is_refused_for_a_class_it_cannot_predict() {
    let tmp = tempfile::tempdir().unwrap();
    assert_eq!(
        refused_demo(
            tmp.path(),
            &["--example", "screw-bob", "--plant", "geometry"]
        ),
        "error: --plant geometry: the parts' prediction (`mpc-rig simulate`) handles 1R \
         mechanisms; this motion is 1R1T. `--plant target` measures it on the target law\n"
    );
    // A build option out of range is refused before the synthesis, in the build's words.
    assert_eq!(
        refused_demo(tmp.path(), &["--cell-mm", "5"]),
        "error: --cell-mm: 5 is outside 0.1–1\n"
    );
}
