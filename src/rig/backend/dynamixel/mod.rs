//! The Dynamixel backend: a Protocol 2.0 servo turns the driver and torque-off servos on the
//! same bus serve as absolute encoders on the follower joint, all through the `dynamixel2`
//! crate on a bus thread of its own ([`worker`]).
//!
//! Owns: finding the servos (ping, with a bus scan in the error message when an ID does not
//! answer), checking their model against the rig file, setting up the driver (operating
//! mode velocity or extended position, profile velocity/acceleration, the bus watchdog at
//! address 98 from `safety.watchdog_ms`) and the followers (torque off), an indirect-address
//! block on every servo so one sync read per sample returns realtime tick, present velocity
//! and present position, unit conversions between the driver shaft (deg, rpm, after gear
//! ratio and direction) and servo units (pulses, 0.229 rpm), and torque off on every way
//! out: [`Driver::shutdown`], drop (which also runs while unwinding) and the servo's own bus
//! watchdog if the host dies. The session's Ctrl-C handling calls `shutdown`.
//!
//! Does not own the session, the recording, or the rig file's schema.

pub mod echo;
pub mod models;
pub mod tick;
pub mod worker;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::mpsc::{self, Receiver, Sender};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use crate::rig::backend::{Driver, Sample, SampleStream};
use crate::rig::config::{
    DriverConfig, DynamixelDriverConfig, DynamixelMode, RigConfig, SensorConfig,
};
use crate::rig::recording::{flags, Counts, DeviceInfo};
use crate::rig::RigError;
use worker::{call, DxlBus, Event, Message, WorkerSetup};

/// Pulses per servo revolution (X-series).
pub const PULSES_PER_REV: f64 = 4096.0;

/// Servo velocity unit, rpm per count (X-series Goal/Present Velocity, Profile Velocity).
pub const VELOCITY_UNIT_RPM: f64 = 0.229;

/// Extended Position Control range, pulses either side of zero (±256 turns).
pub const EXTENDED_POSITION_LIMIT: i64 = 1_048_575;

/// After a silence of at least this fraction of the bus watchdog period the backend checks
/// whether the watchdog tripped. Default 0.8: the servo's timer and ours start at slightly
/// different moments.
pub const WATCHDOG_CHECK_FRACTION: f64 = 0.8;

/// Attempts per command transaction before giving up. Default 8, so setup survives the
/// noise the stream survives: with 1 % of the bytes corrupted (the stream runs on, losing
/// about half its samples) a reply of 11–20 bytes is damaged one time in five to ten, so
/// three attempts failed together about once per setup in a hundred (issue 16), eight once
/// in millions. A servo that is really gone still fails within ~0.3 s at 57600 baud.
pub const COMMAND_ATTEMPTS: u32 = 8;

/// Bus watchdog unit (address 98), ms per count.
pub const BUS_WATCHDOG_UNIT_MS: u32 = 20;

/// Longest idle time between instructions from the bus thread, as a fraction of the bus
/// watchdog period. Default 1/4: three heartbeats can be lost before the servo stops.
pub const HEARTBEAT_FRACTION: u32 = 4;

// Control table addresses used by the backend (X-series, e-manual).
const OPERATING_MODE: u16 = 11;
const VELOCITY_LIMIT: u16 = 44;
const TORQUE_ENABLE: u16 = 64;
const HARDWARE_ERROR_STATUS: u16 = 70;
const BUS_WATCHDOG: u16 = 98;
const GOAL_VELOCITY: u16 = 104;
const PROFILE_ACCELERATION: u16 = 108;
const PROFILE_VELOCITY: u16 = 112;
const GOAL_POSITION: u16 = 116;
const PRESENT_POSITION: u16 = 132;
const MODE_VELOCITY: u8 = 1;
const MODE_EXTENDED_POSITION: u8 = 4;

/// A follower encoder servo.
#[derive(Debug, Clone)]
struct Follower {
    id: u8,
}

/// The last motion command, to repeat after the bus watchdog stopped the driver.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Motion {
    /// Stopped or holding.
    Idle,
    /// Constant speed, driver rpm.
    RunAt(f64),
    /// Moving to an absolute driver angle, deg.
    MoveTo(f64),
}

/// State shared with the sample conversion.
#[derive(Debug, Clone, Copy)]
struct Shared {
    /// Driver present position taken as 0° (pulses).
    home_pulses: f64,
    /// Emergency stop latched.
    estop: bool,
    /// Operating mode currently set on the driver.
    mode: u8,
    /// Torque on.
    enabled: bool,
    /// What the driver was last told to do.
    motion: Motion,
    /// Profile Velocity last written (counts): what a watchdog trip zeroed and re-arming
    /// restores.
    profile_velocity: i32,
}

/// A Dynamixel bench: driver servo plus torque-off follower servos on one bus.
pub struct DynamixelBench {
    path: PathBuf,
    driver: DynamixelDriverConfig,
    followers: Vec<Follower>,
    max_speed_rpm: f64,
    velocity_limit_units: i32,
    watchdog_counts: u8,
    tx: Sender<Message>,
    events: Receiver<Event>,
    thread: Option<JoinHandle<()>>,
    counts: Arc<Mutex<Counts>>,
    /// Why the bus thread ended, when it ended on its own.
    fatal: worker::Fatal,
    shared: Shared,
    device: DeviceInfo,
    lost: Option<String>,
    /// The driver's hardware error, read once after its first reply with the alert bit.
    fault: Option<String>,
    shut_down: bool,
}

