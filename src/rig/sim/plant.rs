//! The plant model shared by the simulated benches: where the follower is for a given
//! driver angle, with the imperfections of a real printed mechanism and real sensors.
//!
//! The ideal follower obeys the target law (follower at driver angle φ is `M²(φ/2π)`,
//! `docs/conventions.md`). [`PlantConfig`] adds, in this order:
//! 1. **missed steps** — the physical driver loses a microstep with a given probability
//!    (the simulator asks [`Plant::step_missed`] for each pulse and feeds the *physical*
//!    angle back in);
//! 2. **backlash** — a dead band of `backlash_deg` between driver and follower input: the
//!    follower input only moves when the driver pushes on one side of the gap. It starts in
//!    contact on the forward side (the follower lags `backlash/2` behind going forward);
//! 3. **phase lag** — the follower acts as if the driver were `phase_lag_deg` behind;
//! 4. sensor imperfections: **gain error** (encoder scale, `reading = true·(1+gain)`),
//!    **quantization** (`encoder_resolution` counts per turn), Gaussian **encoder noise**,
//!    IMU **bias** (a constant rotation) and Gaussian **IMU noise** (a random small
//!    rotation per reading).
//!
//! Link faults (dropped or corrupted bytes, a disconnect, a brief drop-out) and faults of
//! the driver and the mechanism at a given time (a driver hardware fault, a blocked driver
//! shaft, a follower that binds) are parsed here too, so one `--fault key=value` list
//! configures a whole simulated bench; the simulators apply them at their time (the
//! follower's binding through [`Plant::jam`]).
//!
//! Randomness comes from ChaCha8 streams seeded by `seed`, one stream for sensors and one
//! for the link, so the same seed gives the same run and link faults do not change sensor
//! noise. The model does not know about serial ports, firmware or Dynamixel registers.

use std::f64::consts::TAU;

use nalgebra::{UnitQuaternion, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// Default seed of the simulated imperfections (any fixed value; runs are reproducible).
pub const DEFAULT_SEED: u64 = 0x6d70_6372_6967;

use crate::motion::DEFAULT_SCALE_MM;
use crate::predict::law::Load;
use crate::predict::table::PlayTable;

/// Axis of the simulated IMU bias rotation: fixed (not random) and tilted off every
/// coordinate axis so a bias shows up in all three angles.
pub const IMU_BIAS_AXIS: [f64; 3] = [1.0, 1.0, 0.5];

/// Error in a `--fault` option.
#[derive(Debug, thiserror::Error)]
pub enum PlantError {
    /// Not `key=value`, unknown key or bad value.
    #[error("--fault `{given}`: {message}")]
    Fault {
        /// The option as given.
        given: String,
        /// What is wrong.
        message: String,
    },
}

/// The target law the plant follows: the follower pose at a fraction `t` of the period.
///
/// [`crate::motion::Motion`] implements it; tests use small closed-form laws.
pub trait PlantLaw: Send + Sync {
    /// Follower state at `t` (any real `t`; 1R/1R1T angles unwrapped across periods).
    fn follower_at(&self, t: f64) -> FollowerState;
}

/// The driver angle (rad, unwrapped) of a mechanism turned by another simulated device,
/// read at the present instant: how a mixed bench's simulated sensor board learns where
/// the simulated Dynamixel driver is.
pub type DriverAngleSource = std::sync::Arc<dyn Fn() -> f64 + Send + Sync>;

/// Follower state.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FollowerState {
    /// Unwrapped rotation about +z in radians (1R/1R1T; 0 for 3R).
    pub angle_z: f64,
    /// Height along z in model units (1R1T; 0 otherwise).
    pub height: f64,
    /// Full orientation R₂.
    pub rotation: UnitQuaternion<f64>,
}

/// Link fault settings (applied by the simulators' serial side).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct LinkFaults {
    /// Probability that a byte sent to the host is dropped.
    pub drop_prob: f64,
    /// Probability that a byte sent to the host has a bit flipped.
    pub corrupt_prob: f64,
    /// Close the pseudo-terminal for good at this time (s since the simulator started).
    pub disconnect_at_s: Option<f64>,
    /// Start of a brief drop-out (s): the device disappears and comes back on the same path.
    pub dropout_at_s: Option<f64>,
    /// Length of the drop-out (s).
    pub dropout_s: f64,
    /// Protocol version the simulated firmware claims (to test version checks).
    pub protocol_version: Option<u16>,
    /// Start of a stall (s): what the device sends is held back, as by a USB adapter or a
    /// loaded machine, and arrives late and in order (Dynamixel bus).
    pub stall_at_s: Option<f64>,
    /// Length of the stall (s).
    pub stall_s: f64,
    /// The Dynamixel driver servo reboots at this time (s), as after a brown-out: RAM back
    /// at factory defaults (torque off, the streamed block's indirect addresses unmapped,
    /// bus watchdog off), realtime tick restarting from 0.
    pub reboot_at_s: Option<f64>,
    /// Dynamixel bus: every byte the host sends comes straight back to it before the
    /// servos' replies, as through a half-duplex (RS-485) adapter without echo suppression.
    pub echo: bool,
}

