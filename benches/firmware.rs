//! Firmware figures: how fast the wire decoder eats a 1 kHz sample stream, and how fast the
//! device logic (`mpc-firmware-core`) runs on the host the way the simulated stepper bench
//! runs it — event by event at 1 kHz sampling of an AS5600 and a BNO055 with the motor at
//! 16 000 microsteps/s. Prints frames/s, MB/s, ns per device poll and the ratio of
//! simulated to wall-clock time.
//!
//! Run with `cargo bench --bench firmware`.

use std::cell::Cell;
use std::convert::Infallible;
use std::rc::Rc;
use std::time::Instant;

use embedded_hal::digital::{ErrorType as PinErrorType, OutputPin};
use embedded_hal::i2c::{self, ErrorKind, I2c, Operation};
use mpc_firmware_core::{BoardConfig, Clock, Device, NoBus, NoQuadrature, Parts, Platform};
use mpc_wire::{encode_frame, Command, Config, Decoder, Report, SensorSet, MAX_FRAME_LEN};

#[path = "../firmware/wire/benches/support/decoder.rs"]
mod decoder;

#[derive(Clone, Default)]
struct SimClock(Rc<Cell<u64>>);
impl Clock for SimClock {
    fn now_us(&self) -> u64 {
        self.0.get()
    }
}

#[derive(Clone, Default)]
struct CountingPin(Rc<Cell<u64>>);
impl PinErrorType for CountingPin {
    type Error = Infallible;
}
impl OutputPin for CountingPin {
    fn set_high(&mut self) -> Result<(), Infallible> {
        self.0.set(self.0.get() + 1);
        Ok(())
    }
    fn set_low(&mut self) -> Result<(), Infallible> {
        Ok(())
    }
}

#[derive(Debug)]
struct BusError;
impl i2c::Error for BusError {
    fn kind(&self) -> ErrorKind {
        ErrorKind::Other
    }
}

/// AS5600 at 0x36 whose angle follows the clock, BNO055 at 0x28.
struct PlantBus(SimClock);
impl i2c::ErrorType for PlantBus {
    type Error = BusError;
}
impl I2c for PlantBus {
    fn transaction(&mut self, addr: u8, ops: &mut [Operation<'_>]) -> Result<(), BusError> {
        let mut reg = 0u8;
        let angle = ((self.0.now_us() / 250) % 4096) as u16;
        for op in ops {
            match op {
                Operation::Write(w) => reg = w[0],
                Operation::Read(buf) => {
                    for (i, b) in buf.iter_mut().enumerate() {
                        *b = match (addr, reg.wrapping_add(i as u8)) {
                            (0x36, 0x0B) => 0x20,
                            (0x36, 0x0C) => (angle >> 8) as u8,
                            (0x36, 0x0D) => angle as u8,
                            (0x28, 0x00) => 0xA0,
                            (0x28, 0x21) => 0x40,
                            _ => 0,
                        }
                    }
                }
            }
        }
        if addr == 0x36 || addr == 0x28 {
            Ok(())
        } else {
            Err(BusError)
        }
    }
}

struct NoDelay;
impl embedded_hal::delay::DelayNs for NoDelay {
    fn delay_ns(&mut self, _: u32) {}
}

struct Sim;
impl Platform for Sim {
    type I2cA = PlantBus;
    type I2cB = NoBus;
    type Step = CountingPin;
    type Dir = CountingPin;
    type Enable = CountingPin;
    type Delay = NoDelay;
    type Clock = SimClock;
    type Quadrature = NoQuadrature;
}

fn device_speed(simulated_s: u64) {
    let clock = SimClock::default();
    let steps = CountingPin::default();
    let parts = Parts::<Sim> {
        i2c_a: PlantBus(clock.clone()),
        i2c_b: NoBus,
        step: steps.clone(),
        dir: CountingPin::default(),
        enable: CountingPin::default(),
        delay: NoDelay,
        clock: clock.clone(),
        quadrature: NoQuadrature,
    };
    let board = BoardConfig::new("bench", SensorSet::ENCODER_A | SensorSet::IMU, 50_000);
    let mut device = Device::new(parts, board);
    let config = Config {
        sensors: SensorSet::ENCODER_A | SensorSet::IMU,
        max_speed_mdeg_s: 1_800_000,
        max_accel_mdeg_s2: 3_600_000,
        ..Config::default()
    };
    let mut buf = [0u8; MAX_FRAME_LEN];
    let mut seq = 0u16;
    let mut send = |device: &mut Device<Sim>, cmd: Command| {
        let n = encode_frame(seq, &cmd, &mut buf).expect("encodes");
        seq = seq.wrapping_add(1);
        device.receive(&buf[..n]);
    };
    for cmd in [
        Command::Configure(config),
        Command::SetMotorEnabled(true),
        Command::StartStream,
        Command::RunSpeed {
            speed_mdeg_s: 1_800_000,
        },
    ] {
        send(&mut device, cmd);
    }
    let mut out = vec![0u8; 16 * 1024];
    let mut decoder = Decoder::<Report>::new();
    let mut samples = 0u64;
    let mut polls = 0u64;
    let end = simulated_s * 1_000_000;
    let mut next_heartbeat = 100_000;
    let start = Instant::now();
    while let Some(t) = device.next_deadline_us() {
        let t = t.min(next_heartbeat);
        if t > end {
            break;
        }
        clock.0.set(t);
        if t == next_heartbeat {
            send(&mut device, Command::Heartbeat);
            next_heartbeat += 100_000;
        }
        device.poll();
        polls += 1;
        let n = device.transmit(&mut out);
        decoder.feed(&out[..n], |r| {
            if let Ok(f) = r {
                if let Report::Samples(b) = f.msg {
                    samples += b.len() as u64;
                }
            }
        });
    }
    let wall = start.elapsed().as_secs_f64();
    let steps = steps.0.get();
    println!(
        "device on the host: {simulated_s} s simulated in {wall:.3} s ({:.0}x real time), \
         {steps} steps, {samples} samples, {polls} polls, {:.0} ns/poll",
        simulated_s as f64 / wall,
        wall * 1e9 / polls as f64
    );
    assert!(steps > 0 && samples >= simulated_s * 1000 - 10);
}

fn main() {
    decoder::run_all();
    device_speed(20);
}
