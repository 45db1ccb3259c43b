//! Dynamic form closure: projected generalized normals and the signed distance from the
//! origin to the boundary of their convex hull, in 1, 2 and 3 dimensions.
//!
//! Owns ñ (the projection of [n; p × n] onto the follower's motion space, per class, as fixed
//! in `docs/conventions.md`), the exact small-hull routines, the robust-closure filter (only
//! contacts whose torque arm is useful count), the 3-D hull's facet nearest the origin
//! (what the 3R margin push widens) and the per-sample summary
//! (E_valiTime, E_maxDist). It does not know about curves or optimization.
//!
//! Hull routines are exact for the small point counts of a mechanism (K ≤ ~10): the 2-D
//! hull is a monotone chain; the 3-D hull is found by brute-force enumeration of supporting
//! planes through point triples. Degenerate sets (fewer than d + 1 points, or all points
//! collinear in 2-D / coplanar in 3-D) have no interior and get [`NO_INTERIOR_DIST`].

use serde::{Deserialize, Serialize};

use super::math::V3;

/// Signed distance reported when the hull has no interior in its dimension. Default 1000:
/// the conventions ask for "+∞ or a large positive number"; JSON has no ∞ and every real
/// distance of unit vectors is within [−1, 1], so 1000 cannot be mistaken for one.
pub const NO_INTERIOR_DIST: f64 = 1000.0;

/// A signed distance for people: `no interior` for [`NO_INTERIOR_DIST`] (the file's
/// stand-in for +∞), the number to 3 decimals otherwise. It used to be printed clipped to
/// `99.000`, a value no file holds (issue 20).
pub fn dist_text(d: f64) -> String {
    if d >= NO_INTERIOR_DIST {
        "no interior".into()
    } else {
        format!("{d:.3}")
    }
}

/// Closure tolerance ε: a sample is valid when dist < −ε. Default 0.02 (paper §5.2).
pub const EPSILON: f64 = 0.02;

/// Useful-contact angle γ₀ of the robust closure and the 3R cone: 10° (paper Eq. 30).
pub const GAMMA0_DEG: f64 = 10.0;

/// Which reading of the paper's 3R closure constraint (Eq. 30) bounds the contact normals.
///
/// Eq. 30 is printed as (n·p̂)² − cos²(γ₀ + π/2) ≤ 0, i.e. |n·p̂| ≤ sin γ₀: every normal
/// within γ₀ = 10° of the tangent plane of the sphere through the contact. The sentence
/// before it gives its purpose as "avoiding n × p = 0", which with the same γ₀ reads
/// |n × p̂| ≥ sin γ₀, i.e. |n·p̂| ≤ cos γ₀: no normal within γ₀ of the line through the
/// joint centre, the same torque-arm test our 1R and 1R1T robust closure applies. The
/// conventions adopt the printed form, so it is the default; `Arm` is the stated purpose.
/// Measured (seed 1): with `Tangent` and the 3R start loops of `candidate::initial_guess`,
/// cone-sweep, figure-eight (K = 6), helicopter and paddle (K = 5) close at d_x = 6 in
/// 28–34 s, pick-and-place and spherical-four-bar do not (circle-like starts closed none);
/// with `Arm` every 3R example closes (K = 6–7, d_x = 6).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum NormalCone {
    /// Eq. 30 as printed: |n·p̂| ≤ sin γ₀ (conventions; default).
    #[default]
    Tangent,
    /// Eq. 30's stated purpose: |n·p̂| ≤ cos γ₀ (torque arm at least sin γ₀ · |p|).
    Arm,
}

impl NormalCone {
    /// Largest allowed |n·p̂|.
    pub fn max_abs_dot(self) -> f64 {
        match self {
            NormalCone::Tangent => GAMMA0_DEG.to_radians().sin(),
            NormalCone::Arm => GAMMA0_DEG.to_radians().cos(),
        }
    }

    /// Whether a 3R contact (p, n) meets this bound.
    pub fn allows(self, p: [f64; 3], n: [f64; 3]) -> bool {
        let (p, n) = (V3::from(p), V3::from(n));
        let l = p.norm();
        l > 0.0 && (n.dot(p) / l).abs() <= self.max_abs_dot()
    }

