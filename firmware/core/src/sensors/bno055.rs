//! BNO055 9-axis absolute orientation sensor (Bosch) over I²C: its fused quaternion.
//!
//! Registers used (datasheet BST-BNO055-DS000, section 4, register map page 0):
//! - `CHIP_ID` 0x00 reads 0xA0.
//! - `PAGE_ID` 0x07: register page (0 for everything here).
//! - `QUA_Data_w_LSB` 0x20 … `QUA_Data_z_MSB` 0x27: quaternion w, x, y, z, each a signed
//!   16-bit little-endian value with 1 = 2¹⁴ LSB (section 3.6.5.5).
//! - `SYS_STATUS` 0x39: 5 = fusion algorithm running.
//! - `OPR_MODE` 0x3D: 0x00 CONFIGMODE, 0x0C NDOF (9-DOF fusion, 100 Hz output).
//! - `PWR_MODE` 0x3E: 0x00 normal.
//!
//! Mode switching times (table 3-6): any mode → CONFIGMODE 19 ms, CONFIGMODE → any 7 ms.
//! The fusion output rate in NDOF is 100 Hz ([`FUSION_RATE_HZ`]).

use embedded_hal::delay::DelayNs;
use embedded_hal::i2c::I2c;

use super::SensorError;

/// Address with the ADR pin low (default on most breakout boards).
pub const ADDRESS_ADR_LOW: u8 = 0x28;
/// Address with the ADR pin high.
pub const ADDRESS_ADR_HIGH: u8 = 0x29;
/// `CHIP_ID` register.
pub const REG_CHIP_ID: u8 = 0x00;
/// `PAGE_ID` register.
pub const REG_PAGE_ID: u8 = 0x07;
/// `QUA_Data_w_LSB`, first of the 8 quaternion bytes.
pub const REG_QUA_DATA: u8 = 0x20;
/// `SYS_STATUS` register.
pub const REG_SYS_STATUS: u8 = 0x39;
/// `OPR_MODE` register.
pub const REG_OPR_MODE: u8 = 0x3D;
/// `PWR_MODE` register.
pub const REG_PWR_MODE: u8 = 0x3E;
/// Value of `CHIP_ID`.
pub const CHIP_ID: u8 = 0xA0;
/// `OPR_MODE` CONFIGMODE.
pub const MODE_CONFIG: u8 = 0x00;
/// `OPR_MODE` NDOF fusion.
pub const MODE_NDOF: u8 = 0x0C;
/// `PWR_MODE` normal.
pub const POWER_NORMAL: u8 = 0x00;
/// Time to switch from any mode to CONFIGMODE, ms.
pub const TO_CONFIG_MS: u32 = 19;
/// Time to switch from CONFIGMODE to an operating mode, ms.
pub const FROM_CONFIG_MS: u32 = 7;
/// Output rate of the fusion in NDOF mode, Hz.
pub const FUSION_RATE_HZ: u16 = 100;
/// One unit of a quaternion component, LSB (2¹⁴).
pub const QUATERNION_ONE: i16 = 1 << 14;

/// One BNO055 at `address`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Bno055 {
    /// 7-bit I²C address.
    pub address: u8,
}

impl Default for Bno055 {
    fn default() -> Self {
        Self {
            address: ADDRESS_ADR_LOW,
        }
    }
}

impl Bno055 {
    /// A sensor at `address`.
    pub const fn new(address: u8) -> Self {
        Self { address }
    }

