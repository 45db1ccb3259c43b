//! The checks the built meshes must pass, measured on the meshes themselves.
//!
//! Owns [`run`] and [`CheckFigures`]:
//! - **interference over the period**: at [`CHECK_TIMES`] times, every vertex of each part
//!   placed by the target motion is tested against the other parts' meshes (follower ↔
//!   driver, each ↔ the support); the worst penetration depth and its time are kept.
//!   A vertex outside by some room skips the instants it cannot cover that room by (its
//!   speed bound), which gives the same figures as testing every instant. The sharp
//!   convex edges of the follower (against the driver and the support) and of the driver
//!   (against the support) are tested along their length too (`deepest_ridge`): where
//!   two such edges cross, each can be inside the other with no vertex inside;
//! - **contact gaps**: at every sample time of every curve pair, the design contact point's
//!   signed distance to the driver mesh (c¹, driver frame) plus its distance to the follower
//!   mesh (c², follower frame): the play the printed pair has at that contact, which should
//!   be the clearance. A gap below it binds (a failure); a gap above it means the contact is
//!   lost at that instant (the carve took the driver's material there, or a piece the carve
//!   isolated was left out);
//! - **closure of the printed parts**: at every sample time, the paper's dist(t) (and the
//!   robust one, when the design holds it) from the contacts the parts keep: lost contacts
//!   are harmless while the others still close the follower, which is the paper's dynamic
//!   form closure applied to the parts as built;
//! - **walls**, measured and not judged: each part's wall thickness estimate
//!   (`geometry::thickness`), with the queries made here.
//!
//! Distances come from `parry3d-f64`'s triangle-mesh queries (BVH, inside/outside by
//! pseudo-normals), independent of the implicit solids the meshes were made from. A coarse
//! occupancy grid per part skips vertices far outside it, and a finer grid of signed
//! distances near its surface (each computed when a vertex first reads it) skips the
//! vertices it proves outside (the distance changes
//! by at most the distance moved): at 1 mm cells the check went from 99 to 20 s with the
//! same figures. With the skipped instants, on the 0.4 mm half-turn-2to1 parts it went
//! from 183 to 50 s, a tenth of the vertex tests, with the same figures (also on a
//! follower grown 1 % so that it penetrates). With the parity columns off the mesher's
//! grid lines (`COLUMN_OFFSET_MM`) and a bound at the fine centres of far coarse voxels,
//! parry's queries fell from 5.2 M to 2.8 M and the check from 16.5 to 11.5 s, the same
//! figures. Vertices are followed in chunks of near ones, skipped together while the
//! chunk is far outside: the vertex–instant tests fell from 153 M to 31 M and the check
//! from 14.0–15.3 to 10.0–10.8 s (2026-12-07, on a machine a third slower than for the
//! figures before), the same figures. It does not build anything.

use nalgebra::{Isometry3, Point3};
use rayon::prelude::*;

use crate::geometry::mesh::{edge_uses, Aabb, Mesh};
use crate::geometry::query::MeshQuery;
use crate::geometry::sdf::Vec3;
use crate::geometry::thickness::{wall_thickness, WallThickness};
use crate::geometry::voxel::{distance_transform, OnceValues, VoxelGrid};
use crate::synth::mechanism::Mechanism;

use super::dims::SLIVER_MM;
use super::kinematics::{Frame, Kinematics};
use super::parts::Design;
use super::swept::ExactSweep;

/// Times per period of the interference check. 720: twice the 360, so a part moves
/// by less than 1.3 mm between checks at the examples' fastest points.
pub const CHECK_TIMES: usize = 720;
/// Penetration accepted between parts, mm: the meshes' own error (≤ 0.05 mm on curved
/// surfaces at the default cell) and nothing more.
pub const PENETRATION_TOL_MM: f64 = 0.05;
/// Accepted deviation of a design contact's gap from the clearance, mm: twice the mesh
/// error of the two surfaces that meet there.
pub const GAP_TOL_MM: f64 = 0.1;
/// How far the wall measurement follows each ray, mm: the walls of note are the thin ones,
/// below [`SLIVER_MM`] (which a slicer cannot lay as a wall); a wall thicker than 2 mm is
/// only said to be that thick, and the rays through plates, bands, columns and the base
/// stop there instead of crossing them (at 5 mm the measurement cost 7 s of the 0.4 mm
/// half-turn-2to1 build).
pub const WALL_REACH_MM: f64 = 2.0;
/// Voxel of the occupancy grids that skip far vertices, mm.
const OCCUPANCY_VOXEL_MM: f64 = 1.0;
/// Vertices nearer than this to a part's surface (by the occupancy grid) are measured
/// exactly, mm.
const NEAR_MM: f64 = 2.0;
/// Voxel of the grid of signed distances near a part's surface, mm. The distance changes
/// by at most the distance moved, so a vertex whose voxel centre is farther outside than
/// the vertex is from that centre cannot be inside and skips parry's query. 0.5 mm: in a
/// part that passes, the vertices left to query are those within about 0.4 mm of the other
/// part, the contact strips; finer grids cost more queries up front.
const FINE_VOXEL_MM: f64 = 0.5;
/// Fine centres whose bound from the coarse voxel's centre is above this are not queried,
/// mm: the bound already lets every vertex in their voxel (at most 0.43 mm away) skip.
const FINE_EXACT_WITHIN_MM: f64 = 0.5;
/// Rounding of the fine grid's values (stored as f32, a few mm), mm.
const FINE_ROUNDING_MM: f64 = 1e-5;
/// How far the parity columns lie beside the coarse voxel centres in x and y, mm. The
/// mesher puts vertices on its grid lines, and a part's box (which the grid starts from)
/// on one of them, so columns through the centres themselves passed exactly through
/// vertices and edges, where every triangle sharing one counted and the parity flipped.
/// Either way is wrong: on half-turn-2to1's support every deep-inside voxel a vertex
/// reached was in fact outside, and each of its vertex tests went to parry (1.4 M of the
/// check's 5.2 M queries); on a cube with its corners on the grid's lines the voxels
/// under its face diagonals came out far outside, so a vertex there would have passed
/// unseen. Far below any voxel, far above round-off, and no simple fraction of a voxel:
/// a column beside the centre has the centre's parity wherever the surface is farther
/// than this from it, and a voxel counts as deep only a voxel's half diagonal and more
/// away from the surface.
const COLUMN_OFFSET_MM: [f64; 2] = [3.14e-4, 2.72e-4];

/// The contact gaps of one curve pair over its samples.
#[derive(Clone, Debug, PartialEq)]
pub struct PairGap {
    /// Curve pair (1-based, as in reports).
    pub pair: usize,
    /// Smallest gap, mm.
    pub min_mm: f64,
    /// Its time.
    pub min_t: f64,
    /// Largest gap, mm.
    pub max_mm: f64,
    /// Mean gap over the instants the contact is kept, mm.
    pub mean_mm: f64,
    /// Time windows `[from, to]` (inclusive sample times) where the gap exceeds the
    /// clearance by more than [`GAP_TOL_MM`]: the contact is lost there. A window that
    /// runs past the end of the period into the next has `from > to`.
    pub lost: Vec<[f64; 2]>,
    /// Fraction of the samples where the contact is lost.
    pub lost_fraction: f64,
    /// Which rims cut the driver at this pair's contact curve: (curve pair of the rim,
    /// 1-based; fraction of the samples where its sweep reaches [`GAP_TOL_MM`] or more
    /// past c¹), most first. Lost samples no rim explains are where a piece of band was
    /// left out.
    pub cut_by: Vec<(usize, f64)>,
}

/// The paper's closure of the printed parts, from the contacts they keep.
#[derive(Clone, Debug, PartialEq)]
pub struct BuiltClosure {
    /// Largest dist(t) over the samples (E_maxDist of the parts as built).
    pub max_dist: f64,
    /// Its time.
    pub worst_t: f64,
    /// Largest robust dist(t).
    pub robust_max_dist: f64,
    /// Its time.
    pub robust_worst_t: f64,
    /// Whether robust closure is required (the design holds it).
    pub robust_required: bool,
    /// Samples where some contact is lost.
    pub instants_with_lost_contacts: usize,
    /// Samples per period.
    pub samples: usize,
}

