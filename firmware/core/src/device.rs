//! The device: command dispatch, handshake, safety (motor disabled at boot, latched
//! emergency stop, dead-man watchdog), step output on the STEP/DIR/EN pins, and the sample
//! stream, all driven by received bytes and the platform clock.
//!
//! Owns the device's behaviour as seen from the wire. It owns no I/O loop: a board (or the
//! host's simulated bench) feeds received bytes to [`Device::receive`], calls
//! [`Device::poll`] at or after [`Device::next_deadline_us`], and sends what
//! [`Device::transmit`] hands out.

use embedded_hal::delay::DelayNs;
use embedded_hal::digital::OutputPin;
use mpc_wire::{
    encode_frame, AckCode, BoardName, Capabilities, Command, Config, Decoder, DeviceInfo, Event,
    EventKind, Report, Sample, SampleFlags, SensorSet, Status, StatusFlags, ESTOP_BY_INPUT,
    MAX_BATCH, MAX_FRAME_LEN, PROTOCOL_VERSION,
};

use crate::outbox::Outbox;
use crate::platform::{BoardConfig, Clock, Parts, Platform, QuadratureCounter};
use crate::sampler::Sampler;
use crate::sensors::as5600::As5600;
use crate::sensors::bno055::{self, Bno055};
use crate::stepper::{Completion, Limits, StepGenerator};
use crate::watchdog::{Watchdog, DEFAULT_WATCHDOG_MS};

/// Firmware version reported in the handshake: this crate's version.
pub const FIRMWARE_VERSION: [u8; 3] = {
    const fn parse(s: &str) -> u8 {
        let b = s.as_bytes();
        let mut i = 0;
        let mut v = 0u8;
        while i < b.len() {
            v = v * 10 + (b[i] - b'0');
            i += 1;
        }
        v
    }
    [
        parse(env!("CARGO_PKG_VERSION_MAJOR")),
        parse(env!("CARGO_PKG_VERSION_MINOR")),
        parse(env!("CARGO_PKG_VERSION_PATCH")),
    ]
};

/// Largest |position| a move may target, microsteps: the wire's `i32` range.
pub const MAX_POSITION: i64 = i32::MAX as i64;

/// Microsteps for `mdeg` millidegrees of the driver shaft (rounded to nearest).
pub fn mdeg_to_usteps(config: &Config, mdeg: i64) -> i64 {
    let (num, den) = config.microsteps_per_output_rev();
    let n = mdeg as i128 * num as i128;
    let d = 360_000i128 * den as i128;
    let q = if n >= 0 {
        (n + d / 2) / d
    } else {
        (n - d / 2) / d
    };
    q.clamp(i64::MIN as i128, i64::MAX as i128) as i64
}

/// The bench device over platform `P`.
pub struct Device<P: Platform> {
    parts: Parts<P>,
    board: BoardConfig,
    capabilities: SensorSet,
    encoder_a: As5600,
    encoder_b: As5600,
    imu: Bno055,
    config: Option<Config>,
    stepper: StepGenerator,
    enabled: bool,
    estop: bool,
    estop_input: bool,
    disable_at_rest: bool,
    watchdog: Watchdog,
    watchdog_tripped: bool,
    sampler: Sampler,
    decoder: Decoder<Command>,
    outbox: Outbox,
    tx_seq: u16,
    last: Option<(u16, Command, Report)>,
    version_ok: bool,
    rx_errors: u32,
    samples_dropped: u32,
    dir_level: Option<bool>,
    healthy: SensorSet,
    last_encoder_a: u16,
    last_encoder_b: u16,
    last_quaternion: [i16; 4],
    pin_fault: bool,
}

