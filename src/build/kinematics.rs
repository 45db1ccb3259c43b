//! The relative motion of the parts over one period, in millimetres.
//!
//! Owns [`Kinematics`]: the follower's pose M²(t) (the periodic law interpolating the
//! mechanism's `follower_motion`, scaled to mm), the driver's pose (a turn of 2πt about the
//! axis through (d_x, 0, 0)), the [`Frame`]s and the maps between them, and bounds on how
//! fast a point of one frame moves in another (mm per period), over the whole period and
//! over any interval of it ([`Kinematics::speed_within`]), which the swept-volume code uses
//! to sample time finely enough and to bound distances between samples. It does not know
//! the parts' shapes.

use std::sync::OnceLock;

use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};

use crate::motion::{DenseRow, Motion, MotionClass};
use crate::synth::closure::Class;
use crate::synth::mechanism::Mechanism;

use super::BuildError;

/// Samples per period used to find the largest angular and linear speeds of the law (the
/// bounds are then raised by [`SPEED_SAFETY`]). 4096: 11× the file's 360 samples.
const SPEED_SAMPLES: usize = 4096;
/// Factor on the sampled maximum speeds, covering peaks between samples. 1.05.
const SPEED_SAFETY: f64 = 1.05;
/// Time bins per period of the per-interval speed bounds ([`Kinematics::speed_within`]).
/// 4096: 11 bins per key of the file's 360, so the law changes little within a bin, and
/// each bin is sampled at its ends and middle.
const SPEED_BINS: usize = 4096;

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

impl Frame {
    const ALL: [Frame; 3] = [Frame::Driver, Frame::Follower, Frame::Reference];

    fn index(self) -> usize {
        self as usize
    }
}

/// Steps per period of the tables of frame-to-frame maps ([`Kinematics::transform`],
/// [`Kinematics::table`]): 2¹⁴. The exact sweep's branch and bound halves intervals from 32
/// starting ones, so its instants are multiples of 2⁻ᵏ; down to intervals of 2⁻¹⁴ of a
/// period they are read from the table instead of evaluating the law's spline and
/// composing two poses again. The coarse swept field steps through the same table.
pub const TRANSFORM_TABLE: usize = 1 << 14;

/// Per ordered pair of frames, the map `from` → `to` at the instants j / [`TRANSFORM_TABLE`],
/// each table built when first asked for (the same function at the same instant, so a
/// value read from it is bit for bit the one computed).
#[derive(Clone, Default)]
struct TransformTables([OnceLock<Vec<Isometry3<f64>>>; 9]);

impl std::fmt::Debug for TransformTables {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let built = self.0.iter().filter(|t| t.get().is_some()).count();
        write!(f, "TransformTables {{ built: {built} of 9 }}")
    }
}

/// Frames: D (driver), F (follower), R (reference = support). Poses map a frame into R.
#[derive(Clone, Debug)]
pub struct Kinematics {
    law: Motion,
    class: Class,
    scale_mm: f64,
    dx_mm: f64,
    /// Largest |ω₂| over the period, rad per period.
    omega_max: f64,
    /// Largest |Ṫ₂|, mm per period.
    vel_max: f64,
    /// Largest |T₂|, mm.
    trans_max: f64,
    /// Per ordered pair of frames (`from.index() * 3 + to.index()`; empty when equal).
    within: Vec<IntervalSpeed>,
    /// The maps between frames at the table's instants.
    tables: TransformTables,
}

/// How fast the points of one frame move in another over any interval of time: a point p
/// moves no faster than spin·|p| + drift, each the largest over the interval's bins (the
/// pairs of `bins`, spin first).
#[derive(Clone, Debug, Default)]
struct IntervalSpeed {
    bins: BinMax,
}

