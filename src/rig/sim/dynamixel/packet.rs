//! Protocol 2.0 framing: header, byte stuffing, CRC-16, and a resynchronizing stream decoder.
//!
//! A packet on the wire is `FF FF FD 00 | ID | LEN_L LEN_H | INST | body… | CRC_L CRC_H`
//! where `LEN` counts the (stuffed) instruction, body and CRC bytes. Byte stuffing inserts an
//! extra `FD` after every `FF FF FD` inside the instruction/body region; the CRC
//! (polynomial 0x8005, initial value 0, no reflection) covers the stuffed packet from the
//! first header byte up to the last body byte.
//!
//! This file owns only the bytes: it knows nothing about servos or control tables. The same
//! decoder reads instruction packets (device side) and status packets (tests, host checks);
//! for a status packet the instruction is `0x55` and the first body byte is the error field.

/// The four header bytes (three header bytes plus the reserved `00`).
pub const HEADER: [u8; 4] = [0xFF, 0xFF, 0xFD, 0x00];

/// Largest LEN field the decoder accepts. Default 1024: larger than any packet a host sends
/// to two XL430s (a sync write of the whole 662-byte table to one servo is 670), small
/// enough that a corrupted length resynchronizes after a short wait.
pub const MAX_LENGTH_FIELD: usize = 1024;

/// Broadcast ID: every device executes, only ping/sync read/bulk read are answered.
pub const BROADCAST_ID: u8 = 0xFE;

/// Instruction codes (e-manual, Protocol 2.0).
pub mod inst {
    /// Ping.
    pub const PING: u8 = 0x01;
    /// Read.
    pub const READ: u8 = 0x02;
    /// Write.
    pub const WRITE: u8 = 0x03;
    /// Reg Write (register, execute on Action).
    pub const REG_WRITE: u8 = 0x04;
    /// Action.
    pub const ACTION: u8 = 0x05;
    /// Factory Reset.
    pub const FACTORY_RESET: u8 = 0x06;
    /// Reboot.
    pub const REBOOT: u8 = 0x08;
    /// Clear (multi-turn information).
    pub const CLEAR: u8 = 0x10;
    /// Status (the instruction field of every reply).
    pub const STATUS: u8 = 0x55;
    /// Sync Read.
    pub const SYNC_READ: u8 = 0x82;
    /// Sync Write.
    pub const SYNC_WRITE: u8 = 0x83;
    /// Bulk Read.
    pub const BULK_READ: u8 = 0x92;
    /// Bulk Write.
    pub const BULK_WRITE: u8 = 0x93;
}

/// Error numbers of the status packet's error field (bits 0..6; bit 7 is the alert flag).
pub mod err {
    /// Failed to process the instruction.
    pub const RESULT_FAIL: u8 = 0x01;
    /// Undefined instruction, or Action without Reg Write.
    pub const INSTRUCTION: u8 = 0x02;
    /// CRC mismatch.
    pub const CRC: u8 = 0x03;
    /// Value outside the item's range.
    pub const DATA_RANGE: u8 = 0x04;
    /// Data shorter than the item (or malformed parameters).
    pub const DATA_LENGTH: u8 = 0x05;
    /// Value outside a limit set by another item.
    pub const DATA_LIMIT: u8 = 0x06;
    /// Read-only, undefined, or EEPROM while torque is on.
    pub const ACCESS: u8 = 0x07;
    /// Alert bit: a hardware error is latched (see Hardware Error Status).
    pub const ALERT: u8 = 0x80;
}

const fn crc_table() -> [u16; 256] {
    let mut table = [0u16; 256];
    let mut i = 0;
    while i < 256 {
        let mut crc = (i as u16) << 8;
        let mut bit = 0;
        while bit < 8 {
            crc = if crc & 0x8000 != 0 {
                (crc << 1) ^ 0x8005
            } else {
                crc << 1
            };
            bit += 1;
        }
        table[i] = crc;
        i += 1;
    }
    table
}

static CRC_TABLE: [u16; 256] = crc_table();

/// CRC-16 of Protocol 2.0 (polynomial 0x8005, MSB first, initial value 0).
pub fn crc16(bytes: &[u8]) -> u16 {
    bytes.iter().fold(0u16, |crc, &b| {
        (crc << 8) ^ CRC_TABLE[usize::from(((crc >> 8) as u8) ^ b)]
    })
}

