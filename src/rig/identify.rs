//! What is on a serial port, for `measure --port` without a rig file, and the shipped rig
//! that fits it.
//!
//! Owns [`identify`]: our firmware answers its handshake with its board's name and the
//! sensors that answered at boot; failing that, a Dynamixel bus answers a broadcast ping
//! at one of the usual baud rates ([`DYNAMIXEL_BAUDS`]) with each servo's ID and model.
//! Neither moves anything. Owns the shipped rig files too ([`SHIPPED`], compiled in, so the
//! binary finds them wherever it runs), and [`default_rig`]: the first shipped rig made for
//! what was found (board, or servo bus; a pseudo-terminal is a simulator) whose sensors
//! the device has and that can measure the target's class. It does not run a session, and
//! a rig file stays the way to say anything that is not a default.

use std::path::{Path, PathBuf};

use mpc_wire::host::CommandChannel;
use mpc_wire::{Decoder, DeviceInfo, Report, SensorSet};

use crate::motion::MotionClass;
use crate::rig::backend::dynamixel::{echo, models, worker::DxlBus};
use crate::rig::backend::stepper::convert::SensorMap;
use crate::rig::backend::stepper::link;
use crate::rig::config::{DriverConfig, RigConfig, SensorConfig};
use crate::rig::RigError;

/// The rig files in `rigs/`, by name, as shipped.
pub const SHIPPED: [(&str, &str); 11] = [
    ("sim-stepper", include_str!("../../rigs/sim-stepper.toml")),
    (
        "sim-stepper-1r1t",
        include_str!("../../rigs/sim-stepper-1r1t.toml"),
    ),
    (
        "sim-stepper-imu",
        include_str!("../../rigs/sim-stepper-imu.toml"),
    ),
    ("sim-pico", include_str!("../../rigs/sim-pico.toml")),
    ("pico-as5600", include_str!("../../rigs/pico-as5600.toml")),
    ("pico-bno055", include_str!("../../rigs/pico-bno055.toml")),
    (
        "sim-dynamixel",
        include_str!("../../rigs/sim-dynamixel.toml"),
    ),
    ("xl430-bench", include_str!("../../rigs/xl430-bench.toml")),
    (
        "sim-dynamixel-1r1t",
        include_str!("../../rigs/sim-dynamixel-1r1t.toml"),
    ),
    (
        "sim-dynamixel-imu",
        include_str!("../../rigs/sim-dynamixel-imu.toml"),
    ),
    ("xl430-bno055", include_str!("../../rigs/xl430-bno055.toml")),
];

/// Baud rates a Dynamixel bus is scanned at, most likely first: the X series' factory
/// default 57 600, then 1 M (what most benches are set to), 115 200, and the fast 2 M, 3 M
/// and 4 M. A broadcast ping waits for 253 replies' wire time, 0.65 s at 57 600 and less
/// above, so the whole scan takes about 1.5 s when nothing answers.
pub const DYNAMIXEL_BAUDS: [u32; 6] = [57_600, 1_000_000, 115_200, 2_000_000, 3_000_000, 4_000_000];

/// What answered on a port.
#[derive(Debug, Clone, PartialEq)]
pub enum Found {
    /// Our firmware: its handshake.
    Firmware {
        /// The device's own description.
        info: DeviceInfo,
    },
    /// A Dynamixel Protocol 2.0 bus.
    Dynamixel {
        /// The baud rate it answered at.
        baud: u32,
        /// Each servo that answered: ID and model number.
        servos: Vec<(u8, u16)>,
    },
}

impl std::fmt::Display for Found {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Found::Firmware { info } => write!(
                f,
                "our firmware {} on board `{}` with sensors {}",
                link::version_string(info.firmware_version),
                info.board.as_str(),
                sensor_names(info.capabilities.sensors)
            ),
            Found::Dynamixel { baud, servos } => write!(
                f,
                "a Dynamixel bus at {baud} baud with {}",
                servos
                    .iter()
                    .map(|(id, m)| format!(
                        "ID {id} ({})",
                        models::model_name(*m).unwrap_or("unknown model")
                    ))
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
        }
    }
}

/// The sensors of a set, named as rig files name them.
fn sensor_names(s: SensorSet) -> String {
    let names: Vec<&str> = [
        (SensorSet::ENCODER_A, "AS5600 (channel 0)"),
        (SensorSet::ENCODER_B, "AS5600 (channel 1)"),
        (SensorSet::QUADRATURE, "quadrature"),
        (SensorSet::IMU, "BNO055"),
    ]
    .into_iter()
    .filter(|(bit, _)| s.contains(*bit))
    .map(|(_, n)| n)
    .collect();
    if names.is_empty() {
        "none".into()
    } else {
        names.join(", ")
    }
}

