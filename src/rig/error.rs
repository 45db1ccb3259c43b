//! The bench's error type.
//!
//! Owns [`RigError`], the one error every bench operation returns, with messages that tell
//! the user what to check (port, cable, firmware version, configuration field). It does not
//! decide exit codes; the command line maps errors to them.

use std::path::PathBuf;

use crate::rig::config::ConfigError;
use crate::rig::recording::RecordingError;
use crate::rig::sim::plant::PlantError;

/// [`RigError::WrongDevice`] on a port where our firmware was expected.
pub const NOT_OUR_FIRMWARE: &str =
    "does not speak the mpc-rig firmware protocol (is it a Dynamixel bus or another device?)";

/// [`RigError::WrongDevice`] on a port probed without a rig (`rig::identify`).
pub const NEITHER_KNOWN_DEVICE: &str = "answers neither as our firmware nor as a Dynamixel bus";

/// [`RigError::WrongDevice`] on a port where the rig's Dynamixel servos were expected.
pub const NOT_THE_SERVOS: &str =
    "is not the Dynamixel bus the rig describes (is it our firmware board or another device?)";

/// Anything that can go wrong at the bench.
#[derive(Debug, thiserror::Error)]
pub enum RigError {
    /// The rig configuration is invalid.
    #[error(transparent)]
    Config(#[from] ConfigError),
    /// The recording could not be written or read.
    #[error(transparent)]
    Recording(#[from] RecordingError),
    /// A `--fault` option is invalid.
    #[error(transparent)]
    Plant(#[from] PlantError),
    /// The port has no path: neither the rig file, `--port`, nor a USB serial number gave one.
    #[error("port `{name}` has no path: give it in the rig file, with --port {name}=PATH, or by usb_serial")]
    NoPortPath {
        /// Port name in the rig.
        name: String,
    },
    /// The serial port could not be opened.
    #[error("cannot open serial port {path}: {message} (is the device plugged in, and is the path right? `mpc-rig ports` lists ports)")]
    Open {
        /// The port path.
        path: PathBuf,
        /// The OS / library message.
        message: String,
    },
    /// I/O on an open port failed.
    #[error("serial I/O on {path}: {message}")]
    Io {
        /// The port path.
        path: PathBuf,
        /// What failed.
        message: String,
    },
    /// The device on the port is not the one the rig file puts there (our firmware, or
    /// the Dynamixel servos it names).
    ///
    /// The predicates end in a question in parentheses, and details carry parentheses of
    /// their own, so the detail follows a colon: nested parentheses read poorly.
    #[error("{path}: the device on this port {expected}: {detail}. Is this the right port (`mpc-rig ports`)?")]
    WrongDevice {
        /// The port path.
        path: PathBuf,
        /// What was expected, as a predicate: [`NOT_OUR_FIRMWARE`] or [`NOT_THE_SERVOS`].
        expected: &'static str,
        /// What was seen: a clause without a final full stop.
        detail: String,
    },
    /// Nothing answered the handshake.
    #[error("{path}: no answer to the handshake within {timeout_ms} ms (is the firmware flashed and running? is this the right port?)")]
    NoAnswer {
        /// The port path.
        path: PathBuf,
        /// How long we waited.
        timeout_ms: u64,
    },
    /// The firmware speaks another protocol version.
    #[error("{path}: firmware {firmware} speaks wire protocol version {device}, this host speaks {host}; flash a matching firmware (see firmware/README.md) or use a matching mpc-rig")]
    VersionMismatch {
        /// The port path.
        path: PathBuf,
        /// The device's protocol version.
        device: u32,
        /// Ours.
        host: u32,
        /// The firmware version string.
        firmware: String,
    },
    /// The device refused or failed a command.
    #[error("{path}: device refused `{command}`: {message}")]
    Device {
        /// The port path.
        path: PathBuf,
        /// The command.
        command: String,
        /// The device's reason.
        message: String,
    },
    /// A command got no acknowledgement despite retries.
    #[error("{path}: no acknowledgement for `{command}` after {attempts} attempts")]
    CommandTimeout {
        /// The port path.
        path: PathBuf,
        /// The command.
        command: String,
        /// Attempts made.
        attempts: u32,
    },
    /// The device went away and did not come back.
    #[error("{path}: device disconnected ({message})")]
    Disconnected {
        /// The port path.
        path: PathBuf,
        /// What was seen.
        message: String,
    },
    /// A request exceeds the rig's safety limits or the device's capabilities.
    #[error("refused: {0}")]
    Safety(String),
    /// The target (mechanism or motion) could not be loaded.
    #[error("target {path}: {message}")]
    Target {
        /// The file.
        path: PathBuf,
        /// What went wrong.
        message: String,
    },
    /// The rig's sensors cannot measure the target's motion class.
    #[error("refused: rig `{rig}` cannot measure a {class} target: {missing}")]
    CannotMeasure {
        /// The rig's name.
        rig: String,
        /// The target's class.
        class: String,
        /// What sensor is missing, and what to do.
        missing: String,
    },
    /// Creating or serving a pseudo-terminal failed.
    #[error("pseudo-terminal: {0}")]
    Pty(String),
    /// Something else in the bench setup is unusable.
    #[error("{0}")]
    Setup(String),
}
