//! The sidecar's sample counts agree with the CSV on disk for every backend, and a run that
//! lost most of its samples is marked degraded with no figure its data cannot support
//! (issue 16: a Dynamixel drop-out of 1 s was counted as 12 missing samples next to an
//! 80-sample hole; with `drop_prob = 0.01` the sidecar said 34 gaps, the CSV had 71; a
//! stepper run with 72 % of its samples missing was "complete" with a timing ratio).

use std::path::Path;

use mpc_rig::rig::config::RigConfig;
use mpc_rig::rig::recording::{missing_before, Recording};
use mpc_rig::rig::session::{measure, EndReason};
use mpc_rig::rig::sim::mixed;
use mpc_rig::rig::sim::plant::PlantConfig;

use crate::support::bench::{dxl_sim, motion, options, repo, stepper_sim};
use crate::support::serial_group;
use crate::support::SimChild;

/// Holes in the CSV's device time at the recording's nominal rate: (gaps, missing).
fn holes_on_disk(rec: &Recording) -> (u64, u64) {
    let period_us = 1e6 / rec.meta.session.sample_rate_hz;
    rec.device_time_us
        .windows(2)
        .map(|w| missing_before(w[1] - w[0], period_us))
        .filter(|&m| m > 0)
        .fold((0, 0), |(g, m), x| (g + 1, m + x))
}

/// The sidecar's rows, gaps and missing samples are those of the CSV.
fn assert_counts_match_disk(dir: &Path) -> (u64, u64) {
    let rec = Recording::load(dir).unwrap();
    let c = rec.meta.counts;
    assert_eq!(c.samples as usize, rec.len(), "{c:?}");
    assert_eq!((c.gaps, c.missing_samples), holes_on_disk(&rec), "{c:?}");
    (c.gaps, c.missing_samples)
}

/// Guards the stepper bench: with bytes dropped on the link, the lost frames are holes on
/// disk, counted exactly in the sidecar.
#[test]
fn stepper_counts_match_the_csv() {
    let _serial = serial_group::real_time();
    let sim = stepper_sim("half-turn-2to1", &["drop_prob=0.002", "seed=5"]);
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("rec");
    let mut o = options(
        "rigs/sim-stepper.toml",
        vec![sim.path().display().to_string()],
        "half-turn-2to1",
        &dir,
    );
    o.speed_rpm = 90.0;
    let out = measure(&mut o).unwrap();
    assert_eq!(out.end, EndReason::Finished);
    let (gaps, _) = assert_counts_match_disk(&dir);
    assert!(gaps > 0, "the injected drops made no hole");
}

/// Guards the Dynamixel bench: a 1 s drop-out is counted as the ~80 samples the 80 Hz
/// stream lost (not one per failed transaction), and with 1 % of the bytes dropped every
/// hole on disk is counted, for each.
#[test]
fn dynamixel_counts_match_the_csv() {
    let _serial = serial_group::real_time();
    let tmp = tempfile::tempdir().unwrap();
    for (faults, name) in [
        (&["dropout_at_s=1.5", "dropout_s=1.0"][..], "dropout"),
        (&["drop_prob=0.01", "seed=3"][..], "drops"),
    ] {
        let sim = dxl_sim("half-turn-2to1", faults);
        let dir = tmp.path().join(name);
        let mut o = options(
            "rigs/sim-dynamixel.toml",
            vec![sim.path().display().to_string()],
            "half-turn-2to1",
            &dir,
        );
        let out = measure(&mut o).unwrap();
        assert_eq!(out.end, EndReason::Finished, "{name}");
        let (gaps, missing) = assert_counts_match_disk(&dir);
        assert!(gaps > 0, "{name}: no hole counted");
        if name == "dropout" {
            assert!(
                missing >= 60,
                "a 1 s hole at 80 Hz counted as {missing} samples"
            );
        }
    }
}

/// Guards the mixed bench: the board's timeline is the CSV's; with bytes dropped on the
/// board's link its holes are counted exactly (bus losses are bridged, not holes).
#[test]
fn mixed_counts_match_the_csv() {
    let _serial = serial_group::real_time();
    let rig = RigConfig::load(&repo("rigs/sim-dynamixel-1r1t.toml")).unwrap();
    let sim = mixed::spawn_with(
        &rig,
        motion("screw-bob"),
        PlantConfig::default(),
        PlantConfig::from_faults(&["drop_prob=0.002", "seed=9"]).unwrap(),
    )
    .unwrap();
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("rec");
    let mut o = options(
        "rigs/sim-dynamixel-1r1t.toml",
        sim.port_overrides(),
        "screw-bob",
        &dir,
    );
    let out = measure(&mut o).unwrap();
    assert_eq!(out.end, EndReason::Finished);
    let (gaps, _) = assert_counts_match_disk(&dir);
    assert!(gaps > 0, "the injected drops made no hole");
}

/// Guards the degraded mark: a stepper link corrupting 1 % of its bytes loses most sample
/// frames; `measure` finishes the plan but exits 6 saying "degraded", the sidecar carries
/// the reason with counts that match the CSV, and the analysis gives no timing ratio and
/// counts no complete cycle (it printed a ratio from "0 cycles" before).
#[test]
fn a_run_missing_most_samples_is_degraded() {
    let _serial = serial_group::real_time();
    let sim = SimChild::spawn([
        "sim-device".into(),
        "stepper".into(),
        "--motion".into(),
        repo("data/motions/half-turn-2to1.toml").into_os_string(),
        "--fault".into(),
        "corrupt_prob=0.01".into(),
    ]);
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("rec");
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_mpc-rig"))
        .args(["measure", "--rig"])
        .arg(repo("rigs/sim-stepper.toml"))
        .args(["--port", &sim.first_line, "--motion"])
        .arg(repo("data/motions/half-turn-2to1.toml"))
        .args(["--speed", "60", "--cycles", "2", "-o"])
        .arg(&dir)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(
        out.status.code(),
        Some(i32::from(mpc_rig::cli::measure::EXIT_DEGRADED)),
        "{stderr}"
    );
    assert!(stderr.contains("degraded"), "{stderr}");
    let (_, missing) = assert_counts_match_disk(&dir);
    let rec = Recording::load(&dir).unwrap();
    assert!(rec.meta.complete);
    let why = rec.meta.degraded.clone().expect("marked degraded");
    assert!(why.contains("missing"), "{why}");
    assert!(
        missing > rec.len() as u64,
        "{missing} missing, {} rows",
        rec.len()
    );
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("report/summary.json")).unwrap())
            .unwrap();
    let h = &summary["headline"];
    assert!(h["timing_ratio_measured"].is_null(), "{h}");
    assert_eq!(h["cycles"], 0, "{h}");
    assert_eq!(summary["source"]["degraded"].as_str(), Some(why.as_str()));
}
