//! Frames: a sequence number, a message body and a CRC-32, COBS-stuffed and ended by 0x00.
//!
//! ```text
//! payload = seq:u16 LE | body (tag + fields) | crc32(seq | body):u32 LE
//! wire    = COBS(payload) | 0x00
//! ```
//! Owns frame encoding and the incremental [`Decoder`], which is fed received bytes one at a
//! time (or in slices), never panics on any input, reports bad frames as typed errors and
//! resynchronizes at the next 0x00. It owns no I/O and no retry policy.

use core::marker::PhantomData;

use crate::cobs::{self, Unstuffed, Unstuffer};
use crate::codec::{DecodeError, EncodeError, Message, Reader, Writer};
use crate::crc::crc32;
use crate::{MAX_BODY_LEN, MAX_PAYLOAD_LEN};

/// Bytes of a payload besides the body: sequence number and CRC.
pub const FRAME_OVERHEAD: usize = 2 + 4;

/// A decoded frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Frame<M> {
    /// Sender's sequence number of this frame.
    pub seq: u16,
    /// The message.
    pub msg: M,
}

/// Why a received frame was dropped. The decoder is ready for the next frame either way.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum FrameError {
    /// The COBS stuffing was cut short by a delimiter (a byte was lost or garbage arrived).
    #[error("COBS block truncated by a delimiter after {len} payload bytes")]
    Stuffing {
        /// Payload bytes decoded before the cut.
        len: usize,
    },
    /// Too short to hold a sequence number, a tag and a CRC.
    #[error("frame of {len} bytes is too short (minimum {min})")]
    TooShort {
        /// Payload length.
        len: usize,
        /// Minimum length.
        min: usize,
    },
    /// Longer than any valid frame; bytes were skipped up to the next delimiter.
    #[error("frame exceeds {max} payload bytes; skipped to the next delimiter")]
    TooLong {
        /// Largest payload accepted.
        max: usize,
    },
    /// The checksum does not match.
    #[error("CRC mismatch: frame says 0x{received:08x}, payload gives 0x{computed:08x}")]
    Crc {
        /// CRC carried by the frame.
        received: u32,
        /// CRC computed over the payload.
        computed: u32,
    },
    /// Checksum fine, but the body is not a valid message.
    #[error("frame {seq}: {error}")]
    Body {
        /// Sequence number of the frame.
        seq: u16,
        /// What is wrong with the body.
        error: DecodeError,
    },
}

/// Encode `msg` as a complete frame (ending in 0x00) into `out`; returns the length.
/// `out` of [`crate::MAX_FRAME_LEN`] bytes always suffices.
pub fn encode_frame<M: Message>(seq: u16, msg: &M, out: &mut [u8]) -> Result<usize, EncodeError> {
    let mut payload = [0u8; MAX_PAYLOAD_LEN];
    let mut w = Writer::new(&mut payload[..2 + MAX_BODY_LEN]);
    w.u16(seq)?;
    msg.encode(&mut w)?;
    let n = w.position();
    let crc = crc32(&payload[..n]);
    payload[n..n + 4].copy_from_slice(&crc.to_le_bytes());
    let n = n + 4;
    let len = cobs::encode(&payload[..n], out).map_err(|e| EncodeError::BufferFull {
        at: 0,
        capacity: e.capacity,
    })?;
    if len >= out.len() {
        return Err(EncodeError::BufferFull {
            at: len,
            capacity: out.len(),
        });
    }
    out[len] = 0;
    Ok(len + 1)
}

/// Encode a frame into a new `Vec` (host side).
#[cfg(feature = "std")]
pub fn encode_frame_vec<M: Message>(seq: u16, msg: &M) -> Result<std::vec::Vec<u8>, EncodeError> {
    let mut out = [0u8; crate::MAX_FRAME_LEN];
    let n = encode_frame(seq, msg, &mut out)?;
    Ok(out[..n].to_vec())
}

/// Incremental frame decoder for messages of type `M`.
///
/// Holds one partial frame (at most [`MAX_PAYLOAD_LEN`] bytes). Feed it bytes as they
/// arrive; each 0x00 completes a frame (or an error). Any byte sequence is acceptable
/// input: garbage yields errors, and the first well-formed frame after the next 0x00
/// decodes normally.
#[derive(Debug, Clone)]
pub struct Decoder<M> {
    unstuffer: Unstuffer,
    buf: [u8; MAX_PAYLOAD_LEN],
    len: usize,
    overflow: bool,
    _msg: PhantomData<fn() -> M>,
}

impl<M: Message> Default for Decoder<M> {
    fn default() -> Self {
        Self::new()
    }
}

impl<M: Message> Decoder<M> {
    /// A decoder waiting for a frame.
    pub const fn new() -> Self {
        Self {
            unstuffer: Unstuffer::new(),
            buf: [0; MAX_PAYLOAD_LEN],
            len: 0,
            overflow: false,
            _msg: PhantomData,
        }
    }

    /// Drop any partial frame.
    pub fn reset(&mut self) {
        self.unstuffer.reset();
        self.len = 0;
        self.overflow = false;
    }

    /// Whether a frame is partly received.
    pub fn in_frame(&self) -> bool {
        self.len > 0 || self.overflow
    }

