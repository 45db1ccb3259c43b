//! One conjugate curve pair at one instant: contact point, tangents, frame and normal.
//!
//! Owns the geometric model of paper §5.1 in generic form (evaluated with `f64` for output
//! and with dual numbers for gradients): the follower curve c²(t) (closed cubic B-spline,
//! [`CURVE_CPS`] control points, follower-local), the normal angle θ(t) (closed cubic
//! B-spline, [`ANGLE_CPS`] control points), the contact point p = R₂c² + T₂, the driver
//! curve c¹ = Rz(−φ)(p − D), the tangents T² = R₂ċ² and T¹ = Rz(φ)ċ¹, and the contact
//! normal n = N cos θ + B sin θ.
//!
//! **Frame {N, B}.** N is the follower-local +z axis projected onto the normal plane of the
//! local tangent t̂² = ċ²/|ċ²| (then mapped to R by R₂), B = T̂² × N. It is smooth and
//! periodic along any closed curve whose tangent never becomes vertical; the candidate
//! problem enforces that with a tangent-steepness constraint (`energy::MAX_TANGENT_SLOPE`).
//! No frame built from the tangent alone can avoid a singularity everywhere (hairy-ball
//! theorem), so we put it where curves confined to thin horizontal bands have no reason to
//! go. With θ = 0 the normal points "up" along the follower's z axis; θ = π/2 points along
//! T̂² × ẑ (horizontal).
//!
//! It does not sum energies or know about constraints (see `energy`).

use super::bspline::Basis;
use super::math::{Scalar, V3};
use super::pose::Pose;

/// Control points of each follower curve c²ₖ: 8 (paper §5.1).
pub const CURVE_CPS: usize = 8;
/// Control points of each normal-angle spline θₖ: 10 (paper §5.1).
pub const ANGLE_CPS: usize = 10;
/// Design variables per curve pair: 3 coordinates per curve control point plus one angle per
/// angle control point. Layout: x[3j..3j+3] = Pⱼ, x[3·CURVE_CPS + j] = θⱼ.
pub const NV: usize = 3 * CURVE_CPS + ANGLE_CPS;

/// Regularization δ of the unit curvature direction κ/√(|κ|² + δ²) in E_plan, in curvature
/// units (1/model unit). Default 0.05: curves have radius ~2–3 (curvature ~0.4), so real
/// curvature is untouched while straight stretches (κ → 0) keep a finite gradient.
pub const CURVATURE_REG: f64 = 0.05;

/// Everything about one contact at one instant.
#[derive(Clone, Copy, Debug)]
pub struct Contact<S> {
    /// Contact point in R.
    pub p: V3<S>,
    /// Follower curve point c² (follower-local).
    pub c2: V3<S>,
    /// Driver curve point c¹ (driver-local).
    pub c1: V3<S>,
    /// Unit contact normal in R (driver → follower).
    pub n: V3<S>,
    /// T² (follower tangent mapped to R).
    pub t2: V3<S>,
    /// T¹ (driver tangent mapped to R).
    pub t1: V3<S>,
    /// Local follower tangent ċ².
    pub c2d: V3<S>,
    /// Local driver tangent ċ¹.
    pub c1d: V3<S>,
    /// Regularized unit curvature direction of c² in R.
    pub kappa: V3<S>,
}

/// c², ċ², c̈² from the active control points and basis.
pub fn curve_at<S: Scalar>(b: &Basis, cp: &dyn Fn(usize) -> V3<S>) -> [V3<S>; 3] {
    let mut out = [V3::<S>::zero(); 3];
    for r in 0..4 {
        let p = cp(b.idx[r]);
        out[0] = out[0] + p.scalec(b.w0[r]);
        out[1] = out[1] + p.scalec(b.w1[r]);
        out[2] = out[2] + p.scalec(b.w2[r]);
    }
    out
}

/// θ from the active angle control points.
pub fn angle_at<S: Scalar>(b: &Basis, th: &dyn Fn(usize) -> S) -> S {
    let mut v = S::cst(0.0);
    for r in 0..4 {
        v += th(b.idx[r]) * b.w0[r];
    }
    v
}

/// The tangent-only part of a contact: (p, c¹, ċ¹, T¹, T²).
pub type Tangents<S> = (V3<S>, V3<S>, V3<S>, V3<S>, V3<S>);

/// Tangent-only part of the model (no normal): p, c¹, ċ¹, T¹, T² — used for the
/// smoothness term at the next sample. Inlined always: on dual numbers, a call copies the
/// jets in and the five vectors out (see `math`).
#[inline(always)]
pub fn tangents<S: Scalar>(pose: &Pose, dx: f64, c2: [V3<S>; 3]) -> Tangents<S> {
    let q = c2[0].rot(&pose.rot);
    let p = q + V3::cst(pose.trans);
    let t2 = c2[1].rot(&pose.rot);
    let omega = V3::<S>::cst(pose.omega);
    let phi_rate = std::f64::consts::TAU;
    let rel = p - V3::cst([dx, 0.0, 0.0]);
    // ṗ − ω_driver × (p − D) with ṗ = ω × q + T² + v.
    let zx_rel = V3::new(-rel.y, rel.x, S::cst(0.0)).scalec(phi_rate);
    let t1 = t2 + omega.cross(q) + V3::cst(pose.vel) - zx_rel;
    let c1 = rel.rot_t(&pose.driver);
    let c1d = t1.rot_t(&pose.driver);
    (p, c1, c1d, t1, t2)
}

