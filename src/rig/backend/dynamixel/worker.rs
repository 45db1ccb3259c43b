//! The bus thread: `dynamixel2` is blocking, so one thread owns the serial bus and everyone
//! else talks to it through a channel.
//!
//! Owns the [`dynamixel2::Bus`], runs jobs sent by the backend (one transaction each, in
//! order), keeps the servos' bus watchdog fed with a heartbeat when idle, and while
//! streaming performs one sync read per sample period of the indirect block every servo
//! was set up with (realtime tick, present velocity, present position). It keeps the
//! device clock (the driver's realtime tick unwrapped by `tick`), counts failed
//! transactions as gaps and CRC failures, declares the link lost after a run of failures,
//! and turns the driver's torque off when the backend goes away (dropped, or the process
//! unwinding). A panic inside `dynamixel2` on malformed input (a length byte damaged by
//! noise) is caught: a failed transaction, retried or counted like a damaged reply.
//!
//! It does not decide what to command (that is [`super::DynamixelBench`]).

use std::sync::mpsc::{self, Receiver, RecvTimeoutError, Sender};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use dynamixel2::{ReadError, TransferError};

use super::tick::TickClock;
use crate::rig::recording::{flags, Counts};

/// The bus type the worker owns.
pub type DxlBus = dynamixel2::Bus<Vec<u8>, Vec<u8>>;

/// First Indirect Data address (Indirect Data 1): the streamed block is read from here.
pub const STREAM_BLOCK_ADDRESS: u16 = 224;

/// First Indirect Address item (Indirect Address 1), 2 bytes per entry.
pub const INDIRECT_ADDRESS_1: u16 = 168;

/// The control-table bytes mapped into the streamed block, in order: Realtime Tick (120,
/// 2 bytes), Present Velocity (128, 4 bytes), Moving (122, 1 byte), Present Position (132,
/// 4 bytes).
///
/// Moving (always 0 or 1) sits between velocity and position on purpose: `dynamixel2` 0.9.1
/// fails to remove byte stuffing after a run of three `FF` (its matcher restarts from
/// scratch instead of from the last `FF`), so a small negative velocity (`xx FF FF FF`)
/// directly followed by a position byte `FD` would be misread. With the separator, and with
/// the tick's high byte below 0x80 and |velocity| ≤ 1023, no in-range block contains
/// `FF FF FF FD` (guarded by a test below).
pub const STREAM_SOURCES: [u16; 11] = [120, 121, 128, 129, 130, 131, 122, 132, 133, 134, 135];

/// Offset of Present Velocity in the streamed block.
const BLOCK_VELOCITY: usize = 2;
/// Offset of Present Position in the streamed block.
const BLOCK_POSITION: usize = 7;

/// Length of the streamed block, bytes.
pub const STREAM_BLOCK_LEN: u16 = STREAM_SOURCES.len() as u16;

/// Consecutive failed transactions after which the link counts as lost. Default 25: at
/// 100 Hz a quarter second of silence — longer than any CRC burst of a noisy but working
/// bus, shorter than the default 250 ms bus watchdog plus a margin would let a host drift.
pub const LOST_AFTER_FAILURES: u32 = 25;

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
    /// Whether the driver set the alert bit in its reply (a hardware error is latched).
    pub alert: bool,
    /// On the first sample after failed reads: how long the bus was silent (the servos'
    /// bus watchdog may have stopped the driver meanwhile).
    pub resumed_after: Option<Duration>,
    /// Host-clock estimate of when the driver latched the sample: the arrival of its reply
    /// minus its return delay and the reply's wire time.
    pub host_instant: Instant,
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
    /// Driver servo ID.
    pub driver_id: u8,
    /// Follower servo IDs, in sensor order.
    pub follower_ids: Vec<u8>,
    /// Heartbeat period when idle (keeps the bus watchdog fed).
    pub heartbeat: Duration,
    /// Bus baud rate (for the wire time of a reply).
    pub baud: u32,
}

/// Return Delay Time (address 9), 2 µs per count; the factory value 250 (500 µs) is
/// assumed when it cannot be read.
const RETURN_DELAY_TIME: u16 = 9;

/// Factory Return Delay Time, counts of 2 µs.
pub const FACTORY_RETURN_DELAY: u8 = 250;

