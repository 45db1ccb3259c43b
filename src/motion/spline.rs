//! Periodic C² cubic splines through values at non-uniform knots of one period.
//!
//! The spline interpolates values `y_i` at knots `t_0 < … < t_{n−1}` in `[t_0, t_0 + 1)` and
//! continues over all real t by the *period rule* `y(t + 1) = σ·y(t) + D`:
//! - `σ = +1, D = 0`: an ordinary periodic spline (heights, quaternion components);
//! - `σ = +1, D ≠ 0`: a spline with a per-period offset (an unwrapped angle gaining `D`
//!   radians per period, e.g. one full turn);
//! - `σ = −1, D = 0`: an anti-periodic spline (the quaternion path of a rotation loop that
//!   is not contractible in SO(3) ends at `−q₀`, which is the same rotation).
//!
//! The second derivatives at the knots solve the cyclic tridiagonal system of the classic
//! C² conditions; the spline and its first and second derivatives are continuous everywhere,
//! including across the period boundary. Each interval is stored as a polynomial in the
//! local offset `s = t − t_i`, whose constant term is the knot value itself, so evaluating at
//! a knot returns that knot's value exactly. Evaluation is a binary search plus a cubic:
//! O(log n), no allocation.
//!
//! This module knows nothing about angles or rotations; [`super::angle`] and
//! [`super::rotation`] give the values their meaning.

/// A periodic (or offset-periodic, or anti-periodic) C² cubic spline with values in `R^D`.
#[derive(Debug, Clone)]
pub(crate) struct PeriodicSpline<const D: usize> {
    /// Knot times `t_0 < … < t_{n−1}`, with `t_{n−1} < t_0 + 1`.
    knots: Vec<f64>,
    /// Per interval i (from `t_i` to `t_{i+1}`, the last one to `t_0 + 1`): coefficients
    /// `[c0, c1, c2, c3]` of `y = c0 + c1 s + c2 s² + c3 s³`, `s = t − t_i`.
    coeffs: Vec<[[f64; D]; 4]>,
    /// σ in the period rule.
    sign: f64,
    /// D in the period rule.
    offset: [f64; D],
}

/// Value, first and second derivative of a D-dimensional spline at one time.
pub(crate) type Jet<const D: usize> = [[f64; D]; 3];

impl<const D: usize> PeriodicSpline<D> {
    /// Build the spline.
    ///
    /// `knots` must be strictly increasing with span below 1 and `values` the same length
    /// (≥ 1); `sign` is ±1 and `offset` must be zero when `sign` is −1. Callers validate user
    /// input before calling; violations here are programming errors.
    pub(crate) fn new(knots: &[f64], values: &[[f64; D]], sign: f64, offset: [f64; D]) -> Self {
        let n = knots.len();
        assert!(
            n >= 1 && values.len() == n,
            "spline needs matching, non-empty knots"
        );
        assert!(sign == 1.0 || sign == -1.0, "period sign must be ±1");
        assert!(
            sign == 1.0 || offset.iter().all(|&d| d == 0.0),
            "an anti-periodic spline has no offset"
        );
        debug_assert!(knots.windows(2).all(|w| w[0] < w[1]));
        debug_assert!(knots[n - 1] < knots[0] + 1.0);

        // Interval lengths h_i = t_{i+1} − t_i with t_n = t_0 + 1.
        let h: Vec<f64> = (0..n)
            .map(|i| {
                if i + 1 < n {
                    knots[i + 1] - knots[i]
                } else {
                    knots[0] + 1.0 - knots[n - 1]
                }
            })
            .collect();
        // y_{i+1} with the period rule applied for the last interval.
        let next_value = |i: usize, k: usize| -> f64 {
            if i + 1 < n {
                values[i + 1][k]
            } else {
                sign * values[0][k] + offset[k]
            }
        };
        // y_{i−1}: y(t − 1) = σ (y(t) − D).
        let prev_value = |i: usize, k: usize| -> f64 {
            if i > 0 {
                values[i - 1][k]
            } else {
                sign * (values[n - 1][k] - offset[k])
            }
        };

        // Second derivatives M_i per component.
        let mut second = vec![[0.0; D]; n];
        for k in 0..D {
            let rhs: Vec<f64> = (0..n)
                .map(|i| {
                    let h_prev = h[(i + n - 1) % n];
                    6.0 * ((next_value(i, k) - values[i][k]) / h[i]
                        - (values[i][k] - prev_value(i, k)) / h_prev)
                })
                .collect();
            let m = solve_cyclic(&h, sign, &rhs);
            for i in 0..n {
                second[i][k] = m[i];
            }
        }

        let coeffs = (0..n)
            .map(|i| {
                let mut c = [[0.0; D]; 4];
                for k in 0..D {
                    let m0 = second[i][k];
                    let m1 = if i + 1 < n {
                        second[i + 1][k]
                    } else {
                        sign * second[0][k]
                    };
                    let y0 = values[i][k];
                    let y1 = next_value(i, k);
                    c[0][k] = y0;
                    c[1][k] = (y1 - y0) / h[i] - h[i] * (2.0 * m0 + m1) / 6.0;
                    c[2][k] = m0 / 2.0;
                    c[3][k] = (m1 - m0) / (6.0 * h[i]);
                }
                c
            })
            .collect();
        Self {
            knots: knots.to_vec(),
            coeffs,
            sign,
            offset,
        }
    }

