//! Rig configuration: what a bench is made of, loaded from `rigs/*.toml`.
//!
//! Owns the schema (driver backend, sensors with their calibration, serial ports, sampling,
//! homing, safety limits), its validation with file/line/field errors, and the calibration
//! helpers that turn raw sensor values into physical follower coordinates
//! ([`SensorConfig::to_physical`], [`ImuConfig::follower_rotation`]). The schema is
//! documented for users in `rigs/README.md`.
//!
//! It does not open ports or talk to devices (that is [`crate::rig::backend`]), and it does
//! not unwrap angles or align anything with the target (that is [`crate::analysis`]).

use std::path::{Path, PathBuf};

use nalgebra::{Quaternion, UnitQuaternion};
use serde::{Deserialize, Serialize};

/// Counts per revolution of an AS5600 12-bit magnetic encoder (datasheet: 0..4095).
pub const AS5600_COUNTS_PER_REV: u32 = 4096;

/// Counts per revolution of an XL430/XM430 Dynamixel's present position (0..4095 per turn).
pub const DYNAMIXEL_COUNTS_PER_REV: u32 = 4096;

/// Default sample rate in Hz: the firmware's 1 kHz encoder sampling, the rate the bench is
/// specified for.
pub const DEFAULT_SAMPLE_RATE_HZ: f64 = 1000.0;

/// Default dead-man watchdog period in ms: the firmware stops the motor if no heartbeat or
/// command arrives within this time. 250 ms is four missed 50 ms heartbeats.
pub const DEFAULT_WATCHDOG_MS: u32 = 250;

/// Default longest run in seconds before the session stops the driver on its own: ten
/// minutes covers many cycles at bench speeds and bounds an unattended run.
pub const DEFAULT_MAX_RUN_S: f64 = 600.0;

/// Default largest deviation of the follower from the target law before the session stops
/// the motor as a jammed mechanism, degrees of follower rotation (`safety.
/// max_follower_error_deg`): 20°. A printed mechanism with a few degrees of backlash and
/// lag stays far below it even where the law is steep, while a follower that binds falls
/// this far behind within a fraction of a driver turn.
pub const DEFAULT_MAX_FOLLOWER_ERROR_DEG: f64 = 20.0;

/// Profile Acceleration unit of an X-series servo in velocity-based profile mode, degrees
/// per second squared at the servo shaft (214.577 rev/min², e-manual).
pub const DYNAMIXEL_ACCEL_UNIT_DEG_S2: f64 = 214.577 * 360.0 / 3600.0;

/// Largest gear ratio accepted (its inverse is the smallest), for either driver kind:
/// 1000:1. Bench gearboxes and belts stay below 100:1; far beyond, a typo such as `1e9`
/// makes every speed and step-rate figure derived from it meaningless. The firmware carries
/// the ratio as a fraction of two 16-bit numbers, which this range always allows.
pub const MAX_GEAR_RATIO: f64 = 1000.0;

/// An IMU quaternion reading whose norm is further than this from 1 is garbage, not a
/// rotation to normalize: 0.1. Fused-orientation IMUs report unit quaternions to a few
/// 10⁻⁴ (the BNO055 uses 2¹⁴ LSB per unit); anything 10 % off is a corrupted value. Used by
/// the live error and the analysis alike.
pub const IMU_NORM_TOLERANCE: f64 = 0.1;

/// Tolerance on the norm of a configured mounting quaternion: beyond it the file is
/// rejected rather than silently normalized (a typo, not rounding).
pub const MOUNTING_NORM_TOLERANCE: f64 = 1e-3;

/// Error while loading or validating a rig configuration.
#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    /// The file could not be read.
    #[error("cannot read rig configuration {path}: {source}")]
    Read {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// The TOML is malformed or a field has the wrong type / an unknown name.
    #[error("{path}:{line}: {message}")]
    Parse {
        /// The file.
        path: PathBuf,
        /// 1-based line (0 when unknown).
        line: usize,
        /// The parser's message.
        message: String,
    },
    /// A field has a value that is well-formed but not acceptable.
    #[error("{path}:{line}: field `{field}`: {message}")]
    Invalid {
        /// The file.
        path: PathBuf,
        /// 1-based line of the field (0 when unknown).
        line: usize,
        /// Dotted path of the field, e.g. `sensors[1].counts_per_rev`.
        field: String,
        /// What is wrong.
        message: String,
    },
    /// A `--port` override does not fit the configured ports.
    #[error("port override `{given}`: {message}")]
    PortOverride {
        /// The override as given.
        given: String,
        /// What is wrong.
        message: String,
    },
}

/// A whole bench: driver, sensors, ports, sampling, homing and safety.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RigConfig {
    /// Short name of the bench (shown in reports).
    pub name: String,
    /// Free text for people.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub description: Option<String>,
    /// The serial ports the bench uses.
    pub ports: Vec<PortConfig>,
    /// What turns the driver.
    pub driver: DriverConfig,
    /// Our firmware board when it only reads sensors: a rig whose driver is a Dynamixel
    /// servo and whose follower is measured by firmware sensors (an IMU for 3R, an
    /// AS5600 and a linear encoder for 1R1T) names the board's port here. Absent for a
    /// stepper-firmware driver, whose board reads the firmware sensors itself.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sensor_board: Option<SensorBoardConfig>,
    /// What measures the follower, in column order of the recording.
    #[serde(default)]
    pub sensors: Vec<SensorConfig>,
    /// Sampling.
    #[serde(default)]
    pub sampling: SamplingConfig,
    /// Zeroing before a run.
    #[serde(default)]
    pub home: HomeConfig,
    /// Safety limits.
    #[serde(default)]
    pub safety: SafetyConfig,
}

