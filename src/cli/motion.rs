//! `mpc-rig motion check|show|sample`: validate, plot and sample motion specifications.

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::{bail, Context};
use clap::{Args, Subcommand};

use crate::motion::{
    self, BenchScale, Motion, MotionClass, DEFAULT_BENCH_RPM, DEFAULT_SAMPLES, DEFAULT_SCALE_MM,
};

/// Work with motion specifications (.toml keyframes, .csv dense samples).
#[derive(Debug, Args)]
pub struct MotionArgs {
    /// What to do with a motion.
    #[command(subcommand)]
    pub command: MotionCommand,
}

/// The `motion` subcommands.
#[derive(Debug, Subcommand)]
pub enum MotionCommand {
    /// Load and validate motion files; print a summary and any warnings.
    Check {
        /// Motion files (.toml or .csv) or mechanism.json files/directories.
        #[arg(required = true)]
        files: Vec<PathBuf>,
        /// Treat warnings as errors (exit code 3, as a missed criterion elsewhere; 2 is a
        /// usage error).
        #[arg(long)]
        strict: bool,
        /// How lengths and rates are read at the bench.
        #[command(flatten)]
        bench: BenchScaleArgs,
    },
    /// Plot a motion (PNG and SVG): angles/heights over t, and for 3R the end-effector
    /// axis path with the keyframes marked.
    Show {
        /// Motion file (.toml or .csv) or mechanism.json.
        file: PathBuf,
        /// Output directory (created if missing).
        #[arg(
            short,
            long,
            alias = "out",
            value_name = "DIR",
            default_value = "out/motion"
        )]
        output: PathBuf,
        /// Samples per period for the curves.
        #[arg(short = 'n', long, default_value_t = 4 * DEFAULT_SAMPLES)]
        samples: usize,
        /// How lengths and rates are read at the bench.
        #[command(flatten)]
        bench: BenchScaleArgs,
    },
    /// Write the motion sampled at t_i = i/N as CSV (the dense format, readable again).
    Sample {
        /// Motion file (.toml or .csv) or mechanism.json.
        file: PathBuf,
        /// Number of samples per period.
        #[arg(short = 'n', long, default_value_t = DEFAULT_SAMPLES)]
        samples: usize,
        /// Output file (its folder is created if missing); standard output when absent.
        #[arg(short, long, alias = "out", value_name = "FILE")]
        output: Option<PathBuf>,
        /// Add angular velocity/acceleration and velocity/acceleration columns.
        #[arg(long)]
        derivatives: bool,
    },
}

/// How a motion's lengths and rates are read at the bench: millimetres and seconds.
#[derive(Debug, Args)]
pub struct BenchScaleArgs {
    /// Millimetres per model unit for the heights shown (default: a mechanism file's
    /// `scale_mm`, else 10).
    #[arg(long, value_name = "MM", value_parser = crate::cli::analyze::positive)]
    pub scale_mm: Option<f64>,
    /// Driver speed, rpm, at which rates are shown per second (one period is one driver
    /// turn).
    #[arg(
        long,
        value_name = "RPM",
        default_value_t = DEFAULT_BENCH_RPM,
        value_parser = crate::cli::analyze::positive
    )]
    pub speed: f64,
}

impl BenchScaleArgs {
    /// The scale for `path`: `--scale-mm`, else a mechanism file's own, else the default.
    fn scale_for(&self, path: &Path) -> anyhow::Result<BenchScale> {
        let scale_mm = match self.scale_mm {
            Some(s) => s,
            None if is_mechanism(path) => motion::mechanism_scale_mm(path)?,
            None => DEFAULT_SCALE_MM,
        };
        // Both are positive (their parsers) and a file's scale_mm is checked where it is read.
        BenchScale::new(scale_mm, self.speed)
            .map_err(|e| anyhow::anyhow!("{}: {e}", path.display()))
    }
}

/// Whether `path` names a mechanism (a directory or a .json file) rather than a motion file.
fn is_mechanism(path: &Path) -> bool {
    path.is_dir()
        || path
            .extension()
            .is_some_and(|e| e.eq_ignore_ascii_case("json"))
}

/// Load a motion file, or the target law of a mechanism (a .json file or a directory).
pub fn load(path: &Path) -> anyhow::Result<Motion> {
    let motion = if is_mechanism(path) {
        Motion::from_mechanism_file(path)
    } else {
        Motion::from_file(path)
    };
    // Library errors already name the file, line and field.
    Ok(motion?)
}