/// Append `data` to `out` with byte stuffing (an `FD` after each `FF FF FD`), considering
/// the last bytes already in `out` from `region_start` on as part of the stuffed region.
fn push_stuffed(out: &mut Vec<u8>, region_start: usize, data: &[u8]) {
    for &b in data {
        out.push(b);
        let n = out.len();
        if b == 0xFD && n - region_start >= 3 && out[n - 3] == 0xFF && out[n - 2] == 0xFF {
            // Only a *fresh* FF FF FD triggers stuffing; the inserted FD itself must not be
            // the end of another pattern, which it cannot be (it follows FD).
            out.push(0xFD);
        }
    }
}

/// Remove byte stuffing: every `FF FF FD FD` becomes `FF FF FD`.
pub fn unstuff(stuffed: &[u8]) -> Vec<u8> {
    let mut out = Vec::with_capacity(stuffed.len());
    let mut i = 0;
    while i < stuffed.len() {
        let b = stuffed[i];
        out.push(b);
        let n = out.len();
        if b == 0xFD
            && n >= 3
            && out[n - 3] == 0xFF
            && out[n - 2] == 0xFF
            && stuffed.get(i + 1) == Some(&0xFD)
        {
            i += 1; // skip the stuffing byte
        }
        i += 1;
    }
    out
}

/// Encode a whole packet: header, ID, length, `instruction`, stuffed `body`, CRC.
pub fn encode(id: u8, instruction: u8, body: &[u8]) -> Vec<u8> {
    let mut out = Vec::with_capacity(10 + body.len() + body.len() / 8);
    out.extend_from_slice(&HEADER);
    out.push(id);
    out.extend_from_slice(&[0, 0]);
    let region = out.len();
    push_stuffed(&mut out, region, &[instruction]);
    push_stuffed(&mut out, region, body);
    let len = (out.len() - region + 2) as u16;
    out[5..7].copy_from_slice(&len.to_le_bytes());
    let crc = crc16(&out);
    out.extend_from_slice(&crc.to_le_bytes());
    out
}

/// Encode a status packet (instruction 0x55) with the given error field and parameters.
pub fn encode_status(id: u8, error: u8, params: &[u8]) -> Vec<u8> {
    let mut body = Vec::with_capacity(params.len() + 1);
    body.push(error);
    body.extend_from_slice(params);
    encode(id, inst::STATUS, &body)
}

/// One decoded packet, stuffing removed.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Packet {
    /// Packet ID.
    pub id: u8,
    /// Instruction field (0x55 for a status packet).
    pub instruction: u8,
    /// Everything after the instruction, unstuffed (for a status packet: error, then params).
    pub body: Vec<u8>,
}

/// What the decoder found next in the stream.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Decoded {
    /// A packet with a valid CRC.
    Packet(Packet),
    /// A complete packet whose CRC did not match (ID and instruction as received; they
    /// may themselves be damaged).
    CrcMismatch {
        /// Packet ID field as received.
        id: u8,
        /// Instruction field as received.
        instruction: u8,
    },
}

/// Counters of what the decoder threw away.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct DecoderStats {
    /// Valid packets returned.
    pub packets: u64,
    /// Complete packets with a CRC mismatch.
    pub crc_errors: u64,
    /// Bytes skipped while searching for a header (garbage, bad lengths, stale partials).
    pub skipped_bytes: u64,
}

/// A resynchronizing Protocol 2.0 stream decoder: push bytes as they arrive, pull packets.
///
/// Garbage before a header is skipped; a length field outside `3..=MAX_LENGTH_FIELD` or a
/// CRC mismatch makes the decoder resume the header search one byte after the rejected
/// header, so a corrupted packet never swallows the next good one for long.
#[derive(Debug, Default)]
pub struct Decoder {
    buf: Vec<u8>,
    stats: DecoderStats,
}

impl Decoder {
    /// An empty decoder.
    pub fn new() -> Self {
        Self::default()
    }

    /// Append received bytes.
    pub fn push(&mut self, bytes: &[u8]) {
        self.buf.extend_from_slice(bytes);
    }

    /// Bytes buffered but not yet part of a returned packet.
    pub fn pending(&self) -> usize {
        self.buf.len()
    }

    /// Drop any partial packet (used after an inter-byte timeout).
    pub fn discard_partial(&mut self) {
        self.stats.skipped_bytes += self.buf.len() as u64;
        self.buf.clear();
    }

