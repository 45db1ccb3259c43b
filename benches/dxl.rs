//! Benchmark of the Dynamixel half: the Protocol 2.0 codec, the simulated bus, and the
//! backend streaming from a simulated bus in another process through a real
//! pseudo-terminal.
//!
//! Prints:
//! - decoder throughput (status packets/s and MB/s) and encoder throughput;
//! - simulated-bus instruction rate (sync read of two servos handled per second, no I/O);
//! - for the backend streaming at a requested rate: samples/s sustained, gaps, and host CPU
//!   per 1000 samples (this process only; the simulator runs in a child process), at the
//!   factory 57600 baud and at 1 Mbps (both paced like a real bus) and unpaced (the pty's
//!   own limit).
//!
//! Run with `cargo bench --bench dxl`; `MPC_BENCH_SECONDS` sets each streaming window
//! (default 3 s).

use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use mpc_rig::rig::backend::dynamixel::DynamixelBench;
use mpc_rig::rig::backend::{Driver, SampleStream};
use mpc_rig::rig::config::RigConfig;
use mpc_rig::rig::sim::dynamixel::packet::{self, Decoded, Decoder};
use mpc_rig::rig::sim::dynamixel::{Bus, BusConfig};

fn repo(p: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join(p)
}

/// CPU time of this process's threads, seconds, at nanosecond resolution: the sum of the
/// first field of `/proc/self/task/*/schedstat` (time spent on a CPU).
fn cpu_seconds() -> f64 {
    let Ok(tasks) = std::fs::read_dir("/proc/self/task") else {
        return f64::NAN;
    };
    let ns: u64 = tasks
        .filter_map(|t| t.ok())
        .filter_map(|t| std::fs::read_to_string(t.path().join("schedstat")).ok())
        .filter_map(|s| s.split_whitespace().next()?.parse::<u64>().ok())
        .sum();
    ns as f64 * 1e-9
}

fn codec() {
    // A stream of sync-read replies like the backend's: 11-byte blocks from two servos.
    let mut one = Vec::new();
    for id in [1u8, 2] {
        let block: Vec<u8> = (0..11u8)
            .map(|k| k.wrapping_mul(37).wrapping_add(id))
            .collect();
        one.extend_from_slice(&packet::encode_status(id, 0, &block));
    }
    let reps = 200_000;
    let stream: Vec<u8> = one.iter().copied().cycle().take(one.len() * reps).collect();
    let t = Instant::now();
    let mut d = Decoder::new();
    let mut n = 0u64;
    for chunk in stream.chunks(4096) {
        d.push(chunk);
        while let Some(p) = d.next_packet() {
            if matches!(p, Decoded::Packet(_)) {
                n += 1;
            }
        }
    }
    let dt = t.elapsed().as_secs_f64();
    assert_eq!(n, 2 * reps as u64);
    println!(
        "decoder: {:.2} M status packets/s, {:.0} MB/s ({} packets of {} bytes in {:.3} s)",
        n as f64 / dt / 1e6,
        stream.len() as f64 / dt / 1e6,
        n,
        one.len() / 2,
        dt
    );
    // At 4.5 Mbps (the XL430's fastest) the wire carries 450 kB/s.
    println!(
        "         {:.0}× the fastest XL430 bus (4.5 Mbps = 0.45 MB/s)",
        stream.len() as f64 / dt / 0.45e6
    );
    let t = Instant::now();
    let mut bytes = 0usize;
    for k in 0..reps {
        bytes += packet::encode_status(1, 0, &(k as u32).to_le_bytes()).len();
    }
    let dt = t.elapsed().as_secs_f64();
    println!(
        "encoder: {:.2} M status packets/s ({bytes} bytes)",
        reps as f64 / dt / 1e6
    );
}

fn sim_bus() {
    let mut bus = Bus::new(
        BusConfig::default(),
        Box::new(|phi: f64, _t: f64| 0.5 * phi),
    );
    let request = packet::encode(
        packet::BROADCAST_ID,
        packet::inst::SYNC_READ,
        &[224, 0, 11, 0, 1, 2],
    );
    let mut d = Decoder::new();
    d.push(&request);
    let decoded = d.next_packet().unwrap();
    let n = 100_000;
    let t = Instant::now();
    let mut replies = 0;
    for k in 0..n {
        // 1 ms of simulated time per request: the mechanics advance one control step each.
        replies += bus.handle(k as f64 * 1e-3, &decoded).len();
    }
    let dt = t.elapsed().as_secs_f64();
    assert_eq!(replies, 2 * n);
    println!(
        "simulated bus: {:.0} k sync reads (2 servos, 1 ms of mechanics each) handled per s",
        n as f64 / dt / 1e3
    );
}

