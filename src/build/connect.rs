//! Joining each part into one piece through space the other part never enters.
//!
//! Owns the planning of struts and posts on voxel grids of free space: the other part's
//! (and the support's) swept volume, seen from this part's frame ([`swept_field`]), says
//! how far each voxel is from anything that will pass there during the period; a strut of
//! radius [`STRUT_RADIUS_MM`] may run where that clearance is at least its radius plus
//! [`STRUT_MARGIN_MM`]. Plates (follower) and bands (driver) are joined one by one, nearest
//! first, to what is already joined, starting from the hub, by the cheapest path (A*,
//! `geometry::voxel`) straightened into a few segments, the paper's "thickened polyline"
//! (§5.3) found by search instead of by hand. For 3R it also plans the support's post to
//! the ball's cup, and places the IMU pad and end-effector where the driver never passes.
//! It does not shape the final parts (`parts`).

use crate::geometry::mesh::Aabb;
use crate::geometry::sdf::{arr, Sdf, ThickPolyline, Vec3};
use crate::geometry::voxel::{shortest_path, DistanceField, PathQuery, VoxelGrid};

use super::dims::*;
use super::kinematics::Frame;
use super::kinematics::Kinematics;
use super::swept::{swept_bounds, swept_field, Balls};
use super::BuildError;

/// Extra room around a part's material in its planning grid, mm.
const GRID_MARGIN_MM: f64 = 25.0;
/// Samples per period for grid bounds.
const BOUNDS_SAMPLES: usize = 360;
/// Clearance at which a path step costs no more than its length: twice the minimum.
const COMFORT_FACTOR: f64 = 2.0;

/// A planning grid around `bodies` seen from `frame` (static bodies of that frame only).
pub fn grid_around(kin: &Kinematics, bodies: &[&Balls], frame: Frame) -> VoxelGrid {
    let mut b = Aabb::EMPTY;
    for body in bodies {
        if body.frame == frame {
            b = b.union(&swept_bounds(kin, body, frame, BOUNDS_SAMPLES));
        }
    }
    VoxelGrid::covering(b.inflate(GRID_MARGIN_MM), PLAN_VOXEL_MM)
}

/// Clearance field in `frame` from the union of `obstacles` (any frames) over the period.
pub fn clearance(
    kin: &Kinematics,
    obstacles: &[Balls],
    frame: Frame,
    grid: VoxelGrid,
) -> DistanceField {
    swept_field(kin, obstacles, frame, grid)
}

/// Clearance field in `frame` from `body` alone over the period, on a grid of its own that
/// covers where the body goes grown by `reach`: beyond that grid it says infinity, true of
/// every value up to `reach` (the body's sweep is farther). Values below `reach` are
/// bounded as [`clearance`]'s are. On the planning grid of the part it is seen from, one
/// rim's field took as much memory as the whole part's, while a rim's sweep fills a band of
/// heights of it.
pub fn clearance_within(kin: &Kinematics, body: &Balls, frame: Frame, reach: f64) -> DistanceField {
    let bounds = swept_bounds(kin, body, frame, BOUNDS_SAMPLES).inflate(reach + PLAN_VOXEL_MM);
    swept_field(
        kin,
        std::slice::from_ref(body),
        frame,
        VoxelGrid::covering(bounds, PLAN_VOXEL_MM),
    )
}

/// What is joined so far: a boolean per voxel.
pub struct Joined {
    grid: VoxelGrid,
    set: Vec<bool>,
}

impl Joined {
    /// Nothing joined.
    pub fn new(grid: VoxelGrid) -> Joined {
        Joined {
            grid,
            set: vec![false; grid.len()],
        }
    }

    /// Mark the voxels within `radius` of `centers`.
    pub fn mark_balls(&mut self, centers: &[Vec3], radius: f64) {
        let g = self.grid;
        let r = (radius / g.h).ceil() as i64;
        for c in centers {
            let Some(v) = g.voxel_of(*c).or_else(|| nearest_inside(&g, *c)) else {
                continue;
            };
            for dk in -r..=r {
                for dj in -r..=r {
                    for di in -r..=r {
                        let w = [v[0] as i64 + di, v[1] as i64 + dj, v[2] as i64 + dk];
                        if (0..3).any(|k| w[k] < 0 || w[k] >= g.n[k] as i64) {
                            continue;
                        }
                        let w = [w[0] as usize, w[1] as usize, w[2] as usize];
                        if (g.center(w) - c).norm() <= radius {
                            self.set[g.index(w)] = true;
                        }
                    }
                }
            }
        }
    }