impl<P: Platform> Device<P> {
    /// Boot: drive EN to "disabled", STEP low, probe the fitted sensors (those that answer
    /// become capabilities), start the watchdog and queue a `Boot` event.
    pub fn new(parts: Parts<P>, board: BoardConfig) -> Self {
        let now = parts.clock.now_us();
        let mut d = Self {
            parts,
            board,
            capabilities: SensorSet::EMPTY,
            encoder_a: As5600::new(board.encoder_a_address),
            encoder_b: As5600::new(board.encoder_b_address),
            imu: Bno055::new(board.imu_address),
            config: None,
            stepper: StepGenerator::new(Limits {
                max_speed: 1,
                accel: 1,
            }),
            enabled: false,
            estop: false,
            estop_input: false,
            disable_at_rest: false,
            watchdog: Watchdog::new(DEFAULT_WATCHDOG_MS, now),
            watchdog_tripped: false,
            sampler: Sampler::new(),
            decoder: Decoder::new(),
            outbox: Outbox::new(),
            tx_seq: 0,
            last: None,
            version_ok: true,
            rx_errors: 0,
            samples_dropped: 0,
            dir_level: None,
            healthy: SensorSet::EMPTY,
            last_encoder_a: 0,
            last_encoder_b: 0,
            last_quaternion: [bno055::QUATERNION_ONE, 0, 0, 0],
            pin_fault: false,
        };
        d.set_enable_pin(false);
        if d.parts.step.set_low().is_err() {
            d.pin_fault = true;
        }
        d.probe_sensors();
        if d.pin_fault {
            d.estop = true;
            error!("boot: a driver pin cannot be set; emergency stop latched");
        }
        info!(
            "boot: sensors answering {=u8:#x} of {=u8:#x} fitted",
            d.capabilities.bits(),
            d.board.fitted.bits()
        );
        d.event(EventKind::Boot, 0, now);
        d
    }

    fn probe_sensors(&mut self) {
        let fitted = self.board.fitted;
        let mut caps = SensorSet::EMPTY;
        if fitted.contains(SensorSet::ENCODER_A) {
            // A sensor that answers counts even without a magnet (it shows as a fault).
            if let Ok(s) = self.encoder_a.status(&mut self.parts.i2c_a) {
                caps = caps | SensorSet::ENCODER_A;
                self.healthy.set(SensorSet::ENCODER_A, s.detected);
            }
        }
        if fitted.contains(SensorSet::ENCODER_B) {
            if let Ok(s) = self.encoder_b.status(&mut self.parts.i2c_b) {
                caps = caps | SensorSet::ENCODER_B;
                self.healthy.set(SensorSet::ENCODER_B, s.detected);
            }
        }
        if fitted.contains(SensorSet::IMU)
            && self
                .imu
                .init(&mut self.parts.i2c_a, &mut self.parts.delay)
                .is_ok()
        {
            caps = caps | SensorSet::IMU;
            self.healthy = self.healthy | SensorSet::IMU;
        }
        if fitted.contains(SensorSet::QUADRATURE) {
            caps = caps | SensorSet::QUADRATURE;
            self.healthy = self.healthy | SensorSet::QUADRATURE;
        }
        self.capabilities = caps;
    }

    /// Sensors that answered at boot.
    pub fn capabilities(&self) -> SensorSet {
        self.capabilities
    }

    /// Driver position, microsteps.
    pub fn position(&self) -> i64 {
        self.stepper.position()
    }

    /// Whether the driver is enabled.
    pub fn is_enabled(&self) -> bool {
        self.enabled
    }

    /// Whether the emergency stop is latched.
    pub fn estop_latched(&self) -> bool {
        self.estop
    }

    /// The board's e-stop input: `asserted` while the button is pressed or its loop is
    /// broken. Asserting it latches the emergency stop (an [`EventKind::EmergencyStop`]
    /// event with detail [`ESTOP_BY_INPUT`]); while it stays asserted, `ClearEmergencyStop`
    /// is refused. A board without the input never calls it.
    pub fn set_estop_input(&mut self, asserted: bool) {
        if asserted && !self.estop_input {
            warn!("e-stop input asserted");
            let now = self.parts.clock.now_us();
            self.emergency_stop(now, ESTOP_BY_INPUT);
        } else if !asserted && self.estop_input {
            info!("e-stop input released (the stop stays latched until cleared)");
        }
        self.estop_input = asserted;
    }

    /// Whether steps are being generated.
    pub fn is_moving(&self) -> bool {
        !self.stepper.is_idle()
    }

    /// Whether samples are being streamed.
    pub fn is_streaming(&self) -> bool {
        self.sampler.is_running()
    }

    /// The configuration in force.
    pub fn config(&self) -> Option<&Config> {
        self.config.as_ref()
    }

    /// The platform's clock.
    pub fn clock(&self) -> &P::Clock {
        &self.parts.clock
    }

    /// Bytes waiting to be transmitted.
    pub fn pending_output(&self) -> usize {
        self.outbox.len()
    }