    fn bus<E: core::fmt::Debug>(&self) -> impl Fn(E) -> SensorError<E> + '_ {
        move |error| SensorError::Bus {
            address: self.address,
            error,
        }
    }

    fn write_reg<I: I2c>(
        &self,
        bus: &mut I,
        reg: u8,
        value: u8,
    ) -> Result<(), SensorError<I::Error>> {
        bus.write(self.address, &[reg, value]).map_err(self.bus())
    }

    /// Read `CHIP_ID` and check it is 0xA0.
    pub fn check_chip_id<I: I2c>(&self, bus: &mut I) -> Result<(), SensorError<I::Error>> {
        let mut id = [0u8];
        bus.write_read(self.address, &[REG_CHIP_ID], &mut id)
            .map_err(self.bus())?;
        if id[0] != CHIP_ID {
            return Err(SensorError::WrongChip {
                address: self.address,
                expected: CHIP_ID,
                found: id[0],
            });
        }
        Ok(())
    }

    /// Bring the sensor into NDOF fusion: check the chip id, enter CONFIGMODE, select page 0
    /// and normal power, then NDOF, waiting the datasheet's switching times.
    pub fn init<I: I2c, D: DelayNs>(
        &self,
        bus: &mut I,
        delay: &mut D,
    ) -> Result<(), SensorError<I::Error>> {
        self.check_chip_id(bus)?;
        self.write_reg(bus, REG_OPR_MODE, MODE_CONFIG)?;
        delay.delay_ms(TO_CONFIG_MS);
        self.write_reg(bus, REG_PAGE_ID, 0)?;
        self.write_reg(bus, REG_PWR_MODE, POWER_NORMAL)?;
        self.write_reg(bus, REG_OPR_MODE, MODE_NDOF)?;
        delay.delay_ms(FROM_CONFIG_MS);
        Ok(())
    }

    /// Read the fused quaternion `[w, x, y, z]` in Q14 in one 8-byte burst from 0x20.
    pub fn quaternion<I: I2c>(&self, bus: &mut I) -> Result<[i16; 4], SensorError<I::Error>> {
        let mut b = [0u8; 8];
        bus.write_read(self.address, &[REG_QUA_DATA], &mut b)
            .map_err(self.bus())?;
        Ok([
            i16::from_le_bytes([b[0], b[1]]),
            i16::from_le_bytes([b[2], b[3]]),
            i16::from_le_bytes([b[4], b[5]]),
            i16::from_le_bytes([b[6], b[7]]),
        ])
    }

    /// Read `SYS_STATUS` (5 = fusion running).
    pub fn system_status<I: I2c>(&self, bus: &mut I) -> Result<u8, SensorError<I::Error>> {
        let mut s = [0u8];
        bus.write_read(self.address, &[REG_SYS_STATUS], &mut s)
            .map_err(self.bus())?;
        Ok(s[0])
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use embedded_hal_mock::eh1::delay::{CheckedDelay, Transaction as D};
    use embedded_hal_mock::eh1::i2c::{Mock, Transaction as T};

    /// Guards the init sequence register by register, with the datasheet's mode-switch
    /// delays (19 ms into CONFIGMODE, 7 ms out of it).
    #[test]
    fn init_enters_ndof_with_datasheet_delays() {
        let mut bus = Mock::new(&[
            T::write_read(0x28, vec![0x00], vec![0xA0]),
            T::write(0x28, vec![0x3D, 0x00]),
            T::write(0x28, vec![0x07, 0x00]),
            T::write(0x28, vec![0x3E, 0x00]),
            T::write(0x28, vec![0x3D, 0x0C]),
        ]);
        let mut delay = CheckedDelay::new(&[D::delay_ms(19), D::delay_ms(7)]);
        Bno055::default().init(&mut bus, &mut delay).unwrap();
        bus.done();
        delay.done();
    }

    /// Guards that a wrong chip id stops the init before any write.
    #[test]
    fn wrong_chip_id_is_refused() {
        let mut bus = Mock::new(&[T::write_read(0x29, vec![0x00], vec![0x32])]);
        let mut delay = CheckedDelay::new(&[]);
        assert_eq!(
            Bno055::new(0x29).init(&mut bus, &mut delay),
            Err(SensorError::WrongChip {
                address: 0x29,
                expected: 0xA0,
                found: 0x32
            })
        );
        bus.done();
        delay.done();
    }

    /// Guards the quaternion burst: 8 bytes from 0x20, little-endian, w first, Q14.
    #[test]
    fn quaternion_is_little_endian_w_first() {
        // w = 1.0 (0x4000), x = -0.5 (0xE000), y = 0x0123, z = -1 (0xFFFF)
        let mut bus = Mock::new(&[
            T::write_read(
                0x28,
                vec![0x20],
                vec![0x00, 0x40, 0x00, 0xE0, 0x23, 0x01, 0xFF, 0xFF],
            ),
            T::write_read(0x28, vec![0x39], vec![0x05]),
        ]);
        let imu = Bno055::default();
        assert_eq!(imu.quaternion(&mut bus), Ok([16384, -8192, 0x0123, -1]));
        assert_eq!(imu.system_status(&mut bus), Ok(5));
        bus.done();
    }
}
