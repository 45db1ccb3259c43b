//! What the session watches in every sample besides recording it: the follower's error
//! against the target law (shown live, and a jammed mechanism when it grows beyond the
//! rig's `safety.max_follower_error_deg` once the target is aligned with the follower over
//! the first driver revolution), and a driver that does not follow its command (a
//! hardware fault it reports, or an angle that stops advancing).
//!
//! Owns the three detectors and their limits; the session decides what to do when one of
//! them fires (stop the motor, record why). It does not talk to the bench.

use std::collections::VecDeque;
use std::time::Duration;

use nalgebra::{Quaternion, UnitQuaternion};

use crate::motion::{Motion, MotionClass};
use crate::rig::backend::Sample;
use crate::rig::config::{Dof, ImuConfig, RigConfig, SensorConfig, IMU_NORM_TOLERANCE};
use crate::rig::recording::flags;

/// Span of device time over which the driver's progress is judged: 0.3 s. With the 20 ms
/// poll and a 10 ms sample batch a stall is stopped within about 0.35 s of its start, inside
/// the 0.5 s the bench promises, and the span holds 24 samples even of an 80 Hz bus.
pub const STALL_WINDOW: Duration = Duration::from_millis(300);

/// The driver counts as stalled when it advanced, in the commanded direction, less than
/// this fraction of what the commanded speed gives over [`STALL_WINDOW`]: 0.2. Far below
/// any steady run (speed ripple, a 1 ms servo tick), far above a blocked shaft, which
/// moves a few encoder counts at most.
pub const STALL_MIN_FRACTION: f64 = 0.2;

/// Time added to the ramp a new speed command needs before the driver's progress is
/// judged: 0.2 s, for the command's own latency and a servo's velocity loop settling.
pub const STALL_GRACE: Duration = Duration::from_millis(200);

/// The ramp a new speed command needs is taken this much longer than the rig's
/// acceleration limit says: 1.5, for a driver that accelerates more slowly than its limit
/// (a heavy mechanism, a servo's profile rounding).
pub const RAMP_MARGIN: f64 = 1.5;

/// How long (device time) the follower error must stay beyond the rig's limit before the
/// mechanism counts as jammed: 50 ms, so one odd reading does not stop a run, while a
/// binding follower is stopped within a few degrees of driver angle.
pub const JAM_CONFIRM: Duration = Duration::from_millis(50);

/// Rows whose follower value is not a fresh reading (repeated IMU value, failed read,
/// stale servo) or whose driver angle is held: the error is not computed on them.
const NOT_FRESH: u32 =
    flags::IMU_STALE | flags::SENSOR_ERROR | flags::FOLLOWER_STALE | flags::DRIVER_HELD;

/// Driver travel over which the probe aligns the target with the follower before it
/// judges a jam: one revolution, so the whole law is seen once and the alignment is
/// unambiguous. The settle cycle normally provides it.
pub const ALIGN_TRAVEL_DEG: f64 = 360.0;

/// Readings kept for the alignment: at most this many, spread over [`ALIGN_TRAVEL_DEG`]
/// (one per 0.5° of driver angle), so the fit costs a few ms once.
const ALIGN_POINTS: usize = 720;

/// Where a follower reading comes from.
enum Reading {
    /// A rotary sensor about z (1R, 1R1T): its column and calibration.
    Rz(usize, SensorConfig),
    /// An IMU (3R): the column of its `qw` and its mounting.
    Imu(usize, ImuConfig),
}

/// One follower reading: an angle about z (deg, wrapping) or an orientation.
#[derive(Debug, Clone, Copy)]
enum Value {
    Rz(f64),
    Rotation(UnitQuaternion<f64>),
}

/// How the target is laid onto the follower: the driver-angle offset (a mechanism not at
/// its zero when the run started, as after a previous run) and the sensor's offset (its
/// zero; for an IMU, its world frame).
#[derive(Debug, Clone, Copy)]
struct Alignment {
    driver_deg: f64,
    rz_deg: f64,
    world: UnitQuaternion<f64>,
}

