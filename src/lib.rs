//! # mpc-rig
//!
//! Design, fabricate and bench-verify *multi-point conjugation* mechanisms: a driver turned
//! by one motor and a follower on a revolute (1R), cylindrical (1R1T) or spherical (3R)
//! joint, whose freeform contact surfaces make the follower perform a user-specified
//! periodic motion.
//!
//! ## Data flow
//! ```text
//! motion spec ──► synth ──► mechanism.json ──► geometry ──► STL / 3MF / GLB
//!                                  │
//!                                  ▼  target law: follower pose at driver angle φ is M²(φ/2π)
//! rigs/*.toml ──► rig session ──► recording (CSV + JSON sidecar) ──► analysis ──► report
//! ```
//!
//! ## Modules
//! - [`motion`]: motion specifications (TOML keyframes, dense CSV), validation, periodic C²
//!   interpolation on SO(3), sampled poses and derivatives; the target law.
//! - [`synth`]: conjugate curve pairs with dynamic form closure; `mechanism.json`.
//! - [`rig`]: bench configuration, serial links, backends, simulated devices, sessions and
//!   recordings.
//! - [`analysis`]: measured versus target poses, metrics, timing ratios, reports.
//! - [`build`]: printable parts from a mechanism (rims, carved driver, struts, support),
//!   their checks over the period.
//! - [`geometry`]: triangle meshes in mm, the watertightness check, scenes of moving parts.
//! - [`predict`]: the virtual prototype: how the built parts move the follower.
//! - [`live`]: the live view of a run in a browser (`measure --live`): an HTTP server on
//!   the session's live feed and its page.
//! - [`plot`]: PNG/SVG charts with an embedded font, shared by every report.
//! - [`cli`]: one file per subcommand; calls into the modules above.
//!
//! Frames, classes, closure and the `mechanism.json` format follow `docs/conventions.md`.

pub mod analysis;
pub mod build;
pub mod cli;
pub mod geometry;
pub mod live;
pub mod motion;
pub mod plot;
pub mod predict;
pub mod rig;
pub mod synth;
