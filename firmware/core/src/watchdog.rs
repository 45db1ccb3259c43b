//! The dead-man watchdog: the motor must not keep running when the host has gone quiet.
//!
//! Owns the deadline only: every valid command frame feeds it; once the configured time
//! passes without one, [`Watchdog::check`] reports the expiry exactly once. What happens
//! then (decelerate to rest, disable the driver, stop the stream) is done by
//! [`crate::Device`].

/// Dead-man timeout before any configuration, ms. Default 250 ms: the protocol's default
/// ([`mpc_wire::Config::default`]), a few heartbeats of a host sending every 50–100 ms.
pub const DEFAULT_WATCHDOG_MS: u16 = 250;

/// Deadline tracker.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Watchdog {
    timeout_us: u64,
    last_feed_us: u64,
    expired: bool,
}

impl Watchdog {
    /// A watchdog with `timeout_ms`, fed at `now_us`.
    pub fn new(timeout_ms: u16, now_us: u64) -> Self {
        Self {
            timeout_us: timeout_ms as u64 * 1000,
            last_feed_us: now_us,
            expired: false,
        }
    }

    /// Change the timeout (counts from the last feed).
    pub fn set_timeout_ms(&mut self, timeout_ms: u16) {
        self.timeout_us = timeout_ms as u64 * 1000;
    }

    /// A command arrived at `now_us`.
    pub fn feed(&mut self, now_us: u64) {
        self.last_feed_us = now_us;
        self.expired = false;
    }

    /// When it expires, unless fed (None once expired).
    pub fn deadline_us(&self) -> Option<u64> {
        (!self.expired).then_some(self.last_feed_us + self.timeout_us)
    }

    /// True exactly once when the deadline has passed without a feed.
    pub fn check(&mut self, now_us: u64) -> bool {
        if !self.expired && now_us >= self.last_feed_us + self.timeout_us {
            self.expired = true;
            return true;
        }
        false
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Guards the one-shot expiry and re-arming by a feed.
    #[test]
    fn expires_once_and_rearms_on_feed() {
        let mut w = Watchdog::new(250, 1_000);
        assert!(!w.check(250_999));
        assert!(w.check(251_000));
        assert!(!w.check(400_000));
        assert_eq!(w.deadline_us(), None);
        w.feed(500_000);
        assert_eq!(w.deadline_us(), Some(750_000));
        assert!(!w.check(700_000));
        assert!(w.check(750_000));
    }
}
