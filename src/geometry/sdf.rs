//! Implicit solids: signed distance bounds, primitives and constructive solid geometry.
//!
//! Owns the [`Sdf`] trait and the shapes parts are built from: spheres, capsules and thick
//! polylines, finite cylinders, boxes, half-spaces, and the operations union, intersection,
//! difference, offset and rigid transform. A value is negative inside, positive outside,
//! and never larger in magnitude than the distance to the surface (a *bound*, exact for the
//! primitives), so a caller may skip a region whose centre is farther from the surface than
//! the region is wide. CSG by min/max keeps that property. Units are millimetres.
//!
//! It does not mesh (`geometry::mesher`) nor sweep along curves (`geometry::sweep`).

use nalgebra::{Rotation3, Vector3};

use super::mesh::Aabb;

/// A point or vector in mm.
pub type Vec3 = Vector3<f64>;

/// A solid given by a signed distance bound.
pub trait Sdf: Send + Sync {
    /// Signed distance bound at `p`: negative inside, |value| ≤ distance to the surface.
    fn dist(&self, p: Vec3) -> f64;
    /// The same bound, continuous inside as well as outside: a compound solid takes the
    /// smallest value of every part that holds `p`, where [`Sdf::dist`] may stop at the
    /// first (the sign is then settled, which is all a mesher needs, but the value jumps
    /// where another part's turn comes first). Searches that bound a distance's change by
    /// how far the point moved need it ([`crate::build::swept::ExactSweep`]: on the rims of
    /// half-turn-2to1, [`Sdf::dist`] along a point's path jumped by up to 1 mm inside).
    /// Where a solid gives a cheaper lower bound far out, the value may drop to it there;
    /// such a search then errs low, never high.
    ///
    /// The value is exact only below `limit`: at or above it, any value between `limit` and
    /// the exact one may come back (a search that will discard it saves finding it; pass
    /// infinity for the exact value).
    fn dist_continuous(&self, p: Vec3, limit: f64) -> f64 {
        let _ = limit;
        self.dist(p)
    }
    /// A bound on how fast [`Sdf::dist_continuous`] changes, per mm moved: 1 for a true
    /// distance, more for a solid whose value is measured in a frame that turns as the
    /// point moves (a twisted sweep, [`crate::geometry::sweep::Sweep`]).
    fn lipschitz(&self) -> f64 {
        1.0
    }
    /// A box holding the whole solid.
    fn bounds(&self) -> Aabb;
}

impl<T: Sdf + ?Sized> Sdf for Box<T> {
    fn dist(&self, p: Vec3) -> f64 {
        (**self).dist(p)
    }
    fn dist_continuous(&self, p: Vec3, limit: f64) -> f64 {
        (**self).dist_continuous(p, limit)
    }
    fn lipschitz(&self) -> f64 {
        (**self).lipschitz()
    }
    fn bounds(&self) -> Aabb {
        (**self).bounds()
    }
}

impl<T: Sdf + ?Sized> Sdf for std::sync::Arc<T> {
    fn dist(&self, p: Vec3) -> f64 {
        (**self).dist(p)
    }
    fn dist_continuous(&self, p: Vec3, limit: f64) -> f64 {
        (**self).dist_continuous(p, limit)
    }
    fn lipschitz(&self) -> f64 {
        (**self).lipschitz()
    }
    fn bounds(&self) -> Aabb {
        (**self).bounds()
    }
}

/// `[x, y, z]` as a vector.
pub fn v3(a: [f64; 3]) -> Vec3 {
    Vec3::new(a[0], a[1], a[2])
}

/// A vector as `[x, y, z]`.
pub fn arr(v: Vec3) -> [f64; 3] {
    [v.x, v.y, v.z]
}

/// A solid ball.
#[derive(Clone, Debug)]
pub struct Sphere {
    /// Centre.
    pub center: Vec3,
    /// Radius.
    pub radius: f64,
}