impl std::fmt::Debug for DynamixelBench {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("DynamixelBench")
            .field("path", &self.path)
            .field("driver", &self.driver)
            .finish()
    }
}

fn io_err(path: &Path, what: &str, e: impl std::fmt::Display) -> RigError {
    RigError::Io {
        path: path.to_path_buf(),
        message: format!("{what}: {e}"),
    }
}

impl DynamixelBench {
    /// Open the bench of a rig whose driver is `kind = "dynamixel"`, finding the bus's port
    /// path from the rig's `[[ports]]` (path, `--port` override already applied, or USB
    /// serial number).
    pub fn from_rig(rig: &RigConfig) -> Result<Self, RigError> {
        let name = rig.driver.port();
        let port = rig.port(name).ok_or_else(|| {
            RigError::Setup(format!("rig `{}` has no port named `{name}`", rig.name))
        })?;
        let path = crate::rig::link::resolve_port(port)?;
        Self::open(rig, &path)
    }

    /// Open the bench of a rig whose driver is `kind = "dynamixel"`, with the bus at
    /// `path` (already resolved from the rig's ports and `--port` overrides). Every
    /// `kind = "dynamixel"` sensor on the same port becomes a follower column.
    pub fn open(rig: &RigConfig, path: &Path) -> Result<Self, RigError> {
        let DriverConfig::Dynamixel(driver) = &rig.driver else {
            return Err(RigError::Setup(format!(
                "rig `{}`: the Dynamixel backend needs `driver.kind = \"dynamixel\"` (it is `{}`)",
                rig.name,
                rig.driver.kind()
            )));
        };
        let mut followers = Vec::new();
        for s in &rig.sensors {
            match s {
                SensorConfig::Dynamixel(d) if d.port == driver.port => followers.push(Follower { id: d.id }),
                SensorConfig::Dynamixel(d) => {
                    return Err(RigError::Setup(format!(
                        "sensor `{}` is on port `{}` but the driver bus is `{}`: one Dynamixel bus per bench",
                        d.name, d.port, driver.port
                    )))
                }
                other => {
                    return Err(RigError::Setup(format!(
                        "sensor `{}` is read by the stepper firmware, which a Dynamixel bench does not have",
                        other.name()
                    )))
                }
            }
        }
        let expected_model = models::model_number(&driver.model).ok_or_else(|| {
            RigError::Setup(format!(
                "driver.model `{}` is not a known Dynamixel X-series model (known: {})",
                driver.model,
                models::MODELS
                    .iter()
                    .map(|m| m.0)
                    .collect::<Vec<_>>()
                    .join(", ")
            ))
        })?;
        // dynamixel2 reads an echoed instruction as a reply and panics on it: refuse an
        // echoing adapter before the library sees a byte (docs/faults.md).
        if echo::port_echoes(path, driver.baud, driver.id)? {
            return Err(RigError::WrongDevice {
                path: path.to_path_buf(),
                expected: crate::rig::error::NOT_THE_SERVOS,
                detail: "it sends back every byte written to it (an RS-485 adapter without \
                         echo suppression, or a loopback): use an adapter that suppresses its \
                         own echo, such as a U2D2"
                    .into(),
            });
        }
        worker::quiet_caught_library_panics();
        let bus = DxlBus::open(path, driver.baud).map_err(|e| RigError::Open {
            path: path.to_path_buf(),
            message: e.to_string(),
        })?;
        let watchdog_counts = rig
            .safety
            .watchdog_ms
            .div_ceil(BUS_WATCHDOG_UNIT_MS)
            .clamp(1, 127);
        let heartbeat = Duration::from_millis(u64::from(
            watchdog_counts * BUS_WATCHDOG_UNIT_MS / HEARTBEAT_FRACTION,
        ));
        let setup = WorkerSetup {
            driver_id: driver.id,
            follower_ids: followers.iter().map(|f| f.id).collect(),
            heartbeat,
            baud: driver.baud,
        };
        let (tx, rx) = mpsc::channel();
        let (etx, erx) = mpsc::channel();
        let counts = Arc::new(Mutex::new(Counts::default()));
        let wcounts = counts.clone();
        let fatal = worker::Fatal::default();
        let wfatal = fatal.clone();
        let thread = std::thread::Builder::new()
            .name(worker::THREAD_NAME.into())
            .spawn(move || worker::run(bus, setup, rx, etx, wcounts, wfatal))
            .map_err(|e| RigError::Setup(format!("cannot start the Dynamixel bus thread: {e}")))?;
        let mut bench = DynamixelBench {
            path: path.to_path_buf(),
            driver: driver.clone(),
            followers,
            max_speed_rpm: rig.safety.max_speed_rpm,
            velocity_limit_units: 0,
            watchdog_counts: watchdog_counts as u8,
            tx,
            events: erx,
            thread: Some(thread),
            counts,
            fatal,
            shared: Shared {
                home_pulses: 0.0,
                estop: false,
                mode: MODE_VELOCITY,
                enabled: false,
                motion: Motion::Idle,
                profile_velocity: 0,
            },
            device: DeviceInfo {
                backend: "dynamixel".into(),
                ports: vec![path.display().to_string()],
                ..Default::default()
            },
            lost: None,
            fault: None,
            shut_down: false,
        };
        bench.identify(expected_model)?;
        bench.configure(watchdog_counts as u8)?;
        Ok(bench)
    }