    /// Value, first and second derivative at any real `t`.
    pub(crate) fn eval(&self, t: f64) -> Jet<D> {
        let (i, s, periods) = locate(&self.knots, t);
        let c = &self.coeffs[i];
        let mut out = [[0.0; D]; 3];
        for k in 0..D {
            out[0][k] = c[0][k] + s * (c[1][k] + s * (c[2][k] + s * c[3][k]));
            out[1][k] = c[1][k] + s * (2.0 * c[2][k] + s * 3.0 * c[3][k]);
            out[2][k] = 2.0 * c[2][k] + s * 6.0 * c[3][k];
        }
        if periods != 0.0 {
            // y(τ + k) = σ^k y(τ) + k D (σ = −1 only with D = 0).
            let flip = self.sign < 0.0 && periods.rem_euclid(2.0) == 1.0;
            for row in &mut out {
                for v in row.iter_mut() {
                    if flip {
                        *v = -*v;
                    }
                }
            }
            for (v, d) in out[0].iter_mut().zip(&self.offset) {
                *v += periods * d;
            }
        }
        out
    }
}

/// Find the interval holding `t`: returns `(i, s, k)` with `t = k + t_i + s`, `k` a whole
/// number of periods and `0 ≤ s < h_i` (up to rounding). `knots` must be non-empty and
/// increasing within one period.
pub(crate) fn locate(knots: &[f64], t: f64) -> (usize, f64, f64) {
    let t0 = knots[0];
    let mut periods = (t - t0).floor();
    let mut tau = t - periods;
    // Rounding can leave τ a hair outside [t_0, t_0 + 1).
    if tau < t0 {
        tau += 1.0;
        periods -= 1.0;
    } else if tau >= t0 + 1.0 {
        tau -= 1.0;
        periods += 1.0;
    }
    let i = knots.partition_point(|&k| k <= tau).saturating_sub(1);
    (i, tau - knots[i], periods)
}

