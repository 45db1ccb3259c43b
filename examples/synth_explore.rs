//! Exploration aids for synthesis: what `docs/synthesis.md`'s experiments were measured with.
//! They are not part of the product (`mpc-rig synth` is); they print figures for a study.
//!
//! ```text
//! cargo run --release --example synth_explore -- band MOTION --dx 6 --band 1 -m 16
//! cargo run --release --example synth_explore -- oracle-points cone-sweep --dx 6 -k 6
//! cargo run --release --example synth_explore -- oracle-starts pick-and-place --dx 6 -k 6
//! cargo run --release --example synth_explore -- diagnose out/cs/mechanism.json cone-sweep
//! ```
//! MOTION is a file stem in `data/motions/` or a path.
//!
//! - `band`: solve M candidates of one band with the search's problem and print each
//!   outcome (start constraints, solver status, evaluations, usable or why not, residual;
//!   for 1R/1R1T the share of samples with a robust contact of each torque sign).
//! - `oracle-points` (3R, tangent cone): K contacts fixed at follower-local points, one per
//!   band, with ñ = ±ŵ⊥p exactly (what a conjugate normal in a cone with no slack gives);
//!   random search for the best worst-case dist. Asks whether closure is possible at all.
//! - `oracle-starts` (3R, tangent cone): the same ñ along M start curves per band
//!   (`candidate::initial_guess`), combined by the GA. Asks whether the starts can close.
//! - `diagnose` (3R): per pair of a mechanism file, how far ñ is from ±ŵ⊥p and where p sits.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use clap::{Parser, Subcommand};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use mpc_rig::motion::Motion;
use mpc_rig::synth::closure::{self, Class, NormalCone};
use mpc_rig::synth::combine::{self, Density};
use mpc_rig::synth::math::V3;
use mpc_rig::synth::pose::PoseTrack;
use mpc_rig::synth::{bands, candidate, ga, model, optimizer, Mechanism};

#[derive(Parser)]
#[command(about = "Exploration aids for synthesis (see docs/synthesis.md)")]
struct Cli {
    #[command(subcommand)]
    cmd: Cmd,
}

#[derive(Subcommand)]
enum Cmd {
    /// Solve the candidates of one band and print each outcome.
    Band {
        /// Motion: a file stem in data/motions/ or a path.
        motion: String,
        /// Driver offset d_x.
        #[arg(long, default_value_t = 6.0)]
        dx: f64,
        /// Band index (0 centre, then +1, −1, +2, …).
        #[arg(long, default_value_t = 0)]
        band: usize,
        /// Candidates to solve.
        #[arg(short, default_value_t = 16)]
        m: usize,
        /// Samples per period.
        #[arg(long, default_value_t = 360)]
        samples: usize,
        /// Seed.
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// SLSQP evaluation cap.
        #[arg(long, default_value_t = optimizer::MAX_EVAL)]
        max_eval: usize,
        /// 3R: use the `arm` reading of Eq. 30.
        #[arg(long)]
        arm: bool,
    },
    /// Solve K plain bands, then compare the GA's best combination with the exhaustive best.
    Pool {
        /// Motion: a file stem in data/motions/ or a path.
        motion: String,
        /// Driver offset d_x.
        #[arg(long, default_value_t = 6.0)]
        dx: f64,
        /// Bands K.
        #[arg(short, default_value_t = 3)]
        k: usize,
        /// Candidates per band.
        #[arg(short, default_value_t = 30)]
        m: usize,
        /// Seed.
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Skip the exhaustive search when it has more combinations than this.
        #[arg(long, default_value_t = 2_000_000)]
        max_combinations: usize,
        /// Band height (default: the search's).
        #[arg(long, default_value_t = bands::BAND_HEIGHT)]
        band_height: f64,
        /// Gap between bands (default: the search's).
        #[arg(long, default_value_t = bands::BAND_GAP)]
        band_gap: f64,
    },
    /// 3R oracle: contacts fixed at follower-local points with ñ = ±ŵ⊥p.
    OraclePoints {
        /// Motion (3R).
        motion: String,
        /// Driver offset d_x.
        #[arg(long, default_value_t = 6.0)]
        dx: f64,
        /// Contacts K.
        #[arg(short, default_value_t = 6)]
        k: usize,
        /// Random trials.
        #[arg(long, default_value_t = 20000)]
        trials: usize,
    },
    /// 3R oracle: ñ = ±ŵ⊥p along the start curves, combined by the GA.
    OracleStarts {
        /// Motion (3R).
        motion: String,
        /// Driver offset d_x.
        #[arg(long, default_value_t = 6.0)]
        dx: f64,
        /// Bands K.
        #[arg(short, default_value_t = 6)]
        k: usize,
        /// Start curves per band.
        #[arg(short, default_value_t = 30)]
        m: usize,
    },
    /// 3R: per pair of a mechanism file, ñ against ±ŵ⊥p and where p sits.
    Diagnose {
        /// mechanism.json (or mechanism.partial.json).
        mechanism: PathBuf,
        /// The motion it was made for.
        motion: String,
    },
}