/// One serial port.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PortConfig {
    /// Name the driver and sensors refer to (e.g. "firmware", "dxl").
    pub name: String,
    /// Device path, e.g. `/dev/ttyACM0`. May be omitted when given by `--port` or found by
    /// `usb_serial`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub path: Option<PathBuf>,
    /// USB serial number to find the port by, when the OS reports it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub usb_serial: Option<String>,
    /// Baud rate (USB CDC ignores it; a Dynamixel bus needs the servos' rate).
    #[serde(default = "default_baud")]
    pub baud: u32,
}

fn default_baud() -> u32 {
    115_200
}

/// Our firmware on a board of its own, reading follower sensors next to a Dynamixel bus.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SensorBoardConfig {
    /// Name of the port (in `ports`) the board is on; not the Dynamixel bus's port.
    pub port: String,
}

/// Direction sign: +1 when the motor's positive direction turns the driver counter-clockwise
/// about +z, -1 otherwise. Also used for sensor signs.
pub type Sign = i8;

/// What turns the driver.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "kebab-case")]
pub enum DriverConfig {
    /// Our firmware driving a STEP/DIR stepper driver.
    StepperFirmware(StepperDriverConfig),
    /// A Dynamixel servo (Protocol 2.0).
    Dynamixel(DynamixelDriverConfig),
}

/// Stepper through our firmware.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StepperDriverConfig {
    /// Name of the port (in `ports`) the firmware is on.
    pub port: String,
    /// Full steps per motor revolution (200 for a 1.8° motor).
    pub steps_per_rev: u32,
    /// Microstepping factor set on the driver chip (1, 2, 4, ... 256).
    pub microsteps: u32,
    /// Motor revolutions per driver revolution (1.0 for direct drive).
    #[serde(default = "one")]
    pub gear_ratio: f64,
    /// Highest driver speed in rpm (driver shaft, after the gear).
    pub max_speed_rpm: f64,
    /// Highest driver acceleration in degrees per second squared (driver shaft).
    pub max_accel: f64,
    /// +1 when positive motor steps turn the driver counter-clockwise about +z, else -1.
    #[serde(default = "plus_one")]
    pub direction: Sign,
}

impl StepperDriverConfig {
    /// Microsteps per driver revolution (after the gear ratio).
    pub fn microsteps_per_driver_rev(&self) -> f64 {
        f64::from(self.steps_per_rev) * f64::from(self.microsteps) * self.gear_ratio
    }

    /// Driver angle in degrees (direction applied) for a motor position in microsteps.
    pub fn steps_to_driver_deg(&self, microsteps: i64) -> f64 {
        f64::from(self.direction) * microsteps as f64 * 360.0 / self.microsteps_per_driver_rev()
    }

    /// Motor microsteps (signed, direction applied) for a driver angle in degrees.
    pub fn driver_deg_to_steps(&self, deg: f64) -> f64 {
        f64::from(self.direction) * deg / 360.0 * self.microsteps_per_driver_rev()
    }
}

/// Dynamixel operating mode used for the driver servo.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum DynamixelMode {
    /// Velocity control (operating mode 1).
    Velocity,
    /// Extended position control, multi-turn (operating mode 4).
    ExtendedPosition,
}

/// Driver servo on a Dynamixel bus.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DynamixelDriverConfig {
    /// Name of the port (in `ports`) the bus is on.
    pub port: String,
    /// Servo id on the bus (0..=252).
    pub id: u8,
    /// Bus baud rate (factory 57600).
    #[serde(default = "default_dxl_baud")]
    pub baud: u32,
    /// Model name, e.g. "XL430-W250" (checked against the model number on ping).
    pub model: String,
    /// Operating mode.
    pub mode: DynamixelMode,
    /// Profile velocity register value (0 = unlimited), in the servo's units.
    #[serde(default)]
    pub profile_velocity: u32,
    /// Profile acceleration register value (0 = unlimited), in the servo's units.
    #[serde(default)]
    pub profile_acceleration: u32,
    /// Servo revolutions per driver revolution.
    #[serde(default = "one")]
    pub gear_ratio: f64,
    /// +1 when the servo's positive direction turns the driver counter-clockwise about +z.
    #[serde(default = "plus_one")]
    pub direction: Sign,
}

fn default_dxl_baud() -> u32 {
    57_600
}

fn one() -> f64 {
    1.0
}

fn plus_one() -> Sign {
    1
}

impl DriverConfig {
    /// Name of the port the driver is on.
    pub fn port(&self) -> &str {
        match self {
            DriverConfig::StepperFirmware(s) => &s.port,
            DriverConfig::Dynamixel(d) => &d.port,
        }
    }

    /// Short backend name ("stepper-firmware" or "dynamixel").
    pub fn kind(&self) -> &'static str {
        match self {
            DriverConfig::StepperFirmware(_) => "stepper-firmware",
            DriverConfig::Dynamixel(_) => "dynamixel",
        }
    }
}

/// Which follower degree of freedom an encoder measures.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Dof {
    /// Rotation about z (degrees).
    Rz,
    /// Translation along z (mm).
    Tz,
}

/// A follower sensor, one or more recording columns.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "kebab-case")]
pub enum SensorConfig {
    /// AS5600 magnetic encoder read by our firmware (raw 0..4095).
    As5600(EncoderConfig),
    /// Quadrature encoder counted by our firmware (raw signed counts).
    Quadrature(EncoderConfig),
    /// IMU (BNO055-class fused orientation) read by our firmware.
    Imu(ImuConfig),
    /// A Dynamixel with torque off used as an absolute encoder on the follower joint.
    Dynamixel(DynamixelSensorConfig),
}

