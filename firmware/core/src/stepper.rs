//! Step generation: when the next STEP pulse is due and in which direction, for constant
//! speed runs, trapezoidal moves and decelerating stops, with the position kept in
//! microsteps.
//!
//! Owns the motion profile only; it touches no pins ([`crate::Device`] pulses them) and reads
//! no clock (times are passed in, in µs).
//!
//! # Profile
//! The speed state is a *ramp index* `n`: the number of steps needed to come to rest at the
//! configured acceleration `a` (speed `sqrt(2·a·n)`). Starting from rest, step `n` of a ramp
//! happens `sqrt(2n/a)` after the ramp starts; accelerating takes `n → n+1`, decelerating
//! `n → n−1`, so stopping from index `n` takes exactly `n` steps. A move therefore
//! decelerates exactly when the steps left equal `n` and ends **exactly on its target at
//! rest**. Step times are differences of integer square roots of `K·n` with
//! `K = 2·10¹²/a` µs², which telescope: a ramp accumulates no rounding drift. Cruising at
//! speed `S` places step `k` at `origin + round(k·10⁶/S)` µs, so any whole second of
//! cruise holds exactly `S` steps. The direction changes only at index 0 (at rest).

use mpc_wire::MotionMode;

/// Longest acceleration ramp accepted, seconds (`max_speed / accel`). Default 1000 s: keeps
/// `K·n` (the squared ramp time in µs²) below 10¹⁸, inside `u64`; real ramps last
/// milliseconds to seconds.
pub const MAX_RAMP_S: u64 = 1000;

/// Floor of the square root of `x`, by the digit-by-digit (binary) method: at most 32
/// rounds of shifts and subtractions, no floating point (the RP2040 has no FPU).
pub fn isqrt(x: u64) -> u64 {
    let mut rem = x;
    let mut root = 0u64;
    let mut bit = 1u64 << 62;
    while bit > rem {
        bit >>= 2;
    }
    while bit != 0 {
        if rem >= root + bit {
            rem -= root + bit;
            root = (root >> 1) + bit;
        } else {
            root >>= 1;
        }
        bit >>= 2;
    }
    root
}

/// Speed and acceleration limits in microsteps.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Limits {
    /// Highest speed, microsteps/s (> 0).
    pub max_speed: u32,
    /// Acceleration and deceleration, microsteps/s² (> 0).
    pub accel: u32,
}

/// Why limits were refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum LimitsError {
    /// Zero speed or acceleration.
    #[error(
        "max speed and acceleration must be positive (got {max_speed} µsteps/s, {accel} µsteps/s²)"
    )]
    Zero {
        /// Given speed.
        max_speed: u32,
        /// Given acceleration.
        accel: u32,
    },
    /// The ramp to full speed would last longer than [`MAX_RAMP_S`].
    #[error("ramp of {seconds} s to full speed is longer than {MAX_RAMP_S} s")]
    RampTooLong {
        /// Ramp duration, s.
        seconds: u64,
    },
}

impl Limits {
    /// Check the limits.
    pub fn validate(&self) -> Result<(), LimitsError> {
        if self.max_speed == 0 || self.accel == 0 {
            return Err(LimitsError::Zero {
                max_speed: self.max_speed,
                accel: self.accel,
            });
        }
        let seconds = self.max_speed as u64 / self.accel as u64;
        if seconds > MAX_RAMP_S {
            return Err(LimitsError::RampTooLong { seconds });
        }
        Ok(())
    }
}

/// How the step after the current one changes the speed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StepKind {
    /// Ramp index +1.
    Accel,
    /// Ramp index −1.
    Decel,
    /// Ramp index unchanged, at the ramp's pace (short moves).
    Hold,
    /// Constant speed, microsteps/s.
    Cruise(u32),
}

/// A step that is due.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct StepEvent {
    /// Scheduled time, µs.
    pub at_us: u64,
    /// +1 or −1 microstep.
    pub dir: i8,
    /// The direction differs from the previous step's (DIR must be set first).
    pub dir_changed: bool,
}

/// A motion that ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Completion {
    /// A move reached its target.
    MoveDone,
    /// A stop (or a run at speed 0) came to rest.
    Stopped,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Goal {
    Idle,
    Run { speed: u32, dir: i8 },
    Move { target: i64 },
    Stop,
}

#[derive(Debug, Clone, Copy)]
struct Planned {
    at_us: u64,
    kind: StepKind,
    dir: i8,
}

#[derive(Debug, Clone, Copy)]
struct Cruise {
    speed: u32,
    origin_us: u64,
    count: u64,
}

