//! Stage A: candidate curve pairs for one height band (paper §5.2.3, supplementary notes).
//!
//! Owns the initial guesses (circle-like curves with seeded variations of phase,
//! eccentricity, waviness and height, and a start normal that is feasible for the class),
//! one SLSQP solve per candidate, and the post-solve checks that decide whether a candidate
//! may enter the combination: exact feasibility and a conjugation residual within
//! [`MAX_RESIDUAL_DEG`] at [`OVERSAMPLE`]× the sample density. It does not combine
//! candidates (see `ga`).
//!
//! **Initial guess.** For 1R and 1R1T we pick a contact path in frame R near the driver
//! (azimuth ψ₀ ∈ ±50°, radius r₀ varying with waviness in radius and height) and pull it
//! back into the follower frame, c² = R₂ᵀ(p − T₂): for a follower that turns, the contact
//! then stays between the two axes as in a gear pair. For 3R under the tangent cone (the
//! default) the path is a loop around a seeded follower-local centre, traversed twice, lying
//! in the plane span(p, w) that a conjugate normal inside the 10° cone leaves for the
//! tangent (`R3Loop`); under the `arm` cone, which does not pin the tangent, it is a
//! circle-like curve directly in follower coordinates; under the tangent cone a curve-only
//! pre-solve ([`align_start`]) then pulls the loop's tangent into that plane where it strays
//! and sets the start normal again on the moved curve. Control points come from a linear
//! least-squares fit to the path, rescaled (radially, or the loop size) so the length is
//! mid-way between L₁ and L₂. The start normal is the circumferential direction ±ẑ×p̂ made
//! perpendicular to T² (1R, 1R1T; the sign alternates between candidates so every band gets
//! both torque directions); for 3R the conjugate direction ±p̂ × w turned into the cone where
//! it leaves it (`r3_start_normal`, tangent cone) or T̂² × p̂ (arm cone). The exact
//! conjugate normal T² × T¹ of a curve not made for the cone violates it, and SLSQP diverged
//! from it in a prototype.

use std::f64::consts::TAU;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::bspline;
use super::closure::{self, Class};
use super::energy::{PairProblem, Stage, LENGTH_BOUNDS};
use super::math::{DMatrix, DVector, V3};
use super::model::{self, ANGLE_CPS, CURVE_CPS, NV};
use super::optimizer::{Minimizer, SolveStatus};
use super::undercut;

/// Largest accepted conjugation residual, degrees. Default 1° (conventions: acceptance).
pub const MAX_RESIDUAL_DEG: f64 = 1.0;
/// Oversampling factor of the residual and closure checks. Default 4 (conventions).
pub const OVERSAMPLE: usize = 4;
/// Why a candidate whose solve returned non-finite numbers is not usable.
pub const NAN_REASON: &str = "optimizer returned NaN";
/// Constraint violation tolerated in the feasibility check, in the constraints' own units
/// (relative length, model units, squared sines). Default 1e-6.
pub const FEAS_TOL: f64 = 1e-6;

/// A solved candidate with what the combination needs.
#[derive(Clone, Debug)]
pub struct Candidate {
    /// Band index k.
    pub band: usize,
    /// The band's [z_min, z_max].
    pub slab: [f64; 2],
    /// Candidate index within the band.
    pub index: usize,
    /// Design vector.
    pub x: Vec<f64>,
    /// Objective value.
    pub f: f64,
    /// Solver status.
    pub status: SolveStatus,
    /// Passed feasibility and residual checks.
    pub valid: bool,
    /// Why it is not valid.
    pub reason: Option<String>,
    /// Worst conjugation residual at OVERSAMPLE× density, degrees.
    pub residual_deg: f64,
    /// Per instant at [`OVERSAMPLE`]× the sample density (entry `OVERSAMPLE·i` is sample
    /// i): ñ (zero-padded), or None when it vanishes. Empty for a candidate that is not
    /// usable.
    pub ntilde: Vec<Option<[f64; 3]>>,
    /// Per instant as `ntilde`: whether the contact counts for the robust closure (3R: for
    /// the cone the search uses).
    pub robust: Vec<bool>,
    /// Objective evaluations used.
    pub evals: usize,
    /// The sample index of its E_vary (3R, 1R1T), kept so that a candidate solved again
    /// from this one (the 3R margin push) has the same objective.
    pub vary: Option<usize>,
}

/// Signed normalized ẑ×p̂ circumferential direction made perpendicular to t (t × p where
/// the two are parallel).
fn circumferential_normal(p: V3<f64>, t: V3<f64>, sign: f64) -> V3<f64> {
    let c = V3::new(-p.y, p.x, 0.0);
    let tl = t.norm().max(1e-12);
    let th = V3::new(t.x / tl, t.y / tl, t.z / tl);
    let mut n = c - th.scalec(c.dot(th));
    let mut l = n.norm();
    if l < 1e-9 {
        n = th.cross(p);
        l = n.norm().max(1e-12);
    }
    V3::new(sign * n.x / l, sign * n.y / l, sign * n.z / l)
}

