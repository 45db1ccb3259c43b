//! AS5600 12-bit contactless magnetic rotary position sensor (ams), I²C at a fixed 7-bit
//! address 0x36, up to 1 MHz (Fast-mode Plus).
//!
//! Registers used (datasheet DS000365, "Register Description"):
//! - `STATUS` 0x0B: bit 5 MD (magnet detected), bit 4 ML (too weak, AGC maximum overflow),
//!   bit 3 MH (too strong, AGC minimum overflow).
//! - `RAW ANGLE` 0x0C (bits 11:8) / 0x0D (bits 7:0): unscaled, unfiltered by ZPOS/MPOS; a
//!   two-byte read from 0x0C returns the high byte then the low byte.
//! - `AGC` 0x1A and `MAGNITUDE` 0x1B/0x1C: diagnostics of the magnet's field.
//!
//! The bench reads RAW ANGLE (the host calibrates zero and direction), so no OTP register is
//! ever written (`BURN` 0xFF is never touched).

use embedded_hal::i2c::I2c;

use super::SensorError;

/// The AS5600's fixed I²C address.
pub const ADDRESS: u8 = 0x36;
/// `STATUS` register.
pub const REG_STATUS: u8 = 0x0B;
/// `RAW ANGLE` high byte (bits 11:8); the low byte follows at 0x0D.
pub const REG_RAW_ANGLE: u8 = 0x0C;
/// `AGC` register.
pub const REG_AGC: u8 = 0x1A;
/// `MAGNITUDE` high byte (bits 11:8); the low byte follows at 0x1C.
pub const REG_MAGNITUDE: u8 = 0x1B;
/// `STATUS.MD`: magnet detected.
pub const STATUS_MD: u8 = 1 << 5;
/// `STATUS.ML`: magnet too weak.
pub const STATUS_ML: u8 = 1 << 4;
/// `STATUS.MH`: magnet too strong.
pub const STATUS_MH: u8 = 1 << 3;
/// Counts per revolution of the 12-bit angle.
pub const COUNTS_PER_REV: u16 = 4096;

/// Decoded `STATUS` register.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct MagnetStatus {
    /// A magnet is detected.
    pub detected: bool,
    /// The field is too weak.
    pub too_weak: bool,
    /// The field is too strong.
    pub too_strong: bool,
}

impl MagnetStatus {
    /// Decode the register value.
    pub fn from_register(status: u8) -> Self {
        Self {
            detected: status & STATUS_MD != 0,
            too_weak: status & STATUS_ML != 0,
            too_strong: status & STATUS_MH != 0,
        }
    }
}

/// One AS5600 at `address` (0x36 unless behind an address translator).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct As5600 {
    /// 7-bit I²C address.
    pub address: u8,
}

impl Default for As5600 {
    fn default() -> Self {
        Self { address: ADDRESS }
    }
}

impl As5600 {
    /// A sensor at `address`.
    pub const fn new(address: u8) -> Self {
        Self { address }
    }

    fn read<I: I2c, const N: usize>(
        &self,
        bus: &mut I,
        reg: u8,
    ) -> Result<[u8; N], SensorError<I::Error>> {
        let mut buf = [0u8; N];
        bus.write_read(self.address, &[reg], &mut buf)
            .map_err(|error| SensorError::Bus {
                address: self.address,
                error,
            })?;
        Ok(buf)
    }

    /// Read `STATUS`.
    pub fn status<I: I2c>(&self, bus: &mut I) -> Result<MagnetStatus, SensorError<I::Error>> {
        let [s] = self.read::<I, 1>(bus, REG_STATUS)?;
        Ok(MagnetStatus::from_register(s))
    }

    /// Check that the sensor answers and sees a magnet (used at boot).
    pub fn probe<I: I2c>(&self, bus: &mut I) -> Result<MagnetStatus, SensorError<I::Error>> {
        let [s] = self.read::<I, 1>(bus, REG_STATUS)?;
        let status = MagnetStatus::from_register(s);
        if !status.detected {
            return Err(SensorError::NoMagnet {
                address: self.address,
                status: s,
            });
        }
        Ok(status)
    }

