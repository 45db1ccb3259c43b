//! The emulated board: the release image of `firmware/rp2040` running in the rp2040js
//! emulator, its USB serial port on a pseudo-terminal, its pins and I²C buses wired to the
//! same plant and sensor models as the simulated stepper bench.
//!
//! ```text
//!  host (mpc-rig measure) ─ /dev/pts/N ─ this thread ═ pipe ═ node firmware/emu/harness.mjs
//!                                          │                    rp2040js: boot ROM, image,
//!              pacing to the wall clock ───┤                    USB host, pins, I²C
//!              wiring: STEP/DIR/EN ──► DriverChip ──► Bench (stepper sim's) ──► Plant
//!                      I²C pins ──► ByteTarget ──► SensorBus (AS5600, BNO055 registers)
//!                      quadrature, e-stop inputs ◄── plant, button
//! ```
//!
//! The board process ([`board`]) owns the chip and runs it in slices of
//! [`SLICE_US`] of simulated time; at the end of each slice it sends what the firmware wrote
//! on USB and waits for the answer: the bytes the host wrote, whether the host holds the
//! port open (DTR), and the input changes for the next slice. This thread answers once the
//! wall clock has caught up with the slice, so the board runs in real time; when the
//! emulator is slower than real time it falls behind, and beyond [`MAX_CATCH_UP`] the
//! origin slips rather than making the board race to catch up. Between syncs the board
//! reports every GPIO change and every I²C event as it happens, stamped with simulated time;
//! STEP/DIR/EN levels on the GPIOs [`wiring`] connects to the driver reach the emulated
//! driver chip, an I²C address phase on the pins of a sensor bus refreshes the plant at
//! that instant and is answered by that bus's register models ([`i2c_target`]), and
//! transfers on pins where nothing is wired are not acknowledged. The quadrature channels
//! follow the plant's linear counter; the e-stop input follows [`PicoHandle::set_estop`].
//!
//! The follower is the simulated stepper bench's ([`crate::rig::sim::stepper`]): its
//! `Bench` turns counted steps into the plant's follower and the sensor values, so the
//! emulated board and the host-run firmware core measure the same mechanism.
//!
//! Of the `--fault` keys, the plant's imperfections and the byte faults (`drop_prob`,
//! `corrupt_prob`) apply; the unplug, drop-out, stall, reboot and protocol-version faults are
//! those of the other simulators and are refused here ([`PicoError::UnsupportedFault`]).

pub mod board;
pub mod i2c_target;
pub mod link;
pub mod port;
pub mod wiring;

