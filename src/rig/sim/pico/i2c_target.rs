//! The bench's sensor buses as the emulated I²C controller sees them, byte by byte: an
//! address phase answered with the target's acknowledge, data bytes written, data bytes
//! read, STOP.
//!
//! The targets are the register models of the simulated stepper bench
//! ([`crate::rig::sim::stepper::i2c::SensorBus`]: AS5600, BNO055), driven through their
//! `embedded_hal::i2c::I2c` interface: a write phase becomes one write operation (its first
//! byte sets the register pointer) when the controller turns the bus around or stops, and
//! each byte read is a one-byte read at the pointer, which advances as on the chips. The
//! address phase probes the target with an empty transaction. Owns this translation and the
//! per-bus transfer state; not the registers.

use embedded_hal::i2c::{I2c, Operation};

use crate::rig::sim::stepper::i2c::SensorBus;

/// A transfer in progress on one bus.
#[derive(Debug, Default)]
struct Transfer {
    /// Address acknowledged in the current phase.
    address: Option<u8>,
    /// Bytes written in the current write phase, not yet handed to the target.
    written: Vec<u8>,
}

/// One bus seen byte by byte.
#[derive(Debug)]
pub struct ByteTarget {
    bus: SensorBus,
    transfer: Transfer,
    transfers: u64,
}

impl ByteTarget {
    /// The targets on `bus`.
    pub fn new(bus: SensorBus) -> ByteTarget {
        ByteTarget {
            bus,
            transfer: Transfer::default(),
            transfers: 0,
        }
    }

    /// An address phase (a START or repeated START before it): whether a target answers.
    pub fn connect(&mut self, address: u8) -> bool {
        self.finish_write();
        self.transfers += 1;
        let ack = self.bus.transaction(address, &mut []).is_ok();
        self.transfer.address = ack.then_some(address);
        ack
    }

    /// A data byte written to the addressed target (acknowledged).
    pub fn write(&mut self, byte: u8) {
        if self.transfer.address.is_some() {
            self.transfer.written.push(byte);
        }
    }

    /// A data byte read from the addressed target (0xFF, the idle bus, when none is).
    pub fn read(&mut self) -> u8 {
        self.finish_write();
        let Some(address) = self.transfer.address else {
            return 0xff;
        };
        let mut b = [0xffu8];
        match self
            .bus
            .transaction(address, &mut [Operation::Read(&mut b)])
        {
            Ok(()) => b[0],
            Err(_) => 0xff,
        }
    }

    /// STOP: the transfer ends.
    pub fn stop(&mut self) {
        self.finish_write();
        self.transfer.address = None;
    }

    /// Address phases seen.
    pub fn transfers(&self) -> u64 {
        self.transfers
    }

    fn finish_write(&mut self) {
        if self.transfer.written.is_empty() {
            return;
        }
        let bytes = std::mem::take(&mut self.transfer.written);
        if let Some(address) = self.transfer.address {
            // The models accept every write to a present chip.
            let _ = self
                .bus
                .transaction(address, &mut [Operation::Write(&bytes)]);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rig::sim::stepper::i2c::{
        AS5600_ADDRESS, AS5600_RAW_ANGLE, BNO055_ADDRESS, BNO055_OPR_MODE,
    };

    /// Guards the byte-level view of a register read as the firmware does it (write the
    /// register address, repeated START, read two bytes): it returns the model's value, and
    /// an absent chip is not acknowledged.
    #[test]
    fn register_read_byte_by_byte() {
        let bus = SensorBus::new(true, false);
        bus.set_as5600_angle(0x123);
        let mut t = ByteTarget::new(bus);
        assert!(t.connect(AS5600_ADDRESS));
        t.write(AS5600_RAW_ANGLE);
        assert!(t.connect(AS5600_ADDRESS));
        assert_eq!([t.read(), t.read()], [0x01, 0x23]);
        t.stop();
        assert!(!t.connect(BNO055_ADDRESS));
        assert_eq!(t.read(), 0xff);
        t.stop();
        assert_eq!(t.transfers(), 3);
    }

    /// Guards that a write phase reaches the model as one write (pointer, then data) when
    /// the transfer stops: the BNO055's mode register takes the value.
    #[test]
    fn write_phase_reaches_the_model_at_stop() {
        let mut t = ByteTarget::new(SensorBus::new(false, true));
        assert!(t.connect(BNO055_ADDRESS));
        t.write(BNO055_OPR_MODE);
        t.write(0x0c);
        t.stop();
        assert!(t.connect(BNO055_ADDRESS));
        t.write(BNO055_OPR_MODE);
        assert!(t.connect(BNO055_ADDRESS));
        assert_eq!(t.read(), 0x0c);
    }
}
