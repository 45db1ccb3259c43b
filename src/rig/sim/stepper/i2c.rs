//! Emulated I²C sensors for the simulated stepper bench: AS5600 magnetic encoders and a
//! BNO055 orientation sensor, as register files behind an `embedded_hal::i2c::I2c` bus.
//!
//! Register addresses, widths and reset values follow the datasheets (AS5600: ams
//! AS5600 datasheet v1-06, register map; BNO055: Bosch BST-BNO055-DS000, page 0 register
//! map). A write transaction sets the register pointer with its first byte and writes the
//! following bytes with auto-increment; a read returns bytes from the pointer on, also with
//! auto-increment. Unknown device addresses are not acknowledged. The simulator sets the
//! measured values ([`SensorBus::set_as5600_angle`], [`SensorBus::set_quaternion`]) after
//! every firmware poll and, through the bus's [`ReadHook`], just before every transaction,
//! so a read sees the plant at that instant.

use std::cell::RefCell;
use std::rc::Rc;

use embedded_hal::i2c::{ErrorKind, ErrorType, I2c, NoAcknowledgeSource, Operation};

use super::pins::ReadHook;

/// AS5600 7-bit address (fixed).
pub const AS5600_ADDRESS: u8 = 0x36;
/// AS5600 STATUS register (MD = bit 5, ML = bit 4, MH = bit 3).
pub const AS5600_STATUS: u8 = 0x0B;
/// AS5600 RAW ANGLE register, high byte (bits 11:8), then low byte.
pub const AS5600_RAW_ANGLE: u8 = 0x0C;
/// AS5600 ANGLE register (scaled output; equals RAW ANGLE with ZPOS = MPOS = MANG = 0).
pub const AS5600_ANGLE: u8 = 0x0E;
/// AS5600 AGC register.
pub const AS5600_AGC: u8 = 0x1A;
/// AS5600 MAGNITUDE register (12 bits).
pub const AS5600_MAGNITUDE: u8 = 0x1B;

/// BNO055 7-bit address with ADR low.
pub const BNO055_ADDRESS: u8 = 0x28;
/// BNO055 CHIP_ID register (reads 0xA0).
pub const BNO055_CHIP_ID: u8 = 0x00;
/// BNO055 quaternion data, w LSB first (w, x, y, z; 1 = 2¹⁴ LSB).
pub const BNO055_QUA_DATA: u8 = 0x20;
/// BNO055 CALIB_STAT register.
pub const BNO055_CALIB_STAT: u8 = 0x35;
/// BNO055 ST_RESULT register.
pub const BNO055_ST_RESULT: u8 = 0x36;
/// BNO055 SYS_STATUS register (5 = fusion algorithm running).
pub const BNO055_SYS_STATUS: u8 = 0x39;
/// BNO055 SYS_ERR register.
pub const BNO055_SYS_ERR: u8 = 0x3A;
/// BNO055 OPR_MODE register (0x0C = NDOF).
pub const BNO055_OPR_MODE: u8 = 0x3D;
/// BNO055 SYS_TRIGGER register (bit 5 = RST_SYS).
pub const BNO055_SYS_TRIGGER: u8 = 0x3F;

/// Magnitude reported by the emulated AS5600: mid-range, magnet well placed.
pub const AS5600_SIM_MAGNITUDE: u16 = 2048;

/// One emulated I²C device: 256 byte registers and a pointer.
#[derive(Debug, Clone)]
struct RegisterFile {
    regs: [u8; 256],
    pointer: u8,
}

impl RegisterFile {
    fn new() -> Self {
        RegisterFile {
            regs: [0; 256],
            pointer: 0,
        }
    }
}

/// Which chip a register file emulates (for side effects of writes and reads).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Chip {
    As5600,
    Bno055,
}

#[derive(Debug)]
struct BusState {
    devices: Vec<(u8, Chip, RegisterFile)>,
    transactions: u64,
}

/// An emulated I²C bus shared between the firmware (as its `I2c`) and the simulator (which
/// sets the values). Cheap to clone; single-threaded like the firmware loop it serves.
#[derive(Debug, Clone)]
pub struct SensorBus {
    state: Rc<RefCell<BusState>>,
    hook: ReadHook,
}

/// Error of the emulated bus.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct BusError(pub ErrorKind);

impl embedded_hal::i2c::Error for BusError {
    fn kind(&self) -> ErrorKind {
        self.0
    }
}