    /// Name as written in files and on the command line.
    pub fn label(self) -> &'static str {
        match self {
            NormalCone::Tangent => "tangent",
            NormalCone::Arm => "arm",
        }
    }
}

/// Relative tolerance for "on the plane" / "collinear" decisions in the hull routines.
/// Default 1e-10: ñ are unit vectors, so anything below this is round-off.
pub const HULL_TOL: f64 = 1e-10;

/// Motion class of the follower joint, as far as closure is concerned.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum Class {
    /// Revolute joint about z.
    #[serde(rename = "1R")]
    R1,
    /// Cylindrical joint along and about z.
    #[serde(rename = "1R1T")]
    R1T1,
    /// Spherical joint about the origin.
    #[serde(rename = "3R")]
    R3,
}

impl Class {
    /// Degrees of freedom of the follower joint (dimension of ñ).
    pub fn dof(self) -> usize {
        match self {
            Class::R1 => 1,
            Class::R1T1 => 2,
            Class::R3 => 3,
        }
    }
    /// Minimal number of contacts, dof + 1.
    pub fn min_k(self) -> usize {
        self.dof() + 1
    }
    /// The label used in files ("1R", "1R1T", "3R").
    pub fn label(self) -> &'static str {
        match self {
            Class::R1 => "1R",
            Class::R1T1 => "1R1T",
            Class::R3 => "3R",
        }
    }
}

/// ñ for one contact (p, n in frame R), zero-padded to 3 components; `None` when the
/// projection vanishes (the contact cannot act in the motion space at all).
pub fn project(class: Class, p: [f64; 3], n: [f64; 3]) -> Option<[f64; 3]> {
    let m = V3::from(p).cross(V3::from(n)).vals();
    match class {
        Class::R1 => {
            if m[2] > 0.0 {
                Some([1.0, 0.0, 0.0])
            } else if m[2] < 0.0 {
                Some([-1.0, 0.0, 0.0])
            } else {
                None
            }
        }
        Class::R1T1 => {
            let (a, b) = (n[2], m[2]);
            let l = (a * a + b * b).sqrt();
            (l > 0.0).then(|| [a / l, b / l, 0.0])
        }
        Class::R3 => {
            let l = V3::from(m).norm();
            (l > 0.0).then(|| [m[0] / l, m[1] / l, m[2] / l])
        }
    }
}

/// Signed torque arm about the z axis per unit radius, (p × n)·ẑ / |p_xy| (0 on the axis):
/// what the 1R and 1R1T robust closure look at.
pub fn torque_arm(p: [f64; 3], n: [f64; 3]) -> f64 {
    let pxy = (p[0] * p[0] + p[1] * p[1]).sqrt();
    if pxy > 0.0 {
        V3::from(p).cross(V3::from(n)).z / pxy
    } else {
        0.0
    }
}

/// Whether a contact counts for the robust closure (conventions: "Robust closure").
pub fn is_robust(class: Class, p: [f64; 3], n: [f64; 3]) -> bool {
    let s = GAMMA0_DEG.to_radians().sin();
    let arm = torque_arm(p, n).abs();
    match class {
        Class::R1 => arm >= s,
        Class::R1T1 => n[2].abs().max(arm) >= s,
        Class::R3 => NormalCone::Tangent.allows(p, n),
    }
}

/// Signed distance from the origin to the boundary of the hull of 1-D points.
pub fn signed_dist_1d(xs: &[f64]) -> f64 {
    if xs.len() < 2 {
        return NO_INTERIOR_DIST;
    }
    let lo = xs.iter().cloned().fold(f64::INFINITY, f64::min);
    let hi = xs.iter().cloned().fold(f64::NEG_INFINITY, f64::max);
    if hi - lo <= HULL_TOL {
        return NO_INTERIOR_DIST;
    }
    if lo < 0.0 && hi > 0.0 {
        -(-lo).min(hi)
    } else if lo >= 0.0 {
        lo
    } else {
        -hi
    }
}

