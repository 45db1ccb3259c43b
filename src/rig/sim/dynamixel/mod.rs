//! A simulated Dynamixel Protocol 2.0 bus on a pseudo-terminal: an XL430-class driver
//! servo and a torque-off follower servo whose present position obeys the plant model.
//!
//! It is faithful enough for ROBOTIS's own SDK and for the `dynamixel2` crate: the e-manual
//! framing (header, byte stuffing, CRC-16), the instructions ping, read, write, reg
//! write/action, factory reset, reboot, clear, sync read/write and bulk read/write, the
//! XL430-W250 control table (addresses, sizes, access rights, factory defaults, ranges),
//! status return level, return delay time, error numbers and the alert bit, hardware error
//! status with the shutdown mask, torque enable gating of the EEPROM, the operating modes
//! (velocity, position, extended position, PWM) with velocity-based profiles, present
//! position/velocity, the realtime tick and the bus watchdog at address 98.
//!
//! Files, one concept each:
//! - [`packet`]: framing, stuffing, CRC, the stream decoder;
//! - [`control_table`]: the XL430-W250 table description;
//! - [`servo`]: one servo's behaviour;
//! - [`bus`]: dispatch, status return rules, the driver–follower coupling;
//! - [`server`]: the pseudo-terminal thread, wire pacing and link faults.
//!
//! Known simplifications: the time-based profile (Drive Mode bit 2) is treated as
//! velocity-based; gains are stored but the motion follows the profile exactly (the plant
//! model, not the servo, carries the mechanism's imperfections); a servo never needs time
//! to boot after a reboot; the simulator answers at any baud (a pty has none) and paces its
//! replies at the baud selected in the driver's control table.
//!
//! Does not own the host side (that is `rig::backend::dynamixel`) nor the plant model.

pub mod bus;
pub mod control_table;
pub mod packet;
pub mod server;
pub mod servo;

use std::f64::consts::TAU;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};
use std::thread::JoinHandle;
use std::time::Instant;

pub use bus::{Bus, BusConfig, FollowerLaw};
pub use server::{HardwareFault, ServerEnd, ServerOptions};

use crate::rig::sim::plant::{DriverAngleSource, FollowerState, Plant, PlantConfig, PlantLaw};
use crate::rig::RigError;

/// A target law shared between threads (the simulator's plant and its caller).
#[derive(Clone)]
pub struct SharedLaw(pub Arc<dyn PlantLaw>);

impl PlantLaw for SharedLaw {
    fn follower_at(&self, t: f64) -> FollowerState {
        self.0.follower_at(t)
    }
}

impl std::fmt::Debug for SharedLaw {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("SharedLaw(..)")
    }
}

/// A motion (from a motion file or a mechanism) as the follower law of the Dynamixel bench:
/// the bench measures one rotation, so only 1R and 1R1T targets are accepted.
#[derive(Debug, Clone)]
pub struct MotionTarget(crate::motion::Motion);

impl MotionTarget {
    /// Wrap a motion; refuses a 3R motion, which a single follower servo cannot measure.
    pub fn new(motion: crate::motion::Motion) -> Result<Self, RigError> {
        if motion.angle_z(0.0).is_none() {
            return Err(RigError::Setup(format!(
                "motion `{}` is {}: a Dynamixel follower encoder measures one rotation about z; use a 1R or 1R1T target, or measure 3R with an IMU on a firmware board (`sim-device mixed --rig rigs/sim-dynamixel-imu.toml`, or the stepper bench)",
                motion.name(),
                motion.class()
            )));
        }
        Ok(Self(motion))
    }
}

impl PlantLaw for MotionTarget {
    fn follower_at(&self, t: f64) -> FollowerState {
        let pose = self.0.sample(t);
        FollowerState {
            angle_z: self.0.angle_z(t).map_or(0.0, |a| a[0]),
            height: self.0.height(t).map_or(0.0, |h| h[0]),
            rotation: pose.rotation,
        }
    }
}

/// Everything the simulated bus needs.
#[derive(Debug, Clone)]
pub struct SimDynamixelOptions {
    /// The target law the follower obeys (a mechanism's or a motion file's).
    pub target: SharedLaw,
    /// Imperfections and link faults (`--fault key=value`).
    pub plant: PlantConfig,
    /// Servo IDs, gear ratio and mounting offsets.
    pub bus: BusConfig,
    /// Wire pacing and injected hardware faults.
    pub server: ServerOptions,
}

impl SimDynamixelOptions {
    /// Default bench (driver ID 1, follower ID 2, direct drive, no faults) for a target law.
    pub fn new(target: Arc<dyn PlantLaw>) -> Self {
        Self {
            target: SharedLaw(target),
            plant: PlantConfig::default(),
            bus: BusConfig::default(),
            server: ServerOptions::default(),
        }
    }
}

