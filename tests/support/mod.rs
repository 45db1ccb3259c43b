//! Helpers shared by the integration tests, which are all modules of one test binary
//! (`tests/main.rs`):
//!
//! - [`serial_group`]: the lock that keeps the CPU-heavy tests from running beside each
//!   other or beside the real-time bench tests; its doc gives the rule and lists its members.
//! - [`SimChild`]: an `mpc-rig sim-device` child process, killed on drop.
//! - [`bench`]: simulated benches and session options for the tests of the bench's safety
//!   and data integrity.
//! - [`scenes`]: a small animated scene for the geometry export tests.
//!
//! Python scripts run by tests live here too: `dxl_robotis_sdk_check.py`
//! (`dxl_robotis_sdk`) and `trimesh_check.py` (`geometry_trimesh`).

pub mod bench;
pub mod scenes;
pub mod serial_group;
mod sim_child;

pub use sim_child::SimChild;