/// The largest of per-bin pairs of values over any run of bins of one period, each of the
/// two on its own (a sparse table: level k holds the maxima of the runs of 2ᵏ bins that do
/// not wrap). The two are kept side by side so that a query finds its bins once and reads
/// one place per end: the carve asks for both at every interval it bounds, and perf put a
/// tenth of the driver stage here when they were two tables (the index worked out twice,
/// with libm's `floor`, `ceil` and `fmod`).
#[derive(Clone, Debug, Default)]
struct BinMax {
    levels: Vec<Vec<[f64; 2]>>,
}

/// Each of two pairs' values, the larger.
fn pair_max(a: [f64; 2], b: [f64; 2]) -> [f64; 2] {
    [a[0].max(b[0]), a[1].max(b[1])]
}

impl BinMax {
    fn new(bins: Vec<[f64; 2]>) -> BinMax {
        let mut levels = vec![bins];
        let mut run = 1;
        while 2 * run <= levels[0].len() {
            let prev = levels.last().expect("level 0 is there");
            let next: Vec<[f64; 2]> = (0..prev.len() - run)
                .map(|i| pair_max(prev[i], prev[i + run]))
                .collect();
            levels.push(next);
            run *= 2;
        }
        BinMax { levels }
    }

    /// The largest values of bins `lo..=hi` (0 ≤ lo ≤ hi < bins).
    fn run(&self, lo: usize, hi: usize) -> [f64; 2] {
        let k = (hi - lo + 1).ilog2() as usize;
        pair_max(self.levels[k][lo], self.levels[k][hi + 1 - (1 << k)])
    }

    /// The largest values of the bins that meet [t0, t1] (fractions of a period, any reals
    /// within ±2⁵³ bins; the period wraps).
    fn over(&self, t0: f64, t1: f64) -> [f64; 2] {
        let n = self.levels[0].len();
        let first = floor_int(t0 * n as f64);
        let last = (ceil_int(t1 * n as f64) - 1).max(first);
        if last - first + 1 >= n as i64 {
            return self.run(0, n - 1);
        }
        // Nearly every interval asked starts within the period: no integer division then.
        let lo = if (0..n as i64).contains(&first) {
            first as usize
        } else {
            first.rem_euclid(n as i64) as usize
        };
        let hi = lo + (last - first) as usize;
        if hi < n {
            self.run(lo, hi)
        } else {
            pair_max(self.run(lo, n - 1), self.run(0, hi - n))
        }
    }
}

/// ⌊x⌋ as an integer, without a call to libm (x within ±2⁵³).
fn floor_int(x: f64) -> i64 {
    let i = x as i64;
    if (i as f64) > x {
        i - 1
    } else {
        i
    }
}

/// ⌈x⌉ as an integer, without a call to libm (x within ±2⁵³).
fn ceil_int(x: f64) -> i64 {
    let i = x as i64;
    if (i as f64) < x {
        i + 1
    } else {
        i
    }
}

fn class_of(c: Class) -> MotionClass {
    match c {
        Class::R1 => MotionClass::R1,
        Class::R1T1 => MotionClass::R1T1,
        Class::R3 => MotionClass::R3,
    }
}

impl Kinematics {
    /// The motion of `mech`'s parts at `scale_mm` mm per model unit.
    pub fn new(mech: &Mechanism, scale_mm: f64) -> Result<Kinematics, BuildError> {
        let rows: Vec<DenseRow> = mech
            .follower_motion
            .iter()
            .map(|f| DenseRow {
                t: f.t,
                rotation: UnitQuaternion::new_normalize(nalgebra::Quaternion::new(
                    f.rotation[0],
                    f.rotation[1],
                    f.rotation[2],
                    f.rotation[3],
                )),
                translation: Vector3::new(f.translation[0], f.translation[1], f.translation[2]),
            })
            .collect();
        let law = Motion::from_dense(class_of(mech.class), &mech.motion.name, &rows)
            .map_err(|e| BuildError::Motion(e.to_string()))?;
        let mut k = Kinematics {
            law,
            class: mech.class,
            scale_mm,
            dx_mm: mech.driver_offset * scale_mm,
            omega_max: 0.0,
            vel_max: 0.0,
            trans_max: 0.0,
            within: Vec::new(),
            tables: TransformTables::default(),
        };
        k.within = k.interval_speeds();
        for i in 0..SPEED_SAMPLES {
            let s = k.law.sample(i as f64 / SPEED_SAMPLES as f64);
            k.omega_max = k.omega_max.max(s.angular_velocity.norm());
            k.vel_max = k.vel_max.max(s.velocity.norm() * scale_mm);
            k.trans_max = k.trans_max.max(s.translation.norm() * scale_mm);
        }
        k.omega_max *= SPEED_SAFETY;
        k.vel_max *= SPEED_SAFETY;
        Ok(k)
    }

