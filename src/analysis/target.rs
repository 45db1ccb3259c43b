//! The target law sampled once onto the driver angle, so that the analysis can evaluate it
//! millions of times cheaply.
//!
//! With the driver at angle φ (degrees), the follower must be at M²(φ/360°). A
//! [`TargetLaw`] holds that law per degree of freedom as dense periodic tables over one driver
//! revolution ([`TARGET_TABLE_SAMPLES`] intervals): the unwrapped rotation about z in degrees,
//! the height along z in millimetres, or the 3R orientation. Tables are evaluated by linear
//! interpolation (normalized linear interpolation for quaternions) and extended to any driver
//! angle by periodicity: a 1R law that turns once per period advances by 360° per driver
//! revolution. This module does not read motion files; constructors take closures or a
//! [`crate::motion::Motion`].

use nalgebra::{UnitQuaternion, Vector3};

/// Intervals per driver revolution in the target tables. Default 36 000 (0.01° of driver
/// angle): linear interpolation of a smooth law with |θ''| ≤ 100 rad/rad² is then within
/// 4·10⁻⁶ rad of the law, far below any sensor's resolution, while the tables stay small
/// (≈ 0.3 MB per DOF) and are built in milliseconds.
pub const TARGET_TABLE_SAMPLES: usize = 36_000;

/// Slopes below this magnitude (follower units per driver degree) count as "not moving" when
/// the direction of follower motion is needed (backlash sign). Default 10⁻⁹: only exact
/// dwells, so that slow but moving followers keep their sign.
pub const DWELL_SLOPE: f64 = 1e-9;

/// A scalar law over one driver revolution, extended periodically with a constant advance
/// per revolution.
#[derive(Debug, Clone)]
pub struct PeriodicTable {
    /// Values at φ = 360°·i/n, i = 0..=n (n + 1 entries; the last is the first plus `advance`).
    values: Vec<f64>,
    /// value(φ + 360°) − value(φ).
    advance: f64,
}

impl PeriodicTable {
    /// Sample `f(t)` for t ∈ [0, 1] at `n` intervals. `f(1) − f(0)` becomes the advance per
    /// revolution (360·turns for an unwrapped angle, 0 for a periodic height).
    pub fn from_fn(n: usize, f: impl Fn(f64) -> f64) -> Self {
        let n = n.max(2);
        let values: Vec<f64> = (0..=n).map(|i| f(i as f64 / n as f64)).collect();
        let advance = values[n] - values[0];
        Self { values, advance }
    }

    /// Value and slope (per driver degree) at driver angle `phi_deg` (any real value).
    #[inline]
    pub fn eval(&self, phi_deg: f64) -> (f64, f64) {
        let n = self.values.len() - 1;
        let u = phi_deg / 360.0;
        let k = u.floor();
        let x = (u - k) * n as f64;
        let i = (x as usize).min(n - 1);
        let w = x - i as f64;
        let (a, b) = (self.values[i], self.values[i + 1]);
        let slope = (b - a) * n as f64 / 360.0;
        (a + w * (b - a) + k * self.advance, slope)
    }

    /// Value at driver angle `phi_deg`.
    #[inline]
    pub fn value(&self, phi_deg: f64) -> f64 {
        self.eval(phi_deg).0
    }

    /// Advance per driver revolution.
    pub fn advance(&self) -> f64 {
        self.advance
    }

    /// Smallest and largest value over one revolution.
    pub fn range(&self) -> (f64, f64) {
        self.values
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &v| {
                (lo.min(v), hi.max(v))
            })
    }

    /// The first driver angle φ ∈ [from, from + 360·max_revs] where the law reaches `level`
    /// (exact for the interpolated table), or `None`.
    pub fn first_crossing(&self, level: f64, from_deg: f64, max_revs: f64) -> Option<f64> {
        let n = self.values.len() - 1;
        let step = 360.0 / n as f64;
        let steps = (max_revs * n as f64).ceil() as usize;
        let mut prev = self.value(from_deg);
        if prev == level {
            return Some(from_deg);
        }
        for s in 1..=steps {
            let phi = from_deg + s as f64 * step;
            let v = self.value(phi);
            if (prev - level) * (v - level) <= 0.0 && v != prev {
                let w = (level - prev) / (v - prev);
                return Some(phi - step + w * step);
            }
            prev = v;
        }
        None
    }
}

/// A 3R orientation law over one driver revolution.
#[derive(Debug, Clone)]
pub struct RotationTable {
    /// Unit quaternions (w, x, y, z) at φ = 360°·i/n, i = 0..n, sign-continuous; entry n
    /// repeats entry 0 (sign-matched).
    quats: Vec<[f64; 4]>,
}

