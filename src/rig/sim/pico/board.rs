//! The emulated board's files and process: the firmware image, the boot ROM, the Node.js
//! harness that runs them in rp2040js, and starting it.
//!
//! Owns where the files are expected (the build outputs under `firmware/`), the checks that
//! they are there with the command that makes each one, and the child process with its
//! standard error forwarded to the log. Not the pipe protocol ([`super::link`]).

use std::collections::VecDeque;
use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::{Arc, Mutex};

use super::PicoError;

/// The board image, relative to the repository root: the release build of `firmware/rp2040`.
pub const IMAGE: &str = "firmware/rp2040/target/thumbv6m-none-eabi/release/mpc-bench-rp2040";
/// The boot ROM, relative to the repository root: the release build of `firmware/emu/rom`.
pub const ROM: &str = "firmware/emu/rom/target/thumbv6m-none-eabi/release/mpc-emu-rom";
/// The harness script, relative to the repository root.
pub const HARNESS: &str = "firmware/emu/harness.mjs";
/// A file of the emulator package that `npm ci` in `firmware/emu` installs.
pub const EMULATOR_PACKAGE: &str = "firmware/emu/node_modules/rp2040js/package.json";

/// Lines of the board's standard error kept for an error message when it exits.
const STDERR_TAIL: usize = 20;

/// The files an emulated board runs from, and the Node.js program.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct BoardFiles {
    /// Node.js (`node` on the `PATH` by default).
    pub node: PathBuf,
    /// `firmware/emu/harness.mjs`.
    pub harness: PathBuf,
    /// The boot ROM (ELF).
    pub rom: PathBuf,
    /// The firmware image (ELF).
    pub image: PathBuf,
}

impl BoardFiles {
    /// The build outputs of a checkout at `root`, and `node` from the `PATH`.
    pub fn in_repo(root: &Path) -> BoardFiles {
        BoardFiles {
            node: PathBuf::from("node"),
            harness: root.join(HARNESS),
            rom: root.join(ROM),
            image: root.join(IMAGE),
        }
    }

    /// Check that every file is there, naming the command that makes a missing one.
    pub fn check(&self) -> Result<(), PicoError> {
        let need = |path: &Path, what: &'static str, hint: &'static str| {
            if path.is_file() {
                Ok(())
            } else {
                Err(PicoError::Missing {
                    what,
                    path: path.to_path_buf(),
                    hint,
                })
            }
        };
        need(
            &self.image,
            "the board image",
            "build it with `cd firmware/rp2040 && cargo build --release` (after `rustup target add thumbv6m-none-eabi`)",
        )?;
        need(
            &self.rom,
            "the emulator's boot ROM",
            "build it with `cd firmware/emu/rom && cargo build --release`",
        )?;
        need(
            &self.harness,
            "the emulator harness",
            "it is part of the repository: run from the checkout's root or pass --checkout DIR",
        )?;
        let package = self
            .harness
            .parent()
            .unwrap_or(Path::new("."))
            .join("node_modules/rp2040js/package.json");
        need(
            &package,
            "the rp2040js emulator",
            "install it with `cd firmware/emu && npm ci`",
        )
    }

    /// Start the harness on these files.
    pub fn spawn(&self, flash_id: u64, slice_us: u32) -> Result<BoardProcess, PicoError> {
        self.check()?;
        let mut child = Command::new(&self.node)
            .arg(&self.harness)
            .arg("--rom")
            .arg(&self.rom)
            .arg("--image")
            .arg(&self.image)
            .arg("--flash-id")
            .arg(format!("{flash_id:016x}"))
            .arg("--slice-us")
            .arg(slice_us.to_string())
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .map_err(|e| PicoError::Spawn {
                program: self.node.clone(),
                message: e.to_string(),
            })?;
        let tail = Arc::new(Mutex::new(VecDeque::new()));
        if let Some(stderr) = child.stderr.take() {
            let tail = tail.clone();
            std::thread::Builder::new()
                .name("mpc-pico-stderr".into())
                .spawn(move || {
                    for line in BufReader::new(stderr).lines().map_while(Result::ok) {
                        tracing::warn!("emulated board: {line}");
                        let mut t = tail.lock().unwrap_or_else(|p| p.into_inner());
                        if t.len() == STDERR_TAIL {
                            t.pop_front();
                        }
                        t.push_back(line);
                    }
                })
                .map_err(|e| PicoError::Pipe(format!("cannot start the stderr reader: {e}")))?;
        }
        Ok(BoardProcess { child, tail })
    }
}

/// A running harness.
pub struct BoardProcess {
    /// The child (its standard input and output are the pipe).
    pub child: Child,
    tail: Arc<Mutex<VecDeque<String>>>,
}

impl BoardProcess {
    /// The last lines the board wrote to its standard error.
    pub fn stderr_tail(&self) -> String {
        let t = self.tail.lock().unwrap_or_else(|p| p.into_inner());
        t.iter().cloned().collect::<Vec<_>>().join("\n")
    }

    /// Stop the board and reap it.
    pub fn kill(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

impl Drop for BoardProcess {
    fn drop(&mut self) {
        self.kill();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Guards that a missing build output is named with the command that makes it.
    #[test]
    fn missing_files_name_their_command() {
        let dir = tempfile::tempdir().unwrap();
        let files = BoardFiles::in_repo(dir.path());
        let err = files.check().unwrap_err().to_string();
        assert!(err.contains("mpc-bench-rp2040"), "{err}");
        assert!(
            err.contains("cd firmware/rp2040 && cargo build --release"),
            "{err}"
        );
        std::fs::create_dir_all(files.image.parent().unwrap()).unwrap();
        std::fs::write(&files.image, b"").unwrap();
        let err = files.check().unwrap_err().to_string();
        assert!(
            err.contains("cd firmware/emu/rom && cargo build --release"),
            "{err}"
        );
    }
}
