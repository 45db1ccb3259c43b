//! Sample scheduling and batching: when the next sample is due at the configured rate,
//! which samples read the IMU (every `imu_every`-th; the others repeat its latest value
//! without the fresh flag), and when a batch is full.
//!
//! Owns timing and batching only; reading the sensors and sending batches is done by
//! [`crate::Device`]. Sample `k` of a stream is due at `origin + round(k·10⁶/rate)` µs, so the
//! rate is exact over any span. A late poll does not produce a burst of stale samples: the
//! missed ticks are skipped and the next sample carries [`mpc_wire::SampleFlags::OVERRUN`].

use mpc_wire::{Sample, SampleBatch, SensorSet};

/// The sampler of one stream.
#[derive(Debug, Clone)]
pub struct Sampler {
    rate_hz: u32,
    origin_us: u64,
    index: u64,
    running: bool,
    batch_len: usize,
    imu_every: u8,
    imu_phase: u8,
    batch: SampleBatch,
}

impl Default for Sampler {
    fn default() -> Self {
        Self::new()
    }
}

impl Sampler {
    /// A stopped sampler.
    pub const fn new() -> Self {
        Self {
            rate_hz: 1,
            origin_us: 0,
            index: 0,
            running: false,
            batch_len: 1,
            imu_every: 1,
            imu_phase: 0,
            batch: SampleBatch::new(SensorSet::EMPTY),
        }
    }

    /// Start a stream at `now_us`: first sample due at once.
    pub fn start(
        &mut self,
        now_us: u64,
        rate_hz: u16,
        fields: SensorSet,
        batch_len: u8,
        imu_every: u8,
    ) {
        self.rate_hz = rate_hz.max(1) as u32;
        self.origin_us = now_us;
        self.index = 0;
        self.running = true;
        self.batch_len = (batch_len as usize).clamp(1, mpc_wire::MAX_BATCH);
        self.imu_every = imu_every.max(1);
        self.imu_phase = 0;
        self.batch = SampleBatch::new(fields);
    }

    /// Stop the stream; returns the partial batch if it holds samples.
    pub fn stop(&mut self) -> Option<SampleBatch> {
        self.running = false;
        let partial = (!self.batch.is_empty()).then_some(self.batch);
        self.batch.clear();
        partial
    }

    /// Whether a stream runs.
    pub fn is_running(&self) -> bool {
        self.running
    }

    /// Fields of the samples.
    pub fn fields(&self) -> SensorSet {
        self.batch.fields
    }

    fn due_at(&self, index: u64) -> u64 {
        let r = self.rate_hz as u64;
        self.origin_us + (index * 1_000_000 + r / 2) / r
    }

    /// When the next sample is due, if streaming.
    pub fn next_due_us(&self) -> Option<u64> {
        self.running.then(|| self.due_at(self.index))
    }

    /// Begin the sample due now: returns whether this sample should read the IMU and
    /// whether ticks were missed before it. Advances the schedule past `now_us`.
    pub fn begin_sample(&mut self, now_us: u64) -> (bool, bool) {
        let read_imu = self.imu_phase == 0;
        self.imu_phase = (self.imu_phase + 1) % self.imu_every;
        let mut overrun = false;
        self.index += 1;
        // Skip ticks already in the past: no bursts after a stall.
        if self.due_at(self.index) <= now_us {
            let r = self.rate_hz as u64;
            let elapsed = now_us - self.origin_us;
            // First index strictly after now.
            let mut k = (elapsed * r) / 1_000_000;
            while self.due_at(k) <= now_us {
                k += 1;
            }
            if k > self.index {
                overrun = true;
            }
            self.index = k;
        }
        (read_imu, overrun)
    }

    /// Add a finished sample; returns a full batch to send.
    pub fn finish_sample(&mut self, sample: Sample) -> Option<SampleBatch> {
        // Cannot fail: the batch is sent and cleared whenever it reaches batch_len ≤ MAX_BATCH.
        let _ = self.batch.push(sample);
        if self.batch.len() >= self.batch_len {
            let full = self.batch;
            self.batch.clear();
            Some(full)
        } else {
            None
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Guards the exact rate: 1000 Hz from t = 7 µs gives samples at 7, 1007, 2007, … and
    /// a batch every `batch_len` samples; the IMU is read on every 4th sample.
    #[test]
    fn schedule_batches_and_imu_phase() {
        let mut s = Sampler::new();
        s.start(7, 1000, SensorSet::ENCODER_A, 5, 4);
        let mut imu_reads = 0;
        let mut batches = 0;
        for k in 0..20u64 {
            let t = s.next_due_us().unwrap();
            assert_eq!(t, 7 + k * 1000);
            let (imu, overrun) = s.begin_sample(t);
            assert!(!overrun);
            imu_reads += imu as u32;
            if s.finish_sample(Sample {
                timestamp_us: t as u32,
                ..Sample::default()
            })
            .is_some()
            {
                batches += 1;
            }
        }
        assert_eq!((imu_reads, batches), (5, 4));
        assert!(s.stop().is_none());
    }

    /// Guards a non-integer period (3 Hz): the schedule does not drift.
    #[test]
    fn non_integer_period_does_not_drift() {
        let mut s = Sampler::new();
        s.start(0, 3, SensorSet::EMPTY, 1, 1);
        let mut t = 0;
        for _ in 0..3000 {
            t = s.next_due_us().unwrap();
            s.begin_sample(t);
        }
        assert_eq!(t, 999_666_667);
        assert_eq!(s.next_due_us(), Some(1_000_000_000));
    }

    /// Guards stall handling: after a 10.5 ms stall, one sample (flagged overrun) and then
    /// the schedule continues on its grid.
    #[test]
    fn stall_skips_ticks_and_flags_overrun() {
        let mut s = Sampler::new();
        s.start(0, 1000, SensorSet::EMPTY, 10, 1);
        s.begin_sample(0);
        let (_, overrun) = s.begin_sample(10_500);
        assert!(overrun);
        assert_eq!(s.next_due_us(), Some(11_000));
        s.finish_sample(Sample::default());
        let partial = s.stop().unwrap();
        assert_eq!(partial.len(), 1);
    }
}
