//! The relative motion of the parts over one period, in millimetres.
//!
//! Owns [`Kinematics`]: the follower's pose M²(t) (the periodic law interpolating the
//! mechanism's `follower_motion`, scaled to mm), the driver's pose (a turn of 2πt about the
//! axis through (d_x, 0, 0)), the maps between the driver, follower and support (reference)
//! frames, and bounds on how fast a point of one frame moves in another (mm per period),
//! which the swept-volume code uses to sample time finely enough and to bound distances
//! between samples. It does not know the parts' shapes.

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
        };
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

    /// D → F at time `t`.
    pub fn driver_to_follower(&self, t: f64) -> Isometry3<f64> {
        self.follower(t).inverse() * self.driver(t)
    }

    /// F → D at time `t`.
    pub fn follower_to_driver(&self, t: f64) -> Isometry3<f64> {
        self.driver(t).inverse() * self.follower(t)
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
    use nalgebra::Point3;

    /// Contact points must coincide within this, mm: the file's own coincidence tolerance
    /// (1e-6 model units, conventions.md) at 10 mm per unit, widened for the law's spline
    /// between its 360 keys.
    const COINCIDENT_MM: f64 = 1e-3;

    /// Guards the frames every part is posed in: at each sample of each curve pair, the
    /// driver point c¹ posed by `driver(t)` and the follower point c² posed by
    /// `follower(t)` land on the same point p of R (scaled to mm), as the mechanism file
    /// says (R₂c² + T₂ = p = Rz(φ)c¹ + D).
    #[test]
    fn parts_posed_by_the_law_meet_at_the_contacts() {
        let file = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("tests/data/mechanism/half-turn-2to1/mechanism.json");
        let mech = Mechanism::load(&file).expect("the test mechanism loads");
        let s = 10.0;
        let kin = Kinematics::new(&mech, s).expect("its law rebuilds");
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
