//! The bus thread: `dynamixel2` is blocking, so one thread owns the serial bus and everyone
//! else talks to it through a channel.
//!
//! Owns the [`dynamixel2::Bus`], runs jobs sent by the backend (one transaction each, in
//! order), keeps the servos' bus watchdog fed with a heartbeat when idle, and while
//! streaming performs one sync read per sample period of the indirect block every servo
//! was set up with (realtime tick, present velocity, present position). It unwraps the
//! driver's realtime tick into the device clock, counts failed transactions as gaps and
//! CRC failures, declares the link lost after a run of failures, and turns the driver's
//! torque off when the backend goes away (dropped, or the process unwinding).
//!
//! It does not decide what to command (that is [`super::DynamixelBench`]).

use std::path::PathBuf;
use std::sync::mpsc::{self, Receiver, RecvTimeoutError, Sender};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use dynamixel2::{ReadError, TransferError};

use crate::rig::recording::{flags, Counts};

/// The bus type the worker owns.
pub type DxlBus = dynamixel2::Bus<Vec<u8>, Vec<u8>>;

/// First Indirect Data address (Indirect Data 1): the streamed block is read from here.
pub const STREAM_BLOCK_ADDRESS: u16 = 224;

/// First Indirect Address item (Indirect Address 1), 2 bytes per entry.
pub const INDIRECT_ADDRESS_1: u16 = 168;

/// The control-table bytes mapped into the streamed block, in order: Realtime Tick (120,
/// 2 bytes), Present Velocity (128, 4 bytes), Present Position (132, 4 bytes).
pub const STREAM_SOURCES: [u16; 10] = [120, 121, 128, 129, 130, 131, 132, 133, 134, 135];

/// Length of the streamed block, bytes.
pub const STREAM_BLOCK_LEN: u16 = STREAM_SOURCES.len() as u16;

/// Consecutive failed transactions after which the link counts as lost. Default 25: at
/// 100 Hz a quarter second of silence — longer than any CRC burst of a noisy but working
/// bus, shorter than the default 250 ms bus watchdog plus a margin would let a host drift.
pub const LOST_AFTER_FAILURES: u32 = 25;

/// Largest acceptable jump of the driver's Realtime Tick between samples before it counts
/// as a reboot of the servo rather than time passing. Default 5 s.
pub const MAX_TICK_STEP_MS: u64 = 5_000;

/// One streamed reading of the bus.
#[derive(Debug, Clone, PartialEq)]
pub struct RawSample {
    /// Driver realtime tick unwrapped, µs since the stream started.
    pub device_time_us: u64,
    /// Driver present position (pulses).
    pub driver_position: i32,
    /// Driver present velocity (0.229 rpm units).
    pub driver_velocity: i32,
    /// Follower present positions (pulses), in the order the followers were given.
    pub followers: Vec<i32>,
    /// [`flags`] bits decided by the worker (gap before, follower stale).
    pub flags: u32,
    /// Whether any servo set the alert bit (a hardware error is latched).
    pub alert: bool,
}

/// What the worker reports while streaming.
#[derive(Debug, Clone, PartialEq)]
pub enum Event {
    /// A sample.
    Sample(RawSample),
    /// The link is gone (after [`LOST_AFTER_FAILURES`] failures in a row).
    Lost(String),
}

/// A unit of work on the bus.
pub type Job = Box<dyn FnOnce(&mut DxlBus) + Send>;

/// Messages to the worker.
pub enum Message {
    /// Run a job.
    Job(Job),
    /// Start streaming at this period.
    Start(Duration),
    /// Stop streaming.
    Stop,
    /// Turn the driver's torque off and end the thread.
    Quit,
}

/// Static description of the bus the worker serves.
#[derive(Debug, Clone)]
pub struct WorkerSetup {
    /// Port path (for messages).
    pub path: PathBuf,
    /// Driver servo ID.
    pub driver_id: u8,
    /// Follower servo IDs, in sensor order.
    pub follower_ids: Vec<u8>,
    /// Heartbeat period when idle (keeps the bus watchdog fed).
    pub heartbeat: Duration,
}

/// Classify a failed transaction: (is a CRC failure, message).
pub fn describe(e: &TransferError) -> (bool, String) {
    let crc = matches!(
        e,
        TransferError::ReadError(ReadError::InvalidMessage(
            dynamixel2::InvalidMessage::InvalidChecksum(_)
        ))
    );
    (crc, e.to_string())
}

struct Streamer {
    period: Duration,
    next_due: Instant,
    last_tick: Option<u16>,
    time_ms: u64,
    last_followers: Vec<i32>,
    failures_in_a_row: u32,
    gap_pending: bool,
}

