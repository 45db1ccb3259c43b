//! Decoder throughput measurement shared by the `mpc-wire` benchmark and the workspace's
//! `firmware` benchmark.

use std::hint::black_box;
use std::time::Instant;

use mpc_wire::{
    encode_frame, Decoder, Report, Sample, SampleBatch, SampleFlags, SensorSet, MAX_FRAME_LEN,
};

/// A stream of `frames` sample-batch frames of `batch` samples carrying `fields`.
pub fn stream(fields: SensorSet, batch: usize, frames: usize) -> Vec<u8> {
    let mut out = Vec::with_capacity(frames * 300);
    let mut buf = [0u8; MAX_FRAME_LEN];
    let mut t = 0u32;
    for seq in 0..frames {
        let mut b = SampleBatch::new(fields);
        for _ in 0..batch {
            let pos = (t / 100) as i32;
            let s = Sample {
                timestamp_us: t,
                position: pos,
                flags: SampleFlags::MOVING | SampleFlags::ENABLED,
                encoder_a: (pos as u32 % 4096) as u16,
                encoder_b: ((pos as u32 * 3) % 4096) as u16,
                quadrature: pos * 4,
                quaternion: [16384, 12, -40, 7],
            };
            b.push(s).expect("batch below capacity");
            t = t.wrapping_add(1000);
        }
        let n = encode_frame(seq as u16, &Report::Samples(b), &mut buf).expect("encodes");
        out.extend_from_slice(&buf[..n]);
    }
    out
}

/// Time the decoder over a 200 000-frame stream and print the best of five runs.
pub fn run(label: &str, fields: SensorSet) {
    let frames = 200_000;
    let bytes = stream(fields, 10, frames);
    let mut best = f64::INFINITY;
    let mut count = 0usize;
    for _ in 0..5 {
        let mut d = Decoder::<Report>::new();
        count = 0;
        let start = Instant::now();
        d.feed(black_box(&bytes), |r| {
            if let Ok(f) = r {
                black_box(&f);
                count += 1;
            }
        });
        best = best.min(start.elapsed().as_secs_f64());
    }
    assert_eq!(count, frames, "every frame decodes");
    let fps = frames as f64 / best;
    let mbs = bytes.len() as f64 / best / 1e6;
    let frame_len = bytes.len() / frames;
    println!(
        "{label:<28} {frame_len:>4} B/frame  {fps:>12.0} frames/s  {mbs:>8.1} MB/s  \
         ({:.0}x a 1 kHz stream of 100 frames/s)",
        fps / 100.0
    );
}

/// Measure the three typical field sets.
pub fn run_all() {
    println!("mpc-wire decoder throughput, batches of 10 samples (1 kHz stream = 100 frames/s)");
    run("encoder A only", SensorSet::ENCODER_A);
    run(
        "encoders A+B + quadrature",
        SensorSet::ENCODER_A | SensorSet::ENCODER_B | SensorSet::QUADRATURE,
    );
    run("all sensors incl. IMU", SensorSet::ALL);
}
