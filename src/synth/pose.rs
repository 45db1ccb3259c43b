//! The follower motion as the synthesis sees it: poses and their time derivatives sampled
//! over one period.
//!
//! Owns [`Pose`] (rotation matrix, translation, angular and linear velocity of M²(t)) and
//! [`PoseTrack`] (N samples plus a way to evaluate any t, for oversampled checks). It is
//! built from a [`crate::motion::Motion`] or, in tests, from any function of t. It does not
//! interpolate keyframes (the motion module does).

use std::f64::consts::TAU;
use std::sync::Arc;

use super::math::{mat3_of, quaternion_of, rz, Mat3, UnitQuaternion, Vector3, V3};

/// One follower pose with first derivatives, in frame R.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Pose {
    /// t ∈ [0, 1).
    pub t: f64,
    /// R₂(t).
    pub rot: Mat3,
    /// T₂(t).
    pub trans: [f64; 3],
    /// ω (`dR₂/dt = [ω]ₓ R₂`), per unit t.
    pub omega: [f64; 3],
    /// dT₂/dt.
    pub vel: [f64; 3],
    /// The driver's rotation Rz(φ) at t, φ = 2πt: kept with the pose because the candidate
    /// problem maps every sample into the driver frame at every evaluation.
    pub driver: Mat3,
}

impl Pose {
    /// From a unit quaternion and vectors.
    pub fn new(
        t: f64,
        q: &UnitQuaternion<f64>,
        trans: Vector3<f64>,
        omega: Vector3<f64>,
        vel: Vector3<f64>,
    ) -> Self {
        Self {
            t,
            rot: mat3_of(q),
            trans: trans.into(),
            omega: omega.into(),
            vel: vel.into(),
            driver: rz(TAU * t),
        }
    }

    /// Rotation as a unit quaternion.
    pub fn quaternion(&self) -> UnitQuaternion<f64> {
        quaternion_of(&self.rot)
    }
}

/// Function giving the pose at any t (periodic).
pub type PoseFn = Arc<dyn Fn(f64) -> Pose + Send + Sync>;

/// The follower motion sampled at tᵢ = i/N, plus the underlying function of t.
#[derive(Clone)]
pub struct PoseTrack {
    /// Samples i = 0..N−1.
    pub samples: Vec<Pose>,
    /// Pose at any t.
    pub at: PoseFn,
}

impl std::fmt::Debug for PoseTrack {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("PoseTrack")
            .field("n", &self.samples.len())
            .finish()
    }
}

impl PoseTrack {
    /// Sample `at` at N points.
    pub fn from_fn(n: usize, at: PoseFn) -> Self {
        let samples = (0..n).map(|i| at(i as f64 / n as f64)).collect();
        Self { samples, at }
    }

    /// From a motion specification (poses and derivatives from `Motion::sample`).
    pub fn from_motion(motion: &crate::motion::Motion, n: usize) -> Self {
        let m = motion.clone();
        let at: PoseFn = Arc::new(move |t: f64| {
            let s = m.sample(t);
            Pose::new(
                t,
                &s.rotation,
                s.translation,
                s.angular_velocity,
                s.velocity,
            )
        });
        Self::from_fn(n, at)
    }

    /// Number of samples N.
    pub fn len(&self) -> usize {
        self.samples.len()
    }

    /// Whether there are no samples.
    pub fn is_empty(&self) -> bool {
        self.samples.is_empty()
    }

    /// Share of the samples at which the follower stands still (|ω| and |dT₂/dt| at most
    /// [`STILL_SPEED`]).
    pub fn still_share(&self) -> f64 {
        let still = self.samples.iter().filter(|p| p.is_still()).count();
        still as f64 / self.len().max(1) as f64
    }
}

/// Follower speed below which a pose counts as standing still: angular speed in radians per
/// period and linear speed in model units per period. Default 1e-6: a dwell of the motion
/// schemes is exactly still (zero to round-off), and no sample of the examples without
/// dwells comes below it (`bands::tests::only_the_dwell_example_gets_the_dwell_layout`).
pub const STILL_SPEED: f64 = 1e-6;

impl Pose {
    /// Whether the follower stands still at this pose.
    pub fn is_still(&self) -> bool {
        V3::from(self.omega).norm() <= STILL_SPEED && V3::from(self.vel).norm() <= STILL_SPEED
    }
}

/// A 1R pose about z with angle, rate (per unit t): used by tests and benchmarks.
pub fn pose_1r(t: f64, angle: f64, rate: f64) -> Pose {
    let (s, c) = angle.sin_cos();
    Pose {
        t,
        rot: [[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]],
        trans: [0.0; 3],
        omega: [0.0, 0.0, rate],
        vel: [0.0; 3],
        driver: rz(TAU * t),
    }
}
