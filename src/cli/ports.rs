//! `mpc-rig ports`: list serial ports with USB vendor/product/serial where known.

use std::process::ExitCode;

use clap::Args;

use crate::rig::link::list_ports;

/// Arguments of `mpc-rig ports`.
#[derive(Debug, Args)]
pub struct PortsArgs {
    /// Only USB serial ports (the usual bench devices).
    #[arg(long)]
    pub usb: bool,
}

/// List the ports on stdout, one per line.
pub fn run(args: PortsArgs) -> anyhow::Result<ExitCode> {
    let ports = list_ports()?;
    let ports: Vec<_> = ports
        .into_iter()
        .filter(|p| !args.usb || p.kind == "usb")
        .collect();
    if ports.is_empty() {
        println!("no serial ports found");
        return Ok(ExitCode::SUCCESS);
    }
    for p in ports {
        let mut line = format!("{}\t{}", p.path, p.kind);
        if let (Some(vid), Some(pid)) = (p.vid, p.pid) {
            line.push_str(&format!("\t{vid:04x}:{pid:04x}"));
        }
        if let Some(s) = &p.serial_number {
            line.push_str(&format!("\tserial={s}"));
        }
        let desc: Vec<&str> = [p.manufacturer.as_deref(), p.product.as_deref()]
            .into_iter()
            .flatten()
            .collect();
        if !desc.is_empty() {
            line.push_str(&format!("\t{}", desc.join(" ")));
        }
        println!("{line}");
    }
    Ok(ExitCode::SUCCESS)
}
