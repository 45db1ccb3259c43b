//! Synthesis benchmark: synthesizes every example in `data/motions/` with the default
//! settings and prints, per example, K, d_x, E_valiTime, E_maxDist (paper and robust), the
//! robust E_maxDist at 4× the samples (the accepted margin), the worst conjugation
//! residual, the wall-clock seconds, and the best robust E_valiTime at 4× that every (K,
//! d_x) tried reached (`K@d_x:figure`, `K-@…` for a combination that leaves bands out of
//! one that closed; `Kp3@d_x:margin`, for round 3 of the 3R margin push, gives the robust
//! E_maxDist at 4× that round reached instead, since every round closes).
//!
//! Run with `cargo bench --bench synth`. Set `SYNTH_BENCH_FILTER=<substring>` to run only
//! matching motion files, `SYNTH_BENCH_THREADS=<n>` to fix the thread count and
//! `SYNTH_BENCH_CONE=arm` for the `arm` reading of the 3R cone (`--normal-cone arm`).
//! Targets (issue 17): K no larger than the paper's for the class (1R 3, 1R1T 4, 3R 5–6;
//! quarter-turn-dwell at most 5), every example ≤ 30 s on this 2-core machine, closed at
//! every instant of the 4× check (paper and robust).

use std::time::Instant;

use mpc_rig::motion::Motion;
use mpc_rig::synth::closure::NormalCone;
use mpc_rig::synth::{synthesize, NoProgress, Outcome, SynthOptions};

#[path = "support/examples.rs"]
mod examples;

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
    let files = examples::example_motions(&filter);
    println!(
        "{:<22} {:<5} {:>2} {:>5} {:>8} {:>9} {:>8} {:>9} {:>9} {:>8} {:>8}  result; tried",
        "motion",
        "class",
        "K",
        "d_x",
        "valiTime",
        "maxDist",
        "r.vali",
        "r.maxDist",
        "r.max@4x",
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
            Ok(Outcome::Infeasible { best, .. }) => (best, "NOT ACCEPTED"),
            Ok(Outcome::Cancelled { best }) => (best, "cancelled"),
            Err(e) => {
                println!("{name:<22} error: {e} ({secs:.1} s)");
                continue;
            }
        };
        match m {
            Some(m) => {
                let tried: Vec<String> = m
                    .solve
                    .attempts
                    .iter()
                    .map(|a| {
                        let o = a.oversampled.as_ref();
                        let out = if a.left_out.is_empty() { "" } else { "-" };
                        if a.pushed > 0 {
                            let r = o.map_or(0.0, |o| o.robust_max_dist);
                            format!("{}{out}p{}@{}:{r:.3}", a.k, a.pushed, a.dx)
                        } else {
                            let r = o.map_or(0.0, |o| o.robust_vali_time);
                            format!("{}{out}@{}:{r:.3}", a.k, a.dx)
                        }
                    })
                    .collect();
                println!(
                    "{:<22} {:<5} {:>2} {:>5.2} {:>8.4} {:>9.4} {:>8.4} {:>9.4} {:>9.4} {:>8.3} {:>8.1}  {}; {}",
                    name,
                    m.class.label(),
                    m.curve_pairs.len(),
                    m.driver_offset,
                    m.closure.vali_time,
                    m.closure.max_dist.min(99.0),
                    m.closure.robust_vali_time,
                    m.closure.robust_max_dist.min(99.0),
                    m.closure
                        .oversampled
                        .as_ref()
                        .map_or(f64::NAN, |o| o.robust_max_dist.min(99.0)),
                    m.closure.worst_residual_deg,
                    secs,
                    verdict,
                    tried.join(" ")
                )
            }
            None => println!("{name:<22} no mechanism ({secs:.1} s)"),
        }
    }
}