/// Find out what is on `path`: our firmware's handshake first, then a Dynamixel broadcast
/// ping at each of [`DYNAMIXEL_BAUDS`].
pub fn identify(path: &Path) -> Result<Found, RigError> {
    let firmware = {
        let mut port = link::open_port(path, 115_200)?;
        let mut decoder = Decoder::<Report>::new();
        let mut channel = CommandChannel::new(link::HANDSHAKE_RETRY, 0);
        link::handshake(&mut port, path, &mut decoder, &mut channel)
    };
    let firmware_said = match firmware {
        Ok(hs) => return Ok(Found::Firmware { info: hs.info }),
        // Our firmware, but another protocol version: that is the answer to give.
        Err(e @ RigError::VersionMismatch { .. }) => return Err(e),
        Err(e) => e.to_string(),
    };
    for baud in DYNAMIXEL_BAUDS {
        // dynamixel2 panics on an echoing adapter: ask the raw port first.
        if echo::port_echoes(path, baud, 1)? {
            return Err(RigError::WrongDevice {
                path: path.to_path_buf(),
                expected: crate::rig::error::NEITHER_KNOWN_DEVICE,
                detail: format!(
                    "it sends back what is written to it at {baud} baud: a Dynamixel adapter \
                     without echo suppression, which the bench cannot use (docs/faults.md)"
                ),
            });
        }
        let mut bus = DxlBus::open(path, baud).map_err(|e| RigError::Open {
            path: path.to_path_buf(),
            message: e.to_string(),
        })?;
        let servos: Vec<(u8, u16)> = match bus.scan() {
            Ok(replies) => replies
                .into_iter()
                .filter_map(|r| r.ok())
                .map(|r| (r.motor_id, r.data.model))
                .collect(),
            Err(_) => Vec::new(),
        };
        if !servos.is_empty() {
            return Ok(Found::Dynamixel { baud, servos });
        }
    }
    Err(RigError::WrongDevice {
        path: path.to_path_buf(),
        expected: crate::rig::error::NEITHER_KNOWN_DEVICE,
        detail: format!(
            "the firmware handshake said: {firmware_said}; no Dynamixel answered a broadcast \
             ping at {} baud",
            DYNAMIXEL_BAUDS.map(|b| b.to_string()).join(", ")
        ),
    })
}

/// Whether `path` is a pseudo-terminal: the simulators serve one, real adapters do not.
pub fn is_pseudo_terminal(path: &Path) -> bool {
    let real = std::fs::canonicalize(path).unwrap_or_else(|_| path.to_path_buf());
    real.starts_with("/dev/pts")
}

/// The shipped rigs made for `found` (on a pseudo-terminal when `simulated`), in order of
/// preference.
fn candidates(found: &Found, simulated: bool) -> Result<&'static [&'static str], String> {
    Ok(match found {
        Found::Firmware { info } => match (info.board.as_str(), simulated) {
            (crate::rig::sim::stepper::SIM_BOARD_NAME, _) => {
                &["sim-stepper", "sim-stepper-1r1t", "sim-stepper-imu"]
            }
            ("rp2040-pico", true) => &["sim-pico"],
            ("rp2040-pico", false) => &["pico-as5600", "pico-bno055"],
            (board, _) => {
                return Err(format!(
                    "no rig is shipped for board `{board}`: write one for it (rigs/README.md)"
                ))
            }
        },
        Found::Dynamixel { .. } if simulated => &["sim-dynamixel"],
        Found::Dynamixel { .. } => &["xl430-bench"],
    })
}

/// A shipped rig, parsed.
pub fn shipped(name: &str) -> Option<RigConfig> {
    let (_, text) = SHIPPED.iter().find(|(n, _)| *n == name)?;
    RigConfig::from_toml_str(text, &shipped_path(name)).ok()
}

/// Where a shipped rig lives in the repository (for messages and errors).
pub fn shipped_path(name: &str) -> PathBuf {
    PathBuf::from(format!("rigs/{name}.toml"))
}

