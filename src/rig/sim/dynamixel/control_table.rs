//! The XL430-W250 control table: every item's address, size, access right, factory default
//! and value range, as published in the ROBOTIS e-manual (XL430-W250-T page, firmware v45+).
//!
//! This file owns only the *description* of the table and the value checks a write must
//! pass; the behaviour behind the items (torque gating, profiles, watchdog) lives in
//! [`super::servo`].

/// Total size of the control table in bytes (addresses 0..=661).
pub const TABLE_SIZE: usize = 662;

/// Model number of the XL430-W250 (address 0).
pub const MODEL_XL430_W250: u16 = 1060;

/// Firmware version the simulated servo reports at address 6 and in ping replies.
/// Default 46: a current X-series firmware (v45+ has Startup Configuration at 60).
pub const FIRMWARE_VERSION: u8 = 46;

/// Who may touch an item.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Access {
    /// Read only.
    Read,
    /// Read and write.
    ReadWrite,
}

/// Which memory area an item lives in: EEPROM items are locked while torque is on.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Area {
    /// Non-volatile settings (addresses below 64); writable only with torque off.
    Eeprom,
    /// Volatile state and commands (64 and up).
    Ram,
}

/// How a written value is checked.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Range {
    /// Any value of the item's size.
    Any,
    /// A fixed inclusive range, checked on the value as a signed integer.
    Fixed(i64, i64),
    /// Limited by another item: `±value` of the item at this address (Goal PWM, Goal
    /// Velocity); violations are *Data Limit* errors.
    SymmetricLimit(u16),
    /// Goal Position: between Min and Max Position Limit in Position mode, ±256 rev in
    /// Extended Position mode; violations are *Data Limit* errors.
    GoalPosition,
    /// Bus Watchdog: 0 (off / clear error) or 1..=127 (×20 ms).
    BusWatchdog,
}

/// One item of the control table.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Item {
    /// Start address.
    pub address: u16,
    /// Size in bytes (1, 2 or 4), little endian.
    pub size: u8,
    /// Name as in the e-manual.
    pub name: &'static str,
    /// Access right.
    pub access: Access,
    /// Factory default (as a signed value; written little endian).
    pub default: i64,
    /// Accepted values for writes.
    pub range: Range,
}

impl Item {
    /// The memory area the item is in.
    pub fn area(&self) -> Area {
        if self.address < addr::TORQUE_ENABLE {
            Area::Eeprom
        } else {
            Area::Ram
        }
    }

    /// Whether the item is signed (negative values are meaningful).
    pub fn signed(&self) -> bool {
        matches!(
            self.address,
            addr::HOMING_OFFSET
                | addr::GOAL_PWM
                | addr::GOAL_VELOCITY
                | addr::GOAL_POSITION
                | addr::BUS_WATCHDOG
                | addr::PRESENT_PWM
                | addr::PRESENT_LOAD
                | addr::PRESENT_VELOCITY
                | addr::PRESENT_POSITION
                | addr::VELOCITY_TRAJECTORY
                | addr::POSITION_TRAJECTORY
        )
    }

    /// Decode the item's bytes from a little-endian slice of its size, sign-extended when
    /// the item is signed.
    pub fn decode(&self, bytes: &[u8]) -> i64 {
        let raw = match self.size {
            1 => u64::from(bytes[0]),
            2 => u64::from(u16::from_le_bytes([bytes[0], bytes[1]])),
            _ => u64::from(u32::from_le_bytes([bytes[0], bytes[1], bytes[2], bytes[3]])),
        };
        if self.signed() {
            let shift = 64 - 8 * u32::from(self.size);
            ((raw << shift) as i64) >> shift
        } else {
            raw as i64
        }
    }
}

