//! Host-side bookkeeping that needs no I/O: command retries (stop-and-wait with a timeout),
//! sequence-gap counting of device frames, and unwrapping of 32-bit µs timestamps.
//!
//! Owns the policies, driven by time values the caller supplies (so they are testable and
//! usable under simulated time). It does not own the serial port or any task.

use crate::codec::EncodeError;
use crate::command::Command;
use crate::frame::encode_frame;
use crate::report::Report;

/// Time to wait for a command's reply before sending it again, ms. Default 100 ms: a USB
/// CDC round trip is a few ms; a device stalled longer than this is worth a retry.
pub const DEFAULT_RETRY_TIMEOUT_MS: u64 = 100;

/// Total transmissions of one command before giving up. Default 4 (one send, three
/// retries): with the default timeout, 400 ms, longer than the default dead-man watchdog,
/// so a device that never answers has stopped itself by then.
pub const DEFAULT_MAX_ATTEMPTS: u8 = 4;

/// Retry policy of a [`CommandChannel`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RetryPolicy {
    /// Wait for a reply this long before resending, ms.
    pub timeout_ms: u64,
    /// Transmissions before giving up (≥ 1).
    pub max_attempts: u8,
}

impl Default for RetryPolicy {
    fn default() -> Self {
        Self {
            timeout_ms: DEFAULT_RETRY_TIMEOUT_MS,
            max_attempts: DEFAULT_MAX_ATTEMPTS,
        }
    }
}

/// A command waiting for its reply.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Outstanding {
    /// Sequence number it was sent with (retries reuse it).
    pub seq: u16,
    /// The command.
    pub command: Command,
    /// When it was last sent, ms.
    pub sent_at_ms: u64,
    /// Transmissions so far.
    pub attempts: u8,
}

/// Why [`CommandChannel::send`] refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum SendError {
    /// Another command is still waiting for its reply.
    #[error("command {pending} (seq {seq}) is still waiting for its reply")]
    Busy {
        /// Name of the pending command.
        pending: &'static str,
        /// Its sequence number.
        seq: u16,
    },
    /// The frame could not be encoded.
    #[error(transparent)]
    Encode(#[from] EncodeError),
}

/// What [`CommandChannel::poll`] asks the caller to do.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PollAction {
    /// Nothing pending.
    Idle,
    /// Still waiting for the reply.
    Waiting,
    /// Write the first `len` bytes of the output buffer again (a retry).
    Resend {
        /// Frame length.
        len: usize,
    },
    /// No reply after every attempt; the command is dropped.
    GaveUp(Outstanding),
}

/// Stop-and-wait command sender: one command in flight, resent with the same sequence
/// number on timeout (the device recognizes the retry and does not execute it twice).
#[derive(Debug, Clone)]
pub struct CommandChannel {
    next_seq: u16,
    pending: Option<Outstanding>,
    policy: RetryPolicy,
}

impl CommandChannel {
    /// A channel whose first command gets sequence number `first_seq`.
    pub fn new(policy: RetryPolicy, first_seq: u16) -> Self {
        Self {
            next_seq: first_seq,
            pending: None,
            policy,
        }
    }

    /// The command in flight, if any.
    pub fn pending(&self) -> Option<&Outstanding> {
        self.pending.as_ref()
    }

    /// Forget the command in flight (e.g. to send an emergency stop at once).
    pub fn abandon(&mut self) -> Option<Outstanding> {
        self.pending.take()
    }

    /// Encode `command` with a fresh sequence number into `out` and mark it in flight;
    /// returns the frame length to write.
    pub fn send(
        &mut self,
        command: Command,
        now_ms: u64,
        out: &mut [u8],
    ) -> Result<usize, SendError> {
        if let Some(p) = &self.pending {
            return Err(SendError::Busy {
                pending: p.command.name(),
                seq: p.seq,
            });
        }
        let seq = self.next_seq;
        let len = encode_frame(seq, &command, out)?;
        self.next_seq = self.next_seq.wrapping_add(1);
        self.pending = Some(Outstanding {
            seq,
            command,
            sent_at_ms: now_ms,
            attempts: 1,
        });
        Ok(len)
    }

    /// Offer a received report: if it answers the command in flight, that command is done
    /// and returned. Replies to older sequence numbers (late duplicates) are ignored.
    pub fn on_report(&mut self, report: &Report) -> Option<Outstanding> {
        match (report.ack(), &self.pending) {
            (Some(ack), Some(p)) if ack == p.seq => self.pending.take(),
            _ => None,
        }
    }

    /// Check the timeout at time `now_ms`; on a retry the frame is re-encoded into `out`.
    pub fn poll(&mut self, now_ms: u64, out: &mut [u8]) -> Result<PollAction, EncodeError> {
        let Some(p) = self.pending.as_mut() else {
            return Ok(PollAction::Idle);
        };
        if now_ms.saturating_sub(p.sent_at_ms) < self.policy.timeout_ms {
            return Ok(PollAction::Waiting);
        }
        if p.attempts >= self.policy.max_attempts {
            let gone = *p;
            self.pending = None;
            return Ok(PollAction::GaveUp(gone));
        }
        let len = encode_frame(p.seq, &p.command, out)?;
        p.attempts += 1;
        p.sent_at_ms = now_ms;
        Ok(PollAction::Resend { len })
    }
}