/// Solve the cyclic system of the periodic spline for the knot second derivatives:
/// row i reads `h_{i−1} M_{i−1} + 2(h_{i−1} + h_i) M_i + h_i M_{i+1} = r_i` with indices
/// taken cyclically and `M_{i±n} = σ M_i`.
fn solve_cyclic(h: &[f64], sign: f64, rhs: &[f64]) -> Vec<f64> {
    let n = h.len();
    let hp = |i: usize| h[(i + n - 1) % n];
    if n <= 2 {
        // Tiny systems: assemble densely (neighbour terms may land on the same unknown).
        let mut a = nalgebra::DMatrix::<f64>::zeros(n, n);
        for i in 0..n {
            a[(i, i)] += 2.0 * (hp(i) + h[i]);
            // M_{i−1}
            let (j, s) = if i == 0 { (n - 1, sign) } else { (i - 1, 1.0) };
            a[(i, j)] += s * hp(i);
            // M_{i+1}
            let (j, s) = if i + 1 == n { (0, sign) } else { (i + 1, 1.0) };
            a[(i, j)] += s * h[i];
        }
        let b = nalgebra::DVector::from_column_slice(rhs);
        return a
            .lu()
            .solve(&b)
            .expect("periodic spline system is diagonally dominant")
            .iter()
            .copied()
            .collect();
    }
    // Sherman–Morrison on a tridiagonal matrix: A = T + u vᵀ with the corner terms moved
    // into the rank-one update.
    let sub: Vec<f64> = (0..n).map(hp).collect(); // coefficient of M_{i−1}
    let sup: Vec<f64> = h.to_vec(); // coefficient of M_{i+1}
    let mut diag: Vec<f64> = (0..n).map(|i| 2.0 * (hp(i) + h[i])).collect();
    let alpha = sign * sub[0]; // A[0][n−1]
    let beta = sign * sup[n - 1]; // A[n−1][0]
    let gamma = -diag[0];
    diag[0] -= gamma;
    diag[n - 1] -= alpha * beta / gamma;
    let y = solve_tridiagonal(&sub, &diag, &sup, rhs);
    let mut u = vec![0.0; n];
    u[0] = gamma;
    u[n - 1] = beta;
    let z = solve_tridiagonal(&sub, &diag, &sup, &u);
    // v = (1, 0, …, 0, alpha / gamma)
    let vy = y[0] + alpha / gamma * y[n - 1];
    let vz = z[0] + alpha / gamma * z[n - 1];
    let factor = vy / (1.0 + vz);
    y.iter().zip(&z).map(|(yi, zi)| yi - factor * zi).collect()
}

