//! `mpc-rig sim-device …`: serve a simulated bench on a pseudo-terminal until stopped.
//!
//! Prints the pseudo-terminal path on the first line of standard output (scripts and tests
//! read it; a mixed bench prints `NAME=PATH` per port), then serves until Ctrl-C or a configured disconnect (`--fault
//! disconnect_at_s=…`). Only argument handling lives here; the simulators are
//! [`crate::rig::sim`].

use std::io::Write;
use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Duration;

use anyhow::Context;
use clap::{Args, Subcommand};

use crate::motion::Motion;
use crate::predict::table::PlayTable;
use crate::rig::config::RigConfig;
use crate::rig::sim::dynamixel::{
    self, BusConfig, HardwareFault, MotionTarget, ServerEnd, SimDynamixelOptions,
};
use crate::rig::sim::mixed;
use crate::rig::sim::plant::PlantConfig;
use crate::rig::sim::stepper::{self, Mechanics, SimStepperOptions};
use crate::rig::target;
use crate::synth::mechanism::Mechanism;

/// Serve a simulated device on a pseudo-terminal.
#[derive(Debug, Args)]
pub struct SimDeviceArgs {
    /// Which bench to simulate.
    #[command(subcommand)]
    pub device: SimDevice,
}

/// The simulated devices.
#[derive(Debug, Subcommand)]
pub enum SimDevice {
    /// Our stepper firmware: the real firmware core on emulated pins and I²C sensors
    /// (AS5600, BNO055) whose follower obeys the plant model.
    Stepper(SimStepperArgs),
    /// A Dynamixel Protocol 2.0 bus: an XL430-W250 driver servo and a torque-off XL430
    /// follower servo whose present position obeys the plant model.
    Dynamixel(SimDynamixelArgs),
    /// The board image of firmware/rp2040 in the rp2040js emulator (Node.js), on the
    /// stepper bench's plant and sensors; its USB serial port on a pseudo-terminal.
    Pico(super::sim_pico::SimPicoArgs),
    /// A mixed bench from a rig file with `[sensor_board]`: a Dynamixel bus whose driver
    /// servo turns the mechanism and our firmware reading the follower on a second
    /// pseudo-terminal. Prints `NAME=PATH NAME=PATH` (the rig's port names) on its first
    /// line: pass each with `--port NAME=PATH`.
    Mixed(SimMixedArgs),
}

/// Options of `sim-device mixed`.
#[derive(Debug, Args)]
pub struct SimMixedArgs {
    /// The motion to serve.
    #[command(flatten)]
    pub target: TargetArgs,
    /// The mixed rig (e.g. rigs/sim-dynamixel-imu.toml): driver servo ID and gear, the
    /// board's sensors, the port names.
    #[arg(long, value_name = "FILE")]
    pub rig: PathBuf,
    /// Plant imperfection or link fault, `key=value`, repeatable; link faults apply to
    /// both pseudo-terminals (the keys are listed by --help).
    #[arg(long = "fault", value_name = "KEY=VALUE", long_help = fault_keys_help!(
        "Plant imperfection or link fault, repeatable; link faults apply to both pseudo-terminals."
    ))]
    pub faults: Vec<String>,
    /// The geometry plant.
    #[command(flatten)]
    pub geometry: GeometryArgs,
}

/// The geometry plant (docs/simulate.md).
#[derive(Debug, Args)]
pub struct GeometryArgs {
    /// Move the follower as the built parts would: the free turn over the driver angle
    /// from `mpc-rig simulate` (its prediction.json), under a drag, instead of exactly on
    /// the target law (1R).
    #[arg(long, value_name = "FILE")]
    pub prediction: Option<PathBuf>,
}

/// The target law: a mechanism or a motion file.
#[derive(Debug, Args)]
#[group(required = true, multiple = false)]
pub struct TargetArgs {
    /// mechanism.json (or its directory): the follower obeys its target law.
    #[arg(long, value_name = "PATH")]
    pub mechanism: Option<PathBuf>,
    /// Motion file (.toml keyframes or .csv dense): the follower obeys it.
    #[arg(long, value_name = "FILE")]
    pub motion: Option<PathBuf>,
}

