//! Solids swept along closed curves: a 2-D cross-section carried along a loop of frames.
//!
//! Owns [`Section`] (the cross-sections parts use: a half ellipse for the follower's contact
//! rims, a rounded rectangle for the driver's bands), [`Frame`] and [`Sweep`], whose
//! distance is the union of the section extruded along each segment of the sampled loop
//! (reaching to the mitre planes that bisect the turns, so that no wedge opens between
//! segments), found through per-cell lists of the segments near each 1 mm cell round the
//! sweep ([`CellLists`]) and, beyond their reach, a bounding-volume hierarchy over the
//! segments. A sweep can be
//! cut into parts by how sharply its section twists ([`Sweep::split_by_twist`]), each
//! part with its own bound on how fast its value changes. A half ellipse's distance is
//! read from a table made once per ellipse ([`EllipseTable`]), its exact value
//! ([`ellipse_distance`]) costing a bisection. The section
//! lies in the plane normal to the loop; its coordinates are (u, v) along the frame's `u`
//! and `v = t × u`. It does not know what the curves mean (contact curves are `build`'s).

use std::sync::{Arc, Mutex, OnceLock};

use rayon::prelude::*;

use super::cell_lists::CellLists;
use super::mesh::Aabb;
use super::sdf::{arr, v3, Sdf, Vec3};

/// A 2-D cross-section in (u, v) coordinates, mm.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Section {
    /// The half of an ellipse on the +u side of its centre, apex at the origin: the centre
    /// is (−a, 0), semi-axis `a` along u and `b` along v. Its outward normal at the apex
    /// is +u, so a rim swept with u = the contact normal touches with that normal.
    HalfEllipse {
        /// Semi-axis along u (depth of the rim).
        a: f64,
        /// Semi-axis along v (half the rim's thickness).
        b: f64,
    },
    /// A rectangle u ∈ [u_min, u_max], |v| ≤ half_width with corners rounded by `round`.
    RoundedRect {
        /// Lowest u.
        u_min: f64,
        /// Highest u.
        u_max: f64,
        /// Half the extent along v.
        half_width: f64,
        /// Corner radius (≤ half of the smaller side).
        round: f64,
    },
}

/// Farther than this (in the ellipse's units) beyond the circle around the ellipse, its
/// distance is replaced by the distance to that circle, a lower bound: callers need exact
/// values near surfaces and bounds elsewhere, and the closest point's search dominated the
/// cost of far queries (and [`EllipseTable`] covers no more than this reach).
pub const ELLIPSE_FAR: f64 = 2.0;

/// √(a² + b²) for the mm-sized values here (`f64::hypot` guards against overflow at a cost
/// that dominated the sweeps' profile).
#[inline]
pub fn norm2(a: f64, b: f64) -> f64 {
    (a * a + b * b).sqrt()
}

/// Signed distance from (x, y) to the ellipse with semi-axes a, b centred at the origin:
/// exact within [`ELLIPSE_FAR`] of the ellipse's enclosing circle, a lower bound beyond.
///
/// The closest point (q₀, q₁) of a point (p₀, p₁) in the first quadrant, a ≥ b, is
/// qᵢ = eᵢ² pᵢ / (t + eᵢ²) for the one t that puts it on the ellipse (the normal through
/// it passes through p); with s = t / b², r = a² / b², zᵢ = pᵢ / eᵢ, that is the root of
/// (r z₀ / (s + r))² + (z₁ / (s + 1))² = 1, which falls monotonically in s and is
/// bracketed by s = z₁ − 1 and s = |(r z₀, z₁)| − 1, so bisection (in s + 1) finds it however near
/// the point is to the centre of curvature (Eberly's formulation; the iteration on the
/// evolute used before stopped up to 1.7·10⁻⁴ mm off near the major axis). A point on the
/// major axis has its closest point in closed form. Each value costs about a hundred
/// steps: [`EllipseTable`] serves the sweeps.
pub fn ellipse_distance(x: f64, y: f64, a: f64, b: f64) -> f64 {
    let r = norm2(x, y);
    let m = a.max(b);
    if r > m + ELLIPSE_FAR {
        return r - m;
    }
    exact_ellipse_distance(x, y, a, b)
}