/// Run the worker until [`Message::Quit`] or the sender is dropped.
pub fn run(
    mut bus: DxlBus,
    setup: WorkerSetup,
    rx: Receiver<Message>,
    events: Sender<Event>,
    counts: Arc<Mutex<Counts>>,
) {
    let ids: Vec<u8> = std::iter::once(setup.driver_id)
        .chain(setup.follower_ids.iter().copied())
        .collect();
    let mut stream: Option<Streamer> = None;
    let mut last_traffic = Instant::now();
    loop {
        let timeout = match &stream {
            Some(s) => s.next_due.saturating_duration_since(Instant::now()),
            None => setup.heartbeat.saturating_sub(last_traffic.elapsed()),
        };
        match rx.recv_timeout(timeout) {
            Ok(Message::Job(job)) => {
                job(&mut bus);
                last_traffic = Instant::now();
                continue;
            }
            Ok(Message::Start(period)) => {
                stream = Some(Streamer {
                    period,
                    next_due: Instant::now(),
                    last_tick: None,
                    time_ms: 0,
                    last_followers: vec![0; setup.follower_ids.len()],
                    failures_in_a_row: 0,
                    gap_pending: false,
                });
                continue;
            }
            Ok(Message::Stop) => {
                stream = None;
                continue;
            }
            Ok(Message::Quit) | Err(RecvTimeoutError::Disconnected) => break,
            Err(RecvTimeoutError::Timeout) => {}
        }
        match &mut stream {
            Some(s) => {
                let lost = sample_once(&mut bus, &ids, s, &events, &counts);
                last_traffic = Instant::now();
                let now = Instant::now();
                s.next_due += s.period;
                if s.next_due < now {
                    // The bus is slower than the requested rate: sample back to back.
                    s.next_due = now;
                }
                if let Some(message) = lost {
                    let _ =
                        events.send(Event::Lost(format!("{}: {message}", setup.path.display())));
                    stream = None;
                }
            }
            None => {
                // Heartbeat: any instruction resets the servos' bus watchdog timers.
                let _ = bus.ping(setup.driver_id);
                last_traffic = Instant::now();
            }
        }
    }
    // Last line of defence besides the servo's own bus watchdog: torque off on the way out.
    let _ = bus.write_u8(setup.driver_id, 64, 0);
}

/// One sync read; returns `Some(message)` when the link is to be considered lost.
fn sample_once(
    bus: &mut DxlBus,
    ids: &[u8],
    s: &mut Streamer,
    events: &Sender<Event>,
    counts: &Mutex<Counts>,
) -> Option<String> {
    let mut blocks: Vec<Option<Vec<u8>>> = vec![None; ids.len()];
    let mut alert = false;
    let mut failure: Option<(bool, String)> = None;
    let sent = bus.sync_read_cb(ids, STREAM_BLOCK_ADDRESS, STREAM_BLOCK_LEN, |r| match r {
        Ok(resp) => {
            if let Some(k) = ids.iter().position(|&id| id == resp.motor_id) {
                alert |= resp.alert;
                blocks[k] = Some(resp.data.to_vec());
            }
        }
        Err(e) => {
            if failure.is_none() {
                failure = Some(describe(&TransferError::ReadError(e)));
            }
        }
    });
    if let Err(e) = sent {
        failure = Some((false, format!("cannot send to the bus: {e}")));
    }
    let mut c = counts.lock().unwrap_or_else(|p| p.into_inner());
    if let Some((true, _)) = &failure {
        c.crc_errors += 1;
    }
    let Some(driver) = blocks[0].as_ref() else {
        // No driver reading: this sample is lost.
        s.failures_in_a_row += 1;
        if !s.gap_pending {
            c.gaps += 1;
        }
        c.missing_samples += 1;
        s.gap_pending = true;
        if s.failures_in_a_row >= LOST_AFTER_FAILURES {
            let why = failure.map_or_else(|| "no reply".to_string(), |f| f.1);
            return Some(format!(
                "{} transactions failed in a row (last: {why})",
                s.failures_in_a_row
            ));
        }
        return None;
    };
    s.failures_in_a_row = 0;
    let tick = u16::from_le_bytes([driver[0], driver[1]]);
    if let Some(prev) = s.last_tick {
        let step = u64::from(tick.wrapping_sub(prev) & 0x7FFF);
        if step <= MAX_TICK_STEP_MS {
            s.time_ms += step;
        }
    }
    s.last_tick = Some(tick);
    let mut sample_flags = 0;
    if s.gap_pending {
        sample_flags |= flags::GAP_BEFORE;
        s.gap_pending = false;
    }
    let mut followers = Vec::with_capacity(ids.len() - 1);
    for (k, block) in blocks.iter().enumerate().skip(1) {
        match block {
            Some(b) => {
                let p = i32::from_le_bytes([b[6], b[7], b[8], b[9]]);
                s.last_followers[k - 1] = p;
                followers.push(p);
            }
            None => {
                sample_flags |= flags::FOLLOWER_STALE;
                followers.push(s.last_followers[k - 1]);
            }
        }
    }
    c.samples += 1;
    drop(c);
    let _ = events.send(Event::Sample(RawSample {
        device_time_us: s.time_ms * 1000,
        driver_velocity: i32::from_le_bytes([driver[2], driver[3], driver[4], driver[5]]),
        driver_position: i32::from_le_bytes([driver[6], driver[7], driver[8], driver[9]]),
        followers,
        flags: sample_flags,
        alert,
    }));
    None
}

/// Run `f` on the worker and wait for its result.
pub fn call<T: Send + 'static>(
    tx: &Sender<Message>,
    f: impl FnOnce(&mut DxlBus) -> T + Send + 'static,
) -> Option<T> {
    let (rtx, rrx) = mpsc::channel();
    tx.send(Message::Job(Box::new(move |bus| {
        let _ = rtx.send(f(bus));
    })))
    .ok()?;
    rrx.recv().ok()
}