/// Run a `motion` subcommand.
pub fn run(args: MotionArgs) -> anyhow::Result<ExitCode> {
    match args.command {
        MotionCommand::Check {
            files,
            strict,
            bench,
        } => check(&files, strict, &bench),
        MotionCommand::Show {
            file,
            output,
            samples,
            bench,
        } => {
            let m = load(&file)?;
            let scale = bench.scale_for(&file)?;
            report_warnings(&m);
            let written = motion::figures::write_all(&m, &output, samples, &scale)?;
            if !super::quiet() {
                for p in written {
                    println!("{}", p.display());
                }
            }
            Ok(ExitCode::SUCCESS)
        }
        MotionCommand::Sample {
            file,
            samples,
            output,
            derivatives,
        } => {
            if samples == 0 {
                bail!("--samples must be at least 1");
            }
            let m = load(&file)?;
            report_warnings(&m);
            let s = m.samples(samples);
            match output {
                Some(path) => {
                    // As `motion show -o` does for its folder.
                    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
                        std::fs::create_dir_all(dir)
                            .with_context(|| format!("cannot create {}", dir.display()))?;
                    }
                    let f = std::fs::File::create(&path)
                        .with_context(|| format!("cannot create {}", path.display()))?;
                    motion::dense::write_csv(f, &m, &s, derivatives)
                        .with_context(|| format!("cannot write {}", path.display()))?;
                }
                None => motion::dense::write_csv(std::io::stdout().lock(), &m, &s, derivatives)
                    .context("cannot write to standard output")?,
            }
            Ok(ExitCode::SUCCESS)
        }
    }
}

fn report_warnings(m: &Motion) {
    for w in m.warnings() {
        tracing::warn!("{w}");
    }
}

/// Exit code of `motion check --strict` when a file has warnings: 3, the code every command
/// uses for "ran, but a criterion was missed"; it was 2, which clap uses for usage errors,
/// so a script could not tell a typo from a warning (issue 20).
pub const STRICT_WARNINGS_EXIT: u8 = 3;

fn check(files: &[PathBuf], strict: bool, bench: &BenchScaleArgs) -> anyhow::Result<ExitCode> {
    let mut failed = 0;
    let mut warned = 0;
    for path in files {
        let loaded = load(path).and_then(|m| Ok((bench.scale_for(path)?, m)));
        let (scale, m) = match loaded {
            Ok(x) => x,
            Err(e) => {
                // Report every file; fail at the end.
                eprintln!("error: {e:#}");
                failed += 1;
                continue;
            }
        };
        println!("{}", summary(&m, path, &scale));
        for w in m.warnings() {
            println!("  warning: {w}");
        }
        if !m.warnings().is_empty() {
            warned += 1;
        }
    }
    if failed > 0 {
        return Err(crate::cli::ExitStatusError {
            code: 1,
            message: format!("{failed} of {} motion file(s) invalid", files.len()),
        }
        .into());
    }
    if strict && warned > 0 {
        return Err(crate::cli::ExitStatusError {
            code: STRICT_WARNINGS_EXIT,
            message: format!("{warned} motion file(s) have warnings (--strict)"),
        }
        .into());
    }
    Ok(ExitCode::SUCCESS)
}

/// One-paragraph description of a loaded motion: figures in the files' units (model units,
/// per period) with their bench reading (mm, per second at `scale`) beside them.
fn summary(m: &Motion, path: &Path, scale: &BenchScale) -> String {
    let n = motion::WARNING_SCAN_SAMPLES;
    let samples = m.samples(n);
    let max = |f: &dyn Fn(&motion::PoseSample) -> f64| samples.iter().map(f).fold(0.0, f64::max);
    let w = max(&|s| s.angular_velocity.norm());
    let a = max(&|s| s.angular_acceleration.norm());
    let mut out = format!(
        "ok: {} — {} \"{}\", {} keyframe(s)",
        path.display(),
        m.class(),
        m.name(),
        m.keyframes().len()
    );
    match m.class() {
        MotionClass::R1 | MotionClass::R1T1 => {
            let (lo, hi) = samples
                .iter()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |r, s| {
                    let th = m.angle_z(s.t).map_or(0.0, |x| x[0]).to_degrees();
                    (r.0.min(th), r.1.max(th))
                });
            out += &format!(
                ", net {} turn(s), angle {lo:.1}°..{hi:.1}° ({} scheme)",
                m.net_turns(),
                m.angle_scheme().map_or("-".into(), |s| s.to_string())
            );
            if m.class() == MotionClass::R1T1 {
                let (lo, hi) = samples
                    .iter()
                    .fold((f64::INFINITY, f64::NEG_INFINITY), |r, s| {
                        (r.0.min(s.translation.z), r.1.max(s.translation.z))
                    });
                let v = samples
                    .iter()
                    .map(|s| s.velocity.z.abs())
                    .fold(0.0, f64::max);
                out += &format!(
                    ", height {lo:.3}..{hi:.3} model units ({:.1}..{:.1} mm), \
                     max |dh/dt| {v:.2} units/period ({:.1} mm/s)",
                    scale.mm(lo),
                    scale.mm(hi),
                    scale.per_s(scale.mm(v))
                );
            }
        }
        MotionClass::R3 => {
            let tilt = samples
                .iter()
                .map(|s| motion::rotation::tilt_deg(&s.rotation))
                .fold(0.0, f64::max);
            out += &format!(", max tilt {tilt:.1}°");
        }
    }
    out += &format!(
        ", max |ω| {w:.2} rad/period ({:.0}°/s), max |ω'| {a:.1} rad/period² ({:.0}°/s²), \
         {} warning(s)\n  at the bench: {}",
        scale.per_s(w).to_degrees(),
        scale.per_s2(a).to_degrees(),
        m.warnings().len(),
        if m.class() == MotionClass::R1T1 {
            scale.describe()
        } else {
            scale.describe_period()
        }
    );
    out
}