impl BuiltClosure {
    /// Why closure fails, if it does.
    pub fn failure(&self) -> Option<String> {
        let eps = crate::synth::closure::EPSILON;
        if self.max_dist > -eps {
            return Some(format!(
                "with the contacts the parts keep, dynamic form closure fails at t = {:.4} (dist {} > −{eps})",
                self.worst_t,
                crate::synth::closure::dist_text(self.max_dist)
            ));
        }
        if self.robust_required && self.robust_max_dist > -eps {
            return Some(format!(
                "with the contacts the parts keep, robust closure fails at t = {:.4} (dist {} > −{eps})",
                self.robust_worst_t,
                crate::synth::closure::dist_text(self.robust_max_dist)
            ));
        }
        None
    }
}

/// One part entering another.
#[derive(Clone, Debug, PartialEq)]
pub struct Penetration {
    /// "follower into driver", ...
    pub what: String,
    /// Deepest point inside, mm (0 when none is): a vertex, or the middle of a ridge's
    /// stretch inside (see `RIDGE_DEG`).
    pub depth_mm: f64,
    /// Its time.
    pub t: f64,
}

/// What the checks measured.
#[derive(Clone, Debug, PartialEq)]
pub struct CheckFigures {
    /// Times checked per period.
    pub times: usize,
    /// The clearance the gaps are compared with, mm.
    pub clearance_mm: f64,
    /// Per pair of parts.
    pub penetrations: Vec<Penetration>,
    /// Per curve pair.
    pub gaps: Vec<PairGap>,
    /// Closure from the contacts the parts keep.
    pub closure: BuiltClosure,
    /// Each part's walls (driver, follower, support), measured, not judged: thin walls
    /// are for the person printing to weigh.
    pub walls: Vec<WallThickness>,
}

impl CheckFigures {
    /// The deepest penetration of all.
    pub fn worst_penetration(&self) -> Option<&Penetration> {
        self.penetrations
            .iter()
            .max_by(|a, b| a.depth_mm.total_cmp(&b.depth_mm))
    }

    /// The pair whose gap closes most below the clearance, if any does beyond the tolerance.
    pub fn binding(&self) -> Option<&PairGap> {
        self.gaps
            .iter()
            .filter(|g| g.min_mm < self.clearance_mm - GAP_TOL_MM)
            .min_by(|a, b| a.min_mm.total_cmp(&b.min_mm))
    }

    /// Why the check fails, if it does: a penetration, a binding contact, or closure lost
    /// with the contacts the parts keep. Lost contacts alone do not fail it.
    pub fn failure(&self) -> Option<String> {
        let mut why = Vec::new();
        if let Some(p) = self.worst_penetration() {
            if p.depth_mm > PENETRATION_TOL_MM {
                why.push(format!(
                    "{} by {:.3} mm at t = {:.4} (tolerance {PENETRATION_TOL_MM} mm)",
                    p.what, p.depth_mm, p.t
                ));
            }
        }
        if let Some(g) = self.binding() {
            why.push(format!(
                "the gap at curve pair {}'s contact closes to {:.3} mm at t = {:.4}, below the clearance {:.2} − {GAP_TOL_MM} mm",
                g.pair, g.min_mm, g.min_t, self.clearance_mm
            ));
        }
        why.extend(self.closure.failure());
        (!why.is_empty()).then(|| why.join("; "))
    }
}

/// The windows (first and last sample time) of the runs of `true` in a periodic sequence.
pub fn windows(flags: &[bool]) -> Vec<[f64; 2]> {
    let n = flags.len();
    if n == 0 {
        return Vec::new();
    }
    if flags.iter().all(|&f| f) {
        return vec![[0.0, (n - 1) as f64 / n as f64]];
    }
    // Start right after a false, so no run wraps unseen.
    let start = (0..n).find(|&i| !flags[i]).map_or(0, |i| i + 1);
    let mut out = Vec::new();
    let mut run: Option<usize> = None;
    for j in 0..=n {
        let i = (start + j) % n;
        let on = j < n && flags[i];
        match (on, run) {
            (true, None) => run = Some(i),
            (false, Some(first)) => {
                let last = (i + n - 1) % n;
                out.push([first as f64 / n as f64, last as f64 / n as f64]);
                run = None;
            }
            _ => {}
        }
    }
    out.sort_by(|a, b| a[0].total_cmp(&b[0]));
    out
}

/// A mesh ready for queries: parry's BVH with pseudo-normals, a coarse occupancy grid
/// (0 far outside, 1 near the surface, 2 inside by the parity of its column) with each
/// voxel centre's distance to the nearest voxel a face meets, and, where the occupancy
/// is not 0, a lower bound of the signed distance at the centres of a finer grid: exact
/// within [`FINE_EXACT_WITHIN_MM`] of the surface, from the coarse voxel's centre farther
/// out (NaN where there is none, and inside, where a bound proves nothing). The signed
/// distances of both grids are computed when a vertex first asks for them: the other
/// part's vertices come near the surface along the contact strips only, and computing
/// every centre within reach of the whole surface up front took most of the check's
/// preparation.
struct Queryable {
    tri: MeshQuery,
    /// The mesh's bounding box.
    bounds: Aabb,
    grid: VoxelGrid,
    occ: Vec<u8>,
    /// Per coarse voxel, its centre's distance to the nearest centre of a voxel that some
    /// face's box meets, mm.
    to_surface: Vec<f32>,
    /// What [`Queryable::to_surface`] exceeds a point's distance to the surface by at
    /// most: a voxel's half diagonal (a surface point in its marked voxel), mm.
    to_surface_slack: f64,
    /// Per coarse voxel, [`Queryable::coarse_at`].
    coarse: OnceValues,
    fine: VoxelGrid,
    /// Per fine voxel, [`Queryable::lower_at`].
    lower: OnceValues,
}

impl Queryable {
    fn new(m: &Mesh) -> Queryable {
        let tri = MeshQuery::new(m).expect("a checked, non-empty mesh");
        let b = m.aabb().inflate(NEAR_MM + 2.0 * OCCUPANCY_VOXEL_MM);
        let grid = VoxelGrid::covering(b, OCCUPANCY_VOXEL_MM);
        // Near: within NEAR_MM of a voxel holding some of the surface. Each face marks
        // every voxel its box meets, so every surface point is within a voxel's half
        // diagonal of a marked centre, whatever the faces' sizes (marked by the vertices
        // alone, the slack would be half a diagonal plus the longest edge, 2 mm on
        // simplified meshes).
        let marks = grid.marks_of_triangle_boxes((0..m.triangles.len()).map(|i| m.corners(i)));
        let to_surface = distance_transform(&grid, &marks);
        let half_diagonal = 0.5 * 3f64.sqrt() * grid.h;
        let to_surface_slack = half_diagonal;
        let mut occ: Vec<u8> = to_surface
            .iter()
            .map(|&x| u8::from((x as f64) <= NEAR_MM + grid.h))
            .collect();
        // Inside: parity along z of each voxel column's centre.
        let mut columns: Vec<Vec<f64>> = vec![Vec::new(); grid.n[0] * grid.n[1]];
        for i in 0..m.triangles.len() {
            let [a, b, c] = m.corners(i);
            let (xmin, xmax) = (a[0].min(b[0]).min(c[0]), a[0].max(b[0]).max(c[0]));
            let (ymin, ymax) = (a[1].min(b[1]).min(c[1]), a[1].max(b[1]).max(c[1]));
            let [ox, oy] = [
                grid.origin.x + COLUMN_OFFSET_MM[0],
                grid.origin.y + COLUMN_OFFSET_MM[1],
            ];
            let i0 = ((xmin - ox) / grid.h).ceil().max(0.0) as usize;
            let i1 = (((xmax - ox) / grid.h).floor() as usize).min(grid.n[0] - 1);
            let j0 = ((ymin - oy) / grid.h).ceil().max(0.0) as usize;
            let j1 = (((ymax - oy) / grid.h).floor() as usize).min(grid.n[1] - 1);
            for j in j0..=j1 {
                for ii in i0..=i1 {
                    let (x, y) = (ox + ii as f64 * grid.h, oy + j as f64 * grid.h);
                    // Barycentric coordinates in the xy projection (a column on an edge
                    // counts in both triangles: the offset keeps columns off them).
                    let det = (b[1] - c[1]) * (a[0] - c[0]) + (c[0] - b[0]) * (a[1] - c[1]);
                    if det.abs() < 1e-14 {
                        continue;
                    }
                    let l1 = ((b[1] - c[1]) * (x - c[0]) + (c[0] - b[0]) * (y - c[1])) / det;
                    let l2 = ((c[1] - a[1]) * (x - c[0]) + (a[0] - c[0]) * (y - c[1])) / det;
                    let l3 = 1.0 - l1 - l2;
                    if l1 < 0.0 || l2 < 0.0 || l3 < 0.0 {
                        continue;
                    }
                    columns[ii + grid.n[0] * j].push(l1 * a[2] + l2 * b[2] + l3 * c[2]);
                }
            }
        }
        for (ci, col) in columns.iter_mut().enumerate() {
            if col.is_empty() {
                continue;
            }
            col.sort_by(f64::total_cmp);
            let (ii, j) = (ci % grid.n[0], ci / grid.n[0]);
            for k in 0..grid.n[2] {
                let z = grid.origin.z + k as f64 * grid.h;
                let below = col.partition_point(|&c| c < z);
                if below % 2 == 1 {
                    occ[grid.index([ii, j, k])] = 2;
                }
            }
        }
        let fine = VoxelGrid::covering(b, FINE_VOXEL_MM);
        Queryable {
            tri,
            bounds: m.aabb(),
            grid,
            occ,
            to_surface,
            to_surface_slack,
            coarse: OnceValues::new(grid.len()),
            lower: OnceValues::new(fine.len()),
            fine,
        }
    }

