//! The checks the built meshes must pass, measured on the meshes themselves.
//!
//! Owns [`run`] and [`CheckFigures`]:
//! - **interference over the period**: at [`CHECK_TIMES`] times, every vertex of each part
//!   placed by the target motion is tested against the other parts' meshes (follower ↔
//!   driver, both against the support); the worst penetration depth and its time are kept;
//! - **contact gaps**: at every sample time of every curve pair, the design contact point's
//!   signed distance to the driver mesh (c¹, driver frame) plus its distance to the follower
//!   mesh (c², follower frame): the play the printed pair has at that contact, which should
//!   be the clearance.
//!
//! Distances come from `parry3d-f64`'s triangle-mesh queries (BVH, inside/outside by
//! pseudo-normals), independent of the implicit solids the meshes were made from. A coarse
//! occupancy grid per part skips vertices far outside it. It does not build anything.

use nalgebra::Point3;
use parry3d_f64::math::Vector as PVec;
use parry3d_f64::query::PointQuery;
use parry3d_f64::shape::{TriMesh, TriMeshFlags};
use rayon::prelude::*;

use crate::geometry::mesh::Mesh;
use crate::geometry::sdf::Vec3;
use crate::geometry::voxel::{distance_transform, VoxelGrid};
use crate::synth::mechanism::Mechanism;

use super::parts::Design;
use super::swept::{transform, Frame};

/// Times per period of the interference check. 720: twice the 360, so a part moves
/// by less than 1.3 mm between checks at the examples' fastest points.
pub const CHECK_TIMES: usize = 720;
/// Penetration accepted between parts, mm: the meshes' own error (≤ 0.05 mm on curved
/// surfaces at the default cell) and nothing more.
pub const PENETRATION_TOL_MM: f64 = 0.05;
/// Accepted deviation of a design contact's gap from the clearance, mm: twice the mesh
/// error of the two surfaces that meet there.
pub const GAP_TOL_MM: f64 = 0.1;
/// Voxel of the occupancy grids that skip far vertices, mm.
const OCCUPANCY_VOXEL_MM: f64 = 1.0;
/// Vertices nearer than this to a part's surface (by the occupancy grid) are measured
/// exactly, mm.
const NEAR_MM: f64 = 2.0;

/// The worst contact gaps of one curve pair over its samples.
#[derive(Clone, Debug, PartialEq)]
pub struct PairGap {
    /// Curve pair (1-based, as in reports).
    pub pair: usize,
    /// Smallest gap, mm.
    pub min_mm: f64,
    /// Largest gap, mm.
    pub max_mm: f64,
    /// Mean gap, mm.
    pub mean_mm: f64,
    /// Time of the gap farthest from the clearance.
    pub worst_t: f64,
}

/// One part entering another.
#[derive(Clone, Debug, PartialEq)]
pub struct Penetration {
    /// "follower into driver", ...
    pub what: String,
    /// Deepest vertex, mm (0 when none is inside).
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
}

impl CheckFigures {
    /// The deepest penetration of all.
    pub fn worst_penetration(&self) -> Option<&Penetration> {
        self.penetrations
            .iter()
            .max_by(|a, b| a.depth_mm.total_cmp(&b.depth_mm))
    }

    /// The pair whose gap strays farthest from the clearance, and by how much (mm).
    pub fn worst_gap(&self) -> Option<(&PairGap, f64)> {
        self.gaps
            .iter()
            .map(|g| {
                let d = (g.min_mm - self.clearance_mm)
                    .abs()
                    .max((g.max_mm - self.clearance_mm).abs());
                (g, d)
            })
            .max_by(|a, b| a.1.total_cmp(&b.1))
    }

    /// Why the check fails, if it does.
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
        if let Some((g, d)) = self.worst_gap() {
            if d > GAP_TOL_MM {
                why.push(format!(
                    "the gap at curve pair {}'s contact ranges {:.3}–{:.3} mm (worst at t = {:.4}), not {:.2} ± {GAP_TOL_MM} mm",
                    g.pair, g.min_mm, g.max_mm, g.worst_t, self.clearance_mm
                ));
            }
        }
        (!why.is_empty()).then(|| why.join("; "))
    }
}

/// A mesh ready for queries: parry's BVH with pseudo-normals and a coarse occupancy grid
/// (0 far outside, 1 near the surface, 2 inside).
struct Queryable {
    tri: TriMesh,
    grid: VoxelGrid,
    occ: Vec<u8>,
}

