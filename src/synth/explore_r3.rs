//! Exploration aids (ignored tests) for 3R under the tangent cone |n·p̂| ≤ sin γ₀.
//!
//! A conjugate normal is perpendicular to T² and to w = T¹ − T², the relative velocity of
//! the follower's material point against the driver's; if it is also (nearly) perpendicular
//! to p, the projection ñ = p × n is pinned to ±w⊥p (w's component perpendicular to p, the
//! sign fixed along a curve), up to the cone's slack. These oracles ask whether such ñ can
//! close at all: [`oracle_fixed_points`] for contacts fixed at follower-local points (one
//! per band), [`oracle_initial_guesses`] for the start curves of `candidate::initial_guess`
//! combined by the GA; [`diagnose_mechanism`] reports, per pair of a mechanism file, how far
//! ñ is from ±ŵ⊥p and where p sits. Run with `cargo test --release --lib explore_r3 --
//! --ignored --nocapture` (env: MOTION, DX, K, M; MECH for the diagnosis).
#![cfg(test)]

use super::closure::{self, Class};
use super::math::{Mat3, V3};
use super::pose::PoseTrack;
use rand::{Rng, SeedableRng};
use std::sync::Arc;

fn unit(a: [f64; 3]) -> [f64; 3] {
    let a = V3::from(a);
    a.scalec(1.0 / a.norm().max(1e-300)).vals()
}
fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    V3::from(a).cross(V3::from(b)).vals()
}
fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    V3::from(a).dot(V3::from(b))
}
fn rot(m: &Mat3, v: [f64; 3]) -> [f64; 3] {
    V3::from(v).rot(m).vals()
}

/// ŵ⊥p: the relative velocity of the follower material point at p (w.r.t. the driver),
/// component perpendicular to p, normalized.
pub fn w_perp(p: [f64; 3], omega: [f64; 3], dx: f64) -> [f64; 3] {
    let tau = std::f64::consts::TAU;
    let a = cross(omega, p);
    let w = [a[0] + tau * p[1], a[1] - tau * (p[0] - dx), a[2]];
    let pp = dot(p, p);
    let d = dot(w, p) / pp;
    unit([w[0] - d * p[0], w[1] - d * p[1], w[2] - d * p[2]])
}

/// Environment setting `key` parsed, or `default` when unset or unparsable.
fn env_or<T: std::str::FromStr>(key: &str, default: T) -> T {
    std::env::var(key)
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(default)
}

/// The pose track of example `name` at `samples` samples per period.
fn track(name: &str, samples: usize) -> Arc<PoseTrack> {
    let m = crate::motion::Motion::from_file(std::path::Path::new(&format!(
        "data/motions/{name}.toml"
    )))
    .unwrap();
    Arc::new(PoseTrack::from_motion(&m, samples))
}

/// Oracle: K contacts fixed at follower-local points (one per band height), with
/// ñ = s·ŵ⊥p exactly (the tangent cone with zero slack). Random search over points and
/// signs for the best worst-case dist.
#[test]
#[ignore]
fn oracle_fixed_points() {
    let name = env_or("MOTION", String::from("cone-sweep"));
    let dx: f64 = env_or("DX", 6.0);
    let k: usize = env_or("K", 6);
    let tr = track(&name, 120);
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(1);
    let mut best = (f64::INFINITY, Vec::new());
    for _ in 0..20000 {
        let pts: Vec<([f64; 3], f64)> = (0..k)
            .map(|b| {
                let (lo, hi) = super::search::band(b);
                let z = rng.random_range(lo..hi);
                let r = rng.random_range(1.0..3.0);
                let a = rng.random_range(0.0..std::f64::consts::TAU);
                let s = if rng.random_bool(0.5) { 1.0 } else { -1.0 };
                ([r * a.cos(), r * a.sin(), z], s)
            })
            .collect();
        let mut worst = f64::NEG_INFINITY;
        for pose in &tr.samples {
            let nt: Vec<[f64; 3]> = pts
                .iter()
                .map(|(c, s)| {
                    let p = rot(&pose.rot, *c);
                    let u = w_perp(p, pose.omega, dx);
                    [s * u[0], s * u[1], s * u[2]]
                })
                .collect();
            let d = closure::signed_dist(Class::R3, &nt);
            worst = worst.max(d);
            if worst > best.0 {
                break;
            }
        }
        if worst < best.0 {
            best = (worst, pts);
        }
    }
    eprintln!("{name} dx={dx} K={k}: best worst-case dist {:.3}", best.0);
    for (c, s) in &best.1 {
        let r = dot(*c, *c).sqrt();
        eprintln!(
            "  c2 = ({:6.2},{:6.2},{:6.2})  az {:6.1}°  el {:5.1}°  sign {s}",
            c[0],
            c[1],
            c[2],
            c[1].atan2(c[0]).to_degrees(),
            (c[2] / r).asin().to_degrees()
        );
    }
}

