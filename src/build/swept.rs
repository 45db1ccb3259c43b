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
//!   times the solid's [`Sdf::lipschitz`]; [`Kinematics`] bounds that speed over each
//!   interval) followed by a local refinement; the driver's groove
//!   is carved with it, so the groove is the true envelope of the follower's rims, without
//!   the scallops a finite number of boolean subtractions would leave. [`Certificates`]
//!   share the coarse part of that search between the grid points of one small cube (the
//!   distance is 1-Lipschitz in space, so intervals ruled out at the cube's centre with
//!   room to spare stay ruled out at its points), which is what makes the carve's
//!   tolerance affordable.
//!
//! It does not decide what is swept against what (`build::parts` does).

use std::borrow::Borrow;
use std::sync::{Arc, Mutex};

use nalgebra::Isometry3;
use rayon::prelude::*;
use rustc_hash::FxHashMap as HashMap;

use crate::geometry::mesh::Aabb;
use crate::geometry::sdf::{Sdf, Vec3};
use crate::geometry::voxel::{distance_transform, DistanceField, VoxelGrid};

use super::kinematics::{Frame, Kinematics, TRANSFORM_TABLE};

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
            // The kinematics' table of maps; a point uses every 2ᵏ-th entry.
            let identity = [Isometry3::identity()];
            let table: &[Isometry3<f64>] = if b.frame == target {
                &identity
            } else {
                kin.table(b.frame, target)
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
                            let steps = want.next_power_of_two().min(TRANSFORM_TABLE);
                            worst = worst.max(v / steps as f64);
                            (steps, TRANSFORM_TABLE / steps)
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
/// this across it, mm; neighbouring such intervals are merged into runs and each run's
/// minimum is refined by Brent's method. The minimum is always in some basin and each
/// basin holds a value found within this of its own minimum (at its centre or its nearer
/// end, whichever the search knows), so the value is never more than this
/// above the true one, however many local minima a run holds. 0.1 mm, the check's gap
/// tolerance: at 1.5 mm (before 2026-12-03) the runs were wide enough to hold several
/// local minima and 3 % of the grid points near the groove came out more than 0.01 mm
/// above the true minimum, up to 0.26 mm (an uncarved bump); at 0.1 mm the largest
/// difference from a brute-force minimum over 10⁵ instants was within the brute force's
/// own error (0.007 mm). The cost (about 1.7 times the evaluations) is taken back in the
/// carve by [`Certificates`].
const EXACT_BASIN_TOL_MM: f64 = 0.1;
/// How far above the best value so far, in basin tolerances, the local refinement asks
/// for exact values ([`ExactSweep::search`]): the basins it refines hold values less than
/// two tolerances above the best the branch and bound ended with, and nothing more than one
/// tolerance below it, so the refinement of earlier runs lowers the best by one at most.
const RUN_EXACT_ABOVE_BEST: f64 = 3.0;
/// Time tolerance of the local refinement (fraction of a period): 1e-6 of a period moves
/// the fastest point of the examples by less than 2 µm.
const EXACT_TIME_TOL: f64 = 1e-6;
/// A point's search rules out an interval of time whose lower bound is within this of the
/// best value found so far, mm, and so ends at most this above the true minimum (besides
/// [`EXACT_BASIN_TOL_MM`] within a run of basins). Near a minimum the bound is loose (the
/// distance is flat there while the bound falls at the point's whole speed), and the
/// search split every interval around the minimum down to the basin tolerance to prove
/// what this ends at once. 0.01 mm: a tenth of the check's gap tolerance, what the
/// brute-force tests hold the carve to (at 0.1 mm the first of them fails). Measured on
/// half-turn-2to1's printable design at 0.4 mm cells: the driver's branch and bound at
/// grid points went from 111 M to 54 M values of the rims (all its searches, certificates
/// included, from 218 M to 160 M); its mesh moved by at most 0.06 mm (12 of 1.3 M
/// vertices by more than 0.05 mm), every figure of the check the same. Certificates
/// search without it: their basins are a reach wide, which 0.01 mm does not change.
const SEARCH_SLACK_MM: f64 = 0.01;

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
    /// The search stops as soon as it finds a value at or below this and reports that value
    /// (`f64::NEG_INFINITY`: never): a caller that only needs to know that the point is this
    /// deep inside the swept volume is spared the search for the exact minimum.
    pub floor: f64,
}

/// Several solids of one frame swept through another: the smallest of their swept
/// distances at a point ([`SweptEach::value`]). Each solid is searched on its own, so that
/// each search bounds the distance's change by that solid's [`Sdf::lipschitz`] (a union
/// takes the largest of its parts'), and capped by the smallest value found so far.
pub struct SweptEach<'a, S: Sdf> {
    kin: &'a Kinematics,
    solids: &'a [S],
    frame: Frame,
    target: Frame,
    /// Per solid, a lower bound of its own swept distance ([`SweptEach::with_coarse_each`]).
    coarse_each: Option<&'a [Arc<DistanceField>]>,
    certificates: Option<&'a [Certificates]>,
    floor: f64,
}

impl<'a, S: Sdf> SweptEach<'a, S> {
    /// `solids` (of `frame`) swept through `target`, each value searched from scratch.
    pub fn new(kin: &'a Kinematics, solids: &'a [S], frame: Frame, target: Frame) -> Self {
        SweptEach {
            kin,
            solids,
            frame,
            target,
            coarse_each: None,
            certificates: None,
            floor: f64::NEG_INFINITY,
        }
    }

    /// Skip each solid where its own lower bound (`coarse[k]` bounds the swept distance of
    /// `solids[k]`) puts it at or beyond the smallest value so far, and search the solids
    /// nearest by that bound first, so that the value found early caps the others. A field
    /// of the union bounds every solid by the nearest one: near one rim's groove it skips
    /// none of the others.
    pub fn with_coarse_each(mut self, coarse: &'a [Arc<DistanceField>]) -> Self {
        debug_assert_eq!(coarse.len(), self.solids.len());
        self.coarse_each = Some(coarse);
        self
    }

    /// Start each solid's search from its own lattice of certificates: `certificates[k]`
    /// serves `solids[k]` alone (a lattice is made for one solid and motion).
    pub fn with_certificates(mut self, certificates: &'a [Certificates]) -> Self {
        debug_assert_eq!(certificates.len(), self.solids.len());
        self.certificates = Some(certificates);
        self
    }

