//! The golden frames kept in `data/wire/`: one file per case, `<name>.bin`, holding the
//! exact bytes of the frame on the wire (0x00 delimiter included).
//!
//! Owns the list of cases so that the firmware's tests and the host's tests decode the same
//! files against the same expected messages. Changing a message layout changes these bytes:
//! that needs a new [`crate::PROTOCOL_VERSION`].

use crate::{
    AckCode, BoardName, Capabilities, Command, Config, DeviceInfo, Event, EventKind, MotionMode,
    Report, Sample, SampleBatch, SampleFlags, SensorSet, Status, StatusFlags, PROTOCOL_VERSION,
};

/// A golden message of either direction.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[allow(clippy::large_enum_variant)] // see `Report`
pub enum GoldenMessage {
    /// Host → device.
    Command(Command),
    /// Device → host.
    Report(Report),
}

/// One golden frame: file stem, sequence number and message.
#[derive(Debug, Clone, Copy)]
pub struct GoldenCase {
    /// File name without `.bin` in `data/wire/`.
    pub name: &'static str,
    /// Sequence number of the frame.
    pub seq: u16,
    /// The message.
    pub msg: GoldenMessage,
}

fn batch() -> SampleBatch {
    let mut b = SampleBatch::new(SensorSet::ENCODER_A | SensorSet::IMU);
    for i in 0..3u16 {
        let s = Sample {
            timestamp_us: 4_294_966_000u32.wrapping_add(i as u32 * 1000),
            position: -2 + i as i32 * 7,
            flags: if i == 0 {
                SampleFlags::MOVING | SampleFlags::ENABLED | SampleFlags::IMU_FRESH
            } else {
                SampleFlags::MOVING | SampleFlags::ENABLED
            },
            encoder_a: 4095 - i,
            encoder_b: 0,
            quadrature: 0,
            quaternion: [16384, 0, -11585, 11585],
        };
        let _ = b.push(s);
    }
    b
}

/// Every golden case, in a fixed order.
pub fn cases() -> [GoldenCase; 12] {
    use GoldenMessage::{Command as C, Report as R};
    [
        GoldenCase {
            name: "cmd_hello",
            seq: 0,
            msg: C(Command::Hello {
                protocol_version: PROTOCOL_VERSION,
            }),
        },
        GoldenCase {
            name: "cmd_configure_default",
            seq: 1,
            msg: C(Command::Configure(Config::default())),
        },
        GoldenCase {
            name: "cmd_set_motor_enabled",
            seq: 2,
            msg: C(Command::SetMotorEnabled(true)),
        },
        GoldenCase {
            name: "cmd_run_speed_negative",
            seq: 3,
            msg: C(Command::RunSpeed {
                speed_mdeg_s: -180_000,
            }),
        },
        GoldenCase {
            name: "cmd_move_to",
            seq: 4,
            msg: C(Command::MoveTo { angle_mdeg: 90_000 }),
        },
        GoldenCase {
            name: "cmd_emergency_stop",
            seq: 0xFFFF,
            msg: C(Command::EmergencyStop),
        },
        GoldenCase {
            name: "rep_hello",
            seq: 0,
            msg: R(Report::Hello(DeviceInfo {
                ack: 0,
                protocol_version: PROTOCOL_VERSION,
                firmware_version: [0, 1, 0],
                board: match BoardName::new("rp2040-pico") {
                    Some(b) => b,
                    None => unreachable!(),
                },
                capabilities: Capabilities {
                    sensors: SensorSet::ENCODER_A | SensorSet::ENCODER_B | SensorSet::IMU,
                    max_step_rate_hz: 20_000,
                    max_sample_rate_hz: 1000,
                    imu_rate_hz: 100,
                    max_batch: 32,
                },
                clock_hz: 1_000_000,
            })),
        },
        GoldenCase {
            name: "rep_ack_ok",
            seq: 1,
            msg: R(Report::Ack {
                ack: 1,
                code: AckCode::Ok,
            }),
        },
        GoldenCase {
            name: "rep_ack_estop_latched",
            seq: 2,
            msg: R(Report::Ack {
                ack: 7,
                code: AckCode::EStopLatched,
            }),
        },
        GoldenCase {
            name: "rep_status",
            seq: 3,
            msg: R(Report::Status(Status {
                ack: 9,
                timestamp_us: 123_456_789,
                position: -3200,
                speed: 1600,
                target: 0,
                mode: MotionMode::Move,
                flags: StatusFlags::CONFIGURED
                    .union(StatusFlags::ENABLED)
                    .union(StatusFlags::MOVING)
                    .union(StatusFlags::ENCODER_A_OK),
                rx_errors: 2,
                samples_dropped: 0,
            })),
        },
        GoldenCase {
            name: "rep_samples_wraparound",
            seq: 0x0100,
            msg: R(Report::Samples(batch())),
        },
        GoldenCase {
            name: "rep_event_watchdog",
            seq: 5,
            msg: R(Report::Event(Event {
                kind: EventKind::WatchdogExpired,
                detail: 0,
                timestamp_us: 250_000,
                position: 12_345,
            })),
        },
    ]
}

impl GoldenCase {
    /// The frame's bytes as this crate encodes them.
    pub fn encode(&self) -> std::vec::Vec<u8> {
        let r = match &self.msg {
            GoldenMessage::Command(c) => crate::encode_frame_vec(self.seq, c),
            GoldenMessage::Report(r) => crate::encode_frame_vec(self.seq, r),
        };
        r.expect("golden messages are valid")
    }

    /// Decode `bytes` (one whole frame) with the decoder of this case's direction and say
    /// whether it yields exactly this case's sequence number and message.
    pub fn matches(&self, bytes: &[u8]) -> Result<(), std::string::String> {
        use std::format;
        let mut frames = 0;
        let mut outcome = Err(std::string::String::from("no frame decoded"));
        match &self.msg {
            GoldenMessage::Command(want) => crate::Decoder::<Command>::new().feed(bytes, |r| {
                frames += 1;
                outcome = match r {
                    Ok(f) if f.seq == self.seq && f.msg == *want => Ok(()),
                    other => Err(format!("{}: decoded {other:?}", self.name)),
                };
            }),
            GoldenMessage::Report(want) => crate::Decoder::<Report>::new().feed(bytes, |r| {
                frames += 1;
                outcome = match r {
                    Ok(f) if f.seq == self.seq && f.msg == *want => Ok(()),
                    other => Err(format!("{}: decoded {other:?}", self.name)),
                };
            }),
        }
        if frames > 1 {
            return Err(format!("{}: {frames} frames in one file", self.name));
        }
        outcome
    }
}
