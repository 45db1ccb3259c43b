//! Build benchmark (issue 14): for every example in `data/motions/`, a printable design
//! (`mpc-rig synth MOTION --printable`, the layout docs/build.md says the parts need; the
//! same options `demo` synthesizes with) and its parts (`mpc-rig build`), each in a child
//! process as a user runs them. Prints per example: class, K, d_x, the synthesis seconds,
//! the build's seconds per stage, its peak resident memory, the triangles per part, the
//! mesh error (99th percentile, largest, and largest away from sharp edges, each of the
//! part where it is widest; see docs/build.md, "Mesh error") and the verdict (printable, not printable and why, or
//! where the command stopped).
//!
//! Run with `cargo bench --bench build`. Designs are kept in `BUILD_BENCH_DIR` (default
//! `target/build-bench`) and reused, so a second run times the builds alone; delete the
//! folder to synthesize again. `BUILD_BENCH_FILTER=<substring>` runs only matching motion
//! files; `BUILD_BENCH_CELL_MM=<mm>` sets the mesher cell (default: the build's own, the
//! one its check's tolerances are set for).
//!
//! Target (issue 14): each build under 60 s and 4 GiB on this 2-core machine, at a cell
//! that keeps geometric error below 0.1 mm. Figures taken on a loaded machine are not
//! comparable: say the load with them.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

use mpc_rig::build::dims;
use serde_json::Value;

#[path = "support/examples.rs"]
mod examples;

fn main() {
    let filter = std::env::var("BUILD_BENCH_FILTER").unwrap_or_default();
    let cell = std::env::var("BUILD_BENCH_CELL_MM").ok();
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let work = std::env::var("BUILD_BENCH_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|_| root.join("target/build-bench"));
    let exe = env!("CARGO_BIN_EXE_mpc-rig");
    let files = examples::example_motions(&filter);
    let default_cell = format!("{} (the build's default)", dims::DEFAULT_CELL_MM);
    println!(
        "cell: {} mm; designs and parts in {}",
        cell.as_deref().unwrap_or(&default_cell),
        work.display()
    );
    println!(
        "{:<20} {:<5} {:>2} {:>5} {:>7} {:>8} {:>7} {:>7} {:>7} {:>6} {:>6} {:>6} {:>7}  {:>20} {:>18}  result",
        "motion",
        "class",
        "K",
        "d_x",
        "synth s",
        "build s",
        "design",
        "driver",
        "follow",
        "supp",
        "check",
        "files",
        "peak MB",
        "triangles d/f/s",
        "err p99/max/smooth"
    );
    for f in files {
        let name = f.file_stem().unwrap().to_string_lossy().into_owned();
        let dir = work.join(&name);
        let mech = dir.join("mechanism.json");
        let synth_s = if mech.exists() {
            "kept".to_string()
        } else {
            let t0 = Instant::now();
            let out = Command::new(exe)
                .arg("synth")
                .arg(&f)
                .arg("--printable")
                .arg("-q")
                .arg("-o")
                .arg(&dir)
                .output()
                .expect("mpc-rig runs");
            let s = t0.elapsed().as_secs_f64();
            if !mech.exists() {
                println!(
                    "{name:<20} no printable design ({s:.0} s): {}",
                    failure_line(&out.stderr)
                );
                continue;
            }
            format!("{s:.0}")
        };
        let design = read_json(&mech);
        let parts = dir.join(format!("parts-{}", cell.as_deref().unwrap_or("default")));
        let mut cmd = Command::new(exe);
        cmd.arg("build").arg(&mech).arg("-q").arg("-o").arg(&parts);
        if let Some(c) = &cell {
            cmd.args(["--cell-mm", c]);
        }
        // A build.json left by an earlier run must not pass for this one.
        let _ = std::fs::remove_file(parts.join("build.json"));
        let t0 = Instant::now();
        let out = cmd.output().expect("mpc-rig runs");
        let build_s = t0.elapsed().as_secs_f64();
        let head = format!(
            "{name:<20} {:<5} {:>2} {:>5.2} {synth_s:>7} {build_s:>8.0}",
            design["class"].as_str().unwrap_or("?"),
            design["curve_pairs"].as_array().map_or(0, Vec::len),
            design["driver_offset"].as_f64().unwrap_or(f64::NAN),
        );
        let report = parts.join("build.json");
        if !report.exists() {
            println!("{head}  stopped: {}", failure_line(&out.stderr));
            continue;
        }
        let b = read_json(&report);
        let stage = |s: &str| {
            b["timings_s"]
                .as_array()
                .and_then(|a| a.iter().find(|t| t["stage"] == s))
                .and_then(|t| t["seconds"].as_f64())
                .map_or("–".to_string(), |v| format!("{v:.0}"))
        };
        let triangles: Vec<String> = b["parts"]
            .as_array()
            .map(|ps| ps.iter().map(|p| p["triangles"].to_string()).collect())
            .unwrap_or_default();
        // The mesh error of the part with the widest 99th percentile (mm).
        let worst = |key: &str| {
            b["parts"]
                .as_array()
                .and_then(|ps| {
                    ps.iter()
                        .filter_map(|p| p["mesh_error"][key].as_f64())
                        .max_by(f64::total_cmp)
                })
                .map_or("–".to_string(), |v| format!("{v:.2}"))
        };
        let error = format!(
            "{}/{}/{}",
            worst("p99_mm"),
            worst("max_mm"),
            worst("smooth_max_mm")
        );
        let verdict = if b["printable"] == true {
            "printable, check passes".to_string()
        } else {
            let first = b["problems"][0].as_str().unwrap_or("no reason given");
            format!("NOT PRINTABLE: {first}")
        };
        println!(
            "{head} {:>7} {:>7} {:>7} {:>6} {:>6} {:>6} {:>7}  {:>20} {error:>18}  {verdict}",
            stage("design"),
            stage("mesh driver"),
            stage("mesh follower"),
            stage("mesh support"),
            stage("check"),
            stage("files"),
            b["peak_memory_mb"]
                .as_f64()
                .map_or("–".to_string(), |m| format!("{m:.0}")),
            triangles.join("/"),
        );
    }
}

fn read_json(path: &Path) -> Value {
    let text = std::fs::read_to_string(path).expect("the command wrote it");
    serde_json::from_str(&text).expect("the command writes valid JSON")
}

/// What a command's error output says about why it failed, for the table: its `error:`
/// line and the `caused by:` line under it, or failing those its first line. A failed
/// synthesis prints every attempt before it, a build its progress.
fn failure_line(stderr: &[u8]) -> String {
    let text = String::from_utf8_lossy(stderr);
    let lines: Vec<&str> = text.lines().filter(|l| !l.trim().is_empty()).collect();
    match lines.iter().position(|l| l.starts_with("error:")) {
        Some(i) => {
            let cause = lines
                .get(i + 1)
                .map(|l| l.trim())
                .filter(|l| l.starts_with("caused by:"));
            match cause {
                Some(c) => format!("{} {c}", lines[i]),
                None => lines[i].to_string(),
            }
        }
        None => lines.first().unwrap_or(&"(no message)").to_string(),
    }
}
