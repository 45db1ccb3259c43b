//! The rotation angle law θ(t) of 1R and 1R1T motions.
//!
//! Two schemes, both periodic-with-offset (`θ(t + 1) = θ(t) + D`, D = 2π·net turns), C² in
//! t and exact at every keyframe:
//!
//! - [`AngleScheme::Monotone`] (default for keyframe specs) — *shape preserving*. Between
//!   two keyframes the angle moves monotonically from one key value to the next, so a
//!   follower whose keyframes always advance never stops and reverses, and an oscillation
//!   never overshoots its extreme keys. The velocity g = dθ/dt on interval i (length h,
//!   local u = (t − t_i)/h ∈ [0, 1], mean velocity μ = Δθ/h) is the quartic
//!
//!   g(u) = v₀ + (v₁ − v₀)(3u² − 2u³) + c·u²(1 − u)²,  c = 30(μ − (v₀ + v₁)/2),
//!
//!   i.e. a cubic Hermite blend of the knot velocities with zero slope at the knots plus a
//!   bump that makes the interval's integral exactly Δθ; θ is its integral, a quintic.
//!   Since g′ = 0 at every knot, θ″ is continuous (it is 0 at the keyframes), so θ is C².
//!   Knot velocities start as the Fritsch–Butland weighted harmonic mean of the neighbouring
//!   mean velocities (0 where they differ in sign: a turning point). Because
//!   g ≥ min(v₀, v₁) + c/16 (the Hermite blend stays between v₀ and v₁, the bump peaks at
//!   1/16), an interval is provably sign-preserving when `min(|v₀|,|v₁|) + sgn(μ)·c/16 ≥ 0`;
//!   where that fails, both of its knots fall back to `sgn·min(|μ_{i−1}|, |μ_i|)`, for which
//!   c has the sign of μ and the property holds outright. Repeating until no interval fails
//!   terminates (every step only moves knots to the fallback). A dwell (two equal keys) gives
//!   g ≡ 0 on that interval.
//! - [`AngleScheme::Spline`] — the ordinary periodic cubic spline through the keys (with
//!   the per-period offset). Smoother accelerations, but it may overshoot between sparse
//!   keys. Used for dense samples (CSV, `mechanism.json`), where overshoot is negligible
//!   and the spline's accurate second derivative matters.
//!
//! Evaluation is O(log n) with no allocation.

use super::spline::{locate, PeriodicSpline};

/// How θ(t) is interpolated between keyframes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum AngleScheme {
    /// Shape preserving, monotone between keys (the default for keyframe specs).
    Monotone,
    /// Periodic cubic spline (used for dense samples).
    Spline,
}

impl std::fmt::Display for AngleScheme {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Self::Monotone => "monotone",
            Self::Spline => "spline",
        })
    }
}

/// θ(t) in radians with its derivatives.
#[derive(Debug, Clone)]
pub(crate) enum AngleLaw {
    Monotone(MonotoneAngle),
    Spline(PeriodicSpline<1>),
}

impl AngleLaw {
    /// Build the law through `(knots[i], angles[i])` (radians, unwrapped) gaining `offset`
    /// radians per period.
    pub(crate) fn new(scheme: AngleScheme, knots: &[f64], angles: &[f64], offset: f64) -> Self {
        match scheme {
            AngleScheme::Monotone => Self::Monotone(MonotoneAngle::new(knots, angles, offset)),
            AngleScheme::Spline => {
                let values: Vec<[f64; 1]> = angles.iter().map(|&a| [a]).collect();
                Self::Spline(PeriodicSpline::new(knots, &values, 1.0, [offset]))
            }
        }
    }

    /// `[θ, dθ/dt, d²θ/dt²]` at any real t.
    pub(crate) fn eval(&self, t: f64) -> [f64; 3] {
        match self {
            Self::Monotone(m) => m.eval(t),
            Self::Spline(s) => {
                let j = s.eval(t);
                [j[0][0], j[1][0], j[2][0]]
            }
        }
    }
}

/// The shape-preserving quintic angle law (see the module doc).
#[derive(Debug, Clone)]
pub(crate) struct MonotoneAngle {
    knots: Vec<f64>,
    /// Per interval: `[θ_i, p1, p2, p3, p4, p5]`, θ = θ_i + Σ p_k s^k, s = t − t_i.
    coeffs: Vec<[f64; 6]>,
    offset: f64,
}

