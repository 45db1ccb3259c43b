//! The simulated stepper bench: the real firmware core (`mpc-firmware-core`) and wire
//! protocol behind a pseudo-terminal, with emulated pins and I²C sensors fed by the plant.
//!
//! One thread runs the bench in simulated time paced by the wall clock: every
//! [`SUBSTEP_US`] of simulated time it hands the firmware the bytes the host wrote, polls
//! it (the firmware pulses STEP/DIR/EN on [`pins`] and reads the sensors on [`i2c`]),
//! turns the counted steps into the physical driver angle (minus missed steps), asks the
//! [`Plant`] where the follower is, and updates the emulated sensor registers; the same
//! update runs just before each sensor read ([`pins::ReadHook`]), so a sample taken right
//! after a step in the same poll reads the sensor after that step, as on hardware. Bytes the
//! firmware sends pass through the link faults before reaching the host. At
//! `disconnect_at_s` the pseudo-terminal is closed for good (an unplug); a drop-out closes
//! it and opens a new one after `dropout_s`, re-pointing the stable link, while the
//! firmware keeps running (its watchdog stops the motor), as a self-powered board whose USB
//! cable was wiggled.
//!
//! It owns no host logic: the host talks to it through the ordinary stepper backend.

pub mod i2c;
pub mod pins;

use std::cell::RefCell;
use std::f64::consts::TAU;
use std::path::{Path, PathBuf};
use std::rc::Rc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use mpc_wire::{Decoder, Report, SensorSet};

use crate::motion::Motion;
use crate::rig::config::{DriverConfig, RigConfig};
use crate::rig::sim::plant::{DriverAngleSource, LinkByte, Plant, PlantConfig};
use crate::rig::sim::pty::{Pty, StableLink};
use crate::rig::RigError;

use i2c::SensorBus;
use pins::{DriverChip, ReadHook, SimClock, SimQuadrature};

/// Simulated time between firmware polls, µs. 100 µs keeps the sensor values the firmware
/// reads within 100 µs of its step count (0.04° of driver at 60 rpm) at 10 000 polls per
/// simulated second.
pub const SUBSTEP_US: u64 = 100;

/// Wall-clock pause between bursts of simulation: 1 ms, the granularity of the pacing.
pub const PACING: Duration = Duration::from_millis(1);

/// Longest simulated time the loop catches up in one burst; beyond it the simulation
/// slips (a stalled host process must not make the device time jump).
pub const MAX_CATCH_UP: Duration = Duration::from_millis(50);

/// Board name the simulated firmware reports.
pub const SIM_BOARD_NAME: &str = "sim-stepper";

/// Step rate the simulated board guarantees (steps/s): that of the RP2040 board loop.
pub const SIM_MAX_STEP_RATE_HZ: u32 = 40_000;

/// The physical bench being simulated.
#[derive(Debug, Clone, PartialEq)]
pub struct Mechanics {
    /// Full steps per motor revolution.
    pub steps_per_rev: u32,
    /// Microsteps set on the driver chip.
    pub microsteps: u32,
    /// Motor revolutions per driver revolution.
    pub gear_ratio: f64,
    /// +1 when positive steps (DIR high) turn the driver counter-clockwise.
    pub direction: i8,
    /// An AS5600 on the follower (bus A).
    pub as5600: bool,
    /// A second AS5600 (bus B).
    pub as5600_b: bool,
    /// A BNO055 on the follower (bus A).
    pub imu: bool,
    /// How the BNO055 is mounted: IMU axes → follower axes (it reports `R₂ · mounting`).
    pub imu_mounting: nalgebra::UnitQuaternion<f64>,
    /// Linear encoder (quadrature) resolution, mm per count, for a 1R1T follower.
    pub quadrature_mm_per_count: Option<f64>,
}

impl Default for Mechanics {
    /// The bench of `rigs/sim-stepper.toml`: 200 steps/rev, 16 microsteps, direct drive,
    /// one AS5600.
    fn default() -> Self {
        Mechanics {
            steps_per_rev: 200,
            microsteps: 16,
            gear_ratio: 1.0,
            direction: 1,
            as5600: true,
            as5600_b: false,
            imu: false,
            imu_mounting: nalgebra::UnitQuaternion::identity(),
            quadrature_mm_per_count: None,
        }
    }
}

