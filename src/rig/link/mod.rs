//! Serial links: finding ports (by path or USB serial number) and listing them.
//!
//! Owns port enumeration and resolution of a rig's `[[ports]]` entries to device paths. It
//! does not speak any protocol; backends open the resolved paths themselves.

mod ports;

pub use ports::{list_ports, port_by_path_or_serial, resolve_port, PortInfo};