    /// Mark a solid's voxels (centre inside).
    pub fn mark_solid(&mut self, s: &dyn Sdf) {
        let g = self.grid;
        let b = s.bounds();
        let lo = g.voxel_of(Vec3::new(b.min[0], b.min[1], b.min[2]));
        let hi = g.voxel_of(Vec3::new(b.max[0], b.max[1], b.max[2]));
        let (lo, hi) = match (lo, hi) {
            (Some(l), Some(h)) => (l, h),
            _ => ([0, 0, 0], [g.n[0] - 1, g.n[1] - 1, g.n[2] - 1]),
        };
        for k in lo[2]..=hi[2] {
            for j in lo[1]..=hi[1] {
                for i in lo[0]..=hi[0] {
                    if s.dist(g.center([i, j, k])) <= 0.0 {
                        self.set[g.index([i, j, k])] = true;
                    }
                }
            }
        }
    }

    /// Whether voxel `v` is joined.
    pub fn contains(&self, v: [usize; 3]) -> bool {
        self.set[self.grid.index(v)]
    }
}

fn nearest_inside(g: &VoxelGrid, p: Vec3) -> Option<[usize; 3]> {
    let q = (p - g.origin) / g.h;
    let mut v = [0usize; 3];
    for k in 0..3 {
        let r = q[k].round();
        if r < -2.0 || r > g.n[k] as f64 + 1.0 {
            return None;
        }
        v[k] = (r.max(0.0) as usize).min(g.n[k] - 1);
    }
    Some(v)
}

/// Where a strut may start: a free point `at` (clear enough for the strut), and the point
/// `root` inside the piece it joins that the strut's first segment reaches back to.
#[derive(Clone, Copy, Debug)]
pub struct Start {
    /// Inside the piece (rim, band, hub …).
    pub root: Vec3,
    /// In free space.
    pub at: Vec3,
}

/// Plan one strut from one of `starts` to what is `joined`; an error naming `what` when
/// none is free or no free path exists.
pub fn strut(
    field: &DistanceField,
    joined: &Joined,
    starts: &[Start],
    toward: Vec3,
    what: &str,
) -> Result<ThickPolyline, BuildError> {
    let need = STRUT_RADIUS_MM + STRUT_MARGIN_MM;
    let mut sources: Vec<[usize; 3]> = Vec::new();
    let mut root_of: std::collections::HashMap<[usize; 3], Vec3> = Default::default();
    for st in starts {
        if let Some(v) = field.grid.voxel_of(st.at) {
            if field.at(v) >= need {
                sources.push(v);
                root_of.entry(v).or_insert(st.root);
            }
        }
    }
    if sources.is_empty() {
        return Err(BuildError::NoRoom {
            what: what.to_string(),
            detail: format!(
                "no point of it is {need:.1} mm clear of the other part's swept volume, so no strut can start there"
            ),
        });
    }
    // The heuristic aims at the hub (a guide only: any joined voxel ends the search).
    let is_goal = |v: [usize; 3]| joined.contains(v);
    let heuristic = |p: Vec3| 0.5 * (p - toward).norm();
    let q = PathQuery {
        clearance: field,
        min_clearance: need,
        comfortable: need * COMFORT_FACTOR,
        sources: &sources,
        is_goal: &is_goal,
        heuristic: &heuristic,
    };
    let path = shortest_path(&q).ok_or_else(|| BuildError::NoRoom {
        what: what.to_string(),
        detail: format!(
            "no path {need:.1} mm clear of the other part's swept volume joins it to the rest of its part"
        ),
    })?;
    let first = field
        .grid
        .voxel_of(path[0])
        .and_then(|v| root_of.get(&v).copied());
    let mut points = Vec::with_capacity(path.len() + 1);
    points.extend(first);
    points.extend(path);
    Ok(ThickPolyline {
        points,
        radius: STRUT_RADIUS_MM,
    })
}

