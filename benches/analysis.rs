//! Benchmark: analysis of a one-hour 1 kHz recording (3.6 M samples) of the half-turn-2to1
//! mechanism on the simulated stepper rig, with noise, AS5600 quantization, a 1° driver-side
//! backlash and forward + reverse runs.
//!
//! The benchmark writes the recording itself (through the real recording writer), then runs
//! the analysis in a fresh child process so that the peak resident memory it prints
//! (`VmHWM`) belongs to the analysis alone. Target: under 10 s, memory bounded by the
//! recording's size (a few tens of bytes per sample). Run with
//! `cargo bench --bench analysis`; `MPC_BENCH_SECONDS` shortens the recording.

use std::path::{Path, PathBuf};
use std::time::Instant;

use mpc_rig::analysis::synthetic::{write_recording, SyntheticBench};
use mpc_rig::analysis::{
    analyze, load_run, load_target, AnalysisOptions, ReportOptions, TargetSource,
};
use mpc_rig::rig::config::RigConfig;
use mpc_rig::rig::recording::TargetRef;

#[path = "support/process.rs"]
mod process;
use process::peak_rss_mb;

const CHILD_ENV: &str = "MPC_BENCH_ANALYSIS_DIR";

fn repo(p: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join(p)
}

fn child(dir: &Path) {
    let motion = repo("data/motions/half-turn-2to1.toml");
    let t0 = Instant::now();
    let loaded = load_run(dir).expect("load");
    let t_load = t0.elapsed().as_secs_f64();
    let t1 = Instant::now();
    let law = load_target(&TargetSource::Motion(motion)).expect("target");
    let a = analyze(&loaded.run, &law, &AnalysisOptions::default()).expect("analysis");
    let t_analyze = t1.elapsed().as_secs_f64();
    let t2 = Instant::now();
    let source = mpc_rig::analysis::report::SourceInfo {
        recording_dir: dir.to_path_buf(),
        complete: Some(loaded.meta.complete),
        end_reason: loaded.meta.end_reason.clone(),
        rows: loaded.rows,
        stale_rows: loaded.stale_rows,
        held_rows: loaded.held_rows,
        late_rows: loaded.late_rows,
        truncated_last_line: loaded.truncated_last_line,
        degraded: None,
        device_counts: serde_json::json!({}),
        target_kind: "motion".into(),
        target_path: "data/motions/half-turn-2to1.toml".into(),
    };
    let s = mpc_rig::analysis::report::write_report(
        &dir.join("report"),
        &a,
        &loaded.run,
        &law,
        source,
        &ReportOptions::default(),
    )
    .expect("report");
    let t_report = t2.elapsed().as_secs_f64();
    let total = t0.elapsed().as_secs_f64();
    let n = loaded.run.len();
    println!("samples                 {n}");
    println!("load (CSV → physical)   {t_load:.2} s");
    println!("analysis                {t_analyze:.2} s");
    println!("report (plots, html)    {t_report:.2} s");
    println!("total                   {total:.2} s   (target < 10 s)");
    println!(
        "throughput              {:.2} M samples/s",
        n as f64 / total / 1e6
    );
    if let Some(mb) = peak_rss_mb() {
        println!(
            "peak RSS                {mb:.0} MB  ({:.0} bytes per sample)",
            mb * 1024.0 * 1024.0 / n as f64
        );
    }
    let r = s.timing.as_ref().and_then(|t| t.ratios.first());
    println!(
        "result                  RMS {:.3}°, ratio {:.4} ± {:.4} (target {:.1}), backlash {:.3}° over {} cycles",
        s.headline.rms_error_deg.unwrap_or(f64::NAN),
        r.map_or(f64::NAN, |r| r.measured),
        r.map_or(f64::NAN, |r| r.u95),
        r.map_or(f64::NAN, |r| r.target),
        s.headline.backlash_driver_deg.unwrap_or(f64::NAN),
        s.headline.cycles
    );
}

fn main() {
    if let Ok(dir) = std::env::var(CHILD_ENV) {
        child(Path::new(&dir));
        return;
    }
    let seconds: f64 = std::env::var("MPC_BENCH_SECONDS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(3600.0);
    let rpm = 10.0;
    let cycles = seconds * rpm / 60.0;
    let motion = repo("data/motions/half-turn-2to1.toml");
    let law = load_target(&TargetSource::Motion(motion.clone())).expect("target");
    let bench = SyntheticBench {
        rate_hz: 1000.0,
        speed_rpm: rpm,
        settle_cycles: 1.0,
        forward_cycles: ((cycles - 1.0) / 2.0).floor(),
        reverse_cycles: ((cycles - 1.0) / 2.0).floor(),
        driver_backlash_deg: 1.0,
        driver_offset_deg: 0.5,
        noise: 0.05,
        quantum: 360.0 / 4096.0,
        seed: 2026,
        ..Default::default()
    };
    let tmp = tempfile::tempdir().expect("temp dir");
    let dir = tmp.path().join("hour");
    let t0 = Instant::now();
    {
        let run = bench.generate(&law);
        let rig = RigConfig::load(&repo("rigs/sim-stepper.toml")).expect("rig");
        let target = TargetRef {
            kind: "motion".into(),
            path: motion,
            sha256: String::new(),
            class: "1R".into(),
            name: "half-turn-2to1".into(),
        };
        write_recording(&run, rig, target, &dir).expect("write recording");
        println!(
            "generated {} samples ({:.0} s at 1 kHz) in {:.1} s; CSV {:.0} MB",
            run.len(),
            seconds,
            t0.elapsed().as_secs_f64(),
            std::fs::metadata(dir.join("recording.csv"))
                .map(|m| m.len() as f64 / 1e6)
                .unwrap_or(0.0)
        );
    }
    let exe = std::env::current_exe().expect("own path");
    let status = std::process::Command::new(exe)
        .env(CHILD_ENV, &dir)
        .status()
        .expect("run the analysis child");
    assert!(status.success(), "analysis child failed: {status}");
}