/// Least-squares fit of closed-spline control points to samples at tᵢ = i/N (per column).
fn fit_spline(n_cps: usize, values: &[Vec<f64>]) -> Vec<Vec<f64>> {
    let n = values.len();
    let dim = values[0].len();
    let mut a = DMatrix::<f64>::zeros(n, n_cps);
    for i in 0..n {
        let b = bspline::basis(n_cps, i as f64 / n as f64);
        for r in 0..4 {
            a[(i, b.idx[r])] += b.w0[r];
        }
    }
    let ata = a.transpose() * &a;
    let chol = ata
        .cholesky()
        .expect("uniform B-spline normal matrix is SPD for N ≥ n");
    let mut out = vec![vec![0.0; dim]; n_cps];
    for d in 0..dim {
        let y = DVector::from_iterator(n, values.iter().map(|v| v[d]));
        let s = chol.solve(&(a.transpose() * y));
        for j in 0..n_cps {
            out[j][d] = s[j];
        }
    }
    out
}

/// Length of the follower curve of a design (mean speed over N samples).
fn curve_length(x: &[f64], n: usize) -> f64 {
    let cps = model::curve_cps(x);
    (0..n)
        .map(|i| V3::from(bspline::eval_point(&cps, i as f64 / n as f64)[1]).norm())
        .sum::<f64>()
        / n as f64
}

/// Range of the horizontal distance of a 3R loop's centre from the follower z axis, model
/// units. Default 1.5–2.8: the loop (half-length up to ~2) then stays clear of the joint
/// centre ([`super::energy::MIN_FOLLOWER_RADIUS`]) in most directions, and curves of length
/// 4π–6π live at radius ~2–3 anyway.
pub const R3_CENTRE_RADIUS: [f64; 2] = [1.5, 2.8];
/// Range of the ratio of a 3R loop's minor to major semi-axis. Default 0.2–0.6: thin loops
/// keep the tangent near the plane the cone allows; the minor axis is further capped so the
/// loop stays inside its band.
pub const R3_LOOP_MINOR: [f64; 2] = [0.2, 0.6];

/// Largest |t̂.z| of a 3R start loop's turning points. Default sin 45°: well inside
/// `energy::MAX_TANGENT_SLOPE` (sin 60°), so the {N, B} frame and the start normal's angle
/// stay smooth there.
pub const R3_START_SLOPE: f64 = std::f64::consts::FRAC_1_SQRT_2;

/// Loops of a 3R start curve per period. Default 2: the normal's angle θ (10 control
/// points) turns with the tangent once per loop and must follow it; with 2 or 3 loops
/// (drawn at random) figure-eight's band 3 gave 5 of 30 usable candidates, with 2 always 8.
pub const R3_LOOP_TURNS: f64 = 2.0;

/// The 3R start curve: a loop around a fixed follower-local centre c₀, traversed
/// [`R3_LOOP_TURNS`] times.
///
/// With the tangent cone (the default, paper Eq. 30 as printed), a conjugate normal is
/// perpendicular to p, to T² and to the relative velocity w of the follower's material point
/// against the driver's (w = T¹ − T²), so the curve's tangent T² must lie (within the cone)
/// in the plane span(p, w), and ñ = p × n is pinned to ±w⊥p. A circle about the follower's z
/// axis meets that only in the central band (the outer bands then failed), and its contact
/// sweeps every azimuth, so ñ turns with it. The loop instead keeps the contact near c₀, where
/// ±w⊥p has a definite direction (with z and x parts where c₀ has both y and z parts), and
/// lies in span(ĉ₀, w⊥) pulled back into the follower frame, averaged over the period: its
/// major axis h is the horizontal line of that plane (the band is thin), its minor axis v the
/// in-plane perpendicular, turned down to [`R3_START_SLOPE`] and capped in length by the
/// band. Axes that follow the plane sample by sample turn with the follower, and that turning
/// cancelled the loop's horizontal motion at some turning points (vertical tangents in 27 of
/// 30 starts of figure-eight's band 3). Seeded centres over all azimuths give the GA ñ that
/// positively span R³.
struct R3Loop {
    centre: [f64; 3],
    /// Major-axis direction (follower-local, horizontal).
    h: [f64; 3],
    /// Minor-axis direction (follower-local).
    v: [f64; 3],
    minor: f64,
    half_band: f64,
}

/// Turn v within the vertical plane perpendicular to the horizontal h until |v.z| is at most
/// [`R3_START_SLOPE`].
fn cap_slope(v: V3<f64>, h: V3<f64>) -> V3<f64> {
    if v.z.abs() <= R3_START_SLOPE {
        return v;
    }
    let ez = V3::<f64>::cst([0.0, 0.0, 1.0]);
    let g = ez.cross(h).unit();
    let sg = if v.dot(g) < 0.0 { -1.0 } else { 1.0 };
    g.scalec(sg * (1.0 - R3_START_SLOPE * R3_START_SLOPE).sqrt())
        + ez.scalec(R3_START_SLOPE * v.z.signum())
}