/// Imperfections of a simulated bench.
#[derive(Debug, Clone, PartialEq)]
pub struct PlantConfig {
    /// Dead band between driver and follower input, degrees of driver angle.
    pub backlash_deg: f64,
    /// The follower acts as if the driver were this many degrees behind.
    pub phase_lag_deg: f64,
    /// Relative encoder scale error (0.01 = reads 1 % large).
    pub gain_error: f64,
    /// Standard deviation of encoder noise, in counts.
    pub encoder_noise_counts: f64,
    /// Quantization of the simulated encoders, counts per turn (`None`: the sensor's own).
    pub encoder_resolution: Option<f64>,
    /// Standard deviation of IMU noise, degrees (angle of a random rotation).
    pub imu_noise_deg: f64,
    /// IMU bias: a constant rotation of this angle about [`IMU_BIAS_AXIS`], degrees.
    pub imu_bias_deg: f64,
    /// Probability that one step pulse does not move the motor.
    pub missed_step_prob: f64,
    /// Millimetres per model unit for the follower height.
    pub scale_mm: f64,
    /// Link faults.
    pub link: LinkFaults,
    /// Faults of the driver and the mechanism.
    pub events: BenchFaults,
    /// Seed of all randomness.
    pub seed: u64,
    /// The geometry plant: the built parts' free turn over the driver angle (from
    /// `mpc-rig simulate`). With it a 1R follower is not on the target law but where the
    /// prediction's load (a drag, a torque, a spring) leaves it inside that free interval,
    /// as the printed parts would move it; a 1R1T follower is where a drag leaves it in
    /// its free region, height and turn together.
    pub play: Option<std::sync::Arc<PlayTable>>,
}

/// Faults of the driver and the mechanism at a time (s since the simulator started).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct BenchFaults {
    /// The driver reports a hardware fault and stops: a Dynamixel driver latches an
    /// overload (torque off), the firmware's STEP output fails and it latches its
    /// emergency stop.
    pub driver_fault_at_s: Option<f64>,
    /// The driver's shaft is blocked, with no fault reported: a Dynamixel's position stops
    /// changing; a stepper loses every step (its firmware still counts them, so only the
    /// follower shows it).
    pub driver_stall_at_s: Option<f64>,
    /// The follower binds and stops where it is while the driver turns on (a slipping
    /// coupling, a broken tooth).
    pub jam_at_s: Option<f64>,
}

impl Default for PlantConfig {
    fn default() -> Self {
        PlantConfig {
            backlash_deg: 0.0,
            phase_lag_deg: 0.0,
            gain_error: 0.0,
            encoder_noise_counts: 0.0,
            encoder_resolution: None,
            imu_noise_deg: 0.0,
            imu_bias_deg: 0.0,
            missed_step_prob: 0.0,
            scale_mm: DEFAULT_SCALE_MM,
            link: LinkFaults::default(),
            events: BenchFaults::default(),
            seed: DEFAULT_SEED,
            play: None,
        }
    }
}

/// The `--fault` keys, with a short description each (for help texts and errors).
pub const FAULT_KEYS: &[(&str, &str)] = &[
    ("backlash_deg", "dead band between driver and follower, deg"),
    (
        "phase_lag_deg",
        "follower lags the driver by this angle, deg",
    ),
    ("gain_error", "relative encoder scale error, e.g. 0.01"),
    (
        "encoder_noise_counts",
        "encoder noise standard deviation, counts",
    ),
    (
        "encoder_resolution",
        "encoder quantization, counts per turn",
    ),
    ("imu_noise_deg", "IMU noise standard deviation, deg"),
    ("imu_bias_deg", "IMU constant rotation bias, deg"),
    ("missed_step_prob", "probability a step pulse is lost"),
    ("scale_mm", "mm per model unit for heights"),
    ("drop_prob", "probability a byte to the host is dropped"),
    (
        "corrupt_prob",
        "probability a byte to the host is corrupted",
    ),
    ("disconnect_at_s", "unplug for good at this time, s"),
    ("dropout_at_s", "brief unplug starting at this time, s"),
    ("dropout_s", "length of the brief unplug, s (default 0.5)"),
    (
        "stall_at_s",
        "Dynamixel bus: replies held back from this time, s",
    ),
    ("stall_s", "length of the stall, s (default 0.06)"),
    (
        "reboot_at_s",
        "Dynamixel bus: the driver reboots at this time, s (a brown-out)",
    ),
    (
        "driver_fault_at_s",
        "the driver reports a hardware fault (overload, firmware e-stop) at this time, s",
    ),
    (
        "driver_stall_at_s",
        "the driver's shaft is blocked from this time, s (no fault reported)",
    ),
    ("jam_at_s", "the follower binds and stops from this time, s"),
    (
        "echo",
        "Dynamixel bus: 1 echoes every byte the host sends (adapter without echo suppression)",
    ),
    (
        "protocol_version",
        "protocol version the simulated device claims",
    ),
    ("seed", "seed of the simulated randomness"),
];