/// The follower's error against the target law: degrees about z for a turning follower,
/// the geodesic angle for a 3R one. Until the driver has travelled [`ALIGN_TRAVEL_DEG`]
/// the error is relative to the first reading (shown, not judged); then the target is
/// aligned with what was measured over that revolution (driver-angle and sensor offsets
/// fitted, as the analysis does) and the error is one a jam can be judged by.
pub struct ErrorProbe {
    reading: Reading,
    /// The first reading's offset to the unaligned target (display until aligned).
    first: Option<Alignment>,
    /// (driver deg, value) collected for the alignment, with the driver angle of the first.
    collected: Vec<(f64, Value)>,
    aligned: Option<Alignment>,
}

/// The probe's error at one sample.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FollowerError {
    /// Degrees (signed about z, or a geodesic magnitude).
    pub deg: f64,
    /// The target has been aligned with the follower: a jam can be judged by it.
    pub aligned: bool,
    /// The target's angle about z at this sample under the alignment, within one period of
    /// the law, deg (a reading about z only; the measured angle is this plus `deg`).
    pub target_deg: Option<f64>,
}

impl ErrorProbe {
    /// A probe for `motion` on `rig`, when the rig has the sensor its class needs.
    pub fn new(rig: &RigConfig, motion: &Motion) -> Option<ErrorProbe> {
        let mut column = 0;
        for s in &rig.sensors {
            let reading = match s {
                SensorConfig::Imu(i) if motion.class() == MotionClass::R3 => {
                    Some(Reading::Imu(column, i.clone()))
                }
                _ if motion.class() != MotionClass::R3
                    && s.dof() == Some(Dof::Rz)
                    && s.counts_per_rev().is_some() =>
                {
                    Some(Reading::Rz(column, s.clone()))
                }
                _ => None,
            };
            if let Some(reading) = reading {
                return Some(ErrorProbe {
                    reading,
                    first: None,
                    collected: Vec::with_capacity(ALIGN_POINTS + 1),
                    aligned: None,
                });
            }
            column += s.columns().len();
        }
        None
    }

    fn value(&self, s: &Sample) -> Option<Value> {
        match &self.reading {
            Reading::Rz(column, sensor) => {
                Some(Value::Rz(sensor.to_physical(*s.values.get(*column)?)?))
            }
            Reading::Imu(column, imu) => {
                let v = s.values.get(*column..*column + 4)?;
                let q = Quaternion::new(v[0], v[1], v[2], v[3]);
                let norm = q.norm();
                if !norm.is_finite() || (norm - 1.0).abs() > IMU_NORM_TOLERANCE {
                    return None;
                }
                Some(Value::Rotation(
                    imu.follower_rotation(UnitQuaternion::from_quaternion(q)),
                ))
            }
        }
    }

    /// The error at sample `s`, `None` when the sample holds no fresh follower reading.
    pub fn error(&mut self, motion: &Motion, s: &Sample) -> Option<FollowerError> {
        if s.flags & NOT_FRESH != 0 {
            return None;
        }
        let value = self.value(s)?;
        let phi = s.driver_angle_deg;
        if self.aligned.is_none() {
            let start = self.collected.first().map_or(phi, |c| c.0);
            let spacing = ALIGN_TRAVEL_DEG / ALIGN_POINTS as f64;
            if self
                .collected
                .last()
                .is_none_or(|c| (phi - c.0).abs() >= spacing)
            {
                self.collected.push((phi, value));
            }
            if (phi - start).abs() >= ALIGN_TRAVEL_DEG {
                self.aligned = Some(fit(motion, &self.collected));
                self.collected = Vec::new();
            }
        }
        let alignment = match self.aligned {
            Some(a) => a,
            None => *self
                .first
                .get_or_insert_with(|| offsets(motion, &[(phi, value)], 0.0).0),
        };
        // Within one period, so that every cycle draws over the first.
        let target_deg = match value {
            Value::Rz(_) => motion
                .angle_z(((phi + alignment.driver_deg) / 360.0).rem_euclid(1.0))
                .map(|v| v[0].to_degrees() + alignment.rz_deg),
            Value::Rotation(_) => None,
        };
        Some(FollowerError {
            deg: error_deg(motion, phi, value, &alignment),
            aligned: self.aligned.is_some(),
            target_deg,
        })
    }
}

/// The target at driver angle `phi` (deg) under `a`, against `value`: degrees.
fn error_deg(motion: &Motion, phi: f64, value: Value, a: &Alignment) -> f64 {
    let t = (phi + a.driver_deg) / 360.0;
    match value {
        Value::Rz(measured) => {
            let target = motion.angle_z(t).map_or(0.0, |v| v[0].to_degrees());
            wrap180(measured - target - a.rz_deg)
        }
        Value::Rotation(q) => (a.world * motion.sample(t).rotation)
            .angle_to(&q)
            .to_degrees(),
    }
}