impl R3Loop {
    fn new(pb: &PairProblem, centre: [f64; 3], minor: f64, half_band: f64) -> Self {
        let c0 = V3::<f64>::cst(centre);
        let ep = c0.unit();
        let mut prev: Option<(V3<f64>, V3<f64>)> = None;
        let (mut hs, mut vs) = (V3::<f64>::cst([0.0; 3]), V3::<f64>::cst([0.0; 3]));
        for pose in &pb.poses.samples {
            let p = c0.rot(&pose.rot);
            let w =
                V3::<f64>::cst(pose.omega).cross(p) - V3::new(-p.y, p.x - pb.dx, 0.0).scalec(TAU);
            let ew = (w - p.scalec(w.dot(p) / p.norm2())).rot_t(&pose.rot).unit();
            let nrm = ep.cross(ew);
            let zin = ep.scalec(ep.z) + ew.scalec(ew.z);
            let mut h = if zin.norm() < 1e-3 {
                ew
            } else {
                zin.cross(nrm).unit()
            };
            let mut v = cap_slope(nrm.cross(h), h);
            if let Some((ph, pv)) = prev {
                if h.dot(ph) < 0.0 {
                    h = -h;
                }
                if v.dot(pv) < 0.0 {
                    v = -v;
                }
            }
            prev = Some((h, v));
            hs = hs + h;
            vs = vs + v;
        }
        let h = V3::new(hs.x, hs.y, 0.0).unit();
        let v = cap_slope((vs - h.scalec(vs.dot(h))).unit(), h);
        Self {
            centre,
            h: h.vals(),
            v: v.vals(),
            minor,
            half_band,
        }
    }

    /// Loop point with semi-major axis `a` at loop angle `w`.
    fn at(&self, a: f64, w: f64) -> Vec<f64> {
        let (h, v) = (self.h, self.v);
        let b = (self.minor * a).min(0.8 * self.half_band / v[2].abs().max(1e-9));
        (0..3)
            .map(|d| self.centre[d] + a * w.cos() * h[d] + b * w.sin() * v[d])
            .collect()
    }
}

/// Fraction of the cone's bound |n·p̂| ≤ s that a 3R start normal may use. Default 0.8:
/// the start is strictly inside the cone, so SLSQP begins feasible there.
pub const R3_START_CONE_FRACTION: f64 = 0.8;

/// 3R start normal: the conjugate direction ±p̂ × w (w = T¹ − T², perpendicular to p, to w
/// and, when the curve's tangent lies in span(p, w), to T²) taken into the normal plane of
/// T² (where the model's normals live) and, if that leaves the cone, turned within that plane
/// towards T̂² × p̂ until |n·p̂| = [`R3_START_CONE_FRACTION`]·s.
fn r3_start_normal(c: &model::Contact<f64>, sign: f64, s: f64) -> V3<f64> {
    let t = c.t2.unit();
    let ph = c.p.unit();
    let want = ph.cross((c.t1 - c.t2).unit()).scalec(sign);
    let want = want - t.scalec(want.dot(t));
    let mut u = t.cross(ph);
    if u.norm() < 1e-9 || want.norm() < 1e-9 {
        return if u.norm() < 1e-9 {
            want.unit()
        } else {
            u.unit().scalec(sign)
        };
    }
    u = u.unit();
    if want.dot(u) < 0.0 {
        u = -u;
    }
    let q = t.cross(u);
    let phi = want.dot(q).atan2(want.dot(u));
    let lim = (R3_START_CONE_FRACTION * s / q.dot(ph).abs().max(1e-12))
        .min(1.0)
        .asin();
    let phi = phi.clamp(-lim, lim);
    u.scalec(phi.cos()) + q.scalec(phi.sin())
}

/// Overall sign of candidate `index`'s start normal: + for even, − for odd indices, so every
/// band offers both torque directions (1R, 1R1T) and both signs of ñ (3R). The initial guess
/// and the 3R pre-solve, which sets the normal again, must agree on it.
fn normal_sign(index: usize) -> f64 {
    if index % 2 == 0 {
        1.0
    } else {
        -1.0
    }
}