/// Short names accepted for some `--fault` keys by every command that takes them:
/// `backlash=2` is `backlash_deg=2`. Errors repeat the option as typed.
pub const FAULT_ALIASES: &[(&str, &str)] = &[
    ("backlash", "backlash_deg"),
    ("phase_lag", "phase_lag_deg"),
    ("imu_noise", "imu_noise_deg"),
    ("imu_bias", "imu_bias_deg"),
    ("encoder_noise", "encoder_noise_counts"),
];

/// Default length of a brief drop-out when only `dropout_at_s` is given: half a second,
/// like a USB cable wiggled loose and back.
pub const DEFAULT_DROPOUT_S: f64 = 0.5;

/// Default length of a stall when only `stall_at_s` is given: 60 ms, longer than the host's
/// reply timeout (34 ms plus the wire time), so at least one transaction times out while
/// its replies are still on their way.
pub const DEFAULT_STALL_S: f64 = 0.06;

impl PlantConfig {
    /// Parse repeated `--fault key=value` options (see [`FAULT_KEYS`]).
    pub fn from_faults<S: AsRef<str>>(faults: &[S]) -> Result<PlantConfig, PlantError> {
        let mut cfg = PlantConfig::default();
        cfg.link.dropout_s = DEFAULT_DROPOUT_S;
        cfg.link.stall_s = DEFAULT_STALL_S;
        for given in faults {
            cfg.apply(given.as_ref())?;
        }
        Ok(cfg)
    }

    /// Apply one `key=value`.
    pub fn apply(&mut self, given: &str) -> Result<(), PlantError> {
        let fail = |message: String| PlantError::Fault {
            given: given.to_string(),
            message,
        };
        let (key, value) = given
            .split_once('=')
            .ok_or_else(|| fail("expected key=value".into()))?;
        let (key, value) = (key.trim(), value.trim());
        let key = FAULT_ALIASES
            .iter()
            .find(|(short, _)| *short == key)
            .map_or(key, |(_, long)| long);
        let num = || -> Result<f64, PlantError> {
            let v: f64 = value
                .parse()
                .map_err(|_| fail(format!("`{value}` is not a number")))?;
            if v.is_finite() {
                Ok(v)
            } else {
                Err(fail("must be finite".into()))
            }
        };
        let nonneg = || -> Result<f64, PlantError> {
            let v = num()?;
            if v < 0.0 {
                Err(fail("must not be negative".into()))
            } else {
                Ok(v)
            }
        };
        let prob = || -> Result<f64, PlantError> {
            let v = num()?;
            if (0.0..=1.0).contains(&v) {
                Ok(v)
            } else {
                Err(fail("a probability must be in [0, 1]".into()))
            }
        };
        match key {
            "backlash_deg" => self.backlash_deg = nonneg()?,
            "phase_lag_deg" => self.phase_lag_deg = num()?,
            "gain_error" => {
                let g = num()?;
                if g <= -1.0 {
                    return Err(fail("must be > -1".into()));
                }
                self.gain_error = g;
            }
            "encoder_noise_counts" => self.encoder_noise_counts = nonneg()?,
            "encoder_resolution" => {
                let r = num()?;
                if r < 1.0 {
                    return Err(fail("must be at least 1 count per turn".into()));
                }
                self.encoder_resolution = Some(r);
            }
            "imu_noise_deg" => self.imu_noise_deg = nonneg()?,
            "imu_bias_deg" => self.imu_bias_deg = num()?,
            "missed_step_prob" => self.missed_step_prob = prob()?,
            "scale_mm" => {
                let s = num()?;
                if s <= 0.0 {
                    return Err(fail("must be positive".into()));
                }
                self.scale_mm = s;
            }
            "drop_prob" => self.link.drop_prob = prob()?,
            "corrupt_prob" => self.link.corrupt_prob = prob()?,
            "disconnect_at_s" => self.link.disconnect_at_s = Some(nonneg()?),
            "dropout_at_s" => self.link.dropout_at_s = Some(nonneg()?),
            "dropout_s" => self.link.dropout_s = nonneg()?,
            "stall_at_s" => self.link.stall_at_s = Some(nonneg()?),
            "stall_s" => self.link.stall_s = nonneg()?,
            "reboot_at_s" => self.link.reboot_at_s = Some(nonneg()?),
            "driver_fault_at_s" => self.events.driver_fault_at_s = Some(nonneg()?),
            "driver_stall_at_s" => self.events.driver_stall_at_s = Some(nonneg()?),
            "jam_at_s" => self.events.jam_at_s = Some(nonneg()?),
            "echo" => {
                self.link.echo = match value {
                    "1" | "true" => true,
                    "0" | "false" => false,
                    _ => return Err(fail("expected 1 or 0".into())),
                }
            }
            "protocol_version" => {
                self.link.protocol_version = Some(
                    value
                        .parse()
                        .map_err(|_| fail(format!("`{value}` is not a version number")))?,
                )
            }
            "seed" => {
                self.seed = value
                    .parse()
                    .map_err(|_| fail(format!("`{value}` is not an unsigned integer")))?
            }
            _ => {
                let keys: Vec<&str> = FAULT_KEYS.iter().map(|(k, _)| *k).collect();
                return Err(fail(format!(
                    "unknown key `{key}`; known: {}",
                    keys.join(", ")
                )));
            }
        }
        Ok(())
    }
}