impl SensorBus {
    /// A bus with the given chips fitted.
    pub fn new(as5600: bool, bno055: bool) -> SensorBus {
        let mut devices = Vec::new();
        if as5600 {
            let mut f = RegisterFile::new();
            f.regs[usize::from(AS5600_STATUS)] = 0x20; // MD: magnet detected
            f.regs[usize::from(AS5600_AGC)] = 0x80;
            f.regs[usize::from(AS5600_MAGNITUDE)] = (AS5600_SIM_MAGNITUDE >> 8) as u8;
            f.regs[usize::from(AS5600_MAGNITUDE) + 1] = AS5600_SIM_MAGNITUDE as u8;
            devices.push((AS5600_ADDRESS, Chip::As5600, f));
        }
        if bno055 {
            devices.push((BNO055_ADDRESS, Chip::Bno055, bno055_reset()));
        }
        SensorBus {
            state: Rc::new(RefCell::new(BusState {
                devices,
                transactions: 0,
            })),
            hook: ReadHook::default(),
        }
    }

    /// The same bus, refreshed through `hook` before every transaction.
    pub fn with_read_hook(mut self, hook: ReadHook) -> SensorBus {
        self.hook = hook;
        self
    }

    /// Set the AS5600's angle in counts (wrapped to 0..4095).
    pub fn set_as5600_angle(&self, counts: i64) {
        let raw = counts.rem_euclid(4096) as u16;
        let mut st = self.state.borrow_mut();
        if let Some((_, _, f)) = st.devices.iter_mut().find(|d| d.1 == Chip::As5600) {
            for reg in [AS5600_RAW_ANGLE, AS5600_ANGLE] {
                f.regs[usize::from(reg)] = (raw >> 8) as u8;
                f.regs[usize::from(reg) + 1] = raw as u8;
            }
        }
    }

    /// Set the BNO055's fused quaternion `[w, x, y, z]` (only visible in a fusion mode).
    pub fn set_quaternion(&self, q: [f64; 4]) {
        let mut st = self.state.borrow_mut();
        if let Some((_, _, f)) = st.devices.iter_mut().find(|d| d.1 == Chip::Bno055) {
            let fusion = f.regs[usize::from(BNO055_OPR_MODE)] & 0x0F >= 0x08;
            for (i, v) in q.iter().enumerate() {
                let raw = if fusion {
                    (v * 16384.0).round().clamp(-32768.0, 32767.0) as i16
                } else {
                    0
                };
                let [lo, hi] = raw.to_le_bytes();
                f.regs[usize::from(BNO055_QUA_DATA) + 2 * i] = lo;
                f.regs[usize::from(BNO055_QUA_DATA) + 2 * i + 1] = hi;
            }
        }
    }

    /// Transactions served so far.
    pub fn transactions(&self) -> u64 {
        self.state.borrow().transactions
    }
}

fn bno055_reset() -> RegisterFile {
    let mut f = RegisterFile::new();
    f.regs[usize::from(BNO055_CHIP_ID)] = 0xA0;
    f.regs[0x01] = 0xFB; // ACC_ID
    f.regs[0x02] = 0x32; // MAG_ID
    f.regs[0x03] = 0x0F; // GYR_ID
    f.regs[0x04] = 0x11; // SW_REV_ID LSB (3.11)
    f.regs[0x05] = 0x03; // SW_REV_ID MSB
    f.regs[0x06] = 0x15; // BL_REV_ID
    f.regs[usize::from(BNO055_ST_RESULT)] = 0x0F; // all self tests passed
    f.regs[usize::from(BNO055_CALIB_STAT)] = 0xFF; // fully calibrated
    f.regs[usize::from(BNO055_OPR_MODE)] = 0x00; // CONFIG mode after reset
    f.regs[usize::from(BNO055_SYS_STATUS)] = 0x00; // idle
    f
}

impl ErrorType for SensorBus {
    type Error = BusError;
}