    /// The value of coarse voxel `i`, computed when first asked: the signed distance at its
    /// centre where it may matter. Far from the surface it bounds the fine centres in the
    /// voxel, near it the fine centres are queried. Deep inside by the parity (its centre
    /// farther from the surface than any fine centre in it is from the centre) it is not
    /// queried: the fine centres there are inside, and an inside value proves nothing
    /// outside (were the parity wrong, the vertices there would only be queried). NaN far
    /// outside.
    fn coarse_at(&self, i: usize) -> f64 {
        let v = self.coarse.get_or(i, || {
            let half_diagonal = 0.5 * 3f64.sqrt() * self.grid.h;
            let deep = self.to_surface[i] as f64 > self.to_surface_slack + half_diagonal;
            match self.occ[i] {
                0 => f32::NAN,
                2 if deep => f32::NEG_INFINITY,
                _ => {
                    let c = self.grid.center(self.grid.unflat(i));
                    self.signed(c) as f32
                }
            }
        });
        f64::from(v)
    }

    /// The bound at fine voxel `i`'s centre, computed when first asked: from its coarse
    /// voxel's value (or, far from the surface, its bound from the nearest marked voxel)
    /// where that is more than [`FINE_EXACT_WITHIN_MM`] outside it, NaN outside the grid or
    /// where the coarse centre is inside (nothing to prove outside with), else the signed
    /// distance at the fine centre.
    fn lower_at(&self, i: usize) -> f64 {
        let v = self.lower.get_or(i, || {
            let c = self.fine.center(self.fine.unflat(i));
            let Some(v) = self.grid.voxel_of(c) else {
                return f32::NAN;
            };
            let vi = self.grid.index(v);
            let off = (c - self.grid.center(v)).norm();
            // A coarse voxel far from the surface has no value; the nearest marked voxel
            // bounds the distance in it, as for a vertex there (`room`). The fine grid's
            // voxels straddle the coarse ones, so a vertex in a near coarse voxel may have
            // its fine centre in a far one: with no value there, each of its tests went
            // to parry (on half-turn-2to1 the outer edge of every near band).
            let (bound, coarse_inside) = if self.occ[vi] == 0 {
                (self.far_bound(vi, off), false)
            } else {
                let at_coarse = self.coarse_at(vi);
                (at_coarse - off, at_coarse + off < 0.0)
            };
            if bound > FINE_EXACT_WITHIN_MM {
                bound as f32
            } else if bound.is_nan() || coarse_inside {
                f32::NAN
            } else {
                self.signed(c) as f32
            }
        });
        f64::from(v)
    }

    /// Where `p` is outside, a lower bound of its distance to the surface (0 when none is
    /// known); inside, minus its depth (exact). Outside the grid, the distance to the mesh's
    /// box; far outside by the occupancy, the distance to the nearest marked voxel less
    /// the slack; where the fine grid proves `p` outside, its bound; elsewhere parry's
    /// signed distance.
    fn room(&self, p: Vec3) -> f64 {
        let Some(v) = self.grid.voxel_of(p) else {
            // The grid covers the box with room to spare.
            return self.bounds.distance([p.x, p.y, p.z]);
        };
        let i = self.grid.index(v);
        if self.occ[i] == 0 {
            return self.far_bound(i, (p - self.grid.center(v)).norm()).max(0.0);
        }
        self.proved_room(p).unwrap_or_else(|| self.signed(p))
    }

    /// In coarse voxel `i`, far from the surface by the occupancy, a lower bound of the
    /// distance at a point `off` from its centre: the distance to the nearest voxel a face
    /// meets, less the slack from a surface point to such a voxel's centre.
    fn far_bound(&self, i: usize, off: f64) -> f64 {
        f64::from(self.to_surface[i]) - off - self.to_surface_slack
    }

    /// The fine grid's bound at `p`'s voxel centre less `p`'s distance from it, where that
    /// is above 0: `p` is outside by at least that. None where there is no bound (NaN
    /// compares false).
    fn proved_room(&self, p: Vec3) -> Option<f64> {
        let f = self.fine.voxel_of(p)?;
        let room =
            self.lower_at(self.fine.index(f)) - FINE_ROUNDING_MM - (p - self.fine.center(f)).norm();
        (room > 0.0).then_some(room)
    }

    fn signed(&self, p: Vec3) -> f64 {
        self.tri.signed([p.x, p.y, p.z])
    }

    /// How deep the segment from `a` to `b` goes inside, where it does: the depth at the
    /// middle of its stretch inside, from where it enters (at `a` when `a` is inside,
    /// `a_inside`) to where it leaves (at `b` when `b` is). `None` when it enters nowhere.
    /// For a ridge that cuts across another part's ridge that middle is the deepest point
    /// (the two wedges are symmetric about it); elsewhere it is a lower bound of the
    /// deepest.
    fn segment_depth(&self, a: Vec3, b: Vec3, a_inside: bool, b_inside: bool) -> Option<f64> {
        let len = (b - a).norm();
        if len <= 0.0 {
            return None;
        }
        let dir = (b - a) / len;
        let enters = if a_inside {
            0.0
        } else {
            self.tri
                .entry_along([a.x, a.y, a.z], [dir.x, dir.y, dir.z], len)?
        };
        let leaves = if b_inside {
            len
        } else {
            len - self
                .tri
                .entry_along([b.x, b.y, b.z], [-dir.x, -dir.y, -dir.z], len)?
        };
        if leaves < enters {
            return None;
        }
        let middle = a + dir * (0.5 * (enters + leaves));
        Some((-self.signed(middle)).max(0.0))
    }
}

/// A part ready for the interference test, its chunks made once for every other part it
/// goes into: its name and frame, its queries, its vertices and its ridges ([`ridges`];
/// none asked for the support's) in [`Chunk`]s.
struct Prepared {
    name: &'static str,
    frame: Frame,
    query: Queryable,
    vertices: Vec<Chunk<Point3<f64>>>,
    ridges: Vec<Chunk<[Point3<f64>; 2]>>,
}

impl Prepared {
    /// `mesh`, the part `name` in its frame `frame`; its ridges too when `with_ridges`.
    /// The queries (most of them serial: parry's hierarchy, the pseudo-normals, the parity
    /// columns) and the chunks are made side by side.
    fn new(name: &'static str, frame: Frame, mesh: &Mesh, with_ridges: bool) -> Prepared {
        let (query, (vertices, ridges)) = rayon::join(
            || Queryable::new(mesh),
            || {
                rayon::join(
                    || vertex_chunks(mesh),
                    || {
                        if with_ridges {
                            ridge_chunks(&ridges(mesh))
                        } else {
                            Vec::new()
                        }
                    },
                )
            },
        );
        Prepared {
            name,
            frame,
            query,
            vertices,
            ridges,
        }
    }
}

