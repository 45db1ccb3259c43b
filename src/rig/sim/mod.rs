//! Simulated benches on pseudo-terminals: devices that look exactly like real ones to the
//! host code, driven by the plant model.

pub mod dynamixel;
