//! Merging the bus's samples into the board's: one timeline, one row per board sample.
//!
//! The board (our firmware) samples the follower sensors at the rig's rate on its own
//! clock; the Dynamixel bus reports the driver angle (and any follower servos) at its own,
//! slower rate on another clock. Both are mapped onto the host clock ([`ClockMap`]); each
//! board sample then takes the bus values **linearly interpolated** at its host time. The
//! bus values are all unwrapped positions (driver angle in degrees, present positions in
//! pulses, continuous over turns), so interpolation is exact for constant speed; the
//! board's values (wrapping AS5600 counts, quaternions) are never interpolated.
//!
//! A board sample waits until a bus sample later than it has arrived. If none comes within
//! [`MERGE_MAX_WAIT_S`] (the bus stalled), or the two bracketing bus samples are more than
//! [`INTERPOLATION_MAX_SPAN_S`] apart (failed transactions between them), it takes the
//! nearest bus sample's values and the [`flags::DRIVER_HELD`] flag. Board samples from
//! before the first bus sample cannot be given a driver angle and are dropped (counted in
//! [`Merger::unmatched`]); that happens only as streaming starts.
//!
//! Owns the buffering, the clock maps and the column layout; does not talk to devices.

use std::collections::VecDeque;

use super::clock::ClockMap;
use crate::rig::backend::Sample;
use crate::rig::recording::flags;

/// Longest a board sample waits for a later bus sample, seconds. Default 0.25 s: twenty
/// periods of an 80 Hz bus (so it only expires when the bus really stalled) and short
/// enough that the live display and the one-second flush keep up.
pub const MERGE_MAX_WAIT_S: f64 = 0.25;

/// Largest gap between two bus samples that is interpolated across, seconds. Default
/// 50 ms: four periods of the factory-baud bus (~80 Hz); a longer gap means lost
/// transactions, across which the driver may have changed speed.
pub const INTERPOLATION_MAX_SPAN_S: f64 = 0.05;

/// Resolution of the Dynamixel realtime tick, seconds (whole milliseconds).
pub const BUS_TICK_S: f64 = 1e-3;

/// Flags of the bus's samples that carry over to the rows built from them: the driver's
/// state (e-stop, hardware fault) and the follower servo's staleness.
const BUS_FLAGS: u32 = flags::ESTOP | flags::DRIVER_FAULT | flags::FOLLOWER_STALE;

/// Where one recording column comes from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Source {
    /// The board's value at this index.
    Board(usize),
    /// The bus's value at this index (interpolated).
    Bus(usize),
}

/// A sample waiting, with the host time its stream reported.
#[derive(Debug, Clone)]
struct Held {
    sample: Sample,
    host_s: f64,
}

/// The merger of a mixed bench.
#[derive(Debug, Clone)]
pub struct Merger {
    columns: Vec<Source>,
    board_clock: ClockMap,
    bus_clock: ClockMap,
    board: VecDeque<Held>,
    bus: VecDeque<Held>,
    unmatched: u64,
    held: u64,
    started: bool,
}

fn device_s(s: &Sample) -> f64 {
    s.device_time_us as f64 * 1e-6
}

impl Merger {
    /// A merger producing `columns` (in the rig's column order).
    pub fn new(columns: Vec<Source>) -> Self {
        Self {
            columns,
            board_clock: ClockMap::new(0.0),
            bus_clock: ClockMap::new(BUS_TICK_S),
            board: VecDeque::new(),
            bus: VecDeque::new(),
            unmatched: 0,
            held: 0,
            started: false,
        }
    }

    /// Where each produced column comes from.
    pub fn columns(&self) -> &[Source] {
        &self.columns
    }

    /// Board samples dropped because no bus sample preceded them.
    pub fn unmatched(&self) -> u64 {
        self.unmatched
    }

    /// Rows whose bus values were held rather than interpolated.
    pub fn held(&self) -> u64 {
        self.held
    }