/// A firmware encoder channel.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EncoderConfig {
    /// Column name in the recording.
    pub name: String,
    /// Firmware encoder channel (0 or 1).
    #[serde(default)]
    pub channel: u8,
    /// Degree of freedom measured.
    pub dof: Dof,
    /// Counts per follower revolution (for `dof = "rz"`; AS5600: 4096).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub counts_per_rev: Option<f64>,
    /// Millimetres per count (for `dof = "tz"`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mm_per_count: Option<f64>,
    /// +1 when increasing counts mean a positive follower motion, else -1.
    #[serde(default = "plus_one")]
    pub sign: Sign,
    /// Raw reading at the follower's zero.
    #[serde(default)]
    pub zero_offset: f64,
}

/// A firmware IMU.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ImuConfig {
    /// Column prefix in the recording (`<name>_qw` ...).
    pub name: String,
    /// Mounting rotation q_m, scalar first `[w, x, y, z]`: a vector in IMU axes maps to
    /// follower axes as `v_f = q_m · v_imu`. Identity when omitted.
    #[serde(default = "identity_quat")]
    pub mounting: [f64; 4],
}

fn identity_quat() -> [f64; 4] {
    [1.0, 0.0, 0.0, 0.0]
}

/// A torque-off Dynamixel used as the follower's absolute encoder.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DynamixelSensorConfig {
    /// Column name in the recording.
    pub name: String,
    /// Name of the port (in `ports`) of its bus.
    pub port: String,
    /// Servo id.
    pub id: u8,
    /// Counts per revolution (4096 for XL430/XM430).
    #[serde(default = "dxl_counts")]
    pub counts_per_rev: f64,
    /// +1 when increasing position means a positive follower rotation about z.
    #[serde(default = "plus_one")]
    pub sign: Sign,
    /// Raw present position at the follower's zero.
    #[serde(default)]
    pub zero_offset: f64,
}

fn dxl_counts() -> f64 {
    f64::from(DYNAMIXEL_COUNTS_PER_REV)
}

impl SensorConfig {
    /// The sensor's name (column name or column prefix).
    pub fn name(&self) -> &str {
        match self {
            SensorConfig::As5600(e) | SensorConfig::Quadrature(e) => &e.name,
            SensorConfig::Imu(i) => &i.name,
            SensorConfig::Dynamixel(d) => &d.name,
        }
    }

    /// The recording columns this sensor produces, in order.
    pub fn columns(&self) -> Vec<ColumnSpec> {
        match self {
            SensorConfig::As5600(e) | SensorConfig::Quadrature(e) => vec![ColumnSpec {
                name: e.name.clone(),
                unit: "counts".into(),
                sensor: Some(e.name.clone()),
            }],
            SensorConfig::Dynamixel(d) => vec![ColumnSpec {
                name: d.name.clone(),
                unit: "counts".into(),
                sensor: Some(d.name.clone()),
            }],
            SensorConfig::Imu(i) => ["qw", "qx", "qy", "qz"]
                .iter()
                .map(|c| ColumnSpec {
                    name: format!("{}_{c}", i.name),
                    unit: "1".into(),
                    sensor: Some(i.name.clone()),
                })
                .collect(),
        }
    }

    /// The follower DOF a scalar sensor measures (`None` for an IMU).
    pub fn dof(&self) -> Option<Dof> {
        match self {
            SensorConfig::As5600(e) | SensorConfig::Quadrature(e) => Some(e.dof),
            SensorConfig::Dynamixel(_) => Some(Dof::Rz),
            SensorConfig::Imu(_) => None,
        }
    }

    /// Raw scalar reading → follower coordinate: degrees about z for `rz`, millimetres along
    /// z for `tz`, `(raw − zero_offset) · sign · scale`. Not unwrapped (AS5600 readings wrap
    /// every turn). `None` for an IMU (use [`ImuConfig::follower_rotation`]).
    pub fn to_physical(&self, raw: f64) -> Option<f64> {
        match self {
            SensorConfig::As5600(e) | SensorConfig::Quadrature(e) => {
                let d = (raw - e.zero_offset) * f64::from(e.sign);
                Some(match e.dof {
                    Dof::Rz => d * 360.0 / self.counts_per_rev().unwrap_or(f64::NAN),
                    Dof::Tz => d * e.mm_per_count.unwrap_or(f64::NAN),
                })
            }
            SensorConfig::Dynamixel(s) => {
                Some((raw - s.zero_offset) * f64::from(s.sign) * 360.0 / s.counts_per_rev)
            }
            SensorConfig::Imu(_) => None,
        }
    }

    /// Counts per follower revolution of a rotary scalar sensor (`None` otherwise); analysis
    /// needs it to unwrap.
    pub fn counts_per_rev(&self) -> Option<f64> {
        match self {
            SensorConfig::As5600(e) if e.dof == Dof::Rz => {
                Some(e.counts_per_rev.unwrap_or(f64::from(AS5600_COUNTS_PER_REV)))
            }
            SensorConfig::Quadrature(e) if e.dof == Dof::Rz => e.counts_per_rev,
            SensorConfig::Dynamixel(s) => Some(s.counts_per_rev),
            _ => None,
        }
    }

    /// Whether the firmware (rather than a Dynamixel bus) reads this sensor.
    pub fn is_firmware(&self) -> bool {
        !matches!(self, SensorConfig::Dynamixel(_))
    }
}

impl ImuConfig {
    /// The mounting rotation as a unit quaternion (validated at load).
    pub fn mounting_rotation(&self) -> UnitQuaternion<f64> {
        let [w, x, y, z] = self.mounting;
        UnitQuaternion::from_quaternion(Quaternion::new(w, x, y, z))
    }