impl Mechanics {
    /// The mechanics a rig file describes (driver and fitted firmware sensors).
    pub fn from_rig(rig: &RigConfig) -> Result<Mechanics, RigError> {
        let DriverConfig::StepperFirmware(d) = &rig.driver else {
            return Err(RigError::Setup(format!(
                "rig `{}` has a {} driver; the simulated stepper bench needs stepper-firmware",
                rig.name,
                rig.driver.kind()
            )));
        };
        let mut m = Mechanics {
            steps_per_rev: d.steps_per_rev,
            microsteps: d.microsteps,
            gear_ratio: d.gear_ratio,
            direction: d.direction,
            as5600: false,
            as5600_b: false,
            imu: false,
            imu_mounting: nalgebra::UnitQuaternion::identity(),
            quadrature_mm_per_count: None,
        };
        m.fit_sensors(rig);
        Ok(m)
    }

    /// The mechanics of a mixed rig's sensor board: the firmware's default motor output
    /// (unused) and the rig's firmware sensors.
    pub fn sensor_board(rig: &RigConfig) -> Result<Mechanics, RigError> {
        if !rig.is_mixed() {
            return Err(RigError::Setup(format!(
                "rig `{}` has no [sensor_board]",
                rig.name
            )));
        }
        let mut m = Mechanics {
            as5600: false,
            ..Mechanics::default()
        };
        m.fit_sensors(rig);
        Ok(m)
    }

    fn fit_sensors(&mut self, rig: &RigConfig) {
        for s in &rig.sensors {
            use crate::rig::config::SensorConfig as S;
            match s {
                S::As5600(e) if e.channel == 0 => self.as5600 = true,
                S::As5600(_) => self.as5600_b = true,
                S::Imu(i) => {
                    self.imu = true;
                    self.imu_mounting = i.mounting_rotation();
                }
                S::Quadrature(e) => {
                    self.quadrature_mm_per_count = e.mm_per_count.or(Some(0.01));
                }
                S::Dynamixel(_) => {}
            }
        }
    }

    fn usteps_per_driver_rev(&self) -> f64 {
        f64::from(self.steps_per_rev) * f64::from(self.microsteps) * self.gear_ratio
    }

    /// The firmware sensors fitted.
    pub fn fitted(&self) -> SensorSet {
        let mut s = SensorSet::EMPTY;
        if self.as5600 {
            s = s | SensorSet::ENCODER_A;
        }
        if self.as5600_b {
            s = s | SensorSet::ENCODER_B;
        }
        if self.imu {
            s = s | SensorSet::IMU;
        }
        if self.quadrature_mm_per_count.is_some() {
            s = s | SensorSet::QUADRATURE;
        }
        s
    }
}

/// Options of a simulated stepper bench.
#[derive(Clone)]
pub struct SimStepperOptions {
    /// The target law the follower obeys.
    pub target: Motion,
    /// Imperfections and link faults.
    pub plant: PlantConfig,
    /// The physical bench.
    pub mechanics: Mechanics,
    /// Also expose the device at this stable path (a symlink re-pointed on re-plug).
    /// Created automatically in the temp directory when a drop-out is configured.
    pub link: Option<PathBuf>,
    /// `Some` for the sensor board of a mixed bench: the mechanism's driver is turned by
    /// another device (a simulated Dynamixel) and the plant follows this angle; the
    /// firmware's own step output drives nothing. `None`: the firmware's steps turn it.
    pub driver: Option<DriverAngleSource>,
}

/// What the simulator has done so far.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct SimStatus {
    /// Simulated seconds since start.
    pub time_s: f64,
    /// Steps the firmware pulsed (signed, while enabled).
    pub steps: i64,
    /// Steps the motor actually made.
    pub physical_steps: i64,
    /// Steps lost to the missed-step fault.
    pub missed_steps: u64,
    /// Driver enabled (EN active).
    pub enabled: bool,
    /// Steps were pulsed within the last 50 ms of simulated time.
    pub moving: bool,
    /// Bytes received from the host.
    pub bytes_in: u64,
    /// Bytes sent to the host.
    pub bytes_out: u64,
    /// Bytes dropped by the link fault.
    pub bytes_dropped: u64,
    /// Bytes corrupted by the link fault.
    pub bytes_corrupted: u64,
    /// The pseudo-terminal is closed for good.
    pub disconnected: bool,
    /// Drop-outs performed.
    pub dropouts: u32,
    /// Firmware polls made.
    pub polls: u64,
}

