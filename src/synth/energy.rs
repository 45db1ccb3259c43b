//! The candidate problem of one curve pair: objective (paper Eqs. 19–23 plus the class's
//! closure energy and E_vary; for 1R/1R1T our E_robust, and E_focus for a 1R candidate of a
//! gap-filling band) and constraints, with exact gradients by forward-mode AD.
//!
//! Owns the weights, the constraint set and its aggregation, and the evaluation of a design
//! vector (layout in `model::NV`). It does not run the optimizer (see `optimizer`) or pick
//! initial guesses (see `candidate`).
//!
//! **Evaluation.** Every sample i depends on only 4 consecutive curve control points (and the
//! smoothness term on sample i + 1 adds one more) and 4 angle control points, so each sample
//! is evaluated with a 20-slot dual number over that local set and scattered into the
//! 34-entry gradient. E_vary couples two samples half a period apart and uses a full
//! 34-slot dual.
//!
//! **Scale.** The objective is the paper's sum over samples (E_vary added once, as in the
//! paper) divided by N: the weights keep the paper's ratios, and values of order 1–10 keep
//! SLSQP's first quasi-Newton steps (identity Hessian) sensible.
//!
//! **Constraints** (all written g ≤ 0): curve length L₁ ≤ Length(c²) ≤ L₂; the height band
//! by bounds on the control points' z (B-spline convex hull); minimum distance of the contact
//! from the follower joint axis (1R/1R1T) or centre (3R) and of c¹ from the driver axis;
//! a tangent-steepness bound that keeps the {N, B} frame regular; for 3R the cone
//! |n·p̂| ≤ sin γ₀ (paper Eq. 30 as printed; cos γ₀ with [`NormalCone::Arm`]). Per-sample
//! constraints are aggregated into one smooth Kreisselmeier–Steinhauser maximum each
//! (KS ≥ max, so KS ≤ 0 implies every sample holds); the acceptance checks use the exact
//! per-sample maxima.

use super::closure::{Class, NormalCone};
use super::dual::{Dual, Scalar, V3};
use super::model::{self, ANGLE_CPS, CURVE_CPS, NV};
use super::pose::PoseTrack;
use std::sync::Arc;

