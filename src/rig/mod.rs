//! The bench: rig configuration, serial links, drive and sense backends (our stepper
//! firmware, Dynamixel servos, simulated devices on pseudo-terminals), the measurement
//! session and the recording it writes.
//!
//! It does not judge the measurement: comparing against the target is [`crate::analysis`].
//!
//! - [`config`]: `rigs/*.toml` schema, validation and sensor calibration helpers.
//! - [`recording`]: the recording directory (CSV + JSON sidecar), writer and reader.
//! - [`backend`]: the driver and sample-stream traits, one folder per backend.
//! - [`link`]: serial port listing and resolution.
//! - [`session`]: the measurement session (`mpc-rig measure`).
//! - [`target`]: what a run is measured against: motion files, mechanism files validated
//!   as `synth --check` does, and whether a rig can measure a class.
//! - [`sim`]: the plant model and the simulated devices behind pseudo-terminals.

pub mod backend;
pub mod config;
pub mod error;
pub mod identify;
pub mod link;
pub mod recording;
pub mod session;
pub mod sim;
pub mod target;

pub use error::RigError;