/// Time from the driver latching a streamed sample to its reply having crossed the wire:
/// the return delay plus the status packet (11 framing bytes and the block) at 10 bits
/// per byte.
pub fn reply_latency(return_delay_counts: u8, baud: u32) -> Duration {
    let wire_s = (11.0 + f64::from(STREAM_BLOCK_LEN)) * 10.0 / f64::from(baud.max(1));
    Duration::from_micros(u64::from(return_delay_counts) * 2) + Duration::from_secs_f64(wire_s)
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
    /// [`reply_latency`] of the driver.
    latency: Duration,
    period: Duration,
    next_due: Instant,
    /// The driver's Realtime Tick, unwrapped.
    clock: TickClock,
    last_followers: Vec<i32>,
    failures_in_a_row: u32,
    gap_pending: bool,
    /// When the last sample was read successfully.
    last_success: Instant,
}

/// Why the worker thread ended early, for the errors of calls made after it: set when
/// `dynamixel2` panicked on something read from the bus.
pub type Fatal = Arc<Mutex<Option<String>>>;

/// `dynamixel2` panicked while parsing what it read: its message. `dynamixel2` 0.9.1 does
/// not check a status packet's length field before using it, so a length byte damaged by
/// line noise (or an echoed instruction, see `super::echo`) panics inside `Bus`
/// (docs/faults.md). The bus itself stays usable: the next instruction clears its read
/// buffer.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("the Dynamixel library panicked reading a reply ({0})")]
pub struct LibraryPanic(pub String);

/// Name of the bus thread.
pub const THREAD_NAME: &str = "dynamixel-bus";

/// Keep the panics of `dynamixel2` that the bus thread catches ([`transaction`]) out of
/// the terminal: they are failed transactions, reported as such, not crashes. Installed once
/// per process; every other panic goes to the hook that was there before.
pub fn quiet_caught_library_panics() {
    static ONCE: std::sync::Once = std::sync::Once::new();
    ONCE.call_once(|| {
        let previous = std::panic::take_hook();
        std::panic::set_hook(Box::new(move |info| {
            let ours = std::thread::current().name() == Some(THREAD_NAME)
                && info
                    .location()
                    .is_some_and(|l| l.file().contains("dynamixel2"));
            if ours {
                tracing::debug!("dynamixel2 panicked (caught): {info}");
            } else {
                previous(info);
            }
        }));
    });
}

fn panic_message(p: Box<dyn std::any::Any + Send>) -> String {
    p.downcast_ref::<&str>()
        .map(|s| s.to_string())
        .or_else(|| p.downcast_ref::<String>().cloned())
        .unwrap_or_else(|| "no message".into())
}

/// Run `f` on the bus, with a panic inside `dynamixel2` caught as [`LibraryPanic`].
fn catch<T>(f: impl FnOnce() -> T) -> Result<T, LibraryPanic> {
    std::panic::catch_unwind(std::panic::AssertUnwindSafe(f))
        .map_err(|p| LibraryPanic(panic_message(p)))
}

/// One transaction, with a panic inside `dynamixel2` returned as a failed read (an I/O
/// error carrying [`LibraryPanic`]) that the caller may retry like a damaged reply.
pub fn transaction<T>(f: impl FnOnce() -> Result<T, TransferError>) -> Result<T, TransferError> {
    catch(f).unwrap_or_else(|p| {
        Err(TransferError::ReadError(ReadError::Io(
            std::io::Error::other(p),
        )))
    })
}

/// Whether a failed transaction is a caught [`LibraryPanic`].
pub fn is_library_panic(e: &TransferError) -> bool {
    matches!(e, TransferError::ReadError(ReadError::Io(io))
        if io.get_ref().is_some_and(|inner| inner.is::<LibraryPanic>()))
}

