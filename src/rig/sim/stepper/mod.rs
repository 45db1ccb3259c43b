//! The simulated stepper bench: the real firmware core (`mpc-firmware-core`) and wire
//! protocol behind a pseudo-terminal, with emulated pins and I²C sensors fed by the plant.

pub mod i2c;
pub mod pins;
