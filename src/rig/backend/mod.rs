//! Drive and sense backends behind two small traits, one folder per backend.
//!
//! - [`Driver`]: what turns the driver (enable, run at a speed, move, stop, e-stop,
//!   position, safe shutdown).
//! - [`SampleStream`]: where the synchronized samples come from (start/stop streaming, poll
//!   a batch, link counts, device identity).
//!
//! A bench backend implements both ([`Bench`]); the measurement session
//! (`crate::rig::session`) is generic over them and never knows which device it talks
//! to. Simulated devices are served on pseudo-terminals, so the same backends drive them as
//! drive real hardware. Backends own their link (threads, heartbeats, reconnects, CRC and
//! gap counting); they do not write recordings or know the target law.
//!
//! Units at this interface are the driver shaft's (after gear ratio and direction sign):
//! degrees and rpm, positive = counter-clockwise about +z.

use std::time::{Duration, Instant};

pub mod stepper;

use crate::rig::recording::{Counts, DeviceInfo};
use crate::rig::RigError;

/// One synchronized sample of the whole bench.
#[derive(Debug, Clone, PartialEq)]
pub struct Sample {
    /// Device clock, unwrapped, µs since the stream started.
    pub device_time_us: u64,
    /// Driver angle, deg, unwrapped, 0 at home.
    pub driver_angle_deg: f64,
    /// One raw value per sensor column of the rig, in column order.
    pub values: Vec<f64>,
    /// [`crate::rig::recording::flags`] bits.
    pub flags: u32,
    /// Host-clock estimate of when the sample was taken, when the backend can tell: a
    /// Dynamixel sample's reply arrival minus the servo's return delay and the reply's wire
    /// time; a firmware sample's frame arrival (later than the sample by up to a batch).
    /// The mixed bench maps the two device clocks onto the host clock with it.
    pub host_instant: Option<Instant>,
}

/// What turns the driver.
pub trait Driver {
    /// Energize the motor / enable torque.
    fn enable(&mut self) -> Result<(), RigError>;
    /// De-energize the motor / disable torque.
    fn disable(&mut self) -> Result<(), RigError>;
    /// Declare the current driver position to be 0°.
    fn zero(&mut self) -> Result<(), RigError>;
    /// Turn at a constant signed speed (rpm of the driver shaft), ramping as configured.
    fn run_at(&mut self, rpm: f64) -> Result<(), RigError>;
    /// Move to an absolute driver angle (deg) with the configured profile.
    fn move_to(&mut self, deg: f64) -> Result<(), RigError>;
    /// Move by a relative driver angle (deg) with the configured profile.
    fn move_by(&mut self, deg: f64) -> Result<(), RigError>;
    /// Decelerate to a stop.
    fn stop(&mut self) -> Result<(), RigError>;
    /// Stop immediately and latch the emergency stop.
    fn estop(&mut self) -> Result<(), RigError>;
    /// Current driver angle (deg).
    fn position_deg(&mut self) -> Result<f64, RigError>;
    /// What hardware fault the driver reports, in words for the user, once a sample carried
    /// [`crate::rig::recording::flags::DRIVER_FAULT`]; `None` when it cannot tell.
    fn fault(&mut self) -> Option<String> {
        None
    }
    /// Leave the hardware safe: stop, disable the motor / torque, stop streaming. Called on
    /// every exit path of a session (end, error, Ctrl-C); must be safe to call twice.
    fn shutdown(&mut self) -> Result<(), RigError>;
}

/// Where samples come from.
pub trait SampleStream {
    /// Number of sensor values in each [`Sample`] (the rig's sensor columns).
    fn value_count(&self) -> usize;
    /// Start streaming at `rate_hz`.
    fn start_stream(&mut self, rate_hz: f64) -> Result<(), RigError>;
    /// Stop streaming.
    fn stop_stream(&mut self) -> Result<(), RigError>;
    /// Append the samples that arrive within `timeout` (returns early when some have
    /// arrived). `Err` when the link is gone for good.
    fn poll_samples(&mut self, timeout: Duration, out: &mut Vec<Sample>) -> Result<(), RigError>;
    /// Link counts so far (gaps, CRC errors, reconnects, ...; `samples` = delivered).
    fn counts(&self) -> Counts;
    /// Identity of the device(s) for the recording sidecar.
    fn device_info(&self) -> DeviceInfo;
}

/// A complete bench backend: a driver and the sample stream that goes with it.
pub trait Bench: Driver + SampleStream {}

impl<T: Driver + SampleStream> Bench for T {}

pub mod dynamixel;
pub mod mixed;

/// Open the backend a rig's driver needs, with ports resolved from the rig (after any
/// `--port` overrides).
pub fn open(rig: &crate::rig::config::RigConfig) -> Result<Box<dyn Bench + Send>, RigError> {
    use crate::rig::config::DriverConfig;
    match &rig.driver {
        DriverConfig::StepperFirmware(_) => Ok(Box::new(stepper::StepperBench::open(rig)?)),
        DriverConfig::Dynamixel(_) if rig.is_mixed() => Ok(Box::new(mixed::MixedBench::open(rig)?)),
        DriverConfig::Dynamixel(_) => Ok(Box::new(dynamixel::DynamixelBench::from_rig(rig)?)),
    }
}
