//! The board's identity on USB: its serial number, made from the 64-bit unique ID that every
//! RP2040 board's QSPI flash chip carries (the chip's "Read Unique ID" command), so that two
//! boards on one host have different serial numbers and a rig can name its board by serial
//! (`usb_serial` in `rigs/*.toml`).
//!
//! The format is the Pico SDK's (`pico_get_unique_board_id_string`): the ID's 8 bytes in
//! order as 16 upper-case hex digits, so a board shows the same serial number under this
//! firmware as under SDK-built ones. Owns the formatting only; reading the ID is the board's.

/// Length of the serial number, characters.
pub const SERIAL_NUMBER_LEN: usize = 16;

/// A USB serial number made from a flash unique ID.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SerialNumber([u8; SERIAL_NUMBER_LEN]);

impl SerialNumber {
    /// The serial number of the board whose flash has `unique_id`.
    pub const fn from_unique_id(unique_id: [u8; 8]) -> SerialNumber {
        const HEX: &[u8; 16] = b"0123456789ABCDEF";
        let mut s = [0u8; SERIAL_NUMBER_LEN];
        let mut i = 0;
        while i < 8 {
            s[2 * i] = HEX[(unique_id[i] >> 4) as usize];
            s[2 * i + 1] = HEX[(unique_id[i] & 0x0f) as usize];
            i += 1;
        }
        SerialNumber(s)
    }

    /// The serial number as text.
    pub fn as_str(&self) -> &str {
        // Only ASCII hex digits are ever stored.
        core::str::from_utf8(&self.0).unwrap_or("")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Guards the SDK's format: bytes in order, upper-case hex, two digits each.
    #[test]
    fn serial_number_is_the_id_in_upper_case_hex() {
        let s = SerialNumber::from_unique_id([0xe6, 0x61, 0x4c, 0x31, 0x1b, 0x4a, 0x7a, 0x08]);
        assert_eq!(s.as_str(), "E6614C311B4A7A08");
        assert_eq!(
            SerialNumber::from_unique_id([0; 8]).as_str(),
            "0000000000000000"
        );
    }
}