impl Sdf for Sphere {
    fn dist(&self, p: Vec3) -> f64 {
        (p - self.center).norm() - self.radius
    }
    fn bounds(&self) -> Aabb {
        Aabb::new(arr(self.center), arr(self.center)).inflate(self.radius)
    }
}

/// Distance from `p` to the segment `a`–`b`.
pub fn segment_distance(p: Vec3, a: Vec3, b: Vec3) -> f64 {
    let e = b - a;
    let l2 = e.norm_squared();
    let s = if l2 > 0.0 {
        ((p - a).dot(&e) / l2).clamp(0.0, 1.0)
    } else {
        0.0
    };
    (p - (a + e * s)).norm()
}

/// A polyline thickened to a radius (a chain of capsules): struts.
#[derive(Clone, Debug)]
pub struct ThickPolyline {
    /// Corner points (at least one).
    pub points: Vec<Vec3>,
    /// Radius.
    pub radius: f64,
}

impl Sdf for ThickPolyline {
    fn dist(&self, p: Vec3) -> f64 {
        let d = if self.points.len() == 1 {
            (p - self.points[0]).norm()
        } else {
            self.points
                .windows(2)
                .map(|w| segment_distance(p, w[0], w[1]))
                .fold(f64::INFINITY, f64::min)
        };
        d - self.radius
    }
    fn bounds(&self) -> Aabb {
        self.points
            .iter()
            .fold(Aabb::EMPTY, |b, q| b.union(&Aabb::new(arr(*q), arr(*q))))
            .inflate(self.radius)
    }
}

/// A finite solid cylinder: radius `radius` about the axis from `base` along the unit
/// `axis` for `length`.
#[derive(Clone, Debug)]
pub struct Cylinder {
    /// Centre of one end face.
    pub base: Vec3,
    /// Unit axis direction (towards the other end face).
    pub axis: Vec3,
    /// Length along the axis.
    pub length: f64,
    /// Radius.
    pub radius: f64,
}

impl Cylinder {
    /// A cylinder along +z from height `z0` to `z1` centred on (x, y).
    pub fn z(x: f64, y: f64, z0: f64, z1: f64, radius: f64) -> Cylinder {
        Cylinder {
            base: Vec3::new(x, y, z0),
            axis: Vec3::z(),
            length: z1 - z0,
            radius,
        }
    }
}

impl Sdf for Cylinder {
    fn dist(&self, p: Vec3) -> f64 {
        let d = p - self.base;
        let h = d.dot(&self.axis);
        let r = (d - self.axis * h).norm();
        let dr = r - self.radius;
        let dh = (-h).max(h - self.length);
        if dr > 0.0 && dh > 0.0 {
            super::sweep::norm2(dr, dh)
        } else {
            dr.max(dh)
        }
    }
    fn bounds(&self) -> Aabb {
        let a = self.base;
        let b = self.base + self.axis * self.length;
        // Exact box of a disc: radius · sqrt(1 − axisₖ²) along each axis k.
        let mut out = Aabb::new(arr(a), arr(a)).union(&Aabb::new(arr(b), arr(b)));
        for k in 0..3 {
            let e = self.radius * (1.0 - self.axis[k] * self.axis[k]).max(0.0).sqrt();
            out.min[k] -= e;
            out.max[k] += e;
        }
        out
    }
}

/// A solid box with half extents `half`, centred at `center`, turned by `rotation`.
#[derive(Clone, Debug)]
pub struct Cuboid {
    /// Centre.
    pub center: Vec3,
    /// Half extents along the box's own axes.
    pub half: Vec3,
    /// Orientation of the box's axes.
    pub rotation: Rotation3<f64>,
}

impl Cuboid {
    /// An axis-aligned box from `min` to `max`.
    pub fn aligned(min: Vec3, max: Vec3) -> Cuboid {
        Cuboid {
            center: (min + max) * 0.5,
            half: (max - min) * 0.5,
            rotation: Rotation3::identity(),
        }
    }
}

