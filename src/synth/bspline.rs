//! Closed (periodic) uniform cubic B-splines over one period t ∈ [0, 1).
//!
//! Owns the knot convention used by every curve in a mechanism and its evaluation with the
//! first two derivatives with respect to t. It does not know what the control points mean
//! (follower curve points or normal angles).
//!
//! **Convention.** With `n` control points P₀…Pₙ₋₁ the parameter is u = n·t; on span
//! j = ⌊u⌋ (s = u − j ∈ [0, 1)) the curve is
//! `c(t) = Σ_{r=0..3} b_r(s) · P_{(j+r) mod n}` with the uniform cubic basis
//! b₀ = (1−s)³/6, b₁ = (3s³ − 6s² + 4)/6, b₂ = (−3s³ + 3s² + 3s + 1)/6, b₃ = s³/6.
//! So c(0) = (P₀ + 4P₁ + P₂)/6; the curve is C² and periodic with period 1.

/// The degree of every spline in a mechanism.
pub const DEGREE: usize = 3;

/// Basis weights of one parameter value: the 4 active control point indices and the weights
/// for the value and the first and second derivatives with respect to t.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Basis {
    /// Indices of the 4 active control points (already reduced mod n).
    pub idx: [usize; 4],
    /// The first active index (span), before reduction.
    pub span: usize,
    /// Weights for c(t).
    pub w0: [f64; 4],
    /// Weights for dc/dt.
    pub w1: [f64; 4],
    /// Weights for d²c/dt².
    pub w2: [f64; 4],
}

/// Basis of a closed uniform cubic B-spline with `n` (≥ 4) control points at `t` (any real;
/// reduced to one period).
pub fn basis(n: usize, t: f64) -> Basis {
    debug_assert!(n >= 4);
    let u = t.rem_euclid(1.0) * n as f64;
    let mut j = u.floor() as usize;
    let mut s = u - j as f64;
    if j >= n {
        // u rounded up to n.
        j = n - 1;
        s = 1.0;
    }
    let nf = n as f64;
    let s2 = s * s;
    let s3 = s2 * s;
    let w0 = [
        (1.0 - s).powi(3) / 6.0,
        (3.0 * s3 - 6.0 * s2 + 4.0) / 6.0,
        (-3.0 * s3 + 3.0 * s2 + 3.0 * s + 1.0) / 6.0,
        s3 / 6.0,
    ];
    let d1 = [
        -0.5 * (1.0 - s) * (1.0 - s),
        (9.0 * s2 - 12.0 * s) / 6.0,
        (-9.0 * s2 + 6.0 * s + 3.0) / 6.0,
        0.5 * s2,
    ];
    let d2 = [1.0 - s, 3.0 * s - 2.0, -3.0 * s + 1.0, s];
    Basis {
        idx: [j % n, (j + 1) % n, (j + 2) % n, (j + 3) % n],
        span: j,
        w0,
        w1: d1.map(|x| x * nf),
        w2: d2.map(|x| x * nf * nf),
    }
}

/// Evaluate a closed cubic spline of scalars at `t`: (value, d/dt, d²/dt²).
pub fn eval_scalar(cps: &[f64], t: f64) -> [f64; 3] {
    let b = basis(cps.len(), t);
    let mut out = [0.0; 3];
    for r in 0..4 {
        let c = cps[b.idx[r]];
        out[0] += b.w0[r] * c;
        out[1] += b.w1[r] * c;
        out[2] += b.w2[r] * c;
    }
    out
}

/// Evaluate a closed cubic spline of 3-D points at `t`: (value, d/dt, d²/dt²).
pub fn eval_point(cps: &[[f64; 3]], t: f64) -> [[f64; 3]; 3] {
    let b = basis(cps.len(), t);
    let mut out = [[0.0; 3]; 3];
    for r in 0..4 {
        let c = cps[b.idx[r]];
        for a in 0..3 {
            out[0][a] += b.w0[r] * c[a];
            out[1][a] += b.w1[r] * c[a];
            out[2][a] += b.w2[r] * c[a];
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cps() -> Vec<[f64; 3]> {
        (0..8)
            .map(|i| {
                let a = i as f64 * 0.8;
                [
                    a.cos() * 2.0 + 0.1 * i as f64,
                    a.sin() * 1.5,
                    (a * 1.7).sin(),
                ]
            })
            .collect()
    }

    /// Guards the derivative weights: d/dt and d²/dt² agree with central finite differences.
    #[test]
    fn bspline_derivatives_match_finite_differences() {
        let c = cps();
        let h = 1e-6;
        for k in 0..50 {
            let t = k as f64 / 50.0 + 0.0037;
            let e = eval_point(&c, t);
            let ep = eval_point(&c, t + h);
            let em = eval_point(&c, t - h);
            for a in 0..3 {
                let fd1 = (ep[0][a] - em[0][a]) / (2.0 * h);
                let fd2 = (ep[1][a] - em[1][a]) / (2.0 * h);
                assert!(
                    (fd1 - e[1][a]).abs() < 1e-5 * (1.0 + fd1.abs()),
                    "d1 at t={t}"
                );
                assert!(
                    (fd2 - e[2][a]).abs() < 1e-4 * (1.0 + fd2.abs()),
                    "d2 at t={t}"
                );
            }
        }
    }

    /// Guards periodicity and C² continuity across the seam t = 1 → 0 and across spans.
    #[test]
    fn bspline_is_periodic_and_c2_across_knots() {
        let c = cps();
        let a = eval_point(&c, 1.0 - 1e-12);
        let b = eval_point(&c, 0.0);
        for d in 0..3 {
            for x in 0..3 {
                assert!((a[d][x] - b[d][x]).abs() < 1e-6, "seam d{d}");
            }
        }
        for j in 1..8 {
            let t = j as f64 / 8.0;
            let a = eval_point(&c, t - 1e-12);
            let b = eval_point(&c, t);
            for d in 0..3 {
                for x in 0..3 {
                    assert!((a[d][x] - b[d][x]).abs() < 1e-6, "knot {j} d{d}");
                }
            }
        }
    }

    /// Guards the knot convention documented above: c(0) = (P₀ + 4P₁ + P₂)/6 and the basis
    /// is a partition of unity.
    #[test]
    fn bspline_knot_convention_and_partition_of_unity() {
        let v = [1.0, 2.0, 7.0, -3.0, 0.5];
        let e = eval_scalar(&v, 0.0);
        assert!((e[0] - (1.0 + 8.0 + 7.0) / 6.0).abs() < 1e-12);
        for k in 0..100 {
            let b = basis(10, k as f64 / 100.0);
            let s: f64 = b.w0.iter().sum();
            assert!((s - 1.0).abs() < 1e-12);
            assert!(b.w1.iter().sum::<f64>().abs() < 1e-9);
        }
    }
}
