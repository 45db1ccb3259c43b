//! `mpc-rig demo`: the main job on a machine without hardware.
//!
//! Synthesizes the example mechanism (or reuses the cached one under `out/demo/`, keyed by
//! the motion file's SHA-256, the seed, the synthesis settings and the tool version), or
//! takes the one `--mechanism` names (its parts cached under `out/demo/mechanisms/`). For a
//! 1R or 1R1T motion it then builds the printable parts (`mpc-rig build`, cached beside the
//! mechanism, keyed by the mechanism file, the build settings and the executable's hash) and
//! predicts how they move the follower (`mpc-rig simulate`): the *geometry plant*, so the
//! simulated bench's follower moves as the printed parts would move it. It starts a
//! simulated bench in-process on pseudo-terminals (our firmware core behind the stepper
//! bench, or the Protocol 2.0 Dynamixel bus, with a firmware sensor board beside it for 1R1T
//! and 3R), measures a few cycles through the real serial session, analyses the recording
//! against the target and the prediction, and prints where the mechanism, the parts and the
//! report are, with the headline figures. Options choose another example, the bench, the
//! plant (`--plant target`: the follower on the target law, no parts) and injected faults
//! (`--fault backlash=2`). Every step is a library call; this file only orchestrates.

use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Instant, SystemTime};

use anyhow::{bail, Context as _};
use clap::{Args, ValueEnum};
use sha2::{Digest, Sha256};

use crate::analysis::{analyze_and_report, ReportOptions};
use crate::build::{Bench, BuildOptions};
use crate::motion::{Motion, MotionClass};
use crate::predict::table::PlayTable;
use crate::predict::PredictOptions;
use crate::rig::config::RigConfig;
use crate::rig::recording::{utc_dir_stamp, Phase};
use crate::rig::session::{self, MeasureOptions, Progress, TargetSpec};
use crate::rig::sim::plant::PlantConfig;
use crate::synth::{Mechanism, Outcome, SynthOptions};

/// What moves the simulated bench's follower.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum DemoPlant {
    /// The printable parts of the mechanism, as `mpc-rig simulate` predicts they move the
    /// follower (1R, 1R1T): the mechanism is synthesized with the printable layout
    /// (`synth --printable`) and built (`mpc-rig build`).
    Geometry,
    /// The target law (plus the injected faults): no parts are built.
    Target,
}

/// Which simulated bench the demo measures on.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum DemoBench {
    /// Our firmware core driving a stepper, an AS5600 on the follower (rigs/sim-stepper.toml).
    Stepper,
    /// A Dynamixel driver servo and a torque-off follower servo (rigs/sim-dynamixel.toml);
    /// for 1R1T and 3R the follower sensors are on a firmware sensor board next to the bus
    /// (rigs/sim-dynamixel-1r1t.toml, rigs/sim-dynamixel-imu.toml).
    Dynamixel,
}