struct SimChild {
    child: Child,
    path: String,
}

impl Drop for SimChild {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

fn sim_child(paced: bool) -> SimChild {
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_mpc-rig"));
    cmd.args(["sim-device", "dynamixel", "--motion"])
        .arg(repo("data/motions/half-turn-2to1.toml"));
    if !paced {
        cmd.arg("--no-pacing");
    }
    let mut child = cmd
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .expect("mpc-rig sim-device runs");
    let mut line = String::new();
    BufReader::new(child.stdout.take().unwrap())
        .read_line(&mut line)
        .unwrap();
    SimChild {
        child,
        path: line.trim().to_string(),
    }
}

fn stream(label: &str, paced: bool, baud_index: u8, return_delay: u8, rate_hz: f64, seconds: f64) {
    let sim = sim_child(paced);
    {
        // Select the baud rate in the driver's control table (EEPROM, torque off; a real
        // servo would switch, the simulator paces the bus at it) and the Return Delay Time
        // (2 µs units, factory 250) of both servos.
        let mut bus = dynamixel2::Bus::open(&sim.path, 57_600).unwrap();
        bus.write_u8(1, 8, baud_index).unwrap();
        for id in [1, 2] {
            bus.write_u8(id, 9, return_delay).unwrap();
        }
    }
    let mut rig = RigConfig::load(&repo("rigs/sim-dynamixel.toml")).unwrap();
    rig.apply_port_overrides(std::slice::from_ref(&sim.path))
        .unwrap();
    let mut bench = DynamixelBench::from_rig(&rig).expect("bench opens");
    bench.enable().unwrap();
    bench.start_stream(rate_hz).unwrap();
    bench.run_at(30.0).unwrap();
    // Warm up, then measure a window.
    let mut out = Vec::new();
    let warm = Instant::now() + Duration::from_millis(300);
    while Instant::now() < warm {
        bench
            .poll_samples(Duration::from_millis(20), &mut out)
            .unwrap();
    }
    out.clear();
    let c0 = bench.counts();
    let cpu0 = cpu_seconds();
    let t0 = Instant::now();
    while t0.elapsed().as_secs_f64() < seconds {
        bench
            .poll_samples(Duration::from_millis(20), &mut out)
            .unwrap();
    }
    let dt = t0.elapsed().as_secs_f64();
    let cpu = cpu_seconds() - cpu0;
    let c1 = bench.counts();
    bench.shutdown().unwrap();
    let n = out.len() as f64;
    println!(
        "{label}: requested {rate_hz:.0} Hz → {:.0} samples/s sustained over {dt:.1} s, gaps {} (missing {}), CRC errors {}, host CPU {:.1} ms per 1000 samples",
        n / dt,
        c1.gaps - c0.gaps,
        c1.missing_samples - c0.missing_samples,
        c1.crc_errors - c0.crc_errors,
        cpu / n * 1e6
    );
}

fn main() {
    // `cargo bench` passes --bench; accept and ignore harness arguments.
    let seconds: f64 = std::env::var("MPC_BENCH_SECONDS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(3.0);
    codec();
    sim_bus();
    let runs: [(&str, bool, u8, u8, f64); 5] = [
        (
            "factory 57600 baud, return delay 500 µs",
            true,
            1,
            250,
            1000.0,
        ),
        ("1 Mbps, return delay 500 µs", true, 3, 250, 1000.0),
        ("1 Mbps, return delay 0", true, 3, 0, 1000.0),
        ("4 Mbps, return delay 0", true, 6, 0, 1000.0),
        (
            "unpaced pty, return delay 0, flat out",
            false,
            1,
            0,
            20_000.0,
        ),
    ];
    for (label, paced, baud, delay, rate) in runs {
        stream(
            &format!("backend, {label}"),
            paced,
            baud,
            delay,
            rate,
            seconds,
        );
    }
}