/// [`ellipse_distance`] without the bound far away.
fn exact_ellipse_distance(x: f64, y: f64, a: f64, b: f64) -> f64 {
    if a < b {
        return exact_ellipse_distance(y, x, b, a);
    }
    let (p0, p1) = (x.abs(), y.abs());
    let (z0, z1) = (p0 / a, p1 / b);
    let g = z0 * z0 + z1 * z1 - 1.0;
    let (q0, q1) = if g == 0.0 {
        (p0, p1)
    } else if p1 > 0.0 {
        // In w = s + 1, which keeps its precision where the root nears s = −1 (a point near
        // the major axis: q₁ = p₁ / w).
        let ratio = (a / b) * (a / b);
        let f = |w: f64| (ratio * z0 / (w - 1.0 + ratio)).powi(2) + (z1 / w).powi(2) - 1.0;
        let (mut lo, mut hi) = (z1, norm2(ratio * z0, z1));
        // At most as many halvings as an f64 has bits of exponent and mantissa.
        for _ in 0..ELLIPSE_BISECTIONS {
            let mid = 0.5 * (lo + hi);
            if mid <= lo || mid >= hi {
                break;
            }
            if f(mid) > 0.0 {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        let w = 0.5 * (lo + hi);
        (ratio * p0 / (w - 1.0 + ratio), p1 / w)
    } else {
        // On the major axis: the closest point leaves it when p is nearer the centre than
        // the centre of curvature of the vertex.
        let c = a * a - b * b;
        if p0 * a < c {
            let q0 = a * a * p0 / c;
            (q0, b * (1.0 - (q0 / a).powi(2)).max(0.0).sqrt())
        } else {
            (a, 0.0)
        }
    };
    let d = norm2(p0 - q0, p1 - q1);
    if g < 0.0 {
        -d
    } else {
        d
    }
}

/// Halvings of [`ellipse_distance`]'s bracket at most: 1 100 covers every f64 between the
/// two ends (the loop stops when the middle equals an end, after 60–100 in practice).
const ELLIPSE_BISECTIONS: usize = 1100;

/// Cell of an [`EllipseTable`], in the ellipse's units (mm for the parts). 0.01: the table
/// of the rims' 3 × 1.6 mm section is 500 × 500 values (1 MB of f32, small enough to stay
/// in cache), bilinear interpolation stays within 4·10⁻⁵ mm of the exact distance within
/// 0.5 mm of the ellipse (the curvature there is at most a/b² = 1.2 per mm, an error of
/// h²κ/8), and a value took 10 ns against 150 ns for the four steps of the evolute
/// iteration used before, which made a quarter of the carve's time (measured on 2·10⁶
/// random points around the section; a 0.005 table, 4 MB, took 37 ns).
pub const ELLIPSE_TABLE_CELL: f64 = 0.01;

/// [`ellipse_distance`] tabulated on a lattice of [`ELLIPSE_TABLE_CELL`] over the
/// quadrant (the ellipse is symmetric) out to [`ELLIPSE_FAR`] beyond its enclosing circle,
/// and interpolated bilinearly; beyond, the same lower bound. Made once per ellipse
/// ([`EllipseTable::shared`]).
#[derive(Debug)]
pub struct EllipseTable {
    a: f64,
    b: f64,
    /// Values per row and rows.
    n: usize,
    values: Vec<f32>,
}

impl EllipseTable {
    /// The table of the ellipse with semi-axes a, b, made when first asked for and shared
    /// by every sweep of that section after.
    pub fn shared(a: f64, b: f64) -> Arc<EllipseTable> {
        static TABLES: OnceLock<Mutex<Vec<Arc<EllipseTable>>>> = OnceLock::new();
        let tables = TABLES.get_or_init(Default::default);
        let find = |tables: &[Arc<EllipseTable>]| {
            tables
                .iter()
                .find(|t| t.a.to_bits() == a.to_bits() && t.b.to_bits() == b.to_bits())
                .cloned()
        };
        if let Some(t) = find(&tables.lock().expect("no panics under the lock")) {
            return t;
        }
        // Made outside the lock: its rows are made in parallel, and a thread waiting for
        // them may take up another task that asks for a table. Two threads may both make
        // one; the first kept serves both.
        let made = Arc::new(EllipseTable::new(a, b));
        let mut tables = tables.lock().expect("no panics under the lock");
        if let Some(t) = find(&tables) {
            return t;
        }
        tables.push(made.clone());
        made
    }

    fn new(a: f64, b: f64) -> EllipseTable {
        // Two cells beyond the reach, so that every point within it has a whole cell.
        let reach = a.max(b) + ELLIPSE_FAR;
        let n = (reach / ELLIPSE_TABLE_CELL).ceil() as usize + 2;
        let mut values = vec![0.0f32; n * n];
        values.par_chunks_mut(n).enumerate().for_each(|(j, row)| {
            let y = j as f64 * ELLIPSE_TABLE_CELL;
            for (i, v) in row.iter_mut().enumerate() {
                // Exact at every corner, also those just beyond the reach whose cells
                // straddle it.
                *v = exact_ellipse_distance(i as f64 * ELLIPSE_TABLE_CELL, y, a, b) as f32;
            }
        });
        EllipseTable { a, b, n, values }
    }

    /// The signed distance at (x, y) ([`ellipse_distance`] within the error above).
    #[inline]
    pub fn dist(&self, x: f64, y: f64) -> f64 {
        let (px, py) = (x.abs(), y.abs());
        let (r, m) = (norm2(px, py), self.a.max(self.b));
        if r > m + ELLIPSE_FAR {
            return r - m;
        }
        let (fx, fy) = (px / ELLIPSE_TABLE_CELL, py / ELLIPSE_TABLE_CELL);
        // Within the reach, so both below n − 2.
        let (i, j) = (fx as usize, fy as usize);
        let (sx, sy) = (fx - i as f64, fy - j as f64);
        let k = j * self.n + i;
        let v = |k: usize| f64::from(self.values[k]);
        let low = v(k) + (v(k + 1) - v(k)) * sx;
        let high = v(k + self.n) + (v(k + self.n + 1) - v(k + self.n)) * sx;
        low + (high - low) * sy
    }
}

/// The distance of [`Section::HalfEllipse`] at (u, v) through `ellipse`, the signed
/// distance to its whole ellipse about that ellipse's centre.
fn half_ellipse_dist(u: f64, v: f64, a: f64, b: f64, ellipse: impl Fn(f64, f64) -> f64) -> f64 {
    let e = ellipse(u + a, v);
    let cut = -(u + a);
    if e > 0.0 && cut > 0.0 {
        // Behind the flat side and outside the ellipse: nearest is the flat side's segment
        // |v| ≤ b at u = −a.
        let dv = (v.abs() - b).max(0.0);
        norm2(cut, dv)
    } else {
        e.max(cut)
    }
}

impl Section {
    /// Signed distance at (u, v).
    pub fn dist(&self, u: f64, v: f64) -> f64 {
        match *self {
            Section::HalfEllipse { a, b } => {
                half_ellipse_dist(u, v, a, b, |x, y| ellipse_distance(x, y, a, b))
            }
            Section::RoundedRect {
                u_min,
                u_max,
                half_width,
                round,
            } => {
                let cu = 0.5 * (u_min + u_max);
                let hu = 0.5 * (u_max - u_min) - round;
                let hv = half_width - round;
                let du = (u - cu).abs() - hu;
                let dv = v.abs() - hv;
                norm2(du.max(0.0), dv.max(0.0)) + du.max(dv).min(0.0) - round
            }
        }
    }

    /// A lower bound of [`Section::dist`] outside the section (0 inside). Cheap, so a
    /// segment that cannot win is skipped before the ellipse's closest-point iteration: the
    /// distance to the section's bounding rectangle (the half ellipse lies in u ∈ [−a, 0],
    /// |v| ≤ b), and for the half ellipse also (g − 1)·min(a, b) with
    /// g = √((x/a)² + (y/b)²) about its centre: g changes by at most 1/min(a, b) per mm, and
    /// the whole ellipse (which holds the half) is where g ≤ 1. It bounds the exact
    /// distance; beyond [`ELLIPSE_FAR`], where `dist` gives a lower bound itself, it may
    /// be the larger of the two (both stay below the exact distance).
    pub fn lower_bound(&self, u: f64, v: f64) -> f64 {
        let (u_lo, u_hi, hv) = self.rect();
        let rect = norm2((u_lo - u).max(u - u_hi).max(0.0), (v.abs() - hv).max(0.0));
        match *self {
            Section::HalfEllipse { a, b } => {
                let g = norm2((u + a) / a, v / b);
                rect.max((g - 1.0) * a.min(b))
            }
            Section::RoundedRect { .. } => rect,
        }
    }

    /// The section's bounding rectangle: u from, u to, and the half width in v.
    fn rect(&self) -> (f64, f64, f64) {
        match *self {
            Section::HalfEllipse { a, b } => (-a, 0.0, b),
            Section::RoundedRect {
                u_min,
                u_max,
                half_width,
                ..
            } => (u_min, u_max, half_width),
        }
    }

    /// The squared distance to the section's bounding rectangle (the first term of
    /// [`Section::lower_bound`]) at (u, v) = (`su`, `sv`) / `scale`, times `scale`²: the
    /// rectangle's bound of a point measured along axes of length `scale` (not yet made
    /// unit), without a square root or a division.
    fn rect_gap_sq_scaled(&self, su: f64, sv: f64, scale: f64) -> f64 {
        let (u_lo, u_hi, hv) = self.rect();
        let gu = (u_lo * scale - su).max(su - u_hi * scale).max(0.0);
        let gv = (sv.abs() - hv * scale).max(0.0);
        gu * gu + gv * gv
    }

    /// Largest distance of the section from the origin (for bounding boxes). The half
    /// ellipse's farthest points are the ends of its flat side, (−a, ±b): along the arc
    /// u = −a + a·cos θ, v = b·sin θ the squared distance a²(1 − cos θ)² + b² sin² θ grows
    /// as cos θ falls to 0.
    pub fn extent(&self) -> f64 {
        match *self {
            Section::HalfEllipse { a, b } => a.hypot(b),
            Section::RoundedRect {
                u_min,
                u_max,
                half_width,
                ..
            } => u_min.abs().max(u_max.abs()).hypot(half_width),
        }
    }
}

/// A point of a swept path with its unit tangent `t` and the section's unit `u` axis
/// (normal to `t`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Frame {
    /// Position.
    pub o: Vec3,
    /// Section u axis (the v axis is t × u).
    pub u: Vec3,
}

/// A bounding-volume hierarchy over indexed boxes: leaves hold one index.
#[derive(Clone, Debug)]
pub struct Bvh {
    nodes: Vec<BvhNode>,
}

#[derive(Clone, Debug)]
struct BvhNode {
    bounds: Aabb,
    /// Leaf: the item; inner: `usize::MAX`.
    item: usize,
    /// Inner: children indices.
    left: usize,
    right: usize,
}

impl Bvh {
    /// Build over `boxes` (item i has box i) by median splits along the longest axis.
    pub fn new(boxes: &[Aabb]) -> Bvh {
        let mut nodes = Vec::with_capacity(2 * boxes.len());
        let mut items: Vec<usize> = (0..boxes.len()).collect();
        if !boxes.is_empty() {
            Self::build(boxes, &mut items, &mut nodes);
        }
        Bvh { nodes }
    }

    fn build(boxes: &[Aabb], items: &mut [usize], nodes: &mut Vec<BvhNode>) -> usize {
        let bounds = items.iter().fold(Aabb::EMPTY, |b, &i| b.union(&boxes[i]));
        let at = nodes.len();
        if items.len() == 1 {
            nodes.push(BvhNode {
                bounds,
                item: items[0],
                left: 0,
                right: 0,
            });
            return at;
        }
        nodes.push(BvhNode {
            bounds,
            item: usize::MAX,
            left: 0,
            right: 0,
        });
        let s = bounds.size();
        let axis = if s[0] >= s[1] && s[0] >= s[2] {
            0
        } else if s[1] >= s[2] {
            1
        } else {
            2
        };
        let mid = items.len() / 2;
        items.select_nth_unstable_by(mid, |&a, &b| {
            let ca = boxes[a].min[axis] + boxes[a].max[axis];
            let cb = boxes[b].min[axis] + boxes[b].max[axis];
            ca.total_cmp(&cb)
        });
        let (l, r) = items.split_at_mut(mid);
        let left = Self::build(boxes, l, nodes);
        let right = Self::build(boxes, r, nodes);
        nodes[at].left = left;
        nodes[at].right = right;
        at
    }

    /// The whole box.
    pub fn bounds(&self) -> Aabb {
        self.nodes.first().map_or(Aabb::EMPTY, |n| n.bounds)
    }

    /// Smallest `eval(item)` over items whose box distance to `p` is below the running
    /// minimum (or that contain `p`), nearer boxes first, starting from `start` (items
    /// farther than it are not looked at; `start` is returned when none is nearer).
    /// `eval` must never be smaller than the distance from `p` to its item's box when
    /// positive, so the skipped items cannot win. `eval(item, best)` receives the running
    /// minimum and may return any value not below it (e.g. infinity) once it knows its item
    /// cannot beat it. Once the minimum is negative (`p` is inside an item), items are
    /// looked at only if `every_holder` and their box holds `p`.
    pub fn min_over(
        &self,
        p: [f64; 3],
        start: f64,
        every_holder: bool,
        mut eval: impl FnMut(usize, f64) -> f64,
    ) -> f64 {
        let mut best = start;
        if self.nodes.is_empty() {
            return best;
        }
        // Squared box distances throughout (no root per node). The tree is balanced (median
        // splits), so the stack never holds more than its depth plus one entries.
        let mut stack = [(0usize, 0.0f64); BVH_STACK];
        stack[0] = (0, self.nodes[0].bounds.distance_squared(p));
        let mut len = 1;
        while len > 0 {
            len -= 1;
            let (i, d2) = stack[len];
            let holder_wanted = every_holder && d2 <= 0.0;
            let reach = best.max(0.0);
            if d2 >= reach * reach && best.is_finite() && !holder_wanted {
                continue;
            }
            let n = &self.nodes[i];
            if n.item != usize::MAX {
                best = best.min(eval(n.item, best));
                continue;
            }
            let (dl, dr) = (
                self.nodes[n.left].bounds.distance_squared(p),
                self.nodes[n.right].bounds.distance_squared(p),
            );
            // Push the farther first so the nearer is visited first.
            let (first, second) = if dl <= dr {
                ((n.right, dr), (n.left, dl))
            } else {
                ((n.left, dl), (n.right, dr))
            };
            stack[len] = first;
            stack[len + 1] = second;
            len += 2;
        }
        best
    }
}

/// Entries of [`Bvh::min_over`]'s stack: a balanced tree over n items is ⌈log₂ n⌉ deep and
/// the stack holds at most one more entry than that, so 64 serves any number of items.
const BVH_STACK: usize = 64;

/// A section swept along a closed loop of frames (the last frame joins the first).
#[derive(Clone, Debug)]
pub struct Sweep {
    frames: Vec<Frame>,
    /// For segment i, the unit normals of the planes that end its piece at frame i and at
    /// frame i + 1: the mitres of those joints, or the segment's own direction where a
    /// joint has none (see [`Sweep::segment_dist`]).
    ends: Vec<[Vec3; 2]>,
    /// Per segment, what [`Sweep::segment_dist`] needs of its frames, computed once.
    segs: Vec<Segment>,
    section: Section,
    /// A half ellipse's table ([`EllipseTable`]), which the pieces' distances read.
    ellipse: Option<Arc<EllipseTable>>,
    /// The segments that make this solid, in leaf order: all of them, or the part of the
    /// loop [`Sweep::split_by_twist`] gave it. Leaf g of `bvh` holds entries
    /// g·[`SEGMENTS_PER_LEAF`] onwards.
    ids: Vec<usize>,
    /// Over runs of [`SEGMENTS_PER_LEAF`] entries of `ids`.
    bvh: Bvh,
    /// Per segment, its box (see [`Sweep::new`]): a piece's value is never below its
    /// box's distance.
    boxes: Vec<Aabb>,
    /// Per segment, how fast its piece's value may change per mm (see [`Sweep::new`]).
    slopes: Vec<f64>,
    /// [`Sdf::lipschitz`]: the largest of `slopes` over `ids`.
    lipschitz: f64,
    /// The pieces near each cell of the space round this solid (see
    /// [`Sweep::pieces_dist`]).
    cells: CellLists,
}

/// Why a loop of frames cannot be swept ([`Sweep::new`]). Frames are numbered from 0.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum SweepError {
    /// Fewer than three frames.
    #[error("{frames} frames: a closed loop needs at least 3")]
    TooFewFrames {
        /// How many there are.
        frames: usize,
    },
    /// A frame's `u` lies along the loop, so the section's plane has no orientation there.
    #[error("frame {frame}: its u axis lies along the loop, so the cross-section has no orientation there")]
    AxisAlongLoop {
        /// The frame.
        frame: usize,
    },
    /// Two neighbouring frames' `u` axes are opposite: the section would turn through 180°
    /// at one point between them.
    #[error("frames {segment} and {next}: their u axes are opposite, so the cross-section would turn through 180° between them")]
    OppositeAxes {
        /// The first frame of the segment.
        segment: usize,
        /// The next frame.
        next: usize,
    },
}