    /// Follower orientation from the IMU's reported orientation `q_imu` (IMU axes → IMU
    /// world): `R₂ = q_imu · q_m⁻¹`. The IMU's world frame differs from frame R by a constant
    /// rotation that analysis estimates at home.
    pub fn follower_rotation(&self, q_imu: UnitQuaternion<f64>) -> UnitQuaternion<f64> {
        q_imu * self.mounting_rotation().inverse()
    }
}

/// A recording column: name, unit and the sensor it belongs to.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct ColumnSpec {
    /// Column header.
    pub name: String,
    /// Unit ("us", "s", "deg", "counts", "1", ...).
    pub unit: String,
    /// The sensor name, for sensor columns.
    #[serde(default)]
    pub sensor: Option<String>,
}

/// Sampling settings.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SamplingConfig {
    /// Samples per second requested from the device.
    #[serde(default = "default_rate")]
    pub rate_hz: f64,
}

fn default_rate() -> f64 {
    DEFAULT_SAMPLE_RATE_HZ
}

impl Default for SamplingConfig {
    fn default() -> Self {
        SamplingConfig {
            rate_hz: DEFAULT_SAMPLE_RATE_HZ,
        }
    }
}

/// How the bench finds its zero before a run.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum HomeMethod {
    /// The driver's current position is its zero (the user set it up by hand / by marks).
    #[default]
    ZeroHere,
    /// Leave the driver's position counter as it is.
    None,
}

/// Homing settings.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, Default)]
#[serde(deny_unknown_fields)]
pub struct HomeConfig {
    /// Method.
    #[serde(default)]
    pub method: HomeMethod,
}

/// Safety limits enforced by the host (and, for the watchdog, by the device).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SafetyConfig {
    /// Highest driver speed the session will command, rpm.
    #[serde(default = "default_safety_rpm")]
    pub max_speed_rpm: f64,
    /// Longest run in seconds; the session stops the driver after it.
    #[serde(default = "default_max_run")]
    pub max_run_s: f64,
    /// Device dead-man watchdog period in ms.
    #[serde(default = "default_watchdog")]
    pub watchdog_ms: u32,
    /// Largest follower deviation from the target (after the offset at the start is
    /// removed), degrees, before the session stops the motor as a jammed mechanism.
    #[serde(default = "default_max_follower_error")]
    pub max_follower_error_deg: f64,
}

fn default_safety_rpm() -> f64 {
    60.0
}
fn default_max_run() -> f64 {
    DEFAULT_MAX_RUN_S
}
fn default_watchdog() -> u32 {
    DEFAULT_WATCHDOG_MS
}
fn default_max_follower_error() -> f64 {
    DEFAULT_MAX_FOLLOWER_ERROR_DEG
}

impl Default for SafetyConfig {
    fn default() -> Self {
        SafetyConfig {
            max_speed_rpm: default_safety_rpm(),
            max_run_s: DEFAULT_MAX_RUN_S,
            watchdog_ms: DEFAULT_WATCHDOG_MS,
            max_follower_error_deg: DEFAULT_MAX_FOLLOWER_ERROR_DEG,
        }
    }
}

impl RigConfig {
    /// Load and validate `rigs/<name>.toml`.
    pub fn load(path: &Path) -> Result<RigConfig, ConfigError> {
        let text = std::fs::read_to_string(path).map_err(|source| ConfigError::Read {
            path: path.to_path_buf(),
            source,
        })?;
        RigConfig::from_toml_str(&text, path)
    }

    /// Parse and validate TOML text; `path` is used in messages only.
    pub fn from_toml_str(text: &str, path: &Path) -> Result<RigConfig, ConfigError> {
        let cfg: RigConfig = toml::from_str(text).map_err(|e| {
            let message = e.message().trim().to_string();
            let mut line = e.span().map_or(0, |s| line_of(text, s.start));
            // Inside tagged tables the parser points at the table header; point at the
            // offending key instead when the message names one.
            if let Some(key) = message
                .strip_prefix("unknown field `")
                .and_then(|r| r.split('`').next())
            {
                if let Some(l) = key_line_after(text, line, key) {
                    line = l;
                }
            }
            ConfigError::Parse {
                path: path.to_path_buf(),
                line,
                message,
            }
        })?;
        if let Err((segments, message)) = cfg.validate() {
            let field = render_field(&segments);
            return Err(ConfigError::Invalid {
                path: path.to_path_buf(),
                line: field_line(text, &segments).unwrap_or(0),
                field,
                message,
            });
        }
        Ok(cfg)
    }

    /// All recording sensor columns in order.
    pub fn sensor_columns(&self) -> Vec<ColumnSpec> {
        self.sensors.iter().flat_map(|s| s.columns()).collect()
    }

    /// Whether the rig mixes a Dynamixel driver bus with our firmware board as a sensor
    /// board (two ports, two device clocks).
    pub fn is_mixed(&self) -> bool {
        self.sensor_board.is_some()
    }

    /// The same rig restricted to the sensors one device reads (`firmware` true: the
    /// firmware sensors, else the Dynamixel ones), keeping their relative order. A mixed
    /// bench opens each device with its part.
    pub fn part(&self, firmware: bool) -> RigConfig {
        let mut r = self.clone();
        r.sensors.retain(|s| s.is_firmware() == firmware);
        r
    }

    /// The driver's acceleration limit in degrees per second squared of the driver shaft,
    /// as the rig sets it (`max_accel` of a stepper; a Dynamixel's `profile_acceleration`
    /// through [`DYNAMIXEL_ACCEL_UNIT_DEG_S2`] and the gear); `None` when unlimited.
    pub fn driver_accel_deg_s2(&self) -> Option<f64> {
        match &self.driver {
            DriverConfig::StepperFirmware(s) => Some(s.max_accel),
            DriverConfig::Dynamixel(d) => (d.profile_acceleration > 0).then(|| {
                f64::from(d.profile_acceleration) * DYNAMIXEL_ACCEL_UNIT_DEG_S2 / d.gear_ratio
            }),
        }
    }

