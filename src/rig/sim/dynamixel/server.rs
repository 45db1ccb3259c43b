//! The simulated bus behind a pseudo-terminal: a thread that reads instruction packets from
//! the pty master, lets the [`Bus`] answer them in real time, and writes status packets
//! back, optionally paced at the control table's baud rate and with injected link faults
//! (including an adapter that echoes what the host sends).
//!
//! The simulator keeps its own handle on the pty slave open, so a client closing and
//! reopening the port (as hosts do between runs) never ends the simulation; a pty has no
//! baud rate, so the device answers whatever baud the client configured.
//!
//! Does not own what a reply contains (that is [`Bus`]) nor the byte framing (that is
//! [`super::packet`]).

use std::fs::File;
use std::io::{Read, Write};
use std::os::fd::{AsFd, OwnedFd};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use super::bus::Bus;
use super::packet::{Decoded, Decoder};
use crate::rig::sim::plant::{LinkByte, LinkFaults, Plant};
use crate::rig::RigError;
use nix::poll::{poll, PollFd, PollFlags, PollTimeout};

/// Inter-byte timeout after which a partial packet is discarded. Default 100 ms: far longer
/// than any gap inside a packet from a host, short enough to recover quickly from a
/// truncated packet.
pub const PARTIAL_PACKET_TIMEOUT: Duration = Duration::from_millis(100);

/// How long the server thread waits for input before advancing the mechanics anyway.
/// Default 2 ms: the follower keeps moving smoothly between host requests.
pub const IDLE_POLL: Duration = Duration::from_millis(2);

/// The last stretch of a wait spent spinning instead of sleeping. Default 100 µs: about
/// the overshoot of a thread sleep on a loaded Linux machine.
pub const SPIN_MARGIN: Duration = Duration::from_micros(100);

/// A hardware error to raise on a servo at a given time (e.g. an overload mid-run).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HardwareFault {
    /// Seconds after start.
    pub at_s: f64,
    /// Which servo: `true` for the driver, `false` for the follower.
    pub driver: bool,
    /// Hardware Error Status bits to latch.
    pub bits: u8,
}

/// Server behaviour.
#[derive(Debug, Clone, PartialEq)]
pub struct ServerOptions {
    /// Pace the bus at the baud rate in the driver's control table, as a real half-duplex
    /// bus is: act on an instruction only after its transmission time, and send each status
    /// packet after its own. Default true.
    pub pace_wire: bool,
    /// Hardware faults to inject.
    pub hardware_faults: Vec<HardwareFault>,
}

impl Default for ServerOptions {
    fn default() -> Self {
        Self {
            pace_wire: true,
            hardware_faults: Vec::new(),
        }
    }
}

/// Seconds to transmit `bytes` at `baud` (10 bits per byte: start, 8 data, stop).
pub fn wire_time_s(bytes: usize, baud: u32) -> f64 {
    bytes as f64 * 10.0 / f64::from(baud.max(1))
}

/// Why the server thread ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ServerEnd {
    /// `stop()` was called or the handle dropped.
    Stopped,
    /// The configured disconnect time was reached; the pty was closed.
    Disconnected,
}

pub(super) struct Server {
    pub master: File,
    pub slave: OwnedFd,
    pub bus: Arc<Mutex<Bus>>,
    /// The plant, shared with the follower law: its link faults apply to every status byte.
    pub plant: Arc<Mutex<Plant>>,
    pub options: ServerOptions,
    pub stop: Arc<AtomicBool>,
    /// Time zero of the bus's simulation clock.
    pub start: Instant,
}

impl Server {
    pub fn spawn(self) -> Result<JoinHandle<ServerEnd>, RigError> {
        std::thread::Builder::new()
            .name("sim-dynamixel".into())
            .spawn(move || self.run())
            .map_err(|e| RigError::Pty(format!("spawning the simulator thread: {e}")))
    }

