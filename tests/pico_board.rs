//! The board image itself, run in the rp2040js emulator (`sim-device pico`), checked for the
//! bugs that only show on a board: pins and I²C buses assigned other than the bench is
//! wired, the USB serial number, the dead-man watchdog when the host goes silent, the e-stop
//! input, and a sensor missing at boot. The host speaks the wire protocol directly over the
//! pseudo-terminal, and the bench's side (steps counted at the driver, the e-stop button) is
//! read from the emulated board's status.
//!
//! Needs the release image (`cd firmware/rp2040 && cargo build --release`), the boot ROM
//! (`cd firmware/emu/rom && cargo build --release`), Node.js and `npm ci` in firmware/emu;
//! without them every test says what is missing and passes without running, unless
//! `MPC_PICO_REQUIRED` is set, as in CI's emulated-board step, which builds them first. Each
//! test holds the serial group (`support/serial_group.rs`), so the boards run one at a time
//! and beside no other real-time or CPU-heavy test: each needs most of a core to keep pace
//! with the wall clock.

use std::path::Path;
use std::time::{Duration, Instant};

use crate::support::serial_group;
use mpc_rig::motion::Motion;
use mpc_rig::rig::sim::pico::{self, BoardFiles, PicoHandle, PicoStatus, SimPicoOptions};
use mpc_rig::rig::sim::plant::PlantConfig;
use mpc_rig::rig::sim::stepper::Mechanics;
use mpc_wire::{
    encode_frame_vec, AckCode, Command, Config, Decoder, Event, EventKind, Report, Sample,
    SensorSet, ESTOP_BY_INPUT, PROTOCOL_VERSION,
};

/// Longest wait for a reply, wall clock: generous, the emulator may run behind real time
/// on a loaded machine.
const REPLY_WAIT: Duration = Duration::from_secs(5);

fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

fn motion() -> Motion {
    Motion::from_file(&root().join("data/motions/half-turn-2to1.toml")).unwrap()
}

/// Set (to anything) where the emulated board must run: a missing file then fails the
/// test instead of skipping it (CI's emulated-board step sets it).
const REQUIRED: &str = "MPC_PICO_REQUIRED";

/// The checkout's board files, or `None` (with the reason printed) when they are missing.
fn files() -> Option<BoardFiles> {
    let files = BoardFiles::in_repo(root());
    let missing = match files.check() {
        Err(e) => e.to_string(),
        Ok(()) => match std::process::Command::new(&files.node)
            .arg("--version")
            .output()
        {
            Err(_) => "Node.js (`node`) is not on the PATH".to_string(),
            Ok(_) => return Some(files),
        },
    };
    assert!(
        std::env::var_os(REQUIRED).is_none(),
        "{REQUIRED} is set but the emulated board cannot run: {missing}"
    );
    eprintln!("SKIPPED (emulated board): {missing}");
    None
}

fn board(files: BoardFiles, mechanics: Mechanics, flash_id: u64) -> PicoHandle {
    pico::spawn(SimPicoOptions {
        target: motion(),
        plant: PlantConfig::default(),
        mechanics,
        files,
        flash_id,
        link: None,
        defmt_log: None,
        capture: None,
    })
    .unwrap()
}

/// Every sensor of the Pico bench fitted: AS5600 on both buses, the BNO055 on bus A.
fn all_sensors() -> Mechanics {
    Mechanics {
        as5600_b: true,
        imu: true,
        ..Mechanics::default()
    }
}

/// Encoder A at 1 kHz with a 2 s watchdog, for the tests that are not about the watchdog:
/// on a heavily loaded machine the test's own thread can stall for longer than the
/// default 250 ms, which the board rightly takes for a silent host.
fn patient() -> Config {
    Config {
        watchdog_ms: 2_000,
        ..Config::default()
    }
}

