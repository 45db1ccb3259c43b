//! `mpc-rig synth`: synthesize a mechanism from a motion, or check a mechanism file.

use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

use anyhow::{bail, Context};
use clap::Args;
use indicatif::{ProgressBar, ProgressStyle};

use crate::motion::Motion;
use crate::synth::closure::{dist_text as dist, NormalCone};
use crate::synth::mechanism::Attempt;
use crate::synth::{self, Mechanism, Outcome, SynthOptions, SynthProgress};

use super::ExitStatusError;

/// Arguments of `mpc-rig synth`.
#[derive(Debug, Args)]
pub struct SynthArgs {
    /// Motion file (.toml or .csv).
    #[arg(required_unless_present = "check")]
    pub motion: Option<PathBuf>,
    /// Output directory (gets mechanism.json and report/).
    #[arg(
        short,
        long,
        alias = "out",
        value_name = "DIR",
        required_unless_present = "check"
    )]
    pub output: Option<PathBuf>,
    /// Re-verify a mechanism.json (file or directory) from its samples alone.
    #[arg(long, conflicts_with_all = ["motion", "output"])]
    pub check: Option<PathBuf>,
    /// With --check: print the verdict as JSON on standard output (the file, whether it
    /// passed, and each check's name, verdict and figures), for scripts.
    #[arg(long, requires = "check")]
    pub json: bool,
    /// Random seed.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Number of curve pairs K (default: the smallest from dof + 1 that closes at every
    /// instant of the 4× check with the --min-margin).
    #[arg(long)]
    pub k: Option<usize>,
    /// Closure margin M to ask of the design: E_maxDist ≤ −M (paper and robust) at every
    /// instant of the 4× check. Default ε = 0.02, the conventions' validity bar; a wider
    /// margin usually costs curve pairs (see docs/synthesis.md, "K against margin").
    #[arg(long, default_value_t = synth::closure::EPSILON)]
    pub min_margin: f64,
    /// Driver offset d_x in model units, × `--scale-mm` for mm (default: search a grid).
    #[arg(long)]
    pub dx: Option<f64>,
    /// Samples per period N.
    #[arg(long, default_value_t = 360)]
    pub samples: usize,
    /// Worker threads (default: all cores).
    #[arg(long)]
    pub threads: Option<usize>,
    /// Candidates per band M (default 30 as the paper's; 60 with --printed-rim, whose
    /// candidates each keep fewer contacts).
    #[arg(long)]
    pub candidates: Option<usize>,
    /// GA generations (paper: 300).
    #[arg(long, default_value_t = synth::ga::GENERATIONS)]
    pub generations: usize,
    /// Millimetres per model unit written into the file: the size the parts are built at
    /// and the mm figures of the summary.
    #[arg(long, default_value_t = synth::mechanism::DEFAULT_SCALE_MM)]
    pub scale_mm: f64,
    /// 3R only: bound on the contact normals. `tangent` is the paper's Eq. 30 as printed
    /// (|n·p̂| ≤ sin 10°, the conventions' default); `arm` is its stated purpose, "avoid
    /// n × p = 0" (|n·p̂| ≤ cos 10°). Every 3R example closes with either (see
    /// docs/synthesis.md).
    #[arg(long, value_enum, default_value_t = ConeArg::Tangent)]
    pub normal_cone: ConeArg,
    /// Free height between neighbouring bands, model units (0 to 5; 5 mm per 0.5 at the
    /// default scale). The default 0.5 leaves
    /// no room for a printed follower's plate and rim between two driver bands; 1.5 does,
    /// at the cost of curve pairs (see docs/synthesis.md, "Printable layouts").
    #[arg(long, default_value_t = synth::bands::BAND_GAP, allow_negative_numbers = true)]
    pub band_gap: f64,
    /// Room A kept free around each part's axis, model units (default: none). Every
    /// follower contact stays within d_x − A of the follower axis (3R: of its joint centre)
    /// and every driver curve within d_x − A of the driver axis, so that neither part's
    /// swept curves cross the other's hub column. Costs curve pairs (see docs/synthesis.md).
    #[arg(long, allow_negative_numbers = true)]
    pub axis_room: Option<f64>,
    /// Close with the contacts the printed parts keep: a contact that its own rim (3 mm
    /// deep, 3.2 mm wide at `--scale-mm`) cuts out of the driver band at another instant
    /// does not count towards closure. Costs curve pairs (see docs/synthesis.md).
    #[arg(long)]
    pub printed_rim: bool,
    /// The layout `mpc-rig build` can turn into parts, as `demo` synthesizes it:
    /// `--band-gap 1.5 --axis-room 1.0 --printed-rim` with 60 candidates per band (unless
    /// `--candidates` says otherwise). Costs curve pairs and time (see docs/synthesis.md).
    #[arg(long, conflicts_with_all = ["band_gap", "axis_room", "printed_rim"])]
    pub printable: bool,
}

