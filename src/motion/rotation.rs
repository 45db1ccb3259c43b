//! Rotations: the C² orientation law of 3R motions and the conversions from the ways users
//! write an orientation.
//!
//! **Interpolation on SO(3).** The keyframe quaternions are first made sign-continuous
//! (each one is negated if that brings it closer to its predecessor, so consecutive keys are
//! at most 180° apart on the quaternion sphere and the path never takes the long way round).
//! The four components are then interpolated by one periodic cubic spline
//! (the `spline` module), and the result p(t) is normalized: q(t) = p(t)/|p(t)|. If the loop
//! of keys closes with a sign flip (the last key is nearer to −q₀ than to q₀: the motion
//! contains a net turn that is not contractible in SO(3)), the spline is anti-periodic,
//! p(t + 1) = −p(t), which describes the same rotations. Normalization keeps every key
//! exactly, is smooth wherever p ≠ 0 (keys closer than [`MAX_KEY_STEP_DEG`] guarantee that
//! in practice) and gives a C² rotation law. Euler angles are never interpolated.
//!
//! **Derivatives.** With r = |p|: q′ = (p′ − q r′)/r and q″ = (p″ − 2q′r′ − q r″)/r where
//! r′ = q·p′ and r″ = (|p′|² + p·p″ − r′²)/r. The angular velocity in the reference frame R
//! (dR/dt = \[ω\]ₓR) is ω = 2·vec(q′ q̄) and its derivative is ω′ = 2·vec(q″ q̄) (the term
//! q′ q̄′ = |q′|² is real).

use nalgebra::{Quaternion, UnitQuaternion, Vector3, Vector4};

use super::spline::PeriodicSpline;

/// Consecutive keyframe orientations farther apart than this (degrees) are rejected: the
/// spline through nearly opposite quaternions can pass close to zero, where normalizing is
/// ill-conditioned, and the user's intended way round is ambiguous. 170° leaves room for
/// large but deliberate steps; add an intermediate keyframe for anything larger.
pub const MAX_KEY_STEP_DEG: f64 = 170.0;

/// The C² orientation law q(t) of a 3R motion.
#[derive(Debug, Clone)]
pub(crate) struct RotationLaw {
    spline: PeriodicSpline<4>,
}

/// Orientation with its angular velocity and acceleration in the reference frame.
#[derive(Debug, Clone, Copy)]
pub(crate) struct RotationJet {
    pub rotation: UnitQuaternion<f64>,
    pub angular_velocity: Vector3<f64>,
    pub angular_acceleration: Vector3<f64>,
}

impl RotationLaw {
    /// Build the law through the keyframe orientations at `knots` (validated by the
    /// caller: increasing, within one period, non-empty).
    pub(crate) fn new(knots: &[f64], keys: &[UnitQuaternion<f64>]) -> Self {
        let mut values: Vec<[f64; 4]> = Vec::with_capacity(keys.len());
        for q in keys {
            let mut v = quat_to_array(q);
            if let Some(prev) = values.last() {
                if dot4(prev, &v) < 0.0 {
                    v = v.map(|x| -x);
                }
            }
            values.push(v);
        }
        let sign = if dot4(&values[values.len() - 1], &values[0]) < 0.0 {
            -1.0
        } else {
            1.0
        };
        Self {
            spline: PeriodicSpline::new(knots, &values, sign, [0.0; 4]),
        }
    }

    /// Orientation and derivatives at any real t.
    pub(crate) fn eval(&self, t: f64) -> RotationJet {
        let [p, dp, ddp] = self.spline.eval(t).map(Vector4::from);
        let r = p.norm();
        let q = p / r;
        let r1 = q.dot(&dp);
        let q1 = (dp - q * r1) / r;
        let r2 = (dp.norm_squared() + p.dot(&ddp) - r1 * r1) / r;
        let q2 = (ddp - q1 * (2.0 * r1) - q * r2) / r;
        let qq = Quaternion::new(q[0], q[1], q[2], q[3]);
        let conj = qq.conjugate();
        let w = (Quaternion::new(q1[0], q1[1], q1[2], q1[3]) * conj).vector() * 2.0;
        let a = (Quaternion::new(q2[0], q2[1], q2[2], q2[3]) * conj).vector() * 2.0;
        RotationJet {
            rotation: UnitQuaternion::new_unchecked(qq),
            angular_velocity: w.into_owned(),
            angular_acceleration: a.into_owned(),
        }
    }
}

