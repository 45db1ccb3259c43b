//! Which bench hardware the parts are made for: the motor coupling on the driver and what
//! reads the follower.
//!
//! Owns [`Bench`], chosen from a rig file (`--rig`) or, by default, the simulated stepper
//! bench of the class (`rigs/sim-stepper.toml`, `sim-stepper-1r1t.toml`,
//! `sim-stepper-imu.toml`: a NEMA 17 stepper, an AS5600 on the follower's axis, a
//! quadrature linear encoder for 1R1T, a BNO055 for 3R). It refuses a rig that cannot
//! measure the mechanism's class. It does not shape anything.

use std::fmt;

use crate::rig::config::{Dof, DriverConfig, RigConfig, SensorConfig};
use crate::synth::closure::Class;

use super::BuildError;

/// How the motor turns the driver.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Coupling {
    /// A NEMA 17 stepper's 5 mm D-shaft in a D-bore of the driver's hub; the motor hangs
    /// under the base plate on its four M3 screws.
    Nema17,
    /// A Dynamixel X430 servo's horn bolted to the hub (8 × M2); the servo sits under the
    /// base plate.
    Xl430Horn,
}

/// What measures the follower's rotation.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Reading {
    /// An AS5600 above a diametric magnet seated on the follower's axis.
    As5600,
    /// A second servo (torque off) whose horn is bolted to the follower's hub.
    ServoHorn,
    /// A BNO055 board on a pad of the follower (3R).
    Imu,
}

/// The bench the parts are made for.
#[derive(Clone, Debug, PartialEq)]
pub struct Bench {
    /// Name (the rig's, or the default's).
    pub name: String,
    /// Motor coupling.
    pub coupling: Coupling,
    /// Rotation reading.
    pub reading: Reading,
    /// A linear encoder reads the follower's translation (1R1T).
    pub linear_encoder: bool,
}

impl fmt::Display for Bench {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let c = match self.coupling {
            Coupling::Nema17 => "NEMA 17 stepper (5 mm D-shaft)",
            Coupling::Xl430Horn => "Dynamixel X430 horn (8 × M2)",
        };
        let r = match self.reading {
            Reading::As5600 => "AS5600 over a 6 × 2.5 mm magnet",
            Reading::ServoHorn => "follower servo horn",
            Reading::Imu => "BNO055 pad",
        };
        write!(
            f,
            "{}: {c}; {r}{}",
            self.name,
            if self.linear_encoder {
                "; plunger linear encoder"
            } else {
                ""
            }
        )
    }
}

impl Bench {
    /// The simulated stepper bench `demo` and CI use for `class`.
    pub fn default_for(class: Class) -> Bench {
        let (name, reading, linear) = match class {
            Class::R1 => ("sim-stepper", Reading::As5600, false),
            Class::R1T1 => ("sim-stepper-1r1t", Reading::As5600, true),
            Class::R3 => ("sim-stepper-imu", Reading::Imu, false),
        };
        Bench {
            name: name.into(),
            coupling: Coupling::Nema17,
            reading,
            linear_encoder: linear,
        }
    }

    /// The bench a rig file describes, for a mechanism of `class`.
    pub fn from_rig(rig: &RigConfig, class: Class) -> Result<Bench, BuildError> {
        let coupling = match rig.driver {
            DriverConfig::StepperFirmware(_) => Coupling::Nema17,
            DriverConfig::Dynamixel(_) => Coupling::Xl430Horn,
        };
        let mut reading = None;
        let mut linear = false;
        for s in &rig.sensors {
            match s {
                SensorConfig::As5600(e) | SensorConfig::Quadrature(e) => match e.dof {
                    Dof::Rz => reading = reading.or(Some(Reading::As5600)),
                    Dof::Tz => linear = true,
                },
                SensorConfig::Imu(_) => reading = Some(Reading::Imu),
                SensorConfig::Dynamixel(_) => reading = reading.or(Some(Reading::ServoHorn)),
            }
        }
        let refuse = |what: &str| BuildError::RigCannotMeasure {
            rig: rig.name.clone(),
            class,
            missing: what.to_string(),
        };
        let reading = match class {
            Class::R3 if reading != Some(Reading::Imu) => return Err(refuse("IMU")),
            Class::R1 | Class::R1T1 if reading.is_none() || reading == Some(Reading::Imu) => {
                return Err(refuse(
                    "rotation encoder about z (AS5600 or a follower servo)",
                ))
            }
            _ => reading.expect("checked above"),
        };
        if class == Class::R1T1 && !linear {
            return Err(refuse("linear encoder along z"));
        }
        Ok(Bench {
            name: rig.name.clone(),
            coupling,
            reading,
            linear_encoder: linear,
        })
    }
}