/// Diagnostic of a (partial) mechanism: per pair, where p sits and how ñ relates to ŵ⊥p.
#[test]
#[ignore]
fn diagnose_mechanism() {
    let path = std::env::var("MECH").unwrap();
    let text = std::fs::read_to_string(&path).unwrap();
    let m: super::Mechanism = serde_json::from_str(&text).unwrap();
    let name = env_or("MOTION", String::from("cone-sweep"));
    let mo = crate::motion::Motion::from_file(std::path::Path::new(&format!(
        "data/motions/{name}.toml"
    )))
    .unwrap();
    let tr = PoseTrack::from_motion(&mo, m.samples);
    let dx = m.driver_offset;
    eprintln!(
        "K={} dx={dx} vali={:.3} maxd={:.3}",
        m.curve_pairs.len(),
        m.closure.vali_time,
        m.closure.max_dist
    );
    for (k, cp) in m.curve_pairs.iter().enumerate() {
        let mut ang = Vec::new();
        let mut sgn = 0.0;
        let (mut az_lo, mut az_hi, mut el_lo, mut el_hi) = (1e9f64, -1e9f64, 1e9f64, -1e9f64);
        let mut nsum = [0.0; 3];
        let mut nabsy = 0.0;
        for (i, pose) in tr.samples.iter().enumerate() {
            let p = cp.samples.p[i];
            let n = cp.samples.n[i];
            let nt = unit(cross(p, n));
            let u = w_perp(p, pose.omega, dx);
            let c = dot(nt, u);
            sgn += c.signum();
            ang.push(c.abs().min(1.0).acos().to_degrees());
            let r = dot(p, p).sqrt();
            let az = p[1].atan2(p[0]).to_degrees();
            az_lo = az_lo.min(az);
            az_hi = az_hi.max(az);
            el_lo = el_lo.min((p[2] / r).asin().to_degrees());
            el_hi = el_hi.max((p[2] / r).asin().to_degrees());
            for a in 0..3 {
                nsum[a] += nt[a];
            }
            nabsy += nt[1].abs();
        }
        let nn = tr.samples.len() as f64;
        ang.sort_by(f64::total_cmp);
        eprintln!(
            "pair {k} slab {:?}: angle(ñ, ±ŵ⊥p) median {:.1}° p90 {:.1}° max {:.1}°; sign mean {:+.2}; p az [{:.0},{:.0}] el [{:.0},{:.0}]; mean ñ ({:+.2},{:+.2},{:+.2}) mean|ñy| {:.2}",
            cp.slab, ang[ang.len() / 2], ang[ang.len() * 9 / 10], ang[ang.len() - 1], sgn / nn,
            az_lo, az_hi, el_lo, el_hi, nsum[0] / nn, nsum[1] / nn, nsum[2] / nn, nabsy / nn
        );
    }
}