/// Weight of E_smth: 50 (paper §5.1).
pub const W_SMTH: f64 = 50.0;
/// Weight of E_tang: 1 (paper §5.1).
pub const W_TANG: f64 = 1.0;
/// Weight of E_norm: 10⁴, not the paper's 100. With 100, the summed E_tang/E_plan swamp it
/// and no candidate of a prototype reached a conjugation residual ≤ 1°; 10⁴ makes a 1°
/// residual cost as much as a unit change of E_tang.
pub const W_NORM: f64 = 1.0e4;
/// Weight of E_plan: 1 (paper §5.1).
pub const W_PLAN: f64 = 1.0;
/// Weight of E_closure_1R / E_closure_1R1T: 0.1 (supplementary notes).
pub const W_CLOSURE: f64 = 0.1;
/// Weight of E_robust (ours, 1R and 1R1T): Σᵢ max(0, a₀ − |aᵢ|)² where aᵢ = n·(ẑ×p̂) is the
/// contact's torque arm per unit radius. Default 20: a contact with no arm then costs
/// 20·a₀² ≈ 1.8 per sample, comparable to E_plan's worst case, so the optimizer shortens
/// the intervals in which a contact cannot drive, while contacts above the threshold feel
/// nothing (E_plan and conjugation are not disturbed). Set to 0 for the paper's energy.
pub const W_ROBUST: f64 = 20.0;
/// Threshold a₀ of E_robust. Default 0.3: comfortably above sin γ₀ = sin 10° ≈ 0.17, the
/// robust-closure limit, so contacts that meet it count robustly with margin.
pub const ROBUST_ARM: f64 = 0.3;
/// Smoothing of |a| in E_robust (|a| ≈ √(a² + δ²)). Default 1e-3.
pub const ROBUST_SMOOTH: f64 = 1.0e-3;
/// Weight of E_focus (ours, 1R): Σᵢ max(0, a₀ − sᵢ·aᵢ)² over the samples i where the
/// candidate of a gap-filling band (see `search`) is asked for a robust torque of sign sᵢ.
/// Default 50. Measured on quarter-turn-dwell (d_x = 9, seed 1), robust closure at K = 5:
/// 0.711 without gap-filling bands, 0.703 at weight 20, 0.819 at 50; at 100 (and focus on
/// every band) most candidates failed the 1° conjugation check.
pub const W_FOCUS: f64 = 50.0;
/// Weight of E_vary: 20 (supplementary notes).
pub const W_VARY: f64 = 20.0;
/// Follower curve length bounds L₁ = 4π, L₂ = 6π (paper §5.1).
pub const LENGTH_BOUNDS: [f64; 2] = [4.0 * std::f64::consts::PI, 6.0 * std::f64::consts::PI];
/// Minimum distance of every contact from the follower joint axis (1R/1R1T) or centre (3R),
/// model units. Default 0.8: at the default scale of 10 mm per unit this leaves 8 mm for
/// the follower's pin and hub.
pub const MIN_FOLLOWER_RADIUS: f64 = 0.8;
/// Minimum distance of the driver curve from the driver axis, model units. Default 0.8, for
/// the driver shaft (8 mm at 10 mm per unit).
pub const MIN_DRIVER_RADIUS: f64 = 0.8;
/// Largest allowed |t̂².z| (sine of the follower curve's slope against the horizontal).
/// Default sin 60°: keeps the {N, B} frame (projected z axis) at least 30° from its
/// singularity.
pub const MAX_TANGENT_SLOPE: f64 = 0.866_025_403_784_438_6;
/// Sharpness ρ of the KS aggregation for constraints in model units (radii). Default 60:
/// KS overestimates the maximum by at most ln(N)/ρ ≈ 0.1 units for N = 360.
pub const KS_RHO_LENGTH: f64 = 60.0;
/// Sharpness ρ of the KS aggregation for dimensionless constraints (slope, 3R cone, both in
/// squared-sine units). Default 2000: the overestimate ≤ ln(360)/2000 ≈ 0.003 is a tenth of
/// sin²10° ≈ 0.03.
pub const KS_RHO_UNITLESS: f64 = 2000.0;
/// Half width of the box on control point x and y, model units. Default 8: curves of length
/// ≤ 6π have radius ~3, so the box never binds a sensible curve but stops divergence.
pub const XY_BOX: f64 = 8.0;
/// Bound on |θ| control points, radians. Default 4π: θ is an angle, two turns either way is
/// more freedom than any smooth normal needs.
pub const THETA_BOX: f64 = 4.0 * std::f64::consts::PI;

/// Local dual width for one sample.
const DL: usize = 20;

/// One candidate problem: a curve pair in a band for a given motion, class and d_x.
#[derive(Clone, Debug)]
pub struct PairProblem {
    /// Motion class.
    pub class: Class,
    /// Sampled follower motion.
    pub poses: Arc<PoseTrack>,
    /// Driver offset d_x.
    pub dx: f64,
    /// Height band [z_min, z_max] (follower-local z).
    pub band: (f64, f64),
    /// Sample index t_v of E_vary (None: no E_vary, as for 1R).
    pub vary: Option<usize>,
    /// Weight of E_closure (1R, 1R1T).
    pub w_closure: f64,
    /// Weight of E_robust (1R, 1R1T).
    pub w_robust: f64,
    /// Bound on |n·p̂| (3R only; see [`NormalCone`]).
    pub cone: NormalCone,
    /// 1R only: per sample, the torque sign this candidate is asked to supply robustly
    /// (+1, −1, 0 for none); see [`W_FOCUS`]. `None` for an ordinary candidate.
    pub focus: Option<Arc<Vec<f64>>>,
}

/// Names of the constraints, in evaluation order.
pub const CONSTRAINT_NAMES: [&str; 6] = [
    "length ≥ L1",
    "length ≤ L2",
    "follower axis clearance",
    "driver axis clearance",
    "tangent steepness",
    "3R normal cone",
];

/// Objective, constraints and their gradients at one design vector.
#[derive(Clone, Debug)]
pub struct Evaluation {
    /// Objective value.
    pub f: f64,
    /// Objective gradient.
    pub grad: Vec<f64>,
    /// Constraint values (≤ 0 feasible).
    pub cons: Vec<f64>,
    /// Constraint gradients.
    pub cons_grad: Vec<Vec<f64>>,
    /// Exact (non-aggregated) worst per-sample values of the aggregated constraints.
    pub cons_exact: Vec<f64>,
}

