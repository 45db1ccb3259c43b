//! `mpc-rig analyze RECORDING`: measured versus target, written as a report.
//!
//! Parses the options, calls [`crate::analysis::analyze_and_report`] and prints where the
//! report is with the headline figures. Exit code 3 when a tolerance was given and missed.

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::Context as _;
use clap::Args;

use crate::analysis::report::f3;
use crate::analysis::{analyze_and_report, timing::parse_levels, ReportOptions, Summary};

/// Exit code when the analysis ran but a tolerance (`--tol-*`) was missed.
pub const EXIT_TOLERANCE_MISSED: u8 = 3;

/// Analyse a recording against its target law and write the report.
#[derive(Debug, Args)]
pub struct AnalyzeArgs {
    /// Recording directory (holding recording.csv and recording.json).
    pub recording: PathBuf,
    /// Compare against this mechanism (mechanism.json or its directory) instead of the
    /// target named in the recording.
    #[arg(long, conflicts_with = "motion")]
    pub mechanism: Option<PathBuf>,
    /// Compare against this motion file instead of the target named in the recording.
    #[arg(long)]
    pub motion: Option<PathBuf>,
    /// Report directory (default: RECORDING/report).
    #[arg(short = 'o', long = "output", alias = "out", value_name = "DIR")]
    pub out: Option<PathBuf>,
    /// Follower crossing angles for timing ratios, degrees relative to each cycle's start
    /// (default 0,180,360 for a turning follower).
    #[arg(long, value_name = "DEG,DEG,...")]
    pub timing: Option<String>,
    /// Tolerance on the RMS rotation error in degrees (exit code 3 when missed).
    #[arg(long, value_parser = positive)]
    pub tol_deg: Option<f64>,
    /// Tolerance on the RMS height error in millimetres (1R1T).
    #[arg(long, value_parser = positive)]
    pub tol_mm: Option<f64>,
    /// Tolerance on |measured − target| of every timing ratio.
    #[arg(long, value_parser = positive)]
    pub tol_ratio: Option<f64>,
    /// Also compare with the law `mpc-rig simulate` predicted for the built parts (its
    /// prediction.json; 1R and 1R1T: the turn, and for 1R1T the height).
    #[arg(long, value_name = "FILE")]
    pub prediction: Option<PathBuf>,
    /// The folder `mpc-rig build` wrote the measured parts into: the report shows their
    /// pictures and figures.
    #[arg(long, value_name = "DIR")]
    pub parts: Option<PathBuf>,
    /// Print the summary as JSON on standard output (the content of summary.json) instead
    /// of the text, for scripts.
    #[arg(long)]
    pub json: bool,
}

/// clap value parser: a positive finite number.
pub fn positive(s: &str) -> Result<f64, String> {
    match s.parse::<f64>() {
        Ok(v) if v.is_finite() && v > 0.0 => Ok(v),
        _ => Err(format!("`{s}` is not a positive number")),
    }
}

impl AnalyzeArgs {
    /// The report options these arguments ask for.
    pub fn report_options(&self) -> anyhow::Result<ReportOptions> {
        Ok(ReportOptions {
            out_dir: self.out.clone(),
            mechanism: self.mechanism.clone(),
            motion: self.motion.clone(),
            timing_levels: self.timing.as_deref().map(parse_levels).transpose()?,
            tol_deg: self.tol_deg,
            tol_mm: self.tol_mm,
            tol_ratio: self.tol_ratio,
            prediction: self.prediction.clone(),
            parts: self.parts.clone(),
        })
    }
}

/// Run `analyze`.
pub fn run(args: AnalyzeArgs) -> anyhow::Result<ExitCode> {
    let opts = args.report_options()?;
    let summary = analyze_and_report(&args.recording, &opts)
        .with_context(|| format!("analysing {}", args.recording.display()))?;
    let report_dir = opts
        .out_dir
        .clone()
        .unwrap_or_else(|| args.recording.join("report"));
    if args.json {
        println!("{}", serde_json::to_string_pretty(&summary)?);
    } else {
        print_summary(&summary, &report_dir);
    }
    Ok(ExitCode::from(exit_status(&summary)))
}