/// Build the initial design of candidate `index` in band `band`.
pub fn initial_guess(pb: &PairProblem, seed: u64, band: usize, index: usize) -> Vec<f64> {
    let mut rng = ChaCha8Rng::seed_from_u64(
        seed ^ (band as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15)
            ^ (index as u64 + 1).wrapping_mul(0xD1B5_4A32_D192_ED03),
    );
    let poses = &pb.poses.samples;
    let n = poses.len();
    let (zlo, zhi) = pb.band;
    let zc = 0.5 * (zlo + zhi);
    let zh = 0.5 * (zhi - zlo);
    let psi0 =
        rng.random_range(15f64..55.0).to_radians() * if rng.random_bool(0.5) { 1.0 } else { -1.0 };
    // Tube winding: the contact circles a torus-like tube m times per period, so (ṙ, ż)
    // never vanish together and a normal with a steady circumferential part exists.
    let m_wind = rng.random_range(2..=3) as f64;
    let tube_r = rng.random_range(0.15..0.45);
    let tube_z = rng.random_range(0.5..0.9) * zh;
    let wind_dir = if rng.random_bool(0.5) { 1.0 } else { -1.0 };
    let ph1 = rng.random_range(0.0..TAU);
    let ecc = rng.random_range(0.0..0.15);
    let wob = rng.random_range(0.0..0.25);
    let sign = normal_sign(index);
    // 3R under the tangent cone: a loop around a follower-local centre, in the plane the
    // cone allows (drawn after the common parameters, so 1R/1R1T and 3R with the arm cone
    // keep their guesses).
    let r3 = (pb.class == Class::R3 && pb.cone == closure::NormalCone::Tangent).then(|| {
        let az0 = rng.random_range(0.0..TAU);
        let rho0 = rng.random_range(R3_CENTRE_RADIUS[0]..R3_CENTRE_RADIUS[1]);
        let minor = rng.random_range(R3_LOOP_MINOR[0]..R3_LOOP_MINOR[1]);
        R3Loop::new(pb, [rho0 * az0.cos(), rho0 * az0.sin(), zc], minor, zh)
    });
    let path = |scale: f64| -> Vec<Vec<f64>> {
        if let Some(l) = &r3 {
            return (0..n)
                .map(|i| l.at(scale, R3_LOOP_TURNS * TAU * i as f64 / n as f64 + ph1))
                .collect();
        }
        (0..n)
            .map(|i| {
                let t = i as f64 / n as f64;
                let pose = &poses[i];
                let w = m_wind * TAU * t + ph1;
                let r = scale * (1.0 + ecc * (TAU * t + ph1).cos()) + tube_r * scale * w.cos();
                let z = zc + wind_dir * tube_z * w.sin();
                match pb.class {
                    Class::R3 => {
                        let a = TAU * t + psi0;
                        let rr = r * (1.0 + wob * (3.0 * TAU * t).sin());
                        vec![rr * a.cos(), rr * a.sin(), z]
                    }
                    _ => {
                        let a = psi0 + wob * (TAU * t + ph1).cos();
                        let p = [r * a.cos(), r * a.sin(), 0.0];
                        // c² = R₂ᵀ p (rotation about z only for these classes), local z = z.
                        let q = V3::<f64>::cst(p).rot_t(&pose.rot);
                        vec![q.x, q.y, z]
                    }
                }
            })
            .collect()
    };
    let target_len = 0.5 * (LENGTH_BOUNDS[0] + LENGTH_BOUNDS[1]);
    let mut scale = if r3.is_some() { 1.0 } else { 2.0 };
    let mut x = vec![0.0; NV];
    for _ in 0..4 {
        let cps = fit_spline(CURVE_CPS, &path(scale));
        for (j, c) in cps.iter().enumerate() {
            x[3 * j] = c[0];
            x[3 * j + 1] = c[1];
            x[3 * j + 2] = c[2].clamp(zlo, zhi);
        }
        let len = curve_length(&x, n);
        if len > 1e-9 {
            scale *= (target_len / len).clamp(0.3, 3.0);
        }
    }
    start_angles(pb, &mut x, sign, r3.is_some());
    x
}

/// Set the normal-angle control points of `x` from the start normal of its curve (see
/// [`initial_guess`]); `r3_loop`: the tangent-cone start normal of a 3R loop.
fn start_angles(pb: &PairProblem, x: &mut [f64], sign: f64, r3_loop: bool) {
    let poses = &pb.poses.samples;
    let n = poses.len();
    // Start normals: for 1R/1R1T the exact conjugate normal ±T² × T¹ (continuous sign,
    // overall sign chosen so that the mean torque has the candidate's sign); where T¹ ∥ T²
    // the previous normal is kept (projected). For 3R, `r3_start_normal` (tangent cone) or
    // T̂² × p̂ (arm cone), both inside the cone.
    let contacts: Vec<_> = poses
        .iter()
        .map(|pose| model::contact_f64(x, pose, pb.dx))
        .collect();
    let wants: Vec<V3<f64>> = match pb.class {
        Class::R3 if r3_loop => contacts
            .iter()
            .map(|c| r3_start_normal(c, sign, pb.cone.max_abs_dot()))
            .collect(),
        Class::R3 => contacts
            .iter()
            .map(|c| {
                let v = c.t2.unit().cross(c.p.unit());
                let l = v.norm().max(1e-12);
                v.scalec(sign / l)
            })
            .collect(),
        _ => {
            let mut out: Vec<V3<f64>> = Vec::with_capacity(n);
            let mut prev: Option<V3<f64>> = None;
            for c in &contacts {
                let t2 = c.t2.unit();
                let cr = t2.cross(c.t1.unit());
                let mut v = if cr.norm() > 0.05 {
                    cr.unit()
                } else if let Some(pv) = prev {
                    (pv - t2.scale(pv.dot(t2))).unit()
                } else {
                    circumferential_normal(c.p, c.t2, 1.0)
                };
                if let Some(pv) = prev {
                    if v.dot(pv) < 0.0 {
                        v = -v;
                    }
                }
                prev = Some(v);
                out.push(v);
            }
            let torque: f64 = out
                .iter()
                .zip(&contacts)
                .map(|(v, c)| c.p.cross(*v).z)
                .sum();
            let flip = if torque * sign < 0.0 { -1.0 } else { 1.0 };
            out.iter().map(|v| v.scalec(flip)).collect()
        }
    };
    let mut thetas = Vec::with_capacity(n);
    let mut prev: Option<f64> = None;
    for ((pose, c), &want) in poses.iter().zip(&contacts).zip(&wants) {
        // Express in the local frame: θ = atan2(n·B, n·N) with N, B rotated into R.
        let th0 = model::contact_f64(
            &{
                let mut y = x.to_vec();
                for v in y[3 * CURVE_CPS..].iter_mut() {
                    *v = 0.0;
                }
                y
            },
            pose,
            pb.dx,
        );
        let nn = th0.n; // θ = 0 → N
        let bb = c.t2.unit().cross(nn);
        let dn = want.dot(nn);
        let db = want.dot(bb);
        let mut a = db.atan2(dn);
        if let Some(pv) = prev {
            while a - pv > std::f64::consts::PI {
                a -= TAU;
            }
            while a - pv < -std::f64::consts::PI {
                a += TAU;
            }
        }
        prev = Some(a);
        thetas.push(vec![a]);
    }
    // A closed spline cannot follow a net 2π winding; remove the linear drift if any.
    let drift = {
        let first = thetas[0][0];
        let last = thetas[n - 1][0];
        ((last - first) / TAU).round() * TAU
    };
    if drift != 0.0 {
        for (i, v) in thetas.iter_mut().enumerate() {
            v[0] -= drift * i as f64 / n as f64;
        }
    }
    let th = fit_spline(ANGLE_CPS, &thetas);
    for j in 0..ANGLE_CPS {
        x[3 * CURVE_CPS + j] = th[j][0].clamp(-super::energy::THETA_BOX, super::energy::THETA_BOX);
    }
}