/// Addresses of the items the simulator gives behaviour to.
pub mod addr {
    /// Model Number (2 bytes, R).
    pub const MODEL_NUMBER: u16 = 0;
    /// Model Information (4 bytes, R).
    pub const MODEL_INFORMATION: u16 = 2;
    /// Firmware Version (1 byte, R).
    pub const FIRMWARE_VERSION: u16 = 6;
    /// ID (1 byte).
    pub const ID: u16 = 7;
    /// Baud Rate index (1 byte): 0 9600, 1 57600, 2 115200, 3 1M, 4 2M, 5 3M, 6 4M, 7 4.5M.
    pub const BAUD_RATE: u16 = 8;
    /// Return Delay Time (1 byte, ×2 µs).
    pub const RETURN_DELAY_TIME: u16 = 9;
    /// Drive Mode (1 byte): bit 0 reverse, bit 2 time-based profile, bit 3 torque on by goal update.
    pub const DRIVE_MODE: u16 = 10;
    /// Operating Mode (1 byte): 1 velocity, 3 position, 4 extended position, 16 PWM.
    pub const OPERATING_MODE: u16 = 11;
    /// Secondary (Shadow) ID (1 byte).
    pub const SECONDARY_ID: u16 = 12;
    /// Protocol Type (1 byte).
    pub const PROTOCOL_TYPE: u16 = 13;
    /// Homing Offset (4 bytes, pulses).
    pub const HOMING_OFFSET: u16 = 20;
    /// Moving Threshold (4 bytes, ×0.229 rpm).
    pub const MOVING_THRESHOLD: u16 = 24;
    /// Temperature Limit (1 byte).
    pub const TEMPERATURE_LIMIT: u16 = 31;
    /// Max Voltage Limit (2 bytes).
    pub const MAX_VOLTAGE_LIMIT: u16 = 32;
    /// Min Voltage Limit (2 bytes).
    pub const MIN_VOLTAGE_LIMIT: u16 = 34;
    /// PWM Limit (2 bytes).
    pub const PWM_LIMIT: u16 = 36;
    /// Velocity Limit (4 bytes, ×0.229 rpm).
    pub const VELOCITY_LIMIT: u16 = 44;
    /// Max Position Limit (4 bytes).
    pub const MAX_POSITION_LIMIT: u16 = 48;
    /// Min Position Limit (4 bytes).
    pub const MIN_POSITION_LIMIT: u16 = 52;
    /// Startup Configuration (1 byte).
    pub const STARTUP_CONFIGURATION: u16 = 60;
    /// Shutdown (1 byte): which hardware errors turn torque off.
    pub const SHUTDOWN: u16 = 63;
    /// Torque Enable (1 byte).
    pub const TORQUE_ENABLE: u16 = 64;
    /// LED (1 byte).
    pub const LED: u16 = 65;
    /// Status Return Level (1 byte): 0 ping only, 1 ping and reads, 2 all.
    pub const STATUS_RETURN_LEVEL: u16 = 68;
    /// Registered Instruction (1 byte, R).
    pub const REGISTERED_INSTRUCTION: u16 = 69;
    /// Hardware Error Status (1 byte, R).
    pub const HARDWARE_ERROR_STATUS: u16 = 70;
    /// Velocity I Gain.
    pub const VELOCITY_I_GAIN: u16 = 76;
    /// Velocity P Gain.
    pub const VELOCITY_P_GAIN: u16 = 78;
    /// Position D Gain.
    pub const POSITION_D_GAIN: u16 = 80;
    /// Position I Gain.
    pub const POSITION_I_GAIN: u16 = 82;
    /// Position P Gain.
    pub const POSITION_P_GAIN: u16 = 84;
    /// Feedforward 2nd Gain.
    pub const FEEDFORWARD_2ND_GAIN: u16 = 88;
    /// Feedforward 1st Gain.
    pub const FEEDFORWARD_1ST_GAIN: u16 = 90;
    /// Bus Watchdog (1 byte, ×20 ms; −1 = watchdog error).
    pub const BUS_WATCHDOG: u16 = 98;
    /// Goal PWM (2 bytes).
    pub const GOAL_PWM: u16 = 100;
    /// Goal Velocity (4 bytes, ×0.229 rpm).
    pub const GOAL_VELOCITY: u16 = 104;
    /// Profile Acceleration (4 bytes, ×214.577 rev/min²).
    pub const PROFILE_ACCELERATION: u16 = 108;
    /// Profile Velocity (4 bytes, ×0.229 rpm).
    pub const PROFILE_VELOCITY: u16 = 112;
    /// Goal Position (4 bytes, pulses).
    pub const GOAL_POSITION: u16 = 116;
    /// Realtime Tick (2 bytes, ms, wraps at 32767).
    pub const REALTIME_TICK: u16 = 120;
    /// Moving (1 byte).
    pub const MOVING: u16 = 122;
    /// Moving Status (1 byte).
    pub const MOVING_STATUS: u16 = 123;
    /// Present PWM (2 bytes).
    pub const PRESENT_PWM: u16 = 124;
    /// Present Load (2 bytes).
    pub const PRESENT_LOAD: u16 = 126;
    /// Present Velocity (4 bytes, ×0.229 rpm).
    pub const PRESENT_VELOCITY: u16 = 128;
    /// Present Position (4 bytes, pulses).
    pub const PRESENT_POSITION: u16 = 132;
    /// Velocity Trajectory (4 bytes).
    pub const VELOCITY_TRAJECTORY: u16 = 136;
    /// Position Trajectory (4 bytes).
    pub const POSITION_TRAJECTORY: u16 = 140;
    /// Present Input Voltage (2 bytes, ×0.1 V).
    pub const PRESENT_INPUT_VOLTAGE: u16 = 144;
    /// Present Temperature (1 byte, °C).
    pub const PRESENT_TEMPERATURE: u16 = 146;
    /// Backup Ready (1 byte).
    pub const BACKUP_READY: u16 = 147;
    /// Indirect Address 1 (2 bytes each, 1..=28 at 168..=222).
    pub const INDIRECT_ADDRESS_1: u16 = 168;
    /// Indirect Data 1 (1 byte each, 1..=28 at 224..=251).
    pub const INDIRECT_DATA_1: u16 = 224;
    /// Indirect Address 29 (2 bytes each, 29..=56 at 578..=632).
    pub const INDIRECT_ADDRESS_29: u16 = 578;
    /// Indirect Data 29 (1 byte each, 29..=56 at 634..=661).
    pub const INDIRECT_DATA_29: u16 = 634;
}