struct Ks {
    vals: Vec<f64>,
    grads: Vec<(usize, usize, [f64; DL])>,
}

impl Ks {
    fn new(n: usize) -> Self {
        Self {
            vals: Vec::with_capacity(n),
            grads: Vec::with_capacity(n),
        }
    }
    fn push(&mut self, g: Dual<DL>, j0: usize, ja: usize) {
        self.vals.push(g.v);
        self.grads.push((j0, ja, g.g));
    }
    fn finish(&self, rho: f64) -> (f64, Vec<f64>, f64) {
        let m = self.vals.iter().cloned().fold(f64::NEG_INFINITY, f64::max);
        let w: Vec<f64> = self.vals.iter().map(|v| (rho * (v - m)).exp()).collect();
        let s: f64 = w.iter().sum();
        let mut grad = vec![0.0; NV];
        for (wi, (j0, ja, g)) in w.iter().zip(&self.grads) {
            scatter(&mut grad, *j0, *ja, g, wi / s);
        }
        (m + s.ln() / rho, grad, m)
    }
}

/// Add `scale × local gradient` into the global gradient.
fn scatter(grad: &mut [f64], j0: usize, ja: usize, g: &[f64; DL], scale: f64) {
    for s in 0..15 {
        let cp = (j0 + s / 3) % CURVE_CPS;
        grad[3 * cp + s % 3] += scale * g[s];
    }
    for s in 0..4 {
        grad[3 * CURVE_CPS + (ja + s) % ANGLE_CPS] += scale * g[15 + s];
    }
}

fn sq<S: Scalar>(v: V3<S>) -> S {
    v.norm2()
}

impl PairProblem {
    /// Number of constraints for this class.
    pub fn n_constraints(&self) -> usize {
        if self.class == Class::R3 {
            6
        } else {
            5
        }
    }

    /// Variable bounds: x, y in the box, z in the band, θ in its box.
    pub fn bounds(&self) -> Vec<(f64, f64)> {
        let mut b = Vec::with_capacity(NV);
        for _ in 0..CURVE_CPS {
            b.push((-XY_BOX, XY_BOX));
            b.push((-XY_BOX, XY_BOX));
            b.push(self.band);
        }
        for _ in 0..ANGLE_CPS {
            b.push((-THETA_BOX, THETA_BOX));
        }
        b
    }

    /// ñ as generic numbers (zero-padded); 1R has no smooth ñ and is not used here.
    fn ntilde<S: Scalar>(&self, c: &model::Contact<S>) -> V3<S> {
        let m = c.p.cross(c.n);
        match self.class {
            Class::R1 => V3::new(m.z, S::cst(0.0), S::cst(0.0)),
            Class::R1T1 => {
                let v = V3::new(c.n.z, m.z, S::cst(0.0));
                v.scale(S::cst(1.0) / (v.norm2() + 1e-12).sqrt())
            }
            Class::R3 => m.scale(S::cst(1.0) / (m.norm2() + 1e-12).sqrt()),
        }
    }

