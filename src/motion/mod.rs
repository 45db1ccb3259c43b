//! Motion specifications: what the follower must do over one period.
//!
//! Owns parsing (TOML keyframes, dense CSV, the follower motion stored in `mechanism.json`),
//! validation with file/line/field errors, periodic C² interpolation (on SO(3) for
//! rotations), sampling of poses with analytic first and second time derivatives, and the
//! *target law* (follower pose as a function of the driver angle, `sample(φ / 2π)`) that
//! the bench compares against. It does not synthesize anything and knows nothing of curve
//! pairs. Its pictures ([`figures`]) decide what to show and draw through [`crate::plot`].
//!
//! # Time and frames
//! t is the fraction of one period (one driver revolution), keys lie in `[0, 1)`, and the
//! law repeats: a 1R/1R1T angle gains `2π·net_turns` per period, everything else is
//! periodic. Frames and classes follow `docs/conventions.md`: the follower pose is
//! x_R = R₂(t)·x_f + T₂(t); 1R turns about +z, 1R1T also slides along z, 3R turns about the
//! origin.
//!
//! # Interpolation schemes
//! - 1R / 1R1T angle: [`AngleScheme::Monotone`] by default for keyframe specs (shape
//!   preserving quintic: monotone between keys, so monotone keys give a follower that never
//!   reverses; see [`angle`]) or [`AngleScheme::Spline`] (periodic cubic spline, used for
//!   dense samples).
//! - 1R1T height: periodic cubic spline.
//! - 3R orientation: sign-continuous quaternion components through one periodic cubic
//!   spline, normalized (see [`rotation`]).
//!
//! All schemes pass exactly through every keyframe and are C² across the period boundary.
//! Evaluation is a binary search plus a polynomial: O(log n), no allocation.
//!
//! # Files
//! - `.toml` keyframe specs ([`spec`]): the format is documented there and in
//!   `data/README.md`.
//! - `.csv` dense files ([`dense`]): `t,qw,qx,qy,qz,tx,ty,tz` rows after a `# class = ...`
//!   comment.
//! - `mechanism.json` ([`Motion::from_mechanism_file`]): `class`, `motion.source` and
//!   `follower_motion`.

pub mod angle;
mod build;
mod class;
pub mod dense;
mod error;
pub mod figures;
mod mechanism;
pub mod rotation;
pub mod spec;
mod spline;
pub mod units;

use std::path::{Path, PathBuf};

use nalgebra::{Quaternion, UnitQuaternion, Vector3};

pub use angle::AngleScheme;
pub use class::{MotionClass, UnknownClass};
pub use error::{Location, MotionError, MotionWarning, WarningKind};
pub use mechanism::{mechanism_scale_mm, DEFAULT_SCALE_MM, MECHANISM_FILE};
pub use units::{BenchScale, DEFAULT_BENCH_RPM};

use angle::AngleLaw;
use rotation::RotationLaw;
use spline::PeriodicSpline;

/// Default number of uniform samples per period (docs/conventions.md: N = 360).
pub const DEFAULT_SAMPLES: usize = 360;

/// A quaternion whose norm is within this of 1 is normalized with a warning; beyond it is an
/// error. 1e-3 accepts quaternions typed with three or four decimals but catches a forgotten
/// component or a wrong sign.
pub const QUATERNION_NORM_TOLERANCE: f64 = 1e-3;

/// Norm deviations below this are rounding, normalized silently (no warning). 1e-6 covers
/// quaternions written with six or more decimals, as CAD and mocap exports do.
pub const QUATERNION_NORM_SILENT: f64 = 1e-6;

/// Largest tilt of the z axis (degrees) accepted as "a rotation about z" in 1R and 1R1T
/// dense rows and keys. 0.01° is far above the rounding of six-decimal quaternions (about
/// 1e-4°) and far below any deliberate tilt.
pub const OFF_AXIS_TOLERANCE_DEG: f64 = 0.01;