    /// Run a transaction on the bus thread, retrying it on a timeout or a damaged reply
    /// (every transaction the backend makes is idempotent).
    fn bus<T: Send + 'static>(
        &self,
        what: &str,
        f: impl Fn(&mut DxlBus) -> Result<T, dynamixel2::TransferError> + Send + 'static,
    ) -> Result<T, RigError> {
        self.bus_outcome(f)
            .map_err(|failure| self.bus_failure(what, failure))
    }

    /// Run a transaction like [`Self::bus`] but hand back the library's error with the
    /// attempts made, for a caller that acts on the servo's error number.
    fn bus_outcome<T: Send + 'static>(
        &self,
        f: impl Fn(&mut DxlBus) -> Result<T, dynamixel2::TransferError> + Send + 'static,
    ) -> Result<T, BusFailure> {
        let pause = self.retry_pause();
        match call(&self.tx, move |b| with_retries(b, pause, f)) {
            Some((Ok(v), _)) => Ok(v),
            Some((Err(e), attempts)) => Err(BusFailure::Transfer(e, attempts)),
            None => Err(BusFailure::ThreadEnded),
        }
    }

    fn bus_failure(&self, what: &str, failure: BusFailure) -> RigError {
        match failure {
            BusFailure::Transfer(e, attempts) => self.transfer_error(what, &e, attempts),
            BusFailure::ThreadEnded => self.thread_ended(),
        }
    }

    fn transfer_error(&self, what: &str, e: &dynamixel2::TransferError, attempts: u32) -> RigError {
        use dynamixel2::{ReadError, TransferError};
        if let Some(n) = servo_error(e) {
            return RigError::Device {
                path: self.path.clone(),
                command: what.to_string(),
                message: format!("servo error {n} ({})", motor_error_text(n)),
            };
        }
        match e {
            TransferError::ReadError(ReadError::Io(io))
                if io.kind() == std::io::ErrorKind::TimedOut =>
            {
                RigError::CommandTimeout {
                    path: self.path.clone(),
                    command: what.to_string(),
                    attempts,
                }
            }
            other => io_err(&self.path, &format!("{what} ({attempts} attempts)"), other),
        }
    }

    fn write(&self, id: u8, address: u16, data: Vec<u8>, what: &str) -> Result<(), RigError> {
        self.bus(what, move |b| b.write(id, address, &data).map(|_| ()))
    }

    fn write_u8(&self, id: u8, address: u16, v: u8, what: &str) -> Result<(), RigError> {
        self.write(id, address, vec![v], what)
    }

    fn write_i32(&self, id: u8, address: u16, v: i32, what: &str) -> Result<(), RigError> {
        self.write(id, address, v.to_le_bytes().to_vec(), what)
    }

    /// Write a goal (velocity or position) to the driver. A servo whose bus watchdog has
    /// tripped refuses goals with a data range error until the watchdog is cleared: the
    /// host was silent too long (a stalled or loaded machine), and the servo has already
    /// stopped itself. Then re-arm it ([`Self::rearm_if_tripped`]) and write the goal once
    /// more, so a stop or a new speed is not refused for a silence that is over.
    fn write_goal(&mut self, address: u16, v: i32, what: &str) -> Result<(), RigError> {
        let id = self.driver.id;
        let write = move |b: &mut DxlBus| b.write(id, address, &v.to_le_bytes()).map(|_| ());
        match self.bus_outcome(write) {
            Err(BusFailure::Transfer(e, attempts)) if servo_error(&e) == Some(ERR_DATA_RANGE) => {
                if self.rearm_if_tripped(&format!("`{what}` was refused (data range error)"))? {
                    self.write_i32(id, address, v, what)
                } else {
                    Err(self.transfer_error(what, &e, attempts))
                }
            }
            r => r.map_err(|f| self.bus_failure(what, f)),
        }
    }

    fn read_i32(&self, id: u8, address: u16, what: &str) -> Result<i32, RigError> {
        self.bus(what, move |b| {
            b.read_u32(id, address).map(|r| r.data as i32)
        })
    }

    /// Ping the driver and followers; check models. Scan the bus for the error message when
    /// an ID does not answer.
    fn identify(&mut self, expected_model: u16) -> Result<(), RigError> {
        let ids: Vec<(u8, &str)> = std::iter::once((self.driver.id, "driver"))
            .chain(self.followers.iter().map(|f| (f.id, "follower encoder")))
            .collect();
        let mut firmware = Vec::new();
        for (id, role) in ids {
            let pause = self.retry_pause();
            let ping = call(&self.tx, move |b| with_retries(b, pause, |b| b.ping(id)).0);
            let ping = match ping {
                Some(Ok(p)) => p,
                Some(Err(e)) => {
                    let found = call(&self.tx, |b| {
                        b.scan().map(|v| {
                            v.into_iter()
                                .filter_map(|r| r.ok())
                                .map(|r| (r.motor_id, r.data.model))
                                .collect::<Vec<_>>()
                        })
                    });
                    let found = match found {
                        Some(Ok(v)) if v.is_empty() => {
                            "nothing answered a broadcast ping".to_string()
                        }
                        Some(Ok(v)) => format!(
                            "servos on the bus: {}",
                            v.iter()
                                .map(|(i, m)| format!(
                                    "ID {i} ({})",
                                    models::model_name(*m).unwrap_or("unknown model")
                                ))
                                .collect::<Vec<_>>()
                                .join(", ")
                        ),
                        _ => "the bus scan failed too".to_string(),
                    };
                    return Err(RigError::WrongDevice {
                        path: self.path.clone(),
                        expected: crate::rig::error::NOT_THE_SERVOS,
                        detail: format!(
                            "no Dynamixel answered as the {role}, ID {id}, at {} baud ({e}); {found}. Check the servo power supply, the baud rate and the IDs in the rig file",
                            self.driver.baud
                        ),
                    });
                }
                None => return Err(self.thread_ended()),
            };
            let model = ping.data.model;
            if role == "driver" && model != expected_model {
                return Err(RigError::WrongDevice {
                    path: self.path.clone(),
                    expected: crate::rig::error::NOT_THE_SERVOS,
                    detail: format!(
                        "ID {id} is model {} (model number {model}), but driver.model in the rig file is `{}` ({expected_model})",
                        models::model_name(model).unwrap_or("unknown model"),
                        self.driver.model
                    ),
                });
            }
            if models::model_name(model).is_none() {
                return Err(RigError::WrongDevice {
                    path: self.path.clone(),
                    expected: crate::rig::error::NOT_THE_SERVOS,
                    detail: format!(
                        "ID {id} ({role}) reports model number {model}, not an X-series servo with the control table this backend uses"
                    ),
                });
            }
            firmware.push(format!(
                "ID {id}: {} fw {}",
                models::model_name(model).unwrap_or("?"),
                ping.data.firmware
            ));
            if role == "driver" {
                self.device.firmware_version = Some(ping.data.firmware.to_string());
                self.device.board = Some(models::model_name(model).unwrap_or("?").to_string());
            }
        }
        self.device
            .extra
            .insert("servos".into(), serde_json::json!(firmware));
        self.device
            .extra
            .insert("baud".into(), serde_json::json!(self.driver.baud));
        self.device.clock_hz = Some(1000);
        Ok(())
    }

    /// Driver: torque off, clear a latched watchdog, operating mode, profile, watchdog,
    /// indirect block. Followers: torque off, indirect block.
    fn configure(&mut self, watchdog_counts: u8) -> Result<(), RigError> {
        let id = self.driver.id;
        self.write_u8(id, TORQUE_ENABLE, 0, "torque off (driver)")?;
        self.write_u8(id, BUS_WATCHDOG, 0, "clear bus watchdog")?;
        let hw = self.bus("read hardware error status", move |b| {
            b.read_u8(id, HARDWARE_ERROR_STATUS).map(|r| r.data)
        })?;
        if hw != 0 {
            return Err(RigError::Device {
                path: self.path.clone(),
                command: "check hardware error status".into(),
                message: format!(
                    "driver ID {id} has a latched hardware error (status 0x{hw:02X}: {}); power-cycle or reboot it after fixing the cause",
                    hardware_error_text(hw)
                ),
            });
        }
        let mode = match self.driver.mode {
            DynamixelMode::Velocity => MODE_VELOCITY,
            DynamixelMode::ExtendedPosition => MODE_EXTENDED_POSITION,
        };
        self.set_mode(mode)?;
        self.velocity_limit_units = self.read_i32(id, VELOCITY_LIMIT, "read velocity limit")?;
        self.write_u8(id, BUS_WATCHDOG, watchdog_counts, "set bus watchdog")?;
        for f in self.followers.clone() {
            self.write_u8(f.id, TORQUE_ENABLE, 0, "torque off (follower encoder)")?;
        }
        let all: Vec<u8> = std::iter::once(id)
            .chain(self.followers.iter().map(|f| f.id))
            .collect();
        for sid in all {
            let mut data = Vec::with_capacity(2 * worker::STREAM_SOURCES.len());
            for src in worker::STREAM_SOURCES {
                data.extend_from_slice(&src.to_le_bytes());
            }
            self.write(
                sid,
                worker::INDIRECT_ADDRESS_1,
                data,
                "map the streamed block (indirect addresses)",
            )?;
        }
        self.zero()?;
        Ok(())
    }

    /// Write the driver's Profile Velocity (counts) and remember it for re-arming.
    fn set_profile_velocity(&mut self, units: i32) -> Result<(), RigError> {
        self.write_i32(
            self.driver.id,
            PROFILE_VELOCITY,
            units,
            "set profile velocity",
        )?;
        self.shared.profile_velocity = units;
        Ok(())
    }

    /// Switch the driver's operating mode (torque off meanwhile) and restore the profile,
    /// which a mode change resets.
    fn set_mode(&mut self, mode: u8) -> Result<(), RigError> {
        let id = self.driver.id;
        let was_enabled = self.shared.enabled;
        if was_enabled {
            self.write_u8(id, TORQUE_ENABLE, 0, "torque off for a mode change")?;
        }
        self.write_u8(id, OPERATING_MODE, mode, "set operating mode")?;
        self.write_i32(
            id,
            PROFILE_ACCELERATION,
            self.driver.profile_acceleration as i32,
            "set profile acceleration",
        )?;
        self.set_profile_velocity(self.driver.profile_velocity as i32)?;
        self.shared.mode = mode;
        if was_enabled {
            self.write_u8(id, TORQUE_ENABLE, 1, "torque on after a mode change")?;
        }
        Ok(())
    }

    /// Servo pulses per driver degree, signed by the direction.
    fn pulses_per_deg(&self) -> f64 {
        f64::from(self.driver.direction) * self.driver.gear_ratio * PULSES_PER_REV / 360.0
    }

    /// Driver angle (deg) for a servo present position.
    pub fn driver_deg(&self, pulses: i32) -> f64 {
        (f64::from(pulses) - self.shared.home_pulses) / self.pulses_per_deg()
    }

    /// Goal Velocity units for a driver speed (rpm), checked against the rig's safety limit
    /// and the servo's Velocity Limit.
    pub fn velocity_units(&self, rpm: f64) -> Result<i32, RigError> {
        if !rpm.is_finite() || rpm.abs() > self.max_speed_rpm {
            return Err(RigError::Safety(format!(
                "{rpm} rpm exceeds safety.max_speed_rpm = {} rpm of the rig",
                self.max_speed_rpm
            )));
        }
        let servo_rpm = rpm * self.driver.gear_ratio * f64::from(self.driver.direction);
        let units = (servo_rpm / VELOCITY_UNIT_RPM).round();
        if units.abs() > f64::from(self.velocity_limit_units) {
            return Err(RigError::Safety(format!(
                "{rpm} rpm at the driver is {:.1} rpm at the servo, above its Velocity Limit of {:.1} rpm ({} × 0.229 rpm)",
                servo_rpm.abs(),
                f64::from(self.velocity_limit_units) * VELOCITY_UNIT_RPM,
                self.velocity_limit_units
            )));
        }
        Ok(units as i32)
    }

    /// The error for a bus thread that is gone, with its reason when it ended on its own.
    fn thread_ended(&self) -> RigError {
        RigError::Disconnected {
            path: self.path.clone(),
            message: self
                .fatal
                .lock()
                .unwrap_or_else(|p| p.into_inner())
                .clone()
                .unwrap_or_else(|| "the bus thread has ended".into()),
        }
    }

    fn check_lost(&self) -> Result<(), RigError> {
        match &self.lost {
            Some(m) => Err(RigError::Disconnected {
                path: self.path.clone(),
                message: m.clone(),
            }),
            None => Ok(()),
        }
    }

    fn goal_position(&mut self, pulses: f64) -> Result<(), RigError> {
        let goal = pulses.round() as i64;
        if goal.abs() > EXTENDED_POSITION_LIMIT {
            return Err(RigError::Safety(format!(
                "goal {goal} pulses is outside the servo's extended position range ±{EXTENDED_POSITION_LIMIT} (±256 turns)"
            )));
        }
        if self.shared.mode != MODE_EXTENDED_POSITION {
            self.set_mode(MODE_EXTENDED_POSITION)?;
        }
        self.write_goal(GOAL_POSITION, goal as i32, "set goal position")
    }

    /// After the bus was silent for `silent`: if that was long enough for the servos' bus
    /// watchdog to trip, clear it, re-arm it and repeat the last motion command. Returns
    /// whether the watchdog had tripped (counted as a reconnect).
    fn rearm_after_silence(&mut self, silent: Duration) -> Result<bool, RigError> {
        let period = Duration::from_millis(
            u64::from(self.watchdog_counts) * u64::from(BUS_WATCHDOG_UNIT_MS),
        );
        if silent < period.mul_f64(WATCHDOG_CHECK_FRACTION) {
            return Ok(false);
        }
        let why = format!(
            "the bus was silent for {:.0} ms",
            silent.as_secs_f64() * 1e3
        );
        if !self.rearm_if_tripped(&why)? {
            return Ok(false);
        }
        match self.shared.motion {
            Motion::Idle => {}
            Motion::RunAt(rpm) => self.run_at(rpm)?,
            Motion::MoveTo(deg) => self.move_to(deg)?,
        }
        Ok(true)
    }

    /// If the driver's bus watchdog has tripped (it reads 0xFF): clear it, re-arm it and
    /// restore the profile the trip zeroed; counted as a reconnect. `why` says what noticed
    /// it, for the warning. Returns whether it had tripped. The caller repeats or writes
    /// the goal it wants: a trip leaves the driver stopped.
    fn rearm_if_tripped(&mut self, why: &str) -> Result<bool, RigError> {
        let id = self.driver.id;
        let wd = self.bus("read bus watchdog", move |b| {
            b.read_u8(id, BUS_WATCHDOG).map(|r| r.data)
        })?;
        if wd != 0xFF {
            return Ok(false);
        }
        tracing::warn!("{why}: the driver's bus watchdog had stopped it; re-arming");
        self.write_u8(id, BUS_WATCHDOG, 0, "clear bus watchdog error")?;
        self.write_u8(
            id,
            BUS_WATCHDOG,
            self.watchdog_counts,
            "re-arm bus watchdog",
        )?;
        // The trip zeroed the profile registers: restore them before repeating the command.
        self.write_i32(
            id,
            PROFILE_ACCELERATION,
            self.driver.profile_acceleration as i32,
            "set profile acceleration",
        )?;
        self.set_profile_velocity(self.shared.profile_velocity)?;
        self.counts
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .reconnects += 1;
        Ok(true)
    }

    /// The port path.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The wait before retrying a failed command: as long as the streamed replies of every
    /// servo take at the factory return delay ([`worker::quiet_time`]).
    fn retry_pause(&self) -> Duration {
        worker::quiet_time(
            worker::reply_latency(worker::FACTORY_RETURN_DELAY, self.driver.baud),
            1 + self.followers.len(),
        )
    }

    /// The driver's Hardware Error Status in words (after it set the alert bit).
    fn read_hardware_error(&self) -> String {
        let id = self.driver.id;
        match self.bus("read hardware error status", move |b| {
            b.read_u8(id, HARDWARE_ERROR_STATUS).map(|r| r.data)
        }) {
            Ok(bits) => format!(
                "driver ID {id} reports a hardware error: {} (status 0x{bits:02X}); it has \
                 switched its torque off, power-cycle or reboot it after fixing the cause",
                hardware_error_text(bits)
            ),
            Err(e) => format!(
                "driver ID {id} reports a hardware error (alert bit); its Hardware Error \
                 Status could not be read: {e}"
            ),
        }
    }
}

