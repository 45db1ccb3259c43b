//! `mpc-rig measure`: run a measurement session on a bench and record it.

use std::io::{IsTerminal, Write};
use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::Arc;

use anyhow::Context;
use clap::Args;

use crate::cli::ExitStatusError;
use crate::live::LiveServer;
use crate::rig::identify;
use crate::rig::recording::Phase;
use crate::rig::session::live::LiveFeed;
use crate::rig::session::{self, EndReason, MeasureOptions, Progress, TargetSpec};

/// Exit code when the device disconnected during the run (recording kept, incomplete).
pub const EXIT_DISCONNECTED: u8 = 5;
/// Exit code when the run stopped early: `safety.max_run_s`, a stalled driver, a jammed
/// mechanism, a full disk, or another error mid-run.
pub const EXIT_INCOMPLETE: u8 = 4;
/// Exit code after Ctrl-C (the shell convention 128 + SIGINT); after SIGTERM or SIGHUP it
/// is 128 plus that signal's number (143, 129), as if the signal had ended the process.
pub const EXIT_CANCELLED: u8 = 130;
/// Exit code when the run finished but its data is degraded (too many samples missing; the
/// recording's sidecar says why and the analysis gives only what the data supports).
pub const EXIT_DEGRADED: u8 = 6;

/// The signals that stop a run like Ctrl-C — motor stopped, recording finished and marked
/// `cancelled` — with their names: the terminal's interrupt, what `timeout` and service
/// managers send, and a closed terminal.
const STOP_SIGNALS: [(i32, &str); 3] = [
    (signal_hook::consts::SIGINT, "SIGINT"),
    (signal_hook::consts::SIGTERM, "SIGTERM"),
    (signal_hook::consts::SIGHUP, "SIGHUP"),
];

/// Make every [`STOP_SIGNALS`] set `cancel` and remember which one came. A second signal
/// while the motor is being stopped is ignored (the firmware watchdog and the servo's bus
/// watchdog cover a host that dies; SIGKILL still ends it).
fn stop_on_signals(cancel: &Arc<AtomicBool>) -> anyhow::Result<Arc<AtomicUsize>> {
    let which = Arc::new(AtomicUsize::new(0));
    for (signal, name) in STOP_SIGNALS {
        // The signal's number first, so it is there when the session sees the flag.
        signal_hook::flag::register_usize(signal, which.clone(), signal as usize)
            .and_then(|_| signal_hook::flag::register(signal, cancel.clone()))
            .with_context(|| format!("cannot install the {name} handler"))?;
    }
    Ok(which)
}