    /// What the rig lacks to measure a follower of `class`, or `None` when it can: the
    /// sensors the analysis compares with the target — an IMU for 3R, a rotary (`rz`)
    /// sensor for 1R and 1R1T, and a linear (`tz`) one as well for 1R1T.
    pub fn missing_sensors(&self, class: crate::motion::MotionClass) -> Option<String> {
        use crate::motion::MotionClass;
        let has = |dof: Dof| self.sensors.iter().any(|s| s.dof() == Some(dof));
        let has_imu = self
            .sensors
            .iter()
            .any(|s| matches!(s, SensorConfig::Imu(_)));
        let mut missing = Vec::new();
        match class {
            MotionClass::R3 if !has_imu => {
                missing.push("an orientation sensor (`kind = \"imu\"`) on the follower")
            }
            MotionClass::R3 => {}
            MotionClass::R1 | MotionClass::R1T1 => {
                if !has(Dof::Rz) {
                    missing.push("a rotary sensor (`dof = \"rz\"` or a follower servo)");
                }
                if class == MotionClass::R1T1 && !has(Dof::Tz) {
                    missing.push("a linear sensor (`dof = \"tz\"`) for the height");
                }
            }
        }
        (!missing.is_empty()).then(|| {
            format!(
                "it has no {} (rigs/README.md lists the sensors each class needs)",
                missing.join(" and no ")
            )
        })
    }

    /// The port with this name.
    pub fn port(&self, name: &str) -> Option<&PortConfig> {
        self.ports.iter().find(|p| p.name == name)
    }

    /// Apply `--port` overrides: `PATH` (only when the rig has a single port) or
    /// `NAME=PATH`.
    pub fn apply_port_overrides(&mut self, overrides: &[String]) -> Result<(), ConfigError> {
        for given in overrides {
            let (name, path) = match given.split_once('=') {
                Some((n, p)) => (n.to_string(), p),
                None => {
                    if self.ports.len() != 1 {
                        return Err(ConfigError::PortOverride {
                            given: given.clone(),
                            message: format!(
                                "the rig has {} ports ({}); say which one with NAME=PATH",
                                self.ports.len(),
                                self.port_names()
                            ),
                        });
                    }
                    (self.ports[0].name.clone(), given.as_str())
                }
            };
            let names = self.port_names();
            let port = self
                .ports
                .iter_mut()
                .find(|p| p.name == name)
                .ok_or_else(|| ConfigError::PortOverride {
                    given: given.clone(),
                    message: format!("no port named `{name}` in the rig (it has: {names})"),
                })?;
            port.path = Some(PathBuf::from(path));
        }
        Ok(())
    }

    fn port_names(&self) -> String {
        self.ports
            .iter()
            .map(|p| p.name.as_str())
            .collect::<Vec<_>>()
            .join(", ")
    }