/// What happened to one byte on a faulty link.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LinkByte {
    /// Delivered as is.
    Pass(u8),
    /// Delivered with a bit flipped.
    Corrupted(u8),
    /// Lost.
    Dropped,
}

/// A simulated mechanism with its sensors.
pub struct Plant {
    target: Box<dyn PlantLaw>,
    cfg: PlantConfig,
    /// Follower input angle after the backlash gap, rad (None before the first call).
    input: Option<f64>,
    /// The follower has bound: it stays at this state.
    jammed: Option<FollowerState>,
    /// The last state returned.
    last: Option<FollowerState>,
    /// Geometry plant: the target angle at the last call and the follower's deviation
    /// from it (rad).
    drag: Option<(f64, f64)>,
    /// Geometry plant, 1R1T: the target at the last call and the follower's deviation from
    /// it, both in the plane of the prediction's lever (turn × lever, height; mm).
    drag_plane: Option<([f64; 2], [f64; 2])>,
    sensor_rng: ChaCha8Rng,
    link_rng: ChaCha8Rng,
    step_rng: ChaCha8Rng,
    imu_bias: UnitQuaternion<f64>,
}

impl Plant {
    /// A plant following `target` with the imperfections of `cfg`.
    pub fn new<T: PlantLaw + 'static>(target: T, cfg: PlantConfig) -> Plant {
        let stream = |n: u64| {
            let mut r = ChaCha8Rng::seed_from_u64(cfg.seed);
            r.set_stream(n);
            r
        };
        let axis = nalgebra::Unit::new_normalize(Vector3::from(IMU_BIAS_AXIS));
        Plant {
            target: Box::new(target),
            input: None,
            jammed: None,
            last: None,
            drag: None,
            drag_plane: None,
            sensor_rng: stream(1),
            link_rng: stream(2),
            step_rng: stream(3),
            imu_bias: UnitQuaternion::from_axis_angle(&axis, cfg.imu_bias_deg.to_radians()),
            cfg,
        }
    }

    /// The configuration.
    pub fn config(&self) -> &PlantConfig {
        &self.cfg
    }

    /// The ideal follower state at driver angle `phi` (rad), no imperfections.
    pub fn ideal(&self, phi: f64) -> FollowerState {
        self.target.follower_at(phi / TAU)
    }

    /// The follower binds where it is now ([`BenchFaults::jam_at_s`]): from here on
    /// [`Plant::follower`] returns this state whatever the driver does.
    pub fn jam(&mut self) {
        if self.jammed.is_none() {
            self.jammed = Some(self.last.unwrap_or_else(|| self.ideal(0.0)));
        }
    }

    /// The true follower state for the physical driver angle `phi` (rad, unwrapped). Call
    /// with successive angles: backlash is stateful.
    pub fn follower(&mut self, phi: f64) -> FollowerState {
        if let Some(state) = self.jammed {
            return state;
        }
        let state = self.follow(phi);
        self.last = Some(state);
        state
    }

    fn follow(&mut self, phi: f64) -> FollowerState {
        let half_gap = self.cfg.backlash_deg.to_radians() / 2.0;
        let input = match self.input {
            None => phi - half_gap,
            Some(prev) => {
                if phi - prev > half_gap {
                    phi - half_gap
                } else if prev - phi > half_gap {
                    phi + half_gap
                } else {
                    prev
                }
            }
        };
        self.input = Some(input);
        let effective = input - self.cfg.phase_lag_deg.to_radians();
        let mut state = self.target.follower_at(effective / TAU);
        if let Some(region) = self.cfg.play.as_ref().and_then(|t| t.region_at(effective)) {
            // 1R1T: a dragged follower stays where it was unless the parts push it, to the
            // nearest point of the free region (`predict::law::drag_plane`).
            let lever = crate::predict::SCREW_LEVER_MM;
            let now = [state.angle_z * lever, state.height * self.cfg.scale_mm];
            let e = self.drag_plane.map_or([0.0, 0.0], |(was, e)| {
                [e[0] + was[0] - now[0], e[1] + was[1] - now[1]]
            });
            let e = region.clamp(e);
            self.drag_plane = Some((now, e));
            let turn = e[0] / lever;
            state.angle_z += turn;
            state.rotation =
                UnitQuaternion::from_axis_angle(&Vector3::z_axis(), turn) * state.rotation;
            state.height += e[1] / self.cfg.scale_mm;
        } else if let Some(table) = &self.cfg.play {
            // The follower's deviation from the target, within the free interval at this
            // angle, where the prediction's load leaves it (`predict::law`).
            let (plus, minus) = table.at(effective);
            let e = match table.load_applied() {
                // A dragged follower stays where it was unless the parts push it.
                Load::Drag => self
                    .drag
                    .map_or(0.0, |(target, e)| e + target - state.angle_z)
                    .clamp(-minus, plus),
                // A torque holds it against that side of its play.
                Load::Torque(sense) if sense > 0.0 => plus,
                Load::Torque(_) => -minus,
                // A spring pulls it towards its rest angle, as far as the play allows;
                // the rest angle is against the target within one period, as predicted.
                Load::Spring(rest_deg) => {
                    let within = self
                        .target
                        .follower_at((effective / TAU).rem_euclid(1.0))
                        .angle_z;
                    (rest_deg.to_radians() - within).clamp(-minus, plus)
                }
            };
            self.drag = Some((state.angle_z, e));
            state.angle_z += e;
            state.rotation =
                UnitQuaternion::from_axis_angle(&Vector3::z_axis(), e) * state.rotation;
        }
        state
    }

    /// Whether the next step pulse is lost (missed-step fault).
    pub fn step_missed(&mut self) -> bool {
        self.cfg.missed_step_prob > 0.0 && self.step_rng.random::<f64>() < self.cfg.missed_step_prob
    }

    /// A rotary encoder reading, in (unwrapped, fractional-free) counts of a sensor with
    /// `counts_per_rev`, for the follower rotation `angle` (rad): gain error, quantization to
    /// `encoder_resolution` and noise applied. The caller wraps it as the sensor does.
    pub fn rotary_counts(&mut self, angle: f64, counts_per_rev: f64) -> i64 {
        let turns = angle / TAU * (1.0 + self.cfg.gain_error);
        let turns = match self.cfg.encoder_resolution {
            Some(res) => (turns * res).round() / res,
            None => turns,
        };
        let noise = self.gaussian() * self.cfg.encoder_noise_counts;
        (turns * counts_per_rev + noise).round() as i64
    }

    /// A linear encoder reading in counts of `mm_per_count` for a height in model units.
    pub fn linear_counts(&mut self, height: f64, mm_per_count: f64) -> i64 {
        let mm = height * self.cfg.scale_mm * (1.0 + self.cfg.gain_error);
        let noise = self.gaussian() * self.cfg.encoder_noise_counts;
        (mm / mm_per_count + noise).round() as i64
    }

    /// The IMU's orientation reading for a follower rotation: bias, then noise (a rotation
    /// about a random axis by a Gaussian angle).
    pub fn imu_reading(&mut self, rotation: UnitQuaternion<f64>) -> UnitQuaternion<f64> {
        let mut q = self.imu_bias * rotation;
        if self.cfg.imu_noise_deg > 0.0 {
            let axis = Vector3::new(self.gaussian(), self.gaussian(), self.gaussian());
            if let Some(axis) = nalgebra::Unit::try_new(axis, 1e-12) {
                let angle = self.gaussian() * self.cfg.imu_noise_deg.to_radians();
                q = UnitQuaternion::from_axis_angle(&axis, angle) * q;
            }
        }
        q
    }

    /// Pass one byte to the host through the faulty link.
    pub fn link_byte(&mut self, byte: u8) -> LinkByte {
        let l = &self.cfg.link;
        if l.drop_prob > 0.0 && self.link_rng.random::<f64>() < l.drop_prob {
            return LinkByte::Dropped;
        }
        if l.corrupt_prob > 0.0 && self.link_rng.random::<f64>() < l.corrupt_prob {
            let bit = self.link_rng.random_range(0..8);
            return LinkByte::Corrupted(byte ^ (1 << bit));
        }
        LinkByte::Pass(byte)
    }

    /// A standard normal variate (Box–Muller).
    fn gaussian(&mut self) -> f64 {
        let u1: f64 = self.sensor_rng.random::<f64>().max(f64::MIN_POSITIVE);
        let u2: f64 = self.sensor_rng.random();
        (-2.0 * u1.ln()).sqrt() * (TAU * u2).cos()
    }
}

