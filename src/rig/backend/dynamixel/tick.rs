//! The device clock of a Dynamixel stream: the driver servo's Realtime Tick (control table
//! address 120, milliseconds since the servo booted, wrapping at 32 768) unwrapped into
//! milliseconds since the stream's first sample, and the check that it still counts them.
//!
//! Owns the rule that decides how far the clock moves between two successful reads. The
//! tick is precise (the servo latches it when the sync read arrives) but ambiguous on its
//! own: it wraps every 32.8 s, and it restarts from 0 when the servo reboots (a brown-out,
//! or a Reboot instruction from elsewhere). The host's elapsed time is coarse (scheduling,
//! reply wire time) but never ambiguous. So:
//! - the tick's step counts the whole wraps that bring it nearest the host's elapsed time
//!   since the previous read (a silence longer than 32.8 s keeps the tick's precision);
//! - a step further than [`TICK_HOST_TOLERANCE`] from the host's elapsed time, or a clock
//!   that has fallen behind or run ahead of the host's time since the first sample by more
//!   than that tolerance plus [`TICK_RATE_TOLERANCE`] of it, means the tick no longer counts
//!   time since the stream started: [`TickRestarted`].
//!
//! After a reboot the servo's RAM is at factory defaults: the streamed block is no longer
//! mapped (the indirect addresses are RAM; the block then reads its own zeroed data, tick 0
//! included), the bus watchdog is off and torque is off. So a restart is reported to the
//! worker, which ends the stream with that reason rather than record readings that are no
//! longer measurements; the samples before it are kept. Re-configuring a rebooted servo
//! mid-run is not attempted.
//!
//! It does not read the bus or decide what a sample is (see `worker`).

use std::time::Duration;

/// Period of the Realtime Tick, ms.
pub const TICK_WRAP_MS: u64 = 32_768;

/// How far the tick's time may be from the host's, per step and (plus the rate tolerance)
/// since the first sample. Default 1 s: host jitter between replies is a few tens of ms, but
/// a worker thread descheduled on a loaded machine stretches one host step, and a false
/// restart would end a good run. After a reboot the step is the new tick minus an unrelated
/// old one, which lands this close to the host's figure only by chance (about 6 % of
/// reboots); a tick stuck at the zeroed block's 0 then falls behind the host by this much
/// (plus the rate tolerance) within about a second.
pub const TICK_HOST_TOLERANCE: Duration = Duration::from_millis(1_000);

/// Relative rate difference between the servo's and the host's clocks tolerated over the
/// whole stream. Default 5 %: far more than any crystal or RC oscillator is off, so a long
/// run never trips the check by drift alone.
pub const TICK_RATE_TOLERANCE: f64 = 0.05;

/// The tick no longer counts time since the stream started.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TickRestarted {
    /// The previous tick, ms.
    pub previous_tick: u16,
    /// The tick just read, ms.
    pub tick: u16,
    /// Host time since the previous read, ms.
    pub host_step_ms: u64,
}

impl std::fmt::Display for TickRestarted {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "the driver's realtime tick went from {} to {} ms while the host counted {} ms: \
             the servo rebooted (brown-out or a Reboot instruction from elsewhere) and its RAM \
             settings (streamed block, bus watchdog, torque) are back at factory defaults; \
             stopping the stream, the samples before it are kept",
            self.previous_tick, self.tick, self.host_step_ms
        )
    }
}

/// The unwrapped Realtime Tick of one stream.
#[derive(Debug, Clone, Default)]
pub struct TickClock {
    last_tick: Option<u16>,
    time_ms: u64,
    host_ms: u64,
}

impl TickClock {
    /// A clock at 0 that has seen no tick yet.
    pub fn new() -> Self {
        Self::default()
    }

    /// Milliseconds since the stream's first sample, by the tick.
    pub fn time_ms(&self) -> u64 {
        self.time_ms
    }