    /// Semantic checks; on failure the field path and the message.
    fn validate(&self) -> Result<(), (Vec<Seg>, String)> {
        use Seg::{Idx, Key};
        let bad = |segs: Vec<Seg>, msg: String| Err((segs, msg));
        if self.name.trim().is_empty() {
            return bad(vec![Key("name")], "must not be empty".into());
        }
        if self.ports.is_empty() {
            return bad(
                vec![Key("ports")],
                "at least one [[ports]] entry is needed".into(),
            );
        }
        for (i, p) in self.ports.iter().enumerate() {
            if self.ports[..i].iter().any(|q| q.name == p.name) {
                return bad(
                    vec![Key("ports"), Idx(i), Key("name")],
                    format!("port name `{}` is used twice", p.name),
                );
            }
            if p.baud == 0 {
                return bad(
                    vec![Key("ports"), Idx(i), Key("baud")],
                    "must be > 0".into(),
                );
            }
        }
        let has_port = |name: &str| self.ports.iter().any(|p| p.name == name);
        let sign_ok = |s: Sign| s == 1 || s == -1;
        let pos = |x: f64| x.is_finite() && x > 0.0;
        let gear_ok = |g: f64| pos(g) && (1.0 / MAX_GEAR_RATIO..=MAX_GEAR_RATIO).contains(&g);
        let gear_msg = || {
            format!(
                "must be a number from 1/{MAX_GEAR_RATIO} to {MAX_GEAR_RATIO} (motor or servo \
                 revolutions per driver revolution)"
            )
        };
        match &self.driver {
            DriverConfig::StepperFirmware(s) => {
                let f = |k: &'static str| vec![Key("driver"), Key(k)];
                if !has_port(&s.port) {
                    return bad(f("port"), format!("no [[ports]] entry named `{}`", s.port));
                }
                if s.steps_per_rev == 0 {
                    return bad(f("steps_per_rev"), "must be > 0".into());
                }
                if s.microsteps == 0 || !s.microsteps.is_power_of_two() || s.microsteps > 256 {
                    return bad(f("microsteps"), "must be a power of two, 1..=256".into());
                }
                if !gear_ok(s.gear_ratio) {
                    return bad(f("gear_ratio"), gear_msg());
                }
                if !pos(s.max_speed_rpm) {
                    return bad(f("max_speed_rpm"), "must be a positive number".into());
                }
                if !pos(s.max_accel) {
                    return bad(f("max_accel"), "must be a positive number (deg/s²)".into());
                }
                if !sign_ok(s.direction) {
                    return bad(f("direction"), "must be 1 or -1".into());
                }
            }
            DriverConfig::Dynamixel(d) => {
                let f = |k: &'static str| vec![Key("driver"), Key(k)];
                if !has_port(&d.port) {
                    return bad(f("port"), format!("no [[ports]] entry named `{}`", d.port));
                }
                if d.id > 252 {
                    return bad(f("id"), "Dynamixel ids are 0..=252".into());
                }
                if d.baud == 0 {
                    return bad(f("baud"), "must be > 0".into());
                }
                if !gear_ok(d.gear_ratio) {
                    return bad(f("gear_ratio"), gear_msg());
                }
                if !sign_ok(d.direction) {
                    return bad(f("direction"), "must be 1 or -1".into());
                }
            }
        }
        for (i, s) in self.sensors.iter().enumerate() {
            let f = |k: &'static str| vec![Key("sensors"), Idx(i), Key(k)];
            let name = s.name();
            if name.is_empty()
                || !name
                    .chars()
                    .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-')
            {
                return bad(
                    f("name"),
                    "must be non-empty and use only letters, digits, `_` and `-`".into(),
                );
            }
            let reserved = [
                "device_time_us",
                "host_time_s",
                "phase",
                "driver_angle_deg",
                "flags",
            ];
            if reserved.contains(&name) {
                return bad(f("name"), format!("`{name}` is a reserved column name"));
            }
            let cols = s.columns();
            for (j, other) in self.sensors[..i].iter().enumerate() {
                if other
                    .columns()
                    .iter()
                    .any(|c| cols.iter().any(|d| d.name == c.name))
                {
                    return bad(
                        f("name"),
                        format!("column name clashes with sensors[{j}] `{}`", other.name()),
                    );
                }
            }
            match s {
                SensorConfig::As5600(e) | SensorConfig::Quadrature(e) => {
                    if e.channel > 1 {
                        return bad(f("channel"), "the firmware has channels 0 and 1".into());
                    }
                    if !sign_ok(e.sign) {
                        return bad(f("sign"), "must be 1 or -1".into());
                    }
                    match e.dof {
                        Dof::Rz => match e.counts_per_rev {
                            Some(c) if pos(c) => {}
                            Some(_) => {
                                return bad(f("counts_per_rev"), "must be > 0".into());
                            }
                            None if matches!(s, SensorConfig::As5600(_)) => {}
                            None => {
                                return bad(
                                    f("counts_per_rev"),
                                    "needed for a rotary (dof = \"rz\") encoder".into(),
                                )
                            }
                        },
                        Dof::Tz => match e.mm_per_count {
                            Some(m) if m.is_finite() && m != 0.0 => {}
                            _ => {
                                return bad(
                                    f("mm_per_count"),
                                    "needed (non-zero) for a linear (dof = \"tz\") encoder".into(),
                                )
                            }
                        },
                    }
                    if !e.zero_offset.is_finite() {
                        return bad(f("zero_offset"), "must be finite".into());
                    }
                }
                SensorConfig::Imu(m) => {
                    let n = m.mounting.iter().map(|v| v * v).sum::<f64>().sqrt();
                    if !n.is_finite() || (n - 1.0).abs() > MOUNTING_NORM_TOLERANCE {
                        return bad(
                            f("mounting"),
                            format!("must be a unit quaternion [w, x, y, z] (norm is {n:.4})"),
                        );
                    }
                }
                SensorConfig::Dynamixel(d) => {
                    if !has_port(&d.port) {
                        return bad(f("port"), format!("no [[ports]] entry named `{}`", d.port));
                    }
                    if d.id > 252 {
                        return bad(f("id"), "Dynamixel ids are 0..=252".into());
                    }
                    if let DriverConfig::Dynamixel(drv) = &self.driver {
                        if drv.port == d.port && drv.id == d.id {
                            return bad(f("id"), "same id as the driver servo".into());
                        }
                    }
                    if !pos(d.counts_per_rev) {
                        return bad(f("counts_per_rev"), "must be > 0".into());
                    }
                    if !sign_ok(d.sign) {
                        return bad(f("sign"), "must be 1 or -1".into());
                    }
                }
            }
            if s.is_firmware()
                && matches!(self.driver, DriverConfig::Dynamixel(_))
                && self.sensor_board.is_none()
            {
                return bad(
                    f("kind"),
                    "a firmware sensor on a Dynamixel-driven rig needs our firmware board: add `[sensor_board]` with the board's `port`".into(),
                );
            }
            if let SensorConfig::Dynamixel(d) = s {
                match &self.driver {
                    DriverConfig::Dynamixel(drv) if drv.port != d.port => {
                        return bad(
                            f("port"),
                            format!(
                                "a follower servo must be on the driver's bus `{}` (one Dynamixel bus per rig)",
                                drv.port
                            ),
                        );
                    }
                    DriverConfig::StepperFirmware(_) => {
                        return bad(
                            f("kind"),
                            "a Dynamixel follower encoder needs a Dynamixel driver on its bus; a stepper-firmware rig measures the follower with firmware sensors (as5600, quadrature, imu)".into(),
                        );
                    }
                    DriverConfig::Dynamixel(_) => {}
                }
            }
        }
        if let Some(board) = &self.sensor_board {
            let f = |k: &'static str| vec![Key("sensor_board"), Key(k)];
            match &self.driver {
                DriverConfig::StepperFirmware(_) => {
                    return bad(
                        f("port"),
                        "the stepper-firmware driver's board reads the firmware sensors; `[sensor_board]` is only for a Dynamixel-driven rig".into(),
                    );
                }
                DriverConfig::Dynamixel(d) if d.port == board.port => {
                    return bad(
                        f("port"),
                        format!(
                            "`{}` is the Dynamixel bus; the firmware board needs a port of its own",
                            board.port
                        ),
                    );
                }
                DriverConfig::Dynamixel(_) => {}
            }
            if !has_port(&board.port) {
                return bad(
                    f("port"),
                    format!("no [[ports]] entry named `{}`", board.port),
                );
            }
            if !self.sensors.iter().any(SensorConfig::is_firmware) {
                return bad(
                    f("port"),
                    "the sensor board reads no sensor: add a firmware sensor (as5600, quadrature, imu) or remove `[sensor_board]`".into(),
                );
            }
        }
        if !pos(self.sampling.rate_hz) || self.sampling.rate_hz > 10_000.0 {
            return bad(
                vec![Key("sampling"), Key("rate_hz")],
                "must be in (0, 10000]".into(),
            );
        }
        let f = |k: &'static str| vec![Key("safety"), Key(k)];
        if !pos(self.safety.max_speed_rpm) {
            return bad(f("max_speed_rpm"), "must be a positive number".into());
        }
        if !pos(self.safety.max_run_s) {
            return bad(f("max_run_s"), "must be a positive number".into());
        }
        if self.safety.watchdog_ms < 20 || self.safety.watchdog_ms > 60_000 {
            return bad(f("watchdog_ms"), "must be in 20..=60000".into());
        }
        if !(pos(self.safety.max_follower_error_deg) && self.safety.max_follower_error_deg <= 180.0)
        {
            return bad(
                f("max_follower_error_deg"),
                "must be a number of degrees in (0, 180]".into(),
            );
        }
        Ok(())
    }
}