/// 0 unless tolerances were given and missed.
pub fn exit_status(summary: &Summary) -> u8 {
    if summary.pass == Some(false) {
        EXIT_TOLERANCE_MISSED
    } else {
        0
    }
}

/// Print where the report is and its headline figures (stdout).
pub fn print_summary(s: &Summary, report_dir: &Path) {
    let h = &s.headline;
    if !super::quiet() {
        println!("report:   {}", report_dir.join("report.html").display());
        println!("          {}", report_dir.join("report.md").display());
        println!("summary:  {}", report_dir.join("summary.json").display());
    }
    println!("motion:   {} ({})", h.motion, h.class);
    if let (Some(m), Some(u), Some(t)) = (
        h.timing_ratio_measured,
        h.timing_ratio_u95,
        h.timing_ratio_target,
    ) {
        let lv = s
            .timing
            .as_ref()
            .and_then(|t| t.ratios.first())
            .map(|r| r.levels_deg)
            .unwrap_or_default();
        println!(
            "timing:   ({}°→{}°)/({}°→{}°) measured {m:.3} ± {u:.3} vs target {t:.3}",
            lv[0], lv[1], lv[1], lv[2]
        );
    }
    if let Some(why) = &h.not_enough_data {
        println!("error:    {why}");
    }
    if let Some(r) = h.rms_error_deg {
        println!(
            "error:    RMS {r:.3}°, max {:.3}° (after removing the offsets below)",
            h.max_error_deg.unwrap_or(f64::NAN)
        );
    }
    if let Some(p) = &s.prediction {
        println!(
            "predict:  RMS {:.3}°, max {:.3}° from the parts' predicted law (vs {:.3}° from the target)",
            p.rms_deg, p.max_deg, p.rms_vs_target_deg
        );
        let lost = crate::analysis::report::drive_lost_sentence(&p.drive_lost_deg);
        if !lost.is_empty() {
            println!("{:10}{}", "", lost.trim_start());
        }
    }
    if let Some(r) = h.rms_error_mm {
        println!("height:   RMS {r:.3} mm");
    }
    if let Some(p) = s.prediction.as_ref().and_then(|p| p.height) {
        println!(
            "predict:  RMS {:.3} mm, max {:.3} mm of height from the parts' predicted law (vs \
             {:.3} mm from the target)",
            p.rms_mm, p.max_mm, p.rms_vs_target_mm
        );
    }
    print!("offsets:  driver {}°", f3(s.alignment.driver_offset_deg));
    if let Some(c) = s.alignment.sensor_offset_rz_deg {
        print!(", sensor rz {}°", f3(c));
    }
    if let Some(c) = s.alignment.sensor_offset_tz_mm {
        print!(", sensor tz {} mm", f3(c));
    }
    if let Some(w) = s.alignment.world_offset_deg {
        print!(", IMU frame {w:.2}°");
    }
    println!();
    if let Some(b) = h.backlash_driver_deg {
        println!(
            "backlash: {}° of driver angle{} (forward vs reverse)",
            crate::analysis::report::backlash_with_error(b, s.lag.backlash_driver_std_err_deg),
            crate::analysis::report::follower_play(
                h.backlash_follower_deg,
                h.backlash_follower_free_deg
            )
        );
    }
    println!(
        "samples:  {} at {:.1} Hz, {} gaps, {} cycles{}",
        s.sampling.samples,
        s.sampling.mean_rate_hz,
        s.sampling.gaps,
        h.cycles,
        crate::analysis::report::behind(&s.source)
    );
    if let Some(why) = &s.source.degraded {
        println!("degraded: {why}");
    }
    match s.pass {
        Some(true) => println!("verdict:  PASS ({} checks)", s.checks.len()),
        Some(false) => {
            let missed: Vec<String> = s
                .checks
                .iter()
                .filter(|c| !c.pass)
                .map(|c| match c.measured {
                    Some(m) => format!(
                        "{} = {m:.4} (target {} ± {})",
                        c.name, c.target, c.tolerance
                    ),
                    None => format!("{} not measured", c.name),
                })
                .collect();
            println!("verdict:  FAIL: {}", missed.join("; "));
        }
        None => {}
    }
}
