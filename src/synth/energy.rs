//! The candidate problem of one curve pair: objective (paper Eqs. 19–23 plus the class's
//! closure energy and E_vary; for 1R/1R1T our E_robust, E_focus for a 1R candidate of a
//! gap-filling band, and E_push for a chosen 3R contact the margin push solves again) and
//! constraints, with exact gradients by forward-mode AD.
//!
//! Owns the weights, the constraint set and its aggregation, and the evaluation of a design
//! vector (layout in `model::NV`). It does not run the optimizer (see `optimizer`) or pick
//! initial guesses (see `candidate`).
//!
//! **Evaluation.** Every sample i depends on the design only through its *jet*: c², ċ², c̈²
//! (linear in 4 consecutive curve control points, by the basis weights) and θ (linear in 4
//! angle control points). So each sample is evaluated with a 10-slot dual number over its
//! jet, and the chain rule through the basis weights scatters that into the 34-entry
//! gradient. The smoothness term couples sample i with i + 1 only through their unit
//! tangents, which are evaluated once per sample on a 6-slot jet (c², ċ²). E_vary couples two
//! samples half a period apart and uses a full 34-slot dual. (Before, each sample used a
//! 20-slot dual over its local control points and re-evaluated the next sample's tangents:
//! twice the work per sample; see `docs/synthesis.md`.) The per-sample buffers and the
//! spline bases at the sample times are kept per thread between evaluations (`Scratch`).
//!
//! **Scale.** The objective is the paper's sum over samples (E_vary added once, as in the
//! paper) divided by N: the weights keep the paper's ratios, and values of order 1–10 keep
//! SLSQP's first quasi-Newton steps (identity Hessian) sensible.
//!
//! **Stages.** [`Stage::Full`] is the candidate problem above. [`Stage::Align`] is the 3R
//! pre-solve under the tangent cone (see `candidate::align_start`): E_smth plus an alignment
//! term that pulls the curve's tangent into span(p, w), where the conjugate normal lies in
//! the cone; it has no normal, so no E_norm, E_tang, E_plan, E_vary or cone constraint.
//!
//! **Constraints** (all written g ≤ 0): curve length L₁ ≤ Length(c²) ≤ L₂; the height band
//! by bounds on the control points' z (B-spline convex hull); minimum distance of the contact
//! from the follower joint axis (1R/1R1T) or centre (3R) and of c¹ from the driver axis;
//! a tangent-steepness bound that keeps the {N, B} frame regular; for 3R the cone
//! |n·p̂| ≤ sin γ₀ (paper Eq. 30 as printed; cos γ₀ with [`NormalCone::Arm`]). Per-sample
//! constraints are aggregated into one smooth Kreisselmeier–Steinhauser maximum each
//! (KS ≥ max, so KS ≤ 0 implies every sample holds); the acceptance checks use the exact
//! per-sample maxima.

use super::bspline::Basis;
use super::closure::{Class, NormalCone};
use super::dual::Dual;
use super::math::{Scalar, V3};
use super::model::{self, ANGLE_CPS, CURVE_CPS, NV};
use super::pose::PoseTrack;
use std::cell::RefCell;
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

/// Dual width of a sample's jet: c², ċ², c̈² at the sample (slots 0–8) and θ (slot 9).
const DJ: usize = 10;
/// Dual width of a sample's tangent jet (E_smth): c², ċ² (slots 0–5).
const DT: usize = 6;

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
    /// 3R only: where this chosen contact is asked to widen a combination's margin (see
    /// [`Push`]). `None` for an ordinary candidate.
    pub push: Option<Arc<Push>>,
    /// Which objective: the candidate's, or the 3R curve-alignment pre-solve.
    pub stage: Stage,
    /// Room A kept free around the other part's axis, model units (`None`: no bound). With
    /// A, every contact stays within d_x − A of the follower joint axis (1R/1R1T; of the
    /// joint centre for 3R, which bounds the horizontal distance under any rotation) and
    /// |c¹_xy| ≤ d_x − A: the driver curve sweeps a circle of radius |c¹_xy| about its axis
    /// and the follower's material stays within that radius of the follower axis, so each
    /// stays at least A from the other's axis column (hub, shaft). Two more constraints,
    /// "follower reach" and "driver reach", after the others.
    pub axis_room: Option<f64>,
    /// The printed rim the candidate is judged with (`None`: every contact counts). With a
    /// rim, the contacts its own rim cuts at other instants ([`undercut`](super::undercut))
    /// are dropped from the candidate's closure data, so the combination closes with the
    /// contacts the printed parts keep. Not part of the objective.
    pub rim: Option<super::undercut::RimSection>,
}

