//! Link benchmark of the bench host. Prints:
//! 1. decoder throughput (frames/s, MB/s) on a recorded-style 1 kHz sample stream, and how
//!    many times faster than the link delivers it (target ≥ 100×);
//! 2. samples per second sustained end to end — the simulated stepper bench (the real
//!    firmware core, in its own `mpc-rig sim-device` process) → pseudo-terminal → stepper
//!    backend — at 1 kHz sampling, with gaps and missing samples (target: 1 kHz, zero loss);
//! 3. host CPU time per 1000 samples for that stream (this process only: backend I/O
//!    thread and the consumer);
//! 4. the same for a mixed bench (`sim-device mixed`, rigs/sim-dynamixel-1r1t.toml: a
//!    Dynamixel bus at the factory baud turning the driver, the firmware board sampling at
//!    1 kHz): merged rows per second, rows whose driver angle had to be held rather than
//!    interpolated, board samples dropped for want of a driver angle, and host CPU.
//!
//! Run with `cargo bench --bench link`. `LINK_BENCH_SECONDS` sets the streaming time
//! (default 10 s).

use std::path::Path;
use std::time::{Duration, Instant};

use mpc_rig::rig::backend::mixed::MixedBench;
use mpc_rig::rig::backend::stepper::StepperBench;
use mpc_rig::rig::backend::{Driver, SampleStream};
use mpc_rig::rig::config::RigConfig;
#[path = "../tests/support/sim_child.rs"]
mod sim_child;
use sim_child::SimChild;

use mpc_wire::{encode_frame_vec, Decoder, Report, Sample, SampleBatch, SampleFlags, SensorSet};

fn main() {
    decoder_throughput();
    end_to_end();
    mixed_end_to_end();
}

