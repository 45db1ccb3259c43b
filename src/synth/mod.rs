//! Synthesis: from a motion to K conjugate curve pairs with dynamic form closure.
//!
//! Owns the B-spline curve pair model, the energies and constraints of the paper, closure
//! (signed distance to hulls of projected normals in 1–3 D), SLSQP candidates, the genetic
//! combination, the K/d_x search and the `mechanism.json` file. It does not build meshes or
//! talk to hardware.

pub mod bspline;
pub mod closure;
pub mod dual;
pub mod model;
pub mod pose;
pub mod energy;
pub mod optimizer;
pub mod candidate;
pub mod ga;
pub mod error;
pub mod mechanism;
pub mod search;

pub use closure::Class;
pub use error::SynthError;
pub use mechanism::{CheckReport, Mechanism};
pub use search::{synthesize_track, NoProgress, SynthOptions, SynthProgress};