impl Driver for DynamixelBench {
    fn enable(&mut self) -> Result<(), RigError> {
        self.check_lost()?;
        self.shared.estop = false;
        self.write_u8(self.driver.id, TORQUE_ENABLE, 1, "torque on")?;
        self.shared.enabled = true;
        Ok(())
    }

    fn disable(&mut self) -> Result<(), RigError> {
        self.shared.motion = Motion::Idle;
        self.write_u8(self.driver.id, TORQUE_ENABLE, 0, "torque off")?;
        self.shared.enabled = false;
        Ok(())
    }

    fn zero(&mut self) -> Result<(), RigError> {
        let p = self.read_i32(self.driver.id, PRESENT_POSITION, "read present position")?;
        self.shared.home_pulses = f64::from(p);
        Ok(())
    }

    fn run_at(&mut self, rpm: f64) -> Result<(), RigError> {
        self.check_lost()?;
        let units = self.velocity_units(rpm)?;
        match self.driver.mode {
            DynamixelMode::Velocity => {
                if self.shared.mode != MODE_VELOCITY {
                    self.set_mode(MODE_VELOCITY)?;
                }
                self.write_goal(GOAL_VELOCITY, units, "set goal velocity")?;
            }
            DynamixelMode::ExtendedPosition => {
                // Constant speed in position mode: the far end of the range at the profile
                // velocity of the requested speed.
                if self.shared.mode != MODE_EXTENDED_POSITION {
                    self.set_mode(MODE_EXTENDED_POSITION)?;
                }
                self.set_profile_velocity(units.abs())?;
                let far = if units >= 0 {
                    EXTENDED_POSITION_LIMIT
                } else {
                    -EXTENDED_POSITION_LIMIT
                };
                self.write_goal(GOAL_POSITION, far as i32, "set goal position")?;
            }
        }
        self.shared.motion = Motion::RunAt(rpm);
        Ok(())
    }