/// Largest number of objective evaluations of the 3R alignment pre-solve
/// ([`align_start`]). Default 200. Measured on pick-and-place (K = 7, d_x = 7.5, seed 1):
/// 60 and 120 left too few usable candidates in the outer bands (E_valiTime 0.81 and 0.98),
/// 200 closed it (−0.050), 400 did not (0.95) and took a quarter longer; the alignment's
/// median misalignment is about 1° after 150–180 evaluations.
pub const ALIGN_MAX_EVAL: usize = 200;

/// Evaluation cap of a 3R tangent-cone candidate's solve after [`align_start`], as a
/// multiple of the usual cap (`optimizer::MAX_EVAL`, or `SynthOptions::max_eval`). Default
/// 1.75 (700 evaluations). The aligned start's normal is often still outside the cone (its
/// θ spline cannot follow the conjugate normal everywhere), and SLSQP needs more steps to
/// bring it in: with 400, 115–132 of a K = 7 pick-and-place run's rejections were "cone
/// violated" at the cap, and the example closed at seeds 1, 2, 3 and 5 only; with 700 it
/// closed at all five, at d_x = 6. At K = 7, d_x = 6, seeds 1 and 4: 550 closed seed 1 only
/// (28 s each), 700 both (33 s), 1000 both (36–42 s). (Before the pre-solve, 1000
/// evaluations did not help.)
pub const R3_TANGENT_EVAL_SCALE: f64 = 1.75;

/// 3R under the tangent cone: move the start curve `x0` so its tangent lies in span(p, w)
/// (`energy::Stage::Align`, the curve only), then set the start normal again on the moved
/// curve. Returns the new start and the evaluations used.
///
/// Why: the start loop lies in that plane only on average over the period, and where it
/// leaves it the conjugate normal ±T² × w leaves the cone; SLSQP then had to bend the curve
/// and turn the normal at once, and in pick-and-place's outer bands most candidates ended
/// 10–78° from conjugate (see `docs/synthesis.md`, "Candidates"). A result
/// that is not finite is dropped and the loop is kept.
pub fn align_start(
    pb: &PairProblem,
    minimizer: &dyn Minimizer,
    x0: &[f64],
    sign: f64,
) -> (Vec<f64>, usize) {
    let pa = PairProblem {
        stage: Stage::Align,
        ..pb.clone()
    };
    let ra = minimizer.minimize(&pa, x0, ALIGN_MAX_EVAL);
    if !ra.x.iter().all(|v| v.is_finite()) {
        return (x0.to_vec(), ra.evals);
    }
    let mut x = ra.x;
    start_angles(pb, &mut x, sign, true);
    (x, ra.evals)
}

