//! How far the follower can move, at one driver angle, before its mesh touches the driver's.
//!
//! Owns [`Solid`] (a part's mesh ready for distance queries, its vertices grouped in
//! clusters, each with the faces it owns), [`Screw`] (a motion the follower's joint
//! allows: a turn about its axis, R's z axis, a slide along it, or both at once) and
//! [`free_along`], which answers, for every sample time of a period and each sense of each
//! given screw, the largest motion δ ≤ a cap from the design pose that leaves the two
//! meshes apart. Both ways are tested: every follower vertex against the driver's mesh
//! and every driver vertex against the follower's, so an edge of either part that would
//! cut into a face of the other is seen.
//!
//! A vertex is *sphere-traced* along its path: at δ its distance d to the other mesh is a
//! ball it cannot leave before the motion advances d / r more (r how far the vertex moves
//! per unit of δ: its distance from the axis for a turn, 1 for a slide), so δ advances by
//! d / r until d falls below [`HIT_MM`]. The result is exact to `HIT_MM / r` and never
//! overshoots a contact. What makes it affordable, each step safe because it only uses
//! lower bounds on distances:
//! - clusters of vertices (cells of [`CLUSTER_MM`]) are skipped while a lower bound on
//!   their distance, carried from their last query by the parts' speed bound, shows they
//!   cannot touch within the search limit;
//! - each part carries a coarse distance grid ([`GRID_MM`], made when first asked) whose
//!   lower bound answers for points more than about a millimetre away without a mesh
//!   query, and nearer the surface the exact distance of the point's voxel centre,
//!   computed once for every point and every sample that asks there (its own query the
//!   first time);
//! - the search limit starts at twice the last sample's free motion (the whole cap only when
//!   nothing touches within it), and the vertex that touched first at the last sample is
//!   traced first;
//! - a vertex whose faces all look away from its motion (its normal cone: the mean of its
//!   faces' normals and their spread) is not traced: it moves into space its own part
//!   held just before, so the part's faces ahead of it meet the other part first (their
//!   vertices, or the other part's vertices entering them, are traced). Measured on the
//!   0.4 mm parts of half-turn-2to1 it skips about half the traced vertices.
//!
//! A test holds these against a plain trace of every vertex.
//!
//! `predict` finds every free motion of a follower that moves about R's z axis (1R and
//! 1R1T, so every class it takes today) exactly by [`crossings`](super::crossings), which
//! shares [`Solid`] and [`Screw`] but not the trace; the trace is kept for a follower
//! whose design pose moves its axis, which the crossings refuse.
//!
//! Exact distances are parry3d-f64's point–mesh projections with pseudo-normals (inside or
//! outside), the same queries the build's check uses. The module does not know the target
//! law, the load or the files; it does not look at the support.

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::OnceLock;

use nalgebra::{Isometry3, Point3, UnitQuaternion, Vector3};
use rayon::prelude::*;

use crate::geometry::mesh::{Aabb, Mesh};
use crate::geometry::query::MeshQuery;
use crate::geometry::sdf::{closest_on_triangle, Vec3};
use crate::geometry::voxel::{distance_transform, OnceValues, VoxelGrid};

/// A vertex this near the other part's surface touches it, mm. 0.002 mm: a hundredth of
/// the default clearance and far below the meshes' own error (≈ 0.05 mm), so the turn it
/// stops short of a true touch is negligible (0.002 mm / 20 mm = 0.006°).
pub const HIT_MM: f64 = 0.002;
/// Edge of the cells that group vertices into clusters, mm. 2 mm: a few hundred vertices
/// per cluster on the default meshes, small enough that a cluster near the contact does not
/// drag many far vertices into the exact test.
pub const CLUSTER_MM: f64 = 2.0;
/// Largest number of steps along one vertex's arc. A step is at least `HIT_MM / r`, so a
/// grazing vertex needs at most cap·r / `HIT_MM` steps (≈ 2 600 at a 10° cap and 30 mm);
/// beyond this the vertex is taken to touch where it is (never to be free).
const MAX_STEPS: usize = 20_000;
/// Voxel of the coarse distance grid each part carries, mm. 0.5 mm: its lower bound is
/// √3·h ≈ 0.87 mm loose, so a point farther than about a millimetre from a part is
/// judged by a table lookup instead of a mesh query; one f32 per voxel, about 100 MB for
/// the largest examples' driver.
pub const GRID_MM: f64 = 0.5;
/// Margin of the distance grid around the mesh's box, mm; beyond it the distance to the box
/// is the bound.
const GRID_MARGIN_MM: f64 = 4.0;
/// Along a traced arc, a grid bound above this is stepped on without a mesh query, mm: a
/// grid step is at most this much shorter than the exact one (the bound's slack), so a
/// few wasted steps cost less than a query each.
const FAR_MM: f64 = 1.0;
/// A vertex that moves less than this per unit of the motion is not traced, mm: one on the
/// axis does not move under a turn.
pub(crate) const ON_AXIS_MM: f64 = 1e-6;

/// Error building a [`Solid`].
#[derive(Debug, thiserror::Error)]
pub enum SolidError {
    /// The mesh has no triangles, or parry refused it.
    #[error("the {part} mesh cannot be queried: {message}")]
    Mesh {
        /// Which part.
        part: String,
        /// parry's reason.
        message: String,
    },
}

/// One group of nearby vertices: a ball around them and their index range, and the
/// triangles it owns (those whose first corner in the sorted order is one of its
/// vertices) with a ball around all their corners.
#[derive(Clone, Debug)]
pub(crate) struct Cluster {
    pub(crate) center: Point3<f64>,
    pub(crate) radius: f64,
    pub(crate) start: usize,
    pub(crate) end: usize,
    /// Range of the cluster's triangles in [`Solid::tris`].
    pub(crate) tri_start: usize,
    /// See `tri_start`.
    pub(crate) tri_end: usize,
    /// Distance from `center` to the farthest vertex or corner of an owned triangle, mm
    /// (at least `radius`).
    pub(crate) tri_radius: f64,
}

/// The directions a vertex's faces look in: the mean of their unit normals (`axis`, unit)
/// and the sine of the largest angle between it and any of them (`spread`; 2, never
/// reached, when that angle is 90° or more).
#[derive(Clone, Copy, Debug)]
struct NormalCone {
    axis: Vector3<f64>,
    spread: f64,
}

impl NormalCone {
    /// Whether a vertex with this cone, moving along `dir` (unit), moves into the space its
    /// own part held just before: every face around it looks away from `dir` (the angle
    /// between `dir` and the axis exceeds 90° plus the cone's half-angle). Such a vertex is
    /// never the first of its part to touch another, whose surface would have met the
    /// part's faces ahead of it.
    fn trails(&self, dir: &Vector3<f64>) -> bool {
        self.axis.dot(dir) < -self.spread
    }
}

/// When a [`Solid`] makes parry's hierarchy and the pseudo-normals behind
/// [`Solid::signed`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Query {
    /// With the solid: a part asked many exact distances (its own distance grid, the
    /// tracer's steps).
    Now,
    /// When first asked. For a part only ever placed against the other's bounds and asked
    /// a few exact distances ([`Solid::signed_near`]): the driver of a prediction by
    /// crossings, whose hierarchy and pseudo-normals took 3.35 s of the 6.0 s its
    /// preparation took on half-turn-2to1's printable parts (docs/simulate.md).
    WhenAsked,
}

/// The faces within this of the nearest one, with their nearest point within this of its,
/// count as nearest too in [`Solid::signed_near`], mm: the faces round a vertex or along
/// an edge the nearest point lies on are as near to the last bits.
const NEAREST_TIE_MM: f64 = 1e-9;