fn dot4(a: &[f64; 4], b: &[f64; 4]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

/// `[w, x, y, z]` of a unit quaternion (scalar first).
pub fn quat_to_array(q: &UnitQuaternion<f64>) -> [f64; 4] {
    [q.w, q.i, q.j, q.k]
}

/// Rotation by `angle_deg` degrees about `axis` (any non-zero length); `None` for a zero or
/// non-finite axis.
pub fn from_axis_angle_deg(axis: [f64; 3], angle_deg: f64) -> Option<UnitQuaternion<f64>> {
    let v = Vector3::from(axis);
    let n = v.norm();
    if !(n.is_finite() && n > 0.0 && angle_deg.is_finite()) {
        return None;
    }
    Some(UnitQuaternion::from_axis_angle(
        &nalgebra::Unit::new_unchecked(v / n),
        angle_deg.to_radians(),
    ))
}

/// Intrinsic Z-Y′-X″ Euler angles in degrees (yaw about z, then pitch about the new y, then
/// roll about the newest x): R = Rz(z)·Ry(y)·Rx(x).
pub fn from_euler_zyx_deg(z: f64, y: f64, x: f64) -> UnitQuaternion<f64> {
    UnitQuaternion::from_axis_angle(&Vector3::z_axis(), z.to_radians())
        * UnitQuaternion::from_axis_angle(&Vector3::y_axis(), y.to_radians())
        * UnitQuaternion::from_axis_angle(&Vector3::x_axis(), x.to_radians())
}

/// The follower-local axis that is the 3R *end-effector axis*: +z, pointing out of the
/// spherical joint like a joystick. At rest (identity) it points along +z of frame R.
pub fn end_effector_axis() -> Vector3<f64> {
    Vector3::z()
}

/// Orientation from the end-effector axis direction and a roll about that axis (degrees).
///
/// R = T·Rz(roll), where T = Rz(azimuth)·Ry(90° − elevation)·Rz(−azimuth) is the *swing*:
/// the smallest rotation that tips the axis from rest (+z) to the direction at `azimuth`
/// (from +x towards +y) and `elevation` (above the xy plane; 90° is rest). Roll turns the
/// follower about its own axis relative to that swing. Because the swing does not spin the
/// follower about z, a path that circles the rest direction does not make the follower
/// turn with it, and at elevation 90° the azimuth has no effect (no singularity at rest).
pub fn from_direction_roll_deg(azimuth: f64, elevation: f64, roll: f64) -> UnitQuaternion<f64> {
    swing(azimuth, 90.0 - elevation)
        * UnitQuaternion::from_axis_angle(&Vector3::z_axis(), roll.to_radians())
}

/// The swing T = Rz(a)·Ry(tilt)·Rz(−a), degrees.
fn swing(azimuth: f64, tilt: f64) -> UnitQuaternion<f64> {
    let rz = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), azimuth.to_radians());
    rz * UnitQuaternion::from_axis_angle(&Vector3::y_axis(), tilt.to_radians()) * rz.inverse()
}

/// Roll (degrees, in (−180°, 180°]) of `q` about the end-effector axis relative to the
/// swing that tips the axis to where it points (the inverse of
/// [`from_direction_roll_deg`]'s roll). Undefined when the axis points straight down; 0
/// is returned there.
pub fn roll_deg(q: &UnitQuaternion<f64>) -> f64 {
    let a = q * end_effector_axis();
    let tilt = a.z.clamp(-1.0, 1.0).acos().to_degrees();
    if tilt > 179.999 {
        return 0.0;
    }
    let az = a.y.atan2(a.x).to_degrees();
    let r = swing(az, tilt).inverse() * q;
    let d = (2.0 * r.k.atan2(r.w)).to_degrees().rem_euclid(360.0);
    if d > 180.0 {
        d - 360.0
    } else {
        d
    }
}