/// A running simulated stepper bench.
pub struct SimHandle {
    path: PathBuf,
    stop: Arc<AtomicBool>,
    status: Arc<Mutex<SimStatus>>,
    thread: Option<JoinHandle<Result<(), RigError>>>,
    _link: Option<Arc<StableLink>>,
}

impl SimHandle {
    /// The path the host opens (the stable link if any, else `/dev/pts/N`).
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// A snapshot of the simulator's state.
    pub fn status(&self) -> SimStatus {
        self.status
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .clone()
    }

    /// Whether the simulator thread is still serving.
    pub fn is_running(&self) -> bool {
        self.thread.as_ref().is_some_and(|t| !t.is_finished())
    }

    /// Stop serving (closes the pseudo-terminal) and return the final state.
    pub fn stop(mut self) -> Result<SimStatus, RigError> {
        self.stop_inner()?;
        Ok(self.status())
    }

    /// Block until the simulator ends on its own (a permanent disconnect) or `stop` is
    /// set from elsewhere.
    pub fn wait(mut self) -> Result<SimStatus, RigError> {
        if let Some(t) = self.thread.take() {
            t.join()
                .map_err(|_| RigError::Pty("the simulator thread panicked".into()))??;
        }
        Ok(self.status())
    }

    fn stop_inner(&mut self) -> Result<(), RigError> {
        self.stop.store(true, Ordering::Relaxed);
        if let Some(t) = self.thread.take() {
            t.join()
                .map_err(|_| RigError::Pty("the simulator thread panicked".into()))??;
        }
        Ok(())
    }
}

impl Drop for SimHandle {
    fn drop(&mut self) {
        let _ = self.stop_inner();
    }
}

/// Start a simulated stepper bench on a new pseudo-terminal.
pub fn spawn(opts: SimStepperOptions) -> Result<SimHandle, RigError> {
    let pty = Pty::open()?;
    let link_path = opts.link.clone().or_else(|| {
        opts.plant.link.dropout_at_s.map(|_| {
            std::env::temp_dir().join(format!(
                "mpc-rig-sim-stepper-{}-{}",
                std::process::id(),
                pty.path()
                    .file_name()
                    .map_or_else(String::new, |n| n.to_string_lossy().into_owned())
            ))
        })
    });
    let link = match &link_path {
        Some(l) => Some(Arc::new(StableLink::create(l, pty.path())?)),
        None => None,
    };
    let path = link_path.unwrap_or_else(|| pty.path().to_path_buf());
    let stop = Arc::new(AtomicBool::new(false));
    let status = Arc::new(Mutex::new(SimStatus::default()));
    let (stop2, status2, link2) = (stop.clone(), status.clone(), link.clone());
    let thread = std::thread::Builder::new()
        .name("mpc-sim-stepper".into())
        .spawn(move || run(opts, pty, link2, stop2, status2))
        .map_err(|e| RigError::Pty(format!("cannot start the simulator thread: {e}")))?;
    Ok(SimHandle {
        path,
        stop,
        status,
        thread: Some(thread),
        _link: link,
    })
}

/// The simulator's loop state besides the firmware: the driver chip's step count turned
/// into the plant's follower and the sensor values. The emulated-board bench
/// ([`crate::rig::sim::pico`]) drives the same one from the board image's pins.
pub(in crate::rig::sim) struct Bench {
    pub(in crate::rig::sim) plant: Plant,
    mech: Mechanics,
    pub(in crate::rig::sim) chip: DriverChip,
    bus_a: SensorBus,
    bus_b: SensorBus,
    pub(in crate::rig::sim) quadrature: SimQuadrature,
    pub(in crate::rig::sim) last_steps: i64,
    pub(in crate::rig::sim) physical: i64,
    pub(in crate::rig::sim) missed: u64,
    last_step_change_us: u64,
    /// The driver's shaft is blocked (`driver_stall_at_s`): every step is lost.
    shaft_blocked: bool,
    external: Option<External>,
}

/// A driver turned by another device: its angle is read once per burst of simulation (at
/// the burst's end, which is the wall clock's now) and interpolated linearly for the
/// substeps in between, so sensor readings follow the driver within a substep rather than
/// a burst.
struct External {
    source: DriverAngleSource,
    /// (simulated µs, angle rad) at the previous burst's end.
    from: (u64, f64),
    /// (simulated µs, angle rad) at this burst's end.
    to: (u64, f64),
}