/// Whether a shipped Dynamixel rig fits the servos found: its driver's ID answered with
/// its model and every follower servo's ID answered. Sets the driver's baud to the one
/// found.
fn fits_bus(rig: &mut RigConfig, baud: u32, servos: &[(u8, u16)]) -> Result<(), String> {
    let DriverConfig::Dynamixel(d) = &mut rig.driver else {
        return Err("not a Dynamixel rig".into());
    };
    let model = servos.iter().find(|s| s.0 == d.id).map(|s| s.1);
    match model {
        None => return Err(format!("its driver is ID {}, which did not answer", d.id)),
        Some(m) if Some(m) != models::model_number(&d.model) => {
            return Err(format!(
                "its driver, ID {}, should be model {} but is model {}",
                d.id,
                d.model,
                models::model_name(m).unwrap_or("unknown")
            ))
        }
        Some(_) => {}
    }
    d.baud = baud;
    for s in &rig.sensors {
        if let SensorConfig::Dynamixel(f) = s {
            if !servos.iter().any(|x| x.0 == f.id) {
                return Err(format!(
                    "its follower servo is ID {}, which did not answer",
                    f.id
                ));
            }
        }
    }
    Ok(())
}

/// The first shipped rig that fits `found` on `path` and measures `class`, with the port
/// set to `path`, and its name.
pub fn default_rig(
    found: &Found,
    path: &Path,
    class: MotionClass,
) -> Result<(&'static str, RigConfig), RigError> {
    let no_rig = |why: String| {
        RigError::Setup(format!(
            "{}: found {found}, but {why}; give a rig file with --rig (rigs/README.md)",
            path.display()
        ))
    };
    let names = candidates(found, is_pseudo_terminal(path)).map_err(no_rig)?;
    let mut refused = Vec::new();
    for name in names {
        let Some(mut rig) = shipped(name) else {
            continue;
        };
        let fit = match found {
            // The sensors the stepper backend would ask the board for.
            Found::Firmware { info } => match SensorMap::new(&rig) {
                Ok(map) if info.capabilities.sensors.contains(map.set) => Ok(()),
                Ok(map) => Err(format!("it reads {}", sensor_names(map.set))),
                Err(e) => Err(e.to_string()),
            },
            Found::Dynamixel { baud, servos } => fits_bus(&mut rig, *baud, servos),
        }
        .and_then(|()| match rig.missing_sensors(class) {
            None => Ok(()),
            Some(missing) => Err(format!("for a {class} follower {missing}")),
        });
        match fit {
            Ok(()) => {
                let p = path.display().to_string();
                rig.apply_port_overrides(std::slice::from_ref(&p))
                    .map_err(|e| no_rig(e.to_string()))?;
                return Ok((name, rig));
            }
            Err(why) => refused.push(format!("{name}: {why}")),
        }
    }
    Err(no_rig(format!(
        "no shipped rig fits ({})",
        refused.join("; ")
    )))
}