/// The host side: wire frames over the board's serial port.
struct Host {
    port: Box<dyn serialport::SerialPort>,
    decoder: Decoder<Report>,
    seq: u16,
    events: Vec<Event>,
    samples: Vec<Sample>,
}

impl Host {
    fn open(path: &Path) -> Host {
        let port = serialport::new(path.to_string_lossy(), 115_200)
            .timeout(Duration::from_millis(10))
            .open()
            .unwrap();
        let mut h = Host {
            port,
            decoder: Decoder::new(),
            seq: 0,
            events: Vec::new(),
            samples: Vec::new(),
        };
        h.port.write_all(&[0]).unwrap();
        h
    }

    /// Read for `d`, keeping events and samples; returns the replies seen.
    fn pump(&mut self, d: Duration) -> Vec<Report> {
        let end = Instant::now() + d;
        let mut replies = Vec::new();
        let mut buf = [0u8; 1024];
        while Instant::now() < end {
            let n = match self.port.read(&mut buf) {
                Ok(n) => n,
                Err(e) if e.kind() == std::io::ErrorKind::TimedOut => 0,
                Err(e) => panic!("reading the board's port: {e}"),
            };
            let (events, samples) = (&mut self.events, &mut self.samples);
            self.decoder.feed(&buf[..n], |r| match r.map(|f| f.msg) {
                Ok(Report::Event(e)) => events.push(e),
                Ok(Report::Samples(b)) => samples.extend_from_slice(b.samples()),
                Ok(other) => replies.push(other),
                Err(e) => panic!("damaged frame from the board: {e}"),
            });
        }
        replies
    }

    /// Send a command and wait for its reply.
    fn request(&mut self, cmd: Command) -> Report {
        let seq = self.seq;
        self.seq = self.seq.wrapping_add(1);
        self.port
            .write_all(&encode_frame_vec(seq, &cmd).unwrap())
            .unwrap();
        let end = Instant::now() + REPLY_WAIT;
        while Instant::now() < end {
            if let Some(r) = self
                .pump(Duration::from_millis(20))
                .into_iter()
                .find(|r| r.ack() == Some(seq))
            {
                return r;
            }
        }
        panic!("no reply to {cmd:?} within {REPLY_WAIT:?}");
    }

    fn ack(&mut self, cmd: Command) -> AckCode {
        match self.request(cmd) {
            Report::Ack { code, .. } => code,
            other => panic!("{cmd:?} answered {other:?}"),
        }
    }

    fn hello(&mut self) -> mpc_wire::DeviceInfo {
        match self.request(Command::Hello {
            protocol_version: PROTOCOL_VERSION,
        }) {
            Report::Hello(info) => info,
            other => panic!("Hello answered {other:?}"),
        }
    }

    /// Keep the watchdog fed for `d`.
    fn heartbeats(&mut self, d: Duration) {
        let end = Instant::now() + d;
        while Instant::now() < end {
            assert_eq!(self.ack(Command::Heartbeat), AckCode::Ok);
            self.pump(Duration::from_millis(50));
        }
    }

    /// Wait for an event, keeping the watchdog fed or not.
    fn wait_event(&mut self, kind: EventKind, within: Duration, feed: bool) -> Event {
        let end = Instant::now() + within;
        loop {
            if let Some(e) = self.events.iter().find(|e| e.kind == kind) {
                return *e;
            }
            assert!(
                Instant::now() < end,
                "no {kind:?} event within {within:?}; events: {:?}",
                self.events
            );
            if feed {
                self.heartbeats(Duration::from_millis(50));
            } else {
                self.pump(Duration::from_millis(20));
            }
        }
    }
}

/// The board's status once its simulated time has passed `t_s` (it may lag the wall clock;
/// the status is published at the end of each 1 ms slice).
fn status_after(board: &PicoHandle, t_s: f64) -> PicoStatus {
    let end = Instant::now() + REPLY_WAIT;
    loop {
        let s = board.status();
        if s.time_s >= t_s || Instant::now() > end {
            return s;
        }
        std::thread::sleep(Duration::from_millis(10));
    }
}

