//! Host → device commands and the bench configuration they carry.
//!
//! Owns the command set, its tags and field layout, and the range checks a configuration
//! must pass on any device. It does not decide what a device does with a command
//! (`mpc-firmware-core` does) nor when the host retries ([`crate::host`]).
//!
//! Angles and speeds are those of the **driver (output) shaft**, in millidegrees,
//! millidegrees/s and millidegrees/s²; the device converts them to microsteps with the
//! configured steps/rev, microstepping and gear ratio. Positions reported back by the device
//! are in microsteps, exact.

use crate::codec::{DecodeError, EncodeError, Message, Reader, Writer};
use crate::flags::SensorSet;
use crate::MAX_BATCH;

/// Microstep settings a STEP/DIR driver of the A4988/TMC2209 class offers.
pub const VALID_MICROSTEPS: [u16; 9] = [1, 2, 4, 8, 16, 32, 64, 128, 256];

/// Shortest dead-man timeout a configuration may ask for, in ms. Default 20 ms: below that
/// ordinary USB scheduling jitter on the host would trip the watchdog.
pub const MIN_WATCHDOG_MS: u16 = 20;

/// Highest sample rate a configuration may ask for, in Hz. Default 1000 Hz: the encoder
/// rate the bench is designed for; the device may advertise less.
pub const MAX_SAMPLE_RATE_HZ: u16 = 1000;

/// Bench configuration sent with [`Command::Configure`].
///
/// Wire layout (25 bytes): `steps_per_rev u16, microsteps u16, gear_motor u16,
/// gear_output u16, max_speed_mdeg_s u32, max_accel_mdeg_s2 u32, reverse bool,
/// sample_rate_hz u16, sensors u8, batch_len u8, watchdog_ms u16, imu_every u8,
/// reserved u8 (0)`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Config {
    /// Full steps per motor revolution (200 for a 1.8° motor).
    pub steps_per_rev: u16,
    /// Microsteps per full step, one of [`VALID_MICROSTEPS`].
    pub microsteps: u16,
    /// Gear ratio numerator: motor revolutions per `gear_output` driver revolutions.
    pub gear_motor: u16,
    /// Gear ratio denominator: driver revolutions per `gear_motor` motor revolutions.
    pub gear_output: u16,
    /// Highest driver speed, millidegrees per second (> 0).
    pub max_speed_mdeg_s: u32,
    /// Acceleration and deceleration of every ramp, millidegrees per second² (> 0).
    pub max_accel_mdeg_s2: u32,
    /// Invert the DIR pin (positive angles turn the other way).
    pub reverse: bool,
    /// Sampling rate, Hz (1..=[`MAX_SAMPLE_RATE_HZ`]).
    pub sample_rate_hz: u16,
    /// Sensors to sample; their fields appear in every sample batch.
    pub sensors: SensorSet,
    /// Samples per batch frame (1..=[`MAX_BATCH`]).
    pub batch_len: u8,
    /// Dead-man timeout: the motor stops when no command arrives for this long, ms
    /// (≥ [`MIN_WATCHDOG_MS`]).
    pub watchdog_ms: u16,
    /// Read the IMU on every `imu_every`-th sample (≥ 1); between reads the latest
    /// quaternion is repeated with [`crate::SampleFlags::IMU_FRESH`] clear.
    pub imu_every: u8,
}

impl Default for Config {
    /// A 1.8° motor at 1/16 microstepping, direct drive, 1 rev/s max, 2 rev/s², 1 kHz
    /// sampling of encoder A in batches of 10, 250 ms watchdog, IMU at 1/10 of the rate.
    fn default() -> Self {
        Self {
            steps_per_rev: 200,
            microsteps: 16,
            gear_motor: 1,
            gear_output: 1,
            max_speed_mdeg_s: 360_000,
            max_accel_mdeg_s2: 720_000,
            reverse: false,
            sample_rate_hz: 1000,
            sensors: SensorSet::ENCODER_A,
            batch_len: 10,
            watchdog_ms: 250,
            imu_every: 10,
        }
    }
}