    fn move_to(&mut self, deg: f64) -> Result<(), RigError> {
        self.check_lost()?;
        let target = self.shared.home_pulses + deg * self.pulses_per_deg();
        if self.shared.mode == MODE_EXTENDED_POSITION
            && self.driver.mode == DynamixelMode::ExtendedPosition
        {
            self.set_profile_velocity(self.driver.profile_velocity as i32)?;
        }
        self.goal_position(target)?;
        self.shared.motion = Motion::MoveTo(deg);
        Ok(())
    }

    fn move_by(&mut self, deg: f64) -> Result<(), RigError> {
        let now = self.position_deg()?;
        self.move_to(now + deg)
    }

    fn stop(&mut self) -> Result<(), RigError> {
        self.shared.motion = Motion::Idle;
        if self.shared.mode == MODE_VELOCITY {
            self.write_goal(GOAL_VELOCITY, 0, "stop (goal velocity 0)")
        } else {
            let p = self.read_i32(self.driver.id, PRESENT_POSITION, "read present position")?;
            self.write_goal(GOAL_POSITION, p, "stop (goal = present position)")
        }
    }

    fn estop(&mut self) -> Result<(), RigError> {
        self.shared.estop = true;
        self.disable()
    }

    fn position_deg(&mut self) -> Result<f64, RigError> {
        let p = self.read_i32(self.driver.id, PRESENT_POSITION, "read present position")?;
        Ok(self.driver_deg(p))
    }