/// Command-line names of [`synth::closure::NormalCone`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum ConeArg {
    /// |n·p̂| ≤ sin γ₀ (Eq. 30 as printed).
    Tangent,
    /// |n·p̂| ≤ cos γ₀ (Eq. 30's purpose: a torque arm of at least sin γ₀·|p|).
    Arm,
}

impl From<ConeArg> for synth::closure::NormalCone {
    fn from(c: ConeArg) -> Self {
        match c {
            ConeArg::Tangent => Self::Tangent,
            ConeArg::Arm => Self::Arm,
        }
    }
}

/// The synthesis progress bar on standard error (hidden when it is not a terminal, the
/// attempts' lines printed instead), shared with `demo`.
pub(crate) struct Bar {
    bar: ProgressBar,
}

impl Bar {
    /// A bar with the synthesis' style.
    pub(crate) fn new() -> Bar {
        let bar = ProgressBar::new(0);
        bar.set_style(
            ProgressStyle::with_template("{spinner} {msg} [{bar:30}] {pos}/{len} {elapsed}")
                .unwrap_or_else(|_| ProgressStyle::default_bar()),
        );
        Bar { bar }
    }

    /// Remove the bar when the synthesis is over.
    pub(crate) fn finish(&self) {
        self.bar.finish_and_clear();
    }
}

impl SynthProgress for Bar {
    fn attempt_started(&self, k: usize, dx: f64, new_candidates: usize) {
        self.bar.reset();
        self.bar.set_length(new_candidates as u64);
        self.bar.set_position(0);
        self.bar
            .set_message(format!("K = {k}, d_x = {dx}: candidates"));
    }
    fn candidate_done(&self) {
        self.bar.inc(1);
    }
    fn generation(&self, g: usize, total: usize) {
        if g == 1 {
            self.bar.reset();
            self.bar.set_length(total as u64);
            self.bar.set_message("GA generations");
        }
        self.bar.set_position(g as u64);
    }
    fn attempt_finished(&self, a: &Attempt) {
        let line = format!(
            "  {}, usable candidates {:?}{}",
            attempt_figures(a),
            a.valid_candidates,
            if a.accepted { "  → accepted" } else { "" }
        );
        if self.bar.is_hidden() {
            eprintln!("{line}");
        } else {
            self.bar.println(line);
        }
    }
}

/// What the closure figures mean, printed under the table.
const LEGEND: &str =
    "E_valiTime: fraction of the instants at which the contacts hold the follower \
(form closure, 1 = all); E_maxDist: the worst instant's signed distance from the origin to \
the hull of the contact normals (below −ε = closed, \"no interior\" = the normals span no \
volume, so nothing is held); robust: the same counting only contacts whose normal has a \
useful torque arm";

/// K, d_x and what the attempt's best combination reached, at the samples and at 4×.
fn attempt_figures(a: &Attempt) -> String {
    let at4 = match &a.oversampled {
        Some(o) => format!(
            "; at {}×: {:.3}, robust {:.3}, E_maxDist {}, robust {}",
            o.factor,
            o.vali_time,
            o.robust_vali_time,
            dist(o.max_dist),
            dist(o.robust_max_dist)
        ),
        None => "; too few bands with usable candidates".into(),
    };
    let mut left_out = if a.left_out.is_empty() {
        String::new()
    } else {
        format!(" (bands {:?} left out)", a.left_out)
    };
    if a.pushed > 0 {
        left_out += &format!(" (margin push, round {})", a.pushed);
    }
    format!(
        "K = {}{left_out}, d_x = {}: E_valiTime {:.3}, robust {:.3}, E_maxDist {}, robust {}{at4}",
        a.k,
        a.dx,
        a.vali_time,
        a.robust_vali_time,
        dist(a.max_dist),
        dist(a.robust_max_dist),
    )
}

