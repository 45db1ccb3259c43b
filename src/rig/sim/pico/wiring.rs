//! How the emulated bench is wired to the Pico: which GPIO goes to which driver input,
//! which pins carry which sensor bus, where the quadrature encoder and the e-stop button
//! are connected.
//!
//! This is the bench as `firmware/README.md` ("Pin map") tells a builder to wire it, written
//! down independently of the board crate on purpose: the board crate's own pin assignment is
//! what running its image here checks. A firmware that pulses STEP on another GPIO moves
//! nothing; one that routes a sensor bus to other pins finds no sensor there.
//!
//! It owns the wiring only: what a level or a transfer does is [`super`]'s.

/// GPIO of the driver's STEP input.
pub const STEP: u8 = 10;
/// GPIO of the driver's DIR input.
pub const DIR: u8 = 11;
/// GPIO of the driver's EN input (active low).
pub const ENABLE: u8 = 12;
/// GPIO of the e-stop button: a normally closed contact to ground, so the pin reads low
/// while the button is released and the loop intact.
pub const ESTOP: u8 = 13;
/// GPIO of the quadrature encoder's channel A.
pub const QUADRATURE_A: u8 = 14;
/// GPIO of the quadrature encoder's channel B.
pub const QUADRATURE_B: u8 = 15;

/// SDA and SCL GPIOs of sensor bus A (AS5600 A and the BNO055).
pub const BUS_A_PINS: (u8, u8) = (4, 5);
/// SDA and SCL GPIOs of sensor bus B (AS5600 B).
pub const BUS_B_PINS: (u8, u8) = (6, 7);

/// A driver input the firmware drives.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DriverInput {
    /// STEP.
    Step,
    /// DIR.
    Dir,
    /// EN.
    Enable,
}

/// The driver input wired to `gpio`, if any.
pub fn driver_input(gpio: u8) -> Option<DriverInput> {
    match gpio {
        STEP => Some(DriverInput::Step),
        DIR => Some(DriverInput::Dir),
        ENABLE => Some(DriverInput::Enable),
        _ => None,
    }
}

/// One of the bench's two sensor buses.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SensorBusId {
    /// Bus A.
    A,
    /// Bus B.
    B,
}

/// The sensor bus a controller reaches when its SDA and SCL are routed to these GPIOs:
/// both lines must land on the bus's pins.
pub fn bus_on_pins(sda: u8, scl: u8) -> Option<SensorBusId> {
    if (sda, scl) == BUS_A_PINS {
        Some(SensorBusId::A)
    } else if (sda, scl) == BUS_B_PINS {
        Some(SensorBusId::B)
    } else {
        None
    }
}

/// Levels of the quadrature channels (A, B) at `count` edges: the Gray sequence
/// 00 → 01 → 11 → 10 counts up, as the firmware's decoder reads it.
pub fn quadrature_channels(count: i64) -> (bool, bool) {
    match count.rem_euclid(4) {
        0 => (false, false),
        1 => (false, true),
        2 => (true, true),
        _ => (true, false),
    }
}

/// The input changes that take the encoder from `from` to `to` counts, one edge at a time
/// (each step changes one channel), as `(gpio, level)`.
pub fn quadrature_edges(from: i64, to: i64) -> Vec<(u8, bool)> {
    let step = if to >= from { 1 } else { -1 };
    let mut out = Vec::with_capacity(from.abs_diff(to) as usize);
    let mut c = from;
    while c != to {
        let (a0, b0) = quadrature_channels(c);
        c += step;
        let (a1, b1) = quadrature_channels(c);
        if a0 != a1 {
            out.push((QUADRATURE_A, a1));
        }
        if b0 != b1 {
            out.push((QUADRATURE_B, b1));
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use mpc_firmware_core::sensors::quadrature::QuadratureDecoder;
    use mpc_firmware_core::QuadratureCounter;

    /// Guards that the edges generated here count the same way in the firmware's own
    /// decoder, both directions, one channel per edge (no decoding errors).
    #[test]
    fn quadrature_edges_decode_to_the_count() {
        let (a, b) = quadrature_channels(0);
        let mut dec = QuadratureDecoder::new(a, b);
        let (mut la, mut lb) = (a, b);
        let mut count = 0;
        for target in [7i64, -5, 12, 12, 0] {
            for (gpio, level) in quadrature_edges(count, target) {
                if gpio == QUADRATURE_A {
                    la = level;
                } else {
                    lb = level;
                }
                dec.update(la, lb);
            }
            count = target;
            assert_eq!(i64::from(dec.count()), target);
        }
        assert_eq!(dec.errors(), 0);
    }

    /// Guards the bus routing: a bus is reached only with both lines on its pins.
    #[test]
    fn buses_need_both_lines() {
        assert_eq!(bus_on_pins(4, 5), Some(SensorBusId::A));
        assert_eq!(bus_on_pins(6, 7), Some(SensorBusId::B));
        assert_eq!(bus_on_pins(4, 7), None);
        assert_eq!(bus_on_pins(8, 9), None);
    }
}