/// Largest translation component (model units) accepted as "zero" where a class forbids
/// translation (1R, 3R; x and y of 1R1T). 1e-6 is rounding for six-decimal exports of
/// models a few units in size.
pub const TRANSLATION_TOLERANCE: f64 = 1e-6;

/// Largest rotation about z (degrees) between consecutive dense rows of a 1R/1R1T file;
/// beyond it the unwrapping of the angle (which picks the shorter way round) is ambiguous.
/// 90° is generous: 360 samples of one turn step 1°.
pub const MAX_DENSE_STEP_DEG: f64 = 90.0;

/// Tolerance (in turns) for "a whole number of turns" in a keyframe spec's net rotation:
/// 1e-9 turn accepts exact decimal input like 360 or 720 and rejects anything typed
/// differently.
pub const WHOLE_TURN_TOLERANCE: f64 = 1e-9;

/// 3R tilt warning threshold (degrees): beyond about 45° of tilt of the end-effector axis
/// from rest, the follower surface turns far towards the driver and the paper's examples
/// stay within this; the synthesis is unlikely to find closed curve pairs.
pub const MAX_TILT_DEG: f64 = 45.0;

/// Angular acceleration warning threshold in rad per period². A sinusoidal swing of ±30°
/// repeated four times per period peaks at about 330 rad/period²; far beyond that the
/// conjugate curves become highly curved and rarely fabricable. 600 leaves room for the
/// paper's examples (the 2:1 half-turn law peaks near 70).
pub const MAX_ANGULAR_ACCELERATION: f64 = 600.0;

/// 1R1T vertical acceleration warning threshold in model units per period², chosen like
/// [`MAX_ANGULAR_ACCELERATION`] for a follower of radius about one unit (the paper's curve
/// lengths 4π..6π).
pub const MAX_LINEAR_ACCELERATION: f64 = 600.0;

/// Sample density (per period) at which the loaded law is scanned for warnings: four times
/// the default N, matching the conjugation acceptance check of the conventions.
pub const WARNING_SCAN_SAMPLES: usize = 4 * DEFAULT_SAMPLES;

/// Largest keyframe spec (`.toml`) read, in bytes. The TOML parser holds about 2 kB per
/// key while it reads (1.15 M keys in 65 MB of text took 2.4 GB), so a larger spec is
/// refused before parsing. 8 MiB holds over 100 000 keys, hundreds per degree of a period;
/// data that dense belongs in the dense CSV format, which reads 1.15 M rows in about 2 s
/// and 0.5 GB.
pub const MAX_SPEC_BYTES: usize = 8 << 20;

/// Largest magnitude of any angle in a motion (keyframe angles, Euler and direction
/// angles, net rotation, timing segments; unwrapped), degrees: 1000 turns. No mechanism
/// turns its follower a thousand times per driver revolution, and beyond it a typo such as
/// `angle = 1e300` would make ω infinite (and synthesis run for minutes on nonsense).
pub const MAX_ABS_ANGLE_DEG: f64 = 360_000.0;

/// Largest magnitude of a translation or height, model units: 1000 (10 m at the default
/// 10 mm per unit) for a follower about one unit in size (the paper's curve lengths of
/// 4π–6π units).
pub const MAX_ABS_TRANSLATION: f64 = 1000.0;

/// Follower pose and its derivatives with respect to t (t = fraction of the period).
#[derive(Debug, Clone, Copy)]
pub struct PoseSample {
    /// The time.
    pub t: f64,
    /// R₂(t), scalar-first when serialized.
    pub rotation: UnitQuaternion<f64>,
    /// T₂(t).
    pub translation: Vector3<f64>,
    /// ω in frame R: dR₂/dt = \[ω\]ₓ R₂ (rad per period).
    pub angular_velocity: Vector3<f64>,
    /// dω/dt (rad per period²).
    pub angular_acceleration: Vector3<f64>,
    /// dT₂/dt (units per period).
    pub velocity: Vector3<f64>,
    /// d²T₂/dt² (units per period²).
    pub acceleration: Vector3<f64>,
}