    /// Current estimate of the bus clock's offset to the board clock (host-mapped), s.
    pub fn clock_offset_s(&self) -> Option<f64> {
        Some(self.bus_clock.offset_s()? - self.board_clock.offset_s()?)
    }

    /// A board sample arrived at host time `host_s` (`sample.host_instant` mapped by the
    /// caller; `None` falls back to the caller's now).
    pub fn push_board(&mut self, sample: Sample, host_s: f64) {
        self.board_clock.observe(device_s(&sample), host_s);
        self.board.push_back(Held { sample, host_s });
    }

    /// A bus sample arrived with host time `host_s`.
    pub fn push_bus(&mut self, sample: Sample, host_s: f64) {
        self.bus_clock.observe(device_s(&sample), host_s);
        self.bus.push_back(Held { sample, host_s });
    }

    /// Emit the board samples that can be completed at host time `now_s` into `out`.
    pub fn drain(&mut self, now_s: f64, out: &mut Vec<Sample>) {
        self.emit(Some(now_s), out);
    }

    /// Emit every waiting board sample (end of stream, lost link), with held values
    /// where no later bus sample exists.
    pub fn flush(&mut self, out: &mut Vec<Sample>) {
        self.emit(None, out);
    }

    fn emit(&mut self, now_s: Option<f64>, out: &mut Vec<Sample>) {
        while let Some(front) = self.board.front() {
            let expired = now_s.is_none_or(|n| n - front.host_s > MERGE_MAX_WAIT_S);
            let (Some(board_off), Some(bus_off), Some(first), Some(last)) = (
                self.board_clock.offset_s(),
                self.bus_clock.offset_s(),
                self.bus.front(),
                self.bus.back(),
            ) else {
                // No bus sample yet: nothing to give this board sample a driver angle.
                if !expired {
                    break;
                }
                self.board.pop_front();
                self.unmatched += 1;
                continue;
            };
            let t = device_s(&front.sample) + board_off;
            let before_bus = t < device_s(&first.sample) + bus_off;
            let complete = device_s(&last.sample) + bus_off >= t;
            if !complete && !expired {
                break;
            }
            let Some(held) = self.board.pop_front() else {
                break;
            };
            if before_bus && !self.started {
                // Streaming is starting and the bus has not reported yet.
                self.unmatched += 1;
                continue;
            }
            self.started = true;
            let row = self.compose(held.sample, t, bus_off);
            out.push(row);
            // Keep the bus samples of the last interpolation span before the latest row:
            // the clock estimates move a little as the window slides.
            while self.bus.len() > 1
                && device_s(&self.bus[1].sample) + bus_off < t - INTERPOLATION_MAX_SPAN_S
            {
                self.bus.pop_front();
            }
        }
    }

