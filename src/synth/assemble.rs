//! The mechanism file's content from the chosen candidates: every pair's sampled contact
//! data (p, n, c¹, n¹, c², n²), its band and splines, and the closure block computed again
//! from those samples (paper and conventions' robust figures) and at [`OVERSAMPLE`]× the
//! sample density from the splines.
//!
//! Owns the mapping from candidates to `mechanism.json` fields; it does not choose
//! candidates (see `search`) or check a file (see `mechanism`).

use super::candidate::{Candidate, OVERSAMPLE};
use super::closure::{self, Class, ClosureSummary};
use super::energy::LENGTH_BOUNDS;
use super::math::rz;
use super::mechanism::{
    ClosureBlock, CurvePair, FollowerPose, Mechanism, MotionInfo, OversampledClosure, PairSamples,
    SolveInfo, SplineAngle, SplineCurve, FORMAT,
};
use super::model::{self, ANGLE_CPS, CURVE_CPS};
use super::pose::PoseTrack;

/// Build the mechanism file content from chosen candidates (one per band).
pub fn assemble(
    class: Class,
    poses: &PoseTrack,
    motion: MotionInfo,
    scale_mm: f64,
    dx: f64,
    chosen: &[Candidate],
    solve: SolveInfo,
) -> Mechanism {
    let n = poses.len();
    let tau = std::f64::consts::TAU;
    let mut pairs = Vec::with_capacity(chosen.len());
    for c in chosen {
        let mut s = PairSamples {
            p: Vec::with_capacity(n),
            n: Vec::with_capacity(n),
            c1: Vec::with_capacity(n),
            n1: Vec::with_capacity(n),
            c2: Vec::with_capacity(n),
            n2: Vec::with_capacity(n),
        };
        for pose in &poses.samples {
            let ct = model::contact_f64(&c.x, pose, dx);
            s.p.push(ct.p.vals());
            s.n.push(ct.n.vals());
            s.c1.push(ct.c1.vals());
            s.c2.push(ct.c2.vals());
            s.n1.push(ct.n.rot_t(&rz(tau * pose.t)).vals());
            s.n2.push((-ct.n).rot_t(&pose.rot).vals());
        }
        pairs.push(CurvePair {
            slab: c.slab,
            follower_curve: SplineCurve {
                degree: 3,
                closed: true,
                control_points: model::curve_cps(&c.x),
            },
            normal_angle: SplineAngle {
                degree: 3,
                closed: true,
                control_points: model::angle_cps(&c.x),
            },
            samples: s,
            residual_deg: c.residual_deg,
        });
    }
    let contacts_at = |i: usize| -> Vec<([f64; 3], [f64; 3])> {
        pairs
            .iter()
            .map(|p| (p.samples.p[i], p.samples.n[i]))
            .collect()
    };
    let (dist, rdist): (Vec<f64>, Vec<f64>) = (0..n)
        .map(|i| closure::dist_at(class, &contacts_at(i)))
        .unzip();
    let summary = ClosureSummary::from_dists(dist, rdist);
    // Oversampled closure from the splines; with printed rims, from the contacts they keep
    // (a candidate's ñ is None where its rim cuts the contact, or where ñ vanishes, which
    // adds nothing to a hull either).
    let m = n * OVERSAMPLE;
    let kept =
        |c: &Candidate, i: usize| !solve.printed_rim || c.ntilde.get(i).is_none_or(Option::is_some);
    let (od, ord): (Vec<f64>, Vec<f64>) = (0..m)
        .map(|i| {
            let pose = (poses.at)(i as f64 / m as f64);
            let cs: Vec<_> = chosen
                .iter()
                .filter(|c| kept(c, i))
                .map(|c| {
                    let ct = model::contact_f64(&c.x, &pose, dx);
                    (ct.p.vals(), ct.n.vals())
                })
                .collect();
            closure::dist_at(class, &cs)
        })
        .unzip();
    let over = ClosureSummary::from_dists(od, ord);
    let worst_residual = chosen.iter().map(|c| c.residual_deg).fold(0.0, f64::max);
    debug_assert_eq!(CURVE_CPS, pairs[0].follower_curve.control_points.len());
    debug_assert_eq!(ANGLE_CPS, pairs[0].normal_angle.control_points.len());
    Mechanism {
        format: FORMAT.to_string(),
        class,
        driver_offset: dx,
        samples: n,
        scale_mm,
        length_bounds: LENGTH_BOUNDS,
        motion,
        follower_motion: poses
            .samples
            .iter()
            .map(|p| {
                let q = p.quaternion();
                FollowerPose {
                    t: p.t,
                    rotation: [q.w, q.i, q.j, q.k],
                    translation: p.trans,
                }
            })
            .collect(),
        curve_pairs: pairs,
        closure: ClosureBlock {
            epsilon: summary.epsilon,
            dist: summary.dist.clone(),
            vali_time: summary.vali_time,
            max_dist: summary.max_dist,
            robust_vali_time: summary.robust_vali_time,
            robust_max_dist: summary.robust_max_dist,
            robust_dist: summary.robust_dist.clone(),
            oversampled: Some(OversampledClosure {
                factor: OVERSAMPLE,
                vali_time: over.vali_time,
                max_dist: over.max_dist,
                robust_vali_time: over.robust_vali_time,
                robust_max_dist: over.robust_max_dist,
            }),
            worst_residual_deg: worst_residual,
        },
        solve,
    }
}
