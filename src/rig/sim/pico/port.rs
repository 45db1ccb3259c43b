//! The emulated board's USB serial port on the host: a pseudo-terminal whose other end the
//! host opens like `/dev/ttyACM0`, and which tells whether a program holds it open.
//!
//! Unlike [`crate::rig::sim::pty::Pty`], the simulator keeps no handle on the host end:
//! while no program has it open the pseudo-terminal reports a hang-up, which is how the
//! bench knows to drop DTR, as Linux's cdc-acm driver does when the last program closes a
//! ttyACM. Bytes for a closed port are dropped here rather than written, because a
//! pseudo-terminal would keep them for the next program, which a USB device never sends
//! without being asked. Owns the pseudo-terminal only.

use std::fs::File;
use std::os::fd::AsFd;
use std::path::{Path, PathBuf};

use nix::poll::{PollFd, PollFlags, PollTimeout};

use crate::rig::sim::pty::{self, open_raw_pair};
use crate::rig::RigError;

/// The device end of the board's serial port.
pub struct HostPort {
    master: File,
    path: PathBuf,
}

impl HostPort {
    /// A new pseudo-terminal in raw mode; nobody holds its host end yet.
    pub fn open() -> Result<HostPort, RigError> {
        let (master, slave, path) = open_raw_pair()?;
        drop(slave);
        Ok(HostPort {
            master: File::from(master),
            path,
        })
    }

    /// The path the host opens (`/dev/pts/N`).
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Whether a program holds the host end open.
    pub fn host_present(&self) -> bool {
        let mut fds = [PollFd::new(self.master.as_fd(), PollFlags::POLLIN)];
        match nix::poll::poll(&mut fds, PollTimeout::ZERO) {
            Ok(_) => !fds[0]
                .revents()
                .is_some_and(|r| r.contains(PollFlags::POLLHUP)),
            Err(_) => false,
        }
    }

    /// Read what the host wrote so far (0 when nothing waits or nobody holds the port).
    pub fn read_available(&mut self, buf: &mut [u8]) -> Result<usize, RigError> {
        pty::read_available(&mut self.master, buf)
    }

    /// Append everything the host wrote so far to `out`.
    pub fn read_all(&mut self, out: &mut Vec<u8>) -> Result<(), RigError> {
        let mut buf = [0u8; 4096];
        loop {
            let n = self.read_available(&mut buf)?;
            if n == 0 {
                return Ok(());
            }
            out.extend_from_slice(&buf[..n]);
        }
    }

    /// Write bytes to the host; what does not fit (a host that stopped reading) is dropped.
    /// Returns how many were written.
    pub fn write_lossy(&mut self, bytes: &[u8]) -> Result<usize, RigError> {
        pty::write_lossy(&mut self.master, bytes)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::{Read, Write};
    use std::time::{Duration, Instant};

    /// Guards the presence detection DTR follows: nobody at first, present while a program
    /// holds the port, gone again after it closes, present after a reopen; bytes cross both
    /// ways while present.
    #[test]
    fn presence_follows_open_and_close() {
        let mut port = HostPort::open().unwrap();
        assert!(!port.host_present());
        for _ in 0..2 {
            let mut host = std::fs::OpenOptions::new()
                .read(true)
                .write(true)
                .open(port.path())
                .unwrap();
            assert!(port.host_present());
            host.write_all(b"ping").unwrap();
            let mut buf = [0u8; 16];
            let deadline = Instant::now() + Duration::from_secs(2);
            let mut got = Vec::new();
            while got.len() < 4 && Instant::now() < deadline {
                let n = port.read_available(&mut buf).unwrap();
                got.extend_from_slice(&buf[..n]);
            }
            assert_eq!(got, b"ping");
            assert_eq!(port.write_lossy(b"pong").unwrap(), 4);
            let mut back = [0u8; 4];
            host.read_exact(&mut back).unwrap();
            assert_eq!(&back, b"pong");
            drop(host);
            assert!(!port.host_present());
        }
    }
}