/// The cell of [`CLUSTER_MM`] a point lies in: a [`Solid`]'s clusters are its vertices by
/// cell, and [`Solid::signed_near`] finds those round a point by the same cells.
fn cluster_cell(p: [f64; 3]) -> [i64; 3] {
    p.map(|x| (x / CLUSTER_MM).floor() as i64)
}

/// A part's mesh ready for distance queries (parry's BVH with pseudo-normals, made with it
/// or when first asked: [`Query`]), with its vertices sorted into clusters.
pub struct Solid {
    tri: OnceLock<MeshQuery>,
    pub(crate) verts: Vec<Point3<f64>>,
    /// The mesh's triangles as indices into `verts`, grouped by the cluster that owns
    /// them.
    pub(crate) tris: Vec<[u32; 3]>,
    /// Per triangle (the order of `tris`), the distance from its cluster's centre to its
    /// farthest corner, mm.
    pub(crate) tri_offset: Vec<f32>,
    /// Per vertex, its distance from its cluster's centre, mm.
    pub(crate) vert_offset: Vec<f32>,
    /// Per vertex (the order of `verts`), the directions its faces look in.
    cones: Vec<NormalCone>,
    pub(crate) clusters: Vec<Cluster>,
    aabb: Aabb,
    /// Per cluster, its cell of [`CLUSTER_MM`] (the clusters are in the cells' order).
    cells: Vec<[i64; 3]>,
    /// The largest [`Cluster::tri_radius`], mm.
    cluster_reach: f64,
    /// The distance grid behind [`Solid::lower_bound`], made when first needed: a part
    /// only ever placed against the other's bounds (the driver of a 1R prediction) never
    /// needs its own, and it is the largest thing a `Solid` holds.
    bounds: OnceLock<Bounds>,
    /// Voxel centres whose exact distance was computed (mesh queries, a cost figure).
    centres: AtomicU64,
}

/// A part's coarse distance grid and the exact distances of its voxel centres.
struct Bounds {
    grid: VoxelGrid,
    /// Distance from each voxel centre to the nearest voxel the surface passes through.
    coarse: Vec<f32>,
    /// The exact distance from each voxel centre to the surface, computed the first time a
    /// point near the surface asks.
    exact: OnceValues,
}

impl Bounds {
    /// The grid of [`GRID_MM`] voxels over `aabb` and [`GRID_MARGIN_MM`] around it, with
    /// the coarse distances of the triangles `tris` of `verts`.
    fn new(aabb: Aabb, verts: &[Point3<f64>], tris: &[[u32; 3]]) -> Bounds {
        let grid = VoxelGrid::covering(aabb.inflate(GRID_MARGIN_MM), GRID_MM);
        // Every voxel whose cell meets a triangle's box holds the surface points there.
        let marks = grid.marks_of_triangle_boxes(tris.iter().map(|t| {
            t.map(|v| {
                let p = verts[v as usize];
                [p.x, p.y, p.z]
            })
        }));
        let coarse = distance_transform(&grid, &marks);
        let exact = OnceValues::new(grid.len());
        Bounds {
            grid,
            coarse,
            exact,
        }
    }
}

/// Subtracted from a stored centre distance for its rounding to f32, mm: an f32 near
/// 300 mm is within 2e-5 mm of the f64 it came from.
pub(crate) const F32_SLACK_MM: f64 = 1e-4;
/// Below this coarse bound a point asks its voxel centre's exact distance, mm. 2 mm: the
/// bound is compared with free arcs (r × free turn, up to about 1.5 mm at the examples'
/// levers and plays) and with `FAR_MM`; above 2 mm the coarse bound already decides, and
/// an exact centre there would be a query spent for nothing.
pub const EXACT_BELOW_MM: f64 = 2.0;

impl Solid {
    /// Prepare `mesh` (the part `part`, in its own frame, mm), its queries with it.
    pub fn new(mesh: &Mesh, part: &str) -> Result<Solid, SolidError> {
        Solid::with_query(mesh, part, Query::Now)
    }

    /// Prepare `mesh` (the part `part`, in its own frame, mm), its queries `when`.
    pub fn with_query(mesh: &Mesh, part: &str, when: Query) -> Result<Solid, SolidError> {
        match when {
            Query::Now => Solid::with_query_beside(mesh, part, |_| ()).map(|(solid, ())| solid),
            Query::WhenAsked => {
                Solid::refuse_empty(mesh, part)?;
                Ok(Solid::laid_out(mesh))
            }
        }
    }

    /// [`Solid::new`], running `beside` on the solid while parry's hierarchy and the
    /// pseudo-normals are made on another thread, and what it returns. Making them is
    /// serial for the most part (1.6 s of the 2.3 s half-turn-2to1's follower took to
    /// prepare); the clusters, and what a caller makes of them (`simulate`'s distance grid
    /// and bins, 0.9 s more), need only the vertices and the triangles.
    ///
    /// `beside` must not ask for the queries (an exact distance): they are made beside it
    /// from the mesh in its own order, and a query made on demand would have been made from
    /// the clusters' order instead.
    pub fn with_query_beside<T: Send>(
        mesh: &Mesh,
        part: &str,
        beside: impl FnOnce(&Solid) -> T + Send,
    ) -> Result<(Solid, T), SolidError> {
        Solid::refuse_empty(mesh, part)?;
        let (query, (solid, made)) = rayon::join(
            || MeshQuery::new(mesh),
            || {
                let solid = Solid::laid_out(mesh);
                let made = beside(&solid);
                (solid, made)
            },
        );
        let query = query.map_err(|message| SolidError::Mesh {
            part: part.to_string(),
            message,
        })?;
        let unasked = solid.tri.set(query).is_ok();
        debug_assert!(unasked, "`beside` asked for the queries of {part}");
        Ok((solid, made))
    }

    /// parry refuses a mesh without triangles and nothing else (no topology flags are
    /// asked for), so that is checked first, and making the queries later cannot fail.
    fn refuse_empty(mesh: &Mesh, part: &str) -> Result<(), SolidError> {
        if mesh.triangles.is_empty() {
            return Err(SolidError::Mesh {
                part: part.to_string(),
                message: "it has no triangles".to_string(),
            });
        }
        Ok(())
    }