/// Below this fraction of its length, the part of a `u` axis normal to its segment (or of
/// the axis interpolated between two frames) leaves the section without an orientation:
/// far above round-off, and far below what a sampled curve's normals give (they make tens
/// of degrees with the curve at least).
const AXIS_MIN_NORMAL: f64 = 1e-9;

/// How far beyond its mitre plane a point still counts as within a piece, mm: far below
/// any resolution, far above the round-off of the plane test (a point on the plane shared
/// by two pieces once fell in neither, and came out outside the sweep, by 1e-16).
const MITRE_SLACK_MM: f64 = 1e-9;

/// How far above the best value so far [`Sweep::segment_dist`]'s first test of the
/// section's rectangle must put a piece before it is skipped, mm. That test measures
/// along the interpolated section axis before it is made unit, so its value differs from
/// the exact test's by round-off (below 10⁻¹³ mm at the parts' sizes); with this slack it
/// skips only pieces the exact test skips, and the sweep's value stays the same to the
/// last bit.
const RECT_SKIP_SLACK_MM: f64 = 1e-9;

/// One segment of a [`Sweep`]'s loop, from frame i to frame i + 1.
#[derive(Clone, Copy, Debug)]
struct Segment {
    /// Frame i's origin.
    o: Vec3,
    /// Unit direction, or zero when the two frames' origins coincide (never measured).
    t: Vec3,
    /// Length, mm.
    len: f64,
    /// The two frames' u axes made normal to the segment: the section's u at parameter s
    /// is `a (1 − s) + b s`, normalized.
    a: Vec3,
    b: Vec3,
}

/// Largest turn between two segments that is joined by a mitre, degrees; sharper joints
/// keep the segments' square ends (a mitre's reach beyond the frame grows as 1/cos of
/// half the turn). The parts' loops turn by at most 11° per segment.
const MITRE_MAX_TURN_DEG: f64 = 60.0;

impl Sweep {
    /// Sweep `section` along the closed loop `frames` (at least 3; `u` need not be exactly
    /// normal to the loop: each segment re-orthogonalizes it). Refused where the section's
    /// orientation is undefined: a `u` along the loop, or two neighbours' `u` opposite
    /// (the section would turn through 180° at one point of the segment between them).
    pub fn new(frames: Vec<Frame>, section: Section) -> Result<Sweep, SweepError> {
        let n = frames.len();
        if n < 3 {
            return Err(SweepError::TooFewFrames { frames: n });
        }
        let tangent = |i: usize| (frames[(i + 1) % n].o - frames[i].o).try_normalize(0.0);
        let cos_max = MITRE_MAX_TURN_DEG.to_radians().cos();
        // A mitre bisects the turn; a joint too sharp (or next to an empty segment) has
        // none, and its segments keep square ends there.
        let mitres: Vec<Option<Vec3>> = (0..n)
            .map(|i| match (tangent((i + n - 1) % n), tangent(i)) {
                (Some(a), Some(b)) if a.dot(&b) >= cos_max => Some((a + b).normalize()),
                _ => None,
            })
            .collect();
        let ends: Vec<[Vec3; 2]> = (0..n)
            .map(|i| {
                // An empty segment is never measured (see `segment_dist`).
                let t = tangent(i).unwrap_or_else(Vec3::zeros);
                [mitres[i].unwrap_or(t), mitres[(i + 1) % n].unwrap_or(t)]
            })
            .collect();
        let r = section.extent();
        let boxes: Vec<Aabb> = (0..n)
            .map(|i| {
                let (a, b) = (frames[i].o, frames[(i + 1) % n].o);
                // Beyond a square end the piece reaches out to the mitre, so a point in it
                // at lateral offset ρ is up to ρ / cos α from the frame (α half the turn),
                // while its distance is at least ρ − r. The box must never be farther than
                // the distance (the hierarchy prunes by it), which holds for every ρ whose
                // distance can matter (ρ < r + SWEEP_EXACT_WITHIN_MM) when the frame's
                // ball grows by (r + SWEEP_EXACT_WITHIN_MM)(1 / cos α − 1).
                let cos_half =
                    tangent(i).map_or(1.0, |t| ends[i][0].dot(&t).min(ends[i][1].dot(&t)));
                let grow = (r + SWEEP_EXACT_WITHIN_MM) * (1.0 / cos_half - 1.0);
                Aabb::new(arr(a), arr(a))
                    .union(&Aabb::new(arr(b), arr(b)))
                    .inflate(r + grow)
            })
            .collect();
        // A point moving along a segment sees the section's axes turn (u is interpolated
        // between the frames') at ω = dφ/ds / len radians per mm; the section's distance
        // changes with that turn by at most |c × n| ≤ r per radian (c the closest point of
        // the section, n its normal), so moving one mm changes the value by at most
        // √(1 + (r·ω)²). For the nlerp of the u axes a, b (made normal to the segment),
        // dφ/ds = |a × b| / |a(1 − s) + b s|², largest where the denominator is least.
        // Each segment with its frames' u made normal to it; the frames are checked first,
        // so that a u along the loop is named as such rather than as a turn.
        let segs: Vec<Segment> = (0..n)
            .map(|i| {
                let (f0, f1) = (&frames[i], &frames[(i + 1) % n]);
                let t = tangent(i).unwrap_or_else(Vec3::zeros);
                Segment {
                    o: f0.o,
                    t,
                    len: (f1.o - f0.o).norm(),
                    a: f0.u - t * f0.u.dot(&t),
                    b: f1.u - t * f1.u.dot(&t),
                }
            })
            .collect();
        let measured = |i: usize| segs[i].len > 0.0;
        for i in (0..n).filter(|&i| measured(i)) {
            for (frame, normal) in [(i, segs[i].a), ((i + 1) % n, segs[i].b)] {
                // Written so that a NaN (a u of NaN) is refused too.
                let enough = normal.norm() > AXIS_MIN_NORMAL * frames[frame].u.norm();
                if !enough {
                    return Err(SweepError::AxisAlongLoop { frame });
                }
            }
        }
        let mut slopes = vec![1.0f64; n];
        for i in (0..n).filter(|&i| measured(i)) {
            let Segment { a, b, len, .. } = segs[i];
            let d = a - b;
            let s = if d.norm_squared() > 0.0 {
                (a.dot(&d) / d.norm_squared()).clamp(0.0, 1.0)
            } else {
                0.0
            };
            let least = (a * (1.0 - s) + b * s).norm();
            if least <= AXIS_MIN_NORMAL * a.norm().max(b.norm()) {
                return Err(SweepError::OppositeAxes {
                    segment: i,
                    next: (i + 1) % n,
                });
            }
            let omega = a.cross(&b).norm() / (least * least) / len;
            slopes[i] = (1.0 + (r * omega).powi(2)).sqrt();
        }
        Ok(Sweep::of_segments(
            frames,
            ends,
            segs,
            section,
            boxes,
            slopes,
            (0..n).collect(),
        ))
    }