use std::io::{BufReader, BufWriter, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use embedded_hal::digital::OutputPin;

use crate::motion::Motion;
use crate::rig::sim::plant::{LinkByte, Plant, PlantConfig};
use crate::rig::sim::pty::StableLink;
use crate::rig::sim::stepper::i2c::SensorBus;
use crate::rig::sim::stepper::pins::{
    DirPin, DriverChip, EnablePin, PinFault, SimQuadrature, StepPin,
};
use crate::rig::sim::stepper::{Bench, Mechanics, MAX_CATCH_UP};
use crate::rig::RigError;

pub use board::BoardFiles;
pub use link::UsbDescriptors;

use i2c_target::ByteTarget;
use link::{BoardMessage, I2cEvent, Level, SyncReply};
use port::HostPort;
use wiring::{DriverInput, SensorBusId};

/// Simulated time between syncs with the board, µs. 1 ms: a USB full-speed frame, so the
/// host's bytes reach the firmware with the latency of a real bus, and a pacing granularity
/// far below the 250 ms watchdog; at 1 000 syncs per second the pipe costs little.
pub const SLICE_US: u32 = 1_000;

/// The flash unique ID of an emulated board unless told otherwise (any fixed value: the
/// serial number it makes is then stable from run to run).
pub const DEFAULT_FLASH_ID: u64 = 0xe660_5838_833c_2b2f;

/// Error of the emulated board.
#[derive(Debug, thiserror::Error)]
pub enum PicoError {
    /// A file the board runs from is missing.
    #[error("{what} not found at {path}: {hint}")]
    Missing {
        /// What the file is.
        what: &'static str,
        /// Where it was expected.
        path: PathBuf,
        /// How to make it.
        hint: &'static str,
    },
    /// Node.js could not be started.
    #[error("cannot start `{program}`: {message} (the emulated board needs Node.js 18 or newer on the PATH)", program = program.display())]
    Spawn {
        /// The program tried.
        program: PathBuf,
        /// Why it failed.
        message: String,
    },
    /// Reading from or writing to the board process failed.
    #[error("pipe to the emulated board: {0}")]
    Pipe(String),
    /// The board sent something the protocol does not allow.
    #[error("emulated board protocol: {0}")]
    Protocol(String),
    /// The board process ended by itself.
    #[error("the emulated board exited unexpectedly{}", if .0.is_empty() { String::new() } else { format!(":\n{}", .0) })]
    Exited(String),
    /// A `--fault` the emulated board does not implement.
    #[error("--fault {key}: not available on the emulated board (use sim-device stepper for unplug, drop-out and protocol faults)")]
    UnsupportedFault {
        /// The key.
        key: &'static str,
    },
    /// Writing the board's log or a capture.
    #[error("{path}: {message}", path = path.display())]
    Log {
        /// The file.
        path: PathBuf,
        /// What failed.
        message: String,
    },
    /// Setting up the pseudo-terminal.
    #[error(transparent)]
    Rig(#[from] RigError),
}

/// Options of an emulated board.
#[derive(Clone)]
pub struct SimPicoOptions {
    /// The target law the follower obeys.
    pub target: Motion,
    /// Imperfections (link faults: bytes only, see the module doc).
    pub plant: PlantConfig,
    /// The bench: steps per revolution, microsteps, gear, direction, the sensors fitted
    /// (a sensor not fitted does not answer on its bus).
    pub mechanics: Mechanics,
    /// The image, ROM and harness.
    pub files: BoardFiles,
    /// The 64-bit unique ID of the emulated flash chip (the USB serial number is made from it).
    pub flash_id: u64,
    /// Also expose the port at this path (a symlink).
    pub link: Option<PathBuf>,
    /// Append the firmware's defmt log frames (its RTT up-channel) to this file; decode them
    /// with `defmt-print -e IMAGE < FILE`.
    pub defmt_log: Option<PathBuf>,
    /// Record the link in this directory: `to-device.bin` (what the host wrote) and
    /// `to-host.bin` (what reached the host, after the byte faults), for `mpc-rig wire-dump`.
    pub capture: Option<PathBuf>,
}

/// What the emulated board has done so far.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct PicoStatus {
    /// Simulated seconds since reset.
    pub time_s: f64,
    /// Largest lag of simulated time behind the wall clock, seconds.
    pub max_behind_s: f64,
    /// Wall-clock time given up because the emulator could not keep pace, seconds.
    pub slipped_s: f64,
    /// Steps pulsed while the driver was enabled (signed).
    pub steps: i64,
    /// Steps the motor made (minus missed steps).
    pub physical_steps: i64,
    /// The driver is enabled (EN at its active level).
    pub enabled: bool,
    /// The descriptors the host read when the board enumerated.
    pub usb: Option<UsbDescriptors>,
    /// A program holds the host end of the serial port open.
    pub host_open: bool,
    /// Bytes from the host to the board.
    pub bytes_in: u64,
    /// Bytes from the board to the host.
    pub bytes_out: u64,
    /// Bytes dropped (link fault, or no program holding the port).
    pub bytes_dropped: u64,
    /// Bytes corrupted by the link fault.
    pub bytes_corrupted: u64,
    /// I²C address phases on bus A and bus B.
    pub i2c_transfers: [u64; 2],
    /// Bytes of defmt log frames the firmware wrote.
    pub log_bytes: u64,
    /// The board stopped (a breakpoint or a hard fault), with the reason.
    pub halted: Option<String>,
}

/// A running emulated board.
pub struct PicoHandle {
    path: PathBuf,
    stop: Arc<AtomicBool>,
    estop: Arc<AtomicBool>,
    status: Arc<Mutex<PicoStatus>>,
    thread: Option<JoinHandle<Result<(), PicoError>>>,
    _link: Option<StableLink>,
}

impl PicoHandle {
    /// The path the host opens (the symlink if one was asked for, else `/dev/pts/N`).
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// A snapshot of the board's state.
    pub fn status(&self) -> PicoStatus {
        self.status
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .clone()
    }

    /// Press (true) or release the e-stop button.
    pub fn set_estop(&self, pressed: bool) {
        self.estop.store(pressed, Ordering::Relaxed);
    }

    /// Whether the board is still running.
    pub fn is_running(&self) -> bool {
        self.thread.as_ref().is_some_and(|t| !t.is_finished())
    }

    /// Stop the board and return its final state (or why it ended early).
    pub fn stop(mut self) -> Result<PicoStatus, PicoError> {
        self.stop_inner()?;
        Ok(self.status())
    }

    fn stop_inner(&mut self) -> Result<(), PicoError> {
        self.stop.store(true, Ordering::Relaxed);
        match self.thread.take() {
            Some(t) => t
                .join()
                .map_err(|_| PicoError::Pipe("the emulated board's thread panicked".into()))?,
            None => Ok(()),
        }
    }
}

impl Drop for PicoHandle {
    fn drop(&mut self) {
        let _ = self.stop_inner();
    }
}

/// Start an emulated board on a new pseudo-terminal.
pub fn spawn(opts: SimPicoOptions) -> Result<PicoHandle, PicoError> {
    refuse_unsupported_faults(&opts.plant)?;
    // Checked here too (the board thread checks again when it starts the harness) so that a
    // missing file is an error of `spawn`, not of a thread already running.
    opts.files.check()?;
    let port = HostPort::open()?;
    let link = match &opts.link {
        Some(l) => Some(StableLink::create(l, port.path())?),
        None => None,
    };
    let path = opts
        .link
        .clone()
        .unwrap_or_else(|| port.path().to_path_buf());
    let stop = Arc::new(AtomicBool::new(false));
    let estop = Arc::new(AtomicBool::new(false));
    let status = Arc::new(Mutex::new(PicoStatus::default()));
    let (stop2, estop2, status2) = (stop.clone(), estop.clone(), status.clone());
    let thread = std::thread::Builder::new()
        .name("mpc-sim-pico".into())
        .spawn(move || run(opts, port, &stop2, &estop2, &status2))
        .map_err(|e| PicoError::Pipe(format!("cannot start the board thread: {e}")))?;
    Ok(PicoHandle {
        path,
        stop,
        estop,
        status,
        thread: Some(thread),
        _link: link,
    })
}

fn refuse_unsupported_faults(plant: &PlantConfig) -> Result<(), PicoError> {
    let l = &plant.link;
    let unsupported = [
        ("disconnect_at_s", l.disconnect_at_s.is_some()),
        ("dropout_at_s", l.dropout_at_s.is_some()),
        ("protocol_version", l.protocol_version.is_some()),
        ("stall_at_s", l.stall_at_s.is_some()),
        ("reboot_at_s", l.reboot_at_s.is_some()),
    ];
    match unsupported.into_iter().find(|(_, set)| *set) {
        Some((key, _)) => Err(PicoError::UnsupportedFault { key }),
        None => Ok(()),
    }
}

/// What is connected to the chip's pins: the driver, the sensor buses, the quadrature
/// encoder and the e-stop button, with the plant behind them.
struct Attached {
    bench: Bench,
    step: StepPin,
    dir: DirPin,
    enable: EnablePin,
    buses: [ByteTarget; 2],
    /// The bench bus each I²C controller addressed in its present transfer.
    routed: [Option<SensorBusId>; 2],
    /// Quadrature count and e-stop level last put on the pins (`None` before the first sync).
    inputs_sent: Option<(i64, bool)>,
    /// GPIOs already reported as driven with nothing wired (bit n: GPn).
    reported_gpios: u32,
    /// I²C (controller, SDA, SCL) routings already reported as leading nowhere.
    reported_routes: Vec<(u8, u8, u8)>,
}

impl Attached {
    fn new(opts: &SimPicoOptions) -> Attached {
        let mech = &opts.mechanics;
        let chip = DriverChip::new(true);
        let bus_a = SensorBus::new(mech.as5600, mech.imu);
        let bus_b = SensorBus::new(mech.as5600_b, false);
        let mut bench = Bench::new(
            Plant::new(opts.target.clone(), opts.plant.clone()),
            mech.clone(),
            chip.clone(),
            bus_a.clone(),
            bus_b.clone(),
            SimQuadrature::default(),
            None,
        );
        bench.update(0);
        Attached {
            bench,
            step: chip.step_pin(),
            dir: chip.dir_pin(),
            enable: chip.enable_pin(),
            buses: [ByteTarget::new(bus_a), ByteTarget::new(bus_b)],
            routed: [None, None],
            inputs_sent: None,
            reported_gpios: 0,
            reported_routes: Vec::new(),
        }
    }

    fn pin(&mut self, gpio: u8, level: Level) {
        // An undriven input of the driver reads low: the worst case for EN (enabled).
        let high = level == Level::High;
        let pin: &mut dyn OutputPin<Error = PinFault> = match wiring::driver_input(gpio) {
            Some(DriverInput::Step) => &mut self.step,
            Some(DriverInput::Dir) => &mut self.dir,
            Some(DriverInput::Enable) => &mut self.enable,
            None => {
                if level != Level::Undriven {
                    self.report_unwired_gpio(gpio, high);
                }
                return;
            }
        };
        let _ = if high { pin.set_high() } else { pin.set_low() };
    }

    /// Say once per GPIO that the firmware drives a pin the driver is not wired to.
    fn report_unwired_gpio(&mut self, gpio: u8, high: bool) {
        let bit = 1u32.checked_shl(u32::from(gpio)).unwrap_or(0);
        if self.reported_gpios & bit != 0 {
            return;
        }
        self.reported_gpios |= bit;
        let what = if [wiring::ESTOP, wiring::QUADRATURE_A, wiring::QUADRATURE_B].contains(&gpio) {
            "an input of the bench (e-stop or quadrature), against which the firmware drives"
        } else {
            "nothing on the bench"
        };
        let level = if high { "high" } else { "low" };
        tracing::warn!(
            "emulated board: GP{gpio} is driven {level} but is wired to {what} (the bench: STEP GP{}, DIR GP{}, EN GP{})",
            wiring::STEP,
            wiring::DIR,
            wiring::ENABLE
        );
    }

    /// Say once per routing that a controller addresses pins where no bus is wired.
    fn report_unwired_bus(&mut self, controller: u8, sda: u8, scl: u8, address: u8) {
        if self.reported_routes.contains(&(controller, sda, scl)) {
            return;
        }
        self.reported_routes.push((controller, sda, scl));
        let (a, b) = (wiring::BUS_A_PINS, wiring::BUS_B_PINS);
        tracing::warn!(
            "emulated board: I2C{controller} addresses 0x{address:02x} on SDA {} / SCL {}, where no sensor bus is wired (bus A: GP{}/GP{}, bus B: GP{}/GP{})",
            gpio_name(sda),
            gpio_name(scl),
            a.0,
            a.1,
            b.0,
            b.1
        );
    }

    fn i2c(&mut self, t_us: f64, controller: u8, sda: u8, scl: u8, event: I2cEvent) -> Option<u8> {
        let c = usize::from(controller);
        match event {
            I2cEvent::Connect { address, .. } => {
                self.bench.update(t_us as u64);
                let bus = wiring::bus_on_pins(sda, scl);
                self.routed[c] = bus;
                let ack = match bus {
                    Some(b) => self.buses[b as usize].connect(address),
                    None => {
                        self.report_unwired_bus(controller, sda, scl, address);
                        false
                    }
                };
                Some(u8::from(ack))
            }
            I2cEvent::Write(byte) => {
                if let Some(b) = self.routed[c] {
                    self.buses[b as usize].write(byte);
                }
                None
            }
            I2cEvent::Read { .. } => Some(match self.routed[c] {
                Some(b) => self.buses[b as usize].read(),
                None => 0xff,
            }),
            I2cEvent::Stop => {
                if let Some(b) = self.routed[c].take() {
                    self.buses[b as usize].stop();
                }
                None
            }
        }
    }

    /// Input changes for the next slice: all input levels at the first sync, then the
    /// quadrature edges since the last sync and the e-stop contact when it changed (open,
    /// so the pin is pulled high, while the button is pressed).
    fn inputs(&mut self, estop_pressed: bool) -> Vec<(u8, bool)> {
        let count = i64::from(self.bench.quadrature.0.get());
        let out = match self.inputs_sent {
            None => {
                let (a, b) = wiring::quadrature_channels(count);
                vec![
                    (wiring::QUADRATURE_A, a),
                    (wiring::QUADRATURE_B, b),
                    (wiring::ESTOP, estop_pressed),
                ]
            }
            Some((sent, estop_sent)) => {
                let mut edges = wiring::quadrature_edges(sent, count);
                if estop_sent != estop_pressed {
                    edges.push((wiring::ESTOP, estop_pressed));
                }
                edges
            }
        };
        self.inputs_sent = Some((count, estop_pressed));
        out
    }
}

fn gpio_name(gpio: u8) -> String {
    if gpio == link::NO_PIN {
        "no pin".into()
    } else {
        format!("GP{gpio}")
    }
}

/// Pacing: when simulated time `t` is due on the wall clock, and how far behind it runs.
struct Pacing {
    start: Instant,
    slip: Duration,
    max_behind: Duration,
}

impl Pacing {
    /// Wait until simulated time `t` is due; returns at once when already behind, slipping
    /// the origin by what exceeds [`MAX_CATCH_UP`].
    fn wait_until(&mut self, t: Duration) {
        let due = self.start + t + self.slip;
        let now = Instant::now();
        if now < due {
            std::thread::sleep(due - now);
            return;
        }
        let behind = now - due;
        self.max_behind = self.max_behind.max(behind);
        if behind > MAX_CATCH_UP {
            self.slip += behind - MAX_CATCH_UP;
        }
    }
}

/// The host's side of the board: its port, what is attached to the pins, the files kept,
/// the pacing and the status being built.
struct Surroundings {
    port: HostPort,
    attached: Attached,
    defmt_log: Option<OutputFile>,
    /// (to-device.bin, to-host.bin)
    capture: Option<(OutputFile, OutputFile)>,
    pacing: Pacing,
    st: PicoStatus,
}

impl Surroundings {
    fn new(opts: &SimPicoOptions, port: HostPort) -> Result<Surroundings, PicoError> {
        let capture = match &opts.capture {
            Some(dir) => {
                std::fs::create_dir_all(dir).map_err(|e| PicoError::Log {
                    path: dir.clone(),
                    message: e.to_string(),
                })?;
                Some((
                    OutputFile::append(&dir.join("to-device.bin"))?,
                    OutputFile::append(&dir.join("to-host.bin"))?,
                ))
            }
            None => None,
        };
        Ok(Surroundings {
            port,
            attached: Attached::new(opts),
            defmt_log: opts
                .defmt_log
                .as_deref()
                .map(OutputFile::append)
                .transpose()?,
            capture,
            pacing: Pacing {
                start: Instant::now(),
                slip: Duration::ZERO,
                max_behind: Duration::ZERO,
            },
            st: PicoStatus::default(),
        })
    }

    /// The end of a slice: pass the board's bytes to the host, wait for the wall clock,
    /// and gather the answer (`None` when told to stop meanwhile).
    fn sync(
        &mut self,
        t_us: f64,
        usb: &[u8],
        stop: &AtomicBool,
        estop: &AtomicBool,
    ) -> Result<Option<SyncReply>, PicoError> {
        let now_us = t_us as u64;
        let a = &mut self.attached;
        a.bench.update(now_us);
        let host_open = self.port.host_present();
        let sent = to_host(
            &mut self.port,
            &mut a.bench.plant,
            usb,
            host_open,
            &mut self.st,
        )?;
        if let Some((_, to_host_file)) = self.capture.as_mut() {
            to_host_file.write(&sent)?;
        }
        self.pacing.wait_until(Duration::from_micros(now_us));
        if stop.load(Ordering::Relaxed) {
            return Ok(None);
        }
        let host_open = self.port.host_present();
        let mut host_bytes = Vec::new();
        if host_open {
            self.port.read_all(&mut host_bytes)?;
        }
        if let Some((to_device_file, _)) = self.capture.as_mut() {
            to_device_file.write(&host_bytes)?;
        }
        let st = &mut self.st;
        st.bytes_in += host_bytes.len() as u64;
        st.host_open = host_open;
        st.time_s = t_us / 1e6;
        st.max_behind_s = self.pacing.max_behind.as_secs_f64();
        st.slipped_s = self.pacing.slip.as_secs_f64();
        st.steps = a.bench.last_steps;
        st.physical_steps = a.bench.physical;
        st.enabled = a.bench.chip.enabled();
        st.i2c_transfers = [a.buses[0].transfers(), a.buses[1].transfers()];
        Ok(Some(SyncReply {
            host_open,
            inputs: a.inputs(estop.load(Ordering::Relaxed)),
            host_bytes,
        }))
    }

    fn publish(&self, status: &Mutex<PicoStatus>) {
        *status.lock().unwrap_or_else(|p| p.into_inner()) = self.st.clone();
    }
}

fn run(
    opts: SimPicoOptions,
    port: HostPort,
    stop: &AtomicBool,
    estop: &AtomicBool,
    status: &Mutex<PicoStatus>,
) -> Result<(), PicoError> {
    let mut around = Surroundings::new(&opts, port)?;
    let mut process = opts.files.spawn(opts.flash_id, SLICE_US)?;
    let stdout = process.child.stdout.take().expect("piped stdout");
    let stdin = process.child.stdin.take().expect("piped stdin");
    let mut from_board = BufReader::with_capacity(1 << 16, stdout);
    let mut to_board = BufWriter::new(stdin);
    loop {
        let Some(msg) = link::read_message(&mut from_board)? else {
            if stop.load(Ordering::Relaxed) || around.st.halted.is_some() {
                break;
            }
            let _ = process.child.wait();
            return Err(PicoError::Exited(process.stderr_tail()));
        };
        match msg {
            BoardMessage::Pin { gpio, level, .. } => around.attached.pin(gpio, level),
            BoardMessage::I2c {
                t_us,
                controller,
                sda,
                scl,
                event,
            } => {
                if let Some(v) = around.attached.i2c(t_us, controller, sda, scl, event) {
                    link::send(&mut to_board, &link::encode_i2c_reply(v))?;
                }
            }
            BoardMessage::Sync { t_us, usb } => match around.sync(t_us, &usb, stop, estop)? {
                Some(reply) => {
                    link::send(&mut to_board, &link::encode_sync_reply(&reply))?;
                    around.publish(status);
                }
                None => break,
            },
            BoardMessage::Usb(d) => {
                tracing::info!(
                    "emulated board enumerated: {:04x}:{:04x} `{}` `{}`, serial number `{}`",
                    d.vid,
                    d.pid,
                    d.manufacturer.as_deref().unwrap_or("-"),
                    d.product.as_deref().unwrap_or("-"),
                    d.serial.as_deref().unwrap_or("-"),
                );
                around.st.usb = Some(d);
                // Published now, not at the end of the slice: the board may answer the
                // host's first bytes in the slice it enumerates in, and the reply reaches
                // the host (in `sync`) before that slice's status does. A host that read
                // the reply and then the status found no USB descriptors (a CI run of
                // `pico_board::sensors_pins_and_serial_number_as_wired`, 2026-12-04).
                around.publish(status);
            }
            BoardMessage::Log { warning, text } => {
                if warning {
                    tracing::warn!("emulated board: {text}");
                } else {
                    tracing::debug!("emulated board: {text}");
                }
            }
            BoardMessage::Halt(reason) => {
                tracing::error!("emulated board stopped: {reason}");
                around.st.halted = Some(reason);
                around.publish(status);
            }
            BoardMessage::Rtt(bytes) => {
                around.st.log_bytes += bytes.len() as u64;
                if let Some(f) = around.defmt_log.as_mut() {
                    f.write(&bytes)?;
                }
            }
        }
    }
    process.kill();
    Ok(())
}

/// A file the board's log or a capture is appended to.
struct OutputFile {
    file: std::fs::File,
    path: PathBuf,
}

impl OutputFile {
    fn append(path: &Path) -> Result<OutputFile, PicoError> {
        let file = std::fs::OpenOptions::new()
            .create(true)
            .append(true)
            .open(path)
            .map_err(|e| PicoError::Log {
                path: path.to_path_buf(),
                message: e.to_string(),
            })?;
        Ok(OutputFile {
            file,
            path: path.to_path_buf(),
        })
    }

    fn write(&mut self, bytes: &[u8]) -> Result<(), PicoError> {
        if bytes.is_empty() {
            return Ok(());
        }
        self.file.write_all(bytes).map_err(|e| PicoError::Log {
            path: self.path.clone(),
            message: e.to_string(),
        })
    }
}

/// The board's USB bytes to the host, through the link faults; dropped while no program
/// holds the port. Returns the bytes the host received.
fn to_host(
    port: &mut HostPort,
    plant: &mut Plant,
    bytes: &[u8],
    host_open: bool,
    st: &mut PicoStatus,
) -> Result<Vec<u8>, PicoError> {
    if bytes.is_empty() {
        return Ok(Vec::new());
    }
    if !host_open {
        st.bytes_dropped += bytes.len() as u64;
        return Ok(Vec::new());
    }
    let mut wire = Vec::with_capacity(bytes.len());
    for &b in bytes {
        match plant.link_byte(b) {
            LinkByte::Pass(x) => wire.push(x),
            LinkByte::Corrupted(x) => {
                st.bytes_corrupted += 1;
                wire.push(x);
            }
            LinkByte::Dropped => st.bytes_dropped += 1,
        }
    }
    let n = port.write_lossy(&wire)?;
    st.bytes_out += n as u64;
    st.bytes_dropped += (wire.len() - n) as u64;
    wire.truncate(n);
    Ok(wire)
}