    /// Only tell that a point is at least this deep inside the swept volume: values at or
    /// below `floor` are reported as `floor`, and each search stops at the first such value
    /// it finds ([`ExactSweep::floor`]). Values above it are the same as without.
    pub fn with_floor(mut self, floor: f64) -> Self {
        self.floor = floor;
        self
    }

    /// The smallest swept distance at `p`, or `cap` if it is not below `cap`, or the floor
    /// ([`SweptEach::with_floor`]) if it is not above it.
    pub fn value(&self, p: Vec3, cap: f64) -> f64 {
        let search = |k: usize, best: f64| {
            let sweep = ExactSweep {
                kin: self.kin,
                solid: &self.solids[k],
                frame: self.frame,
                target: self.target,
                cap: best,
                floor: self.floor,
            };
            match self.certificates {
                Some(lattices) => lattices[k].value(&sweep, p),
                None => sweep.value(p),
            }
        };
        let mut best = cap;
        match self.coarse_each {
            None => {
                for k in 0..self.solids.len() {
                    if best <= self.floor {
                        break;
                    }
                    best = best.min(search(k, best));
                }
            }
            Some(fields) => {
                for (bound, k) in nearest_first(fields, p) {
                    if best <= self.floor || bound >= best {
                        // Sorted: no later solid's bound is lower.
                        break;
                    }
                    best = best.min(search(k, best));
                }
            }
        }
        best.max(self.floor)
    }
}

/// The indices of `fields` with their values at `p`, lowest value first, ties in index
/// order (so the order depends on `p` alone): the order in which [`SweptEach`] and the
/// webs' band clearance search their solids, each field a lower bound of one solid's
/// swept distance, so that the nearest's value caps the others' searches.
pub fn nearest_first<F: Borrow<DistanceField>>(fields: &[F], p: Vec3) -> Vec<(f64, usize)> {
    let mut order: Vec<(f64, usize)> = fields
        .iter()
        .enumerate()
        .map(|(k, f)| (f.borrow().sample(p), k))
        .collect();
    order.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
    order
}

/// One interval of time a branch and bound ended on: its centre and half width, a lower
/// bound of the distance over it, and whether it was pruned or kept as a basin (to be
/// refined). The points a certificate serves evaluate its intervals again for themselves.
#[derive(Clone, Copy, Debug)]
struct Leaf {
    c: f64,
    w: f64,
    /// A lower bound over the interval.
    lo: f64,
    basin: bool,
}

/// A point's branch and bound over time, kept so that points near it can start from it:
/// at each instant the solid's value changes by at most its Lipschitz bound λ per mm
/// ([`Sdf::lipschitz`]: 1 for a true distance, more for a twisted sweep), so an interval
/// whose lower bound at `p` is b holds nothing below b − λ|p − q| at `q`. Only the leaves
/// that may matter within `reach` of `p` are kept (basins, and pruned leaves whose bound is
/// below the cap plus λ·reach); the others are pruned at every such point.
#[derive(Clone, Debug)]
struct Certificate {
    p: Vec3,
    reach: f64,
    /// The cap it was made for (it speaks for sweeps capped at or below it).
    cap: f64,
    leaves: Vec<Leaf>,
}

/// Most certificates a [`Certificates`] holds before it forgets them all. A certificate
/// near a groove keeps about a hundred intervals (3.6 kB): holding every one of a driver's
/// raised the build's peak memory from 2.5 to 3.6 GB at 0.4 mm cells. 2¹⁵ (about 120 MB)
/// covers the blocks the mesher has in flight and their neighbours along x and y.
const CERTIFICATES_HELD: usize = 1 << 15;

/// Certificates of one solid's [`ExactSweep`]s on a lattice of `cell` mm, made when first
/// asked for: a point's value starts from the certificate of its lattice cell's centre.
/// Each certificate is made for the lattice's cap and depends only on its centre, so every
/// value is the same whichever thread or order asked first; it serves sweeps of the same
/// solid capped at or below the lattice's cap (a lower cap only rules out more).
pub struct Certificates {
    cell: f64,
    cap: f64,
    map: Mutex<HashMap<[i64; 3], Arc<Certificate>>>,
}

impl Certificates {
    /// An empty lattice of `cell` mm for sweeps capped at `cap` or below.
    pub fn new(cell: f64, cap: f64) -> Certificates {
        Certificates {
            cell,
            cap,
            map: Mutex::new(HashMap::default()),
        }
    }

    /// `sweep`'s value at `p`, through the certificate of `p`'s cell. Use one lattice per
    /// solid and motion; a sweep capped above the lattice's cap is searched on its own.
    pub fn value<S: Sdf>(&self, sweep: &ExactSweep<'_, S>, p: Vec3) -> f64 {
        if sweep.cap > self.cap {
            return sweep.value(p);
        }
        let key = [p.x, p.y, p.z].map(|x| (x / self.cell).floor() as i64);
        let found = self
            .map
            .lock()
            .expect("no panics under the lock")
            .get(&key)
            .cloned();
        let cert = found.unwrap_or_else(|| {
            let centre =
                Vec3::new(key[0] as f64, key[1] as f64, key[2] as f64).add_scalar(0.5) * self.cell;
            // Two threads may make the same certificate; both are equal.
            let reach = 0.5 * 3f64.sqrt() * self.cell;
            let c = Arc::new(sweep.certificate(centre, reach, self.cap));
            let mut map = self.map.lock().expect("no panics under the lock");
            if map.len() >= CERTIFICATES_HELD {
                // Values never depend on what is held, only the time does.
                map.clear();
            }
            map.insert(key, c.clone());
            c
        });
        sweep.value_near(p, &cert)
    }
}

/// How fast the value of one point may change over an interval of time, per period: how
/// fast the point moves in the solid's frame (over the whole period, and over the interval,
/// often far less) times how fast the solid's value changes per mm.
struct Pace<'a> {
    kin: &'a Kinematics,
    from: Frame,
    to: Frame,
    norm: f64,
    lipschitz: f64,
    period: f64,
}

impl Pace<'_> {
    /// The bound over [c − w, c + w].
    fn over(&self, c: f64, w: f64) -> f64 {
        (self
            .kin
            .speed_within(self.from, self.to, self.norm, c - w, c + w)
            * self.lipschitz)
            .min(self.period)
            .max(1e-9)
    }
}