impl External {
    fn new(source: DriverAngleSource) -> Self {
        let phi = source();
        Self {
            source,
            from: (0, phi),
            to: (0, phi),
        }
    }

    /// Read the driver for a burst ending at `end_us`.
    fn begin_burst(&mut self, end_us: u64) {
        self.from = self.to;
        self.to = (end_us, (self.source)());
    }

    fn angle_at(&self, now_us: u64) -> f64 {
        let (t0, a0) = self.from;
        let (t1, a1) = self.to;
        if t1 <= t0 {
            return a1;
        }
        let w = (now_us.clamp(t0, t1) - t0) as f64 / (t1 - t0) as f64;
        a0 + w * (a1 - a0)
    }
}

impl Bench {
    /// A bench at rest whose follower obeys `plant` and whose sensors are those of `mech`.
    pub(in crate::rig::sim) fn new(
        plant: Plant,
        mech: Mechanics,
        chip: DriverChip,
        bus_a: SensorBus,
        bus_b: SensorBus,
        quadrature: SimQuadrature,
        external: Option<DriverAngleSource>,
    ) -> Bench {
        Bench {
            plant,
            mech,
            chip,
            bus_a,
            bus_b,
            quadrature,
            last_steps: 0,
            physical: 0,
            missed: 0,
            last_step_change_us: 0,
            shaft_blocked: false,
            external: external.map(External::new),
        }
    }

    /// Account new steps and refresh the sensors for the present physical angle.
    pub(in crate::rig::sim) fn update(&mut self, now_us: u64) {
        let steps = self.chip.pins().steps;
        let delta = steps - self.last_steps;
        if delta != 0 {
            self.last_step_change_us = now_us;
            for _ in 0..delta.unsigned_abs() {
                // A blocked shaft loses every step the firmware makes.
                if self.shaft_blocked || self.plant.step_missed() {
                    self.missed += 1;
                } else {
                    self.physical += delta.signum();
                }
            }
            self.last_steps = steps;
        }
        let phi = match &self.external {
            Some(driver) => driver.angle_at(now_us),
            None => {
                f64::from(self.mech.direction) * self.physical as f64
                    / self.mech.usteps_per_driver_rev()
                    * TAU
            }
        };
        let f = self.plant.follower(phi);
        if self.mech.as5600 || self.mech.as5600_b {
            let counts = self.plant.rotary_counts(f.angle_z, 4096.0);
            self.bus_a.set_as5600_angle(counts);
            self.bus_b.set_as5600_angle(counts);
        }
        if self.mech.imu {
            let q = self.plant.imu_reading(f.rotation * self.mech.imu_mounting);
            self.bus_a.set_quaternion([q.w, q.i, q.j, q.k]);
        }
        if let Some(mm) = self.mech.quadrature_mm_per_count {
            let c = self.plant.linear_counts(f.height, mm);
            self.quadrature.0.set(c as i32);
        }
    }
}