impl Queryable {
    fn new(m: &Mesh) -> Queryable {
        let verts: Vec<PVec> = m
            .vertices
            .iter()
            .map(|v| PVec::new(v[0], v[1], v[2]))
            .collect();
        let tri = TriMesh::with_flags(verts, m.triangles.clone(), TriMeshFlags::ORIENTED)
            .expect("a checked, non-empty mesh");
        let b = m.aabb().inflate(NEAR_MM + 2.0 * OCCUPANCY_VOXEL_MM);
        let grid = VoxelGrid::covering(b, OCCUPANCY_VOXEL_MM);
        // Near: within NEAR_MM of a vertex (vertices are < 1 mm apart on these meshes, so
        // every surface point is within half that of one).
        let mut marks = vec![false; grid.len()];
        for v in &m.vertices {
            if let Some(i) = grid.voxel_of(Vec3::new(v[0], v[1], v[2])) {
                marks[grid.index(i)] = true;
            }
        }
        let d = distance_transform(&grid, &marks);
        let mut occ: Vec<u8> = d
            .iter()
            .map(|&x| u8::from((x as f64) <= NEAR_MM + grid.h))
            .collect();
        // Inside: parity along z of each voxel column's centre.
        let mut columns: Vec<Vec<f64>> = vec![Vec::new(); grid.n[0] * grid.n[1]];
        for i in 0..m.triangles.len() {
            let [a, b, c] = m.corners(i);
            let (xmin, xmax) = (a[0].min(b[0]).min(c[0]), a[0].max(b[0]).max(c[0]));
            let (ymin, ymax) = (a[1].min(b[1]).min(c[1]), a[1].max(b[1]).max(c[1]));
            let i0 = ((xmin - grid.origin.x) / grid.h).ceil().max(0.0) as usize;
            let i1 = (((xmax - grid.origin.x) / grid.h).floor() as usize).min(grid.n[0] - 1);
            let j0 = ((ymin - grid.origin.y) / grid.h).ceil().max(0.0) as usize;
            let j1 = (((ymax - grid.origin.y) / grid.h).floor() as usize).min(grid.n[1] - 1);
            for j in j0..=j1 {
                for ii in i0..=i1 {
                    let (x, y) = (
                        grid.origin.x + ii as f64 * grid.h,
                        grid.origin.y + j as f64 * grid.h,
                    );
                    // Barycentric coordinates in the xy projection (half-open edges).
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
        Queryable { tri, grid, occ }
    }

    /// Signed distance (negative inside) if `p` may be inside or near, else `None`.
    fn signed_if_near(&self, p: Vec3) -> Option<f64> {
        let v = self.grid.voxel_of(p)?;
        if self.occ[self.grid.index(v)] == 0 {
            return None;
        }
        Some(self.signed(p))
    }

    fn signed(&self, p: Vec3) -> f64 {
        let pr = self
            .tri
            .project_local_point(PVec::new(p.x, p.y, p.z), false);
        let d =
            ((pr.point.x - p.x).powi(2) + (pr.point.y - p.y).powi(2) + (pr.point.z - p.z).powi(2))
                .sqrt();
        if pr.is_inside {
            -d
        } else {
            d
        }
    }
}

/// Deepest vertex of `moving` (frame `from`) inside `fixed` (frame `into`) over the period.
fn penetration(
    design: &Design,
    moving: &Mesh,
    from: Frame,
    fixed: &Queryable,
    into: Frame,
    what: &str,
) -> Penetration {
    let kin = &design.kin;
    let verts: Vec<Point3<f64>> = moving
        .vertices
        .iter()
        .map(|v| Point3::new(v[0], v[1], v[2]))
        .collect();
    let times = if from == into { 1 } else { CHECK_TIMES };
    let worst = (0..times)
        .into_par_iter()
        .map(|j| {
            let t = j as f64 / times as f64;
            let m = transform(kin, from, into, t);
            let mut deepest = 0.0f64;
            for v in &verts {
                let p = (m * v).coords;
                if let Some(d) = fixed.signed_if_near(p) {
                    deepest = deepest.max(-d);
                }
            }
            (deepest, t)
        })
        .reduce(|| (0.0, 0.0), |a, b| if b.0 > a.0 { b } else { a });
    Penetration {
        what: what.to_string(),
        depth_mm: worst.0,
        t: worst.1,
    }
}

/// Run every check on the meshes of `design` (driver, follower, support in their frames).
pub fn run(
    design: &Design,
    mech: &Mechanism,
    driver: &Mesh,
    follower: &Mesh,
    support: &Mesh,
) -> CheckFigures {
    let (qd, qf, qs) = (
        Queryable::new(driver),
        Queryable::new(follower),
        Queryable::new(support),
    );
    let penetrations = vec![
        penetration(
            design,
            follower,
            Frame::Follower,
            &qd,
            Frame::Driver,
            "follower into driver",
        ),
        penetration(
            design,
            driver,
            Frame::Driver,
            &qf,
            Frame::Follower,
            "driver into follower",
        ),
        penetration(
            design,
            follower,
            Frame::Follower,
            &qs,
            Frame::Reference,
            "follower into support",
        ),
        penetration(
            design,
            driver,
            Frame::Driver,
            &qs,
            Frame::Reference,
            "driver into support",
        ),
    ];
    let s = design.kin.scale_mm();
    let gaps = mech
        .curve_pairs
        .iter()
        .enumerate()
        .filter(|(k, _)| Some(*k) != design.without_pair)
        .map(|(k, cp)| {
            let n = cp.samples.c1.len();
            let g: Vec<f64> = (0..n)
                .into_par_iter()
                .map(|i| {
                    let c1 = cp.samples.c1[i];
                    let c2 = cp.samples.c2[i];
                    qd.signed(Vec3::new(c1[0], c1[1], c1[2]) * s)
                        + qf.signed(Vec3::new(c2[0], c2[1], c2[2]) * s)
                })
                .collect();
            let worst = (0..n)
                .max_by(|&a, &b| {
                    (g[a] - design.clearance)
                        .abs()
                        .total_cmp(&(g[b] - design.clearance).abs())
                })
                .unwrap_or(0);
            PairGap {
                pair: k + 1,
                min_mm: g.iter().copied().fold(f64::INFINITY, f64::min),
                max_mm: g.iter().copied().fold(f64::NEG_INFINITY, f64::max),
                mean_mm: g.iter().sum::<f64>() / n as f64,
                worst_t: worst as f64 / n as f64,
            }
        })
        .collect();
    CheckFigures {
        times: CHECK_TIMES,
        clearance_mm: design.clearance,
        penetrations,
        gaps,
    }
}