/// One step of a field path.
#[derive(Debug, Clone, Copy)]
enum Seg {
    Key(&'static str),
    Idx(usize),
}

fn render_field(segs: &[Seg]) -> String {
    let mut s = String::new();
    for seg in segs {
        match seg {
            Seg::Key(k) => {
                if !s.is_empty() {
                    s.push('.');
                }
                s.push_str(k);
            }
            Seg::Idx(i) => s.push_str(&format!("[{i}]")),
        }
    }
    s
}

/// 1-based line number of a byte offset.
fn line_of(text: &str, offset: usize) -> usize {
    text[..offset.min(text.len())]
        .bytes()
        .filter(|&b| b == b'\n')
        .count()
        + 1
}

/// First line at or after `from` (1-based) that assigns `key`.
fn key_line_after(text: &str, from: usize, key: &str) -> Option<usize> {
    text.lines()
        .enumerate()
        .skip(from.saturating_sub(1))
        .find(|(_, l)| {
            l.trim_start()
                .strip_prefix(key)
                .is_some_and(|rest| rest.trim_start().starts_with('='))
        })
        .map(|(i, _)| i + 1)
}

/// Line of the value at a field path, using the TOML parser's spans; falls back to the
/// deepest parent found.
fn field_line(text: &str, segs: &[Seg]) -> Option<usize> {
    use toml::de::{DeTable, DeValue};
    let doc = DeTable::parse(text).ok()?;
    let mut span = None;
    let mut table: Option<&DeTable> = Some(doc.get_ref());
    let mut array: Option<&toml::de::DeArray> = None;
    for seg in segs {
        let next = match (*seg, table, array) {
            (Seg::Key(k), Some(t), _) => t
                .iter()
                .find(|(key, _)| key.get_ref().as_ref() == k)
                .map(|(key, v)| (key.span(), v)),
            (Seg::Idx(i), _, Some(a)) => a.get(i).map(|v| (v.span(), v)),
            _ => None,
        };
        let Some((s, v)) = next else { break };
        span = Some(s);
        table = None;
        array = None;
        match v.get_ref() {
            DeValue::Table(t) => table = Some(t),
            DeValue::Array(a) => array = Some(a),
            _ => {}
        }
    }
    span.map(|s| line_of(text, s.start))
}

#[cfg(test)]
mod tests {
    use super::*;

    const GOOD: &str = r#"
name = "test"
[[ports]]
name = "fw"
path = "/dev/null"

[driver]
kind = "stepper-firmware"
port = "fw"
steps_per_rev = 200
microsteps = 16
max_speed_rpm = 60
max_accel = 720

[[sensors]]
kind = "as5600"
name = "follower"
dof = "rz"
sign = -1
zero_offset = 100

[[sensors]]
kind = "imu"
name = "imu"
mounting = [0.7071067811865476, 0.0, 0.0, 0.7071067811865476]
"#;

    fn load(text: &str) -> Result<RigConfig, ConfigError> {
        RigConfig::from_toml_str(text, Path::new("rigs/t.toml"))
    }

    /// Guards: a valid file loads with defaults filled in and columns in sensor order.
    #[test]
    fn loads_valid_config_with_defaults() {
        let cfg = load(GOOD).unwrap();
        assert_eq!(cfg.sampling.rate_hz, DEFAULT_SAMPLE_RATE_HZ);
        assert_eq!(cfg.safety.watchdog_ms, DEFAULT_WATCHDOG_MS);
        let cols: Vec<_> = cfg.sensor_columns().into_iter().map(|c| c.name).collect();
        assert_eq!(cols, ["follower", "imu_qw", "imu_qx", "imu_qy", "imu_qz"]);
        let DriverConfig::StepperFirmware(s) = &cfg.driver else {
            panic!()
        };
        assert_eq!(s.microsteps_per_driver_rev(), 3200.0);
        assert!((s.steps_to_driver_deg(1600) - 180.0).abs() < 1e-12);
    }

    /// Guards: a semantic error names file, line and field.
    #[test]
    fn invalid_value_names_file_line_and_field() {
        let text = GOOD.replace("microsteps = 16", "microsteps = 12");
        let err = load(&text).unwrap_err().to_string();
        assert_eq!(
            err,
            "rigs/t.toml:11: field `driver.microsteps`: must be a power of two, 1..=256"
        );
        let text = GOOD.replace("sign = -1", "sign = 2");
        let err = load(&text).unwrap_err().to_string();
        assert!(
            err.starts_with("rigs/t.toml:19: field `sensors[0].sign`"),
            "{err}"
        );
    }