    /// Move up to `out.len()` bytes of queued frames into `out`; returns how many.
    pub fn transmit(&mut self, out: &mut [u8]) -> usize {
        self.outbox.pop(out)
    }

    /// Copy up to `out.len()` queued bytes without removing them (for a link that may time
    /// out); call [`Device::consume_output`] with what was actually sent.
    pub fn peek_output(&self, out: &mut [u8]) -> usize {
        self.outbox.peek(out)
    }

    /// Drop the first `n` queued bytes after the link took them.
    pub fn consume_output(&mut self, n: usize) {
        self.outbox.consume(n);
    }

    /// The earliest time at which [`Device::poll`] has work: next step, next sample or the
    /// watchdog deadline. A loop may sleep until then (or until bytes arrive).
    pub fn next_deadline_us(&self) -> Option<u64> {
        [
            self.stepper.next_step_us(),
            self.sampler.next_due_us(),
            self.watchdog.deadline_us(),
        ]
        .into_iter()
        .flatten()
        .min()
    }

    /// Feed bytes received from the host; complete commands are executed at once.
    pub fn receive(&mut self, bytes: &[u8]) {
        for &b in bytes {
            match self.decoder.push(b) {
                None => {}
                Some(Ok(frame)) => self.on_command(frame.seq, frame.msg),
                Some(Err(_)) => {
                    debug!("dropped a damaged frame from the host");
                    self.rx_errors = self.rx_errors.wrapping_add(1);
                }
            }
        }
    }

    /// Do everything due up to the clock's present time, in time order: steps, samples,
    /// watchdog.
    pub fn poll(&mut self) {
        let now = self.parts.clock.now_us();
        loop {
            let step = self.stepper.next_step_us().filter(|&t| t <= now);
            let sample = self.sampler.next_due_us().filter(|&t| t <= now);
            match (step, sample) {
                (Some(ts), Some(tm)) if ts <= tm => self.do_step(now),
                (Some(_), None) => self.do_step(now),
                (_, Some(_)) => self.do_sample(now),
                (None, None) => break,
            }
        }
        self.after_motion(now);
        if self.watchdog.check(now) {
            self.on_watchdog(now);
        }
    }

    fn do_step(&mut self, now: u64) {
        let Some(ev) = self.stepper.pop_due(now) else {
            return;
        };
        let reverse = self.config.map(|c| c.reverse).unwrap_or(false);
        let level = (ev.dir > 0) != reverse;
        if self.dir_level != Some(level) {
            let ok = if level {
                self.parts.dir.set_high().is_ok()
            } else {
                self.parts.dir.set_low().is_ok()
            };
            self.pin_fault |= !ok;
            self.dir_level = Some(level);
            self.parts.delay.delay_ns(self.board.dir_setup_ns);
        }
        let high = self.parts.step.set_high().is_ok();
        self.parts.delay.delay_ns(self.board.step_pulse_ns);
        let low = self.parts.step.set_low().is_ok();
        if !(high && low) || self.pin_fault {
            self.pin_fault = true;
            error!("STEP or DIR pin cannot be set; emergency stop");
            self.emergency_stop(now, 0);
        }
        if let Some(c) = self.stepper.take_completion() {
            self.completed(c, ev.at_us.max(now));
        }
    }

    fn after_motion(&mut self, now: u64) {
        if let Some(c) = self.stepper.take_completion() {
            self.completed(c, now);
        }
    }

    fn completed(&mut self, c: Completion, now: u64) {
        let kind = match c {
            Completion::MoveDone => EventKind::MoveDone,
            Completion::Stopped => EventKind::Stopped,
        };
        self.event(kind, 0, now);
        if self.disable_at_rest {
            self.disable_at_rest = false;
            self.set_enable_pin(false);
        }
    }

    fn set_enable_pin(&mut self, on: bool) {
        self.enabled = on;
        let level_high = on != self.board.enable_active_low;
        let ok = if level_high {
            self.parts.enable.set_high().is_ok()
        } else {
            self.parts.enable.set_low().is_ok()
        };
        self.pin_fault |= !ok;
    }

    /// Stop stepping at once, disable the driver and latch; `detail` says why (the event's
    /// [`Event::detail`]: 0 for the command or a pin fault, [`ESTOP_BY_INPUT`]).
    fn emergency_stop(&mut self, now: u64, detail: u8) {
        self.stepper.halt();
        self.set_enable_pin(false);
        self.disable_at_rest = false;
        let was = self.estop;
        self.estop = true;
        if !was {
            self.event(EventKind::EmergencyStop, detail, now);
        }
    }

