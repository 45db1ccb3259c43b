//! Conversions between the rig configuration / host units and the wire protocol's.

use mpc_wire::{SampleFlags, SensorSet};

use crate::rig::config::{RigConfig, SensorConfig, StepperDriverConfig};
use crate::rig::recording::flags;
use crate::rig::RigError;

/// Largest numerator/denominator of the gear ratio sent to the firmware (u16 fields).
const GEAR_MAX: u64 = 65_535;

/// Tolerance of the rational approximation of a gear ratio: 1 ppm, far below any belt or
/// gear tolerance.
pub const GEAR_RATIO_TOLERANCE: f64 = 1e-6;

/// A gear ratio as `motor / output` with u16 terms (continued fractions).
pub fn gear_fraction(ratio: f64) -> Result<(u16, u16), RigError> {
    let (mut h0, mut h1, mut k0, mut k1) = (0u64, 1u64, 1u64, 0u64);
    let mut x = ratio;
    let mut best = None;
    for _ in 0..32 {
        let a = x.floor();
        if a > GEAR_MAX as f64 {
            break;
        }
        let a = a as u64;
        let (h2, k2) = (a * h1 + h0, a * k1 + k0);
        if h2 > GEAR_MAX || k2 > GEAR_MAX {
            break;
        }
        (h0, h1, k0, k1) = (h1, h2, k1, k2);
        best = Some((h1, k1));
        if ((h1 as f64 / k1 as f64) - ratio).abs() <= GEAR_RATIO_TOLERANCE * ratio {
            break;
        }
        let frac = x - a as f64;
        if frac.abs() < 1e-12 {
            break;
        }
        x = 1.0 / frac;
    }
    match best {
        Some((h, k)) if h > 0 && ((h as f64 / k as f64) - ratio).abs() <= 1e-4 * ratio => {
            Ok((h as u16, k as u16))
        }
        _ => Err(RigError::Setup(format!(
            "gear_ratio {ratio} cannot be expressed as a ratio of two numbers up to {GEAR_MAX}"
        ))),
    }
}

/// The firmware sensors a rig needs, and which wire field feeds each value column.
#[derive(Debug, Clone, PartialEq)]
pub struct SensorMap {
    /// Sensors to enable on the device.
    pub set: SensorSet,
    /// One entry per value column.
    pub fields: Vec<Field>,
    /// Whether an IMU column exists (to flag stale values).
    pub has_imu: bool,
}

/// Where a value column comes from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Field {
    /// AS5600 on channel 0.
    EncoderA,
    /// AS5600 on channel 1.
    EncoderB,
    /// Quadrature counter.
    Quadrature,
    /// IMU quaternion component 0..4 (w, x, y, z).
    Quat(usize),
}

impl SensorMap {
    /// Map the rig's sensors onto the firmware's fields; Dynamixel sensors are refused here
    /// (they belong to another backend).
    pub fn new(rig: &RigConfig) -> Result<SensorMap, RigError> {
        let mut set = SensorSet::EMPTY;
        let mut fields = Vec::new();
        let mut has_imu = false;
        for s in &rig.sensors {
            match s {
                SensorConfig::As5600(e) => {
                    let (f, bit) = if e.channel == 0 {
                        (Field::EncoderA, SensorSet::ENCODER_A)
                    } else {
                        (Field::EncoderB, SensorSet::ENCODER_B)
                    };
                    set = set | bit;
                    fields.push(f);
                }
                SensorConfig::Quadrature(_) => {
                    set = set | SensorSet::QUADRATURE;
                    fields.push(Field::Quadrature);
                }
                SensorConfig::Imu(_) => {
                    set = set | SensorSet::IMU;
                    has_imu = true;
                    fields.extend((0..4).map(Field::Quat));
                }
                SensorConfig::Dynamixel(d) => {
                    return Err(RigError::Setup(format!(
                        "sensor `{}` is a Dynamixel; the stepper-firmware backend reads only firmware sensors",
                        d.name
                    )))
                }
            }
        }
        Ok(SensorMap {
            set,
            fields,
            has_imu,
        })
    }

    /// Fill `out` with the value columns of one wire sample.
    pub fn values(&self, s: &mpc_wire::Sample, out: &mut Vec<f64>) {
        out.clear();
        let q = s.quaternion_f32();
        for f in &self.fields {
            out.push(match f {
                Field::EncoderA => f64::from(s.encoder_a),
                Field::EncoderB => f64::from(s.encoder_b),
                Field::Quadrature => f64::from(s.quadrature),
                Field::Quat(i) => f64::from(q[*i]),
            });
        }
    }

    /// Recording flags of one wire sample.
    pub fn flags(&self, f: SampleFlags) -> u32 {
        let mut out = 0;
        if self.has_imu && !f.contains(SampleFlags::IMU_FRESH) {
            out |= flags::IMU_STALE;
        }
        if f.contains(SampleFlags::ENCODER_A_FAULT)
            || f.contains(SampleFlags::ENCODER_B_FAULT)
            || f.contains(SampleFlags::IMU_FAULT)
        {
            out |= flags::SENSOR_ERROR;
        }
        if f.contains(SampleFlags::ESTOP) {
            out |= flags::ESTOP;
        }
        if f.contains(SampleFlags::OVERRUN) {
            out |= flags::LATE;
        }
        out
    }
}

/// Driver degrees → the firmware's millidegrees of output (direction applied on the host;
/// the firmware is configured with `reverse = false`).
pub fn deg_to_mdeg(cfg: &StepperDriverConfig, deg: f64) -> Result<i32, RigError> {
    let m = (f64::from(cfg.direction) * deg * 1000.0).round();
    if m.abs() > f64::from(i32::MAX) {
        return Err(RigError::Safety(format!(
            "{deg}° is beyond the firmware's range of ±{}°",
            i32::MAX / 1000
        )));
    }
    Ok(m as i32)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Guards: gear ratios become exact small fractions when they are, close ones otherwise.
    #[test]
    fn gear_fractions() {
        assert_eq!(gear_fraction(1.0).unwrap(), (1, 1));
        assert_eq!(gear_fraction(3.0).unwrap(), (3, 1));
        assert_eq!(gear_fraction(2.5).unwrap(), (5, 2));
        assert_eq!(gear_fraction(60.0 / 20.0).unwrap(), (3, 1));
        let (m, o) = gear_fraction(std::f64::consts::PI).unwrap();
        assert!((f64::from(m) / f64::from(o) - std::f64::consts::PI).abs() < 1e-6);
        assert!(gear_fraction(1e9).is_err());
    }
}
