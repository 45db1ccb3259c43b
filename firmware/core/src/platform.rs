//! What a board (or the host's simulated bench) hands the device logic: embedded-hal 1.0
//! buses and pins, a delay, a microsecond clock and a quadrature counter, bundled by the
//! [`Platform`] trait, plus the board's fixed facts ([`BoardConfig`]).
//!
//! Owns the injection points only; nothing here touches hardware. Two I²C buses: bus A
//! carries encoder A and the IMU, bus B encoder B (two AS5600 share the address 0x36, so they
//! need two buses or a mux; two buses keep the simulator simple). A board without a second
//! bus or a quadrature counter passes [`NoBus`] / [`NoQuadrature`].

use embedded_hal::delay::DelayNs;
use embedded_hal::digital::OutputPin;
use embedded_hal::i2c::{ErrorKind, ErrorType, I2c, Operation, SevenBitAddress};
use mpc_wire::SensorSet;

/// A monotonic microsecond clock: the device's own time base for steps and samples.
///
/// On the RP2040 it is the 1 MHz system timer; in the simulated bench a shared counter the
/// simulator advances. It must never go backwards.
pub trait Clock {
    /// Microseconds since an arbitrary origin (boot).
    fn now_us(&self) -> u64;
}

impl<C: Clock + ?Sized> Clock for &C {
    fn now_us(&self) -> u64 {
        (**self).now_us()
    }
}

/// A counter of quadrature-encoder edges (hardware counter, PIO program or an interrupt
/// running [`crate::sensors::quadrature::QuadratureDecoder`]).
pub trait QuadratureCounter {
    /// Signed edge count since boot (wrapping).
    fn count(&mut self) -> i32;
}

/// The types a platform provides. Implement it on a marker type.
pub trait Platform {
    /// I²C bus of encoder A and the IMU.
    type I2cA: I2c<SevenBitAddress>;
    /// I²C bus of encoder B.
    type I2cB: I2c<SevenBitAddress>;
    /// STEP output of the driver.
    type Step: OutputPin;
    /// DIR output of the driver.
    type Dir: OutputPin;
    /// EN output of the driver.
    type Enable: OutputPin;
    /// Short blocking delays (step pulse width, sensor start-up).
    type Delay: DelayNs;
    /// The microsecond clock.
    type Clock: Clock;
    /// The quadrature counter.
    type Quadrature: QuadratureCounter;
}

/// The parts of a platform, moved into [`crate::Device::new`].
pub struct Parts<P: Platform> {
    /// Bus of encoder A and the IMU.
    pub i2c_a: P::I2cA,
    /// Bus of encoder B.
    pub i2c_b: P::I2cB,
    /// STEP pin.
    pub step: P::Step,
    /// DIR pin.
    pub dir: P::Dir,
    /// EN pin.
    pub enable: P::Enable,
    /// Delay provider.
    pub delay: P::Delay,
    /// Clock.
    pub clock: P::Clock,
    /// Quadrature counter.
    pub quadrature: P::Quadrature,
}

/// Fixed facts of a board, announced in the handshake.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct BoardConfig {
    /// Board name (≤ 16 bytes), e.g. `"rp2040-pico"`.
    pub name: &'static str,
    /// Sensors wired to the board; those that answer at boot become capabilities.
    pub fitted: SensorSet,
    /// Highest step rate the board's loop guarantees, steps/s.
    pub max_step_rate_hz: u32,
    /// Resolution of [`Clock`], ticks per second.
    pub clock_hz: u32,
    /// The driver's EN input is active low (A4988, DRV8825, TMC2209: yes).
    pub enable_active_low: bool,
    /// STEP high time, ns (A4988 needs ≥ 1 µs, TMC2209 ≥ 100 ns).
    pub step_pulse_ns: u32,
    /// DIR set-up time before a STEP edge, ns (A4988 200 ns, TMC2209 20 ns).
    pub dir_setup_ns: u32,
    /// I²C address of encoder A (AS5600: 0x36).
    pub encoder_a_address: u8,
    /// I²C address of encoder B.
    pub encoder_b_address: u8,
    /// I²C address of the BNO055 (0x28 with ADR low, 0x29 high).
    pub imu_address: u8,
}

/// Default STEP high time, ns. Default 2 µs: twice the A4988's 1 µs minimum, and far above
/// the TMC2209's 100 ns.
pub const DEFAULT_STEP_PULSE_NS: u32 = 2_000;

/// Default DIR set-up time, ns. Default 1 µs: five times the A4988's 200 ns minimum.
pub const DEFAULT_DIR_SETUP_NS: u32 = 1_000;

impl BoardConfig {
    /// A board with A4988/TMC2209 timing, default sensor addresses and the given facts.
    pub const fn new(name: &'static str, fitted: SensorSet, max_step_rate_hz: u32) -> Self {
        Self {
            name,
            fitted,
            max_step_rate_hz,
            clock_hz: 1_000_000,
            enable_active_low: true,
            step_pulse_ns: DEFAULT_STEP_PULSE_NS,
            dir_setup_ns: DEFAULT_DIR_SETUP_NS,
            encoder_a_address: crate::sensors::as5600::ADDRESS,
            encoder_b_address: crate::sensors::as5600::ADDRESS,
            imu_address: crate::sensors::bno055::ADDRESS_ADR_LOW,
        }
    }
}

/// An I²C bus that is not there: every transaction fails with [`ErrorKind::Other`].
#[derive(Debug, Clone, Copy, Default)]
pub struct NoBus;

/// Error of [`NoBus`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct NoBusError;

impl embedded_hal::i2c::Error for NoBusError {
    fn kind(&self) -> ErrorKind {
        ErrorKind::Other
    }
}

impl ErrorType for NoBus {
    type Error = NoBusError;
}

impl I2c<SevenBitAddress> for NoBus {
    fn transaction(&mut self, _: u8, _: &mut [Operation<'_>]) -> Result<(), NoBusError> {
        Err(NoBusError)
    }
}

/// A quadrature counter that is not there (always 0).
#[derive(Debug, Clone, Copy, Default)]
pub struct NoQuadrature;

impl QuadratureCounter for NoQuadrature {
    fn count(&mut self) -> i32 {
        0
    }
}