/// Azimuth and elevation (degrees) of the end-effector axis under rotation `q`.
pub fn direction_deg(q: &UnitQuaternion<f64>) -> (f64, f64) {
    let a = q * end_effector_axis();
    let elevation = a.z.clamp(-1.0, 1.0).asin().to_degrees();
    let azimuth = a.y.atan2(a.x).to_degrees();
    (azimuth, elevation)
}

/// Tilt of the end-effector axis away from its rest direction +z, in degrees.
pub fn tilt_deg(q: &UnitQuaternion<f64>) -> f64 {
    let a = q * end_effector_axis();
    a.z.clamp(-1.0, 1.0).acos().to_degrees()
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    fn random_keys(rng: &mut ChaCha8Rng, n: usize) -> (Vec<f64>, Vec<UnitQuaternion<f64>>) {
        let knots: Vec<f64> = (0..n)
            .map(|i| (i as f64 + 0.3 * rng.random::<f64>()) / n as f64)
            .collect();
        let keys = (0..n)
            .map(|_| {
                let q = from_euler_zyx_deg(
                    rng.random_range(-60.0..60.0),
                    rng.random_range(-40.0..40.0),
                    rng.random_range(-40.0..40.0),
                );
                if rng.random_bool(0.5) {
                    UnitQuaternion::new_unchecked(-q.into_inner())
                } else {
                    q
                }
            })
            .collect();
        (knots, keys)
    }

    /// Guards key interpolation on SO(3): keys are reproduced (as rotations) even when
    /// their quaternion signs are scrambled.
    #[test]
    fn hits_keys_with_scrambled_signs() {
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let (knots, keys) = random_keys(&mut rng, 6);
        let law = RotationLaw::new(&knots, &keys);
        for (t, q) in knots.iter().zip(&keys) {
            assert!(law.eval(*t).rotation.angle_to(q) < 1e-12);
        }
    }

    /// Guards quaternion sign continuity: along a densely sampled period (and across the
    /// wrap) consecutive quaternions never jump to the antipode.
    #[test]
    fn quaternion_path_is_continuous() {
        let mut rng = ChaCha8Rng::seed_from_u64(9);
        let (knots, keys) = random_keys(&mut rng, 5);
        let law = RotationLaw::new(&knots, &keys);
        let mut prev = law.eval(-0.01).rotation.into_inner();
        for i in 0..=2000 {
            let q = law.eval(f64::from(i) / 2000.0).rotation.into_inner();
            assert!(q.coords.dot(&prev.coords) > 0.99, "flip at sample {i}");
            prev = q;
        }
    }

    /// Guards the anti-periodic case: a full turn about x in four 90° keys closes at −q₀,
    /// and the law is still continuous (as rotations) across the wrap.
    #[test]
    fn full_turn_loop_is_continuous_across_wrap() {
        let knots = [0.0, 0.25, 0.5, 0.75];
        let keys: Vec<_> = [0.0, 90.0, 180.0, 270.0]
            .iter()
            .map(|&a| from_axis_angle_deg([1.0, 0.0, 0.0], a).unwrap())
            .collect();
        let law = RotationLaw::new(&knots, &keys);
        let (a, b) = (law.eval(1.0 - 1e-7), law.eval(1.0 + 1e-7));
        assert!(a.rotation.angle_to(&b.rotation) < 1e-5);
        assert!((a.angular_velocity - b.angular_velocity).norm() < 1e-4);
        // Uniform turn: ω ≈ 2π about x everywhere.
        let w = law.eval(0.4).angular_velocity;
        assert!((w.x - std::f64::consts::TAU).abs() < 0.2 && w.y.abs() < 1e-9);
    }

    /// Guards ω and ω′ against finite differences of the rotation itself
    /// (ω ≈ log(R(t+e) R(t−e)ᵀ)/2e) and of ω.
    #[test]
    fn angular_derivatives_match_finite_differences() {
        let mut rng = ChaCha8Rng::seed_from_u64(21);
        let (knots, keys) = random_keys(&mut rng, 7);
        let law = RotationLaw::new(&knots, &keys);
        let e = 1e-6;
        for i in 0..100 {
            let t = f64::from(i) / 100.0 + 1e-3;
            let j = law.eval(t);
            let (p, m) = (law.eval(t + e), law.eval(t - e));
            let w_fd = (p.rotation * m.rotation.inverse()).scaled_axis() / (2.0 * e);
            assert!((w_fd - j.angular_velocity).norm() < 1e-5 * (1.0 + j.angular_velocity.norm()));
            let a_fd = (p.angular_velocity - m.angular_velocity) / (2.0 * e);
            assert!((a_fd - j.angular_acceleration).norm() < 1e-4 * (1.0 + a_fd.norm()));
        }
    }

    /// Guards C² continuity of the SO(3) law at every keyframe and across the wrap: the
    /// rotation, ω and dω/dt agree from both sides (after removing the smooth change over
    /// the probe distance).
    #[test]
    fn rotation_law_is_c2_at_keys_and_wrap() {
        let mut rng = ChaCha8Rng::seed_from_u64(33);
        let (knots, keys) = random_keys(&mut rng, 6);
        let law = RotationLaw::new(&knots, &keys);
        let eps = 1e-7;
        let mut joints = knots.clone();
        joints.push(knots[0] + 1.0);
        for &t in &joints {
            let (l, r) = (law.eval(t - eps), law.eval(t + eps));
            assert!(
                l.rotation.angle_to(&r.rotation) < 3.0 * eps * (1.0 + l.angular_velocity.norm())
            );
            let dw = r.angular_velocity
                - l.angular_velocity
                - (l.angular_acceleration + r.angular_acceleration) * eps;
            assert!(
                dw.norm() < 1e-6 * (1.0 + l.angular_velocity.norm()),
                "ω jumps at {t}"
            );
            let da = (r.angular_acceleration - l.angular_acceleration).norm();
            assert!(
                da < 1e-3 * (1.0 + l.angular_acceleration.norm()),
                "dω/dt jumps at {t}: {da}"
            );
        }
    }

    /// Guards the direction/roll convention: the end-effector axis lands at the requested
    /// azimuth and elevation, and roll does not move it.
    #[test]
    fn direction_roll_round_trip() {
        for (az, el, roll) in [
            (30.0, 60.0, 0.0),
            (-120.0, 45.0, 33.0),
            (170.0, 80.0, -90.0),
        ] {
            let q = from_direction_roll_deg(az, el, roll);
            let (a, e) = direction_deg(&q);
            assert!((a - az).abs() < 1e-9 && (e - el).abs() < 1e-9);
            assert!((tilt_deg(&q) - (90.0 - el)).abs() < 1e-9);
            assert!((roll_deg(&q) - roll).abs() < 1e-9);
        }
    }

    /// Guards the swing convention: at rest (elevation 90°) the azimuth has no effect, and
    /// circling the rest direction at constant tilt and zero roll never spins the follower
    /// about z by more than the tilt itself implies (no accumulated turn).
    #[test]
    fn direction_form_does_not_spin_with_azimuth() {
        let a = from_direction_roll_deg(0.0, 90.0, 10.0);
        let b = from_direction_roll_deg(123.0, 90.0, 10.0);
        assert!(a.angle_to(&b) < 1e-12);
        // Quarter steps around a 20° cone: consecutive orientations differ by the swing only.
        let q0 = from_direction_roll_deg(0.0, 70.0, 0.0);
        let q1 = from_direction_roll_deg(90.0, 70.0, 0.0);
        assert!(q0.angle_to(&q1) < 30.0_f64.to_radians());
    }

    /// Guards the Euler convention: R = Rz·Ry·Rx maps x to the yaw/pitch direction.
    #[test]
    fn euler_zyx_convention() {
        let q = from_euler_zyx_deg(90.0, 0.0, 0.0);
        assert!((q * Vector3::x() - Vector3::y()).norm() < 1e-12);
        let q = from_euler_zyx_deg(0.0, 90.0, 0.0);
        assert!((q * Vector3::x() + Vector3::z()).norm() < 1e-12);
        let q = from_euler_zyx_deg(90.0, 0.0, 90.0);
        // Rx first moves y to z, then Rz leaves z.
        assert!((q * Vector3::y() - Vector3::z()).norm() < 1e-12);
    }
}