    /// Evaluate objective, constraints and gradients.
    pub fn evaluate(&self, x: &[f64]) -> Evaluation {
        let n = self.poses.len();
        let mut f = 0.0;
        let mut grad = vec![0.0; NV];
        let mut len = 0.0;
        let mut len_grad = vec![0.0; NV];
        let mut ks_rf = Ks::new(n);
        let mut ks_rd = Ks::new(n);
        let mut ks_sl = Ks::new(n);
        let mut ks_cone = Ks::new(n);
        let max_dot = self.cone.max_abs_dot();
        for i in 0..n {
            let pose = &self.poses.samples[i];
            let next = &self.poses.samples[(i + 1) % n];
            let bc = super::bspline::basis(CURVE_CPS, pose.t);
            let bn = super::bspline::basis(CURVE_CPS, next.t);
            let ba = super::bspline::basis(ANGLE_CPS, pose.t);
            let j0 = bc.span % CURVE_CPS;
            let ja = ba.span % ANGLE_CPS;
            let cp = |g: usize| -> V3<Dual<DL>> {
                let off = (g + CURVE_CPS - j0) % CURVE_CPS;
                let mk = |a: usize| {
                    let v = x[3 * g + a];
                    if off < 5 {
                        Dual::var(v, 3 * off + a)
                    } else {
                        Dual::cst(v)
                    }
                };
                V3::new(mk(0), mk(1), mk(2))
            };
            let th = |g: usize| -> Dual<DL> {
                let off = (g + ANGLE_CPS - ja) % ANGLE_CPS;
                let v = x[3 * CURVE_CPS + g];
                if off < 4 {
                    Dual::var(v, 15 + off)
                } else {
                    Dual::cst(v)
                }
            };
            let c2 = model::curve_at(&bc, &cp);
            let theta = model::angle_at(&ba, &th);
            let c = model::contact(pose, self.dx, c2, theta);
            let c2n = model::curve_at(&bn, &cp);
            let (_, _, c1d_next, _, _) = model::tangents(next, self.dx, c2n);
            let t1h = c.t1.unit();
            let t2h = c.t2.unit();
            let one = Dual::<DL>::cst(1.0);
            let e_norm = {
                let d = c.n.dot(t1h);
                d * d
            };
            let e_tang = sq(t1h - t2h);
            let e_plan = sq(c.n - c.kappa);
            let e_smth = sq(c2n[1].unit() - c.c2d.unit()) + sq(c1d_next.unit() - c.c1d.unit());
            let mut e = e_norm * W_NORM + e_tang * W_TANG + e_plan * W_PLAN + e_smth * W_SMTH;
            let pxy = (c.p.x * c.p.x + c.p.y * c.p.y).sqrt();
            if matches!(self.class, Class::R1 | Class::R1T1) {
                // (ẑ × p)/|ẑ × p| · n
                let circ = (c.n.y * c.p.x - c.n.x * c.p.y) / pxy;
                let mut cl = -(circ * circ);
                if self.class == Class::R1T1 {
                    cl = cl - c.n.z * c.n.z;
                }
                e += cl * self.w_closure;
                let arm = (circ * circ + ROBUST_SMOOTH * ROBUST_SMOOTH).sqrt();
                if arm.v < ROBUST_ARM {
                    let d = -arm + ROBUST_ARM;
                    e += d * d * self.w_robust;
                }
                if let Some(sign) = self.focus.as_ref().map(|f| f[i]).filter(|s| *s != 0.0) {
                    let d = -(circ * sign) + ROBUST_ARM;
                    if d.v > 0.0 {
                        e += d * d * W_FOCUS;
                    }
                }
            }
            f += e.v;
            scatter(&mut grad, j0, ja, &e.g, 1.0);
            let speed = c.c2d.norm();
            len += speed.v / n as f64;
            scatter(&mut len_grad, j0, ja, &speed.g, 1.0 / n as f64);
            let radius = if self.class == Class::R3 {
                c.p.norm()
            } else {
                pxy
            };
            ks_rf.push(-radius + MIN_FOLLOWER_RADIUS, j0, ja);
            let c1xy = (c.c1.x * c.c1.x + c.c1.y * c.c1.y).sqrt();
            ks_rd.push(-c1xy + MIN_DRIVER_RADIUS, j0, ja);
            let slope = c.c2d.z / speed;
            ks_sl.push(
                slope * slope - MAX_TANGENT_SLOPE * MAX_TANGENT_SLOPE,
                j0,
                ja,
            );
            if self.class == Class::R3 {
                let d = c.n.dot(c.p) / c.p.norm();
                ks_cone.push(d * d - one * (max_dot * max_dot), j0, ja);
            }
        }
        if let (Some(iv), true) = (self.vary, self.class != Class::R1) {
            let (v, g) = self.e_vary(x, iv);
            f += W_VARY * v;
            for (a, b) in grad.iter_mut().zip(g.iter()) {
                *a += W_VARY * b;
            }
        }
        // Mean per sample: the same ratios as the paper's sums, but an objective of order
        // 1–10 keeps SLSQP's first (unit-Hessian) steps sensible.
        f /= n as f64;
        for g in grad.iter_mut() {
            *g /= n as f64;
        }
        let mut cons = Vec::with_capacity(6);
        let mut cons_grad = Vec::with_capacity(6);
        let mut cons_exact = Vec::with_capacity(6);
        let [l1, l2] = LENGTH_BOUNDS;
        cons.push((l1 - len) / l1);
        cons_grad.push(len_grad.iter().map(|g| -g / l1).collect());
        cons_exact.push((l1 - len) / l1);
        cons.push((len - l2) / l2);
        cons_grad.push(len_grad.iter().map(|g| g / l2).collect());
        cons_exact.push((len - l2) / l2);
        let mut agg = |ks: &Ks, rho: f64| {
            let (v, g, m) = ks.finish(rho);
            cons.push(v);
            cons_grad.push(g);
            cons_exact.push(m);
        };
        agg(&ks_rf, KS_RHO_LENGTH);
        agg(&ks_rd, KS_RHO_LENGTH);
        agg(&ks_sl, KS_RHO_UNITLESS);
        if self.class == Class::R3 {
            agg(&ks_cone, KS_RHO_UNITLESS);
        }
        Evaluation {
            f,
            grad,
            cons,
            cons_grad,
            cons_exact,
        }
    }