/// Run the main job on a simulated bench: synthesize, measure, analyse, report.
#[derive(Debug, Args)]
pub struct DemoArgs {
    /// Example motion from data/motions (file stem).
    #[arg(long, default_value = "half-turn-2to1", conflicts_with = "motion")]
    pub example: String,
    /// A motion file instead of an example.
    #[arg(long, value_name = "FILE")]
    pub motion: Option<PathBuf>,
    /// A synthesized mechanism (`mpc-rig synth`'s mechanism.json, or its folder) instead of
    /// synthesizing one: its parts are built, predicted and measured. They are cached under
    /// OUT/mechanisms/, never beside the file.
    #[arg(
        long,
        value_name = "FILE",
        conflicts_with_all = ["example", "motion", "quick", "resynthesize", "seed", "normal_cone"]
    )]
    pub mechanism: Option<PathBuf>,
    /// Simulated bench.
    #[arg(long, value_enum, default_value_t = DemoBench::Stepper)]
    pub bench: DemoBench,
    /// Injected imperfection of the simulated mechanism or link, `key=value`, repeatable
    /// (e.g. backlash=2; the keys are listed by --help).
    #[arg(long = "fault", value_name = "KEY=VALUE", long_help = fault_keys_help!(
        "Injected imperfection of the simulated mechanism or link, repeatable (e.g. backlash=2)."
    ))]
    pub faults: Vec<String>,
    /// Measured cycles per direction.
    #[arg(long, default_value_t = 3)]
    pub cycles: u32,
    /// Driver speed, rpm.
    #[arg(long, default_value_t = crate::motion::DEFAULT_BENCH_RPM)]
    pub speed: f64,
    /// Measure forward only (no reverse run, so no backlash figure).
    #[arg(long)]
    pub no_reverse: bool,
    /// Output directory (mechanism cache, recordings, reports).
    #[arg(
        short = 'o',
        long = "output",
        alias = "out",
        value_name = "DIR",
        default_value = "out/demo"
    )]
    pub out: PathBuf,
    /// What moves the follower (default: `geometry` for a 1R or 1R1T motion, `target` for
    /// 3R, whose prediction is not built yet, and with `--quick`).
    #[arg(long, value_enum)]
    pub plant: Option<DemoPlant>,
    /// Print clearance of the parts, mm (geometry plant).
    #[arg(long, default_value_t = crate::build::dims::DEFAULT_CLEARANCE_MM)]
    pub clearance: f64,
    /// Mesher cell of the parts, mm (geometry plant; coarser is quicker, but the build's
    /// check fails the parts above about 0.5 mm, see docs/build.md).
    #[arg(long = "cell-mm", default_value_t = crate::build::dims::DEFAULT_CELL_MM)]
    pub cell_mm: f64,
    /// Synthesis seed.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Reduced synthesis effort (fewer candidates and GA generations): faster, maybe a worse
    /// mechanism, and not a printable one, so the plant is the target law. Used by the
    /// tests.
    #[arg(long)]
    pub quick: bool,
    /// Synthesize again even when a cached mechanism exists.
    #[arg(long)]
    pub resynthesize: bool,
    /// 3R only: bound on the contact normals (see `mpc-rig synth --help`); every 3R example
    /// closes with `arm`, five of six (not pick-and-place) with the default.
    #[arg(long, value_enum, default_value_t = crate::cli::synth::ConeArg::Tangent)]
    pub normal_cone: crate::cli::synth::ConeArg,
    /// Tolerance on the RMS rotation error (degrees) for a pass/fail verdict.
    #[arg(long, value_parser = crate::cli::analyze::positive)]
    pub tol_deg: Option<f64>,
    /// Tolerance on the timing ratio for a pass/fail verdict.
    #[arg(long, value_parser = crate::cli::analyze::positive)]
    pub tol_ratio: Option<f64>,
}

/// Find a file shipped with the repository: relative to the working directory first, then
/// to the source tree the binary was built from.
fn shipped(rel: &str) -> PathBuf {
    let here = PathBuf::from(rel);
    if here.exists() {
        here
    } else {
        Path::new(env!("CARGO_MANIFEST_DIR")).join(rel)
    }
}

/// The simulated bench's rig for a motion class: the stepper bench measures a 1R follower
/// with an AS5600, 1R1T adds a linear encoder, 3R uses a BNO055. The Dynamixel bench reads
/// a 1R follower with a torque-off servo; for 1R1T and 3R the same sensors as the stepper
/// bench sit on a firmware sensor board next to the bus (a mixed rig).
fn rig_for(bench: DemoBench, class: MotionClass) -> &'static str {
    match (bench, class) {
        (DemoBench::Stepper, MotionClass::R1) => "rigs/sim-stepper.toml",
        (DemoBench::Stepper, MotionClass::R1T1) => "rigs/sim-stepper-1r1t.toml",
        (DemoBench::Stepper, MotionClass::R3) => "rigs/sim-stepper-imu.toml",
        (DemoBench::Dynamixel, MotionClass::R1) => "rigs/sim-dynamixel.toml",
        // A torque-off servo reads one angle: 1R1T and 3R followers are read by our
        // firmware on a sensor board next to the bus.
        (DemoBench::Dynamixel, MotionClass::R1T1) => "rigs/sim-dynamixel-1r1t.toml",
        (DemoBench::Dynamixel, MotionClass::R3) => "rigs/sim-dynamixel-imu.toml",
    }
}

/// The plant the demo runs with: `--plant`, or the geometry for 1R and 1R1T and the target
/// law for 3R or with `--quick`. Refuses the geometry for 3R, and with `--quick`, before
/// anything runs.
fn plant_for(args: &DemoArgs, class: MotionClass) -> anyhow::Result<DemoPlant> {
    match args.plant {
        Some(DemoPlant::Geometry) if class == MotionClass::R3 => bail!(
            "--plant geometry: the parts' prediction (`mpc-rig simulate`) handles 1R and 1R1T \
             mechanisms; this motion is {class}. `--plant target` measures it on the target law"
        ),
        // Measured: half-turn-2to1 with the printable layout and the quick search (d_x 6,
        // 6 candidates, 40 generations) closes at no K from 3 to 6.
        Some(DemoPlant::Geometry) if args.quick => bail!(
            "--plant geometry --quick: the printable layout needs the full search (the quick \
             one finds no printable design); drop --quick, or measure with `--plant target`"
        ),
        Some(p) => Ok(p),
        None if class != MotionClass::R3 && !args.quick => Ok(DemoPlant::Geometry),
        None => Ok(DemoPlant::Target),
    }
}