    /// `mesh`'s vertices sorted into clusters, its triangles grouped by them, without the
    /// queries (made when first asked, unless set now).
    fn laid_out(mesh: &Mesh) -> Solid {
        let tri = OnceLock::new();
        let cell = |v: &[f64; 3]| cluster_cell(*v);
        let mut order: Vec<usize> = (0..mesh.vertices.len()).collect();
        order.sort_by_key(|&i| (cell(&mesh.vertices[i]), i));
        let verts: Vec<Point3<f64>> = order
            .iter()
            .map(|&i| Point3::from(mesh.vertices[i]))
            .collect();
        let mut clusters = Vec::new();
        let mut cells = Vec::new();
        let mut start = 0;
        while start < order.len() {
            let key = cell(&mesh.vertices[order[start]]);
            let mut end = start + 1;
            while end < order.len() && cell(&mesh.vertices[order[end]]) == key {
                end += 1;
            }
            let sum = verts[start..end]
                .iter()
                .fold(Vector3::zeros(), |s, v| s + v.coords);
            let center = Point3::from(sum / (end - start) as f64);
            let radius = verts[start..end]
                .iter()
                .map(|v| (v - center).norm())
                .fold(0.0, f64::max);
            clusters.push(Cluster {
                center,
                radius,
                start,
                end,
                tri_start: 0,
                tri_end: 0,
                tri_radius: radius,
            });
            cells.push(key);
            start = end;
        }
        // Each triangle, its corners renumbered in the sorted order, goes to the cluster of
        // its first corner there.
        let mut rank = vec![0u32; order.len()];
        for (new, &old) in order.iter().enumerate() {
            rank[old] = new as u32;
        }
        let mut owner_of = vec![0u32; order.len()];
        for (ci, c) in clusters.iter().enumerate() {
            owner_of[c.start..c.end].fill(ci as u32);
        }
        let mut tris: Vec<[u32; 3]> = mesh
            .triangles
            .iter()
            .map(|t| t.map(|v| rank[v as usize]))
            .collect();
        tris.sort_by_key(|t| {
            (
                owner_of[*t.iter().min().expect("three corners") as usize],
                *t,
            )
        });
        let mut tri_offset = Vec::with_capacity(tris.len());
        let mut at = 0;
        for (ci, c) in clusters.iter_mut().enumerate() {
            c.tri_start = at;
            while at < tris.len()
                && owner_of[*tris[at].iter().min().expect("three corners") as usize] == ci as u32
            {
                let far = tris[at]
                    .iter()
                    .map(|&v| (verts[v as usize] - c.center).norm())
                    .fold(0.0, f64::max);
                c.tri_radius = c.tri_radius.max(far);
                tri_offset.push(far as f32);
                at += 1;
            }
            c.tri_end = at;
        }
        let mut vert_offset = vec![0f32; verts.len()];
        for c in &clusters {
            for v in c.start..c.end {
                vert_offset[v] = (verts[v] - c.center).norm() as f32;
            }
        }
        let cones = normal_cones(mesh);
        let cones = order.iter().map(|&i| cones[i]).collect();
        let aabb = mesh.aabb();
        let cluster_reach = clusters.iter().map(|c| c.tri_radius).fold(0.0, f64::max);
        Solid {
            tri,
            verts,
            tris,
            tri_offset,
            vert_offset,
            cones,
            clusters,
            aabb,
            cluster_reach,
            cells,
            bounds: OnceLock::new(),
            centres: AtomicU64::new(0),
        }
    }

    /// Make the distance grid behind [`lower_bound`](Self::lower_bound) now, if not yet
    /// made. Otherwise the first call makes it, and other threads asking meanwhile wait.
    pub fn prepare_bounds(&self) {
        self.bounds();
    }

    /// Whether the distance grid has been made.
    #[cfg(test)]
    pub(crate) fn has_bounds(&self) -> bool {
        self.bounds.get().is_some()
    }

    fn bounds(&self) -> &Bounds {
        self.bounds
            .get_or_init(|| Bounds::new(self.aabb, &self.verts, &self.tris))
    }

    /// A lower bound on the distance of `p` to the surface, mm. From the coarse grid: the
    /// distance between voxel centres less the two half-diagonals (`p` and the surface
    /// point each lie within one of their voxel's centre). Near the surface (a coarse
    /// bound below [`EXACT_BELOW_MM`]) also the exact distance of `p`'s voxel centre less
    /// `p`'s distance from it (the distance is 1-Lipschitz), the centre's computed once
    /// and kept. Far from the grid, the distance to the mesh's box.
    pub fn lower_bound(&self, p: &Point3<f64>) -> f64 {
        let Bounds {
            grid,
            coarse,
            exact,
        } = self.bounds();
        let Some(v) = grid.voxel_of(Vec3::new(p.x, p.y, p.z)) else {
            return self.aabb.distance([p.x, p.y, p.z]);
        };
        let i = grid.index(v);
        let coarse = (f64::from(coarse[i]) - 3f64.sqrt() * grid.h).max(0.0);
        if coarse >= EXACT_BELOW_MM {
            return coarse;
        }
        let c = grid.center(v);
        let centre = Point3::new(c.x, c.y, c.z);
        let at_centre = exact.get_or(i, || {
            self.centres.fetch_add(1, Ordering::Relaxed);
            self.signed(&centre).abs() as f32
        });
        (f64::from(at_centre) - (p - centre).norm() - F32_SLACK_MM)
            .max(coarse)
            .max(0.0)
    }

    /// Signed distance of `p` (this part's frame) to the surface, mm, negative inside.
    pub fn signed(&self, p: &Point3<f64>) -> f64 {
        self.query().signed([p.x, p.y, p.z])
    }

    /// [`signed`](Self::signed) when the surface is within `max_mm` of `p`; `None` when it
    /// is farther, at a fraction of the cost.
    pub fn signed_within(&self, p: &Point3<f64>, max_mm: f64) -> Option<f64> {
        self.query().signed_within([p.x, p.y, p.z], max_mm)
    }

    /// parry's queries, made now if they were not ([`Query::WhenAsked`]): from the sorted
    /// vertices and triangles, the same surface.
    fn query(&self) -> &MeshQuery {
        self.tri.get_or_init(|| {
            let mesh = Mesh {
                vertices: self.verts.iter().map(|v| [v.x, v.y, v.z]).collect(),
                triangles: self.tris.clone(),
            };
            MeshQuery::new(&mesh).expect("a mesh with triangles, checked when it was prepared")
        })
    }

    /// [`signed`](Self::signed) from the clusters, without parry's hierarchy: exact, its
    /// sign from the angle-weighted pseudo-normal at the nearest point (the faces as near
    /// as the nearest, each weighted by its angle there where that is a corner of it, else
    /// alike: one face, or the two along an edge). It reads the clusters of the cells round
    /// the point, nearest first, and the faces of those that may hold a nearer point,
    /// 68 µs a point on half-turn-2to1's driver: for the few points a part is asked about
    /// when making its hierarchy would cost more than all of them ([`Query::WhenAsked`]).
    /// NaN for a point that is not finite, as [`signed`](Self::signed) gives.
    pub fn signed_near(&self, p: &Point3<f64>) -> f64 {
        let q = p.coords;
        let home = cluster_cell([q.x, q.y, q.z]);
        // The clusters of the cells within `r` of the point's, by a binary search each;
        // all of them where there would be more such cells than a tenth of the clusters.
        let around = |r: i64| -> Vec<usize> {
            let side = (2 * r + 1) as usize;
            if side.saturating_pow(3) > self.clusters.len() / 10 {
                return (0..self.clusters.len()).collect();
            }
            let mut found = Vec::new();
            for a in -r..=r {
                for b in -r..=r {
                    for c in -r..=r {
                        let key = [home[0] + a, home[1] + b, home[2] + c];
                        if let Ok(i) = self.cells.binary_search(&key) {
                            found.push(i);
                        }
                    }
                }
            }
            found
        };
        // No point is farther than the nearest vertex, each within its cluster's radius of
        // its centre: first among the cells round the point, else among all.
        let bound = |ids: &[usize]| {
            ids.iter()
                .map(|&i| (p - self.clusters[i].center).norm() + self.clusters[i].radius)
                .fold(f64::INFINITY, f64::min)
        };
        if !(q.x.is_finite() && q.y.is_finite() && q.z.is_finite()) {
            return f64::NAN;
        }
        let mut best = bound(&around(1));
        if !best.is_finite() {
            best = bound(&(0..self.clusters.len()).collect::<Vec<_>>());
        }
        // A face nearer than `best` has its cluster's centre within `best` plus the
        // cluster's reach of the point, and that centre lies in the cluster's cell.
        let r = ((best + self.cluster_reach + NEAREST_TIE_MM) / CLUSTER_MM).ceil() as i64 + 1;
        // Nearest first, so that the bound falls fast and the farther clusters are passed by.
        let mut order: Vec<(f64, usize)> = around(r)
            .into_iter()
            .map(|i| {
                let c = &self.clusters[i];
                ((p - c.center).norm() - c.tri_radius, i)
            })
            .filter(|&(lower, _)| lower <= best + NEAREST_TIE_MM)
            .collect();
        order.sort_by(|a, b| a.0.total_cmp(&b.0));
        let mut near: Vec<(f64, usize, Vec3)> = Vec::new();
        for (lower, i) in order {
            if lower > best + NEAREST_TIE_MM {
                break;
            }
            let c = &self.clusters[i];
            for ti in c.tri_start..c.tri_end {
                let [a, b, d] = self.tris[ti].map(|v| self.verts[v as usize].coords);
                let x = closest_on_triangle(q, a, b, d);
                let dist = (q - x).norm();
                if dist <= best + NEAREST_TIE_MM {
                    best = best.min(dist);
                    near.push((dist, ti, x));
                }
            }
        }
        let Some(&(_, _, x)) = near.iter().find(|n| n.0 == best) else {
            return f64::NAN;
        };
        let normal: Vector3<f64> = near
            .iter()
            // A point as far from two places of the surface (between two posts, say) has
            // the faces of one of them, those whose nearest point is the same.
            .filter(|n| n.0 <= best + NEAREST_TIE_MM && (n.2 - x).norm() <= NEAREST_TIE_MM)
            .map(|&(_, ti, at)| {
                let c = self.tris[ti].map(|v| self.verts[v as usize].coords);
                let Some(n) = (c[1] - c[0]).cross(&(c[2] - c[0])).try_normalize(0.0) else {
                    return Vector3::zeros();
                };
                // Where the nearest point is a corner, the face counts by its angle there.
                let weight = (0..3).find(|&k| c[k] == at).map_or(1.0, |k| {
                    let (u, v) = (c[(k + 1) % 3] - c[k], c[(k + 2) % 3] - c[k]);
                    u.angle(&v)
                });
                n * weight
            })
            .sum();
        if (q - x).dot(&normal) <= 0.0 {
            -best
        } else {
            best
        }
    }

