//! The pipe between the bench (this process) and the emulated board (`firmware/emu/harness.mjs`,
//! whose `lib/link.mjs` is the other half).
//!
//! Every message is `tag: u8 · length: u32 LE · payload`. The board writes on its standard
//! output and blocks on its standard input for the answers: while the bench computes an
//! answer the emulated CPU stands still, so both sides share one simulated time.
//!
//! Board → bench (`f64` simulated µs since reset, little-endian, first where timed):
//! | tag | message | payload | answer |
//! |---|---|---|---|
//! | 0x01 | [`BoardMessage::Sync`] | µs, bytes the board sent on USB since the last one | [`SyncReply`] |
//! | 0x02 | [`BoardMessage::Pin`] | µs, gpio u8, level u8 (0 low, 1 high, 2 not driven) | — |
//! | 0x03 | [`BoardMessage::I2c`] | µs, controller u8, SDA gpio u8, SCL gpio u8 (0xFF: none), kind u8, arg u8 | CONNECT, READ: [`encode_i2c_reply`] |
//! | 0x04 | [`BoardMessage::Usb`] | UTF-8 JSON `{vid, pid, manufacturer, product, serial}` | — |
//! | 0x05 | [`BoardMessage::Log`] | level u8 (0 debug, 1 warning), UTF-8 text | — |
//! | 0x06 | [`BoardMessage::Halt`] | UTF-8 reason; the board exits after it | — |
//! | 0x07 | [`BoardMessage::Rtt`] | bytes of the firmware's RTT up-channel 0 | — |
//!
//! Bench → board: 0x81 answers a sync (flags u8 — bit 0: a host holds the serial port open —,
//! n u16, n × (gpio u8, level u8) input changes spread over the next slice, then the bytes
//! the host sent); 0x82 answers an I²C CONNECT (1 = ACK) or READ (the byte).
//!
//! Owns the byte layout only; what the messages mean to the bench is [`super`]'s.

use std::io::{self, Read, Write};

use super::PicoError;

const SYNC: u8 = 0x01;
const PIN: u8 = 0x02;
const I2C: u8 = 0x03;
const USB: u8 = 0x04;
const LOG: u8 = 0x05;
const HALT: u8 = 0x06;
const RTT: u8 = 0x07;
const SYNC_REPLY: u8 = 0x81;
const I2C_REPLY: u8 = 0x82;

/// Longest payload accepted from the board, bytes: far above one slice's USB traffic
/// (≈ 20 packets of 64 bytes per millisecond at most), small enough that a corrupt length
/// cannot make the bench allocate without bound.
pub const MAX_PAYLOAD: usize = 1 << 20;

/// GPIO number the board sends for "no pin".
pub const NO_PIN: u8 = 0xff;

/// Level of a GPIO as the board reports it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Level {
    /// Driven low.
    Low,
    /// Driven high.
    High,
    /// Not driven by the chip (input, or output disabled).
    Undriven,
}

/// What happened on an I²C bus.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum I2cEvent {
    /// The controller addresses `address` (7 bit) for a read or a write; answered with the
    /// target's acknowledge.
    Connect {
        /// 7-bit address.
        address: u8,
        /// Read (true) or write.
        read: bool,
    },
    /// A data byte written to the addressed target.
    Write(u8),
    /// The controller reads a byte (`ack`: it will acknowledge it and read more); answered
    /// with the byte.
    Read {
        /// The controller acknowledges the byte.
        ack: bool,
    },
    /// STOP condition.
    Stop,
}

/// One message from the board.
#[derive(Debug, Clone, PartialEq)]
pub enum BoardMessage {
    /// End of a slice of simulated time.
    Sync {
        /// Simulated µs since reset.
        t_us: f64,
        /// Bytes the firmware sent to the host over USB since the last sync.
        usb: Vec<u8>,
    },
    /// A GPIO changed level.
    Pin {
        /// Simulated µs.
        t_us: f64,
        /// GPIO number.
        gpio: u8,
        /// The new level.
        level: Level,
    },
    /// An I²C bus event.
    I2c {
        /// Simulated µs.
        t_us: f64,
        /// Controller (I2C0 or I2C1).
        controller: u8,
        /// GPIO carrying the controller's SDA ([`NO_PIN`]: none).
        sda: u8,
        /// GPIO carrying its SCL.
        scl: u8,
        /// The event.
        event: I2cEvent,
    },
    /// USB enumeration finished.
    Usb(UsbDescriptors),
    /// A line for the log.
    Log {
        /// A warning (true) or detail.
        warning: bool,
        /// The text.
        text: String,
    },
    /// The emulated CPU stopped.
    Halt(String),
    /// Bytes of the firmware's RTT up-channel 0 (its defmt log).
    Rtt(Vec<u8>),
}

/// What the host learnt from the device's descriptors when it enumerated.
#[derive(Debug, Clone, Default, PartialEq, Eq, serde::Deserialize)]
pub struct UsbDescriptors {
    /// Vendor ID.
    pub vid: u16,
    /// Product ID.
    pub pid: u16,
    /// Manufacturer string.
    pub manufacturer: Option<String>,
    /// Product string.
    pub product: Option<String>,
    /// Serial number string.
    pub serial: Option<String>,
}