    /// The solid made of the pieces `ids` (in that order in the hierarchy's leaves).
    fn of_segments(
        frames: Vec<Frame>,
        ends: Vec<[Vec3; 2]>,
        segs: Vec<Segment>,
        section: Section,
        boxes: Vec<Aabb>,
        slopes: Vec<f64>,
        ids: Vec<usize>,
    ) -> Sweep {
        let leaf_boxes: Vec<Aabb> = ids
            .chunks(SEGMENTS_PER_LEAF)
            .map(|c| c.iter().fold(Aabb::EMPTY, |b, &i| b.union(&boxes[i])))
            .collect();
        let bvh = Bvh::new(&leaf_boxes);
        let lipschitz = ids.iter().map(|&i| slopes[i]).fold(1.0, f64::max);
        let cells = Sweep::make_cells(&segs, &ends, section, &boxes, &ids);
        let ellipse = match section {
            Section::HalfEllipse { a, b } => Some(EllipseTable::shared(a, b)),
            Section::RoundedRect { .. } => None,
        };
        Sweep {
            frames,
            ends,
            segs,
            section,
            ellipse,
            ids,
            bvh,
            boxes,
            slopes,
            lipschitz,
            cells,
        }
    }

    /// This solid cut into parts whose union it is, each of the pieces whose slope (how
    /// fast a piece's value may change per mm, from how fast its section turns) lies in
    /// one band: at most `mild`, or above it. A search whose bound on the change is the
    /// solid's [`Sdf::lipschitz`] (the swept volumes of `build`) pays for a short, sharply
    /// twisted stretch of a loop along the whole loop: half-turn-2to1's fifth rim turns
    /// 11° in a quarter of a millimetre over a few segments (slope 2.84) and about 1° per
    /// mm elsewhere (slope 1.02). Split, each part is searched with its own bound. One part
    /// (this solid) when every piece is on one side.
    pub fn split_by_twist(&self, mild: f64) -> Vec<Sweep> {
        let (gentle, steep): (Vec<usize>, Vec<usize>) =
            self.ids.iter().partition(|&&i| self.slopes[i] <= mild);
        if gentle.is_empty() || steep.is_empty() {
            return vec![self.clone()];
        }
        [gentle, steep]
            .into_iter()
            .map(|ids| {
                Sweep::of_segments(
                    self.frames.clone(),
                    self.ends.clone(),
                    self.segs.clone(),
                    self.section,
                    self.boxes.clone(),
                    self.slopes.clone(),
                    ids,
                )
            })
            .collect()
    }

    /// The section's distance at (u, v): a half ellipse's through its table.
    fn section_dist(&self, u: f64, v: f64) -> f64 {
        match (&self.ellipse, self.section) {
            (Some(table), Section::HalfEllipse { a, b }) => {
                half_ellipse_dist(u, v, a, b, |x, y| table.dist(x, y))
            }
            _ => self.section.dist(u, v),
        }
    }

    /// The frames.
    pub fn frames(&self) -> &[Frame] {
        &self.frames
    }

    /// The section.
    pub fn section(&self) -> Section {
        self.section
    }

    /// Distance from `p` to the piece of the sweep between frames `i` and `i + 1`, or
    /// infinity when it is known not to be below `best`: the union over segments is the
    /// sweep.
    ///
    /// The piece is the section extruded along the segment, with square ends, together with
    /// its continuation up to the mitre planes that bisect the turns at its frames. Square
    /// ends alone leave a thin wedge open on the outer side of every turn, at every frame:
    /// a point there is beyond both segments' ends and came out just outside the solid
    /// however deep in it, and where a grid point fell into a wedge the mesher cut a pit
    /// up to the section's depth (seen on the 0.4 mm driver of half-turn-2to1 as hundreds
    /// of dark specks on the bands' faces).
    ///
    /// A point beyond the square end by `along` (and outside the mitres) is at least `along`
    /// from the piece whatever the section, so the section's distance (the costly part) is
    /// skipped when that cannot win.
    fn segment_dist(&self, i: usize, p: Vec3, best: f64) -> f64 {
        let seg = &self.segs[i];
        let len = seg.len;
        if len <= 0.0 {
            return f64::INFINITY;
        }
        let t = seg.t;
        let from = p - seg.o;
        let raw = from.dot(&t);
        let s = (raw / len).clamp(0.0, 1.0);
        let [m0, m1] = self.ends[i];
        // Both pieces that share a mitre plane count the plane as theirs, so round-off can
        // never leave a point on it in neither.
        let within_mitres =
            || from.dot(&m0) >= -MITRE_SLACK_MM && (from - t * len).dot(&m1) <= MITRE_SLACK_MM;
        let along = if (0.0..=len).contains(&raw) || within_mitres() {
            0.0
        } else if raw < 0.0 {
            -raw
        } else {
            raw - len
        };
        if along > 0.0 && along >= best {
            return f64::INFINITY;
        }
        let mut u = seg.a * (1.0 - s) + seg.b * s;
        let l2 = u.norm_squared();
        if l2 <= 0.0 {
            return f64::INFINITY;
        }
        let ul = l2.sqrt();
        let d = from - t * (len * s);
        // The section's rectangle first, measured along the axis before it is made unit
        // and compared squared: of the pieces that pass the ends' test, most are skipped
        // here (on half-turn-2to1's driver carve 182 M of 337 M), without the divisions
        // and square roots of the exact bounds below. The slack keeps it from skipping a
        // piece those would keep.
        let reach = best.max(0.0) + RECT_SKIP_SLACK_MM;
        let gap = self
            .section
            .rect_gap_sq_scaled(d.dot(&u), d.dot(&t.cross(&u)), ul);
        if gap + along * along * l2 >= reach * reach * l2 {
            return f64::INFINITY;
        }
        u /= ul;
        let v = t.cross(&u);
        let (du, dv) = (d.dot(&u), d.dot(&v));
        let bound = self.section.lower_bound(du, dv);
        // The exact bounds, compared squared with the same slack as the rectangle's.
        if bound * bound + along * along >= reach * reach {
            return f64::INFINITY;
        }
        // Far from a half ellipse its distance is a lower bound that may be below `bound`;
        // the larger of the two is a lower bound too. Taking it makes every piece's value at
        // least the bounds it is pruned by (`lower` here, its box in the hierarchy), so the
        // sweep's value is the least over all its pieces whatever the walk skipped, far out
        // as near: with the smaller, the far values depended on which pieces were visited
        // (grouping segments into leaves moved a strut of demo's driver).
        let sigma = match self.section_dist(du, dv) {
            sigma if sigma > 0.0 => sigma.max(bound),
            sigma => sigma,
        };
        if along == 0.0 {
            sigma
        } else if sigma > 0.0 {
            norm2(sigma, along)
        } else {
            sigma.max(along)
        }
    }
}

/// Distances to a sweep are exact up to this many mm from it and a lower bound beyond
/// (the BVH then skips every far segment: seen from the middle of a loop all segments are
/// equally far, and visiting them all dominated meshing). 8 mm: above every consumer's
/// need (the mesher's block test at 0.4 mm cells needs 3.9, the carve and column checks at
/// most 5.7).
pub const SWEEP_EXACT_WITHIN_MM: f64 = 8.0;

