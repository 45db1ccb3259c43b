//! The device's transmit queue: a fixed ring of bytes holding whole encoded frames until
//! the link (USB CDC, or the simulator's pseudo-terminal) takes them.
//!
//! Owns buffering only. Frames are queued whole or not at all, so a full queue never puts a
//! half frame on the wire; what to do when a frame does not fit is decided by
//! [`crate::Device`] (sample batches are dropped and counted, replies are re-sent when the
//! host retries).

/// Bytes of the transmit queue. Default 4096: about 15 full-sensor batches (150 ms of a
/// 1 kHz stream) of slack for a host that reads late, in 4 KiB of the RP2040's 264 KiB.
pub const OUTBOX_CAPACITY: usize = 4096;

/// A byte ring of [`OUTBOX_CAPACITY`].
#[derive(Debug, Clone)]
pub struct Outbox {
    buf: [u8; OUTBOX_CAPACITY],
    head: usize,
    len: usize,
}

impl Default for Outbox {
    fn default() -> Self {
        Self::new()
    }
}

impl Outbox {
    /// An empty queue.
    pub const fn new() -> Self {
        Self {
            buf: [0; OUTBOX_CAPACITY],
            head: 0,
            len: 0,
        }
    }

    /// Bytes queued.
    pub fn len(&self) -> usize {
        self.len
    }

    /// Whether nothing is queued.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Bytes free.
    pub fn free(&self) -> usize {
        OUTBOX_CAPACITY - self.len
    }

    /// Queue a whole frame; false (and nothing queued) if it does not fit.
    pub fn push(&mut self, frame: &[u8]) -> bool {
        if frame.len() > self.free() {
            return false;
        }
        let mut tail = (self.head + self.len) % OUTBOX_CAPACITY;
        for &b in frame {
            self.buf[tail] = b;
            tail = (tail + 1) % OUTBOX_CAPACITY;
        }
        self.len += frame.len();
        true
    }

    /// Copy up to `out.len()` queued bytes into `out` without removing them; returns how
    /// many. Pair with [`Outbox::consume`] once the link has taken them.
    pub fn peek(&self, out: &mut [u8]) -> usize {
        let n = out.len().min(self.len);
        let first = n.min(OUTBOX_CAPACITY - self.head);
        out[..first].copy_from_slice(&self.buf[self.head..self.head + first]);
        out[first..n].copy_from_slice(&self.buf[..n - first]);
        n
    }

    /// Remove the first `n` queued bytes (at most all of them).
    pub fn consume(&mut self, n: usize) {
        let n = n.min(self.len);
        self.head = (self.head + n) % OUTBOX_CAPACITY;
        self.len -= n;
    }

    /// Move up to `out.len()` queued bytes into `out`; returns how many.
    pub fn pop(&mut self, out: &mut [u8]) -> usize {
        let n = self.peek(out);
        self.consume(n);
        n
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Guards FIFO order across the ring's wrap and all-or-nothing pushes.
    #[test]
    fn fifo_across_wrap_and_whole_frames_only() {
        let mut o = Outbox::new();
        let big = [7u8; OUTBOX_CAPACITY - 10];
        assert!(o.push(&big));
        assert!(!o.push(&[1u8; 11]));
        assert_eq!(o.len(), OUTBOX_CAPACITY - 10);
        let mut sink = [0u8; OUTBOX_CAPACITY];
        assert_eq!(
            o.pop(&mut sink[..OUTBOX_CAPACITY - 20]),
            OUTBOX_CAPACITY - 20
        );
        let frame: [u8; 25] = core::array::from_fn(|i| i as u8);
        assert!(o.push(&frame));
        let mut out = [0u8; 64];
        let n = o.pop(&mut out);
        assert_eq!(n, 35);
        assert_eq!(&out[..10], &[7u8; 10]);
        assert_eq!(&out[10..35], &frame);
        assert!(o.is_empty());
    }

    /// Guards that peek does not remove and consume removes exactly what it is told.
    #[test]
    fn peek_then_consume() {
        let mut o = Outbox::new();
        assert!(o.push(&[1, 2, 3, 4]));
        let mut out = [0u8; 3];
        assert_eq!(o.peek(&mut out), 3);
        assert_eq!(o.len(), 4);
        o.consume(2);
        assert_eq!(o.pop(&mut out), 2);
        assert_eq!(&out[..2], &[3, 4]);
    }
}