/// The follower servo's view of the plant: the true follower angle with the encoder's gain
/// error, quantization and noise applied (the servo *is* the encoder), at 4096 counts/rev.
struct PlantFollower(Arc<Mutex<Plant>>);

impl FollowerLaw for PlantFollower {
    fn follower_angle(&mut self, driver_angle: f64, _t_s: f64) -> f64 {
        let mut plant = server::lock(&self.0);
        let angle = plant.follower(driver_angle).angle_z;
        let counts = plant.rotary_counts(angle, servo::PULSES_PER_REV);
        counts as f64 / servo::PULSES_PER_REV * TAU
    }
}

/// A running simulated bus. Dropping it (or [`SimDynamixelHandle::stop`]) ends the thread
/// and closes the pseudo-terminal.
#[derive(Debug)]
pub struct SimDynamixelHandle {
    path: PathBuf,
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<ServerEnd>>,
    bus: Arc<Mutex<Bus>>,
    start: Instant,
}

impl SimDynamixelHandle {
    /// Path of the pseudo-terminal to open as the serial port (e.g. `/dev/pts/7`).
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Lock the bus to inspect (or inject faults into) the simulated servos.
    pub fn bus(&self) -> MutexGuard<'_, Bus> {
        server::lock(&self.bus)
    }

    /// The driver angle (rad) at the present instant, for another simulated device on the
    /// same mechanism (the sensor board of a mixed bench): it advances the bus's mechanics
    /// to now before reading, so it is as fresh as the wall clock.
    pub fn driver_angle_source(&self) -> DriverAngleSource {
        let (bus, start) = (self.bus.clone(), self.start);
        Arc::new(move || {
            let mut b = server::lock(&bus);
            b.advance(start.elapsed().as_secs_f64());
            b.driver_angle()
        })
    }

    /// Whether the server thread is still serving.
    pub fn is_running(&self) -> bool {
        self.thread.as_ref().is_some_and(|t| !t.is_finished())
    }

    /// Stop serving and close the pseudo-terminal; returns why the server ended.
    pub fn stop(mut self) -> ServerEnd {
        self.shutdown()
    }

    /// Block until the server ends by itself (a configured disconnect).
    pub fn wait(mut self) -> ServerEnd {
        self.thread.take().map_or(ServerEnd::Stopped, |t| {
            t.join().unwrap_or(ServerEnd::Stopped)
        })
    }

    fn shutdown(&mut self) -> ServerEnd {
        self.stop.store(true, Ordering::Relaxed);
        self.thread.take().map_or(ServerEnd::Stopped, |t| {
            t.join().unwrap_or(ServerEnd::Stopped)
        })
    }
}

impl Drop for SimDynamixelHandle {
    fn drop(&mut self) {
        self.shutdown();
    }
}

/// Start a simulated bus on a new pseudo-terminal.
pub fn spawn(options: SimDynamixelOptions) -> Result<SimDynamixelHandle, RigError> {
    let plant = Arc::new(Mutex::new(Plant::new(
        options.target.clone(),
        options.plant.clone(),
    )));
    spawn_with_law(
        options.bus,
        options.server,
        Box::new(PlantFollower(plant.clone())),
        plant,
    )
}

/// Start a simulated bus whose follower obeys `law` (tests with closed-form couplings);
/// link faults come from `plant`'s configuration.
pub fn spawn_with_law(
    bus: BusConfig,
    server: ServerOptions,
    law: Box<dyn FollowerLaw>,
    plant: Arc<Mutex<Plant>>,
) -> Result<SimDynamixelHandle, RigError> {
    if bus.follower_id == Some(bus.driver_id) {
        return Err(RigError::Setup(format!(
            "simulated Dynamixel bus: driver and follower share ID {}",
            bus.driver_id
        )));
    }
    for id in std::iter::once(bus.driver_id).chain(bus.follower_id) {
        if id > 252 {
            return Err(RigError::Setup(format!(
                "simulated Dynamixel bus: servo ID {id} is outside 0..=252"
            )));
        }
    }
    if !(bus.gear_ratio.is_finite() && bus.gear_ratio != 0.0) {
        return Err(RigError::Setup(format!(
            "simulated Dynamixel bus: gear ratio {} must be finite and non-zero",
            bus.gear_ratio
        )));
    }
    let (master, slave, path) = crate::rig::sim::pty::open_raw_pair()?;
    let bus = Arc::new(Mutex::new(Bus::new(bus, law)));
    let stop = Arc::new(AtomicBool::new(false));
    let start = Instant::now();
    let thread = server::Server {
        master: std::fs::File::from(master),
        slave,
        bus: bus.clone(),
        plant,
        options: server,
        stop: stop.clone(),
        start,
    }
    .spawn()?;
    Ok(SimDynamixelHandle {
        path,
        stop,
        thread: Some(thread),
        bus,
        start,
    })
}
