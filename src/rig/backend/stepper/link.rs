//! The firmware link: one serial port, the frame decoder, the command channel with
//! retries, heartbeats, gap/CRC counting and reconnection, run on its own I/O thread.

use std::collections::VecDeque;
use std::io::{Read, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{Receiver, Sender, SyncSender, TryRecvError};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use mpc_wire::host::{CommandChannel, GapCounter, PollAction, RetryPolicy, TimestampUnwrapper};
use mpc_wire::{
    AckCode, Command, Decoder, EventKind, FrameError, Report, MAX_FRAME_LEN, PROTOCOL_VERSION,
};

use crate::rig::backend::Sample;
use crate::rig::recording::{flags, Counts};
use crate::rig::RigError;

use super::convert::SensorMap;

/// How long `read` waits for bytes before the I/O loop does its other chores: 2 ms, well
/// below the 10 ms between 1 kHz sample batches of 10.
pub const READ_TIMEOUT: Duration = Duration::from_millis(2);

/// How long the handshake waits for the device's `Hello` in total: 1.5 s covers a board
/// that is still enumerating after being plugged in.
pub const HANDSHAKE_TIMEOUT: Duration = Duration::from_millis(1500);

/// Retry policy of the handshake: 250 ms between six attempts (within
/// [`HANDSHAKE_TIMEOUT`]).
pub const HANDSHAKE_RETRY: RetryPolicy = RetryPolicy {
    timeout_ms: 250,
    max_attempts: 6,
};

/// How long after an unplug the link keeps trying to reopen the port before giving up:
/// 5 s is enough for a USB device to re-enumerate after a brief cable drop.
pub const RECONNECT_WINDOW: Duration = Duration::from_secs(5);

/// Pause between attempts to reopen a lost port.
pub const RECONNECT_POLL: Duration = Duration::from_millis(50);

/// How long restoring after a reconnect waits for a device that answers "busy" (still
/// decelerating after its watchdog stop): 3 s covers a stop from full speed at the
/// slowest sensible acceleration.
pub const RESTORE_BUSY_WAIT: Duration = Duration::from_secs(3);

/// Capacity of the sample channel (samples). 60 s at 1 kHz: the session drains it every
/// few ms, so this only fills if the host stalls badly; beyond it samples are counted lost.
pub const SAMPLE_QUEUE: usize = 60_000;

/// A command from the backend handle to the I/O thread.
pub struct Request {
    /// The command.
    pub command: Command,
    /// Where the reply goes.
    pub reply: Sender<Result<Report, RigError>>,
}

/// State shared between the I/O thread and the handle.
#[derive(Debug, Default)]
pub struct Shared {
    /// Link counts.
    pub counts: Counts,
    /// Last fatal error of the link (the thread has ended).
    pub fatal: Option<String>,
    /// Device events seen (kind, device time).
    pub events: Vec<(EventKind, u32)>,
    /// Samples dropped because the host queue was full.
    pub host_overflow: u64,
}

/// What to restore after a reconnect: the commands that put the device back in the state
/// the session had it in.
#[derive(Debug, Clone, Default)]
pub struct Restore {
    /// The configuration sent.
    pub configure: Option<Command>,
    /// Motor enabled.
    pub enabled: bool,
    /// Streaming.
    pub streaming: bool,
    /// The last motion command (RunSpeed/MoveTo/MoveBy) still in force.
    pub motion: Option<Command>,
}

/// Open a port the way the firmware link needs it.
pub fn open_port(path: &Path, baud: u32) -> Result<serialport::TTYPort, RigError> {
    serialport::new(path.to_string_lossy(), baud)
        .timeout(READ_TIMEOUT)
        .open_native()
        .map_err(|e| RigError::Open {
            path: path.to_path_buf(),
            message: e.to_string(),
        })
}

/// What the handshake learned.
#[derive(Debug, Clone)]
pub struct Handshake {
    /// The device's info.
    pub info: mpc_wire::DeviceInfo,
    /// Frames that arrived and were not the reply (late stream batches etc.).
    pub other_frames: u64,
}

/// Do the version handshake on an open port: flush a half frame with 0x00, send `Hello`
/// with retries, and check the answer. Distinguishes silence, garbage (wrong device) and a
/// version mismatch.
pub fn handshake(
    port: &mut serialport::TTYPort,
    path: &Path,
    decoder: &mut Decoder<Report>,
    channel: &mut CommandChannel,
) -> Result<Handshake, RigError> {
    let io = |e: std::io::Error| RigError::Io {
        path: path.to_path_buf(),
        message: e.to_string(),
    };
    let start = Instant::now();
    let now_ms = || start.elapsed().as_millis() as u64;
    let mut out = [0u8; MAX_FRAME_LEN];
    port.write_all(&[0]).map_err(io)?;
    channel.abandon();
    let n = channel
        .send(
            Command::Hello {
                protocol_version: PROTOCOL_VERSION,
            },
            now_ms(),
            &mut out,
        )
        .map_err(|e| RigError::Setup(format!("cannot encode Hello: {e}")))?;
    port.write_all(&out[..n]).map_err(io)?;
    let mut buf = [0u8; 4096];
    let mut raw_bytes = 0usize;
    let mut first_bytes: Vec<u8> = Vec::new();
    let mut good_frames = 0u64;
    let mut bad_frames = 0u64;
    let mut result: Option<Result<mpc_wire::DeviceInfo, RigError>> = None;
    while start.elapsed() < HANDSHAKE_TIMEOUT {
        match port.read(&mut buf) {
            Ok(0) => {}
            Ok(k) => {
                raw_bytes += k;
                if first_bytes.len() < 16 {
                    first_bytes.extend(buf[..k].iter().take(16 - first_bytes.len()));
                }
                decoder.feed(&buf[..k], |r| match r {
                    Ok(frame) => {
                        good_frames += 1;
                        if channel.on_report(&frame.msg).is_none() {
                            return;
                        }
                        result = Some(match frame.msg {
                            Report::Hello(info) if info.protocol_version == PROTOCOL_VERSION => {
                                Ok(info)
                            }
                            Report::Hello(info) => Err(RigError::VersionMismatch {
                                path: path.to_path_buf(),
                                device: u32::from(info.protocol_version),
                                host: u32::from(PROTOCOL_VERSION),
                                firmware: version_string(info.firmware_version),
                            }),
                            Report::Ack {
                                code: AckCode::VersionMismatch,
                                ..
                            } => Err(RigError::VersionMismatch {
                                path: path.to_path_buf(),
                                device: 0,
                                host: u32::from(PROTOCOL_VERSION),
                                firmware: "(unknown)".into(),
                            }),
                            other => Err(RigError::WrongDevice {
                                path: path.to_path_buf(),
                                expected: crate::rig::error::NOT_OUR_FIRMWARE,
                                detail: format!(
                                    "it answered Hello with {} instead of its device info",
                                    other.name()
                                ),
                            }),
                        });
                    }
                    Err(_) => bad_frames += 1,
                });
                if let Some(r) = result.take() {
                    return r.map(|info| Handshake {
                        info,
                        other_frames: good_frames - 1,
                    });
                }
            }
            Err(e) if e.kind() == std::io::ErrorKind::TimedOut => {}
            Err(e) => {
                return Err(RigError::Disconnected {
                    path: path.to_path_buf(),
                    message: format!("during the handshake: {e}"),
                })
            }
        }
        match channel.poll(now_ms(), &mut out) {
            Ok(PollAction::Resend { len }) => port.write_all(&out[..len]).map_err(io)?,
            Ok(PollAction::GaveUp(_)) => break,
            _ => {}
        }
    }
    channel.abandon();
    if raw_bytes == 0 {
        Err(RigError::NoAnswer {
            path: path.to_path_buf(),
            timeout_ms: HANDSHAKE_TIMEOUT.as_millis() as u64,
        })
    } else if good_frames == 0 {
        Err(RigError::WrongDevice {
            path: path.to_path_buf(),
            expected: crate::rig::error::NOT_OUR_FIRMWARE,
            detail: format!(
                "{raw_bytes} bytes arrived but none formed a valid frame ({bad_frames} rejected); first bytes: {}",
                hex(&first_bytes)
            ),
        })
    } else {
        Err(RigError::WrongDevice {
            path: path.to_path_buf(),
            expected: crate::rig::error::NOT_OUR_FIRMWARE,
            detail: format!("{good_frames} frames arrived but none answered Hello"),
        })
    }
}

fn hex(b: &[u8]) -> String {
    b.iter()
        .map(|x| format!("{x:02x}"))
        .collect::<Vec<_>>()
        .join(" ")
}

/// `major.minor.patch`.
pub fn version_string(v: [u8; 3]) -> String {
    format!("{}.{}.{}", v[0], v[1], v[2])
}

/// Everything the I/O thread owns.
pub struct IoThread {
    /// Port path (reopened on reconnect).
    pub path: PathBuf,
    /// Baud rate.
    pub baud: u32,
    /// The open port.
    pub port: serialport::TTYPort,
    /// Frame decoder.
    pub decoder: Decoder<Report>,
    /// Commands with retries.
    pub channel: CommandChannel,
    /// Requests from the handle.
    pub requests: Receiver<Request>,
    /// Samples to the handle.
    pub samples: SyncSender<Sample>,
    /// Shared counts and state.
    pub shared: Arc<Mutex<Shared>>,
    /// Set by the handle to end the thread.
    pub quit: Arc<AtomicBool>,
    /// Sensor mapping.
    pub map: SensorMap,
    /// Microsteps → driver degrees.
    pub deg_per_step: f64,
    /// Heartbeat interval.
    pub heartbeat: Duration,
    /// Expected sample interval, µs.
    pub sample_interval_us: f64,
    /// What to restore after a reconnect.
    pub restore: Arc<Mutex<Restore>>,
}

struct Loop {
    queue: VecDeque<Request>,
    in_flight: Option<Request>,
    gaps: GapCounter,
    unwrap: TimestampUnwrapper,
    stream_start: Option<u64>,
    time_offset: u64,
    last_device_us: Option<u64>,
    last_angle_deg: f64,
    angle_offset_deg: f64,
    mark_next: u32,
    last_sent: Instant,
    start: Instant,
    values: Vec<f64>,
}

impl IoThread {
    /// Run until told to quit or the link is lost for good.
    pub fn run(mut self) {
        let mut st = Loop {
            queue: VecDeque::new(),
            in_flight: None,
            gaps: GapCounter::new(),
            unwrap: TimestampUnwrapper::new(),
            stream_start: None,
            time_offset: 0,
            last_device_us: None,
            last_angle_deg: 0.0,
            angle_offset_deg: 0.0,
            mark_next: 0,
            last_sent: Instant::now(),
            start: Instant::now(),
            values: Vec::new(),
        };
        let mut buf = [0u8; 8192];
        let mut out = [0u8; MAX_FRAME_LEN];
        loop {
            if self.quit.load(Ordering::Relaxed) {
                return;
            }
            let read = self.port.read(&mut buf);
            let lost = match read {
                Ok(n) => {
                    self.on_bytes(&buf[..n], &mut st);
                    None
                }
                Err(e) if e.kind() == std::io::ErrorKind::TimedOut => None,
                Err(e) => Some(e.to_string()),
            };
            let lost = lost.or_else(|| self.chores(&mut st, &mut out).err());
            if let Some(message) = lost {
                if let Err(e) = self.reconnect(&mut st, &message) {
                    self.fail(&mut st, e);
                    return;
                }
            }
        }
    }

    fn now_ms(&self, st: &Loop) -> u64 {
        st.start.elapsed().as_millis() as u64
    }

    /// Send queued commands, retries and heartbeats. `Err` = the port is gone.
    fn chores(&mut self, st: &mut Loop, out: &mut [u8]) -> Result<(), String> {
        loop {
            match self.requests.try_recv() {
                Ok(r) => {
                    if matches!(r.command, Command::EmergencyStop) {
                        // An e-stop jumps the queue and abandons whatever is in flight.
                        if let Some(old) = st.in_flight.take() {
                            self.channel.abandon();
                            let _ = old.reply.send(Err(RigError::Safety(
                                "superseded by an emergency stop".into(),
                            )));
                        }
                        st.queue.push_front(r);
                    } else {
                        st.queue.push_back(r);
                    }
                }
                Err(TryRecvError::Empty) => break,
                Err(TryRecvError::Disconnected) => {
                    self.quit.store(true, Ordering::Relaxed);
                    break;
                }
            }
        }
        let now = self.now_ms(st);
        match self.channel.poll(now, out) {
            Ok(PollAction::Resend { len }) => {
                self.port
                    .write_all(&out[..len])
                    .map_err(|e| e.to_string())?;
                st.last_sent = Instant::now();
            }
            Ok(PollAction::GaveUp(o)) => {
                if let Some(r) = st.in_flight.take() {
                    let _ = r.reply.send(Err(RigError::CommandTimeout {
                        path: self.path.clone(),
                        command: o.command.name().into(),
                        attempts: u32::from(o.attempts),
                    }));
                }
            }
            _ => {}
        }
        if self.channel.pending().is_none() {
            let next = st.queue.pop_front();
            let heartbeat_due = st.last_sent.elapsed() >= self.heartbeat;
            let command = match &next {
                Some(r) => Some(r.command),
                None if heartbeat_due => Some(Command::Heartbeat),
                None => None,
            };
            if let Some(command) = command {
                let len = self
                    .channel
                    .send(command, now, out)
                    .map_err(|e| format!("cannot encode {}: {e}", command.name()))?;
                self.port
                    .write_all(&out[..len])
                    .map_err(|e| e.to_string())?;
                st.last_sent = Instant::now();
                st.in_flight = next;
            }
        }
        Ok(())
    }

    fn on_bytes(&mut self, bytes: &[u8], st: &mut Loop) {
        let arrived = Instant::now();
        let mut frames = Vec::new();
        let mut crc = 0;
        let mut other = 0;
        self.decoder.feed(bytes, |r| match r {
            Ok(f) => frames.push(f),
            Err(FrameError::Crc { .. }) => crc += 1,
            Err(_) => other += 1,
        });
        if crc + other > 0 {
            let mut sh = self.shared.lock().unwrap_or_else(|p| p.into_inner());
            sh.counts.crc_errors += crc;
            sh.counts.decode_errors += other;
        }
        for f in frames {
            // The device numbers all its frames with one counter: a hole is a lost frame.
            if st.gaps.observe(f.seq) > 0 {
                st.mark_next |= flags::GAP_BEFORE;
                let mut sh = self.shared.lock().unwrap_or_else(|p| p.into_inner());
                sh.counts.gaps += 1;
            }
            match f.msg {
                Report::Samples(batch) => {
                    for s in batch.samples() {
                        self.on_sample(s, st, arrived);
                    }
                }
                Report::Event(e) => {
                    let mut sh = self.shared.lock().unwrap_or_else(|p| p.into_inner());
                    sh.events.push((e.kind, e.timestamp_us));
                    if e.kind == EventKind::Boot {
                        // The device restarted: its position and clock start again.
                        st.angle_offset_deg = st.last_angle_deg;
                        st.unwrap = TimestampUnwrapper::new();
                        st.time_offset = st.last_device_us.map_or(0, |t| t + 1);
                        st.stream_start = None;
                    }
                }
                other => {
                    if self.channel.on_report(&other).is_some() {
                        if let Some(r) = st.in_flight.take() {
                            let _ = r.reply.send(Ok(other));
                        }
                    }
                }
            }
        }
    }

    fn on_sample(&mut self, s: &mpc_wire::Sample, st: &mut Loop, arrived: Instant) {
        let raw = st.unwrap.unwrap(s.timestamp_us);
        let start = *st.stream_start.get_or_insert(raw);
        let t = st.time_offset + raw.saturating_sub(start);
        let mut flags_out = self.map.flags(s.flags) | std::mem::take(&mut st.mark_next);
        if let Some(prev) = st.last_device_us {
            let dt = t.saturating_sub(prev) as f64;
            let missing = (dt / self.sample_interval_us - 1.0).round();
            if missing >= 1.0 {
                flags_out |= flags::GAP_BEFORE;
                let mut sh = self.shared.lock().unwrap_or_else(|p| p.into_inner());
                sh.counts.missing_samples += missing as u64;
            }
        }
        st.last_device_us = Some(t);
        let angle = st.angle_offset_deg + f64::from(s.position) * self.deg_per_step;
        st.last_angle_deg = angle;
        self.map.values(s, &mut st.values);
        let sample = Sample {
            device_time_us: t,
            driver_angle_deg: angle,
            values: st.values.clone(),
            flags: flags_out,
            host_instant: Some(arrived),
        };
        let mut sh = self.shared.lock().unwrap_or_else(|p| p.into_inner());
        if self.samples.try_send(sample).is_ok() {
            sh.counts.samples += 1;
        } else {
            sh.host_overflow += 1;
        }
    }

    fn reconnect(&mut self, st: &mut Loop, why: &str) -> Result<(), RigError> {
        tracing::warn!(
            "{}: link lost ({why}); trying to reconnect",
            self.path.display()
        );
        let give_up = Instant::now() + RECONNECT_WINDOW;
        loop {
            if self.quit.load(Ordering::Relaxed) {
                return Err(RigError::Disconnected {
                    path: self.path.clone(),
                    message: why.to_string(),
                });
            }
            if Instant::now() > give_up {
                return Err(RigError::Disconnected {
                    path: self.path.clone(),
                    message: format!(
                        "{why}; the port did not come back within {} s",
                        RECONNECT_WINDOW.as_secs()
                    ),
                });
            }
            std::thread::sleep(RECONNECT_POLL);
            let Ok(mut port) = open_port(&self.path, self.baud) else {
                continue;
            };
            let mut decoder = Decoder::<Report>::new();
            match handshake(&mut port, &self.path, &mut decoder, &mut self.channel) {
                Ok(_) => {}
                Err(e @ RigError::VersionMismatch { .. }) => return Err(e),
                Err(_) => continue,
            }
            self.port = port;
            self.decoder = decoder;
            // Restore configuration, enable, stream and motion, synchronously.
            let restore = self
                .restore
                .lock()
                .unwrap_or_else(|p| p.into_inner())
                .clone();
            let mut cmds = Vec::new();
            cmds.extend(restore.configure);
            if restore.enabled {
                cmds.push(Command::SetMotorEnabled(true));
            }
            if restore.streaming {
                cmds.push(Command::StartStream);
            }
            cmds.extend(restore.motion);
            let mut ok = true;
            for c in cmds {
                if let Err(e) = self.restore_command(c, st) {
                    tracing::warn!("{}: restoring after reconnect: {e}", self.path.display());
                    ok = false;
                    break;
                }
            }
            if !ok {
                continue;
            }
            // The device clock runs on through a USB drop (a reboot announces itself with a
            // Boot event, handled where events arrive), so timestamps stay continuous.
            st.gaps = GapCounter::new();
            st.mark_next |= flags::RECONNECTED | flags::GAP_BEFORE;
            let mut sh = self.shared.lock().unwrap_or_else(|p| p.into_inner());
            sh.counts.reconnects += 1;
            sh.counts.gaps += 1;
            drop(sh);
            tracing::warn!("{}: reconnected", self.path.display());
            return Ok(());
        }
    }

    /// Re-send one command after a reconnect, waiting while the device is still busy
    /// (decelerating after its watchdog stopped it).
    fn restore_command(&mut self, command: Command, st: &mut Loop) -> Result<(), RigError> {
        let deadline = Instant::now() + RESTORE_BUSY_WAIT;
        loop {
            match self.command_sync(command, st)? {
                Report::Ack {
                    code: AckCode::Busy,
                    ..
                } if Instant::now() < deadline => std::thread::sleep(RECONNECT_POLL),
                Report::Ack { code, .. } if code != AckCode::Ok => {
                    return Err(RigError::Device {
                        path: self.path.clone(),
                        command: command.name().into(),
                        message: format!("{code:?}"),
                    })
                }
                _ => return Ok(()),
            }
        }
    }

    /// Send one command and wait for its reply on the I/O thread itself (used while
    /// restoring after a reconnect).
    fn command_sync(&mut self, command: Command, st: &mut Loop) -> Result<Report, RigError> {
        let mut out = [0u8; MAX_FRAME_LEN];
        let mut buf = [0u8; 4096];
        self.channel.abandon();
        let io = |e: std::io::Error| RigError::Io {
            path: self.path.clone(),
            message: e.to_string(),
        };
        let len = self
            .channel
            .send(command, self.now_ms(st), &mut out)
            .map_err(|e| RigError::Setup(e.to_string()))?;
        self.port.write_all(&out[..len]).map_err(io)?;
        loop {
            let n = match self.port.read(&mut buf) {
                Ok(n) => n,
                Err(e) if e.kind() == std::io::ErrorKind::TimedOut => 0,
                Err(e) => return Err(io(e)),
            };
            let mut reply = None;
            let channel = &mut self.channel;
            self.decoder.feed(&buf[..n], |r| {
                if let Ok(f) = r {
                    if channel.on_report(&f.msg).is_some() {
                        reply = Some(f.msg);
                    }
                }
            });
            if let Some(r) = reply {
                return Ok(r);
            }
            match self.channel.poll(self.now_ms(st), &mut out) {
                Ok(PollAction::Resend { len }) => self.port.write_all(&out[..len]).map_err(io)?,
                Ok(PollAction::GaveUp(o)) => {
                    return Err(RigError::CommandTimeout {
                        path: self.path.clone(),
                        command: o.command.name().into(),
                        attempts: u32::from(o.attempts),
                    })
                }
                _ => {}
            }
        }
    }

    fn fail(&mut self, st: &mut Loop, e: RigError) {
        tracing::error!("{e}");
        // What happened, without the port: every error built from it names the port itself
        // (it read "PORT: device disconnected (PORT: device disconnected (…))" before).
        let message = match &e {
            RigError::Disconnected { message, .. } => message.clone(),
            other => {
                let full = other.to_string();
                let port = format!("{}: ", self.path.display());
                full.strip_prefix(&port).unwrap_or(&full).to_string()
            }
        };
        {
            let mut sh = self.shared.lock().unwrap_or_else(|p| p.into_inner());
            sh.fatal = Some(message.clone());
        }
        for r in st.in_flight.take().into_iter().chain(st.queue.drain(..)) {
            let _ = r.reply.send(Err(RigError::Disconnected {
                path: self.path.clone(),
                message: message.clone(),
            }));
        }
    }
}