fn run(
    opts: SimStepperOptions,
    pty: Pty,
    link: Option<Arc<StableLink>>,
    stop: Arc<AtomicBool>,
    status: Arc<Mutex<SimStatus>>,
) -> Result<(), RigError> {
    let faults = opts.plant.link.clone();
    let mech = opts.mechanics.clone();
    let clock = SimClock::default();
    let chip = DriverChip::new(true);
    let hook = ReadHook::default();
    let bus_a = SensorBus::new(mech.as5600, mech.imu).with_read_hook(hook.clone());
    let bus_b = SensorBus::new(mech.as5600_b, false).with_read_hook(hook.clone());
    let quadrature = SimQuadrature(Default::default(), hook.clone());
    let bench = Rc::new(RefCell::new(Bench::new(
        Plant::new(opts.target.clone(), opts.plant.clone()),
        mech.clone(),
        chip.clone(),
        bus_a.clone(),
        bus_b.clone(),
        quadrature.clone(),
        opts.driver.clone(),
    )));
    let events = opts.plant.events.clone();
    let mut events_done = (false, false, false);
    bench.borrow_mut().update(0);
    {
        // Sensors read what the plant is at the read's instant. Weak: the bench owns the
        // buses that own the hook.
        let (weak, clock) = (Rc::downgrade(&bench), clock.clone());
        hook.set(Rc::new(move || {
            if let Some(b) = weak.upgrade() {
                b.borrow_mut().update(clock.get_us());
            }
        }));
    }
    let mut fw = firmware::Firmware::new(&mech, clock.clone(), chip, bus_a, bus_b, quadrature)?;
    let mut pty = Some(pty);
    let mut rewrite = faults
        .protocol_version
        .map(|v| (v, Decoder::<Report>::new()));
    let start = Instant::now();
    let mut sim_us: u64 = 0;
    let mut slip = Duration::ZERO;
    let mut inbuf = [0u8; 4096];
    let mut out = Vec::with_capacity(8192);
    let mut wire = Vec::with_capacity(8192);
    let mut dropout_until: Option<f64> = None;
    let mut dropped_out = false;
    let mut st = SimStatus::default();
    loop {
        if stop.load(Ordering::Relaxed) {
            break;
        }
        if let Some(p) = &pty {
            p.wait_readable(PACING);
        } else {
            std::thread::sleep(PACING);
        }
        let wall = start.elapsed().saturating_sub(slip);
        let mut target_us = wall.as_micros() as u64;
        if target_us > sim_us + MAX_CATCH_UP.as_micros() as u64 {
            let behind = target_us - sim_us - MAX_CATCH_UP.as_micros() as u64;
            slip += Duration::from_micros(behind);
            target_us = sim_us + MAX_CATCH_UP.as_micros() as u64;
        }
        // Host → device.
        if let Some(p) = pty.as_mut() {
            loop {
                let n = p.read_available(&mut inbuf)?;
                if n == 0 {
                    break;
                }
                st.bytes_in += n as u64;
                fw.receive(&inbuf[..n], sim_us);
            }
        }
        // Advance simulated time.
        if let Some(e) = bench.borrow_mut().external.as_mut() {
            e.begin_burst(target_us);
        }
        while sim_us + SUBSTEP_US <= target_us {
            sim_us += SUBSTEP_US;
            clock.set_us(sim_us);
            fw.poll(sim_us);
            st.polls += 1;
            bench.borrow_mut().update(sim_us);
        }
        // Device → host, through the faulty link.
        out.clear();
        fw.transmit(&mut out);
        if !out.is_empty() {
            if let Some((version, dec)) = rewrite.as_mut() {
                out = rewrite_hello(dec, *version, &out);
            }
            wire.clear();
            let mut link = bench.borrow_mut();
            for &b in &out {
                match link.plant.link_byte(b) {
                    LinkByte::Pass(x) => wire.push(x),
                    LinkByte::Corrupted(x) => {
                        st.bytes_corrupted += 1;
                        wire.push(x);
                    }
                    LinkByte::Dropped => st.bytes_dropped += 1,
                }
            }
            drop(link);
            if let Some(p) = pty.as_mut() {
                st.bytes_out += p.write_lossy(&wire)? as u64;
            }
        }
        // Faults of the driver and the mechanism (a board turning no driver has none of the
        // driver's).
        let t = sim_us as f64 / 1e6;
        {
            let due = |at: Option<f64>, done: &mut bool| {
                let now = at.is_some_and(|a| t >= a) && !*done;
                *done |= now;
                now
            };
            let mut b = bench.borrow_mut();
            let own_driver = b.external.is_none();
            if due(events.driver_fault_at_s, &mut events_done.0) && own_driver {
                b.chip.fail_step_output();
            }
            if due(events.driver_stall_at_s, &mut events_done.1) && own_driver {
                b.shaft_blocked = true;
            }
            if due(events.jam_at_s, &mut events_done.2) {
                b.plant.jam();
            }
        }
        // Unplug and re-plug.
        if let Some(at) = faults.disconnect_at_s {
            if t >= at && !st.disconnected {
                st.disconnected = true;
                drop(pty);
                if let Some(l) = &link {
                    l.remove();
                }
                publish(&status, &st, &bench.borrow(), sim_us);
                tracing::info!("simulated stepper bench unplugged at {t:.3} s");
                return Ok(());
            }
        }
        if let (Some(at), false) = (faults.dropout_at_s, dropped_out) {
            if t >= at {
                dropped_out = true;
                dropout_until = Some(t + faults.dropout_s);
                pty = None;
                if let Some(l) = &link {
                    l.remove();
                }
                st.dropouts += 1;
                tracing::info!("simulated stepper bench drop-out at {t:.3} s");
            }
        }
        if let Some(until) = dropout_until {
            if t >= until {
                dropout_until = None;
                let p = Pty::open()?;
                if let Some(l) = &link {
                    l.point_to(p.path())?;
                }
                pty = Some(p);
                tracing::info!("simulated stepper bench back at {t:.3} s");
            }
        }
        publish(&status, &st, &bench.borrow(), sim_us);
    }
    Ok(())
}