impl Sdf for Cuboid {
    fn dist(&self, p: Vec3) -> f64 {
        let q = self.rotation.inverse() * (p - self.center);
        let d = q.abs() - self.half;
        let outside = Vec3::new(d.x.max(0.0), d.y.max(0.0), d.z.max(0.0)).norm();
        outside + d.x.max(d.y).max(d.z).min(0.0)
    }
    fn bounds(&self) -> Aabb {
        let m = self.rotation.matrix();
        let mut e = [0.0; 3];
        for (k, ek) in e.iter_mut().enumerate() {
            *ek = (0..3).map(|j| m[(k, j)].abs() * self.half[j]).sum();
        }
        Aabb::new(arr(self.center), arr(self.center)).union(&Aabb::new(
            [
                self.center.x - e[0],
                self.center.y - e[1],
                self.center.z - e[2],
            ],
            [
                self.center.x + e[0],
                self.center.y + e[1],
                self.center.z + e[2],
            ],
        ))
    }
}

/// The half-space on the side of `point` opposite to the unit `normal`, clipped to a box
/// (so that it has bounds): the points x with (x − point)·normal ≤ 0 inside `clip`.
#[derive(Clone, Debug)]
pub struct HalfSpace {
    /// A point on the plane.
    pub point: Vec3,
    /// Unit normal pointing out of the solid.
    pub normal: Vec3,
    /// Where the solid may be non-empty (a bound for pruning; not a face).
    pub clip: Aabb,
}

impl Sdf for HalfSpace {
    fn dist(&self, p: Vec3) -> f64 {
        (p - self.point).dot(&self.normal)
    }
    fn bounds(&self) -> Aabb {
        self.clip
    }
}

/// Union of solids. Children whose boxes are farther than the best value so far are
/// skipped, so a union of many small parts costs little away from them.
pub struct Union {
    children: Vec<Box<dyn Sdf>>,
    bounds: Aabb,
    /// The children's largest.
    lipschitz: f64,
}

impl Union {
    /// The union of `children` (at least one).
    pub fn new(children: Vec<Box<dyn Sdf>>) -> Union {
        let bounds = children
            .iter()
            .fold(Aabb::EMPTY, |b, c| b.union(&c.bounds()));
        let lipschitz = children.iter().map(|c| c.lipschitz()).fold(1.0, f64::max);
        Union {
            children,
            bounds,
            lipschitz,
        }
    }

    /// The smallest `value` of the children (each told the best so far, and the first told
    /// `limit`; `limit` comes back when none is below it), skipping those that cannot win: a child
    /// cannot be nearer than its box, so it is skipped unless its box is within the best
    /// distance so far. Inside a child already (best < 0) the sign is settled and, unless
    /// `every_holder`, the rest are skipped; exactly on a child's face (best = 0) a child
    /// whose box holds p may still hold p inside, so it is looked at: skipping it made a
    /// plane of zeros where a face of one child lies inside another, and a mesher node on
    /// that plane cut the part in two there (the 1R1T support's clamp ring came off the
    /// base plate).
    fn smallest(
        &self,
        p: Vec3,
        every_holder: bool,
        limit: f64,
        value: impl Fn(&dyn Sdf, f64) -> f64,
    ) -> f64 {
        let pa = arr(p);
        let mut best = limit;
        for c in &self.children {
            let d = c.bounds().distance(pa);
            let settled = best < 0.0 && !every_holder;
            if best.is_finite() && d >= best.max(0.0) && (d > 0.0 || settled) {
                continue;
            }
            best = best.min(value(c.as_ref(), best));
        }
        if best.is_finite() {
            best
        } else {
            self.bounds.distance(pa).max(f64::MIN_POSITIVE)
        }
    }
}

impl Sdf for Union {
    fn dist(&self, p: Vec3) -> f64 {
        self.smallest(p, false, f64::INFINITY, |c, _| c.dist(p))
    }
    fn dist_continuous(&self, p: Vec3, limit: f64) -> f64 {
        self.smallest(p, true, limit, |c, best| c.dist_continuous(p, best))
    }
    fn lipschitz(&self) -> f64 {
        self.lipschitz
    }
    fn bounds(&self) -> Aabb {
        self.bounds
    }
}