/// Counts frames lost between sequence numbers received from the device.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct GapCounter {
    last: Option<u16>,
    /// Frames received.
    pub received: u64,
    /// Frames missing between received ones.
    pub lost: u64,
    /// Frames repeating or preceding the last sequence number seen.
    pub out_of_order: u64,
}

impl GapCounter {
    /// A counter that has seen nothing.
    pub fn new() -> Self {
        Self::default()
    }

    /// Record sequence number `seq`; returns how many frames were lost just before it.
    pub fn observe(&mut self, seq: u16) -> u16 {
        self.received += 1;
        let Some(last) = self.last else {
            self.last = Some(seq);
            return 0;
        };
        let ahead = seq.wrapping_sub(last);
        if ahead == 0 || ahead >= 0x8000 {
            self.out_of_order += 1;
            return 0;
        }
        self.last = Some(seq);
        let gap = ahead - 1;
        self.lost += gap as u64;
        gap
    }
}

/// Turns the device's wrapping 32-bit µs timestamps into a monotonic 64-bit count.
///
/// Works as long as consecutive timestamps are less than 2³¹ µs (≈ 36 min) apart; a
/// timestamp slightly older than the last one (reordering) is mapped backwards, not a
/// whole wrap forwards.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct TimestampUnwrapper {
    last: Option<(u32, u64)>,
}

impl TimestampUnwrapper {
    /// An unwrapper that has seen nothing; the first timestamp maps to itself.
    pub fn new() -> Self {
        Self::default()
    }

    /// The 64-bit time of `ts`.
    pub fn unwrap(&mut self, ts: u32) -> u64 {
        let t = match self.last {
            None => ts as u64,
            Some((last, last64)) => {
                let delta = ts.wrapping_sub(last) as i32 as i64;
                (last64 as i64 + delta).max(0) as u64
            }
        };
        self.last = Some((ts, t));
        t
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{AckCode, MAX_FRAME_LEN};

    /// Guards the retry cycle: resend with the same sequence number after the timeout, give
    /// up after the last attempt, and complete on the matching ack only.
    #[test]
    fn command_channel_retries_then_gives_up() {
        let mut ch = CommandChannel::new(RetryPolicy::default(), 10);
        let mut out = [0u8; MAX_FRAME_LEN];
        let n = ch.send(Command::Heartbeat, 0, &mut out).unwrap();
        let first = out[..n].to_vec();
        assert!(matches!(
            ch.send(Command::Stop, 1, &mut out),
            Err(SendError::Busy { seq: 10, .. })
        ));
        assert_eq!(ch.poll(99, &mut out), Ok(PollAction::Waiting));
        assert_eq!(ch.poll(100, &mut out), Ok(PollAction::Resend { len: n }));
        assert_eq!(&out[..n], &first[..], "a retry is byte-identical");
        assert_eq!(ch.poll(200, &mut out), Ok(PollAction::Resend { len: n }));
        assert_eq!(ch.poll(300, &mut out), Ok(PollAction::Resend { len: n }));
        match ch.poll(400, &mut out) {
            Ok(PollAction::GaveUp(o)) => assert_eq!((o.seq, o.attempts), (10, 4)),
            other => panic!("{other:?}"),
        }
        assert_eq!(ch.poll(500, &mut out), Ok(PollAction::Idle));
        ch.send(Command::Stop, 500, &mut out).unwrap();
        let stale = Report::Ack {
            ack: 10,
            code: AckCode::Ok,
        };
        assert_eq!(ch.on_report(&stale), None);
        let ok = Report::Ack {
            ack: 11,
            code: AckCode::Ok,
        };
        assert_eq!(ch.on_report(&ok).map(|o| o.command), Some(Command::Stop));
        assert!(ch.pending().is_none());
    }

    /// Guards gap counting across the u16 wrap and against duplicates.
    #[test]
    fn gap_counter_counts_losses_across_wrap() {
        let mut g = GapCounter::new();
        assert_eq!(g.observe(65_533), 0);
        assert_eq!(g.observe(65_534), 0);
        assert_eq!(g.observe(1), 2); // 65535 and 0 lost
        assert_eq!(g.observe(1), 0); // duplicate
        assert_eq!(g.observe(2), 0);
        assert_eq!((g.received, g.lost, g.out_of_order), (5, 2, 1));
    }

    /// Guards timestamp unwrapping across the 2³² µs wrap.
    #[test]
    fn timestamps_unwrap_monotonically() {
        let mut u = TimestampUnwrapper::new();
        assert_eq!(u.unwrap(u32::MAX - 10), u32::MAX as u64 - 10);
        assert_eq!(u.unwrap(5), u32::MAX as u64 + 6);
        assert_eq!(u.unwrap(1_000), u32::MAX as u64 + 1_001);
        assert_eq!(u.unwrap(990), u32::MAX as u64 + 991);
    }
}