/// Operating Mode values (address 11).
pub mod mode {
    /// Velocity control.
    pub const VELOCITY: u8 = 1;
    /// Position control (single turn, limited by the position limits).
    pub const POSITION: u8 = 3;
    /// Extended position control (multi-turn, ±256 rev).
    pub const EXTENDED_POSITION: u8 = 4;
    /// PWM (voltage) control.
    pub const PWM: u8 = 16;
}

/// Hardware Error Status bits (address 70).
pub mod hw_error {
    /// Input voltage out of the configured limits.
    pub const INPUT_VOLTAGE: u8 = 0x01;
    /// Internal temperature above the limit.
    pub const OVERHEATING: u8 = 0x04;
    /// Motor encoder malfunction.
    pub const MOTOR_ENCODER: u8 = 0x08;
    /// Electrical shock on the circuit or insufficient power.
    pub const ELECTRICAL_SHOCK: u8 = 0x10;
    /// Persistent load beyond the maximum.
    pub const OVERLOAD: u8 = 0x20;
}

/// Extended Position range: ±256 revolutions of 4096 pulses (e-manual: −1,048,575..1,048,575).
pub const EXTENDED_POSITION_LIMIT: i64 = 1_048_575;

const fn item(
    address: u16,
    size: u8,
    name: &'static str,
    access: Access,
    default: i64,
    range: Range,
) -> Item {
    Item {
        address,
        size,
        name,
        access,
        default,
        range,
    }
}

use Access::{Read as R, ReadWrite as RW};