/// Arguments of `mpc-rig measure`.
#[derive(Debug, Args)]
#[command(group = clap::ArgGroup::new("bench").args(["rig", "port"]).required(true).multiple(true))]
#[command(group = clap::ArgGroup::new("target").args(["mechanism", "motion"]).required(true))]
pub struct MeasureArgs {
    /// Rig configuration (rigs/*.toml). Without it, the one --port is probed (our
    /// firmware's handshake, then a Dynamixel ping scan) and the shipped rig that fits what
    /// answered is used; the choice is printed.
    #[arg(long, value_name = "FILE")]
    pub rig: Option<PathBuf>,
    /// Serial port: PATH (single-port rigs) or NAME=PATH, repeatable; without --rig, the
    /// bench's one port as a PATH or a USB serial number (`mpc-rig ports` lists them).
    #[arg(long, value_name = "PORT")]
    pub port: Vec<String>,
    /// Without --rig: also write the rig chosen for the port to FILE (the shipped rig file
    /// with the port set), to edit and pass with --rig next time.
    #[arg(long, value_name = "FILE", conflicts_with = "rig")]
    pub save_rig: Option<PathBuf>,
    /// Target: a mechanism.json or the directory holding it.
    #[arg(long, value_name = "PATH")]
    pub mechanism: Option<PathBuf>,
    /// Target: a motion file (.toml or .csv).
    #[arg(long, value_name = "FILE")]
    pub motion: Option<PathBuf>,
    /// Driver speed, rpm.
    #[arg(long, default_value_t = crate::motion::DEFAULT_BENCH_RPM)]
    pub speed: f64,
    /// Measured cycles (driver revolutions) per direction.
    #[arg(long, default_value_t = 3)]
    pub cycles: u32,
    /// Settle cycles before the measured ones.
    #[arg(long, default_value_t = session::DEFAULT_SETTLE_CYCLES)]
    pub settle: u32,
    /// Also run the same cycles in reverse (for backlash).
    #[arg(long)]
    pub reverse: bool,
    /// Recording directory (default: a new `out/measure/<UTC timestamp>`). A directory that
    /// already holds a recording is refused unless --replace is given.
    #[arg(short, long, alias = "out", value_name = "DIR")]
    pub output: Option<PathBuf>,
    /// Replace the recording already in the -o directory (its CSV, sidecar and report).
    #[arg(long, requires = "output")]
    pub replace: bool,
    /// Do not analyse the recording at the end (run `mpc-rig analyze DIR` later).
    #[arg(long)]
    pub no_analysis: bool,
    /// Tolerance on the RMS rotation error in degrees for the analysis at the end.
    #[arg(long, value_parser = crate::cli::analyze::positive)]
    pub tol_deg: Option<f64>,
    /// Tolerance on every timing ratio for the analysis at the end.
    #[arg(long, value_parser = crate::cli::analyze::positive)]
    pub tol_ratio: Option<f64>,
    /// Serve a live view of the run for a browser: follower against target, error, rate,
    /// gaps, phase, and a Stop button that stops the motor as Ctrl-C does. ADDR is HOST or
    /// HOST:PORT (default 127.0.0.1 on a free port; the page's address is printed). Any
    /// other host than the loopback opens the page and its Stop button to the network.
    #[arg(
        long,
        value_name = "ADDR",
        num_args = 0..=1,
        default_missing_value = crate::live::DEFAULT_ADDR
    )]
    pub live: Option<String>,
    /// Print one JSON object on standard output instead of the text (for scripts): the
    /// recording, how the run ended, its counts, the analysis (summary.json's content) and
    /// the exit code. Progress and errors stay on standard error.
    #[arg(long)]
    pub json: bool,
}

/// After the run, the live view answers this much longer, so an open page (asking ten
/// times a second) shows how the run ended before the program exits.
const LIVE_LINGER: std::time::Duration = std::time::Duration::from_millis(400);

