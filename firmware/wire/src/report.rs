//! Device → host messages: the handshake answer, acknowledgements, status, events and
//! sample batches.
//!
//! Owns their fields, tags and layout. Sample batches are sequence-numbered by the frame
//! layer and never retried: a lost batch shows as a gap in the device's sequence numbers
//! ([`crate::host::GapCounter`]).

use crate::codec::{DecodeError, EncodeError, Message, Reader, Writer};
use crate::command::decode_sensors;
use crate::flags::{SampleFlags, SensorSet, StatusFlags};
use crate::MAX_BATCH;

/// Longest board name, bytes of UTF-8.
pub const BOARD_NAME_MAX: usize = 16;

/// A short board name (≤ [`BOARD_NAME_MAX`] bytes of UTF-8), without allocation.
#[derive(Clone, Copy, PartialEq, Eq)]
pub struct BoardName {
    len: u8,
    bytes: [u8; BOARD_NAME_MAX],
}

impl BoardName {
    /// The name, or `None` if it is longer than [`BOARD_NAME_MAX`] bytes.
    pub fn new(name: &str) -> Option<Self> {
        if name.len() > BOARD_NAME_MAX {
            return None;
        }
        let mut bytes = [0u8; BOARD_NAME_MAX];
        bytes[..name.len()].copy_from_slice(name.as_bytes());
        Some(Self {
            len: name.len() as u8,
            bytes,
        })
    }

    /// The name cut to at most [`BOARD_NAME_MAX`] bytes (at a character boundary).
    pub fn truncated(name: &str) -> Self {
        let mut end = name.len().min(BOARD_NAME_MAX);
        while !name.is_char_boundary(end) {
            end -= 1;
        }
        let mut bytes = [0u8; BOARD_NAME_MAX];
        bytes[..end].copy_from_slice(&name.as_bytes()[..end]);
        Self {
            len: end as u8,
            bytes,
        }
    }

    /// The name as text.
    pub fn as_str(&self) -> &str {
        // Constructed from &str or checked UTF-8 only.
        core::str::from_utf8(&self.bytes[..self.len as usize]).unwrap_or("")
    }
}

impl core::fmt::Debug for BoardName {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        core::fmt::Debug::fmt(self.as_str(), f)
    }
}

/// What a device can do, announced in the handshake.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Capabilities {
    /// Sensors fitted and answering at boot.
    pub sensors: SensorSet,
    /// Highest step rate the step generator guarantees, steps/s.
    pub max_step_rate_hz: u32,
    /// Highest sample rate, Hz.
    pub max_sample_rate_hz: u16,
    /// Native output rate of the IMU, Hz (0 without IMU).
    pub imu_rate_hz: u16,
    /// Largest batch the device sends.
    pub max_batch: u8,
}

/// The device's answer to [`crate::Command::Hello`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct DeviceInfo {
    /// Sequence number of the `Hello` command answered.
    pub ack: u16,
    /// The device's [`crate::PROTOCOL_VERSION`].
    pub protocol_version: u16,
    /// Firmware version, (major, minor, patch).
    pub firmware_version: [u8; 3],
    /// Board name, e.g. `"rp2040-pico"` or `"sim-stepper"`.
    pub board: BoardName,
    /// What the device can do.
    pub capabilities: Capabilities,
    /// Ticks per second of the device clock that stamps samples (timestamps are in µs
    /// derived from it; this tells the host the clock's resolution).
    pub clock_hz: u32,
}

/// Outcome of a command.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u8)]
pub enum AckCode {
    /// Executed.
    Ok = 0,
    /// The host speaks another protocol version.
    VersionMismatch = 1,
    /// The configuration failed its range checks or exceeds a capability.
    InvalidConfig = 2,
    /// Motion or streaming asked before any configuration.
    NotConfigured = 3,
    /// Motion asked with the driver disabled.
    MotorDisabled = 4,
    /// Refused while the emergency stop is latched.
    EStopLatched = 5,
    /// A speed or angle beyond the configured limits or the position range.
    OutOfRange = 6,
    /// Not possible while moving (configure, zero).
    Busy = 7,
    /// A sensor was enabled that the device does not have.
    Unsupported = 8,
}

impl AckCode {
    fn from_u8(v: u8) -> Option<Self> {
        Some(match v {
            0 => Self::Ok,
            1 => Self::VersionMismatch,
            2 => Self::InvalidConfig,
            3 => Self::NotConfigured,
            4 => Self::MotorDisabled,
            5 => Self::EStopLatched,
            6 => Self::OutOfRange,
            7 => Self::Busy,
            8 => Self::Unsupported,
            _ => return None,
        })
    }
}