/// Why a configuration is invalid on any device.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum ConfigError {
    /// `field` is out of its range.
    #[error("config field `{field}` = {value} is out of range ({expected})")]
    OutOfRange {
        /// Field name.
        field: &'static str,
        /// Value given.
        value: u32,
        /// The accepted range, in words.
        expected: &'static str,
    },
}

impl Config {
    /// Microsteps per driver-shaft revolution as a fraction `(num, den)`.
    pub fn microsteps_per_output_rev(&self) -> (u64, u64) {
        (
            self.steps_per_rev as u64 * self.microsteps as u64 * self.gear_motor as u64,
            self.gear_output as u64,
        )
    }

    /// Check every field against its documented range.
    pub fn validate(&self) -> Result<(), ConfigError> {
        fn bad(field: &'static str, value: u32, expected: &'static str) -> ConfigError {
            ConfigError::OutOfRange {
                field,
                value,
                expected,
            }
        }
        if self.steps_per_rev == 0 {
            return Err(bad("steps_per_rev", 0, "1..=65535"));
        }
        if !VALID_MICROSTEPS.contains(&self.microsteps) {
            return Err(bad(
                "microsteps",
                self.microsteps as u32,
                "a power of two 1..=256",
            ));
        }
        if self.gear_motor == 0 {
            return Err(bad("gear_motor", 0, "1..=65535"));
        }
        if self.gear_output == 0 {
            return Err(bad("gear_output", 0, "1..=65535"));
        }
        if self.max_speed_mdeg_s == 0 {
            return Err(bad("max_speed_mdeg_s", 0, "> 0"));
        }
        if self.max_accel_mdeg_s2 == 0 {
            return Err(bad("max_accel_mdeg_s2", 0, "> 0"));
        }
        if self.sample_rate_hz == 0 || self.sample_rate_hz > MAX_SAMPLE_RATE_HZ {
            return Err(bad(
                "sample_rate_hz",
                self.sample_rate_hz as u32,
                "1..=1000",
            ));
        }
        if self.batch_len == 0 || self.batch_len as usize > MAX_BATCH {
            return Err(bad("batch_len", self.batch_len as u32, "1..=32"));
        }
        if self.watchdog_ms < MIN_WATCHDOG_MS {
            return Err(bad("watchdog_ms", self.watchdog_ms as u32, ">= 20"));
        }
        if self.imu_every == 0 {
            return Err(bad("imu_every", 0, "1..=255"));
        }
        Ok(())
    }

    fn encode(&self, w: &mut Writer<'_>) -> Result<(), EncodeError> {
        w.u16(self.steps_per_rev)?;
        w.u16(self.microsteps)?;
        w.u16(self.gear_motor)?;
        w.u16(self.gear_output)?;
        w.u32(self.max_speed_mdeg_s)?;
        w.u32(self.max_accel_mdeg_s2)?;
        w.bool(self.reverse)?;
        w.u16(self.sample_rate_hz)?;
        w.u8(self.sensors.bits())?;
        w.u8(self.batch_len)?;
        w.u16(self.watchdog_ms)?;
        w.u8(self.imu_every)?;
        w.u8(0)
    }

    fn decode(r: &mut Reader<'_>) -> Result<Self, DecodeError> {
        let c = Self {
            steps_per_rev: r.u16("config.steps_per_rev")?,
            microsteps: r.u16("config.microsteps")?,
            gear_motor: r.u16("config.gear_motor")?,
            gear_output: r.u16("config.gear_output")?,
            max_speed_mdeg_s: r.u32("config.max_speed_mdeg_s")?,
            max_accel_mdeg_s2: r.u32("config.max_accel_mdeg_s2")?,
            reverse: r.bool("config.reverse")?,
            sample_rate_hz: r.u16("config.sample_rate_hz")?,
            sensors: decode_sensors(r, "config.sensors")?,
            batch_len: r.u8("config.batch_len")?,
            watchdog_ms: r.u16("config.watchdog_ms")?,
            imu_every: r.u8("config.imu_every")?,
        };
        let reserved = r.u8("config.reserved")?;
        if reserved != 0 {
            return Err(DecodeError::InvalidValue {
                field: "config.reserved",
                value: reserved as u32,
            });
        }
        Ok(c)
    }
}