/// The synthesis settings of the demo: the printable layout when parts are built.
fn synth_options(args: &DemoArgs, plant: DemoPlant) -> SynthOptions {
    let mut o = SynthOptions {
        seed: args.seed,
        cone: args.normal_cone.into(),
        ..SynthOptions::default()
    };
    if plant == DemoPlant::Geometry {
        o = o.printable();
    }
    if args.quick {
        // The paper's d_x for 1R/1R1T, fewer candidates and a shorter GA: a valid but less
        // polished mechanism in a fraction of the time.
        o.dx = Some(6.0);
        o.candidates = 6;
        o.generations = 40;
        o.population = 12;
    }
    o
}

/// A cache key: the first 6 bytes of the SHA-256 of `bytes` and `settings`, in hex.
fn short_hash(bytes: &[u8], settings: &str) -> String {
    let mut h = Sha256::new();
    h.update(bytes);
    h.update(settings.as_bytes());
    h.finalize()
        .iter()
        .take(6)
        .map(|b| format!("{b:02x}"))
        .collect()
}

/// Cache key: motion bytes, seed, synthesis settings, tool version; with the printed rim,
/// also the version of the rules that decide what such a design keeps
/// (`undercut::RULES`: a cache from before they changed would hand the demo a design its
/// build disowns).
fn cache_key(motion_bytes: &[u8], o: &SynthOptions) -> String {
    let rules = if o.printed_rim {
        format!(" rules={}", crate::synth::undercut::RULES)
    } else {
        String::new()
    };
    short_hash(
        motion_bytes,
        &format!(
            "seed={} k={:?} dx={:?} n={} m={} g={} p={} e={} scale={} cone={} margin={} \
             gap={} room={:?} rim={} version={}{rules}",
            o.seed,
            o.k,
            o.dx,
            o.samples,
            o.candidates,
            o.generations,
            o.population,
            o.max_eval,
            o.scale_mm,
            o.cone.label(),
            o.min_margin,
            o.band_gap,
            o.axis_room,
            o.printed_rim,
            env!("CARGO_PKG_VERSION")
        ),
    )
}

/// Synthesize or reuse the cached mechanism; returns its path and whether it was cached.
fn mechanism_for(
    args: &DemoArgs,
    plant: DemoPlant,
    motion_path: &Path,
    motion: &Motion,
) -> anyhow::Result<(PathBuf, bool)> {
    let bytes =
        std::fs::read(motion_path).with_context(|| format!("reading {}", motion_path.display()))?;
    let o = synth_options(args, plant);
    if o.printed_rim {
        eprintln!("      printable layout (as `mpc-rig synth --printable`)");
    }
    let dir = args.out.join(format!(
        "mechanism-{}-{}",
        motion.name(),
        cache_key(&bytes, &o)
    ));
    let file = dir.join(crate::motion::MECHANISM_FILE);
    if file.exists() && !args.resynthesize {
        match Mechanism::load(&file) {
            Ok(_) => return Ok((file, true)),
            Err(e) => eprintln!("      cached mechanism unusable ({e}); synthesizing again"),
        }
    }
    let t0 = Instant::now();
    // The progress bar `synth` shows (issue 20: a static line through a 105 s synthesis).
    let progress = super::synth::Bar::new();
    let result = crate::synth::synthesize(motion, &o, &progress);
    progress.finish();
    let mech =
        match result.with_context(|| format!("synthesizing a mechanism for {}", motion.name()))? {
            Outcome::Accepted(m) => m,
            Outcome::Infeasible { reason, .. } => {
                bail!("no mechanism for {} was accepted: {reason}", motion.name())
            }
            Outcome::Cancelled { .. } => bail!("synthesis cancelled"),
        };
    mech.save(&file)
        .with_context(|| format!("saving {}", file.display()))?;
    eprintln!("      synthesized in {:.1} s", t0.elapsed().as_secs_f64());
    // The synthesis charts `synth` writes (issue 20: the demo wrote none).
    let report = dir.join("report");
    let charts = crate::synth::report::write_report(&mech, &report)
        .with_context(|| format!("writing the synthesis charts in {}", report.display()))?;
    eprintln!(
        "      synthesis charts ({} files): {}",
        charts.len(),
        report.display()
    );
    Ok((file, false))
}