/// What the step generator is doing.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u8)]
pub enum MotionMode {
    /// At rest.
    Idle = 0,
    /// Ramping to or holding a constant speed.
    Run = 1,
    /// Following a trapezoidal move to a target position.
    Move = 2,
    /// Decelerating to rest.
    Stopping = 3,
}

/// Device state, the answer to [`crate::Command::QueryStatus`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Status {
    /// Sequence number of the query answered.
    pub ack: u16,
    /// Device time, µs (wraps every 2³² µs ≈ 71.6 min).
    pub timestamp_us: u32,
    /// Driver position, microsteps from zero.
    pub position: i32,
    /// Present speed, microsteps/s (signed).
    pub speed: i32,
    /// Target position of a move (equals `position` otherwise).
    pub target: i32,
    /// What the step generator does.
    pub mode: MotionMode,
    /// State flags.
    pub flags: StatusFlags,
    /// Frames received with a framing, checksum or body error since boot.
    pub rx_errors: u32,
    /// Samples dropped since boot because the output link was full.
    pub samples_dropped: u32,
}

/// One sample of the device's sampler. Fields of sensors absent from the batch's
/// [`SampleBatch::fields`] are not sent and read back as zero.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Sample {
    /// Device time at the sample, µs (wrapping; see [`crate::host::TimestampUnwrapper`]).
    pub timestamp_us: u32,
    /// Driver position, microsteps from zero.
    pub position: i32,
    /// Flags of this sample.
    pub flags: SampleFlags,
    /// AS5600 raw angle of encoder A (0..=4095).
    pub encoder_a: u16,
    /// AS5600 raw angle of encoder B (0..=4095).
    pub encoder_b: u16,
    /// Quadrature counter (edges, signed).
    pub quadrature: i32,
    /// Orientation, unit quaternion scalar first, Q14 fixed point (1.0 = 16384) as the
    /// BNO055 reports it.
    pub quaternion: [i16; 4],
}

impl Sample {
    /// Encoded size of one sample carrying `fields`.
    pub const fn encoded_len(fields: SensorSet) -> usize {
        let mut n = 4 + 4 + 1;
        if fields.contains(SensorSet::ENCODER_A) {
            n += 2;
        }
        if fields.contains(SensorSet::ENCODER_B) {
            n += 2;
        }
        if fields.contains(SensorSet::QUADRATURE) {
            n += 4;
        }
        if fields.contains(SensorSet::IMU) {
            n += 8;
        }
        n
    }

    /// The quaternion as floats `[w, x, y, z]`.
    pub fn quaternion_f32(&self) -> [f32; 4] {
        self.quaternion.map(|q| q as f32 / 16384.0)
    }

    /// This sample with the fields outside `fields` zeroed (what the receiver sees).
    pub fn masked(mut self, fields: SensorSet) -> Self {
        if !fields.contains(SensorSet::ENCODER_A) {
            self.encoder_a = 0;
        }
        if !fields.contains(SensorSet::ENCODER_B) {
            self.encoder_b = 0;
        }
        if !fields.contains(SensorSet::QUADRATURE) {
            self.quadrature = 0;
        }
        if !fields.contains(SensorSet::IMU) {
            self.quaternion = [0; 4];
        }
        self
    }

    fn encode(&self, fields: SensorSet, w: &mut Writer<'_>) -> Result<(), EncodeError> {
        w.u32(self.timestamp_us)?;
        w.i32(self.position)?;
        w.u8(self.flags.bits())?;
        if fields.contains(SensorSet::ENCODER_A) {
            w.u16(self.encoder_a)?;
        }
        if fields.contains(SensorSet::ENCODER_B) {
            w.u16(self.encoder_b)?;
        }
        if fields.contains(SensorSet::QUADRATURE) {
            w.i32(self.quadrature)?;
        }
        if fields.contains(SensorSet::IMU) {
            for q in self.quaternion {
                w.i16(q)?;
            }
        }
        Ok(())
    }

