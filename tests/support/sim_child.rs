//! [`SimChild`]: an `mpc-rig sim-device` child process for the tests that run the simulator
//! as a user does (the link benchmark includes this file by `#[path]`).

use std::ffi::OsStr;
use std::io::{BufRead, BufReader};
use std::process::{Child, Command, Stdio};

/// A `mpc-rig sim-device …` child process and the first line it printed (the
/// pseudo-terminal path, or `NAME=PATH` pairs for a mixed bench); killed on drop.
pub struct SimChild {
    /// The simulator process.
    pub child: Child,
    /// Its first line of standard output, trimmed.
    pub first_line: String,
}

impl SimChild {
    /// Run `mpc-rig` with `args` (starting with `sim-device`) and wait for its first line.
    pub fn spawn<I, S>(args: I) -> SimChild
    where
        I: IntoIterator<Item = S>,
        S: AsRef<OsStr>,
    {
        let mut child = Command::new(env!("CARGO_BIN_EXE_mpc-rig"))
            .args(args)
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .spawn()
            .expect("mpc-rig runs");
        let mut line = String::new();
        BufReader::new(child.stdout.take().expect("piped stdout"))
            .read_line(&mut line)
            .expect("the simulator prints its first line");
        SimChild {
            child,
            first_line: line.trim().to_string(),
        }
    }
}

impl Drop for SimChild {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}