/// The named (non-indirect) items of the XL430-W250, in address order.
pub const NAMED_ITEMS: &[Item] = &[
    item(0, 2, "Model Number", R, MODEL_XL430_W250 as i64, Range::Any),
    item(2, 4, "Model Information", R, 0, Range::Any),
    item(
        6,
        1,
        "Firmware Version",
        R,
        FIRMWARE_VERSION as i64,
        Range::Any,
    ),
    item(7, 1, "ID", RW, 1, Range::Fixed(0, 252)),
    item(8, 1, "Baud Rate", RW, 1, Range::Fixed(0, 7)),
    item(9, 1, "Return Delay Time", RW, 250, Range::Fixed(0, 254)),
    item(10, 1, "Drive Mode", RW, 0, Range::Fixed(0, 13)),
    item(11, 1, "Operating Mode", RW, 3, Range::Fixed(0, 16)),
    item(12, 1, "Secondary(Shadow) ID", RW, 255, Range::Fixed(0, 255)),
    item(13, 1, "Protocol Type", RW, 2, Range::Fixed(1, 2)),
    item(
        20,
        4,
        "Homing Offset",
        RW,
        0,
        Range::Fixed(-1_044_479, 1_044_479),
    ),
    item(24, 4, "Moving Threshold", RW, 10, Range::Fixed(0, 1023)),
    item(31, 1, "Temperature Limit", RW, 72, Range::Fixed(0, 100)),
    item(32, 2, "Max Voltage Limit", RW, 140, Range::Fixed(60, 140)),
    item(34, 2, "Min Voltage Limit", RW, 60, Range::Fixed(60, 140)),
    item(36, 2, "PWM Limit", RW, 885, Range::Fixed(0, 885)),
    item(44, 4, "Velocity Limit", RW, 265, Range::Fixed(0, 1023)),
    item(48, 4, "Max Position Limit", RW, 4095, Range::Fixed(0, 4095)),
    item(52, 4, "Min Position Limit", RW, 0, Range::Fixed(0, 4095)),
    item(60, 1, "Startup Configuration", RW, 0, Range::Fixed(0, 3)),
    item(63, 1, "Shutdown", RW, 52, Range::Any),
    item(64, 1, "Torque Enable", RW, 0, Range::Fixed(0, 1)),
    item(65, 1, "LED", RW, 0, Range::Fixed(0, 1)),
    item(68, 1, "Status Return Level", RW, 2, Range::Fixed(0, 2)),
    item(69, 1, "Registered Instruction", R, 0, Range::Any),
    item(70, 1, "Hardware Error Status", R, 0, Range::Any),
    item(76, 2, "Velocity I Gain", RW, 1000, Range::Fixed(0, 16383)),
    item(78, 2, "Velocity P Gain", RW, 100, Range::Fixed(0, 16383)),
    item(80, 2, "Position D Gain", RW, 4000, Range::Fixed(0, 16383)),
    item(82, 2, "Position I Gain", RW, 0, Range::Fixed(0, 16383)),
    item(84, 2, "Position P Gain", RW, 640, Range::Fixed(0, 16383)),
    item(88, 2, "Feedforward 2nd Gain", RW, 0, Range::Fixed(0, 16383)),
    item(90, 2, "Feedforward 1st Gain", RW, 0, Range::Fixed(0, 16383)),
    item(98, 1, "Bus Watchdog", RW, 0, Range::BusWatchdog),
    item(100, 2, "Goal PWM", RW, 0, Range::SymmetricLimit(36)),
    item(104, 4, "Goal Velocity", RW, 0, Range::SymmetricLimit(44)),
    item(
        108,
        4,
        "Profile Acceleration",
        RW,
        0,
        Range::Fixed(0, 32767),
    ),
    item(112, 4, "Profile Velocity", RW, 0, Range::Fixed(0, 32767)),
    item(116, 4, "Goal Position", RW, 0, Range::GoalPosition),
    item(120, 2, "Realtime Tick", R, 0, Range::Any),
    item(122, 1, "Moving", R, 0, Range::Any),
    item(123, 1, "Moving Status", R, 0, Range::Any),
    item(124, 2, "Present PWM", R, 0, Range::Any),
    item(126, 2, "Present Load", R, 0, Range::Any),
    item(128, 4, "Present Velocity", R, 0, Range::Any),
    item(132, 4, "Present Position", R, 0, Range::Any),
    item(136, 4, "Velocity Trajectory", R, 0, Range::Any),
    item(140, 4, "Position Trajectory", R, 0, Range::Any),
    item(144, 2, "Present Input Voltage", R, 120, Range::Any),
    item(146, 1, "Present Temperature", R, 30, Range::Any),
    item(147, 1, "Backup Ready", R, 0, Range::Any),
];

/// Number of indirect address/data pairs (1..=56).
pub const INDIRECT_COUNT: usize = 56;

/// Address of Indirect Address `n` (1-based).
pub fn indirect_address_addr(n: usize) -> u16 {
    debug_assert!((1..=INDIRECT_COUNT).contains(&n));
    if n <= 28 {
        addr::INDIRECT_ADDRESS_1 + 2 * (n as u16 - 1)
    } else {
        addr::INDIRECT_ADDRESS_29 + 2 * (n as u16 - 29)
    }
}

/// Address of Indirect Data `n` (1-based).
pub fn indirect_data_addr(n: usize) -> u16 {
    debug_assert!((1..=INDIRECT_COUNT).contains(&n));
    if n <= 28 {
        addr::INDIRECT_DATA_1 + (n as u16 - 1)
    } else {
        addr::INDIRECT_DATA_29 + (n as u16 - 29)
    }
}

/// Which indirect slot (1-based) an Indirect Data address belongs to, if any.
pub fn indirect_slot_of_data(address: u16) -> Option<usize> {
    match address {
        224..=251 => Some(usize::from(address - 224) + 1),
        634..=661 => Some(usize::from(address - 634) + 29),
        _ => None,
    }
}

/// A per-byte map of the table: which item (if any) covers each address, and at which byte.
#[derive(Debug, Clone)]
pub struct Layout {
    owner: Vec<Option<(Item, u8)>>,
}

