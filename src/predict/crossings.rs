//! The free motions of a follower about its joint axis (1R: turns; 1R1T: turns, slides and
//! the screws between), from where each vertex's path crosses the other part's faces.
//!
//! Owns [`free_along`], the counterpart of
//! [`play::free_along`](super::play::free_along) that `predict` uses whenever the follower
//! moves about R's z axis (through `free_along_binned`, with the follower's bins made
//! while its queries were). It answers the same question (how far the follower can move from
//! its design pose along a screw about that axis, either way, before a vertex of one part
//! meets a face of the other, capped) with the same tests (every follower vertex against
//! the driver's faces and every driver vertex against the follower's), but exactly and in
//! bulk rather than by sphere-tracing each vertex with mesh queries:
//!
//! - Everything is seen from the follower's frame F, whose z axis is the joint axis: the
//!   follower stands still and the driver is placed by the design motion at each time.
//!   Moving the follower by s along a screw moves each of its vertices by s, and each
//!   driver vertex by −s.
//! - A vertex turned about z stays at its distance ρ from the axis; a turn keeps its
//!   height z too, a slide or a screw moves it along z by the screw's rise. So the only
//!   faces it can meet are those whose footprint in (ρ, z) holds its own (or the heights
//!   it rises through). The follower's vertices and faces are sorted once into bins of
//!   (ρ, z) ([`BIN_MM`]), each bin's entries ordered by polar angle, so the candidates of a
//!   driver face or vertex are a binary search away. Along a screw the polar angle and the
//!   height both grow in proportion to s, so a face's box of angles and heights gives an
//!   interval of s that the path must meet.
//! - Where a circle crosses a face's plane is a quadratic in tan(β/2). Along a helix the
//!   plane's value is u cos ωs + v sin ωs + k s + w: cut where its derivative vanishes (in
//!   closed form), each monotone piece holds at most one root, found by Newton's steps
//!   kept in its bracket; along a slide it is linear. A root within the search limit that
//!   lies in the triangle is a crossing, entering or leaving by the face's outward normal.
//!   A vertex's first crossing each way that enters is its free motion that way; no step
//!   size, no distance tolerance.
//! - Only crossings that enter the other part are kept, and a driver face is looked up only
//!   from the ways a point moving by the screw can enter it (`Limit::entering`: its
//!   normal against the point's velocity, which is linear over the triangle). On the
//!   examples' parts all but 0.4 % of the driver faces near the follower are entered one
//!   way only, so their windows of polar angles lose the other way's side.
//! - A vertex that would decide a free motion is first asked its exact distance to the
//!   other part: one inside it at the design pose is not counted (it would lock the
//!   follower where the meshes already overlap) but reported as overlap, and the next
//!   vertex in order is asked. The driver answers from its clusters
//!   ([`Solid::signed_near`]), so it never makes parry's hierarchy: about 3 200 such
//!   questions a period on half-turn-2to1's parts, 0.2 s of the two cores, where the
//!   hierarchy and its pseudo-normals took 3.35 s to make. Overlaps where no vertex would
//!   stop the follower are not looked for: the build's check measures the parts'
//!   interference.
//! - Only the driver's clusters near the follower are looked at, by the same carried lower
//!   bounds the tracer uses (`Solid`'s distance grid, the cluster's last bound and the
//!   parts' speed bound), and within them only vertices and faces whose own bounds leave
//!   them within reach of the search limit: first their offset from the cluster's centre,
//!   then the grid's bound at each vertex (a face's: its corners' largest less its longest
//!   edge) against the length of its own path. No mesh query is asked to choose them.
//! - Each way has its own limit. At each time the elements that decided the last time's
//!   free motions are looked at first (`Run::seeds`): what they allow now bounds each way
//!   from above, and the whole pass then looks only within that bound, each way's polar
//!   angles cut to its own. The pass still meets every element that could cross sooner,
//!   so the free motions are the same as with one wide limit: to the last bit for a turn
//!   or a slide, and to the rounding of a screw's root (its Newton's steps start from a
//!   bracket cut at the limit).
//!
//! Edge-against-edge contacts are not tested, as in the tracer: two sharp edges that cross
//! can each go inside the other by up to half an edge before a vertex meets a face, so a
//! free motion may be that much long where two ridges meet first. Measured with a probe
//! (2026-12-07, not committed) at both ends of every free turn on the two printable designs'
//! parts (1 440 angles, the follower's sharp convex edges against the driver, as the build's
//! check tests them): the deepest was 0.0044 mm inside on half-turn-2to1's and 0.0126 mm on
//! screw-bob's, a quarter of the interference the check accepts and less. Those parts
//! were not simplified. The build now simplifies its meshes within 0.01 mm
//! (`geometry::simplify`), and an edge along a straight ridge may then reach 2 mm; the probe
//! was not run again. The predicted laws of half-turn-2to1's parts simplified and not
//! differ by at most 0.053° (0.028 mm at a 30 mm arm), which bounds what longer ridges
//! changed there.
//!
//! On half-turn-2to1's printable parts (1 327 228 + 685 584 vertices, 1 440 driver angles)
//! the turns take 5.1–6.0 s (`mpc-rig simulate`; 5.5–6.3 s before the faces' ways, 7.1–8.1 s
//! before the seeds and the per-point bounds, 22.7 s with the tracer); on screw-bob's
//! (1R1T, 1 509 566 + 660 284 vertices) the four lines take 22–25 s (41 s before, 53 s
//! with the tracer). docs/simulate.md, "Exact free turns", "Seeded, each way its own" and
//! "A driver face looked up only from the ways it can be entered". Simplified (340 052 +
//! 189 768 vertices; 367 289 + 192 992 for screw-bob), on a faster machine where the parts
//! above took 3.8–3.9 s and 18.6 s: 1.9 s and 9.0 s ("Simplified parts").

use std::f64::consts::{PI, TAU};

use nalgebra::{Isometry3, Point3, Vector3};
use rayon::prelude::*;

use super::play::{FreeTurns, PartMotion, Screw, Solid, F32_SLACK_MM, ON_AXIS_MM};
use crate::geometry::sdf::{segment_distance, Vec3};

/// Edge of the (ρ, z) bins the follower's vertices and faces are sorted into, mm. 0.5 mm:
/// about one edge of the default 0.4 mm meshes, so a face's footprint spans a few bins and
/// a bin holds a few vertices of each surface the circle crosses.
pub const BIN_MM: f64 = 0.5;
/// A follower whose pose moves its z axis off R's by more than this (mm of the origin, and
/// the sine of the tilt) does not turn about that axis, and is left to the tracer.
const AXIS_TOLERANCE: f64 = 1e-9;
/// Slack of the inside test, relative to the squared edge: a circle through an edge
/// shared by two faces crosses both, so none slips between them.
const EDGE_SLACK: f64 = 1e-9;
/// The search limit at a time is the last time's larger free motion times this, plus
/// [`FLOOR_OF_CAP`] of the cap. A pass costs about in proportion to its limit (the reach it
/// looks within), and one that finds a free motion at its limit is run again wider. 1.25:
/// on the demo's parts at 1 440 times the larger free turn grows at most 1.21 times from
/// one time to the next, so no pass there is run twice.
const GROWTH: f64 = 1.25;
/// See [`GROWTH`]: 1 % of the cap (0.1° of `simulate`'s 10° turn, 0.05 mm of its 5.2 mm
/// slide), so parts that touch at one time still search a useful motion at the next.
const FLOOR_OF_CAP: f64 = 0.01;
/// A pass that finds a free turn at its limit is run again with the limit times this (up
/// to the cap): a free turn that jumps (a contact lost) takes a few passes, not one at the
/// whole cap each time.
const RETRY_GROWTH: f64 = 4.0;
/// Runs of consecutive times per thread: each run starts without carried bounds, so a few
/// per thread balance the load at little cost.
const RUNS_PER_THREAD: usize = 4;

/// The free motions of the follower along each of `lines` (a screw about R's z axis and
/// its cap, in the screw's unit) at `n` times per period, one [`FreeTurns`] per line in
/// their order: the counterpart of [`play::free_along`](super::play::free_along). `None`
/// when the follower's design pose moves its axis off R's z axis (use the tracer).
pub fn free_along(
    motion: &dyn PartMotion,
    driver: &Solid,
    follower: &Solid,
    n: usize,
    lines: &[(Screw, f64)],
) -> Option<Vec<FreeTurns>> {
    free_along_binned(motion, driver, follower, None, n, lines)
}

/// [`free_along`] with the follower's bins made already ([`Bins::new`]), or made here
/// when `None`: `simulate` makes them while the follower's queries are being made.
pub(super) fn free_along_binned(
    motion: &dyn PartMotion,
    driver: &Solid,
    follower: &Solid,
    bins: Option<&Bins>,
    n: usize,
    lines: &[(Screw, f64)],
) -> Option<Vec<FreeTurns>> {
    let about_z = (0..n).all(|i| {
        let f = motion.follower(i as f64 / n as f64);
        (f.rotation * Vector3::z() - Vector3::z()).norm() < AXIS_TOLERANCE
            && f.translation.vector.xy().norm() < AXIS_TOLERANCE
    });
    if !about_z {
        return None;
    }
    // Only the follower's distance grid is asked (where the driver's clusters are), so
    // the driver's is never made; the follower's is made beside its bins.
    let ((made, edges), ()) = rayon::join(
        || {
            rayon::join(
                || bins.is_none().then(|| Bins::new(follower)),
                || longest_edges(driver),
            )
        },
        || follower.prepare_bounds(),
    );
    let bins = bins.or(made.as_ref()).expect("bins given or made");
    let runs = (rayon::current_num_threads() * RUNS_PER_THREAD).clamp(1, n.max(1));
    let per_run = n.div_ceil(runs);
    let along = |screw: Screw, cap: f64| {
        let centres_before = driver.centre_queries() + follower.centre_queries();
        // Each run's scratch is dropped as it ends; only its figures are kept.
        let results: Vec<RunFigures> = (0..runs)
            .into_par_iter()
            .map(|k| {
                let mut run = Run::new(motion, driver, follower, bins, &edges, screw, cap);
                for i in (k * per_run)..((k + 1) * per_run).min(n) {
                    run.sample(i as f64 / n as f64);
                }
                (run.free, run.queries, run.overlap)
            })
            .collect();
        let mut out = FreeTurns {
            plus: Vec::with_capacity(n),
            minus: Vec::with_capacity(n),
            overlap_mm: 0.0,
            overlap_t: 0.0,
            queries: driver.centre_queries() + follower.centre_queries() - centres_before,
        };
        for (free, queries, overlap) in results {
            out.plus.extend(free.iter().map(|f| f[0]));
            out.minus.extend(free.iter().map(|f| f[1]));
            out.queries += queries;
            if overlap.0 > out.overlap_mm {
                (out.overlap_mm, out.overlap_t) = overlap;
            }
        }
        out
    };
    Some(
        lines
            .iter()
            .map(|&(screw, cap)| along(screw, cap))
            .collect(),
    )
}

/// What a run leaves: the free turns per time, its queries, its deepest overlap and when.
type RunFigures = (Vec<[f64; 2]>, u64, (f64, f64));

