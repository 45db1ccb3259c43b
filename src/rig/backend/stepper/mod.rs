//! The stepper-firmware backend: our firmware (real Pico or the simulated bench) over a
//! serial port, speaking `mpc-wire`.
//!
//! Owns the handshake and version check (with distinct messages for silence, a foreign
//! device and a version mismatch), the device configuration derived from the rig file,
//! capability checks, and the [`Driver`] / [`SampleStream`] implementation. The link
//! itself (decoder, retries, heartbeats, gap and CRC counting, reconnect after a brief USB
//! drop, restoring configuration/enable/stream/motion afterwards) runs on its own I/O
//! thread ([`link`]); the handle talks to it through channels, so a slow session loop never
//! starves the device's dead-man watchdog.
//!
//! Direction and gear ratio are applied on the host: the firmware is configured with
//! `reverse = false`, and driver angles are `direction · position · 360 / microsteps per
//! driver turn`.

pub(crate) mod convert;
pub mod link;

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{self, Receiver, RecvTimeoutError, Sender};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::Duration;

use mpc_wire::host::{CommandChannel, RetryPolicy};
use mpc_wire::{AckCode, Command, Config, Decoder, Report, MAX_BATCH};

pub use convert::{gear_fraction, SensorMap, GEAR_RATIO_TOLERANCE};

use crate::rig::backend::{Driver, Sample, SampleStream};
use crate::rig::config::{DriverConfig, RigConfig, StepperDriverConfig};
use crate::rig::link::resolve_port;
use crate::rig::recording::{flags, Counts, DeviceInfo};
use crate::rig::RigError;

use link::{IoThread, Request, Restore, Shared};

/// How long a command may take end to end (queueing, retries, reply) before the handle
/// gives up: 2 s, longer than the link's own retry budget (4 × 100 ms) plus a reconnect
/// poll, so the link's own error normally arrives first.
pub const COMMAND_WAIT: Duration = Duration::from_secs(2);

/// Target number of sample frames per second: batches are sized so a stream sends about
/// 100 frames/s (10 samples per frame at 1 kHz), which keeps per-frame overhead small and
/// latency at 10 ms.
pub const FRAMES_PER_SECOND: f64 = 100.0;

/// Placeholder mechanics configured on a sensor board's unused motor output: the
/// firmware's defaults (1.8° motor, 1/16 microsteps, direct drive) at a crawl of 1 rpm, so
/// that even a stray command could not spin anything fast.
pub const SENSOR_BOARD_MOTOR: StepperDriverConfig = StepperDriverConfig {
    port: String::new(),
    steps_per_rev: 200,
    microsteps: 16,
    gear_ratio: 1.0,
    max_speed_rpm: 1.0,
    max_accel: 360.0,
    direction: 1,
};

/// The stepper-firmware bench backend.
pub struct StepperBench {
    path: PathBuf,
    driver: StepperDriverConfig,
    rig: RigConfig,
    wire_config: Config,
    info: mpc_wire::DeviceInfo,
    deg_per_step: f64,
    requests: Option<Sender<Request>>,
    samples: Receiver<Sample>,
    shared: Arc<Mutex<Shared>>,
    restore: Arc<Mutex<Restore>>,
    quit: Arc<AtomicBool>,
    thread: Option<JoinHandle<()>>,
    value_count: usize,
    /// This board turns the driver (false for a mixed bench's sensor board): its emergency
    /// stop is a driver fault.
    drives: bool,
    shut: bool,
}

impl StepperBench {
    /// Open the rig's firmware port (path from the rig, `--port` or USB serial), handshake,
    /// check capabilities and configure the device.
    pub fn open(rig: &RigConfig) -> Result<StepperBench, RigError> {
        let DriverConfig::StepperFirmware(driver) = &rig.driver else {
            return Err(RigError::Setup(format!(
                "rig `{}` has a {} driver, not stepper-firmware",
                rig.name,
                rig.driver.kind()
            )));
        };
        let port_cfg = rig
            .port(&driver.port)
            .ok_or_else(|| RigError::Setup(format!("rig has no port named `{}`", driver.port)))?;
        let path = resolve_port(port_cfg)?;
        Self::open_path(rig, driver, &path, port_cfg.baud, true)
    }

