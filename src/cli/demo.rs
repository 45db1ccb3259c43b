//! `mpc-rig demo`: the main job on a machine without hardware.
//!
//! Synthesizes the example mechanism (or reuses the cached one under `out/demo/`, keyed by
//! the motion file's SHA-256, the seed, the synthesis settings and the tool version), starts
//! a simulated bench in-process on pseudo-terminals (our firmware core behind the stepper
//! bench, or the Protocol 2.0 Dynamixel bus, with a firmware sensor board beside it for 1R1T
//! and 3R), measures a few cycles through the real serial
//! session, analyses the recording and prints where the mechanism and the report are, with
//! the headline figures. Options choose another example, the bench and injected faults
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
use crate::motion::{Motion, MotionClass};
use crate::rig::config::RigConfig;
use crate::rig::recording::{utc_dir_stamp, Phase};
use crate::rig::session::{self, MeasureOptions, Progress, TargetSpec};
use crate::rig::sim::plant::PlantConfig;
use crate::synth::{Mechanism, Outcome, SynthOptions};

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
    /// Synthesis seed.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Reduced synthesis effort (fewer candidates and GA generations): faster, maybe a worse
    /// mechanism. Used by the tests.
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

/// The synthesis settings of the demo.
fn synth_options(args: &DemoArgs) -> SynthOptions {
    let mut o = SynthOptions {
        seed: args.seed,
        cone: args.normal_cone.into(),
        ..SynthOptions::default()
    };
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

/// Cache key: motion bytes, seed, synthesis settings, tool version.
fn cache_key(motion_bytes: &[u8], o: &SynthOptions) -> String {
    let mut h = Sha256::new();
    h.update(motion_bytes);
    h.update(
        format!(
            "seed={} k={:?} dx={:?} n={} m={} g={} p={} e={} scale={} cone={} margin={} version={}",
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
            env!("CARGO_PKG_VERSION")
        )
        .as_bytes(),
    );
    h.finalize()
        .iter()
        .take(6)
        .map(|b| format!("{b:02x}"))
        .collect()
}

/// Synthesize or reuse the cached mechanism; returns its path and whether it was cached.
fn mechanism_for(
    args: &DemoArgs,
    motion_path: &Path,
    motion: &Motion,
) -> anyhow::Result<(PathBuf, bool)> {
    let bytes =
        std::fs::read(motion_path).with_context(|| format!("reading {}", motion_path.display()))?;
    let o = synth_options(args);
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

/// Run `demo`.
pub fn run(args: DemoArgs) -> anyhow::Result<ExitCode> {
    let motion_path = match &args.motion {
        Some(p) => p.clone(),
        None => {
            let p = shipped(&format!("data/motions/{}.toml", args.example));
            if !p.exists() {
                bail!(
                    "no example `{}` (looked for {}); the examples are the files in data/motions",
                    args.example,
                    p.display()
                );
            }
            p
        }
    };
    let motion = Motion::from_file(&motion_path)
        .with_context(|| format!("loading {}", motion_path.display()))?;
    let plant = super::sim_device::plant_from(&args.faults)?;
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

    eprintln!("[1/4] mechanism for {} ({})", motion.name(), motion.class());
    let (mech_path, cached) = mechanism_for(&args, &motion_path, &motion)?;
    eprintln!(
        "      {} {}",
        if cached { "reusing" } else { "wrote" },
        mech_path.display()
    );
    let target = Motion::from_mechanism_file(&mech_path)
        .with_context(|| format!("reading the target law of {}", mech_path.display()))?;

    eprintln!("[2/4] starting the simulated {:?} bench", args.bench);
    let sim = Sim::spawn(args.bench, target, plant, &rig)?;
    eprintln!("      device on {}", sim.ports().join(" "));

    eprintln!(
        "[3/4] measuring {} cycle(s){} at {} rpm",
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

    eprintln!("[4/4] analysing {}", outcome.dir.display());
    let report = ReportOptions {
        tol_deg: args.tol_deg,
        tol_ratio: args.tol_ratio,
        ..Default::default()
    };
    let summary = analyze_and_report(&outcome.dir, &report)
        .with_context(|| format!("analysing {}", outcome.dir.display()))?;
    println!();
    println!(
        "mechanism: {}{}",
        mech_path.display(),
        if cached { " (cached)" } else { "" }
    );
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