/// A design at [`OVERSAMPLE`]× the sample density: its worst conjugation residual (degrees)
/// and, per instant, ñ and whether the contact counts for the robust closure. For 3R the
/// combination counts the contacts that the chosen cone allows (all of them, since it is a
/// hard constraint); the file still reports the conventions' robust figure (see
/// `search::assemble`).
fn oversampled(pb: &PairProblem, x: &[f64]) -> (f64, Vec<Option<[f64; 3]>>, Vec<bool>) {
    let m = pb.poses.len() * OVERSAMPLE;
    let (mut residual, mut ntilde, mut robust) =
        (0.0f64, Vec::with_capacity(m), Vec::with_capacity(m));
    for i in 0..m {
        // Entry OVERSAMPLE·j has t = j/N exactly, the pose of sample j.
        let pose = (pb.poses.at)(i as f64 / m as f64);
        let c = model::contact_f64(x, &pose, pb.dx);
        residual = residual.max(model::conjugation_residual_deg(c.n, c.t1, c.t2));
        let (p, n) = (c.p.vals(), c.n.vals());
        ntilde.push(closure::project(pb.class, p, n));
        robust.push(match pb.class {
            Class::R3 => pb.cone.allows(p, n),
            _ => closure::is_robust(pb.class, p, n),
        });
    }
    (residual, ntilde, robust)
}

/// Per sample, whether the printed parts lose the candidate's contact: its own printed rim
/// cuts it at another instant or leaves it on an island of band
/// ([`undercut::lost_contacts`] on the N samples).
fn lost_samples(pb: &PairProblem, x: &[f64], rim: &undercut::RimSection) -> Vec<bool> {
    let n = pb.poses.len();
    let (mut c2, mut n2, mut c1, mut n1, mut maps) = (
        Vec::with_capacity(n),
        Vec::with_capacity(n),
        Vec::with_capacity(n),
        Vec::with_capacity(n),
        Vec::with_capacity(n),
    );
    for pose in &pb.poses.samples {
        let c = model::contact_f64(x, pose, pb.dx);
        let phi = TAU * pose.t;
        c2.push(c.c2.vals());
        n2.push((-c.n.rot_t(&pose.rot)).vals());
        c1.push(c.c1.vals());
        n1.push(c.n.rot_t(&super::math::rz(phi)).vals());
        maps.push(undercut::DriverToFollower::new(
            &pose.rot, pose.trans, phi, pb.dx,
        ));
    }
    undercut::lost_contacts(&c2, &n2, &c1, &n1, &maps, rim)
}

/// Drop from the oversampled closure data the contacts the printed parts lose
/// ([`lost_samples`]): an oversampled instant is dropped when either sample around it is
/// lost, so a lost window is never narrowed by the interpolation.
fn drop_lost_contacts(
    pb: &PairProblem,
    x: &[f64],
    rim: &undercut::RimSection,
    ntilde: &mut [Option<[f64; 3]>],
    robust: &mut [bool],
) {
    let n = pb.poses.len();
    let lost = lost_samples(pb, x, rim);
    for (i, (nt, rb)) in ntilde.iter_mut().zip(robust.iter_mut()).enumerate() {
        let j = i / OVERSAMPLE;
        let exact = i % OVERSAMPLE == 0;
        if lost[j] || (!exact && lost[(j + 1) % n]) {
            *nt = None;
            *rb = false;
        }
    }
}

/// Solve one candidate and run the checks.
pub fn solve(
    pb: &PairProblem,
    minimizer: &dyn Minimizer,
    seed: u64,
    band: usize,
    index: usize,
    max_eval: usize,
) -> Candidate {
    let mut x0 = initial_guess(pb, seed, band, index);
    let mut evals = 0;
    let mut cap = max_eval;
    if pb.class == Class::R3 && pb.cone == closure::NormalCone::Tangent {
        let sign = normal_sign(index);
        let (xa, ea) = align_start(pb, minimizer, &x0, sign);
        x0 = xa;
        evals = ea;
        cap = (max_eval as f64 * R3_TANGENT_EVAL_SCALE).round() as usize;
    }
    solve_from(pb, minimizer, &x0, cap, band, index, evals)
}