fn summary(m: &Mechanism) -> String {
    use crate::motion::units::trim;
    let over = m.closure.oversampled.as_ref();
    let note = if m.class == synth::Class::R3 && m.solve.normal_cone == NormalCone::Arm {
        "\nnormal cone: arm (|n·p̂| ≤ cos 10°); the search's \"robust\" above counts the contacts \
         this cone allows, robust_vali/robust_max keep the conventions' definition \
         (|n·p̂| ≤ sin 10°) and are reported only"
    } else {
        ""
    };
    let tried: Vec<String> = m
        .solve
        .attempts
        .iter()
        .map(|a| {
            format!(
                "\n  {}{}",
                attempt_figures(a),
                if a.accepted { "  (accepted)" } else { "" }
            )
        })
        .collect();
    format!(
        "class  K  d_x    E_valiTime  E_maxDist  robust_vali  robust_max  vali@4x  residual°  time s\n\
         {:<6} {:<2} {:<6} {:<11.4} {:<10} {:<12.4} {:<11} {:<8.4} {:<10.3} {:.1}{note}\n\
         lengths in model units, {} mm each (scale_mm): d_x {} = {} mm, band gap {} = {} mm, \
         axis room {}{}\n\
         {LEGEND}\n\
         best reached per K tried (closure margin asked: E_maxDist ≤ −{}):{}",
        m.class.label(),
        m.curve_pairs.len(),
        m.driver_offset,
        m.closure.vali_time,
        dist(m.closure.max_dist),
        m.closure.robust_vali_time,
        dist(m.closure.robust_max_dist),
        over.map_or(f64::NAN, |o| o.vali_time),
        m.closure.worst_residual_deg,
        m.solve.seconds,
        trim(m.scale_mm, 3),
        m.driver_offset,
        trim(m.scale_mm * m.driver_offset, 2),
        m.solve.band_gap,
        trim(m.scale_mm * m.solve.band_gap, 2),
        m.solve.axis_room.map_or("none".to_string(), |a| format!(
            "{a} = {} mm (curves within d_x − {a} of the axes)",
            trim(m.scale_mm * a, 2)
        )),
        if m.solve.printed_rim {
            "; closure counts only the contacts the printed rims keep (--printed-rim)"
        } else {
            ""
        },
        m.solve.min_margin,
        tried.concat()
    )
}

fn write_partial(m: &Mechanism, dir: &Path) -> anyhow::Result<PathBuf> {
    let path = dir.join("mechanism.partial.json");
    m.save(&path)?;
    Ok(path)
}