    /// Voxel centres whose exact distance was computed so far (a cost figure).
    pub(crate) fn centre_queries(&self) -> u64 {
        self.centres.load(Ordering::Relaxed)
    }

    /// Number of vertices.
    pub fn vertex_count(&self) -> usize {
        self.verts.len()
    }
}

/// Each vertex's [`NormalCone`], in the mesh's vertex order. A vertex without a face of
/// non-zero area gets a cone that never trails.
fn normal_cones(mesh: &Mesh) -> Vec<NormalCone> {
    let unit_normals: Vec<Option<Vector3<f64>>> = (0..mesh.triangles.len())
        .map(|i| {
            let [a, b, c] = mesh.corners(i).map(Vector3::from);
            (b - a).cross(&(c - a)).try_normalize(0.0)
        })
        .collect();
    let mut sum = vec![Vector3::zeros(); mesh.vertices.len()];
    for (t, n) in mesh.triangles.iter().zip(&unit_normals) {
        if let Some(n) = n {
            for &v in t {
                sum[v as usize] += n;
            }
        }
    }
    let axes: Vec<Option<Vector3<f64>>> = sum.iter().map(|s| s.try_normalize(1e-12)).collect();
    // The smallest cosine between a vertex's axis and its faces' normals.
    let mut cos_min = vec![1.0f64; mesh.vertices.len()];
    for (t, n) in mesh.triangles.iter().zip(&unit_normals) {
        for &v in t {
            let v = v as usize;
            cos_min[v] = match (axes[v], n) {
                (Some(a), Some(n)) => cos_min[v].min(a.dot(n)),
                _ => cos_min[v],
            };
        }
    }
    axes.iter()
        .zip(&cos_min)
        .map(|(axis, &c)| match axis {
            Some(axis) if c > 0.0 => NormalCone {
                axis: *axis,
                spread: (1.0 - c * c).max(0.0).sqrt(),
            },
            _ => NormalCone {
                axis: Vector3::z(),
                spread: 2.0,
            },
        })
        .collect()
}

/// The parts' design motion, as [`free_along`] needs it: poses of both frames in R (the
/// follower's joint axis is R's z axis) and bounds on how fast a point of one part moves
/// as seen from the other, and how far from the axis it can be.
pub trait PartMotion: Sync {
    /// Follower frame → R at time `t` (fraction of a period), at the design pose.
    fn follower(&self, t: f64) -> Isometry3<f64>;
    /// Driver frame → R at time `t`.
    fn driver(&self, t: f64) -> Isometry3<f64>;
    /// Bound on the speed of follower point `q` (F frame) seen from the driver, mm per
    /// period.
    fn follower_speed(&self, q: &Point3<f64>) -> f64;
    /// Bound on the speed of driver point `p` (D frame) seen from the follower, mm per
    /// period.
    fn driver_speed(&self, p: &Point3<f64>) -> f64;
    /// Bound on the distance from R's z axis of follower point `q` over the period, mm.
    fn follower_reach(&self, q: &Point3<f64>) -> f64;
    /// Bound on the distance from R's z axis of driver point `p` over the period, mm.
    fn driver_reach(&self, p: &Point3<f64>) -> f64;
}

/// A motion of the follower its joint allows about R's z axis: per unit of the motion's
/// parameter, a turn of `spin` rad (counter-clockwise about +z when positive) and a slide
/// of `slide` mm along +z. A 1R follower only turns ([`Screw::TURN`], in rad); a 1R1T one
/// also slides ([`Screw::SLIDE`], in mm) and screws (both at once).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Screw {
    /// Turn per unit, rad.
    pub spin: f64,
    /// Slide per unit, mm.
    pub slide: f64,
}

impl Screw {
    /// A turn, its parameter in rad.
    pub const TURN: Screw = Screw {
        spin: 1.0,
        slide: 0.0,
    };
    /// A slide along the axis, its parameter in mm.
    pub const SLIDE: Screw = Screw {
        spin: 0.0,
        slide: 1.0,
    };

    /// The same motion the other way.
    fn reversed(self) -> Screw {
        Screw {
            spin: -self.spin,
            slide: -self.slide,
        }
    }

    /// How far a point at distance `r` from the axis moves per unit of the parameter, mm
    /// (exactly `|spin|·r` for a turn, so a turn traces as it always did).
    pub(crate) fn lever(&self, r: f64) -> f64 {
        if self.slide == 0.0 {
            self.spin.abs() * r
        } else {
            (self.spin * r).hypot(self.slide)
        }
    }

    /// The motion by `delta` units, as a map of R.
    fn at(&self, delta: f64) -> Isometry3<f64> {
        Isometry3::from_parts(
            nalgebra::Translation3::new(0.0, 0.0, self.slide * delta),
            UnitQuaternion::from_axis_angle(&Vector3::z_axis(), self.spin * delta),
        )
    }

    /// The velocity of the point `w` (R) per unit of the parameter, mm. The motion's
    /// velocity field is carried along by the motion itself, so a point's velocity seen
    /// from its own part does not change along its path.
    fn velocity(&self, w: &Point3<f64>) -> Vector3<f64> {
        Vector3::new(-w.y * self.spin, w.x * self.spin, self.slide)
    }
}

/// The free turns of the follower over one period, at times `i / n`.
#[derive(Clone, Debug, PartialEq)]
pub struct FreeTurns {
    /// Largest free turn in the positive sense (counter-clockwise about +z), rad, ≤ cap.
    pub plus: Vec<f64>,
    /// Largest free turn in the negative sense, rad (a magnitude), ≤ cap.
    pub minus: Vec<f64>,
    /// Deepest vertex of one part inside the other at the design pose, mm, over the
    /// period (0 when they never overlap), and its time. Such vertices do not stop the
    /// follower: they would lock it where the meshes already overlap. The exact
    /// crossings ([`crossings`](super::crossings)) look only at the vertices that would
    /// otherwise stop it.
    pub overlap_mm: f64,
    /// Time of `overlap_mm`.
    pub overlap_t: f64,
    /// Distance queries made, the voxel centres' among them (a cost figure).
    pub queries: u64,
}