    /// Read the 12-bit `RAW ANGLE` (0..=4095) in one two-byte transaction.
    pub fn raw_angle<I: I2c>(&self, bus: &mut I) -> Result<u16, SensorError<I::Error>> {
        let [hi, lo] = self.read::<I, 2>(bus, REG_RAW_ANGLE)?;
        Ok((((hi & 0x0F) as u16) << 8) | lo as u16)
    }

    /// Read `AGC` (automatic gain; 0..=255 at 5 V, 0..=128 at 3.3 V).
    pub fn agc<I: I2c>(&self, bus: &mut I) -> Result<u8, SensorError<I::Error>> {
        Ok(self.read::<I, 1>(bus, REG_AGC)?[0])
    }

    /// Read the 12-bit `MAGNITUDE` of the field (CORDIC output).
    pub fn magnitude<I: I2c>(&self, bus: &mut I) -> Result<u16, SensorError<I::Error>> {
        let [hi, lo] = self.read::<I, 2>(bus, REG_MAGNITUDE)?;
        Ok((((hi & 0x0F) as u16) << 8) | lo as u16)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use embedded_hal::i2c::ErrorKind;
    use embedded_hal_mock::eh1::i2c::{Mock, Transaction};

    /// Guards the raw-angle read: one write of register 0x0C then a two-byte read, high
    /// nibble masked (bits 15:12 are unused and may read as anything).
    #[test]
    fn raw_angle_reads_register_0x0c_high_then_low() {
        let mut bus = Mock::new(&[
            Transaction::write_read(0x36, vec![0x0C], vec![0x0A, 0xBC]),
            Transaction::write_read(0x36, vec![0x0C], vec![0xFF, 0xFF]),
        ]);
        let enc = As5600::default();
        assert_eq!(enc.raw_angle(&mut bus), Ok(0x0ABC));
        assert_eq!(enc.raw_angle(&mut bus), Ok(4095));
        bus.done();
    }

    /// Guards the STATUS bit positions (MD 5, ML 4, MH 3) and the probe's magnet check.
    #[test]
    fn status_bits_and_probe() {
        let mut bus = Mock::new(&[
            Transaction::write_read(0x36, vec![0x0B], vec![0b0010_0000]),
            Transaction::write_read(0x36, vec![0x0B], vec![0b0011_0000]),
            Transaction::write_read(0x36, vec![0x0B], vec![0b0000_1000]),
        ]);
        let enc = As5600::default();
        assert_eq!(
            enc.probe(&mut bus),
            Ok(MagnetStatus {
                detected: true,
                too_weak: false,
                too_strong: false
            })
        );
        let s = enc.status(&mut bus).unwrap();
        assert!(s.detected && s.too_weak && !s.too_strong);
        assert_eq!(
            enc.probe(&mut bus),
            Err(SensorError::NoMagnet {
                address: 0x36,
                status: 0x08
            })
        );
        bus.done();
    }

    /// Guards the diagnostics registers AGC 0x1A and MAGNITUDE 0x1B/0x1C.
    #[test]
    fn agc_and_magnitude_registers() {
        let mut bus = Mock::new(&[
            Transaction::write_read(0x36, vec![0x1A], vec![0x80]),
            Transaction::write_read(0x36, vec![0x1B], vec![0xF7, 0x21]),
        ]);
        let enc = As5600::default();
        assert_eq!(enc.agc(&mut bus), Ok(0x80));
        assert_eq!(enc.magnitude(&mut bus), Ok(0x0721));
        bus.done();
    }

    /// Guards that a bus error (no acknowledge) is reported with the address, not a panic.
    #[test]
    fn bus_error_is_reported() {
        let mut bus = Mock::new(&[Transaction::write_read(0x36, vec![0x0C], vec![0, 0])
            .with_error(ErrorKind::NoAcknowledge(
                embedded_hal::i2c::NoAcknowledgeSource::Address,
            ))]);
        let r = As5600::default().raw_angle(&mut bus);
        assert!(
            matches!(r, Err(SensorError::Bus { address: 0x36, .. })),
            "{r:?}"
        );
        bus.done();
    }
}