    /// Guards: unknown fields and wrong types are parse errors with a line.
    #[test]
    fn unknown_field_is_rejected_with_line() {
        let text = GOOD.replace(
            "steps_per_rev = 200",
            "steps_per_rev = 200\nstep_per_rev = 1",
        );
        let err = load(&text).unwrap_err();
        match &err {
            ConfigError::Parse { line, message, .. } => {
                assert!(message.contains("step_per_rev"), "{message}");
                assert_eq!(*line, 11);
            }
            other => panic!("{other}"),
        }
    }

    /// Guards: the shipped mixed rig (Dynamixel driver + firmware board) loads, splits into
    /// its two devices' parts in column order, and each misuse of `[sensor_board]` is an
    /// error naming the field.
    #[test]
    fn mixed_rig_loads_and_sensor_board_misuse_is_rejected() {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("rigs/sim-dynamixel-imu.toml");
        let text = std::fs::read_to_string(&path).unwrap();
        let cfg = load(&text).unwrap();
        assert!(cfg.is_mixed());
        assert_eq!(cfg.part(true).sensors.len(), 1);
        assert!(cfg.part(false).sensors.is_empty());
        let cases = [
            (
                text.replace("[sensor_board]\nport = \"board\"", ""),
                "sensors[0].kind",
                "needs our firmware board",
            ),
            (
                text.replace(
                    "[sensor_board]\nport = \"board\"",
                    "[sensor_board]\nport = \"dxl\"",
                ),
                "sensor_board.port",
                "is the Dynamixel bus",
            ),
            (
                text.replace(
                    "[sensor_board]\nport = \"board\"",
                    "[sensor_board]\nport = \"pico\"",
                ),
                "sensor_board.port",
                "no [[ports]] entry named `pico`",
            ),
        ];
        for (t, field, msg) in cases {
            let err = load(&t).unwrap_err().to_string();
            assert!(
                err.contains(&format!("field `{field}`")) && err.contains(msg),
                "{err}"
            );
        }
        // A board on a stepper-firmware rig is refused.
        let err = load(&format!("{GOOD}\n[sensor_board]\nport = \"fw\"\n"))
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("sensor_board.port") && err.contains("only for a Dynamixel-driven rig"),
            "{err}"
        );
    }

    /// Guards: a reference to a port that does not exist is caught.
    #[test]
    fn dangling_port_reference_is_rejected() {
        let text = GOOD.replace("port = \"fw\"", "port = \"nope\"");
        let err = load(&text).unwrap_err().to_string();
        assert!(err.contains("driver.port") && err.contains("nope"), "{err}");
    }

    /// Guards: raw → physical conversions apply offset, sign and scale.
    #[test]
    fn to_physical_applies_calibration() {
        let cfg = load(GOOD).unwrap();
        let enc = &cfg.sensors[0];
        // AS5600 without counts_per_rev uses its 4096 counts per turn.
        assert_eq!(enc.counts_per_rev(), Some(4096.0));
        assert!((enc.to_physical(100.0 + 1024.0).unwrap() + 90.0).abs() < 1e-12);
        let SensorConfig::Imu(imu) = &cfg.sensors[1] else {
            panic!()
        };
        // IMU mounted turned +90° about z: an IMU reading of +90° about z is follower rest.
        let q = UnitQuaternion::from_euler_angles(0.0, 0.0, std::f64::consts::FRAC_PI_2);
        assert!(imu.follower_rotation(q).angle() < 1e-12);
    }

    /// Guards: `--port` overrides by bare path (single port) or by NAME=PATH.
    #[test]
    fn port_overrides() {
        let mut cfg = load(GOOD).unwrap();
        cfg.apply_port_overrides(&["/dev/ttyX".into()]).unwrap();
        assert_eq!(cfg.ports[0].path.as_deref(), Some(Path::new("/dev/ttyX")));
        cfg.apply_port_overrides(&["fw=/dev/ttyY".into()]).unwrap();
        assert_eq!(cfg.ports[0].path.as_deref(), Some(Path::new("/dev/ttyY")));
        let err = cfg.apply_port_overrides(&["dxl=/dev/ttyZ".into()]);
        assert!(err.unwrap_err().to_string().contains("no port named `dxl`"));
    }

    /// Guards: the Dynamixel driver and follower-encoder variants parse (dxl's rigs).
    #[test]
    fn dynamixel_variants_parse() {
        let text = r#"
name = "dxl"
[[ports]]
name = "bus"
baud = 57600
[driver]
kind = "dynamixel"
port = "bus"
id = 1
model = "XL430-W250"
mode = "velocity"
profile_acceleration = 50
[[sensors]]
kind = "dynamixel"
name = "follower"
port = "bus"
id = 2
"#;
        let cfg = load(text).unwrap();
        assert_eq!(cfg.sensors[0].counts_per_rev(), Some(4096.0));
        let DriverConfig::Dynamixel(d) = &cfg.driver else {
            panic!()
        };
        assert_eq!(d.mode, DynamixelMode::Velocity);
        assert_eq!(d.baud, 57600);
        let clash = text.replace("id = 2", "id = 1");
        let err = load(&clash).unwrap_err().to_string();
        assert!(err.contains("sensors[0].id"), "{err}");
    }

    /// Guards: the config round-trips through JSON (it is embedded in the sidecar).
    #[test]
    fn json_round_trip() {
        let cfg = load(GOOD).unwrap();
        let json = serde_json::to_string(&cfg).unwrap();
        let back: RigConfig = serde_json::from_str(&json).unwrap();
        assert_eq!(cfg, back);
    }
}
