//! The simulated mixed bench: a simulated Dynamixel bus whose driver servo turns the
//! mechanism, and a simulated sensor board (the real firmware core, as in
//! [`super::stepper`]) whose follower sensors read the same mechanism. Two
//! pseudo-terminals, as a real U2D2 and a real Pico are two USB devices.
//!
//! The board's plant follows the bus's driver angle ([`DriverAngleSource`]); each device
//! has its own [`Plant`](super::plant::Plant) built from the same configuration, so one
//! `--fault` list sets the mechanism's imperfections for both and its link faults on both
//! links. A follower servo on the bus (a Dynamixel sensor in the rig) is served too.
//!
//! Owns only the wiring of the two simulators from a rig file; it does not know the host.

use std::path::PathBuf;
use std::sync::Arc;

use crate::motion::Motion;
use crate::rig::config::{DriverConfig, RigConfig, SensorConfig};
use crate::rig::sim::dynamixel::{
    self, BusConfig, MotionTarget, SimDynamixelHandle, SimDynamixelOptions,
};
use crate::rig::sim::plant::{DriverAngleSource, PlantConfig, PlantLaw};
use crate::rig::sim::stepper::{self, Mechanics, SimHandle, SimStepperOptions};
use crate::rig::RigError;

/// A running simulated mixed bench; dropping it stops both devices.
pub struct SimMixedHandle {
    // Field order: the board stops first (it reads the bus's driver angle).
    board: SimHandle,
    bus: SimDynamixelHandle,
    bus_port: String,
    board_port: String,
}

impl std::fmt::Debug for SimMixedHandle {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SimMixedHandle")
            .field("bus", &self.bus.path())
            .field("board", &self.board.path())
            .finish()
    }
}

impl SimMixedHandle {
    /// The rig's port names with the pseudo-terminals serving them.
    pub fn ports(&self) -> Vec<(String, PathBuf)> {
        vec![
            (self.bus_port.clone(), self.bus.path().to_path_buf()),
            (self.board_port.clone(), self.board.path().to_path_buf()),
        ]
    }

    /// `--port` overrides (`NAME=PATH`) that point the rig at this bench.
    pub fn port_overrides(&self) -> Vec<String> {
        self.ports()
            .into_iter()
            .map(|(n, p)| format!("{n}={}", p.display()))
            .collect()
    }

    /// The simulated bus.
    pub fn bus(&self) -> &SimDynamixelHandle {
        &self.bus
    }

    /// The simulated sensor board.
    pub fn board(&self) -> &SimHandle {
        &self.board
    }

    /// Whether both devices are still serving.
    pub fn is_running(&self) -> bool {
        self.bus.is_running() && self.board.is_running()
    }
}

/// Start the simulated devices of a mixed rig (`[sensor_board]`, Dynamixel driver) whose
/// follower obeys `target`, both with the imperfections and link faults of `plant`.
pub fn spawn(
    rig: &RigConfig,
    target: Motion,
    plant: PlantConfig,
) -> Result<SimMixedHandle, RigError> {
    spawn_with(rig, target, plant.clone(), plant)
}

/// As [`spawn`], with separate configurations for the bus and the board (e.g. a link fault
/// on one of them only).
pub fn spawn_with(
    rig: &RigConfig,
    target: Motion,
    bus_plant: PlantConfig,
    board_plant: PlantConfig,
) -> Result<SimMixedHandle, RigError> {
    let (DriverConfig::Dynamixel(driver), Some(board)) = (&rig.driver, &rig.sensor_board) else {
        return Err(RigError::Setup(format!(
            "rig `{}` is not a mixed bench (a Dynamixel driver and a [sensor_board])",
            rig.name
        )));
    };
    let follower = rig.sensors.iter().find_map(|s| match s {
        SensorConfig::Dynamixel(d) => Some(d),
        _ => None,
    });
    let law: Arc<dyn PlantLaw> = match follower {
        Some(_) => Arc::new(MotionTarget::new(target.clone())?),
        None => Arc::new(target.clone()),
    };
    let mut opts = SimDynamixelOptions::new(law);
    opts.plant = bus_plant;
    opts.bus = BusConfig {
        driver_id: driver.id,
        follower_id: follower.map(|f| f.id),
        gear_ratio: driver.gear_ratio,
        follower_zero_pulses: follower.map_or(1024.0, |f| f.zero_offset),
        ..BusConfig::default()
    };
    let bus = dynamixel::spawn(opts)?;
    let source: DriverAngleSource = bus.driver_angle_source();
    let board_sim = stepper::spawn(SimStepperOptions {
        target,
        plant: board_plant,
        mechanics: Mechanics::sensor_board(rig)?,
        link: None,
        driver: Some(source),
    })?;
    Ok(SimMixedHandle {
        board: board_sim,
        bus,
        bus_port: driver.port.clone(),
        board_port: board.port.clone(),
    })
}