impl RotationTable {
    /// Sample `f(t)` for t ∈ [0, 1) at `n` intervals.
    pub fn from_fn(n: usize, f: impl Fn(f64) -> UnitQuaternion<f64>) -> Self {
        let n = n.max(2);
        let mut quats: Vec<[f64; 4]> = Vec::with_capacity(n + 1);
        for i in 0..=n {
            let q = if i == n {
                f(0.0)
            } else {
                f(i as f64 / n as f64)
            };
            let mut c = [q.w, q.i, q.j, q.k];
            if let Some(p) = quats.last() {
                if p[0] * c[0] + p[1] * c[1] + p[2] * c[2] + p[3] * c[3] < 0.0 {
                    c = c.map(|v| -v);
                }
            }
            quats.push(c);
        }
        Self { quats }
    }

    /// Orientation at driver angle `phi_deg` (any real value).
    #[inline]
    pub fn eval(&self, phi_deg: f64) -> UnitQuaternion<f64> {
        let n = self.quats.len() - 1;
        let u = phi_deg / 360.0;
        let x = (u - u.floor()) * n as f64;
        let i = (x as usize).min(n - 1);
        let w = x - i as f64;
        let (a, b) = (self.quats[i], self.quats[i + 1]);
        let q = nalgebra::Quaternion::new(
            a[0] + w * (b[0] - a[0]),
            a[1] + w * (b[1] - a[1]),
            a[2] + w * (b[2] - a[2]),
            a[3] + w * (b[3] - a[3]),
        );
        UnitQuaternion::from_quaternion(q)
    }
}

/// One key pose of a 3R motion, for the per-key-pose report.
#[derive(Debug, Clone, Copy)]
pub struct KeyPose {
    /// Fraction of the period (driver angle / 360°).
    pub t: f64,
    /// Target orientation.
    pub rotation: UnitQuaternion<f64>,
}

/// The target law per degree of freedom, as functions of the driver angle in degrees.
#[derive(Debug, Clone)]
pub struct TargetLaw {
    /// Name of the motion (e.g. `half-turn-2to1`).
    pub name: String,
    /// 1R, 1R1T: unwrapped follower rotation about +z in degrees.
    pub rz_deg: Option<PeriodicTable>,
    /// 1R1T: follower height along z in millimetres.
    pub tz_mm: Option<PeriodicTable>,
    /// 3R: follower orientation.
    pub rotation: Option<RotationTable>,
    /// Key poses (3R), for per-key-pose errors.
    pub key_poses: Vec<KeyPose>,
    /// The motion the tables were built from, when there is one (its charts are reused so
    /// the report draws the axis path on the same plot as `motion show`).
    pub motion: Option<crate::motion::Motion>,
    /// The [`Mechanism::digest`](crate::synth::mechanism::Mechanism::digest) of the
    /// mechanism the law was read from, when it was: a prediction made for another one is
    /// refused.
    pub mechanism_digest: Option<String>,
}

impl TargetLaw {
    /// A 1R law from θ(t) in degrees, t ∈ [0, 1] (θ(1) − θ(0) must be a whole number of
    /// turns for a mechanism; the table takes whatever it is given).
    pub fn rotation_1r(name: &str, theta_deg: impl Fn(f64) -> f64) -> Self {
        Self {
            name: name.to_string(),
            rz_deg: Some(PeriodicTable::from_fn(TARGET_TABLE_SAMPLES, theta_deg)),
            tz_mm: None,
            rotation: None,
            key_poses: Vec::new(),
            motion: None,
            mechanism_digest: None,
        }
    }

    /// A 1R1T law from θ(t) in degrees and h(t) in millimetres.
    pub fn cylindrical(
        name: &str,
        theta_deg: impl Fn(f64) -> f64,
        height_mm: impl Fn(f64) -> f64,
    ) -> Self {
        Self {
            name: name.to_string(),
            rz_deg: Some(PeriodicTable::from_fn(TARGET_TABLE_SAMPLES, theta_deg)),
            tz_mm: Some(PeriodicTable::from_fn(TARGET_TABLE_SAMPLES, height_mm)),
            rotation: None,
            key_poses: Vec::new(),
            motion: None,
            mechanism_digest: None,
        }
    }

    /// A 3R law from R(t), with its key poses.
    pub fn spherical(
        name: &str,
        rotation: impl Fn(f64) -> UnitQuaternion<f64>,
        key_poses: Vec<KeyPose>,
    ) -> Self {
        Self {
            name: name.to_string(),
            rz_deg: None,
            tz_mm: None,
            rotation: Some(RotationTable::from_fn(TARGET_TABLE_SAMPLES, rotation)),
            key_poses,
            motion: None,
            mechanism_digest: None,
        }
    }