    fn decode(fields: SensorSet, r: &mut Reader<'_>) -> Result<Self, DecodeError> {
        let mut s = Sample {
            timestamp_us: r.u32("sample.timestamp_us")?,
            position: r.i32("sample.position")?,
            ..Sample::default()
        };
        let flags = r.u8("sample.flags")?;
        s.flags = SampleFlags(flags);
        if fields.contains(SensorSet::ENCODER_A) {
            s.encoder_a = r.u16("sample.encoder_a")?;
        }
        if fields.contains(SensorSet::ENCODER_B) {
            s.encoder_b = r.u16("sample.encoder_b")?;
        }
        if fields.contains(SensorSet::QUADRATURE) {
            s.quadrature = r.i32("sample.quadrature")?;
        }
        if fields.contains(SensorSet::IMU) {
            for q in s.quaternion.iter_mut() {
                *q = r.i16("sample.quaternion")?;
            }
        }
        Ok(s)
    }
}

/// Up to [`MAX_BATCH`] consecutive samples sent in one frame, with the set of sensor fields
/// every one of them carries.
#[derive(Debug, Clone, Copy)]
pub struct SampleBatch {
    /// Sensor fields present in each sample.
    pub fields: SensorSet,
    len: u8,
    samples: [Sample; MAX_BATCH],
}

impl PartialEq for SampleBatch {
    fn eq(&self, other: &Self) -> bool {
        self.fields == other.fields && self.samples() == other.samples()
    }
}
impl Eq for SampleBatch {}

impl SampleBatch {
    /// An empty batch whose samples will carry `fields`.
    pub const fn new(fields: SensorSet) -> Self {
        Self {
            fields,
            len: 0,
            samples: [Sample {
                timestamp_us: 0,
                position: 0,
                flags: SampleFlags::EMPTY,
                encoder_a: 0,
                encoder_b: 0,
                quadrature: 0,
                quaternion: [0; 4],
            }; MAX_BATCH],
        }
    }

    /// Append a sample (fields outside [`Self::fields`] are zeroed); gives it back when the
    /// batch is full.
    pub fn push(&mut self, sample: Sample) -> Result<(), Sample> {
        if self.len as usize >= MAX_BATCH {
            return Err(sample);
        }
        self.samples[self.len as usize] = sample.masked(self.fields);
        self.len += 1;
        Ok(())
    }

    /// The samples, oldest first.
    pub fn samples(&self) -> &[Sample] {
        &self.samples[..self.len as usize]
    }

    /// Number of samples.
    pub fn len(&self) -> usize {
        self.len as usize
    }

    /// Whether there is no sample.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Whether the batch holds [`MAX_BATCH`] samples.
    pub fn is_full(&self) -> bool {
        self.len as usize == MAX_BATCH
    }

    /// Remove every sample, keeping the field set.
    pub fn clear(&mut self) {
        self.len = 0;
    }
}

/// Something that happened on the device without being asked.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u8)]
pub enum EventKind {
    /// The device (re)started; the motor is disabled.
    Boot = 1,
    /// A move reached its target exactly.
    MoveDone = 2,
    /// A `Stop` finished decelerating.
    Stopped = 3,
    /// The emergency stop latched; `detail` says why: 0 for the `EmergencyStop` command (or
    /// a driver pin that cannot be set), [`ESTOP_BY_INPUT`] for the board's e-stop input.
    EmergencyStop = 4,
    /// The dead-man watchdog stopped the motor and the stream.
    WatchdogExpired = 5,
    /// A sensor stopped answering; `detail` holds its [`SensorSet`] bits.
    SensorFault = 6,
}

impl EventKind {
    fn from_u8(v: u8) -> Option<Self> {
        Some(match v {
            1 => Self::Boot,
            2 => Self::MoveDone,
            3 => Self::Stopped,
            4 => Self::EmergencyStop,
            5 => Self::WatchdogExpired,
            6 => Self::SensorFault,
            _ => return None,
        })
    }
}

/// [`Event::detail`] of an [`EventKind::EmergencyStop`] latched by the board's e-stop input.
pub const ESTOP_BY_INPUT: u8 = 1;

/// An unsolicited device event.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Event {
    /// What happened.
    pub kind: EventKind,
    /// Kind-specific detail: sensor bits for [`EventKind::SensorFault`], the cause for
    /// [`EventKind::EmergencyStop`], else 0.
    pub detail: u8,
    /// Device time, µs.
    pub timestamp_us: u32,
    /// Driver position at that time, microsteps.
    pub position: i32,
}