impl<S: Sdf> ExactSweep<'_, S> {
    /// The solid's value at `p` at time `t`: exact below `limit`, some value between
    /// `limit` and the exact one otherwise (continuous: the search bounds the change
    /// between instants by how far the point moved).
    fn at(&self, p: Vec3, t: f64, limit: f64) -> f64 {
        let x = self.kin.transform(self.target, self.frame, t) * nalgebra::Point3::from(p);
        self.solid.dist_continuous(x.coords, limit)
    }

    fn pace(&self, p: Vec3) -> Pace<'_> {
        let lipschitz = self.solid.lipschitz();
        Pace {
            kin: self.kin,
            from: self.target,
            to: self.frame,
            norm: p.norm(),
            lipschitz,
            period: speed(self.kin, self.target, self.frame, p) * lipschitz,
        }
    }

    /// min over t of the solid's distance at `p`, or `cap` if it is not below `cap`.
    pub fn value(&self, p: Vec3) -> f64 {
        self.search(
            p,
            self.start(p, self.cap, self.floor),
            self.cap,
            EXACT_BASIN_TOL_MM,
            None,
        )
        .min(self.cap)
    }

    /// The [`ExactSweep::value`] at `q`, starting from the certificate of a point within its
    /// reach: only the intervals the certificate cannot rule out at `q` are searched.
    /// Equal to [`ExactSweep::value`] within the search's tolerance.
    fn value_near(&self, q: Vec3, cert: &Certificate) -> f64 {
        let d = (q - cert.p).norm();
        if d > cert.reach || cert.cap < self.cap {
            return self.value(q);
        }
        let mut open: Vec<Open> = Vec::with_capacity(cert.leaves.len());
        let mut best = f64::INFINITY;
        let pace = self.pace(q);
        let moved = self.solid.lipschitz() * d;
        // Basins first: they hold the certificate's minimum, so the best is low early and
        // rules out more of the rest.
        let basins = cert.leaves.iter().filter(|l| l.basin);
        let pruned = cert.leaves.iter().filter(|l| !l.basin);
        for l in basins.chain(pruned) {
            // Nothing in the interval, basin or pruned, is below its bound less how far
            // the value may have changed since the certificate's centre.
            if l.lo - moved >= best.min(self.cap) {
                continue;
            }
            let f = self.at(q, l.c, best.min(self.cap) + pace.over(l.c, l.w) * l.w);
            best = best.min(f);
            open.push(Open::Centre { c: l.c, w: l.w, f });
            if best <= self.floor {
                return best;
            }
        }
        self.search(q, open, self.cap, EXACT_BASIN_TOL_MM, None)
            .min(self.cap)
    }

    /// The search at `p` with every leaf kept that may matter within `reach` of it to a
    /// sweep capped at `cap_for` or below, for [`ExactSweep::value_near`]. This sweep's own
    /// cap is not consulted.
    fn certificate(&self, p: Vec3, reach: f64, cap_for: f64) -> Certificate {
        let cap = cap_for + self.solid.lipschitz() * reach;
        let mut leaves = Vec::new();
        // Leaves finer than the reach would only be reopened at the points it serves.
        self.search(
            p,
            self.start(p, cap, f64::NEG_INFINITY),
            cap,
            reach.max(EXACT_BASIN_TOL_MM),
            Some(&mut leaves),
        );
        leaves.retain(|l| l.basin || l.lo < cap);
        Certificate {
            p,
            reach,
            cap: cap_for,
            leaves,
        }
    }

    /// The starting intervals, [`EXACT_START_INTERVALS`] of them end to end over the
    /// period, with the values at their ends. An end's value at or above `cap` plus the
    /// reach of the intervals beside it need not be exact: an interval both of whose ends
    /// are that high is pruned. Ends early, after the first value at or below `floor`.
    fn start(&self, p: Vec3, cap: f64, floor: f64) -> Vec<Open> {
        let n = EXACT_START_INTERVALS;
        let w0 = 0.5 / n as f64;
        let pace = self.pace(p);
        let mut ends = Vec::with_capacity(n);
        for i in 0..n {
            let t = i as f64 / n as f64;
            let f = self.at(p, t, cap + pace.over(t, 2.0 * w0) * w0);
            ends.push(f);
            if f <= floor {
                return vec![Open::Ends {
                    a: t,
                    b: t,
                    fa: f,
                    fb: f,
                }];
            }
        }
        // The period closes: the last interval ends at 1, the instant 0 again.
        (0..n)
            .map(|i| Open::Ends {
                a: i as f64 / n as f64,
                b: (i + 1) as f64 / n as f64,
                fa: ends[i],
                fb: ends[(i + 1) % n],
            })
            .collect()
    }

    /// Branch and bound over `open` (intervals with values known at their centre or ends),
    /// pruning against `cap` and the best value so far (less [`SEARCH_SLACK_MM`] at a
    /// point), then a local refinement of each run of basins. Records the leaves when asked
    /// (a certificate, which must be whole: the floor and the slack are then not used).
    /// Returns the smallest value found (not capped), or the first found at or below the
    /// floor.
    ///
    /// An interval is split at its middle, so its children share the parent's ends and a
    /// split costs one value (an interval known at its centre costs its two ends once).
    /// Over [a, b] with values fa, fb at the ends and the value changing by at most v per
    /// period, nothing is below (fa + fb)/2 − v(b − a)/2; near a minimum, where the
    /// distance is flat, that bound is higher than the centre's f(c) − v(b − a)/2 by
    /// about the curvature there times the square of the half width.
    fn search(
        &self,
        p: Vec3,
        mut open: Vec<Open>,
        cap: f64,
        basin_tol: f64,
        mut leaves: Option<&mut Vec<Leaf>>,
    ) -> f64 {
        let pace = self.pace(p);
        let floor = if leaves.is_some() {
            f64::NEG_INFINITY
        } else {
            self.floor
        };
        let mut best = open.iter().map(Open::least).fold(f64::INFINITY, f64::min);
        if best <= floor {
            return best;
        }
        let slack = if leaves.is_some() {
            0.0
        } else {
            SEARCH_SLACK_MM
        };
        // Every value found ([`Sample`]): what the runs' refinement starts from, and where
        // an interval split from its centre finds an end its neighbour already asked.
        let mut samples: Vec<Sample> = Vec::new();
        // Which of `samples` were asked at a leaf's end (see `end` below).
        let mut at_ends: Vec<usize> = Vec::new();
        for o in &open {
            match *o {
                Open::Centre { c, w, f } => {
                    samples.push(Sample::new(c, f, best.min(cap) + pace.over(c, w) * w))
                }
                // The starting ends were asked below their own limits (`start`), which
                // are not kept: refinement uses none of them.
                Open::Ends { .. } => {}
            }
        }
        // (centre, half width, lower bound over the interval).
        let mut basins: Vec<(f64, f64, f64)> = Vec::new();
        while let Some(o) = open.pop() {
            let (c, w) = o.centre_width();
            let v = pace.over(c, w);
            let lower = o.lower(v * w);
            if lower >= best.min(cap) - slack {
                if let Some(l) = leaves.as_deref_mut() {
                    l.push(Leaf {
                        c,
                        w,
                        lo: lower,
                        basin: false,
                    });
                }
                continue;
            }
            if v * w <= basin_tol || w < EXACT_TIME_TOL {
                basins.push((c, w, lower));
                if let Some(l) = leaves.as_deref_mut() {
                    l.push(Leaf {
                        c,
                        w,
                        lo: lower,
                        basin: true,
                    });
                }
                continue;
            }
            // The children's half width, and how fast the value changes over each.
            let h = 0.5 * w;
            let (vl, vr) = (pace.over(c - h, h), pace.over(c + h, h));
            // A value at or above a child's limit prunes that child when popped, whatever it
            // is exactly (and cannot lower `best` below the cap): the solid need not find
            // it. Over [x, y] with f(x) known, f(y) ≥ 2(B + v·h) − f(x) prunes.
            let floor_of = best.min(cap);
            let pruning = |v: f64, known: f64| (2.0 * (floor_of + v * h) - known).max(floor_of);
            match o {
                Open::Centre { f, .. } => {
                    // A leaf's end is no other value's instant (the values inside the leaves
                    // lie strictly within them), so one found there is a neighbour's end.
                    // So only the values asked here can be found here: they are looked
                    // through alone (searching every sample, 104 on average, took 2.7 G
                    // comparisons over half-turn-2to1's build).
                    let mut end = |t: f64, limit: f64| {
                        let found = at_ends
                            .iter()
                            .rev()
                            .map(|&i| &samples[i])
                            .find(|s| s.t == t && s.serves(limit));
                        debug_assert_eq!(
                            found.map(|s| s.f),
                            samples
                                .iter()
                                .rfind(|s| s.t == t && s.serves(limit))
                                .map(|s| s.f),
                            "a leaf's end at {t} is another value's instant"
                        );
                        if let Some(s) = found {
                            return s.f;
                        }
                        let fe = self.at(p, t, limit);
                        at_ends.push(samples.len());
                        samples.push(Sample::new(t, fe, limit));
                        fe
                    };
                    let fa = end(c - w, pruning(vl, f));
                    let fb = end(c + w, pruning(vr, f));
                    best = best.min(fa).min(fb);
                    open.push(Open::Ends {
                        a: c - w,
                        b: c,
                        fa,
                        fb: f,
                    });
                    open.push(Open::Ends {
                        a: c,
                        b: c + w,
                        fa: f,
                        fb,
                    });
                }
                Open::Ends { a, b, fa, fb } => {
                    let limit = pruning(vl, fa).max(pruning(vr, fb));
                    let fc = self.at(p, c, limit);
                    samples.push(Sample::new(c, fc, limit));
                    best = best.min(fc);
                    open.push(Open::Ends {
                        a,
                        b: c,
                        fa,
                        fb: fc,
                    });
                    open.push(Open::Ends {
                        a: c,
                        b,
                        fa: fc,
                        fb,
                    });
                }
            }
            if best <= floor {
                return best;
            }
        }
        if leaves.is_some() {
            // A certificate: the points it serves refine for themselves.
            return best;
        }
        // Merge touching basins into runs, then refine each run's minimum, from the least
        // exact value found in it, within the run widened a little on each side (`pad`;
        // see [`Seed::within`]). A basin whose lower bound is not below the
        // best found since it was kept holds nothing that matters: left out, so that every
        // basin refined holds values within two tolerances above the best (its nearer
        // end's value is within one of its lower bound, and its values within one of that).
        basins.retain(|b| b.2 < best.min(cap) - slack);
        basins.sort_by(|a, b| a.0.total_cmp(&b.0));
        // (start, end, lowest lower bound).
        let mut runs: Vec<(f64, f64, f64)> = Vec::new();
        for (c, w, lower) in basins {
            match runs.last_mut() {
                Some(r) if c - w <= r.1 + 1e-12 => {
                    r.1 = r.1.max(c + w);
                    r.2 = r.2.min(lower);
                }
                _ => runs.push((c - w, c + w, lower)),
            }
        }
        samples.sort_by(|a, b| a.t.total_cmp(&b.t));
        for (lo, hi, lower) in runs {
            if lower >= best.min(cap) - slack {
                // An earlier run's refinement found a value this one cannot beat.
                continue;
            }
            let pad = (hi - lo).min(0.01);
            // Exact values only below a limit, which makes each one cheaper (the solid's
            // hierarchy prunes by it): every value inside the run is below it (see above),
            // so Brent's steps there are those of unlimited values; only the padding
            // beyond the run may see values at the limit, above every value inside.
            let limit = best.min(cap) + RUN_EXACT_ABOVE_BEST * basin_tol;
            let exact = |t| self.at(p, t, limit);
            let seed = Seed::within(&samples, lo - pad, hi + pad);
            best = best.min(minimize(exact, seed, floor));
            if best <= floor {
                return best;
            }
        }
        best
    }
}