/// Which way the moving part of a test is turned relative to the fixed one, and which
/// part is which.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Side {
    /// Follower vertices against the driver's mesh.
    FollowerIntoDriver,
    /// Driver vertices against the follower's mesh.
    DriverIntoFollower,
}

/// Per-sample results of one (side, sense) sweep.
struct Sweep {
    free: Vec<f64>,
    overlap: (f64, f64),
    queries: u64,
}

/// How far the follower is free to move along each of `motions` (a [`Screw`] and the cap
/// on its parameter) both ways, at `n` times per period: one [`FreeTurns`] per motion, in
/// the screw's units (rad for a turn, mm for a slide). The overlap is the parts' at the
/// design pose (the same for every motion) and the queries are the whole run's, so both
/// are set on every result alike.
pub fn free_along(
    motion: &dyn PartMotion,
    driver: &Solid,
    follower: &Solid,
    n: usize,
    motions: &[(Screw, f64)],
) -> Vec<FreeTurns> {
    // Every sweep asks both parts' distance grids: made first, side by side, not by
    // whichever sweep asks first while the others wait.
    rayon::join(|| driver.prepare_bounds(), || follower.prepare_bounds());
    let jobs: Vec<(Side, Screw, f64)> = motions
        .iter()
        .flat_map(|&(screw, cap)| {
            [
                (Side::FollowerIntoDriver, screw, cap),
                (Side::FollowerIntoDriver, screw.reversed(), cap),
                (Side::DriverIntoFollower, screw, cap),
                (Side::DriverIntoFollower, screw.reversed(), cap),
            ]
        })
        .collect();
    let centres_before =
        driver.centres.load(Ordering::Relaxed) + follower.centres.load(Ordering::Relaxed);
    let sweeps: Vec<Sweep> = jobs
        .par_iter()
        .map(|&(side, screw, cap)| sweep(motion, driver, follower, side, screw, n, cap))
        .collect();
    let overlap = sweeps
        .iter()
        .map(|s| s.overlap)
        .fold((0.0, 0.0), |a, b| if b.0 > a.0 { b } else { a });
    let queries = sweeps.iter().map(|s| s.queries).sum::<u64>()
        + driver.centres.load(Ordering::Relaxed)
        + follower.centres.load(Ordering::Relaxed)
        - centres_before;
    sweeps
        .chunks(4)
        .map(|s| FreeTurns {
            plus: (0..n).map(|i| s[0].free[i].min(s[2].free[i])).collect(),
            minus: (0..n).map(|i| s[1].free[i].min(s[3].free[i])).collect(),
            overlap_mm: overlap.0,
            overlap_t: overlap.1,
            queries,
        })
        .collect()
}

/// One side and sense over the period, in time order so each cluster's last distance
/// bounds its next.
fn sweep(
    motion: &dyn PartMotion,
    driver: &Solid,
    follower: &Solid,
    side: Side,
    screw: Screw,
    n: usize,
    cap: f64,
) -> Sweep {
    let (moving, fixed) = match side {
        Side::FollowerIntoDriver => (follower, driver),
        Side::DriverIntoFollower => (driver, follower),
    };
    // The follower moving by +δ is, seen from the follower, the driver moving by −δ.
    let screw = match side {
        Side::FollowerIntoDriver => screw,
        Side::DriverIntoFollower => screw.reversed(),
    };
    let speed: Vec<f64> = moving
        .clusters
        .iter()
        .map(|c| match side {
            Side::FollowerIntoDriver => motion.follower_speed(&c.center),
            Side::DriverIntoFollower => motion.driver_speed(&c.center),
        })
        .collect();
    // How far each cluster's points can move per unit of the screw, from the bound on
    // their distance from the axis.
    let reach: Vec<f64> = moving
        .clusters
        .iter()
        .map(|c| {
            screw.lever(
                c.radius
                    + match side {
                        Side::FollowerIntoDriver => motion.follower_reach(&c.center),
                        Side::DriverIntoFollower => motion.driver_reach(&c.center),
                    },
            )
        })
        .collect();
    // Each cluster's last measured distance to the fixed part and when: with the speed
    // bound, a lower bound on its distance at any later time.
    let mut last = vec![(f64::NEG_INFINITY, 0.0f64); moving.clusters.len()];
    let mut free = Vec::with_capacity(n);
    let mut overlap = (0.0f64, 0.0f64);
    let mut queries = 0u64;
    let mut witness: Option<usize> = None;
    let mut previous = cap;
    for i in 0..n {
        let t = i as f64 / n as f64;
        let (to_r, r_to_fixed) = match side {
            Side::FollowerIntoDriver => (motion.follower(t), motion.driver(t).inverse()),
            Side::DriverIntoFollower => (motion.driver(t), motion.follower(t).inverse()),
        };
        let mut at = AtTime {
            moving,
            fixed,
            to_r: &to_r,
            r_to_fixed: &r_to_fixed,
            screw,
            t,
            speed: &speed,
            reach: &reach,
            last: &mut last,
            witness,
            queries: 0,
            overlap: (0.0, t),
        };
        // Free turns change little from one sample to the next: search first within
        // twice the last one, and the whole cap only when nothing touches within that.
        let limit = (2.0 * previous + cap * SEARCH_FLOOR).min(cap);
        let mut best = at.free_within(limit);
        if best >= limit && limit < cap {
            best = at.free_within(cap);
        }
        queries += at.queries;
        if at.overlap.0 > overlap.0 {
            overlap = at.overlap;
        }
        witness = at.witness;
        previous = best;
        free.push(best);
    }
    Sweep {
        free,
        overlap,
        queries,
    }
}

/// Smallest search limit, a fraction of the cap (0.5° of the default 10° cap): a free
/// motion near zero (parts nearly touching) still searches a useful span at the next
/// sample.
pub(crate) const SEARCH_FLOOR: f64 = 0.05;

/// One (side, sense) test at one time.
struct AtTime<'a> {
    moving: &'a Solid,
    fixed: &'a Solid,
    to_r: &'a Isometry3<f64>,
    r_to_fixed: &'a Isometry3<f64>,
    screw: Screw,
    t: f64,
    speed: &'a [f64],
    reach: &'a [f64],
    last: &'a mut [(f64, f64)],
    witness: Option<usize>,
    queries: u64,
    overlap: (f64, f64),
}