/// The build settings the demo's options give (`--clearance`, `--cell-mm`), before the
/// bench is known: checked before the synthesis, completed by [`build_options`].
fn parts_settings(args: &DemoArgs) -> BuildOptions {
    BuildOptions {
        clearance_mm: args.clearance,
        cell_mm: args.cell_mm,
        ..BuildOptions::default()
    }
}

/// The build settings of the demo's parts, for the bench the demo measures on.
fn build_options(
    args: &DemoArgs,
    rig: &RigConfig,
    mech: &Mechanism,
) -> anyhow::Result<BuildOptions> {
    Ok(BuildOptions {
        bench: Some(Bench::from_rig(rig, mech.class)?),
        ..parts_settings(args)
    })
}

/// Cache key of the parts: the mechanism file's bytes, the build settings and `tool`, the
/// fingerprint of the program that builds them ([`tool_fingerprint`]).
fn parts_key(mechanism_bytes: &[u8], o: &BuildOptions, tool: &str) -> String {
    short_hash(
        mechanism_bytes,
        &format!(
            "scale={:?} clearance={} cell={} simplify={} bench={} without={:?} tool={tool}",
            o.scale_mm,
            o.clearance_mm,
            o.cell_mm,
            o.simplify_mm,
            o.bench.as_ref().map_or(String::new(), |b| b.to_string()),
            o.without_pair,
        ),
    )
}

/// What identifies the code that builds and simulates the parts: the SHA-256 of the running
/// executable, or the tool version when the executable cannot be read. The version alone
/// stays the same across commits, so a checkout that ran `demo` before a change to the parts
/// (the magnet cap carried up the column, e2ca13f) kept showing the old parts; the parts
/// take minutes to build, a hash of the executable a third of a second.
fn tool_fingerprint() -> String {
    let exe = std::env::current_exe().and_then(std::fs::read);
    match exe {
        Ok(bytes) => short_hash(&bytes, ""),
        Err(_) => format!("version {}", env!("CARGO_PKG_VERSION")),
    }
}

/// Remove the `parts-*` folders beside `keep` other than `keep` itself: parts built for other
/// settings or by another build of the tool. Each set is several hundred MB (the 0.4 mm
/// meshes, the 3MF and the GLB), and a new one is written after every change of the tool,
/// so the demo's cache keeps only the latest. A `*.partial` folder is left alone: another
/// run may be writing it (an interrupted one is removed by the next build of its key).
/// Says what it removed; a folder it cannot remove is reported and left.
fn prune_other_parts(keep: &Path) {
    let (Some(parent), Some(name)) = (keep.parent(), keep.file_name()) else {
        return;
    };
    let Ok(entries) = std::fs::read_dir(parent) else {
        return;
    };
    for e in entries.flatten() {
        let other = e.file_name();
        let other = other.to_string_lossy();
        if other == name.to_string_lossy()
            || !other.starts_with("parts-")
            || other.ends_with(".partial")
        {
            continue;
        }
        let path = e.path();
        match std::fs::remove_dir_all(&path) {
            Ok(()) => eprintln!("      removed older parts {}", path.display()),
            Err(err) => eprintln!(
                "      could not remove older parts {}: {err}",
                path.display()
            ),
        }
    }
}

/// The parts built from the mechanism (read from `mech_path`, whose bytes `mech_bytes` key
/// the cache), or the cached ones in `cache` (the mechanism's cache folder): their folder,
/// whether they were cached, and the build's problems (empty when the parts are
/// printable). A build that is not printable still leaves its parts, which the prediction
/// then moves; a mechanism the build cannot lay out is an error.
fn parts_for(
    mech_path: &Path,
    mech_bytes: &[u8],
    mech: &Mechanism,
    opts: &BuildOptions,
    cache: &Path,
) -> anyhow::Result<(PathBuf, bool, Vec<String>)> {
    let dir = cache.join(format!(
        "parts-{}",
        parts_key(mech_bytes, opts, &tool_fingerprint())
    ));
    // `build.json` is the last file a build writes: its presence marks a whole build.
    if let Ok(done) = crate::predict::BuiltParts::load(&dir) {
        return Ok((dir, true, done.problems));
    }
    let t0 = Instant::now();
    let built =
        crate::build::build(mech, opts, &|s| eprintln!("      {s}")).with_context(|| {
            format!(
                "building the parts of {} (`--plant target` measures the target law without parts)",
                mech_path.display()
            )
        })?;
    written_aside(&dir, |partial| {
        crate::build::output::write(&built, mech_path, opts, partial, &|s| {
            eprintln!("      {s}")
        })?;
        Ok(())
    })?;
    eprintln!("      built in {:.1} s", t0.elapsed().as_secs_f64());
    prune_other_parts(&dir);
    Ok((dir, false, built.problems.clone()))
}