    fn put(&mut self, b: u8) {
        if self.len < self.buf.len() {
            self.buf[self.len] = b;
            self.len += 1;
        } else {
            self.overflow = true;
        }
    }

    /// Process one received byte; returns a frame or an error when a 0x00 ends a frame.
    pub fn push(&mut self, byte: u8) -> Option<Result<Frame<M>, FrameError>> {
        match self.unstuffer.push(byte) {
            Unstuffed::Nothing => None,
            Unstuffed::Byte(b) => {
                self.put(b);
                None
            }
            Unstuffed::Zero => {
                self.put(0);
                None
            }
            Unstuffed::Empty => {
                self.reset();
                None
            }
            Unstuffed::Truncated => {
                let len = self.len;
                let overflow = self.overflow;
                self.reset();
                Some(Err(if overflow {
                    FrameError::TooLong {
                        max: MAX_PAYLOAD_LEN,
                    }
                } else {
                    FrameError::Stuffing { len }
                }))
            }
            Unstuffed::End => {
                let result = if self.overflow {
                    Err(FrameError::TooLong {
                        max: MAX_PAYLOAD_LEN,
                    })
                } else {
                    decode_payload(&self.buf[..self.len])
                };
                self.reset();
                Some(result)
            }
        }
    }

    /// Process a slice of received bytes, calling `on_frame` for each completed frame or
    /// error, in order.
    pub fn feed(&mut self, bytes: &[u8], mut on_frame: impl FnMut(Result<Frame<M>, FrameError>)) {
        for &b in bytes {
            if let Some(r) = self.push(b) {
                on_frame(r);
            }
        }
    }
}

/// Check and decode one unstuffed payload (`seq | body | crc`).
pub fn decode_payload<M: Message>(payload: &[u8]) -> Result<Frame<M>, FrameError> {
    let min = FRAME_OVERHEAD + 1;
    if payload.len() < min {
        return Err(FrameError::TooShort {
            len: payload.len(),
            min,
        });
    }
    let (data, crc_bytes) = payload.split_at(payload.len() - 4);
    let received = u32::from_le_bytes([crc_bytes[0], crc_bytes[1], crc_bytes[2], crc_bytes[3]]);
    let computed = crc32(data);
    if received != computed {
        return Err(FrameError::Crc { received, computed });
    }
    let seq = u16::from_le_bytes([data[0], data[1]]);
    let mut r = Reader::new(&data[2..]);
    let msg = M::decode(&mut r).map_err(|error| FrameError::Body { seq, error })?;
    Ok(Frame { seq, msg })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{Command, Report, MAX_FRAME_LEN};

    /// Guards that a frame contains exactly one 0x00, at its end.
    #[test]
    fn encoded_frame_has_single_trailing_delimiter() {
        let mut out = [0u8; MAX_FRAME_LEN];
        let n = encode_frame(7, &Command::MoveTo { angle_mdeg: 0 }, &mut out).unwrap();
        assert_eq!(out[n - 1], 0);
        assert!(out[..n - 1].iter().all(|&b| b != 0));
    }

    /// Guards that a corrupted byte is caught by the CRC and the next frame still decodes.
    #[test]
    fn corrupted_frame_is_rejected_then_decoder_recovers() {
        let mut a = [0u8; MAX_FRAME_LEN];
        let na = encode_frame(1, &Command::Heartbeat, &mut a).unwrap();
        let mut b = [0u8; MAX_FRAME_LEN];
        let nb = encode_frame(2, &Command::Stop, &mut b).unwrap();
        a[2] ^= 0x10;
        if a[2] == 0 {
            a[2] = 0x55;
        }
        let mut d = Decoder::<Command>::new();
        let mut got = [None, None];
        let mut i = 0;
        d.feed(&a[..na], |r| {
            got[i] = Some(r);
            i += 1;
        });
        d.feed(&b[..nb], |r| {
            got[i] = Some(r);
            i += 1;
        });
        assert!(matches!(got[0], Some(Err(_))), "{:?}", got[0]);
        assert_eq!(
            got[1],
            Some(Ok(Frame {
                seq: 2,
                msg: Command::Stop
            }))
        );
    }

    /// Guards that an endless run of non-zero bytes is reported once as too long and the
    /// following frame decodes.
    #[test]
    fn overlong_garbage_is_skipped_to_next_delimiter() {
        let mut d = Decoder::<Report>::new();
        for _ in 0..5000 {
            assert!(d.push(0x01).is_none());
        }
        let r = d.push(0);
        assert!(matches!(r, Some(Err(FrameError::TooLong { .. }))), "{r:?}");
        let mut out = [0u8; MAX_FRAME_LEN];
        let n = encode_frame(
            9,
            &Report::Ack {
                ack: 3,
                code: crate::AckCode::Ok,
            },
            &mut out,
        )
        .unwrap();
        let mut last = None;
        d.feed(&out[..n], |r| last = Some(r));
        assert!(matches!(last, Some(Ok(Frame { seq: 9, .. }))));
    }

    /// Guards the minimum-length check (a 0x00-separated short fragment).
    #[test]
    fn short_frame_is_rejected() {
        let mut d = Decoder::<Command>::new();
        d.push(0x02);
        d.push(0x05);
        assert_eq!(
            d.push(0),
            Some(Err(FrameError::TooShort { len: 1, min: 7 }))
        );
    }
}