/// Options of `sim-device dynamixel`.
#[derive(Debug, Args)]
pub struct SimDynamixelArgs {
    /// The motion to serve.
    #[command(flatten)]
    pub target: TargetArgs,
    /// Plant imperfection or link fault, `key=value`, repeatable (e.g. backlash=0.5,
    /// drop_prob=0.001, echo=1; the keys are listed by --help).
    #[arg(long = "fault", value_name = "KEY=VALUE", long_help = fault_keys_help!(
        "Plant imperfection or link fault, repeatable (e.g. backlash=0.5, drop_prob=0.001, echo=1)."
    ))]
    pub faults: Vec<String>,
    /// The geometry plant.
    #[command(flatten)]
    pub geometry: GeometryArgs,
    /// ID of the driver servo.
    #[arg(long, default_value_t = 1)]
    pub driver_id: u8,
    /// ID of the follower servo (torque off, the follower encoder).
    #[arg(long, default_value_t = 2)]
    pub follower_id: u8,
    /// Servo revolutions per mechanism driver revolution.
    #[arg(long, default_value_t = 1.0)]
    pub gear_ratio: f64,
    /// Follower servo's present position at the follower's zero (its mounting).
    #[arg(long, default_value_t = 1024.0)]
    pub follower_zero: f64,
    /// Answer immediately instead of pacing replies at the control table's baud rate.
    #[arg(long)]
    pub no_pacing: bool,
    /// Latch an overload hardware error on the driver this many seconds after start (it
    /// turns torque off, as the default Shutdown mask does on a real servo).
    #[arg(long, value_name = "S")]
    pub overload_at_s: Option<f64>,
}

/// Options of `sim-device stepper`.
#[derive(Debug, Args)]
pub struct SimStepperArgs {
    /// The motion to serve.
    #[command(flatten)]
    pub target: TargetArgs,
    /// Plant imperfection or link fault, `key=value`, repeatable (e.g. backlash=0.5,
    /// missed_step_prob=0.001; the keys are listed by --help).
    #[arg(long = "fault", value_name = "KEY=VALUE", long_help = fault_keys_help!(
        "Plant imperfection or link fault, repeatable (e.g. backlash=0.5, missed_step_prob=0.001)."
    ))]
    pub faults: Vec<String>,
    /// The geometry plant.
    #[command(flatten)]
    pub geometry: GeometryArgs,
    /// Take the bench's mechanics (steps/rev, microsteps, gear, direction, fitted sensors)
    /// from this rig file; default: those of rigs/sim-stepper.toml.
    #[arg(long, value_name = "FILE")]
    pub rig: Option<PathBuf>,
    /// Also expose the device at this stable path (a symlink kept across simulated
    /// re-plugs; one is made in the temp directory when `dropout_at_s` is given).
    #[arg(long, value_name = "PATH")]
    pub link: Option<PathBuf>,
}

/// Run `sim-device`.
pub fn run(args: SimDeviceArgs) -> anyhow::Result<ExitCode> {
    match args.device {
        SimDevice::Stepper(a) => run_stepper(a),
        SimDevice::Dynamixel(a) => run_dynamixel(a),
        SimDevice::Mixed(a) => run_mixed(a),
        SimDevice::Pico(a) => super::sim_pico::run(a),
    }
}