impl I2c for SensorBus {
    fn transaction(
        &mut self,
        address: u8,
        operations: &mut [Operation<'_>],
    ) -> Result<(), Self::Error> {
        self.hook.fire();
        let mut st = self.state.borrow_mut();
        st.transactions += 1;
        let Some((_, chip, file)) = st.devices.iter_mut().find(|d| d.0 == address) else {
            return Err(BusError(ErrorKind::NoAcknowledge(
                NoAcknowledgeSource::Address,
            )));
        };
        let chip = *chip;
        for op in operations.iter_mut() {
            match op {
                Operation::Write(bytes) => {
                    let Some((&first, rest)) = bytes.split_first() else {
                        continue;
                    };
                    file.pointer = first;
                    for &b in rest {
                        write_register(chip, file, b);
                        file.pointer = file.pointer.wrapping_add(1);
                    }
                }
                Operation::Read(buf) => {
                    for b in buf.iter_mut() {
                        *b = file.regs[usize::from(file.pointer)];
                        file.pointer = file.pointer.wrapping_add(1);
                    }
                }
            }
        }
        Ok(())
    }
}

fn write_register(chip: Chip, file: &mut RegisterFile, value: u8) {
    let reg = file.pointer;
    match (chip, reg) {
        (Chip::Bno055, BNO055_SYS_TRIGGER) if value & 0x20 != 0 => {
            // RST_SYS: back to reset values.
            *file = bno055_reset();
            return;
        }
        (Chip::Bno055, BNO055_OPR_MODE) => {
            let fusion = value & 0x0F >= 0x08;
            file.regs[usize::from(BNO055_SYS_STATUS)] = if fusion { 5 } else { 0 };
        }
        // Read-only registers of the AS5600 (status and outputs) and BNO055 (ids, data,
        // status) ignore writes.
        (Chip::As5600, 0x0B..=0x1C) => return,
        (Chip::Bno055, 0x00..=0x06 | 0x08..=0x3A) => return,
        _ => {}
    }
    file.regs[usize::from(reg)] = value;
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Guards: the AS5600 raw angle reads back big-endian and wrapped, as the datasheet
    /// lays it out.
    #[test]
    fn as5600_raw_angle_register() {
        let mut bus = SensorBus::new(true, false);
        bus.set_as5600_angle(4096 + 0x123);
        let mut buf = [0u8; 2];
        bus.write_read(AS5600_ADDRESS, &[AS5600_RAW_ANGLE], &mut buf)
            .unwrap();
        assert_eq!(buf, [0x01, 0x23]);
        let mut status = [0u8];
        bus.write_read(AS5600_ADDRESS, &[AS5600_STATUS], &mut status)
            .unwrap();
        assert_eq!(status[0] & 0x20, 0x20);
        bus.set_as5600_angle(-1);
        bus.write_read(AS5600_ADDRESS, &[AS5600_ANGLE], &mut buf)
            .unwrap();
        assert_eq!(buf, [0x0F, 0xFF]);
    }

    /// Guards: the BNO055 reports its chip id, shows quaternions only in a fusion mode,
    /// little-endian at 2¹⁴ LSB per unit, and resets on RST_SYS.
    #[test]
    fn bno055_quaternion_in_fusion_mode() {
        let mut bus = SensorBus::new(false, true);
        let mut id = [0u8];
        bus.write_read(BNO055_ADDRESS, &[BNO055_CHIP_ID], &mut id)
            .unwrap();
        assert_eq!(id[0], 0xA0);
        bus.set_quaternion([0.5, -0.5, 0.5, 0.5]);
        let mut q = [0u8; 8];
        bus.write_read(BNO055_ADDRESS, &[BNO055_QUA_DATA], &mut q)
            .unwrap();
        assert_eq!(q, [0; 8], "no data in CONFIG mode");
        bus.write(BNO055_ADDRESS, &[BNO055_OPR_MODE, 0x0C]).unwrap();
        bus.set_quaternion([0.5, -0.5, 0.5, 0.5]);
        bus.write_read(BNO055_ADDRESS, &[BNO055_QUA_DATA], &mut q)
            .unwrap();
        let w = i16::from_le_bytes([q[0], q[1]]);
        let x = i16::from_le_bytes([q[2], q[3]]);
        assert_eq!((w, x), (8192, -8192));
        let mut sys = [0u8];
        bus.write_read(BNO055_ADDRESS, &[BNO055_SYS_STATUS], &mut sys)
            .unwrap();
        assert_eq!(sys[0], 5);
        bus.write(BNO055_ADDRESS, &[BNO055_SYS_TRIGGER, 0x20])
            .unwrap();
        bus.write_read(BNO055_ADDRESS, &[BNO055_OPR_MODE], &mut sys)
            .unwrap();
        assert_eq!(sys[0], 0);
    }

    /// Guards: an absent chip does not acknowledge its address.
    #[test]
    fn absent_chip_nacks() {
        let mut bus = SensorBus::new(true, false);
        let e = bus.write(BNO055_ADDRESS, &[0]).unwrap_err();
        assert_eq!(e.0, ErrorKind::NoAcknowledge(NoAcknowledgeSource::Address));
    }
}