/// The step generator. See the module documentation for the profile.
#[derive(Debug, Clone)]
pub struct StepGenerator {
    limits: Limits,
    k: u64,
    n_max: u64,
    min_interval_us: u64,
    position: i64,
    dir: i8,
    last_dir: i8,
    n: u64,
    goal: Goal,
    last_step_us: u64,
    last_kind: Option<StepKind>,
    cruise: Option<Cruise>,
    next: Option<Planned>,
    completion: Option<Completion>,
}

impl StepGenerator {
    /// A generator at rest at position 0. `limits` must pass [`Limits::validate`].
    pub fn new(limits: Limits) -> Self {
        let mut g = Self {
            limits,
            k: 0,
            n_max: 0,
            min_interval_us: 0,
            position: 0,
            dir: 1,
            last_dir: 1,
            n: 0,
            goal: Goal::Idle,
            last_step_us: 0,
            last_kind: None,
            cruise: None,
            next: None,
            completion: None,
        };
        g.apply_limits(limits);
        g
    }

    fn apply_limits(&mut self, limits: Limits) {
        let a = limits.accel.max(1) as u64;
        let v = limits.max_speed.max(1) as u64;
        self.limits = limits;
        self.k = 2_000_000_000_000 / a;
        self.n_max = v * v / (2 * a);
        self.min_interval_us = 1_000_000_u64.div_ceil(v);
    }

    /// Change the limits; only at rest (returns false otherwise).
    pub fn set_limits(&mut self, limits: Limits) -> bool {
        if !self.is_idle() {
            return false;
        }
        self.apply_limits(limits);
        true
    }

    /// The limits in force.
    pub fn limits(&self) -> Limits {
        self.limits
    }

    /// Position, microsteps.
    pub fn position(&self) -> i64 {
        self.position
    }

    /// Redefine the present position (only at rest; returns false otherwise).
    pub fn set_position(&mut self, position: i64) -> bool {
        if !self.is_idle() {
            return false;
        }
        self.position = position;
        true
    }

    /// Whether no motion is planned.
    pub fn is_idle(&self) -> bool {
        self.next.is_none() && self.goal == Goal::Idle
    }

    /// The ramp index (steps needed to stop).
    pub fn ramp_index(&self) -> u64 {
        self.n
    }

    /// Target of a move, else the position.
    pub fn target(&self) -> i64 {
        match self.goal {
            Goal::Move { target } => target,
            _ => self.position,
        }
    }

    /// What the generator is doing.
    pub fn mode(&self) -> MotionMode {
        match self.goal {
            Goal::Idle => MotionMode::Idle,
            Goal::Run { .. } => MotionMode::Run,
            Goal::Move { .. } => MotionMode::Move,
            Goal::Stop => MotionMode::Stopping,
        }
    }

    /// Present speed, microsteps/s, signed (0 at rest).
    pub fn speed(&self) -> i64 {
        if self.next.is_none() {
            return 0;
        }
        let s = match self.last_kind {
            Some(StepKind::Cruise(s)) => s as u64,
            _ => isqrt(2 * self.limits.accel as u64 * self.n),
        };
        s as i64 * self.dir as i64
    }

    /// Time of the next step, µs, if one is planned.
    pub fn next_step_us(&self) -> Option<u64> {
        self.next.map(|p| p.at_us)
    }

    /// A motion that ended since the last call.
    pub fn take_completion(&mut self) -> Option<Completion> {
        self.completion.take()
    }

    fn start(&mut self, now_us: u64) {
        if self.next.is_none() {
            // From rest: the ramp starts now.
            self.last_step_us = now_us;
            self.n = 0;
            self.cruise = None;
        }
        self.completion = None;
        self.plan();
    }

    /// Ramp to a constant signed speed (|speed| ≤ max speed; larger is clamped).
    pub fn run(&mut self, speed: i64, now_us: u64) {
        let mag = speed.unsigned_abs().min(self.limits.max_speed as u64) as u32;
        self.goal = Goal::Run {
            speed: mag,
            dir: if speed < 0 { -1 } else { 1 },
        };
        self.start(now_us);
    }

    /// Trapezoidal move to an absolute position.
    pub fn move_to(&mut self, target: i64, now_us: u64) {
        self.goal = Goal::Move { target };
        self.start(now_us);
    }

    /// Decelerate to rest.
    pub fn stop(&mut self, now_us: u64) {
        if self.is_idle() {
            return;
        }
        self.goal = Goal::Stop;
        self.start(now_us);
    }

    /// Stop at once, without deceleration (emergency stop, driver disabled).
    pub fn halt(&mut self) {
        self.goal = Goal::Idle;
        self.next = None;
        self.n = 0;
        self.cruise = None;
        self.last_kind = None;
    }

    fn t(&self, n: u64) -> u64 {
        isqrt(self.k.saturating_mul(n))
    }