/// What a chosen 3R contact is asked for where its combination's margin is thin (the
/// search's margin push, ours): at each sample where the contact lies on the facet of the
/// hull of ñ nearest the origin, that facet's outward unit normal u, and the depth `goal`
/// its ñ·u should reach. Moving the facet's contacts out along u moves the facet away from
/// the origin, which is the margin at that sample. The objective gains E_push =
/// `weight`·Σᵢ max(0, g − ñᵢ·uᵢ)² over the samples asked (divided by N like every term).
#[derive(Clone, Debug, PartialEq)]
pub struct Push {
    /// The ñ·u asked for, where asked.
    pub goal: f64,
    /// Weight of E_push.
    pub weight: f64,
    /// Per sample: the facet normal u where the contact is asked, else `None`.
    pub dirs: Vec<Option<[f64; 3]>>,
}

/// The objective a [`PairProblem`] evaluates.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Stage {
    /// The candidate problem (paper energies, closure terms, E_vary).
    #[default]
    Full,
    /// 3R tangent cone, curve only: W_SMTH·E_smth + [`W_ALIGN`]·Σ q with
    /// q = ((T̂² × ŵ)·p̂)² / (|T̂² × ŵ|² + δ²), the squared cosine between the conjugate normal
    /// ±T² × w and the sphere's normal p̂: zero when the tangent lies in span(p, w). The cone
    /// constraint is dropped (the normal angle is not used) and the others are kept.
    Align,
}

/// Weight of the alignment term of [`Stage::Align`]. Default 100: a sample whose conjugate
/// normal is 8° out of the tangent plane (q ≈ 0.019) then costs about 2, against E_smth's
/// ~0.06 per sample (×50) on a fair curve, so alignment leads while E_smth keeps the curve
/// fair.
pub const W_ALIGN: f64 = 100.0;
/// Regularization δ of the alignment term (where T² ∥ w any normal is conjugate). Default 0.05.
pub const ALIGN_REG: f64 = 0.05;