    fn on_watchdog(&mut self, now: u64) {
        let active = self.enabled || !self.stepper.is_idle() || self.sampler.is_running();
        if !active {
            return;
        }
        self.watchdog_tripped = true;
        warn!("watchdog: no command or heartbeat in time; stopping the motor and the stream");
        if let Some(b) = self.sampler.stop() {
            self.send(Report::Samples(b));
        }
        if self.stepper.is_idle() {
            self.set_enable_pin(false);
        } else {
            self.stepper.stop(now);
            self.disable_at_rest = true;
        }
        self.event(EventKind::WatchdogExpired, 0, now);
    }

    fn do_sample(&mut self, now: u64) {
        let (read_imu, overrun) = self.sampler.begin_sample(now);
        let fields = self.sampler.fields();
        let mut flags = SampleFlags::EMPTY;
        flags.set(SampleFlags::OVERRUN, overrun);
        flags.set(SampleFlags::MOVING, !self.stepper.is_idle());
        flags.set(SampleFlags::ENABLED, self.enabled);
        flags.set(SampleFlags::ESTOP, self.estop);
        if fields.contains(SensorSet::ENCODER_A) {
            match self.encoder_a.raw_angle(&mut self.parts.i2c_a) {
                Ok(v) => {
                    self.last_encoder_a = v;
                    self.mark(SensorSet::ENCODER_A, true, now);
                }
                Err(_) => {
                    flags = flags | SampleFlags::ENCODER_A_FAULT;
                    self.mark(SensorSet::ENCODER_A, false, now);
                }
            }
        }
        if fields.contains(SensorSet::ENCODER_B) {
            match self.encoder_b.raw_angle(&mut self.parts.i2c_b) {
                Ok(v) => {
                    self.last_encoder_b = v;
                    self.mark(SensorSet::ENCODER_B, true, now);
                }
                Err(_) => {
                    flags = flags | SampleFlags::ENCODER_B_FAULT;
                    self.mark(SensorSet::ENCODER_B, false, now);
                }
            }
        }
        if fields.contains(SensorSet::IMU) && read_imu {
            match self.imu.quaternion(&mut self.parts.i2c_a) {
                Ok(q) => {
                    self.last_quaternion = q;
                    flags = flags | SampleFlags::IMU_FRESH;
                    self.mark(SensorSet::IMU, true, now);
                }
                Err(_) => {
                    flags = flags | SampleFlags::IMU_FAULT;
                    self.mark(SensorSet::IMU, false, now);
                }
            }
        }
        let quadrature = if fields.contains(SensorSet::QUADRATURE) {
            self.parts.quadrature.count()
        } else {
            0
        };
        let sample = Sample {
            timestamp_us: now as u32,
            position: self.stepper.position() as i32,
            flags,
            encoder_a: self.last_encoder_a,
            encoder_b: self.last_encoder_b,
            quadrature,
            quaternion: self.last_quaternion,
        };
        if let Some(batch) = self.sampler.finish_sample(sample) {
            self.send(Report::Samples(batch));
        }
    }

    fn mark(&mut self, sensor: SensorSet, ok: bool, now: u64) {
        let was = self.healthy.contains(sensor);
        self.healthy.set(sensor, ok);
        if was && !ok {
            warn!("sensor {=u8:#x} stopped answering", sensor.bits());
            self.event(EventKind::SensorFault, sensor.bits(), now);
        }
    }

    fn event(&mut self, kind: EventKind, detail: u8, now: u64) {
        self.send(Report::Event(Event {
            kind,
            detail,
            timestamp_us: now as u32,
            position: self.stepper.position() as i32,
        }));
    }

    /// Encode and queue a report; a frame that does not fit is dropped (its sequence number
    /// is used anyway, so the host sees the gap).
    fn send(&mut self, report: Report) {
        let mut buf = [0u8; MAX_FRAME_LEN];
        let seq = self.tx_seq;
        self.tx_seq = self.tx_seq.wrapping_add(1);
        let queued = match encode_frame(seq, &report, &mut buf) {
            Ok(n) => self.outbox.push(&buf[..n]),
            Err(_) => false,
        };
        if !queued {
            if let Report::Samples(b) = report {
                if self.samples_dropped == 0 {
                    warn!("output queue full: dropping sample batches (the host does not read)");
                }
                self.samples_dropped = self.samples_dropped.wrapping_add(b.len() as u32);
            }
        }
    }