/// Convex hull of 2-D points (counter-clockwise, no collinear vertices); fewer than 3
/// vertices means no interior.
pub fn hull_2d(pts: &[[f64; 2]]) -> Vec<[f64; 2]> {
    let mut p: Vec<[f64; 2]> = pts.to_vec();
    p.sort_by(|a, b| a[0].total_cmp(&b[0]).then(a[1].total_cmp(&b[1])));
    p.dedup_by(|a, b| (a[0] - b[0]).abs() <= HULL_TOL && (a[1] - b[1]).abs() <= HULL_TOL);
    if p.len() < 3 {
        return p;
    }
    let turn = |o: [f64; 2], a: [f64; 2], b: [f64; 2]| {
        (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])
    };
    let mut h: Vec<[f64; 2]> = Vec::with_capacity(2 * p.len());
    for pass in 0..2 {
        let start = h.len();
        let iter: Box<dyn Iterator<Item = &[f64; 2]>> = if pass == 0 {
            Box::new(p.iter())
        } else {
            Box::new(p.iter().rev())
        };
        for &q in iter {
            while h.len() >= start + 2 && turn(h[h.len() - 2], h[h.len() - 1], q) <= HULL_TOL {
                h.pop();
            }
            h.push(q);
        }
        h.pop();
    }
    h
}

