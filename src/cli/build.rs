//! `mpc-rig build`: printable parts from a mechanism.

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::Context;
use clap::Args;

use crate::build::{self, output, Bench, BuildOptions};
use crate::rig::config::RigConfig;
use crate::synth::mechanism::Mechanism;

/// The output folder beside the mechanism file when `-o` is not given.
pub const DEFAULT_OUT_DIR: &str = "parts";

/// Arguments of `mpc-rig build`.
#[derive(Debug, Args)]
pub struct BuildArgs {
    /// The mechanism file (or its directory).
    pub mechanism: PathBuf,
    /// Output folder (default: `parts/` beside the mechanism file).
    #[arg(short = 'o', long = "output", alias = "out", value_name = "DIR")]
    pub out: Option<PathBuf>,
    /// Millimetres per model unit (default: the file's `scale_mm`).
    #[arg(long = "scale-mm")]
    pub scale_mm: Option<f64>,
    /// Print clearance between driver and follower, mm.
    #[arg(long, default_value_t = build::dims::DEFAULT_CLEARANCE_MM)]
    pub clearance: f64,
    /// Mesher cell size, mm (smaller: finer and slower).
    #[arg(long = "cell-mm", default_value_t = build::dims::DEFAULT_CELL_MM)]
    pub cell_mm: f64,
    /// Simplify the meshes within this distance, mm (0: keep every triangle the mesher
    /// makes, three to four times as many).
    #[arg(long = "simplify-mm", default_value_t = build::dims::DEFAULT_SIMPLIFY_MM)]
    pub simplify_mm: f64,
    /// Make the motor coupling and sensor mounts for this rig (default: the simulated
    /// stepper bench of the mechanism's class).
    #[arg(long)]
    pub rig: Option<PathBuf>,
    /// Leave curve pair K (1-based) out: an experiment whose parts need not close; the
    /// interference figures are reported, not enforced.
    #[arg(long = "without-pair", value_name = "K")]
    pub without_pair: Option<usize>,
}

/// Run `mpc-rig build`.
pub fn run(args: BuildArgs) -> anyhow::Result<ExitCode> {
    let file = super::mechanism_file(&args.mechanism);
    let mech = Mechanism::load(&file)?;
    let bench = match &args.rig {
        Some(r) => Some(Bench::from_rig(&RigConfig::load(r)?, mech.class)?),
        None => None,
    };
    let opts = BuildOptions {
        scale_mm: args.scale_mm,
        clearance_mm: args.clearance,
        cell_mm: args.cell_mm,
        simplify_mm: args.simplify_mm,
        bench,
        without_pair: args.without_pair.map(|k| k.saturating_sub(1)),
        allow_interference: args.without_pair.is_some(),
    };
    let t = std::time::Instant::now();
    let built = build::build(&mech, &opts, &|s| eprintln!("  {s}"))
        .with_context(|| format!("building {}", file.display()))?;
    let out = args.out.clone().unwrap_or_else(|| {
        file.parent()
            .unwrap_or_else(|| Path::new("."))
            .join(DEFAULT_OUT_DIR)
    });
    let written = output::write(&built, &file, &opts, &out, &|s| eprintln!("  {s}"))?;
    for p in &built.parts {
        let c = &p.check;
        let b = p.mesh.aabb().size();
        println!(
            "{:<9} {:>8} triangles  {:>9.0} mm³  {:.0} × {:.0} × {:.0} mm  {}  {:.1} s",
            p.name,
            c.triangles,
            c.volume_mm3,
            b[0],
            b[1],
            b[2],
            c.summary(),
            p.seconds
        );
    }
    for (p, w) in built.parts.iter().zip(&built.figures.walls) {
        println!("{} walls: {}", p.name, output::walls_text(w));
    }
    for p in &built.parts {
        println!(
            "{} mesh error: {}",
            p.name,
            output::mesh_error_text(&p.error)
        );
    }
    for pe in &built.figures.penetrations {
        println!("{:<24} {:.3} mm at t = {:.4}", pe.what, pe.depth_mm, pe.t);
    }
    for g in &built.figures.gaps {
        let lost = if g.lost.is_empty() {
            String::new()
        } else {
            format!(
                ", contact lost over {:.1} % of the period",
                100.0 * g.lost_fraction
            )
        };
        println!(
            "pair {}: gap {:.3}–{:.3} mm (mean kept {:.3}){lost}",
            g.pair, g.min_mm, g.max_mm, g.mean_mm
        );
    }
    let c = &built.figures.closure;
    println!(
        "closure with the contacts kept: E_maxDist {} (robust {})",
        crate::synth::closure::dist_text(c.max_dist),
        crate::synth::closure::dist_text(c.robust_max_dist)
    );
    for (what, s) in &built.timings {
        println!("{what}: {s:.1} s");
    }
    println!("files: {:.1} s", written.files_s);
    if let Some(note) = &written.bed_note {
        println!("note: {note}");
    }
    println!("total {:.1} s", t.elapsed().as_secs_f64());
    println!("wrote {} files to {}", written.files.len(), out.display());
    if !super::quiet() {
        for f in &written.files {
            println!("  {}", f.display());
        }
    }
    if built.printable() {
        return Ok(ExitCode::SUCCESS);
    }
    anyhow::bail!(
        "the parts are not printable as they are (written to {} for inspection):\n  - {}",
        out.display(),
        built.problems.join("\n  - ")
    )
}