    fn plan(&mut self) {
        let n = self.n;
        let (kind, dir) = match self.goal {
            Goal::Idle => {
                self.next = None;
                return;
            }
            Goal::Stop => {
                if n > 0 {
                    (StepKind::Decel, self.dir)
                } else {
                    self.finish(Completion::Stopped);
                    return;
                }
            }
            Goal::Run { speed, dir } => {
                if n > 0 && dir != self.dir {
                    (StepKind::Decel, self.dir)
                } else if speed == 0 {
                    if n > 0 {
                        (StepKind::Decel, self.dir)
                    } else {
                        self.finish(Completion::Stopped);
                        return;
                    }
                } else {
                    let a = self.limits.accel as u64;
                    let ns = (speed as u64 * speed as u64 / (2 * a)).min(self.n_max);
                    if n < ns {
                        (StepKind::Accel, dir)
                    } else if n > ns {
                        (StepKind::Decel, dir)
                    } else {
                        (StepKind::Cruise(speed), dir)
                    }
                }
            }
            Goal::Move { target } => {
                let delta = target - self.position;
                let d: i8 = if delta < 0 { -1 } else { 1 };
                if n > 0 && (delta == 0 || d != self.dir) {
                    // Overshooting or reversing: come to rest first.
                    (StepKind::Decel, self.dir)
                } else if delta == 0 {
                    self.finish(Completion::MoveDone);
                    return;
                } else {
                    let r = delta.unsigned_abs();
                    if n >= r {
                        (StepKind::Decel, d)
                    } else if n < self.n_max && n + 2 <= r {
                        (StepKind::Accel, d)
                    } else if n >= self.n_max {
                        (StepKind::Cruise(self.limits.max_speed), d)
                    } else {
                        (StepKind::Hold, d)
                    }
                }
            }
        };
        let at_us = match kind {
            StepKind::Cruise(speed) => {
                let c = match self.cruise {
                    Some(c) if c.speed == speed => c,
                    _ => Cruise {
                        speed,
                        origin_us: self.last_step_us,
                        count: 0,
                    },
                };
                self.cruise = Some(c);
                let s = speed as u64;
                c.origin_us + ((c.count + 1) * 1_000_000 + s / 2) / s
            }
            StepKind::Accel | StepKind::Hold => {
                self.cruise = None;
                self.last_step_us + (self.t(n + 1) - self.t(n)).max(self.min_interval_us)
            }
            StepKind::Decel => {
                self.cruise = None;
                self.last_step_us + (self.t(n) - self.t(n - 1)).max(self.min_interval_us)
            }
        };
        self.next = Some(Planned { at_us, kind, dir });
    }

    fn finish(&mut self, c: Completion) {
        self.goal = Goal::Idle;
        self.next = None;
        self.n = 0;
        self.cruise = None;
        self.last_kind = None;
        self.completion = Some(c);
    }