impl MonotoneAngle {
    fn new(knots: &[f64], angles: &[f64], offset: f64) -> Self {
        let n = knots.len();
        assert!(n >= 1 && angles.len() == n);
        let h: Vec<f64> = (0..n)
            .map(|i| {
                if i + 1 < n {
                    knots[i + 1] - knots[i]
                } else {
                    knots[0] + 1.0 - knots[n - 1]
                }
            })
            .collect();
        let delta: Vec<f64> = (0..n)
            .map(|i| {
                let next = if i + 1 < n {
                    angles[i + 1]
                } else {
                    angles[0] + offset
                };
                next - angles[i]
            })
            .collect();
        let mu: Vec<f64> = (0..n).map(|i| delta[i] / h[i]).collect();
        let prev = |i: usize| (i + n - 1) % n;

        // Fallback knot velocities: always safe.
        let fallback: Vec<f64> = (0..n)
            .map(|i| {
                let (a, b) = (mu[prev(i)], mu[i]);
                if a * b <= 0.0 {
                    0.0
                } else {
                    a.signum() * a.abs().min(b.abs())
                }
            })
            .collect();
        // Preferred: Fritsch–Butland weighted harmonic mean.
        let mut v: Vec<f64> = (0..n)
            .map(|i| {
                let (a, b) = (mu[prev(i)], mu[i]);
                if a * b <= 0.0 {
                    0.0
                } else {
                    let (ha, hb) = (h[prev(i)], h[i]);
                    let w = (ha + 2.0 * hb) / (3.0 * (ha + hb));
                    1.0 / (w / a + (1.0 - w) / b)
                }
            })
            .collect();
        // Fall back where an interval could change sign; terminates within n passes.
        for _ in 0..=n {
            let mut changed = false;
            for i in 0..n {
                let j = (i + 1) % n;
                let s = mu[i].signum();
                let c = 30.0 * (mu[i] - 0.5 * (v[i] + v[j]));
                let low = (s * v[i]).min(s * v[j]);
                let safe = mu[i] == 0.0 || low + s * c / 16.0 >= 0.0;
                if !safe && (v[i] != fallback[i] || v[j] != fallback[j]) {
                    v[i] = fallback[i];
                    v[j] = fallback[j];
                    changed = true;
                }
            }
            if !changed {
                break;
            }
        }

        let coeffs = (0..n)
            .map(|i| {
                let j = (i + 1) % n;
                let (v0, v1, hi) = (v[i], v[j], h[i]);
                let c = 30.0 * (mu[i] - 0.5 * (v0 + v1));
                // ∫₀ᵘ g = v0 u + (v1 − v0)(u³ − u⁴/2) + c(u³/3 − u⁴/2 + u⁵/5), θ = θ_i + h ∫.
                let a1 = v0;
                let a3 = (v1 - v0) + c / 3.0;
                let a4 = -0.5 * (v1 - v0) - 0.5 * c;
                let a5 = c / 5.0;
                // In s = h u: θ = θ_i + h Σ a_k (s/h)^k.
                [
                    angles[i],
                    a1,
                    0.0,
                    a3 / (hi * hi),
                    a4 / (hi * hi * hi),
                    a5 / (hi * hi * hi * hi),
                ]
            })
            .collect();
        Self {
            knots: knots.to_vec(),
            coeffs,
            offset,
        }
    }