/// The answer to a [`BoardMessage::Sync`].
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct SyncReply {
    /// A program holds the host end of the serial port open (DTR follows it).
    pub host_open: bool,
    /// Input changes `(gpio, high)`, applied in order across the next slice.
    pub inputs: Vec<(u8, bool)>,
    /// Bytes the host wrote to the serial port.
    pub host_bytes: Vec<u8>,
}

fn bad(message: String) -> PicoError {
    PicoError::Protocol(message)
}

/// Read one message; `Ok(None)` at the end of the stream (the board exited).
pub fn read_message(r: &mut impl Read) -> Result<Option<BoardMessage>, PicoError> {
    let mut head = [0u8; 5];
    match r.read_exact(&mut head) {
        Ok(()) => {}
        Err(e) if e.kind() == io::ErrorKind::UnexpectedEof => return Ok(None),
        Err(e) => return Err(PicoError::Pipe(e.to_string())),
    }
    let len = u32::from_le_bytes([head[1], head[2], head[3], head[4]]) as usize;
    if len > MAX_PAYLOAD {
        return Err(bad(format!(
            "message 0x{:02x} announces {len} bytes (at most {MAX_PAYLOAD})",
            head[0]
        )));
    }
    let mut p = vec![0u8; len];
    r.read_exact(&mut p)
        .map_err(|e| PicoError::Pipe(format!("reading a {len}-byte message: {e}")))?;
    decode(head[0], p).map(Some)
}

fn time(tag: u8, p: &[u8], rest: usize) -> Result<f64, PicoError> {
    if p.len() < 8 + rest {
        return Err(bad(format!(
            "message 0x{tag:02x} has {} bytes, needs at least {}",
            p.len(),
            8 + rest
        )));
    }
    let t = f64::from_le_bytes(p[..8].try_into().expect("8 bytes"));
    if !t.is_finite() || t < 0.0 {
        return Err(bad(format!("message 0x{tag:02x} has time {t} µs")));
    }
    Ok(t)
}

fn text(p: Vec<u8>) -> String {
    String::from_utf8(p).unwrap_or_else(|e| String::from_utf8_lossy(e.as_bytes()).into_owned())
}

fn decode(tag: u8, mut p: Vec<u8>) -> Result<BoardMessage, PicoError> {
    Ok(match tag {
        SYNC => {
            let t_us = time(tag, &p, 0)?;
            BoardMessage::Sync {
                t_us,
                usb: p.split_off(8),
            }
        }
        PIN => {
            let t_us = time(tag, &p, 2)?;
            let level = match p[9] {
                0 => Level::Low,
                1 => Level::High,
                2 => Level::Undriven,
                l => return Err(bad(format!("pin level {l}"))),
            };
            BoardMessage::Pin {
                t_us,
                gpio: p[8],
                level,
            }
        }
        I2C => {
            let t_us = time(tag, &p, 5)?;
            if p[8] > 1 {
                return Err(bad(format!(
                    "I²C controller {} (the RP2040 has 0 and 1)",
                    p[8]
                )));
            }
            let arg = p[12];
            let event = match p[11] {
                0 => I2cEvent::Connect {
                    address: arg >> 1,
                    read: arg & 1 == 1,
                },
                1 => I2cEvent::Write(arg),
                2 => I2cEvent::Read { ack: arg != 0 },
                3 => I2cEvent::Stop,
                k => return Err(bad(format!("I²C event kind {k}"))),
            };
            BoardMessage::I2c {
                t_us,
                controller: p[8],
                sda: p[9],
                scl: p[10],
                event,
            }
        }
        USB => BoardMessage::Usb(
            serde_json::from_slice(&p)
                .map_err(|e| bad(format!("USB descriptors `{}`: {e}", text(p.clone()))))?,
        ),
        LOG => {
            let warning = p.first().is_some_and(|&l| l != 0);
            BoardMessage::Log {
                warning,
                text: text(p.split_off(1.min(p.len()))),
            }
        }
        HALT => BoardMessage::Halt(text(p)),
        RTT => BoardMessage::Rtt(p),
        t => return Err(bad(format!("unknown message tag 0x{t:02x}"))),
    })
}

fn frame(tag: u8, payload: &[u8], out: &mut Vec<u8>) {
    out.push(tag);
    out.extend_from_slice(&(payload.len() as u32).to_le_bytes());
    out.extend_from_slice(payload);
}

/// Encode the answer to a sync.
pub fn encode_sync_reply(reply: &SyncReply) -> Vec<u8> {
    let inputs = reply.inputs.len().min(usize::from(u16::MAX));
    let mut p = Vec::with_capacity(3 + 2 * inputs + reply.host_bytes.len());
    p.push(u8::from(reply.host_open));
    p.extend_from_slice(&(inputs as u16).to_le_bytes());
    for &(gpio, high) in &reply.inputs[..inputs] {
        p.extend_from_slice(&[gpio, u8::from(high)]);
    }
    p.extend_from_slice(&reply.host_bytes);
    let mut out = Vec::with_capacity(5 + p.len());
    frame(SYNC_REPLY, &p, &mut out);
    out
}