/// Thomas algorithm; `sub[0]` and `sup[n−1]` are ignored.
fn solve_tridiagonal(sub: &[f64], diag: &[f64], sup: &[f64], rhs: &[f64]) -> Vec<f64> {
    let n = diag.len();
    let mut c = vec![0.0; n];
    let mut d = vec![0.0; n];
    c[0] = sup[0] / diag[0];
    d[0] = rhs[0] / diag[0];
    for i in 1..n {
        let m = diag[i] - sub[i] * c[i - 1];
        c[i] = if i + 1 < n { sup[i] / m } else { 0.0 };
        d[i] = (rhs[i] - sub[i] * d[i - 1]) / m;
    }
    let mut x = vec![0.0; n];
    x[n - 1] = d[n - 1];
    for i in (0..n - 1).rev() {
        x[i] = d[i] - c[i] * x[i + 1];
    }
    x
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    fn random_knots(rng: &mut ChaCha8Rng, n: usize) -> Vec<f64> {
        let mut k: Vec<f64> = (0..n).map(|_| rng.random::<f64>()).collect();
        k.sort_by(f64::total_cmp);
        k.dedup();
        k
    }

    /// Guards interpolation: every knot value is returned exactly at its knot, for all three
    /// period rules and for tiny (1, 2 knots) and larger systems.
    #[test]
    fn hits_knot_values_exactly() {
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        for n in [1, 2, 3, 5, 17] {
            let knots = random_knots(&mut rng, n);
            let values: Vec<[f64; 2]> = knots
                .iter()
                .map(|_| [rng.random::<f64>(), rng.random::<f64>() - 0.5])
                .collect();
            for (sign, offset) in [(1.0, [0.0, 0.0]), (1.0, [2.5, -1.0]), (-1.0, [0.0, 0.0])] {
                let s = PeriodicSpline::new(&knots, &values, sign, offset);
                for (t, v) in knots.iter().zip(&values) {
                    assert_eq!(s.eval(*t)[0], *v);
                }
            }
        }
    }

    /// Guards C² continuity across the period boundary and across knots: value, slope and
    /// curvature agree from both sides (after the period rule) to rounding.
    #[test]
    fn continuous_to_second_derivative_everywhere() {
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        for n in [1, 2, 3, 4, 9] {
            let knots = random_knots(&mut rng, n);
            let values: Vec<[f64; 1]> = knots.iter().map(|_| [rng.random::<f64>()]).collect();
            for (sign, offset) in [(1.0, [0.0]), (1.0, [3.0]), (-1.0, [0.0])] {
                let s = PeriodicSpline::new(&knots, &values, sign, offset);
                let eps = 1e-9;
                let mut joints: Vec<f64> = knots.clone();
                joints.push(knots[0] + 1.0);
                for &t in &joints {
                    let left = s.eval(t - eps);
                    let right = s.eval(t + eps);
                    for d in 0..3 {
                        let tol = [1e-6, 1e-5, 1e-4][d] * (1.0 + right[d][0].abs());
                        assert!(
                            (left[d][0] - right[d][0]).abs() < tol,
                            "n={n} σ={sign} D={offset:?} t={t} derivative {d}: {} vs {}",
                            left[d][0],
                            right[d][0]
                        );
                    }
                }
                // The period rule itself.
                let a = s.eval(0.3)[0][0];
                let b = s.eval(1.3)[0][0];
                assert!((b - (sign * a + offset[0])).abs() < 1e-12);
                let c = s.eval(-1.7)[0][0];
                // Two periods back: σ² = 1.
                assert!((a - (c + 2.0 * offset[0])).abs() < 1e-9);
            }
        }
    }

    /// Guards the analytic derivatives against central finite differences.
    #[test]
    fn derivatives_match_finite_differences() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let knots = random_knots(&mut rng, 8);
        let values: Vec<[f64; 1]> = knots.iter().map(|_| [rng.random::<f64>()]).collect();
        let s = PeriodicSpline::new(&knots, &values, 1.0, [1.0]);
        let e = 1e-6;
        for i in 0..200 {
            let t = -0.5 + 2.0 * f64::from(i) / 200.0 + 1e-4;
            let j = s.eval(t);
            let (p, m) = (s.eval(t + e), s.eval(t - e));
            let d1 = (p[0][0] - m[0][0]) / (2.0 * e);
            let d2 = (p[1][0] - m[1][0]) / (2.0 * e);
            assert!((d1 - j[1][0]).abs() < 1e-5 * (1.0 + j[1][0].abs()));
            assert!((d2 - j[2][0]).abs() < 1e-4 * (1.0 + j[2][0].abs()));
        }
    }

    /// Guards the model: a periodic spline through samples of a smooth periodic function
    /// reproduces it closely between the samples (fourth-order accuracy).
    #[test]
    fn reproduces_smooth_periodic_function() {
        let n = 36;
        let knots: Vec<f64> = (0..n).map(|i| f64::from(i) / f64::from(n)).collect();
        let f = |t: f64| {
            (std::f64::consts::TAU * t).sin() + 0.3 * (2.0 * std::f64::consts::TAU * t).cos()
        };
        let values: Vec<[f64; 1]> = knots.iter().map(|&t| [f(t)]).collect();
        let s = PeriodicSpline::new(&knots, &values, 1.0, [0.0]);
        let worst = (0..1000)
            .map(|i| {
                let t = f64::from(i) / 1000.0;
                (s.eval(t)[0][0] - f(t)).abs()
            })
            .fold(0.0, f64::max);
        assert!(worst < 1e-4, "worst error {worst}");
    }
}