/// What the rays leaving a piece found: the starts, and for a piece without any, why.
#[derive(Clone, Debug, Default)]
pub struct RayStarts {
    /// Starts found (at most one per ray).
    pub starts: Vec<Start>,
    /// Rays tried.
    pub rays: usize,
    /// Where each ray that came within the root clearance of the other part's functional
    /// surfaces before it found free space was stopped (for saying what stopped it).
    pub blocked_at: Vec<Vec3>,
    /// How far the rays went, mm.
    pub reach: f64,
    /// The root clearance asked, mm.
    pub root_clearance: f64,
}

impl RayStarts {
    /// Why no strut can start from the piece, for [`BuildError::NoRoom`]: how many rays ran
    /// into the other part's functional surfaces and how many found no free point.
    pub fn none_detail(&self) -> String {
        let need = STRUT_RADIUS_MM + STRUT_MARGIN_MM;
        let stopped = self.blocked_at.len();
        let unreached = self.rays - stopped - self.starts.len();
        let (reach, clear) = (self.reach, self.root_clearance);
        let verb =
            |n: usize, one: &'static str, many: &'static str| if n == 1 { one } else { many };
        let blocked = |n| {
            format!(
                "{} within {clear:.1} mm of the other part's moving contact surfaces",
                verb(n, "comes", "come")
            )
        };
        let unreached_text = |n| {
            format!(
                "{} no point {need:.1} mm clear of the other part's swept volume within {reach:.0} mm",
                verb(n, "reaches", "reach")
            )
        };
        let what = match (stopped, unreached) {
            (0, _) => format!(
                "none of the {} rays leaving it reach a point {need:.1} mm clear of the other \
                 part's swept volume within {reach:.0} mm",
                self.rays
            ),
            (b, 0) => format!("all {} rays leaving it {}", self.rays, blocked(b)),
            (b, u) => format!(
                "of the {} rays leaving it, {b} {} and {u} {}",
                self.rays,
                blocked(b),
                unreached_text(u)
            ),
        };
        format!("{what}, so no strut can start there")
    }
}

/// Where [`ray_starts`] tests a ray between its root and the first millimetre (synthesis
/// tests the same points).
pub use crate::synth::undercut::ROOT_STEP_MM;

/// Starts along rays leaving a piece: from each `(root, dir)`, the first point at distance
/// s = 1, 2, … up to `reach` mm whose coarse clearance in `field` suffices, provided
/// `exact` (the exact clearance from the other part's functional surfaces) stays at least
/// `root_clearance` at every point tested up to there. With `from_root`, the root itself
/// and the point [`ROOT_STEP_MM`] out are tested too: a strut that is trimmed by that
/// clearance (a follower strut rooted by its core) keeps nothing where it is low, and a
/// strut cut off at its root joins nothing.
pub fn ray_starts(
    rays: &[(Vec3, Vec3)],
    field: &DistanceField,
    exact: &(dyn Fn(Vec3) -> f64 + Sync),
    root_clearance: f64,
    reach: f64,
    from_root: bool,
) -> RayStarts {
    use rayon::prelude::*;
    let need = STRUT_RADIUS_MM + STRUT_MARGIN_MM;
    // Per ray: Ok(start), Err(Some(where)) when blocked, Err(None) when out of reach.
    let found: Vec<Result<Start, Option<Vec3>>> = rays
        .par_iter()
        .map(|&(root, dir)| {
            if from_root {
                for s in [0.0, ROOT_STEP_MM] {
                    let p = root + dir * s;
                    if exact(p) < root_clearance {
                        return Err(Some(p));
                    }
                }
            }
            let mut s = 1.0;
            while s <= reach {
                let p = root + dir * s;
                if exact(p) < root_clearance {
                    return Err(Some(p));
                }
                if field.sample(p) >= need {
                    return Ok(Start { root, at: p });
                }
                s += 1.0;
            }
            Err(None)
        })
        .collect();
    let blocked_at: Vec<Vec3> = found
        .iter()
        .filter_map(|f| f.as_ref().err().copied().flatten())
        .collect();
    RayStarts {
        rays: rays.len(),
        blocked_at,
        starts: found.into_iter().filter_map(Result::ok).collect(),
        reach,
        root_clearance,
    }
}

