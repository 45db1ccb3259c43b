//! Sensor drivers: AS5600 magnetic absolute encoder and BNO055 orientation sensor over I²C,
//! and a quadrature decoder state machine.
//!
//! Owns register maps and bus transactions, taken from the manufacturers' datasheets
//! (ams AS5600 DS000365, Bosch BNO055 BST-BNO055-DS000). The drivers hold no bus: every
//! call borrows one, so one bus can carry several devices without a sharing layer. They do
//! not schedule reads (that is [`crate::sampler`]).

pub mod as5600;
pub mod bno055;
pub mod quadrature;

/// Error of a sensor driver over a bus with error type `E`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum SensorError<E: core::fmt::Debug> {
    /// The I²C transaction failed (no acknowledge, arbitration lost, bus error…).
    #[error("I²C transaction with device 0x{address:02x} failed: {error:?}")]
    Bus {
        /// 7-bit device address.
        address: u8,
        /// The bus error.
        error: E,
    },
    /// The device answered with an unexpected identity.
    #[error("device 0x{address:02x} has chip id 0x{found:02x}, expected 0x{expected:02x}")]
    WrongChip {
        /// 7-bit device address.
        address: u8,
        /// Expected id.
        expected: u8,
        /// Id read.
        found: u8,
    },
    /// AS5600: no magnet detected (STATUS.MD clear); the angle is meaningless.
    #[error("no magnet detected by the AS5600 at 0x{address:02x} (STATUS 0x{status:02x})")]
    NoMagnet {
        /// 7-bit device address.
        address: u8,
        /// The STATUS register.
        status: u8,
    },
}