/// A triangle's footprint about the z axis: the ranges of its points' distance from the
/// axis, height and polar angle (`lo` in [−π, π), the angle growing `span` from it; the
/// whole circle for a triangle about the axis).
#[derive(Clone, Copy, Debug)]
struct Footprint {
    rho_lo: f64,
    rho_hi: f64,
    z_lo: f64,
    z_hi: f64,
    lo: f64,
    span: f64,
}

impl Footprint {
    fn of(c: &[Point3<f64>; 3]) -> Footprint {
        Footprint::with(
            c,
            c.map(|p| p.coords.xy().norm()),
            c.map(|p| p.y.atan2(p.x)),
        )
    }

    /// The footprint of the triangle `c` whose corners' distances from the axis and polar
    /// angles are `rho` and `theta`.
    fn with(c: &[Point3<f64>; 3], rho: [f64; 3], theta: [f64; 3]) -> Footprint {
        let rho_hi = rho[0].max(rho[1]).max(rho[2]);
        let rho_lo = nearest_to_axis(c, rho);
        let z_lo = c[0].z.min(c[1].z).min(c[2].z);
        let z_hi = c[0].z.max(c[1].z).max(c[2].z);
        let (lo, span) = if rho_lo <= ON_AXIS_MM {
            (-PI, TAU)
        } else {
            // A convex set that leaves the origin out is seen from it within a half turn,
            // and its extreme directions are corners.
            let a0 = theta[0];
            let rel = theta.map(|a| wrap(a - a0));
            let lo = rel.iter().copied().fold(f64::INFINITY, f64::min);
            let hi = rel.iter().copied().fold(f64::NEG_INFINITY, f64::max);
            (wrap(a0 + lo), hi - lo)
        };
        Footprint {
            rho_lo,
            rho_hi,
            z_lo,
            z_hi,
            lo,
            span,
        }
    }

    fn holds(&self, rho: f64, z: f64) -> bool {
        rho >= self.rho_lo && rho <= self.rho_hi && z >= self.z_lo && z <= self.z_hi
    }
}

/// Whether a point at polar angle `theta` and height `z`, moved by the limit's screw by
/// some s in `ab` (within ±limit), can come within the box of polar angles from `lo` to
/// `lo + span` (`angles`) and heights from `z_lo` to `z_hi` (`heights`); its distance from
/// the axis does not change. Along the path both grow in proportion to s, so each gives an
/// interval of s. The callers have widened the box for rounding.
fn path_meets(
    theta: f64,
    z: f64,
    lim: &Limit,
    ab: [f64; 2],
    [lo, span]: [f64; 2],
    [z_lo, z_hi]: [f64; 2],
) -> bool {
    let (om, sg) = (lim.screw.spin, lim.screw.slide);
    let [mut a, mut b] = ab;
    if sg == 0.0 {
        if z < z_lo || z > z_hi {
            return false;
        }
    } else {
        let (s1, s2) = ((z_lo - z) / sg, (z_hi - z) / sg);
        a = a.max(s1.min(s2));
        b = b.min(s1.max(s2));
        if a > b {
            return false;
        }
    }
    // The box's angles from the point's: [d, d + span] and its copies a turn either way
    // (the path turns by less than π each way; its limit is a fraction of a turn).
    let d = wrap(lo - theta);
    if om == 0.0 {
        return (d <= 0.0 && d + span >= 0.0) || d - TAU + span >= 0.0;
    }
    [d + TAU, d, d - TAU].into_iter().any(|d| {
        let (s1, s2) = (d / om, (d + span) / om);
        a.max(s1.min(s2)) <= b.min(s1.max(s2))
    })
}

/// The angle `a` taken into [−π, π). Angles here are sums and differences of a few polar
/// angles and turns within a half turn, so a few steps of a full turn do; a remainder
/// would cost more than the rest of a face's test.
fn wrap(a: f64) -> f64 {
    if !a.is_finite() {
        return a;
    }
    if a.abs() > 4.0 * TAU {
        return (a + PI).rem_euclid(TAU) - PI;
    }
    let mut w = a;
    while w >= PI {
        w -= TAU;
    }
    while w < -PI {
        w += TAU;
    }
    w
}

/// A lower bound on the distance from the z axis to the triangle `c`, whose corners are
/// `rho` from it. Where the nearest corner is farther than the longest edge (in the xy
/// plane), the axis is outside the triangle's shadow and an edge dips towards it at most
/// as a chord of that length does, so √(ρ² − e²/4) bounds it at the cost of a square root;
/// otherwise the exact distance.
fn nearest_to_axis(c: &[Point3<f64>; 3], rho: [f64; 3]) -> f64 {
    let near = rho[0].min(rho[1]).min(rho[2]);
    let edge2 = (0..3)
        .map(|k| (c[(k + 1) % 3].xy() - c[k].xy()).norm_squared())
        .fold(0.0, f64::max);
    if near * near > edge2 {
        (near * near - edge2 / 4.0).sqrt()
    } else {
        distance_to_origin_2d(c)
    }
}

/// Distance from the z axis to the triangle: from the origin to its projection on the
/// xy plane (0 when the projection holds the origin).
fn distance_to_origin_2d(c: &[Point3<f64>; 3]) -> f64 {
    let p = c.map(|v| [v.x, v.y]);
    let cross = |a: [f64; 2], b: [f64; 2]| a[0] * b[1] - a[1] * b[0];
    let s = [0, 1, 2].map(|k| cross(p[k], p[(k + 1) % 3]));
    if (s[0] >= 0.0 && s[1] >= 0.0 && s[2] >= 0.0) || (s[0] <= 0.0 && s[1] <= 0.0 && s[2] <= 0.0) {
        return 0.0;
    }
    let flat = |k: usize| Vec3::new(p[k][0], p[k][1], 0.0);
    (0..3)
        .map(|k| segment_distance(Vec3::zeros(), flat(k), flat((k + 1) % 3)))
        .fold(f64::INFINITY, f64::min)
}

/// The ranges of `keys` (sorted, in [−π, π), each an f32 rounding of an angle) that hold
/// every angle on the arc from `a` to `b` (b ≥ a) round the circle: one or two runs,
/// widened by [`ANGLE_SLACK`] for the rounding. A run is found by a binary search for its
/// start and a walk to its end, which is near: the keys are compact so that the search
/// touches few cache lines, the cost that dominated the bins' lookups.
fn on_arc(keys: &[f32], a: f64, b: f64) -> [std::ops::Range<usize>; 2] {
    if b - a >= TAU - 2.0 * ANGLE_SLACK {
        return [0..keys.len(), 0..0];
    }
    let start = wrap(a) - ANGLE_SLACK;
    let end = start + (b - a) + 2.0 * ANGLE_SLACK;
    let run = |lo: f64, hi: f64| {
        let (lo, hi) = (lo as f32, hi as f32);
        let i = keys.partition_point(|&k| k < lo);
        let mut j = i;
        while j < keys.len() && keys[j] <= hi {
            j += 1;
        }
        i..j
    };
    if end < PI {
        [run(start, end), 0..0]
    } else {
        [run(start, PI), run(-PI, end - TAU)]
    }
}

/// Slack of [`Limit::entering`], relative to the speed of a face's fastest corner: a face
/// whose corners all move out along its normal by less than this is taken to be entered
/// both ways. 1e-6: many orders above the rounding of the velocity and of a crossing a hair
/// outside the triangle (1e-9 of an edge), and it keeps only faces within about 1e-6 rad
/// of parallel to the motion both ways.
const DIRECTION_SLACK: f64 = 1e-6;

/// Widening of a window of polar angles for their rounding to f32 in the bins' keys, rad:
/// an f32 near π is within 2.4e-7 of the angle it rounds.
const ANGLE_SLACK: f64 = 1e-6;

/// A follower vertex in its bin.
#[derive(Clone, Copy, Debug)]
struct VertexEntry {
    theta: f64,
    rho: f64,
    z: f64,
    id: u32,
}

/// A follower face in a bin its footprint meets.
#[derive(Clone, Copy, Debug)]
struct FaceEntry {
    lo: f64,
    /// The face's footprint in (ρ, z), widened to f32 outwards: kept with the entry so that
    /// the faces a vertex is tested against are read in order, not fetched one by one.
    rho_lo: f32,
    rho_hi: f32,
    z_lo: f32,
    z_hi: f32,
    id: u32,
    /// The footprint's angular span from `lo`, widened by [`ANGLE_SLACK`].
    span: f32,
}

impl FaceEntry {
    fn new(f: &Footprint, id: usize) -> FaceEntry {
        let down = |x: f64| (x - F32_SLACK_MM) as f32;
        let up = |x: f64| (x + F32_SLACK_MM) as f32;
        FaceEntry {
            lo: f.lo,
            rho_lo: down(f.rho_lo),
            rho_hi: up(f.rho_hi),
            z_lo: down(f.z_lo),
            z_hi: up(f.z_hi),
            id: id as u32,
            span: (f.span + ANGLE_SLACK) as f32,
        }
    }

    /// Whether the footprint holds a point at `rho` with a height from `z_lo` to `z_hi`
    /// (perhaps a hair beyond it).
    fn holds(&self, rho: f32, z_lo: f32, z_hi: f32) -> bool {
        rho >= self.rho_lo && rho <= self.rho_hi && z_hi >= self.z_lo && z_lo <= self.z_hi
    }
}

/// A triangle's plane: its unit outward normal and offset (n · x = d on the plane).
#[derive(Clone, Copy, Debug)]
struct Plane {
    n: Vector3<f64>,
    d: f64,
}

impl Plane {
    fn of(c: &[Point3<f64>; 3]) -> Option<Plane> {
        let n = (c[1] - c[0]).cross(&(c[2] - c[0])).try_normalize(0.0)?;
        Some(Plane {
            n,
            d: n.dot(&c[0].coords),
        })
    }
}

/// The follower's vertices and faces sorted into (ρ, z) bins of [`BIN_MM`], each bin's by
/// polar angle.
pub(super) struct Bins {
    z0: f64,
    n_rho: usize,
    n_z: usize,
    vert_start: Vec<u32>,
    verts: Vec<VertexEntry>,
    /// The vertices' polar angles, in the order of `verts`.
    vert_keys: Vec<f32>,
    face_start: Vec<u32>,
    faces: Vec<FaceEntry>,
    /// The faces' least polar angles, in the order of `faces`.
    face_keys: Vec<f32>,
    /// Per bin, the widest angular span of its faces.
    face_span: Vec<f64>,
    /// Per follower face (the order of `Solid::tris`), its plane.
    planes: Vec<Option<Plane>>,
}

