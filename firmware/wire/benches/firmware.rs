//! Decoder throughput for a 1 kHz sample stream: encodes a long stream of realistic sample
//! batches (timestamps 1 ms apart, a turning driver, two encoders and an IMU, batches of
//! 10), then times the incremental decoder over it and prints frames/s and MB/s.
//!
//! Run with `cargo bench -p mpc-wire --bench firmware` (the workspace's
//! `cargo bench --bench firmware` prints the same figures and the device's).

#[path = "support/decoder.rs"]
mod decoder;

fn main() {
    decoder::run_all();
}