/// The sensor offsets that best lay the target, shifted by `driver_deg`, onto `points`
/// (circular mean about z; chordal mean rotation for an IMU), and the sum of squared
/// errors left.
fn offsets(motion: &Motion, points: &[(f64, Value)], driver_deg: f64) -> (Alignment, f64) {
    let mut a = Alignment {
        driver_deg,
        rz_deg: 0.0,
        world: UnitQuaternion::identity(),
    };
    let (mut sin, mut cos) = (0.0, 0.0);
    let mut sum = Quaternion::new(0.0, 0.0, 0.0, 0.0);
    for &(phi, value) in points {
        let t = (phi + driver_deg) / 360.0;
        match value {
            Value::Rz(measured) => {
                let target = motion.angle_z(t).map_or(0.0, |v| v[0].to_degrees());
                let r = (measured - target).to_radians();
                sin += r.sin();
                cos += r.cos();
            }
            Value::Rotation(q) => {
                let w = (q * motion.sample(t).rotation.inverse()).into_inner();
                // q and −q are one rotation: add them on one side.
                let w = if w.dot(&sum) < 0.0 { -w } else { w };
                sum += w;
            }
        }
    }
    a.rz_deg = sin.atan2(cos).to_degrees();
    if sum.norm() > 0.0 {
        a.world = UnitQuaternion::from_quaternion(sum);
    }
    let cost = points
        .iter()
        .map(|&(phi, value)| error_deg(motion, phi, value, &a).powi(2))
        .sum();
    (a, cost)
}

/// The driver-angle offset (a 1° grid, then 0.05° about the best) and sensor offsets that
/// best lay the target onto `points`.
fn fit(motion: &Motion, points: &[(f64, Value)]) -> Alignment {
    let best = |candidates: &mut dyn Iterator<Item = f64>| {
        candidates
            .map(|d| offsets(motion, points, d))
            .min_by(|a, b| a.1.total_cmp(&b.1))
            .map(|(a, _)| a)
    };
    let coarse = best(&mut (0..360).map(f64::from)).map_or(0.0, |a| a.driver_deg);
    best(&mut (-20..=20).map(|k| coarse + f64::from(k) * 0.05))
        .unwrap_or_else(|| offsets(motion, points, coarse).0)
}

/// Map degrees to [−180, 180).
pub fn wrap180(deg: f64) -> f64 {
    (deg + 180.0).rem_euclid(360.0) - 180.0
}

/// Where a detector fired: the sample where the problem began and the one that decided it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Fired {
    /// Device time of the first sample of the problem, µs.
    pub onset_us: u64,
    /// Driver angle there, deg.
    pub onset_driver_deg: f64,
    /// Device time of the sample that decided it, µs.
    pub decided_us: u64,
}

/// A jammed mechanism: the follower error beyond the rig's limit for [`JAM_CONFIRM`].
pub struct JamWatch {
    limit_deg: f64,
    /// First sample of the current excursion beyond the limit: (µs, driver deg, error).
    beyond: Option<(u64, f64, f64)>,
}

impl JamWatch {
    /// A watch for the rig's `safety.max_follower_error_deg`.
    pub fn new(limit_deg: f64) -> JamWatch {
        JamWatch {
            limit_deg,
            beyond: None,
        }
    }

    /// Feed the error of sample `s`; the jam and the error where it began, once confirmed.
    pub fn observe(&mut self, s: &Sample, error_deg: f64) -> Option<(Fired, f64)> {
        if error_deg.abs() <= self.limit_deg {
            self.beyond = None;
            return None;
        }
        let (t0, phi0, e0) =
            *self
                .beyond
                .get_or_insert((s.device_time_us, s.driver_angle_deg, error_deg));
        let lasted = Duration::from_micros(s.device_time_us.saturating_sub(t0));
        (lasted >= JAM_CONFIRM).then_some((
            Fired {
                onset_us: t0,
                onset_driver_deg: phi0,
                decided_us: s.device_time_us,
            },
            e0,
        ))
    }
}

