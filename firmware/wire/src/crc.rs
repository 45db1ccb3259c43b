//! CRC-32 (ISO-HDLC, the one of Ethernet, zip and PNG) over a frame's payload.
//!
//! Owns only the checksum arithmetic; where the checksum sits in a frame is decided by
//! [`crate::frame`]. A 32-bit CRC rather than CRC-16 because sample batches reach several
//! hundred bytes, where CRC-16's error-detection guarantees thin out.

/// Reflected polynomial of CRC-32/ISO-HDLC.
const POLY: u32 = 0xEDB8_8320;

/// 256-entry lookup table, built at compile time.
const TABLE: [u32; 256] = {
    let mut table = [0u32; 256];
    let mut i = 0;
    while i < 256 {
        let mut c = i as u32;
        let mut k = 0;
        while k < 8 {
            c = if c & 1 != 0 { POLY ^ (c >> 1) } else { c >> 1 };
            k += 1;
        }
        table[i] = c;
        i += 1;
    }
    table
};

/// CRC-32/ISO-HDLC of `bytes` (init 0xFFFFFFFF, reflected, final xor 0xFFFFFFFF).
pub fn crc32(bytes: &[u8]) -> u32 {
    let mut c = 0xFFFF_FFFFu32;
    for &b in bytes {
        c = TABLE[((c ^ b as u32) & 0xFF) as usize] ^ (c >> 8);
    }
    c ^ 0xFFFF_FFFF
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Guards the table and bit order: the catalogue check value of CRC-32/ISO-HDLC.
    #[test]
    fn crc32_matches_catalogue_check_value() {
        assert_eq!(crc32(b"123456789"), 0xCBF4_3926);
        assert_eq!(crc32(b""), 0);
    }

    /// Guards that a single flipped bit anywhere changes the checksum.
    #[test]
    fn crc32_detects_every_single_bit_flip() {
        let data: [u8; 64] = core::array::from_fn(|i| (i * 37 + 11) as u8);
        let good = crc32(&data);
        for byte in 0..data.len() {
            for bit in 0..8 {
                let mut d = data;
                d[byte] ^= 1 << bit;
                assert_ne!(crc32(&d), good, "flip at byte {byte} bit {bit}");
            }
        }
    }
}