/// Fill the folder `dir` by `write` into `dir.partial` (emptied first) and rename it when
/// `write` is done, replacing what `dir` held: an interrupted step never leaves a folder
/// that looks whole to the next run.
fn written_aside(
    dir: &Path,
    write: impl FnOnce(&Path) -> anyhow::Result<()>,
) -> anyhow::Result<()> {
    let mut name = dir.file_name().unwrap_or_default().to_os_string();
    name.push(".partial");
    let partial = dir.with_file_name(name);
    for stale in [&partial, dir] {
        if stale.exists() {
            std::fs::remove_dir_all(stale)
                .with_context(|| format!("removing the unfinished {}", stale.display()))?;
        }
    }
    write(&partial)?;
    std::fs::rename(&partial, dir)
        .with_context(|| format!("renaming {} to {}", partial.display(), dir.display()))
}

/// The prediction of how the parts in `parts` move the follower, written into
/// `parts/prediction/` (or the one already there: the parts' folder is keyed by everything
/// the prediction depends on); its `prediction.json`.
fn prediction_for(mech_path: &Path, mech: &Mechanism, parts: &Path) -> anyhow::Result<PathBuf> {
    let out = parts.join(super::simulate::DEFAULT_OUT_DIR);
    let file = out.join(crate::predict::output::PREDICTION_FILE);
    if PlayTable::load(&file).is_ok() {
        eprintln!("      reusing {}", file.display());
        return Ok(file);
    }
    let p = crate::predict::predict(mech, parts, &PredictOptions::default())
        .with_context(|| format!("simulating the parts in {}", parts.display()))?;
    written_aside(&out, |partial| {
        crate::predict::output::write(&p, mech_path, parts, partial)?;
        Ok(())
    })?;
    let lost = p.samples.iter().filter(|s| s.drive_lost).count();
    eprintln!(
        "      worst play {:.3}°, worst deviation from the target {:.3}° at driver {:.1}°{} ({:.1} s)",
        p.worst_play.deg,
        p.worst_deviation.deg,
        p.worst_deviation.driver_deg,
        if lost == 0 {
            String::new()
        } else {
            format!("; drive lost at driver {}", p.lost_windows_text())
        },
        p.seconds
    );
    Ok(file)
}

/// Where the demo's mechanism comes from.
enum Source {
    /// Synthesized from (or cached for) this motion file.
    Motion(PathBuf),
    /// Given by `--mechanism`.
    Given(PathBuf),
}