/// The full contact model at one instant. Inlined always, as [`tangents`].
#[inline(always)]
pub fn contact<S: Scalar>(pose: &Pose, dx: f64, c2: [V3<S>; 3], theta: S) -> Contact<S> {
    let (p, c1, c1d, t1, t2) = tangents(pose, dx, c2);
    let that = c2[1].unit();
    let ez = V3::<S>::cst([0.0, 0.0, 1.0]);
    let nl = (ez - that.scale(that.z)).unit();
    let bl = that.cross(nl);
    let nloc = nl.scale(theta.cos()) + bl.scale(theta.sin());
    let n = nloc.rot(&pose.rot);
    // Curvature direction: component of c̈² normal to the tangent.
    let acc = c2[2];
    let kl = acc - that.scale(acc.dot(that));
    let speed2 = c2[1].norm2();
    let kvec = kl.scale(S::cst(1.0) / speed2); // curvature vector magnitude |κ|
    let kn = (kvec.norm2() + CURVATURE_REG * CURVATURE_REG).sqrt();
    let kappa = kvec.scale(S::cst(1.0) / kn).rot(&pose.rot);
    Contact {
        p,
        c2: c2[0],
        c1,
        n,
        t2,
        t1,
        c2d: c2[1],
        c1d,
        kappa,
    }
}

/// Control points of the follower curve from a design vector.
pub fn curve_cps(x: &[f64]) -> Vec<[f64; 3]> {
    (0..CURVE_CPS)
        .map(|j| [x[3 * j], x[3 * j + 1], x[3 * j + 2]])
        .collect()
}

/// Control points of the angle spline from a design vector.
pub fn angle_cps(x: &[f64]) -> Vec<f64> {
    x[3 * CURVE_CPS..NV].to_vec()
}

/// Evaluate a contact with plain numbers at any t for a given pose.
pub fn contact_f64(x: &[f64], pose: &Pose, dx: f64) -> Contact<f64> {
    let bc = super::bspline::basis(CURVE_CPS, pose.t);
    let ba = super::bspline::basis(ANGLE_CPS, pose.t);
    let cpf = |j: usize| V3::new(x[3 * j], x[3 * j + 1], x[3 * j + 2]);
    let thf = |j: usize| x[3 * CURVE_CPS + j];
    let c2 = curve_at::<f64>(&bc, &cpf);
    let th = angle_at::<f64>(&ba, &thf);
    contact(pose, dx, c2, th)
}

/// Conjugation residual in degrees: the worst angle between n and the normal planes of T¹
/// and T², i.e. asin(max(|n·T̂¹|, |n·T̂²|)).
pub fn conjugation_residual_deg(n: V3<f64>, t1: V3<f64>, t2: V3<f64>) -> f64 {
    let f = |t: V3<f64>| {
        let l = t.norm();
        if l == 0.0 {
            0.0
        } else {
            (n.dot(t) / l).abs()
        }
    };
    f(t1).max(f(t2)).min(1.0).asin().to_degrees()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::synth::pose::pose_1r;

    fn design() -> Vec<f64> {
        let mut x = vec![0.0; NV];
        for j in 0..CURVE_CPS {
            let a = j as f64 / CURVE_CPS as f64 * std::f64::consts::TAU;
            x[3 * j] = 2.5 * a.cos() + 0.2 * (3.0 * a).cos();
            x[3 * j + 1] = 2.5 * a.sin();
            x[3 * j + 2] = 0.3 * (2.0 * a).sin();
        }
        for j in 0..ANGLE_CPS {
            x[3 * CURVE_CPS + j] = 1.0 + 0.3 * (j as f64).sin();
        }
        x
    }

    /// Guards the kinematics: p computed from c² equals Rz(φ)c¹ + D, and T¹ is the time
    /// derivative of Rz(φ)c¹(t) taken with the driver fixed (finite differences of c¹).
    #[test]
    fn contact_kinematics_are_consistent() {
        let x = design();
        let dx = 6.0;
        let rate = -std::f64::consts::TAU;
        let pose = |t: f64| {
            pose_1r(
                t,
                rate * t + 0.3 * (std::f64::consts::TAU * t).sin(),
                rate + 0.3 * std::f64::consts::TAU * (std::f64::consts::TAU * t).cos(),
            )
        };
        for k in 0..20 {
            let t = k as f64 / 20.0 + 0.01;
            let c = contact_f64(&x, &pose(t), dx);
            let r = crate::synth::math::rz(std::f64::consts::TAU * t);
            let back = V3::<f64>::new(c.c1.x, c.c1.y, c.c1.z).rot(&r);
            assert!((back.x + dx - c.p.x).abs() < 1e-12);
            assert!((back.y - c.p.y).abs() < 1e-12);
            let h = 1e-6;
            let cp = contact_f64(&x, &pose(t + h), dx);
            let cm = contact_f64(&x, &pose(t - h), dx);
            let fd = [
                (cp.c1.x - cm.c1.x) / (2.0 * h),
                (cp.c1.y - cm.c1.y) / (2.0 * h),
                (cp.c1.z - cm.c1.z) / (2.0 * h),
            ];
            let an = c.c1d.vals();
            for a in 0..3 {
                assert!(
                    (fd[a] - an[a]).abs() < 1e-5 * (1.0 + an[a].abs()),
                    "t={t} axis {a}"
                );
            }
            // Normal is unit and perpendicular to T².
            assert!((c.n.norm() - 1.0).abs() < 1e-12);
            assert!(c.n.dot(c.t2).abs() < 1e-9);
        }
    }
}
