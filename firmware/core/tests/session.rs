//! Host tests of the whole device doing what the simulated stepper bench does: a platform
//! made of an injectable clock, pins that count pulses and an I²C bus emulating AS5600 and
//! BNO055 registers; commands go in as wire bytes, reports come out as wire bytes, and time
//! advances event by event.

use std::cell::{Cell, RefCell};
use std::rc::Rc;

use embedded_hal::digital::{ErrorType as PinErrorType, OutputPin};
use embedded_hal::i2c::{self, ErrorKind, I2c, Operation};
use mpc_firmware_core::{BoardConfig, Clock, Device, NoQuadrature, Parts, Platform};
use mpc_wire::{
    encode_frame, AckCode, Command, Config, Decoder, EventKind, Frame, MotionMode, Report,
    SampleFlags, SensorSet, StatusFlags, MAX_FRAME_LEN, PROTOCOL_VERSION,
};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

#[derive(Clone, Default)]
struct SimClock(Rc<Cell<u64>>);
impl Clock for SimClock {
    fn now_us(&self) -> u64 {
        self.0.get()
    }
}

/// A pin recording its level and counting rising edges.
#[derive(Clone, Default)]
struct Pin {
    high: Rc<Cell<bool>>,
    rises: Rc<Cell<u64>>,
}
impl PinErrorType for Pin {
    type Error = core::convert::Infallible;
}
impl OutputPin for Pin {
    fn set_high(&mut self) -> Result<(), Self::Error> {
        if !self.high.get() {
            self.rises.set(self.rises.get() + 1);
        }
        self.high.set(true);
        Ok(())
    }
    fn set_low(&mut self) -> Result<(), Self::Error> {
        self.high.set(false);
        Ok(())
    }
}

