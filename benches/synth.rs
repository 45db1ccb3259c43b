//! Synthesis benchmark: synthesizes every example in `data/motions/` with the default
//! settings and prints, per example, K, d_x, E_valiTime, E_maxDist (paper and robust),
//! the worst conjugation residual and the wall-clock seconds.
//!
//! Run with `cargo bench --bench synth`. Set `SYNTH_BENCH_FILTER=<substring>` to run only
//! matching motion files, `SYNTH_BENCH_THREADS=<n>` to fix the thread count and
//! `SYNTH_BENCH_CONE=arm` for the `arm` reading of the 3R cone (`--normal-cone arm`).
//! Target (issue 3): every example under 60 s on a 2-core machine with E_valiTime = 1
//! (paper and robust).

use std::path::PathBuf;
use std::time::Instant;

use mpc_rig::motion::Motion;
use mpc_rig::synth::closure::NormalCone;
use mpc_rig::synth::{synthesize, NoProgress, Outcome, SynthOptions};

fn main() {
    let filter = std::env::var("SYNTH_BENCH_FILTER").unwrap_or_default();
    let threads = std::env::var("SYNTH_BENCH_THREADS")
        .ok()
        .and_then(|v| v.parse().ok());
    // SYNTH_BENCH_CONE=arm: 3R with the `arm` reading of Eq. 30 (see `NormalCone`).
    let cone = match std::env::var("SYNTH_BENCH_CONE").as_deref() {
        Ok("arm") => NormalCone::Arm,
        _ => NormalCone::Tangent,
    };
    println!("3R normal cone: {}", cone.label());
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("data/motions");
    let mut files: Vec<PathBuf> = std::fs::read_dir(&dir)
        .expect("data/motions exists")
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| x == "toml"))
        .filter(|p| p.to_string_lossy().contains(&filter))
        .collect();
    files.sort();
    println!(
        "{:<22} {:<5} {:>2} {:>5} {:>8} {:>9} {:>8} {:>9} {:>8} {:>8}  result",
        "motion",
        "class",
        "K",
        "d_x",
        "valiTime",
        "maxDist",
        "r.vali",
        "r.maxDist",
        "resid°",
        "seconds"
    );
    for f in files {
        let name = f.file_stem().unwrap().to_string_lossy().into_owned();
        let motion = match Motion::from_file(&f) {
            Ok(m) => m,
            Err(e) => {
                println!("{name:<22} cannot load: {e}");
                continue;
            }
        };
        let opts = SynthOptions {
            threads,
            cone,
            ..SynthOptions::default()
        };
        let t0 = Instant::now();
        let r = synthesize(&motion, &opts, &NoProgress);
        let secs = t0.elapsed().as_secs_f64();
        let (m, verdict) = match r {
            Ok(Outcome::Accepted(m)) => {
                let ok = m.check().passed();
                (
                    Some(m),
                    if ok {
                        "accepted, check ok"
                    } else {
                        "accepted, CHECK FAILS"
                    },
                )
            }
            Ok(Outcome::Infeasible { best: None, reason }) => {
                // No combination was ever scored: say why (the reason's first clause).
                let why = reason.split(':').next().unwrap_or(&reason);
                println!("{name:<22} not accepted, no GA run: {why} ({secs:.1} s)");
                continue;
            }
            Ok(Outcome::Infeasible { best, .. }) => (best.map(|b| *b), "NOT ACCEPTED"),
            Ok(Outcome::Cancelled { best }) => (best.map(|b| *b), "cancelled"),
            Err(e) => {
                println!("{name:<22} error: {e} ({secs:.1} s)");
                continue;
            }
        };
        match m {
            Some(m) => println!(
                "{:<22} {:<5} {:>2} {:>5.2} {:>8.4} {:>9.4} {:>8.4} {:>9.4} {:>8.3} {:>8.1}  {}",
                name,
                m.class.label(),
                m.curve_pairs.len(),
                m.driver_offset,
                m.closure.vali_time,
                m.closure.max_dist.min(99.0),
                m.closure.robust_vali_time,
                m.closure.robust_max_dist.min(99.0),
                m.closure.worst_residual_deg,
                secs,
                verdict
            ),
            None => println!("{name:<22} no mechanism ({secs:.1} s)"),
        }
    }
}
