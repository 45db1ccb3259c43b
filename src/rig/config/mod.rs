//! Rig configuration: what a bench is made of, loaded from `rigs/*.toml`.
//!
//! Owns the schema (driver backend, sensors with their calibration, serial ports, sampling,
//! homing, safety limits), its validation with file/line/field errors, and the calibration
//! helpers that turn raw sensor values into physical follower coordinates
//! ([`SensorConfig::to_physical`], [`ImuConfig::follower_rotation`]). The schema is
//! documented for users in `rigs/README.md`.
//!
//! One file per part: [`schema`] (the types serde reads, with defaults, and what the bench
//! asks of them), `validate` (declarative bounds per field, Klipper-style, and the checks
//! between fields), `lines` (where a field is in the file, for messages); loading (parse,
//! validate, locate) is here.
//!
//! It does not open ports or talk to devices (that is [`crate::rig::backend`]), and it does
//! not unwrap angles or align anything with the target (that is [`crate::analysis`]).

use std::path::{Path, PathBuf};

mod lines;
pub mod schema;
mod validate;

pub use schema::*;

use lines::{field_line, key_line_after, line_of, render_field};

/// Counts per revolution of an AS5600 12-bit magnetic encoder (datasheet: 0..4095).
pub const AS5600_COUNTS_PER_REV: u32 = 4096;

/// Counts per revolution of an XL430/XM430 Dynamixel's present position (0..4095 per turn).
pub const DYNAMIXEL_COUNTS_PER_REV: u32 = 4096;

/// Default sample rate in Hz: the firmware's 1 kHz encoder sampling, the rate the bench is
/// specified for.
pub const DEFAULT_SAMPLE_RATE_HZ: f64 = 1000.0;

/// Default dead-man watchdog period in ms: the firmware stops the motor if no heartbeat or
/// command arrives within this time. 250 ms is four missed 50 ms heartbeats.
pub const DEFAULT_WATCHDOG_MS: u32 = 250;

/// Default longest run in seconds before the session stops the driver on its own: ten
/// minutes covers many cycles at bench speeds and bounds an unattended run.
pub const DEFAULT_MAX_RUN_S: f64 = 600.0;

/// Default largest deviation of the follower from the target law before the session stops
/// the motor as a jammed mechanism, degrees of follower rotation (`safety.
/// max_follower_error_deg`): 20°. A printed mechanism with a few degrees of backlash and
/// lag stays far below it even where the law is steep, while a follower that binds falls
/// this far behind within a fraction of a driver turn.
pub const DEFAULT_MAX_FOLLOWER_ERROR_DEG: f64 = 20.0;

/// Profile Acceleration unit of an X-series servo in velocity-based profile mode, degrees
/// per second squared at the servo shaft (214.577 rev/min², e-manual).
pub const DYNAMIXEL_ACCEL_UNIT_DEG_S2: f64 = 214.577 * 360.0 / 3600.0;

/// Largest gear ratio accepted (its inverse is the smallest), for either driver kind:
/// 1000:1. Bench gearboxes and belts stay below 100:1; far beyond, a typo such as `1e9`
/// makes every speed and step-rate figure derived from it meaningless. The firmware carries
/// the ratio as a fraction of two 16-bit numbers, which this range always allows.
pub const MAX_GEAR_RATIO: f64 = 1000.0;

/// An IMU quaternion reading whose norm is further than this from 1 is garbage, not a
/// rotation to normalize: 0.1. Fused-orientation IMUs report unit quaternions to a few
/// 10⁻⁴ (the BNO055 uses 2¹⁴ LSB per unit); anything 10 % off is a corrupted value. Used by
/// the live error and the analysis alike.
pub const IMU_NORM_TOLERANCE: f64 = 0.1;

/// Highest sample rate a rig may ask for, Hz: ten times the firmware's specified 1 kHz;
/// beyond it neither our firmware nor a Dynamixel bus delivers, and a typo (`1e6`) would
/// size buffers and batches for nothing.
pub const MAX_SAMPLE_RATE_HZ: f64 = 10_000.0;

/// Tolerance on the norm of a configured mounting quaternion: beyond it the file is
/// rejected rather than silently normalized (a typo, not rounding).
pub const MOUNTING_NORM_TOLERANCE: f64 = 1e-3;

/// Error while loading or validating a rig configuration.
#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    /// The file could not be read.
    #[error("cannot read rig configuration {path}: {source}")]
    Read {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// The TOML is malformed or a field has the wrong type / an unknown name.
    #[error("{path}:{line}: {message}")]
    Parse {
        /// The file.
        path: PathBuf,
        /// 1-based line (0 when unknown).
        line: usize,
        /// The parser's message.
        message: String,
    },
    /// A field has a value that is well-formed but not acceptable.
    #[error("{path}:{line}: field `{field}`: {message}")]
    Invalid {
        /// The file.
        path: PathBuf,
        /// 1-based line of the field (0 when unknown).
        line: usize,
        /// Dotted path of the field, e.g. `sensors[1].counts_per_rev`.
        field: String,
        /// What is wrong.
        message: String,
    },
    /// A `--port` override does not fit the configured ports.
    #[error("port override `{given}`: {message}")]
    PortOverride {
        /// The override as given.
        given: String,
        /// What is wrong.
        message: String,
    },
}

impl RigConfig {
    /// Load and validate `rigs/<name>.toml`.
    pub fn load(path: &Path) -> Result<RigConfig, ConfigError> {
        let text = std::fs::read_to_string(path).map_err(|source| ConfigError::Read {
            path: path.to_path_buf(),
            source,
        })?;
        RigConfig::from_toml_str(&text, path)
    }

    /// Parse and validate TOML text; `path` is used in messages only.
    pub fn from_toml_str(text: &str, path: &Path) -> Result<RigConfig, ConfigError> {
        let cfg: RigConfig = toml::from_str(text).map_err(|e| {
            let message = e.message().trim().to_string();
            let mut line = e.span().map_or(0, |s| line_of(text, s.start));
            // Inside tagged tables the parser points at the table header; point at the
            // offending key instead when the message names one.
            if let Some(key) = message
                .strip_prefix("unknown field `")
                .and_then(|r| r.split('`').next())
            {
                if let Some(l) = key_line_after(text, line, key) {
                    line = l;
                }
            }
            ConfigError::Parse {
                path: path.to_path_buf(),
                line,
                message,
            }
        })?;
        if let Err((segments, message)) = validate::validate(&cfg) {
            let field = render_field(&segments);
            return Err(ConfigError::Invalid {
                path: path.to_path_buf(),
                line: field_line(text, &segments).unwrap_or(0),
                field,
                message,
            });
        }
        Ok(cfg)
    }
}

#[cfg(test)]
mod tests;