/// `base` minus every solid of `cut`.
pub struct Difference {
    base: Box<dyn Sdf>,
    cut: Vec<Box<dyn Sdf>>,
}

impl Difference {
    /// `base` with `cut` removed.
    pub fn new(base: Box<dyn Sdf>, cut: Vec<Box<dyn Sdf>>) -> Difference {
        Difference { base, cut }
    }
}

impl Sdf for Difference {
    fn dist(&self, p: Vec3) -> f64 {
        let pa = arr(p);
        let mut v = self.base.dist(p);
        for c in &self.cut {
            // max(v, −c) changes only where c < −v; c ≥ its box distance.
            if c.bounds().distance(pa) >= -v {
                continue;
            }
            v = v.max(-c.dist(p));
        }
        v
    }
    fn bounds(&self) -> Aabb {
        self.base.bounds()
    }
}

/// Intersection of solids.
pub struct Intersection {
    children: Vec<Box<dyn Sdf>>,
}

impl Intersection {
    /// The common part of `children` (at least one).
    pub fn new(children: Vec<Box<dyn Sdf>>) -> Intersection {
        Intersection { children }
    }
}

impl Sdf for Intersection {
    fn dist(&self, p: Vec3) -> f64 {
        self.children
            .iter()
            .map(|c| c.dist(p))
            .fold(f64::NEG_INFINITY, f64::max)
    }
    fn bounds(&self) -> Aabb {
        let mut b = self.children[0].bounds();
        for c in &self.children[1..] {
            let o = c.bounds();
            for k in 0..3 {
                b.min[k] = b.min[k].max(o.min[k]);
                b.max[k] = b.max[k].min(o.max[k]);
            }
        }
        b
    }
}

/// A solid grown (positive `by`) or shrunk (negative) by a distance: exact for exact
/// distances, a bound otherwise.
pub struct Offset<S> {
    /// The solid.
    pub inner: S,
    /// Distance, mm.
    pub by: f64,
}

impl<S: Sdf> Sdf for Offset<S> {
    fn dist(&self, p: Vec3) -> f64 {
        self.inner.dist(p) - self.by
    }
    fn bounds(&self) -> Aabb {
        self.inner.bounds().inflate(self.by.max(0.0))
    }
}

/// Closest point to `p` on the triangle (a, b, c), by the triangle's Voronoi regions.
pub fn closest_on_triangle(p: Vec3, a: Vec3, b: Vec3, c: Vec3) -> Vec3 {
    let (ab, ac, ap) = (b - a, c - a, p - a);
    let (d1, d2) = (ab.dot(&ap), ac.dot(&ap));
    if d1 <= 0.0 && d2 <= 0.0 {
        return a;
    }
    let bp = p - b;
    let (d3, d4) = (ab.dot(&bp), ac.dot(&bp));
    if d3 >= 0.0 && d4 <= d3 {
        return b;
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        return a + ab * (d1 / (d1 - d3));
    }
    let cp = p - c;
    let (d5, d6) = (ab.dot(&cp), ac.dot(&cp));
    if d6 >= 0.0 && d5 <= d6 {
        return c;
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        return a + ac * (d2 / (d2 - d6));
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        return b + (c - b) * ((d4 - d3) / ((d4 - d3) + (d5 - d6)));
    }
    let denom = 1.0 / (va + vb + vc);
    a + ab * (vb * denom) + ac * (vc * denom)
}

/// Triangles thickened to a half thickness: a plate around a surface given as triangles
/// (the webs that close the follower's rims).
pub struct ThickTriangles {
    tris: Vec<[Vec3; 3]>,
    bvh: super::sweep::Bvh,
    half_thickness: f64,
}