/// Run `demo`.
pub fn run(args: DemoArgs) -> anyhow::Result<ExitCode> {
    let source = match (&args.mechanism, &args.motion) {
        (Some(m), _) => Source::Given(super::mechanism_file(m)),
        (None, Some(p)) => Source::Motion(p.clone()),
        (None, None) => {
            let p = shipped(&format!("data/motions/{}.toml", args.example));
            if !p.exists() {
                bail!(
                    "no example `{}` (looked for {}); the examples are the files in data/motions",
                    args.example,
                    p.display()
                );
            }
            Source::Motion(p)
        }
    };
    let motion = match &source {
        Source::Motion(p) => {
            Motion::from_file(p).with_context(|| format!("loading {}", p.display()))?
        }
        Source::Given(m) => Motion::from_mechanism_file(m)
            .with_context(|| format!("reading the target law of {}", m.display()))?,
    };
    let mut plant = super::sim_device::plant_from(&args.faults)?;
    let plant_kind = plant_for(&args, motion.class())?;
    if plant_kind == DemoPlant::Geometry {
        // The build would refuse these only after the synthesis.
        parts_settings(&args).check_ranges()?;
    }
    let rig_path = shipped(rig_for(args.bench, motion.class()));
    let rig = RigConfig::load(&rig_path)?;
    // Refuse a plan the bench would refuse before minutes of synthesis (issue 20).
    session::check_run(
        &rig,
        &session::RunPlan {
            speed_rpm: args.speed,
            cycles: args.cycles,
            settle_cycles: session::DEFAULT_SETTLE_CYCLES,
            reverse: !args.no_reverse,
        },
    )
    .with_context(|| format!("the demo's run on rig {}", rig_path.display()))?;

    let steps = match plant_kind {
        DemoPlant::Geometry => 6,
        DemoPlant::Target => 4,
    };
    let mut step = 0;
    let mut next = || {
        step += 1;
        format!("[{step}/{steps}]")
    };
    eprintln!(
        "{} mechanism for {} ({})",
        next(),
        motion.name(),
        motion.class()
    );
    let (mech_path, cached) = match &source {
        Source::Motion(motion_path) => mechanism_for(&args, plant_kind, motion_path, &motion)?,
        Source::Given(file) => (file.clone(), true),
    };
    // The file's bytes key the caches of its parts (read once, for every key).
    let mech_bytes =
        std::fs::read(&mech_path).with_context(|| format!("reading {}", mech_path.display()))?;
    let cache_dir = match &source {
        Source::Motion(_) => mech_path
            .parent()
            .unwrap_or_else(|| Path::new("."))
            .to_path_buf(),
        Source::Given(_) => args.out.join("mechanisms").join(format!(
            "{}-{}",
            motion.name(),
            short_hash(&mech_bytes, "")
        )),
    };
    // How the mechanism came: the progress line's verb and the headline's note.
    let (origin, note) = match (&source, cached) {
        (Source::Given(_), _) => ("given", " (given)"),
        (_, true) => ("reusing", " (cached)"),
        (_, false) => ("wrote", ""),
    };
    eprintln!("      {origin} {}", mech_path.display());
    let target = match &source {
        Source::Given(_) => motion.clone(),
        Source::Motion(_) => Motion::from_mechanism_file(&mech_path)
            .with_context(|| format!("reading the target law of {}", mech_path.display()))?,
    };

    // The parts and how they move the follower (the geometry plant).
    let mut parts: Option<(PathBuf, bool, Vec<String>)> = None;
    let mut prediction: Option<PathBuf> = None;
    if plant_kind == DemoPlant::Geometry {
        let mech = Mechanism::load(&mech_path)?;
        let opts = build_options(&args, &rig, &mech)?;
        eprintln!(
            "{} printable parts at {} mm cells, {} mm clearance, for bench {}",
            next(),
            opts.cell_mm,
            opts.clearance_mm,
            opts.bench.as_ref().map_or(String::new(), |b| b.to_string())
        );
        let (dir, parts_cached, problems) =
            parts_for(&mech_path, &mech_bytes, &mech, &opts, &cache_dir)?;
        eprintln!(
            "      {} {}",
            if parts_cached { "reusing" } else { "wrote" },
            dir.display()
        );
        for p in &problems {
            eprintln!("      not printable: {p}");
        }
        eprintln!("{} how the parts move the follower", next());
        let file = prediction_for(&mech_path, &mech, &dir)?;
        let table =
            PlayTable::load(&file).context("reading the prediction for the geometry plant")?;
        plant.play = Some(Arc::new(table));
        parts = Some((dir, parts_cached, problems));
        prediction = Some(file);
    }

    eprintln!("{} starting the simulated {:?} bench", next(), args.bench);
    let sim = Sim::spawn(args.bench, target, plant, &rig)?;
    eprintln!(
        "      device on {}{}",
        sim.ports().join(" "),
        match plant_kind {
            DemoPlant::Geometry => ", follower moved by the parts",
            DemoPlant::Target => ", follower on the target law",
        }
    );

    eprintln!(
        "{} measuring {} cycle(s){} at {} rpm",
        next(),
        args.cycles,
        if args.no_reverse {
            ""
        } else {
            " forward and reverse"
        },
        args.speed
    );
    let run_dir = args.out.join("runs").join(format!(
        "{}-{}-{}",
        utc_dir_stamp(SystemTime::now()),
        motion.name(),
        match args.bench {
            DemoBench::Stepper => "stepper",
            DemoBench::Dynamixel => "dynamixel",
        }
    ));
    let cancel = Arc::new(AtomicBool::new(false));
    {
        let cancel = cancel.clone();
        // Only the first handler wins; in tests the process may already have one.
        let _ = ctrlc::set_handler(move || cancel.store(true, Ordering::Relaxed));
    }
    let mut last = Instant::now();
    let mut opts = MeasureOptions {
        rig_path: rig_path.clone(),
        ports: sim.ports(),
        target: TargetSpec::Mechanism(mech_path.clone()),
        speed_rpm: args.speed,
        cycles: args.cycles,
        settle_cycles: session::DEFAULT_SETTLE_CYCLES,
        reverse: !args.no_reverse,
        out_dir: Some(run_dir.clone()),
        replace: false,
        cancel,
        live: None,
        progress: Some(Box::new(move |p: &Progress| {
            // Every second, and the end of each measured direction.
            let end_of_direction = p.phase != Phase::Settle && p.cycle >= f64::from(p.cycles);
            if last.elapsed().as_secs_f64() >= 1.0 || end_of_direction {
                eprintln!("      {}", super::measure::progress_line(p));
                last = Instant::now();
            }
        })),
    };
    let outcome = session::measure(&mut opts).context("measuring on the simulated bench")?;
    drop(sim);
    if !outcome.complete {
        eprintln!(
            "      the session ended early ({}); analysing what was recorded",
            outcome.end
        );
    }

    eprintln!("{} analysing {}", next(), outcome.dir.display());
    let report = ReportOptions {
        tol_deg: args.tol_deg,
        tol_ratio: args.tol_ratio,
        prediction: prediction.clone(),
        parts: parts.as_ref().map(|p| p.0.clone()),
        ..Default::default()
    };
    let summary = analyze_and_report(&outcome.dir, &report)
        .with_context(|| format!("analysing {}", outcome.dir.display()))?;
    println!();
    println!("mechanism: {}{note}", mech_path.display());
    if let Some((dir, parts_cached, problems)) = &parts {
        println!(
            "parts:     {} ({}{})",
            dir.display(),
            if *parts_cached { "cached, " } else { "" },
            if problems.is_empty() {
                "printable".to_string()
            } else {
                format!("NOT printable: {}", problems.join("; "))
            }
        );
    }
    if let Some(p) = &prediction {
        println!("predicted: {}", p.display());
    }
    println!("recording: {}", outcome.dir.display());
    crate::cli::analyze::print_summary(&summary, &outcome.dir.join("report"));
    Ok(ExitCode::from(crate::cli::analyze::exit_status(&summary)))
}

