//! Pseudo-terminals for simulated devices.
//!
//! A [`Pty`] is the device end (master) of a pseudo-terminal pair whose other end
//! (`/dev/pts/N`) looks to the host exactly like `/dev/ttyUSB0`. The simulator keeps its own
//! handle on the slave open, so a host that closes and reopens the port does not hang the
//! pair up; closing the [`Pty`] is what an unplug looks like to the host (its reads fail
//! with a hang-up). The slave is put in raw mode at creation so nothing the device writes
//! is echoed back or line-edited before the host configures the port.
//!
//! An optional stable path (a symlink) lets a simulator "re-plug" on a new pair while the
//! host keeps reopening the same path, as a USB device re-enumerating under a udev rule.

use std::fs::File;
use std::io::{Read, Write};
use std::os::fd::{AsFd, AsRawFd, OwnedFd};
use std::path::{Path, PathBuf};
use std::time::Duration;

use nix::fcntl::{fcntl, FcntlArg, OFlag};
use nix::poll::{PollFd, PollFlags, PollTimeout};
use nix::sys::termios::{cfmakeraw, tcgetattr, tcsetattr, SetArg};

use crate::rig::RigError;

fn pty_err(what: &str) -> impl FnOnce(nix::errno::Errno) -> RigError + '_ {
    move |e| RigError::Pty(format!("{what}: {e}"))
}

/// Open a pseudo-terminal pair with the slave in raw mode and a non-blocking master;
/// returns (master, slave, slave path). Shared by every simulator's device end.
pub fn open_raw_pair() -> Result<(OwnedFd, OwnedFd, PathBuf), RigError> {
    let pair = nix::pty::openpty(None, None).map_err(pty_err("openpty"))?;
    let mut t = tcgetattr(pair.slave.as_fd()).map_err(pty_err("tcgetattr"))?;
    cfmakeraw(&mut t);
    tcsetattr(pair.slave.as_fd(), SetArg::TCSANOW, &t).map_err(pty_err("tcsetattr"))?;
    let slave_path = nix::unistd::ttyname(pair.slave.as_fd()).map_err(pty_err("ttyname"))?;
    let fd = pair.master.as_raw_fd();
    let fl = fcntl(fd, FcntlArg::F_GETFL).map_err(pty_err("fcntl"))?;
    fcntl(
        fd,
        FcntlArg::F_SETFL(OFlag::from_bits_truncate(fl) | OFlag::O_NONBLOCK),
    )
    .map_err(pty_err("fcntl"))?;
    Ok((pair.master, pair.slave, slave_path))
}

/// The device end of a pseudo-terminal pair.
pub struct Pty {
    master: File,
    _slave: OwnedFd,
    slave_path: PathBuf,
}

impl Pty {
    /// Open a new pair in raw mode; the master is non-blocking.
    pub fn open() -> Result<Pty, RigError> {
        let (master, slave, slave_path) = open_raw_pair()?;
        Ok(Pty {
            master: File::from(master),
            _slave: slave,
            slave_path,
        })
    }

    /// The host-side path (`/dev/pts/N`).
    pub fn path(&self) -> &Path {
        &self.slave_path
    }

    /// Wait up to `timeout` for bytes from the host.
    pub fn wait_readable(&self, timeout: Duration) -> bool {
        let mut fds = [PollFd::new(self.master.as_fd(), PollFlags::POLLIN)];
        let ms = PollTimeout::try_from(timeout.as_millis().min(10_000) as i32)
            .unwrap_or(PollTimeout::ZERO);
        matches!(nix::poll::poll(&mut fds, ms), Ok(n) if n > 0)
    }

    /// Read what the host has written so far (0 when nothing is waiting).
    pub fn read_available(&mut self, buf: &mut [u8]) -> Result<usize, RigError> {
        read_available(&mut self.master, buf)
    }

    /// Write bytes to the host. When the host does not read and the pty buffer is full,
    /// the excess is dropped (like a USB CDC device whose host stopped polling) and the
    /// number of bytes actually written is returned.
    pub fn write_lossy(&mut self, bytes: &[u8]) -> Result<usize, RigError> {
        write_lossy(&mut self.master, bytes)
    }
}

/// Read what the host has written to a non-blocking master so far (0 when nothing is
/// waiting, or no slave is open: EIO).
pub fn read_available(master: &mut File, buf: &mut [u8]) -> Result<usize, RigError> {
    match master.read(buf) {
        Ok(n) => Ok(n),
        Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => Ok(0),
        Err(e) if e.raw_os_error() == Some(nix::libc::EIO) => Ok(0),
        Err(e) => Err(RigError::Pty(format!("read: {e}"))),
    }
}

/// Write to a non-blocking master what fits; the rest (the host not reading, or no slave
/// open: EIO) is dropped. Returns how many bytes were written.
pub fn write_lossy(master: &mut File, bytes: &[u8]) -> Result<usize, RigError> {
    let mut done = 0;
    while done < bytes.len() {
        match master.write(&bytes[done..]) {
            Ok(0) => break,
            Ok(n) => done += n,
            Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => break,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
            Err(e) if e.raw_os_error() == Some(nix::libc::EIO) => break,
            Err(e) => return Err(RigError::Pty(format!("write: {e}"))),
        }
    }
    Ok(done)
}

/// A symlink that always points at the current pseudo-terminal of a simulator.
#[derive(Debug)]
pub struct StableLink {
    link: PathBuf,
}

impl StableLink {
    /// Create (or replace) `link` pointing at `target`.
    pub fn create(link: &Path, target: &Path) -> Result<StableLink, RigError> {
        let l = StableLink {
            link: link.to_path_buf(),
        };
        l.point_to(target)?;
        Ok(l)
    }

    /// The link's path.
    pub fn path(&self) -> &Path {
        &self.link
    }

    /// Atomically re-point the link.
    pub fn point_to(&self, target: &Path) -> Result<(), RigError> {
        let tmp = self.link.with_extension("tmp-link");
        let _ = std::fs::remove_file(&tmp);
        std::os::unix::fs::symlink(target, &tmp)
            .map_err(|e| RigError::Pty(format!("symlink {}: {e}", tmp.display())))?;
        std::fs::rename(&tmp, &self.link)
            .map_err(|e| RigError::Pty(format!("rename to {}: {e}", self.link.display())))
    }

    /// Remove the link (the device is "unplugged").
    pub fn remove(&self) {
        let _ = std::fs::remove_file(&self.link);
    }
}

impl Drop for StableLink {
    fn drop(&mut self) {
        self.remove();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Guards: bytes cross the pair both ways unchanged (raw mode, no echo), and a host
    /// closing its end does not hang the pair up for the next open.
    #[test]
    fn pty_round_trip_and_reopen() {
        let mut pty = Pty::open().unwrap();
        for _ in 0..2 {
            let mut host = std::fs::OpenOptions::new()
                .read(true)
                .write(true)
                .open(pty.path())
                .unwrap();
            let data: Vec<u8> = (0u8..=255).collect();
            host.write_all(&data).unwrap();
            let mut got = Vec::new();
            let mut buf = [0u8; 512];
            while got.len() < data.len() {
                assert!(pty.wait_readable(Duration::from_secs(2)));
                let n = pty.read_available(&mut buf).unwrap();
                got.extend_from_slice(&buf[..n]);
            }
            assert_eq!(got, data);
            assert_eq!(pty.write_lossy(&data).unwrap(), data.len());
            let mut back = vec![0u8; data.len()];
            host.read_exact(&mut back).unwrap();
            assert_eq!(back, data);
            drop(host);
        }
    }
}