/// Run the worker until [`Message::Quit`] or the sender is dropped. A panic of `dynamixel2`
/// inside a transaction counts as a failed transaction ([`transaction`]); one anywhere else
/// in a job ends the worker: the stream ends with [`Event::Lost`], `fatal` says why, and the
/// driver's torque is switched off if the bus still answers.
pub fn run(
    mut bus: DxlBus,
    setup: WorkerSetup,
    rx: Receiver<Message>,
    events: Sender<Event>,
    counts: Arc<Mutex<Counts>>,
    fatal: Fatal,
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
                // Transactions in jobs catch the library's panics themselves (retried like
                // damaged replies); one that escapes anything else ends the worker.
                if let Err(p) = catch(|| job(&mut bus)) {
                    fail(&fatal, &events, format!("{p} outside a transaction"));
                    break;
                }
                last_traffic = Instant::now();
                continue;
            }
            Ok(Message::Start(period)) => {
                let delay = transaction(|| bus.read_u8(setup.driver_id, RETURN_DELAY_TIME))
                    .map_or(FACTORY_RETURN_DELAY, |r| r.data);
                stream = Some(Streamer {
                    latency: reply_latency(delay, setup.baud),
                    period,
                    next_due: Instant::now(),
                    clock: TickClock::new(),
                    last_followers: vec![0; setup.follower_ids.len()],
                    failures_in_a_row: 0,
                    gap_pending: false,
                    last_success: Instant::now(),
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
                    let _ = events.send(Event::Lost(message));
                    stream = None;
                }
            }
            None => {
                // Heartbeat: any instruction resets the servos' bus watchdog timers.
                let _ = transaction(|| bus.ping(setup.driver_id));
                last_traffic = Instant::now();
            }
        }
    }
    // Last line of defence besides the servo's own bus watchdog: torque off on the way out.
    let _ = transaction(|| bus.write_u8(setup.driver_id, 64, 0));
}

/// Record why the worker ends and end any stream with it.
fn fail(fatal: &Fatal, events: &Sender<Event>, message: String) {
    tracing::error!("{message}");
    *fatal.lock().unwrap_or_else(|p| p.into_inner()) = Some(message.clone());
    let _ = events.send(Event::Lost(message));
}

/// Margin added to a sync read's reply time in [`quiet_time`]. Default 2 ms: a few
/// scheduler ticks, and the order of a USB adapter's latency timer.
pub const QUIET_MARGIN: Duration = Duration::from_millis(2);

/// How long the worker waits after a failed sync read before the next one: the time all
/// `replies` (each [`reply_latency`] long) take to cross the wire, plus [`QUIET_MARGIN`].
/// The next instruction discards whatever arrived by then. Without the wait, a reply that
/// came late (after a stall of the adapter or of a loaded machine) landed after that discard
/// and was read as the next sync read's first reply; each sync read then read the previous
/// one's follower reply as its driver reply, and the link was declared lost after
/// [`LOST_AFTER_FAILURES`] failures ("invalid packet ID, expected 0x1, got 0x2").
pub fn quiet_time(reply_latency: Duration, replies: usize) -> Duration {
    reply_latency * replies as u32 + QUIET_MARGIN
}

/// One sync read; returns `Some(message)` when the stream must end: the link is lost, or
/// the driver rebooted (see `tick`).
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
    let mut driver_reply_at = None;
    let sent = catch(|| {
        bus.sync_read_cb(ids, STREAM_BLOCK_ADDRESS, STREAM_BLOCK_LEN, |r| match r {
            Ok(resp) => {
                if resp.motor_id == ids[0] {
                    driver_reply_at = Some(Instant::now());
                }
                if let Some(k) = ids.iter().position(|&id| id == resp.motor_id) {
                    if k == 0 {
                        alert = resp.alert;
                    }
                    blocks[k] = Some(resp.data.to_vec());
                }
            }
            Err(e) => {
                if failure.is_none() {
                    failure = Some(describe(&TransferError::ReadError(e)));
                }
            }
        })
    });
    match sent {
        Ok(Ok(())) => {}
        Ok(Err(e)) => failure = Some((false, format!("cannot send to the bus: {e}"))),
        // A reply the library cannot parse: a failed read like a damaged one.
        Err(p) => failure = Some((false, p.to_string())),
    }
    if failure.is_some() || blocks.iter().any(Option::is_none) {
        // Let late replies arrive before the next instruction discards the input.
        std::thread::sleep(quiet_time(s.latency, ids.len()));
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
    if let Err(restarted) = s.clock.advance(tick, s.last_success.elapsed()) {
        return Some(restarted.to_string());
    }
    let mut sample_flags = 0;
    let mut resumed_after = None;
    if s.gap_pending {
        sample_flags |= flags::GAP_BEFORE;
        s.gap_pending = false;
        resumed_after = Some(s.last_success.elapsed());
    }
    s.last_success = Instant::now();
    let mut followers = Vec::with_capacity(ids.len() - 1);
    for (k, block) in blocks.iter().enumerate().skip(1) {
        match block {
            Some(b) => {
                let p = block_i32(b, BLOCK_POSITION);
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
        device_time_us: s.clock.time_ms() * 1000,
        driver_velocity: block_i32(driver, BLOCK_VELOCITY),
        driver_position: block_i32(driver, BLOCK_POSITION),
        followers,
        flags: sample_flags,
        alert,
        resumed_after,
        host_instant: driver_reply_at
            .unwrap_or_else(Instant::now)
            .checked_sub(s.latency)
            .unwrap_or_else(Instant::now),
    }));
    None
}