impl serde::Serialize for PoseSample {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        use serde::ser::SerializeStruct;
        let v = |x: &Vector3<f64>| [x.x, x.y, x.z];
        let mut st = s.serialize_struct("PoseSample", 7)?;
        st.serialize_field("t", &self.t)?;
        st.serialize_field("rotation", &rotation::quat_to_array(&self.rotation))?;
        st.serialize_field("translation", &v(&self.translation))?;
        st.serialize_field("angular_velocity", &v(&self.angular_velocity))?;
        st.serialize_field("angular_acceleration", &v(&self.angular_acceleration))?;
        st.serialize_field("velocity", &v(&self.velocity))?;
        st.serialize_field("acceleration", &v(&self.acceleration))?;
        st.end()
    }
}

/// One row of a dense motion: time, orientation and position.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DenseRow {
    /// Time in `[0, 1)`.
    pub t: f64,
    /// R₂(t).
    pub rotation: UnitQuaternion<f64>,
    /// T₂(t).
    pub translation: Vector3<f64>,
}

/// A pose the motion passes through exactly.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Keyframe {
    /// Time in `[0, 1)`.
    pub t: f64,
    /// R₂ at `t`.
    pub rotation: UnitQuaternion<f64>,
    /// T₂ at `t`.
    pub translation: Vector3<f64>,
    /// 1-based line in the source file, when known.
    pub line: Option<usize>,
}

/// The interpolated law.
#[derive(Debug, Clone)]
enum Law {
    /// 1R and 1R1T: θ(t) about z and, for 1R1T, h(t) along z.
    Planar {
        angle: AngleLaw,
        height: Option<PeriodicSpline<1>>,
    },
    /// 3R: R₂(t).
    Spherical(RotationLaw),
}

/// More keyframes than this make a motion dense for [`Motion::key_poses`]. Default 64: the
/// example specs have 4–8 keys, dense files hundreds of rows.
pub const MAX_KEY_POSES: usize = 64;

/// A validated, interpolated periodic follower motion.
#[derive(Debug, Clone)]
pub struct Motion {
    name: String,
    class: MotionClass,
    source: Option<PathBuf>,
    keyframes: Vec<Keyframe>,
    warnings: Vec<MotionWarning>,
    net_turns: i32,
    angle_scheme: Option<AngleScheme>,
    law: Law,
}