/// An interval of time the branch and bound holds open, with the values known of it.
#[derive(Clone, Copy, Debug)]
enum Open {
    /// Its centre and half width, and the value at the centre (a certificate's leaf,
    /// asked again at a point it serves).
    Centre { c: f64, w: f64, f: f64 },
    /// Its ends, and the values there.
    Ends { a: f64, b: f64, fa: f64, fb: f64 },
}

impl Open {
    /// Centre and half width.
    fn centre_width(&self) -> (f64, f64) {
        match *self {
            Open::Centre { c, w, .. } => (c, w),
            Open::Ends { a, b, .. } => (0.5 * (a + b), 0.5 * (b - a)),
        }
    }

    /// A lower bound over the interval, where the value changes by at most `reach` over
    /// half its width.
    fn lower(&self, reach: f64) -> f64 {
        match *self {
            Open::Centre { f, .. } => f - reach,
            Open::Ends { fa, fb, .. } => 0.5 * (fa + fb) - reach,
        }
    }

    /// The least value known of it.
    fn least(&self) -> f64 {
        match *self {
            Open::Centre { f, .. } => f,
            Open::Ends { fa, fb, .. } => fa.min(fb),
        }
    }
}

/// A value a search found: at `t`, `f`, asked exact below `limit` (at or above it, `f` is
/// only a lower bound of the value, at or above the limit).
#[derive(Clone, Copy, Debug)]
struct Sample {
    t: f64,
    f: f64,
    limit: f64,
}