fn main() {
    let cli = Cli::parse();
    match cli.cmd {
        Cmd::Band {
            motion,
            dx,
            band,
            m,
            samples,
            seed,
            max_eval,
            arm,
        } => solve_band(&motion, dx, band, m, samples, seed, max_eval, arm),
        Cmd::Pool {
            motion,
            dx,
            k,
            m,
            seed,
            max_combinations,
            band_height,
            band_gap,
        } => pool(
            &motion,
            dx,
            k,
            m,
            seed,
            max_combinations,
            (band_height, band_gap),
        ),
        Cmd::OraclePoints {
            motion,
            dx,
            k,
            trials,
        } => oracle_points(&motion, dx, k, trials),
        Cmd::OracleStarts { motion, dx, k, m } => oracle_starts(&motion, dx, k, m),
        Cmd::Diagnose { mechanism, motion } => diagnose(&mechanism, &motion),
    }
}

fn load_motion(name: &str) -> Motion {
    let path = if Path::new(name).exists() {
        PathBuf::from(name)
    } else {
        PathBuf::from(format!("data/motions/{name}.toml"))
    };
    Motion::from_file(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

fn track(name: &str, samples: usize) -> (Class, Arc<PoseTrack>) {
    let m = load_motion(name);
    (
        m.class().into(),
        Arc::new(PoseTrack::from_motion(&m, samples)),
    )
}

/// ŵ⊥p: the relative velocity of the follower's material point at p against the driver's,
/// its component perpendicular to p, normalized.
fn w_perp(p: V3<f64>, omega: [f64; 3], dx: f64) -> V3<f64> {
    let tau = std::f64::consts::TAU;
    let w = V3::from(omega).cross(p) + V3::new(tau * p.y, -tau * (p.x - dx), 0.0);
    (w - p.scalec(w.dot(p) / p.norm2())).unit()
}

#[allow(clippy::too_many_arguments)]
fn solve_band(
    name: &str,
    dx: f64,
    b: usize,
    m: usize,
    samples: usize,
    seed: u64,
    max_eval: usize,
    arm: bool,
) {
    let (class, tr) = track(name, samples);
    let n = tr.len();
    let cone = if arm {
        NormalCone::Arm
    } else {
        NormalCone::Tangent
    };
    let mut usable = 0;
    for i in 0..m {
        let t0 = std::time::Instant::now();
        let layout = bands::BandLayout::for_motion(class, &tr, bands::BAND_GAP);
        let mut pb = bands::band_problem(class, &tr, dx, layout, b, cone);
        if class != Class::R1 {
            pb.vary = Some((i * n / m) % n);
        }
        let x0 = candidate::initial_guess(&pb, seed, b, i);
        let e0 = pb.evaluate(&x0);
        let c = candidate::solve(&pb, optimizer::default_minimizer(), seed, b, i, max_eval);
        usable += c.valid as usize;
        let share = |s: f64| {
            c.ntilde
                .iter()
                .zip(&c.robust)
                .filter(|(v, r)| **r && v.is_some_and(|v| v[0] * s > 0.0))
                .count() as f64
                / n as f64
        };
        let robust = if class == Class::R3 {
            String::new()
        } else {
            format!(" robust +{:.2} −{:.2}", share(1.0), share(-1.0))
        };
        println!(
            "{i:3}: start constraints [{}] → {:?}, {} evaluations, {}, residual {:.2}°{robust} ({:.1} s)",
            e0.cons_exact
                .iter()
                .map(|v| format!("{v:.2}"))
                .collect::<Vec<_>>()
                .join(", "),
            c.status,
            c.evals,
            c.reason.as_deref().unwrap_or("usable"),
            c.residual_deg,
            t0.elapsed().as_secs_f64()
        );
    }
    println!("{name} d_x = {dx} band {b}: {usable} of {m} usable");
}

fn pool(
    name: &str,
    dx: f64,
    k: usize,
    m: usize,
    seed: u64,
    max_combinations: usize,
    (height, gap): (f64, f64),
) {
    use rayon::prelude::*;
    let (class, tr) = track(name, 360);
    let n = tr.len();
    let t0 = std::time::Instant::now();
    let bands: Vec<Vec<candidate::Candidate>> = (0..k)
        .map(|b| {
            (0..m)
                .into_par_iter()
                .map(|i| {
                    let layout = bands::BandLayout { height, gap };
                    let mut pb =
                        bands::band_problem(class, &tr, dx, layout, b, NormalCone::Tangent);
                    if class != Class::R1 {
                        pb.vary = Some((i * n / m) % n);
                    }
                    let minimizer = optimizer::default_minimizer();
                    candidate::solve(&pb, minimizer, seed, b, i, optimizer::MAX_EVAL)
                })
                .filter(|c| c.valid)
                .collect()
        })
        .collect();
    println!(
        "{name} d_x = {dx}: usable per band {:?} ({:.1} s)",
        bands.iter().map(Vec::len).collect::<Vec<_>>(),
        t0.elapsed().as_secs_f64()
    );
    if class == Class::R1 {
        // Per band: mean share of samples a usable candidate drives robustly in + and in −,
        // and the share that some candidate of the band covers in each sign.
        for (b, cands) in bands.iter().enumerate() {
            let drives = |c: &candidate::Candidate, i: usize, s: f64| {
                c.robust[i] && c.ntilde[i].is_some_and(|v| v[0] * s > 0.0)
            };
            let mean = |s: f64| {
                cands
                    .iter()
                    .map(|c| (0..n).filter(|&i| drives(c, i, s)).count() as f64 / n as f64)
                    .sum::<f64>()
                    / cands.len().max(1) as f64
            };
            let union = |s: f64| {
                (0..n)
                    .filter(|&i| cands.iter().any(|c| drives(c, i, s)))
                    .count() as f64
                    / n as f64
            };
            println!(
                "  band {b}: robust share per candidate + {:.2} − {:.2}; covered by the band + {:.2} − {:.2}",
                mean(1.0),
                mean(-1.0),
                union(1.0),
                union(-1.0)
            );
        }
    }
    let pool = combine::Pool {
        class,
        bands: bands
            .iter()
            .map(|b| {
                b.iter()
                    .map(|c| (c.ntilde.as_slice(), c.robust.as_slice()))
                    .collect()
            })
            .collect(),
    };
    let show =
        |what: &str, g: &[usize]| {
            let s = pool.summary(g, Density::Samples);
            println!(
            "  {what}: genome {g:?}: E_valiTime {:.3}, robust {:.3}, E_maxDist {:.3}, robust {:.3}",
            s.vali_time, s.robust_vali_time, s.max_dist.min(99.0), s.robust_max_dist.min(99.0)
        );
        };
    let t0 = std::time::Instant::now();
    let settings = ga::GaSettings {
        population: ga::POPULATION,
        generations: ga::GENERATIONS,
        seed,
    };
    let res = ga::run(&pool, settings, &mut |_| true);
    show(
        &format!("GA ({:.2} s)", t0.elapsed().as_secs_f64()),
        &res.genome,
    );
    let t0 = std::time::Instant::now();
    let c = combine::combine(&pool, settings, &mut |_| true);
    show(
        &format!(
            "combine, {} ({:.2} s)",
            if c.exact {
                "exhaustive"
            } else {
                "GA + local search"
            },
            t0.elapsed().as_secs_f64()
        ),
        &c.genome,
    );
    let o = &c.oversampled;
    println!(
        "    at 4×: E_valiTime {:.3}, robust {:.3}, E_maxDist {:.3}, robust {:.3}",
        o.vali_time,
        o.robust_vali_time,
        o.max_dist.min(99.0),
        o.robust_max_dist.min(99.0)
    );
    let sizes: Vec<usize> = bands.iter().map(Vec::len).collect();
    let total: usize = sizes.iter().product();
    if total == 0 || total > max_combinations {
        println!("  exhaustive: skipped ({total} combinations)");
        return;
    }
    let t0 = std::time::Instant::now();
    let genome = |mut c: usize| -> Vec<usize> {
        sizes
            .iter()
            .map(|&s| {
                let g = c % s;
                c /= s;
                g
            })
            .collect()
    };
    let best = (0..total)
        .into_par_iter()
        .map(|c| {
            let g = genome(c);
            (pool.fitness(&g, Density::Samples), g)
        })
        .reduce_with(|a, b| {
            if b.0.cmp_better(&a.0) == std::cmp::Ordering::Greater {
                b
            } else {
                a
            }
        })
        .expect("at least one combination");
    show(
        &format!(
            "exhaustive over {total} ({:.2} s)",
            t0.elapsed().as_secs_f64()
        ),
        &best.1,
    );
    if class == Class::R1 {
        // The chosen contacts over the period, 90 columns: robust + / robust − / not robust
        // (lower case: the sign without a robust arm).
        for (b, &g) in best.1.iter().enumerate() {
            let c = &bands[b][g];
            let line: String = (0..90)
                .map(|col| {
                    let i = col * n / 90;
                    match (c.ntilde[i].map(|v| v[0] > 0.0), c.robust[i]) {
                        (Some(true), true) => '+',
                        (Some(false), true) => '-',
                        (Some(true), false) => '\'',
                        (Some(false), false) => ',',
                        (None, _) => ' ',
                    }
                })
                .collect();
            println!("  band {b} #{:2}: {line}", c.index);
        }
    }
}

fn oracle_points(name: &str, dx: f64, k: usize, trials: usize) {
    let (_, tr) = track(name, 120);
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    let mut best = (f64::INFINITY, Vec::new());
    for _ in 0..trials {
        let pts: Vec<(V3<f64>, f64)> = (0..k)
            .map(|b| {
                let (lo, hi) = bands::BandLayout::default().band(b);
                let z = rng.random_range(lo..hi);
                let r = rng.random_range(1.0..3.0);
                let a = rng.random_range(0.0..std::f64::consts::TAU);
                let s = if rng.random_bool(0.5) { 1.0 } else { -1.0 };
                (V3::new(r * a.cos(), r * a.sin(), z), s)
            })
            .collect();
        let mut worst = f64::NEG_INFINITY;
        for pose in &tr.samples {
            let nt: Vec<[f64; 3]> = pts
                .iter()
                .map(|(c, s)| w_perp(c.rot(&pose.rot), pose.omega, dx).scalec(*s).vals())
                .collect();
            worst = worst.max(closure::signed_dist(Class::R3, &nt));
            if worst > best.0 {
                break;
            }
        }
        if worst < best.0 {
            best = (worst, pts);
        }
    }
    println!(
        "{name} d_x = {dx} K = {k}: best worst-case dist {:.3}",
        best.0
    );
    for (c, s) in &best.1 {
        println!(
            "  c2 = ({:6.2},{:6.2},{:6.2})  az {:6.1}°  el {:5.1}°  sign {s}",
            c.x,
            c.y,
            c.z,
            c.y.atan2(c.x).to_degrees(),
            (c.z / c.norm()).asin().to_degrees()
        );
    }
}

fn oracle_starts(name: &str, dx: f64, k: usize, m: usize) {
    let (_, tr) = track(name, 120);
    type View = (Vec<Option<[f64; 3]>>, Vec<bool>);
    let mut all: Vec<Vec<View>> = Vec::new();
    for b in 0..k {
        let layout = bands::BandLayout::default();
        let pb = bands::band_problem(Class::R3, &tr, dx, layout, b, NormalCone::Tangent);
        let mut viol = [0usize; 5];
        let mut cands = Vec::new();
        for i in 0..m {
            let x = candidate::initial_guess(&pb, 1, b, i);
            let ev = pb.evaluate(&x);
            for (c, v) in ev.cons_exact.iter().take(5).enumerate() {
                viol[c] += (*v > candidate::FEAS_TOL) as usize;
            }
            let nt = tr
                .samples
                .iter()
                .map(|pose| {
                    let c = model::contact_f64(&x, pose, dx);
                    let u = w_perp(c.p, pose.omega, dx);
                    let s = c.p.cross(c.n).dot(u).signum();
                    Some(u.scalec(s).vals())
                })
                .collect();
            cands.push((nt, vec![true; tr.len()]));
        }
        println!("band {b}: start-constraint violations (len ≥, len ≤, follower, driver, slope) {viol:?}");
        all.push(cands);
    }
    let pool = combine::Pool {
        class: Class::R3,
        bands: all
            .iter()
            .map(|b| {
                b.iter()
                    .map(|(a, r)| (a.as_slice(), r.as_slice()))
                    .collect()
            })
            .collect(),
    };
    let settings = ga::GaSettings {
        population: ga::POPULATION,
        generations: ga::GENERATIONS,
        seed: 1,
    };
    let res = ga::run(&pool, settings, &mut |_| true);
    println!(
        "{name} d_x = {dx} K = {k} M = {m}: ideal-ñ GA E_valiTime {:.3}, E_maxDist {:.3}",
        res.fitness.vali_time, res.fitness.max_dist
    );
}

fn diagnose(file: &Path, name: &str) {
    let m = Mechanism::load(file).unwrap_or_else(|e| panic!("{e}"));
    let mo = load_motion(name);
    let tr = PoseTrack::from_motion(&mo, m.samples);
    let dx = m.driver_offset;
    println!(
        "K = {} d_x = {dx}: E_valiTime {:.3}, E_maxDist {:.3}",
        m.curve_pairs.len(),
        m.closure.vali_time,
        m.closure.max_dist
    );
    for (k, cp) in m.curve_pairs.iter().enumerate() {
        let mut ang = Vec::new();
        let (mut sgn, mut nabsy) = (0.0, 0.0);
        let mut nsum = V3::<f64>::zero();
        let (mut az, mut el) = ([1e9f64, -1e9f64], [1e9f64, -1e9f64]);
        for (i, pose) in tr.samples.iter().enumerate() {
            let (p, n) = (V3::from(cp.samples.p[i]), V3::from(cp.samples.n[i]));
            let nt = p.cross(n).unit();
            let c = nt.dot(w_perp(p, pose.omega, dx));
            sgn += c.signum();
            ang.push(c.abs().min(1.0).acos().to_degrees());
            let (a, e) = (
                p.y.atan2(p.x).to_degrees(),
                (p.z / p.norm()).asin().to_degrees(),
            );
            az = [az[0].min(a), az[1].max(a)];
            el = [el[0].min(e), el[1].max(e)];
            nsum = nsum + nt;
            nabsy += nt.y.abs();
        }
        let nn = tr.len() as f64;
        ang.sort_by(f64::total_cmp);
        println!(
            "pair {k} slab {:?}: angle(ñ, ±ŵ⊥p) median {:.1}° p90 {:.1}° max {:.1}°; sign mean {:+.2}; \
             p az [{:.0}, {:.0}] el [{:.0}, {:.0}]; mean ñ ({:+.2}, {:+.2}, {:+.2}), mean |ñy| {:.2}",
            cp.slab,
            ang[ang.len() / 2],
            ang[ang.len() * 9 / 10],
            ang[ang.len() - 1],
            sgn / nn,
            az[0],
            az[1],
            el[0],
            el[1],
            nsum.x / nn,
            nsum.y / nn,
            nsum.z / nn,
            nabsy / nn
        );
    }
}
