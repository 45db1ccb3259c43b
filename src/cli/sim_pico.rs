//! `mpc-rig sim-device pico`: serve the emulated board (the board image in rp2040js) on a
//! pseudo-terminal until stopped.
//!
//! Prints the pseudo-terminal path on the first line of standard output, like the other
//! simulated devices, then serves until Ctrl-C or until the board stops by itself. Only
//! argument handling lives here; the board is [`crate::rig::sim::pico`].

use std::io::Write;
use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::Context;
use clap::Args;

use super::sim_device::{
    geometry_plant, load_target, serve_until_ctrl_c, GeometryArgs, TargetArgs,
};
use crate::rig::config::RigConfig;
use crate::rig::sim::pico::{self, BoardFiles, SimPicoOptions, DEFAULT_FLASH_ID};
use crate::rig::sim::stepper::Mechanics;

/// Options of `sim-device pico`.
#[derive(Debug, Args)]
pub struct SimPicoArgs {
    /// The motion to serve.
    #[command(flatten)]
    pub target: TargetArgs,
    /// Plant imperfection or byte fault, `key=value`, repeatable (unplug, drop-out, stall,
    /// reboot and protocol faults are refused; the keys are listed by --help).
    #[arg(long = "fault", value_name = "KEY=VALUE", long_help = fault_keys_help!(
        "Plant imperfection or byte fault, repeatable. Unplug, drop-out, stall, reboot and protocol faults are refused here."
    ))]
    pub faults: Vec<String>,
    /// The geometry plant.
    #[command(flatten)]
    pub geometry: GeometryArgs,
    /// Take the bench's mechanics (steps/rev, microsteps, gear, direction, fitted sensors)
    /// from this rig file; default: those of rigs/sim-stepper.toml.
    #[arg(long, value_name = "FILE")]
    pub rig: Option<PathBuf>,
    /// The checkout whose firmware/ holds the image, the boot ROM and the harness.
    #[arg(long, value_name = "DIR", default_value = ".")]
    pub checkout: PathBuf,
    /// Run this board image (ELF) instead of the checkout's release build.
    #[arg(long, value_name = "ELF")]
    pub image: Option<PathBuf>,
    /// The emulated flash chip's 64-bit unique ID, 16 hex digits (the board's USB serial
    /// number is made from it; give two boards different IDs).
    #[arg(long, value_name = "HEX", value_parser = parse_flash_id)]
    pub flash_id: Option<u64>,
    /// Node.js to run the emulator with.
    #[arg(long, value_name = "PROGRAM", default_value = "node")]
    pub node: PathBuf,
    /// Also expose the port at this path (a symlink), like a udev name.
    #[arg(long, value_name = "PATH")]
    pub link: Option<PathBuf>,
    /// Append the board's defmt log frames to this file (decode them with
    /// `defmt-print -e IMAGE < FILE`).
    #[arg(long, value_name = "FILE")]
    pub defmt_log: Option<PathBuf>,
    /// Record both directions of the link in this directory (to-device.bin, to-host.bin)
    /// for `mpc-rig wire-dump`.
    #[arg(long, value_name = "DIR")]
    pub capture: Option<PathBuf>,
}

fn parse_flash_id(s: &str) -> Result<u64, String> {
    if s.len() != 16 {
        return Err(format!("`{s}`: expected 16 hex digits, got {}", s.len()));
    }
    u64::from_str_radix(s, 16).map_err(|e| format!("`{s}`: {e}"))
}

/// Run `sim-device pico`.
pub fn run(a: SimPicoArgs) -> anyhow::Result<ExitCode> {
    let target = load_target(&a.target, None)?;
    let plant = geometry_plant(&a.faults, &a.geometry, &target)?;
    let motion = target.motion;
    let mechanics = match &a.rig {
        Some(r) => Mechanics::from_rig(&RigConfig::load(r)?)?,
        None => Mechanics::default(),
    };
    let mut files = BoardFiles::in_repo(&a.checkout);
    files.node = a.node;
    if let Some(image) = a.image {
        files.image = image;
    }
    let image = files.image.clone();
    let sim = pico::spawn(SimPicoOptions {
        target: motion,
        plant,
        mechanics,
        files,
        flash_id: a.flash_id.unwrap_or(DEFAULT_FLASH_ID),
        link: a.link,
        defmt_log: a.defmt_log,
        capture: a.capture,
    })
    .context("starting the emulated board")?;
    {
        let mut out = std::io::stdout().lock();
        writeln!(out, "{}", sim.path().display())?;
        out.flush()?;
    }
    eprintln!(
        "emulated board (rp2040js, image {}) on {}; Ctrl-C stops",
        image.display(),
        sim.path().display()
    );
    serve_until_ctrl_c(|| sim.is_running())?;
    let status = sim.stop().context("the emulated board")?;
    eprintln!(
        "emulated board ended after {:.1} s of board time: driver at {} microsteps, USB serial number {}, {} bytes out ({} dropped, {} corrupted), I²C transfers A {} B {}, at most {:.0} ms behind the wall clock",
        status.time_s,
        status.steps,
        status
            .usb
            .as_ref()
            .and_then(|u| u.serial.as_deref())
            .unwrap_or("(not enumerated)"),
        status.bytes_out,
        status.bytes_dropped,
        status.bytes_corrupted,
        status.i2c_transfers[0],
        status.i2c_transfers[1],
        status.max_behind_s * 1e3,
    );
    Ok(match status.halted {
        Some(reason) => {
            eprintln!("the board stopped: {reason}");
            ExitCode::FAILURE
        }
        None => ExitCode::SUCCESS,
    })
}