/// Distance from the origin to the segment a–b.
fn dist_to_segment_2d(a: [f64; 2], b: [f64; 2]) -> f64 {
    let d = [b[0] - a[0], b[1] - a[1]];
    let l2 = d[0] * d[0] + d[1] * d[1];
    let s = if l2 > 0.0 {
        (-(a[0] * d[0] + a[1] * d[1]) / l2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    let q = [a[0] + s * d[0], a[1] + s * d[1]];
    (q[0] * q[0] + q[1] * q[1]).sqrt()
}

/// Signed distance from the origin to the boundary of the hull of 2-D points.
pub fn signed_dist_2d(pts: &[[f64; 2]]) -> f64 {
    let h = hull_2d(pts);
    if h.len() < 3 {
        return NO_INTERIOR_DIST;
    }
    let mut inside = true;
    let mut min_plane = f64::INFINITY;
    let mut min_seg = f64::INFINITY;
    for i in 0..h.len() {
        let a = h[i];
        let b = h[(i + 1) % h.len()];
        let e = [b[0] - a[0], b[1] - a[1]];
        let l = (e[0] * e[0] + e[1] * e[1]).sqrt();
        // Signed distance of the origin to the edge line, positive inside (CCW hull).
        let s = (e[0] * (-a[1]) - e[1] * (-a[0])) / l;
        if s <= 0.0 {
            inside = false;
        }
        min_plane = min_plane.min(s);
        min_seg = min_seg.min(dist_to_segment_2d(a, b));
    }
    if inside {
        -min_plane
    } else {
        min_seg
    }
}

/// Closest point to the origin on triangle abc (Ericson's region tests), returned as distance.
fn dist_to_triangle(a: V3<f64>, b: V3<f64>, c: V3<f64>) -> f64 {
    let ab = b - a;
    let ac = c - a;
    let ap = -a;
    let d1 = ab.dot(ap);
    let d2 = ac.dot(ap);
    if d1 <= 0.0 && d2 <= 0.0 {
        return a.norm();
    }
    let bp = -b;
    let d3 = ab.dot(bp);
    let d4 = ac.dot(bp);
    if d3 >= 0.0 && d4 <= d3 {
        return b.norm();
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        let v = d1 / (d1 - d3);
        return (a + ab.scalec(v)).norm();
    }
    let cp = -c;
    let d5 = ab.dot(cp);
    let d6 = ac.dot(cp);
    if d6 >= 0.0 && d5 <= d6 {
        return c.norm();
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        let w = d2 / (d2 - d6);
        return (a + ac.scalec(w)).norm();
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        let w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        return (b + (c - b).scalec(w)).norm();
    }
    let denom = 1.0 / (va + vb + vc);
    let v = vb * denom;
    let w = vc * denom;
    (a + ab.scalec(v) + ac.scalec(w)).norm()
}

/// A supporting plane of the hull of 3-D points, found through the points `tri`: its unit
/// normal `u` points away from the hull, and `depth` is how far the origin lies below the
/// plane (positive on the hull's side).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Facet {
    /// The three points the plane was found through (indices into the point list).
    pub tri: [usize; 3],
    /// Outward unit normal.
    pub u: [f64; 3],
    /// The origin's distance below the plane, positive on the hull's side.
    pub depth: f64,
}

/// Whether the points have no interior, or else every supporting plane through a triple of
/// them, given to `visit` (a facet with more than three points on its plane comes once per
/// triple). `false`: fewer than 4 points, or all coplanar.
///
/// Facets are found by brute force: a triple (i, j, k) spans a supporting plane when every
/// other point lies on one side of it.
fn hull_facets_3d(pts: &[[f64; 3]], mut visit: impl FnMut(&Facet)) -> bool {
    let m = pts.len();
    if m < 4 {
        return false;
    }
    let mut any_facet = false;
    for i in 0..m {
        for j in i + 1..m {
            for k in j + 1..m {
                let (a, b, c) = (V3::from(pts[i]), V3::from(pts[j]), V3::from(pts[k]));
                let nrm = (b - a).cross(c - a);
                let l = nrm.norm();
                if l <= HULL_TOL {
                    continue;
                }
                let u = V3::new(nrm.x / l, nrm.y / l, nrm.z / l);
                let off = u.dot(a);
                let (mut pos, mut neg) = (false, false);
                for (q, pt) in pts.iter().enumerate() {
                    if q == i || q == j || q == k {
                        continue;
                    }
                    let s = u.dot(V3::from(*pt)) - off;
                    if s > HULL_TOL {
                        pos = true;
                    } else if s < -HULL_TOL {
                        neg = true;
                    }
                    if pos && neg {
                        // Points on both sides: not a facet, whatever the rest.
                        break;
                    }
                }
                if pos && neg {
                    continue;
                }
                if !pos && !neg {
                    // All points coplanar: no interior.
                    return false;
                }
                any_facet = true;
                // Orient u away from the other points.
                let (u, depth) = if pos {
                    (u.scalec(-1.0), -off)
                } else {
                    (u, off)
                };
                visit(&Facet {
                    tri: [i, j, k],
                    u: u.vals(),
                    depth,
                });
            }
        }
    }
    any_facet
}

/// Signed distance from the origin to the boundary of the hull of 3-D points.
///
/// Inside: minus the distance to the nearest facet plane. Outside: the distance to the
/// nearest facet triangle.
pub fn signed_dist_3d(pts: &[[f64; 3]]) -> f64 {
    let mut inside = true;
    let mut min_plane = f64::INFINITY;
    let mut min_tri = f64::INFINITY;
    let any = hull_facets_3d(pts, |f| {
        if f.depth <= 0.0 {
            inside = false;
        }
        min_plane = min_plane.min(f.depth);
        let [i, j, k] = f.tri;
        min_tri = min_tri.min(dist_to_triangle(
            V3::from(pts[i]),
            V3::from(pts[j]),
            V3::from(pts[k]),
        ));
    });
    if !any {
        return NO_INTERIOR_DIST;
    }
    if inside {
        -min_plane
    } else {
        min_tri
    }
}

/// The facet of the hull of 3-D points nearest the origin, when the origin lies inside:
/// the plane that sets [`signed_dist_3d`] (its `depth` is minus that distance). `None` when
/// the points have no interior or the origin is not inside. Ties go to the first triple in
/// index order.
pub fn nearest_facet_3d(pts: &[[f64; 3]]) -> Option<Facet> {
    let mut inside = true;
    let mut nearest: Option<Facet> = None;
    let any = hull_facets_3d(pts, |f| {
        if f.depth <= 0.0 {
            inside = false;
        }
        if nearest.is_none_or(|n| f.depth < n.depth) {
            nearest = Some(*f);
        }
    });
    (any && inside).then_some(nearest).flatten()
}

/// Signed distance for a set of projected normals of a class (1-D uses the first component,
/// 2-D the first two).
pub fn signed_dist(class: Class, pts: &[[f64; 3]]) -> f64 {
    match class {
        Class::R1 => signed_dist_1d(&pts.iter().map(|p| p[0]).collect::<Vec<_>>()),
        Class::R1T1 => signed_dist_2d(&pts.iter().map(|p| [p[0], p[1]]).collect::<Vec<_>>()),
        Class::R3 => signed_dist_3d(pts),
    }
}

/// dist(t) at one instant from K contacts (p, n): paper and robust variants.
pub fn dist_at(class: Class, contacts: &[([f64; 3], [f64; 3])]) -> (f64, f64) {
    let mut all = Vec::with_capacity(contacts.len());
    let mut rob = Vec::with_capacity(contacts.len());
    for &(p, n) in contacts {
        if let Some(q) = project(class, p, n) {
            all.push(q);
            if is_robust(class, p, n) {
                rob.push(q);
            }
        }
    }
    signed_dists(class, &all, &rob)
}

/// The signed distances of all projected normals and of their robust subsequence `rob`.
/// A subsequence as long as `all` is `all`, and its distance is not computed twice: under
/// the 3R tangent cone every contact counts robustly, and the second hull was half of the
/// 3R combination search's hull work (measured in `docs/synthesis.md`).
pub fn signed_dists(class: Class, all: &[[f64; 3]], rob: &[[f64; 3]]) -> (f64, f64) {
    let d = signed_dist(class, all);
    let r = if rob.len() == all.len() {
        d
    } else {
        signed_dist(class, rob)
    };
    (d, r)
}

/// Closure figures over a sampled period.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ClosureSummary {
    /// ε used.
    pub epsilon: f64,
    /// dist(tᵢ) for every sample.
    pub dist: Vec<f64>,
    /// Robust dist(tᵢ) for every sample.
    pub robust_dist: Vec<f64>,
    /// E_valiTime.
    pub vali_time: f64,
    /// E_maxDist.
    pub max_dist: f64,
    /// Robust E_valiTime.
    pub robust_vali_time: f64,
    /// Robust E_maxDist.
    pub robust_max_dist: f64,
}

