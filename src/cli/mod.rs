//! The command line: one file per subcommand.
//!
//! Each subcommand only parses its arguments and calls into the library modules; no
//! synthesis, geometry, bench or analysis logic lives here. This is the only place (with
//! `main.rs`) where `anyhow` is used: library errors are typed and converted at this edge.

use std::io::IsTerminal;
use std::process::ExitCode;

use clap::{Parser, Subcommand};

/// The `--fault` keys for the long help of every command that takes them (one list, the
/// plant's [`crate::rig::sim::plant::FAULT_KEYS`] and short names; a test keeps them equal).
macro_rules! fault_keys_help {
    ($what:literal) => {
        concat!(
            $what,
            "\n\nKeys:\n",
            "  backlash_deg (or backlash): dead band between driver and follower, deg\n",
            "  phase_lag_deg (or phase_lag): follower lags the driver by this angle, deg\n",
            "  gain_error: relative encoder scale error, e.g. 0.01\n",
            "  encoder_noise_counts (or encoder_noise): encoder noise standard deviation, counts\n",
            "  encoder_resolution: encoder quantization, counts per turn\n",
            "  imu_noise_deg (or imu_noise): IMU noise standard deviation, deg\n",
            "  imu_bias_deg (or imu_bias): IMU constant rotation bias, deg\n",
            "  missed_step_prob: probability a step pulse is lost\n",
            "  scale_mm: mm per model unit for heights\n",
            "  drop_prob: probability a byte to the host is dropped\n",
            "  corrupt_prob: probability a byte to the host is corrupted\n",
            "  disconnect_at_s: unplug for good at this time, s\n",
            "  dropout_at_s: brief unplug starting at this time, s\n",
            "  dropout_s: length of the brief unplug, s (default 0.5)\n",
            "  stall_at_s: Dynamixel bus: replies held back from this time, s\n",
            "  stall_s: length of the stall, s (default 0.06)\n",
            "  reboot_at_s: Dynamixel bus: the driver reboots at this time, s (a brown-out)\n",
            "  driver_fault_at_s: the driver reports a hardware fault (overload, firmware e-stop) at this time, s\n",
            "  driver_stall_at_s: the driver's shaft is blocked from this time, s (no fault reported)\n",
            "  jam_at_s: the follower binds and stops from this time, s\n",
            "  echo: Dynamixel bus: 1 echoes every byte the host sends (adapter without echo suppression)\n",
            "  protocol_version: protocol version the simulated device claims\n",
            "  seed: seed of the simulated randomness"
        )
    };
}

pub mod analyze;
pub mod build;
pub mod completions;
pub mod demo;
pub mod measure;
pub mod motion;
pub mod ports;
pub mod sim_device;
pub mod sim_pico;
pub mod simulate;
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
    /// Predict how the built parts move the follower (the virtual prototype).
    Simulate(simulate::SimulateArgs),
    /// Print a captured byte stream of the bench link frame by frame, to debug a link.
    WireDump(wire_dump::WireDumpArgs),
    /// Print a shell completion script (bash, zsh, fish, elvish, powershell).
    ///
    /// Where to put it — bash: `mpc-rig completions bash >
    /// ~/.local/share/bash-completion/completions/mpc-rig`; zsh: `mpc-rig completions zsh >
    /// ~/.zfunc/_mpc-rig` (with `fpath+=~/.zfunc` before `compinit` in ~/.zshrc); fish:
    /// `mpc-rig completions fish > ~/.config/fish/completions/mpc-rig.fish`.
    Completions(completions::CompletionsArgs),
}

/// Set by `-q`: commands leave out the lists of files they wrote (issue 20: `-q` still
/// printed them); results and errors are still printed.
static QUIET: std::sync::atomic::AtomicBool = std::sync::atomic::AtomicBool::new(false);

/// Whether `-q` was given (see [`QUIET`]).
pub(crate) fn quiet() -> bool {
    QUIET.load(std::sync::atomic::Ordering::Relaxed)
}

/// Set up `tracing` output on stderr from the -v/-q flags (`RUST_LOG` overrides), and
/// remember `-q` for the commands' file lists.
pub fn init_logging(verbose: u8, quiet: bool) {
    QUIET.store(quiet, std::sync::atomic::Ordering::Relaxed);
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
        .with_writer(|| LogWriter)
        .with_ansi(colour_on(
            std::io::stderr().is_terminal(),
            std::env::var_os("NO_COLOR").as_deref(),
        ))
        .with_target(false)
        .try_init();
}

/// Set while a live status line, ended by `\r` and no newline, is the last thing on
/// standard error (`measure` on a terminal).
static STATUS_LINE: std::sync::atomic::AtomicBool = std::sync::atomic::AtomicBool::new(false);

/// A status line was just printed with `\r` and no newline: the next log line starts on
/// a line of its own.
pub(crate) fn status_line_shown() {
    STATUS_LINE.store(true, std::sync::atomic::Ordering::Relaxed);
}

/// The status line was ended by a newline.
pub(crate) fn status_line_ended() {
    STATUS_LINE.store(false, std::sync::atomic::Ordering::Relaxed);
}

/// Where log lines go: standard error, after a newline when a status line is showing
/// (issue 20: timestamped WARN lines were glued onto the live status line).
struct LogWriter;

impl std::io::Write for LogWriter {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        write_log(&mut std::io::stderr().lock(), &STATUS_LINE, buf)
    }

    fn flush(&mut self) -> std::io::Result<()> {
        std::io::stderr().flush()
    }
}