    /// Open our firmware as the sensor board of a mixed rig (`[sensor_board]`): the
    /// handshake, version and capability checks and the sampling configuration are those
    /// of a stepper bench; the motor output is configured with placeholder mechanics
    /// ([`SENSOR_BOARD_MOTOR`]) and never enabled. `rig` is the whole rig; only its
    /// firmware sensors are read.
    pub fn open_sensor_board(rig: &RigConfig) -> Result<StepperBench, RigError> {
        let board = rig
            .sensor_board
            .as_ref()
            .ok_or_else(|| RigError::Setup(format!("rig `{}` has no [sensor_board]", rig.name)))?;
        let port_cfg = rig
            .port(&board.port)
            .ok_or_else(|| RigError::Setup(format!("rig has no port named `{}`", board.port)))?;
        let path = resolve_port(port_cfg)?;
        let part = rig.part(true);
        let motor = StepperDriverConfig {
            port: board.port.clone(),
            ..SENSOR_BOARD_MOTOR
        };
        Self::open_path(&part, &motor, &path, port_cfg.baud, false)
    }

    fn open_path(
        rig: &RigConfig,
        driver: &StepperDriverConfig,
        path: &Path,
        baud: u32,
        drives: bool,
    ) -> Result<StepperBench, RigError> {
        let map = SensorMap::new(rig)?;
        let mut port = link::open_port(path, baud)?;
        let mut decoder = Decoder::<Report>::new();
        let mut channel = CommandChannel::new(link::HANDSHAKE_RETRY, 0);
        let hs = link::handshake(&mut port, path, &mut decoder, &mut channel)?;
        let info = hs.info;
        let caps = info.capabilities;
        if !caps.sensors.contains(map.set) {
            return Err(RigError::Setup(format!(
                "{}: the rig needs firmware sensors {:?} but the board `{}` reports only {:?}",
                path.display(),
                map.set,
                info.board.as_str(),
                caps.sensors
            )));
        }
        let rate = rig.sampling.rate_hz;
        if rate > f64::from(caps.max_sample_rate_hz) {
            return Err(RigError::Setup(format!(
                "sampling.rate_hz = {rate} but the board samples at most {} Hz",
                caps.max_sample_rate_hz
            )));
        }
        let (gear_motor, gear_output) = gear_fraction(driver.gear_ratio)?;
        let max_rpm = driver.max_speed_rpm.min(rig.safety.max_speed_rpm);
        let usteps_per_rev =
            f64::from(driver.steps_per_rev) * f64::from(driver.microsteps) * f64::from(gear_motor)
                / f64::from(gear_output);
        let step_rate = max_rpm / 60.0 * usteps_per_rev;
        if step_rate > f64::from(caps.max_step_rate_hz) {
            return Err(RigError::Safety(format!(
                "{max_rpm} rpm needs {step_rate:.0} steps/s but the board makes at most {} steps/s; lower max_speed_rpm or microsteps",
                caps.max_step_rate_hz
            )));
        }
        let batch = (rate / FRAMES_PER_SECOND).round().clamp(
            1.0,
            (MAX_BATCH.min(usize::from(caps.max_batch.max(1)))) as f64,
        ) as u8;
        let imu_every = if caps.imu_rate_hz > 0 {
            (rate / f64::from(caps.imu_rate_hz))
                .round()
                .clamp(1.0, 255.0) as u8
        } else {
            1
        };
        let wire_config = Config {
            steps_per_rev: u16::try_from(driver.steps_per_rev)
                .map_err(|_| RigError::Setup("driver.steps_per_rev must fit in 16 bits".into()))?,
            microsteps: driver.microsteps as u16,
            gear_motor,
            gear_output,
            max_speed_mdeg_s: (max_rpm * 6.0 * 1000.0).round() as u32,
            max_accel_mdeg_s2: (driver.max_accel * 1000.0).round() as u32,
            reverse: false,
            sample_rate_hz: rate.round() as u16,
            sensors: map.set,
            batch_len: batch,
            watchdog_ms: u16::try_from(rig.safety.watchdog_ms).unwrap_or(u16::MAX),
            imu_every,
        };
        wire_config
            .validate()
            .map_err(|e| RigError::Setup(format!("device configuration: {e}")))?;
        let (req_tx, req_rx) = mpsc::channel();
        let (sample_tx, sample_rx) = mpsc::sync_channel(link::SAMPLE_QUEUE);
        let shared = Arc::new(Mutex::new(Shared::default()));
        let restore = Arc::new(Mutex::new(Restore::default()));
        let quit = Arc::new(AtomicBool::new(false));
        let deg_per_step = f64::from(driver.direction) * 360.0 / usteps_per_rev;
        let heartbeat = Duration::from_millis(u64::from(rig.safety.watchdog_ms / 4).max(5));
        let io = IoThread {
            path: path.to_path_buf(),
            baud,
            port,
            decoder,
            channel: CommandChannel::new(RetryPolicy::default(), 1000),
            requests: req_rx,
            samples: sample_tx,
            shared: shared.clone(),
            quit: quit.clone(),
            map: map.clone(),
            deg_per_step,
            heartbeat,
            sample_interval_us: 1e6 / f64::from(wire_config.sample_rate_hz),
            restore: restore.clone(),
        };
        let thread = std::thread::Builder::new()
            .name(format!("mpc-link {}", path.display()))
            .spawn(move || io.run())
            .map_err(|e| RigError::Setup(format!("cannot start the link thread: {e}")))?;
        let bench = StepperBench {
            path: path.to_path_buf(),
            driver: driver.clone(),
            rig: rig.clone(),
            wire_config,
            info,
            deg_per_step,
            requests: Some(req_tx),
            samples: sample_rx,
            shared,
            restore,
            quit,
            thread: Some(thread),
            value_count: map.fields.len(),
            drives,
            shut: false,
        };
        bench.command(Command::Configure(wire_config))?;
        bench.lock_restore().configure = Some(Command::Configure(wire_config));
        Ok(bench)
    }

