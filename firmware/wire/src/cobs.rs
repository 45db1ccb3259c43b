//! Consistent Overhead Byte Stuffing: turns a payload into bytes free of 0x00, so a single
//! 0x00 can mark the end of every frame and a receiver that joined mid-stream (or saw
//! garbage) resynchronizes at the next 0x00.
//!
//! Owns the byte stuffing only, both one-shot encoding and an incremental, byte-at-a-time
//! unstuffer for receivers. It does not know about checksums or messages ([`crate::frame`]).

/// Largest encoded length of a payload of `len` bytes, without the trailing delimiter.
pub const fn max_encoded_len(len: usize) -> usize {
    len + len / 254 + 1
}

/// Error of [`encode`]: the output buffer is too small.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[error("COBS output buffer of {capacity} bytes is too small (need up to {needed})")]
pub struct BufferTooSmall {
    /// Bytes available.
    pub capacity: usize,
    /// Bytes the encoding may need.
    pub needed: usize,
}

/// Stuff `input` into `out` (no trailing 0x00) and return the encoded length.
pub fn encode(input: &[u8], out: &mut [u8]) -> Result<usize, BufferTooSmall> {
    let needed = max_encoded_len(input.len());
    if out.len() < needed {
        return Err(BufferTooSmall {
            capacity: out.len(),
            needed,
        });
    }
    let mut code_at = 0usize;
    let mut w = 1usize;
    let mut code = 1u8;
    for &b in input {
        if b == 0 {
            out[code_at] = code;
            code_at = w;
            w += 1;
            code = 1;
        } else {
            out[w] = b;
            w += 1;
            code += 1;
            if code == 0xFF {
                out[code_at] = code;
                code_at = w;
                w += 1;
                code = 1;
            }
        }
    }
    out[code_at] = code;
    Ok(w)
}

/// What an [`Unstuffer`] made of one received byte.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Unstuffed {
    /// Nothing to hand out yet.
    Nothing,
    /// One decoded payload byte.
    Byte(u8),
    /// One decoded 0x00: the implicit zero that closed the previous block, handed out when
    /// the next block's code byte (which itself carries no data) shows more data follows.
    Zero,
    /// The delimiter closed a well-formed frame.
    End,
    /// The delimiter closed a frame whose last block was cut short.
    Truncated,
    /// A delimiter with no frame before it (idle line or a leading resync byte).
    Empty,
}

/// Incremental COBS decoder: feed one wire byte at a time, collect decoded bytes.
///
/// It never fails permanently: every 0x00 resets it for the next frame.
#[derive(Debug, Clone, Default)]
pub struct Unstuffer {
    /// Data bytes left in the current block.
    remaining: u8,
    /// Code byte of the current block (0 before the first block of a frame).
    code: u8,
}

impl Unstuffer {
    /// A decoder waiting for the first byte of a frame.
    pub const fn new() -> Self {
        Self {
            remaining: 0,
            code: 0,
        }
    }

    /// Forget any partial frame.
    pub fn reset(&mut self) {
        *self = Self::new();
    }

    /// Process one wire byte.
    pub fn push(&mut self, byte: u8) -> Unstuffed {
        if byte == 0 {
            let out = if self.code == 0 {
                Unstuffed::Empty
            } else if self.remaining != 0 {
                Unstuffed::Truncated
            } else {
                Unstuffed::End
            };
            self.reset();
            return out;
        }
        if self.remaining == 0 {
            // A new block starts; the previous block (if any, and if it was not a full
            // 254-byte block) ended with an implicit zero that is real data now that more
            // follows.
            let had_zero = self.code != 0 && self.code != 0xFF;
            self.code = byte;
            self.remaining = byte - 1;
            if had_zero {
                Unstuffed::Zero
            } else {
                Unstuffed::Nothing
            }
        } else {
            self.remaining -= 1;
            Unstuffed::Byte(byte)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn roundtrip(input: &[u8]) -> ([u8; 2048], usize) {
        let mut enc = [0u8; 2048];
        let n = encode(input, &mut enc).unwrap();
        assert!(
            enc[..n].iter().all(|&b| b != 0),
            "encoded bytes contain 0x00"
        );
        assert!(n <= max_encoded_len(input.len()));
        let mut u = Unstuffer::new();
        let mut out = [0u8; 2048];
        let mut len = 0;
        for &b in &enc[..n] {
            match u.push(b) {
                Unstuffed::Byte(x) => {
                    out[len] = x;
                    len += 1;
                }
                Unstuffed::Zero => {
                    out[len] = 0;
                    len += 1;
                }
                Unstuffed::Nothing => {}
                other => panic!("unexpected {other:?} inside a frame"),
            }
        }
        assert_eq!(u.push(0), Unstuffed::End);
        (out, len)
    }

    /// Guards the textbook examples of COBS (Cheshire & Baker) byte for byte.
    #[test]
    fn encode_matches_published_examples() {
        let mut out = [0u8; 16];
        let n = encode(&[0x00], &mut out).unwrap();
        assert_eq!(&out[..n], &[0x01, 0x01]);
        let n = encode(&[0x00, 0x00], &mut out).unwrap();
        assert_eq!(&out[..n], &[0x01, 0x01, 0x01]);
        let n = encode(&[0x11, 0x22, 0x00, 0x33], &mut out).unwrap();
        assert_eq!(&out[..n], &[0x03, 0x11, 0x22, 0x02, 0x33]);
        let n = encode(&[0x11, 0x00, 0x00, 0x00], &mut out).unwrap();
        assert_eq!(&out[..n], &[0x02, 0x11, 0x01, 0x01, 0x01]);
    }

    /// Guards the 254-byte block boundary, where an off-by-one would corrupt long frames.
    #[test]
    fn roundtrip_across_block_boundaries() {
        for len in [0usize, 1, 253, 254, 255, 508, 509, 600, 1000] {
            for fill in [0u8, 1, 0xFF] {
                let mut input = [fill; 1000];
                if len > 3 {
                    input[len / 2] = 0;
                }
                let (out, n) = roundtrip(&input[..len]);
                assert_eq!(n, len, "len {len} fill {fill}");
                assert_eq!(&out[..n], &input[..len]);
            }
        }
    }

    /// Guards that a frame cut short by a delimiter is reported, and the next frame is fine.
    #[test]
    fn truncated_block_is_reported_and_decoder_recovers() {
        let mut u = Unstuffer::new();
        assert_eq!(u.push(0x05), Unstuffed::Nothing);
        assert_eq!(u.push(0x11), Unstuffed::Byte(0x11));
        assert_eq!(u.push(0x00), Unstuffed::Truncated);
        assert_eq!(u.push(0x00), Unstuffed::Empty);
        assert_eq!(u.push(0x02), Unstuffed::Nothing);
        assert_eq!(u.push(0x33), Unstuffed::Byte(0x33));
        assert_eq!(u.push(0x00), Unstuffed::End);
    }

    /// Guards the size check of the one-shot encoder.
    #[test]
    fn encode_rejects_short_buffer() {
        let mut out = [0u8; 3];
        assert_eq!(
            encode(&[1, 2, 3], &mut out),
            Err(BufferTooSmall {
                capacity: 3,
                needed: 4
            })
        );
    }
}
