//! Listing serial ports and resolving a rig port to a path.

use std::path::{Path, PathBuf};

use serialport::SerialPortType;

use crate::rig::config::PortConfig;
use crate::rig::RigError;

/// A serial port the OS knows about.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct PortInfo {
    /// Device path.
    pub path: String,
    /// "usb", "pci", "bluetooth" or "unknown".
    pub kind: &'static str,
    /// USB vendor id.
    pub vid: Option<u16>,
    /// USB product id.
    pub pid: Option<u16>,
    /// USB serial number.
    pub serial_number: Option<String>,
    /// USB manufacturer string.
    pub manufacturer: Option<String>,
    /// USB product string.
    pub product: Option<String>,
}

/// All serial ports the OS reports (on Linux by scanning `/sys/class/tty`), sorted by path.
pub fn list_ports() -> Result<Vec<PortInfo>, RigError> {
    let ports = serialport::available_ports()
        .map_err(|e| RigError::Setup(format!("cannot list serial ports: {e}")))?;
    let mut out: Vec<PortInfo> = ports
        .into_iter()
        .map(|p| {
            let mut info = PortInfo {
                path: p.port_name,
                kind: "unknown",
                vid: None,
                pid: None,
                serial_number: None,
                manufacturer: None,
                product: None,
            };
            match p.port_type {
                SerialPortType::UsbPort(u) => {
                    info.kind = "usb";
                    info.vid = Some(u.vid);
                    info.pid = Some(u.pid);
                    info.serial_number = u.serial_number;
                    info.manufacturer = u.manufacturer;
                    info.product = u.product;
                }
                SerialPortType::PciPort => info.kind = "pci",
                SerialPortType::BluetoothPort => info.kind = "bluetooth",
                SerialPortType::Unknown => {}
            }
            info
        })
        .collect();
    out.sort_by(|a, b| a.path.cmp(&b.path));
    Ok(out)
}

/// The device path of a rig port: its `path` when set, else the USB port whose serial
/// number is `usb_serial`.
pub fn resolve_port(port: &PortConfig) -> Result<PathBuf, RigError> {
    if let Some(p) = &port.path {
        return Ok(p.clone());
    }
    let Some(serial) = &port.usb_serial else {
        return Err(RigError::NoPortPath {
            name: port.name.clone(),
        });
    };
    let ports = list_ports()?;
    ports
        .iter()
        .find(|p| p.serial_number.as_deref() == Some(serial.as_str()))
        .map(|p| PathBuf::from(&p.path))
        .ok_or_else(|| {
            RigError::Setup(format!(
                "port `{}`: no USB serial port with serial number `{serial}` is plugged in ({} ports seen; `mpc-rig ports` lists them)",
                port.name,
                ports.len()
            ))
        })
}

/// The device path of a `--port` given alone: a path as it is, or else the USB serial
/// number of a plugged-in port.
pub fn port_by_path_or_serial(given: &str) -> Result<PathBuf, RigError> {
    if given.contains('/') || Path::new(given).exists() {
        return Ok(PathBuf::from(given));
    }
    resolve_port(&PortConfig {
        name: format!("--port {given}"),
        path: None,
        usb_serial: Some(given.to_string()),
        baud: 115_200,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Guards: a port with neither path nor USB serial is a clear error naming the port.
    #[test]
    fn port_without_path_is_named() {
        let p = PortConfig {
            name: "fw".into(),
            path: None,
            usb_serial: None,
            baud: 115_200,
        };
        let err = resolve_port(&p).unwrap_err().to_string();
        assert!(err.contains("`fw`") && err.contains("--port"), "{err}");
    }

    /// Guards: a USB serial number that is not plugged in is reported, not ignored.
    #[test]
    fn absent_usb_serial_is_reported() {
        let p = PortConfig {
            name: "fw".into(),
            path: None,
            usb_serial: Some("NO-SUCH-SERIAL-0000".into()),
            baud: 115_200,
        };
        let err = resolve_port(&p).unwrap_err().to_string();
        assert!(err.contains("NO-SUCH-SERIAL-0000"), "{err}");
    }
}