fn run_mixed(a: SimMixedArgs) -> anyhow::Result<ExitCode> {
    let rig = RigConfig::load(&a.rig)?;
    let target = load_target(&a.target, Some(&rig))?;
    let plant = geometry_plant(&a.faults, &a.geometry, &target)?;
    let motion = target.motion;
    let sim = mixed::spawn(&rig, motion, plant).context("starting the simulated mixed bench")?;
    {
        let mut out = std::io::stdout().lock();
        writeln!(out, "{}", sim.port_overrides().join(" "))?;
        out.flush()?;
    }
    eprintln!(
        "simulated mixed bench `{}`: {}; Ctrl-C stops",
        rig.name,
        sim.ports()
            .iter()
            .map(|(n, p)| format!("{n} on {}", p.display()))
            .collect::<Vec<_>>()
            .join(", ")
    );
    serve_until_ctrl_c(|| sim.is_running())?;
    eprintln!("stopped");
    Ok(ExitCode::SUCCESS)
}

/// Block until Ctrl-C or until the simulator stops serving by itself.
pub(super) fn serve_until_ctrl_c(running: impl Fn() -> bool) -> anyhow::Result<()> {
    let stop = Arc::new(AtomicBool::new(false));
    let flag = stop.clone();
    ctrlc::set_handler(move || flag.store(true, Ordering::Relaxed))
        .context("installing the Ctrl-C handler")?;
    while !stop.load(Ordering::Relaxed) && running() {
        std::thread::sleep(Duration::from_millis(50));
    }
    Ok(())
}

/// The plant `--fault` describes. The library's error names the flag, the key and what is
/// wrong (and lists the known keys for an unknown one); a context listing the keys again
/// put them before the problem, twice (issue 18).
pub(super) fn plant_from(faults: &[String]) -> anyhow::Result<PlantConfig> {
    Ok(PlantConfig::from_faults(faults)?)
}

/// The plant of `faults`, moved by the built parts when `geometry` names a prediction
/// (refused for a 3R target, and for a prediction of another class than the target's).
pub(super) fn geometry_plant(
    faults: &[String],
    geometry: &GeometryArgs,
    target: &Target,
) -> anyhow::Result<PlantConfig> {
    let motion = &target.motion;
    let mut plant = plant_from(faults)?;
    if let Some(path) = &geometry.prediction {
        use crate::motion::MotionClass;
        if motion.class() == MotionClass::R3 {
            anyhow::bail!(
                "--prediction {}: the geometry plant handles 1R and 1R1T mechanisms; this \
                 target is {}",
                path.display(),
                motion.class()
            );
        }
        let table =
            PlayTable::load(path).context("reading the prediction for the geometry plant")?;
        if table.slides() != (motion.class() == MotionClass::R1T1) {
            anyhow::bail!(
                "--prediction {}: a prediction of a {} mechanism, but this target is {}",
                path.display(),
                if table.slides() { "1R1T" } else { "1R" },
                motion.class()
            );
        }
        // A prediction says which mechanism it was made for: another mechanism's target
        // would move the follower by the wrong parts' play.
        if let Some((mechanism, digest)) = &target.mechanism {
            if let Some((made_for, this)) =
                Mechanism::other_than(table.mechanism_digest(), Some(digest))
            {
                anyhow::bail!(
                    "--prediction {}: a prediction for another mechanism than {} (its mechanism \
                     digest is {}…, this one's {}…). Predict this one: mpc-rig simulate {}",
                    path.display(),
                    mechanism.display(),
                    Mechanism::short_digest(made_for),
                    Mechanism::short_digest(this),
                    mechanism.display()
                );
            }
        }
        plant.play = Some(std::sync::Arc::new(table));
    }
    Ok(plant)
}