impl Motion {
    /// Load a `.toml` keyframe spec or a `.csv` dense file; warnings are kept in the Motion.
    pub fn from_file(path: &Path) -> Result<Motion, MotionError> {
        let text = std::fs::read_to_string(path).map_err(|source| MotionError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        let ext = path
            .extension()
            .and_then(|e| e.to_str())
            .map(str::to_ascii_lowercase);
        match ext.as_deref() {
            Some("toml") => spec::parse_spec(&text, Some(path)),
            Some("csv") => dense::parse_csv(&text, Some(path)),
            _ => Err(MotionError::UnknownFormat {
                path: path.to_path_buf(),
            }),
        }
    }

    /// Build from dense samples (used for mechanism.json's follower_motion).
    ///
    /// Rows must have increasing times in `[0, 1)` and poses valid for `class`; 1R/1R1T
    /// angles are unwrapped row to row (steps below [`MAX_DENSE_STEP_DEG`]) and
    /// interpolated by the periodic cubic spline.
    pub fn from_dense(
        class: MotionClass,
        name: &str,
        rows: &[DenseRow],
    ) -> Result<Motion, MotionError> {
        dense::from_rows(class, name, rows, None, &|i| format!("rows[{i}]"), &[])
    }

    /// The target law stored in a mechanism file (path to mechanism.json or to the directory
    /// holding it): reads only `class`, `motion.source` and `follower_motion`.
    pub fn from_mechanism_file(path: &Path) -> Result<Motion, MotionError> {
        mechanism::load(path)
    }

    /// The motion class.
    pub fn class(&self) -> MotionClass {
        self.class
    }

    /// The motion's name, e.g. "half-turn-2to1".
    pub fn name(&self) -> &str {
        &self.name
    }

    /// The file it was loaded from, if any.
    pub fn source(&self) -> Option<&Path> {
        self.source.as_deref()
    }

    /// The angle interpolation scheme (1R/1R1T); `None` for 3R.
    pub fn angle_scheme(&self) -> Option<AngleScheme> {
        self.angle_scheme
    }

    /// Pose and derivatives at any real `t` (periodic wrap; 1R/1R1T angles keep turning).
    pub fn sample(&self, t: f64) -> PoseSample {
        match &self.law {
            Law::Planar { angle, height } => {
                let [th, dth, ddth] = angle.eval(t);
                let (s, c) = (0.5 * th).sin_cos();
                let rotation = UnitQuaternion::new_unchecked(Quaternion::new(c, 0.0, 0.0, s));
                let [h, dh, ddh] = match height {
                    Some(spline) => spline.eval(t).map(|x| x[0]),
                    None => [0.0; 3],
                };
                PoseSample {
                    t,
                    rotation,
                    translation: Vector3::new(0.0, 0.0, h),
                    angular_velocity: Vector3::new(0.0, 0.0, dth),
                    angular_acceleration: Vector3::new(0.0, 0.0, ddth),
                    velocity: Vector3::new(0.0, 0.0, dh),
                    acceleration: Vector3::new(0.0, 0.0, ddh),
                }
            }
            Law::Spherical(law) => {
                let j = law.eval(t);
                PoseSample {
                    t,
                    rotation: j.rotation,
                    translation: Vector3::zeros(),
                    angular_velocity: j.angular_velocity,
                    angular_acceleration: j.angular_acceleration,
                    velocity: Vector3::zeros(),
                    acceleration: Vector3::zeros(),
                }
            }
        }
    }

    /// The `n` uniform samples `t_i = i/n`, i = 0..n−1.
    pub fn samples(&self, n: usize) -> Vec<PoseSample> {
        (0..n).map(|i| self.sample(i as f64 / n as f64)).collect()
    }

    /// The keyframes (for dense inputs: every row).
    pub fn keyframes(&self) -> &[Keyframe] {
        &self.keyframes
    }

    /// The keyframes worth marking and reporting as key poses: all of them for a keyframe
    /// spec, none for a dense motion (more than [`MAX_KEY_POSES`] rows: CSV or a mechanism's
    /// samples), whose rows are samples rather than poses a user chose.
    pub fn key_poses(&self) -> &[Keyframe] {
        if self.keyframes.len() <= MAX_KEY_POSES {
            &self.keyframes
        } else {
            &[]
        }
    }

    /// Warnings found while loading and scanning the motion.
    pub fn warnings(&self) -> &[MotionWarning] {
        &self.warnings
    }

    /// 1R/1R1T: the unwrapped rotation angle about +z in radians, continuous over all real t
    /// (`angle(t + 1) = angle(t) + 2π·net_turns`), with its first and second t-derivatives.
    /// `None` for 3R.
    pub fn angle_z(&self, t: f64) -> Option<[f64; 3]> {
        match &self.law {
            Law::Planar { angle, .. } => Some(angle.eval(t)),
            Law::Spherical(_) => None,
        }
    }

    /// 1R1T: height along z (model units) with its first and second derivatives.
    /// 1R: `Some([0, 0, 0])` (the follower never leaves its plane). 3R: `None`.
    pub fn height(&self, t: f64) -> Option<[f64; 3]> {
        match &self.law {
            Law::Planar {
                height: Some(spline),
                ..
            } => Some(spline.eval(t).map(|x| x[0])),
            Law::Planar { height: None, .. } => Some([0.0; 3]),
            Law::Spherical(_) => None,
        }
    }

    /// 1R/1R1T: net whole turns per period (0 oscillation, ±1 full turn, ...); 3R: 0.
    pub fn net_turns(&self) -> i32 {
        self.net_turns
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn assert_send_sync<T: Send + Sync + Clone>() {}

    /// Guards the API contract: Motion can be shared across threads (simulators, rayon).
    #[test]
    fn motion_is_send_sync_clone() {
        assert_send_sync::<Motion>();
    }
}
