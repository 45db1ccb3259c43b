//! The mixed bench: a Dynamixel servo turns the driver (its bus may also carry torque-off
//! follower servos) while our firmware, on a board of its own (`[sensor_board]` in the rig
//! file), reads the follower sensors: an IMU for a 3R follower, an AS5600 and a linear
//! encoder for 1R1T. Two ports, two device clocks, one recording.
//!
//! Owns: opening both devices ([`DynamixelBench`] with the rig's Dynamixel part,
//! [`StepperBench::open_sensor_board`] with its firmware part), the [`Driver`] side (all of
//! it the bus's), polling both streams and merging them ([`merge`]: the board's samples are
//! the timeline, the bus's unwrapped positions are interpolated onto it after both clocks
//! are mapped onto the host's, [`clock`]), summed link counts, and a device description
//! naming both devices and the merge's figures. Shutdown stops the driver first, then the
//! board's stream.
//!
//! Does not own either device's protocol (their backends do), the session or the recording.

pub mod clock;
pub mod merge;

use std::time::{Duration, Instant};

use crate::rig::backend::dynamixel::DynamixelBench;
use crate::rig::backend::stepper::StepperBench;
use crate::rig::backend::{Driver, Sample, SampleStream};
use crate::rig::config::{DriverConfig, RigConfig};
use crate::rig::recording::{Counts, DeviceInfo};
use crate::rig::RigError;
use merge::{Merger, Source};

/// Longest single wait on the board's stream inside one poll before the bus is read
/// again. Default 2 ms: well under a bus period (~12 ms at the factory baud), so bus
/// samples are taken in promptly, and long enough not to spin.
pub const POLL_SLICE: Duration = Duration::from_millis(2);

/// A Dynamixel driver bus plus our firmware as a sensor board.
pub struct MixedBench {
    bus: DynamixelBench,
    board: StepperBench,
    merger: Merger,
    epoch: Instant,
    board_buf: Vec<Sample>,
    bus_buf: Vec<Sample>,
    /// A link error seen while samples were still waiting: those were delivered first.
    pending_error: Option<RigError>,
    delivered: u64,
}

impl std::fmt::Debug for MixedBench {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("MixedBench")
            .field("bus", &self.bus)
            .field("delivered", &self.delivered)
            .finish()
    }
}

/// Recording columns of `rig` in order, each from the board or the bus (the index within
/// that device's own values, which follow the rig's sensor order).
pub fn column_sources(rig: &RigConfig) -> Vec<Source> {
    let (mut board, mut bus) = (0, 0);
    let mut out = Vec::new();
    for s in &rig.sensors {
        for _ in s.columns() {
            if s.is_firmware() {
                out.push(Source::Board(board));
                board += 1;
            } else {
                out.push(Source::Bus(bus));
                bus += 1;
            }
        }
    }
    out
}

impl MixedBench {
    /// Open both devices of a mixed rig (ports from the rig after `--port` overrides).
    pub fn open(rig: &RigConfig) -> Result<Self, RigError> {
        if !rig.is_mixed() || !matches!(rig.driver, DriverConfig::Dynamixel(_)) {
            return Err(RigError::Setup(format!(
                "rig `{}`: a mixed bench needs a Dynamixel driver and a [sensor_board]",
                rig.name
            )));
        }
        let bus = DynamixelBench::from_rig(&rig.part(false))?;
        let board = StepperBench::open_sensor_board(rig)?;
        Ok(Self {
            bus,
            board,
            merger: Merger::new(column_sources(rig)),
            epoch: Instant::now(),
            board_buf: Vec::new(),
            bus_buf: Vec::new(),
            pending_error: None,
            delivered: 0,
        })
    }

    /// Seconds of `at` (or now) since the bench was opened, on the host clock.
    fn host_s(&self, at: Option<Instant>) -> f64 {
        let at = at.unwrap_or_else(Instant::now);
        match at.checked_duration_since(self.epoch) {
            Some(d) => d.as_secs_f64(),
            None => -(self.epoch - at).as_secs_f64(),
        }
    }

    fn take_in(&mut self) {
        for s in std::mem::take(&mut self.board_buf) {
            let h = self.host_s(s.host_instant);
            self.merger.push_board(s, h);
        }
        for s in std::mem::take(&mut self.bus_buf) {
            let h = self.host_s(s.host_instant);
            self.merger.push_bus(s, h);
        }
    }
}