    /// The target law of a [`crate::motion::Motion`]: θ(t) from its unwrapped angle, h(t)
    /// in millimetres (`scale_mm` per model unit), R(t) and the key poses for 3R.
    pub fn from_motion(motion: &crate::motion::Motion, scale_mm: f64) -> Self {
        use crate::motion::MotionClass;
        let name = motion.name();
        let angle = |t: f64| motion.angle_z(t).map_or(0.0, |a| a[0].to_degrees());
        let mut law = match motion.class() {
            MotionClass::R1 => Self::rotation_1r(name, angle),
            MotionClass::R1T1 => Self::cylindrical(name, angle, |t| {
                motion.height(t).map_or(0.0, |h| h[0] * scale_mm)
            }),
            MotionClass::R3 => Self::spherical(
                name,
                |t| motion.sample(t).rotation,
                motion
                    .key_poses()
                    .iter()
                    .map(|k| KeyPose {
                        t: k.t,
                        rotation: k.rotation,
                    })
                    .collect(),
            ),
        };
        law.motion = Some(motion.clone());
        law
    }

    /// The motion class this law describes: "1R", "1R1T" or "3R".
    pub fn class_name(&self) -> &'static str {
        match (&self.rz_deg, &self.tz_mm, &self.rotation) {
            (_, _, Some(_)) => "3R",
            (_, Some(_), None) => "1R1T",
            _ => "1R",
        }
    }

    /// Whole follower turns per driver revolution (1R/1R1T), rounded; 0 for 3R.
    pub fn net_turns(&self) -> i64 {
        self.rz_deg
            .as_ref()
            .map_or(0, |t| (t.advance() / 360.0).round() as i64)
    }

    /// The end-effector axis (follower-local +z mapped to the reference frame) at driver
    /// angle `phi_deg`, for 3R laws.
    pub fn axis(&self, phi_deg: f64) -> Option<Vector3<f64>> {
        self.rotation
            .as_ref()
            .map(|r| r.eval(phi_deg) * Vector3::z())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Guards periodic extension: a law turning once per period continues by +360° per driver
    /// revolution, also for negative driver angles, and the table is exact at its nodes.
    #[test]
    fn periodic_table_extends_by_its_advance() {
        let t = PeriodicTable::from_fn(360, |t| {
            360.0 * t + 10.0 * (2.0 * std::f64::consts::PI * t).sin()
        });
        assert!((t.advance() - 360.0).abs() < 1e-12);
        for phi in [0.0, 33.0, 359.0] {
            let base = t.value(phi);
            assert!((t.value(phi + 720.0) - base - 720.0).abs() < 1e-9);
            assert!((t.value(phi - 360.0) - base + 360.0).abs() < 1e-9);
        }
        // Node exactness: φ = 90° is node 90.
        assert!((t.value(90.0) - (90.0 + 10.0)).abs() < 1e-9);
    }

    /// Guards the inverse used for target timing: the first crossing of 180° of a
    /// piecewise-linear 2:1 law is at exactly 240° of driver angle.
    #[test]
    fn first_crossing_inverts_piecewise_linear_law() {
        let t = PeriodicTable::from_fn(36_000, |t| {
            if t <= 2.0 / 3.0 {
                270.0 * t
            } else {
                180.0 + 540.0 * (t - 2.0 / 3.0)
            }
        });
        let phi = t.first_crossing(180.0, 0.0, 1.0).unwrap();
        assert!((phi - 240.0).abs() < 1e-9, "{phi}");
        let phi = t.first_crossing(360.0, 0.0, 1.5).unwrap();
        assert!((phi - 360.0).abs() < 1e-9, "{phi}");
    }

    /// Guards the quaternion table: interpolation stays unit length and matches the law
    /// between nodes to well below a hundredth of a degree.
    #[test]
    fn rotation_table_interpolates_smoothly() {
        let law = |t: f64| {
            UnitQuaternion::from_euler_angles(
                0.5 * (std::f64::consts::TAU * t).sin(),
                0.3,
                std::f64::consts::TAU * t,
            )
        };
        let tab = RotationTable::from_fn(3600, law);
        for i in 0..100 {
            let phi = i as f64 * 3.7 + 0.05;
            let err = tab.eval(phi).angle_to(&law(phi / 360.0));
            assert!(err < 1e-5, "phi {phi}: {err}");
        }
    }
}
