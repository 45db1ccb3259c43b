//! Mapping a device clock onto the host clock by the minimum observed latency.
//!
//! Every sample carries its device time `d` and the host instant `h` at which the host
//! learnt of it; `h − d = C + L`, the unknown clock offset `C` plus a latency `L ≥ 0`
//! (wire, USB, scheduling, batching). The smallest `h − d` seen within a sliding window is
//! the best available estimate of `C`: latencies vary from sample to sample, and the
//! window needs only one quick delivery to pin the offset. The window slides so the
//! estimate follows the drift between two crystals. A device clock counting in coarse
//! units (the Dynamixel realtime tick: whole milliseconds) reads up to one unit early; the
//! minimum then matches the start of a unit, so half a unit is added back.
//!
//! Owns only the estimate; it does not know which device it serves.

use std::collections::VecDeque;

/// Length of the sliding window, seconds. Default 2 s: long enough to hold many quick
/// deliveries of either stream (firmware batches every 10 ms, bus replies every ~12 ms),
/// short enough that a 50 ppm crystal drifts only 0.1 ms within it.
pub const CLOCK_WINDOW_S: f64 = 2.0;

/// A device clock's offset to the host clock.
#[derive(Debug, Clone)]
pub struct ClockMap {
    window_s: f64,
    resolution_s: f64,
    /// (host time, offset) pairs with increasing offsets: the front is the window's
    /// minimum (a monotonic queue).
    queue: VecDeque<(f64, f64)>,
}

impl ClockMap {
    /// A map for a clock that counts in units of `resolution_s` (0 for a fine clock).
    pub fn new(resolution_s: f64) -> Self {
        Self::with_window(resolution_s, CLOCK_WINDOW_S)
    }

    /// As [`ClockMap::new`] with a window other than [`CLOCK_WINDOW_S`].
    pub fn with_window(resolution_s: f64, window_s: f64) -> Self {
        Self {
            window_s,
            resolution_s,
            queue: VecDeque::new(),
        }
    }

    /// Record that a sample taken at `device_s` (device clock) reached the host at
    /// `host_s` (host clock). Non-finite inputs are ignored.
    pub fn observe(&mut self, device_s: f64, host_s: f64) {
        let offset = host_s - device_s;
        if !offset.is_finite() {
            return;
        }
        while self.queue.back().is_some_and(|&(_, o)| o >= offset) {
            self.queue.pop_back();
        }
        self.queue.push_back((host_s, offset));
        while self
            .queue
            .front()
            .is_some_and(|&(h, _)| h < host_s - self.window_s)
        {
            self.queue.pop_front();
        }
    }

    /// Host time minus device time, once something has been observed.
    pub fn offset_s(&self) -> Option<f64> {
        self.queue
            .front()
            .map(|&(_, o)| o + 0.5 * self.resolution_s)
    }

    /// The host time of device time `device_s`.
    pub fn to_host(&self, device_s: f64) -> Option<f64> {
        self.offset_s().map(|o| device_s + o)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// Guards: with random non-negative latencies the estimate lands within the smallest
    /// latency of the true offset, and a quantized clock is centred by half a unit.
    #[test]
    fn minimum_latency_recovers_the_offset() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let offset = 12.345;
        let mut fine = ClockMap::new(0.0);
        let mut coarse = ClockMap::new(1e-3);
        for k in 0..2000 {
            let d = k as f64 * 0.004 + rng.random_range(0.0..1e-4);
            let latency = rng.random_range(0.0002..0.010);
            fine.observe(d, d + offset + latency);
            let tick = (d * 1000.0).floor() / 1000.0;
            coarse.observe(tick, d + offset + latency);
        }
        let e = fine.offset_s().unwrap() - offset;
        assert!((0.0..0.0005).contains(&e), "fine error {e}");
        // A sample's true time is tick + U(0, 1 ms): centred, the error is within ±0.5 ms
        // plus the smallest latency.
        let e = coarse.offset_s().unwrap() - (offset + 0.0005);
        assert!(e.abs() < 0.0006, "coarse error {e}");
    }

    /// Guards: the window forgets old minima, so a drifting clock is followed.
    #[test]
    fn sliding_window_follows_drift() {
        let mut m = ClockMap::with_window(0.0, 1.0);
        for k in 0..10_000 {
            let h = k as f64 * 0.001;
            // The device clock runs 100 ppm slow; latency 1 ms except every 50th sample.
            let d = h * (1.0 - 1e-4) - 5.0;
            let latency = if k % 50 == 0 { 0.0 } else { 0.001 };
            m.observe(d, h + latency);
        }
        let expect = 9.999 - (9.999 * (1.0 - 1e-4) - 5.0);
        let got = m.offset_s().unwrap();
        assert!((got - expect).abs() < 2e-4, "{got} vs {expect}");
        assert!(m.to_host(0.0).is_some());
        assert!(ClockMap::new(0.0).offset_s().is_none());
    }
}
