//! Synthesis: from a motion to K conjugate curve pairs with dynamic form closure.
//!
//! Owns the B-spline curve pair model, the energies and constraints of the paper, closure
//! (signed distance to hulls of projected normals in 1–3 D), SLSQP candidates, the genetic
//! combination, the K/d_x search and the `mechanism.json` file. It does not build meshes or
//! talk to hardware.

pub mod assemble;
pub mod bands;
pub mod bspline;
pub mod candidate;
pub mod closure;
pub mod combine;
pub mod dual;
pub mod energy;
pub mod error;
pub mod ga;
pub mod math;
pub mod mechanism;
pub mod model;
pub mod optimizer;
pub mod outcome;
pub mod pose;
pub mod report;
pub mod search;
pub mod undercut;

pub use closure::Class;
pub use error::{MechanismFileError, ReportError, SynthError};
pub use mechanism::{CheckReport, Mechanism};
pub use outcome::Outcome;
pub use search::{synthesize_track, NoProgress, SynthOptions, SynthProgress};

use std::sync::Arc;

use crate::motion::{Motion, MotionClass};

impl From<MotionClass> for Class {
    fn from(c: MotionClass) -> Self {
        match c {
            MotionClass::R1 => Class::R1,
            MotionClass::R1T1 => Class::R1T1,
            MotionClass::R3 => Class::R3,
        }
    }
}

/// Synthesize a mechanism for a motion: K conjugate curve pairs with dynamic form closure
/// (paper and robust) at every instant. The [`Outcome`] says whether a design was accepted
/// and carries the best one reached otherwise; an error is a request that cannot be served.
pub fn synthesize(
    motion: &Motion,
    opts: &SynthOptions,
    progress: &dyn SynthProgress,
) -> Result<Outcome, SynthError> {
    let poses = Arc::new(pose::PoseTrack::from_motion(motion, opts.samples));
    let source = motion
        .source()
        .and_then(|p| p.file_name())
        .map(|f| f.to_string_lossy().into_owned())
        .unwrap_or_else(|| motion.name().to_string());
    let mut o = opts.clone();
    if o.source.is_none() {
        o.source = Some(source);
    }
    search::synthesize_track(motion.class().into(), poses, motion.name(), &o, progress)
}