/// Encode the answer to an I²C CONNECT (1 = ACK, 0 = NACK) or READ (the byte).
pub fn encode_i2c_reply(value: u8) -> [u8; 6] {
    [I2C_REPLY, 1, 0, 0, 0, value]
}

/// Write an answer and flush it.
pub fn send(w: &mut impl Write, bytes: &[u8]) -> Result<(), PicoError> {
    w.write_all(bytes)
        .and_then(|()| w.flush())
        .map_err(|e| PicoError::Pipe(e.to_string()))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn msg(tag: u8, payload: &[u8]) -> Vec<u8> {
        let mut out = Vec::new();
        frame(tag, payload, &mut out);
        out
    }

    fn timed(t: f64, rest: &[u8]) -> Vec<u8> {
        let mut p = t.to_le_bytes().to_vec();
        p.extend_from_slice(rest);
        p
    }

    /// Guards the board → bench layout: each message kind decodes to its fields, in order,
    /// and the end of the stream is `None`, not an error.
    #[test]
    fn decodes_every_message_kind() {
        let mut bytes = msg(SYNC, &timed(1500.0, b"hi"));
        bytes.extend(msg(PIN, &timed(2.5, &[10, 1])));
        bytes.extend(msg(I2C, &timed(3.0, &[1, 6, 7, 0, 0x36 << 1 | 1])));
        bytes.extend(msg(I2C, &timed(3.0, &[0, 4, 5, 2, 1])));
        bytes.extend(msg(
            USB,
            br#"{"vid":11914,"pid":10,"manufacturer":"m","product":"p","serial":"E660"}"#,
        ));
        bytes.extend(msg(LOG, b"\x01usb: no CDC"));
        bytes.extend(msg(HALT, b"breakpoint 0x1"));
        let mut r = bytes.as_slice();
        let mut all = Vec::new();
        while let Some(m) = read_message(&mut r).unwrap() {
            all.push(m);
        }
        assert_eq!(
            all,
            vec![
                BoardMessage::Sync {
                    t_us: 1500.0,
                    usb: b"hi".to_vec()
                },
                BoardMessage::Pin {
                    t_us: 2.5,
                    gpio: 10,
                    level: Level::High
                },
                BoardMessage::I2c {
                    t_us: 3.0,
                    controller: 1,
                    sda: 6,
                    scl: 7,
                    event: I2cEvent::Connect {
                        address: 0x36,
                        read: true
                    }
                },
                BoardMessage::I2c {
                    t_us: 3.0,
                    controller: 0,
                    sda: 4,
                    scl: 5,
                    event: I2cEvent::Read { ack: true }
                },
                BoardMessage::Usb(UsbDescriptors {
                    vid: 0x2e8a,
                    pid: 10,
                    manufacturer: Some("m".into()),
                    product: Some("p".into()),
                    serial: Some("E660".into())
                }),
                BoardMessage::Log {
                    warning: true,
                    text: "usb: no CDC".into()
                },
                BoardMessage::Halt("breakpoint 0x1".into()),
            ]
        );
    }

    /// Guards that malformed messages are errors naming what is wrong, never panics: short
    /// payloads, unknown tags and kinds, oversized lengths, a stream cut mid-message.
    #[test]
    fn malformed_messages_are_errors() {
        let cases: Vec<(Vec<u8>, &str)> = vec![
            (msg(PIN, &timed(1.0, &[10])), "needs at least 10"),
            (msg(PIN, &timed(1.0, &[10, 7])), "pin level 7"),
            (msg(I2C, &timed(1.0, &[0, 4, 5, 9, 0])), "event kind 9"),
            (msg(I2C, &timed(1.0, &[2, 4, 5, 0, 0])), "I²C controller 2"),
            (msg(0x42, b""), "unknown message tag 0x42"),
            (msg(SYNC, &timed(-1.0, b"")), "time -1"),
            (msg(USB, b"{"), "USB descriptors"),
            (
                vec![SYNC, 0xff, 0xff, 0xff, 0x7f],
                "announces 2147483647 bytes",
            ),
            (vec![SYNC, 9, 0, 0, 0, 1, 2], "reading a 9-byte message"),
        ];
        for (bytes, want) in cases {
            let err = read_message(&mut bytes.as_slice()).unwrap_err().to_string();
            assert!(err.contains(want), "{err} (wanted `{want}`)");
        }
    }

    /// Guards the bench → board layout the harness parses (`parseSyncReply`).
    #[test]
    fn encodes_replies() {
        let r = SyncReply {
            host_open: true,
            inputs: vec![(14, true), (15, false)],
            host_bytes: vec![0, 1, 2],
        };
        assert_eq!(
            encode_sync_reply(&r),
            vec![0x81, 10, 0, 0, 0, 1, 2, 0, 14, 1, 15, 0, 0, 1, 2]
        );
        assert_eq!(encode_i2c_reply(0xab), [0x82, 1, 0, 0, 0, 0xab]);
    }
}
