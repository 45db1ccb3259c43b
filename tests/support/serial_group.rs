//! The serial group: the integration tests that must not run beside some others.
//!
//! Two kinds of test belong to it, and each holds its guard for its whole duration (as its
//! first line):
//!
//! - **Real-time tests** ([`real_time`]): every test that runs a simulated device (an
//!   in-process `rig::sim::*::spawn`, an `mpc-rig sim-device` child process) or another
//!   device thread behind a pseudo-terminal. The devices keep pace with the wall clock
//!   (1 kHz sample streams, bus replies within `dynamixel2`'s 34 ms, watchdogs of 250 ms),
//!   and a run that falls behind loses samples, misses a deadline or takes a late reply for a
//!   fault. This holds even for the tests that check that a device saw nothing: its threads
//!   still take CPU from a real-time test beside it.
//!
//!   They wait, though, far more than they compute: 24 of them (`rig_mixed`, `rig_stepper`,
//!   `dxl_backend`) ran for 89.9 s of wall clock on 5.4 s of CPU (6 %). So they share the
//!   group among themselves: two of them at once (libtest's one thread per core on a 2-core
//!   machine) use an eighth of one core. Run one after the other they were most of the
//!   integration binary's critical path: its tests took 382 s on one thread and 356 s on
//!   two; sharing, 261 s on two.
//!
//!   The price is on a machine with other work on it: there the real-time tests fail more
//!   often when they share. With two busy loops beside them on the 2-core machine,
//!   `rig_mixed` and `rig_stepper` lost 2–6 of their 13 tests per run sharing and 0–1 run
//!   one at a time. With one busy loop, the whole binary lost one test in one of two runs
//!   sharing and none in one run one at a time. Without other work none was lost: three
//!   runs of 46 real-time tests sharing, the whole binary once, and CI. On a busy machine
//!   set [`ONE_AT_A_TIME_VAR`] to run them one at a time as before (`rig_mixed`: 42.4 s
//!   instead of 23.0 s).
//! - **Tests that need the machine alone** ([`alone`]): synthesis, a parts build and the
//!   demo, which use every core for seconds to minutes and would starve a real-time test
//!   beside them; and the Pico board in the rp2040js emulator, which needs most of a core to
//!   keep pace with the wall clock.
//!
//! The other tests (reading files, analysing synthetic recordings, exporting and reading
//! back meshes, sessions against the in-memory fake bench, refusals of bad arguments before
//! any device is opened or any work starts) take neither: they run beside the members of
//! the group, which costs those little.
//!
//! [`alone`] is taken by every test of `demo_e2e` and `pico_board`, and by some tests of
//! `build_cli` (the refused build) and `synth_cli` (the two syntheses).
//!
//! [`real_time`] is taken by every test of `analysis_sim_bench`, `dxl_backend`, `dxl_echo`,
//! `dxl_measure`, `dxl_robotis_sdk`, `dxl_sim_dynamixel2`, `rig_cli`, `rig_counts`,
//! `rig_identify`, `rig_live`, `rig_mixed`, `rig_recording_integrity`, `rig_safety_stops`,
//! `rig_signals` and `rig_stepper`, and by some tests of `dxl_cli_sim_device` (the two that
//! serve a bus), `rig_link` (the two with a device on the port) and `rig_target` (the two
//! against live benches).
//!
//! A test that panics while it holds the lock may poison it; the next test takes it all the
//! same (the lock guards no data, only time), so one failure does not fail every later
//! member of the group.

use std::sync::{RwLock, RwLockReadGuard, RwLockWriteGuard};

/// The environment variable that makes the real-time tests run one at a time too, for a
/// machine with other work on it (its value is not read, only whether it is set).
pub const ONE_AT_A_TIME_VAR: &str = "MPC_REAL_TIME_TESTS_ONE_AT_A_TIME";

/// The group's lock; it guards no data. Real-time tests hold it shared, the others alone.
static LOCK: RwLock<()> = RwLock::new(());

/// A member's hold on the group, released when dropped.
#[allow(dead_code)] // held for its drop only
pub enum Guard {
    /// Beside other real-time tests.
    Shared(RwLockReadGuard<'static, ()>),
    /// Beside no other member.
    Alone(RwLockWriteGuard<'static, ()>),
}

/// Wait until no test that needs the machine alone runs, and keep such tests out until the
/// returned guard is dropped. Other real-time tests may run meanwhile, unless
/// [`ONE_AT_A_TIME_VAR`] is set.
pub fn real_time() -> Guard {
    if std::env::var_os(ONE_AT_A_TIME_VAR).is_some() {
        return alone();
    }
    Guard::Shared(LOCK.read().unwrap_or_else(|poisoned| poisoned.into_inner()))
}

/// Wait until no other member of the serial group runs, and keep them all out until the
/// returned guard is dropped.
pub fn alone() -> Guard {
    Guard::Alone(
        LOCK.write()
            .unwrap_or_else(|poisoned| poisoned.into_inner()),
    )
}