/// A running simulated bench of any kind (stopped when dropped).
enum Sim {
    Stepper(crate::rig::sim::stepper::SimHandle),
    Dynamixel(crate::rig::sim::dynamixel::SimDynamixelHandle),
    Mixed(crate::rig::sim::mixed::SimMixedHandle),
}

impl Sim {
    fn spawn(
        bench: DemoBench,
        target: Motion,
        plant: PlantConfig,
        rig: &RigConfig,
    ) -> anyhow::Result<Sim> {
        Ok(match bench {
            DemoBench::Stepper => {
                let opts = crate::rig::sim::stepper::SimStepperOptions {
                    target,
                    plant,
                    mechanics: crate::rig::sim::stepper::Mechanics::from_rig(rig)?,
                    link: None,
                    driver: None,
                };
                Sim::Stepper(crate::rig::sim::stepper::spawn(opts)?)
            }
            DemoBench::Dynamixel if rig.is_mixed() => {
                Sim::Mixed(crate::rig::sim::mixed::spawn(rig, target, plant)?)
            }
            DemoBench::Dynamixel => {
                let law = crate::rig::sim::dynamixel::MotionTarget::new(target)?;
                let mut opts = crate::rig::sim::dynamixel::SimDynamixelOptions::new(Arc::new(law));
                opts.plant = plant;
                Sim::Dynamixel(crate::rig::sim::dynamixel::spawn(opts)?)
            }
        })
    }