/// Consecutive segments per leaf of a sweep's hierarchy: a leaf's box is the union of its
/// segments' boxes, and a query that reaches it tries each segment in turn (the cheap
/// bounds of [`Sweep::segment_dist`] skip most). A segment (0.2–0.8 mm on the parts'
/// loops) is far shorter than its box (the section's extent on every side, 3.4 mm for a
/// rim), so one-segment leaves overlap heavily and a query near a loop walked 42 nodes to
/// reach 17 leaves. Measured with a probe of 2.4 M queries near the rims and bands of the
/// demo's design (the values below 2 mm identical): 2.03–2.29 µs per query with one
/// segment per leaf, 1.67 with 2, 1.49–1.73 with 4, 1.42–1.46 with 8, 1.60 with 16.
const SEGMENTS_PER_LEAF: usize = 8;

/// The cells of a sweep's lists of near pieces ([`Sweep::pieces_dist`]), mm. Measured on
/// half-turn-2to1's printable build (docs/build.md, "Each sweep's pieces listed per
/// cell"): 0.7 mm cells visit 5.9 pieces per query instead of 6.9 and hold 2.6 times the
/// entries, for no time gained.
const SWEEP_CELL_MM: f64 = 1.0;

/// What [`Sweep::bounds_over`] allows its bounds, mm: a half ellipse's distance is read
/// from a table within 6·10⁻⁵ mm of the exact value ([`EllipseTable`]), and the bounds
/// must hold for the value read.
const SECTION_TABLE_SLACK_MM: f64 = 1e-3;

/// How far from a cell its list of near pieces holds every piece, mm: a query whose limit
/// is above it, at a point whose cell cannot promise a piece within it, walks the
/// hierarchy instead. The carve's and the mesher's queries ask below 3 mm or near a part;
/// a reach of 4 mm held 1.5 times the entries (11 M over the 16 sweeps of half-turn-2to1's
/// build, against 7.2 M) for the same time.
const SWEEP_CELLS_REACH_MM: f64 = 3.0;

impl Sweep {
    /// The distance over the pieces, exact below `limit` ([`Sdf::dist_continuous`]; `limit`
    /// itself when no piece is nearer). Inside, every piece that holds `p` is asked and the
    /// deepest wins, for [`Sdf::dist`] too: where two pieces meet at a mitre both may hold
    /// a point, and the first one's value was up to 0.065 mm shallower on half-turn-2to1's
    /// twisted rim (measured on 2 × 10⁵ points per rim; the mesher shrinks the follower by
    /// half the clearance, so its rims came out that much thin at their joints). Measured
    /// with a probe of 2.4 M queries near the rims and bands of the demo's design, asking
    /// every holder costs no more than the run-to-run spread (2.0–2.6 µs per query).
    ///
    /// A point asks first the pieces its cell lists ([`CellLists`]), nearest bound first,
    /// and stops at the first bound not below its best: it visited 6.9 pieces per query
    /// where the hierarchy's walk visited 18.9 (and 24 nodes), on the driver's carve of
    /// half-turn-2to1. Where the lists cannot promise the value (a limit beyond their reach
    /// at a point the cell cannot promise a piece near), the hierarchy is walked; the value
    /// is the least over every piece either way, to the last bit (a test compares them).
    fn pieces_dist(&self, p: Vec3, limit: f64) -> f64 {
        let start = limit.min(SWEEP_EXACT_WITHIN_MM);
        if let Some(near) = self.cells.near(arr(p)) {
            let reach = self.cells.reach();
            if start <= reach || near.high <= reach {
                // A piece's value is never below its bound, and the bounds come smallest
                // first: past the first bound not below the best (and above 0, where
                // pieces holding `p` may still come), no piece can lower it. The pieces
                // left out of the cell's list are at least the reach away, and the least
                // value is at most the cell's upper bound, so the best found is the least
                // over every piece (below `start`), as the hierarchy's walk gives it.
                let mut best = start.min(near.high);
                for (&i, &low) in near.items.iter().zip(near.lows) {
                    let low = f64::from(low);
                    if low > 0.0 && low >= best {
                        break;
                    }
                    best = best.min(self.segment_dist(i as usize, p, best));
                }
                return best;
            }
        }
        self.walked_dist(p, start)
    }

    /// [`Sweep::pieces_dist`] through the hierarchy alone, from `start` (at most
    /// [`SWEEP_EXACT_WITHIN_MM`]): what the cells' lists must agree with.
    fn walked_dist(&self, p: Vec3, start: f64) -> f64 {
        let v = self.bvh.min_over(arr(p), start, true, |leaf, mut best| {
            let first = leaf * SEGMENTS_PER_LEAF;
            for &i in &self.ids[first..(first + SEGMENTS_PER_LEAF).min(self.ids.len())] {
                best = best.min(self.segment_dist(i, p, best));
            }
            best
        });
        if v < SWEEP_EXACT_WITHIN_MM {
            v
        } else {
            self.bvh
                .bounds()
                .distance(arr(p))
                .max(SWEEP_EXACT_WITHIN_MM)
        }
    }

    /// [`Sweep::pieces_dist`]'s lists: the pieces `ids` per [`SWEEP_CELL_MM`] cell,
    /// bounded over the cell below by their boxes and [`Sweep::bounds_over`].
    fn make_cells(
        segs: &[Segment],
        ends: &[[Vec3; 2]],
        section: Section,
        boxes: &[Aabb],
        ids: &[usize],
    ) -> CellLists {
        let mut listed = vec![Aabb::EMPTY; segs.len()];
        for &i in ids {
            listed[i] = boxes[i];
        }
        // The section's share of the bounds, the same for every piece and cell.
        let (extent, origin_gap) = (section.extent(), section.dist(0.0, 0.0).max(0.0));
        CellLists::new(&listed, SWEEP_CELL_MM, SWEEP_CELLS_REACH_MM, |i, cell| {
            Sweep::bounds_over(&segs[i], ends[i], extent, origin_gap, cell)
        })
    }

    /// A lower and an upper bound of a piece's value ([`Sweep::segment_dist`]) at every
    /// point of `cell`. Below: the value is at least how far beyond the piece's square ends
    /// the point lies (0 between them, or between its mitres), and at least its distance
    /// from the segment's line less the section's extent (the section lies within that of
    /// the line wherever along it the point is measured). Above: the value is at most the
    /// point's distance from the segment plus the section's distance at its origin (the
    /// section's distance changes by at most the distance moved in its plane). `extent` is
    /// the section's [`Section::extent`], `origin_gap` its distance at the origin (0 when
    /// the section holds it). Infinity for an empty segment, which is never measured.
    fn bounds_over(
        seg: &Segment,
        [m0, m1]: [Vec3; 2],
        extent: f64,
        origin_gap: f64,
        cell: &Aabb,
    ) -> (f64, f64) {
        if seg.len <= 0.0 {
            return (f64::INFINITY, f64::INFINITY);
        }
        let c = v3(cell.center());
        let size = cell.size();
        // How far a linear function with gradient n varies from the centre over the cell.
        let spread =
            |n: Vec3| 0.5 * (n.x.abs() * size[0] + n.y.abs() * size[1] + n.z.abs() * size[2]);
        let half_diagonal = 0.5 * norm2(norm2(size[0], size[1]), size[2]);
        let from = c - seg.o;
        let (raw, r) = (from.dot(&seg.t), spread(seg.t));
        let lateral =
            ((from - seg.t * raw).norm() - half_diagonal - extent - SECTION_TABLE_SLACK_MM)
                .max(0.0);
        let along = if raw + r >= 0.0 && raw - r <= seg.len {
            0.0
        } else {
            let slack = 2.0 * MITRE_SLACK_MM;
            let may_be_within = from.dot(&m0) + spread(m0) >= -slack
                && (from - seg.t * seg.len).dot(&m1) - spread(m1) <= slack;
            if may_be_within {
                0.0
            } else if raw + r < 0.0 {
                -(raw + r)
            } else {
                raw - r - seg.len
            }
        };
        let to_segment = (from - seg.t * raw.clamp(0.0, seg.len)).norm();
        let high = to_segment + half_diagonal + origin_gap + SECTION_TABLE_SLACK_MM;
        (norm2(lateral, along), high)
    }
}