/// Guards the board's wiring and identity: every fitted sensor answers on the bus it is
/// wired to (a bus assigned to other pins, or to the wrong controller's pins, loses its
/// sensors from the capabilities), the USB serial number is the flash's unique ID in hex,
/// and a 90° move puts exactly 800 microsteps, positive, on the driver's STEP/DIR inputs
/// with EN active, after which the AS5600 on bus A reads the follower where the target law
/// puts it (a wrong STEP, DIR or EN pin moves nothing, the wrong way, or disabled).
#[test]
fn sensors_pins_and_serial_number_as_wired() {
    let _serial = serial_group::alone();
    let Some(files) = files() else { return };
    let b = board(files, all_sensors(), 0x0123_4567_89ab_cdef);
    let mut host = Host::open(b.path());
    let info = host.hello();
    assert_eq!(info.board.as_str(), "rp2040-pico");
    assert_eq!(
        info.capabilities.sensors,
        SensorSet::ENCODER_A | SensorSet::ENCODER_B | SensorSet::IMU | SensorSet::QUADRATURE,
        "sensors answering at boot"
    );
    let usb = b.status().usb.expect("the board enumerated");
    assert_eq!(usb.serial.as_deref(), Some("0123456789ABCDEF"));
    assert_eq!((usb.vid, usb.pid), (0x2e8a, 0x000a));

    assert_eq!(host.ack(Command::Configure(patient())), AckCode::Ok);
    assert_eq!(host.ack(Command::SetMotorEnabled(true)), AckCode::Ok);
    assert_eq!(host.ack(Command::StartStream), AckCode::Ok);
    assert_eq!(
        host.ack(Command::MoveTo { angle_mdeg: 90_000 }),
        AckCode::Ok
    );
    host.wait_event(EventKind::MoveDone, REPLY_WAIT, true);
    host.pump(Duration::from_millis(100));
    let s = b.status();
    assert_eq!(s.steps, 800, "microsteps at the driver: {s:?}");
    assert!(s.enabled, "EN active while enabled: {s:?}");
    // After the move the follower rests at the target law's angle for a quarter period.
    let expected = motion().angle_z(0.25).unwrap()[0] / std::f64::consts::TAU * 4096.0;
    let expected = expected.round().rem_euclid(4096.0) as i64;
    let last = host.samples.last().expect("samples streamed");
    assert_eq!(last.position, 800);
    assert!(
        (i64::from(last.encoder_a) - expected).abs() <= 1,
        "AS5600 A reads {} counts, the plant is at {expected}",
        last.encoder_a
    );
    assert_eq!(host.ack(Command::SetMotorEnabled(false)), AckCode::Ok);
    let s = status_after(&b, b.status().time_s + 0.005);
    assert!(!s.enabled, "EN inactive after disabling: {s:?}");
    let s = b.stop().unwrap();
    assert!(s.i2c_transfers[1] > 0, "bus B was probed: {s:?}");
}