impl Bins {
    /// The follower's vertices and faces sorted into bins of (ρ, z) ([`BIN_MM`]), each
    /// bin's in order of polar angle.
    pub(super) fn new(follower: &Solid) -> Bins {
        let corners = |t: &[u32; 3]| t.map(|v| follower.verts[v as usize]);
        let footprints: Vec<Footprint> = follower
            .tris
            .par_iter()
            .map(|t| Footprint::of(&corners(t)))
            .collect();
        let planes: Vec<Option<Plane>> = follower
            .tris
            .par_iter()
            .map(|t| Plane::of(&corners(t)))
            .collect();
        let rho_max = footprints.iter().map(|f| f.rho_hi).fold(0.0, f64::max);
        let z_lo = footprints
            .iter()
            .map(|f| f.z_lo)
            .fold(f64::INFINITY, f64::min);
        let z_hi = footprints
            .iter()
            .map(|f| f.z_hi)
            .fold(f64::NEG_INFINITY, f64::max);
        let z0 = if z_lo.is_finite() { z_lo } else { 0.0 };
        let mut bins = Bins {
            z0,
            n_rho: (rho_max / BIN_MM).floor() as usize + 1,
            n_z: ((z_hi - z0).max(0.0) / BIN_MM).floor() as usize + 1,
            vert_start: Vec::new(),
            verts: Vec::new(),
            vert_keys: Vec::new(),
            face_start: Vec::new(),
            faces: Vec::new(),
            face_keys: Vec::new(),
            face_span: Vec::new(),
            planes,
        };
        let mut verts: Vec<(usize, VertexEntry)> = follower
            .verts
            .iter()
            .enumerate()
            .filter_map(|(id, p)| {
                let rho = p.coords.xy().norm();
                let bin = bins.bin(rho, p.z)?;
                Some((
                    bin,
                    VertexEntry {
                        theta: wrap(p.y.atan2(p.x)),
                        rho,
                        z: p.z,
                        id: id as u32,
                    },
                ))
            })
            .collect();
        verts.par_sort_unstable_by(|a, b| {
            (a.0, a.1.theta)
                .partial_cmp(&(b.0, b.1.theta))
                .expect("finite")
        });
        bins.vert_start = starts(verts.iter().map(|v| v.0), bins.len());
        bins.verts = verts.into_iter().map(|v| v.1).collect();
        bins.vert_keys = bins.verts.iter().map(|v| v.theta as f32).collect();
        let mut faces: Vec<(usize, FaceEntry)> = Vec::new();
        for (id, f) in footprints.iter().enumerate() {
            bins.for_bins(f, |bin| faces.push((bin, FaceEntry::new(f, id))));
        }
        faces.par_sort_unstable_by(|a, b| {
            (a.0, a.1.lo).partial_cmp(&(b.0, b.1.lo)).expect("finite")
        });
        bins.face_start = starts(faces.iter().map(|f| f.0), bins.len());
        let mut span = vec![0.0f64; bins.len()];
        for (bin, f) in &faces {
            span[*bin] = span[*bin].max(footprints[f.id as usize].span);
        }
        bins.face_span = span;
        bins.faces = faces.into_iter().map(|f| f.1).collect();
        bins.face_keys = bins.faces.iter().map(|f| f.lo as f32).collect();
        bins
    }

    fn len(&self) -> usize {
        self.n_rho * self.n_z
    }

    /// The bin of a point at distance `rho` from the axis and height `z`, if any.
    fn bin(&self, rho: f64, z: f64) -> Option<usize> {
        let (r, h) = (rho / BIN_MM, (z - self.z0) / BIN_MM);
        // Both are at least 0 here, where truncation is the floor.
        if !(r >= 0.0 && h >= 0.0) || r as usize >= self.n_rho || h as usize >= self.n_z {
            return None;
        }
        Some(r as usize * self.n_z + h as usize)
    }

    /// Calls `each` with every bin at distance `rho` from the axis from height `z_lo` to
    /// `z_hi`.
    fn for_column(&self, rho: f64, z_lo: f64, z_hi: f64, each: impl FnMut(usize)) {
        let column = Footprint {
            rho_lo: rho,
            rho_hi: rho,
            z_lo,
            z_hi,
            lo: -PI,
            span: TAU,
        };
        self.for_bins(&column, each);
    }

    /// Calls `f` with every bin the footprint meets.
    fn for_bins(&self, f: &Footprint, mut each: impl FnMut(usize)) {
        // Clamped at 0 first, where truncation is the floor.
        let cell = |x: f64, n: usize| ((x / BIN_MM).max(0.0) as usize).min(n);
        let (r0, r1) = (cell(f.rho_lo, self.n_rho), cell(f.rho_hi, self.n_rho - 1));
        if f.z_hi < self.z0 {
            return;
        }
        let (h0, h1) = (
            cell(f.z_lo - self.z0, self.n_z),
            cell(f.z_hi - self.z0, self.n_z - 1),
        );
        for r in r0..=r1.min(self.n_rho - 1) {
            for h in h0..=h1.min(self.n_z - 1) {
                each(r * self.n_z + h);
            }
        }
    }

    /// The vertices of `bin` whose polar angle lies on the arc from `a` to `b`.
    fn verts_on_arc(&self, bin: usize, a: f64, b: f64) -> impl Iterator<Item = &VertexEntry> {
        bin_on_arc(&self.vert_start, &self.vert_keys, &self.verts, bin, a, b)
    }

    /// The faces of `bin` whose least polar angle lies on the arc from `a` to `b`.
    fn faces_on_arc(&self, bin: usize, a: f64, b: f64) -> impl Iterator<Item = &FaceEntry> {
        bin_on_arc(&self.face_start, &self.face_keys, &self.faces, bin, a, b)
    }
}

/// The entries of `bin` (its run of `items` from `start[bin]` to `start[bin + 1]`, sorted
/// by `keys`) whose key lies on the arc from `a` to `b`.
fn bin_on_arc<'a, T>(
    start: &[u32],
    keys: &[f32],
    items: &'a [T],
    bin: usize,
    a: f64,
    b: f64,
) -> impl Iterator<Item = &'a T> {
    let (s, e) = (start[bin] as usize, start[bin + 1] as usize);
    on_arc(&keys[s..e], a, b)
        .into_iter()
        .flat_map(move |r| &items[s + r.start..s + r.end])
}

/// Start offsets of each bin's run in a list sorted by bin (one more than bins).
fn starts(sorted_bins: impl Iterator<Item = usize>, bins: usize) -> Vec<u32> {
    let mut count = vec![0u32; bins + 1];
    for b in sorted_bins {
        count[b + 1] += 1;
    }
    for i in 0..bins {
        count[i + 1] += count[i];
    }
    count
}

/// The search limit of one pass: the follower's motion `screw` by a parameter s with
/// −`ways[1]` ≤ s ≤ `ways[0]` (rad for a turn, mm for a slide, the screw's own unit
/// otherwise). The roots and bounds take the larger of the two both ways (`limit`); the
/// windows of polar angles are cut to each way's own, and a driver face's to the ways it
/// can be entered from ([`Limit::entering`]).
#[derive(Clone, Copy, Debug)]
struct Limit {
    screw: Screw,
    ways: [f64; 2],
    limit: f64,
    /// How far a follower point's polar angle can grow (`up`) and fall (`down`) within the
    /// limits each way, rad.
    up: f64,
    down: f64,
    /// The largest turn and rise within the limit: |spin|·limit rad, |slide|·limit mm.
    turn: f64,
    rise: f64,
    /// cos(turn) and sin(turn): how far the turning part of a plane's value can change
    /// along the path ([`Limit::turning_reach`]), and a screw's path at its ends (±limit)
    /// without another sine or cosine.
    cos: f64,
    sin: f64,
    /// tan(turn / 2): the largest root taken by a pure turn's quadratic.
    tau: f64,
}

impl Limit {
    fn new(screw: Screw, ways: [f64; 2]) -> Limit {
        let limit = ways[0].max(ways[1]);
        let turn = screw.spin.abs() * limit;
        let [up, down] = if screw.spin >= 0.0 {
            ways
        } else {
            [ways[1], ways[0]]
        }
        .map(|l| screw.spin.abs() * l);
        // The windows of angles, the paths' boxes and the screws' cuts assume less.
        debug_assert!(turn < PI, "a search limit of {turn} rad of turn");
        Limit {
            screw,
            ways,
            limit,
            up,
            down,
            turn,
            rise: screw.slide.abs() * limit,
            cos: turn.cos(),
            sin: turn.sin(),
            tau: (turn / 2.0).tan(),
        }
    }

    /// How far u cos β + v sin β can move from its value at β = 0 over the turns within
    /// the limit: |u|(1 − cos) + |v| sin while they stay within a quarter turn, the whole
    /// swing 2·|(u, v)| beyond.
    fn turning_reach(&self, u: f64, v: f64) -> f64 {
        if self.turn <= std::f64::consts::FRAC_PI_2 {
            u.abs() * (1.0 - self.cos) + v.abs() * self.sin
        } else {
            2.0 * u.hypot(v)
        }
    }

    /// A turn about +z, found by the quadratic in tan(β/2): its crossings are recorded in
    /// tan(β/2) ([`Limit::param`] turns that into β).
    fn pure_turn(&self) -> bool {
        self.screw.slide == 0.0 && self.screw.spin > 0.0
    }

    /// The interval [a, b] of s (a ≤ 0 ≤ b, within the limits each way) along which a
    /// follower vertex can enter a driver face with these corners and unit outward normal:
    /// `None` when it can enter from neither way. A point moving by the screw enters where
    /// its velocity ω z × q + σ z points against the normal, and that velocity's component
    /// along the normal is linear in q, so its least and largest over the triangle are at
    /// the corners: a face whose every corner moves out along its normal as s grows is
    /// entered only as s falls, and the other way round. On the examples' parts all but
    /// 0.4 % of the driver faces near the follower are entered one way only. `far` is the
    /// corners' largest distance from the axis.
    fn entering(&self, c: &[Point3<f64>; 3], n: &Vector3<f64>, far: f64) -> Option<[f64; 2]> {
        let (om, sg) = (self.screw.spin, self.screw.slide);
        let along = c.map(|q| om * (n.y * q.x - n.x * q.y) + n.z * sg);
        let lo = along[0].min(along[1]).min(along[2]);
        let hi = along[0].max(along[1]).max(along[2]);
        // The crossing's point may lie a hair outside the triangle (`EDGE_SLACK`): a
        // slack relative to the fastest a corner moves keeps a face that is nearly
        // parallel to the motion both ways.
        let slack = DIRECTION_SLACK * (om.abs() * (far + 1.0) + sg.abs());
        let growing = lo < slack;
        let falling = hi > -slack;
        (growing || falling).then(|| {
            [
                if falling { -self.ways[1] } else { 0.0 },
                if growing { self.ways[0] } else { 0.0 },
            ]
        })
    }

    /// The parameter of a crossing recorded as `key`.
    fn param(&self, key: f64) -> f64 {
        if self.pure_turn() {
            2.0 * key.atan() / self.screw.spin
        } else {
            key
        }
    }
}

/// Where the path of `p` moved by the screw (|s| within the limit) crosses the triangle `c`
/// on `plane`: calls `hit` with the crossing's key (tan(β/2) for a pure turn, s otherwise;
/// both grow with s) and whether the point enters the face's part there as s grows.
fn crossings(
    p: &Point3<f64>,
    plane: &Plane,
    c: &[Point3<f64>; 3],
    lim: &Limit,
    hit: impl FnMut(f64, bool),
) {
    if lim.pure_turn() {
        turn_crossings(p, plane, c, lim, hit);
    } else {
        screw_crossings(p, plane, c, lim, hit);
    }
}