/// The deepest each part goes into each other over the period: the driver, the follower
/// and the support.
fn interference(kin: &Kinematics, [d, f, s]: [&Prepared; 3]) -> Vec<Penetration> {
    // Two ridges that cross are each inside the other: the follower's ridges against the
    // driver find them, so the driver's are not looked at there, and the moving parts'
    // ridges against the support stand for the support's (what else they can hide is
    // bounded at `RIDGE_DEG`). Every part's vertices go into both others: a corner of
    // the support in a face of a moving part has no vertex of that part inside the support.
    let into = |moving: &Prepared, with_ridges: bool, fixed: &Prepared| {
        penetration(kin, moving, with_ridges, fixed)
    };
    vec![
        into(f, true, d),
        into(d, false, f),
        into(f, true, s),
        into(d, true, s),
        into(s, false, d),
        into(s, false, f),
    ]
}

/// Deepest point of `moving` inside `fixed` over the period: its vertices and, when
/// `with_ridges`, its ridges ([`deepest_ridge`]).
fn penetration(
    kin: &Kinematics,
    moving: &Prepared,
    with_ridges: bool,
    fixed: &Prepared,
) -> Penetration {
    let instants = Instants::new(kin, moving.frame, fixed.frame);
    let by_vertices = deepest(&instants, &moving.vertices, &fixed.query);
    let d = if with_ridges {
        Deepest::deeper(
            by_vertices,
            deepest_ridge(&instants, &moving.ridges, &fixed.query),
        )
    } else {
        by_vertices
    };
    Penetration {
        what: format!("{} into {}", moving.name, fixed.name),
        depth_mm: d.depth,
        t: d.t,
    }
}

/// The deepest a vertex went inside, when (the earliest of the deepest instants), and how
/// many vertex–instant tests finding it took.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Deepest {
    depth: f64,
    t: f64,
    tests: usize,
}

/// The [`Deepest`] vertex of a moving part's vertex `chunks` ([`vertex_chunks`]) inside
/// `fixed` at `instants` ([`CHECK_TIMES`], one
/// when the frames are the same). Each vertex is followed through the instants; where it
/// is outside by some room, the instants it cannot cover that room by (its speed bound
/// over each step, [`Kinematics::spin_drift_within`]) are skipped: it is outside at them
/// too, so the figures are those of testing every instant. The vertices go in [`Chunk`]s
/// of near ones ([`follow`]): the deepest vertex and instant are the same, since only
/// instants proven outside are skipped.
fn deepest(instants: &Instants, chunks: &[Chunk<Point3<f64>>], fixed: &Queryable) -> Deepest {
    follow(instants, chunks, fixed, |&p, pose| {
        let room = fixed.room((pose * p).coords);
        (room, -room, p.coords.norm())
    })
}

/// The [`Deepest`] over `chunks` of elements (vertices, ridges) of a moving part followed
/// through `instants` against `fixed`. `test` measures one element at a pose: a room it
/// is outside by at least (0 or less when it may be inside), how deep inside it found it
/// (anything not above 0 when outside), and how far its points are from their frame's
/// origin at most. Each element is tested at the instants its room and speed bound cannot
/// rule out, and every element of a chunk skips the instants where the chunk's centre is
/// outside by more than the chunk's radius.
fn follow<T: Sync>(
    instants: &Instants,
    chunks: &[Chunk<T>],
    fixed: &Queryable,
    test: impl Fn(&T, &Isometry3<f64>) -> (f64, f64, f64) + Sync,
) -> Deepest {
    let times = instants.times;
    chunks
        .par_iter()
        .map(|chunk| {
            let mut d = Deepest::NONE;
            // Per element of the chunk, the next instant it must be tested at.
            let mut due = vec![0; chunk.items.len()];
            let mut j = 0;
            while j < times {
                let pose = &instants.poses[j];
                let room = fixed.room((pose * chunk.centre).coords) - chunk.radius;
                d.tests += 1;
                if room > 0.0 {
                    let next = instants.next_after(j, room, chunk.farthest);
                    for n in &mut due {
                        *n = (*n).max(next);
                    }
                } else {
                    for (n, item) in due.iter_mut().zip(&chunk.items) {
                        if *n != j {
                            continue;
                        }
                        let (room, depth, norm) = test(item, pose);
                        d.tests += 1;
                        // Instants go in order, so of equal depths the earliest is kept.
                        if depth > d.depth {
                            (d.depth, d.t) = (depth, instants.at(j));
                        }
                        *n = instants.next_after(j, room, norm);
                    }
                }
                j = due.iter().copied().min().unwrap_or(times);
            }
            d
        })
        .reduce(|| Deepest::NONE, Deepest::deeper)
}

/// Edges of a part whose two faces turn by more than this are tested as segments, not by
/// their ends alone, degrees. What the vertices alone can miss, at the default 0.4 mm
/// cells (edges up to about 0.4 mm; a point of a face is at most 0.58 of an edge from a
/// corner, so a lens of overlap wider than that holds a vertex):
/// - two sharp edges that cross: each can go half an edge deep (0.2 mm) with both its ends
///   outside. Both are then inside the other part, so one side's ridges find it;
/// - two surfaces whose faces turn by less than this bend at a radius of 0.4 mm /
///   (2 sin 7.5°) = 1.53 mm or more, and a lens no vertex of either reaches is at most
///   (0.58 · 0.4)² / (2 · 1.53) = 0.018 mm deep on each side: 0.035 mm in all, under
///   [`PENETRATION_TOL_MM`];
/// - a sharp edge of the other part into such a surface: the edge's stretch inside is
///   shorter than an edge only while it is under 0.4² / (8 · 1.53) = 0.013 mm deep.
///
/// At 30° (a 0.77 mm bend) the second would reach 0.06 mm. On half-turn-2to1's printable
/// parts, before they were simplified, 15° made 92.7 k of the follower's edges ridges and
/// 162 k of the driver's, and their tests cost 0.8 s of the check (30°: 47.6 k and 69.9 k,
/// 0.4 s). Ridges are the sharp convex edges ([`ridges`]).
///
/// On simplified meshes (`geometry::simplify`, within δ = 0.01 mm) a face is longer where
/// the surface bends less: L long on a surface of radius R, it departs from it by L²/(8R),
/// about δ at most, so the lens of the second item is (0.58 L)² / (2R) ≈ 1.35 δ = 0.013 mm
/// deep on each side, whatever L; the ridges are tested along their length as before.
const RIDGE_DEG: f64 = 15.0;

/// The convex edges of `mesh` whose faces turn by more than [`RIDGE_DEG`], as their two
/// ends. An edge is convex where the far corner of one of its faces lies behind the other
/// face's plane.
fn ridges(mesh: &Mesh) -> Vec<[Point3<f64>; 2]> {
    let point = |v: u32| Point3::from(mesh.vertices[v as usize]);
    let normal = |t: usize| {
        let [a, b, c] = mesh.triangles[t].map(point);
        (b - a).cross(&(c - a)).try_normalize(0.0)
    };
    let cos_sharp = RIDGE_DEG.to_radians().cos();
    let uses = edge_uses(&mesh.triangles, |_| true);
    uses.chunk_by(|a, b| (a.lo, a.hi) == (b.lo, b.hi))
        .filter_map(|group| {
            let [u, w] = group else {
                return None;
            };
            let (nu, nw) = (normal(u.triangle as usize)?, normal(w.triangle as usize)?);
            if nu.dot(&nw) >= cos_sharp {
                return None;
            }
            let far = mesh.triangles[w.triangle as usize][(w.k as usize + 2) % 3];
            let (lo, hi) = (point(u.lo), point(u.hi));
            ((point(far) - lo).dot(&nu) < 0.0).then_some([lo, hi])
        })
        .collect()
}

/// The [`Deepest`] point of a moving part's ridge `chunks` ([`ridge_chunks`]) inside
/// `fixed` at `instants`: the
/// stretch between a ridge's ends that may be inside, where the vertices' test cannot see
/// it. Ridges go in runs of near ones and skip instants as the vertices do ([`follow`]).
/// At an instant a ridge is
/// looked along ([`Queryable::segment_depth`]) only where its ends leave room for it to
/// reach inside: every point of it is outside by at least half the sum of its ends'
/// rooms less its length.
fn deepest_ridge(
    instants: &Instants,
    chunks: &[Chunk<[Point3<f64>; 2]>],
    fixed: &Queryable,
) -> Deepest {
    follow(instants, chunks, fixed, |[a, b], pose| {
        let (pa, pb) = ((pose * a).coords, (pose * b).coords);
        let (ra, rb) = (fixed.room(pa), fixed.room(pb));
        let room = if ra > 0.0 && rb > 0.0 {
            0.5 * (ra + rb - (pb - pa).norm())
        } else {
            0.0
        };
        let depth = if room <= 0.0 {
            fixed
                .segment_depth(pa, pb, ra <= 0.0, rb <= 0.0)
                .unwrap_or(0.0)
        } else {
            0.0
        };
        (room, depth, a.coords.norm().max(b.coords.norm()))
    })
}

