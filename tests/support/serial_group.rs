//! The serial group: the integration tests that must not run beside each other.
//!
//! Two kinds of test belong to it, and each of them holds [`lock`] for its whole duration
//! (`let _serial = serial_group::lock();` as its first line):
//!
//! - **Real-time tests**: every test that runs a simulated or emulated device (an
//!   in-process `rig::sim::*::spawn`, an `mpc-rig sim-device` child process, the Pico
//!   board in the rp2040js emulator) or another device thread behind a pseudo-terminal.
//!   The devices keep pace with the wall clock (1 kHz sample streams, bus replies within
//!   `dynamixel2`'s 34 ms, watchdogs of 250 ms), and a run that falls behind loses samples,
//!   misses a deadline or takes a late reply for a fault. This holds even for the tests
//!   that check that a device saw nothing: its threads still take CPU from a real-time
//!   test beside it.
//! - **CPU-heavy tests**: synthesis, a parts build and the demo, which use every core for
//!   seconds to minutes and would starve a real-time test beside them.
//!
//! The other tests (reading files, analysing synthetic recordings, exporting and reading
//! back meshes, sessions against the in-memory fake bench, refusals of bad arguments before
//! any device is opened or any work starts) do not take it: they run beside the member
//! of the group that holds it (with libtest's default of one thread per core, one of them
//! at a time on a 2-core machine), which costs that member little.
//!
//! Taken by every test of `analysis_sim_bench`, `demo_e2e`, `dxl_backend`, `dxl_echo`,
//! `dxl_measure`, `dxl_robotis_sdk`, `dxl_sim_dynamixel2`, `pico_board`, `rig_cli`,
//! `rig_counts`, `rig_mixed`, `rig_recording_integrity`, `rig_safety_stops`,
//! `rig_signals` and `rig_stepper`, and by some tests of `build_cli` (the refused build),
//! `dxl_cli_sim_device` (the two that serve a bus), `rig_link` (the two with a device on
//! the port), `rig_target` (the two against live benches) and `synth_cli` (the two
//! syntheses).
//!
//! A test that panics while it holds the lock poisons it; the next test takes it all the
//! same (the lock guards no data, only time), so one failure does not fail every later
//! member of the group.

use std::sync::{Mutex, MutexGuard};

/// The group's lock; it guards no data.
static LOCK: Mutex<()> = Mutex::new(());

/// Wait until no other member of the serial group runs, and keep the others out until the
/// returned guard is dropped.
pub fn lock() -> MutexGuard<'static, ()> {
    LOCK.lock().unwrap_or_else(|poisoned| poisoned.into_inner())
}