    /// The device's handshake answer.
    pub fn wire_info(&self) -> &mpc_wire::DeviceInfo {
        &self.info
    }

    /// The configuration sent to the device.
    pub fn wire_config(&self) -> &Config {
        &self.wire_config
    }

    /// The port path.
    pub fn path(&self) -> &Path {
        &self.path
    }

    fn lock_restore(&self) -> std::sync::MutexGuard<'_, Restore> {
        self.restore.lock().unwrap_or_else(|p| p.into_inner())
    }

    fn link_error(&self) -> RigError {
        let sh = self.shared.lock().unwrap_or_else(|p| p.into_inner());
        RigError::Disconnected {
            path: self.path.clone(),
            message: sh
                .fatal
                .clone()
                .unwrap_or_else(|| "the link thread has ended".into()),
        }
    }

    /// Send one command through the I/O thread and wait for its reply; a non-Ok
    /// acknowledgement becomes [`RigError::Device`].
    pub fn command(&self, command: Command) -> Result<Report, RigError> {
        let Some(tx) = &self.requests else {
            return Err(self.link_error());
        };
        let (reply_tx, reply_rx) = mpsc::channel();
        tx.send(Request {
            command,
            reply: reply_tx,
        })
        .map_err(|_| self.link_error())?;
        let report = match reply_rx.recv_timeout(COMMAND_WAIT) {
            Ok(r) => r?,
            Err(RecvTimeoutError::Timeout) => {
                return Err(RigError::CommandTimeout {
                    path: self.path.clone(),
                    command: command.name().into(),
                    attempts: 0,
                })
            }
            Err(RecvTimeoutError::Disconnected) => return Err(self.link_error()),
        };
        if let Report::Ack { code, .. } = report {
            if code != AckCode::Ok {
                return Err(RigError::Device {
                    path: self.path.clone(),
                    command: command.name().into(),
                    message: ack_message(code).into(),
                });
            }
        }
        Ok(report)
    }

    fn speed_mdeg_s(&self, rpm: f64) -> Result<i32, RigError> {
        let limit = self.driver.max_speed_rpm.min(self.rig.safety.max_speed_rpm);
        if !rpm.is_finite() || rpm.abs() > limit + 1e-9 {
            return Err(RigError::Safety(format!(
                "{rpm} rpm exceeds the rig's limit of {limit} rpm (driver.max_speed_rpm / safety.max_speed_rpm)"
            )));
        }
        Ok((f64::from(self.driver.direction) * rpm * 6000.0).round() as i32)
    }
}