/// Names of the constraints, in evaluation order: the 3R cone only for 3R, the two reach
/// constraints only with [`PairProblem::axis_room`] (see [`PairProblem::constraint_name`]).
pub const CONSTRAINT_NAMES: [&str; 8] = [
    "length ≥ L1",
    "length ≤ L2",
    "follower axis clearance",
    "driver axis clearance",
    "tangent steepness",
    "3R normal cone",
    "follower reach",
    "driver reach",
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

/// The spline bases of one sample: follower curve and normal angle.
struct SampleBasis {
    curve: Basis,
    angle: Basis,
}

/// The buffers of [`PairProblem::evaluate`], one set per thread, reused from one evaluation
/// to the next.
///
/// Why: an evaluation needs about 360 KB of per-sample buffers (N = 360). Allocated and freed
/// on every call, they made glibc's per-thread heaps grow past their trim threshold and give
/// the memory back each time: `strace -c` counted 48 666 `madvise` calls in one
/// `synth half-turn-2to1 --k 3 --dx 6` run (19 with this scratch), and a `--k 4 --dx 6`
/// run spent 3.2 s in the kernel next to 17.2 s of user time, mostly on the page faults
/// that followed. The bases depend only on the sample times, so they are kept until the
/// times change.
#[derive(Default)]
struct Scratch {
    /// Sample times the bases belong to.
    times: Vec<f64>,
    bases: Vec<SampleBasis>,
    /// c², ċ², c̈² per sample.
    curve: Vec<[V3<f64>; 3]>,
    /// Unit tangents t̂², ĉ̇¹ per sample on the tangent jet (E_smth).
    units: Vec<[V3<Dual<DT>>; 2]>,
    /// Follower clearance, driver clearance, tangent steepness, cone, follower reach, driver
    /// reach.
    ks: [Ks; 6],
}

impl Scratch {
    /// Make the bases those of `poses`' sample times.
    fn bases_for(&mut self, poses: &PoseTrack) {
        let same = self.times.len() == poses.len()
            && self
                .times
                .iter()
                .zip(&poses.samples)
                .all(|(t, p)| *t == p.t);
        if same {
            return;
        }
        self.times = poses.samples.iter().map(|p| p.t).collect();
        self.bases = poses
            .samples
            .iter()
            .map(|pose| SampleBasis {
                curve: super::bspline::basis(CURVE_CPS, pose.t),
                angle: super::bspline::basis(ANGLE_CPS, pose.t),
            })
            .collect();
    }
}

thread_local! {
    static SCRATCH: RefCell<Scratch> = RefCell::new(Scratch::default());
}

/// Per-sample constraint values with their jet gradients, aggregated by a KS maximum.
#[derive(Default)]
struct Ks {
    vals: Vec<f64>,
    grads: Vec<[f64; DJ]>,
}

impl Ks {
    /// Empty, keeping the buffers for the next evaluation.
    fn clear(&mut self) {
        self.vals.clear();
        self.grads.clear();
    }
    /// Sample i's value (samples are pushed in order).
    fn push(&mut self, g: Dual<DJ>) {
        self.vals.push(g.v);
        self.grads.push(g.g);
    }
    fn finish(&self, rho: f64, bases: &[SampleBasis]) -> (f64, Vec<f64>, f64) {
        let m = self.vals.iter().cloned().fold(f64::NEG_INFINITY, f64::max);
        let w: Vec<f64> = self.vals.iter().map(|v| (rho * (v - m)).exp()).collect();
        let s: f64 = w.iter().sum();
        let mut grad = vec![0.0; NV];
        for ((wi, g), b) in w.iter().zip(&self.grads).zip(bases) {
            scatter_jet(&mut grad, b, g, wi / s);
        }
        (m + s.ln() / rho, grad, m)
    }
}

/// Add `scale ×` a jet gradient at one sample into the 34-entry gradient, by the chain rule
/// through the sample's basis weights. Slots 3k..3k + 3 hold ∂/∂(k-th derivative of c²)
/// for k = 0, 1 (and 2 in a full jet); a full jet's slot 9 holds ∂/∂θ. Works for both the
/// full jet ([`DJ`]) and the tangent jet ([`DT`]).
fn scatter_jet<const D: usize>(grad: &mut [f64], b: &SampleBasis, g: &[f64; D], scale: f64) {
    let c = &b.curve;
    for r in 0..4 {
        let w = [c.w0[r], c.w1[r], c.w2[r]];
        let j = 3 * c.idx[r];
        for a in 0..3 {
            let d: f64 = (0..D / 3).map(|k| g[3 * k + a] * w[k]).sum();
            grad[j + a] += scale * d;
        }
        if D == DJ {
            grad[3 * CURVE_CPS + b.angle.idx[r]] += scale * g[9] * b.angle.w0[r];
        }
    }
}

/// c², ċ², c̈² at one sample as plain numbers.
fn curve_jet_values(x: &[f64], b: &Basis) -> [V3<f64>; 3] {
    let cp = |j: usize| V3::new(x[3 * j], x[3 * j + 1], x[3 * j + 2]);
    model::curve_at::<f64>(b, &cp)
}

/// Seed a 3-vector as independent variables in slots `first..first + 3`.
fn seed_v3<const D: usize>(v: V3<f64>, first: usize) -> V3<Dual<D>> {
    V3::new(
        Dual::var(v.x, first),
        Dual::var(v.y, first + 1),
        Dual::var(v.z, first + 2),
    )
}

/// Gradient of Σₖ dₖ·uₖ over the slots of u (d constant): the chain rule of |a − b|².
fn dot_grad<const D: usize>(d: [f64; 3], u: &V3<Dual<D>>) -> [f64; D] {
    let mut g = [0.0; D];
    for (k, c) in [u.x, u.y, u.z].iter().enumerate() {
        for (gs, cs) in g.iter_mut().zip(c.g.iter()) {
            *gs += d[k] * cs;
        }
    }
    g
}

fn sq<S: Scalar>(v: V3<S>) -> S {
    v.norm2()
}

/// The alignment term of [`Stage::Align`] at one sample: q = ((T̂² × ŵ)·p̂)² / (|T̂² × ŵ|² +
/// δ²), w = T¹ − T². The conjugate normal is ±T² × w, so q is (up to δ) its squared
/// component along p̂, the quantity the tangent cone bounds by sin²γ₀.
fn misalignment<S: Scalar>(p: V3<S>, t1: V3<S>, t2: V3<S>) -> S {
    let u = t2.unit().cross((t1 - t2).unit());
    let d = u.dot(p.unit());
    d * d / (u.norm2() + S::cst(ALIGN_REG * ALIGN_REG))
}

impl PairProblem {
    /// Number of constraints for this class (and axis room).
    pub fn n_constraints(&self) -> usize {
        let base = if self.class == Class::R3 { 6 } else { 5 };
        base + if self.axis_room.is_some() { 2 } else { 0 }
    }

    /// Name of constraint `i` (an index into [`Evaluation::cons`]).
    pub fn constraint_name(&self, i: usize) -> &'static str {
        let base = if self.class == Class::R3 { 6 } else { 5 };
        if i < base {
            CONSTRAINT_NAMES[i]
        } else {
            CONSTRAINT_NAMES.get(6 + i - base).copied().unwrap_or("?")
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
        SCRATCH.with(|s| self.evaluate_in(x, &mut s.borrow_mut()))
    }

    /// [`Self::evaluate`] with the thread's buffers.
    fn evaluate_in(&self, x: &[f64], scratch: &mut Scratch) -> Evaluation {
        let n = self.poses.len();
        scratch.bases_for(&self.poses);
        let Scratch {
            bases,
            curve,
            units,
            ks: [ks_rf, ks_rd, ks_sl, ks_cone, ks_fr, ks_dr],
            ..
        } = scratch;
        let bases = &bases[..];
        // c², ċ², c̈² at every sample: the values both jets below are seeded with.
        curve.clear();
        curve.extend(bases.iter().map(|b| curve_jet_values(x, &b.curve)));
        let mut f = 0.0;
        let mut grad = vec![0.0; NV];
        // E_smth couples each sample with the next through the unit tangents t̂² = ċ²/|ċ²|
        // and ĉ̇¹: evaluate those once per sample on its tangent jet (c², ċ²).
        units.clear();
        units.extend(
            self.poses
                .samples
                .iter()
                .zip(curve.iter())
                .map(|(pose, c)| {
                    let jet = [seed_v3::<DT>(c[0], 0), seed_v3::<DT>(c[1], 3), V3::zero()];
                    let (_, _, c1d, _, _) = model::tangents(pose, self.dx, jet);
                    [jet[1].unit(), c1d.unit()]
                }),
        );
        for i in 0..n {
            let j = (i + 1) % n;
            let mut e = 0.0;
            let mut gi = [0.0; DT];
            let mut gj = [0.0; DT];
            for (ui, uj) in units[i].iter().zip(&units[j]) {
                let d = V3::<f64>::cst(uj.vals()) - V3::cst(ui.vals());
                e += d.norm2();
                let d = d.vals();
                for (a, b) in gi.iter_mut().zip(dot_grad(d, ui)) {
                    *a -= 2.0 * b;
                }
                for (a, b) in gj.iter_mut().zip(dot_grad(d, uj)) {
                    *a += 2.0 * b;
                }
            }
            f += W_SMTH * e;
            scatter_jet(&mut grad, &bases[i], &gi, W_SMTH);
            scatter_jet(&mut grad, &bases[j], &gj, W_SMTH);
        }
        let mut len = 0.0;
        let mut len_grad = vec![0.0; NV];
        for ks in [
            &mut *ks_rf,
            &mut *ks_rd,
            &mut *ks_sl,
            &mut *ks_cone,
            &mut *ks_fr,
            &mut *ks_dr,
        ] {
            ks.clear();
        }
        let reach = self.axis_room.map(|a| self.dx - a);
        let max_dot = self.cone.max_abs_dot();
        for (i, ((pose, b), c)) in self
            .poses
            .samples
            .iter()
            .zip(bases)
            .zip(curve.iter())
            .enumerate()
        {
            // The sample's jet: everything below depends on the design only through it.
            let jet = [
                seed_v3::<DJ>(c[0], 0),
                seed_v3::<DJ>(c[1], 3),
                seed_v3::<DJ>(c[2], 6),
            ];
            let (p, c1) = match self.stage {
                Stage::Full => {
                    let thf = |g: usize| x[3 * CURVE_CPS + g];
                    let theta = Dual::<DJ>::var(model::angle_at::<f64>(&b.angle, &thf), 9);
                    let c = model::contact(pose, self.dx, jet, theta);
                    let e = self.sample_energy(i, &c);
                    f += e.v;
                    scatter_jet(&mut grad, b, &e.g, 1.0);
                    if self.class == Class::R3 {
                        let d = c.n.dot(c.p) / c.p.norm();
                        ks_cone.push(d * d - max_dot * max_dot);
                    }
                    (c.p, c.c1)
                }
                Stage::Align => {
                    let (p, c1, _, t1, t2) = model::tangents(pose, self.dx, jet);
                    let q = misalignment(p, t1, t2);
                    f += q.v * W_ALIGN;
                    scatter_jet(&mut grad, b, &q.g, W_ALIGN);
                    (p, c1)
                }
            };
            let c2d = jet[1];
            let speed = c2d.norm();
            len += speed.v / n as f64;
            scatter_jet(&mut len_grad, b, &speed.g, 1.0 / n as f64);
            let radius = if self.class == Class::R3 {
                p.norm()
            } else {
                (p.x * p.x + p.y * p.y).sqrt()
            };
            ks_rf.push(-radius + MIN_FOLLOWER_RADIUS);
            let c1xy = (c1.x * c1.x + c1.y * c1.y).sqrt();
            ks_rd.push(-c1xy + MIN_DRIVER_RADIUS);
            if let Some(r) = reach {
                ks_fr.push(radius - r);
                ks_dr.push(c1xy - r);
            }
            let slope = c2d.z / speed;
            ks_sl.push(slope * slope - MAX_TANGENT_SLOPE * MAX_TANGENT_SLOPE);
        }
        if let (Some(iv), true, Stage::Full) = (self.vary, self.class != Class::R1, self.stage) {
            let (v, g) = self.e_vary(x, iv, bases);
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
        let mut cons = Vec::with_capacity(self.n_constraints());
        let mut cons_grad = Vec::with_capacity(self.n_constraints());
        let mut cons_exact = Vec::with_capacity(self.n_constraints());
        let [l1, l2] = LENGTH_BOUNDS;
        cons.push((l1 - len) / l1);
        cons_grad.push(len_grad.iter().map(|g| -g / l1).collect());
        cons_exact.push((l1 - len) / l1);
        cons.push((len - l2) / l2);
        cons_grad.push(len_grad.iter().map(|g| g / l2).collect());
        cons_exact.push((len - l2) / l2);
        let mut agg = |ks: &Ks, rho: f64| {
            let (v, g, m) = ks.finish(rho, bases);
            cons.push(v);
            cons_grad.push(g);
            cons_exact.push(m);
        };
        agg(ks_rf, KS_RHO_LENGTH);
        agg(ks_rd, KS_RHO_LENGTH);
        agg(ks_sl, KS_RHO_UNITLESS);
        match (self.class, self.stage) {
            (Class::R3, Stage::Full) => agg(ks_cone, KS_RHO_UNITLESS),
            // The alignment pre-solve has no normal: its cone constraint holds trivially.
            (Class::R3, Stage::Align) => {
                cons.push(-1.0);
                cons_grad.push(vec![0.0; NV]);
                cons_exact.push(-1.0);
            }
            _ => {}
        }
        if reach.is_some() {
            let mut agg = |ks: &Ks, rho: f64| {
                let (v, g, m) = ks.finish(rho, bases);
                cons.push(v);
                cons_grad.push(g);
                cons_exact.push(m);
            };
            agg(ks_fr, KS_RHO_LENGTH);
            agg(ks_dr, KS_RHO_LENGTH);
        }
        Evaluation {
            f,
            grad,
            cons,
            cons_grad,
            cons_exact,
        }
    }

    /// The candidate objective's terms at sample `i` (before the division by N): the paper's
    /// E_norm, E_tang, E_plan and, for 1R/1R1T, E_closure, E_robust and E_focus.
    fn sample_energy(&self, i: usize, c: &model::Contact<Dual<DJ>>) -> Dual<DJ> {
        let t1h = c.t1.unit();
        let t2h = c.t2.unit();
        let e_norm = {
            let d = c.n.dot(t1h);
            d * d
        };
        let e_tang = sq(t1h - t2h);
        let e_plan = sq(c.n - c.kappa);
        let mut e = e_norm * W_NORM + e_tang * W_TANG + e_plan * W_PLAN;
        if matches!(self.class, Class::R1 | Class::R1T1) {
            let pxy = (c.p.x * c.p.x + c.p.y * c.p.y).sqrt();
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
        if let Some((goal, weight, u)) = self
            .push
            .as_ref()
            .and_then(|p| p.dirs[i].map(|u| (p.goal, p.weight, u)))
        {
            let nt = self.ntilde(c);
            let d = -(nt.x * u[0] + nt.y * u[1] + nt.z * u[2]) + goal;
            if d.v > 0.0 {
                e += d * d * weight;
            }
        }
        e
    }

    /// E_vary = ñ(t_v)·ñ(t_v + ½) with its gradient (full 34-slot dual).
    /// `bases` are those of the sample times (see [`Scratch`]).
    fn e_vary(&self, x: &[f64], iv: usize, bases: &[SampleBasis]) -> (f64, Vec<f64>) {
        let n = self.poses.len();
        let cp = |g: usize| seed_v3::<NV>(V3::new(x[3 * g], x[3 * g + 1], x[3 * g + 2]), 3 * g);
        let th = |g: usize| Dual::<NV>::var(x[3 * CURVE_CPS + g], 3 * CURVE_CPS + g);
        let at = |i: usize| {
            let (pose, b) = (&self.poses.samples[i % n], &bases[i % n]);
            let c = model::contact(
                pose,
                self.dx,
                model::curve_at(&b.curve, &cp),
                model::angle_at(&b.angle, &th),
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
    use crate::synth::math::{UnitQuaternion, Vector3};
    use crate::synth::pose::{pose_1r, Pose, PoseFn, PoseTrack};

    fn problem(class: Class) -> (PairProblem, Vec<f64>) {
        let at: PoseFn = match class {
            Class::R3 => Arc::new(|t: f64| {
                let a = std::f64::consts::TAU * t;
                let q = UnitQuaternion::from_euler_angles(0.3 * a.sin(), 0.2 * a.cos(), a);
                let w = Vector3::new(0.3, -0.1, 1.0) * std::f64::consts::TAU;
                Pose::new(t, &q, Vector3::zeros(), w, Vector3::zeros())
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
                push: None,
                stage: Stage::Full,
                axis_room: None,
                rim: None,
            },
            x,
        )
    }

    /// [`problem`] with an axis room that makes both reach constraints matter (d_x − A = 3
    /// against follower radii about 2.5 and driver radii about 3.5).
    fn reaching(class: Class) -> (PairProblem, Vec<f64>) {
        let (mut pb, x) = problem(class);
        pb.axis_room = Some(3.0);
        (pb, x)
    }

    /// Guards the reach constraints' values and names: with an axis room A they are the
    /// largest |c²| radial distance (1R: from the axis, 3R: from the centre) and |c¹_xy|
    /// over the samples minus d_x − A, come after the others, and are absent without A (the
    /// other constraints unchanged).
    #[test]
    fn reach_constraints_bound_both_curves_by_dx_minus_the_axis_room() {
        for class in [Class::R1, Class::R3] {
            let (plain, x) = problem(class);
            let (pb, _) = reaching(class);
            let (e0, e) = (plain.evaluate(&x), pb.evaluate(&x));
            assert_eq!(e.cons.len(), plain.n_constraints() + 2);
            assert_eq!(pb.n_constraints(), e.cons.len());
            assert_eq!(e.cons[..e0.cons.len()], e0.cons[..]);
            let (mut rf, mut rd) = (f64::MIN, f64::MIN);
            for pose in &pb.poses.samples {
                let c = model::contact_f64(&x, pose, pb.dx);
                let p = c.p.vals();
                let r = if class == Class::R3 {
                    (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt()
                } else {
                    p[0].hypot(p[1])
                };
                rf = rf.max(r);
                let c1 = c.c1.vals();
                rd = rd.max(c1[0].hypot(c1[1]));
            }
            let n = e.cons.len();
            let bound = pb.dx - 3.0;
            assert!(
                (e.cons_exact[n - 2] - (rf - bound)).abs() < 1e-9,
                "{class:?}"
            );
            assert!(
                (e.cons_exact[n - 1] - (rd - bound)).abs() < 1e-9,
                "{class:?}"
            );
            assert!(
                e.cons_exact[n - 1] > 0.0,
                "the test design must reach too far"
            );
            assert_eq!(pb.constraint_name(n - 2), "follower reach");
            assert_eq!(pb.constraint_name(n - 1), "driver reach");
            assert_eq!(plain.constraint_name(4), "tangent steepness");
        }
    }

    /// Guards the per-thread buffers of `evaluate`: problems of other classes, sample counts
    /// and sample times, evaluated one after another on one thread, give bit for bit what a
    /// fresh set of buffers gives, so nothing of one evaluation (bases, jets, per-sample
    /// constraint values) leaks into the next.
    #[test]
    fn reused_buffers_give_the_same_evaluation_as_fresh_ones() {
        let (r3, x3) = problem(Class::R3);
        let (mut r1, x1) = problem(Class::R1);
        r1.poses = Arc::new(PoseTrack::from_fn(50, r1.poses.at.clone()));
        // Same count as `r3` (36) but times shifted by half a step: bases must be rebuilt.
        let mut shifted = r3.clone();
        let at = r3.poses.at.clone();
        shifted.poses = Arc::new(PoseTrack {
            samples: (0..36).map(|i| at((i as f64 + 0.5) / 36.0)).collect(),
            at,
        });
        let (reach3, _) = reaching(Class::R3);
        let cases = [
            (&r3, &x3),
            (&r1, &x1),
            (&reach3, &x3),
            (&shifted, &x3),
            (&r3, &x3),
            (&r1, &x1),
        ];
        for (k, (pb, x)) in cases.into_iter().enumerate() {
            let got = pb.evaluate(x);
            let want = pb.evaluate_in(x, &mut Scratch::default());
            assert_eq!(got.f.to_bits(), want.f.to_bits(), "case {k}: objective");
            assert_eq!(got.grad, want.grad, "case {k}: gradient");
            assert_eq!(got.cons, want.cons, "case {k}: constraints");
            assert_eq!(
                got.cons_grad, want.cons_grad,
                "case {k}: constraint gradients"
            );
            assert_eq!(
                got.cons_exact, want.cons_exact,
                "case {k}: exact constraints"
            );
        }
        let shifted_eval = shifted.evaluate(&x3);
        assert_ne!(
            shifted_eval.f,
            r3.evaluate(&x3).f,
            "the shifted times must change the evaluation, or this test proves nothing"
        );
    }

    /// Guards the analytic (forward-mode) gradients of the objective and of every constraint
    /// against central finite differences, for all three classes, for a 1R gap-filling
    /// candidate (E_focus) and for a pushed 3R candidate (E_push).
    #[test]
    fn energy_gradients_match_finite_differences() {
        let focused = || {
            let (mut pb, x) = problem(Class::R1);
            let n = pb.poses.len();
            // Ask for both signs, so that the term is active at some samples either way.
            pb.focus = Some(Arc::new((0..n).map(|i| [1.0, 0.0, -1.0][i % 3]).collect()));
            (pb, x)
        };
        let aligning = || {
            let (mut pb, x) = problem(Class::R3);
            pb.stage = Stage::Align;
            (pb, x)
        };
        let pushed = || {
            let (mut pb, x) = problem(Class::R3);
            let n = pb.poses.len();
            // Directions that turn with the samples, asked at two samples of three, with a
            // goal ñ·u cannot reach everywhere, so that the term is active somewhere.
            let dirs = (0..n)
                .map(|i| {
                    let a = i as f64 * 0.7;
                    (i % 3 != 0).then(|| [a.cos() * 0.6, a.sin() * 0.6, 0.8])
                })
                .collect();
            pb.push = Some(Arc::new(Push {
                goal: 0.5,
                weight: 50.0,
                dirs,
            }));
            (pb, x)
        };
        let problems = [Class::R1, Class::R1T1, Class::R3]
            .map(problem)
            .into_iter()
            .chain([focused(), aligning(), pushed()])
            .chain([Class::R1, Class::R3].map(reaching));
        for (pb, x) in problems {
            let class = (pb.class, pb.stage);
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
                crate::synth::closure::torque_arm(c.p.vals(), c.n.vals())
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

    /// Guards E_push's value: asking a 3R contact to reach ñ·uᵢ ≥ g at a set of samples adds
    /// exactly w·Σ max(0, g − ñᵢ·uᵢ)² / N over those samples, and nothing elsewhere
    /// or where ñ·u already reaches g.
    #[test]
    fn push_energy_penalizes_only_a_short_reach_where_asked() {
        let (pb, x) = problem(Class::R3);
        let n = pb.poses.len();
        let f0 = pb.evaluate(&x).f;
        let nt: Vec<[f64; 3]> = pb
            .poses
            .samples
            .iter()
            .map(|pose| {
                let c = model::contact_f64(&x, pose, pb.dx);
                crate::synth::closure::project(Class::R3, c.p.vals(), c.n.vals()).unwrap()
            })
            .collect();
        let dot = |a: [f64; 3], b: [f64; 3]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
        // At every other sample: u = ñ itself (reached: ñ·u = 1 ≥ g) at even ones of those,
        // and a direction across ñ at the others.
        let dirs: Vec<Option<[f64; 3]>> = (0..n)
            .map(|i| match i % 4 {
                0 => Some(nt[i]),
                2 => {
                    let v = nt[i];
                    let l = (v[0] * v[0] + v[1] * v[1]).sqrt().max(1e-9);
                    Some([-v[1] / l, v[0] / l, 0.0])
                }
                _ => None,
            })
            .collect();
        let (goal, weight) = (0.3, 700.0);
        let want: f64 = dirs
            .iter()
            .zip(&nt)
            .filter_map(|(u, v)| u.map(|u| (goal - dot(*v, u)).max(0.0).powi(2) * weight))
            .sum::<f64>()
            / n as f64;
        let mut pp = pb.clone();
        pp.push = Some(Arc::new(Push { goal, weight, dirs }));
        let got = pp.evaluate(&x).f - f0;
        assert!(want > 0.0, "the test design must fall short somewhere");
        assert!((got - want).abs() < 1e-9 * (1.0 + want), "{got} vs {want}");
    }

    /// Guards the KS aggregation: it never under-estimates the exact per-sample maximum.
    #[test]
    fn aggregated_constraints_bound_the_exact_maximum() {
        for (pb, x) in [Class::R1, Class::R3]
            .map(problem)
            .into_iter()
            .chain([Class::R1, Class::R3].map(reaching))
        {
            let ev = pb.evaluate(&x);
            for (a, e) in ev.cons.iter().zip(&ev.cons_exact) {
                assert!(a >= e, "{a} < {e}");
            }
        }
    }
}