/// A device → host message.
///
/// `Samples` is much larger than the other variants (a fixed-capacity batch); boxing is not
/// available without an allocator, and one report of ~0.9 KiB is cheap even on the device.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[allow(clippy::large_enum_variant)]
pub enum Report {
    /// Answer to `Hello`.
    Hello(DeviceInfo),
    /// Answer to every command but `Hello` and `QueryStatus`.
    Ack {
        /// Sequence number of the command answered.
        ack: u16,
        /// Outcome.
        code: AckCode,
    },
    /// Answer to `QueryStatus`.
    Status(Status),
    /// Streamed samples (not acknowledged, not retried).
    Samples(SampleBatch),
    /// Unsolicited event.
    Event(Event),
}

impl Report {
    /// Short name for logs and errors.
    pub fn name(&self) -> &'static str {
        match self {
            Report::Hello(_) => "Hello",
            Report::Ack { .. } => "Ack",
            Report::Status(_) => "Status",
            Report::Samples(_) => "Samples",
            Report::Event(_) => "Event",
        }
    }

    /// The command sequence number this report answers, if it is an answer.
    pub fn ack(&self) -> Option<u16> {
        match self {
            Report::Hello(i) => Some(i.ack),
            Report::Ack { ack, .. } => Some(*ack),
            Report::Status(s) => Some(s.ack),
            Report::Samples(_) | Report::Event(_) => None,
        }
    }
}

impl Message for Report {
    fn encode(&self, w: &mut Writer<'_>) -> Result<(), EncodeError> {
        match self {
            Report::Hello(i) => {
                w.u8(0x81)?;
                w.u16(i.ack)?;
                w.u16(i.protocol_version)?;
                w.bytes(&i.firmware_version)?;
                w.u8(i.board.len)?;
                w.bytes(i.board.as_str().as_bytes())?;
                let c = &i.capabilities;
                w.u8(c.sensors.bits())?;
                w.u32(c.max_step_rate_hz)?;
                w.u16(c.max_sample_rate_hz)?;
                w.u16(c.imu_rate_hz)?;
                w.u8(c.max_batch)?;
                w.u32(i.clock_hz)
            }
            Report::Ack { ack, code } => {
                w.u8(0x82)?;
                w.u16(*ack)?;
                w.u8(*code as u8)
            }
            Report::Status(s) => {
                w.u8(0x83)?;
                w.u16(s.ack)?;
                w.u32(s.timestamp_us)?;
                w.i32(s.position)?;
                w.i32(s.speed)?;
                w.i32(s.target)?;
                w.u8(s.mode as u8)?;
                w.u16(s.flags.bits())?;
                w.u32(s.rx_errors)?;
                w.u32(s.samples_dropped)
            }
            Report::Samples(b) => {
                w.u8(0x84)?;
                w.u8(b.fields.bits())?;
                w.u8(b.len)?;
                for s in b.samples() {
                    s.encode(b.fields, w)?;
                }
                Ok(())
            }
            Report::Event(e) => {
                w.u8(0x85)?;
                w.u8(e.kind as u8)?;
                w.u8(e.detail)?;
                w.u32(e.timestamp_us)?;
                w.i32(e.position)
            }
        }
    }