    /// The mechanism's class.
    pub fn class(&self) -> Class {
        self.class
    }

    /// Millimetres per model unit.
    pub fn scale_mm(&self) -> f64 {
        self.scale_mm
    }

    /// Driver offset d_x, mm.
    pub fn dx_mm(&self) -> f64 {
        self.dx_mm
    }

    /// Largest |T₂| over the period, mm.
    pub fn translation_max_mm(&self) -> f64 {
        self.trans_max
    }

    /// Follower pose: F → R at time `t` (fraction of a period).
    pub fn follower(&self, t: f64) -> Isometry3<f64> {
        let s = self.law.sample(t);
        Isometry3::from_parts(
            Translation3::from(s.translation * self.scale_mm),
            s.rotation,
        )
    }

    /// Driver pose: D → R at time `t`.
    pub fn driver(&self, t: f64) -> Isometry3<f64> {
        Isometry3::from_parts(
            Translation3::new(self.dx_mm, 0.0, 0.0),
            UnitQuaternion::from_axis_angle(&Vector3::z_axis(), std::f64::consts::TAU * t),
        )
    }

    /// A frame's angular velocity ω, origin T and the origin's velocity Ṫ, all in the
    /// reference frame at time `t` (rad and mm per period).
    fn rates(&self, f: Frame, t: f64) -> [Vector3<f64>; 3] {
        match f {
            Frame::Reference => [Vector3::zeros(); 3],
            Frame::Driver => [
                Vector3::z() * std::f64::consts::TAU,
                Vector3::new(self.dx_mm, 0.0, 0.0),
                Vector3::zeros(),
            ],
            Frame::Follower => {
                let s = self.law.sample(t);
                [
                    s.angular_velocity,
                    s.translation * self.scale_mm,
                    s.velocity * self.scale_mm,
                ]
            }
        }
    }

    /// The tables of [`Kinematics::speed_within`]: per ordered pair of frames, the spin and
    /// drift of each bin, the largest of the bin's ends and middle raised by
    /// [`SPEED_SAFETY`].
    fn interval_speeds(&self) -> Vec<IntervalSpeed> {
        let n = SPEED_BINS;
        let rates: Vec<[[Vector3<f64>; 3]; 3]> = (0..=2 * n)
            .map(|j| Frame::ALL.map(|f| self.rates(f, j as f64 / (2 * n) as f64)))
            .collect();
        let mut out = vec![IntervalSpeed::default(); 9];
        for from in Frame::ALL {
            for to in Frame::ALL.into_iter().filter(|&to| to != from) {
                let rate: Vec<[f64; 2]> = rates
                    .iter()
                    .map(|r| {
                        let [wa, ta, va] = r[from.index()];
                        let [wb, tb, vb] = r[to.index()];
                        [(wa - wb).norm(), (va - vb - wb.cross(&(ta - tb))).norm()]
                    })
                    .collect();
                let bins = (0..n)
                    .map(|i| {
                        let most =
                            pair_max(pair_max(rate[2 * i], rate[2 * i + 1]), rate[2 * i + 2]);
                        most.map(|x| x * SPEED_SAFETY)
                    })
                    .collect();
                out[from.index() * 3 + to.index()] = IntervalSpeed {
                    bins: BinMax::new(bins),
                };
            }
        }
        out
    }