impl ThickTriangles {
    /// The points within `half_thickness` of `tris`.
    pub fn new(tris: Vec<[Vec3; 3]>, half_thickness: f64) -> ThickTriangles {
        let boxes: Vec<Aabb> = tris
            .iter()
            .map(|t| {
                t.iter()
                    .fold(Aabb::EMPTY, |b, v| b.union(&Aabb::new(arr(*v), arr(*v))))
                    .inflate(half_thickness)
            })
            .collect();
        let bvh = super::sweep::Bvh::new(&boxes);
        ThickTriangles {
            tris,
            bvh,
            half_thickness,
        }
    }

    /// Half the plate's thickness, mm.
    pub fn half_thickness(&self) -> f64 {
        self.half_thickness
    }

    /// The point of the triangles (the plate's mid-surface) nearest to `p` and its distance,
    /// when one is within `reach`; `None` otherwise, or for no triangles.
    pub fn nearest_within(&self, p: Vec3, reach: f64) -> Option<(Vec3, f64)> {
        self.nearest_below(p, reach - self.half_thickness)
            .map(|(foot, v)| (foot, v + self.half_thickness))
    }

    /// The foot on the mid-surface nearest to `p` and the plate's value there (distance
    /// less the half thickness), when that value is below `limit`. Every triangle whose
    /// plate holds `p` is visited, not only the first: the nearest foot is the deepest.
    pub fn nearest_below(&self, p: Vec3, limit: f64) -> Option<(Vec3, f64)> {
        let mut nearest = None;
        let mut best = limit;
        // The boxes are the triangles' grown by the half thickness: their distance is a
        // lower bound on a triangle's plate value.
        self.bvh.min_over(arr(p), limit, true, |i, _| {
            let [a, b, c] = self.tris[i];
            let q = closest_on_triangle(p, a, b, c);
            let v = (p - q).norm() - self.half_thickness;
            if v < best {
                best = v;
                nearest = Some((q, v));
            }
            v
        });
        nearest
    }
}

impl Sdf for ThickTriangles {
    /// Exact inside as well as out: every triangle whose plate holds `p` is visited, not
    /// only the first. The first holder's value is anything between 0 and −half_thickness
    /// (the fan's triangles are slivers, and a point on one lies within the half thickness
    /// of its neighbours' planes), and the follower's shrink by half the clearance turned
    /// every value above −c/2 outside: demo's webs came out riddled with voids and films
    /// (a point on a web's mid-surface read −0.001 to −0.09 instead of −1.2).
    fn dist(&self, p: Vec3) -> f64 {
        let far = super::sweep::SWEEP_EXACT_WITHIN_MM;
        match self.nearest_below(p, far) {
            Some((_, v)) => v,
            None => self.bvh.bounds().distance(arr(p)).max(far),
        }
    }
    fn bounds(&self) -> Aabb {
        self.bvh.bounds()
    }
}

/// A solid cut by a field: `solid` where `field` ≥ `margin` (the field is a distance bound
/// to what must stay clear, e.g. another part's swept volume).
pub struct KeepClear<'a, S> {
    /// The solid.
    pub solid: S,
    /// Distance to what the solid must keep clear of.
    pub field: &'a (dyn Fn(Vec3) -> f64 + Sync),
    /// Clearance to keep.
    pub margin: f64,
}