/// The terms of a plane's value along a point's turn about z by β:
/// n · R(β) p − d = u cos β + v sin β + w, as (u, v, w) (a rise adds n_z times itself).
fn plane_terms(p: &Point3<f64>, plane: &Plane) -> (f64, f64, f64) {
    let n = &plane.n;
    (
        n.x * p.x + n.y * p.y,
        n.y * p.x - n.x * p.y,
        n.z * p.z - plane.d,
    )
}

/// `p` turned about z by the angle whose cosine and sine are given, and raised by `rise`.
fn moved(p: &Point3<f64>, cos: f64, sin: f64, rise: f64) -> Point3<f64> {
    Point3::new(p.x * cos - p.y * sin, p.x * sin + p.y * cos, p.z + rise)
}

/// [`crossings`] for a pure turn: where the circle meets the plane is a quadratic in
/// tan(β/2).
fn turn_crossings(
    p: &Point3<f64>,
    plane: &Plane,
    c: &[Point3<f64>; 3],
    lim: &Limit,
    mut hit: impl FnMut(f64, bool),
) {
    let n = &plane.n;
    let (u, v, w) = plane_terms(p, plane);
    let at_zero = u + w;
    if at_zero.abs() > lim.turning_reach(u, v) + 1e-12 {
        return;
    }
    // With τ = tan(β/2): (w − u) τ² + 2 v τ + (u + w) = 0.
    let (a, b, cc) = (w - u, 2.0 * v, at_zero);
    let mut roots = [f64::NAN; 2];
    if a.abs() <= 1e-14 * (b.abs() + cc.abs()) {
        if b != 0.0 {
            roots[0] = -cc / b;
        }
    } else {
        let disc = b * b - 4.0 * a * cc;
        if disc < 0.0 {
            return;
        }
        let q = -0.5 * (b + b.signum() * disc.sqrt());
        roots[0] = q / a;
        if q != 0.0 {
            roots[1] = cc / q;
        }
    }
    for tau in roots {
        // NaN: no such root.
        if tau.is_nan() || tau.abs() > lim.tau {
            continue;
        }
        let den = 1.0 + tau * tau;
        let q = moved(p, (1.0 - tau * tau) / den, 2.0 * tau / den, 0.0);
        if inside(c, n, &q) {
            // The point's velocity as β grows is z × q.
            hit(tau, n.y * q.x - n.x * q.y < 0.0);
        }
    }
}

/// Newton steps of a screw's root at most; each halves the bracket at least (a step that
/// would leave it is a bisection), and a smooth monotone piece takes about five.
const ROOT_STEPS: usize = 80;

/// [`crossings`] for a slide or a screw: the plane's value along the helix,
/// g(s) = u cos ωs + v sin ωs + k s + w, is split where its derivative vanishes (in closed
/// form), and each monotone piece whose ends differ in sign holds one root, found by
/// Newton's steps kept inside the bracket.
fn screw_crossings(
    p: &Point3<f64>,
    plane: &Plane,
    c: &[Point3<f64>; 3],
    lim: &Limit,
    mut hit: impl FnMut(f64, bool),
) {
    let n = &plane.n;
    let (om, sg) = (lim.screw.spin, lim.screw.slide);
    let (u, v, w) = plane_terms(p, plane);
    let k = n.z * sg;
    if u == 0.0 && v == 0.0 && k == 0.0 {
        // The path runs in a plane parallel to the face's: on it (flush) it slides along
        // the face and enters nothing.
        return;
    }
    let at_zero = u + w;
    // Along the path the rising part changes by |k| per unit.
    if at_zero.abs() > lim.turning_reach(u, v) + k.abs() * lim.limit + 1e-12 {
        return;
    }
    // Closer: g(s) lies within ω²A·s²/2 of its tangent at 0 (|g''| ≤ ω²A, A = |(u, v)|),
    // so a side whose tangent stays that far from 0 at both ends holds no root. Most
    // faces near the path end here, before any sine or cosine.
    let a = (u * u + v * v).sqrt();
    let slope = om * v + k;
    let bend = 0.5 * om * om * a * lim.limit * lim.limit + 1e-12;
    let clear = |end: f64| (at_zero > bend && end > bend) || (at_zero < -bend && end < -bend);
    let (plus_clear, minus_clear) = (
        clear(at_zero + slope * lim.limit),
        clear(at_zero - slope * lim.limit),
    );
    if plus_clear && minus_clear {
        return;
    }
    let g = |s: f64| {
        let (sin, cos) = (om * s).sin_cos();
        u * cos + v * sin + k * s + w
    };
    let dg = |s: f64| {
        let (sin, cos) = (om * s).sin_cos();
        om * (v * cos - u * sin) + k
    };
    // g at ±limit from the limit's own cosine and sine (ω·limit = ±turn).
    let sin_end = lim.sin.copysign(om);
    let g_end = |sign: f64| u * lim.cos + sign * v * sin_end + sign * k * lim.limit + w;
    // Where g' = 0: v cos x − u sin x = A cos(x + φ) = −k/ω, with x = ωs: two per turn,
    // so room for three turns (the lines `predict` asks turn by a fraction of one).
    let mut cuts = [f64::NAN; 8];
    let mut m_cuts = 0;
    if om != 0.0 && a > 0.0 && (k / (om * a)).abs() <= 1.0 {
        let base = (-k / (om * a)).acos();
        let phi = u.atan2(v);
        let reach = (lim.turn / TAU).ceil() as i32 + 1;
        for m in -reach..=reach {
            for x in [base - phi, -base - phi] {
                let s = (x + TAU * f64::from(m)) / om;
                if s.abs() < lim.limit && m_cuts < cuts.len() {
                    cuts[m_cuts] = s;
                    m_cuts += 1;
                }
            }
        }
    }
    let cuts = &mut cuts[..m_cuts];
    cuts.sort_by(f64::total_cmp);
    let mut found = |s: f64| {
        let (sin, cos) = (om * s).sin_cos();
        let q = moved(p, cos, sin, sg * s);
        if inside(c, n, &q) {
            // The point's velocity as s grows is ω z × q + σ z.
            hit(s, om * (n.y * q.x - n.x * q.y) + k < 0.0);
        }
    };
    let mut lo = -lim.limit;
    let mut g_lo = g_end(-1.0);
    let ends = cuts.iter().copied().chain(std::iter::once(lim.limit));
    for hi in ends {
        let g_hi = if hi == lim.limit { g_end(1.0) } else { g(hi) };
        // A piece on a side the tangent test cleared holds no root.
        let skip = (hi <= 0.0 && minus_clear) || (lo >= 0.0 && plus_clear);
        if !skip {
            if g_lo == 0.0 {
                found(lo);
            } else if g_lo.signum() != g_hi.signum() && g_hi != 0.0 {
                found(bracketed_root(&g, &dg, lo, hi, g_lo, at_zero, slope));
            }
        }
        (lo, g_lo) = (hi, g_hi);
    }
    if g_lo == 0.0 {
        found(lo);
    }
}

/// The root of `g` between `lo` and `hi`, where g is monotone and `g_lo` = g(lo) and g(hi)
/// differ in sign: Newton's steps from where the tangent at 0 (`at_zero`, `slope`) meets 0
/// (the bracket's middle if that is outside it), a step that would leave the bracket taken
/// as a bisection, until the bracket or the step is at the last bits.
fn bracketed_root(
    g: &impl Fn(f64) -> f64,
    dg: &impl Fn(f64) -> f64,
    mut lo: f64,
    mut hi: f64,
    g_lo: f64,
    at_zero: f64,
    slope: f64,
) -> f64 {
    let rising = g_lo < 0.0;
    let guess = -at_zero / slope;
    let mut s = if guess > lo && guess < hi {
        guess
    } else {
        0.5 * (lo + hi)
    };
    for _ in 0..ROOT_STEPS {
        let gs = g(s);
        if gs == 0.0 {
            return s;
        }
        if (gs < 0.0) == rising {
            lo = s;
        } else {
            hi = s;
        }
        let d = dg(s);
        let newton = s - gs / d;
        let next = if d != 0.0 && newton > lo && newton < hi {
            newton
        } else {
            0.5 * (lo + hi)
        };
        if next == s || hi - lo <= 4.0 * f64::EPSILON * s.abs().max(lo.abs()).max(hi.abs()) {
            return next;
        }
        s = next;
    }
    s
}

/// Whether `q`, on the triangle's plane, lies in the triangle (edges included).
fn inside(c: &[Point3<f64>; 3], n: &Vector3<f64>, q: &Point3<f64>) -> bool {
    (0..3).all(|k| {
        let e = c[(k + 1) % 3] - c[k];
        e.cross(&(q - c[k])).dot(n) >= -EDGE_SLACK * e.norm_squared()
    })
}

/// A vertex's first entering crossing each way along its path, in |key| (tan(β/2) for a
/// pure turn, |s| otherwise): index 0 as s grows, 1 as it falls. Crossings that leave the
/// other part are not kept: a vertex that leaves it first is inside it, which the exact
/// distance asked of a vertex before it decides a free motion finds ([`Run::decide`]).
#[derive(Clone, Copy, Debug)]
struct Firsts {
    enter: [f64; 2],
    /// The face (an index into the other part's triangles) of each way's `enter`.
    by: [u32; 2],
}

impl Firsts {
    const NONE: Firsts = Firsts {
        enter: [f64::INFINITY; 2],
        by: [u32::MAX; 2],
    };

    /// A crossing at `key` of the face `by`, entering the face's part if the vertex's own
    /// motion grows (`enters_growing`), leaving it otherwise.
    fn add(&mut self, key: f64, enters_growing: bool, by: u32) {
        let k = if enters_growing && key >= 0.0 {
            0
        } else if !enters_growing && key <= 0.0 {
            1
        } else {
            return;
        };
        if key.abs() < self.enter[k] {
            self.enter[k] = key.abs();
            self.by[k] = by;
        }
    }

    /// Whether the vertex enters the other part either way within the limit.
    fn enters(&self) -> bool {
        self.enter.iter().any(|e| e.is_finite())
    }

    /// The free motion each way, in the screw's parameter (beyond every limit when nothing
    /// is entered).
    fn free(&self, lim: &Limit) -> [f64; 2] {
        self.enter.map(|key| lim.param(key))
    }
}

/// A driver vertex placed in F: where, its distance from the axis and its polar angle.
#[derive(Clone, Copy, Debug)]
struct Placed {
    p: Point3<f64>,
    rho: f64,
    theta: f64,
    /// A lower bound on its distance to the follower, mm (`Solid::lower_bound`).
    far: f64,
}

/// A lower bound on the distance from the follower to the driver face with these corners
/// and this longest edge: every point of a triangle lies within its longest edge of each
/// corner.
fn face_far(c: &[Placed; 3], longest_edge: f32) -> f64 {
    c[0].far.max(c[1].far).max(c[2].far) - f64::from(longest_edge)
}

/// Per triangle of `solid`, its longest edge, mm, rounded up to f32.
fn longest_edges(solid: &Solid) -> Vec<f32> {
    solid
        .tris
        .par_iter()
        .map(|t| {
            let c = t.map(|v| solid.verts[v as usize]);
            let longest = (0..3)
                .map(|k| (c[(k + 1) % 3] - c[k]).norm())
                .fold(0.0, f64::max);
            (longest + F32_SLACK_MM) as f32
        })
        .collect()
}