pub(crate) fn decode_sensors(
    r: &mut Reader<'_>,
    field: &'static str,
) -> Result<SensorSet, DecodeError> {
    let bits = r.u8(field)?;
    SensorSet::from_bits(bits).ok_or(DecodeError::InvalidValue {
        field,
        value: bits as u32,
    })
}

/// A host → device command. Every command is answered by exactly one reply carrying the
/// command frame's sequence number: [`crate::Report::Hello`] for [`Command::Hello`],
/// [`crate::Report::Status`] for [`Command::QueryStatus`], [`crate::Report::Ack`] otherwise.
///
/// A command received again with the sequence number of the previous one is a retry: the
/// device answers it again without executing it twice.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Command {
    /// Start of a session: the host's protocol version. The device stops any motion and
    /// stream left from a previous session and answers with its [`crate::DeviceInfo`].
    Hello {
        /// [`crate::PROTOCOL_VERSION`] of the host.
        protocol_version: u16,
    },
    /// Apply a configuration (only while the motor is not moving).
    Configure(Config),
    /// Assert (true) or release (false) the driver's enable pin. Disabling stops at once.
    SetMotorEnabled(bool),
    /// Ramp to a constant signed speed (millidegrees/s of the driver) and hold it.
    RunSpeed {
        /// Target speed; |speed| ≤ the configured maximum.
        speed_mdeg_s: i32,
    },
    /// Trapezoidal move to an absolute driver angle, millidegrees from zero.
    MoveTo {
        /// Target angle.
        angle_mdeg: i32,
    },
    /// Trapezoidal move by a relative angle, millidegrees.
    MoveBy {
        /// Angle to turn.
        delta_mdeg: i32,
    },
    /// Decelerate to rest at the configured acceleration.
    Stop,
    /// Stop stepping immediately and disable the driver; latched until cleared.
    EmergencyStop,
    /// Clear a latched emergency stop (the motor stays disabled).
    ClearEmergencyStop,
    /// Declare the present position zero (only at rest).
    Zero,
    /// Trapezoidal move back to position zero.
    Home,
    /// Keep the dead-man watchdog fed; does nothing else.
    Heartbeat,
    /// Ask for a [`crate::Status`].
    QueryStatus,
    /// Start streaming sample batches at the configured rate.
    StartStream,
    /// Stop streaming sample batches (a partial batch is sent first).
    StopStream,
}

impl Command {
    /// Short name for logs and errors.
    pub fn name(&self) -> &'static str {
        match self {
            Command::Hello { .. } => "Hello",
            Command::Configure(_) => "Configure",
            Command::SetMotorEnabled(_) => "SetMotorEnabled",
            Command::RunSpeed { .. } => "RunSpeed",
            Command::MoveTo { .. } => "MoveTo",
            Command::MoveBy { .. } => "MoveBy",
            Command::Stop => "Stop",
            Command::EmergencyStop => "EmergencyStop",
            Command::ClearEmergencyStop => "ClearEmergencyStop",
            Command::Zero => "Zero",
            Command::Home => "Home",
            Command::Heartbeat => "Heartbeat",
            Command::QueryStatus => "QueryStatus",
            Command::StartStream => "StartStream",
            Command::StopStream => "StopStream",
        }
    }

    fn tag(&self) -> u8 {
        match self {
            Command::Hello { .. } => 0x01,
            Command::Configure(_) => 0x02,
            Command::SetMotorEnabled(_) => 0x03,
            Command::RunSpeed { .. } => 0x04,
            Command::MoveTo { .. } => 0x05,
            Command::MoveBy { .. } => 0x06,
            Command::Stop => 0x07,
            Command::EmergencyStop => 0x08,
            Command::ClearEmergencyStop => 0x09,
            Command::Zero => 0x0A,
            Command::Home => 0x0B,
            Command::Heartbeat => 0x0C,
            Command::QueryStatus => 0x0D,
            Command::StartStream => 0x0E,
            Command::StopStream => 0x0F,
        }
    }
}

