//! Swept volumes: where one part goes, over a period, as seen from another.
//!
//! Owns the two ways parts are swept here:
//! - [`swept_field`]: a coarse field on a voxel grid, a lower bound of the distance to the
//!   union over time of a body covered by balls. Each ball centre is moved through the
//!   period in steps short enough (half a voxel) that its trace has no gaps, its voxels are
//!   marked, and an exact distance transform turns the marks into distances; the bound
//!   subtracts the ball radius, half a step and the voxel rounding. Planning (free space for
//!   struts and webs) and the quick rejection of the exact carve use it.
//! - [`ExactSweep`]: the exact minimum over time of a solid's distance at a point, by branch
//!   and bound over time intervals (the distance changes no faster than the point moves,
//!   [`Kinematics`] bounds that speed) followed by a local refinement; the driver's groove
//!   is carved with it, so the groove is the true envelope of the follower's rims, without
//!   the scallops a finite number of boolean subtractions would leave.
//!
//! It does not decide what is swept against what (`build::parts` does).

use nalgebra::Isometry3;
use rayon::prelude::*;

use crate::geometry::mesh::Aabb;
use crate::geometry::sdf::{Sdf, Vec3};
use crate::geometry::voxel::{distance_transform, DistanceField, VoxelGrid};

use super::kinematics::Kinematics;

/// A frame a body lives in or a grid is laid out in.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Frame {
    /// The driver's frame (turns with the driver).
    Driver,
    /// The follower's frame.
    Follower,
    /// The reference frame (the support's).
    Reference,
}

/// A body given as balls of one radius in its frame (a conservative cover of a part).
#[derive(Clone, Debug)]
pub struct Balls {
    /// The frame the centres are in.
    pub frame: Frame,
    /// Centres, mm.
    pub centers: Vec<Vec3>,
    /// Radius, mm.
    pub radius: f64,
}

/// Map from frame `from` to frame `to` at time `t`.
pub fn transform(kin: &Kinematics, from: Frame, to: Frame, t: f64) -> Isometry3<f64> {
    let pose = |f: Frame| match f {
        Frame::Driver => kin.driver(t),
        Frame::Follower => kin.follower(t),
        Frame::Reference => Isometry3::identity(),
    };
    pose(to).inverse() * pose(from)
}

/// Bound on the speed (mm per period) of the point `p` of frame `from` seen from `to`.
pub fn speed(kin: &Kinematics, from: Frame, to: Frame, p: Vec3) -> f64 {
    match (from, to) {
        (a, b) if a == b => 0.0,
        (Frame::Driver, Frame::Follower) => kin.speed_driver_point_in_follower(p),
        (Frame::Follower, Frame::Driver) => kin.speed_follower_point_in_driver(p),
        (Frame::Reference, Frame::Follower) => kin.speed_support_point_in_follower(p),
        (Frame::Reference, Frame::Driver) => kin.speed_support_point_in_driver(p),
        // A moving part seen from the support: its own motion.
        (Frame::Driver, Frame::Reference) => std::f64::consts::TAU * p.xy().norm(),
        // |ω₂ × R₂q + Ṫ₂| ≤ Ω|q| + V, which this bound exceeds.
        (Frame::Follower, Frame::Reference) => kin.speed_support_point_in_follower(p),
        _ => unreachable!("handled by the first arm"),
    }
}

/// Steps per period of the finest time table the sweeps use; a point uses every 2ᵏ-th entry.
const TIME_TABLE: usize = 1 << 14;