impl ClosureSummary {
    /// Summarize per-sample distances.
    pub fn from_dists(dist: Vec<f64>, robust_dist: Vec<f64>) -> Self {
        let n = dist.len().max(1) as f64;
        let vali = |d: &[f64]| d.iter().filter(|&&x| x < -EPSILON).count() as f64 / n;
        let maxd = |d: &[f64]| d.iter().cloned().fold(f64::NEG_INFINITY, f64::max);
        Self {
            epsilon: EPSILON,
            vali_time: vali(&dist),
            max_dist: maxd(&dist),
            robust_vali_time: vali(&robust_dist),
            robust_max_dist: maxd(&robust_dist),
            dist,
            robust_dist,
        }
    }

    /// Paper criterion (E_valiTime = 1, E_maxDist ≤ −ε) and robust closure at every sample.
    pub fn accepted(&self) -> bool {
        self.vali_time >= 1.0
            && self.max_dist <= -EPSILON
            && self.robust_vali_time >= 1.0
            && self.robust_max_dist <= -EPSILON
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// Independent reference: dist = −min over unit directions u of max_k u·ñ_k (support
    /// function), evaluated on a dense Fibonacci sphere and refined locally.
    fn support_dist_3d(pts: &[[f64; 3]]) -> f64 {
        let h = |u: V3<f64>| {
            pts.iter()
                .map(|&p| V3::from(p).dot(u))
                .fold(f64::MIN, f64::max)
        };
        let n = 20000;
        let mut best = (f64::INFINITY, V3::zero());
        for i in 0..n {
            let z = 1.0 - 2.0 * (i as f64 + 0.5) / n as f64;
            let r = (1.0 - z * z).sqrt();
            let a = i as f64 * 2.399_963_229_728_653;
            let u = V3::new(r * a.cos(), r * a.sin(), z);
            let v = h(u);
            if v < best.0 {
                best = (v, u);
            }
        }
        // Local refinement by random perturbation with shrinking radius.
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let mut rad = 0.05;
        for _ in 0..60 {
            for _ in 0..200 {
                let d = V3::new(
                    rng.random_range(-1.0..1.0),
                    rng.random_range(-1.0..1.0),
                    rng.random_range(-1.0..1.0),
                );
                let u = (best.1 + d.scalec(rad)).unit();
                let v = h(u);
                if v < best.0 {
                    best = (v, u);
                }
            }
            rad *= 0.8;
        }
        -best.0
    }

    fn support_dist_2d(pts: &[[f64; 2]]) -> f64 {
        let n = 200_000;
        let mut best = f64::INFINITY;
        for i in 0..n {
            let a = i as f64 / n as f64 * std::f64::consts::TAU;
            let u = [a.cos(), a.sin()];
            let v = pts
                .iter()
                .map(|p| p[0] * u[0] + p[1] * u[1])
                .fold(f64::MIN, f64::max);
            best = best.min(v);
        }
        -best
    }

    /// Guards the 1R value derived in the supplementary notes: ±1 normals give dist = −1;
    /// a single sign has no interior.
    #[test]
    fn hull_1d_signed_distance_and_1r_value() {
        assert_eq!(signed_dist_1d(&[1.0, -1.0, 1.0]), -1.0);
        assert_eq!(signed_dist_1d(&[1.0, 1.0]), NO_INTERIOR_DIST);
        assert_eq!(signed_dist_1d(&[1.0]), NO_INTERIOR_DIST);
        assert_eq!(signed_dist_1d(&[-0.3, 0.8]), -0.3);
        assert!((signed_dist_1d(&[0.2, 0.7]) - 0.2).abs() < 1e-15);
        assert_eq!(signed_dist_1d(&[0.0, 0.7]), 0.0);
    }

    /// Guards the 2-D routine on hand-built cases: square, triangle outside, degenerate
    /// collinear and too-few-point sets.
    #[test]
    fn hull_2d_hand_built_and_degenerate_cases() {
        let sq = [[1.0, 0.0], [0.0, 1.0], [-1.0, 0.0], [0.0, -1.0]];
        assert!((signed_dist_2d(&sq) + 0.5f64.sqrt()).abs() < 1e-12);
        // Triangle to the right of the origin: nearest point (1, 0).
        let tri = [[1.0, -1.0], [1.0, 1.0], [2.0, 0.0]];
        assert!((signed_dist_2d(&tri) - 1.0).abs() < 1e-12);
        // Outside, nearest feature a vertex.
        let tri2 = [[1.0, 1.0], [2.0, 1.0], [1.0, 2.0]];
        assert!((signed_dist_2d(&tri2) - 2f64.sqrt()).abs() < 1e-12);
        // Collinear through the origin: no interior.
        assert_eq!(
            signed_dist_2d(&[[-1.0, -1.0], [1.0, 1.0], [0.5, 0.5]]),
            NO_INTERIOR_DIST
        );
        assert_eq!(signed_dist_2d(&[[-1.0, 0.0], [1.0, 0.0]]), NO_INTERIOR_DIST);
        // Origin on an edge: 0.
        assert!(signed_dist_2d(&[[-1.0, 0.0], [1.0, 0.0], [0.0, 1.0]]).abs() < 1e-12);
    }

    /// Guards the 3-D routine on hand-built cases: octahedron, a tetrahedron off the origin,
    /// coplanar and too-few-point sets.
    #[test]
    fn hull_3d_hand_built_and_degenerate_cases() {
        let oct = [
            [1.0, 0.0, 0.0],
            [-1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [0.0, -1.0, 0.0],
            [0.0, 0.0, 1.0],
            [0.0, 0.0, -1.0],
        ];
        assert!((signed_dist_3d(&oct) + 1.0 / 3f64.sqrt()).abs() < 1e-12);
        let tet = [
            [1.0, 0.0, 0.0],
            [2.0, 0.0, 0.0],
            [1.0, 1.0, 0.0],
            [1.0, 0.0, 1.0],
        ];
        assert!((signed_dist_3d(&tet) - 1.0).abs() < 1e-12);
        let flat = [
            [1.0, 0.0, 0.0],
            [-1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [0.0, -1.0, 0.0],
        ];
        assert_eq!(signed_dist_3d(&flat), NO_INTERIOR_DIST);
        assert_eq!(signed_dist_3d(&oct[..3]), NO_INTERIOR_DIST);
        // Collinear points with one extra: still coplanar.
        let col = [
            [1.0, 0.0, 0.0],
            [2.0, 0.0, 0.0],
            [3.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
        ];
        assert_eq!(signed_dist_3d(&col), NO_INTERIOR_DIST);
    }

    /// Guards `nearest_facet_3d`: on a tetrahedron with one face nearer the origin it gives
    /// that face (its points, its outward normal, its depth); on random sets with the
    /// origin inside its depth is minus `signed_dist_3d`, its normal is a unit vector with
    /// every point at or below the plane and its three points on it; outside the hull, and
    /// for sets without interior, it gives nothing.
    #[test]
    fn nearest_facet_is_the_plane_that_sets_the_distance() {
        // Face z = -0.1 (points 0, 1, 2) is the nearest; the apex is far above.
        let tet = [
            [1.0, 0.0, -0.1],
            [-0.5, 0.8, -0.1],
            [-0.5, -0.8, -0.1],
            [0.0, 0.0, 1.0],
        ];
        let f = nearest_facet_3d(&tet).expect("the origin is inside");
        assert_eq!(f.tri, [0, 1, 2]);
        assert!((f.depth - 0.1).abs() < 1e-12, "{f:?}");
        assert!((f.u[2] + 1.0).abs() < 1e-12, "{f:?}");
        let shifted: Vec<[f64; 3]> = tet.iter().map(|p| [p[0], p[1], p[2] + 0.2]).collect();
        assert_eq!(
            nearest_facet_3d(&shifted),
            None,
            "the origin is below the hull"
        );
        assert_eq!(nearest_facet_3d(&tet[..3]), None);
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        let mut inside = 0;
        for _ in 0..60 {
            let pts: Vec<[f64; 3]> = (0..6)
                .map(|_| {
                    V3::new(
                        rng.random_range(-1.0..1.0) + 0.3,
                        rng.random_range(-1.0..1.0),
                        rng.random_range(-1.0..1.0),
                    )
                    .unit()
                    .vals()
                })
                .collect();
            let d = signed_dist_3d(&pts);
            let Some(f) = nearest_facet_3d(&pts) else {
                assert!(d >= 0.0, "inside ({d}) but no facet");
                continue;
            };
            inside += 1;
            assert!((f.depth + d).abs() < 1e-12, "{f:?} vs {d}");
            let dot = |p: &[f64; 3]| p[0] * f.u[0] + p[1] * f.u[1] + p[2] * f.u[2];
            assert!((dot(&f.u) - 1.0).abs() < 1e-12);
            assert!(pts.iter().all(|p| dot(p) <= f.depth + 1e-12), "{f:?}");
            assert!(f
                .tri
                .iter()
                .all(|&i| (dot(&pts[i]) - f.depth).abs() < 1e-12));
        }
        assert!(
            (10..=50).contains(&inside),
            "{inside} of 60 inside: both cases must occur"
        );
    }

    /// Cross-checks the exact 2-D and 3-D routines against the independent support-function
    /// formula on random unit-vector sets (inside and outside cases).
    #[test]
    fn hull_routines_agree_with_support_function_reference() {
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        for trial in 0..40 {
            let k = 4 + trial % 4;
            let bias: f64 = if trial % 3 == 0 { 0.9 } else { 0.0 };
            let pts: Vec<[f64; 3]> = (0..k)
                .map(|_| {
                    V3::new(
                        rng.random_range(-1.0..1.0) + bias,
                        rng.random_range(-1.0..1.0),
                        rng.random_range(-1.0..1.0),
                    )
                    .unit()
                    .vals()
                })
                .collect();
            let exact = signed_dist_3d(&pts);
            let reference = support_dist_3d(&pts);
            assert!(
                (exact - reference).abs() < 2e-4,
                "3-D trial {trial}: {exact} vs {reference}"
            );
            let p2: Vec<[f64; 2]> = pts[..k - 1]
                .iter()
                .map(|p| {
                    let l = (p[0] * p[0] + p[1] * p[1]).sqrt();
                    [p[0] / l, p[1] / l]
                })
                .collect();
            let e2 = signed_dist_2d(&p2);
            let r2 = support_dist_2d(&p2);
            assert!((e2 - r2).abs() < 1e-4, "2-D trial {trial}: {e2} vs {r2}");
        }
    }

    /// Guards the two readings of Eq. 30: a normal 45° off the contact direction is inside
    /// the `arm` bound (|n·p̂| ≤ cos 10°) but outside the printed one (|n·p̂| ≤ sin 10°); a
    /// normal through the centre is outside both, a tangential one inside both, and the
    /// conventions' 3R robust filter is the printed reading.
    #[test]
    fn normal_cone_readings_of_eq_30() {
        let p = [0.0, 0.0, 3.0];
        let h = std::f64::consts::FRAC_1_SQRT_2;
        let oblique = [h, 0.0, h];
        let through_centre = [0.0, 0.0, -1.0];
        let tangential = [1.0, 0.0, 0.0];
        assert!(NormalCone::Arm.allows(p, oblique));
        assert!(!NormalCone::Tangent.allows(p, oblique));
        for cone in [NormalCone::Arm, NormalCone::Tangent] {
            assert!(!cone.allows(p, through_centre), "{cone:?}");
            assert!(cone.allows(p, tangential), "{cone:?}");
            assert!(!cone.allows([0.0; 3], tangential), "{cone:?} at the centre");
        }
        // Just inside / outside cos 10° (angle to p̂ of 10.5° and 9.5°).
        let tilt = |deg: f64| {
            let a = deg.to_radians();
            [a.sin(), 0.0, a.cos()]
        };
        assert!(NormalCone::Arm.allows(p, tilt(10.5)));
        assert!(!NormalCone::Arm.allows(p, tilt(9.5)));
        assert!(!is_robust(Class::R3, p, oblique));
        assert_eq!(NormalCone::default(), NormalCone::Tangent);
    }

    /// Guards the per-class projection and the robust filter: a tangential push counts, a
    /// radial one does not.
    #[test]
    fn projection_and_robust_filter_per_class() {
        let p = [2.0, 0.0, 0.5];
        let tangential = [0.0, 1.0, 0.0];
        let radial = [-1.0, 0.0, 0.0];
        assert_eq!(project(Class::R1, p, tangential), Some([1.0, 0.0, 0.0]));
        assert_eq!(
            project(Class::R1, p, [0.0, -1.0, 0.0]),
            Some([-1.0, 0.0, 0.0])
        );
        assert!(is_robust(Class::R1, p, tangential));
        assert!(!is_robust(Class::R1, p, radial));
        let slight = [-(1.0f64 - 0.05f64.powi(2)).sqrt(), 0.05, 0.0];
        assert!(!is_robust(Class::R1, p, slight));
        assert!(is_robust(Class::R1T1, p, [0.0, 0.0, 1.0]));
        assert!(is_robust(Class::R3, p, tangential));
        assert!(!is_robust(Class::R3, p, radial));
        let (d, r) = dist_at(
            Class::R1,
            &[(p, tangential), (p, [0.0, -1.0, 0.0]), (p, slight)],
        );
        assert_eq!((d, r), (-1.0, -1.0));
        let (d, r) = dist_at(Class::R1, &[(p, tangential), (p, [-1.0, -0.05, 0.0])]);
        assert_eq!(d, -1.0);
        assert_eq!(r, NO_INTERIOR_DIST);
    }
}
