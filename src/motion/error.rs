//! Errors and warnings of motion loading and validation.
//!
//! Every message names where the problem is — file, line (when the format has lines) and
//! field — through [`Location`]. Errors stop loading; warnings ([`MotionWarning`]) are kept
//! in the loaded [`super::Motion`] for the caller to show.

use std::fmt;
use std::path::PathBuf;

use super::MotionClass;

/// Where in the input a problem is.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct Location {
    /// The file, if the motion came from one.
    pub file: Option<PathBuf>,
    /// 1-based line number, where the format has lines.
    pub line: Option<usize>,
    /// The field, e.g. `key[2].quaternion` or `follower_motion[17].rotation`.
    pub field: String,
}

impl Location {
    /// A location in `file` (optional) at `line` (optional) naming `field`.
    pub fn new(file: Option<PathBuf>, line: Option<usize>, field: impl Into<String>) -> Self {
        Self {
            file,
            line,
            field: field.into(),
        }
    }
}

impl fmt::Display for Location {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let place = match (&self.file, self.line) {
            (Some(file), Some(line)) => format!("{}:{line}", file.display()),
            (Some(file), None) => file.display().to_string(),
            (None, Some(line)) => format!("line {line}"),
            (None, None) => String::new(),
        };
        match (place.is_empty(), self.field.is_empty()) {
            (false, false) => write!(f, "{place}: field `{}`", self.field),
            (false, true) => f.write_str(&place),
            (true, false) => write!(f, "field `{}`", self.field),
            (true, true) => f.write_str("motion"),
        }
    }
}

/// A number as typed by a person: plain below a million, in exponent form above (`1e300`
/// rather than three hundred digits).
fn short(v: f64) -> String {
    if v.abs() < 1e6 {
        v.to_string()
    } else {
        format!("{v:e}")
    }
}

/// Why a motion could not be loaded.
#[derive(Debug, thiserror::Error)]
pub enum MotionError {
    /// The file could not be read.
    #[error("cannot read motion file {path}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The operating system's error.
        #[source]
        source: std::io::Error,
    },
    /// The file name does not say which format it is.
    #[error(
        "{path}: unknown motion file type (expected a .toml keyframe spec or a .csv dense file)"
    )]
    UnknownFormat {
        /// The file.
        path: PathBuf,
    },
    /// The file is not well-formed TOML, CSV or JSON, or a field has the wrong type.
    #[error("{at}: {message}")]
    Syntax {
        /// Where.
        at: Location,
        /// The parser's explanation.
        message: String,
    },
    /// `class` is not one of the three classes.
    #[error("{at}: unknown motion class {found:?} (expected \"1R\", \"1R1T\" or \"3R\")")]
    UnknownClass {
        /// Where.
        at: Location,
        /// What the file says.
        found: String,
    },
    /// A time is not in `[0, 1)`.
    #[error("{at}: time t = {t} is outside one period [0, 1)")]
    TimeOutOfRange {
        /// Where.
        at: Location,
        /// The time.
        t: f64,
    },
    /// A time is not after the previous one.
    #[error("{at}: time t = {t} is not after the previous keyframe's t = {previous} (times must increase)")]
    TimeNotIncreasing {
        /// Where.
        at: Location,
        /// The time.
        t: f64,
        /// The previous keyframe's time.
        previous: f64,
    },
    /// Two keyframes share a time.
    #[error(
        "{at}: time t = {t} is duplicated (the keyframe at line {previous_line} has the same time)"
    )]
    DuplicateTime {
        /// Where.
        at: Location,
        /// The time.
        t: f64,
        /// Line of the other keyframe (0 when unknown).
        previous_line: usize,
    },
    /// NaN or infinity.
    #[error("{at}: value {value} is not a finite number")]
    NonFinite {
        /// Where.
        at: Location,
        /// The value.
        value: f64,
    },
    /// A quaternion too far from unit length to be a typo of one.
    #[error("{at}: quaternion has norm {norm:.6}, more than {tolerance} away from 1 (give a unit quaternion [w, x, y, z])")]
    NonUnitQuaternion {
        /// Where.
        at: Location,
        /// Its norm.
        norm: f64,
        /// The accepted deviation.
        tolerance: f64,
    },
    /// Translation given in a pure-rotation class, or off the z axis in 1R1T.
    #[error("{at}: translation {translation:?} is not allowed in class {class} ({why})")]
    TranslationNotAllowed {
        /// Where.
        at: Location,
        /// The class.
        class: MotionClass,
        /// The offending translation.
        translation: [f64; 3],
        /// What the class allows.
        why: &'static str,
    },
    /// A 1R/1R1T orientation that is not a rotation about z.
    #[error("{at}: rotation tilts the z axis by {tilt_deg:.4}°; class {class} turns only about the z axis")]
    RotationOffAxis {
        /// Where.
        at: Location,
        /// The class.
        class: MotionClass,
        /// Angle between the rotated z axis and z.
        tilt_deg: f64,
    },
    /// The net rotation of a 1R/1R1T period is not a multiple of 360°.
    #[error("{at}: net rotation {degrees}° over one period is not a whole number of turns (use a multiple of 360°: 0 for an oscillation, ±360° for one full turn)")]
    NotWholeTurns {
        /// Where.
        at: Location,
        /// The net rotation.
        degrees: f64,
    },
    /// Too few keyframes for the interpolation scheme.
    #[error("{at}: {found} keyframe(s), but a {class} motion needs at least {needed}: {why}")]
    TooFewKeyframes {
        /// Where.
        at: Location,
        /// The class.
        class: MotionClass,
        /// How many there are.
        found: usize,
        /// How many are needed.
        needed: usize,
        /// Why.
        why: &'static str,
    },
    /// A finite value no mechanism can have (an angle of 1e300°, a height of a kilometre).
    #[error("{at}: {} {unit} is not a physical value (at most ±{limit} {unit}: {why})", short(*.value))]
    NotPhysical {
        /// Where.
        at: Location,
        /// The value.
        value: f64,
        /// The largest magnitude accepted.
        limit: f64,
        /// Its unit.
        unit: &'static str,
        /// What the limit stands for.
        why: &'static str,
    },
    /// Anything else that is wrong with one field (missing, conflicting, out of range).
    #[error("{at}: {message}")]
    Invalid {
        /// Where.
        at: Location,
        /// What is wrong and what would be right.
        message: String,
    },
}