    fn fault(&mut self) -> Option<String> {
        self.fault.clone()
    }

    fn shutdown(&mut self) -> Result<(), RigError> {
        if self.shut_down {
            return Ok(());
        }
        let _ = self.tx.send(Message::Stop);
        let stopped = self.stop();
        let off = self.disable();
        // Leave the bus watchdog off so a torque-on by another tool is not stopped by it.
        let _ = self.write_u8(self.driver.id, BUS_WATCHDOG, 0, "clear bus watchdog");
        self.shut_down = off.is_ok();
        off.and(stopped.or(Ok(())))
    }
}

impl SampleStream for DynamixelBench {
    fn value_count(&self) -> usize {
        self.followers.len()
    }

    fn start_stream(&mut self, rate_hz: f64) -> Result<(), RigError> {
        self.check_lost()?;
        if !(rate_hz.is_finite() && rate_hz > 0.0) {
            return Err(RigError::Setup(format!(
                "sample rate {rate_hz} Hz must be positive"
            )));
        }
        self.tx
            .send(Message::Start(Duration::from_secs_f64(1.0 / rate_hz)))
            .map_err(|_| self.thread_ended())
    }

    fn stop_stream(&mut self) -> Result<(), RigError> {
        let _ = self.tx.send(Message::Stop);
        Ok(())
    }

