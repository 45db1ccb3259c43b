//! Device logic of the bench firmware: step generation, sensors, sampler, watchdog and
//! command dispatch, generic over embedded-hal 1.0 traits and an injectable clock.
//!
//! It owns no board code: the RP2040 binary in `firmware/rp2040` and the host's simulated
//! bench both drive the same [`Device`]. `#![no_std]`, no allocator.
//!
//! # Modules
//! - [`platform`]: what a board provides ([`Platform`], [`Parts`], [`BoardConfig`],
//!   [`Clock`], [`QuadratureCounter`]).
//! - [`device`]: the [`Device`]: handshake, command dispatch, safety, pins, sample stream.
//! - [`stepper`]: the step generator (ramps, exact moves, exact constant-speed counts).
//! - [`sampler`]: sample scheduling, IMU decimation, batching.
//! - [`sensors`]: AS5600 and BNO055 drivers, quadrature decoder.
//! - [`watchdog`], [`outbox`]: dead-man deadline; transmit queue.
//! - [`identity`]: the USB serial number made from the flash's unique ID.
//!
//! Logging goes through embassy-style macros (`fmt.rs`): defmt frames with the `defmt`
//! feature (the board), nothing without it (host tests, the simulated bench).
//!
//! # Running it (a board, or the host's simulated bench)
//! The device is passive: feed it received bytes, poll it at or after its next deadline
//! with the clock advanced, and send what it queued. Per poll it does only what is due
//! (a few hundred ns on a PC), so a simulator can run it event by event, faster than real
//! time, by setting its clock to `min(device.next_deadline_us(), its own next event)`.
//!
//! ```
//! use std::{cell::Cell, rc::Rc};
//! use embedded_hal::digital::{ErrorType, OutputPin};
//! use mpc_firmware_core::{BoardConfig, Clock, Device, NoBus, NoQuadrature, Parts, Platform};
//! use mpc_wire::{encode_frame, Command, Config, Decoder, Report, SensorSet, MAX_FRAME_LEN};
//!
//! // The simulator's pieces: a clock it advances, pins it observes, no sensors here
//! // (a real simulator passes I²C buses that emulate AS5600/BNO055 registers).
//! #[derive(Clone, Default)]
//! struct SimClock(Rc<Cell<u64>>);
//! impl Clock for SimClock {
//!     fn now_us(&self) -> u64 { self.0.get() }
//! }
//! struct Pin(Rc<Cell<u32>>); // counts rising edges
//! impl ErrorType for Pin { type Error = core::convert::Infallible; }
//! impl OutputPin for Pin {
//!     fn set_high(&mut self) -> Result<(), Self::Error> { self.0.set(self.0.get() + 1); Ok(()) }
//!     fn set_low(&mut self) -> Result<(), Self::Error> { Ok(()) }
//! }
//! struct NoDelay;
//! impl embedded_hal::delay::DelayNs for NoDelay { fn delay_ns(&mut self, _: u32) {} }
//!
//! struct Sim;
//! impl Platform for Sim {
//!     type I2cA = NoBus; type I2cB = NoBus;
//!     type Step = Pin; type Dir = Pin; type Enable = Pin;
//!     type Delay = NoDelay; type Clock = SimClock; type Quadrature = NoQuadrature;
//! }
//!
//! let clock = SimClock::default();
//! let steps = Rc::new(Cell::new(0));
//! let parts = Parts::<Sim> {
//!     i2c_a: NoBus, i2c_b: NoBus,
//!     step: Pin(steps.clone()), dir: Pin(Rc::default()), enable: Pin(Rc::default()),
//!     delay: NoDelay, clock: clock.clone(), quadrature: NoQuadrature,
//! };
//! let board = BoardConfig::new("sim-stepper", SensorSet::EMPTY, 50_000);
//! let mut device = Device::new(parts, board);
//!
//! // Host side: configure (no sensors), enable, run at 1 rev/s (3200 µsteps/s).
//! let config = Config { sensors: SensorSet::EMPTY, ..Config::default() };
//! let mut buf = [0u8; MAX_FRAME_LEN];
//! let commands = [
//!     Command::Configure(config),
//!     Command::SetMotorEnabled(true),
//!     Command::RunSpeed { speed_mdeg_s: 360_000 },
//! ];
//! for (seq, cmd) in commands.into_iter().enumerate() {
//!     let n = encode_frame(seq as u16, &cmd, &mut buf).unwrap();
//!     device.receive(&buf[..n]);
//! }
//!
//! // Simulate 200 ms event by event (a real session sends a Heartbeat every ~100 ms to keep
//! // the 250 ms dead-man watchdog fed).
//! while let Some(t) = device.next_deadline_us().filter(|&t| t <= 200_000) {
//!     clock.0.set(t);
//!     device.poll();
//! }
//! let mut out = [0u8; 4096];
//! let n = device.transmit(&mut out);
//! let mut acks = 0;
//! Decoder::<Report>::new().feed(&out[..n], |r| {
//!     if let Ok(f) = r {
//!         if matches!(f.msg, Report::Ack { .. }) { acks += 1; }
//!     }
//! });
//! assert_eq!(acks, 3);
//! assert_eq!(device.position(), steps.get() as i64);
//! assert!(device.position() > 0);
//! //! ```
#![cfg_attr(not(test), no_std)]
#![warn(missing_docs)]

#[macro_use]
mod fmt;

pub mod device;
pub mod identity;
pub mod outbox;
pub mod platform;
pub mod sampler;
pub mod sensors;
pub mod stepper;
pub mod watchdog;

pub use device::{mdeg_to_usteps, Device, FIRMWARE_VERSION};
pub use identity::SerialNumber;
pub use platform::{BoardConfig, Clock, NoBus, NoQuadrature, Parts, Platform, QuadratureCounter};