/// The text of shipped rig `name` with its (single) port's path set to `path`: what
/// `measure --save-rig` writes, the shipped comments kept, to edit and pass with `--rig`.
pub fn rig_file_text(name: &str, path: &Path) -> Option<String> {
    let (_, text) = SHIPPED.iter().find(|(n, _)| *n == name)?;
    let mut out = String::with_capacity(text.len() + 64);
    let mut in_ports = false;
    let mut done = false;
    for line in text.lines() {
        let t = line.trim_start();
        if t.starts_with('[') {
            in_ports = t.starts_with("[[ports]]");
        }
        let is_path = t.starts_with("path") && t.contains('=');
        let is_path_note = t.starts_with("# path");
        if in_ports && !done && (is_path || is_path_note) {
            out.push_str(&format!("path = {:?}\n", path.display().to_string()));
            done = true;
            continue;
        }
        if in_ports && !done && t.starts_with("name") {
            out.push_str(line);
            out.push('\n');
            // A rig without a path line gets one right after the port's name; a later
            // path or path note in the block is then dropped above.
            out.push_str(&format!("path = {:?}\n", path.display().to_string()));
            done = true;
            continue;
        }
        if in_ports && done && (is_path || is_path_note) {
            continue;
        }
        out.push_str(line);
        out.push('\n');
    }
    Some(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Guards the shipped rigs compiled in: every one parses (a rig file edited into
    /// something invalid fails here, not at a user's bench).
    #[test]
    fn every_shipped_rig_parses() {
        for (name, _) in SHIPPED {
            let rig = shipped(name).unwrap_or_else(|| panic!("{name} does not parse"));
            assert_eq!(rig.name, name);
        }
        let listed = std::fs::read_dir(concat!(env!("CARGO_MANIFEST_DIR"), "/rigs"))
            .unwrap()
            .filter(|e| {
                e.as_ref()
                    .unwrap()
                    .path()
                    .extension()
                    .is_some_and(|x| x == "toml")
            })
            .count();
        assert_eq!(listed, SHIPPED.len(), "a rig in rigs/ is not in SHIPPED");
    }

    fn firmware(board: &str, sensors: SensorSet) -> Found {
        Found::Firmware {
            info: DeviceInfo {
                ack: 0,
                protocol_version: mpc_wire::PROTOCOL_VERSION,
                firmware_version: [0, 3, 0],
                board: mpc_wire::BoardName::truncated(board),
                capabilities: mpc_wire::Capabilities {
                    sensors,
                    max_step_rate_hz: 50_000,
                    max_sample_rate_hz: 1000,
                    imu_rate_hz: 100,
                    max_batch: 32,
                },
                clock_hz: 1_000_000,
            },
        }
    }

    /// Guards the choice of rig: by board and by the target's class, the port set, and
    /// the reasons given when nothing fits.
    #[test]
    fn the_rig_fits_the_board_its_sensors_and_the_class() {
        let tty = Path::new("/dev/ttyACM0");
        let all = SensorSet::ENCODER_A | SensorSet::QUADRATURE | SensorSet::IMU;
        let sim = firmware("sim-stepper", all);
        let pick = |f: &Found, p: &Path, c| default_rig(f, p, c).map(|r| r.0);
        // A tty is not a pseudo-terminal, but the simulator's board name says it all.
        assert_eq!(pick(&sim, tty, MotionClass::R1).unwrap(), "sim-stepper");
        assert_eq!(
            pick(&sim, tty, MotionClass::R1T1).unwrap(),
            "sim-stepper-1r1t"
        );
        assert_eq!(pick(&sim, tty, MotionClass::R3).unwrap(), "sim-stepper-imu");
        let pico = firmware("rp2040-pico", SensorSet::ENCODER_A);
        let (name, rig) = default_rig(&pico, tty, MotionClass::R1).unwrap();
        assert_eq!(name, "pico-as5600");
        assert_eq!(rig.ports[0].path.as_deref(), Some(tty));
        let e = default_rig(&pico, tty, MotionClass::R3)
            .unwrap_err()
            .to_string();
        assert_eq!(
            e,
            "/dev/ttyACM0: found our firmware 0.3.0 on board `rp2040-pico` with sensors \
             AS5600 (channel 0), but no shipped rig fits (pico-as5600: for a 3R follower it \
             has no orientation sensor (`kind = \"imu\"`) on the follower (rigs/README.md \
             lists the sensors each class needs); pico-bno055: it reads BNO055); give a rig \
             file with --rig (rigs/README.md)"
        );
        let e = default_rig(&firmware("my-board", all), tty, MotionClass::R1)
            .unwrap_err()
            .to_string();
        assert!(e.contains("no rig is shipped for board `my-board`"), "{e}");

        let bus = Found::Dynamixel {
            baud: 1_000_000,
            servos: vec![(1, 1060), (2, 1060)],
        };
        let (name, rig) = default_rig(&bus, tty, MotionClass::R1).unwrap();
        assert_eq!(name, "xl430-bench");
        match &rig.driver {
            DriverConfig::Dynamixel(d) => assert_eq!(d.baud, 1_000_000),
            other => panic!("{other:?}"),
        }
        let lonely = Found::Dynamixel {
            baud: 57_600,
            servos: vec![(1, 1060)],
        };
        let e = default_rig(&lonely, tty, MotionClass::R1)
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("xl430-bench: its follower servo is ID 2, which did not answer"),
            "{e}"
        );
    }

    /// Guards the saved rig file: the port's path set (where the shipped file had a path,
    /// or only a note about it), comments kept, and the result loads as that rig.
    #[test]
    fn a_saved_rig_has_the_port_and_loads() {
        for name in ["sim-stepper", "pico-as5600", "xl430-bench"] {
            let text = rig_file_text(name, Path::new("/dev/ttyX9")).unwrap();
            assert_eq!(text.matches("path = \"/dev/ttyX9\"").count(), 1, "{text}");
            assert!(text.starts_with('#'), "comments kept: {text}");
            let rig = RigConfig::from_toml_str(&text, Path::new("saved.toml")).unwrap();
            assert_eq!(rig.ports[0].path.as_deref(), Some(Path::new("/dev/ttyX9")));
            assert_eq!(rig.name, name);
        }
    }
}