impl Deepest {
    /// Nothing inside.
    const NONE: Deepest = Deepest {
        depth: 0.0,
        t: 0.0,
        tests: 0,
    };

    /// The deeper of two (the earlier of equals), with both's tests.
    fn deeper(a: Deepest, b: Deepest) -> Deepest {
        let tests = a.tests + b.tests;
        if b.depth > a.depth || (b.depth == a.depth && b.t < a.t) {
            Deepest { tests, ..b }
        } else {
            Deepest { tests, ..a }
        }
    }
}

/// The instants a moving part is tested at ([`CHECK_TIMES`]; one when the frames are the
/// same), its poses there, and how far its points may move from each to the next.
struct Instants {
    times: usize,
    poses: Vec<Isometry3<f64>>,
    /// Per instant, how far a point may move from it to the next: per mm of its distance
    /// from its frame's origin, and in all.
    steps: Vec<(f64, f64)>,
}

impl Instants {
    fn new(kin: &Kinematics, from: Frame, into: Frame) -> Instants {
        let times = if from == into { 1 } else { CHECK_TIMES };
        let at = |j: usize| j as f64 / times as f64;
        let poses = (0..times)
            .map(|j| kin.transform(from, into, at(j)))
            .collect();
        let steps = (0..times)
            .map(|j| {
                let (spin, drift) = kin.spin_drift_within(from, into, at(j), at(j + 1));
                (spin / times as f64, drift / times as f64)
            })
            .collect();
        Instants {
            times,
            poses,
            steps,
        }
    }

    /// The time of instant `j`.
    fn at(&self, j: usize) -> f64 {
        j as f64 / self.times as f64
    }

    /// The first instant after `j` that a point at `norm` from its frame's origin, outside
    /// by `room` at `j`, may have covered that room by (`times` when none).
    fn next_after(&self, j: usize, room: f64, norm: f64) -> usize {
        let mut next = j + 1;
        let mut moved = 0.0;
        while room > 0.0 && next < self.times {
            let (spin, drift) = self.steps[next - 1];
            moved += spin * norm + drift;
            if moved >= room {
                break;
            }
            next += 1;
        }
        next
    }
}

/// Vertices per [`Chunk`]. Measured on half-turn-2to1's printable parts (2026-12-07, a
/// probe): most vertex–instant tests were of vertices more than 1 mm outside (132 M of
/// 153 M, 94 M more than 4 mm), which a chunk of this many, about a millimetre across on
/// the 0.4 mm meshes, skips together.
const CHUNK_VERTICES: usize = 32;

/// Cell of the order that makes chunks compact, mm: vertices are taken in the Morton order
/// of their cells.
const CHUNK_ORDER_CELL_MM: f64 = 0.5;

/// Elements of a part (vertices, ridges) near one another, tested together while all are
/// far outside.
struct Chunk<T> {
    /// The elements.
    items: Vec<T>,
    /// The centre of their points' box.
    centre: Point3<f64>,
    /// The farthest of their points from `centre`, mm.
    radius: f64,
    /// The farthest of their points from the frame's origin, mm (for the speed bound).
    farthest: f64,
}

/// The indices of `points` in runs of [`CHUNK_VERTICES`] near one another: taken in the
/// Morton order of their [`CHUNK_ORDER_CELL_MM`] cells, ties in the points' order.
fn runs_of_near(points: &[[f64; 3]]) -> Vec<Vec<usize>> {
    let b = Aabb::around(points.iter().copied());
    let mut order: Vec<(u64, usize)> = points
        .par_iter()
        .enumerate()
        .map(|(i, v)| {
            let cell = |k: usize| ((v[k] - b.min[k]) / CHUNK_ORDER_CELL_MM) as u64;
            (morton([cell(0), cell(1), cell(2)]), i)
        })
        .collect();
    order.par_sort_unstable();
    order
        .chunks(CHUNK_VERTICES)
        .map(|run| run.iter().map(|&(_, i)| i).collect())
        .collect()
}

/// A run's centre (of its points' box), its points' farthest distance from that centre
/// and from the frame's origin, mm.
fn centre_radius_farthest(points: &[Point3<f64>]) -> (Point3<f64>, f64, f64) {
    let bx = Aabb::around(points.iter().map(|p| [p.x, p.y, p.z]));
    let centre = Point3::from(bx.center());
    let radius = points
        .iter()
        .map(|p| (p - centre).norm())
        .fold(0.0, f64::max);
    let farthest = points.iter().map(|p| p.coords.norm()).fold(0.0, f64::max);
    (centre, radius, farthest)
}

impl<T: Copy + Send + Sync> Chunk<T> {
    /// `items` in chunks of [`CHUNK_VERTICES`] near one another by the point `at` gives
    /// each ([`runs_of_near`]); a chunk's bounds hold the points `ends` gives (an element
    /// lies within their hull).
    fn cover<const N: usize>(
        items: &[T],
        at: impl Fn(&T) -> Point3<f64> + Sync,
        ends: impl Fn(&T) -> [Point3<f64>; N] + Sync,
    ) -> Vec<Chunk<T>> {
        if items.is_empty() {
            return Vec::new();
        }
        let points: Vec<[f64; 3]> = items.par_iter().map(|e| at(e).coords.into()).collect();
        runs_of_near(&points)
            .par_iter()
            .map(|run| {
                let items: Vec<T> = run.iter().map(|&i| items[i]).collect();
                let points: Vec<Point3<f64>> = items.iter().flat_map(&ends).collect();
                let (centre, radius, farthest) = centre_radius_farthest(&points);
                Chunk {
                    items,
                    centre,
                    radius,
                    farthest,
                }
            })
            .collect()
    }
}

/// `mesh`'s vertices in [`Chunk`]s.
fn vertex_chunks(mesh: &Mesh) -> Vec<Chunk<Point3<f64>>> {
    let vertices: Vec<Point3<f64>> = mesh.vertices.iter().map(|&v| Point3::from(v)).collect();
    Chunk::cover(&vertices, |&p| p, |&p| [p])
}

/// `ridges` in [`Chunk`]s, near by their middles.
fn ridge_chunks(ridges: &[[Point3<f64>; 2]]) -> Vec<Chunk<[Point3<f64>; 2]>> {
    Chunk::cover(ridges, |[a, b]| nalgebra::center(a, b), |&ends| ends)
}

/// The Morton (Z-order) key of a cell: the bits of its three indices interleaved (21 bits
/// each, far more than a part's cells).
fn morton(cell: [u64; 3]) -> u64 {
    let spread = |x: u64| {
        let mut x = x & 0x1f_ffff;
        x = (x | (x << 32)) & 0x001f_0000_0000_ffff;
        x = (x | (x << 16)) & 0x001f_0000_ff00_00ff;
        x = (x | (x << 8)) & 0x100f_00f0_0f00_f00f;
        x = (x | (x << 4)) & 0x10c3_0c30_c30c_30c3;
        x = (x | (x << 2)) & 0x1249_2492_4924_9249;
        x
    };
    spread(cell[0]) | (spread(cell[1]) << 1) | (spread(cell[2]) << 2)
}