/// The largest distance from the z axis of the corners.
fn max_rho(c: &[Placed; 3]) -> f64 {
    c[0].rho.max(c[1].rho).max(c[2].rho)
}

/// The element whose crossing decided a free motion one way.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Decisive {
    /// A driver vertex (an index into the driver's vertices) against the follower's faces.
    DriverVertex(u32),
    /// A follower vertex against the driver face `face` (indices into the follower's
    /// vertices and the driver's triangles).
    FollowerVertex { vertex: u32, face: u32 },
}

/// One run of consecutive times, with what it carries from one to the next.
struct Run<'a> {
    motion: &'a dyn PartMotion,
    driver: &'a Solid,
    follower: &'a Solid,
    bins: &'a Bins,
    /// Per driver triangle, its longest edge ([`longest_edges`]).
    edges: &'a [f32],
    /// The follower's motion and its cap, in the screw's unit.
    screw: Screw,
    cap: f64,
    /// Per driver cluster, bounds on its points' speed seen from the follower and on their
    /// distance from the axis (how far they move per radian of turn).
    speed: Vec<f64>,
    reach: Vec<f64>,
    /// Per driver cluster, its last distance to the follower and when.
    last: Vec<(f64, f64)>,
    /// Per follower vertex, the pass that last met it and its slot in `firsts`.
    seen: Vec<(u32, u32)>,
    /// The follower vertices met in this pass and their crossings.
    firsts: Vec<(u32, Firsts)>,
    /// Per driver vertex, the pass that last placed it and its slot in `placed`.
    placed_at: Vec<(u32, u32)>,
    /// The driver vertices placed in this pass.
    placed: Vec<Placed>,
    /// The free motions the pass met under each way's limit: (free, way, element).
    candidates: Vec<(f64, u8, Decisive)>,
    pass: u32,
    /// Free turns of the follower per time, [positive sense, negative sense], rad.
    free: Vec<[f64; 2]>,
    /// The elements that decided the last time's free motions, each way.
    decisive: [Option<Decisive>; 2],
    queries: u64,
    overlap: (f64, f64),
}