/// Solve one candidate from the start `x0` with at most `max_eval` evaluations and run the
/// checks; `evals` were already spent on its start. Also what a refinement of a chosen
/// candidate runs (see `search`).
pub fn solve_from(
    pb: &PairProblem,
    minimizer: &dyn Minimizer,
    x0: &[f64],
    max_eval: usize,
    band: usize,
    index: usize,
    evals: usize,
) -> Candidate {
    let res = minimizer.minimize(pb, x0, max_eval);
    let x = res.x;
    let mut reason = None;
    let finite = x.iter().all(|v| v.is_finite()) && res.f.is_finite();
    let (mut ntilde, mut robust, mut residual) = (Vec::new(), Vec::new(), f64::INFINITY);
    if !finite {
        reason = Some(NAN_REASON.to_string());
    } else {
        let ev = pb.evaluate(&x);
        if !pb.feasible(&x, &ev, FEAS_TOL) {
            let worst = ev
                .cons_exact
                .iter()
                .enumerate()
                .max_by(|a, b| a.1.total_cmp(b.1))
                .map(|(i, v)| format!("{} violated by {v:.3e}", pb.constraint_name(i)))
                .unwrap_or_default();
            reason = Some(format!("infeasible ({:?}): {worst}", res.status));
        }
        (residual, ntilde, robust) = oversampled(pb, &x);
        if let Some(rim) = &pb.rim {
            drop_lost_contacts(pb, &x, rim, &mut ntilde, &mut robust);
        }
        if reason.is_none() && residual > MAX_RESIDUAL_DEG {
            reason = Some(format!(
                "conjugation residual {residual:.2}° > {MAX_RESIDUAL_DEG}°"
            ));
        }
        if reason.is_some() {
            // Never combined: keep the memory.
            (ntilde, robust) = (Vec::new(), Vec::new());
        }
    }
    Candidate {
        band,
        slab: [pb.band.0, pb.band.1],
        index,
        f: res.f,
        valid: reason.is_none(),
        reason,
        residual_deg: residual,
        status: res.status,
        x,
        ntilde,
        robust,
        evals: evals + res.evals,
        vary: pb.vary,
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::synth::energy::{W_CLOSURE, W_ROBUST};
    use crate::synth::optimizer::SlsqpRs;
    use crate::synth::pose::{pose_1r, PoseFn, PoseTrack};
    use std::sync::Arc;

    /// A 1R motion like the paper's Fig. 11: one turn per period, non-uniform speed.
    pub(crate) fn half_turn_like(n: usize) -> Arc<PoseTrack> {
        let at: PoseFn = Arc::new(|t: f64| {
            let a = 0.5;
            let w = TAU * t;
            pose_1r(t, w - a * w.sin(), TAU * (1.0 - a * w.cos()))
        });
        Arc::new(PoseTrack::from_fn(n, at))
    }

    pub(crate) fn problem_1r(n: usize) -> PairProblem {
        PairProblem {
            class: Class::R1,
            poses: half_turn_like(n),
            dx: 6.0,
            band: (-0.5, 0.5),
            vary: None,
            w_closure: W_CLOSURE,
            w_robust: W_ROBUST,
            cone: closure::NormalCone::Tangent,
            focus: None,
            push: None,
            stage: Stage::Full,
            axis_room: None,
            rim: None,
        }
    }

    /// Guards the printed-rim judgement of a candidate: the same solve with a rim drops ñ
    /// (and the robust flag) at every sample whose contact its own rim cuts or leaves on an
    /// island, and only there among the exact samples; without a rim those contacts count. A 1R candidate
    /// on the half-turn-like motion (N = 60, band ±0.5) whose rim cuts part of its own
    /// curve, so the test would see a mask that did nothing.
    #[test]
    fn a_printed_rim_drops_the_contacts_it_cuts() {
        let rim = undercut::RimSection::printed(10.0);
        let free = problem_1r(60);
        let printed = PairProblem {
            rim: Some(rim),
            ..problem_1r(60)
        };
        let (a, b) = (0..8)
            .map(|i| {
                (
                    solve(&free, &SlsqpRs, 3, 0, i, 300),
                    solve(&printed, &SlsqpRs, 3, 0, i, 300),
                )
            })
            .find(|(a, _)| a.valid)
            .expect("a valid candidate among the first eight");
        assert!(b.valid, "{:?}", b.reason);
        assert_eq!(a.x, b.x, "the rim is not part of the objective");
        let n = free.poses.len();
        let cut = lost_samples(&free, &a.x, &rim);
        let cuts = cut.iter().filter(|c| **c).count();
        assert!(cuts > 0 && cuts < n, "{cuts} of {n} samples cut");
        for (j, &c) in cut.iter().enumerate() {
            let i = OVERSAMPLE * j;
            if c {
                assert_eq!((b.ntilde[i], b.robust[i]), (None, false), "sample {j}");
            } else {
                assert_eq!(
                    (b.ntilde[i], b.robust[i]),
                    (a.ntilde[i], a.robust[i]),
                    "sample {j}"
                );
            }
        }
        assert!(cut
            .iter()
            .zip(0..)
            .any(|(&c, j)| c && a.ntilde[OVERSAMPLE * j].is_some()));
    }

    /// Guards the 3R start normal: unit, in the normal plane of T² (where the model's normals
    /// live), inside the tangent cone with margin, and equal to the conjugate direction
    /// ±p̂ × w when that is inside the cone.
    #[test]
    fn r3_start_normal_is_conjugate_within_the_cone() {
        let s = closure::NormalCone::Tangent.max_abs_dot();
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let mut r = || {
            V3::<f64>::new(
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
            )
        };
        let mut inside = 0;
        for _ in 0..500 {
            let (p, t2, w) = (r().scalec(3.0), r(), r().scalec(5.0));
            let c = model::Contact {
                p,
                c2: p,
                c1: p,
                n: p,
                t2,
                t1: t2 + w,
                c2d: t2,
                c1d: t2,
                kappa: p,
            };
            let n = r3_start_normal(&c, -1.0, s);
            assert!((n.norm() - 1.0).abs() < 1e-9);
            assert!(n.dot(t2.unit()).abs() < 1e-9);
            assert!(n.dot(p.unit()).abs() <= R3_START_CONE_FRACTION * s + 1e-9);
            let conj = p.unit().cross(w.unit()).scalec(-1.0);
            let conj = (conj - t2.unit().scalec(conj.dot(t2.unit()))).unit();
            if conj.dot(p.unit()).abs() < R3_START_CONE_FRACTION * s {
                inside += 1;
                assert!((n - conj).norm() < 1e-9);
            }
        }
        assert!(inside > 10);
    }

    /// `f` of the contact at every sample of design `x`, sorted.
    fn per_sample_sorted(
        pb: &PairProblem,
        x: &[f64],
        f: impl Fn(&model::Contact<f64>) -> f64,
    ) -> Vec<f64> {
        let mut out: Vec<f64> = pb
            .poses
            .samples
            .iter()
            .map(|pose| f(&model::contact_f64(x, pose, pb.dx)))
            .collect();
        out.sort_by(f64::total_cmp);
        out
    }

    /// Angle (degrees) between the conjugate normal ±T² × w and the tangent plane of the
    /// sphere through the contact, per sample, sorted.
    fn misalignments_deg(pb: &PairProblem, x: &[f64]) -> Vec<f64> {
        per_sample_sorted(pb, x, |c| {
            let u = c.t2.cross(c.t1 - c.t2).unit();
            u.dot(c.p.unit()).abs().asin().to_degrees()
        })
    }

    /// Guards the 3R alignment pre-solve (`align_start`) on pick-and-place, the example it
    /// was made for: in an off-centre band the start loop's conjugate normal leaves the 10°
    /// cone at many samples, and after the pre-solve it is within the cone at ≥ 90 % of them
    /// with a median of ≤ 3°, the curve still inside its band and its length, clearance and
    /// steepness bounds, and the start normal set again on the moved curve (over the
    /// candidates, closer to conjugate than the loop's angles kept on it).
    #[test]
    fn align_start_brings_the_conjugate_normal_into_the_cone() {
        let m = crate::motion::Motion::from_file(std::path::Path::new(
            "data/motions/pick-and-place.toml",
        ))
        .unwrap();
        let poses = Arc::new(PoseTrack::from_motion(&m, 360));
        let pb = crate::synth::bands::band_problem(
            Class::R3,
            &poses,
            7.5,
            crate::synth::bands::BandLayout::default(),
            1,
            closure::NormalCone::Tangent,
        );
        let within = |v: &[f64]| v.iter().filter(|a| **a <= 10.0).count() as f64 / v.len() as f64;
        // (Candidate 0 of this band is left out: SLSQP makes no progress from its loop, which
        // the pre-solve then returns as it was; 11 of the first 12 align.)
        let mut sums = (0.0, 0.0);
        for index in 1..5 {
            let sign = normal_sign(index);
            let x0 = initial_guess(&pb, 1, 1, index);
            let before = misalignments_deg(&pb, &x0);
            let (x, evals) = align_start(&pb, &SlsqpRs, &x0, sign);
            let after = misalignments_deg(&pb, &x);
            let (mb, ma) = (before[before.len() / 2], after[after.len() / 2]);
            eprintln!(
                "candidate {index}: within 10° {:.2} → {:.2}, median {mb:.1}° → {ma:.1}°, {evals} evaluations",
                within(&before),
                within(&after)
            );
            assert!(within(&before) < 0.9, "the start loop was already aligned");
            assert!(
                within(&after) >= 0.9 && ma <= 3.0,
                "candidate {index} not aligned"
            );
            assert!(evals > 0 && evals <= ALIGN_MAX_EVAL);
            let ev = pb.evaluate(&x);
            let worst = ev.cons_exact[..5].iter().cloned().fold(f64::MIN, f64::max);
            assert!(worst <= FEAS_TOL, "constraints violated by {worst:e}");
            for (j, v) in x.iter().enumerate().take(3 * CURVE_CPS).skip(2).step_by(3) {
                assert!(
                    (pb.band.0..=pb.band.1).contains(v),
                    "control point {j} left the band"
                );
            }
            // The normal was set again on the moved curve: over the candidates it is closer to
            // conjugate (median over the samples) than the loop's start angles kept on the
            // moved curve. Not for every candidate: the 10-point θ spline cannot follow every
            // curve's normal, and two of these four are worse (summed: 58° against 85°).
            // Setting it again is still what makes more candidates usable (pick-and-place,
            // K = 7, d_x = 7.5: usable per band [6, 2, 1, 0, 3, 1, 1, 3] and closed, against
            // [9, 0, 1, 0, 0, 1, 0, 0, 0] with the angles kept).
            let median_residual = |x: &[f64]| {
                let r =
                    per_sample_sorted(&pb, x, |c| model::conjugation_residual_deg(c.n, c.t1, c.t2));
                r[r.len() / 2]
            };
            let mut kept = x.clone();
            kept[3 * CURVE_CPS..].copy_from_slice(&x0[3 * CURVE_CPS..]);
            let (reset, old) = (median_residual(&x), median_residual(&kept));
            eprintln!("  start normal: median residual {old:.1}° kept, {reset:.1}° set again");
            sums.0 += reset;
            sums.1 += old;
        }
        assert!(
            sums.0 < sums.1,
            "start normals not set again: summed median residuals {:.1}° against {:.1}° kept",
            sums.0,
            sums.1
        );
    }
}