    fn poll_samples(&mut self, timeout: Duration, out: &mut Vec<Sample>) -> Result<(), RigError> {
        self.check_lost()?;
        let deadline = Instant::now() + timeout;
        let mut got = false;
        loop {
            let ev = if got {
                match self.events.try_recv() {
                    Ok(ev) => ev,
                    Err(_) => return Ok(()),
                }
            } else {
                match self
                    .events
                    .recv_timeout(deadline.saturating_duration_since(Instant::now()))
                {
                    Ok(ev) => ev,
                    Err(mpsc::RecvTimeoutError::Timeout) => return Ok(()),
                    Err(mpsc::RecvTimeoutError::Disconnected) => return Err(self.thread_ended()),
                }
            };
            match ev {
                Event::Sample(raw) => {
                    let mut f = raw.flags;
                    if self.shared.estop {
                        f |= flags::ESTOP;
                    }
                    if raw.alert {
                        f |= flags::DRIVER_FAULT;
                        if self.fault.is_none() {
                            self.fault = Some(self.read_hardware_error());
                        }
                    }
                    if let Some(silent) = raw.resumed_after {
                        if self.rearm_after_silence(silent)? {
                            f |= flags::RECONNECTED;
                        }
                    }

                    out.push(Sample {
                        device_time_us: raw.device_time_us,
                        driver_angle_deg: self.driver_deg(raw.driver_position),
                        values: raw.followers.iter().map(|&p| f64::from(p)).collect(),
                        flags: f,
                        host_instant: Some(raw.host_instant),
                    });
                    got = true;
                }
                Event::Lost(message) => {
                    self.lost = Some(message.clone());
                    return Err(RigError::Disconnected {
                        path: self.path.clone(),
                        message,
                    });
                }
            }
        }
    }

    fn counts(&self) -> Counts {
        *self.counts.lock().unwrap_or_else(|p| p.into_inner())
    }

    fn device_info(&self) -> DeviceInfo {
        let mut d = self.device.clone();
        d.extra
            .entry("mode".into())
            .or_insert_with(|| serde_json::json!(format!("{:?}", self.driver.mode)));
        d
    }
}