fn ack_message(code: AckCode) -> &'static str {
    match code {
        AckCode::Ok => "ok",
        AckCode::VersionMismatch => "protocol version mismatch",
        AckCode::InvalidConfig => "invalid configuration",
        AckCode::NotConfigured => "not configured yet",
        AckCode::MotorDisabled => "the motor is disabled",
        AckCode::EStopLatched => "the emergency stop is latched",
        AckCode::OutOfRange => "a value is out of range",
        AckCode::Busy => "busy (the motor is moving)",
        AckCode::Unsupported => "not supported by this board",
    }
}

impl Driver for StepperBench {
    fn enable(&mut self) -> Result<(), RigError> {
        self.command(Command::SetMotorEnabled(true))?;
        self.lock_restore().enabled = true;
        Ok(())
    }

    fn disable(&mut self) -> Result<(), RigError> {
        self.lock_restore().enabled = false;
        self.lock_restore().motion = None;
        self.command(Command::SetMotorEnabled(false)).map(drop)
    }

    fn zero(&mut self) -> Result<(), RigError> {
        self.command(Command::Zero).map(drop)
    }

    fn run_at(&mut self, rpm: f64) -> Result<(), RigError> {
        let cmd = Command::RunSpeed {
            speed_mdeg_s: self.speed_mdeg_s(rpm)?,
        };
        self.command(cmd)?;
        self.lock_restore().motion = Some(cmd);
        Ok(())
    }

    fn move_to(&mut self, deg: f64) -> Result<(), RigError> {
        let cmd = Command::MoveTo {
            angle_mdeg: convert::deg_to_mdeg(&self.driver, deg)?,
        };
        self.command(cmd)?;
        self.lock_restore().motion = Some(cmd);
        Ok(())
    }

    fn move_by(&mut self, deg: f64) -> Result<(), RigError> {
        let cmd = Command::MoveBy {
            delta_mdeg: convert::deg_to_mdeg(&self.driver, deg)?,
        };
        self.command(cmd)?;
        // Repeating a relative move after a reconnect would move twice: do not restore it.
        self.lock_restore().motion = None;
        Ok(())
    }

    fn stop(&mut self) -> Result<(), RigError> {
        self.lock_restore().motion = None;
        self.command(Command::Stop).map(drop)
    }

    fn estop(&mut self) -> Result<(), RigError> {
        {
            let mut r = self.lock_restore();
            r.motion = None;
            r.enabled = false;
        }
        self.command(Command::EmergencyStop).map(drop)
    }

    fn position_deg(&mut self) -> Result<f64, RigError> {
        match self.command(Command::QueryStatus)? {
            Report::Status(s) => Ok(f64::from(s.position) * self.deg_per_step),
            other => Err(RigError::Device {
                path: self.path.clone(),
                command: "QueryStatus".into(),
                message: format!("answered with {} instead of a status", other.name()),
            }),
        }
    }

    fn fault(&mut self) -> Option<String> {
        let sh = self.shared.lock().unwrap_or_else(|p| p.into_inner());
        sh.events
            .iter()
            .any(|(k, _)| *k == mpc_wire::EventKind::EmergencyStop)
            .then(|| {
                "the firmware latched its emergency stop (it could not drive the STEP/DIR/EN \
                 pins, or its e-stop input tripped)"
                    .to_string()
            })
    }