/// A lower bound of the distance from each voxel centre of `grid` (in frame `target`) to
/// the union over one period of `bodies`. Voxels beyond every body's reach get large values.
pub fn swept_field(
    kin: &Kinematics,
    bodies: &[Balls],
    target: Frame,
    grid: VoxelGrid,
) -> DistanceField {
    let h = grid.h;
    let mut out = vec![f32::INFINITY; grid.len()];
    // One distance transform per ball radius.
    let mut radii: Vec<f64> = bodies.iter().map(|b| b.radius).collect();
    radii.sort_by(f64::total_cmp);
    radii.dedup();
    for r in radii {
        let group: Vec<&Balls> = bodies.iter().filter(|b| b.radius == r).collect();
        // Time tables per source frame (shared by all centres of that frame).
        let mut marks = vec![false; grid.len()];
        let mut max_step: f64 = 0.0;
        for b in group {
            let table: Vec<Isometry3<f64>> = if b.frame == target {
                vec![Isometry3::identity()]
            } else {
                (0..TIME_TABLE)
                    .into_par_iter()
                    .map(|j| transform(kin, b.frame, target, j as f64 / TIME_TABLE as f64))
                    .collect()
            };
            let hits: Vec<(Vec<usize>, f64)> = b
                .centers
                .par_chunks(64)
                .map(|chunk| {
                    let mut idx = Vec::new();
                    let mut worst: f64 = 0.0;
                    for &c in chunk {
                        let (steps, stride) = if table.len() == 1 {
                            (1, 1)
                        } else {
                            // Steps of at most half a voxel.
                            let v = speed(kin, b.frame, target, c);
                            let want = (v / (0.5 * h)).ceil().max(16.0) as usize;
                            let steps = want.next_power_of_two().min(TIME_TABLE);
                            worst = worst.max(v / steps as f64);
                            (steps, TIME_TABLE / steps)
                        };
                        for j in 0..steps {
                            let x = table[j * stride] * nalgebra::Point3::from(c);
                            if let Some(v) = grid.voxel_of(x.coords) {
                                idx.push(grid.index(v));
                            }
                        }
                    }
                    (idx, worst)
                })
                .collect();
            for (idx, w) in hits {
                max_step = max_step.max(w);
                for i in idx {
                    marks[i] = true;
                }
            }
        }
        let d = distance_transform(&grid, &marks);
        // Rounding to the voxel centre moves a mark by up to h·√3/2; between two marks of
        // one trace a point is at most half a step from one of them.
        let slack = r + 0.5 * 3f64.sqrt() * h + 0.5 * max_step;
        out.par_iter_mut().zip(d.par_iter()).for_each(|(o, &x)| {
            *o = o.min((x as f64 - slack) as f32);
        });
    }
    DistanceField {
        grid,
        values: out,
        outside: f32::INFINITY,
    }
}

/// Coarse time intervals the exact sweep starts from. 32.
const EXACT_START_INTERVALS: usize = 32;
/// Branch and bound stops splitting an interval once the distance cannot vary by more than
/// this across it, mm; neighbouring such intervals are merged and the minimum in each
/// merged run is found by golden-section search. Near a carved surface the distance varies
/// slowly in time (the rim slides along the groove), so a tight tolerance here would split
/// hundreds of intervals; 1.5 mm isolates the basin in a few levels.
const EXACT_BASIN_TOL_MM: f64 = 1.5;
/// Time tolerance of the local refinement (fraction of a period): 1e-6 of a period moves
/// the fastest point of the examples by less than 2 µm.
const EXACT_TIME_TOL: f64 = 1e-6;

/// The exact swept distance of a solid: the minimum over t of `solid`'s distance at a
/// point of frame `target` mapped into the solid's frame at t, capped at `cap`.
pub struct ExactSweep<'a, S: Sdf> {
    /// The kinematics.
    pub kin: &'a Kinematics,
    /// The moving solid.
    pub solid: &'a S,
    /// Its frame.
    pub frame: Frame,
    /// The frame points are given in.
    pub target: Frame,
    /// Values at or above this are reported as `cap` (only nearby values matter).
    pub cap: f64,
    /// A lower bound of the same swept distance (the coarse field), to skip far points.
    pub coarse: Option<&'a DistanceField>,
}

impl<S: Sdf> ExactSweep<'_, S> {
    fn at(&self, p: Vec3, t: f64) -> f64 {
        let x = transform(self.kin, self.target, self.frame, t) * nalgebra::Point3::from(p);
        self.solid.dist(x.coords)
    }

    /// min over t of the solid's distance at `p`, or `cap` if it is not below `cap`.
    pub fn value(&self, p: Vec3) -> f64 {
        if let Some(c) = self.coarse {
            if c.sample(p) >= self.cap {
                return self.cap;
            }
        }
        // How fast p moves in the solid's frame bounds how fast the distance can change.
        let v = speed(self.kin, self.target, self.frame, p).max(1e-9);
        // Intervals (centre, half width, value at centre).
        let w0 = 0.5 / EXACT_START_INTERVALS as f64;
        let mut open: Vec<(f64, f64, f64)> = (0..EXACT_START_INTERVALS)
            .map(|i| {
                let c = (2 * i + 1) as f64 * w0;
                (c, w0, self.at(p, c))
            })
            .collect();
        let mut best = open.iter().map(|o| o.2).fold(f64::INFINITY, f64::min);
        let mut basins: Vec<(f64, f64)> = Vec::new();
        while let Some((c, w, f)) = open.pop() {
            let lower = f - v * w;
            if lower >= best.min(self.cap) {
                continue;
            }
            if v * w <= EXACT_BASIN_TOL_MM || w < EXACT_TIME_TOL {
                basins.push((c, w));
                continue;
            }
            let h = 0.5 * w;
            for cc in [c - h, c + h] {
                let fc = self.at(p, cc);
                best = best.min(fc);
                open.push((cc, h, fc));
            }
        }
        // Merge touching basins into runs, then find each run's minimum by golden-section
        // search over the run widened by one interval on each side.
        basins.sort_by(|a, b| a.0.total_cmp(&b.0));
        let mut runs: Vec<(f64, f64)> = Vec::new();
        for (c, w) in basins {
            match runs.last_mut() {
                Some(r) if c - w <= r.1 + 1e-12 => r.1 = r.1.max(c + w),
                _ => runs.push((c - w, c + w)),
            }
        }
        for (lo, hi) in runs {
            let pad = (hi - lo).min(0.01);
            let (mut a, mut b) = (lo - pad, hi + pad);
            let g = 0.5 * (5f64.sqrt() - 1.0);
            let (mut x1, mut x2) = (b - g * (b - a), a + g * (b - a));
            let (mut f1, mut f2) = (self.at(p, x1), self.at(p, x2));
            while b - a > EXACT_TIME_TOL {
                if f1 < f2 {
                    b = x2;
                    x2 = x1;
                    f2 = f1;
                    x1 = b - g * (b - a);
                    f1 = self.at(p, x1);
                } else {
                    a = x1;
                    x1 = x2;
                    f1 = f2;
                    x2 = a + g * (b - a);
                    f2 = self.at(p, x2);
                }
            }
            best = best.min(f1).min(f2);
        }
        best.min(self.cap)
    }
}