/// The STEP pin: counts pulses signed by the DIR pin's level at the rising edge.
#[derive(Clone)]
struct StepPin {
    dir: Pin,
    net: Rc<Cell<i64>>,
    high: Rc<Cell<bool>>,
}
impl PinErrorType for StepPin {
    type Error = core::convert::Infallible;
}
impl OutputPin for StepPin {
    fn set_high(&mut self) -> Result<(), Self::Error> {
        if !self.high.get() {
            let d = if self.dir.high.get() { 1 } else { -1 };
            self.net.set(self.net.get() + d);
        }
        self.high.set(true);
        Ok(())
    }
    fn set_low(&mut self) -> Result<(), Self::Error> {
        self.high.set(false);
        Ok(())
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct BusError;
impl i2c::Error for BusError {
    fn kind(&self) -> ErrorKind {
        ErrorKind::Other
    }
}

/// Register-level emulation of an AS5600 (0x36) and a BNO055 (0x28) on one bus.
#[derive(Clone, Default)]
struct SensorBus {
    angle: Rc<Cell<u16>>,
    fail: Rc<Cell<bool>>,
    quat: Rc<Cell<[i16; 4]>>,
    regs_written: Rc<RefCell<Vec<(u8, u8, u8)>>>,
    reads: Rc<Cell<u64>>,
}
impl i2c::ErrorType for SensorBus {
    type Error = BusError;
}
impl I2c for SensorBus {
    fn transaction(&mut self, addr: u8, ops: &mut [Operation<'_>]) -> Result<(), BusError> {
        if self.fail.get() || (addr != 0x36 && addr != 0x28) {
            return Err(BusError);
        }
        let mut reg = 0u8;
        for op in ops {
            match op {
                Operation::Write(w) => {
                    reg = w[0];
                    if w.len() == 2 {
                        self.regs_written.borrow_mut().push((addr, w[0], w[1]));
                    }
                }
                Operation::Read(buf) => {
                    self.reads.set(self.reads.get() + 1);
                    for (i, b) in buf.iter_mut().enumerate() {
                        *b = self.register(addr, reg.wrapping_add(i as u8));
                    }
                }
            }
        }
        Ok(())
    }
}
impl SensorBus {
    fn register(&self, addr: u8, reg: u8) -> u8 {
        let a = self.angle.get();
        let q = self.quat.get();
        match (addr, reg) {
            (0x36, 0x0B) => 0x20,
            (0x36, 0x0C) => (a >> 8) as u8 & 0x0F,
            (0x36, 0x0D) => a as u8,
            (0x28, 0x00) => 0xA0,
            (0x28, r @ 0x20..=0x27) => {
                let i = ((r - 0x20) / 2) as usize;
                q[i].to_le_bytes()[((r - 0x20) % 2) as usize]
            }
            _ => 0,
        }
    }
}

struct NoDelay;
impl embedded_hal::delay::DelayNs for NoDelay {
    fn delay_ns(&mut self, _: u32) {}
}

struct Sim;
impl Platform for Sim {
    type I2cA = SensorBus;
    type I2cB = SensorBus;
    type Step = StepPin;
    type Dir = Pin;
    type Enable = Pin;
    type Delay = NoDelay;
    type Clock = SimClock;
    type Quadrature = NoQuadrature;
}

/// A bench: the device plus the host's view of it.
struct Bench {
    device: Device<Sim>,
    clock: SimClock,
    net_steps: Rc<Cell<i64>>,
    enable: Pin,
    bus_a: SensorBus,
    decoder: Decoder<Report>,
    reports: Vec<Frame<Report>>,
    seq: u16,
    last_command_us: u64,
}

const SENSORS: SensorSet = SensorSet::ENCODER_A.union(SensorSet::IMU);

impl Bench {
    fn new() -> Self {
        let clock = SimClock::default();
        clock.0.set(5_000);
        let dir = Pin::default();
        let net = Rc::new(Cell::new(0));
        let enable = Pin::default();
        let bus_a = SensorBus::default();
        bus_a.quat.set([16384, 0, 0, 0]);
        let bus_b = SensorBus::default();
        bus_b.fail.set(true);
        let parts = Parts::<Sim> {
            i2c_a: bus_a.clone(),
            i2c_b: bus_b,
            step: StepPin {
                dir: dir.clone(),
                net: net.clone(),
                high: Rc::default(),
            },
            dir,
            enable: enable.clone(),
            delay: NoDelay,
            clock: clock.clone(),
            quadrature: NoQuadrature,
        };
        let board = BoardConfig::new(
            "sim-stepper",
            SensorSet::ENCODER_A | SensorSet::ENCODER_B | SensorSet::IMU,
            50_000,
        );
        let device = Device::new(parts, board);
        Self {
            device,
            clock,
            net_steps: net,
            enable,
            bus_a,
            decoder: Decoder::new(),
            reports: Vec::new(),
            seq: 100,
            last_command_us: 0,
        }
    }

    fn now(&self) -> u64 {
        self.clock.0.get()
    }

    /// Send one command; returns its sequence number.
    fn send(&mut self, cmd: Command) -> u16 {
        let seq = self.seq;
        self.seq = self.seq.wrapping_add(1);
        self.send_with_seq(seq, cmd);
        seq
    }

    fn send_with_seq(&mut self, seq: u16, cmd: Command) {
        let mut buf = [0u8; MAX_FRAME_LEN];
        let n = encode_frame(seq, &cmd, &mut buf).unwrap();
        self.last_command_us = self.now();
        self.device.receive(&buf[..n]);
        self.collect();
    }

    /// Send a command and return its reply.
    fn request(&mut self, cmd: Command) -> Report {
        let seq = self.send(cmd);
        self.reply_to(seq)
            .unwrap_or_else(|| panic!("no reply to {cmd:?}"))
    }

    fn reply_to(&self, seq: u16) -> Option<Report> {
        self.reports
            .iter()
            .rev()
            .find(|f| f.msg.ack() == Some(seq))
            .map(|f| f.msg)
    }

    fn collect(&mut self) {
        let mut out = [0u8; 8192];
        loop {
            let n = self.device.transmit(&mut out);
            if n == 0 {
                break;
            }
            let reports = &mut self.reports;
            self.decoder.feed(&out[..n], |r| {
                reports.push(r.expect("device frames are valid"))
            });
        }
    }

    /// Advance simulated time to `until`, event by event, sending a heartbeat every
    /// `heartbeat_us` (0: never).
    fn run_until(&mut self, until: u64, heartbeat_us: u64) {
        let mut next_hb = if heartbeat_us > 0 {
            self.now() + heartbeat_us
        } else {
            u64::MAX
        };
        loop {
            let dev = self.device.next_deadline_us().unwrap_or(u64::MAX);
            let t = dev.min(next_hb).min(until);
            if t > self.now() {
                self.clock.0.set(t);
            }
            if t == next_hb {
                self.send(Command::Heartbeat);
                next_hb += heartbeat_us;
            }
            self.device.poll();
            self.collect();
            if t >= until {
                break;
            }
        }
    }

    fn configure(&mut self, config: Config) {
        assert_eq!(
            self.request(Command::Configure(config)),
            Report::Ack {
                ack: self.seq - 1,
                code: AckCode::Ok
            }
        );
    }

    fn events(&self, kind: EventKind) -> Vec<mpc_wire::Event> {
        self.reports
            .iter()
            .filter_map(|f| match f.msg {
                Report::Event(e) if e.kind == kind => Some(e),
                _ => None,
            })
            .collect()
    }

    fn samples(&self) -> Vec<(u16, mpc_wire::Sample)> {
        self.reports
            .iter()
            .filter_map(|f| match &f.msg {
                Report::Samples(b) => {
                    Some(b.samples().iter().map(|s| (f.seq, *s)).collect::<Vec<_>>())
                }
                _ => None,
            })
            .flatten()
            .collect()
    }
}

fn config() -> Config {
    Config {
        sensors: SENSORS,
        ..Config::default()
    }
}

fn ack_code(r: Report) -> AckCode {
    match r {
        Report::Ack { code, .. } => code,
        other => panic!("not an ack: {other:?}"),
    }
}

/// Guards boot safety and the handshake: the motor is disabled at boot (EN high, active
/// low), a Boot event is sent, and Hello answers with version, board, the sensors that
/// answered (B's bus is dead, so it is missing) and the clock rate.
#[test]
fn boot_is_safe_and_handshake_reports_capabilities() {
    let mut b = Bench::new();
    assert!(
        b.enable.high.get(),
        "EN must be high (driver disabled) at boot"
    );
    assert!(!b.device.is_enabled());
    b.collect();
    assert!(!b.events(EventKind::Boot).is_empty());
    // The IMU was put in NDOF mode at boot.
    assert!(b.bus_a.regs_written.borrow().contains(&(0x28, 0x3D, 0x0C)));
    match b.request(Command::Hello {
        protocol_version: PROTOCOL_VERSION,
    }) {
        Report::Hello(info) => {
            assert_eq!(info.protocol_version, PROTOCOL_VERSION);
            assert_eq!(info.board.as_str(), "sim-stepper");
            assert_eq!(info.capabilities.sensors, SENSORS);
            assert_eq!(info.capabilities.max_step_rate_hz, 50_000);
            assert_eq!(info.capabilities.imu_rate_hz, 100);
            assert_eq!(info.clock_hz, 1_000_000);
            assert_eq!(info.firmware_version, mpc_firmware_core::FIRMWARE_VERSION);
        }
        other => panic!("{other:?}"),
    }
    // Encoder B is not a capability: configuring it is refused.
    let bad = Config {
        sensors: SensorSet::ENCODER_B,
        ..Config::default()
    };
    assert_eq!(
        ack_code(b.request(Command::Configure(bad))),
        AckCode::Unsupported
    );
}

/// Guards the version check: after a Hello with another version every command is refused
/// until a matching Hello.
#[test]
fn version_mismatch_refuses_commands_until_matching_hello() {
    let mut b = Bench::new();
    b.request(Command::Hello {
        protocol_version: PROTOCOL_VERSION + 1,
    });
    assert_eq!(
        ack_code(b.request(Command::Heartbeat)),
        AckCode::VersionMismatch
    );
    b.request(Command::Hello {
        protocol_version: PROTOCOL_VERSION,
    });
    assert_eq!(ack_code(b.request(Command::Heartbeat)), AckCode::Ok);
}

/// Guards the order of preconditions for motion: configure, then enable.
#[test]
fn motion_needs_configuration_and_enable() {
    let mut b = Bench::new();
    let run = Command::RunSpeed { speed_mdeg_s: 1000 };
    assert_eq!(ack_code(b.request(run)), AckCode::NotConfigured);
    b.configure(config());
    assert_eq!(ack_code(b.request(run)), AckCode::MotorDisabled);
    assert_eq!(
        ack_code(b.request(Command::SetMotorEnabled(true))),
        AckCode::Ok
    );
    assert!(!b.enable.high.get(), "EN low = enabled");
    assert_eq!(ack_code(b.request(run)), AckCode::Ok);
    let too_fast = Command::RunSpeed {
        speed_mdeg_s: 360_001 + 180,
    };
    assert_eq!(ack_code(b.request(too_fast)), AckCode::OutOfRange);
    let invalid = Config {
        microsteps: 3,
        ..config()
    };
    assert_eq!(
        ack_code(b.request(Command::Configure(invalid))),
        AckCode::InvalidConfig
    );
    assert_eq!(
        ack_code(b.request(Command::Configure(config()))),
        AckCode::Busy
    );
}

/// Guards exact step counts in a constant-speed run over simulated time, counted on the
/// STEP pin: 0.5 rev/s = 1600 µsteps/s gives exactly 3200 pulses in 2 s of cruise, the
/// device's position equals the pulse count, and Stop decelerates to rest.
#[test]
fn constant_speed_run_has_exact_step_counts() {
    let mut b = Bench::new();
    b.configure(config());
    b.request(Command::SetMotorEnabled(true));
    b.request(Command::RunSpeed {
        speed_mdeg_s: 180_000,
    });
    b.run_until(1_000_000, 100_000);
    let before = b.net_steps.get();
    b.run_until(3_000_000, 100_000);
    assert_eq!(b.net_steps.get() - before, 3200);
    assert_eq!(b.device.position(), b.net_steps.get());
    match b.request(Command::QueryStatus) {
        Report::Status(s) => {
            assert_eq!(s.speed, 1600);
            assert_eq!(s.mode, MotionMode::Run);
            assert!(s.flags.contains(StatusFlags::MOVING | StatusFlags::ENABLED));
        }
        other => panic!("{other:?}"),
    }
    b.request(Command::Stop);
    b.run_until(4_000_000, 100_000);
    assert!(!b.device.is_moving());
    assert_eq!(b.events(EventKind::Stopped).len(), 1);
    assert_eq!(b.device.position(), b.net_steps.get());
}

/// Guards trapezoidal moves ending exactly on target: MoveTo 90° = 800 µsteps, then MoveBy
/// −450° = −4000 µsteps, each ending with a MoveDone event at the exact position, the DIR
/// pin reversing only between moves.
#[test]
fn trapezoidal_moves_end_exactly_on_target() {
    let mut b = Bench::new();
    b.configure(config());
    b.request(Command::SetMotorEnabled(true));
    b.request(Command::MoveTo { angle_mdeg: 90_000 });
    b.run_until(3_000_000, 100_000);
    assert_eq!(b.device.position(), 800);
    assert_eq!(b.net_steps.get(), 800);
    b.request(Command::MoveBy {
        delta_mdeg: -450_000,
    });
    b.run_until(8_000_000, 100_000);
    assert_eq!(b.device.position(), -3200);
    assert_eq!(b.net_steps.get(), -3200);
    let done = b.events(EventKind::MoveDone);
    assert_eq!(done.len(), 2);
    assert_eq!((done[0].position, done[1].position), (800, -3200));
    b.request(Command::Home);
    b.run_until(12_000_000, 100_000);
    assert_eq!((b.device.position(), b.net_steps.get()), (0, 0));
}

/// Guards the e-stop input: asserting it stops the steps and disables the driver at once,
/// latches the stop with an event saying it came from the input, and `ClearEmergencyStop`
/// is refused while the input stays asserted and accepted once it is released.
#[test]
fn estop_input_latches_and_holds_while_asserted() {
    let mut b = Bench::new();
    b.configure(config());
    b.request(Command::SetMotorEnabled(true));
    b.request(Command::RunSpeed {
        speed_mdeg_s: 360_000,
    });
    b.run_until(300_000, 100_000);
    let at_stop = b.net_steps.get();
    assert!(at_stop > 0);
    b.device.set_estop_input(true);
    assert!(b.enable.high.get(), "driver disabled");
    b.run_until(600_000, 100_000);
    assert_eq!(b.net_steps.get(), at_stop, "no step after the e-stop input");
    let events = b.events(EventKind::EmergencyStop);
    assert_eq!(events.len(), 1);
    assert_eq!(events[0].detail, mpc_wire::ESTOP_BY_INPUT);
    assert_eq!(
        ack_code(b.request(Command::ClearEmergencyStop)),
        AckCode::EStopLatched,
        "cleared while the input is asserted"
    );
    b.device.set_estop_input(false);
    assert!(
        b.device.estop_latched(),
        "releasing the input does not clear the stop"
    );
    assert_eq!(
        ack_code(b.request(Command::ClearEmergencyStop)),
        AckCode::Ok
    );
    assert!(!b.device.is_enabled());
}

/// Guards the latched emergency stop: steps cease at once, the driver is disabled, motion
/// and enable are refused until cleared, and clearing does not re-enable the motor.
#[test]
fn emergency_stop_latches_until_cleared() {
    let mut b = Bench::new();
    b.configure(config());
    b.request(Command::SetMotorEnabled(true));
    b.request(Command::RunSpeed {
        speed_mdeg_s: 360_000,
    });
    b.run_until(500_000, 100_000);
    let at_stop = b.net_steps.get();
    assert!(at_stop > 0);
    assert_eq!(ack_code(b.request(Command::EmergencyStop)), AckCode::Ok);
    assert!(b.enable.high.get(), "driver disabled");
    b.run_until(1_000_000, 100_000);
    assert_eq!(
        b.net_steps.get(),
        at_stop,
        "no step after the emergency stop"
    );
    assert_eq!(b.events(EventKind::EmergencyStop).len(), 1);
    for cmd in [
        Command::SetMotorEnabled(true),
        Command::RunSpeed { speed_mdeg_s: 1000 },
        Command::MoveBy { delta_mdeg: 1000 },
        Command::Home,
    ] {
        assert_eq!(ack_code(b.request(cmd)), AckCode::EStopLatched, "{cmd:?}");
    }
    match b.request(Command::QueryStatus) {
        Report::Status(s) => assert!(s.flags.contains(StatusFlags::ESTOP_LATCHED)),
        other => panic!("{other:?}"),
    }
    assert_eq!(
        ack_code(b.request(Command::ClearEmergencyStop)),
        AckCode::Ok
    );
    assert!(!b.device.is_enabled());
    assert_eq!(
        ack_code(b.request(Command::SetMotorEnabled(true))),
        AckCode::Ok
    );
    assert_eq!(
        ack_code(b.request(Command::RunSpeed { speed_mdeg_s: 1000 })),
        AckCode::Ok
    );
}

/// Guards the dead-man watchdog: with heartbeats stopping at 1 s, the device decelerates
/// to rest, disables the driver, stops the stream and reports WatchdogExpired once, about
/// 250 ms after the last command.
#[test]
fn watchdog_stops_motor_and_stream_when_host_goes_quiet() {
    let mut b = Bench::new();
    b.configure(config());
    b.request(Command::SetMotorEnabled(true));
    b.request(Command::StartStream);
    b.request(Command::RunSpeed {
        speed_mdeg_s: 360_000,
    });
    b.run_until(1_000_000, 100_000);
    let last_cmd = b.last_command_us;
    b.run_until(3_000_000, 0);
    let wd = b.events(EventKind::WatchdogExpired);
    assert_eq!(wd.len(), 1);
    assert_eq!(wd[0].timestamp_us as u64, last_cmd + 250_000);
    assert!(!b.device.is_moving());
    assert!(!b.device.is_streaming());
    assert!(
        b.enable.high.get(),
        "driver disabled after the watchdog stop"
    );
    assert_eq!(b.events(EventKind::Stopped).len(), 1);
    assert_eq!(b.device.position(), b.net_steps.get());
    let last_sample = b.samples().last().unwrap().1.timestamp_us as u64;
    assert!(last_sample <= last_cmd + 250_000);
    match b.request(Command::QueryStatus) {
        Report::Status(s) => assert!(s.flags.contains(StatusFlags::WATCHDOG_TRIPPED)),
        other => panic!("{other:?}"),
    }
}

/// Guards the sample stream: 1 kHz in batches of 10, frames with consecutive sequence
/// numbers, timestamps exactly 1000 µs apart, encoder readings from the emulated AS5600,
/// the IMU read on every 10th sample and repeated (not fresh) in between, positions that
/// follow the STEP pulses, and StopStream flushing the partial batch.
#[test]
fn stream_batches_samples_with_sequence_numbers() {
    let mut b = Bench::new();
    b.configure(config());
    b.request(Command::SetMotorEnabled(true));
    b.bus_a.angle.set(1234);
    b.bus_a.quat.set([11585, 0, 0, 11585]);
    b.request(Command::StartStream);
    b.request(Command::RunSpeed {
        speed_mdeg_s: 360_000,
    });
    b.run_until(b.now() + 1_004_500, 100_000);
    b.request(Command::StopStream);
    let samples = b.samples();
    assert_eq!(samples.len(), 1005);
    let seqs: Vec<u16> = b
        .reports
        .iter()
        .filter(|f| matches!(f.msg, Report::Samples(_)))
        .map(|f| f.seq)
        .collect();
    assert_eq!(seqs.len(), 101, "100 full batches and one partial");
    // Every device frame is numbered consecutively (no gap in any report).
    let all: Vec<u16> = b.reports.iter().map(|f| f.seq).collect();
    assert!(
        all.windows(2).all(|w| w[1] == w[0].wrapping_add(1)),
        "{all:?}"
    );
    for w in samples.windows(2) {
        assert_eq!(w[1].1.timestamp_us - w[0].1.timestamp_us, 1000);
        assert!(w[1].1.position >= w[0].1.position);
    }
    for (i, (_, s)) in samples.iter().enumerate() {
        assert_eq!(s.encoder_a, 1234);
        assert_eq!(s.quaternion, [11585, 0, 0, 11585]);
        assert_eq!(
            s.flags.contains(SampleFlags::IMU_FRESH),
            i % 10 == 0,
            "sample {i}"
        );
        assert!(!s.flags.contains(SampleFlags::ENCODER_A_FAULT));
    }
    assert!(samples.last().unwrap().1.position > 2000);
}

/// Guards sensor faults: a dead bus flags the samples, repeats the last good reading and
/// reports one SensorFault event; the stream goes on.
#[test]
fn sensor_fault_is_flagged_and_reported_once() {
    let mut b = Bench::new();
    b.configure(config());
    b.bus_a.angle.set(77);
    b.request(Command::StartStream);
    b.run_until(b.now() + 20_000, 0);
    b.bus_a.fail.set(true);
    b.run_until(b.now() + 50_000, 0);
    let faults = b.events(EventKind::SensorFault);
    assert_eq!(faults.len(), 2, "encoder A and IMU each once: {faults:?}");
    let s = b.samples();
    let last = s.last().unwrap().1;
    assert!(last.flags.contains(SampleFlags::ENCODER_A_FAULT));
    assert_eq!(last.encoder_a, 77);
}

/// Guards retries: a command re-sent with the same sequence number is answered again but
/// executed once (a MoveBy would otherwise move twice).
#[test]
fn retried_command_is_executed_once() {
    let mut b = Bench::new();
    b.configure(config());
    b.request(Command::SetMotorEnabled(true));
    let cmd = Command::MoveBy { delta_mdeg: 36_000 };
    b.send_with_seq(500, cmd);
    b.send_with_seq(500, cmd);
    let acks = b
        .reports
        .iter()
        .filter(|f| f.msg.ack() == Some(500))
        .count();
    assert_eq!(acks, 2);
    b.run_until(2_000_000, 100_000);
    assert_eq!(b.device.position(), 320);
}

/// Guards robustness of the receive path: garbage between commands is counted as receive
/// errors and never stops the next command from executing.
#[test]
fn garbage_on_the_line_is_counted_and_survived() {
    let mut b = Bench::new();
    b.device
        .receive(&[0x55, 0x13, 0x00, 0xFF, 0xFE, 0x00, 0x00]);
    match b.request(Command::QueryStatus) {
        Report::Status(s) => assert_eq!(s.rx_errors, 2),
        other => panic!("{other:?}"),
    }
}

/// One seeded random session: random commands (valid and not), garbage and time jumps.
/// Returns every frame the device sent and its final position.
fn random_session(seed: u64) -> (Vec<Frame<Report>>, i64) {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut b = Bench::new();
    b.configure(config());
    for _ in 0..300 {
        let cmd = match rng.random_range(0..10) {
            0 => Command::SetMotorEnabled(rng.random_bool(0.8)),
            1 => Command::RunSpeed {
                speed_mdeg_s: rng.random_range(-400_000..400_000),
            },
            2 => Command::MoveTo {
                angle_mdeg: rng.random_range(-720_000..720_000),
            },
            3 => Command::MoveBy {
                delta_mdeg: rng.random_range(-90_000..90_000),
            },
            4 => Command::Stop,
            5 => Command::StartStream,
            6 => Command::StopStream,
            7 => {
                if rng.random_bool(0.1) {
                    Command::EmergencyStop
                } else {
                    Command::ClearEmergencyStop
                }
            }
            8 => Command::QueryStatus,
            _ => Command::Heartbeat,
        };
        b.send(cmd);
        if rng.random_bool(0.1) {
            let junk: Vec<u8> = (0..rng.random_range(1..40)).map(|_| rng.random()).collect();
            b.device.receive(&junk);
            b.device.receive(&[0]);
        }
        let dt = rng.random_range(0..200_000);
        b.run_until(b.now() + dt, 0);
        assert_eq!(
            b.device.position(),
            b.net_steps.get(),
            "position follows the pins"
        );
    }
    (b.reports, b.device.position())
}

/// Guards determinism and robustness under random sessions: the same seed gives the same
/// frames on the wire, position always equals the pulses on the pins, and nothing panics.
#[test]
fn random_sessions_are_deterministic_and_consistent() {
    for seed in [1u64, 2, 3] {
        let a = random_session(seed);
        let b = random_session(seed);
        assert_eq!(a, b, "seed {seed}");
    }
}

/// Guards the device side of the golden frames in `data/wire/`: the stored command frames,
/// fed to the device as raw bytes, are decoded and executed (each answered with its golden
/// sequence number and `Ok`), and the motor turns the way `cmd_run_speed_negative` says.
#[test]
fn golden_command_frames_drive_the_device() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../data/wire");
    let frame = |name: &str| std::fs::read(dir.join(format!("{name}.bin"))).unwrap();
    let mut b = Bench::new();
    b.device.receive(&frame("cmd_hello"));
    b.collect();
    assert!(matches!(b.reply_to(0), Some(Report::Hello(_))));
    for (name, seq) in [
        ("cmd_configure_default", 1),
        ("cmd_set_motor_enabled", 2),
        ("cmd_run_speed_negative", 3),
    ] {
        b.device.receive(&frame(name));
        b.collect();
        assert_eq!(
            b.reply_to(seq),
            Some(Report::Ack {
                ack: seq,
                code: AckCode::Ok
            }),
            "{name}"
        );
    }
    b.run_until(b.now() + 200_000, 50_000);
    assert!(b.device.position() < 0, "RunSpeed −180°/s turns backwards");
    b.device.receive(&frame("cmd_emergency_stop"));
    b.collect();
    assert_eq!(
        b.reply_to(0xFFFF),
        Some(Report::Ack {
            ack: 0xFFFF,
            code: AckCode::Ok
        })
    );
    assert!(b.device.estop_latched());
    b.device.receive(&frame("cmd_move_to"));
    b.collect();
    assert_eq!(
        b.reply_to(4),
        Some(Report::Ack {
            ack: 4,
            code: AckCode::EStopLatched
        })
    );
}

/// Guards the session start: a Hello from a new host stops the stream and decelerates the
/// motion left running by a previous session.
#[test]
fn hello_stops_what_a_previous_session_left_running() {
    let mut b = Bench::new();
    b.configure(config());
    b.request(Command::SetMotorEnabled(true));
    b.request(Command::StartStream);
    b.request(Command::RunSpeed {
        speed_mdeg_s: 360_000,
    });
    b.run_until(1_000_000, 100_000);
    assert!(b.device.is_streaming() && b.device.is_moving());
    b.request(Command::Hello {
        protocol_version: PROTOCOL_VERSION,
    });
    assert!(!b.device.is_streaming());
    b.run_until(2_000_000, 100_000);
    assert!(!b.device.is_moving());
    assert_eq!(b.events(EventKind::Stopped).len(), 1);
    assert_eq!(b.device.position(), b.net_steps.get());
}
