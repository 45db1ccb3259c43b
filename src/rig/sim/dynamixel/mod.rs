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

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};
use std::thread::JoinHandle;

pub use bus::{Bus, BusConfig, FollowerLaw};
pub use server::{HardwareFault, LinkFaults, ServerEnd, ServerOptions};

/// What can go wrong when starting the simulated bus.
#[derive(Debug, thiserror::Error)]
pub enum SimDynamixelError {
    /// The pseudo-terminal could not be created or configured.
    #[error("simulated Dynamixel bus: pseudo-terminal: {0}")]
    Pty(String),
    /// The bench layout is inconsistent.
    #[error("simulated Dynamixel bus: {0}")]
    Config(String),
}

/// Everything the simulator needs besides the plant model.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct SimDynamixelOptions {
    /// Servo IDs, gear ratio and mounting offsets.
    pub bus: BusConfig,
    /// Wire pacing and injected faults.
    pub server: ServerOptions,
}

/// A running simulated bus. Dropping it (or [`SimDynamixelHandle::stop`]) ends the thread
/// and closes the pseudo-terminal.
#[derive(Debug)]
pub struct SimDynamixelHandle {
    path: PathBuf,
    stop: Arc<AtomicBool>,
    thread: Option<JoinHandle<ServerEnd>>,
    bus: Arc<Mutex<Bus>>,
}

impl SimDynamixelHandle {
    /// Path of the pseudo-terminal to open as the serial port (e.g. `/dev/pts/7`).
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Lock the bus to inspect (or inject faults into) the simulated servos.
    pub fn bus(&self) -> MutexGuard<'_, Bus> {
        self.bus.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// Whether the server thread is still serving.
    pub fn is_running(&self) -> bool {
        self.thread.as_ref().is_some_and(|t| !t.is_finished())
    }

    /// Stop serving and close the pseudo-terminal; returns why the server ended.
    pub fn stop(mut self) -> ServerEnd {
        self.shutdown()
    }

    /// Block until the server ends by itself (a configured disconnect) or is stopped.
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

/// Start a simulated bus on a new pseudo-terminal with the given follower law.
pub fn spawn_with_law(
    options: SimDynamixelOptions,
    law: Box<dyn FollowerLaw>,
) -> Result<SimDynamixelHandle, SimDynamixelError> {
    let b = &options.bus;
    if b.follower_id == Some(b.driver_id) {
        return Err(SimDynamixelError::Config(format!(
            "driver and follower share ID {}",
            b.driver_id
        )));
    }
    for id in std::iter::once(b.driver_id).chain(b.follower_id) {
        if id > 252 {
            return Err(SimDynamixelError::Config(format!(
                "servo ID {id} is outside 0..=252"
            )));
        }
    }
    if !(b.gear_ratio.is_finite() && b.gear_ratio != 0.0) {
        return Err(SimDynamixelError::Config(format!(
            "gear ratio {} must be finite and non-zero",
            b.gear_ratio
        )));
    }
    let (master, slave, path) = server::open_raw_pty()?;
    let bus = Arc::new(Mutex::new(Bus::new(options.bus.clone(), law)));
    let stop = Arc::new(AtomicBool::new(false));
    let thread = server::Server {
        master: std::fs::File::from(master),
        slave,
        bus: bus.clone(),
        options: options.server,
        stop: stop.clone(),
    }
    .spawn()?;
    Ok(SimDynamixelHandle {
        path,
        stop,
        thread: Some(thread),
        bus,
    })
}
