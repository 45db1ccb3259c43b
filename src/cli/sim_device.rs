//! `mpc-rig sim-device …`: serve a simulated bench on a pseudo-terminal until stopped.
//!
//! Prints the pseudo-terminal path on the first line of standard output (scripts and tests
//! read it), then serves until Ctrl-C or a configured disconnect (`--fault
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
use crate::rig::sim::dynamixel::{
    self, BusConfig, HardwareFault, MotionTarget, ServerEnd, SimDynamixelOptions,
};
use crate::rig::sim::plant::{PlantConfig, FAULT_KEYS};

/// Serve a simulated device on a pseudo-terminal.
#[derive(Debug, Args)]
pub struct SimDeviceArgs {
    #[command(subcommand)]
    pub device: SimDevice,
}

/// The simulated devices.
#[derive(Debug, Subcommand)]
pub enum SimDevice {
    /// A Dynamixel Protocol 2.0 bus: an XL430-W250 driver servo and a torque-off XL430
    /// follower servo whose present position obeys the plant model.
    Dynamixel(SimDynamixelArgs),
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
    #[command(flatten)]
    pub target: TargetArgs,
    /// Plant imperfection or link fault, `key=value`, repeatable (e.g. backlash_deg=0.5,
    /// gain_error=0.01, encoder_noise_counts=1, drop_prob=0.001, corrupt_prob=0.001,
    /// disconnect_at_s=5, dropout_at_s=2, seed=7).
    #[arg(long = "fault", value_name = "KEY=VALUE")]
    pub faults: Vec<String>,
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

/// Run `sim-device`.
pub fn run(args: SimDeviceArgs) -> anyhow::Result<ExitCode> {
    match args.device {
        SimDevice::Dynamixel(a) => run_dynamixel(a),
    }
}

fn load_target(t: &TargetArgs) -> anyhow::Result<Motion> {
    match (&t.mechanism, &t.motion) {
        (Some(m), _) => Motion::from_mechanism_file(m)
            .with_context(|| format!("loading mechanism {}", m.display())),
        (None, Some(f)) => {
            Motion::from_file(f).with_context(|| format!("loading motion {}", f.display()))
        }
        (None, None) => anyhow::bail!("give --mechanism PATH or --motion FILE"),
    }
}

fn run_dynamixel(a: SimDynamixelArgs) -> anyhow::Result<ExitCode> {
    let motion = load_target(&a.target)?;
    let target = MotionTarget::new(motion)?;
    let plant = PlantConfig::from_faults(&a.faults).with_context(|| {
        let keys: Vec<&str> = FAULT_KEYS.iter().map(|k| k.0).collect();
        format!("known --fault keys: {}", keys.join(", "))
    })?;
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
    let stop = Arc::new(AtomicBool::new(false));
    let flag = stop.clone();
    ctrlc::set_handler(move || flag.store(true, Ordering::Relaxed))
        .context("installing the Ctrl-C handler")?;
    while !stop.load(Ordering::Relaxed) && sim.is_running() {
        std::thread::sleep(Duration::from_millis(50));
    }
    match sim.stop() {
        ServerEnd::Disconnected => {
            eprintln!("simulated unplug (disconnect_at_s): pseudo-terminal closed")
        }
        ServerEnd::Stopped => eprintln!("stopped"),
    }
    Ok(ExitCode::SUCCESS)
}