impl<'a> Run<'a> {
    fn new(
        motion: &'a dyn PartMotion,
        driver: &'a Solid,
        follower: &'a Solid,
        bins: &'a Bins,
        edges: &'a [f32],
        screw: Screw,
        cap: f64,
    ) -> Run<'a> {
        let speed = driver
            .clusters
            .iter()
            .map(|c| motion.driver_speed(&c.center))
            .collect();
        let reach = driver
            .clusters
            .iter()
            .map(|c| c.tri_radius + motion.driver_reach(&c.center))
            .collect();
        Run {
            motion,
            driver,
            follower,
            bins,
            edges,
            screw,
            cap,
            speed,
            reach,
            last: vec![(f64::NEG_INFINITY, 0.0); driver.clusters.len()],
            seen: vec![(0, 0); follower.verts.len()],
            firsts: Vec::new(),
            placed_at: vec![(0, 0); driver.verts.len()],
            placed: Vec::new(),
            candidates: Vec::new(),
            pass: 0,
            free: Vec::new(),
            decisive: [None; 2],
            queries: 0,
            overlap: (0.0, 0.0),
        }
    }

    /// The free motions at time `t`. Each way is first bounded by the element that decided
    /// it at the last time ([`Run::seeds`]): a free motion no larger than that element's
    /// own at this time. Each way is then searched within that bound, or, where there is
    /// none, within [`GROWTH`] times the larger of the last time's plus [`FLOOR_OF_CAP`] of
    /// the cap (that floor alone at a run's first time), then [`RETRY_GROWTH`] times wider
    /// while it reaches its limit, up to the cap. A pass costs about in proportion to its
    /// limit, so a run's first time, from the floor, costs a fraction of one at the cap.
    fn sample(&mut self, t: f64) {
        let to_f = self.motion.follower(t).inverse() * self.motion.driver(t);
        let guess = match self.free.last() {
            None => FLOOR_OF_CAP * self.cap,
            Some(f) => (GROWTH * f[0].max(f[1]) + FLOOR_OF_CAP * self.cap).min(self.cap),
        };
        let (seeds, by) = self.seeds(t, &to_f, guess);
        let mut ways = [0, 1].map(|k| seeds[k].min(guess));
        let bounded = [0, 1].map(|k| seeds[k] <= guess);
        loop {
            let (free, decided) = self.pass_at(t, &to_f, ways, bounded, by);
            let open = [0, 1].map(|k| decided[k].is_none() && ways[k] < self.cap);
            if !open[0] && !open[1] {
                self.free.push(free);
                self.decisive = decided;
                return;
            }
            for k in 0..2 {
                if open[k] {
                    ways[k] = (ways[k] * RETRY_GROWTH).min(self.cap);
                }
            }
        }
    }

    /// The last time's deciding elements at time `t` (driver → F by `to_f`), each searched
    /// within `guess` both ways: per way the least free motion they allow and the element
    /// that allows it (infinite and `None` where none does within `guess`). The true free
    /// motion is no larger: the pass meets the same element and finds the same crossing.
    /// A driver vertex is looked up as in a pass. A follower vertex meets the faces of the
    /// driver cluster that holds the face it met (which has moved on), not all of the
    /// driver's. Either counts only when an exact distance puts it outside the other part,
    /// as in a pass.
    fn seeds(
        &mut self,
        t: f64,
        to_f: &Isometry3<f64>,
        guess: f64,
    ) -> ([f64; 2], [Option<Decisive>; 2]) {
        let mut seeds = [f64::INFINITY; 2];
        let mut by = [None; 2];
        let elements = self.decisive;
        if elements.iter().all(Option::is_none) {
            return (seeds, by);
        }
        let lim = Limit::new(self.screw, [guess; 2]);
        self.pass += 1;
        self.firsts.clear();
        self.placed.clear();
        for (k, element) in elements.iter().enumerate() {
            let Some(element) = *element else { continue };
            if k == 1 && elements[0] == Some(element) {
                continue;
            }
            let free = match element {
                Decisive::DriverVertex(vi) => {
                    let p = self.place(vi as usize, to_f);
                    self.driver_vertex(&p, &lim)
                }
                Decisive::FollowerVertex { vertex, face } => {
                    // The face has moved on: the vertex meets its cluster's faces.
                    let clusters = &self.driver.clusters;
                    let ci = clusters.partition_point(|c| c.tri_end <= face as usize);
                    let Some(c) = clusters.get(ci) else { continue };
                    let p = self.follower.verts[vertex as usize];
                    let mut firsts = Firsts::NONE;
                    for ti in c.tri_start..c.tri_end {
                        let corners = self.driver.tris[ti].map(|v| self.place(v as usize, to_f).p);
                        if let Some(plane) = Plane::of(&corners) {
                            crossings(&p, &plane, &corners, &lim, |tau, up| {
                                firsts.add(tau, up, ti as u32)
                            });
                        }
                    }
                    firsts.enters().then(|| firsts.free(&lim))
                }
            };
            // Beyond `guess` a way is not bounded (a way nothing enters shows the cap of
            // its parameter, half a turn for a turn).
            let Some(free) = free.filter(|f| f.iter().any(|&f| f <= guess)) else {
                continue;
            };
            if self.inside(element, to_f, t) {
                continue;
            }
            for (j, f) in free.into_iter().enumerate() {
                if f <= guess && f < seeds[j] {
                    seeds[j] = f;
                    by[j] = Some(element);
                }
            }
        }
        (seeds, by)
    }

    /// One pass at time `t` (driver → F by `to_f`) within `ways` (the follower's motion's
    /// limits each way): per way, the free motion (at most its limit) and the element that
    /// decides it, `None` where none does within the limit. A way that is `bounded` starts
    /// from its limit as a free motion already met, by the element `by`.
    fn pass_at(
        &mut self,
        t: f64,
        to_f: &Isometry3<f64>,
        ways: [f64; 2],
        bounded: [bool; 2],
        by: [Option<Decisive>; 2],
    ) -> ([f64; 2], [Option<Decisive>; 2]) {
        let lim = Limit::new(self.screw, ways);
        let limit = lim.limit;
        let screw = self.screw;
        self.pass += 1;
        self.firsts.clear();
        self.placed.clear();
        self.candidates.clear();
        let driver = self.driver;
        for (ci, c) in driver.clusters.iter().enumerate() {
            let (d_last, t_last) = self.last[ci];
            let lower = d_last - self.speed[ci] * (t - t_last) - c.tri_radius;
            if lower > screw.lever(self.reach[ci]) * limit {
                continue;
            }
            let w = to_f * c.center;
            // How far the cluster's points move per unit of the motion, at most.
            let lever = screw.lever(w.coords.xy().norm() + c.tri_radius);
            let within = c.tri_radius + lever * limit;
            let d = self.follower.lower_bound(&w);
            self.last[ci] = (d, t);
            if d > within {
                continue;
            }
            // Each vertex and face: its distance to the follower is at least the centre's
            // less its offset from the centre, and the motion moves it at most `lever` per
            // unit.
            let near = |offset: f32| d - f64::from(offset) - F32_SLACK_MM <= lever * limit;
            for vi in c.start..c.end {
                if near(driver.vert_offset[vi]) {
                    let p = self.place(vi, to_f);
                    // Its path is no shorter than the distance it must cover.
                    if p.far > screw.lever(p.rho) * limit {
                        continue;
                    }
                    if let Some(free) = self.driver_vertex(&p, &lim) {
                        for (k, free) in free.into_iter().enumerate() {
                            if free < ways[k] {
                                let element = Decisive::DriverVertex(vi as u32);
                                self.candidates.push((free, k as u8, element));
                            }
                        }
                    }
                }
            }
            for ti in c.tri_start..c.tri_end {
                if near(driver.tri_offset[ti]) {
                    let corners = driver.tris[ti].map(|v| self.place(v as usize, to_f));
                    let far = face_far(&corners, self.edges[ti]);
                    if far > screw.lever(max_rho(&corners)) * limit {
                        continue;
                    }
                    self.driver_face(&corners, far, &lim, ti as u32);
                }
            }
        }
        for &(id, firsts) in &self.firsts {
            // A follower vertex turns with the follower.
            for (k, free) in firsts.free(&lim).into_iter().enumerate() {
                if free < ways[k] {
                    let (vertex, face) = (id, firsts.by[k]);
                    let element = Decisive::FollowerVertex { vertex, face };
                    self.candidates.push((free, k as u8, element));
                }
            }
        }
        let mut best = ways;
        let mut decided = [0, 1].map(|k| if bounded[k] { by[k] } else { None });
        self.decide(t, to_f, &mut best, &mut decided);
        (best, decided)
    }

    /// Each way's free motion from the pass's candidates: the least that is under `best`
    /// and whose vertex an exact distance puts outside the other part. A vertex inside it
    /// at the design pose would lock the follower where the meshes already overlap, so it
    /// does not count; the run notes how deep it is. Candidates are taken in the order
    /// they were met among equals, so the deciding element does not depend on the sort.
    fn decide(
        &mut self,
        t: f64,
        to_f: &Isometry3<f64>,
        best: &mut [f64; 2],
        decided: &mut [Option<Decisive>; 2],
    ) {
        let mut candidates = std::mem::take(&mut self.candidates);
        candidates.sort_by(|a, b| a.0.total_cmp(&b.0));
        for k in 0..2 {
            for &(free, way, element) in &candidates {
                if usize::from(way) != k {
                    continue;
                }
                if free >= best[k] {
                    break;
                }
                if !self.inside(element, to_f, t) {
                    best[k] = free;
                    decided[k] = Some(element);
                    break;
                }
            }
        }
        self.candidates = candidates;
    }

    /// Whether the vertex of `element` lies inside the other part at time `t` (driver → F
    /// by `to_f`), by an exact distance; one inside is noted as overlap.
    fn inside(&mut self, element: Decisive, to_f: &Isometry3<f64>, t: f64) -> bool {
        self.queries += 1;
        let signed = match element {
            Decisive::DriverVertex(vi) => {
                let p = self.place(vi as usize, to_f).p;
                self.follower.signed(&p)
            }
            Decisive::FollowerVertex { vertex, .. } => {
                let p = self.follower.verts[vertex as usize];
                // From the clusters: the driver is asked a few thousand of these a
                // period, and making parry's hierarchy for them would cost more.
                self.driver.signed_near(&to_f.inverse_transform_point(&p))
            }
        };
        if signed < 0.0 && -signed > self.overlap.0 {
            self.overlap = (-signed, t);
        }
        signed < 0.0
    }

    /// Driver vertex `vi` placed in F by `to_f`, once per pass.
    fn place(&mut self, vi: usize, to_f: &Isometry3<f64>) -> Placed {
        let slot = &mut self.placed_at[vi];
        if slot.0 == self.pass {
            return self.placed[slot.1 as usize];
        }
        let p = to_f * self.driver.verts[vi];
        let placed = Placed {
            p,
            rho: p.coords.xy().norm(),
            theta: p.y.atan2(p.x),
            far: self.follower.lower_bound(&p),
        };
        *slot = (self.pass, self.placed.len() as u32);
        self.placed.push(placed);
        placed
    }

    /// A driver vertex placed in F against the follower's faces: the free motion of the
    /// follower each way its first entering crossing allows, `None` when it enters
    /// nothing within the limit.
    fn driver_vertex(&mut self, placed: &Placed, lim: &Limit) -> Option<[f64; 2]> {
        let Placed { p, rho, theta, .. } = placed;
        let (p, rho, theta) = (p, *rho, *theta);
        if rho < ON_AXIS_MM && lim.rise == 0.0 {
            // On the axis a turn does not move it. A slide does: its polar angle is then
            // meaningless, but the only faces it can meet span the whole circle, which
            // every window holds.
            return None;
        }
        let bins = self.bins;
        let follower = self.follower;
        let mut firsts = Firsts::NONE;
        let whole = [-lim.limit, lim.limit];
        let mut against = |bin: usize, z_lo: f64, z_hi: f64| {
            let span = bins.face_span[bin];
            let (rho32, z_lo32, z_hi32) = (rho as f32, z_lo as f32, z_hi as f32);
            // Seen from the follower the driver vertex turns the other way.
            for e in bins.faces_on_arc(bin, theta - lim.up - span, theta + lim.down) {
                if !e.holds(rho32, z_lo32, z_hi32) {
                    continue;
                }
                if lim.rise > 0.0
                    && !path_meets(
                        theta,
                        p.z,
                        lim,
                        whole,
                        [e.lo, f64::from(e.span)],
                        [f64::from(e.z_lo), f64::from(e.z_hi)],
                    )
                {
                    continue;
                }
                let id = e.id as usize;
                let Some(plane) = &bins.planes[id] else {
                    continue;
                };
                let c = follower.tris[id].map(|v| follower.verts[v as usize]);
                crossings(p, plane, &c, lim, |key, up| firsts.add(key, up, e.id));
            }
        };
        if lim.rise == 0.0 {
            match bins.bin(rho, p.z) {
                Some(bin) => against(bin, p.z, p.z),
                None => return None,
            }
        } else {
            // A slide or screw moves the vertex along z too: every bin of its column within
            // the rise.
            let (z_lo, z_hi) = (p.z - lim.rise, p.z + lim.rise);
            bins.for_column(rho, z_lo, z_hi, |bin| against(bin, z_lo, z_hi));
        }
        // The follower moving by +s moves a driver vertex, seen from it, by −s.
        firsts.enters().then(|| {
            let free = firsts.free(lim);
            [free[1], free[0]]
        })
    }

    /// A driver face with corners placed in F, at least `far` from the follower, against
    /// the follower's vertices that can enter it: those the ways it can be entered from
    /// ([`Limit::entering`]) bring onto it.
    fn driver_face(&mut self, corners: &[Placed; 3], far: f64, lim: &Limit, face_id: u32) {
        let c = &corners.map(|k| k.p);
        let Some(plane) = Plane::of(c) else {
            return;
        };
        let rho = max_rho(corners);
        let Some(ab @ [a, b]) = lim.entering(c, &plane.n, rho) else {
            return;
        };
        let (om, sg) = (lim.screw.spin, lim.screw.slide);
        if far > lim.screw.lever(rho) * (-a).max(b) {
            return;
        }
        let face = Footprint::with(c, corners.map(|k| k.rho), corners.map(|k| k.theta));
        // The follower's vertices that s in [a, b] can bring onto the face: the face's
        // polar angles and heights less the turn and the rise each end of it gives.
        let (turn_lo, turn_hi) = ((om * a).min(om * b), (om * a).max(om * b));
        let (rise_lo, rise_hi) = ((sg * a).min(sg * b), (sg * a).max(sg * b));
        let mut f = face;
        f.z_lo -= rise_hi;
        f.z_hi -= rise_lo;
        let bins = self.bins;
        let pass = self.pass;
        let (seen, firsts, follower) = (&mut self.seen, &mut self.firsts, self.follower);
        bins.for_bins(&f, |bin| {
            for e in bins.verts_on_arc(bin, f.lo - turn_hi, f.lo + f.span - turn_lo) {
                if !f.holds(e.rho, e.z) {
                    continue;
                }
                if lim.rise > 0.0
                    && !path_meets(
                        e.theta,
                        e.z,
                        lim,
                        ab,
                        [face.lo - ANGLE_SLACK, face.span + 2.0 * ANGLE_SLACK],
                        [face.z_lo - F32_SLACK_MM, face.z_hi + F32_SLACK_MM],
                    )
                {
                    continue;
                }
                let id = e.id as usize;
                crossings(&follower.verts[id], &plane, c, lim, |tau, up| {
                    let slot = &mut seen[id];
                    if slot.0 != pass {
                        *slot = (pass, firsts.len() as u32);
                        firsts.push((id as u32, Firsts::NONE));
                    }
                    firsts[slot.1 as usize].1.add(tau, up, face_id);
                });
            }
        });
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::mesh::Mesh;
    use crate::geometry::primitive_meshes::{cuboid, uv_sphere};
    use crate::predict::play::tests::{
        bar_between_plates, bar_between_posts, bar_between_posts_turns, joined, pin_by_a_bar,
        pin_by_a_bar_turn, Still, Swing, PLATE_LINES, PLATE_REACHES,
    };

    /// [`free_along`] for a turn alone: the free turns at `n` times, each capped at `cap`
    /// rad.
    fn free_turns(
        motion: &dyn PartMotion,
        driver: &Solid,
        follower: &Solid,
        n: usize,
        cap: f64,
    ) -> Option<FreeTurns> {
        free_along(motion, driver, follower, n, &[(Screw::TURN, cap)])
            .map(|mut lines| lines.remove(0))
    }

    fn bar_and_posts() -> (Solid, Solid) {
        let (posts, bar) = bar_between_posts();
        (
            Solid::new(&posts, "driver").unwrap(),
            Solid::new(&bar, "follower").unwrap(),
        )
    }

    /// Guards the whole path against a closed form, exactly (no step or distance
    /// tolerance): turning +δ the bar's top corner at (20, 0.5) meets the upper post's face
    /// when 20 sin δ + 0.5 cos δ = 1.5; turning −δ its lower corner meets y = −2.5.
    #[test]
    fn a_bar_between_two_posts_turns_to_the_closed_form_angle() {
        let (driver, follower) = bar_and_posts();
        let f = free_turns(&Still, &driver, &follower, 4, 0.5).unwrap();
        let [plus, minus] = bar_between_posts_turns();
        for i in 0..4 {
            assert!((f.plus[i] - plus).abs() < 1e-12, "{}", f.plus[i]);
            assert!((f.minus[i] - minus).abs() < 1e-12, "{}", f.minus[i]);
        }
        assert_eq!(f.overlap_mm, 0.0);
    }

    /// Guards the driver-vertex side: a thin pin of the driver whose tip is 1 mm from the
    /// bar's face and between its corners stops the turn although no bar vertex meets it;
    /// the other way the bar turns the whole cap.
    #[test]
    fn a_driver_pin_against_a_flat_face_stops_the_turn() {
        let (pin, bar) = pin_by_a_bar();
        let driver = Solid::new(&pin, "driver").unwrap();
        let follower = Solid::new(&bar, "follower").unwrap();
        let cap = 0.5;
        let f = free_turns(&Still, &driver, &follower, 2, cap).unwrap();
        assert_eq!(f.minus[0], cap);
        let want = pin_by_a_bar_turn();
        assert!((f.plus[0] - want).abs() < 1e-12, "{} vs {want}", f.plus[0]);
    }

    /// Guards each way's own window of polar angles: with a limit each way between the
    /// closed-form free turns (the positive one about half the negative), a pass finds each
    /// way's turn and the element that decides it, on the follower-vertex side (the bar's
    /// corners against the posts) and on the driver-vertex side (a pin's tip against a
    /// tooth); a way whose limit is short of its turn is left open at its limit. With the
    /// windows swapped a way looks only as far as the other's limit and misses its contact.
    #[test]
    fn each_way_searches_within_its_own_limit() {
        let pass = |driver: &Solid, follower: &Solid, ways: [f64; 2]| {
            let bins = Bins::new(follower);
            let edges = longest_edges(driver);
            let mut run = Run::new(&Still, driver, follower, &bins, &edges, Screw::TURN, 0.5);
            run.pass_at(0.0, &Isometry3::identity(), ways, [false; 2], [None; 2])
        };
        let (driver, follower) = bar_and_posts();
        let [plus, minus] = bar_between_posts_turns();
        assert!(plus < 0.6 * minus, "{plus} {minus}");
        let (free, decided) = pass(&driver, &follower, [1.1 * plus, 1.1 * minus]);
        assert!((free[0] - plus).abs() < 1e-12, "{}", free[0]);
        assert!((free[1] - minus).abs() < 1e-12, "{}", free[1]);
        for way in decided {
            assert!(
                matches!(way, Some(Decisive::FollowerVertex { .. })),
                "{way:?}"
            );
        }
        let (free, decided) = pass(&driver, &follower, [1.1 * plus, 0.9 * minus]);
        assert!((free[0] - plus).abs() < 1e-12, "{}", free[0]);
        assert_eq!((free[1], decided[1]), (0.9 * minus, None));

        // A pin of the driver below a tooth of the follower, all of whose faces lie at
        // larger polar angles than the pin's tip: turning the follower back brings the
        // tooth's flat underside y = 1 down onto the tip's corner (20.1, 0.5), between the
        // tooth's own corners, when 20.1 sin δ + 0.5 cos δ = 1.
        let pin = cuboid([19.9, -8.0, -0.1], [20.1, 0.5, 0.1]);
        let tooth = cuboid([15.0, 1.0, -5.0], [25.0, 3.0, 5.0]);
        let driver = Solid::new(&pin, "driver").unwrap();
        let follower = Solid::new(&tooth, "follower").unwrap();
        let want = (1.0 / 20.1f64.hypot(0.5)).asin() - 0.5f64.atan2(20.1);
        let (free, decided) = pass(&driver, &follower, [0.5 * want, 1.1 * want]);
        assert!((free[1] - want).abs() < 1e-12, "{} vs {want}", free[1]);
        assert!(
            matches!(decided[1], Some(Decisive::DriverVertex(_))),
            "{decided:?}"
        );
        assert_eq!((free[0], decided[0]), (0.5 * want, None));
    }

    /// Guards slides and screws against closed forms: the bar between the posts (prisms
    /// along z) screws to the turn's own angles, each divided by the screw's turn per unit;
    /// between two plates it slides and screws up and down by the gaps over the slide per
    /// unit, exactly where the tracer's test allows its `HIT_MM`.
    #[test]
    fn a_bar_slides_and_screws_to_the_closed_forms() {
        let (driver, follower) = bar_and_posts();
        let screw = Screw {
            spin: 0.05,
            slide: 0.7,
        };
        let f = free_along(&Still, &driver, &follower, 2, &[(screw, 4.0)]).unwrap();
        let [plus, minus] = bar_between_posts_turns();
        assert!(
            (f[0].plus[0] - plus / 0.05).abs() < 1e-9,
            "{}",
            f[0].plus[0]
        );
        assert!(
            (f[0].minus[0] - minus / 0.05).abs() < 1e-9,
            "{}",
            f[0].minus[0]
        );

        let (driver, follower) = bar_between_plates();
        let f = free_along(&Still, &driver, &follower, 2, &PLATE_LINES).unwrap();
        for (line, [up, down]) in PLATE_REACHES.into_iter().enumerate() {
            let (plus, minus) = (f[line].plus[0], f[line].minus[0]);
            assert!((plus - up).abs() < 1e-12, "{plus}");
            assert!((minus - down).abs() < 1e-12, "{minus}");
        }
        // Sideways the plates are flush with nothing: the turn is free up to the cap.
        let f = free_along(&Still, &driver, &follower, 2, &[(Screw::TURN, 0.3)]).unwrap();
        assert_eq!([f[0].plus[0], f[0].minus[0]], [0.3, 0.3]);
    }

    /// Guards a vertex on the axis: a turn leaves it where it is, a slide does not. The
    /// driver sphere's pole, on the axis 0.5 mm under the follower's plate, stops the
    /// plate's slide down there, before the ring of vertices below the pole would.
    #[test]
    fn a_vertex_on_the_axis_stops_a_slide() {
        let plate = cuboid([-5.0, -5.0, 2.0], [5.0, 5.0, 3.0]);
        let ball = uv_sphere([0.0, 0.0, 0.0], 1.5, 24, 12);
        let driver = Solid::new(&ball, "driver").unwrap();
        let follower = Solid::new(&plate, "follower").unwrap();
        let f = free_along(&Still, &driver, &follower, 2, &[(Screw::SLIDE, 3.0)]).unwrap();
        assert!((f[0].minus[0] - 0.5).abs() < 1e-12, "{}", f[0].minus[0]);
        assert_eq!(f[0].plus[0], 3.0);
    }

    /// Guards the helix–plane solution: a rise against a horizontal face (linear), a turn
    /// against a vertical one through a screw's sine, and a path that meets one plane twice
    /// (its value turns back between the crossings, where the pieces are cut).
    #[test]
    fn a_helix_crosses_a_plane_where_its_closed_form_says() {
        let p = Point3::new(10.0, 0.0, 0.0);
        let hits_of = |c: [Point3<f64>; 3], screw: Screw, limit: f64| {
            let mut hits = Vec::new();
            crossings(
                &p,
                &Plane::of(&c).unwrap(),
                &c,
                &Limit::new(screw, [limit; 2]),
                |s, enters| hits.push((s, enters)),
            );
            hits
        };
        // The part above z = 1 (its face's normal is −z).
        let roof = [
            Point3::new(-40.0, -40.0, 1.0),
            Point3::new(-40.0, 60.0, 1.0),
            Point3::new(60.0, -40.0, 1.0),
        ];
        let hits = hits_of(
            roof,
            Screw {
                spin: 0.1,
                slide: 1.0,
            },
            2.0,
        );
        assert_eq!(hits.len(), 1);
        assert!((hits[0].0 - 1.0).abs() < 1e-15 && hits[0].1, "{hits:?}");
        // The part beyond y = 3: 10 sin(0.5 s) = 3.
        let wall = [
            Point3::new(0.0, 3.0, -50.0),
            Point3::new(40.0, 3.0, -50.0),
            Point3::new(0.0, 3.0, 100.0),
        ];
        let hits = hits_of(
            wall,
            Screw {
                spin: 0.5,
                slide: 2.0,
            },
            1.0,
        );
        assert_eq!(hits.len(), 1);
        let want = 2.0 * 0.3f64.asin();
        assert!((hits[0].0 - want).abs() < 1e-14 && hits[0].1, "{hits:?}");
        // The part short of x = 9.99: the point's x, 10 cos(0.2 s), dips under it, so it
        // leaves the part as s grows to −root and enters it again at +root.
        let near = [
            Point3::new(9.99, -40.0, -60.0),
            Point3::new(9.99, 60.0, -60.0),
            Point3::new(9.99, -40.0, 60.0),
        ];
        let hits = hits_of(
            near,
            Screw {
                spin: 0.2,
                slide: 1.0,
            },
            1.0,
        );
        let root = 0.999f64.acos() / 0.2;
        assert_eq!(hits.len(), 2, "{hits:?}");
        assert!((hits[0].0 + root).abs() < 1e-12 && !hits[0].1, "{hits:?}");
        assert!((hits[1].0 - root).abs() < 1e-12 && hits[1].1, "{hits:?}");
        // A path in the plane of a face slides along it.
        let flush = [
            Point3::new(-20.0, -20.0, 0.0),
            Point3::new(20.0, -20.0, 0.0),
            Point3::new(-20.0, 20.0, 0.0),
        ];
        assert!(hits_of(
            flush,
            Screw {
                spin: 0.3,
                slide: 0.0
            },
            1.0
        )
        .is_empty());
    }

    /// Guards the circle–plane solution and the sense of a crossing: a point at (10, 0, 0)
    /// turned about z meets the plane y = 3 at β = asin(0.3), entering the part above
    /// it as β grows, and the plane y = −3 at β = −asin(0.3), where as β grows it leaves
    /// the part below (it enters it as β falls).
    #[test]
    fn a_circle_crosses_a_plane_where_its_sine_says() {
        let p = Point3::new(10.0, 0.0, 0.0);
        let lim = Limit::new(Screw::TURN, [0.5; 2]);
        let above = [
            Point3::new(0.0, 3.0, -5.0),
            Point3::new(20.0, 3.0, -5.0),
            Point3::new(0.0, 3.0, 5.0),
        ];
        let plane = Plane::of(&above).unwrap();
        assert!((plane.n - Vector3::new(0.0, -1.0, 0.0)).norm() < 1e-15);
        let mut hits = Vec::new();
        crossings(&p, &plane, &above, &lim, |tau, enters| {
            hits.push((tau, enters))
        });
        assert_eq!(hits.len(), 1);
        assert!((2.0 * hits[0].0.atan() - 0.3f64.asin()).abs() < 1e-15);
        assert!(hits[0].1);
        // The same face at y = −3, wound the other way: its part lies below it.
        let mut below = above.map(|c| Point3::new(c.x, -3.0, c.z));
        below.swap(1, 2);
        let plane = Plane::of(&below).unwrap();
        assert!((plane.n - Vector3::new(0.0, 1.0, 0.0)).norm() < 1e-15);
        let mut hits = Vec::new();
        crossings(&p, &plane, &below, &lim, |tau, enters| {
            hits.push((tau, enters))
        });
        assert_eq!(hits.len(), 1);
        assert!((2.0 * hits[0].0.atan() + 0.3f64.asin()).abs() < 1e-15);
        assert!(
            !hits[0].1,
            "as β grows the point leaves the part below y = −3"
        );
        // Beyond the limit, nothing.
        let mut hits = 0;
        crossings(
            &p,
            &plane,
            &below,
            &Limit::new(Screw::TURN, [0.2; 2]),
            |_, _| hits += 1,
        );
        assert_eq!(hits, 0);
    }

    /// Guards the flush case the tracer gets wrong: a bar whose top face lies in the plane
    /// of a driver plate's bottom face slides along it, which enters nothing, so the bar
    /// turns the whole cap both ways (the tracer, which counts any vertex within its
    /// `HIT_MM` of a face as touching, stops it).
    #[test]
    fn a_face_sliding_in_the_plane_of_another_does_not_stop_the_turn() {
        let bar = cuboid([0.0, -0.5, -1.0], [20.0, 0.5, 1.0]);
        let plate = cuboid([-30.0, -30.0, 1.0], [30.0, 30.0, 2.0]);
        let driver = Solid::new(&plate, "driver").unwrap();
        let follower = Solid::new(&bar, "follower").unwrap();
        let f = free_turns(&Still, &driver, &follower, 2, 0.3).unwrap();
        assert_eq!(f.plus, vec![0.3; 2]);
        assert_eq!(f.minus, vec![0.3; 2]);
        let traced = crate::predict::play::tests::free_turns(&Still, &driver, &follower, 2, 0.3);
        assert!(
            traced.plus[0] < 1e-6,
            "the tracer stops at once: {}",
            traced.plus[0]
        );
    }

    /// Guards the overlap rule: with a thin post pushed 0.3 mm into the bar, the bar's
    /// corner inside it would stop the turn on the plate beyond the post, but it does not
    /// count (it would lock the bar where the meshes already overlap) and the overlap is
    /// reported. The bar's other corner meets the thin post one way and the lower post the
    /// other way where the closed forms say.
    #[test]
    fn vertices_inside_the_other_part_are_reported_not_counted() {
        let bar = cuboid([0.0, -0.5, -1.0], [20.0, 0.5, 1.0]);
        let posts = joined(&[
            cuboid([10.0, 0.2, -3.0], [30.0, 1.0, 3.0]),
            cuboid([10.0, 1.1, -3.0], [30.0, 6.0, 3.0]),
            cuboid([10.0, -8.0, -3.0], [30.0, -2.5, 3.0]),
        ]);
        let driver = Solid::new(&posts, "driver").unwrap();
        let follower = Solid::new(&bar, "follower").unwrap();
        let f = free_turns(&Still, &driver, &follower, 2, 0.5).unwrap();
        assert!((f.overlap_mm - 0.3).abs() < 1e-9, "{}", f.overlap_mm);
        let solve = |a: f64, b: f64, c: f64| (c / a.hypot(b)).asin() - b.atan2(a);
        // The inside corner (20, 0.5) would meet the plate at y = 1.1 first.
        assert!(solve(20.0, 0.5, 1.1) < solve(20.0, -0.5, 0.2));
        assert!(
            (f.plus[0] - solve(20.0, -0.5, 0.2)).abs() < 1e-12,
            "{}",
            f.plus[0]
        );
        assert!(
            (f.minus[0] - solve(20.0, 0.5, 2.5)).abs() < 1e-12,
            "{}",
            f.minus[0]
        );
    }

    /// Guards [`Limit::entering`]: a face is looked up only from the ways a point moving by
    /// the screw can enter it, and both ways when the motion runs along it.
    #[test]
    fn a_face_is_entered_only_against_its_normal() {
        let ways = [0.2, 0.3];
        let turn = Limit::new(Screw::TURN, ways);
        let tri = |c: [[f64; 3]; 3]| c.map(|[x, y, z]| Point3::new(x, y, z));
        // With the corners' largest distance from the axis, as a pass has it.
        let entering = |lim: &Limit, c: &[Point3<f64>; 3], n: Vector3<f64>| {
            let far = c.iter().map(|q| q.coords.xy().norm()).fold(0.0, f64::max);
            lim.entering(c, &n, far)
        };
        // The plane x = 10 facing −x above the x axis: turning it (counter-clockwise)
        // moves its points out along −x, so points enter it only as the turn falls.
        let above = tri([[10.0, 1.0, 0.0], [10.0, 2.0, 0.0], [10.0, 1.5, 1.0]]);
        assert_eq!(entering(&turn, &above, -Vector3::x()), Some([-0.3, 0.0]));
        assert_eq!(entering(&turn, &above, Vector3::x()), Some([0.0, 0.2]));
        // Across the x axis its points move both ways along the normal.
        let across = tri([[10.0, -1.0, 0.0], [10.0, 1.0, 0.0], [10.0, 0.0, 1.0]]);
        assert_eq!(entering(&turn, &across, -Vector3::x()), Some([-0.3, 0.2]));
        // A horizontal face: a turn slides in its plane, a slide crosses it one way.
        let flat = tri([[10.0, 0.0, 0.0], [11.0, 0.0, 0.0], [10.0, 1.0, 0.0]]);
        assert_eq!(entering(&turn, &flat, Vector3::z()), Some([-0.3, 0.2]));
        let slide = Limit::new(Screw::SLIDE, ways);
        assert_eq!(entering(&slide, &flat, Vector3::z()), Some([-0.3, 0.0]));
        assert_eq!(entering(&slide, &flat, -Vector3::z()), Some([0.0, 0.2]));
        // A slide along a vertical face.
        assert_eq!(entering(&slide, &above, -Vector3::x()), Some([-0.3, 0.2]));
    }

    /// Guards the memory the 1R path saves: the driver's distance grid (the largest thing
    /// a `Solid` holds) is never made; the follower's is.
    #[test]
    fn the_driver_s_distance_grid_is_never_made() {
        let (driver, follower) = swing_parts();
        assert!(!driver.has_bounds() && !follower.has_bounds());
        free_turns(&Swing, &driver, &follower, 24, 0.3).unwrap();
        assert!(!driver.has_bounds());
        assert!(follower.has_bounds());
    }

    /// Guards the precondition: a follower whose design pose moves its axis off R's z axis
    /// is left to the tracer.
    #[test]
    fn a_follower_off_the_axis_is_left_to_the_tracer() {
        struct Shifted;
        impl PartMotion for Shifted {
            fn follower(&self, _: f64) -> Isometry3<f64> {
                Isometry3::translation(0.5, 0.0, 0.0)
            }
            fn driver(&self, t: f64) -> Isometry3<f64> {
                Still.driver(t)
            }
            fn follower_speed(&self, q: &Point3<f64>) -> f64 {
                Still.follower_speed(q)
            }
            fn driver_speed(&self, p: &Point3<f64>) -> f64 {
                Still.driver_speed(p)
            }
            fn follower_reach(&self, q: &Point3<f64>) -> f64 {
                Still.follower_reach(q)
            }
            fn driver_reach(&self, p: &Point3<f64>) -> f64 {
                Still.driver_reach(p)
            }
        }
        let (driver, follower) = bar_and_posts();
        assert!(free_turns(&Shifted, &driver, &follower, 4, 0.5).is_none());
        assert!(free_turns(&Still, &driver, &follower, 4, 0.5).is_some());
    }

    /// Guards the angle windows round ±π and their slack for the keys' rounding.
    #[test]
    fn windows_of_angles_wrap_round_the_circle() {
        let keys: Vec<f32> = [-3.1, -1.0, 0.0, 1.0, 3.1].map(|k| k as f32).to_vec();
        let picked = |a: f64, b: f64| -> Vec<f32> {
            on_arc(&keys, a, b)
                .into_iter()
                .flat_map(|r| keys[r].to_vec())
                .collect()
        };
        assert_eq!(picked(-0.5, 0.5), vec![0.0]);
        assert_eq!(picked(3.0, 3.0 + 0.2), vec![3.1, -3.1]);
        assert_eq!(picked(-3.2, -3.0), vec![3.1, -3.1]);
        assert_eq!(picked(1.0, 1.0), vec![1.0], "an end on a key holds it");
        assert_eq!(picked(-10.0, 10.0).len(), 5);
        assert!(picked(1.5, 2.5).is_empty());
    }

    /// Every vertex of each part against every face of the other with the same circle–
    /// plane crossings, no bins, clusters or limits: the reference for the shortcuts.
    fn every_pair(
        driver: &Solid,
        follower: &Solid,
        n: usize,
        screw: Screw,
        cap: f64,
    ) -> Vec<[f64; 2]> {
        let lim = Limit::new(screw, [cap; 2]);
        let faces = |s: &Solid, place: &dyn Fn(&Point3<f64>) -> Point3<f64>| {
            s.tris
                .iter()
                .filter_map(|t| {
                    let c = t.map(|v| place(&s.verts[v as usize]));
                    Plane::of(&c).map(|p| (p, c))
                })
                .collect::<Vec<_>>()
        };
        let firsts = |p: &Point3<f64>, faces: &[(Plane, [Point3<f64>; 3])]| {
            let mut f = Firsts::NONE;
            for (plane, c) in faces {
                crossings(p, plane, c, &lim, |tau, up| f.add(tau, up, 0));
            }
            f
        };
        (0..n)
            .map(|i| {
                let t = i as f64 / n as f64;
                let to_f = Swing.follower(t).inverse() * Swing.driver(t);
                let mut best = [cap; 2];
                let driver_faces = faces(driver, &|p| to_f * p);
                for v in &follower.verts {
                    let f = firsts(v, &driver_faces);
                    // A vertex inside the other part does not count.
                    if f.enters() && driver.signed(&to_f.inverse_transform_point(v)) < 0.0 {
                        continue;
                    }
                    let free = f.free(&lim);
                    best = [best[0].min(free[0]), best[1].min(free[1])];
                }
                let follower_faces = faces(follower, &|p| *p);
                for w in &driver.verts {
                    let p = to_f * w;
                    let f = firsts(&p, &follower_faces);
                    if f.enters() && follower.signed(&p) < 0.0 {
                        continue;
                    }
                    let free = f.free(&lim);
                    best = [best[0].min(free[1]), best[1].min(free[0])];
                }
                best
            })
            .collect()
    }

    fn swing_parts() -> (Solid, Solid) {
        let follower: Mesh = joined(&[
            cuboid([0.0, -0.6, -0.6], [18.0, 0.6, 0.6]),
            uv_sphere([18.0, 0.0, 0.0], 1.5, 24, 12),
        ]);
        let driver: Mesh = joined(&[
            uv_sphere([-7.5, 0.0, 0.0], 1.5, 24, 12),
            uv_sphere([0.0, 7.5, 0.0], 1.5, 24, 12),
        ]);
        (
            Solid::new(&driver, "driver").unwrap(),
            Solid::new(&follower, "follower").unwrap(),
        )
    }

    /// [`swing_parts`] with one more driver sphere, which passes 0.3 mm over the
    /// follower's sphere and 1.2 mm over the end of its bar: contacts along z.
    fn stacked_parts() -> (Solid, Solid) {
        let follower: Mesh = joined(&[
            cuboid([0.0, -0.6, -0.6], [18.0, 0.6, 0.6]),
            uv_sphere([18.0, 0.0, 0.0], 1.5, 24, 12),
        ]);
        let driver: Mesh = joined(&[
            uv_sphere([-7.5, 0.0, 0.0], 1.5, 24, 12),
            uv_sphere([0.0, 7.5, 0.0], 1.5, 24, 12),
            uv_sphere([0.0, -12.0, 2.8], 1.0, 24, 12),
        ]);
        (
            Solid::new(&driver, "driver").unwrap(),
            Solid::new(&follower, "follower").unwrap(),
        )
    }

    /// Guards the shortcuts (clusters skipped by carried bounds, vertices and faces by
    /// their offsets, the bins and their windows of angles and heights, the paths' boxes,
    /// the search limit carried from the last time and widened when reached): on two parts
    /// in motion the free turns, slides and screws are those of every vertex against every
    /// face, to the last bit.
    #[test]
    fn the_shortcuts_find_the_same_free_motions_as_every_pair() {
        let (driver, follower) = stacked_parts();
        let n = 96;
        let lines = [
            (Screw::TURN, 0.3),
            (Screw::SLIDE, 3.0),
            (
                Screw {
                    spin: -0.04,
                    slide: 0.7,
                },
                3.0,
            ),
        ];
        let fast = free_along(&Swing, &driver, &follower, n, &lines).unwrap();
        for (k, &(screw, cap)) in lines.iter().enumerate() {
            let slow = every_pair(&driver, &follower, n, screw, cap);
            let mut touching = 0;
            for (i, want) in slow.iter().enumerate() {
                assert_eq!(
                    [fast[k].plus[i], fast[k].minus[i]],
                    *want,
                    "{screw:?}, sample {i}"
                );
                touching += want.iter().filter(|&&f| f < cap).count();
            }
            // The case exercises contacts, not only free motions.
            assert!(
                touching > 6 && touching < 2 * n - 6,
                "{screw:?}: {touching}"
            );
            assert_eq!(fast[k].overlap_mm, 0.0);
        }
    }

    /// Guards determinism: the period split into runs for one thread or for several gives
    /// the same free turns.
    #[test]
    fn the_free_turns_do_not_depend_on_the_threads() {
        let (driver, follower) = swing_parts();
        let on = |threads: usize| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap()
                .install(|| free_turns(&Swing, &driver, &follower, 144, 0.3).unwrap())
        };
        let one = on(1);
        let three = on(3);
        assert_eq!(one.plus, three.plus);
        assert_eq!(one.minus, three.minus);
    }
}