/// Guards the dead-man watchdog on the board: with the motor running and heartbeats
/// stopping, the board reports WatchdogExpired about `watchdog_ms` after the last command
/// (device clock), disables the driver at its EN input, and no step follows.
#[test]
fn watchdog_stops_the_motor_when_the_host_goes_silent() {
    let _serial = serial_group::alone();
    let Some(files) = files() else { return };
    let b = board(files, Mechanics::default(), pico::DEFAULT_FLASH_ID);
    let mut host = Host::open(b.path());
    host.hello();
    assert_eq!(host.ack(Command::Configure(Config::default())), AckCode::Ok);
    assert_eq!(host.ack(Command::SetMotorEnabled(true)), AckCode::Ok);
    assert_eq!(
        host.ack(Command::RunSpeed {
            speed_mdeg_s: 180_000
        }),
        AckCode::Ok
    );
    host.heartbeats(Duration::from_millis(600));
    // The last command; its answer carries the device time it arrived at.
    let Report::Status(last) = host.request(Command::QueryStatus) else {
        panic!("QueryStatus not answered with a status");
    };
    assert!(b.status().enabled);
    let e = host.wait_event(EventKind::WatchdogExpired, Duration::from_secs(3), false);
    let silent_s = f64::from(e.timestamp_us.wrapping_sub(last.timestamp_us)) / 1e6;
    assert!(
        (0.249..0.26).contains(&silent_s),
        "watchdog fired {silent_s:.4} s after the last command (250 ms watchdog)"
    );
    // Decelerating to rest takes at most max speed / accel = 0.25 s.
    let after = status_after(&b, f64::from(e.timestamp_us) / 1e6 + 0.4);
    assert!(!after.enabled, "driver still enabled: {after:?}");
    let later = status_after(&b, after.time_s + 0.3);
    assert_eq!(later.steps, after.steps, "steps after the watchdog stop");
}

/// Guards the e-stop input: pressing the button stops the steps and disables the driver
/// at once, the board says the stop came from the input, the stop cannot be cleared while
/// the button is pressed and can be after it is released (the motor staying disabled).
#[test]
fn estop_input_stops_and_latches() {
    let _serial = serial_group::alone();
    let Some(files) = files() else { return };
    let b = board(files, Mechanics::default(), pico::DEFAULT_FLASH_ID);
    let mut host = Host::open(b.path());
    host.hello();
    assert_eq!(host.ack(Command::Configure(patient())), AckCode::Ok);
    assert_eq!(host.ack(Command::SetMotorEnabled(true)), AckCode::Ok);
    assert_eq!(
        host.ack(Command::RunSpeed {
            speed_mdeg_s: 180_000
        }),
        AckCode::Ok
    );
    host.heartbeats(Duration::from_millis(300));
    b.set_estop(true);
    let e = host.wait_event(EventKind::EmergencyStop, REPLY_WAIT, true);
    assert_eq!(e.detail, ESTOP_BY_INPUT);
    let stopped = status_after(&b, f64::from(e.timestamp_us) / 1e6 + 0.01);
    assert!(
        !stopped.enabled,
        "driver enabled after the e-stop: {stopped:?}"
    );
    host.heartbeats(Duration::from_millis(200));
    assert_eq!(b.status().steps, stopped.steps, "steps after the e-stop");
    assert_eq!(
        host.ack(Command::ClearEmergencyStop),
        AckCode::EStopLatched,
        "cleared while the button is pressed"
    );
    b.set_estop(false);
    // The release reaches the pin within a slice of board time; the clear must come after.
    status_after(&b, b.status().time_s + 0.01);
    assert_eq!(host.ack(Command::ClearEmergencyStop), AckCode::Ok);
    assert!(!b.status().enabled);
}

/// Guards a board whose sensors are missing at boot (none answers on either bus): it still
/// boots and answers (an I²C address NACK must not hang it), announces none of them, and
/// refuses a configuration that asks for one.
#[test]
fn missing_sensors_at_boot_are_not_capabilities() {
    let _serial = serial_group::alone();
    let Some(files) = files() else { return };
    let none = Mechanics {
        as5600: false,
        ..Mechanics::default()
    };
    let b = board(files, none, pico::DEFAULT_FLASH_ID);
    let mut host = Host::open(b.path());
    let info = host.hello();
    assert_eq!(info.capabilities.sensors, SensorSet::QUADRATURE);
    assert_eq!(
        host.ack(Command::Configure(Config::default())),
        AckCode::Unsupported
    );
    let quadrature_only = Config {
        sensors: SensorSet::QUADRATURE,
        ..Config::default()
    };
    assert_eq!(host.ack(Command::Configure(quadrature_only)), AckCode::Ok);
}