impl<S: Sdf> Sdf for KeepClear<'_, S> {
    fn dist(&self, p: Vec3) -> f64 {
        let v = self.solid.dist(p);
        if v > 0.0 {
            return v;
        }
        v.max(self.margin - (self.field)(p))
    }
    fn bounds(&self) -> Aabb {
        self.solid.bounds()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Guards [`Sdf::dist_continuous`] of a union: inside two overlapping balls it is the
    /// smaller of the two values whichever ball comes first, where [`Sdf::dist`] may stop
    /// at the first ball that holds the point (its sign is all a mesher needs).
    #[test]
    fn a_union_s_continuous_value_is_the_least_over_every_holder() {
        let ball = |x: f64, r: f64| -> Box<dyn Sdf> {
            Box::new(Sphere {
                center: Vec3::new(x, 0.0, 0.0),
                radius: r,
            })
        };
        let p = Vec3::new(1.0, 0.0, 0.0);
        for union in [
            Union::new(vec![ball(0.0, 1.5), ball(2.0, 5.0)]),
            Union::new(vec![ball(2.0, 5.0), ball(0.0, 1.5)]),
        ] {
            // Depths 0.5 and 4.
            assert_eq!(union.dist_continuous(p, f64::INFINITY), -4.0);
            assert!(union.dist(p) < 0.0);
        }
    }

    /// Guards the union's pruning on a face: a point on one child's face inside another
    /// child is inside the union (it used to read 0, and a mesher node there split the part).
    #[test]
    fn a_face_inside_another_child_is_inside_the_union() {
        let plate = Cuboid::aligned(Vec3::new(-20.0, -20.0, 0.0), Vec3::new(20.0, 20.0, 5.0));
        let boss = Cylinder::z(-10.0, 0.0, -12.0, 5.0, 7.0);
        let u = Union::new(vec![Box::new(plate), Box::new(boss)]);
        // On the plate's bottom face, inside the boss's wall.
        let v = u.dist(Vec3::new(-4.0, 0.0, 0.0));
        assert!(v < 0.0, "{v}");
        assert!((v + 1.0).abs() < 1e-12, "{v}");
        // On the face, outside the boss: on the surface.
        assert_eq!(u.dist(Vec3::new(10.0, 0.0, 0.0)), 0.0);
    }

    /// Primitive distances are exact at probe points whose answers are known by hand.
    #[test]
    fn primitive_distances() {
        let s = Sphere {
            center: Vec3::new(1.0, 0.0, 0.0),
            radius: 2.0,
        };
        assert_eq!(s.dist(Vec3::new(4.0, 0.0, 0.0)), 1.0);
        assert_eq!(s.dist(Vec3::new(1.0, 0.0, 0.0)), -2.0);

        let c = Cylinder::z(0.0, 0.0, 0.0, 10.0, 2.0);
        assert_eq!(c.dist(Vec3::new(5.0, 0.0, 5.0)), 3.0);
        assert_eq!(c.dist(Vec3::new(0.0, 0.0, 12.0)), 2.0);
        assert_eq!(c.dist(Vec3::new(0.0, 0.0, 5.0)), -2.0);
        assert!((c.dist(Vec3::new(5.0, 0.0, 14.0)) - 5.0).abs() < 1e-12);

        let b = Cuboid::aligned(Vec3::new(0.0, 0.0, 0.0), Vec3::new(2.0, 4.0, 6.0));
        assert_eq!(b.dist(Vec3::new(1.0, 2.0, 3.0)), -1.0);
        assert_eq!(b.dist(Vec3::new(5.0, 2.0, 3.0)), 3.0);
        let bb = b.bounds();
        assert_eq!((bb.min, bb.max), ([0.0; 3], [2.0, 4.0, 6.0]));

        let t = ThickPolyline {
            points: vec![Vec3::zeros(), Vec3::new(10.0, 0.0, 0.0)],
            radius: 1.0,
        };
        assert_eq!(t.dist(Vec3::new(5.0, 3.0, 0.0)), 2.0);
        assert_eq!(t.dist(Vec3::new(-3.0, 0.0, 0.0)), 2.0);
    }

    /// Union skipping far children gives the same values as evaluating all of them, and a
    /// difference removes what it should.
    #[test]
    fn csg_values() {
        let parts: Vec<Box<dyn Sdf>> = (0..10)
            .map(|i| {
                Box::new(Sphere {
                    center: Vec3::new(5.0 * i as f64, 0.0, 0.0),
                    radius: 1.0,
                }) as Box<dyn Sdf>
            })
            .collect();
        let u = Union::new(parts);
        for k in 0..200 {
            let p = Vec3::new(k as f64 * 0.27 - 3.0, 0.7, -0.2);
            let all = (0..10)
                .map(|i| (p - Vec3::new(5.0 * i as f64, 0.0, 0.0)).norm() - 1.0)
                .fold(f64::INFINITY, f64::min);
            assert!((u.dist(p) - all).abs() < 1e-12, "at {p:?}");
        }
        let d = Difference::new(
            Box::new(Cuboid::aligned(Vec3::repeat(-5.0), Vec3::repeat(5.0))),
            vec![Box::new(Cylinder::z(0.0, 0.0, -10.0, 10.0, 2.0))],
        );
        assert!(d.dist(Vec3::new(0.0, 0.0, 0.0)) > 0.0);
        assert!(d.dist(Vec3::new(3.0, 0.0, 0.0)) < 0.0);
    }

    /// Guards [`ThickTriangles`]' value inside: on a web-like fan of 360 slivers from a
    /// centre to a wavy loop of 30 mm radius, every point of the mid-surface is the half
    /// thickness deep and every point half that far off it half as deep, whichever sliver
    /// the search meets first. (The first holder's value had been as shallow as −0.001,
    /// and the shrink by half the clearance left voids all through the follower's webs.)
    #[test]
    fn a_thick_fan_is_as_deep_as_its_nearest_sliver() {
        let n = 360;
        let loop_at = |i: usize| {
            let a = std::f64::consts::TAU * (i % n) as f64 / n as f64;
            Vec3::new(30.0 * a.cos(), 30.0 * a.sin(), 2.0 * (3.0 * a).sin())
        };
        let centre = Vec3::zeros();
        let tris: Vec<[Vec3; 3]> = (0..n)
            .map(|i| [centre, loop_at(i), loop_at(i + 1)])
            .collect();
        let h = 1.2;
        let web = ThickTriangles::new(tris.clone(), h);
        let mut checked = 0;
        for (i, [a, b, c]) in tris.iter().enumerate().step_by(11) {
            let normal = (b - a).cross(&(c - a)).normalize();
            for w in [[0.6, 0.2, 0.2], [0.2, 0.4, 0.4], [0.05, 0.5, 0.45]] {
                let foot = a * w[0] + b * w[1] + c * w[2];
                // Only where the foot is the nearest point of the whole fan to the points
                // off it (not across a fold).
                let off = foot + normal * (0.5 * h);
                let nearest = tris
                    .iter()
                    .map(|[a, b, c]| (off - closest_on_triangle(off, *a, *b, *c)).norm())
                    .fold(f64::INFINITY, f64::min);
                if (nearest - 0.5 * h).abs() > 1e-9 {
                    continue;
                }
                assert!(
                    (web.dist(foot) + h).abs() < 1e-9,
                    "sliver {i}: {}",
                    web.dist(foot)
                );
                assert!(
                    (web.dist(off) + 0.5 * h).abs() < 1e-9,
                    "sliver {i}: {}",
                    web.dist(off)
                );
                checked += 1;
            }
        }
        assert!(checked >= 50, "{checked} points checked");
    }

    /// The closest point on a triangle is right in each Voronoi region (vertex, edge, face),
    /// checked against a dense sampling of the triangle.
    #[test]
    fn closest_point_on_triangle() {
        let (a, b, c) = (
            Vec3::new(0.0, 0.0, 0.0),
            Vec3::new(4.0, 0.0, 0.0),
            Vec3::new(1.0, 3.0, 0.0),
        );
        let mut samples = Vec::new();
        for i in 0..=200 {
            for j in 0..=(200 - i) {
                let (u, v) = (i as f64 / 200.0, j as f64 / 200.0);
                samples.push(a + (b - a) * u + (c - a) * v);
            }
        }
        for k in 0..60 {
            let p = Vec3::new(
                (k as f64 * 0.91).sin() * 6.0 + 1.5,
                (k as f64 * 1.7).cos() * 5.0 + 1.0,
                (k as f64 * 0.37).sin() * 2.0,
            );
            let q = closest_on_triangle(p, a, b, c);
            let brute = samples
                .iter()
                .map(|s| (p - s).norm())
                .fold(f64::INFINITY, f64::min);
            assert!((p - q).norm() <= brute + 1e-9, "{p:?}");
            assert!((p - q).norm() >= brute - 0.03, "{p:?}");
        }
    }
}