    fn shutdown(&mut self) -> Result<(), RigError> {
        if self.shut {
            return Ok(());
        }
        self.shut = true;
        *self.lock_restore() = Restore::default();
        // Each step is attempted even if an earlier one failed; the first error is kept.
        let mut first_err = None;
        for cmd in [
            Command::Stop,
            Command::SetMotorEnabled(false),
            Command::StopStream,
        ] {
            if let Err(e) = self.command(cmd) {
                first_err.get_or_insert(e);
            }
        }
        self.quit.store(true, Ordering::Relaxed);
        self.requests = None;
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
        match first_err {
            // After an unplug there is nothing to stop; the firmware watchdog has done it.
            Some(RigError::Disconnected { .. }) | None => Ok(()),
            Some(e) => Err(e),
        }
    }
}

impl SampleStream for StepperBench {
    fn value_count(&self) -> usize {
        self.value_count
    }

    fn start_stream(&mut self, rate_hz: f64) -> Result<(), RigError> {
        if (rate_hz - f64::from(self.wire_config.sample_rate_hz)).abs() > 0.5 {
            let mut c = self.wire_config;
            c.sample_rate_hz = rate_hz.round().clamp(1.0, 65_535.0) as u16;
            c.batch_len = (rate_hz / FRAMES_PER_SECOND)
                .round()
                .clamp(1.0, MAX_BATCH as f64) as u8;
            c.validate()
                .map_err(|e| RigError::Setup(format!("device configuration: {e}")))?;
            self.command(Command::Configure(c))?;
            self.wire_config = c;
            self.lock_restore().configure = Some(Command::Configure(c));
        }
        self.command(Command::StartStream)?;
        self.lock_restore().streaming = true;
        Ok(())
    }

    fn stop_stream(&mut self) -> Result<(), RigError> {
        self.lock_restore().streaming = false;
        self.command(Command::StopStream).map(drop)
    }

    fn poll_samples(&mut self, timeout: Duration, out: &mut Vec<Sample>) -> Result<(), RigError> {
        let first = out.len();
        match self.samples.recv_timeout(timeout) {
            Ok(s) => out.push(s),
            Err(RecvTimeoutError::Timeout) => return Ok(()),
            Err(RecvTimeoutError::Disconnected) => return Err(self.link_error()),
        }
        while let Ok(s) = self.samples.try_recv() {
            out.push(s);
        }
        if self.drives {
            // The board that turns the driver stopped it on its own.
            for s in &mut out[first..] {
                if s.flags & flags::ESTOP != 0 {
                    s.flags |= flags::DRIVER_FAULT;
                }
            }
        }
        Ok(())
    }

    fn counts(&self) -> Counts {
        let sh = self.shared.lock().unwrap_or_else(|p| p.into_inner());
        let mut c = sh.counts;
        c.missing_samples += sh.host_overflow;
        c
    }

    fn device_info(&self) -> DeviceInfo {
        let caps = self.info.capabilities;
        let mut extra = std::collections::BTreeMap::new();
        extra.insert(
            "max_step_rate_hz".into(),
            serde_json::json!(caps.max_step_rate_hz),
        );
        extra.insert(
            "max_sample_rate_hz".into(),
            serde_json::json!(caps.max_sample_rate_hz),
        );
        extra.insert("imu_rate_hz".into(), serde_json::json!(caps.imu_rate_hz));
        extra.insert(
            "batch_len".into(),
            serde_json::json!(self.wire_config.batch_len),
        );
        DeviceInfo {
            backend: "stepper-firmware".into(),
            ports: vec![self.path.display().to_string()],
            firmware_version: Some(link::version_string(self.info.firmware_version)),
            protocol_version: Some(u32::from(self.info.protocol_version)),
            board: Some(self.info.board.as_str().to_string()),
            clock_hz: Some(u64::from(self.info.clock_hz)),
            extra,
        }
    }
}

impl Drop for StepperBench {
    fn drop(&mut self) {
        if let Err(e) = self.shutdown() {
            tracing::warn!("{}: shutdown: {e}", self.path.display());
        }
    }
}
