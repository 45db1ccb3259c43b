//! The rig file's schema: what a bench is made of, as serde reads it (with defaults), and
//! what the rest of the bench asks of it: sensor columns, calibration to physical units,
//! ports, the driver's acceleration, what a rig can measure.
//!
//! Does not validate values beyond their types (`validate`) nor locate fields in
//! the file (`lines`).

use std::path::PathBuf;

use nalgebra::{Quaternion, UnitQuaternion};
use serde::{Deserialize, Serialize};

use super::*;

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
            SensorConfig::As5600(e) | SensorConfig::Quadrature(e) => {
                vec![ColumnSpec::sensor(&e.name, "", "counts")]
            }
            SensorConfig::Dynamixel(d) => vec![ColumnSpec::sensor(&d.name, "", "counts")],
            SensorConfig::Imu(i) => ["qw", "qx", "qy", "qz"]
                .iter()
                .map(|c| ColumnSpec::sensor(&i.name, c, "1"))
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

impl ColumnSpec {
    /// A sensor's column: `sensor` and its `part` (`qw`… of an IMU, or none), with the unit
    /// as the header's suffix, as the leading columns carry theirs (`driver_angle_deg`), so
    /// a person or a spreadsheet reading `recording.csv` alone sees the unit
    /// (`follower_rz_counts`; issue 20). A dimensionless unit (`"1"`) adds no suffix
    /// (`imu_qw`). Recordings made before the suffix name a scalar sensor's column by the
    /// sensor alone; readers find a sensor's columns by [`ColumnSpec::sensor`].
    pub fn sensor(sensor: &str, part: &str, unit: &str) -> ColumnSpec {
        let mut name = sensor.to_string();
        for piece in [part, if unit == "1" { "" } else { unit }] {
            if !piece.is_empty() {
                name.push('_');
                name.push_str(piece);
            }
        }
        ColumnSpec {
            name,
            unit: unit.into(),
            sensor: Some(sensor.into()),
        }
    }
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
                missing.push("orientation sensor (`kind = \"imu\"`) on the follower")
            }
            MotionClass::R3 => {}
            MotionClass::R1 | MotionClass::R1T1 => {
                if !has(Dof::Rz) {
                    missing.push("rotary sensor (`dof = \"rz\"` or a follower servo)");
                }
                if class == MotionClass::R1T1 && !has(Dof::Tz) {
                    missing.push("linear sensor (`dof = \"tz\"`) for the height");
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
}