impl PlantLaw for crate::motion::Motion {
    fn follower_at(&self, t: f64) -> FollowerState {
        FollowerState {
            angle_z: self.angle_z(t).map_or(0.0, |a| a[0]),
            height: self.height(t).map_or(0.0, |h| h[0]),
            rotation: self.sample(t).rotation,
        }
    }
}

/// A closed-form 1R law for tests and benchmarks: the follower turns one full turn per
/// period, `θ(t) = 2π·t + a·sin(2π·t)` (monotone for |a| < 1).
#[derive(Debug, Clone, Copy)]
pub struct WobbleTurn {
    /// Amplitude of the sinusoidal deviation from uniform rotation, rad.
    pub amplitude: f64,
}

impl PlantLaw for WobbleTurn {
    fn follower_at(&self, t: f64) -> FollowerState {
        let a = TAU * t + self.amplitude * (TAU * t).sin();
        FollowerState {
            angle_z: a,
            height: 0.0,
            rotation: UnitQuaternion::from_axis_angle(&Vector3::z_axis(), a),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const LAW: WobbleTurn = WobbleTurn { amplitude: 0.3 };

    /// Guards: without faults the plant is exactly the target law.
    #[test]
    fn ideal_plant_follows_target_law() {
        let mut p = Plant::new(LAW, PlantConfig::default());
        for i in 0..100 {
            let phi = i as f64 * 0.1;
            assert_eq!(p.follower(phi), LAW.follower_at(phi / TAU));
        }
    }

    /// Guards: backlash makes forward and reverse readings differ by the gap.
    #[test]
    fn backlash_shows_as_hysteresis() {
        let cfg = PlantConfig::from_faults(&["backlash_deg=2"]).unwrap();
        let mut p = Plant::new(WobbleTurn { amplitude: 0.0 }, cfg);
        let mut fwd = 0.0;
        for i in 0..=360 {
            fwd = p.follower(f64::from(i).to_radians()).angle_z;
        }
        assert!((fwd.to_degrees() - 359.0).abs() < 1e-9);
        // Reverse: nothing moves for the first 2°, then the follower trails by 1° the
        // other way.
        let back1 = p.follower(359.0_f64.to_radians()).angle_z;
        assert!((back1 - fwd).abs() < 1e-12);
        let mut back = 0.0;
        for i in (180..=358).rev() {
            back = p.follower(f64::from(i).to_radians()).angle_z;
        }
        assert!((back.to_degrees() - 181.0).abs() < 1e-9);
    }

    /// Guards: phase lag shifts the follower by the lag angle.
    #[test]
    fn phase_lag_shifts() {
        let cfg = PlantConfig::from_faults(&["phase_lag_deg=5"]).unwrap();
        let mut p = Plant::new(LAW, cfg);
        let s = p.follower(1.0);
        assert_eq!(s, LAW.follower_at((1.0 - 5f64.to_radians()) / TAU));
    }

    /// Guards: quantization and gain error in encoder counts.
    #[test]
    fn encoder_gain_and_quantization() {
        let cfg = PlantConfig::from_faults(&["gain_error=0.01", "encoder_resolution=360"]).unwrap();
        let mut p = Plant::new(LAW, cfg);
        // 90.4° × 1.01 = 91.304° → quantized to 91° of 360 → 91/360·4096 = 1035.4 → 1035.
        assert_eq!(p.rotary_counts(90.4f64.to_radians(), 4096.0), 1035);
    }

    /// Guards: noise is seeded — two plants with one seed agree, other seeds differ.
    #[test]
    fn noise_is_reproducible_by_seed() {
        let run = |seed: u64| {
            let mut cfg =
                PlantConfig::from_faults(&["encoder_noise_counts=3", "drop_prob=0.2"]).unwrap();
            cfg.seed = seed;
            let mut p = Plant::new(LAW, cfg);
            (0..200)
                .map(|i| {
                    (
                        p.rotary_counts(f64::from(i) * 0.01, 4096.0),
                        p.link_byte(i as u8),
                    )
                })
                .collect::<Vec<_>>()
        };
        assert_eq!(run(7), run(7));
        assert_ne!(run(7), run(8));
        // The noise has roughly the asked-for spread.
        let cfg = PlantConfig::from_faults(&["encoder_noise_counts=3"]).unwrap();
        let mut p = Plant::new(LAW, cfg);
        let xs: Vec<f64> = (0..4000)
            .map(|_| p.rotary_counts(0.0, 4096.0) as f64)
            .collect();
        let sd = (xs.iter().map(|x| x * x).sum::<f64>() / xs.len() as f64).sqrt();
        assert!((sd - 3.0).abs() < 0.3, "{sd}");
    }

    /// Guards: IMU bias is a fixed rotation of the given angle.
    #[test]
    fn imu_bias_angle() {
        let cfg = PlantConfig::from_faults(&["imu_bias_deg=2"]).unwrap();
        let mut p = Plant::new(LAW, cfg);
        let q = UnitQuaternion::from_euler_angles(0.1, 0.2, 0.3);
        let r = p.imu_reading(q);
        assert!((r.angle_to(&q).to_degrees() - 2.0).abs() < 1e-9);
    }

    /// Guards one set of fault keys for every command (issue 20: `backlash=2` worked for
    /// `demo` only, and a bad value there was echoed as `backlash_deg=abc`): the short
    /// names are the plant's own, and an error repeats the option as the user typed it.
    #[test]
    fn short_fault_names_everywhere_and_errors_as_typed() {
        for (short, long) in FAULT_ALIASES {
            assert!(FAULT_KEYS.iter().any(|(k, _)| k == long), "{long}");
            let a = PlantConfig::from_faults(&[format!("{short}=0.5")]).unwrap();
            let b = PlantConfig::from_faults(&[format!("{long}=0.5")]).unwrap();
            assert_eq!(format!("{a:?}"), format!("{b:?}"), "{short}");
        }
        assert_eq!(
            PlantConfig::from_faults(&["backlash=abc"])
                .unwrap_err()
                .to_string(),
            "--fault `backlash=abc`: `abc` is not a number"
        );
    }

    /// Guards: bad `--fault` options are rejected with the key named.
    #[test]
    fn bad_faults_are_rejected() {
        for bad in [
            "backlash",
            "backlash_deg=-1",
            "drop_prob=2",
            "wobble=1",
            "seed=x",
            "backlash=abc",
        ] {
            let err = PlantConfig::from_faults(&[bad]).unwrap_err().to_string();
            assert!(err.contains(bad), "{err}");
        }
        let cfg = PlantConfig::from_faults(&["dropout_at_s=2", "protocol_version=9"]).unwrap();
        assert_eq!(cfg.link.dropout_at_s, Some(2.0));
        assert_eq!(cfg.link.dropout_s, DEFAULT_DROPOUT_S);
        assert_eq!(cfg.link.protocol_version, Some(9));
        let cfg = PlantConfig::from_faults(&["stall_at_s=1.5"]).unwrap();
        assert_eq!(cfg.link.stall_at_s, Some(1.5));
        assert_eq!(cfg.link.stall_s, DEFAULT_STALL_S);
        let err = PlantConfig::from_faults(&["stall_s=-0.1"]).unwrap_err();
        assert!(err.to_string().contains("stall_s"), "{err}");
        let cfg = PlantConfig::from_faults(&["reboot_at_s=2.5"]).unwrap();
        assert_eq!(cfg.link.reboot_at_s, Some(2.5));
        let err = PlantConfig::from_faults(&["reboot_at_s=-1"]).unwrap_err();
        assert!(err.to_string().contains("reboot_at_s"), "{err}");
    }

    /// Guards: missed steps happen at about the configured rate.
    #[test]
    fn missed_step_rate() {
        let cfg = PlantConfig::from_faults(&["missed_step_prob=0.01"]).unwrap();
        let mut p = Plant::new(LAW, cfg);
        let n = (0..100_000).filter(|_| p.step_missed()).count();
        assert!((800..1200).contains(&n), "{n}");
    }

    /// Guards the geometry plant: with the same free interval everywhere, a follower
    /// driven forward lags the target by the free turn behind it and, driven back, leads
    /// by the one ahead, as the built parts would leave it under a drag; backlash-free
    /// otherwise (the target law itself where the interval is zero).
    #[test]
    fn the_geometry_plant_leaves_a_dragged_follower_at_the_edge_of_its_play() {
        let table = PlayTable::new(vec![0.02; 8], vec![0.03; 8], Load::Drag);
        let cfg = PlantConfig {
            play: Some(std::sync::Arc::new(table)),
            ..PlantConfig::default()
        };
        let mut plant = Plant::new(LAW, cfg);
        let mut phi = 0.0;
        for _ in 0..2000 {
            phi += 0.005;
            plant.follower(phi);
        }
        let lag = plant.follower(phi).angle_z - plant.ideal(phi).angle_z;
        assert!((lag + 0.03).abs() < 1e-9, "forward: {lag}");
        for _ in 0..2000 {
            phi -= 0.005;
            plant.follower(phi);
        }
        let lead = plant.follower(phi).angle_z - plant.ideal(phi).angle_z;
        assert!((lead - 0.02).abs() < 1e-9, "reverse: {lead}");
        let r = plant.follower(phi).rotation;
        let z = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), plant.follower(phi).angle_z);
        assert!(r.angle_to(&z) < 1e-9, "the rotation turns with the angle");
    }