impl Sdf for Sweep {
    fn dist(&self, p: Vec3) -> f64 {
        self.pieces_dist(p, f64::INFINITY)
    }
    fn dist_continuous(&self, p: Vec3, limit: f64) -> f64 {
        self.pieces_dist(p, limit)
    }
    fn lipschitz(&self) -> f64 {
        self.lipschitz
    }
    fn bounds(&self) -> Aabb {
        self.bvh.bounds()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Guards the segment pruning's premise: [`Section::lower_bound`] is never above the
    /// section's distance, outside it or in, for both sections, and is near it on the
    /// flanks of the half ellipse, where the bounding rectangle alone says 0.
    #[test]
    fn section_lower_bounds_never_exceed_the_distance() {
        let sections = [
            Section::HalfEllipse { a: 3.0, b: 1.6 },
            Section::HalfEllipse { a: 1.0, b: 2.5 },
            Section::RoundedRect {
                u_min: -3.5,
                u_max: 1.5,
                half_width: 1.6,
                round: 0.5,
            },
        ];
        for section in sections {
            for i in 0..4000 {
                let (u, v) = (
                    (i as f64 * 0.618).sin() * 7.0,
                    (i as f64 * 1.303).cos() * 5.0,
                );
                // Beyond ELLIPSE_FAR `dist` is itself a lower bound; compare where it is exact.
                if let Section::HalfEllipse { a, b } = section {
                    if norm2(u + a, v) > a.max(b) + ELLIPSE_FAR {
                        continue;
                    }
                }
                let (lb, d) = (section.lower_bound(u, v), section.dist(u, v));
                assert!(
                    lb <= d.max(0.0) + 1e-12,
                    "{section:?} at ({u}, {v}): {lb} > {d}"
                );
            }
        }
        // Beside the apex, inside the rectangle but 0.42 mm off the ellipse.
        let rim = Section::HalfEllipse { a: 3.0, b: 1.6 };
        let (u, v) = (-0.5, 1.5);
        assert!(rim.dist(u, v) > 0.3);
        assert!(rim.lower_bound(u, v) > 0.2, "{}", rim.lower_bound(u, v));
    }

    /// The ellipse distance agrees with a brute-force distance to a dense polygon of the
    /// ellipse, inside and outside, for flat and round ellipses.
    #[test]
    fn ellipse_distance_matches_brute_force() {
        for &(a, b) in &[(3.0, 1.6), (1.0, 1.0), (5.0, 0.5), (0.8, 2.0)] {
            let poly: Vec<(f64, f64)> = (0..20000)
                .map(|k| {
                    let s = k as f64 / 20000.0 * std::f64::consts::TAU;
                    (a * s.cos(), b * s.sin())
                })
                .collect();
            for i in 0..40 {
                let (x, y) = (
                    (i as f64 * 0.731).sin() * 1.6 * a,
                    (i as f64 * 1.37).cos() * 1.6 * b,
                );
                let brute = poly
                    .iter()
                    .map(|&(px, py)| (x - px).hypot(y - py))
                    .fold(f64::INFINITY, f64::min);
                let d = ellipse_distance(x, y, a, b);
                if norm2(x, y) > a.max(b) + ELLIPSE_FAR {
                    // Far away: a positive lower bound.
                    assert!(d > 0.0 && d <= brute + 1e-9, "far bound {d} vs {brute}");
                    continue;
                }
                assert!(
                    (d.abs() - brute).abs() < 2e-3 * a.max(b),
                    "a {a} b {b} at ({x}, {y}): {d} vs {brute}"
                );
                assert_eq!(d < 0.0, (x / a).powi(2) + (y / b).powi(2) < 1.0);
            }
        }
    }

    /// Guards the sweeps' ellipse: the table stays within 6·10⁻⁵ of the exact distance
    /// within half a unit of the rims' ellipse (what the mesher and the carve read; more
    /// on sharper ellipses, as their curvature says) and within
    /// 10⁻³ anywhere in its reach (near the segment between the centres of curvature, where
    /// the distance has a crease that bilinear interpolation rounds), for flat and round
    /// ellipses either way up, and gives the same lower bound beyond its reach. And the
    /// exact distance is exact where the evolute iteration used before was not: on the
    /// major axis inside, where its four steps stopped up to 1.7·10⁻⁴ off.
    #[test]
    fn the_ellipse_table_matches_the_exact_distance() {
        for &(a, b) in &[(3.0, 1.6), (1.0, 1.0), (5.0, 0.5), (0.8, 2.0)] {
            let table = EllipseTable::shared(a, b);
            assert!(
                Arc::ptr_eq(&table, &EllipseTable::shared(a, b)),
                "made once"
            );
            let (mut near, mut anywhere) = (0.0f64, 0.0f64);
            for i in 0..60_000 {
                let (x, y) = (
                    (i as f64 * 0.618_034).fract() * 2.0 - 1.0,
                    (i as f64 * 0.414_214).fract() * 2.0 - 1.0,
                );
                let reach = a.max(b) + ELLIPSE_FAR + 1.0;
                let (x, y) = (x * reach, y * reach);
                let (got, exact) = (table.dist(x, y), ellipse_distance(x, y, a, b));
                if norm2(x, y) > a.max(b) + ELLIPSE_FAR {
                    assert_eq!(got, exact, "beyond the reach at ({x}, {y})");
                    continue;
                }
                if exact.abs() < 0.5 {
                    near = near.max((got - exact).abs());
                }
                anywhere = anywhere.max((got - exact).abs());
            }
            // Bilinear interpolation errs by up to h²κ/8 where the distance bends at κ per
            // unit: four times that at the sharpest vertex (a/b²), and 5·10⁻⁵ at least.
            let sharpest = a.max(b) / (a.min(b) * a.min(b));
            let tol = (0.5 * ELLIPSE_TABLE_CELL * ELLIPSE_TABLE_CELL * sharpest).max(5e-5);
            assert!(near < tol, "a {a} b {b}: {near} within 0.5 of the ellipse");
            assert!(anywhere < 1e-3, "a {a} b {b}: {anywhere} in the reach");
        }
        // On the major axis inside: the closest points are off the axis, at x = a²p/(a²−b²).
        let (a, b, p) = (3.0, 1.6, 2.0);
        let q = a * a * p / (a * a - b * b);
        let want = -norm2(q - p, b * (1.0 - (q / a) * (q / a)).sqrt());
        assert!((ellipse_distance(p, 0.0, a, b) - want).abs() < 1e-12);
        assert!((ellipse_distance(p, 1e-9, a, b) - want).abs() < 1e-8);
    }

    /// The half ellipse's apex is on its surface with the flat side behind it, and the
    /// rounded rectangle is exact on its sides.
    #[test]
    fn section_distances() {
        let h = Section::HalfEllipse { a: 3.0, b: 1.5 };
        assert!(h.dist(0.0, 0.0).abs() < 1e-9);
        assert!((h.dist(1.0, 0.0) - 1.0).abs() < 1e-9);
        assert!((h.dist(-3.5, 0.0) - 0.5).abs() < 1e-12);
        assert!((h.dist(-3.0, 2.5) - 1.0).abs() < 1e-12);
        // Within the apex's radius of curvature (b²/a = 0.75) the apex is nearest.
        assert!((h.dist(-0.5, 0.0) + 0.5).abs() < 1e-9);
        let r = Section::RoundedRect {
            u_min: -4.0,
            u_max: 1.0,
            half_width: 3.0,
            round: 0.5,
        };
        assert!((r.dist(2.0, 0.0) - 1.0).abs() < 1e-12);
        assert!((r.dist(-1.5, 4.0) - 1.0).abs() < 1e-12);
        assert!((r.dist(-1.5, 0.0) + 2.5).abs() < 1e-12);
    }

    /// `n` frames on the circle of radius `big` about z (in z = 0), the section's u axis
    /// turned from the radial direction towards +z by `phi(a)` at polar angle a.
    fn turning_circle(big: f64, n: usize, phi: impl Fn(f64) -> f64) -> Vec<Frame> {
        (0..n)
            .map(|i| {
                let a = i as f64 / n as f64 * std::f64::consts::TAU;
                let (radial, turn) = (Vec3::new(a.cos(), a.sin(), 0.0), phi(a));
                Frame {
                    o: radial * big,
                    u: radial * turn.cos() + Vec3::z() * turn.sin(),
                }
            })
            .collect()
    }

    /// Guards [`Sdf::dist_continuous`] and [`Sdf::lipschitz`] of a sweep whose section
    /// turns about the loop at 0.5 rad per mm (a contact normal that twists, as on rim 5 of
    /// half-turn-2to1): over seeded random short moves in and around the solid, the value
    /// never changes by more than the bound times the move where it is exact (within
    /// [`ELLIPSE_FAR`]; the exact sweeps prune time by it), and the bound is above 1.5 (a
    /// turning section moves its value faster than the point moves; the untwisted loop's
    /// bound is 1).
    #[test]
    fn a_twisted_sweep_changes_no_faster_than_its_bound() {
        use rand::{Rng, SeedableRng};
        let big = 50.0;
        // 0.5 rad per mm over the loop's 100π mm: 25 whole turns, so the loop closes.
        let frames = |rate: f64| turning_circle(big, 600, |a| rate * big * a);
        let twisted = Sweep::new(frames(0.5), Section::HalfEllipse { a: 3.0, b: 1.6 }).unwrap();
        let straight = Sweep::new(frames(0.0), Section::HalfEllipse { a: 3.0, b: 1.6 }).unwrap();
        assert!(twisted.lipschitz() > 1.5, "bound {}", twisted.lipschitz());
        assert!((straight.lipschitz() - 1.0).abs() < 1e-9);
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(33);
        let mut inside = 0;
        for _ in 0..20_000 {
            let a = rng.random_range(0.0..std::f64::consts::TAU);
            let r = big + rng.random_range(-4.0..4.0);
            let p = Vec3::new(r * a.cos(), r * a.sin(), rng.random_range(-4.0..4.0));
            let step = Vec3::new(
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
            ) * 0.02;
            let (f, g) = (
                twisted.dist_continuous(p, f64::INFINITY),
                twisted.dist_continuous(p + step, f64::INFINITY),
            );
            inside += usize::from(f < 0.0);
            if f.max(g) >= ELLIPSE_FAR {
                // Farther out a value may be the far lower bound.
                continue;
            }
            assert!(
                (g - f).abs() <= twisted.lipschitz() * step.norm() * (1.0 + 1e-9) + 1e-12,
                "at {p:?}: {f} to {g} over {} mm",
                step.norm()
            );
        }
        assert!(inside > 1000, "only {inside} points inside");
    }

    /// Guards [`Sweep::split_by_twist`] on a loop whose section turns a whole turn over a
    /// short stretch and not at all elsewhere: it comes out in two parts, the mild one's
    /// bound at most the threshold and the steep one's the whole loop's; the smaller of the
    /// parts' values is the loop's own to the last bit wherever that is exact (inside and
    /// out, seeded random points over the loop and thick around the twist); each part
    /// changes no faster than its own bound; and an untwisted loop stays one part.
    #[test]
    fn a_loop_split_by_twist_is_its_parts_union() {
        use rand::{Rng, SeedableRng};
        let big = 50.0;
        let frames = |turns: f64| {
            turning_circle(big, 600, |a| {
                // A smoothstep from 0 to `turns` whole turns over a ∈ [1, 1.3].
                let s = ((a - 1.0) / 0.3).clamp(0.0, 1.0);
                std::f64::consts::TAU * turns * s * s * (3.0 - 2.0 * s)
            })
        };
        let section = Section::HalfEllipse { a: 3.0, b: 1.6 };
        let flat = Sweep::new(frames(0.0), section).unwrap();
        assert_eq!(flat.split_by_twist(1.2).len(), 1);
        let whole = Sweep::new(frames(1.0), section).unwrap();
        let parts = whole.split_by_twist(1.2);
        assert_eq!(parts.len(), 2);
        let (mild, steep) = (&parts[0], &parts[1]);
        assert!(
            mild.lipschitz() <= 1.2,
            "mild part's bound {}",
            mild.lipschitz()
        );
        assert_eq!(steep.lipschitz(), whole.lipschitz());
        assert!(whole.lipschitz() > 2.0, "bound {}", whole.lipschitz());
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(34);
        let (mut compared, mut near_twist, mut inside) = (0, 0, 0);
        for k in 0..20_000 {
            // Half the points around the twist, half anywhere on the loop.
            let a = if k % 2 == 0 {
                rng.random_range(0.9..1.4)
            } else {
                rng.random_range(0.0..std::f64::consts::TAU)
            };
            let r = big + rng.random_range(-5.0..5.0);
            let p = Vec3::new(r * a.cos(), r * a.sin(), rng.random_range(-5.0..5.0));
            let d = whole.dist(p);
            if d < SWEEP_EXACT_WITHIN_MM {
                let union = mild.dist(p).min(steep.dist(p));
                assert_eq!(d, union, "at {p:?}");
                compared += 1;
                near_twist += usize::from((0.9..1.4).contains(&a));
                inside += usize::from(d < 0.0);
            }
            let step = Vec3::new(
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
                rng.random_range(-1.0..1.0),
            ) * 0.02;
            for part in &parts {
                let (f, g) = (part.dist(p), part.dist(p + step));
                if f.max(g) < ELLIPSE_FAR {
                    assert!(
                        (g - f).abs() <= part.lipschitz() * step.norm() * (1.0 + 1e-9) + 1e-12,
                        "at {p:?}: {f} to {g} over {} mm, bound {}",
                        step.norm(),
                        part.lipschitz()
                    );
                }
            }
        }
        assert!(compared > 15_000 && near_twist > 7_000 && inside > 1_000);
    }

    /// Guards the cells' lists against the hierarchy they shortcut ([`Sweep::pieces_dist`]
    /// against [`Sweep::walked_dist`]): at points inside, near and beyond the lists' reach
    /// of a twisted rim, of the steep part of a rim split by its twist, of a band with
    /// mitred and square joints, and of a section that does not hold its origin (the
    /// cells' upper bound pays for that), at limits on both sides of the reach, the value
    /// is the walk's to the last bit, and the lists answer most of the points.
    #[test]
    fn the_cells_lists_give_the_hierarchy_s_values() {
        use rand::{Rng, SeedableRng};
        let big = 30.0;
        let rim = Section::HalfEllipse { a: 3.0, b: 1.6 };
        let twisted = Sweep::new(turning_circle(big, 400, |a| 0.4 * (3.0 * a).sin()), rim).unwrap();
        // Five degrees per mm over a tenth of the loop: a steep part and a mild one.
        let kinked = turning_circle(big, 400, |a| {
            let d = (a - 1.0).clamp(0.0, 0.6);
            d * d * 8.0
        });
        let parts = Sweep::new(kinked, rim).unwrap().split_by_twist(1.2);
        assert_eq!(parts.len(), 2, "the kinked rim splits in two");
        let band = Section::RoundedRect {
            u_min: -4.0,
            u_max: 0.6,
            half_width: 2.5,
            round: 0.5,
        };
        // A decagon (36° joints, mitred) and a triangle (120°, square ends).
        let polygon = |corners: usize| -> Vec<Frame> {
            (0..corners)
                .map(|i| {
                    let a = i as f64 / corners as f64 * std::f64::consts::TAU;
                    let radial = Vec3::new(a.cos(), a.sin(), 0.0);
                    Frame {
                        o: radial * big,
                        u: radial,
                    }
                })
                .collect()
        };
        let off_origin = Section::RoundedRect {
            u_min: 1.5,
            u_max: 4.0,
            half_width: 1.0,
            round: 0.3,
        };
        // Each with the angles round the loop where its points are taken.
        let tau = std::f64::consts::TAU;
        let solids = [
            ("twisted rim", twisted, 0.0..tau),
            ("mild part", parts[0].clone(), 0.0..tau),
            ("steep part", parts[1].clone(), 0.9..1.7),
            (
                "decagon band",
                Sweep::new(polygon(10), band).unwrap(),
                0.0..tau,
            ),
            (
                "triangle band",
                Sweep::new(polygon(3), band).unwrap(),
                0.0..tau,
            ),
            (
                "section off its origin",
                Sweep::new(polygon(10), off_origin).unwrap(),
                0.0..tau,
            ),
        ];
        let limits = [0.1, 0.8, 2.0, 2.99, 3.01, 5.0, 8.0, f64::INFINITY];
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(35);
        for (name, sweep, angles) in &solids {
            let (mut listed, mut inside, mut beyond) = (0, 0, 0);
            let n = 20_000;
            for _ in 0..n {
                let a = rng.random_range(angles.clone());
                let r = big + rng.random_range(-8.0..8.0);
                let p = Vec3::new(r * a.cos(), r * a.sin(), rng.random_range(-6.0..6.0));
                let limit = limits[rng.random_range(0..limits.len())];
                let got = sweep.pieces_dist(p, limit);
                let walked = sweep.walked_dist(p, limit.min(SWEEP_EXACT_WITHIN_MM));
                assert_eq!(
                    got.to_bits(),
                    walked.to_bits(),
                    "{name}: {got} against the walk's {walked} at {p:?}, limit {limit}"
                );
                let start = limit.min(SWEEP_EXACT_WITHIN_MM);
                let reach = sweep.cells.reach();
                listed += usize::from(
                    sweep
                        .cells
                        .near(arr(p))
                        .is_some_and(|near| start <= reach || near.high <= reach),
                );
                inside += usize::from(got < 0.0);
                beyond += usize::from(got > reach && got < SWEEP_EXACT_WITHIN_MM);
            }
            assert!(listed > n / 3, "{name}: the lists answered {listed} of {n}");
            assert!(
                inside > 100 && beyond > 100,
                "{name}: {inside} inside, {beyond} beyond the reach"
            );
        }
    }

    /// Guards the pruning in the BVH walk (skipped leaves and segments, the box bound
    /// before the ellipse), for a half ellipse swept along a wavy loop: it returns the
    /// minimum over every segment evaluated in full, exactly, near the surface and far out
    /// (up to [`SWEEP_EXACT_WITHIN_MM`]), where segments' values are lower bounds: the value
    /// does not depend on what the walk skipped or in which order it went.
    #[test]
    fn pruned_distance_equals_the_full_minimum() {
        let n = 360;
        let frames: Vec<Frame> = (0..n)
            .map(|i| {
                let a = i as f64 / n as f64 * std::f64::consts::TAU;
                let r = 25.0 + 4.0 * (3.0 * a).sin();
                Frame {
                    o: Vec3::new(r * a.cos(), r * a.sin(), 3.0 * (2.0 * a).cos()),
                    u: Vec3::new(a.cos(), a.sin(), 0.3 * a.sin()).normalize(),
                }
            })
            .collect();
        let sweep = Sweep::new(frames, Section::HalfEllipse { a: 3.0, b: 1.6 }).unwrap();
        let (mut compared, mut far) = (0, 0);
        for k in 0..400 {
            let a = k as f64 * 0.137;
            let r = 25.0 + 4.0 * (3.0 * a).sin() + 6.0 * (k as f64 * 0.71).sin();
            let p = Vec3::new(r * a.cos(), r * a.sin(), 4.0 * (k as f64 * 0.53).cos());
            let full = (0..n)
                .map(|i| sweep.segment_dist(i, p, f64::INFINITY))
                .fold(f64::INFINITY, f64::min);
            if full >= SWEEP_EXACT_WITHIN_MM {
                continue;
            }
            let d = sweep.dist(p);
            assert!((d - full).abs() < 1e-12, "point {k}: {d} vs {full}");
            compared += 1;
            far += usize::from(full >= ELLIPSE_FAR);
        }
        assert!(far > 50, "only {far} points far out");
        assert!(compared > 100, "only {compared} points compared");
    }

    /// Guards the value inside a twisted sweep (half-turn-2to1's rim 4 turns its section by
    /// 11° over 0.18 mm): where the pieces of neighbouring segments both hold a point, the
    /// value is the deeper, for [`Sdf::dist`] as for the continuous value. Taking the first
    /// piece's value made up to 3 % of the points inside that rim read up to 0.065 mm
    /// shallower, and a part shrunk by half the clearance lost that much at its joints.
    #[test]
    fn a_sweep_s_value_inside_is_its_deepest_piece_s() {
        use rand::{Rng, SeedableRng};
        let (big, n) = (30.0, 600);
        // 1 rad per mm over the loop's 60π mm: 30 whole turns, so the loop closes.
        let frames: Vec<Frame> = (0..n)
            .map(|i| {
                let a = i as f64 / n as f64 * std::f64::consts::TAU;
                let phi = big * a;
                let radial = Vec3::new(a.cos(), a.sin(), 0.0);
                Frame {
                    o: radial * big,
                    u: radial * phi.cos() + Vec3::z() * phi.sin(),
                }
            })
            .collect();
        let sweep = Sweep::new(frames, Section::HalfEllipse { a: 3.0, b: 1.6 }).unwrap();
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        let (mut inside, mut shared) = (0, 0);
        for _ in 0..30_000 {
            let a = rng.random_range(0.0..std::f64::consts::TAU);
            let r = big + rng.random_range(-3.0..3.0);
            let p = Vec3::new(r * a.cos(), r * a.sin(), rng.random_range(-3.0..3.0));
            let pieces: Vec<f64> = (0..n)
                .map(|i| sweep.segment_dist(i, p, f64::INFINITY))
                .filter(|d| *d < 0.0)
                .collect();
            let Some(deepest) = pieces.iter().copied().reduce(f64::min) else {
                continue;
            };
            inside += 1;
            shared += usize::from(pieces.len() > 1);
            let d = sweep.dist(p);
            assert!(
                (d - deepest).abs() < 1e-12,
                "at {p:?}: {d}, deepest piece {deepest}"
            );
        }
        assert!(inside > 2000, "only {inside} points inside");
        assert!(
            shared > 100,
            "only {shared} points in two pieces: the test tests nothing"
        );
    }

    /// A circle of radius `big` about z sampled by `n` frames, swept by a rounded rectangle
    /// that is in fact a disc of radius `r` (u and v half-extents = round = r): a torus.
    fn torus_sweep(big: f64, r: f64, n: usize) -> Sweep {
        let frames: Vec<Frame> = (0..n)
            .map(|i| {
                let a = i as f64 / n as f64 * std::f64::consts::TAU;
                Frame {
                    o: Vec3::new(big * a.cos(), big * a.sin(), 0.0),
                    u: Vec3::new(a.cos(), a.sin(), 0.0),
                }
            })
            .collect();
        Sweep::new(
            frames,
            Section::RoundedRect {
                u_min: -r,
                u_max: r,
                half_width: r,
                round: r,
            },
        )
        .unwrap()
    }

    /// Guards the refusal of loops whose section has no orientation somewhere (the
    /// distance would be undefined there, and the search's Lipschitz bound infinite):
    /// each refusal names the frame, and a loop that merely turns fast is accepted.
    #[test]
    fn loops_without_a_section_orientation_are_refused() {
        let section = Section::HalfEllipse { a: 3.0, b: 1.6 };
        let ring = |u: &dyn Fn(usize, Vec3) -> Vec3| -> Vec<Frame> {
            (0..12)
                .map(|i| {
                    let a = i as f64 / 12.0 * std::f64::consts::TAU;
                    let radial = Vec3::new(a.cos(), a.sin(), 0.0);
                    Frame {
                        o: radial * 20.0,
                        u: u(i, radial),
                    }
                })
                .collect()
        };
        let ok = Sweep::new(ring(&|_, r| r), section);
        assert!(ok.is_ok());
        let short: Vec<Frame> = ring(&|_, r| r).into_iter().take(2).collect();
        assert_eq!(
            Sweep::new(short, section).unwrap_err(),
            SweepError::TooFewFrames { frames: 2 }
        );
        // Frame 5's u along its segment (the chord to frame 6).
        let frames = ring(&|_, r| r);
        let chord = (frames[6].o - frames[5].o).normalize();
        let mut along = frames.clone();
        along[5].u = chord;
        assert_eq!(
            Sweep::new(along, section).unwrap_err(),
            SweepError::AxisAlongLoop { frame: 5 }
        );
        // Frame 8's u flipped: opposite to frame 7's.
        let flipped = ring(&|i, r| if i == 8 { -r } else { r });
        assert_eq!(
            Sweep::new(flipped, section).unwrap_err(),
            SweepError::OppositeAxes {
                segment: 7,
                next: 8
            }
        );
        // A quarter turn per segment is steep but defined.
        let twisting = ring(&|i, r| if i % 2 == 0 { r } else { Vec3::z() });
        let steep = Sweep::new(twisting, section).unwrap();
        assert!(steep.lipschitz().is_finite() && steep.lipschitz() > 1.0);
    }

    /// Points on the outer side of a turn, where two segments' square ends leave a wedge
    /// between them, are inside the sweep at their distance from the segment's axis (with
    /// square ends alone they came out at +ρ·sin α, outside); beyond the surface the pruned
    /// distance still equals the minimum over all segments.
    #[test]
    fn the_outer_side_of_a_turn_is_closed() {
        let (big, r, n) = (20.0, 3.0, 24);
        let at = |i: usize| i as f64 / n as f64 * std::f64::consts::TAU;
        let s = torus_sweep(big, r, n);
        // Each chord is off the radial plane at its frames by half the 15° turn.
        let half_turn = std::f64::consts::PI / n as f64;
        for i in 0..n {
            let out = Vec3::new(at(i).cos(), at(i).sin(), 0.0);
            for rho in [0.5, 1.5, 2.5, 3.5, 5.0, 9.0] {
                let p = out * (big + rho);
                let d = s.dist(p);
                let full = (0..n)
                    .map(|k| s.segment_dist(k, p, f64::INFINITY))
                    .fold(f64::INFINITY, f64::min);
                assert!(
                    (d - full).abs() < 1e-12,
                    "frame {i}, ρ {rho}: {d} vs {full}"
                );
                if rho < r {
                    let want = rho * half_turn.cos() - r;
                    assert!((d - want).abs() < 1e-9, "frame {i}, ρ {rho}: {d} vs {want}");
                }
            }
        }
    }

    /// A circle of radius R swept by a rounded rectangle that is in fact a disc of radius r
    /// (u and v half-extents = round = r) is a torus: distances match the torus formula.
    #[test]
    fn sweep_of_a_circle_is_a_torus() {
        let (big, r) = (20.0, 3.0);
        let s = torus_sweep(big, r, 720);
        for k in 0..100 {
            let p = Vec3::new(
                (k as f64 * 0.77).sin() * 30.0,
                (k as f64 * 1.31).cos() * 30.0,
                (k as f64 * 0.53).sin() * 6.0,
            );
            let q = (p.x.hypot(p.y) - big).hypot(p.z) - r;
            if q >= SWEEP_EXACT_WITHIN_MM {
                // Far: a lower bound no smaller than the exactness radius.
                assert!(s.dist(p) >= SWEEP_EXACT_WITHIN_MM && s.dist(p) <= q + 2e-3);
                continue;
            }
            // The polygon's chords sit inside the circle by at most R(1 − cos(π/n)).
            assert!((s.dist(p) - q).abs() < 2e-3, "{p:?}: {} vs {q}", s.dist(p));
        }
    }
}