    /// If a step is due at `now_us`, take it: update position and speed state, plan the
    /// next one and return it for the caller to pulse. Call repeatedly until `None`.
    pub fn pop_due(&mut self, now_us: u64) -> Option<StepEvent> {
        let p = self.next?;
        if p.at_us > now_us {
            return None;
        }
        match p.kind {
            StepKind::Accel => self.n += 1,
            StepKind::Decel => self.n -= 1,
            StepKind::Hold => {}
            StepKind::Cruise(_) => {
                if let Some(c) = self.cruise.as_mut() {
                    c.count += 1;
                }
            }
        }
        self.dir = p.dir;
        let dir_changed = p.dir != self.last_dir;
        self.last_dir = p.dir;
        self.position += p.dir as i64;
        self.last_step_us = p.at_us;
        self.last_kind = Some(p.kind);
        self.plan();
        Some(StepEvent {
            at_us: p.at_us,
            dir: p.dir,
            dir_changed,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const LIM: Limits = Limits {
        max_speed: 3200,
        accel: 6400,
    };

    /// Run the generator until idle (or `until_us`), returning every step.
    fn drain(g: &mut StepGenerator, until_us: u64) -> Vec<StepEvent> {
        let mut v = Vec::new();
        while let Some(t) = g.next_step_us() {
            if t > until_us {
                break;
            }
            v.push(g.pop_due(t).unwrap());
        }
        v
    }

    /// Guards the integer square root at and around perfect squares.
    #[test]
    fn isqrt_is_exact_floor() {
        for x in [
            0u64,
            1,
            2,
            3,
            4,
            15,
            16,
            17,
            1 << 40,
            (1 << 40) - 1,
            u64::MAX,
        ] {
            let r = isqrt(x);
            assert!(r.checked_mul(r).is_some_and(|s| s <= x));
            assert!((r + 1).checked_mul(r + 1).is_none_or(|s| s > x), "{x}");
        }
    }

    /// Guards the trapezoid: the move ends exactly on target at rest, never exceeds the
    /// maximum step rate, never reverses, and its duration matches the kinematics.
    #[test]
    fn trapezoidal_move_ends_exactly_on_target() {
        let mut g = StepGenerator::new(LIM);
        g.move_to(10_000, 0);
        let steps = drain(&mut g, u64::MAX);
        assert_eq!(steps.len(), 10_000);
        assert_eq!(g.position(), 10_000);
        assert!(g.is_idle());
        assert_eq!(g.take_completion(), Some(Completion::MoveDone));
        assert!(steps.iter().all(|s| s.dir == 1));
        let min = steps
            .windows(2)
            .map(|w| w[1].at_us - w[0].at_us)
            .min()
            .unwrap();
        assert!(
            min >= 1_000_000 / 3200 - 1,
            "interval {min} µs beats the max rate"
        );
        // Ramp 0.5 s each way (800 steps each), 8400 steps of cruise at 3200/s = 2.625 s.
        let total = steps.last().unwrap().at_us as f64 / 1e6;
        assert!((total - 3.625).abs() < 0.01, "move took {total} s");
    }

    /// Guards exact step counts at constant speed: a whole second of cruise holds exactly
    /// the commanded number of steps.
    #[test]
    fn constant_speed_gives_exact_step_counts() {
        let mut g = StepGenerator::new(LIM);
        g.run(-2000, 1_000);
        let steps = drain(&mut g, 5_000_000);
        // Ramp: floor(2000²/(2·6400)) = 312 steps in sqrt(2·312/6400) s ≈ 0.3122 s.
        let in_window = steps
            .iter()
            .filter(|s| s.at_us >= 2_000_000 && s.at_us < 4_000_000)
            .count();
        assert_eq!(in_window, 4000);
        assert!(steps.iter().all(|s| s.dir == -1));
        assert_eq!(g.speed(), -2000);
        assert_eq!(g.position(), -(steps.len() as i64));
    }

    /// Guards the stop: from ramp index n it takes exactly n more steps.
    #[test]
    fn stop_takes_exactly_ramp_index_steps() {
        let mut g = StepGenerator::new(LIM);
        g.run(3200, 0);
        let _ = drain(&mut g, 2_000_000);
        let n = g.ramp_index();
        assert_eq!(n, 800);
        let p = g.position();
        g.stop(2_000_000);
        let _ = drain(&mut g, u64::MAX);
        assert_eq!(g.position() - p, n as i64);
        assert_eq!(g.take_completion(), Some(Completion::Stopped));
        assert_eq!(g.speed(), 0);
    }

    /// Guards "direction changes only at zero speed" when a move is reversed mid-way.
    #[test]
    fn reversal_decelerates_to_rest_before_changing_direction() {
        let mut g = StepGenerator::new(LIM);
        g.move_to(5000, 0);
        let first = drain(&mut g, 600_000);
        assert!(g.ramp_index() > 100);
        g.move_to(-300, 600_000);
        let mut all = first;
        let mut ramp_at_flip = None;
        while let Some(t) = g.next_step_us() {
            let before = g.ramp_index();
            let s = g.pop_due(t).unwrap();
            if s.dir_changed {
                ramp_at_flip = Some(before);
            }
            all.push(s);
        }
        assert_eq!(ramp_at_flip, Some(0));
        assert_eq!(g.position(), -300);
    }

    /// Guards short moves (shorter than a full ramp), including one and two steps.
    #[test]
    fn short_moves_are_exact() {
        for d in [1i64, 2, 3, 5, 100, 1599, 1600, 1601] {
            let mut g = StepGenerator::new(LIM);
            g.move_to(d, 0);
            let steps = drain(&mut g, u64::MAX);
            assert_eq!(steps.len() as i64, d);
            assert_eq!(g.position(), d);
            assert_eq!(g.ramp_index(), 0);
        }
    }

    /// Guards that a low max speed (below one ramp step) is still respected.
    #[test]
    fn tiny_max_speed_is_respected() {
        let lim = Limits {
            max_speed: 10,
            accel: 6400,
        };
        let mut g = StepGenerator::new(lim);
        g.move_to(20, 0);
        let steps = drain(&mut g, u64::MAX);
        assert_eq!(steps.len(), 20);
        let min = steps
            .windows(2)
            .map(|w| w[1].at_us - w[0].at_us)
            .min()
            .unwrap();
        assert!(min >= 100_000);
    }

    /// Guards the limit checks.
    #[test]
    fn limits_are_validated() {
        assert!(LIM.validate().is_ok());
        assert!(Limits {
            max_speed: 0,
            accel: 1
        }
        .validate()
        .is_err());
        assert!(Limits {
            max_speed: 100_000,
            accel: 1
        }
        .validate()
        .is_err());
    }
}
