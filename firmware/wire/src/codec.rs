//! The byte layout of message bodies: a little-endian cursor writer and reader, the
//! [`Message`] trait both message directions implement, and the typed errors of both.
//!
//! Owns primitive encodings (integers little-endian, `bool` as 0/1, short strings with a
//! length byte). It does not own framing ([`crate::frame`]) or the messages themselves
//! ([`crate::command`], [`crate::report`]).
//!
//! A hand codec rather than serde + postcard: every field has a fixed, documented width, so
//! golden frames stay byte-stable, the decoder is a few straight-line reads with explicit
//! range checks, and sample batches can omit the fields of absent sensors.

/// A body could not be encoded.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum EncodeError {
    /// The output buffer ran out while writing at byte `at`.
    #[error("output buffer full at byte {at} (capacity {capacity})")]
    BufferFull {
        /// Write position that did not fit.
        at: usize,
        /// Buffer capacity.
        capacity: usize,
    },
    /// A field holds a value the wire format cannot carry.
    #[error("field `{field}` cannot be encoded: {reason}")]
    Unrepresentable {
        /// Field name.
        field: &'static str,
        /// Why.
        reason: &'static str,
    },
}

/// A body could not be decoded.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum DecodeError {
    /// The body ended while reading `field` at byte `at`.
    #[error("body ends inside field `{field}` at byte {at}")]
    Truncated {
        /// Field being read.
        field: &'static str,
        /// Byte offset in the body.
        at: usize,
    },
    /// Bytes were left after the message was complete.
    #[error("{extra} unexpected bytes after a complete `{message}` message")]
    TrailingBytes {
        /// Message kind.
        message: &'static str,
        /// Number of extra bytes.
        extra: usize,
    },
    /// A tag byte names no known variant.
    #[error("unknown {what} tag 0x{tag:02x}")]
    UnknownTag {
        /// What the tag selects.
        what: &'static str,
        /// The tag read.
        tag: u8,
    },
    /// A field holds a value outside its documented range.
    #[error("field `{field}` holds invalid value {value}")]
    InvalidValue {
        /// Field name.
        field: &'static str,
        /// The value read (widened).
        value: u32,
    },
}

/// Cursor writing little-endian fields into a caller's buffer.
#[derive(Debug)]
pub struct Writer<'a> {
    buf: &'a mut [u8],
    pos: usize,
}

impl<'a> Writer<'a> {
    /// Write from the start of `buf`.
    pub fn new(buf: &'a mut [u8]) -> Self {
        Self { buf, pos: 0 }
    }

    /// Bytes written so far.
    pub fn position(&self) -> usize {
        self.pos
    }

    /// Append raw bytes.
    pub fn bytes(&mut self, b: &[u8]) -> Result<(), EncodeError> {
        let end = self.pos + b.len();
        if end > self.buf.len() {
            return Err(EncodeError::BufferFull {
                at: self.pos,
                capacity: self.buf.len(),
            });
        }
        self.buf[self.pos..end].copy_from_slice(b);
        self.pos = end;
        Ok(())
    }

    /// Append a `u8`.
    pub fn u8(&mut self, v: u8) -> Result<(), EncodeError> {
        self.bytes(&[v])
    }
    /// Append a `bool` as 0 or 1.
    pub fn bool(&mut self, v: bool) -> Result<(), EncodeError> {
        self.u8(v as u8)
    }
    /// Append a little-endian `u16`.
    pub fn u16(&mut self, v: u16) -> Result<(), EncodeError> {
        self.bytes(&v.to_le_bytes())
    }
    /// Append a little-endian `i16`.
    pub fn i16(&mut self, v: i16) -> Result<(), EncodeError> {
        self.bytes(&v.to_le_bytes())
    }
    /// Append a little-endian `u32`.
    pub fn u32(&mut self, v: u32) -> Result<(), EncodeError> {
        self.bytes(&v.to_le_bytes())
    }
    /// Append a little-endian `i32`.
    pub fn i32(&mut self, v: i32) -> Result<(), EncodeError> {
        self.bytes(&v.to_le_bytes())
    }
}

/// Cursor reading little-endian fields from a received body.
#[derive(Debug)]
pub struct Reader<'a> {
    buf: &'a [u8],
    pos: usize,
}

impl<'a> Reader<'a> {
    /// Read from the start of `buf`.
    pub fn new(buf: &'a [u8]) -> Self {
        Self { buf, pos: 0 }
    }