/// Run every check on the meshes of `design` (driver, follower, support in their frames).
pub fn run(
    design: &Design,
    mech: &Mechanism,
    driver: &Mesh,
    follower: &Mesh,
    support: &Mesh,
) -> CheckFigures {
    // The three parts side by side.
    let (pd, (pf, ps)) = rayon::join(
        || Prepared::new("driver", Frame::Driver, driver, true),
        || {
            rayon::join(
                || Prepared::new("follower", Frame::Follower, follower, true),
                || Prepared::new("support", Frame::Reference, support, false),
            )
        },
    );
    let penetrations = interference(&design.kin, [&pd, &pf, &ps]);
    let (qd, qf, qs) = (&pd.query, &pf.query, &ps.query);
    let s = design.kin.scale_mm();
    let pairs: Vec<(usize, &crate::synth::mechanism::CurvePair)> = mech
        .curve_pairs
        .iter()
        .enumerate()
        .filter(|(k, _)| Some(*k) != design.without_pair)
        .collect();
    let per_pair: Vec<Vec<f64>> = pairs
        .iter()
        .map(|(_, cp)| {
            (0..cp.samples.c1.len())
                .into_par_iter()
                .map(|i| {
                    let c1 = cp.samples.c1[i];
                    let c2 = cp.samples.c2[i];
                    qd.signed(Vec3::new(c1[0], c1[1], c1[2]) * s)
                        + qf.signed(Vec3::new(c2[0], c2[1], c2[2]) * s)
                })
                .collect()
        })
        .collect();
    let kept_limit = design.clearance + GAP_TOL_MM;
    let cut_by = culprits(design, &pairs, &per_pair, kept_limit);
    let gaps = pairs
        .iter()
        .zip(&per_pair)
        .zip(cut_by)
        .map(|(((k, _), g), cut_by)| PairGap {
            cut_by,
            ..pair_gap(k + 1, g, kept_limit)
        })
        .collect();
    let closure = built_closure(mech, &pairs, &per_pair, kept_limit);
    let walls = [(qd, driver), (qf, follower), (qs, support)]
        .map(|(q, m)| wall_thickness(&q.tri, m, SLIVER_MM, WALL_REACH_MM))
        .into();
    CheckFigures {
        times: CHECK_TIMES,
        clearance_mm: design.clearance,
        penetrations,
        gaps,
        closure,
        walls,
    }
}

/// The figures of one pair's gaps `g` (one per sample); above `kept_limit` it is lost.
fn pair_gap(pair: usize, g: &[f64], kept_limit: f64) -> PairGap {
    let n = g.len().max(1);
    let lost: Vec<bool> = g.iter().map(|&x| x > kept_limit).collect();
    let kept: Vec<f64> = g.iter().copied().filter(|&x| x <= kept_limit).collect();
    let min_i = (0..g.len())
        .min_by(|&a, &b| g[a].total_cmp(&g[b]))
        .unwrap_or(0);
    PairGap {
        pair,
        min_mm: g.iter().copied().fold(f64::INFINITY, f64::min),
        min_t: min_i as f64 / n as f64,
        max_mm: g.iter().copied().fold(f64::NEG_INFINITY, f64::max),
        mean_mm: if kept.is_empty() {
            f64::NAN
        } else {
            kept.iter().sum::<f64>() / kept.len() as f64
        },
        lost_fraction: lost.iter().filter(|&&l| l).count() as f64 / n as f64,
        lost: windows(&lost),
        cut_by: Vec::new(),
    }
}

/// For each pair, which rims' swept volume reaches past its contact curve c¹ at the samples
/// where the contact is lost (see [`PairGap::cut_by`]).
fn culprits(
    design: &Design,
    pairs: &[(usize, &crate::synth::mechanism::CurvePair)],
    gaps: &[Vec<f64>],
    kept_limit: f64,
) -> Vec<Vec<(usize, f64)>> {
    let s = design.kin.scale_mm();
    pairs
        .iter()
        .zip(gaps)
        .map(|((_, cp), g)| {
            let n = g.len().max(1);
            let mut counts = vec![0usize; design.rims.len()];
            let hits: Vec<Vec<usize>> = (0..g.len())
                .into_par_iter()
                .filter(|&i| g[i] > kept_limit)
                .map(|i| {
                    let c1 = cp.samples.c1[i];
                    let p = Vec3::new(c1[0], c1[1], c1[2]) * s;
                    (0..design.rims.len())
                        .filter(|&j| {
                            ExactSweep {
                                kin: &design.kin,
                                solid: &design.rims[j],
                                frame: Frame::Follower,
                                target: Frame::Driver,
                                cap: 0.0,
                                // Only whether it is this deep matters.
                                floor: -GAP_TOL_MM,
                            }
                            .value(p)
                                <= -GAP_TOL_MM
                        })
                        .collect()
                })
                .collect();
            for h in hits {
                for j in h {
                    counts[j] += 1;
                }
            }
            let mut by: Vec<(usize, f64)> = counts
                .iter()
                .enumerate()
                .filter(|(_, &c)| c > 0)
                .map(|(j, &c)| (pairs[j].0 + 1, c as f64 / n as f64))
                .collect();
            by.sort_by(|a, b| b.1.total_cmp(&a.1));
            by
        })
        .collect()
}