fn publish(status: &Mutex<SimStatus>, st: &SimStatus, bench: &Bench, now_us: u64) {
    let mut s = status.lock().unwrap_or_else(|p| p.into_inner());
    *s = st.clone();
    s.time_s = now_us as f64 / 1e6;
    s.steps = bench.last_steps;
    s.physical_steps = bench.physical;
    s.missed_steps = bench.missed;
    s.enabled = bench.chip.enabled();
    s.moving = now_us.saturating_sub(bench.last_step_change_us) < 50_000 && bench.last_steps != 0;
}

/// Re-encode the device's frames, claiming protocol version `version` in its `Hello`
/// (the `protocol_version` fault, to exercise the host's version check).
fn rewrite_hello(dec: &mut Decoder<Report>, version: u16, bytes: &[u8]) -> Vec<u8> {
    let mut out = Vec::with_capacity(bytes.len());
    dec.feed(bytes, |r| {
        if let Ok(mut f) = r {
            if let Report::Hello(info) = &mut f.msg {
                info.protocol_version = version;
            }
            if let Ok(v) = mpc_wire::encode_frame_vec(f.seq, &f.msg) {
                out.extend_from_slice(&v);
            }
        }
    });
    out
}

/// The adapter to the real firmware core.
mod firmware {
    use mpc_firmware_core::platform::{BoardConfig, Clock, Parts, Platform, QuadratureCounter};
    use mpc_firmware_core::Device;

    use super::i2c::SensorBus;
    use super::pins::{DirPin, DriverChip, EnablePin, NoDelay, SimClock, SimQuadrature, StepPin};
    use super::{Mechanics, SIM_BOARD_NAME, SIM_MAX_STEP_RATE_HZ};
    use crate::rig::RigError;

    impl Clock for SimClock {
        fn now_us(&self) -> u64 {
            self.get_us()
        }
    }

    impl QuadratureCounter for SimQuadrature {
        fn count(&mut self) -> i32 {
            self.1.fire();
            self.0.get()
        }
    }

    /// The simulated board's parts.
    pub struct SimPlatform;

    impl Platform for SimPlatform {
        type I2cA = SensorBus;
        type I2cB = SensorBus;
        type Step = StepPin;
        type Dir = DirPin;
        type Enable = EnablePin;
        type Delay = NoDelay;
        type Clock = SimClock;
        type Quadrature = SimQuadrature;
    }

    /// The firmware core on emulated parts.
    pub struct Firmware {
        device: Device<SimPlatform>,
        buf: Vec<u8>,
    }

    impl Firmware {
        pub fn new(
            mech: &Mechanics,
            clock: SimClock,
            chip: DriverChip,
            bus_a: SensorBus,
            bus_b: SensorBus,
            quadrature: SimQuadrature,
        ) -> Result<Firmware, RigError> {
            let board = BoardConfig::new(SIM_BOARD_NAME, mech.fitted(), SIM_MAX_STEP_RATE_HZ);
            let parts = Parts::<SimPlatform> {
                i2c_a: bus_a,
                i2c_b: bus_b,
                step: chip.step_pin(),
                dir: chip.dir_pin(),
                enable: chip.enable_pin(),
                delay: NoDelay,
                clock,
                quadrature,
            };
            Ok(Firmware {
                device: Device::new(parts, board),
                buf: vec![0; 4096],
            })
        }

        /// Bytes from the host.
        pub fn receive(&mut self, bytes: &[u8], _now_us: u64) {
            self.device.receive(bytes);
        }

        /// Run everything due up to the clock's time.
        pub fn poll(&mut self, _now_us: u64) {
            self.device.poll();
        }

        /// Append the queued output bytes to `out`.
        pub fn transmit(&mut self, out: &mut Vec<u8>) {
            loop {
                let n = self.device.transmit(&mut self.buf);
                if n == 0 {
                    break;
                }
                out.extend_from_slice(&self.buf[..n]);
            }
        }
    }
}