impl Drop for DynamixelBench {
    fn drop(&mut self) {
        // The worker turns the driver's torque off on Quit.
        let _ = self.tx.send(Message::Quit);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

/// Whether a failed transaction is worth repeating: no reply in time, or a reply damaged on
/// the wire (including one `dynamixel2` panicked on). A servo's own error reply (e.g.
/// Access error) is not.
fn retryable(e: &dynamixel2::TransferError) -> bool {
    use dynamixel2::{ReadError, TransferError};
    match e {
        TransferError::ReadError(ReadError::Io(io))
            if io.kind() == std::io::ErrorKind::TimedOut =>
        {
            true
        }
        e if worker::is_library_panic(e) => true,
        TransferError::ReadError(ReadError::InvalidMessage(_)) => true,
        TransferError::ReadError(ReadError::BufferFull(_)) => true,
        _ => false,
    }
}

/// Longest a failed command waits for the line to go quiet before its next attempt: 1 s.
/// A bus stall leaves a backlog of late replies to the sync reads sent during it (a 0.4 s
/// stall at 57 600 baud: about a quarter of a second of them); read as the next attempt's
/// answer, each failed it ("invalid parameter count") until the attempts ran out.
pub const DRAIN_LIMIT: Duration = Duration::from_secs(1);

/// A failed command's line counts as quiet after this many retry pauses without a reply:
/// 3. A backlog's replies answer queued instructions one by one, each gap an
/// instruction's wire time plus the replies' (7 ms for one servo at 57 600 baud), which
/// one pause (the replies' latency plus 2 ms, 6.3 ms there) does not cover; two do for any
/// number of servos, and the third is for a simulator or adapter that hiccups mid-backlog.
pub const DRAIN_QUIET_PAUSES: u32 = 3;

/// Read and drop status replies until none arrives for `quiet` (at most [`DRAIN_LIMIT`]):
/// late answers to earlier instructions, which the next attempt would otherwise take for
/// its own. Returns how many were dropped.
///
/// Only a read that consumed its bytes (a reply, or one with a bad checksum or a servo
/// error) continues the loop. `dynamixel2` leaves a header whose length field a lost byte
/// made too large for its buffer ("buffer full") in place for the next instruction to
/// discard, so reading again returns the same error at once: CI saw that loop spin for the
/// whole second, the host silent on the bus meanwhile, the servos' bus watchdog trip and the
/// run's final stop refused. Such a read, or a failing port, ends the drain after waiting
/// `quiet` for late replies to arrive; the next instruction discards them.
fn drain(bus: &mut DxlBus, quiet: Duration) -> usize {
    use dynamixel2::{ReadError, TransferError};
    let end = Instant::now() + DRAIN_LIMIT;
    let mut dropped = 0;
    while Instant::now() < end {
        let read = worker::transaction(|| {
            bus.read_status_response_deadline(Instant::now() + quiet)
                .map(|_| ())
                .map_err(TransferError::ReadError)
        });
        match read {
            // A late reply, or a damaged one: either way not the next attempt's.
            Ok(())
            | Err(TransferError::ReadError(ReadError::InvalidMessage(_)))
            | Err(TransferError::ReadError(ReadError::MotorError(_))) => dropped += 1,
            Err(TransferError::ReadError(ReadError::Io(io)))
                if io.kind() == std::io::ErrorKind::TimedOut =>
            {
                break
            }
            Err(_) => {
                std::thread::sleep(quiet);
                break;
            }
        }
    }
    dropped
}

/// Run `f` up to [`COMMAND_ATTEMPTS`] times while it fails retryably, draining the line
/// until it has been quiet for [`DRAIN_QUIET_PAUSES`] × `pause` before each new attempt
/// ([`drain`]) so late replies
/// (of this transaction or of sync reads before it) are discarded rather than read as its
/// answer; returns the last result and the number of attempts made.
fn with_retries<T>(
    bus: &mut DxlBus,
    pause: Duration,
    f: impl Fn(&mut DxlBus) -> Result<T, dynamixel2::TransferError>,
) -> (Result<T, dynamixel2::TransferError>, u32) {
    let mut attempt = 1;
    loop {
        match worker::transaction(|| f(bus)) {
            Err(e) if retryable(&e) && attempt < COMMAND_ATTEMPTS => {
                attempt += 1;
                let dropped = drain(bus, pause * DRAIN_QUIET_PAUSES);
                if dropped > 0 {
                    tracing::debug!("dropped {dropped} late replies before attempt {attempt}");
                }
            }
            r => return (r, attempt),
        }
    }
}

/// Status packet error number "data range error" (e-manual, Protocol 2.0), which a servo
/// whose bus watchdog has tripped answers to every goal write.
const ERR_DATA_RANGE: u8 = 4;

/// A bus transaction that failed: the library's error after the attempts made, or the bus
/// thread gone.
enum BusFailure {
    Transfer(dynamixel2::TransferError, u32),
    ThreadEnded,
}

/// The servo's own error number, when the failure is the servo's error reply.
fn servo_error(e: &dynamixel2::TransferError) -> Option<u8> {
    match e {
        dynamixel2::TransferError::ReadError(dynamixel2::ReadError::MotorError(m)) => {
            Some(m.raw & 0x7F)
        }
        _ => None,
    }
}

/// Text for a status packet error number (e-manual, Protocol 2.0).
pub fn motor_error_text(n: u8) -> &'static str {
    match n {
        1 => "result fail",
        2 => "instruction error",
        3 => "CRC error",
        4 => "data range error",
        5 => "data length error",
        6 => "data limit error",
        7 => "access error (read-only item, or EEPROM while torque is on)",
        _ => "unknown error",
    }
}

/// Text for Hardware Error Status bits (address 70).
pub fn hardware_error_text(bits: u8) -> String {
    let names: BTreeMap<u8, &str> = [
        (0x01, "input voltage"),
        (0x04, "overheating"),
        (0x08, "motor encoder"),
        (0x10, "electrical shock"),
        (0x20, "overload"),
    ]
    .into_iter()
    .collect();
    let v: Vec<&str> = names
        .iter()
        .filter(|(b, _)| bits & **b != 0)
        .map(|(_, n)| *n)
        .collect();
    if v.is_empty() {
        "unknown".into()
    } else {
        v.join(", ")
    }
}