    fn run(mut self) -> ServerEnd {
        let start = self.start;
        let link: LinkFaults = lock(&self.plant).config().link.clone();
        let mut reboot_at = link.reboot_at_s;
        let mut decoder = Decoder::new();
        let mut last_byte = Instant::now();
        let mut buf = [0u8; 4096];
        let events = lock(&self.plant).config().events.clone();
        let mut pending_faults = self.options.hardware_faults.clone();
        if let Some(at_s) = events.driver_fault_at_s {
            pending_faults.push(HardwareFault {
                at_s,
                driver: true,
                bits: super::control_table::hw_error::OVERLOAD,
            });
        }
        pending_faults.sort_by(|a, b| a.at_s.total_cmp(&b.at_s));
        let mut stall_at = events.driver_stall_at_s;
        let mut jam_at = events.jam_at_s;
        let end = loop {
            if self.stop.load(Ordering::Relaxed) {
                break ServerEnd::Stopped;
            }
            let t = start.elapsed().as_secs_f64();
            if link.disconnect_at_s.is_some_and(|d| t >= d) {
                break ServerEnd::Disconnected;
            }
            // A brief drop-out: the device neither hears nor answers for a while.
            let silent = link
                .dropout_at_s
                .is_some_and(|d| t >= d && t < d + link.dropout_s);
            while pending_faults.first().is_some_and(|f| f.at_s <= t) {
                let f = pending_faults.remove(0);
                let mut bus = lock(&self.bus);
                bus.advance(t);
                let id = if f.driver {
                    bus.driver().id()
                } else {
                    bus.follower().map_or(0, |s| s.id())
                };
                if let Some(s) = bus.servo_mut(id) {
                    s.inject_hardware_error(f.bits);
                }
            }
            if stall_at.is_some_and(|at| at <= t) {
                // The driver's shaft is blocked; it reports nothing.
                stall_at = None;
                let mut bus = lock(&self.bus);
                bus.advance(t);
                bus.driver_mut().block();
            }
            if jam_at.is_some_and(|at| at <= t) {
                jam_at = None;
                lock(&self.bus).advance(t);
                lock(&self.plant).jam();
            }
            if reboot_at.is_some_and(|at| at <= t) {
                // A brown-out: the driver reboots by itself.
                reboot_at = None;
                let mut bus = lock(&self.bus);
                bus.advance(t);
                bus.driver_mut().reboot(t);
            }
            let readable = {
                let mut fds = [PollFd::new(self.master.as_fd(), PollFlags::POLLIN)];
                let timeout = PollTimeout::try_from(IDLE_POLL).unwrap_or(PollTimeout::ZERO);
                matches!(poll(&mut fds, timeout), Ok(n) if n > 0)
                    && fds[0]
                        .revents()
                        .is_some_and(|r| r.contains(PollFlags::POLLIN))
            };
            if readable {
                match self.master.read(&mut buf) {
                    Ok(n) if n > 0 && silent => {}
                    Ok(n) if n > 0 => {
                        if link.echo {
                            // The adapter hands the host its own bytes back first.
                            let _ = self.master.write(&buf[..n]);
                        }
                        decoder.push(&buf[..n]);
                        last_byte = Instant::now();
                    }
                    _ => {
                        // EIO without a client or EAGAIN: nothing to read now.
                        std::thread::sleep(IDLE_POLL);
                    }
                }
            }
            // The bus timeline: when the last byte of what was read had crossed the wire.
            // Waits are scheduled on it (absolute deadlines), so a late wake-up does not
            // add up over a transaction's instruction and replies.
            let mut bus_time = last_byte;
            while let Some(decoded) = decoder.next_packet() {
                let baud = lock(&self.bus).driver().baud_rate();
                if self.options.pace_wire {
                    // The servo acts once the whole instruction has crossed the wire.
                    if let Decoded::Packet(p) = &decoded {
                        bus_time += Duration::from_secs_f64(wire_time_s(10 + p.body.len(), baud));
                        sleep_until(bus_time);
                    }
                }
                let now = start.elapsed().as_secs_f64();
                let replies = lock(&self.bus).handle(now, &decoded);
                bus_time = bus_time.max(Instant::now());
                for r in replies {
                    let mut wait = r.delay_s;
                    if self.options.pace_wire {
                        wait += wire_time_s(r.bytes.len(), baud);
                    }
                    bus_time += Duration::from_secs_f64(wait);
                    if let Some(at) = link.stall_at_s {
                        // A stall: what would leave in the window leaves at its end.
                        let end = start + Duration::from_secs_f64(at + link.stall_s);
                        let due = bus_time.duration_since(start).as_secs_f64();
                        if due >= at && bus_time < end {
                            bus_time = end;
                        }
                    }
                    sleep_until(bus_time);
                    let bytes = self.apply_link_faults(r.bytes);
                    // A full pty buffer (nobody reading) loses the bytes, as on a real bus.
                    let _ = self.master.write(&bytes);
                }
            }
            if decoder.pending() > 0 && last_byte.elapsed() > PARTIAL_PACKET_TIMEOUT {
                decoder.discard_partial();
            }
            let t = start.elapsed().as_secs_f64();
            self.bus
                .lock()
                .unwrap_or_else(|p| p.into_inner())
                .advance(t);
        };
        // Closing both ends makes the client's reads fail, like an unplugged adapter.
        drop(self.slave);
        drop(self.master);
        end
    }

    fn apply_link_faults(&self, bytes: Vec<u8>) -> Vec<u8> {
        let mut plant = lock(&self.plant);
        let l = &plant.config().link;
        if l.drop_prob <= 0.0 && l.corrupt_prob <= 0.0 {
            return bytes;
        }
        bytes
            .into_iter()
            .filter_map(|b| match plant.link_byte(b) {
                LinkByte::Pass(b) | LinkByte::Corrupted(b) => Some(b),
                LinkByte::Dropped => None,
            })
            .collect()
    }
}

/// Lock a mutex, recovering the data if another thread panicked while holding it.
pub(super) fn lock<T>(m: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|p| p.into_inner())
}

/// Sleep until `until`, finishing with a short spin so sub-millisecond return delays are
/// honoured (a plain sleep overshoots by tens of microseconds).
fn sleep_until(until: Instant) {
    let now = Instant::now();
    if until <= now {
        return;
    }
    let d = until - now;
    if d > SPIN_MARGIN * 2 {
        std::thread::sleep(d - SPIN_MARGIN);
    }
    while Instant::now() < until {
        std::hint::spin_loop();
    }
}
