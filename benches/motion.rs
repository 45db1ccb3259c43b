//! Motion evaluation speed: the bench, the analysis and the simulators call
//! `Motion::sample` / `angle_z` millions of times, and synthesis calls `samples(360)`.
//! Prints ns per call for keyframe and dense (360-row) laws of each kind, and load times
//! of the shipped examples. Run with `cargo bench --bench motion`.

use std::hint::black_box;
use std::path::Path;
use std::time::Instant;

use mpc_rig::motion::{spec::parse_spec, Motion, DEFAULT_SAMPLES};

/// Calls per measurement: enough for a stable figure in well under a second per case.
const CALLS: usize = 2_000_000;

fn time_per_call(mut f: impl FnMut(f64) -> f64) -> f64 {
    // Warm up, then time CALLS evaluations at scattered times (defeats branch prediction
    // of the interval search a little, like a real bench trace would not).
    let mut acc = 0.0;
    for i in 0..10_000 {
        acc += f(i as f64 * 0.618_033_988_7);
    }
    let start = Instant::now();
    for i in 0..CALLS {
        acc += f(i as f64 * 0.618_033_988_7);
    }
    let ns = start.elapsed().as_secs_f64() * 1e9 / CALLS as f64;
    black_box(acc);
    ns
}

fn main() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("data/motions");
    println!("motion evaluation ({CALLS} calls each)");
    for name in [
        "half-turn-2to1",
        "quarter-turn-dwell",
        "screw-bob",
        "figure-eight",
    ] {
        let start = Instant::now();
        let m = Motion::from_file(&dir.join(format!("{name}.toml"))).expect("example loads");
        let load_ms = start.elapsed().as_secs_f64() * 1e3;
        let rows: Vec<_> = m
            .samples(DEFAULT_SAMPLES)
            .iter()
            .map(|s| mpc_rig::motion::DenseRow {
                t: s.t,
                rotation: s.rotation,
                translation: s.translation,
            })
            .collect();
        let dense = Motion::from_dense(m.class(), name, &rows).expect("dense law");
        let key_ns = time_per_call(|t| m.sample(t).angular_acceleration.norm());
        let dense_ns = time_per_call(|t| dense.sample(t).angular_acceleration.norm());
        let start = Instant::now();
        let reps = 2000;
        for _ in 0..reps {
            black_box(m.samples(DEFAULT_SAMPLES));
        }
        let samples_us = start.elapsed().as_secs_f64() * 1e6 / reps as f64;
        print!(
            "  {name:<20} {:<4} load+scan {load_ms:6.2} ms | sample(): keyframes {key_ns:6.1} ns, \
             dense-360 {dense_ns:6.1} ns | samples(360) {samples_us:7.1} µs",
            m.class().to_string()
        );
        if m.angle_z(0.0).is_some() {
            let angle_ns = time_per_call(|t| m.angle_z(t).map_or(0.0, |a| a[0]));
            print!(" | angle_z() {angle_ns:5.1} ns");
        }
        println!();
    }
    println!("keyframe spec parsing (1R, one `[[key]]` table per key)");
    for keys in [10_000usize, 40_000, 100_000] {
        let mut text = String::from("class = \"1R\"\nnet_rotation = 360.0\n");
        for i in 0..keys {
            let t = i as f64 / keys as f64;
            text.push_str(&format!("[[key]]\nt = {t}\nangle = {}\n", 360.0 * t));
        }
        let start = Instant::now();
        let m = parse_spec(&text, None).expect("generated spec parses");
        let ms = start.elapsed().as_secs_f64() * 1e3;
        black_box(m);
        println!(
            "  {keys:>7} keys ({:5.1} MB): {ms:8.1} ms, {:6.2} ms per 1000 keys",
            text.len() as f64 / 1e6,
            ms / keys as f64 * 1e3
        );
    }
}