    fn on_command(&mut self, seq: u16, cmd: Command) {
        let now = self.parts.clock.now_us();
        self.watchdog.feed(now);
        if !matches!(cmd, Command::Hello { .. }) {
            if let Some((last_seq, last_cmd, reply)) = self.last {
                if last_seq == seq && last_cmd == cmd {
                    // A retry of the command just executed: answer again, do not repeat it.
                    self.send(reply);
                    return;
                }
            }
        }
        let reply = self.execute(seq, cmd, now);
        self.last = Some((seq, cmd, reply));
        self.send(reply);
    }

    fn ack(seq: u16, code: AckCode) -> Report {
        Report::Ack { ack: seq, code }
    }

    fn motion_allowed(&self) -> Result<Config, AckCode> {
        if self.estop {
            return Err(AckCode::EStopLatched);
        }
        let Some(c) = self.config else {
            return Err(AckCode::NotConfigured);
        };
        if !self.enabled {
            return Err(AckCode::MotorDisabled);
        }
        Ok(c)
    }

    fn move_to(&mut self, target: i64, now: u64) -> AckCode {
        if target.abs() > MAX_POSITION {
            return AckCode::OutOfRange;
        }
        self.stepper.move_to(target, now);
        self.disable_at_rest = false;
        AckCode::Ok
    }

    fn execute(&mut self, seq: u16, cmd: Command, now: u64) -> Report {
        if !self.version_ok && !matches!(cmd, Command::Hello { .. }) {
            return Self::ack(seq, AckCode::VersionMismatch);
        }
        let code = match cmd {
            Command::Hello { protocol_version } => {
                // A new session: nothing from the previous one keeps running.
                self.sampler.stop();
                self.stepper.stop(now);
                self.version_ok = protocol_version == PROTOCOL_VERSION;
                info!(
                    "hello: host protocol {=u16}, ours {=u16}",
                    protocol_version, PROTOCOL_VERSION
                );
                return Report::Hello(self.info(seq));
            }
            Command::Configure(c) => self.configure(c),
            Command::SetMotorEnabled(true) => {
                if self.estop {
                    AckCode::EStopLatched
                } else {
                    self.set_enable_pin(true);
                    self.disable_at_rest = false;
                    AckCode::Ok
                }
            }
            Command::SetMotorEnabled(false) => {
                self.stepper.halt();
                self.set_enable_pin(false);
                AckCode::Ok
            }
            Command::RunSpeed { speed_mdeg_s } => match self.motion_allowed() {
                Err(code) => code,
                Ok(c) => {
                    let s = mdeg_to_usteps(&c, speed_mdeg_s as i64);
                    if s.unsigned_abs() > self.stepper.limits().max_speed as u64 {
                        AckCode::OutOfRange
                    } else {
                        self.stepper.run(s, now);
                        self.disable_at_rest = false;
                        AckCode::Ok
                    }
                }
            },
            Command::MoveTo { angle_mdeg } => match self.motion_allowed() {
                Err(code) => code,
                Ok(c) => self.move_to(mdeg_to_usteps(&c, angle_mdeg as i64), now),
            },
            Command::MoveBy { delta_mdeg } => match self.motion_allowed() {
                Err(code) => code,
                Ok(c) => {
                    let from = match self.stepper.mode() {
                        mpc_wire::MotionMode::Move => self.stepper.target(),
                        _ => self.stepper.position(),
                    };
                    self.move_to(from + mdeg_to_usteps(&c, delta_mdeg as i64), now)
                }
            },
            Command::Home => match self.motion_allowed() {
                Err(code) => code,
                Ok(_) => self.move_to(0, now),
            },
            Command::Stop => {
                self.stepper.stop(now);
                AckCode::Ok
            }
            Command::EmergencyStop => {
                warn!("emergency stop commanded");
                self.emergency_stop(now, 0);
                AckCode::Ok
            }
            Command::ClearEmergencyStop => {
                if self.pin_fault || self.estop_input {
                    AckCode::EStopLatched
                } else {
                    self.estop = false;
                    AckCode::Ok
                }
            }
            Command::Zero => {
                if self.stepper.set_position(0) {
                    AckCode::Ok
                } else {
                    AckCode::Busy
                }
            }
            Command::Heartbeat => AckCode::Ok,
            Command::QueryStatus => {
                let s = self.status(seq);
                self.watchdog_tripped = false;
                return Report::Status(s);
            }
            Command::StartStream => match self.config {
                None => AckCode::NotConfigured,
                Some(c) => {
                    if !self.sampler.is_running() {
                        self.sampler.start(
                            now,
                            c.sample_rate_hz,
                            c.sensors,
                            c.batch_len,
                            c.imu_every,
                        );
                    }
                    AckCode::Ok
                }
            },
            Command::StopStream => {
                if let Some(b) = self.sampler.stop() {
                    self.send(Report::Samples(b));
                }
                AckCode::Ok
            }
        };
        Self::ack(seq, code)
    }