    /// Bytes not read yet.
    pub fn remaining(&self) -> usize {
        self.buf.len() - self.pos
    }

    /// Fail unless everything was read.
    pub fn finish(&self, message: &'static str) -> Result<(), DecodeError> {
        match self.remaining() {
            0 => Ok(()),
            extra => Err(DecodeError::TrailingBytes { message, extra }),
        }
    }

    /// Take `N` raw bytes for `field`.
    pub fn array<const N: usize>(&mut self, field: &'static str) -> Result<[u8; N], DecodeError> {
        let end = self.pos + N;
        if end > self.buf.len() {
            return Err(DecodeError::Truncated {
                field,
                at: self.pos,
            });
        }
        let mut a = [0u8; N];
        a.copy_from_slice(&self.buf[self.pos..end]);
        self.pos = end;
        Ok(a)
    }

    /// Take `n` raw bytes for `field`.
    pub fn slice(&mut self, n: usize, field: &'static str) -> Result<&'a [u8], DecodeError> {
        let end = self.pos + n;
        if end > self.buf.len() {
            return Err(DecodeError::Truncated {
                field,
                at: self.pos,
            });
        }
        let s = &self.buf[self.pos..end];
        self.pos = end;
        Ok(s)
    }

    /// Read a `u8`.
    pub fn u8(&mut self, field: &'static str) -> Result<u8, DecodeError> {
        Ok(self.array::<1>(field)?[0])
    }
    /// Read a `bool` (0 or 1; anything else is an error).
    pub fn bool(&mut self, field: &'static str) -> Result<bool, DecodeError> {
        match self.u8(field)? {
            0 => Ok(false),
            1 => Ok(true),
            v => Err(DecodeError::InvalidValue {
                field,
                value: v as u32,
            }),
        }
    }
    /// Read a little-endian `u16`.
    pub fn u16(&mut self, field: &'static str) -> Result<u16, DecodeError> {
        Ok(u16::from_le_bytes(self.array(field)?))
    }
    /// Read a little-endian `i16`.
    pub fn i16(&mut self, field: &'static str) -> Result<i16, DecodeError> {
        Ok(i16::from_le_bytes(self.array(field)?))
    }
    /// Read a little-endian `u32`.
    pub fn u32(&mut self, field: &'static str) -> Result<u32, DecodeError> {
        Ok(u32::from_le_bytes(self.array(field)?))
    }
    /// Read a little-endian `i32`.
    pub fn i32(&mut self, field: &'static str) -> Result<i32, DecodeError> {
        Ok(i32::from_le_bytes(self.array(field)?))
    }
}

/// A message body that can cross the wire: one tag byte selects the variant, fields follow.
pub trait Message: Sized {
    /// Write the body (tag and fields, no framing).
    fn encode(&self, w: &mut Writer<'_>) -> Result<(), EncodeError>;
    /// Read a whole body; bytes left over are an error.
    fn decode(r: &mut Reader<'_>) -> Result<Self, DecodeError>;
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Guards little-endian order and the bool range check.
    #[test]
    fn primitives_are_little_endian_and_checked() {
        let mut buf = [0u8; 16];
        let mut w = Writer::new(&mut buf);
        w.u16(0x1234).unwrap();
        w.i32(-2).unwrap();
        w.bool(true).unwrap();
        let n = w.position();
        assert_eq!(&buf[..n], &[0x34, 0x12, 0xFE, 0xFF, 0xFF, 0xFF, 1]);
        let mut r = Reader::new(&buf[..n]);
        assert_eq!(r.u16("a"), Ok(0x1234));
        assert_eq!(r.i32("b"), Ok(-2));
        assert_eq!(r.bool("c"), Ok(true));
        assert_eq!(r.finish("m"), Ok(()));
        assert_eq!(
            Reader::new(&[2]).bool("flag"),
            Err(DecodeError::InvalidValue {
                field: "flag",
                value: 2
            })
        );
    }

    /// Guards that running out of input or output is an error naming the field, not a panic.
    #[test]
    fn short_buffers_are_errors() {
        let mut buf = [0u8; 3];
        let mut w = Writer::new(&mut buf);
        assert_eq!(
            w.u32(1),
            Err(EncodeError::BufferFull { at: 0, capacity: 3 })
        );
        let mut r = Reader::new(&[1, 2, 3]);
        assert_eq!(
            r.u32("speed"),
            Err(DecodeError::Truncated {
                field: "speed",
                at: 0
            })
        );
    }
}