fn bench_seconds() -> f64 {
    std::env::var("LINK_BENCH_SECONDS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(10.0)
}

/// What a steady streaming window gave.
struct Steady {
    /// Samples (rows) delivered.
    n: u64,
    /// Wall-clock seconds of the window.
    wall: f64,
    /// Host CPU seconds of this process in the window.
    cpu: f64,
    /// Device-clock span of the samples, seconds.
    dev_span: f64,
    /// Gaps, missing samples and CRC errors counted in the window.
    gaps: u64,
    missing: u64,
    crc: u64,
}

impl Steady {
    /// The link-loss figures.
    fn losses(&self) -> String {
        format!(
            "gaps {}, missing samples {}, crc errors {}",
            self.gaps, self.missing, self.crc
        )
    }

    /// The host CPU line.
    fn cpu_line(&self, label: &str, unit: &str) -> String {
        format!(
            "{label}: {:.2} s for {} {unit} = {:.2} ms per 1000 {unit} ({:.1} % of one core)",
            self.cpu,
            self.n,
            self.cpu * 1e6 / (self.n as f64).max(1.0),
            self.cpu / self.wall * 100.0
        )
    }
}

/// Stream from `bench` for `secs` after a one-second warm-up (the driver's ramp).
fn steady_stream(bench: &mut dyn SampleStream, secs: f64) -> Steady {
    let mut buf = Vec::new();
    let warm = Instant::now();
    while warm.elapsed() < Duration::from_secs(1) {
        buf.clear();
        bench
            .poll_samples(Duration::from_millis(20), &mut buf)
            .expect("stream");
    }
    let c0 = bench.counts();
    let cpu0 = process_cpu_s();
    let t0 = Instant::now();
    let mut n = 0u64;
    let (mut first_dev, mut last_dev) = (None, 0);
    while t0.elapsed().as_secs_f64() < secs {
        buf.clear();
        bench
            .poll_samples(Duration::from_millis(20), &mut buf)
            .expect("stream");
        for s in &buf {
            first_dev.get_or_insert(s.device_time_us);
            last_dev = s.device_time_us;
        }
        n += buf.len() as u64;
    }
    let c1 = bench.counts();
    Steady {
        n,
        wall: t0.elapsed().as_secs_f64(),
        cpu: process_cpu_s() - cpu0,
        dev_span: (last_dev - first_dev.unwrap_or(last_dev)) as f64 / 1e6,
        gaps: c1.gaps - c0.gaps,
        missing: c1.missing_samples - c0.missing_samples,
        crc: c1.crc_errors - c0.crc_errors,
    }
}

fn mixed_end_to_end() {
    let secs = bench_seconds();
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let sim = SimChild::spawn([
        "sim-device",
        "mixed",
        "--rig",
        "rigs/sim-dynamixel-1r1t.toml",
        "--motion",
        "data/motions/screw-bob.toml",
    ]);
    let mut rig = RigConfig::load(&root.join("rigs/sim-dynamixel-1r1t.toml")).expect("rig");
    let overrides: Vec<String> = sim
        .first_line
        .split_whitespace()
        .map(str::to_string)
        .collect();
    rig.apply_port_overrides(&overrides).expect("ports");
    let mut bench = MixedBench::open(&rig).expect("open both devices");
    bench.zero().expect("zero");
    bench.enable().expect("enable");
    bench.start_stream(1000.0).expect("stream");
    bench.run_at(30.0).expect("run");
    let w = steady_stream(&mut bench, secs);
    let info = bench.device_info();
    bench.shutdown().expect("shutdown");
    drop(sim);
    let merge = &info.extra["merge"];
    println!(
        "mixed: {} rows in {:.2} s = {:.1} rows/s; held driver angle in {} rows, {} board samples without one; {}",
        w.n,
        w.wall,
        w.n as f64 / w.wall,
        merge["rows_with_held_driver_angle"],
        merge["board_samples_without_driver_angle"],
        w.losses()
    );
    println!("{}", w.cpu_line("mixed host CPU", "rows"));
}

fn decoder_throughput() {
    // 1 kHz, one AS5600, 10 samples per frame: what the sim-stepper rig streams.
    let frames = 200_000u32;
    let mut bytes = Vec::new();
    for f in 0..frames {
        let mut batch = SampleBatch::new(SensorSet::ENCODER_A);
        for i in 0..10u32 {
            let k = f * 10 + i;
            batch
                .push(Sample {
                    timestamp_us: k * 1000,
                    position: k as i32 * 3,
                    flags: SampleFlags::MOVING | SampleFlags::ENABLED,
                    encoder_a: (k % 4096) as u16,
                    ..Sample::default()
                })
                .expect("batch of 10 fits");
        }
        bytes.extend(encode_frame_vec(f as u16, &Report::Samples(batch)).expect("encodes"));
    }
    let mut decoder = Decoder::<Report>::new();
    let mut ok = 0u64;
    let t = Instant::now();
    // Feed in 64-byte chunks, as USB CDC delivers.
    for chunk in bytes.chunks(64) {
        decoder.feed(chunk, |r| {
            if r.is_ok() {
                ok += 1
            }
        });
    }
    let s = t.elapsed().as_secs_f64();
    assert_eq!(ok, u64::from(frames));
    let fps = f64::from(frames) / s;
    let link_fps = 100.0; // 1 kHz in batches of 10
    println!(
        "decoder: {frames} frames ({:.1} MB) in {s:.3} s = {fps:.0} frames/s, {:.1} MB/s, {:.0}x the 1 kHz link's {link_fps} frames/s",
        bytes.len() as f64 / 1e6,
        bytes.len() as f64 / 1e6 / s,
        fps / link_fps
    );
}

/// CPU seconds (user + system) of this process, from /proc/self/stat.
fn process_cpu_s() -> f64 {
    let stat = std::fs::read_to_string("/proc/self/stat").unwrap_or_default();
    let after = stat.rsplit_once(')').map_or("", |x| x.1);
    let fields: Vec<&str> = after.split_whitespace().collect();
    let tick = 100.0; // USER_HZ on Linux
    let get = |i: usize| {
        fields
            .get(i)
            .and_then(|v| v.parse::<f64>().ok())
            .unwrap_or(0.0)
    };
    // After the comm field: state is index 0, utime index 11, stime index 12.
    (get(11) + get(12)) / tick
}

fn end_to_end() {
    let secs = bench_seconds();
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let sim = SimChild::spawn([
        "sim-device",
        "stepper",
        "--motion",
        "data/motions/half-turn-2to1.toml",
    ]);
    let mut rig = RigConfig::load(&root.join("rigs/sim-stepper.toml")).expect("rig");
    rig.apply_port_overrides(std::slice::from_ref(&sim.first_line))
        .expect("port");
    let mut bench = StepperBench::open(&rig).expect("handshake with the simulator");
    bench.zero().expect("zero");
    bench.enable().expect("enable");
    bench.start_stream(1000.0).expect("stream");
    bench.run_at(60.0).expect("run");
    let w = steady_stream(&mut bench, secs);
    bench.shutdown().expect("shutdown");
    drop(sim);
    println!(
        "link: {} samples in {:.2} s wall = {:.1} samples/s (device clock span {:.2} s = {:.1} samples/s of device time); {}",
        w.n,
        w.wall,
        w.n as f64 / w.wall,
        w.dev_span,
        w.n as f64 / w.dev_span.max(1e-9),
        w.losses()
    );
    println!("{}", w.cpu_line("host CPU", "samples"));
}