impl MotionError {
    /// Where the problem is, if it has a location.
    pub fn location(&self) -> Option<&Location> {
        match self {
            Self::Io { .. } | Self::UnknownFormat { .. } => None,
            Self::Syntax { at, .. }
            | Self::UnknownClass { at, .. }
            | Self::TimeOutOfRange { at, .. }
            | Self::TimeNotIncreasing { at, .. }
            | Self::DuplicateTime { at, .. }
            | Self::NonFinite { at, .. }
            | Self::NotPhysical { at, .. }
            | Self::NonUnitQuaternion { at, .. }
            | Self::TranslationNotAllowed { at, .. }
            | Self::RotationOffAxis { at, .. }
            | Self::NotWholeTurns { at, .. }
            | Self::TooFewKeyframes { at, .. }
            | Self::Invalid { at, .. } => Some(at),
        }
    }
}

/// What a warning is about.
#[derive(Debug, Clone, PartialEq)]
pub enum WarningKind {
    /// A quaternion within tolerance of unit length was normalized.
    QuaternionNormalized {
        /// Its norm before normalizing.
        norm: f64,
    },
    /// The 3R end-effector axis tilts far from rest.
    LargeTilt {
        /// The largest tilt, degrees.
        tilt_deg: f64,
        /// When it happens.
        t: f64,
    },
    /// The angular acceleration is very large.
    LargeAngularAcceleration {
        /// Its magnitude in rad per period².
        value: f64,
        /// When it happens.
        t: f64,
    },
    /// The vertical acceleration of a 1R1T motion is very large.
    LargeAcceleration {
        /// Its magnitude in model units per period².
        value: f64,
        /// When it happens.
        t: f64,
    },
}

/// A motion that loads but is unlikely to be synthesizable as it stands, or an input that
/// was silently repaired.
#[derive(Debug, Clone, PartialEq)]
pub struct MotionWarning {
    /// Where.
    pub at: Location,
    /// What.
    pub kind: WarningKind,
}

impl fmt::Display for MotionWarning {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}: ", self.at)?;
        match &self.kind {
            WarningKind::QuaternionNormalized { norm } => {
                write!(f, "quaternion norm {norm:.6} is not 1; normalized")
            }
            WarningKind::LargeTilt { tilt_deg, t } => write!(
                f,
                "end-effector axis tilts {tilt_deg:.1}° from rest at t = {t:.4} (beyond {:.0}°; \
                 a spherical-joint follower this tilted is hard to drive)",
                super::MAX_TILT_DEG
            ),
            WarningKind::LargeAngularAcceleration { value, t } => write!(
                f,
                "angular acceleration {value:.1} rad/period² at t = {t:.4} (beyond {:.0}; \
                 the conjugate curves will be highly curved)",
                super::MAX_ANGULAR_ACCELERATION
            ),
            WarningKind::LargeAcceleration { value, t } => write!(
                f,
                "vertical acceleration {value:.1} units/period² at t = {t:.4} (beyond {:.0}; \
                 the conjugate curves will be highly curved)",
                super::MAX_LINEAR_ACCELERATION
            ),
        }
    }
}