impl Sample {
    fn new(t: f64, f: f64, limit: f64) -> Sample {
        Sample { t, f, limit }
    }

    /// Whether `f` is the exact value.
    fn exact(&self) -> bool {
        self.f < self.limit
    }

    /// Whether it answers a request exact below `limit`: exact, or known to be at or above
    /// that limit.
    fn serves(&self, limit: f64) -> bool {
        self.exact() || self.limit >= limit
    }
}

/// Where Brent's method starts on a run ([`minimize`]): its bracket, the least exact value
/// found in it (if any) and the nearest exact values on each side of that one.
struct Seed {
    a: f64,
    b: f64,
    x: Option<(f64, f64)>,
    left: Option<(f64, f64)>,
    right: Option<(f64, f64)>,
}

impl Seed {
    /// The seed of [lo, hi] from `samples` (sorted by time): the least exact value inside,
    /// bracketed by the nearest values on each side that are not below it (a value is
    /// never above the exact one, so the exact one is not below it either), or by the ends
    /// of [lo, hi].
    fn within(samples: &[Sample], lo: f64, hi: f64) -> Seed {
        // The samples strictly inside, found once in the sorted list.
        let from = samples.partition_point(|s| s.t <= lo);
        let to = from + samples[from..].partition_point(|s| s.t < hi);
        let inside = &samples[from..to];
        let best = inside
            .iter()
            .filter(|s| s.exact())
            .min_by(|a, b| a.f.total_cmp(&b.f));
        let Some(x) = best else {
            return Seed {
                a: lo,
                b: hi,
                x: None,
                left: None,
                right: None,
            };
        };
        let left = inside.iter().rfind(|s| s.t < x.t && s.f >= x.f);
        let right = inside.iter().find(|s| s.t > x.t && s.f >= x.f);
        let known = |s: Option<&Sample>| s.filter(|s| s.exact()).map(|s| (s.t, s.f));
        Seed {
            a: left.map_or(lo, |s| s.t),
            b: right.map_or(hi, |s| s.t),
            x: Some((x.t, x.f)),
            left: known(left),
            right: known(right),
        }
    }
}