    /// Bound on the speed (mm per period) of a point of frame `from` at distance `p_norm`
    /// from its origin, seen from frame `to`, at any time of [t0, t1]. With poses (R, T)
    /// into the reference frame, the point's place y = R_Bᵀ(R_A p + T_A − T_B) in B moves at
    /// ẏ = R_Bᵀ((ω_A − ω_B) × R_A p + Ṫ_A − Ṫ_B − ω_B × (T_A − T_B)), so
    /// |ẏ| ≤ |ω_A − ω_B|·|p| + |Ṫ_A − Ṫ_B − ω_B × (T_A − T_B)|, each term taken at its
    /// largest over the interval's bins. Where the law is slow this is far below the
    /// bounds over the whole period.
    pub fn speed_within(&self, from: Frame, to: Frame, p_norm: f64, t0: f64, t1: f64) -> f64 {
        let (spin, drift) = self.spin_drift_within(from, to, t0, t1);
        spin * p_norm + drift
    }

    /// The two terms of [`Kinematics::speed_within`] over [t0, t1]: the largest
    /// |ω_A − ω_B| (rad per period) and the largest |Ṫ_A − Ṫ_B − ω_B × (T_A − T_B)| (mm per
    /// period), for callers that bound many points of one interval.
    pub fn spin_drift_within(&self, from: Frame, to: Frame, t0: f64, t1: f64) -> (f64, f64) {
        if from == to {
            return (0.0, 0.0);
        }
        let [spin, drift] = self.within[from.index() * 3 + to.index()].bins.over(t0, t1);
        (spin, drift)
    }

    /// The map from frame `from` to frame `to` at time `t`. At the instants of the table
    /// (the multiples of 2⁻¹⁴ of a period) it is read from there.
    pub fn transform(&self, from: Frame, to: Frame, t: f64) -> Isometry3<f64> {
        let n = TRANSFORM_TABLE as f64;
        // t·2¹⁴ is exact, so an integer j means t = j / 2¹⁴ exactly.
        let j = t * n;
        // An integer test by a cast (`fract` calls libm's `trunc` on this target).
        if (0.0..n).contains(&j) && (j as usize) as f64 == j {
            return self.table(from, to)[j as usize];
        }
        self.transform_at(from, to, t)
    }

    /// The maps from frame `from` to frame `to` at the instants j / [`TRANSFORM_TABLE`] of
    /// a period, j = 0 … [`TRANSFORM_TABLE`] − 1, built when first asked for.
    pub fn table(&self, from: Frame, to: Frame) -> &[Isometry3<f64>] {
        self.tables.0[from.index() * 3 + to.index()].get_or_init(|| {
            let n = TRANSFORM_TABLE as f64;
            (0..TRANSFORM_TABLE)
                .map(|j| self.transform_at(from, to, j as f64 / n))
                .collect()
        })
    }

    /// [`Self::transform`] evaluated.
    fn transform_at(&self, from: Frame, to: Frame, t: f64) -> Isometry3<f64> {
        let pose = |f: Frame| match f {
            Frame::Driver => self.driver(t),
            Frame::Follower => self.follower(t),
            Frame::Reference => Isometry3::identity(),
        };
        pose(to).inverse() * pose(from)
    }

    /// D → F at time `t`.
    pub fn driver_to_follower(&self, t: f64) -> Isometry3<f64> {
        self.transform(Frame::Driver, Frame::Follower, t)
    }

    /// F → D at time `t`.
    pub fn follower_to_driver(&self, t: f64) -> Isometry3<f64> {
        self.transform(Frame::Follower, Frame::Driver, t)
    }

    /// Bound on the speed (mm per period) of the driver point `p` (D frame) seen from the
    /// follower: |ẏ| ≤ 2π|p_xy| + |Ṫ₂| + |ω₂|·|x − T₂| with x its place in R.
    pub fn speed_driver_point_in_follower(&self, p: Vector3<f64>) -> f64 {
        let r = p.xy().norm();
        let x = ((self.dx_mm + r).powi(2) + p.z * p.z).sqrt();
        std::f64::consts::TAU * r + self.vel_max + self.omega_max * (x + self.trans_max)
    }

