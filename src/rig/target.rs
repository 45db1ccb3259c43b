//! What a bench run is measured against, and the checks that keep a broken or unmeasurable
//! target from ever moving the motor.
//!
//! Owns loading a target for the bench (session and simulators) and for the analysis: a
//! motion file through [`crate::motion`], or a `mechanism.json` **validated as `mpc-rig
//! synth --check` validates it** — the whole file through [`Mechanism::load`] (format,
//! array lengths, finite numbers, unit quaternions), then every check of
//! [`Mechanism::check`] from its samples (coincident points, unit and opposite normals,
//! conjugation residual, bands, closure) — and refused when it is a partial design
//! (`mechanism.partial.json`, written after a cancelled or failed synthesis). Only then does
//! its follower motion become the target law. Also owns whether a rig's sensors can measure
//! a motion class ([`check_measurable`]).
//!
//! The validation lives here rather than in [`crate::motion`], which reads only the follower
//! motion of a mechanism file and must not depend on synthesis. It does not synthesize and
//! does not decide what to do with a valid target.

use std::path::{Path, PathBuf};

use sha2::{Digest, Sha256};

use crate::motion::{Motion, MotionClass};
use crate::rig::config::RigConfig;
use crate::rig::recording::TargetRef;
use crate::rig::RigError;
use crate::synth::Mechanism;

/// What the session measures against.
#[derive(Debug, Clone, PartialEq)]
pub enum TargetSpec {
    /// A `mechanism.json` or the directory holding it.
    Mechanism(PathBuf),
    /// A motion file (`.toml` keyframes or `.csv` dense).
    Motion(PathBuf),
}

/// A loaded target: the motion law and its reference for the sidecar.
#[derive(Debug, Clone)]
pub struct Target {
    /// The law.
    pub motion: Motion,
    /// Reference written into the recording.
    pub reference: TargetRef,
}

impl TargetSpec {
    /// Load the motion (a mechanism only after [`load_mechanism`]'s checks) and hash the
    /// file.
    pub fn load(&self) -> Result<Target, RigError> {
        let (kind, path, motion) = match self {
            TargetSpec::Mechanism(p) => ("mechanism", p, load_mechanism(p)?.1),
            TargetSpec::Motion(p) => ("motion", p, load_motion(p)?),
        };
        let file = mechanism_file(path);
        let bytes = std::fs::read(&file).map_err(|e| RigError::Target {
            path: file.clone(),
            message: e.to_string(),
        })?;
        let sha256 = Sha256::digest(&bytes)
            .iter()
            .map(|b| format!("{b:02x}"))
            .collect();
        Ok(Target {
            reference: TargetRef {
                kind: kind.into(),
                path: path.clone(),
                sha256,
                class: motion.class().to_string(),
                name: motion.name().to_string(),
            },
            motion,
        })
    }
}

/// The file a target path names: `mechanism.json` inside a directory, else the path.
fn mechanism_file(path: &Path) -> PathBuf {
    if path.is_dir() {
        path.join(crate::motion::MECHANISM_FILE)
    } else {
        path.to_path_buf()
    }
}

/// A motion file (`.toml` or `.csv`) as a target law.
pub fn load_motion(path: &Path) -> Result<Motion, RigError> {
    Motion::from_file(path).map_err(|e| RigError::Target {
        path: path.to_path_buf(),
        message: e.to_string(),
    })
}

/// A mechanism file (or its directory) validated as `mpc-rig synth --check` does, and its
/// follower motion as the target law. Refused: a file that does not load as a mechanism,
/// one that fails any check, and a partial design.
pub fn load_mechanism(path: &Path) -> Result<(Mechanism, Motion), RigError> {
    let file = mechanism_file(path);
    let refuse = |message: String| RigError::Target {
        path: file.clone(),
        message,
    };
    let m = Mechanism::load(path).map_err(|e| refuse(without_path(&e.to_string(), &file)))?;
    if m.solve.partial {
        return Err(refuse(
            "a partial design (written after a cancelled or failed synthesis, not accepted); \
             run `mpc-rig synth` to the end and measure its mechanism.json"
                .into(),
        ));
    }
    let report = m.check();
    if !report.passed() {
        let failed: Vec<String> = report
            .items
            .iter()
            .filter(|i| !i.passed)
            .map(|i| format!("{}: {}", i.name, i.detail))
            .collect();
        return Err(refuse(format!(
            "fails the mechanism check (`mpc-rig synth --check` shows it): {}",
            failed.join("; ")
        )));
    }
    let motion = Motion::from_mechanism_file(path).map_err(|e| refuse(e.to_string()))?;
    Ok((m, motion))
}

/// A message of the synthesis module without the file it starts with (`PATH: field …` or
/// `PATH:LINE:COL: …`, whose parser message says where again): the refusal names the file
/// once.
fn without_path(text: &str, file: &Path) -> String {
    match text.strip_prefix(&file.display().to_string()) {
        Some(rest) => rest
            .trim_start_matches(|c: char| c == ':' || c.is_ascii_digit())
            .trim_start()
            .to_string(),
        None => text.to_string(),
    }
}

/// Refuse a target class the rig's sensors cannot measure, before anything moves: a 3R
/// follower needs an IMU, a turning one an `rz` sensor, a 1R1T one also a `tz` sensor (what
/// the analysis compares; [`RigConfig::missing_sensors`]).
pub fn check_measurable(rig: &RigConfig, class: MotionClass) -> Result<(), RigError> {
    match rig.missing_sensors(class) {
        None => Ok(()),
        Some(missing) => Err(RigError::CannotMeasure {
            rig: rig.name.clone(),
            class: class.to_string(),
            missing,
        }),
    }
}