/// Run the session; print where the recording is and how it ended.
pub fn run(args: MeasureArgs) -> anyhow::Result<ExitCode> {
    let target = match (&args.mechanism, &args.motion) {
        (Some(m), _) => TargetSpec::Mechanism(m.clone()),
        (None, Some(m)) => TargetSpec::Motion(m.clone()),
        (None, None) => anyhow::bail!("give the target with --mechanism PATH or --motion FILE"),
    };
    let (rig_path, detected) = match &args.rig {
        Some(path) => (path.clone(), None),
        None => {
            let (name, rig) = detect_rig(&args, &target)?;
            (identify::shipped_path(name), Some(rig))
        }
    };
    let cancel = Arc::new(AtomicBool::new(false));
    let signal = stop_on_signals(&cancel)?;
    let feed = args.live.as_ref().map(|_| LiveFeed::new(cancel.clone()));
    // Serves until the end of this function (the analysis included).
    let _server = match (&args.live, &feed) {
        (Some(addr), Some(feed)) => {
            let server = LiveServer::start(addr, feed.clone())?;
            eprintln!("live view: {} (open it in a browser)", server.url());
            if !server.is_loopback() {
                eprintln!(
                    "warning: the live view listens on {}: anyone who can reach it sees the \
                     run and can stop it",
                    server.addr()
                );
            }
            Some(server)
        }
        _ => None,
    };
    let tty = std::io::stderr().is_terminal();
    let mut last_line = std::time::Instant::now();
    let mut opts = MeasureOptions {
        rig_path: rig_path.clone(),
        // A detected rig has its port already.
        ports: if detected.is_some() {
            Vec::new()
        } else {
            args.port.clone()
        },
        target,
        speed_rpm: args.speed,
        cycles: args.cycles,
        settle_cycles: args.settle,
        reverse: args.reverse,
        out_dir: args.output.clone(),
        replace: args.replace,
        cancel,
        live: feed.clone(),
        progress: Some(Box::new(move |p: &Progress| {
            if tty {
                eprint!("\r{}   ", progress_line(p));
                let _ = std::io::stderr().flush();
                crate::cli::status_line_shown();
            } else if last_line.elapsed().as_secs_f64() >= 2.0 {
                eprintln!("{}", progress_line(p));
                last_line = std::time::Instant::now();
            }
        })),
    };
    let outcome = match detected {
        Some(rig) => session::measure_with(rig, &mut opts),
        None => session::measure(&mut opts),
    };
    if let Some(feed) = &feed {
        feed.end(&match &outcome {
            Ok(o) => format!("{} (recording {})", o.end, o.dir.display()),
            Err(e) => format!("error: {e}"),
        });
        std::thread::sleep(LIVE_LINGER);
    }
    let outcome =
        outcome.with_context(|| format!("measurement with rig {}", rig_path.display()))?;
    if tty {
        eprintln!();
        crate::cli::status_line_ended();
    }
    let c = outcome.meta.counts;
    if !args.json {
        println!("recording: {}", outcome.dir.display());
        println!(
            "samples {}  gaps {} ({} samples missing)  crc errors {}  reconnects {}",
            c.samples, c.gaps, c.missing_samples, c.crc_errors, c.reconnects
        );
    }
    // Analyse whatever was recorded (an incomplete recording is still valid).
    let mut analysis_code = 0;
    let mut summary = None;
    if !args.no_analysis && c.samples > 0 {
        let opts = crate::analysis::ReportOptions {
            tol_deg: args.tol_deg,
            tol_ratio: args.tol_ratio,
            ..Default::default()
        };
        match crate::analysis::analyze_and_report(&outcome.dir, &opts) {
            Ok(s) => {
                if !args.json {
                    crate::cli::analyze::print_summary(&s, &outcome.dir.join("report"));
                }
                analysis_code = crate::cli::analyze::exit_status(&s);
                summary = Some(s);
            }
            Err(e) => eprintln!(
                "warning: analysis failed: {e}; the recording is kept, retry with `mpc-rig analyze {}`",
                outcome.dir.display()
            ),
        }
    }
    let dir = outcome.dir.display();
    let incomplete = |code: u8, what: String| {
        (
            code,
            format!("{what}; the recording in {dir} is kept and marked incomplete"),
        )
    };
    let ended = match &outcome.end {
        EndReason::Finished => outcome.meta.degraded.as_ref().map(|why| {
            (
                EXIT_DEGRADED,
                format!(
                    "run degraded: {why}; the recording in {dir} is kept (complete, marked \
                     degraded)"
                ),
            )
        }),
        EndReason::Cancelled => {
            let number = signal.load(Ordering::SeqCst);
            Some(match STOP_SIGNALS.iter().find(|s| s.0 as usize == number) {
                Some((n, name)) => incomplete(128 + *n as u8, format!("cancelled by {name}")),
                None => incomplete(EXIT_CANCELLED, "cancelled".into()),
            })
        }
        // The end reason's own text starts with "disconnected": give its message once.
        EndReason::Disconnected(m) => Some(incomplete(
            EXIT_DISCONNECTED,
            format!("device disconnected ({m})"),
        )),
        EndReason::MaxRunTime
        | EndReason::DiskFull(_)
        | EndReason::DriverStalled(_)
        | EndReason::Jammed { .. }
        | EndReason::Error(_) => Some(incomplete(
            EXIT_INCOMPLETE,
            format!("run stopped early ({})", outcome.end),
        )),
    };
    let code = ended.as_ref().map_or(analysis_code, |e| e.0);
    if args.json {
        let out = MeasureJson {
            recording: &outcome.dir,
            end_reason: outcome.end.to_string(),
            complete: outcome.complete,
            degraded: outcome.meta.degraded.as_deref(),
            counts: &c,
            summary: summary.as_ref(),
            exit_code: code,
        };
        println!("{}", serde_json::to_string_pretty(&out)?);
    }
    match ended {
        None => Ok(ExitCode::from(code)),
        Some((code, message)) => Err(ExitStatusError { code, message }.into()),
    }
}

/// What `measure --json` prints on standard output: how the run ended, its counts, the
/// analysis (the `summary.json` it wrote) and the exit code the program ends with.
#[derive(serde::Serialize)]
struct MeasureJson<'a> {
    recording: &'a std::path::Path,
    end_reason: String,
    complete: bool,
    degraded: Option<&'a str>,
    counts: &'a crate::rig::recording::Counts,
    summary: Option<&'a crate::analysis::Summary>,
    exit_code: u8,
}