/// Oracle on the start curves: for M initial guesses per band, ñ = s·ŵ⊥p along the start
/// curve (what a conjugate normal in the tangent cone would give, up to the cone's slack),
/// s = the start normal's sign; then the GA. Prints the best closure.
#[test]
#[ignore]
fn oracle_initial_guesses() {
    let name = env_or("MOTION", String::from("cone-sweep"));
    let dx: f64 = env_or("DX", 6.0);
    let k: usize = env_or("K", 6);
    let m: usize = env_or("M", 30);
    let tr = track(&name, 120);
    type View = (Vec<Option<[f64; 3]>>, Vec<bool>);
    let mut all: Vec<Vec<View>> = Vec::new();
    for b in 0..k {
        let pb = super::search::band_problem(Class::R3, &tr, dx, b, closure::NormalCone::Tangent);
        let mut cands = Vec::new();
        let mut viol = [0usize; 6];
        for i in 0..m {
            let x = super::candidate::initial_guess(&pb, 1, b, i);
            let ev = pb.evaluate(&x);
            for (c, v) in ev.cons_exact.iter().enumerate() {
                if *v > 1e-6 && c != 5 {
                    viol[c] += 1;
                }
            }
            let mut nt = Vec::new();
            for pose in &tr.samples {
                let c = super::model::contact_f64(&x, pose, dx);
                let (p, n) = (c.p.vals(), c.n.vals());
                let u = w_perp(p, pose.omega, dx);
                let real = unit(cross(p, n));
                let s = dot(real, u).signum();
                nt.push(Some([s * u[0], s * u[1], s * u[2]]));
            }
            cands.push((nt, vec![true; tr.samples.len()]));
        }
        eprintln!(
            "band {b}: start-constraint violations (len≥,len≤,rf,rd,slope) {:?}",
            &viol[..5]
        );
        all.push(cands);
    }
    let pool = super::ga::Pool {
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
    let res = super::ga::run(
        &pool,
        super::ga::GaSettings {
            population: 48,
            generations: 300,
            seed: 1,
        },
        &mut |_| true,
    );
    eprintln!(
        "{name} dx={dx} K={k} M={m}: ideal-ñ GA vali {:.3} maxdist {:.3}",
        res.fitness.vali_time, res.fitness.max_dist
    );
}

/// Solve M candidates of one band and print each outcome (for parameter studies).
#[test]
#[ignore]
fn solve_band_outcomes() {
    let name = env_or("MOTION", String::from("cone-sweep"));
    let dx: f64 = env_or("DX", 6.0);
    let b: usize = env_or("BAND", 3);
    let m: usize = env_or("M", 16);
    let tr = track(&name, 360);
    let n = tr.len();
    let mut ok = 0;
    for i in 0..m {
        let mut pb =
            super::search::band_problem(Class::R3, &tr, dx, b, closure::NormalCone::Tangent);
        pb.vary = Some((i * n / m) % n);
        let x0 = super::candidate::initial_guess(&pb, 1, b, i);
        let e0 = pb.evaluate(&x0);
        // Where the start normal is furthest out of the tangent plane of the sphere.
        let (worst_t, worst_dot) = tr
            .samples
            .iter()
            .map(|pose| {
                let c = super::model::contact_f64(&x0, pose, dx);
                (pose.t, dot(c.n.vals(), unit(c.p.vals())).abs())
            })
            .fold((0.0, 0.0), |a, v| if v.1 > a.1 { v } else { a });
        let c = super::candidate::solve(&pb, super::optimizer::default_minimizer(), 1, b, i, 400);
        ok += c.valid as usize;
        eprintln!(
            "  {i}: start max|n.p| {worst_dot:.3} at t {worst_t:.3}, cons {:?} -> {:?} evals {} valid {} {:?}",
            e0.cons_exact
                .iter()
                .map(|v| format!("{v:.2}"))
                .collect::<Vec<_>>(),
            c.status,
            c.evals,
            c.valid,
            c.reason
        );
    }
    eprintln!("{name} band {b}: {ok}/{m} usable");
}
