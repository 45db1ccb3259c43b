//! The integration tests of `mpc-rig`, in one test binary (`cargo test --test integration`)
//! instead of one per file, so that the library is linked once rather than once per file.
//! Each former file is a module of its own; `cargo test --test integration rig_mixed` runs
//! one of them, and their tests are named `module::test`.
//!
//! The tests of one binary run in parallel, so the ones that must not run beside some
//! others, the real-time bench tests (beside each other, not beside the CPU-heavy ones) and
//! the CPU-heavy ones (beside neither), hold the lock of [`support::serial_group`]; its doc
//! says which and why. A new test file in `tests/` is only built once it is declared here
//! (`autotests = false` in Cargo.toml).

mod support;

mod analysis_load;
mod analysis_recovery;
mod analysis_report;
mod analysis_sim_bench;
mod build_cli;
mod demo_e2e;
mod dxl_backend;
mod dxl_cli_sim_device;
mod dxl_echo;
mod dxl_measure;
mod dxl_robotis_sdk;
mod dxl_sim_dynamixel2;
mod geometry_glb;
mod geometry_trimesh;
mod motion_examples;
mod motion_malformed;
mod pico_board;
mod rig_cli;
mod rig_config;
mod rig_counts;
mod rig_identify;
mod rig_link;
mod rig_live;
mod rig_mixed;
mod rig_recording_integrity;
mod rig_safety_stops;
mod rig_session;
mod rig_signals;
mod rig_stepper;
mod rig_target;
mod simulate_cli;
mod synth_cli;
