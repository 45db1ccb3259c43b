//! Wire protocol between the `mpc-rig` host and the bench firmware.
//!
//! Owns the message types of both directions ([`Command`] host → device, [`Report`]
//! device → host), their byte layout ([`codec`]), the framing ([`frame`]: sequence number,
//! CRC-32, COBS, 0x00 delimiter), the protocol version, and I/O-free host bookkeeping
//! ([`host`]: retries, gap counting, timestamp unwrapping). It does not own any I/O: callers
//! hand it bytes and take bytes from it. `#![no_std]` without allocation; the `std` feature
//! adds `Vec` conveniences for the host.
//!
//! # The protocol in one page
//! - Every frame is `COBS(seq:u16 | tag:u8 | fields… | crc32:u32) 0x00`, little-endian.
//!   Each side numbers its own frames; a receiver that sees garbage drops it and decodes the
//!   next frame after the next 0x00.
//! - Host → device commands are answered by exactly one reply carrying the command's
//!   sequence number ([`Report::ack`]). The host resends a command with the *same* sequence
//!   number when no reply comes in time ([`host::CommandChannel`]); the device recognizes a
//!   repeat of its last command and only re-sends the reply.
//! - Device → host sample batches are never acknowledged or retried; lost ones show as gaps
//!   in the device's sequence numbers ([`host::GapCounter`]).
//! - Session start: the host writes a 0x00 (flushing any half frame on the device side) and
//!   sends [`Command::Hello`] with [`PROTOCOL_VERSION`]; the device stops any motion and
//!   stream left from a previous session and answers [`Report::Hello`] with its
//!   [`DeviceInfo`] (versions, board, [`Capabilities`], clock rate). Then `Configure`,
//!   `SetMotorEnabled(true)`, `StartStream`, motion commands, and `Heartbeat`s often enough
//!   to keep the device's dead-man watchdog ([`Config::watchdog_ms`]) fed.
//!
//! # Host usage
//! ```
//! use mpc_wire::{encode_frame, Command, Decoder, Report, PROTOCOL_VERSION, MAX_FRAME_LEN};
//! use mpc_wire::host::{CommandChannel, GapCounter, PollAction, RetryPolicy};
//!
//! let mut commands = CommandChannel::new(RetryPolicy::default(), 0);
//! let mut out = [0u8; MAX_FRAME_LEN];
//! // Send the handshake at t = 0 ms; write `out[..n]` to the serial port.
//! let n = commands.send(Command::Hello { protocol_version: PROTOCOL_VERSION }, 0, &mut out)?;
//! # let to_device = out[..n].to_vec();
//!
//! // Bytes read from the port go into one decoder, in whatever chunks they arrive.
//! # let mut from_device = [0u8; MAX_FRAME_LEN];
//! # let m = encode_frame(0, &Report::Ack { ack: 0, code: mpc_wire::AckCode::Ok }, &mut from_device)?;
//! let mut decoder = Decoder::<Report>::new();
//! let mut gaps = GapCounter::new();
//! decoder.feed(&from_device[..m], |result| match result {
//!     Ok(frame) => {
//!         gaps.observe(frame.seq);
//!         if let Some(done) = commands.on_report(&frame.msg) {
//!             println!("{} answered: {:?}", done.command.name(), frame.msg);
//!         }
//!     }
//!     Err(e) => eprintln!("dropped a frame: {e}"),
//! });
//! assert!(commands.pending().is_none());
//!
//! // Call periodically: resend on timeout, give up after the last attempt.
//! match commands.poll(150, &mut out)? {
//!     PollAction::Resend { len } => { /* write out[..len] again */ let _ = len; }
//!     PollAction::GaveUp(cmd) => eprintln!("no reply to {}", cmd.command.name()),
//!     PollAction::Idle | PollAction::Waiting => {}
//! }
//! # let _ = to_device;
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
//!
//! Sizes: a 1 kHz stream of one AS5600 in batches of 10 is 100 frames/s of 120 bytes
//! (12 kB/s); with every sensor, 262 bytes per frame (26 kB/s) — far below USB full speed.
#![no_std]
#![warn(missing_docs)]

#[cfg(feature = "std")]
extern crate std;

pub mod cobs;
pub mod codec;
pub mod command;
pub mod crc;
#[cfg(feature = "std")]
pub mod dump;
pub mod flags;
pub mod frame;
#[cfg(feature = "std")]
pub mod golden;
pub mod host;
pub mod report;

pub use codec::{DecodeError, EncodeError, Message};
pub use command::{Command, Config, ConfigError};
pub use flags::{SampleFlags, SensorSet, StatusFlags};
#[cfg(feature = "std")]
pub use frame::encode_frame_vec;
pub use frame::{decode_payload, encode_frame, Decoder, Frame, FrameError, FRAME_OVERHEAD};
pub use report::{
    AckCode, BoardName, Capabilities, DeviceInfo, Event, EventKind, MotionMode, Report, Sample,
    SampleBatch, Status, ESTOP_BY_INPUT,
};

/// Version of this protocol; both ends must agree exactly (checked in the handshake).
pub const PROTOCOL_VERSION: u16 = 1;

/// Most samples in one batch frame. Default 32: 32 full samples make an 800-byte body,
/// which keeps frames well inside a 1 KiB buffer on the device.
pub const MAX_BATCH: usize = 32;

/// Longest message body (the full sample batch): tag, fields, count and samples.
pub const MAX_BODY_LEN: usize = 3 + MAX_BATCH * Sample::encoded_len(SensorSet::ALL);

/// Longest unstuffed payload: sequence number, body and CRC.
pub const MAX_PAYLOAD_LEN: usize = MAX_BODY_LEN + FRAME_OVERHEAD;

/// Longest frame on the wire, delimiter included: a buffer this long holds any frame.
pub const MAX_FRAME_LEN: usize = cobs::max_encoded_len(MAX_PAYLOAD_LEN) + 1;