    /// Take the tick of a new successful read, `host_step` after the previous successful
    /// read (ignored on the first). Returns the step in ms (0 on the first read).
    pub fn advance(&mut self, tick: u16, host_step: Duration) -> Result<u64, TickRestarted> {
        let tick = tick & 0x7FFF;
        let Some(prev) = self.last_tick.replace(tick) else {
            return Ok(0);
        };
        let host_step_ms = host_step.as_millis() as u64;
        let step = (u64::from(tick) + TICK_WRAP_MS - u64::from(prev)) % TICK_WRAP_MS;
        let wraps = (host_step_ms.saturating_sub(step) + TICK_WRAP_MS / 2) / TICK_WRAP_MS;
        let by_tick = step + wraps * TICK_WRAP_MS;
        let tol = TICK_HOST_TOLERANCE.as_millis() as u64;
        let host_ms = self.host_ms + host_step_ms;
        let time_ms = self.time_ms + by_tick;
        let drift_tol = tol + (TICK_RATE_TOLERANCE * host_ms as f64) as u64;
        if by_tick.abs_diff(host_step_ms) > tol || time_ms.abs_diff(host_ms) > drift_tol {
            return Err(TickRestarted {
                previous_tick: prev,
                tick,
                host_step_ms,
            });
        }
        self.time_ms = time_ms;
        self.host_ms = host_ms;
        Ok(by_tick)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ms(v: u64) -> Duration {
        Duration::from_millis(v)
    }

    /// Guards the normal case: 10 ms ticks read with a jittery host clock give exactly the
    /// ticks' time, across the 32 768 ms wrap.
    #[test]
    fn steady_ticks_give_the_tick_time_across_the_wrap() {
        let mut c = TickClock::new();
        let mut tick: u16 = 32_700;
        assert_eq!(c.advance(tick, ms(0)), Ok(0));
        for i in 0..20u64 {
            tick = ((u64::from(tick) + 10) % TICK_WRAP_MS) as u16;
            let jitter = [0, 7, 3, 15, 1][i as usize % 5];
            assert_eq!(c.advance(tick, ms(10 + jitter)), Ok(10), "read {i}");
        }
        assert_eq!(c.time_ms(), 200);
    }

    /// Guards reboot detection: the tick restarts (near 0, or stuck at the zeroed block's
    /// 0), so its step is unrelated to the time that passed, whatever the previous tick was.
    #[test]
    fn a_restarted_tick_is_reported() {
        for prev in [20_000u16, 100, 5_000] {
            let mut c = TickClock::new();
            c.advance(prev, ms(0)).unwrap();
            let e = c.advance(0, ms(420)).unwrap_err();
            assert_eq!((e.previous_tick, e.tick, e.host_step_ms), (prev, 0, 420));
            assert!(e.to_string().contains("rebooted"), "{e}");
            assert_eq!(c.time_ms(), 0, "the clock did not move");
        }
    }

    /// Guards the chance case: a restart whose first step happens to look plausible is
    /// still caught once the stuck tick has fallen a tolerance behind the host.
    #[test]
    fn a_stuck_tick_is_caught_by_the_time_since_the_start() {
        let mut c = TickClock::new();
        c.advance(500, ms(0)).unwrap();
        for _ in 0..100 {
            c.advance(c.time_ms() as u16 + 500 + 10, ms(10)).unwrap();
        }
        // Restarted at 1 510 with the tick reading 1 510 by chance, then stuck.
        let mut reads = 0;
        let err = loop {
            reads += 1;
            match c.advance(1_510, ms(10)) {
                Ok(_) => assert!(reads < 130, "a stuck tick went unnoticed for {reads} reads"),
                Err(e) => break e,
            }
        };
        assert_eq!(err.tick, 1_510);
        assert!(
            reads > 80,
            "caught after {reads} reads: the drift tolerance is too tight"
        );
    }

    /// Guards long silences and drift: a gap longer than the wrap period keeps the tick's
    /// precision (its whole wraps are counted), and a servo clock 2 % slow over a long run
    /// is not taken for a restart.
    #[test]
    fn long_gaps_and_slow_clocks_keep_the_tick() {
        let mut c = TickClock::new();
        c.advance(1_000, ms(0)).unwrap();
        // 40 000 ms later the tick reads (1 000 + 40 000) mod 32 768 = 8 232; the host saw
        // 40 080 ms (a slow reply).
        assert_eq!(c.advance(8_232, ms(40_080)), Ok(40_000));
        let mut tick = 8_232u64;
        for _ in 0..6_000 {
            tick = (tick + 98) % TICK_WRAP_MS;
            c.advance(tick as u16, ms(100)).unwrap();
        }
        assert_eq!(c.time_ms(), 40_000 + 6_000 * 98);
    }

    /// Guards the tick's unused top bit: a value with bit 15 set reads like its low 15 bits.
    #[test]
    fn the_top_bit_is_ignored() {
        let mut c = TickClock::new();
        c.advance(0x8000 | 5, ms(0)).unwrap();
        assert_eq!(c.advance(15, ms(10)), Ok(10));
    }
}