    /// Guards the 1R1T geometry plant: with the same free region everywhere (a regular
    /// octagon of 0.2 mm in the plane of the lever) and a target that screws at 45° in that
    /// plane, a follower driven forward rests in the region's corner behind the motion,
    /// turn and height together, and driven back in the corner ahead, as
    /// `predict::law::drag_plane` leaves it.
    #[test]
    fn the_geometry_plant_drags_a_1r1t_follower_through_its_free_region() {
        struct Screwing;
        impl PlantLaw for Screwing {
            fn follower_at(&self, t: f64) -> FollowerState {
                // Per radian of the driver: 0.1 rad of turn (3 mm at the 30 mm lever) and
                // 0.3 units of height (3 mm at 10 mm per unit).
                let a = 0.1 * TAU * t;
                FollowerState {
                    angle_z: a,
                    height: 0.3 * TAU * t,
                    rotation: UnitQuaternion::from_axis_angle(&Vector3::z_axis(), a),
                }
            }
        }
        let lever = crate::predict::SCREW_LEVER_MM;
        assert_eq!(lever, 30.0, "the law above is laid out for this lever");
        let table = PlayTable::with_regions(vec![0.0; 8], vec![0.0; 8], vec![[0.2; 8]; 8]);
        let cfg = PlantConfig {
            play: Some(std::sync::Arc::new(table)),
            scale_mm: 10.0,
            ..PlantConfig::default()
        };
        let mut plant = Plant::new(Screwing, cfg);
        let corner = 0.2 * std::f64::consts::FRAC_1_SQRT_2;
        let mut phi = 0.0;
        for _ in 0..200 {
            phi += 0.01;
            plant.follower(phi);
        }
        let (got, want) = (plant.follower(phi), plant.ideal(phi));
        assert!(((got.angle_z - want.angle_z) * lever + corner).abs() < 1e-9);
        assert!(((got.height - want.height) * 10.0 + corner).abs() < 1e-9);
        for _ in 0..200 {
            phi -= 0.01;
            plant.follower(phi);
        }
        let (got, want) = (plant.follower(phi), plant.ideal(phi));
        assert!(((got.angle_z - want.angle_z) * lever - corner).abs() < 1e-9);
        assert!(((got.height - want.height) * 10.0 - corner).abs() < 1e-9);
    }