    /// The `--port` values that point the rig at this bench.
    fn ports(&self) -> Vec<String> {
        match self {
            Sim::Stepper(h) => vec![h.path().display().to_string()],
            Sim::Dynamixel(h) => vec![h.path().display().to_string()],
            Sim::Mixed(h) => h.port_overrides(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser as _;

    /// The demo's arguments as typed after `mpc-rig demo`.
    fn demo_args(extra: &[&str]) -> DemoArgs {
        #[derive(clap::Parser)]
        struct Cli {
            #[command(flatten)]
            demo: DemoArgs,
        }
        Cli::parse_from(std::iter::once("demo").chain(extra.iter().copied())).demo
    }

    /// Guards the demo's plant choice: the parts for 1R and 1R1T by default, the target law
    /// for 3R, which the prediction does not handle yet, `--plant` obeyed where it can be, and
    /// only the geometry plant synthesizes the printable layout (the target plant keeps
    /// the default one, and its cache key, so the earlier demos' mechanisms are reused).
    #[test]
    fn the_plant_is_the_parts_for_1r_and_1r1t_and_the_target_law_otherwise() {
        let default = demo_args(&[]);
        for class in [MotionClass::R1, MotionClass::R1T1] {
            assert_eq!(plant_for(&default, class).unwrap(), DemoPlant::Geometry);
        }
        assert_eq!(
            plant_for(&default, MotionClass::R3).unwrap(),
            DemoPlant::Target
        );
        let target = demo_args(&["--plant", "target"]);
        assert_eq!(
            plant_for(&target, MotionClass::R1).unwrap(),
            DemoPlant::Target
        );
        let geometry = demo_args(&["--plant", "geometry"]);
        assert!(plant_for(&geometry, MotionClass::R3).is_err());
        let quick = demo_args(&["--quick"]);
        assert_eq!(
            plant_for(&quick, MotionClass::R1).unwrap(),
            DemoPlant::Target
        );
        let both = demo_args(&["--quick", "--plant", "geometry"]);
        assert!(plant_for(&both, MotionClass::R1).is_err());
        let printable = synth_options(&default, DemoPlant::Geometry);
        assert!(printable.printed_rim && printable.axis_room.is_some());
        let plain = synth_options(&default, DemoPlant::Target);
        assert!(!plain.printed_rim && plain.axis_room.is_none());
        assert_ne!(cache_key(b"m", &printable), cache_key(b"m", &plain));
    }

    /// Guards the parts' cache key: the same mechanism and settings give the same folder,
    /// and a change of the mechanism, the clearance, the cell, the bench or the program
    /// another.
    #[test]
    fn the_parts_are_rebuilt_when_what_they_depend_on_changes() {
        let o = BuildOptions::default();
        let key = parts_key(b"mechanism", &o, "tool");
        assert_eq!(key, parts_key(b"mechanism", &o, "tool"));
        assert_ne!(key, parts_key(b"mechanism2", &o, "tool"));
        for changed in [
            BuildOptions {
                clearance_mm: 0.5,
                ..BuildOptions::default()
            },
            BuildOptions {
                cell_mm: 0.7,
                ..BuildOptions::default()
            },
        ] {
            assert_ne!(key, parts_key(b"mechanism", &changed, "tool"));
        }
        let rig = RigConfig::load(&shipped("rigs/sim-dynamixel.toml")).unwrap();
        let horn = BuildOptions {
            bench: Some(Bench::from_rig(&rig, crate::synth::Class::R1).unwrap()),
            ..BuildOptions::default()
        };
        assert_ne!(key, parts_key(b"mechanism", &horn, "tool"));
        assert_ne!(key, parts_key(b"mechanism", &o, "another build"));
    }

    /// Guards the cache's size: writing new parts removes the other `parts-*` folders of
    /// the same mechanism (other settings, another build of the tool) and nothing else, not
    /// even a folder another run may be writing.
    #[test]
    fn new_parts_replace_the_older_ones() {
        let dir = tempfile::tempdir().unwrap();
        for sub in ["parts-new", "parts-old", "parts-old.partial", "report"] {
            std::fs::create_dir_all(dir.path().join(sub).join("prediction")).unwrap();
        }
        std::fs::write(dir.path().join("mechanism.json"), "{}").unwrap();
        prune_other_parts(&dir.path().join("parts-new"));
        let mut left: Vec<String> = std::fs::read_dir(dir.path())
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        left.sort();
        assert_eq!(
            left,
            ["mechanism.json", "parts-new", "parts-old.partial", "report"]
        );
    }

    /// Guards the demo's bench choice: every class gets a simulated rig that has its
    /// sensors (and the file loads); the Dynamixel bench reads 1R1T and 3R followers
    /// through a firmware sensor board (a mixed rig).
    #[test]
    fn demo_picks_a_rig_that_can_measure_the_class() {
        for class in [MotionClass::R1, MotionClass::R1T1, MotionClass::R3] {
            let path = rig_for(DemoBench::Stepper, class);
            let rig = RigConfig::load(&shipped(path)).unwrap();
            use crate::rig::config::SensorConfig as S;
            let has = |kind: &str| {
                rig.sensors.iter().any(|s| {
                    matches!(
                        (kind, s),
                        ("as5600", S::As5600(_))
                            | ("quadrature", S::Quadrature(_))
                            | ("imu", S::Imu(_))
                    )
                })
            };
            match class {
                MotionClass::R1 => assert!(has("as5600"), "{path}"),
                MotionClass::R1T1 => assert!(has("as5600") && has("quadrature"), "{path}"),
                MotionClass::R3 => assert!(has("imu"), "{path}"),
            }
        }
        assert_eq!(
            rig_for(DemoBench::Dynamixel, MotionClass::R1),
            "rigs/sim-dynamixel.toml"
        );
        for class in [MotionClass::R1T1, MotionClass::R3] {
            let path = rig_for(DemoBench::Dynamixel, class);
            let rig = RigConfig::load(&shipped(path)).unwrap();
            assert!(
                rig.is_mixed(),
                "{path}: a servo bench needs the sensor board"
            );
        }
    }
}