    fn decode(r: &mut Reader<'_>) -> Result<Self, DecodeError> {
        let tag = r.u8("report.tag")?;
        let report = match tag {
            0x81 => {
                let ack = r.u16("hello.ack")?;
                let protocol_version = r.u16("hello.protocol_version")?;
                let firmware_version = r.array::<3>("hello.firmware_version")?;
                let len = r.u8("hello.board_len")?;
                if len as usize > BOARD_NAME_MAX {
                    return Err(DecodeError::InvalidValue {
                        field: "hello.board_len",
                        value: len as u32,
                    });
                }
                let raw = r.slice(len as usize, "hello.board")?;
                let name = core::str::from_utf8(raw).map_err(|_| DecodeError::InvalidValue {
                    field: "hello.board",
                    value: len as u32,
                })?;
                let board = BoardName::new(name).ok_or(DecodeError::InvalidValue {
                    field: "hello.board_len",
                    value: len as u32,
                })?;
                let capabilities = Capabilities {
                    sensors: decode_sensors(r, "hello.sensors")?,
                    max_step_rate_hz: r.u32("hello.max_step_rate_hz")?,
                    max_sample_rate_hz: r.u16("hello.max_sample_rate_hz")?,
                    imu_rate_hz: r.u16("hello.imu_rate_hz")?,
                    max_batch: r.u8("hello.max_batch")?,
                };
                Report::Hello(DeviceInfo {
                    ack,
                    protocol_version,
                    firmware_version,
                    board,
                    capabilities,
                    clock_hz: r.u32("hello.clock_hz")?,
                })
            }
            0x82 => {
                let ack = r.u16("ack.seq")?;
                let c = r.u8("ack.code")?;
                let code = AckCode::from_u8(c).ok_or(DecodeError::InvalidValue {
                    field: "ack.code",
                    value: c as u32,
                })?;
                Report::Ack { ack, code }
            }
            0x83 => {
                let ack = r.u16("status.ack")?;
                let timestamp_us = r.u32("status.timestamp_us")?;
                let position = r.i32("status.position")?;
                let speed = r.i32("status.speed")?;
                let target = r.i32("status.target")?;
                let m = r.u8("status.mode")?;
                let mode = match m {
                    0 => MotionMode::Idle,
                    1 => MotionMode::Run,
                    2 => MotionMode::Move,
                    3 => MotionMode::Stopping,
                    _ => {
                        return Err(DecodeError::InvalidValue {
                            field: "status.mode",
                            value: m as u32,
                        })
                    }
                };
                let f = r.u16("status.flags")?;
                let flags = StatusFlags::from_bits(f).ok_or(DecodeError::InvalidValue {
                    field: "status.flags",
                    value: f as u32,
                })?;
                Report::Status(Status {
                    ack,
                    timestamp_us,
                    position,
                    speed,
                    target,
                    mode,
                    flags,
                    rx_errors: r.u32("status.rx_errors")?,
                    samples_dropped: r.u32("status.samples_dropped")?,
                })
            }
            0x84 => {
                let fields = decode_sensors(r, "samples.fields")?;
                let len = r.u8("samples.len")?;
                if len as usize > MAX_BATCH {
                    return Err(DecodeError::InvalidValue {
                        field: "samples.len",
                        value: len as u32,
                    });
                }
                let mut b = SampleBatch::new(fields);
                for _ in 0..len {
                    let s = Sample::decode(fields, r)?;
                    // Cannot overflow: len ≤ MAX_BATCH was checked.
                    let _ = b.push(s);
                }
                Report::Samples(b)
            }
            0x85 => {
                let k = r.u8("event.kind")?;
                let kind = EventKind::from_u8(k).ok_or(DecodeError::InvalidValue {
                    field: "event.kind",
                    value: k as u32,
                })?;
                Report::Event(Event {
                    kind,
                    detail: r.u8("event.detail")?,
                    timestamp_us: r.u32("event.timestamp_us")?,
                    position: r.i32("event.position")?,
                })
            }
            tag => {
                return Err(DecodeError::UnknownTag {
                    what: "report",
                    tag,
                })
            }
        };
        r.finish(report.name())?;
        Ok(report)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Guards the per-sample sizes that make a 1 kHz stream fit the link.
    #[test]
    fn sample_sizes_follow_fields() {
        assert_eq!(Sample::encoded_len(SensorSet::EMPTY), 9);
        assert_eq!(Sample::encoded_len(SensorSet::ENCODER_A), 11);
        assert_eq!(Sample::encoded_len(SensorSet::ALL), 25);
    }

    /// Guards that a batch refuses its 33rd sample and masks absent fields.
    #[test]
    fn batch_capacity_and_masking() {
        let mut b = SampleBatch::new(SensorSet::ENCODER_A);
        for i in 0..MAX_BATCH {
            let s = Sample {
                timestamp_us: i as u32,
                encoder_b: 7,
                encoder_a: 5,
                ..Sample::default()
            };
            assert!(b.push(s).is_ok());
        }
        assert!(b.is_full());
        assert!(b.push(Sample::default()).is_err());
        assert_eq!(b.samples()[3].encoder_b, 0);
        assert_eq!(b.samples()[3].encoder_a, 5);
    }

    /// Guards the board-name length limit.
    #[test]
    fn board_name_length_is_limited() {
        assert_eq!(
            BoardName::new("rp2040-pico").unwrap().as_str(),
            "rp2040-pico"
        );
        assert!(BoardName::new("a-board-name-that-is-too-long").is_none());
        assert_eq!(
            BoardName::truncated("a-board-name-that-is-too-long").as_str(),
            "a-board-name-tha"
        );
        assert_eq!(BoardName::truncated("ääääääääé").as_str(), "ääääääää");
    }
}