/// Run `mpc-rig synth`.
pub fn run(args: SynthArgs) -> anyhow::Result<ExitCode> {
    if let Some(file) = &args.check {
        let m = Mechanism::load(file)?;
        let report = m.check();
        if args.json {
            let out = serde_json::json!({
                "file": file,
                "passed": report.passed(),
                "items": report.items,
            });
            println!("{}", serde_json::to_string_pretty(&out)?);
        } else {
            println!("{report}");
        }
        if report.passed() {
            return Ok(ExitCode::SUCCESS);
        }
        return Err(ExitStatusError {
            code: 2,
            message: format!("{} fails the mechanism check", file.display()),
        }
        .into());
    }
    let (Some(motion_path), Some(out)) = (&args.motion, &args.output) else {
        bail!("synth needs a MOTION file and -o DIR (or --check FILE)");
    };
    let motion = Motion::from_file(motion_path)
        .with_context(|| format!("loading motion {}", motion_path.display()))?;
    for w in motion.warnings() {
        eprintln!("warning: {w}");
    }
    let cancel = Arc::new(AtomicBool::new(false));
    {
        let c = cancel.clone();
        // A second handler cannot be installed (e.g. in tests calling run twice): then
        // Ctrl-C simply ends the process as usual.
        let _ = ctrlc::set_handler(move || c.store(true, Ordering::Relaxed));
    }
    let opts = SynthOptions {
        seed: args.seed,
        k: args.k,
        dx: args.dx,
        samples: args.samples,
        threads: args.threads,
        cancel: Some(cancel),
        candidates: args.candidates.unwrap_or(if args.printed_rim {
            synth::search::CANDIDATES_PRINTED_RIM
        } else {
            synth::search::CANDIDATES
        }),
        generations: args.generations,
        scale_mm: args.scale_mm,
        cone: args.normal_cone.into(),
        min_margin: args.min_margin,
        band_gap: args.band_gap,
        axis_room: args.axis_room,
        printed_rim: args.printed_rim,
        ..SynthOptions::default()
    };
    let opts = if args.printable {
        let candidates = args
            .candidates
            .unwrap_or(synth::search::CANDIDATES_PRINTED_RIM);
        SynthOptions {
            candidates,
            ..opts.printable()
        }
    } else {
        opts
    };
    let progress = Bar::new();
    let result = synth::synthesize(&motion, &opts, &progress);
    progress.finish();
    let outcome = result?;
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    match outcome {
        Outcome::Accepted(m) => {
            let file = out.join(crate::motion::MECHANISM_FILE);
            m.save(&file)?;
            // A partial file from an earlier failed or cancelled run would now be stale.
            let stale = out.join("mechanism.partial.json");
            if stale.exists() {
                std::fs::remove_file(&stale)
                    .with_context(|| format!("removing stale {}", stale.display()))?;
            }
            let plots = synth::report::write_report(&m, &out.join("report"))?;
            println!("{}", summary(&m));
            println!(
                "wrote {} and {} report files in {}",
                file.display(),
                plots.len(),
                out.join("report").display()
            );
            Ok(ExitCode::SUCCESS)
        }
        Outcome::Cancelled { best } => {
            let msg = match best {
                Some(m) => {
                    let p = write_partial(&m, out)?;
                    println!("{}", summary(&m));
                    format!("cancelled; best design so far written to {} (marked partial, not accepted)", p.display())
                }
                None => "cancelled before any design was found; nothing written".to_string(),
            };
            Err(ExitStatusError {
                code: 130,
                message: msg,
            }
            .into())
        }
        Outcome::Infeasible { reason, best } => {
            let mut msg = reason;
            if let Some(m) = best {
                let p = write_partial(&m, out)?;
                msg.push_str(&format!(
                    "\nthe best (not accepted) design was written to {} for inspection",
                    p.display()
                ));
            }
            Err(ExitStatusError {
                code: 3,
                message: msg,
            }
            .into())
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::synth::closure::NO_INTERIOR_DIST;
    use crate::synth::mechanism::OversampledClosure;

    /// Guards the attempt line (issue 20: `E_maxDist 99.000` where the file holds 1000 for
    /// a hull without interior): that case reads `no interior`, other distances stay numbers.
    #[test]
    fn a_hull_without_interior_is_named() {
        let a = Attempt {
            k: 2,
            dx: 6.0,
            valid_candidates: vec![3, 4],
            vali_time: 0.5,
            robust_vali_time: 0.25,
            max_dist: NO_INTERIOR_DIST,
            robust_max_dist: NO_INTERIOR_DIST,
            oversampled: Some(OversampledClosure {
                factor: 4,
                vali_time: 0.5,
                max_dist: NO_INTERIOR_DIST,
                robust_vali_time: 0.25,
                robust_max_dist: -0.0312,
            }),
            exhaustive: false,
            left_out: vec![],
            pushed: 0,
            closes: false,
            accepted: false,
        };
        assert_eq!(
            attempt_figures(&a),
            "K = 2, d_x = 6: E_valiTime 0.500, robust 0.250, E_maxDist no interior, robust \
             no interior; at 4×: 0.500, robust 0.250, E_maxDist no interior, robust -0.031"
        );
    }

    /// Guards the attempt line of a combination derived from a closed one: the bands left
    /// out and the round of the margin push that found it are both named.
    #[test]
    fn a_pushed_attempt_says_so() {
        let a = Attempt {
            k: 5,
            dx: 6.0,
            valid_candidates: vec![3, 4, 2, 5, 1, 2],
            vali_time: 1.0,
            robust_vali_time: 1.0,
            max_dist: -0.0713,
            robust_max_dist: -0.0713,
            oversampled: Some(OversampledClosure {
                factor: 4,
                vali_time: 1.0,
                max_dist: -0.0709,
                robust_vali_time: 1.0,
                robust_max_dist: -0.0709,
            }),
            exhaustive: true,
            left_out: vec![2],
            pushed: 3,
            closes: true,
            accepted: true,
        };
        assert_eq!(
            attempt_figures(&a),
            "K = 5 (bands [2] left out) (margin push, round 3), d_x = 6: E_valiTime 1.000, \
             robust 1.000, E_maxDist -0.071, robust -0.071; at 4×: 1.000, robust 1.000, \
             E_maxDist -0.071, robust -0.071"
        );
    }
}