/// The smallest value of `f` on [a, b] by Brent's method: parabolic steps through the three
/// best points where they stay inside the bracket and shrink it, golden-section steps
/// otherwise, until the bracket is [`EXACT_TIME_TOL`] wide around the best point, or a
/// value at or below `floor` is found (then that value). Exact for a unimodal `f`; on a
/// run with several minima it may stop in one that is not the lowest, which the caller's
/// basin tolerance bounds.
fn minimize(f: impl Fn(f64) -> f64, seed: Seed, floor: f64) -> f64 {
    const GOLD: f64 = 0.381_966_011_250_105_1; // (3 − √5) / 2
    let (mut a, mut b) = (seed.a, seed.b);
    let (mut x, mut fx) = match seed.x {
        Some(known) => known,
        None => {
            let x = a + GOLD * (b - a);
            (x, f(x))
        }
    };
    // The next best point and the one before it: the seed's neighbours, through which the
    // first step's parabola passes, or the point itself.
    let (mut w, mut fw) = seed.left.unwrap_or((x, fx));
    let (mut v, mut fv) = seed.right.unwrap_or((x, fx));
    if fv < fw {
        (w, fw, v, fv) = (v, fv, w, fw);
    }
    // The step before last, and the last: with known neighbours the first two steps may
    // be parabolic (each shorter than half the bracket), as if golden steps had led there.
    let (mut e, mut d): (f64, f64) = if seed.left.is_some() && seed.right.is_some() {
        (b - a, b - a)
    } else {
        (0.0, 0.0)
    };
    loop {
        let m = 0.5 * (a + b);
        let tol = 0.5 * EXACT_TIME_TOL;
        if (x - m).abs() <= 2.0 * tol - 0.5 * (b - a) || fx <= floor {
            return fx;
        }
        let mut golden = true;
        if e.abs() > tol {
            // Parabola through (v, fv), (w, fw), (x, fx).
            let r = (x - w) * (fx - fv);
            let q0 = (x - v) * (fx - fw);
            let mut pn = (x - v) * q0 - (x - w) * r;
            let mut q = 2.0 * (q0 - r);
            if q > 0.0 {
                pn = -pn;
            }
            q = q.abs();
            if pn.abs() < (0.5 * q * e).abs() && pn > q * (a - x) && pn < q * (b - x) {
                e = d;
                d = pn / q;
                let u = x + d;
                if u - a < 2.0 * tol || b - u < 2.0 * tol {
                    d = if x < m { tol } else { -tol };
                }
                golden = false;
            }
        }
        if golden {
            e = if x < m { b - x } else { a - x };
            d = GOLD * e;
        }
        let u = if d.abs() >= tol {
            x + d
        } else {
            x + tol.copysign(d)
        };
        let fu = f(u);
        if fu <= fx {
            if u < x {
                b = x;
            } else {
                a = x;
            }
            (v, fv, w, fw, x, fx) = (w, fw, x, fx, u, fu);
        } else {
            if u < x {
                a = u;
            } else {
                b = u;
            }
            if fu <= fw || w == x {
                (v, fv, w, fw) = (w, fw, u, fu);
            } else if fu <= fv || v == x || v == w {
                (v, fv) = (u, fu);
            }
        }
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
    let b = Aabb::around((0..n).flat_map(|j| {
        let m = kin.transform(body.frame, target, j as f64 / n as f64);
        body.centers.iter().map(move |&c| {
            let x = m * nalgebra::Point3::from(c);
            [x.x, x.y, x.z]
        })
    }));
    b.inflate(body.radius + 0.5 * vmax / n as f64)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::build::tests::half_turn;
    use crate::geometry::sdf::Sphere;
    use crate::synth::mechanism::Mechanism;

    /// How close the exact sweep must come to a brute-force minimum over 200 000 instants,
    /// mm: the brute force itself is off by up to (fastest point speed ≈ 2 000 mm per
    /// period) / 200 000 / 2 ≈ 0.005 mm, and the carve needs a tenth of the 0.1 mm gap
    /// tolerance.
    const EXACT_VS_BRUTE_MM: f64 = 0.01;

    /// The sweep that carves the groove: `solid` on the follower, seen from the driver.
    fn carving<'a, S: Sdf>(kin: &'a Kinematics, solid: &'a S, cap: f64) -> ExactSweep<'a, S> {
        ExactSweep {
            kin,
            solid,
            frame: Frame::Follower,
            target: Frame::Driver,
            cap,
            floor: f64::NEG_INFINITY,
        }
    }

    /// Guards the groove: the swept distance of a ball on the follower, seen from the driver
    /// (what carves the groove), equals the minimum over a dense set of instants, at points
    /// near and inside the swept volume, and is capped where it should be.
    #[test]
    fn exact_sweep_is_the_minimum_over_time() {
        let (mech, kin) = half_turn();
        // A ball on the first curve pair's follower curve, 2 mm in radius.
        let c2 = mech.curve_pairs[0].samples.c2[0];
        let ball = Sphere {
            center: Vec3::new(c2[0], c2[1], c2[2]) * 10.0,
            radius: 2.0,
        };
        let cap = 5.0;
        let sweep = carving(&kin, &ball, cap);
        // Probe points: where the ball's centre passes in the driver's frame, offset.
        let n = 200_000;
        let mut checked = 0;
        for k in 0..24 {
            let t0 = (k as f64 + 0.37) / 24.0;
            let centre = kin.transform(Frame::Follower, Frame::Driver, t0)
                * nalgebra::Point3::from(ball.center);
            let off = Vec3::new(
                (k as f64 * 1.3).sin(),
                (k as f64 * 2.1).cos(),
                (k as f64 * 0.7).sin(),
            ) * (0.5 + 0.2 * k as f64);
            let p = centre.coords + off;
            let brute = (0..n)
                .map(|i| sweep.at(p, i as f64 / n as f64, f64::INFINITY))
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

    /// Guards the carve's accuracy where a run of basins holds several minima (the union
    /// of the rims passes a point near a groove at many nearby instants): both the plain
    /// search and the one through [`Certificates`] (also for sweeps capped below the
    /// lattice's cap) stay within [`EXACT_VS_BRUTE_MM`] of a brute-force minimum at points
    /// near the driver's contact curves. With the basin
    /// tolerance of 1.5 mm used before 2026-12-03 the plain search failed it (0.026 mm
    /// above here; up to 0.26 mm at grid points of a build).
    #[test]
    fn exact_sweep_finds_the_lowest_of_several_minima() {
        let (mech, kin) = half_turn();
        let rims = crate::geometry::sdf::Union::new(
            mech.curve_pairs
                .iter()
                .map(|cp| Box::new(crate::build::shapes::rim(cp, 10.0).unwrap()) as Box<dyn Sdf>)
                .collect(),
        );
        let cap = 2.0;
        let sweep = carving(&kin, &rims, cap);
        let certificates = Certificates::new(1.0, cap);
        let n = 200_000;
        let (mut checked, mut worst_plain, mut worst_cert) = (0, 0.0f64, 0.0f64);
        for k in 0..60 {
            let c1s = &mech.curve_pairs[k % mech.curve_pairs.len()].samples.c1;
            let c1 = c1s[(k * 37) % c1s.len()];
            let on = Vec3::new(c1[0], c1[1], c1[2]) * 10.0;
            let off = Vec3::new(
                (k as f64 * 1.7).sin(),
                (k as f64 * 0.9).cos(),
                (k as f64 * 2.3).sin(),
            ) * 0.6;
            let p = on + off;
            let brute = (0..n)
                .map(|i| sweep.at(p, i as f64 / n as f64, f64::INFINITY))
                .fold(f64::INFINITY, f64::min)
                .min(cap);
            if brute >= cap {
                continue;
            }
            checked += 1;
            worst_plain = worst_plain.max((sweep.value(p) - brute).abs());
            worst_cert = worst_cert.max((certificates.value(&sweep, p) - brute).abs());
            // The carve lowers the cap point by point, through certificates made for the
            // lattice's cap.
            for low in [0.1, 0.8] {
                let lower = carving(&kin, &rims, low);
                let got = certificates.value(&lower, p);
                worst_cert = worst_cert.max((got - brute.min(low)).abs());
            }
        }
        assert!(checked >= 30, "only {checked} probes were below the cap");
        assert!(
            worst_plain < EXACT_VS_BRUTE_MM && worst_cert < EXACT_VS_BRUTE_MM,
            "off the brute force by {worst_plain} mm (plain) and {worst_cert} mm (certificates)"
        );
    }

    /// A solid `k` times steeper than `inner`: its values change `k` times faster per mm.
    struct Steep<S> {
        inner: S,
        k: f64,
    }

    impl<S: Sdf> Sdf for Steep<S> {
        fn dist(&self, p: Vec3) -> f64 {
            self.k * self.inner.dist(p)
        }
        fn dist_continuous(&self, p: Vec3, limit: f64) -> f64 {
            self.k * self.inner.dist_continuous(p, limit / self.k)
        }
        fn lipschitz(&self) -> f64 {
            self.k * self.inner.lipschitz()
        }
        fn bounds(&self) -> crate::geometry::mesh::Aabb {
            self.inner.bounds()
        }
    }

    /// Guards the certificates' reach for solids whose values change faster than a point
    /// moves (twisted rims): through [`Certificates`] the value of the rims made four times
    /// steeper is the plain search's, at points spread over many lattice cells.
    #[test]
    fn certificates_serve_solids_steeper_than_a_distance() {
        let (mech, kin) = half_turn();
        let k = 4.0;
        let rims = Steep {
            inner: crate::geometry::sdf::Union::new(
                mech.curve_pairs
                    .iter()
                    .map(|cp| {
                        Box::new(crate::build::shapes::rim(cp, 10.0).unwrap()) as Box<dyn Sdf>
                    })
                    .collect(),
            ),
            k,
        };
        let cap = 2.0 * k;
        let sweep = carving(&kin, &rims, cap);
        let certificates = Certificates::new(1.0, cap);
        let (mut below, mut worst) = (0, 0.0f64);
        for i in 0..240 {
            let c1s = &mech.curve_pairs[i % mech.curve_pairs.len()].samples.c1;
            let c1 = c1s[(i * 29) % c1s.len()];
            let off = Vec3::new(
                (i as f64 * 1.3).sin(),
                (i as f64 * 0.7).cos(),
                (i as f64 * 2.9).sin(),
            ) * 0.8;
            let p = Vec3::new(c1[0], c1[1], c1[2]) * 10.0 + off;
            let plain = sweep.value(p);
            below += usize::from(plain < cap);
            worst = worst.max((certificates.value(&sweep, p) - plain).abs());
        }
        assert!(below >= 120, "only {below} points below the cap");
        assert!(
            worst < k * EXACT_VS_BRUTE_MM,
            "off the plain search by {worst}"
        );
    }

    /// A solid that counts how often its value is asked for.
    struct Counted<S> {
        inner: S,
        asked: std::sync::atomic::AtomicUsize,
    }

    impl<S: Sdf> Sdf for Counted<S> {
        fn dist(&self, p: Vec3) -> f64 {
            self.asked
                .fetch_add(1, std::sync::atomic::Ordering::Relaxed);
            self.inner.dist(p)
        }
        fn dist_continuous(&self, p: Vec3, limit: f64) -> f64 {
            self.asked
                .fetch_add(1, std::sync::atomic::Ordering::Relaxed);
            self.inner.dist_continuous(p, limit)
        }
        fn lipschitz(&self) -> f64 {
            self.inner.lipschitz()
        }
        fn bounds(&self) -> crate::geometry::mesh::Aabb {
            self.inner.bounds()
        }
    }

    /// Each rim of `mech` (at 10 mm per model unit), counting its evaluations.
    fn counted_rims(mech: &Mechanism) -> Vec<Counted<crate::geometry::sweep::Sweep>> {
        mech.curve_pairs
            .iter()
            .map(|cp| Counted {
                inner: crate::build::shapes::rim(cp, 10.0).unwrap(),
                asked: Default::default(),
            })
            .collect()
    }

    /// The evaluations of `rims` so far.
    fn asked<S: Sdf>(rims: &[Counted<S>]) -> usize {
        rims.iter()
            .map(|r| r.asked.load(std::sync::atomic::Ordering::Relaxed))
            .sum()
    }

    /// One lattice of 1 mm certificates per rim, for sweeps capped at `cap`.
    fn lattices_for<S>(rims: &[S], cap: f64) -> Vec<Certificates> {
        (0..rims.len())
            .map(|_| Certificates::new(1.0, cap))
            .collect()
    }

    /// `n` points near the driver's contact curves (at 10 mm per model unit): every
    /// `stride`-th sample of each pair in turn, moved by up to `reach` mm along a direction
    /// whose components turn at the rates `turn`.
    fn near_contacts(
        mech: &Mechanism,
        n: usize,
        stride: usize,
        turn: [f64; 3],
        reach: f64,
    ) -> Vec<Vec3> {
        (0..n)
            .map(|i| {
                let c1s = &mech.curve_pairs[i % mech.curve_pairs.len()].samples.c1;
                let c1 = c1s[(i * stride) % c1s.len()];
                let off = Vec3::new(
                    (i as f64 * turn[0]).sin(),
                    (i as f64 * turn[1]).cos(),
                    (i as f64 * turn[2]).sin(),
                ) * reach;
                Vec3::new(c1[0], c1[1], c1[2]) * 10.0 + off
            })
            .collect()
    }

    /// Guards the carve's floor ([`SweptEach::with_floor`]): through certificates, as the
    /// carve asks, every value above the floor is exactly the one without it, every value at
    /// or below it is reported as the floor, and the points deep in the rims' sweep cost
    /// fewer evaluations of the rims (what the floor is for).
    #[test]
    fn a_floor_ends_the_search_and_changes_no_value_above_it() {
        let (mech, kin) = half_turn();
        let rims = counted_rims(&mech);
        let (cap, floor) = (0.9, -0.7);
        let points = near_contacts(&mech, 300, 31, [1.1, 0.6, 2.7], 2.0);
        let lattices = || lattices_for(&rims, cap);
        let (whole_lattices, floored_lattices) = (lattices(), lattices());
        let whole = || SweptEach::new(&kin, &rims, Frame::Follower, Frame::Driver);
        let floored = || whole().with_floor(floor);
        // As the carve asks: through certificates.
        let exact: Vec<f64> = {
            let whole = whole().with_certificates(&whole_lattices);
            points.iter().map(|&p| whole.value(p, cap)).collect()
        };
        let got: Vec<f64> = {
            let floored = floored().with_certificates(&floored_lattices);
            points.iter().map(|&p| floored.value(p, cap)).collect()
        };
        let deep: Vec<Vec3> = points
            .iter()
            .zip(&exact)
            .filter(|(_, &v)| v <= floor)
            .map(|(&p, _)| p)
            .collect();
        let between = exact.iter().filter(|&&v| v > floor && v < cap).count();
        assert!(
            deep.len() >= 30 && between >= 30,
            "{} points deep, {between} between",
            deep.len()
        );
        for ((e, g), p) in exact.iter().zip(&got).zip(&points) {
            let want = if *e <= floor { floor } else { *e };
            assert_eq!(*g, want, "at {p:?}");
        }
        // The cost at the deep points, searched from scratch (a certificate is made whole).
        let cost = |sweep: &SweptEach<'_, _>| {
            let before = asked(&rims);
            for &p in &deep {
                sweep.value(p, cap);
            }
            asked(&rims) - before
        };
        let (cost_whole, cost_floored) = (cost(&whole()), cost(&floored()));
        assert!(
            (cost_floored as f64) < 0.5 * cost_whole as f64,
            "{cost_floored} evaluations with the floor, {cost_whole} without, at {} points",
            deep.len()
        );
    }

    /// Guards the rims' own coarse fields ([`SweptEach::with_coarse_each`], what the
    /// driver's carve uses): at points near each rim's contact curve, values through
    /// certificates are those of the search without any coarse field (within the search's
    /// slack, as each search is capped by what the others found first), and a third of
    /// the rims' evaluations are spared, since each point is near one rim's groove. The fields
    /// are made as the build makes them: each rim's cover swept on a grid around that
    /// rim's sweep alone ([`crate::build::connect::clearance_within`]), so a value beyond
    /// that grid says infinity.
    #[test]
    fn each_rim_s_own_field_spares_the_far_rims_and_changes_no_value() {
        let (mech, kin) = half_turn();
        let rims = counted_rims(&mech);
        let cap = 0.9;
        let fields: Vec<Arc<DistanceField>> = rims
            .iter()
            .map(|r| {
                let cover = crate::build::shapes::sweep_cover(&r.inner, Frame::Follower);
                Arc::new(crate::build::connect::clearance_within(
                    &kin,
                    &cover,
                    Frame::Driver,
                    cap,
                ))
            })
            .collect();
        let points = near_contacts(&mech, 240, 37, [1.7, 0.9, 2.3], 1.5);
        let lattices = || lattices_for(&rims, cap);
        let run = |each: bool| {
            let lattices = lattices();
            let sweep = SweptEach::new(&kin, &rims, Frame::Follower, Frame::Driver)
                .with_certificates(&lattices);
            let sweep = if each {
                sweep.with_coarse_each(&fields)
            } else {
                sweep
            };
            let before = asked(&rims);
            let values: Vec<f64> = points.iter().map(|&p| sweep.value(p, cap)).collect();
            (values, asked(&rims) - before)
        };
        let (plain, cost_plain) = run(false);
        let (each, cost_each) = run(true);
        let near = plain.iter().filter(|&&v| v < cap).count();
        assert!(near >= 60, "only {near} points below the cap");
        for ((a, b), p) in plain.iter().zip(&each).zip(&points) {
            assert!(
                (a - b).abs() <= SEARCH_SLACK_MM + 1e-9,
                "at {p:?}: {b} with the rims' fields, {a} without"
            );
        }
        // 80 660 against 125 442 when written.
        assert!(
            (cost_each as f64) < 0.75 * cost_plain as f64,
            "{cost_each} evaluations with the rims' fields, {cost_plain} without"
        );
    }

    /// Guards determinism: a value through [`Certificates`] depends on the point alone, not
    /// on which points asked before (the mesher evaluates a block's shared faces twice, in
    /// blocks that other threads may run in any order, and both must agree exactly).
    #[test]
    fn certificate_values_do_not_depend_on_the_order_asked() {
        let (mech, kin) = half_turn();
        let rim = crate::build::shapes::rim(&mech.curve_pairs[0], 10.0).unwrap();
        let sweep = carving(&kin, &rim, 2.0);
        let c1 = mech.curve_pairs[0].samples.c1[5];
        let base = Vec3::new(c1[0], c1[1], c1[2]) * 10.0;
        // A 6 × 6 × 6 grid of 0.4 mm around a point of the groove: several lattice cells.
        let points: Vec<Vec3> = (0..216)
            .map(|i| base + Vec3::new((i % 6) as f64, (i / 6 % 6) as f64, (i / 36) as f64) * 0.4)
            .collect();
        let forward = Certificates::new(1.0, 2.0);
        let a: Vec<f64> = points.iter().map(|&p| forward.value(&sweep, p)).collect();
        let backward = Certificates::new(1.0, 2.0);
        let mut b: Vec<f64> = points
            .iter()
            .rev()
            .map(|&p| backward.value(&sweep, p))
            .collect();
        b.reverse();
        assert!(a.iter().any(|&v| v < 2.0), "no point near the groove");
        assert_eq!(a, b);
    }

    /// Guards what Brent's method may start from ([`Seed::within`]): only an exact value
    /// (a lower bound asked past its limit could lie below the true minimum, and the carve
    /// would then cut deeper than the rims reach), bracketed by the nearest values not
    /// below it.
    #[test]
    fn a_run_is_seeded_by_exact_values_only() {
        let samples = [
            Sample::new(0.10, 0.5, 1.0),
            // Asked exact below 0.3 only: the value is somewhere at or above it.
            Sample::new(0.20, 0.3, 0.3),
            Sample::new(0.30, 0.7, 1.0),
            Sample::new(0.45, 0.2, 1.0),
        ];
        let seed = Seed::within(&samples, 0.0, 0.4);
        assert_eq!(seed.x, Some((0.10, 0.5)));
        assert_eq!((seed.a, seed.left), (0.0, None));
        assert_eq!((seed.b, seed.right), (0.30, Some((0.30, 0.7))));
        let none = Seed::within(&samples[1..2], 0.0, 0.4);
        assert_eq!((none.a, none.b, none.x), (0.0, 0.4, None));
    }

    /// Guards the seeded refinement ([`minimize`]): from a value and its two neighbours it
    /// finds a smooth minimum as exactly as from scratch over the same bracket, and in
    /// fewer values.
    #[test]
    fn a_seeded_refinement_finds_the_minimum_in_fewer_values() {
        let t0 = 0.313_7;
        let asked = std::cell::Cell::new(0);
        let f = |t: f64| {
            asked.set(asked.get() + 1);
            1.0 + 40.0 * (t - t0).powi(2) + 3.0 * (t - t0).powi(3)
        };
        let scratch = minimize(
            f,
            Seed {
                a: 0.25,
                b: 0.35,
                x: None,
                left: None,
                right: None,
            },
            f64::NEG_INFINITY,
        );
        let from_scratch = asked.replace(0);
        let known = |t: f64| (t, 1.0 + 40.0 * (t - t0).powi(2) + 3.0 * (t - t0).powi(3));
        let seeded = minimize(
            f,
            Seed {
                a: 0.25,
                b: 0.35,
                x: Some(known(0.30)),
                left: Some(known(0.25)),
                right: Some(known(0.35)),
            },
            f64::NEG_INFINITY,
        );
        let from_seed = asked.get();
        assert!((scratch - 1.0).abs() < 1e-9 && (seeded - 1.0).abs() < 1e-9);
        assert!(
            from_seed < from_scratch,
            "{from_seed} values seeded, {from_scratch} from scratch"
        );
    }

    /// Guards what the carve's points cost: through certificates, as the carve asks (each
    /// point here in a lattice cell of its own, so with its certificate's cost, and every
    /// rim searched), points near the contact curves ask the rims for fewer than 450 values
    /// each on average. Splitting intervals at their centres (two new values per split,
    /// bounded by the centre's value alone) and refining runs from scratch took 551 here
    /// (2026-12-07); intervals split at shared ends and runs refined from the values found
    /// take 348.
    #[test]
    fn a_point_near_a_groove_costs_few_values() {
        let (mech, kin) = half_turn();
        let rims = counted_rims(&mech);
        let cap = 0.9;
        let points = near_contacts(&mech, 400, 23, [1.3, 0.5, 2.1], 0.8);
        let lattices = lattices_for(&rims, cap);
        let sweep = SweptEach::new(&kin, &rims, Frame::Follower, Frame::Driver)
            .with_certificates(&lattices);
        let below = points
            .iter()
            .filter(|&&p| sweep.value(p, cap) < cap)
            .count();
        let per_point = asked(&rims) as f64 / points.len() as f64;
        assert!(below >= 200, "only {below} points below the cap");
        assert!(per_point < 450.0, "{per_point:.1} values per point");
    }
}