fn run_stepper(a: SimStepperArgs) -> anyhow::Result<ExitCode> {
    let rig = a.rig.as_deref().map(RigConfig::load).transpose()?;
    let target = load_target(&a.target, rig.as_ref())?;
    let plant = geometry_plant(&a.faults, &a.geometry, &target)?;
    let motion = target.motion;
    let mechanics = match &rig {
        Some(r) => Mechanics::from_rig(r)?,
        None => Mechanics::default(),
    };
    let sim = stepper::spawn(SimStepperOptions {
        target: motion,
        plant,
        mechanics,
        link: a.link,
        driver: None,
    })
    .context("starting the simulated stepper bench")?;
    {
        let mut out = std::io::stdout().lock();
        writeln!(out, "{}", sim.path().display())?;
        out.flush()?;
    }
    eprintln!(
        "simulated stepper bench on {} (firmware core, board `{}`); Ctrl-C stops",
        sim.path().display(),
        stepper::SIM_BOARD_NAME
    );
    serve_until_ctrl_c(|| sim.is_running())?;
    let status = if sim.is_running() {
        sim.stop()?
    } else {
        sim.wait()?
    };
    eprintln!(
        "simulated stepper bench ended after {:.1} s: {} steps ({} missed), {} bytes out ({} dropped, {} corrupted){}",
        status.time_s,
        status.steps,
        status.missed_steps,
        status.bytes_out,
        status.bytes_dropped,
        status.bytes_corrupted,
        if status.disconnected { "; simulated unplug: pseudo-terminal closed" } else { "" }
    );
    Ok(ExitCode::SUCCESS)
}

/// The target law to serve: a mechanism only after the checks `synth --check` makes (a
/// broken file must not become a simulated bench that someone then runs a motor against),
/// and, when the bench comes from a rig file, one the rig's sensors can measure.
pub(super) fn load_target(t: &TargetArgs, rig: Option<&RigConfig>) -> anyhow::Result<Target> {
    let loaded = match (&t.mechanism, &t.motion) {
        (Some(m), _) => {
            let (mech, motion) = target::load_mechanism(m)?;
            Target {
                motion,
                mechanism: Some((m.clone(), mech.digest())),
            }
        }
        (None, Some(f)) => Target {
            motion: target::load_motion(f)?,
            mechanism: None,
        },
        (None, None) => anyhow::bail!("give --mechanism PATH or --motion FILE"),
    };
    if let Some(rig) = rig {
        target::check_measurable(rig, loaded.motion.class())?;
    }
    Ok(loaded)
}

/// A bench's target as [`load_target`] read it.
pub(super) struct Target {
    /// The law the follower obeys.
    pub motion: Motion,
    /// For a mechanism: its path as given and its
    /// [`digest`](crate::synth::mechanism::Mechanism::digest), which a prediction given to
    /// the geometry plant must carry.
    pub mechanism: Option<(PathBuf, String)>,
}

fn run_dynamixel(a: SimDynamixelArgs) -> anyhow::Result<ExitCode> {
    let target = load_target(&a.target, None)?;
    let plant = geometry_plant(&a.faults, &a.geometry, &target)?;
    let motion = target.motion;
    let target = MotionTarget::new(motion)?;
    let mut opts = SimDynamixelOptions::new(Arc::new(target));
    opts.plant = plant;
    opts.bus = BusConfig {
        driver_id: a.driver_id,
        follower_id: Some(a.follower_id),
        gear_ratio: a.gear_ratio,
        follower_zero_pulses: a.follower_zero,
        ..BusConfig::default()
    };
    opts.server.pace_wire = !a.no_pacing;
    if let Some(at_s) = a.overload_at_s {
        opts.server.hardware_faults.push(HardwareFault {
            at_s,
            driver: true,
            bits: dynamixel::control_table::hw_error::OVERLOAD,
        });
    }
    let sim = dynamixel::spawn(opts)?;
    {
        let mut out = std::io::stdout().lock();
        writeln!(out, "{}", sim.path().display())?;
        out.flush()?;
    }
    eprintln!(
        "simulated Dynamixel bus on {} (driver ID {}, follower ID {}, factory 57600 baud; answers at any baud); Ctrl-C stops",
        sim.path().display(),
        a.driver_id,
        a.follower_id
    );
    serve_until_ctrl_c(|| sim.is_running())?;
    match sim.stop() {
        ServerEnd::Disconnected => {
            eprintln!("simulated unplug (disconnect_at_s): pseudo-terminal closed")
        }
        ServerEnd::Stopped => eprintln!("stopped"),
    }
    Ok(ExitCode::SUCCESS)
}