impl Layout {
    /// The XL430-W250 layout: named items plus the 56 indirect address/data pairs.
    pub fn xl430() -> Self {
        let mut owner = vec![None; TABLE_SIZE];
        let mut place = |it: Item| {
            for k in 0..it.size {
                owner[usize::from(it.address) + usize::from(k)] = Some((it, k));
            }
        };
        for it in NAMED_ITEMS {
            place(*it);
        }
        for n in 1..=INDIRECT_COUNT {
            // e-manual: the factory default of Indirect Address n is the address of
            // Indirect Data n (224 for n = 1), i.e. the data byte stands for itself.
            let data = indirect_data_addr(n);
            place(item(
                indirect_address_addr(n),
                2,
                "Indirect Address",
                RW,
                i64::from(data),
                Range::Fixed(64, 661),
            ));
            place(item(data, 1, "Indirect Data", RW, 0, Range::Fixed(0, 255)));
        }
        Self { owner }
    }

    /// The item covering `address` and the byte index inside it, or `None` for a reserved
    /// address or one past the end of the table.
    pub fn at(&self, address: usize) -> Option<(Item, u8)> {
        self.owner.get(address).copied().flatten()
    }

    /// All items, each once, in address order.
    pub fn items(&self) -> impl Iterator<Item = Item> + '_ {
        self.owner.iter().filter_map(|o| match o {
            Some((it, 0)) => Some(*it),
            _ => None,
        })
    }

    /// The factory-default table image.
    pub fn defaults(&self) -> [u8; TABLE_SIZE] {
        let mut table = [0u8; TABLE_SIZE];
        for it in self.items() {
            let bytes = (it.default as u32).to_le_bytes();
            let a = usize::from(it.address);
            table[a..a + usize::from(it.size)].copy_from_slice(&bytes[..usize::from(it.size)]);
        }
        table
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Guards the addresses and sizes that hosts depend on (e-manual XL430-W250 table).
    #[test]
    fn key_items_have_e_manual_addresses_and_sizes() {
        let layout = Layout::xl430();
        let check = |a: u16, size: u8, name: &str| {
            let (it, k) = layout.at(usize::from(a)).expect("item exists");
            assert_eq!((it.address, it.size, it.name, k), (a, size, name, 0));
        };
        check(0, 2, "Model Number");
        check(8, 1, "Baud Rate");
        check(11, 1, "Operating Mode");
        check(64, 1, "Torque Enable");
        check(98, 1, "Bus Watchdog");
        check(104, 4, "Goal Velocity");
        check(108, 4, "Profile Acceleration");
        check(112, 4, "Profile Velocity");
        check(120, 2, "Realtime Tick");
        check(128, 4, "Present Velocity");
        check(132, 4, "Present Position");
        check(578, 2, "Indirect Address");
        check(661, 1, "Indirect Data");
        // Reserved gaps stay unmapped.
        for a in [
            14usize, 19, 28, 30, 40, 56, 61, 66, 67, 71, 75, 86, 92, 99, 148, 167, 252, 577,
        ] {
            assert!(layout.at(a).is_none(), "address {a} must be reserved");
        }
        assert!(layout.at(TABLE_SIZE).is_none());
    }

    /// Guards the factory defaults a fresh servo must report (model 1060, baud index 1,
    /// ID 1, return delay 250, position mode, status return level 2).
    #[test]
    fn defaults_match_factory_values() {
        let t = Layout::xl430().defaults();
        assert_eq!(u16::from_le_bytes([t[0], t[1]]), 1060);
        assert_eq!(t[7], 1);
        assert_eq!(t[8], 1);
        assert_eq!(t[9], 250);
        assert_eq!(t[11], 3);
        assert_eq!(t[12], 255);
        assert_eq!(t[63], 52);
        assert_eq!(t[68], 2);
        assert_eq!(u32::from_le_bytes([t[44], t[45], t[46], t[47]]), 265);
        assert_eq!(u16::from_le_bytes([t[168], t[169]]), 224);
        assert_eq!(u16::from_le_bytes([t[632], t[633]]), 661);
    }

    /// Guards sign extension of signed items (e.g. negative Goal Velocity).
    #[test]
    fn decode_sign_extends_signed_items() {
        let layout = Layout::xl430();
        let (gv, _) = layout.at(104).unwrap();
        assert_eq!(gv.decode(&(-200i32).to_le_bytes()), -200);
        let (wd, _) = layout.at(98).unwrap();
        assert_eq!(wd.decode(&[0xFF]), -1);
        let (pv, _) = layout.at(112).unwrap();
        assert_eq!(pv.decode(&300u32.to_le_bytes()), 300);
    }
}