fn block_i32(b: &[u8], at: usize) -> i32 {
    i32::from_le_bytes([b[at], b[at + 1], b[at + 2], b[at + 3]])
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

#[cfg(test)]
mod tests {
    use super::*;

    /// Guards the last resort against `dynamixel2`'s panics: a transaction that panics
    /// comes back as an error marked as the library's panic, with its message, which the
    /// backend retries like a damaged reply, and the thread goes on.
    #[test]
    fn a_panicking_transaction_is_a_failed_one() {
        let r: Result<(), TransferError> =
            transaction(|| panic!("slice index starts at 9 but ends at 8"));
        let e = r.unwrap_err();
        assert!(is_library_panic(&e), "{e}");
        assert!(e.to_string().contains("starts at 9"), "{e}");
        let ok: Result<u8, TransferError> = transaction(|| Ok(7));
        assert_eq!(ok.unwrap(), 7);
    }

    /// The block as a servo sends it, preceded by the status error byte.
    fn block(tick: u16, velocity: i32, moving: u8, position: i32) -> Vec<u8> {
        let mut b = vec![0x80]; // error field with the alert bit: the worst case
        b.extend_from_slice(&tick.to_le_bytes());
        b.extend_from_slice(&velocity.to_le_bytes());
        b.push(moving);
        b.extend_from_slice(&position.to_le_bytes());
        b
    }

    fn has_triple_ff_fd(b: &[u8]) -> bool {
        b.windows(4).any(|w| w == [0xFF, 0xFF, 0xFF, 0xFD])
    }

    /// Guards the stream layout against dynamixel2's unstuffing bug: no in-range block
    /// (tick < 32768, |velocity| ≤ 1023, any position within ±8191 turns) contains the
    /// `FF FF FF FD` run it misreads — while the naive layout (velocity then position) does.
    #[test]
    fn stream_block_never_contains_the_pattern_dynamixel2_misreads() {
        assert_eq!(STREAM_SOURCES.len(), usize::from(STREAM_BLOCK_LEN));
        assert_eq!(STREAM_SOURCES[BLOCK_VELOCITY], 128);
        assert_eq!(STREAM_SOURCES[BLOCK_POSITION], 132);
        // Positions around zero and around the byte values that stuff (FD, FF), plus a
        // sweep of the multi-turn range.
        let mut positions: Vec<i32> = (-260..260).step_by(3).collect();
        positions.extend([
            0x00FD_FFFF,
            -131_073,
            -3,
            0x01FD,
            -0x0203,
            0x7FFF_FFFD_u32 as i32,
        ]);
        positions.extend((-8191 * 4096..8191 * 4096).step_by(409_597));
        for v in -1023..=1023 {
            for &p in &positions {
                for tick in [0x00FFu16, 0x7FFF] {
                    for moving in [0u8, 1] {
                        let b = block(tick, v, moving, p);
                        assert!(!has_triple_ff_fd(&b), "v={v} p={p} tick={tick}");
                    }
                }
            }
        }
        // Without the separator, velocity −1 followed by a position whose low byte is FD
        // produces the run.
        let mut naive = (-1i32).to_le_bytes().to_vec();
        naive.extend_from_slice(&0x0000_01FDi32.to_le_bytes());
        assert!(has_triple_ff_fd(&naive));
    }
}