/// The box that holds a frame's balls over the whole period, seen from `target`: the
/// union of the balls' boxes at `samples` times, grown by the largest distance a ball
/// moves between samples.
pub fn swept_bounds(kin: &Kinematics, body: &Balls, target: Frame, samples: usize) -> Aabb {
    if body.centers.is_empty() {
        return Aabb::EMPTY;
    }
    let vmax = body
        .centers
        .iter()
        .map(|&c| speed(kin, body.frame, target, c))
        .fold(0.0, f64::max);
    let n = if body.frame == target { 1 } else { samples };
    let mut b = Aabb::EMPTY;
    for j in 0..n {
        let m = transform(kin, body.frame, target, j as f64 / n as f64);
        for &c in &body.centers {
            let x = m * nalgebra::Point3::from(c);
            b = b.union(&Aabb::new([x.x, x.y, x.z], [x.x, x.y, x.z]));
        }
    }
    b.inflate(body.radius + 0.5 * vmax / n as f64)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::sdf::Sphere;
    use crate::synth::mechanism::Mechanism;

    /// How close the exact sweep must come to a brute-force minimum over 200 000 instants,
    /// mm: the brute force itself is off by up to (fastest point speed ≈ 2 000 mm per
    /// period) / 200 000 / 2 ≈ 0.005 mm, and the carve needs a tenth of the 0.1 mm gap
    /// tolerance.
    const EXACT_VS_BRUTE_MM: f64 = 0.01;

    /// Guards the groove: the swept distance of a ball on the follower, seen from the driver
    /// (what carves the groove), equals the minimum over a dense set of instants, at points
    /// near and inside the swept volume, and is capped where it should be.
    #[test]
    fn exact_sweep_is_the_minimum_over_time() {
        let file = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("tests/data/mechanism/half-turn-2to1/mechanism.json");
        let mech = Mechanism::load(&file).expect("the test mechanism loads");
        let kin = Kinematics::new(&mech, 10.0).expect("its law rebuilds");
        // A ball on the first curve pair's follower curve, 2 mm in radius.
        let c2 = mech.curve_pairs[0].samples.c2[0];
        let ball = Sphere {
            center: Vec3::new(c2[0], c2[1], c2[2]) * 10.0,
            radius: 2.0,
        };
        let cap = 5.0;
        let sweep = ExactSweep {
            kin: &kin,
            solid: &ball,
            frame: Frame::Follower,
            target: Frame::Driver,
            cap,
            coarse: None,
        };
        // Probe points: where the ball's centre passes in the driver's frame, offset.
        let n = 200_000;
        let mut checked = 0;
        for k in 0..24 {
            let t0 = (k as f64 + 0.37) / 24.0;
            let centre = transform(&kin, Frame::Follower, Frame::Driver, t0)
                * nalgebra::Point3::from(ball.center);
            let off = Vec3::new(
                (k as f64 * 1.3).sin(),
                (k as f64 * 2.1).cos(),
                (k as f64 * 0.7).sin(),
            ) * (0.5 + 0.2 * k as f64);
            let p = centre.coords + off;
            let brute = (0..n)
                .map(|i| sweep.at(p, i as f64 / n as f64))
                .fold(f64::INFINITY, f64::min);
            let exact = sweep.value(p);
            if brute >= cap {
                assert_eq!(exact, cap, "probe {k}: capped");
                continue;
            }
            checked += 1;
            assert!(
                (exact - brute).abs() < EXACT_VS_BRUTE_MM,
                "probe {k}: exact {exact} vs brute {brute}"
            );
        }
        assert!(checked >= 12, "only {checked} probes were below the cap");
    }
}