    fn configure(&mut self, c: Config) -> AckCode {
        if c.validate().is_err() {
            return AckCode::InvalidConfig;
        }
        if !self.capabilities.contains(c.sensors) {
            return AckCode::Unsupported;
        }
        if !self.stepper.is_idle() || self.sampler.is_running() {
            return AckCode::Busy;
        }
        let max_speed = mdeg_to_usteps(&c, c.max_speed_mdeg_s as i64);
        let accel = mdeg_to_usteps(&c, c.max_accel_mdeg_s2 as i64);
        if max_speed <= 0
            || accel <= 0
            || max_speed > self.board.max_step_rate_hz as i64
            || accel > u32::MAX as i64
        {
            return AckCode::InvalidConfig;
        }
        let limits = Limits {
            max_speed: max_speed as u32,
            accel: accel as u32,
        };
        if limits.validate().is_err() || !self.stepper.set_limits(limits) {
            return AckCode::InvalidConfig;
        }
        self.watchdog.set_timeout_ms(c.watchdog_ms);
        self.config = Some(c);
        info!(
            "configured: {=u16} Hz, sensors {=u8:#x}, watchdog {=u16} ms",
            c.sample_rate_hz,
            c.sensors.bits(),
            c.watchdog_ms
        );
        AckCode::Ok
    }

    fn info(&self, seq: u16) -> DeviceInfo {
        DeviceInfo {
            ack: seq,
            protocol_version: PROTOCOL_VERSION,
            firmware_version: FIRMWARE_VERSION,
            board: BoardName::truncated(self.board.name),
            capabilities: Capabilities {
                sensors: self.capabilities,
                max_step_rate_hz: self.board.max_step_rate_hz,
                max_sample_rate_hz: mpc_wire::command::MAX_SAMPLE_RATE_HZ,
                imu_rate_hz: if self.capabilities.contains(SensorSet::IMU) {
                    bno055::FUSION_RATE_HZ
                } else {
                    0
                },
                max_batch: MAX_BATCH as u8,
            },
            clock_hz: self.board.clock_hz,
        }
    }

    /// The present status (as answered to `QueryStatus` with sequence number `ack`).
    pub fn status(&self, ack: u16) -> Status {
        let mut flags = StatusFlags::EMPTY;
        flags.set(StatusFlags::CONFIGURED, self.config.is_some());
        flags.set(StatusFlags::ENABLED, self.enabled);
        flags.set(StatusFlags::MOVING, !self.stepper.is_idle());
        flags.set(StatusFlags::STREAMING, self.sampler.is_running());
        flags.set(StatusFlags::ESTOP_LATCHED, self.estop);
        flags.set(StatusFlags::WATCHDOG_TRIPPED, self.watchdog_tripped);
        flags.set(
            StatusFlags::ENCODER_A_OK,
            self.healthy.contains(SensorSet::ENCODER_A),
        );
        flags.set(
            StatusFlags::ENCODER_B_OK,
            self.healthy.contains(SensorSet::ENCODER_B),
        );
        flags.set(StatusFlags::IMU_OK, self.healthy.contains(SensorSet::IMU));
        Status {
            ack,
            timestamp_us: self.parts.clock.now_us() as u32,
            position: self.stepper.position() as i32,
            speed: self.stepper.speed().clamp(i32::MIN as i64, i32::MAX as i64) as i32,
            target: self.stepper.target() as i32,
            mode: self.stepper.mode(),
            flags,
            rx_errors: self.rx_errors,
            samples_dropped: self.samples_dropped,
        }
    }
}