    /// What has been decoded and skipped so far.
    pub fn stats(&self) -> DecoderStats {
        self.stats
    }

    fn skip(&mut self, n: usize) {
        let n = n.min(self.buf.len());
        self.stats.skipped_bytes += n as u64;
        self.buf.drain(..n);
    }

    /// The next complete packet (or CRC mismatch), or `None` when more bytes are needed.
    pub fn next_packet(&mut self) -> Option<Decoded> {
        loop {
            // Find the header.
            let start = self.buf.windows(4).position(|w| w == HEADER);
            match start {
                None => {
                    // Keep a possible header prefix at the end.
                    let keep = (1..=3)
                        .rev()
                        .find(|&k| {
                            self.buf.len() >= k && self.buf[self.buf.len() - k..] == HEADER[..k]
                        })
                        .unwrap_or(0);
                    let drop = self.buf.len() - keep;
                    self.skip(drop);
                    return None;
                }
                Some(s) if s > 0 => self.skip(s),
                Some(_) => {}
            }
            if self.buf.len() < 7 {
                return None;
            }
            let len = usize::from(u16::from_le_bytes([self.buf[5], self.buf[6]]));
            if !(3..=MAX_LENGTH_FIELD).contains(&len) {
                self.skip(1);
                continue;
            }
            let total = 7 + len;
            if self.buf.len() < total {
                return None;
            }
            let id = self.buf[4];
            let instruction = self.buf[7];
            let crc_rx = u16::from_le_bytes([self.buf[total - 2], self.buf[total - 1]]);
            if crc16(&self.buf[..total - 2]) != crc_rx {
                self.stats.crc_errors += 1;
                self.skip(1);
                return Some(Decoded::CrcMismatch { id, instruction });
            }
            let body = unstuff(&self.buf[8..total - 2]);
            self.buf.drain(..total);
            self.stats.packets += 1;
            return Some(Decoded::Packet(Packet {
                id,
                instruction,
                body,
            }));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn hex(s: &str) -> Vec<u8> {
        s.split_whitespace()
            .map(|b| u8::from_str_radix(b, 16).unwrap())
            .collect()
    }

    /// Guards the CRC against the e-manual's published packets (ping, read, write, status).
    #[test]
    fn crc_matches_e_manual_examples() {
        for pkt in [
            "FF FF FD 00 01 03 00 01 19 4E",
            "FF FF FD 00 01 07 00 55 00 06 04 26 65 5D",
            "FF FF FD 00 01 07 00 02 84 00 04 00 1D 15",
            "FF FF FD 00 01 08 00 55 00 A6 00 00 00 8C C0",
            "FF FF FD 00 01 09 00 03 74 00 00 02 00 00 CA 89",
            "FF FF FD 00 01 04 00 55 00 A1 0C",
            "FF FF FD 00 FE 09 00 82 84 00 04 00 01 02 CE FA",
            "FF FF FD 00 02 08 00 55 00 1F 08 00 00 BA BE",
            "FF FF FD 00 FE 11 00 83 74 00 04 00 01 96 00 00 00 02 AA 00 00 00 82 87",
            "FF FF FD 00 FE 0D 00 92 01 90 00 02 00 02 92 00 01 00 1A 05",
            "FF FF FD 00 01 08 00 10 01 44 58 4C 22 B1 DC",
        ] {
            let b = hex(pkt);
            let n = b.len();
            assert_eq!(
                crc16(&b[..n - 2]).to_le_bytes(),
                [b[n - 2], b[n - 1]],
                "{pkt}"
            );
        }
    }

    /// Guards the encoder: it must reproduce the e-manual's ping, read and write packets.
    #[test]
    fn encode_reproduces_e_manual_packets() {
        assert_eq!(
            encode(1, inst::PING, &[]),
            hex("FF FF FD 00 01 03 00 01 19 4E")
        );
        assert_eq!(
            encode(1, inst::READ, &[0x84, 0, 4, 0]),
            hex("FF FF FD 00 01 07 00 02 84 00 04 00 1D 15")
        );
        assert_eq!(
            encode(1, inst::WRITE, &[0x74, 0, 0, 2, 0, 0]),
            hex("FF FF FD 00 01 09 00 03 74 00 00 02 00 00 CA 89")
        );
        assert_eq!(
            encode_status(1, 0, &[0x06, 0x04, 0x26]),
            hex("FF FF FD 00 01 07 00 55 00 06 04 26 65 5D")
        );
        assert_eq!(
            encode(BROADCAST_ID, inst::SYNC_READ, &[0x84, 0, 4, 0, 1, 2]),
            hex("FF FF FD 00 FE 09 00 82 84 00 04 00 01 02 CE FA")
        );
    }

    /// Guards byte stuffing: `FF FF FD` in the body gains an `FD`, the length counts it,
    /// and decoding restores the original body.
    #[test]
    fn byte_stuffing_round_trips() {
        let body = [0x10, 0x00, 0xFF, 0xFF, 0xFD, 0x01, 0xFF, 0xFF, 0xFD];
        let pkt = encode(3, inst::WRITE, &body);
        // header(4) id(1) len(2) inst(1) body(9 + 2 stuffing) crc(2)
        assert_eq!(pkt.len(), 4 + 1 + 2 + 1 + 11 + 2);
        assert_eq!(u16::from_le_bytes([pkt[5], pkt[6]]), 1 + 11 + 2);
        assert_eq!(
            &pkt[8..19],
            &[0x10, 0x00, 0xFF, 0xFF, 0xFD, 0xFD, 0x01, 0xFF, 0xFF, 0xFD, 0xFD]
        );
        let mut d = Decoder::new();
        d.push(&pkt);
        assert_eq!(
            d.next_packet(),
            Some(Decoded::Packet(Packet {
                id: 3,
                instruction: inst::WRITE,
                body: body.to_vec()
            }))
        );
        // FF FF FD FD (stuffs to FF FF FD FD FD) and three FF before FD (stuffs the last
        // three) must survive too.
        for (tricky, stuffed_len) in [
            (vec![0xFF, 0xFF, 0xFD, 0xFD], 5),
            (vec![0x51, 0xFF, 0xFF, 0xFF, 0xFD, 0x01], 7),
        ] {
            let pkt = encode(1, inst::WRITE, &tricky);
            assert_eq!(pkt.len(), 8 + stuffed_len + 2, "{tricky:02X?}");
            let mut d = Decoder::new();
            d.push(&pkt);
            match d.next_packet() {
                Some(Decoded::Packet(p)) => assert_eq!(p.body, tricky),
                other => panic!("unexpected {other:?}"),
            }
        }
    }

    /// Guards resynchronization: garbage, a split packet, a corrupted packet and a bad
    /// length never hide the good packets around them.
    #[test]
    fn decoder_resynchronizes_after_garbage_and_corruption() {
        let good1 = encode(1, inst::PING, &[]);
        let mut bad = encode(2, inst::READ, &[132, 0, 4, 0]);
        bad[9] ^= 0x40;
        let good2 = encode(2, inst::READ, &[132, 0, 4, 0]);
        let mut stream = vec![0x00, 0xFF, 0x13, 0xFF, 0xFF];
        stream.extend_from_slice(&good1);
        stream.extend_from_slice(&[0xFF, 0xFF, 0xFD, 0x00, 0x01, 0xFF, 0xFF]); // absurd length
        stream.extend_from_slice(&bad);
        stream.extend_from_slice(&good2);
        let mut d = Decoder::new();
        let mut out = Vec::new();
        for chunk in stream.chunks(3) {
            d.push(chunk);
            while let Some(p) = d.next_packet() {
                out.push(p);
            }
        }
        let packets: Vec<_> = out
            .iter()
            .filter_map(|x| match x {
                Decoded::Packet(p) => Some((p.id, p.instruction)),
                Decoded::CrcMismatch { .. } => None,
            })
            .collect();
        assert_eq!(packets, vec![(1, inst::PING), (2, inst::READ)]);
        assert!(out
            .iter()
            .any(|x| matches!(x, Decoded::CrcMismatch { id: 2, .. })));
        assert_eq!(d.stats().packets, 2);
        assert!(d.stats().crc_errors >= 1);
        assert_eq!(d.pending(), 0);
    }

    /// Guards that a partial packet waits for its remaining bytes rather than being dropped.
    #[test]
    fn partial_packet_waits_for_more_bytes() {
        let pkt = encode(1, inst::READ, &[132, 0, 4, 0]);
        let mut d = Decoder::new();
        d.push(&pkt[..9]);
        assert_eq!(d.next_packet(), None);
        assert_eq!(d.pending(), 9);
        d.push(&pkt[9..]);
        assert!(matches!(d.next_packet(), Some(Decoded::Packet(_))));
    }
}