/// A driver that does not follow its speed command: it advances less than
/// [`STALL_MIN_FRACTION`] of the commanded motion over [`STALL_WINDOW`] once the ramp to the
/// command (with [`STALL_GRACE`]) is over.
pub struct StallWatch {
    /// The rig's acceleration limit (deg/s²), `None` when unlimited.
    accel: Option<f64>,
    /// Commanded driver speed, deg/s (signed; 0 while not running).
    speed: f64,
    /// How long after the next sample judging starts again (a new command's ramp).
    grace: Option<Duration>,
    /// No judgement before this device time, µs (the ramp to the last command).
    judge_from_us: u64,
    /// Recent (device µs, driver deg) with a fresh driver angle.
    window: VecDeque<(u64, f64)>,
}

impl StallWatch {
    /// A watch for a driver with the rig's acceleration limit, not yet commanded.
    pub fn new(accel_deg_s2: Option<f64>) -> StallWatch {
        StallWatch {
            accel: accel_deg_s2,
            speed: 0.0,
            grace: None,
            judge_from_us: 0,
            window: VecDeque::new(),
        }
    }

    /// The driver was commanded to `rpm` (from whatever speed it had): judge it again once
    /// it has had time to get there.
    pub fn commanded(&mut self, rpm: f64) {
        self.restart_from(self.speed, rpm * 6.0);
    }

    /// The driver stopped on its own (a device watchdog after a drop-out) and was told to
    /// go on: judge it again once it is back at speed.
    pub fn restarted(&mut self) {
        self.restart_from(0.0, self.speed);
    }

    fn restart_from(&mut self, from_dps: f64, to_dps: f64) {
        let ramp = self
            .accel
            .map_or(0.0, |a| (to_dps - from_dps).abs() / a * RAMP_MARGIN);
        self.grace = Some(Duration::from_secs_f64(ramp) + STALL_GRACE);
        self.speed = to_dps;
        self.window.clear();
    }