/// Without `--rig`: find what is on the one `--port`, choose the shipped rig for it and the
/// target's class, say so, and save it when `--save-rig` asks.
fn detect_rig(
    args: &MeasureArgs,
    target: &TargetSpec,
) -> anyhow::Result<(&'static str, crate::rig::config::RigConfig)> {
    let given = match args.port.as_slice() {
        [one] if !one.contains('=') => one,
        _ => anyhow::bail!(
            "without --rig, give the one port the bench is on: --port PATH or --port \
             USB_SERIAL (`mpc-rig ports` lists them); a bench on several ports needs a rig \
             file (rigs/README.md)"
        ),
    };
    let path = crate::rig::link::port_by_path_or_serial(given)?;
    let class = target.load()?.motion.class();
    eprintln!("no --rig: identifying what is on {} …", path.display());
    let found = identify::identify(&path)?;
    let (name, rig) = identify::default_rig(&found, &path, class)?;
    eprintln!("found {found}");
    eprintln!(
        "using the shipped rig `{name}` ({}{}) on {}",
        identify::shipped_path(name).display(),
        rig.description
            .as_deref()
            .map_or(String::new(), |d| format!(": {d}")),
        path.display()
    );
    match &args.save_rig {
        Some(file) => {
            let text = identify::rig_file_text(name, &path)
                .with_context(|| format!("no shipped rig named {name}"))?;
            std::fs::write(file, text)
                .with_context(|| format!("cannot write the rig file {}", file.display()))?;
            eprintln!(
                "saved it as {}: edit it (rigs/README.md) and pass it with --rig {} next time",
                file.display(),
                file.display()
            );
        }
        None => eprintln!(
            "to change anything (calibration, speed limits), save it with --save-rig FILE, \
             edit it and pass it with --rig FILE"
        ),
    }
    Ok((name, rig))
}

/// The live status line: in the settle phase how far the settle has come (of the settle
/// revolutions), in a measured phase how far the cycles have (of the cycles).
pub(crate) fn progress_line(p: &Progress) -> String {
    // Rounded first, and +0.0 added, so that a small negative error reads "+0.00", not
    // "-0.00".
    let err = p.error_deg.map_or(String::new(), |e| {
        format!("  error {:+.2}°", (e * 100.0).round() / 100.0 + 0.0)
    });
    let (what, of) = if p.phase == Phase::Settle {
        ("settle", p.settle_cycles)
    } else {
        ("cycle", p.cycles)
    };
    format!(
        "[{:>7}] {what} {:.2}/{of}  {} samples  {:.0} Hz  gaps {}{}  {:.1} s",
        p.phase.as_str(),
        p.cycle,
        p.samples,
        p.sample_rate_hz,
        p.gaps,
        err,
        p.elapsed_s
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    fn progress(phase: Phase, cycle: f64) -> Progress {
        Progress {
            phase,
            cycle,
            cycles: 3,
            settle_cycles: 1,
            samples: 1500,
            sample_rate_hz: 1000.0,
            gaps: 0,
            error_deg: Some(0.012),
            elapsed_s: 1.5,
        }
    }

    /// Guards the live line (issue 20: `[ settle] cycle 0.00/3` shown all through the
    /// settle): the settle says how far it has come of its own revolutions, a measured
    /// phase how many of its cycles are done.
    #[test]
    fn progress_line_counts_settle_and_cycles() {
        assert_eq!(
            progress_line(&progress(Phase::Settle, 0.45)),
            "[ settle] settle 0.45/1  1500 samples  1000 Hz  gaps 0  error +0.01°  1.5 s"
        );
        assert_eq!(
            progress_line(&progress(Phase::Forward, 3.0)),
            "[forward] cycle 3.00/3  1500 samples  1000 Hz  gaps 0  error +0.01°  1.5 s"
        );
        // No negative zero (issue 20): a small negative error reads +0.00.
        let mut small = progress(Phase::Forward, 1.0);
        small.error_deg = Some(-0.004);
        assert!(
            progress_line(&small).contains("  error +0.00°  "),
            "{}",
            progress_line(&small)
        );
        small.error_deg = Some(-0.006);
        assert!(progress_line(&small).contains("  error -0.01°  "));
    }
}
