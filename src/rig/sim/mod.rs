//! Simulated benches: the plant model and the simulated devices that serve it on
//! pseudo-terminals, so the host code under test talks to them exactly as to real hardware.
//!
//! - [`plant`]: the follower's response to the driver (target law plus imperfections) and
//!   the link faults, shared by every simulator.
//! - [`dynamixel`]: a Protocol 2.0 bus with an XL430-class driver servo and a torque-off
//!   follower servo.
//! - [`stepper`]: our firmware core on emulated pins and I²C sensors.
//! - [`mixed`]: a Dynamixel bus turning the mechanism and a firmware sensor board reading
//!   it, wired from a mixed rig file.
//! - [`pico`]: the board image itself, run in the rp2040js emulator, on the stepper
//!   bench's plant and sensor models.
//! - [`pty`]: pseudo-terminal pairs (and a stable symlink for re-plugging).
//!
//! It owns no host-side protocol logic: the backends in [`crate::rig::backend`] are the
//! same for real and simulated devices.

pub mod dynamixel;
pub mod mixed;
pub mod pico;
pub mod plant;
pub mod pty;
pub mod stepper;