/// Write `buf` to `out`, ending a showing status line first (`status` says whether one
/// shows; it is cleared).
fn write_log(
    out: &mut impl std::io::Write,
    status: &std::sync::atomic::AtomicBool,
    buf: &[u8],
) -> std::io::Result<usize> {
    if status.swap(false, std::sync::atomic::Ordering::Relaxed) {
        out.write_all(b"\n")?;
    }
    out.write(buf)
}

/// Whether to colour a stream: only a terminal, and only without `NO_COLOR` set to
/// something (no-color.org); a pipe or a file gets plain text (issue 20: escape codes in
/// captured logs).
fn colour_on(terminal: bool, no_color: Option<&std::ffi::OsStr>) -> bool {
    terminal && no_color.is_none_or(|v| v.is_empty())
}

/// The mechanism file a command was given: `PATH` itself, or `PATH/mechanism.json` when
/// `PATH` is a folder (the one `mpc-rig synth -o` writes).
pub fn mechanism_file(path: &std::path::Path) -> std::path::PathBuf {
    if path.is_dir() {
        path.join(crate::motion::MECHANISM_FILE)
    } else {
        path.to_path_buf()
    }
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
        Command::Simulate(args) => simulate::run(args),
        Command::WireDump(args) => wire_dump::run(args),
        Command::Completions(args) => completions::run(args),
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

#[cfg(test)]
mod colour_tests {
    use std::ffi::OsStr;
    use std::sync::atomic::AtomicBool;

    use super::{colour_on, write_log};

    /// Guards log lines on their own line: with a status line showing, a log line starts
    /// after a newline, once; without one, it is written as is.
    #[test]
    fn a_log_line_does_not_glue_onto_the_status_line() {
        let status = AtomicBool::new(true);
        let mut out = Vec::new();
        write_log(&mut out, &status, b"WARN one\n").unwrap();
        write_log(&mut out, &status, b"WARN two\n").unwrap();
        assert_eq!(String::from_utf8(out).unwrap(), "\nWARN one\nWARN two\n");
    }

    /// Guards colour only on a terminal: never into a pipe or file, never with `NO_COLOR`
    /// set to a value, and an empty `NO_COLOR` counts as unset (no-color.org).
    #[test]
    fn colour_only_on_a_terminal_without_no_color() {
        assert!(colour_on(true, None));
        assert!(!colour_on(false, None));
        assert!(!colour_on(true, Some(OsStr::new("1"))));
        assert!(colour_on(true, Some(OsStr::new(""))));
        assert!(!colour_on(false, Some(OsStr::new(""))));
    }
}

#[cfg(test)]
mod fault_help_tests {
    use clap::CommandFactory;

    use super::Cli;
    use crate::rig::sim::plant::{FAULT_ALIASES, FAULT_KEYS};

    /// Guards one list of fault keys (issue 20: `demo` named a few short keys and pointed
    /// elsewhere, `sim-device dynamixel` gave examples only): the `--help` of every command
    /// that takes `--fault` lists every key of the plant with its description and short name.
    #[test]
    fn every_fault_help_lists_every_key() {
        let mut cli = Cli::command();
        cli.build();
        let paths: [&[&str]; 5] = [
            &["demo"],
            &["sim-device", "stepper"],
            &["sim-device", "dynamixel"],
            &["sim-device", "mixed"],
            &["sim-device", "pico"],
        ];
        for path in paths {
            let mut cmd = &mut cli;
            for name in path {
                cmd = cmd.find_subcommand_mut(name).expect(name);
            }
            let help = cmd.render_long_help().to_string();
            for (key, what) in FAULT_KEYS {
                let short = FAULT_ALIASES.iter().find(|(_, long)| long == key);
                let entry = match short {
                    Some((s, _)) => format!("  {key} (or {s}): {what}"),
                    None => format!("  {key}: {what}"),
                };
                assert!(help.contains(&entry), "{path:?}: no `{entry}` in\n{help}");
            }
        }
    }
}

#[cfg(test)]
mod output_option_tests {
    use clap::{CommandFactory, Parser};

    use super::{Cli, Command};

    fn walk(cmd: &clap::Command, path: String, out: &mut Vec<(String, clap::Arg)>) {
        for a in cmd.get_arguments() {
            if a.get_short() == Some('o') {
                out.push((path.clone(), a.clone()));
            }
        }
        for sub in cmd.get_subcommands() {
            walk(sub, format!("{path} {}", sub.get_name()), out);
        }
    }

    /// Guards one meaning of `-o` (issue 20: `--out` in demo, analyze and build, `--output`
    /// elsewhere): every `-o` is `--output`, and `--out` still works as an alias so old
    /// command lines keep running.
    #[test]
    fn every_o_is_output_with_out_as_alias() {
        let mut all = Vec::new();
        walk(&Cli::command(), "mpc-rig".into(), &mut all);
        assert!(all.len() >= 7, "{}", all.len());
        for (path, a) in &all {
            assert_eq!(a.get_long(), Some("output"), "{path}");
            assert_eq!(a.get_all_aliases(), Some(vec!["out"]), "{path}");
        }
        for flag in ["-o", "--output", "--out"] {
            let cli = Cli::try_parse_from(["mpc-rig", "demo", flag, "x"]).unwrap();
            match cli.command {
                Command::Demo(d) => assert_eq!(d.out, std::path::PathBuf::from("x")),
                _ => panic!(),
            }
        }
    }
}
