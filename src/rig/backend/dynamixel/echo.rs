//! Detecting a port that echoes what the host writes, before `dynamixel2` opens it.
//!
//! A half-duplex RS-485 adapter without echo suppression (or a loopback plug) hands the
//! host its own instruction back before any servo answers. `dynamixel2` 0.9.1 takes the
//! echoed instruction packet for a status packet, and for a short one (a ping's length
//! field is 3) slices `buffer[9..8]` in `read_status_response_deadline` (`bus.rs:302`): the
//! bus thread panics. So the backend pings the driver once on the raw port first and
//! refuses the port when what comes back starts with the ping itself. The write-up for the
//! library's maintainers is in `docs/faults.md`.
//!
//! Owns the probe and the few bytes of Protocol 2.0 it needs (a ping packet and its
//! CRC-16); the protocol proper is `dynamixel2`'s.

use std::io::{Read, Write};
use std::path::Path;
use std::time::{Duration, Instant};

use crate::rig::RigError;

/// How long the probe waits for the echo (and for a servo's reply to the probe, which it
/// reads and drops so it cannot be taken for the answer to the next instruction): the
/// ping's and its reply's wire time plus 34 ms, the flat margin ROBOTIS's SDK allows.
fn probe_wait(baud: u32) -> Duration {
    let bits = (PING_LEN + PING_REPLY_LEN) as f64 * 10.0;
    Duration::from_secs_f64(bits / f64::from(baud.max(1))) + Duration::from_millis(34)
}

/// A ping instruction packet is 10 bytes.
const PING_LEN: usize = 10;
/// A servo's status reply to a ping is 14 bytes.
const PING_REPLY_LEN: usize = 14;

/// CRC-16 of Protocol 2.0: polynomial 0x8005, initial value 0, MSB first, no reflection.
pub fn crc16(bytes: &[u8]) -> u16 {
    let mut crc: u16 = 0;
    for &b in bytes {
        crc ^= u16::from(b) << 8;
        for _ in 0..8 {
            crc = if crc & 0x8000 != 0 {
                (crc << 1) ^ 0x8005
            } else {
                crc << 1
            };
        }
    }
    crc
}

/// The ping instruction packet for servo `id`.
pub fn ping_packet(id: u8) -> [u8; PING_LEN] {
    let mut p = [0xFF, 0xFF, 0xFD, 0x00, id, 0x03, 0x00, 0x01, 0, 0];
    let crc = crc16(&p[..8]).to_le_bytes();
    p[8..].copy_from_slice(&crc);
    p
}

/// Whether the port at `path` sends back the ping written to it (to servo `id`, at
/// `baud`) as the first thing it receives.
pub fn port_echoes(path: &Path, baud: u32, id: u8) -> Result<bool, RigError> {
    let open_err = |e: serialport::Error| RigError::Open {
        path: path.to_path_buf(),
        message: e.to_string(),
    };
    let io_err = |e: std::io::Error| RigError::Io {
        path: path.to_path_buf(),
        message: format!("probing for an echo: {e}"),
    };
    let mut port = serialport::new(path.to_string_lossy(), baud)
        .timeout(Duration::from_millis(5))
        .open_native()
        .map_err(open_err)?;
    serialport::SerialPort::clear(&port, serialport::ClearBuffer::Input).map_err(open_err)?;
    let ping = ping_packet(id);
    port.write_all(&ping).map_err(io_err)?;
    let deadline = Instant::now() + probe_wait(baud);
    let mut got = Vec::with_capacity(PING_LEN + PING_REPLY_LEN);
    let mut buf = [0u8; 64];
    while Instant::now() < deadline && got.len() < PING_LEN + PING_REPLY_LEN {
        match port.read(&mut buf) {
            Ok(n) => got.extend_from_slice(&buf[..n]),
            Err(e) if e.kind() == std::io::ErrorKind::TimedOut => {}
            Err(e) => return Err(io_err(e)),
        }
        // A servo that answered without an echo: nothing more to wait for.
        if got.len() >= PING_REPLY_LEN && !got.starts_with(&ping[..PING_LEN.min(got.len())]) {
            break;
        }
    }
    Ok(got.starts_with(&ping))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Guards the packet the probe sends: the e-manual's ping example for ID 1 is
    /// `FF FF FD 00 01 03 00 01 19 4E`.
    #[test]
    fn ping_packet_matches_the_e_manual() {
        assert_eq!(
            ping_packet(1),
            [0xFF, 0xFF, 0xFD, 0x00, 0x01, 0x03, 0x00, 0x01, 0x19, 0x4E]
        );
    }
}
