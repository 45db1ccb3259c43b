//! The bench: rig configuration, serial links, drive and sense backends (our stepper
//! firmware, Dynamixel servos, simulated devices on pseudo-terminals), the measurement
//! session and the recording it writes.
//!
//! It does not judge the measurement: comparing against the target is [`crate::analysis`].

pub mod sim;