    /// Guards the geometry plant under the other loads a prediction can be made with (issue
    /// 15: it applied a drag whatever the load): a torque holds the follower against the
    /// side of its play it pushes to whichever way the driver turns, and a spring leaves it
    /// at the point of its free interval nearest the rest angle.
    #[test]
    fn the_geometry_plant_applies_the_predictions_load() {
        // Driver angle 2 rad (within the first period), reached forward or after 1 rad
        // forward and back: the follower's deviation from the target there.
        let deviation = |load: Load, back: bool| {
            let cfg = PlantConfig {
                play: Some(std::sync::Arc::new(PlayTable::new(
                    vec![0.02; 8],
                    vec![0.03; 8],
                    load,
                ))),
                ..PlantConfig::default()
            };
            let mut plant = Plant::new(LAW, cfg);
            let steps = if back { 600 } else { 400 };
            for k in 0..=steps {
                let at = if k <= 600 && back && k > 400 {
                    0.005 * (800 - k) as f64
                } else {
                    0.005 * k as f64
                };
                plant.follower(at);
            }
            plant.follower(2.0).angle_z - plant.ideal(2.0).angle_z
        };
        for back in [false, true] {
            let up = deviation(Load::Torque(1.0), back);
            assert!((up - 0.02).abs() < 1e-9, "torque+ (back {back}): {up}");
            let down = deviation(Load::Torque(-1.0), back);
            assert!((down + 0.03).abs() < 1e-9, "torque- (back {back}): {down}");
        }
        // A rest angle far below or above every target angle pulls the follower to that
        // edge of its play; one just beside the target, to it.
        let pulled = deviation(Load::Spring(-1000.0), false);
        assert!((pulled + 0.03).abs() < 1e-9, "spring far below: {pulled}");
        let pulled = deviation(Load::Spring(1000.0), false);
        assert!((pulled - 0.02).abs() < 1e-9, "spring far above: {pulled}");
        let target = Plant::new(LAW, PlantConfig::default()).ideal(2.0).angle_z;
        let near = deviation(Load::Spring((target + 0.01).to_degrees()), false);
        assert!(
            (near - 0.01).abs() < 1e-9,
            "spring beside the target: {near}"
        );
    }
}
