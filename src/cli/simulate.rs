//! `mpc-rig simulate`: how the built parts move the follower (the virtual prototype).

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::Context;
use clap::Args;

use crate::predict::law::Load;
use crate::predict::{
    self, output, PredictOptions, DEFAULT_SAMPLES, DRIVE_LOST_DEG, DRIVE_LOST_MM,
};
use crate::synth::mechanism::Mechanism;

/// The output folder beside the parts when `-o` is not given.
pub const DEFAULT_OUT_DIR: &str = "prediction";

/// Arguments of `mpc-rig simulate`.
#[derive(Debug, Args)]
pub struct SimulateArgs {
    /// The mechanism file (or its directory).
    pub mechanism: PathBuf,
    /// The folder `mpc-rig build` wrote the parts into (default: `parts/` beside the
    /// mechanism file).
    #[arg(long, value_name = "DIR")]
    pub parts: Option<PathBuf>,
    /// Output folder (default: `prediction/` beside the mechanism file).
    #[arg(short = 'o', long = "output", alias = "out", value_name = "DIR")]
    pub out: Option<PathBuf>,
    /// Driver angles per period.
    #[arg(long, default_value_t = DEFAULT_SAMPLES)]
    pub samples: usize,
    /// The load on the follower: drag (friction opposing motion), torque+ / torque- (a
    /// constant torque larger than the friction, counter-clockwise or clockwise about
    /// +z), or spring:DEG (a spring towards that follower angle).
    #[arg(long, default_value = "drag", value_parser = Load::parse)]
    pub load: Load,
}

/// Run `mpc-rig simulate`.
pub fn run(args: SimulateArgs) -> anyhow::Result<ExitCode> {
    let file = super::mechanism_file(&args.mechanism);
    let mech = Mechanism::load(&file)?;
    let dir = file
        .parent()
        .map(|p| p.to_path_buf())
        .unwrap_or_else(|| PathBuf::from("."));
    let parts = args
        .parts
        .clone()
        .unwrap_or_else(|| dir.join(super::build::DEFAULT_OUT_DIR));
    let out = args
        .out
        .clone()
        .unwrap_or_else(|| dir.join(DEFAULT_OUT_DIR));
    let opts = PredictOptions {
        samples: args.samples,
        load: args.load,
    };
    let p = predict::predict(&mech, &parts, &opts)
        .with_context(|| format!("simulating the parts in {}", parts.display()))?;
    let files = output::write(&p, &file, &parts, &out)?;
    let lost = p.samples.iter().filter(|s| s.drive_lost).count();
    println!(
        "{} driver angles, load {}, clearance {:.2} mm{}",
        p.samples.len(),
        p.load,
        p.clearance_mm,
        p.without_pair
            .map_or(String::new(), |k| format!(", parts without curve pair {k}"))
    );
    println!(
        "worst play {:.3}° at driver {:.2}°; worst deviation from the target {:.3}° at driver {:.2}°",
        p.worst_play.deg, p.worst_play.driver_deg, p.worst_deviation.deg, p.worst_deviation.driver_deg
    );
    let (held, lost_by) = match &p.slide {
        None => (
            format!("play ≤ {DRIVE_LOST_DEG}°"),
            format!("play > {DRIVE_LOST_DEG}°"),
        ),
        Some(s) => {
            println!(
                "worst play of the slide {:.3} mm at driver {:.2}°, along a screw {:.3} mm at \
                 driver {:.2}° (a turn counting at {} mm); worst height deviation {:.3} mm at \
                 driver {:.2}°",
                s.worst_slide_play.mm,
                s.worst_slide_play.driver_deg,
                s.worst_screw_play.mm,
                s.worst_screw_play.driver_deg,
                s.lever_mm,
                s.worst_height_deviation.mm,
                s.worst_height_deviation.driver_deg
            );
            (
                format!("play along every line ≤ {DRIVE_LOST_MM:.2} mm"),
                format!("play along a line > {DRIVE_LOST_MM:.2} mm"),
            )
        }
    };
    if lost == 0 {
        println!("the driver holds the follower at every angle ({held})");
    } else {
        println!(
            "drive lost at {lost} of {} angles ({lost_by}): driver {}",
            p.samples.len(),
            p.lost_windows_text()
        );
    }
    for (what, c) in [
        ("the file's closure dist(t)", &p.closure),
        (
            "the closure of the contacts the build kept",
            &p.kept_closure,
        ),
    ] {
        println!(
            "against {what}, at its {} samples: lost by both {}, by it only {}, by the parts only {}, held by both {}",
            c.lost_both + c.lost_by_file_only + c.lost_by_parts_only + c.held_both,
            c.lost_both,
            c.lost_by_file_only,
            c.lost_by_parts_only,
            c.held_both
        );
    }
    if p.overlap_mm > 0.0 {
        println!(
            "the meshes overlap by up to {:.3} mm at the design pose (driver {:.2}°) where vertices would stop the follower; those vertices do not count",
            p.overlap_mm, p.overlap_driver_deg
        );
    }
    println!(
        "{} + {} vertices, {} distance queries, {:.1} s",
        p.vertices[0], p.vertices[1], p.queries, p.seconds
    );
    println!("wrote {} files to {}", files.len(), out.display());
    if !super::quiet() {
        for f in &files {
            println!("  {}", f.display());
        }
    }
    Ok(ExitCode::SUCCESS)
}