    /// Bound on the speed of the follower point `q` (F frame) seen from the driver:
    /// |ż| ≤ |ω₂||q| + |Ṫ₂| + 2π·|R₂q + T₂ − d|_xy.
    pub fn speed_follower_point_in_driver(&self, q: Vector3<f64>) -> f64 {
        let l = q.norm();
        self.omega_max * l
            + self.vel_max
            + std::f64::consts::TAU * (l + self.trans_max + self.dx_mm)
    }

    /// Bound on the speed of the support point `x` (R frame) seen from the follower.
    pub fn speed_support_point_in_follower(&self, x: Vector3<f64>) -> f64 {
        self.omega_max * (x.norm() + self.trans_max) + self.vel_max
    }

    /// Bound on the speed of the support point `x` (R frame) seen from the driver.
    pub fn speed_support_point_in_driver(&self, x: Vector3<f64>) -> f64 {
        std::f64::consts::TAU * (x.xy() - Vector3::new(self.dx_mm, 0.0, 0.0).xy()).norm()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::build::tests::half_turn;
    use nalgebra::Point3;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// Contact points must coincide within this, mm: the file's own coincidence tolerance
    /// (1e-6 model units, conventions.md) at 10 mm per unit, widened for the law's spline
    /// between its 360 keys.
    const COINCIDENT_MM: f64 = 1e-3;

    /// Guards the sparse table behind the per-interval bounds: over seeded random intervals,
    /// some wrapping past the period's end and some longer than it, the largest bin equals
    /// the brute-force largest of the bins the interval meets.
    #[test]
    fn bin_maxima_are_the_largest_over_the_bins_met() {
        let mut rng = ChaCha8Rng::seed_from_u64(31);
        let bins: Vec<[f64; 2]> = (0..37)
            .map(|_| [rng.random::<f64>(), rng.random::<f64>()])
            .collect();
        let table = BinMax::new(bins.clone());
        let n = bins.len() as f64;
        for _ in 0..2000 {
            let t0 = rng.random_range(-1.5..1.5);
            let t1 = t0 + rng.random_range(0.0..1.2);
            let first = (t0 * n).floor() as i64;
            let last = (((t1 * n).ceil() as i64) - 1).max(first);
            let brute = (first..=last)
                .map(|i| bins[i.rem_euclid(bins.len() as i64) as usize])
                .fold([f64::NEG_INFINITY; 2], pair_max);
            assert_eq!(table.over(t0, t1), brute, "[{t0}, {t1}]");
        }
        // Ends on bin boundaries, where floor and ceil meet.
        for (t0, t1) in [(0.0, 1.0 / n), (-2.0 / n, 3.0 / n), (5.0 / n, 5.0 / n)] {
            let first = (t0 * n).floor() as i64;
            let last = (((t1 * n).ceil() as i64) - 1).max(first);
            let brute = (first..=last)
                .map(|i| bins[i.rem_euclid(bins.len() as i64) as usize])
                .fold([f64::NEG_INFINITY; 2], pair_max);
            assert_eq!(table.over(t0, t1), brute, "[{t0}, {t1}]");
        }
    }

    /// Guards the per-interval speed bounds the exact sweeps prune with: for every ordered
    /// pair of frames, seeded random points and intervals, no point moves faster (by finite
    /// differences of its place, at 40 instants of the interval) than
    /// [`Kinematics::speed_within`] says; and over intervals of 1/64 period the bound of the
    /// driver's points in the follower is on average well under the bound over the period
    /// (the follower's speed varies fourfold over this law).
    #[test]
    fn interval_speeds_bound_the_motion_and_are_tighter_than_the_period_s() {
        let (_, kin) = half_turn();
        let place =
            |from: Frame, to: Frame, p: &Point3<f64>, t: f64| kin.transform(from, to, t) * p;
        let mut rng = ChaCha8Rng::seed_from_u64(32);
        let e = 1e-7;
        for from in Frame::ALL {
            for to in Frame::ALL {
                for _ in 0..50 {
                    let p = Point3::new(
                        rng.random_range(-60.0..60.0),
                        rng.random_range(-60.0..60.0),
                        rng.random_range(-30.0..30.0),
                    );
                    let t0 = rng.random_range(0.0..1.0);
                    let t1 = t0 + rng.random_range(1e-4..0.3);
                    let bound = kin.speed_within(from, to, p.coords.norm(), t0, t1);
                    for i in 0..40 {
                        let t = t0 + (t1 - t0) * (i as f64 + 0.5) / 40.0;
                        let v = (place(from, to, &p, t + e) - place(from, to, &p, t - e)).norm()
                            / (2.0 * e);
                        assert!(
                            v <= bound * (1.0 + 1e-6) + 1e-6,
                            "{from:?} → {to:?} at {t}: {v} > {bound} mm per period"
                        );
                    }
                }
            }
        }
        let (mut within, mut period) = (0.0, 0.0);
        for i in 0..64 {
            let p = Vector3::new(30.0 * (i as f64).cos(), 30.0 * (i as f64).sin(), 5.0);
            let t0 = i as f64 / 64.0;
            within += kin.speed_within(
                Frame::Driver,
                Frame::Follower,
                p.norm(),
                t0,
                t0 + 1.0 / 64.0,
            );
            period += kin.speed_driver_point_in_follower(p);
        }
        assert!(within < 0.5 * period, "{within} against {period}");
    }

    /// Guards the tables of frame-to-frame maps: at instants on the table (its first and
    /// last, the sweep's start centres, seeded random ones) and off it (between two of its
    /// instants, before 0 and at 1), every ordered pair of frames gets bit for bit the map
    /// computed at that instant, so the carve's values do not depend on the table.
    #[test]
    fn tabled_maps_are_the_computed_ones() {
        let (_, kin) = half_turn();
        let n = TRANSFORM_TABLE as f64;
        let mut rng = ChaCha8Rng::seed_from_u64(33);
        let mut instants: Vec<f64> = vec![0.0, (n - 1.0) / n, 1.0 / 64.0, 63.0 / 64.0];
        instants.extend((0..40).map(|_| rng.random_range(0..TRANSFORM_TABLE) as f64 / n));
        instants.extend([0.5 / n, 1.0, -1.0 / n, rng.random_range(0.0..1.0)]);
        for from in Frame::ALL {
            for to in Frame::ALL {
                for &t in &instants {
                    assert_eq!(
                        kin.transform(from, to, t),
                        kin.transform_at(from, to, t),
                        "{from:?} → {to:?} at {t}"
                    );
                }
            }
        }
        assert!(kin.tables.0.iter().all(|t| t.get().is_some()));
    }

    /// Guards the frames every part is posed in: at each sample of each curve pair, the
    /// driver point c¹ posed by `driver(t)` and the follower point c² posed by
    /// `follower(t)` land on the same point p of R (scaled to mm), as the mechanism file
    /// says (R₂c² + T₂ = p = Rz(φ)c¹ + D).
    #[test]
    fn parts_posed_by_the_law_meet_at_the_contacts() {
        let (mech, kin) = half_turn();
        let s = kin.scale_mm();
        let mut worst: f64 = 0.0;
        for cp in &mech.curve_pairs {
            let n = cp.samples.p.len();
            for i in (0..n).step_by(7) {
                let t = i as f64 / n as f64;
                let mm = |a: [f64; 3]| Point3::new(a[0] * s, a[1] * s, a[2] * s);
                let by_driver = kin.driver(t) * mm(cp.samples.c1[i]);
                let by_follower = kin.follower(t) * mm(cp.samples.c2[i]);
                let p = mm(cp.samples.p[i]);
                worst = worst
                    .max((by_driver - p).norm())
                    .max((by_follower - p).norm());
            }
        }
        assert!(worst < COINCIDENT_MM, "worst {worst} mm");
    }
}