    fn eval(&self, t: f64) -> [f64; 3] {
        let (i, s, periods) = locate(&self.knots, t);
        let p = &self.coeffs[i];
        let value = p[0] + s * (p[1] + s * (p[2] + s * (p[3] + s * (p[4] + s * p[5]))));
        let d1 = p[1] + s * (2.0 * p[2] + s * (3.0 * p[3] + s * (4.0 * p[4] + s * 5.0 * p[5])));
        let d2 = 2.0 * p[2] + s * (6.0 * p[3] + s * (12.0 * p[4] + s * 20.0 * p[5]));
        [value + periods * self.offset, d1, d2]
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;
    use std::f64::consts::{PI, TAU};

    /// Value, slope and curvature agree on both sides of every knot and of the wrap. The
    /// probe distance is far below the shortest interval and the tolerances scale with the
    /// law's own magnitudes (random keys have intervals down to 1e-4 of a period).
    fn check_c2(law: &AngleLaw, knots: &[f64], offset: f64) {
        let mut joints = knots.to_vec();
        joints.push(knots[0] + 1.0);
        let h_min = joints.windows(2).map(|w| w[1] - w[0]).fold(1.0, f64::min);
        let eps = 1e-7 * h_min;
        let scale = joints
            .windows(2)
            .flat_map(|w| (0..64).map(move |i| w[0] + (w[1] - w[0]) * f64::from(i) / 64.0))
            .map(|t| law.eval(t))
            .fold([0.0_f64; 3], |m, j| {
                [
                    m[0].max(j[0].abs()),
                    m[1].max(j[1].abs()),
                    m[2].max(j[2].abs()),
                ]
            });
        for &t in &joints {
            let (l, r) = (law.eval(t - eps), law.eval(t + eps));
            // Trapezoid steps across the joint remove the smooth change over 2·eps.
            let step0 = r[0] - l[0] - eps * (l[1] + r[1]);
            let step1 = r[1] - l[1] - eps * (l[2] + r[2]);
            assert!(step0.abs() < 1e-12 * (1.0 + scale[0]), "θ jumps at {t}");
            assert!(step1.abs() < 1e-8 * (1.0 + scale[1]), "θ' jumps at {t}");
            assert!(
                (l[2] - r[2]).abs() < 1e-5 * (1.0 + scale[2]),
                "θ'' jumps at {t}: {l:?} {r:?}"
            );
        }
        let a = law.eval(0.37)[0];
        assert!((law.eval(1.37)[0] - a - offset).abs() < 1e-9);
    }

    /// Guards the paper's 1R example law: keys θ = 0 at t = 0 and θ = π at t = 2/3 with one
    /// turn per period: exact at the keys, monotone, C² across the wrap, and the first
    /// half-turn takes exactly twice as long as the second.
    #[test]
    fn half_turn_two_to_one_is_monotone_and_exact() {
        let knots = [0.0, 2.0 / 3.0];
        let law = AngleLaw::new(AngleScheme::Monotone, &knots, &[0.0, PI], TAU);
        assert_eq!(law.eval(0.0)[0], 0.0);
        assert_eq!(law.eval(2.0 / 3.0)[0], PI);
        check_c2(&law, &knots, TAU);
        for i in 0..=10_000 {
            let t = f64::from(i) / 10_000.0;
            assert!(law.eval(t)[1] >= 0.0, "reverses at t = {t}");
        }
    }

    /// Guards monotonicity on hard random keys: increasing keys with wildly varying steps and
    /// dwells (equal keys) never give a negative velocity, and keys are hit exactly.
    #[test]
    fn monotone_keys_give_monotone_law() {
        let mut rng = ChaCha8Rng::seed_from_u64(42);
        for _ in 0..200 {
            let n = rng.random_range(1..12);
            let mut knots: Vec<f64> = (0..n).map(|_| rng.random::<f64>()).collect();
            knots.sort_by(f64::total_cmp);
            knots.dedup();
            let mut angle = 0.0;
            let mut angles = Vec::new();
            for _ in &knots {
                angles.push(angle);
                // Steps over four orders of magnitude, sometimes a dwell.
                angle += if rng.random_bool(0.2) {
                    0.0
                } else {
                    10f64.powf(rng.random_range(-2.0..2.0))
                };
            }
            let offset = TAU * (angle / TAU).ceil().max(1.0);
            let law = AngleLaw::new(AngleScheme::Monotone, &knots, &angles, offset);
            for (t, a) in knots.iter().zip(&angles) {
                assert_eq!(law.eval(*t)[0], *a);
            }
            check_c2(&law, &knots, offset);
            for i in 0..2000 {
                let t = f64::from(i) / 2000.0;
                let d = law.eval(t)[1];
                assert!(d >= -1e-9 * offset, "negative velocity {d} at {t}");
            }
        }
    }

    /// Guards shape preservation for an oscillation: the angle never leaves the range of the
    /// keys (no overshoot at turning points).
    #[test]
    fn oscillation_does_not_overshoot() {
        let knots = [0.0, 0.2, 0.5, 0.7];
        let angles = [0.0, 1.0, 0.2, 0.9];
        let law = AngleLaw::new(AngleScheme::Monotone, &knots, &angles, 0.0);
        check_c2(&law, &knots, 0.0);
        for i in 0..5000 {
            let a = law.eval(f64::from(i) / 5000.0)[0];
            assert!((-1e-12..=1.0 + 1e-12).contains(&a), "overshoot {a}");
        }
    }

    /// Guards the analytic derivatives of both schemes against finite differences.
    #[test]
    fn derivatives_match_finite_differences() {
        let knots = [0.05, 0.3, 0.55, 0.8];
        let angles = [0.0, 0.4, 2.0, 2.5];
        for scheme in [AngleScheme::Monotone, AngleScheme::Spline] {
            let law = AngleLaw::new(scheme, &knots, &angles, TAU);
            let e = 1e-6;
            for i in 0..300 {
                let t = -1.0 + 3.0 * f64::from(i) / 300.0 + 1.3e-4;
                let j = law.eval(t);
                let (p, m) = (law.eval(t + e), law.eval(t - e));
                assert!(((p[0] - m[0]) / (2.0 * e) - j[1]).abs() < 1e-5 * (1.0 + j[1].abs()));
                assert!(((p[1] - m[1]) / (2.0 * e) - j[2]).abs() < 1e-4 * (1.0 + j[2].abs()));
            }
        }
    }
}