    /// E_vary = ñ(t_v)·ñ(t_v + ½) with its gradient (full 34-slot dual).
    fn e_vary(&self, x: &[f64], iv: usize) -> (f64, Vec<f64>) {
        let n = self.poses.len();
        let cp = |g: usize| -> V3<Dual<NV>> {
            V3::new(
                Dual::var(x[3 * g], 3 * g),
                Dual::var(x[3 * g + 1], 3 * g + 1),
                Dual::var(x[3 * g + 2], 3 * g + 2),
            )
        };
        let th = |g: usize| Dual::<NV>::var(x[3 * CURVE_CPS + g], 3 * CURVE_CPS + g);
        let at = |i: usize| {
            let pose = &self.poses.samples[i % n];
            let bc = super::bspline::basis(CURVE_CPS, pose.t);
            let ba = super::bspline::basis(ANGLE_CPS, pose.t);
            let c = model::contact(
                pose,
                self.dx,
                model::curve_at(&bc, &cp),
                model::angle_at(&ba, &th),
            );
            self.ntilde(&c)
        };
        let a = at(iv);
        let b = at(iv + n / 2);
        let d = a.dot(b);
        (d.v, d.g.to_vec())
    }

    /// Whether a design satisfies the bounds and every constraint exactly (per sample, not
    /// aggregated), within `tol`.
    pub fn feasible(&self, x: &[f64], ev: &Evaluation, tol: f64) -> bool {
        let b = self.bounds();
        x.iter()
            .zip(b.iter())
            .all(|(v, (lo, hi))| *v >= lo - tol && *v <= hi + tol)
            && ev.cons_exact.iter().all(|c| *c <= tol)
            && ev.f.is_finite()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::synth::pose::{pose_1r, Pose, PoseFn, PoseTrack};

    fn problem(class: Class) -> (PairProblem, Vec<f64>) {
        let at: PoseFn = match class {
            Class::R3 => Arc::new(|t: f64| {
                let a = std::f64::consts::TAU * t;
                let q =
                    nalgebra::UnitQuaternion::from_euler_angles(0.3 * a.sin(), 0.2 * a.cos(), a);
                let w = nalgebra::Vector3::new(0.3, -0.1, 1.0) * std::f64::consts::TAU;
                Pose::new(
                    t,
                    &q,
                    nalgebra::Vector3::zeros(),
                    w,
                    nalgebra::Vector3::zeros(),
                )
            }),
            _ => Arc::new(move |t: f64| {
                let a = std::f64::consts::TAU;
                let mut p = pose_1r(t, a * t + 0.4 * (a * t).sin(), a + 0.4 * a * (a * t).cos());
                if class == Class::R1T1 {
                    p.trans = [0.0, 0.0, 0.5 * (a * t).sin()];
                    p.vel = [0.0, 0.0, 0.5 * a * (a * t).cos()];
                }
                p
            }),
        };
        let poses = Arc::new(PoseTrack::from_fn(36, at));
        let mut x = vec![0.0; NV];
        for j in 0..CURVE_CPS {
            let a = j as f64 / CURVE_CPS as f64 * std::f64::consts::TAU;
            x[3 * j] = 2.5 * a.cos() + 0.3 * (3.0 * a).cos();
            x[3 * j + 1] = -2.5 * a.sin();
            x[3 * j + 2] = 0.2 * (2.0 * a).sin();
        }
        for j in 0..ANGLE_CPS {
            x[3 * CURVE_CPS + j] = 1.2 + 0.4 * (j as f64 * 0.7).sin();
        }
        (
            PairProblem {
                class,
                poses,
                dx: 6.0,
                band: (-0.5, 0.5),
                vary: Some(3),
                w_closure: W_CLOSURE,
                w_robust: W_ROBUST,
                cone: NormalCone::Tangent,
                focus: None,
            },
            x,
        )
    }

    /// Guards the analytic (forward-mode) gradients of the objective and of every constraint
    /// against central finite differences, for all three classes and for a 1R gap-filling
    /// candidate (E_focus).
    #[test]
    fn energy_gradients_match_finite_differences() {
        let focused = || {
            let (mut pb, x) = problem(Class::R1);
            let n = pb.poses.len();
            // Ask for both signs, so that the term is active at some samples either way.
            pb.focus = Some(Arc::new((0..n).map(|i| [1.0, 0.0, -1.0][i % 3]).collect()));
            (pb, x)
        };
        let problems = [Class::R1, Class::R1T1, Class::R3]
            .map(problem)
            .into_iter()
            .chain([focused()]);
        for (pb, x) in problems {
            let class = pb.class;
            let ev = pb.evaluate(&x);
            let h = 1e-6;
            for k in 0..NV {
                let mut xp = x.clone();
                xp[k] += h;
                let mut xm = x.clone();
                xm[k] -= h;
                let ep = pb.evaluate(&xp);
                let em = pb.evaluate(&xm);
                let fd = (ep.f - em.f) / (2.0 * h);
                assert!(
                    (fd - ev.grad[k]).abs() < 1e-4 * (1.0 + fd.abs()),
                    "{class:?} objective d/dx{k}: fd {fd} vs ad {}",
                    ev.grad[k]
                );
                for c in 0..ev.cons.len() {
                    let fd = (ep.cons[c] - em.cons[c]) / (2.0 * h);
                    assert!(
                        (fd - ev.cons_grad[c][k]).abs() < 1e-4 * (1.0 + fd.abs()),
                        "{class:?} constraint {c} d/dx{k}: fd {fd} vs ad {}",
                        ev.cons_grad[c][k]
                    );
                }
            }
        }
    }

    /// Guards E_focus's value: asking a 1R candidate for torque sign s at a set of samples
    /// adds exactly W_FOCUS·Σ max(0, a₀ − s·aᵢ)² / N over those samples (aᵢ the torque arm
    /// per unit radius of the contact), and nothing where no sign is asked.
    #[test]
    fn focus_energy_penalizes_only_a_missing_arm_of_the_asked_sign() {
        let (pb, x) = problem(Class::R1);
        let n = pb.poses.len();
        let f0 = pb.evaluate(&x).f;
        let arms: Vec<f64> = pb
            .poses
            .samples
            .iter()
            .map(|pose| {
                let c = model::contact_f64(&x, pose, pb.dx);
                let (p, nn) = (c.p.vals(), c.n.vals());
                (nn[1] * p[0] - nn[0] * p[1]) / (p[0] * p[0] + p[1] * p[1]).sqrt()
            })
            .collect();
        for sign in [1.0, -1.0] {
            // Every third sample asked for `sign`, the others for nothing.
            let focus: Vec<f64> = (0..n)
                .map(|i| if i % 3 == 0 { sign } else { 0.0 })
                .collect();
            let want: f64 = (0..n)
                .filter(|i| i % 3 == 0)
                .map(|i| (ROBUST_ARM - sign * arms[i]).max(0.0).powi(2) * W_FOCUS)
                .sum::<f64>()
                / n as f64;
            let mut fp = pb.clone();
            fp.focus = Some(Arc::new(focus));
            let got = fp.evaluate(&x).f - f0;
            assert!(want > 0.0, "the test design must miss the arm somewhere");
            assert!((got - want).abs() < 1e-9 * (1.0 + want), "{got} vs {want}");
        }
    }

    /// Guards the KS aggregation: it never under-estimates the exact per-sample maximum.
    #[test]
    fn aggregated_constraints_bound_the_exact_maximum() {
        for class in [Class::R1, Class::R3] {
            let (pb, x) = problem(class);
            let ev = pb.evaluate(&x);
            for (a, e) in ev.cons.iter().zip(&ev.cons_exact) {
                assert!(a >= e, "{a} < {e}");
            }
        }
    }
}