impl Driver for MixedBench {
    fn enable(&mut self) -> Result<(), RigError> {
        self.bus.enable()
    }
    fn disable(&mut self) -> Result<(), RigError> {
        self.bus.disable()
    }
    fn zero(&mut self) -> Result<(), RigError> {
        self.bus.zero()
    }
    fn run_at(&mut self, rpm: f64) -> Result<(), RigError> {
        self.bus.run_at(rpm)
    }
    fn move_to(&mut self, deg: f64) -> Result<(), RigError> {
        self.bus.move_to(deg)
    }
    fn move_by(&mut self, deg: f64) -> Result<(), RigError> {
        self.bus.move_by(deg)
    }
    fn stop(&mut self) -> Result<(), RigError> {
        self.bus.stop()
    }
    fn estop(&mut self) -> Result<(), RigError> {
        self.bus.estop()
    }
    fn position_deg(&mut self) -> Result<f64, RigError> {
        self.bus.position_deg()
    }
    fn fault(&mut self) -> Option<String> {
        self.bus.fault()
    }
    fn shutdown(&mut self) -> Result<(), RigError> {
        // The motor first; the board's stream after, whatever happened to the bus.
        let driver = self.bus.shutdown();
        let board = self.board.shutdown();
        driver.and(board)
    }
}

impl SampleStream for MixedBench {
    fn value_count(&self) -> usize {
        self.merger.columns().len()
    }

    fn start_stream(&mut self, rate_hz: f64) -> Result<(), RigError> {
        // The board samples at the rig's rate; the bus as fast as it can up to that rate
        // (its worker reads back to back when the wire is slower).
        self.board.start_stream(rate_hz)?;
        self.bus.start_stream(rate_hz)
    }

    fn stop_stream(&mut self) -> Result<(), RigError> {
        let bus = self.bus.stop_stream();
        let board = self.board.stop_stream();
        bus.and(board)
    }

    fn poll_samples(&mut self, timeout: Duration, out: &mut Vec<Sample>) -> Result<(), RigError> {
        if let Some(e) = self.pending_error.take() {
            return Err(e);
        }
        let deadline = Instant::now() + timeout;
        let before = out.len();
        loop {
            let slice = deadline
                .saturating_duration_since(Instant::now())
                .min(POLL_SLICE);
            let board = self.board.poll_samples(slice, &mut self.board_buf);
            let bus = self.bus.poll_samples(Duration::ZERO, &mut self.bus_buf);
            self.take_in();
            if let Err(e) = board.and(bus) {
                // Deliver what is waiting, then report the loss on the next poll.
                self.merger.flush(out);
                self.delivered += (out.len() - before) as u64;
                self.pending_error = Some(e);
                return Ok(());
            }
            let now = self.host_s(None);
            self.merger.drain(now, out);
            if out.len() > before || Instant::now() >= deadline {
                break;
            }
        }
        self.delivered += (out.len() - before) as u64;
        Ok(())
    }

    fn counts(&self) -> Counts {
        let (a, b) = (self.bus.counts(), self.board.counts());
        Counts {
            samples: self.delivered,
            gaps: a.gaps + b.gaps,
            missing_samples: a.missing_samples + b.missing_samples,
            crc_errors: a.crc_errors + b.crc_errors,
            reconnects: a.reconnects + b.reconnects,
            decode_errors: a.decode_errors + b.decode_errors,
            ..Counts::default()
        }
    }

    fn device_info(&self) -> DeviceInfo {
        let bus = self.bus.device_info();
        let board = self.board.device_info();
        let mut info = board.clone();
        info.backend = "mixed (dynamixel driver + stepper-firmware sensor board)".into();
        info.ports = bus.ports.iter().chain(&board.ports).cloned().collect();
        info.extra
            .insert("bus".into(), serde_json::to_value(&bus).unwrap_or_default());
        info.extra.insert(
            "merge".into(),
            serde_json::json!({
                "timeline": "sensor board",
                "board_samples_without_driver_angle": self.merger.unmatched(),
                "rows_with_held_driver_angle": self.merger.held(),
                "bus_minus_board_clock_offset_s": self.merger.clock_offset_s(),
            }),
        );
        info
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::Path;

    /// Guards the column layout of a mixed rig: recording columns follow the rig's sensor
    /// order, each taken from the device that reads it at that device's own index (an IMU
    /// spans four board values, a follower servo one bus value).
    #[test]
    fn columns_follow_rig_order_across_both_devices() {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("rigs/sim-dynamixel-imu.toml");
        let text = std::fs::read_to_string(path).unwrap();
        let text = text.replace(
            "[[sensors]]\nkind = \"imu\"",
            "[[sensors]]\nkind = \"as5600\"\nname = \"rz\"\ndof = \"rz\"\n\n[[sensors]]\nkind = \"dynamixel\"\nname = \"servo\"\nport = \"dxl\"\nid = 2\n\n[[sensors]]\nkind = \"imu\"",
        );
        let rig = RigConfig::from_toml_str(&text, Path::new("t.toml")).unwrap();
        assert_eq!(
            column_sources(&rig),
            [
                Source::Board(0),
                Source::Bus(0),
                Source::Board(1),
                Source::Board(2),
                Source::Board(3),
                Source::Board(4),
            ]
        );
        assert_eq!(rig.part(true).sensor_columns().len(), 5);
        assert_eq!(rig.part(false).sensor_columns().len(), 1);
    }
}