/// Points along a polyline, every `step` mm, for covers and marking.
pub fn polyline_points(p: &ThickPolyline, step: f64) -> Vec<Vec3> {
    let mut out = vec![p.points[0]];
    for w in p.points.windows(2) {
        let n = ((w[1] - w[0]).norm() / step).ceil().max(1.0) as usize;
        for i in 1..=n {
            out.push(w[0] + (w[1] - w[0]) * (i as f64 / n as f64));
        }
    }
    out
}

/// A ball cover of a strut.
pub fn strut_cover(p: &ThickPolyline, frame: Frame) -> Balls {
    Balls {
        frame,
        centers: polyline_points(p, 0.5 * p.radius),
        radius: p.radius * 1.05,
    }
}

/// The first free spot along `dir` from the origin, at least `from` mm out, whose
/// clearance is at least `need`: where a pad of that radius fits.
pub fn free_spot(field: &DistanceField, dir: Vec3, from: f64, to: f64, need: f64) -> Option<Vec3> {
    let d = dir.normalize();
    let mut s = from;
    while s <= to {
        let p = d * s;
        if field.sample(p) >= need {
            return Some(p);
        }
        s += 0.5 * field.grid.h;
    }
    None
}

/// Convert a list of points into `[f64; 3]` (for reports).
pub fn points_mm(p: &[Vec3]) -> Vec<[f64; 3]> {
    p.iter().map(|v| arr(*v)).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn starts(rays: usize, blocked: usize) -> RayStarts {
        RayStarts {
            starts: Vec::new(),
            rays,
            blocked_at: vec![Vec3::zeros(); blocked],
            reach: 12.0,
            root_clearance: 2.5,
        }
    }

    /// Guards `from_root`: with an obstacle 1.7 mm behind the root and free space all
    /// round, a ray asked to keep 1.9 mm from its root on is blocked at the root, and one
    /// asked to keep it from 1 mm out starts there (the first point tested).
    #[test]
    fn a_trimmed_strut_is_blocked_at_its_root() {
        let grid = VoxelGrid::covering(Aabb::new([-2.0; 3], [2.0; 3]), 1.0);
        let field = DistanceField {
            values: vec![100.0; grid.len()],
            grid,
            outside: 100.0,
        };
        let obstacle = Vec3::new(-1.7, 0.0, 0.0);
        let exact = |p: Vec3| (p - obstacle).norm();
        let rays = [(Vec3::zeros(), Vec3::new(1.0, 0.0, 0.0))];
        let from_one = ray_starts(&rays, &field, &exact, 1.9, 12.0, false);
        assert_eq!(from_one.starts.len(), 1);
        assert_eq!(from_one.starts[0].at, Vec3::new(1.0, 0.0, 0.0));
        let from_root = ray_starts(&rays, &field, &exact, 1.9, 12.0, true);
        assert!(from_root.starts.is_empty());
        assert_eq!(from_root.blocked_at, vec![Vec3::zeros()]);
    }

    /// Guards the three wordings of why no strut can start from a piece, whole: every ray
    /// blocked by the other part's contact surfaces, none blocked, and a mix.
    #[test]
    fn a_piece_without_starts_says_what_stopped_its_rays() {
        assert_eq!(
            starts(180, 180).none_detail(),
            "all 180 rays leaving it come within 2.5 mm of the other part's moving contact \
             surfaces, so no strut can start there"
        );
        assert_eq!(
            starts(90, 0).none_detail(),
            "none of the 90 rays leaving it reach a point 3.4 mm clear of the other part's \
             swept volume within 12 mm, so no strut can start there"
        );
        assert_eq!(
            starts(90, 30).none_detail(),
            "of the 90 rays leaving it, 30 come within 2.5 mm of the other part's moving \
             contact surfaces and 60 reach no point 3.4 mm clear of the other part's swept \
             volume within 12 mm, so no strut can start there"
        );
    }
}