    /// The row for a board sample at host time `t`.
    fn compose(&mut self, board: Sample, t: f64, bus_off: f64) -> Sample {
        let at = |k: usize| device_s(&self.bus[k].sample) + bus_off;
        let after = (0..self.bus.len()).find(|&k| at(k) >= t);
        let (angle, values, extra_flags) = match after {
            Some(b) if b > 0 && at(b) - at(b - 1) <= INTERPOLATION_MAX_SPAN_S => {
                let (s0, s1) = (&self.bus[b - 1].sample, &self.bus[b].sample);
                let span = at(b) - at(b - 1);
                let w = if span > 0.0 {
                    (t - at(b - 1)) / span
                } else {
                    0.0
                };
                let lerp = |x0: f64, x1: f64| x0 + w * (x1 - x0);
                let values: Vec<f64> = s0
                    .values
                    .iter()
                    .zip(&s1.values)
                    .map(|(&a, &b)| lerp(a, b))
                    .collect();
                let f = (s0.flags | s1.flags) & BUS_FLAGS;
                (lerp(s0.driver_angle_deg, s1.driver_angle_deg), values, f)
            }
            _ => {
                let nearest = (0..self.bus.len())
                    .min_by(|&a, &b| (at(a) - t).abs().total_cmp(&(at(b) - t).abs()))
                    .unwrap_or(0);
                let s = &self.bus[nearest].sample;
                self.held += 1;
                let f = s.flags & BUS_FLAGS;
                (s.driver_angle_deg, s.values.clone(), f | flags::DRIVER_HELD)
            }
        };
        // A bus gap or reconnect is reported once, on the first row at or after it.
        let mut marks = extra_flags;
        for h in self.bus.iter_mut() {
            if device_s(&h.sample) + bus_off <= t {
                marks |= h.sample.flags & (flags::GAP_BEFORE | flags::RECONNECTED);
                h.sample.flags &= !(flags::GAP_BEFORE | flags::RECONNECTED);
            }
        }
        let columns = self
            .columns
            .iter()
            .map(|c| match *c {
                Source::Board(i) => board.values.get(i).copied().unwrap_or(f64::NAN),
                Source::Bus(i) => values.get(i).copied().unwrap_or(f64::NAN),
            })
            .collect();
        Sample {
            device_time_us: board.device_time_us,
            driver_angle_deg: angle,
            values: columns,
            flags: board.flags | marks,
            host_instant: board.host_instant,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// Driver speed of the synthetic runs, deg/s (30 rpm).
    const SPEED: f64 = 180.0;

    fn sample(device_s: f64, angle: f64, values: Vec<f64>, flags: u32) -> Sample {
        Sample {
            device_time_us: (device_s * 1e6).round() as u64,
            driver_angle_deg: angle,
            values,
            flags,
            host_instant: None,
        }
    }

    /// A synthetic run on the host clock: the board samples at 1 kHz (clock 3 s behind the
    /// host, frames of 10 delivered 0.2–3 ms late), the bus at ~80 Hz (clock 5 s ahead,
    /// whole-ms ticks, 0–2 ms residual latency) except during `bus_gap`. Returns the rows
    /// and the merger.
    fn run(bus_gap: Option<(f64, f64)>, seconds: f64) -> (Vec<(f64, Sample)>, Merger) {
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        let mut events: Vec<(f64, bool, Sample)> = Vec::new();
        let n = (seconds * 1000.0) as usize;
        let mut host = 0.0;
        for k in 0..n {
            let t = 0.1 + k as f64 * 1e-3;
            if k % 10 == 0 {
                let frame_end = t + 9e-3;
                host = frame_end + rng.random_range(0.0002..0.003);
            }
            events.push((host, true, sample(t - 0.1, f64::NAN, vec![t], 0)));
        }
        let mut t = 0.1 + rng.random_range(0.0..0.012);
        let mut gap_flag = 0;
        while t < 0.1 + seconds + 0.1 {
            if bus_gap.is_some_and(|(a, b)| t >= a && t < b) {
                gap_flag = flags::GAP_BEFORE;
            } else {
                let tick = ((t + 5.0) * 1000.0).floor() / 1000.0;
                let host = t + rng.random_range(0.0..0.002);
                events.push((
                    host,
                    false,
                    sample(tick, SPEED * t, vec![2.0 * t], gap_flag),
                ));
                gap_flag = 0;
            }
            t += 0.0125;
        }
        // A stable sort keeps each frame's samples in order.
        events.sort_by(|a, b| a.0.total_cmp(&b.0));
        let mut m = Merger::new(vec![Source::Bus(0), Source::Board(0)]);
        let mut rows = Vec::new();
        let mut out = Vec::new();
        for (host, board, s) in events {
            if board {
                m.push_board(s, host);
            } else {
                m.push_bus(s, host);
            }
            out.clear();
            m.drain(host, &mut out);
            rows.extend(out.drain(..).map(|r| (host, r)));
        }
        m.flush(&mut out);
        rows.extend(out.drain(..).map(|r| (f64::INFINITY, r)));
        (rows, m)
    }

    /// Guards: interpolated driver angles match the true angle at each board sample's
    /// time to within the clocks' resolution (±0.5 ms of the bus tick, 0.09° at 30 rpm),
    /// columns come in the requested order, and every board sample after the bus started
    /// becomes exactly one row, in order.
    #[test]
    fn interpolates_the_bus_onto_the_board_timeline() {
        let (rows, m) = run(None, 4.0);
        assert!(m.unmatched() < 20, "unmatched {}", m.unmatched());
        assert_eq!(rows.len() as u64 + m.unmatched(), 4000);
        let mut worst: f64 = 0.0;
        for (_, r) in rows.iter().skip(1000) {
            let t = r.values[1];
            assert_eq!(r.flags & flags::DRIVER_HELD, 0);
            worst = worst.max((r.driver_angle_deg - SPEED * t).abs());
            assert!((r.values[0] - 2.0 * t).abs() < 2.0 * 0.0015);
        }
        assert!(worst < 0.15, "worst driver angle error {worst}°");
        assert!(rows
            .windows(2)
            .all(|w| w[0].1.device_time_us < w[1].1.device_time_us));
        let off = m.clock_offset_s().unwrap();
        assert!((off - (-5.0 - 0.1)).abs() < 0.003, "offset {off}");
    }

    /// Guards: across a stalled bus the rows take the nearest bus sample and say so, the
    /// gap mark of the bus appears on exactly one row, and nothing is dropped or delayed
    /// beyond the wait limit.
    #[test]
    fn a_bus_gap_gives_held_rows_and_one_gap_mark() {
        let (rows, m) = run(Some((2.0, 2.3)), 4.0);
        let held: Vec<f64> = rows
            .iter()
            .filter(|(_, r)| r.flags & flags::DRIVER_HELD != 0)
            .map(|(_, r)| r.values[1])
            .collect();
        assert!(
            held.len() >= 250 && held.len() <= 320,
            "{} held",
            held.len()
        );
        let (lo, hi) = held
            .iter()
            .fold((f64::MAX, f64::MIN), |(a, b), &t| (a.min(t), b.max(t)));
        assert!(lo > 1.98 && hi < 2.33, "held from {lo} to {hi}");
        assert_eq!(m.held() as usize, held.len());
        let marks = rows
            .iter()
            .filter(|(_, r)| r.flags & flags::GAP_BEFORE != 0)
            .count();
        assert_eq!(marks, 1);
        for (host, r) in &rows {
            if host.is_finite() {
                assert!(
                    host - r.values[1] < MERGE_MAX_WAIT_S + 0.03,
                    "row waited too long"
                );
            }
        }
        assert_eq!(rows.len() as u64 + m.unmatched(), 4000);
    }

    /// Guards: board samples taken before the bus's first report are dropped and counted;
    /// with no bus at all, they are dropped after the wait limit, never held forever.
    #[test]
    fn board_samples_without_any_bus_sample_are_dropped_after_the_wait() {
        let mut m = Merger::new(vec![Source::Board(0)]);
        let mut out = Vec::new();
        for k in 0..100 {
            let t = k as f64 * 0.01;
            m.push_board(sample(t, 0.0, vec![t], 0), t + 0.001);
            m.drain(t + 0.001, &mut out);
        }
        assert!(out.is_empty());
        assert!(m.unmatched() >= 70, "{}", m.unmatched());
        m.flush(&mut out);
        assert!(out.is_empty());
        assert_eq!(m.unmatched(), 100);
    }

    /// Guards: two runs of the same inputs give the same rows (no hidden state).
    #[test]
    fn merging_is_deterministic() {
        let a: Vec<Sample> = run(Some((1.0, 1.1)), 2.0)
            .0
            .into_iter()
            .map(|r| r.1)
            .collect();
        let b: Vec<Sample> = run(Some((1.0, 1.1)), 2.0)
            .0
            .into_iter()
            .map(|r| r.1)
            .collect();
        assert_eq!(a, b);
    }
}