impl Message for Command {
    fn encode(&self, w: &mut Writer<'_>) -> Result<(), EncodeError> {
        w.u8(self.tag())?;
        match *self {
            Command::Hello { protocol_version } => w.u16(protocol_version),
            Command::Configure(ref c) => c.encode(w),
            Command::SetMotorEnabled(on) => w.bool(on),
            Command::RunSpeed { speed_mdeg_s } => w.i32(speed_mdeg_s),
            Command::MoveTo { angle_mdeg } => w.i32(angle_mdeg),
            Command::MoveBy { delta_mdeg } => w.i32(delta_mdeg),
            Command::Stop
            | Command::EmergencyStop
            | Command::ClearEmergencyStop
            | Command::Zero
            | Command::Home
            | Command::Heartbeat
            | Command::QueryStatus
            | Command::StartStream
            | Command::StopStream => Ok(()),
        }
    }

    fn decode(r: &mut Reader<'_>) -> Result<Self, DecodeError> {
        let tag = r.u8("command.tag")?;
        let cmd = match tag {
            0x01 => Command::Hello {
                protocol_version: r.u16("hello.protocol_version")?,
            },
            0x02 => Command::Configure(Config::decode(r)?),
            0x03 => Command::SetMotorEnabled(r.bool("set_motor_enabled.on")?),
            0x04 => Command::RunSpeed {
                speed_mdeg_s: r.i32("run_speed.speed_mdeg_s")?,
            },
            0x05 => Command::MoveTo {
                angle_mdeg: r.i32("move_to.angle_mdeg")?,
            },
            0x06 => Command::MoveBy {
                delta_mdeg: r.i32("move_by.delta_mdeg")?,
            },
            0x07 => Command::Stop,
            0x08 => Command::EmergencyStop,
            0x09 => Command::ClearEmergencyStop,
            0x0A => Command::Zero,
            0x0B => Command::Home,
            0x0C => Command::Heartbeat,
            0x0D => Command::QueryStatus,
            0x0E => Command::StartStream,
            0x0F => Command::StopStream,
            tag => {
                return Err(DecodeError::UnknownTag {
                    what: "command",
                    tag,
                })
            }
        };
        r.finish(cmd.name())?;
        Ok(cmd)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Guards that the default configuration is itself valid.
    #[test]
    fn default_config_is_valid() {
        assert_eq!(Config::default().validate(), Ok(()));
        assert_eq!(Config::default().microsteps_per_output_rev(), (3200, 1));
    }

    /// Guards each range check with the field it names.
    #[test]
    fn invalid_configs_name_the_field() {
        type Breaker = fn(&mut Config);
        let cases: [(Breaker, &str); 7] = [
            (|c| c.microsteps = 3, "microsteps"),
            (|c| c.steps_per_rev = 0, "steps_per_rev"),
            (|c| c.gear_output = 0, "gear_output"),
            (|c| c.sample_rate_hz = 1001, "sample_rate_hz"),
            (|c| c.batch_len = 33, "batch_len"),
            (|c| c.watchdog_ms = 5, "watchdog_ms"),
            (|c| c.imu_every = 0, "imu_every"),
        ];
        for (break_it, name) in cases {
            let mut c = Config::default();
            break_it(&mut c);
            match c.validate() {
                Err(ConfigError::OutOfRange { field, .. }) => assert_eq!(field, name),
                Ok(()) => panic!("{name} accepted"),
            }
        }
    }

    /// Guards that a configuration's body has the documented 25-byte layout.
    #[test]
    fn configure_body_has_documented_length() {
        let mut buf = [0u8; 64];
        let mut w = Writer::new(&mut buf);
        Command::Configure(Config::default())
            .encode(&mut w)
            .unwrap();
        assert_eq!(w.position(), 1 + 25);
    }
}
