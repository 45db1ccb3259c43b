//! The command line: one file per subcommand.
//!
//! Each subcommand only parses its arguments and calls into the library modules; no
//! synthesis, geometry, bench or analysis logic lives here. This is the only place (with
//! `main.rs`) where `anyhow` is used: library errors are typed and converted at this edge.

use std::process::ExitCode;

use clap::{Parser, Subcommand};

pub mod analyze;
pub mod build;
pub mod demo;
pub mod measure;
pub mod motion;
pub mod ports;
pub mod sim_device;
pub mod sim_pico;
pub mod synth;
pub mod wire_dump;

/// Design, fabricate and bench-verify multi-point conjugation mechanisms.
#[derive(Debug, Parser)]
#[command(name = "mpc-rig", version, about, long_about = None)]
pub struct Cli {
    /// More log output (-v info, -vv debug, -vvv trace).
    #[arg(short, long, action = clap::ArgAction::Count, global = true)]
    pub verbose: u8,
    /// Only errors.
    #[arg(short, long, global = true, conflicts_with = "verbose")]
    pub quiet: bool,
    /// What to do.
    #[command(subcommand)]
    pub command: Command,
}

/// The subcommands.
#[derive(Debug, Subcommand)]
pub enum Command {
    /// Compare a recording with its target law and write the report (plots, report.md,
    /// report.html, summary.json).
    Analyze(analyze::AnalyzeArgs),
    /// Printable parts from a mechanism: STL, 3MF and an animated GLB, with their checks.
    Build(build::BuildArgs),
    /// The main job on a simulated bench: synthesize the example, measure it, report.
    Demo(demo::DemoArgs),
    /// Check, plot and sample motion specifications.
    Motion(motion::MotionArgs),
    /// List serial ports with USB vendor/product/serial where known.
    Ports(ports::PortsArgs),
    /// Synthesize conjugate curve pairs with dynamic form closure, or check a mechanism file.
    Synth(synth::SynthArgs),
    /// Serve a simulated bench device on a pseudo-terminal (prints its path first).
    SimDevice(sim_device::SimDeviceArgs),
    /// Measure a mechanism on a bench (real or simulated) and record it.
    Measure(measure::MeasureArgs),
    /// Print a captured byte stream of the bench link frame by frame, to debug a link.
    WireDump(wire_dump::WireDumpArgs),
}

/// Set up `tracing` output on stderr from the -v/-q flags (`RUST_LOG` overrides).
pub fn init_logging(verbose: u8, quiet: bool) {
    let level = if quiet {
        "error"
    } else {
        match verbose {
            0 => "warn",
            1 => "info",
            2 => "debug",
            _ => "trace",
        }
    };
    let filter = tracing_subscriber::EnvFilter::try_from_default_env()
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new(level));
    let _ = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .with_target(false)
        .try_init();
}

/// Run a parsed command line.
pub fn run(cli: Cli) -> anyhow::Result<ExitCode> {
    match cli.command {
        Command::Analyze(args) => analyze::run(args),
        Command::Build(args) => build::run(args),
        Command::Demo(args) => demo::run(args),
        Command::Motion(args) => motion::run(args),
        Command::Ports(args) => ports::run(args),
        Command::Synth(args) => synth::run(args),
        Command::SimDevice(args) => sim_device::run(args),
        Command::Measure(args) => measure::run(args),
        Command::WireDump(args) => wire_dump::run(args),
    }
}

/// Exit code for an error that reached the binary edge: 1 unless a subcommand asked for
/// another one by returning an [`ExitStatusError`] somewhere in the chain.
pub fn exit_code_for(err: &anyhow::Error) -> u8 {
    err.chain()
        .find_map(|cause| cause.downcast_ref::<ExitStatusError>())
        .map_or(1, |e| e.code)
}

/// An error that carries the process exit code the binary should end with.
#[derive(Debug, thiserror::Error)]
#[error("{message}")]
pub struct ExitStatusError {
    /// Exit code (non-zero).
    pub code: u8,
    /// What went wrong, for the user.
    pub message: String,
}
