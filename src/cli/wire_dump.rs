//! `mpc-rig wire-dump FILE`: print a captured byte stream of the bench link frame by frame
//! (offset, sender, sequence number, message; damaged frames with the reason and their
//! bytes), then the sequence gaps of each side. Only printing lives here; the reading is
//! [`mpc_wire::dump`].

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::{bail, Context};
use clap::Args;
use mpc_wire::dump::{dump, Decoded};
use mpc_wire::Report;

/// Options of `wire-dump`.
#[derive(Debug, Args)]
pub struct WireDumpArgs {
    /// The capture: the raw bytes of one direction of the link or of both (for example
    /// `sim-device pico --capture DIR`'s to-device.bin and to-host.bin).
    #[arg(value_name = "FILE")]
    pub file: PathBuf,
    /// The file holds hex digits (whitespace and line breaks between bytes allowed), as
    /// `xxd -p` writes them, instead of raw bytes.
    #[arg(long)]
    pub hex: bool,
    /// Also print every frame's bytes (damaged frames always show theirs).
    #[arg(long)]
    pub raw: bool,
}

fn parse_hex(text: &str) -> anyhow::Result<Vec<u8>> {
    let digits: Vec<(usize, char)> = text
        .char_indices()
        .filter(|(_, c)| !c.is_whitespace())
        .collect();
    if let Some((at, c)) = digits.iter().find(|(_, c)| !c.is_ascii_hexdigit()) {
        bail!("`{c}` at character {at} is not a hex digit");
    }
    if digits.len() % 2 != 0 {
        bail!("an odd number of hex digits ({})", digits.len());
    }
    Ok(digits
        .chunks(2)
        .map(|p| {
            let hi = p[0].1.to_digit(16).unwrap_or(0);
            let lo = p[1].1.to_digit(16).unwrap_or(0);
            (hi * 16 + lo) as u8
        })
        .collect())
}

fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

/// A sample batch in one line: its length, fields and the time and position they span.
fn describe(report: &Report) -> String {
    match report {
        Report::Samples(b) => match (b.samples().first(), b.samples().last()) {
            (Some(first), Some(last)) => format!(
                "Samples: {} × {:?}, t {}..{} µs, position {}..{}",
                b.len(),
                b.fields,
                first.timestamp_us,
                last.timestamp_us,
                first.position,
                last.position
            ),
            _ => format!("Samples: none, {:?}", b.fields),
        },
        other => format!("{other:?}"),
    }
}

/// Run `wire-dump`.
pub fn run(a: WireDumpArgs) -> anyhow::Result<ExitCode> {
    let bytes = std::fs::read(&a.file).with_context(|| format!("reading {}", a.file.display()))?;
    let bytes = if a.hex {
        let text = String::from_utf8(bytes).with_context(|| {
            format!("{}: not text (drop --hex for raw bytes)", a.file.display())
        })?;
        parse_hex(&text).with_context(|| format!("{}", a.file.display()))?
    } else {
        bytes
    };
    let d = dump(&bytes);
    let (mut host, mut device, mut cut) = (0, 0, 0);
    for f in &d.frames {
        let (who, what) = match &f.decoded {
            Decoded::Command(c) => {
                host += 1;
                ("host  ", format!("seq {:>5}  {:?}", c.seq, c.msg))
            }
            Decoded::Report(r) => {
                device += 1;
                ("device", format!("seq {:>5}  {}", r.seq, describe(&r.msg)))
            }
            Decoded::Bad {
                as_report,
                as_command,
            } => (
                "BAD   ",
                if as_report == as_command {
                    format!("{as_report}")
                } else {
                    format!("not a report: {as_report}; not a command: {as_command}")
                },
            ),
            Decoded::Cut => {
                cut += 1;
                ("CUT   ", "the capture ends inside this frame".to_string())
            }
        };
        println!("{:>8}  {who}  {what}", f.offset);
        if a.raw || matches!(f.decoded, Decoded::Bad { .. } | Decoded::Cut) {
            println!("{:>8}  {}", "", hex(&f.raw));
        }
    }
    println!(
        "{} frames: {host} from the host, {device} from the device, {} damaged, {cut} cut; \
         device sequence: {} lost, {} repeated or out of order; host sequence: {} lost, {} repeated (retries) or out of order",
        d.frames.len(),
        d.bad(),
        d.device.lost,
        d.device.out_of_order,
        d.host.lost,
        d.host.out_of_order,
    );
    Ok(ExitCode::SUCCESS)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Guards the hex input: whitespace between digits is ignored, a stray character and an
    /// odd digit count are errors naming what is wrong.
    #[test]
    fn hex_input() {
        assert_eq!(parse_hex("01 0a\nff").unwrap(), vec![1, 10, 255]);
        let e = parse_hex("01 0g").unwrap_err().to_string();
        assert!(e.contains("`g` at character 4"), "{e}");
        let e = parse_hex("010").unwrap_err().to_string();
        assert!(e.contains("odd number of hex digits (3)"), "{e}");
    }
}
