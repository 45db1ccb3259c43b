//! `mpc-rig sim-device`: serve a simulated bench on a pseudo-terminal until stopped.
//!
//! Prints the pseudo-terminal path on the first line of stdout (flushed), so scripts and
//! tests can start it and read where to connect.

use std::io::Write;
use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Duration;

use anyhow::Context;
use clap::{Args, Subcommand};

use crate::motion::Motion;
use crate::rig::config::RigConfig;
use crate::rig::sim::plant::{PlantConfig, FAULT_KEYS};
use crate::rig::sim::stepper::{self, Mechanics, SimStepperOptions};

/// Arguments of `mpc-rig sim-device`.
#[derive(Debug, Args)]
pub struct SimDeviceArgs {
    /// Which device to simulate.
    #[command(subcommand)]
    pub device: SimDevice,
}

/// The simulated devices.
#[derive(Debug, Subcommand)]
pub enum SimDevice {
    /// Our stepper firmware (the real firmware core) with a plant-driven follower.
    Stepper(StepperArgs),
}

/// The plant's target law: a mechanism or a motion file.
#[derive(Debug, Args)]
pub struct SimTargetArgs {
    /// A mechanism.json or the directory holding it.
    #[arg(long, value_name = "PATH", conflicts_with = "motion", required_unless_present = "motion")]
    pub mechanism: Option<PathBuf>,
    /// A motion file (.toml or .csv).
    #[arg(long, value_name = "FILE")]
    pub motion: Option<PathBuf>,
    /// Imperfection or link fault, key=value; repeatable. Keys: backlash_deg,
    /// phase_lag_deg, gain_error, encoder_noise_counts, encoder_resolution, imu_noise_deg,
    /// imu_bias_deg, missed_step_prob, scale_mm, drop_prob, corrupt_prob, disconnect_at_s,
    /// dropout_at_s, dropout_s, protocol_version, seed.
    #[arg(long, value_name = "KEY=VALUE")]
    pub fault: Vec<String>,
}

impl SimTargetArgs {
    /// Load the target law.
    pub fn load_motion(&self) -> anyhow::Result<Motion> {
        match (&self.mechanism, &self.motion) {
            (Some(m), _) => Motion::from_mechanism_file(m)
                .with_context(|| format!("loading mechanism {}", m.display())),
            (None, Some(m)) => {
                Motion::from_file(m).with_context(|| format!("loading motion {}", m.display()))
            }
            (None, None) => anyhow::bail!("give --mechanism PATH or --motion FILE"),
        }
    }

    /// Parse the `--fault` options.
    pub fn plant(&self) -> anyhow::Result<PlantConfig> {
        PlantConfig::from_faults(&self.fault).with_context(|| {
            let keys: Vec<&str> = FAULT_KEYS.iter().map(|(k, _)| *k).collect();
            format!("known fault keys: {}", keys.join(", "))
        })
    }
}

/// Arguments of `mpc-rig sim-device stepper`.
#[derive(Debug, Args)]
pub struct StepperArgs {
    /// Target law and faults.
    #[command(flatten)]
    pub target: SimTargetArgs,
    /// Take the bench's mechanics (steps/rev, microsteps, gear, sensors) from this rig
    /// file; default: those of rigs/sim-stepper.toml.
    #[arg(long, value_name = "FILE")]
    pub rig: Option<PathBuf>,
    /// Also expose the device at this stable path (a symlink kept across simulated
    /// re-plugs).
    #[arg(long, value_name = "PATH")]
    pub link: Option<PathBuf>,
}

/// Run the chosen simulator until Ctrl-C (or until a simulated unplug ends it).
pub fn run(args: SimDeviceArgs) -> anyhow::Result<ExitCode> {
    match args.device {
        SimDevice::Stepper(a) => run_stepper(a),
    }
}

fn run_stepper(args: StepperArgs) -> anyhow::Result<ExitCode> {
    let motion = args.target.load_motion()?;
    let plant = args.target.plant()?;
    let mechanics = match &args.rig {
        Some(r) => Mechanics::from_rig(&RigConfig::load(r)?)?,
        None => Mechanics::default(),
    };
    let sim = stepper::spawn(SimStepperOptions {
        target: motion,
        plant,
        mechanics,
        link: args.link,
    })
    .context("starting the simulated stepper bench")?;
    let mut stdout = std::io::stdout();
    writeln!(stdout, "{}", sim.path().display())?;
    stdout.flush()?;
    let stop = Arc::new(AtomicBool::new(false));
    {
        let stop = stop.clone();
        ctrlc::set_handler(move || stop.store(true, Ordering::Relaxed))
            .context("cannot install the Ctrl-C handler")?;
    }
    while !stop.load(Ordering::Relaxed) && sim.is_running() {
        std::thread::sleep(Duration::from_millis(50));
    }
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
        if status.disconnected { ", unplugged" } else { "" }
    );
    Ok(ExitCode::SUCCESS)
}
