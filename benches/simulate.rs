//! Virtual prototype benchmark (issue 15): `mpc-rig simulate` on every set of built parts it
//! finds, each prediction in a fresh child process so that the peak resident memory it
//! prints (`VmHWM`) is that prediction's alone. Prints per design: class, the vertices
//! traced (driver + follower), the seconds of the free-turn trace over one period, the rest
//! of the prediction's seconds (nearly all of it reading and preparing the two meshes; the
//! law and the comparison with the file's closure are the remainder), the whole, the
//! distance queries, the peak memory and the target for the class.
//!
//! Parts are looked for where the other commands leave them: the build benchmark's designs
//! (`BUILD_BENCH_DIR`, default `target/build-bench`, each `<motion>/mechanism.json` with
//! its `parts-*/`) and the demo's cache (`out/demo/mechanism-*/parts-*/`). Run `cargo
//! bench --bench build` or `cargo run --release -- demo` first. `SIMULATE_BENCH_SAMPLES`
//! sets the driver angles per period (default: `simulate`'s own, 1 440).
//!
//! Target (issue 15): one period at ≥ 1 440 driver angles in ≤ 2 s for 1R and ≤ 10 s for 3R
//! on this 2-core machine. The machine's load average is printed before and after: figures
//! taken on a loaded machine are not comparable.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

use mpc_rig::predict::{predict, PredictOptions, DEFAULT_SAMPLES};
use mpc_rig::synth::closure::Class;
use mpc_rig::synth::mechanism::Mechanism;

#[path = "support/process.rs"]
mod process;

/// Set in the child: the mechanism file and the parts folder, separated by a newline.
const CHILD_ENV: &str = "MPC_BENCH_SIMULATE_ONE";
/// What the child prints before its figures, so the parent finds them among its output.
const RESULT_TAG: &str = "simulate-bench-result";

/// The target for one period, seconds, per class; `None` where it sets none.
fn target_s(class: Class) -> Option<f64> {
    match class {
        Class::R1 => Some(2.0),
        Class::R3 => Some(10.0),
        _ => None,
    }
}

fn main() {
    if let Ok(one) = std::env::var(CHILD_ENV) {
        let (mech, parts) = one.split_once('\n').expect("mechanism and parts");
        child(Path::new(mech), Path::new(parts));
        return;
    }
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let designs = found_parts(&root);
    println!("load average before: {}", process::load_average());
    if designs.is_empty() {
        println!(
            "no built parts found: run `cargo bench --bench build` (parts under {}) or \
             `cargo run --release -- demo` (under out/demo/) first",
            build_bench_dir(&root).display()
        );
        return;
    }
    println!(
        "{:<60} {:<5} {:>19} {:>7} {:>6} {:>7} {:>10} {:>8} {:>8}  result",
        "design",
        "class",
        "vertices d+f",
        "trace s",
        "rest s",
        "total s",
        "queries",
        "peak MB",
        "target s"
    );
    let exe = std::env::current_exe().expect("the benchmark knows its path");
    for (name, mech, parts) in designs {
        let out = Command::new(&exe)
            .env(
                CHILD_ENV,
                format!("{}\n{}", mech.display(), parts.display()),
            )
            .output()
            .expect("the benchmark runs itself");
        let text = String::from_utf8_lossy(&out.stdout);
        match text.lines().find_map(|l| l.strip_prefix(RESULT_TAG)) {
            Some(row) => println!("{name:<60}{row}"),
            None => println!(
                "{name:<60} failed: {}",
                String::from_utf8_lossy(&out.stderr).trim()
            ),
        }
    }
    println!("load average after:  {}", process::load_average());
}

/// One prediction, timed: prints its row after [`RESULT_TAG`].
fn child(mech_path: &Path, parts: &Path) {
    let mech = match Mechanism::load(mech_path) {
        Ok(m) => m,
        Err(e) => {
            println!("{RESULT_TAG} unreadable mechanism: {e}");
            return;
        }
    };
    let samples = std::env::var("SIMULATE_BENCH_SAMPLES")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(DEFAULT_SAMPLES);
    let opts = PredictOptions {
        samples,
        ..PredictOptions::default()
    };
    let class = mech.class;
    let target = target_s(class).map_or("–".to_string(), |t| format!("{t:.0}"));
    let t0 = Instant::now();
    let result = predict(&mech, parts, &opts);
    let total = t0.elapsed().as_secs_f64();
    let p = match result {
        Ok(p) => p,
        Err(e) => {
            println!(
                "{RESULT_TAG} {:<5} {:>19} {:>7} {:>6} {:>7} {:>10} {:>8} {target:>8}  \
                 not predicted: {e}",
                class.label(),
                "–",
                "–",
                "–",
                "–",
                "–",
                "–"
            );
            return;
        }
    };
    let rest = total - p.seconds;
    let verdict = match target_s(class) {
        Some(t) if total <= t => format!("within the {t:.0} s target"),
        Some(t) if p.seconds <= t => format!("trace within the {t:.0} s target, the whole not"),
        Some(t) => format!(
            "over the {t:.0} s target: trace {:.1}×, whole {:.1}×",
            p.seconds / t,
            total / t
        ),
        None => "no target for the class".to_string(),
    };
    println!(
        "{RESULT_TAG} {:<5} {:>19} {:>7.1} {rest:>6.1} {total:>7.1} {:>10} {:>8} {target:>8}  \
         {verdict} ({samples} angles)",
        class.label(),
        format!("{} + {}", p.vertices[0], p.vertices[1]),
        p.seconds,
        p.queries,
        process::peak_rss_mb().map_or("–".to_string(), |m| format!("{m:.0}")),
    );
}

fn build_bench_dir(root: &Path) -> PathBuf {
    std::env::var("BUILD_BENCH_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|_| root.join("target/build-bench"))
}

/// (name, mechanism file, parts folder) of every built set of parts: a folder holding
/// `build.json` beside (or below) a `mechanism.json`, sorted by name.
fn found_parts(root: &Path) -> Vec<(String, PathBuf, PathBuf)> {
    let mut found = Vec::new();
    for base in [build_bench_dir(root), root.join("out/demo")] {
        let Ok(entries) = std::fs::read_dir(&base) else {
            continue;
        };
        for design in entries.filter_map(|e| e.ok().map(|e| e.path())) {
            let mech = design.join("mechanism.json");
            let Ok(inner) = std::fs::read_dir(&design) else {
                continue;
            };
            if !mech.exists() {
                continue;
            }
            for parts in inner.filter_map(|e| e.ok().map(|e| e.path())) {
                let is_parts = parts
                    .file_name()
                    .is_some_and(|n| n.to_string_lossy().starts_with("parts-"));
                if is_parts && parts.join("build.json").exists() {
                    let name = format!(
                        "{}/{}",
                        design.file_name().unwrap_or_default().to_string_lossy(),
                        parts.file_name().unwrap_or_default().to_string_lossy()
                    );
                    found.push((name, mech.clone(), parts));
                }
            }
        }
    }
    found.sort();
    found
}