/// dist(t) at every sample from the contacts kept there (gap ≤ `kept_limit`), through
/// [`Mechanism::closure_with`]: the pairs built are `pairs`, `gaps` in their order.
fn built_closure(
    mech: &Mechanism,
    pairs: &[(usize, &crate::synth::mechanism::CurvePair)],
    gaps: &[Vec<f64>],
    kept_limit: f64,
) -> BuiltClosure {
    use crate::synth::closure::EPSILON;
    let mut gap_of: Vec<Option<&Vec<f64>>> = vec![None; mech.curve_pairs.len()];
    for ((k, _), g) in pairs.iter().zip(gaps) {
        gap_of[*k] = Some(g);
    }
    let s = mech.closure_with(|k, i| gap_of[k].is_some_and(|g| g[i] <= kept_limit));
    let n = s.dist.len();
    // The first sample where `d` is largest, as a time.
    let worst = |d: &[f64]| {
        d.iter()
            .enumerate()
            .fold((f64::NEG_INFINITY, 0.0), |w, (i, &v)| {
                if v > w.0 {
                    (v, i as f64 / n as f64)
                } else {
                    w
                }
            })
    };
    let (max_dist, worst_t) = worst(&s.dist);
    let (robust_max_dist, robust_worst_t) = worst(&s.robust_dist);
    BuiltClosure {
        max_dist,
        worst_t,
        robust_max_dist,
        robust_worst_t,
        robust_required: mech.closure.robust_max_dist <= -EPSILON,
        instants_with_lost_contacts: (0..n)
            .filter(|&i| gaps.iter().any(|g| g[i] > kept_limit))
            .count(),
        samples: n,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::build::tests::test_mechanism;
    use crate::synth::closure::{self, EPSILON};

    /// Guards the parity columns where the mesh's edges and vertices lie on them: a cube
    /// whose corners are on the coarse grid's lines (its box starts the grid) has its
    /// face diagonals and corners right under the voxel centres. Every voxel centre inside
    /// must be found inside, by its exact depth, and every one outside given at most its
    /// distance. With the columns through the centres themselves, the diagonals counted
    /// twice and the voxels along them came out as far outside.
    #[test]
    fn a_box_on_the_grid_lines_is_inside_where_it_is() {
        use crate::geometry::primitive_meshes::cuboid;
        let q = Queryable::new(&cuboid([0.0; 3], [12.0; 3]));
        let mut inside = 0;
        for x in -3..=15 {
            for y in -3..=15 {
                for z in [-2, 1, 4, 6, 9, 14] {
                    let p = Vec3::new(x as f64, y as f64, z as f64);
                    let (exact, room) = (q.signed(p), q.room(p));
                    if exact < 0.0 {
                        assert_eq!(room, exact, "at {p:?}");
                        inside += 1;
                    } else {
                        assert!((0.0..=exact).contains(&room), "at {p:?}: {room} of {exact}");
                    }
                }
            }
        }
        assert_eq!(inside, 11 * 11 * 4);
    }

    /// Guards the grids' shortcuts: at points in and around a torus mesh, the room is
    /// exactly parry's signed distance inside, and outside never more than it (nor below 0);
    /// the fine grid lets most points near the surface skip the query, and farther out the
    /// occupancy grid and the box give most points room of several mm.
    #[test]
    fn room_is_exact_inside_and_a_lower_bound_outside() {
        use crate::geometry::primitive_meshes::torus;
        use rand::{Rng, SeedableRng};
        use rand_chacha::ChaCha8Rng;
        let q = Queryable::new(&torus([1.0, -2.0, 0.5], 20.0, 4.0, 96, 32));
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        let (mut inside, mut skipped, mut far_room) = (0, 0, 0);
        for i in 0..25_000 {
            // The first 20 000 within a few mm of the tube's surface, where the fine grid
            // has values; the rest up to 20 mm out, past the grids' edge.
            let off = if i < 20_000 { -1.5..3.5 } else { 3.5..20.0 };
            let a = rng.random_range(0.0..std::f64::consts::TAU);
            let b = rng.random_range(0.0..std::f64::consts::TAU);
            let r = 4.0 + rng.random_range(off);
            let rho = 20.0 + r * b.cos();
            let p = Vec3::new(1.0 + rho * a.cos(), -2.0 + rho * a.sin(), 0.5 + r * b.sin());
            let (exact, room) = (q.signed(p), q.room(p));
            if exact <= 0.0 {
                assert_eq!(room, exact, "at {p:?}");
                inside += 1;
            } else {
                assert!((0.0..=exact).contains(&room), "at {p:?}: {room} of {exact}");
            }
            if i < 20_000 && q.proved_room(p).is_some() {
                skipped += 1;
            }
            if i >= 20_000 && room > 0.5 * exact {
                far_room += 1;
            }
        }
        assert!(inside > 4_000, "{inside} points inside");
        assert!(skipped > 5_000, "{skipped} points skipped the query");
        assert!(far_room > 2_500, "{far_room} far points with room");
    }

    /// Guards when the grids' distances are computed: preparing a part computes none, a
    /// point near the surface computes its fine centre and that centre's coarse one, and a
    /// second point in the same fine voxel computes nothing more (the check's vertices come
    /// near a part along the contact strips only).
    #[test]
    fn the_grids_compute_only_what_points_ask() {
        use crate::geometry::primitive_meshes::torus;
        let q = Queryable::new(&torus([1.0, -2.0, 0.5], 20.0, 4.0, 96, 32));
        let computed = |grid: &OnceValues| grid.computed();
        assert_eq!((computed(&q.coarse), computed(&q.lower)), (0, 0));
        // 0.3 mm outside the tube, on its outer equator.
        let p = Vec3::new(1.0 + 24.3, -2.0, 0.5);
        let first = q.room(p);
        assert!(first > 0.0 && first <= 0.3 + 1e-9, "room {first}");
        assert_eq!((computed(&q.coarse), computed(&q.lower)), (1, 1));
        let f = q.fine.voxel_of(p).unwrap();
        let same_voxel = q.fine.center(f) + (p - q.fine.center(f)) * 0.5;
        q.room(same_voxel);
        assert_eq!((computed(&q.coarse), computed(&q.lower)), (1, 1));
    }

    /// Guards the check's skipping of instants: a ball in the follower's frame that passes
    /// through a ball in the driver's frame for a few instants gives exactly the deepest
    /// vertex and instant of testing every vertex at every instant with parry's query, and
    /// most tests are skipped.
    #[test]
    fn skipping_instants_keeps_the_deepest_penetration() {
        use crate::geometry::primitive_meshes::uv_sphere;
        let mech = test_mechanism();
        let kin = Kinematics::new(&mech, mech.scale_mm).expect("kinematics");
        let centre = nalgebra::Point3::new(30.0, 4.0, 5.0);
        let fixed = Queryable::new(&uv_sphere([centre.x, centre.y, centre.z], 3.0, 32, 16));
        let met = kin.transform(Frame::Driver, Frame::Follower, 0.3) * centre;
        let moving = uv_sphere([met.x + 0.2, met.y, met.z], 2.0, 16, 8);
        let mut want = (0.0, 0.0);
        for j in 0..CHECK_TIMES {
            let t = j as f64 / CHECK_TIMES as f64;
            let m = kin.transform(Frame::Follower, Frame::Driver, t);
            for v in &moving.vertices {
                let x = m * nalgebra::Point3::new(v[0], v[1], v[2]);
                let depth = (-fixed.signed(x.coords)).max(0.0);
                if depth > want.0 {
                    want = (depth, t);
                }
            }
        }
        assert!(want.0 > 0.5, "the balls meet: {want:?}");
        let instants = Instants::new(&kin, Frame::Follower, Frame::Driver);
        let got = deepest(&instants, &vertex_chunks(&moving), &fixed);
        assert_eq!((got.depth, got.t), want);
        let all = moving.vertices.len() * CHECK_TIMES;
        assert!(got.tests * 10 < all, "{} of {all} tests made", got.tests);
    }

    /// A square bar 20 mm long along `along` (x or y), turned 45° about that axis so that
    /// one of its edges runs along the bar at height `tip_z`, pointing up (`up`) or down.
    /// Its half diagonal is 5 mm.
    fn bar_on_edge(along: usize, tip_z: f64, up: bool) -> Mesh {
        use crate::geometry::primitive_meshes::cuboid;
        use nalgebra::{Rotation3, Vector3};
        let s = 5.0 / 2f64.sqrt();
        let (mut lo, mut hi) = ([-s; 3], [s; 3]);
        (lo[along], hi[along]) = (-10.0, 10.0);
        let mut bar = cuboid(lo, hi);
        let axis = if along == 0 {
            Vector3::x_axis()
        } else {
            Vector3::y_axis()
        };
        let turn = Rotation3::from_axis_angle(&axis, std::f64::consts::FRAC_PI_4);
        let centre_z = if up { tip_z - 5.0 } else { tip_z + 5.0 };
        bar.map_vertices(|v| {
            let p = turn * Point3::from(v);
            [p.x, p.y, p.z + centre_z]
        });
        bar
    }

    /// Guards the ridges' test: two square bars crossed at right angles with an edge of
    /// each pointing at the other, 0.3 mm into each other, every corner of each far
    /// outside the other. No vertex is inside, so the vertices' test finds nothing; the
    /// ridges' test finds each edge inside the other bar by the depth of its middle
    /// there: 0.3/√2 mm from the other's two faces. Without the ridges' test the check
    /// would have passed these parts.
    #[test]
    fn crossing_ridges_are_found_where_no_vertex_is_inside() {
        let mech = test_mechanism();
        let kin = Kinematics::new(&mech, mech.scale_mm).expect("kinematics");
        // One instant, the parts as placed.
        let still = Instants::new(&kin, Frame::Driver, Frame::Driver);
        let lower = bar_on_edge(1, 0.0, true);
        let upper = bar_on_edge(0, -0.3, false);
        let want = 0.3 / 2f64.sqrt();
        for (moving, fixed) in [(&upper, &lower), (&lower, &upper)] {
            let fixed = Queryable::new(fixed);
            let by_vertices = deepest(&still, &vertex_chunks(moving), &fixed);
            assert_eq!(by_vertices.depth, 0.0);
            let ridges = ridges(moving);
            let by_ridges = deepest_ridge(&still, &ridge_chunks(&ridges), &fixed);
            assert!(
                (by_ridges.depth - want).abs() < 1e-9,
                "{} deep, {want} expected",
                by_ridges.depth
            );
        }
        // Apart by 0.1 mm, neither is inside.
        let apart = bar_on_edge(0, 0.1, false);
        let fixed = Queryable::new(&lower);
        let by_ridges = deepest_ridge(&still, &ridge_chunks(&ridges(&apart)), &fixed);
        assert_eq!(by_ridges.depth, 0.0);
    }

    /// A 2 mm cube standing on a corner, that corner at `corner` (every other corner above
    /// it).
    fn cube_on_corner(corner: Point3<f64>) -> Mesh {
        use crate::geometry::primitive_meshes::cuboid;
        use nalgebra::{UnitQuaternion, Vector3};
        let up = UnitQuaternion::rotation_between(&Vector3::new(1.0, 1.0, 1.0), &Vector3::z())
            .expect("not opposite");
        let mut cube = cuboid([0.0; 3], [2.0; 3]);
        cube.map_vertices(|v| (corner + up * Vector3::from(v)).coords.into());
        cube
    }

    /// Guards the support's vertices in the interference test: a corner of the support
    /// 0.3 mm into the top face of a slab the driver turns in its plane, and another
    /// 0.2 mm into one the follower turns, at every instant. No vertex of either slab is
    /// inside the support and no ridge of either comes near it, so the tests of the
    /// moving parts' vertices and ridges find nothing: only the support's corners, as deep
    /// as they go, from the first instant. Before the support's vertices were tested, the
    /// check passed such parts.
    #[test]
    fn a_corner_of_the_support_inside_a_moving_part_is_found() {
        use crate::geometry::primitive_meshes::cuboid;
        let (_, kin) = crate::build::tests::half_turn();
        let driver = cuboid([-20.0, -20.0, -1.0], [20.0, 20.0, 0.0]);
        let follower = cuboid([-20.0, -20.0, -21.0], [20.0, 20.0, -20.0]);
        let mut support = cube_on_corner(kin.driver(0.0) * Point3::new(3.0, 0.0, -0.3));
        support.append(&cube_on_corner(
            kin.follower(0.0) * Point3::new(3.0, 0.0, -20.2),
        ));
        let parts = [
            Prepared::new("driver", Frame::Driver, &driver, true),
            Prepared::new("follower", Frame::Follower, &follower, true),
            Prepared::new("support", Frame::Reference, &support, false),
        ];
        let found = interference(&kin, [&parts[0], &parts[1], &parts[2]]);
        let found: Vec<(&str, f64, f64)> = found
            .iter()
            .map(|p| (p.what.as_str(), p.depth_mm, p.t))
            .collect();
        let want = [
            ("follower into driver", 0.0),
            ("driver into follower", 0.0),
            ("follower into support", 0.0),
            ("driver into support", 0.0),
            ("support into driver", 0.3),
            ("support into follower", 0.2),
        ];
        assert_eq!(found.len(), want.len(), "{found:?}");
        for ((what, depth, t), (want_what, want_depth)) in found.iter().zip(want) {
            assert_eq!(*what, want_what, "{found:?}");
            assert!((depth - want_depth).abs() < 1e-9, "{found:?}");
            assert_eq!(*t, 0.0, "{found:?}");
        }
    }

    /// Guards the depth along a segment: through a 10 mm cube, its middle inside is the
    /// cube's centre; from the centre out through a face, the middle of the stretch from
    /// the start to that face; one that passes beside the cube, or ends before it, has none.
    #[test]
    fn a_segment_is_as_deep_as_the_middle_of_its_stretch_inside() {
        use crate::geometry::primitive_meshes::cuboid;
        let q = Queryable::new(&cuboid([0.0; 3], [10.0; 3]));
        let v = |x: f64, y: f64, z: f64| Vec3::new(x, y, z);
        let through = q.segment_depth(v(-5.0, 5.0, 5.0), v(15.0, 5.0, 5.0), false, false);
        assert!((through.unwrap() - 5.0).abs() < 1e-12, "{through:?}");
        let out = q.segment_depth(v(5.0, 5.0, 5.0), v(5.0, 5.0, 15.0), true, false);
        assert!((out.unwrap() - 2.5).abs() < 1e-12, "{out:?}");
        assert_eq!(
            q.segment_depth(v(-5.0, 12.0, 5.0), v(15.0, 12.0, 5.0), false, false),
            None
        );
        assert_eq!(
            q.segment_depth(v(-5.0, 5.0, 5.0), v(-1.0, 5.0, 5.0), false, false),
            None
        );
    }

    /// Guards which edges are ridges: a box's twelve edges (square, convex) and not its
    /// faces' diagonals (flat); none of a finely divided sphere's (its faces turn by about
    /// 11° from one to the next); none of a box turned inside out (every edge concave).
    #[test]
    fn ridges_are_the_sharp_convex_edges() {
        use crate::geometry::primitive_meshes::{cuboid, uv_sphere};
        let mut boxed = cuboid([0.0; 3], [3.0, 4.0, 5.0]);
        assert_eq!(ridges(&boxed).len(), 12);
        for [a, b] in ridges(&boxed) {
            let along = (b - a).map(f64::abs);
            assert_eq!(along.iter().filter(|&&x| x > 0.0).count(), 1, "{a} to {b}");
        }
        assert!(ridges(&uv_sphere([0.0; 3], 5.0, 32, 16)).is_empty());
        for t in &mut boxed.triangles {
            t.swap(1, 2);
        }
        assert!(ridges(&boxed).is_empty());
    }

    /// Guards the chunks' order: the Morton key interleaves the cells' bits (x lowest),
    /// bit for bit as a plain loop does it.
    #[test]
    fn the_morton_key_interleaves_the_bits() {
        let plain = |c: [u64; 3]| {
            (0..21).fold(0u64, |key, b| {
                (0..3).fold(key, |key, k| key | (((c[k] >> b) & 1) << (3 * b + k)))
            })
        };
        for c in [
            [0, 0, 0],
            [1, 0, 0],
            [0, 1, 0],
            [0, 0, 1],
            [5, 9, 3],
            [0x1f_ffff; 3],
            [123_456, 7, 1_048_575],
        ] {
            assert_eq!(morton(c), plain(c), "{c:?}");
        }
    }

    /// Guards the lost-contact windows: runs of lost samples as first and last sample time,
    /// one run across the period's end kept whole (from > to), nothing lost gives none.
    #[test]
    fn windows_are_the_runs_of_lost_samples() {
        let f = |v: &[u8]| windows(&v.iter().map(|&x| x == 1).collect::<Vec<_>>());
        assert_eq!(
            f(&[0, 1, 1, 0, 0, 1, 0, 0]),
            vec![[0.125, 0.25], [0.625, 0.625]]
        );
        assert_eq!(f(&[1, 0, 0, 1, 1]), vec![[0.6, 0.0]]);
        assert_eq!(f(&[0, 0, 0]), Vec::<[f64; 2]>::new());
        assert_eq!(f(&[1, 1]), vec![[0.0, 0.5]]);
    }

    /// Guards the closure of the parts as built: with every contact kept it is the file's
    /// closure; with one pair's contact lost over a window, it is the closure of the other
    /// pairs there (computed here independently), and a pair lost everywhere is counted at
    /// every instant.
    #[test]
    fn closure_is_computed_from_the_contacts_kept() {
        let mech = test_mechanism();
        let pairs: Vec<(usize, &crate::synth::mechanism::CurvePair)> =
            mech.curve_pairs.iter().enumerate().collect();
        let n = pairs[0].1.samples.p.len();
        let clearance = 0.2;
        let limit = clearance + GAP_TOL_MM;
        let all_kept = vec![vec![clearance; n]; pairs.len()];
        let c = built_closure(&mech, &pairs, &all_kept, limit);
        assert!((c.max_dist - mech.closure.max_dist).abs() < 1e-9, "{c:?}");
        assert_eq!(c.instants_with_lost_contacts, 0);
        assert!(c.failure().is_none());

        // Pair 1 lost at every instant: the other pairs' closure, instant by instant.
        let mut lost = all_kept.clone();
        lost[0] = vec![5.0; n];
        let c = built_closure(&mech, &pairs, &lost, limit);
        let expected = (0..n)
            .map(|i| {
                let contacts: Vec<_> = pairs[1..]
                    .iter()
                    .map(|(_, cp)| (cp.samples.p[i], cp.samples.n[i]))
                    .collect();
                closure::dist_at(mech.class, &contacts).0
            })
            .fold(f64::NEG_INFINITY, f64::max);
        assert!((c.max_dist - expected).abs() < 1e-12);
        assert_eq!(c.instants_with_lost_contacts, n);
        assert!(
            c.max_dist >= mech.closure.max_dist - 1e-12,
            "fewer contacts closed better"
        );
        assert_eq!(
            c.failure().is_some(),
            c.max_dist > -EPSILON || c.robust_max_dist > -EPSILON
        );
    }

    /// Guards what fails the check: a gap below the clearance binds and is named with its
    /// pair and time; a lost contact alone does not fail it.
    #[test]
    fn binding_fails_and_lost_contacts_alone_do_not() {
        let closure = BuiltClosure {
            max_dist: -0.05,
            worst_t: 0.0,
            robust_max_dist: -0.04,
            robust_worst_t: 0.0,
            robust_required: true,
            instants_with_lost_contacts: 3,
            samples: 8,
        };
        let lost = pair_gap(1, &[0.2, 0.2, 3.0, 3.0, 0.25, 0.2, 0.2, 0.2], 0.3);
        assert_eq!(lost.lost, vec![[0.25, 0.375]]);
        assert_eq!(lost.lost_fraction, 0.25);
        assert!((lost.mean_mm - 1.25 / 6.0).abs() < 1e-12);
        let mut f = CheckFigures {
            times: CHECK_TIMES,
            clearance_mm: 0.2,
            penetrations: Vec::new(),
            gaps: vec![lost],
            closure,
            walls: Vec::new(),
        };
        assert_eq!(f.failure(), None);
        f.gaps.push(pair_gap(2, &[0.2, 0.05, 0.2, 0.2], 0.3));
        assert_eq!(
            f.failure().as_deref(),
            Some("the gap at curve pair 2's contact closes to 0.050 mm at t = 0.2500, below the clearance 0.20 − 0.1 mm")
        );
    }
}