impl AtTime<'_> {
    /// Largest free turn up to `limit` (returns `limit` when nothing touches within it).
    fn free_within(&mut self, limit: f64) -> f64 {
        let moving = self.moving;
        // Clusters that may touch within the limit, nearest first, with the farthest any of
        // their vertices moves per unit of the screw now.
        let mut active: Vec<(f64, f64, f64, usize)> = Vec::new();
        for (ci, c) in moving.clusters.iter().enumerate() {
            let (d_last, t_last) = self.last[ci];
            let lower = d_last - self.speed[ci] * (self.t - t_last) - c.radius;
            if lower > self.reach[ci] * limit {
                continue;
            }
            let w = self.to_r * c.center;
            let r_max = self.screw.lever(w.coords.xy().norm() + c.radius);
            let q = self.r_to_fixed * w;
            // The grid's bound first; the mesh only for clusters it cannot rule out.
            let mut d = self.fixed.lower_bound(&q);
            let reach = c.radius + r_max * limit;
            let mut beyond = d > reach;
            if !beyond {
                self.queries += 1;
                match self.fixed.signed_within(&q, reach) {
                    Some(exact) => d = exact.max(0.0),
                    // Farther than the reach: the reach is the bound carried on.
                    None => (d, beyond) = (reach, true),
                }
            }
            self.last[ci] = (d, self.t);
            if !beyond {
                active.push((d - c.radius, r_max, d, ci));
            }
        }
        active.sort_by(|a, b| a.0.total_cmp(&b.0));
        let mut best = limit;
        let mut touch = None;
        // The vertex that touched first at the last sample most likely does again: its
        // turn, traced first, lets the bound below skip most of the others.
        if let Some(vi) = self.witness {
            self.try_vertex(vi, 0.0, &mut best, &mut touch);
        }
        for &(lower, r_max, d, ci) in &active {
            if lower > r_max * best {
                continue;
            }
            let c = &moving.clusters[ci];
            for vi in c.start..c.end {
                // The distance is 1-Lipschitz: the centre's bounds each vertex's.
                let bound = d - (moving.verts[vi] - c.center).norm();
                self.try_vertex(vi, bound, &mut best, &mut touch);
            }
        }
        self.witness = touch.or(self.witness);
        best
    }

    /// Trace vertex `vi`, whose distance to the fixed part is at least `bound`; lower
    /// `best` (and note the vertex) if it touches sooner.
    fn try_vertex(&mut self, vi: usize, bound: f64, best: &mut f64, touch: &mut Option<usize>) {
        let w = self.to_r * self.moving.verts[vi];
        let r = self.screw.lever(w.coords.xy().norm());
        if r < ON_AXIS_MM || bound > r * *best {
            return;
        }
        // The path's direction and the faces move together, so a vertex that trails at
        // the start trails along the whole path.
        let dir = self.screw.velocity(&w) / r;
        let dir_in_part = self.to_r.rotation.inverse_transform_vector(&dir);
        if self.moving.cones[vi].trails(&dir_in_part) {
            return;
        }
        if self.fixed.lower_bound(&(self.r_to_fixed * w)) > r * *best {
            return;
        }
        let (hit, q, deep) = trace(self.fixed, self.r_to_fixed, &w, r, self.screw, *best);
        self.queries += q;
        if let Some(depth) = deep {
            if depth > self.overlap.0 {
                self.overlap = (depth, self.t);
            }
            return;
        }
        if hit < *best {
            *best = hit;
            *touch = Some(vi);
        }
    }
}

