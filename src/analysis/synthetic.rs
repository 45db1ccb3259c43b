//! Synthetic measured runs with known, injected imperfections: the ground truth that the
//! analysis tests and the benchmark check the estimators against.
//!
//! A [`SyntheticBench`] turns the driver at constant speed through settle, forward and
//! optional reverse cycles and produces the follower pose that an *actual* law (which may
//! differ from the target, e.g. a timing distortion) would give, then applies a
//! driver-angle offset, a time lag, a backlash dead band (a play model: the follower is
//! dragged only once the driver side has moved β/2 past it), a sensor offset, Gaussian noise,
//! quantization and randomly dropped samples, all from a seeded ChaCha RNG. It models no
//! device or protocol; the simulated benches in [`crate::rig`] do that.

use nalgebra::{UnitQuaternion, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::run::{MeasuredRun, Phase, Resolution};
use super::target::TargetLaw;

/// Imperfections and session settings of a synthetic run.
#[derive(Debug, Clone, PartialEq)]
pub struct SyntheticBench {
    /// Sample rate.
    pub rate_hz: f64,
    /// Driver speed in revolutions per minute.
    pub speed_rpm: f64,
    /// Settle cycles before measuring (excluded from metrics).
    pub settle_cycles: f64,
    /// Forward cycles.
    pub forward_cycles: f64,
    /// Reverse cycles after the forward ones (0 for none).
    pub reverse_cycles: f64,
    /// Constant driver-angle offset δ₀ (follower behaves as if the driver were δ₀ behind).
    pub driver_offset_deg: f64,
    /// Time lag of the follower behind the driver.
    pub lag_s: f64,
    /// Follower-side dead band width (follower units: degrees for rz and per axis for 3R, mm
    /// for tz).
    pub backlash: f64,
    /// Driver-side dead band width in driver degrees (the rig plant's `backlash`).
    pub driver_backlash_deg: f64,
    /// Constant sensor offset added to rz (degrees).
    pub rz_offset_deg: f64,
    /// Constant sensor offset added to tz (mm).
    pub tz_offset_mm: f64,
    /// Gaussian noise standard deviation on rz (degrees) / tz (mm) / each rotation axis (deg).
    pub noise: f64,
    /// Quantization step of rz (degrees) and tz (mm); 0 for none.
    pub quantum: f64,
    /// 3R: world-frame offset (IMU heading) left-multiplied onto the measurement.
    pub world_offset: UnitQuaternion<f64>,
    /// 3R: mounting offset right-multiplied onto the measurement.
    pub mount_offset: UnitQuaternion<f64>,
    /// Probability that a sample is dropped (a gap in the stream).
    pub drop_probability: f64,
    /// RNG seed.
    pub seed: u64,
}

impl Default for SyntheticBench {
    fn default() -> Self {
        Self {
            rate_hz: 1000.0,
            speed_rpm: 10.0,
            settle_cycles: 1.0,
            forward_cycles: 3.0,
            reverse_cycles: 0.0,
            driver_offset_deg: 0.0,
            lag_s: 0.0,
            backlash: 0.0,
            driver_backlash_deg: 0.0,
            rz_offset_deg: 0.0,
            tz_offset_mm: 0.0,
            noise: 0.0,
            quantum: 0.0,
            world_offset: UnitQuaternion::identity(),
            mount_offset: UnitQuaternion::identity(),
            drop_probability: 0.0,
            seed: 1,
        }
    }
}

fn gauss(rng: &mut ChaCha8Rng) -> f64 {
    // Box–Muller; u1 in (0, 1].
    let u1: f64 = 1.0 - rng.random::<f64>();
    let u2: f64 = rng.random::<f64>();
    (-2.0 * u1.ln()).sqrt() * (2.0 * std::f64::consts::PI * u2).cos()
}

fn play(pos: &mut f64, driven: f64, half: f64) -> f64 {
    if driven - *pos > half {
        *pos = driven - half;
    } else if driven - *pos < -half {
        *pos = driven + half;
    }
    *pos
}

impl SyntheticBench {
    /// Generate the run that `actual` (the law the built mechanism really follows) produces
    /// on this bench. The measured DOFs are those of `actual`.
    pub fn generate(&self, actual: &TargetLaw) -> MeasuredRun {
        let mut rng = ChaCha8Rng::seed_from_u64(self.seed);
        let omega = self.speed_rpm * 6.0; // deg/s
        let settle_s = self.settle_cycles * 360.0 / omega;
        let fwd_s = self.forward_cycles * 360.0 / omega;
        let rev_s = self.reverse_cycles * 360.0 / omega;
        let total = settle_s + fwd_s + rev_s;
        let n = (total * self.rate_hz).floor() as usize + 1;
        let mut run = MeasuredRun {
            time_s: Vec::with_capacity(n),
            phase: Vec::with_capacity(n),
            driver_deg: Vec::with_capacity(n),
            rz_deg: actual.rz_deg.as_ref().map(|_| Vec::with_capacity(n)),
            tz_mm: actual.tz_mm.as_ref().map(|_| Vec::with_capacity(n)),
            rotation: actual.rotation.as_ref().map(|_| Vec::with_capacity(n)),
            ramping: Vec::new(),
            resolution: Resolution {
                rz_deg: self.quantum,
                tz_mm: self.quantum,
            },
        };
        let half = self.backlash / 2.0;
        let driver_at = |t: f64| {
            if t <= settle_s + fwd_s {
                omega * t
            } else {
                omega * (settle_s + fwd_s) - omega * (t - settle_s - fwd_s)
            }
        };
        let quant = |v: f64| {
            if self.quantum > 0.0 {
                (v / self.quantum).round() * self.quantum
            } else {
                v
            }
        };
        let start_phi = -self.driver_offset_deg - self.driver_backlash_deg / 2.0;
        let mut driver_input = start_phi + self.driver_offset_deg;
        let mut pos_rz = actual.rz_deg.as_ref().map_or(0.0, |t| t.value(start_phi));
        let mut pos_tz = actual.tz_mm.as_ref().map_or(0.0, |t| t.value(start_phi));
        let mut pos_rot = actual
            .rotation
            .as_ref()
            .map_or(UnitQuaternion::identity(), |r| r.eval(start_phi));
        for i in 0..n {
            let t = i as f64 / self.rate_hz;
            let phase = if t < settle_s {
                Phase::Settle
            } else if t <= settle_s + fwd_s {
                Phase::Forward
            } else {
                Phase::Reverse
            };
            let phi = driver_at(t);
            // The follower responds to where the driver was lag_s ago.
            let lagged = driver_at((t - self.lag_s).max(0.0));
            let phi_eff = play(&mut driver_input, lagged, self.driver_backlash_deg / 2.0)
                - self.driver_offset_deg;
            let keep = self.drop_probability <= 0.0 || rng.random::<f64>() >= self.drop_probability;
            if let Some(table) = &actual.rz_deg {
                let v = play(&mut pos_rz, table.value(phi_eff), half);
                let noisy = quant(v + self.rz_offset_deg + self.noise * gauss(&mut rng));
                if keep {
                    run.rz_deg
                        .as_mut()
                        .expect("allocated with the law")
                        .push(noisy);
                }
            }
            if let Some(table) = &actual.tz_mm {
                let v = play(&mut pos_tz, table.value(phi_eff), half);
                let noisy = quant(v + self.tz_offset_mm + self.noise * gauss(&mut rng));
                if keep {
                    run.tz_mm
                        .as_mut()
                        .expect("allocated with the law")
                        .push(noisy);
                }
            }
            if let Some(r) = &actual.rotation {
                let driven = r.eval(phi_eff);
                // Dead band on SO(3): the follower stays until the driven pose is more than
                // half the backlash away, then is dragged along the geodesic.
                let diff = pos_rot.inverse() * driven;
                let ang = diff.angle().to_degrees();
                if ang > half {
                    let keep_frac = if ang > 0.0 { (ang - half) / ang } else { 1.0 };
                    pos_rot *= UnitQuaternion::from_scaled_axis(diff.scaled_axis() * keep_frac);
                }
                let noise = Vector3::new(gauss(&mut rng), gauss(&mut rng), gauss(&mut rng))
                    * self.noise.to_radians();
                let m = self.world_offset
                    * UnitQuaternion::from_scaled_axis(noise)
                    * pos_rot
                    * self.mount_offset;
                if keep {
                    run.rotation
                        .as_mut()
                        .expect("allocated with the law")
                        .push(m);
                }
            }
            if keep {
                run.time_s.push(t);
                run.phase.push(phase);
                run.driver_deg.push(phi);
            }
        }
        run
    }
}

/// The paper's half-turn law as a piecewise-linear 1R target: the follower turns 0→180° in
/// the first `first_fraction` of the period and 180→360° in the rest. `first_fraction` = 2/3
/// is the 2:1 law of Fig. 11.
pub fn piecewise_half_turn(first_fraction: f64) -> TargetLaw {
    TargetLaw::rotation_1r("half-turn-piecewise", move |t| {
        if t <= first_fraction {
            180.0 * t / first_fraction
        } else {
            180.0 + 180.0 * (t - first_fraction) / (1.0 - first_fraction)
        }
    })
}

/// A smooth, monotone 1R law with one full turn per period and a strongly varying speed
/// (θ(t) = 360·t + 40·sin 2πt degrees, slope 0.30–1.70 follower degrees per driver degree).
pub fn smooth_turn() -> TargetLaw {
    TargetLaw::rotation_1r("smooth-turn", |t| {
        360.0 * t + 40.0 * (2.0 * std::f64::consts::PI * t).sin()
    })
}

/// Write `run` as a recording directory for `rig`, converting physical values back into the
/// raw readings the rig's sensors would give (encoder counts wrapped like an AS5600 or a
/// Dynamixel position, IMU quaternions before the mounting rotation). Used by tests and the
/// benchmark to exercise the real loader. Sensors without a matching measured DOF get 0.
pub fn write_recording(
    run: &MeasuredRun,
    rig: crate::rig::config::RigConfig,
    target: crate::rig::recording::TargetRef,
    dir: &std::path::Path,
) -> Result<crate::rig::recording::RecordingMeta, crate::rig::recording::RecordingError> {
    use crate::rig::config::{Dof as RigDof, SensorConfig};
    use crate::rig::recording::{
        Claim, DeviceInfo, Existing, Phase as RecPhase, RecordingMeta, RecordingWriter, Row,
        SessionInfo,
    };
    let session = SessionInfo {
        speed_rpm: 0.0,
        cycles: 0,
        settle_cycles: 0,
        reverse: run.phase.contains(&Phase::Reverse),
        // The run's own rate (the rig's may differ), so the writer's hole counts are right.
        sample_rate_hz: {
            let periods: Vec<f64> = run.time_s.windows(2).map(|w| w[1] - w[0]).collect();
            super::sampling::median(&periods)
                .filter(|p| *p > 0.0)
                .map_or(rig.sampling.rate_hz, |p| 1.0 / p)
        },
    };
    let device = DeviceInfo {
        backend: "synthetic".into(),
        ..Default::default()
    };
    let sensors = rig.sensors.clone();
    let meta = RecordingMeta::new(rig, device, target, session);
    let mut w = RecordingWriter::create(Claim::folder(dir, Existing::Refuse)?, meta)?;
    let mut values: Vec<f64> = Vec::new();
    for i in 0..run.len() {
        values.clear();
        for s in &sensors {
            match s {
                SensorConfig::Imu(imu) => {
                    let r = run
                        .rotation
                        .as_ref()
                        .map_or(UnitQuaternion::identity(), |v| v[i]);
                    let q = r * imu.mounting_rotation();
                    values.extend([q.w, q.i, q.j, q.k]);
                }
                SensorConfig::As5600(e) | SensorConfig::Quadrature(e) => {
                    let (phys, scale) = match e.dof {
                        RigDof::Rz => (
                            run.rz_deg.as_ref().map_or(0.0, |v| v[i]),
                            s.counts_per_rev().unwrap_or(4096.0) / 360.0,
                        ),
                        RigDof::Tz => (
                            run.tz_mm.as_ref().map_or(0.0, |v| v[i]),
                            1.0 / e.mm_per_count.unwrap_or(1.0),
                        ),
                    };
                    let mut counts = (phys * scale * f64::from(e.sign) + e.zero_offset).round();
                    if matches!(s, SensorConfig::As5600(_)) && e.dof == RigDof::Rz {
                        counts = counts.rem_euclid(s.counts_per_rev().unwrap_or(4096.0));
                    }
                    values.push(counts);
                }
                SensorConfig::Dynamixel(d) => {
                    let phys = run.rz_deg.as_ref().map_or(0.0, |v| v[i]);
                    let counts = (phys / 360.0 * d.counts_per_rev * f64::from(d.sign)
                        + d.zero_offset)
                        .round();
                    values.push(counts);
                }
            }
        }
        w.push(&Row {
            device_time_us: (run.time_s[i] * 1e6).round() as u64,
            host_time_s: run.time_s[i],
            phase: match run.phase[i] {
                Phase::Settle => RecPhase::Settle,
                Phase::Forward => RecPhase::Forward,
                Phase::Reverse => RecPhase::Reverse,
            },
            driver_angle_deg: run.driver_deg[i],
            values: &values,
            flags: 0,
        })?;
    }
    w.finish(true, "synthetic run complete")
}
