//! Decoding a captured byte stream frame by frame, to debug a link, as Klipper's
//! `scripts/parsedump.py` does for its protocol: every frame with its offset in the capture,
//! its sequence number and its message, or why it could not be decoded, and the sequence
//! gaps of each direction.
//!
//! A capture holds one direction of the link (what the host wrote, or what the device sent)
//! or both interleaved; commands and reports have disjoint tags (below and above 0x80), so
//! each frame says which side sent it. Owns this frame-by-frame reading; printing it is the
//! caller's (`mpc-rig wire-dump`).

use std::boxed::Box;
use std::vec::Vec;

use crate::host::GapCounter;
use crate::{Command, Decoder, Frame, FrameError, Report};

/// One frame of a capture.
#[derive(Debug, Clone, PartialEq)]
pub struct DumpedFrame {
    /// Offset of its first byte in the capture.
    pub offset: usize,
    /// Its bytes on the wire, the 0x00 delimiter included.
    pub raw: Vec<u8>,
    /// What it holds.
    pub decoded: Decoded,
}

/// What a frame holds.
#[derive(Debug, Clone, PartialEq)]
pub enum Decoded {
    /// A command from the host.
    Command(Frame<Command>),
    /// A report from the device (boxed: a sample batch is large).
    Report(Box<Frame<Report>>),
    /// Neither: why, as a report and as a command (the same reason when it lies in the
    /// framing, before the message).
    Bad {
        /// Why it is not a report.
        as_report: FrameError,
        /// Why it is not a command.
        as_command: FrameError,
    },
    /// The capture ends inside this frame (no closing delimiter).
    Cut,
}

/// A capture read frame by frame.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Dump {
    /// The frames, in capture order.
    pub frames: Vec<DumpedFrame>,
    /// Sequence numbers of the host's frames (retries repeat a number: out of order).
    pub host: GapCounter,
    /// Sequence numbers of the device's frames.
    pub device: GapCounter,
}

impl Dump {
    /// Frames that could not be decoded (a cut last frame not included).
    pub fn bad(&self) -> usize {
        self.frames
            .iter()
            .filter(|f| matches!(f.decoded, Decoded::Bad { .. }))
            .count()
    }
}

/// Read a capture frame by frame. Empty frames (runs of 0x00, which the host sends to flush
/// a half-received frame) are skipped.
pub fn dump(bytes: &[u8]) -> Dump {
    let mut reports = Decoder::<Report>::new();
    let mut commands = Decoder::<Command>::new();
    let mut out = Dump::default();
    let mut start = 0;
    for (i, &b) in bytes.iter().enumerate() {
        let report = reports.push(b);
        let command = commands.push(b);
        if b != 0 {
            continue;
        }
        let raw = bytes[start..=i].to_vec();
        let offset = start;
        start = i + 1;
        let decoded = match (report, command) {
            (None, None) => continue,
            (Some(Ok(f)), _) => {
                out.device.observe(f.seq);
                Decoded::Report(Box::new(f))
            }
            (_, Some(Ok(f))) => {
                out.host.observe(f.seq);
                Decoded::Command(f)
            }
            (Some(Err(as_report)), Some(Err(as_command))) => Decoded::Bad {
                as_report,
                as_command,
            },
            // Both decoders see the same bytes, so they end frames together.
            (Some(Err(e)), None) | (None, Some(Err(e))) => Decoded::Bad {
                as_report: e,
                as_command: e,
            },
        };
        out.frames.push(DumpedFrame {
            offset,
            raw,
            decoded,
        });
    }
    if bytes[start..].iter().any(|&b| b != 0) {
        out.frames.push(DumpedFrame {
            offset: start,
            raw: bytes[start..].to_vec(),
            decoded: Decoded::Cut,
        });
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::golden;
    use std::vec;

    /// Guards the reading of an interleaved capture: every golden frame comes back with its
    /// offset, direction and message; a damaged frame is named with its CRC error and the
    /// reading goes on at the next frame; flush bytes are skipped; a cut end is reported;
    /// and a missing device frame shows as a gap.
    #[test]
    fn reads_golden_frames_and_damage() {
        let frame = |name: &str| {
            golden::cases()
                .iter()
                .find(|c| c.name == name)
                .expect("a golden case")
                .encode()
        };
        let hello = frame("cmd_hello");
        let rep_hello = frame("rep_hello");
        let ack = frame("rep_ack_ok");
        let status = frame("rep_status");
        let mut damaged = frame("rep_event_watchdog");
        damaged[3] ^= 0x10;
        let mut capture = vec![0, 0];
        let mut offsets = Vec::new();
        for f in [&hello, &rep_hello, &ack, &damaged, &status] {
            offsets.push(capture.len());
            capture.extend_from_slice(f);
        }
        capture.extend_from_slice(&[0x05, 0x01]);
        let d = dump(&capture);
        assert_eq!(d.frames.len(), 6);
        assert_eq!(
            d.frames.iter().map(|f| f.offset).collect::<Vec<_>>()[..5],
            offsets[..]
        );
        assert!(matches!(
            d.frames[0].decoded,
            Decoded::Command(Frame {
                seq: 0,
                msg: Command::Hello { .. }
            })
        ));
        assert!(matches!(
            &d.frames[1].decoded,
            Decoded::Report(f) if f.seq == 0 && matches!(f.msg, Report::Hello(_))
        ));
        assert_eq!(d.frames[2].raw, ack);
        assert!(matches!(
            d.frames[3].decoded,
            Decoded::Bad {
                as_report: FrameError::Crc { .. },
                ..
            }
        ));
        assert!(matches!(&d.frames[4].decoded, Decoded::Report(f) if f.seq == 3));
        assert_eq!(d.frames[5].decoded, Decoded::Cut);
        assert_eq!(d.bad(), 1);
        // Device frames 0, 1 and 3 decoded (the damaged one was 5): 2 is missing.
        assert_eq!((d.device.received, d.device.lost), (3, 1));
        assert_eq!(d.host.received, 1);
    }
}
