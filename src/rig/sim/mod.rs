//! Simulated benches: the plant model and the simulated devices that serve it on
//! pseudo-terminals, so the host code under test talks to them exactly as to real hardware.
//!
//! - [`plant`]: the follower's response to the driver (target law plus imperfections) and
//!   the link faults, shared by every simulator.
//!
//! It owns no host-side protocol logic: the backends in [`crate::rig::backend`] are the
//! same for real and simulated devices.

pub mod plant;