/// Sphere-trace one vertex (at `w` in R, moving `r` mm per unit of `screw`) along the
/// screw against `fixed` (R → its frame by `r_to_fixed`), up to `limit` units. Returns the
/// parameter where it touches (or `limit`), the queries made, and the depth if it starts
/// inside the fixed part.
fn trace(
    fixed: &Solid,
    r_to_fixed: &Isometry3<f64>,
    w: &Point3<f64>,
    r: f64,
    screw: Screw,
    limit: f64,
) -> (f64, u64, Option<f64>) {
    let mut delta = 0.0;
    let mut queries = 0;
    for step in 0..MAX_STEPS {
        let p = r_to_fixed * (screw.at(delta) * w);
        // Far from the part the grid's bound is a safe step and costs no mesh query.
        let far = fixed.lower_bound(&p);
        if step > 0 && far > FAR_MM {
            delta += far / r;
            if delta >= limit {
                return (limit, queries, None);
            }
            continue;
        }
        // Nothing within the arc left: free up to the limit (a vertex deeper inside than
        // that is not seen as overlapping either; the build's check measures overlaps).
        queries += 1;
        let Some(d) = fixed.signed_within(&p, r * (limit - delta)) else {
            return (limit, queries, None);
        };
        if step == 0 && d < 0.0 {
            return (limit, queries, Some(-d));
        }
        if d < HIT_MM {
            return (delta, queries, None);
        }
        delta += d / r;
        if delta >= limit {
            return (limit, queries, None);
        }
    }
    (delta, queries, None)
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::geometry::primitive_meshes::cuboid;

    /// [`free_along`] for a turn alone: the free turns about R's z axis at `n` times per
    /// period, each capped at `cap` rad.
    pub(crate) fn free_turns(
        motion: &dyn PartMotion,
        driver: &Solid,
        follower: &Solid,
        n: usize,
        cap: f64,
    ) -> FreeTurns {
        free_along(motion, driver, follower, n, &[(Screw::TURN, cap)])
            .pop()
            .expect("one motion in, one out")
    }

    /// A fixed driver (identity pose) and a follower turning about z; speeds and reach
    /// from the boxes' sizes.
    pub(crate) struct Still;

    impl PartMotion for Still {
        fn follower(&self, _: f64) -> Isometry3<f64> {
            Isometry3::identity()
        }
        fn driver(&self, _: f64) -> Isometry3<f64> {
            Isometry3::identity()
        }
        fn follower_speed(&self, _: &Point3<f64>) -> f64 {
            0.0
        }
        fn driver_speed(&self, _: &Point3<f64>) -> f64 {
            0.0
        }
        fn follower_reach(&self, q: &Point3<f64>) -> f64 {
            q.coords.norm()
        }
        fn driver_reach(&self, p: &Point3<f64>) -> f64 {
            p.coords.norm()
        }
    }

    /// Guards the driver's exact distances without parry's hierarchy
    /// ([`Solid::signed_near`]): on a box (whose corners and edges test the pseudo-normals'
    /// weights), a coarse sphere and a torus, at 3 000 seeded points from deep inside to
    /// 3 mm out, at points on the box's edges' and corners' diagonals, and at points as far
    /// from two posts (the sign from one place, not a sum of the two), and at 500 points
    /// within 1 mm of a large fine torus (whose points read the clusters of the cells round
    /// them, not all), the value is parry's to 1e-9 mm, sign and all; a point that is not
    /// finite has none. A solid prepared with its queries deferred makes them when first
    /// asked, and they agree too.
    #[test]
    fn distances_from_the_clusters_are_parry_s() {
        use crate::geometry::primitive_meshes::{torus, uv_sphere};
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(9);
        let meshes = [
            cuboid([-4.0, -3.0, -2.0], [4.0, 3.0, 2.0]),
            uv_sphere([1.0, 0.5, 0.0], 5.0, 12, 8),
            torus([0.0, 0.0, 1.0], 6.0, 2.0, 24, 12),
        ];
        for mesh in &meshes {
            let solid = Solid::new(mesh, "test").unwrap();
            let deferred = Solid::with_query(mesh, "test", Query::WhenAsked).unwrap();
            let b = mesh.aabb();
            let mut points: Vec<Point3<f64>> = (0..1000)
                .map(|_| {
                    Point3::from(
                        [0, 1, 2].map(|k| rng.random_range(b.min[k] - 3.0..b.max[k] + 3.0)),
                    )
                })
                .collect();
            // Off the box's corners and edges along their diagonals, where the nearest
            // point is a corner or on an edge, outside and in.
            for s in [-0.3, 0.2, 1.0] {
                points.push(Point3::new(4.0 + s, 3.0 + s, 2.0 + s));
                points.push(Point3::new(4.0 + s, 3.0 + s, 0.5));
                points.push(Point3::new(-4.0 - s, 0.0, -2.0 - s));
            }
            for p in &points {
                let (want, got) = (solid.signed(p), deferred.signed_near(p));
                assert!(
                    (want - got).abs() < 1e-9,
                    "{p}: parry {want}, clusters {got}"
                );
            }
            assert!(
                deferred.tri.get().is_none(),
                "signed_near made parry's queries"
            );
            for p in &points[..50] {
                assert!((solid.signed(p) - deferred.signed(p)).abs() < 1e-9, "{p}");
            }
        }
        // A large fine torus: about 10 000 clusters, so a point near its surface reads the
        // clusters of the cells round it, not all of them.
        let ring = torus([0.0; 3], 200.0, 5.0, 1200, 60);
        let (solid, deferred) = (
            Solid::new(&ring, "ring").unwrap(),
            Solid::with_query(&ring, "ring", Query::WhenAsked).unwrap(),
        );
        assert!(
            deferred.clusters.len() > 10 * 7usize.pow(3),
            "{}",
            deferred.clusters.len()
        );
        for _ in 0..500 {
            let tau = std::f64::consts::TAU;
            let (u, v): (f64, f64) = (rng.random_range(0.0..tau), rng.random_range(0.0..tau));
            let r = 5.0 + rng.random_range(-1.0..1.0);
            let p = Point3::new(
                (200.0 + r * v.cos()) * u.cos(),
                (200.0 + r * v.cos()) * u.sin(),
                r * v.sin(),
            );
            let (want, got) = (solid.signed(&p), deferred.signed_near(&p));
            assert!(
                (want - got).abs() < 1e-9,
                "{p}: parry {want}, clusters {got}"
            );
        }
        // Midway between two posts, 2 mm from each face.
        let (posts, _) = bar_between_posts();
        let (solid, deferred) = (
            Solid::new(&posts, "posts").unwrap(),
            Solid::with_query(&posts, "posts", Query::WhenAsked).unwrap(),
        );
        for p in [[20.0, -0.5, -1.0], [12.0, -0.5, 0.0], [29.0, -0.5, 2.5]] {
            let p = Point3::from(p);
            assert_eq!(deferred.signed_near(&p), 2.0, "{p}");
            assert_eq!(solid.signed(&p), 2.0, "{p}");
        }
        assert!(deferred
            .signed_near(&Point3::new(f64::NAN, 0.0, 0.0))
            .is_nan());
        assert!(matches!(
            Solid::with_query(&Mesh::default(), "empty", Query::WhenAsked),
            Err(SolidError::Mesh { .. })
        ));
    }

    /// Guards the traced turn against a case with a closed form: a thin bar along +x
    /// (tip at 20 mm, faces at y = ±0.5) turning between two posts whose near faces are
    /// at y = +1.5 (beyond x = 10) and y = −2.5. Turning +δ, the bar's top corner at
    /// (20, 0.5) meets the upper post's face first: 20 sin δ + 0.5 cos δ = 1.5; turning
    /// −δ, its lower corner meets y = −2.5. The posts' own corners never lead, as they
    /// face the bar's flat sides.
    #[test]
    fn a_bar_between_two_posts_turns_to_the_closed_form_angle() {
        let (posts, bar) = bar_between_posts();
        let driver = Solid::new(&posts, "driver").unwrap();
        let follower = Solid::new(&bar, "follower").unwrap();
        let cap = 0.5;
        let f = free_turns(&Still, &driver, &follower, 4, cap);
        let [plus, minus] = bar_between_posts_turns();
        for i in 0..4 {
            assert!(
                (f.plus[i] - plus).abs() < 2.0 * HIT_MM / 20.0,
                "{}",
                f.plus[i]
            );
            assert!(
                (f.minus[i] - minus).abs() < 2.0 * HIT_MM / 20.0,
                "{}",
                f.minus[i]
            );
        }
        assert_eq!(f.overlap_mm, 0.0);
    }

    /// The thin bar of [`bar_between_posts`] between two wide plates whose faces are at
    /// z = 1.5 and z = −2.5, as (driver, follower) solids: the plates and the bar.
    pub(crate) fn bar_between_plates() -> (Solid, Solid) {
        let bar = cuboid([0.0, -0.5, -1.0], [20.0, 0.5, 1.0]);
        let plates = joined(&[
            cuboid([-30.0, -30.0, 1.5], [30.0, 30.0, 3.0]),
            cuboid([-30.0, -30.0, -4.0], [30.0, 30.0, -2.5]),
        ]);
        (
            Solid::new(&plates, "driver").unwrap(),
            Solid::new(&bar, "follower").unwrap(),
        )
    }

    /// The lines [`bar_between_plates`] is moved along, each capped at 3 units: the slide,
    /// and a screw of 0.02 rad and 0.8 mm per unit.
    pub(crate) const PLATE_LINES: [(Screw, f64); 2] = [
        (Screw::SLIDE, 3.0),
        (
            Screw {
                spin: 0.02,
                slide: 0.8,
            },
            3.0,
        ),
    ];

    /// The closed-form reaches of [`bar_between_plates`] along [`PLATE_LINES`], each
    /// [up, down]: the bar slides 0.5 mm up and 1.5 mm down; along the screw it meets the
    /// same faces after as many units as its 0.8 mm per unit takes there, since the
    /// plates cover every turn.
    pub(crate) const PLATE_REACHES: [[f64; 2]; 2] = [[0.5, 1.5], [0.5 / 0.8, 1.5 / 0.8]];

    /// Guards the slide and the screw against closed forms ([`bar_between_plates`] along
    /// [`PLATE_LINES`] to [`PLATE_REACHES`]), each within the trace's `HIT_MM`, which is
    /// HIT_MM / 0.8 units of the screw.
    #[test]
    fn a_bar_between_two_plates_slides_and_screws_to_the_closed_form() {
        let (driver, follower) = bar_between_plates();
        let f = free_along(&Still, &driver, &follower, 3, &PLATE_LINES);
        for (line, ([up, down], tol)) in PLATE_REACHES
            .into_iter()
            .zip([HIT_MM, HIT_MM / 0.8])
            .enumerate()
        {
            for i in 0..3 {
                let (plus, minus) = (f[line].plus[i], f[line].minus[i]);
                assert!((plus - up).abs() <= tol, "{plus}");
                assert!((minus - down).abs() <= tol, "{minus}");
            }
        }
        // A turn alone never meets the plates: the whole cap both ways.
        let t = free_turns(&Still, &driver, &follower, 3, 0.3);
        assert_eq!(t.plus, vec![0.3; 3]);
        assert_eq!(t.minus, vec![0.3; 3]);
    }

    /// Guards the cap and the driver-side test: a bar with nothing to hit one way turns the
    /// whole cap that way; a pin of the driver that sits in a notch-free path of the bar's
    /// far face is caught by the driver-vertex test even though no bar vertex enters it
    /// (the pin is narrower than the bar's face and between its corners).
    #[test]
    fn a_driver_pin_against_a_flat_face_stops_the_turn() {
        let (pin, bar) = pin_by_a_bar();
        let driver = Solid::new(&pin, "driver").unwrap();
        let follower = Solid::new(&bar, "follower").unwrap();
        let cap = 0.5;
        let f = free_turns(&Still, &driver, &follower, 2, cap);
        assert_eq!(f.minus[0], cap);
        let want = pin_by_a_bar_turn();
        assert!(
            (f.plus[0] - want).abs() < 2.0 * HIT_MM / 15.0,
            "{} vs {want}",
            f.plus[0]
        );
    }

    /// A thin bar along +x (tip at 20 mm, faces at y = ±0.5, z = ±1) and two posts whose
    /// near faces are at y = +1.5 (beyond x = 10) and y = −2.5: (posts, bar).
    pub(crate) fn bar_between_posts() -> (Mesh, Mesh) {
        let bar = cuboid([0.0, -0.5, -1.0], [20.0, 0.5, 1.0]);
        let posts = joined(&[
            cuboid([10.0, 1.5, -3.0], [30.0, 6.0, 3.0]),
            cuboid([10.0, -8.0, -3.0], [30.0, -2.5, 3.0]),
        ]);
        (posts, bar)
    }

    /// The bar's free turns between the posts, [positive, negative] sense, rad: turning +δ
    /// its top corner at (20, 0.5) meets the upper post's face when
    /// 20 sin δ + 0.5 cos δ = 1.5; turning −δ its lower corner meets y = −2.5.
    pub(crate) fn bar_between_posts_turns() -> [f64; 2] {
        // a sin δ + b cos δ = c, with R = √(a² + b²): δ = asin(c/R) − atan2(b, a).
        let solve = |a: f64, b: f64, c: f64| (c / a.hypot(b)).asin() - b.atan2(a);
        [solve(20.0, 0.5, 1.5), solve(20.0, 0.5, 2.5)]
    }

    /// A thin pin of the driver standing on y > 1, its tip 1 mm from the face y = 0.5 of a
    /// bar and between the bar's corners (at x = 15): (pin, bar).
    pub(crate) fn pin_by_a_bar() -> (Mesh, Mesh) {
        let bar = cuboid([0.0, -0.5, -5.0], [20.0, 0.5, 5.0]);
        let pin = cuboid([14.9, 1.5, -0.1], [15.1, 8.0, 0.1]);
        (pin, bar)
    }

    /// The bar's free turn in the positive sense against the pin, rad: a tip corner
    /// (x, 1.5) of the pin meets the face y = 0.5 of the turned bar when
    /// 1.5 cos δ − x sin δ = 0.5, and the corner at x = 15.1, with the longer lever,
    /// arrives first. As R cos(δ + φ) = 0.5.
    pub(crate) fn pin_by_a_bar_turn() -> f64 {
        let (r, phi) = (1.5f64.hypot(15.1), 15.1f64.atan2(1.5));
        (0.5 / r).acos() - phi
    }

    /// Two parts in motion: a driver turning about a vertical axis at (18, 12, 0) carrying
    /// two balls (r 1.5) on a 7.5 mm radius, and a follower swinging ±0.05 rad whose 18 mm
    /// arm along x ends in a ball (r 1.5). Each driver ball passes over the arm's end once
    /// per turn, its lowest point 4.5 mm above it, so they come within about 0.6 mm
    /// without touching.
    pub(crate) struct Swing;

    impl PartMotion for Swing {
        fn follower(&self, t: f64) -> Isometry3<f64> {
            let a = 0.05 * (std::f64::consts::TAU * t).sin();
            Isometry3::rotation(Vector3::z() * a)
        }
        fn driver(&self, t: f64) -> Isometry3<f64> {
            Isometry3::new(
                Vector3::new(18.0, 12.0, 0.0),
                Vector3::z() * std::f64::consts::TAU * t,
            )
        }
        // |ω_f|·|q| + 2π·(|q| + |axis|): the follower point's speed seen from the driver.
        fn follower_speed(&self, q: &Point3<f64>) -> f64 {
            0.05 * std::f64::consts::TAU * q.coords.norm()
                + std::f64::consts::TAU * (q.coords.norm() + 21.7)
        }
        fn driver_speed(&self, p: &Point3<f64>) -> f64 {
            let x = 21.7 + p.coords.norm();
            std::f64::consts::TAU * p.coords.norm() + 0.05 * std::f64::consts::TAU * x
        }
        fn follower_reach(&self, q: &Point3<f64>) -> f64 {
            q.coords.norm()
        }
        fn driver_reach(&self, p: &Point3<f64>) -> f64 {
            21.7 + p.coords.norm()
        }
    }

    /// Guards the normal cones: at a box's corner (three faces at right angles) a motion
    /// straight into the box trails, one along a face, or out of it, does not; on a fine
    /// sphere a vertex moving inwards trails and one moving along the surface does not.
    #[test]
    fn a_vertex_trails_only_when_every_face_looks_away_from_its_motion() {
        use crate::geometry::primitive_meshes::uv_sphere;
        let cube = cuboid([0.0, 0.0, 0.0], [1.0, 1.0, 1.0]);
        let cones = normal_cones(&cube);
        let corner = cube
            .vertices
            .iter()
            .position(|v| *v == [1.0, 1.0, 1.0])
            .unwrap();
        let c = cones[corner];
        assert!(c.trails(&-Vector3::new(1.0, 1.0, 1.0).normalize()));
        assert!(!c.trails(&-Vector3::x()));
        assert!(!c.trails(&Vector3::new(-1.0, -1.0, 0.2).normalize()));
        assert!(!c.trails(&Vector3::new(1.0, 1.0, 1.0).normalize()));
        let ball = uv_sphere([0.0, 0.0, 0.0], 2.0, 48, 24);
        let cones = normal_cones(&ball);
        let (i, v) = ball
            .vertices
            .iter()
            .enumerate()
            .find(|(_, v)| v[2].abs() < 0.3 && v[0] > 1.0)
            .unwrap();
        let out = Vector3::from(*v).normalize();
        assert!(cones[i].trails(&-out));
        assert!(!cones[i].trails(&out.cross(&Vector3::z()).normalize()));
    }

    pub(crate) fn joined(parts: &[Mesh]) -> Mesh {
        let mut out = Mesh::default();
        for m in parts {
            let off = out.vertices.len() as u32;
            out.vertices.extend(&m.vertices);
            out.triangles
                .extend(m.triangles.iter().map(|t| t.map(|i| i + off)));
        }
        out
    }

    /// Guards the shortcuts (clusters skipped by the speed bound, the grid's lower bound,
    /// the search limit carried from the last sample, the last touching vertex first): on
    /// parts in motion, the free turns equal those of a plain trace of every vertex of both
    /// parts with mesh queries only, within the trace's own tolerance.
    #[test]
    fn the_shortcuts_find_the_same_free_turns_as_tracing_every_vertex() {
        use crate::geometry::primitive_meshes::uv_sphere;
        let follower_mesh = joined(&[
            cuboid([0.0, -0.6, -0.6], [18.0, 0.6, 0.6]),
            uv_sphere([18.0, 0.0, 0.0], 1.5, 48, 24),
        ]);
        let driver_mesh = joined(&[
            uv_sphere([-7.5, 0.0, 0.0], 1.5, 48, 24),
            uv_sphere([0.0, 7.5, 0.0], 1.5, 48, 24),
        ]);
        let driver = Solid::new(&driver_mesh, "driver").unwrap();
        let follower = Solid::new(&follower_mesh, "follower").unwrap();
        let (n, cap) = (720, 0.3);
        let fast = free_turns(&Swing, &driver, &follower, n, cap);
        assert_eq!(
            fast.overlap_mm, 0.0,
            "the parts never overlap at the design pose"
        );
        // The plain trace: every vertex, exact queries, the whole cap.
        let plain = |moving: &Solid, fixed: &Solid, driver_moves: bool, sense: f64, t: f64| {
            let (to_r, r_to_fixed) = if driver_moves {
                (Swing.driver(t), Swing.follower(t).inverse())
            } else {
                (Swing.follower(t), Swing.driver(t).inverse())
            };
            let turn_sense = if driver_moves { -sense } else { sense };
            let mut best = cap;
            for v in &moving.verts {
                let w = to_r * v;
                let r = w.coords.xy().norm();
                let mut delta = 0.0;
                while delta < best {
                    let turn =
                        UnitQuaternion::from_axis_angle(&Vector3::z_axis(), turn_sense * delta);
                    let d = fixed.signed(&(r_to_fixed * (turn * w)));
                    if d < HIT_MM {
                        best = best.min(delta);
                        break;
                    }
                    delta += d / r;
                }
            }
            best
        };
        let mut touching = 0;
        for i in 0..n {
            let t = i as f64 / n as f64;
            for (sense, got) in [(1.0, fast.plus[i]), (-1.0, fast.minus[i])] {
                let want = plain(&follower, &driver, false, sense, t)
                    .min(plain(&driver, &follower, true, sense, t));
                assert!(
                    (got - want).abs() < 2.0 * HIT_MM / 5.0,
                    "t = {t}, sense {sense}: {got} vs {want}"
                );
                if want < cap {
                    touching += 1;
                }
            }
        }
        // The case exercises contacts, not only free turns.
        assert!(touching > 20, "{touching}");
        assert!(touching < 2 * n - 20, "{touching}");
    }
}