    /// Feed sample `s`; a stall, with what the driver did over the window, once it is one.
    pub fn observe(&mut self, s: &Sample) -> Option<(Fired, String)> {
        if s.flags & flags::RECONNECTED != 0 {
            self.restarted();
        }
        if s.flags & flags::DRIVER_HELD != 0 || self.speed == 0.0 {
            return None;
        }
        if let Some(g) = self.grace.take() {
            self.judge_from_us = s.device_time_us + g.as_micros() as u64;
        }
        let window_us = STALL_WINDOW.as_micros() as u64;
        self.window
            .push_back((s.device_time_us, s.driver_angle_deg));
        while self
            .window
            .front()
            .is_some_and(|w| s.device_time_us.saturating_sub(w.0) > window_us)
        {
            self.window.pop_front();
        }
        let &(t0, phi0) = self.window.front()?;
        let span_us = s.device_time_us.saturating_sub(t0);
        // A window with a hole in it (a drop-out) is not a full window.
        if span_us * 10 < window_us * 9 || s.device_time_us < self.judge_from_us {
            return None;
        }
        let span_s = span_us as f64 * 1e-6;
        let moved = (s.driver_angle_deg - phi0) * self.speed.signum();
        let expected = self.speed.abs() * span_s;
        (moved < STALL_MIN_FRACTION * expected).then(|| {
            (
                Fired {
                    onset_us: t0,
                    onset_driver_deg: phi0,
                    decided_us: s.device_time_us,
                },
                format!(
                    "it moved {moved:.1}° in {span_s:.2} s at a commanded {:.1} rpm (about \
                     {expected:.0}° expected): a blocked shaft, a driver that lost power, or \
                     a mechanism it cannot turn",
                    self.speed / 6.0
                ),
            )
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample(t_us: u64, angle: f64, flags: u32) -> Sample {
        Sample {
            device_time_us: t_us,
            driver_angle_deg: angle,
            values: vec![],
            flags,
            host_instant: None,
        }
    }

    /// Guards the stall rule: a driver turning at the commanded 30 rpm is never a stall; one
    /// that stops dead is, within one window of stopping, with the stop's angle as onset;
    /// nothing is judged while a new command's ramp lasts.
    #[test]
    fn a_driver_that_stops_is_a_stall_one_that_turns_is_not() {
        let mut w = StallWatch::new(None);
        w.commanded(30.0);
        let mut t = 0u64;
        let mut angle = 0.0;
        for _ in 0..1000 {
            t += 1000;
            angle += 0.18;
            assert!(w.observe(&sample(t, angle, 0)).is_none());
        }
        let stopped_at = (t, angle);
        let fired = (0..1000).find_map(|_| {
            t += 1000;
            w.observe(&sample(t, angle, 0))
        });
        let (f, why) = fired.expect("a stall");
        assert!(f.decided_us - stopped_at.0 <= STALL_WINDOW.as_micros() as u64 + 1000);
        assert!((f.onset_driver_deg - stopped_at.1).abs() < 0.2 * 0.18 * 300.0);
        assert!(why.contains("30.0 rpm"), "{why}");
        // A new command: not judged during its ramp (2 s from 30 to −30 rpm at 180°/s²).
        w.accel = Some(180.0);
        w.commanded(-30.0);
        for _ in 0..2000 {
            t += 1000;
            assert!(w.observe(&sample(t, angle, 0)).is_none());
        }
    }

    /// Guards the alignment (issue 16's jam watch must not take a mechanism that was not at
    /// its zero, as after a previous run, for a jam): readings of the 2:1 half-turn law
    /// taken 97° of driver angle ahead, through a sensor 30° off its zero, show errors of
    /// tens of degrees against the unaligned target, but none beyond 0.1° once the probe
    /// has seen one revolution; a 3R law with a tilted IMU world frame likewise.
    #[test]
    fn the_probe_aligns_a_shifted_target_before_judging() {
        let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
        for (motion, rig) in [
            ("half-turn-2to1", "sim-stepper"),
            ("figure-eight", "sim-stepper-imu"),
        ] {
            let motion =
                Motion::from_file(&root.join(format!("data/motions/{motion}.toml"))).unwrap();
            let rig = RigConfig::load(&root.join(format!("rigs/{rig}.toml"))).unwrap();
            let mut probe = ErrorProbe::new(&rig, &motion).unwrap();
            let world = UnitQuaternion::from_euler_angles(0.3, -0.2, 1.1);
            let reading = |phi: f64| -> Vec<f64> {
                let t = (phi + 97.0) / 360.0;
                if motion.class() == MotionClass::R3 {
                    let q = world * motion.sample(t).rotation;
                    vec![q.w, q.i, q.j, q.k]
                } else {
                    let deg = motion.angle_z(t).unwrap()[0].to_degrees() + 30.0;
                    vec![(deg / 360.0 * 4096.0).round().rem_euclid(4096.0)]
                }
            };
            let (mut unaligned, mut aligned) = (0.0f64, 0.0f64);
            for i in 0..3000 {
                let phi = i as f64 * 0.25;
                let s = Sample {
                    device_time_us: i * 1000,
                    driver_angle_deg: phi,
                    values: reading(phi),
                    flags: 0,
                    host_instant: None,
                };
                let e = probe.error(&motion, &s).unwrap();
                if e.aligned {
                    aligned = aligned.max(e.deg.abs());
                } else {
                    unaligned = unaligned.max(e.deg.abs());
                }
            }
            assert!(unaligned > 20.0, "{unaligned}");
            assert!(aligned < 0.1, "{aligned}");
        }
    }

    /// Guards the jam rule: an error beyond the limit must last [`JAM_CONFIRM`] of device
    /// time; a short excursion resets.
    #[test]
    fn a_jam_needs_a_lasting_excursion() {
        let mut j = JamWatch::new(20.0);
        assert!(j.observe(&sample(0, 10.0, 0), 25.0).is_none());
        assert!(j.observe(&sample(10_000, 11.0, 0), 5.0).is_none());
        assert!(j.observe(&sample(20_000, 12.0, 0), 25.0).is_none());
        assert!(j.observe(&sample(60_000, 13.0, 0), 26.0).is_none());
        let (f, e) = j.observe(&sample(70_000, 14.0, 0), 27.0).expect("jam");
        assert_eq!((f.onset_us, f.onset_driver_deg, e), (20_000, 12.0, 25.0));
    }

    /// Guards the wrap of the displayed error.
    #[test]
    fn wrap_to_half_turn() {
        assert_eq!(wrap180(190.0), -170.0);
        assert_eq!(wrap180(-190.0), 170.0);
        assert_eq!(wrap180(10.0), 10.0);
    }
}
