//! The measurement session: what `mpc-rig measure` (and `demo`) run at the bench.
//!
//! Owns the run plan (zero/home, settle cycle(s), N forward cycles, optionally a run-out of
//! the settle length and the same N driver revolutions in reverse), the sample loop (recording every sample, counting cycles from the driver
//! angle, live progress with the current error against the target law), the recording
//! folder's claim, the safety limits (speed, run time, sample stall, and the [`watch`]es on
//! every sample: a driver fault or stall, a jammed mechanism) and the exit paths: on the
//! planned end, an unplug, an error, a full disk, a watch firing or a cancel (the `cancel`
//! flag: Ctrl-C, SIGTERM, SIGHUP in `measure`) the motor is stopped, the hardware shut down
//! and the recording finished — complete only in the first case. The firmware's dead-man
//! watchdog is the last line of defence if the host itself dies.
//!
//! It is generic over [`Bench`] and does not know which device it talks to; it does not
//! analyse the recording (the caller runs [`crate::analysis`] afterwards).

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant, SystemTime};

pub mod live;
pub mod watch;

use crate::rig::backend::{Bench, Sample};
use crate::rig::config::{HomeMethod, RigConfig};
use crate::rig::recording::{
    flags, utc_dir_stamp, Claim, Existing, Phase, RecordingError, RecordingMeta, RecordingWriter,
    Row, SafetyStop, SessionInfo,
};
use crate::rig::target::check_measurable;
pub use crate::rig::target::{Target, TargetSpec};
use crate::rig::RigError;
use watch::{ErrorProbe, Fired, JamWatch, StallWatch};

/// How long the session waits for samples before declaring the stream stalled: 8 s,
/// longer than a backend's reconnect window (5 s for the stepper firmware) plus its
/// handshake, so a brief unplug is survived and a permanent one is reported as such by the
/// backend.
pub const STALL_TIMEOUT: Duration = Duration::from_secs(8);

/// Poll interval of the sample loop: 20 ms keeps Ctrl-C and the display responsive
/// without spinning.
pub const POLL_INTERVAL: Duration = Duration::from_millis(20);

/// Interval between live progress reports.
pub const PROGRESS_INTERVAL: Duration = Duration::from_millis(250);

/// After the stop command, wait at most this long for the driver to come to rest (and the
/// last samples to arrive) before shutting down.
pub const STOP_WAIT: Duration = Duration::from_secs(3);

/// The driver counts as at rest when its angle changes less than this (deg) over
/// [`REST_WINDOW`].
pub const REST_TOLERANCE_DEG: f64 = 0.05;

/// Window over which rest is judged.
pub const REST_WINDOW: Duration = Duration::from_millis(150);

/// Driver angle (deg) by which the forward and reverse phases extend beyond the measured
/// cycles on each side (taken from the settle cycles before and the run-out after), so that
/// events exactly at a cycle boundary (a follower crossing 0° at φ = 360°·k) lie inside the
/// labelled samples. 10° is several samples even at high speed and far less than a cycle.
pub const PHASE_MARGIN_DEG: f64 = 10.0;

/// Where recordings go without `-o`: a new folder per run named by its UTC start time
/// (`out/measure/20261122T055901Z`, then `…-2` for a second run in the same second).
pub const DEFAULT_OUT_PARENT: &str = "out/measure";

/// A finished run whose recording misses more than this fraction of the samples its rate
/// promises is marked degraded (sidecar `degraded`, exit code 6): 10 %. Below it the gaps
/// are the odd lost frame; above it whole stretches of every cycle are missing, so cycle
/// statistics and timing ratios no longer rest on the data (a stepper link with 1 % of its
/// bytes corrupted loses 72 % of the samples).
pub const DEGRADED_MISSING_FRACTION: f64 = 0.1;

/// Default settle cycles before the measured ones: one revolution lets the mechanism
/// take up its backlash and the speed settle.
pub const DEFAULT_SETTLE_CYCLES: u32 = 1;

/// Extra time granted on top of the planned run duration before `max_run_s` is checked
/// up front (ramps, settle, stop): 20 %.
pub const RUN_TIME_MARGIN: f64 = 1.2;

/// Live progress of a run.
#[derive(Debug, Clone, PartialEq)]
pub struct Progress {
    /// Current phase.
    pub phase: Phase,
    /// Cycles completed in the current measured direction (fractional); in the settle
    /// phase, the revolutions of settle (or run-out before a reversal) done so far.
    pub cycle: f64,
    /// Cycles planned per direction.
    pub cycles: u32,
    /// Settle revolutions planned before each measured direction.
    pub settle_cycles: u32,
    /// Samples recorded.
    pub samples: u64,
    /// Sample rate over the last progress interval, Hz.
    pub sample_rate_hz: f64,
    /// Holes in the recording so far (as of its last write to disk).
    pub gaps: u64,
    /// Current follower error against the target (deg; geodesic for 3R), when the rig has
    /// the sensor for it: relative to the first reading during the first driver
    /// revolution, against the aligned target after it ([`watch::ErrorProbe`]).
    pub error_deg: Option<f64>,
    /// Seconds since the start.
    pub elapsed_s: f64,
}

/// A live progress callback.
pub type ProgressFn = Box<dyn FnMut(&Progress) + Send>;

/// Everything a session needs.
pub struct MeasureOptions {
    /// Rig file.
    pub rig_path: PathBuf,
    /// `--port` overrides (`PATH` or `NAME=PATH`).
    pub ports: Vec<String>,
    /// The target.
    pub target: TargetSpec,
    /// Driver speed, rpm (positive; reverse runs use the negative).
    pub speed_rpm: f64,
    /// Measured cycles per direction.
    pub cycles: u32,
    /// Settle cycles before the measured ones (per direction).
    pub settle_cycles: u32,
    /// Also run in reverse.
    pub reverse: bool,
    /// Recording directory; default a new `out/measure/<UTC timestamp>` folder
    /// ([`DEFAULT_OUT_PARENT`]). A folder that already holds a recording is refused unless
    /// `replace` is set; one another session is recording into is always refused.
    pub out_dir: Option<PathBuf>,
    /// Replace a recording already in `out_dir` (`measure --replace`).
    pub replace: bool,
    /// Set to stop early (Ctrl-C); the recording is kept, marked incomplete.
    pub cancel: Arc<AtomicBool>,
    /// Called with live progress about every [`PROGRESS_INTERVAL`].
    pub progress: Option<ProgressFn>,
    /// A live view's feed: the session writes its status at every poll and a thinned copy
    /// of its samples ([`live::LiveFeed`]); `None` without a viewer.
    pub live: Option<Arc<live::LiveFeed>>,
}

/// How a session ended.
#[derive(Debug, Clone)]
pub struct MeasureOutcome {
    /// The recording directory.
    pub dir: PathBuf,
    /// The final sidecar.
    pub meta: RecordingMeta,
    /// Whether every planned cycle was recorded.
    pub complete: bool,
    /// Why it ended.
    pub end: EndReason,
}

/// Why a session ended.
#[derive(Debug, Clone, PartialEq)]
pub enum EndReason {
    /// All planned cycles were recorded.
    Finished,
    /// Cancelled by the user.
    Cancelled,
    /// The device disappeared and did not come back.
    Disconnected(String),
    /// The run exceeded `safety.max_run_s`.
    MaxRunTime,
    /// The recording's disk filled up (the file being written); the motor was stopped and
    /// the sidecar describes the rows on disk.
    DiskFull(String),
    /// The driver did not follow its command: it reported a hardware fault or stopped
    /// advancing (why, in words); the motor was stopped.
    DriverStalled(String),
    /// The follower deviated from the target beyond `safety.max_follower_error_deg`; the
    /// motor was stopped.
    Jammed {
        /// Driver angle where the deviation began, deg.
        driver_angle_deg: f64,
        /// The follower's error there, deg.
        error_deg: f64,
    },
    /// Another error during the run.
    Error(String),
}

impl std::fmt::Display for EndReason {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            EndReason::Finished => write!(f, "finished"),
            EndReason::Cancelled => write!(f, "cancelled"),
            EndReason::Disconnected(m) => write!(f, "disconnected: {m}"),
            EndReason::MaxRunTime => write!(f, "stopped: safety.max_run_s reached"),
            EndReason::DiskFull(path) => write!(f, "disk full: {path}"),
            EndReason::DriverStalled(why) => write!(f, "driver stalled: {why}"),
            EndReason::Jammed {
                driver_angle_deg,
                error_deg,
            } => write!(
                f,
                "mechanism jammed: the follower was {error_deg:.1}° off the target at driver \
                 angle {driver_angle_deg:.1}° (a binding mechanism, or a follower sensor whose \
                 sign or scale does not match the rig file)"
            ),
            EndReason::Error(m) => write!(f, "error: {m}"),
        }
    }
}

/// Run a whole session: load the rig and target, open the backend, measure, record.
pub fn measure(opts: &mut MeasureOptions) -> Result<MeasureOutcome, RigError> {
    let rig = RigConfig::load(&opts.rig_path)?;
    measure_with(rig, opts)
}

/// [`measure`] with a rig already loaded (a shipped one chosen for what answered on a port,
/// `rig::identify`); `opts.rig_path` only names it.
pub fn measure_with(
    mut rig: RigConfig,
    opts: &mut MeasureOptions,
) -> Result<MeasureOutcome, RigError> {
    rig.apply_port_overrides(&opts.ports)?;
    let target = opts.target.load()?;
    check_plan(&rig, opts)?;
    check_measurable(&rig, target.motion.class())?;
    let claim = claim_folder(opts)?;
    let mut bench = crate::rig::backend::open(&rig)?;
    run_claimed(bench.as_mut(), &rig, &target, opts, claim)
}

/// Claim the run's recording folder (`-o` or a new default one) before any hardware is
/// touched: a folder being recorded into, or holding a recording not to be replaced, is
/// refused here.
fn claim_folder(opts: &MeasureOptions) -> Result<Claim, RigError> {
    Ok(match &opts.out_dir {
        Some(dir) => Claim::folder(
            dir,
            if opts.replace {
                Existing::Replace
            } else {
                Existing::Refuse
            },
        )?,
        None => Claim::unique(
            Path::new(DEFAULT_OUT_PARENT),
            &utc_dir_stamp(SystemTime::now()),
        )?,
    })
}

/// Refuse plans that break the rig's limits before touching the hardware.
pub fn check_plan(rig: &RigConfig, opts: &MeasureOptions) -> Result<(), RigError> {
    check_run(
        rig,
        &RunPlan {
            speed_rpm: opts.speed_rpm,
            cycles: opts.cycles,
            settle_cycles: opts.settle_cycles,
            reverse: opts.reverse,
        },
    )
}

/// What [`check_run`] judges: the run's speed and extent.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RunPlan {
    /// Driver speed, rpm.
    pub speed_rpm: f64,
    /// Measured cycles per direction.
    pub cycles: u32,
    /// Settle cycles before the measured ones.
    pub settle_cycles: u32,
    /// Also run in reverse.
    pub reverse: bool,
}

/// [`check_plan`] before there are session options (`demo` asks it before its synthesis,
/// so a bad `--cycles` or `--speed` is refused at once, not after minutes of work).
pub fn check_run(rig: &RigConfig, opts: &RunPlan) -> Result<(), RigError> {
    if !(opts.speed_rpm.is_finite() && opts.speed_rpm > 0.0) {
        return Err(RigError::Safety(format!(
            "speed must be a positive number of rpm, got {}",
            opts.speed_rpm
        )));
    }
    if opts.speed_rpm > rig.safety.max_speed_rpm {
        return Err(RigError::Safety(format!(
            "{} rpm exceeds safety.max_speed_rpm = {} of rig `{}`",
            opts.speed_rpm, rig.safety.max_speed_rpm, rig.name
        )));
    }
    if opts.cycles == 0 {
        return Err(RigError::Safety(
            "at least one measured cycle is needed".into(),
        ));
    }
    // Forward: settle, cycles, and (with reverse) a run-out of the settle length; back over
    // the run-out and the cycles.
    let revs = if opts.reverse {
        f64::from(2 * opts.cycles + 3 * opts.settle_cycles)
    } else {
        f64::from(opts.cycles + opts.settle_cycles)
    };
    let planned_s = revs / (opts.speed_rpm / 60.0) * RUN_TIME_MARGIN;
    if planned_s > rig.safety.max_run_s {
        return Err(RigError::Safety(format!(
            "the plan takes about {planned_s:.0} s, more than safety.max_run_s = {} s; use fewer cycles or a higher speed",
            rig.safety.max_run_s
        )));
    }
    Ok(())
}

/// Where the run is, from the driver angle travelled.
struct Plan {
    settle_deg: f64,
    measure_deg: f64,
    reverse: bool,
    /// Angle at the start of the forward run.
    start: f64,
    /// Highest angle reached (turning point of the reverse run).
    turn: Option<f64>,
    max_seen: f64,
}

enum Step {
    Continue(Phase, f64),
    Reverse,
    Done,
}

impl Plan {
    /// The measured cycles of both directions are the same driver revolutions,
    /// `[start + settle, start + settle + measure]`: the analysis numbers cycles by
    /// ⌊φ/360°⌋, so reverse cycles measured from wherever the reversal ramp happened to end
    /// straddled two of its cycles (issue 20: forward 1–3 but reverse 0–3, 6 complete cycles
    /// at one speed and 5 at another). To keep a settle of `settle_deg` after the reversal,
    /// the forward run runs out that far past the measured cycles before it turns.
    fn step(&mut self, angle: f64) -> Step {
        self.max_seen = self.max_seen.max(angle);
        let p = angle - self.start;
        let lo = self.settle_deg;
        let hi = self.settle_deg + self.measure_deg;
        let margin = PHASE_MARGIN_DEG.min(self.settle_deg);
        match self.turn {
            None => {
                if p < lo - margin {
                    Step::Continue(Phase::Settle, (p / 360.0).max(0.0))
                } else if p < hi + PHASE_MARGIN_DEG {
                    let c = ((p - lo) / 360.0).clamp(0.0, self.measure_deg / 360.0);
                    Step::Continue(Phase::Forward, c)
                } else if !self.reverse {
                    Step::Done
                } else if p < hi + self.settle_deg.max(PHASE_MARGIN_DEG) {
                    Step::Continue(Phase::Settle, ((p - hi) / 360.0).max(0.0))
                } else {
                    Step::Reverse
                }
            }
            Some(_) => {
                if p > hi + PHASE_MARGIN_DEG {
                    // Back over the run-out (and the overshoot of the turn), shown as the
                    // fraction of it done in settle revolutions.
                    let top = self.max_seen - self.start;
                    let span = top - hi - PHASE_MARGIN_DEG;
                    let c = if span > 0.0 {
                        ((top - p) / span).clamp(0.0, 1.0) * self.settle_deg / 360.0
                    } else {
                        0.0
                    };
                    Step::Continue(Phase::Settle, c)
                } else if p >= lo - margin {
                    let c = ((hi - p) / 360.0).clamp(0.0, self.measure_deg / 360.0);
                    Step::Continue(Phase::Reverse, c)
                } else {
                    Step::Done
                }
            }
        }
    }
}

/// Run the plan on an open bench and record it. Always shuts the bench down.
pub fn run_session(
    bench: &mut (dyn Bench + Send),
    rig: &RigConfig,
    target: &Target,
    opts: &mut MeasureOptions,
) -> Result<MeasureOutcome, RigError> {
    let claim = claim_folder(opts);
    match claim {
        Ok(claim) => run_claimed(bench, rig, target, opts, claim),
        Err(e) => {
            let _ = bench.shutdown();
            Err(e)
        }
    }
}

/// [`run_session`] into a folder already claimed.
fn run_claimed(
    bench: &mut (dyn Bench + Send),
    rig: &RigConfig,
    target: &Target,
    opts: &mut MeasureOptions,
    claim: Claim,
) -> Result<MeasureOutcome, RigError> {
    let result = run_inner(bench, rig, target, opts, claim);
    let shutdown = bench.shutdown();
    match (result, shutdown) {
        (Ok(o), Ok(())) => Ok(o),
        (Ok(mut o), Err(e)) => {
            // The recording is safe; report the failed shutdown in the outcome.
            tracing::error!("shutdown after the run failed: {e}");
            if o.complete {
                o.end = EndReason::Error(format!("shutdown failed: {e}"));
            }
            Ok(o)
        }
        (Err(e), _) => Err(e),
    }
}

fn run_inner(
    bench: &mut (dyn Bench + Send),
    rig: &RigConfig,
    target: &Target,
    opts: &mut MeasureOptions,
    claim: Claim,
) -> Result<MeasureOutcome, RigError> {
    check_measurable(rig, target.motion.class())?;
    if bench.value_count() != rig.sensor_columns().len() {
        return Err(RigError::Setup(format!(
            "the backend delivers {} sensor values but the rig declares {} columns",
            bench.value_count(),
            rig.sensor_columns().len()
        )));
    }
    let session = SessionInfo {
        speed_rpm: opts.speed_rpm,
        cycles: opts.cycles,
        settle_cycles: opts.settle_cycles,
        reverse: opts.reverse,
        sample_rate_hz: rig.sampling.rate_hz,
    };
    let meta = RecordingMeta::new(
        rig.clone(),
        bench.device_info(),
        target.reference.clone(),
        session,
    );
    let mut writer = RecordingWriter::create(claim, meta)?;
    let dir = writer.dir().to_path_buf();
    let start = Instant::now();
    // Errors from here on end the run but keep the recording.
    let mut end = match drive(bench, rig, target, opts, &mut writer, start) {
        Ok(end) => end,
        Err(e) => {
            // Stop the motor before anything else (the recording is finished next).
            bench.stop().ok();
            end_reason_of(e)
        }
    };
    set_link_counts(&mut writer, bench);
    // Write what is buffered now, so a disk that fills at the very end is the end reason.
    if let Err(e) = writer.flush() {
        if end == EndReason::Finished {
            end = end_reason_of(e.into());
        }
    }
    let complete = end == EndReason::Finished;
    if complete {
        writer.meta_mut().degraded = degraded(&writer.meta().counts, rig.sampling.rate_hz);
    }
    let meta = writer.finish(complete, &end.to_string())?;
    Ok(MeasureOutcome {
        dir,
        meta,
        complete,
        end,
    })
}

/// Why a run ended, from the error that ended it.
fn end_reason_of(e: RigError) -> EndReason {
    match e {
        RigError::Disconnected { path, message } => {
            EndReason::Disconnected(format!("{}: {message}", path.display()))
        }
        RigError::Recording(RecordingError::DiskFull { path }) => {
            EndReason::DiskFull(path.display().to_string())
        }
        e => EndReason::Error(e.to_string()),
    }
}

/// Why a finished run's data is degraded, if it is: more than
/// [`DEGRADED_MISSING_FRACTION`] of the samples the rate promises are missing.
fn degraded(c: &crate::rig::recording::Counts, rate_hz: f64) -> Option<String> {
    let expected = c.samples + c.missing_samples;
    let fraction = c.missing_samples as f64 / expected.max(1) as f64;
    (fraction > DEGRADED_MISSING_FRACTION).then(|| {
        format!(
            "{:.0} % of the samples expected at {rate_hz} Hz are missing ({} in {} gaps); \
             cycle and timing figures need most of every cycle",
            fraction * 100.0,
            c.missing_samples,
            c.gaps
        )
    })
}

/// Copy the backend's link counts into the sidecar (the sample, gap and missing counts are
/// the writer's own, from what is on disk).
fn set_link_counts(writer: &mut RecordingWriter, bench: &(dyn Bench + Send)) {
    let link = bench.counts();
    let c = &mut writer.meta_mut().counts;
    c.crc_errors = link.crc_errors;
    c.reconnects = link.reconnects;
    c.decode_errors = link.decode_errors;
    c.link_gaps = link.gaps;
    c.link_missing_samples = link.missing_samples;
}

fn drive(
    bench: &mut (dyn Bench + Send),
    rig: &RigConfig,
    target: &Target,
    opts: &mut MeasureOptions,
    writer: &mut RecordingWriter,
    start: Instant,
) -> Result<EndReason, RigError> {
    // A cancel (a signal) during the setup must not start the motor.
    if opts.cancel.load(Ordering::Relaxed) {
        return Ok(EndReason::Cancelled);
    }
    if rig.home.method == HomeMethod::ZeroHere {
        bench.zero()?;
    }
    bench.enable()?;
    bench.start_stream(rig.sampling.rate_hz)?;
    if opts.cancel.load(Ordering::Relaxed) {
        bench.stop_stream().ok();
        return Ok(EndReason::Cancelled);
    }
    if let Some(feed) = &opts.live {
        feed.begin(target.motion.name(), &target.motion.class().to_string());
    }
    bench.run_at(opts.speed_rpm)?;
    let mut stall = StallWatch::new(rig.driver_accel_deg_s2());
    stall.commanded(opts.speed_rpm);
    let mut jam = JamWatch::new(rig.safety.max_follower_error_deg);
    // Set when a watch fired: the motor is stopped at once, the batch still recorded.
    let mut stopping: Option<(EndReason, SafetyStop)> = None;
    let mut plan = Plan {
        settle_deg: f64::from(opts.settle_cycles) * 360.0,
        measure_deg: f64::from(opts.cycles) * 360.0,
        reverse: opts.reverse,
        start: f64::NAN,
        turn: None,
        max_seen: f64::NEG_INFINITY,
    };
    let mut probe = ErrorProbe::new(rig, &target.motion);
    let mut batch = Vec::with_capacity(256);
    let mut last_sample_at = Instant::now();
    let mut last_progress = Instant::now();
    let mut rows_at_last_progress = 0u64;
    // The sample rate over the last progress interval, Hz.
    let mut rate_hz = 0.0;
    let mut phase = Phase::Settle;
    let mut cycle = 0.0;
    let mut error_deg = None;
    let max_run = Duration::from_secs_f64(rig.safety.max_run_s);
    let mut done = false;
    while !done {
        if opts.cancel.load(Ordering::Relaxed) {
            bench.stop().ok();
            finish_tail(bench, writer, start)?;
            return Ok(EndReason::Cancelled);
        }
        if start.elapsed() > max_run {
            bench.stop().ok();
            finish_tail(bench, writer, start)?;
            return Ok(EndReason::MaxRunTime);
        }
        batch.clear();
        bench.poll_samples(POLL_INTERVAL, &mut batch)?;
        if batch.is_empty() {
            if last_sample_at.elapsed() > STALL_TIMEOUT {
                return Err(RigError::Setup(format!(
                    "no samples for {} s (is the device still streaming?)",
                    STALL_TIMEOUT.as_secs()
                )));
            }
        } else {
            last_sample_at = Instant::now();
        }
        let host_time_s = start.elapsed().as_secs_f64();
        for s in &batch {
            if plan.start.is_nan() {
                plan.start = s.driver_angle_deg;
            }
            if !done {
                match plan.step(s.driver_angle_deg) {
                    Step::Continue(p, c) => {
                        if p != phase && matches!(phase, Phase::Forward | Phase::Reverse) {
                            // A measured direction is over: say so, whatever the interval.
                            let done_cycles = f64::from(opts.cycles);
                            report_progress(opts, writer, start, phase, done_cycles, error_deg);
                        }
                        phase = p;
                        cycle = c;
                    }
                    Step::Reverse => {
                        plan.turn = Some(s.driver_angle_deg);
                        phase = Phase::Settle;
                        bench.run_at(-opts.speed_rpm)?;
                        stall.commanded(-opts.speed_rpm);
                    }
                    Step::Done => {
                        if phase == Phase::Reverse {
                            let done_cycles = f64::from(opts.cycles);
                            report_progress(opts, writer, start, phase, done_cycles, error_deg);
                        }
                        done = true;
                        // The rest of this batch is the start of the stop ramp.
                        phase = Phase::Settle;
                        bench.stop()?;
                    }
                }
            }
            let error = probe.as_mut().and_then(|p| p.error(&target.motion, s));
            if let Some(feed) = &opts.live {
                feed.sample(phase, s.driver_angle_deg, error);
            }
            error_deg = error.map(|e| e.deg).or(error_deg);
            // Only an error against the aligned target can tell a jam.
            let error = error.filter(|e| e.aligned).map(|e| e.deg);
            if !done && stopping.is_none() {
                stopping = watch_sample(bench, s, error, &mut stall, &mut jam);
                if stopping.is_some() {
                    // Stop first; the rest of the batch is recorded after.
                    bench.stop().ok();
                    done = true;
                    phase = Phase::Settle;
                }
            }
            writer.push(&Row {
                device_time_us: s.device_time_us,
                host_time_s,
                phase,
                driver_angle_deg: s.driver_angle_deg,
                values: &s.values,
                flags: s.flags,
            })?;
        }
        if writer.flush_due() {
            set_link_counts(writer, bench);
            writer.flush()?;
        }
        if let (Some(feed), Some(s)) = (&opts.live, batch.last()) {
            feed.status(live::LiveStatus {
                phase: phase.as_str(),
                cycle,
                cycles: opts.cycles,
                samples: writer.rows_pushed(),
                sample_rate_hz: rate_hz,
                gaps: writer.meta().counts.gaps,
                error_deg,
                driver_deg: s.driver_angle_deg,
                elapsed_s: start.elapsed().as_secs_f64(),
            });
        }
        if last_progress.elapsed() >= PROGRESS_INTERVAL {
            let rows = writer.rows_pushed();
            let dt = last_progress.elapsed().as_secs_f64();
            rate_hz = (rows - rows_at_last_progress) as f64 / dt;
            if let Some(cb) = opts.progress.as_mut() {
                cb(&Progress {
                    phase,
                    cycle,
                    cycles: opts.cycles,
                    settle_cycles: opts.settle_cycles,
                    samples: rows,
                    sample_rate_hz: rate_hz,
                    gaps: writer.meta().counts.gaps,
                    error_deg,
                    elapsed_s: start.elapsed().as_secs_f64(),
                });
            }
            rows_at_last_progress = rows;
            last_progress = Instant::now();
        }
    }
    finish_tail(bench, writer, start)?;
    Ok(match stopping {
        Some((end, record)) => {
            writer.meta_mut().safety_stop = Some(record);
            end
        }
        None => EndReason::Finished,
    })
}

/// Check one sample against the driver and mechanism watches: why to stop, if any.
fn watch_sample(
    bench: &mut (dyn Bench + Send),
    s: &Sample,
    error_deg: Option<f64>,
    stall: &mut StallWatch,
    jam: &mut JamWatch,
) -> Option<(EndReason, SafetyStop)> {
    let record = |kind: &str, fired: Fired, detail: String| SafetyStop {
        kind: kind.into(),
        onset_device_time_us: fired.onset_us,
        detected_device_time_us: fired.decided_us,
        driver_angle_deg: fired.onset_driver_deg,
        detail,
    };
    if s.flags & flags::DRIVER_FAULT != 0 {
        let why = bench
            .fault()
            .unwrap_or_else(|| "the driver reports a hardware fault".into());
        let here = Fired {
            onset_us: s.device_time_us,
            onset_driver_deg: s.driver_angle_deg,
            decided_us: s.device_time_us,
        };
        return Some((
            EndReason::DriverStalled(why.clone()),
            record("driver fault", here, why),
        ));
    }
    if let Some((fired, why)) = stall.observe(s) {
        return Some((
            EndReason::DriverStalled(why.clone()),
            record("driver stall", fired, why),
        ));
    }
    let (fired, error) = jam.observe(s, error_deg?)?;
    let end = EndReason::Jammed {
        driver_angle_deg: fired.onset_driver_deg,
        error_deg: error,
    };
    let detail = end.to_string();
    Some((end, record("jam", fired, detail)))
}

/// After a stop command: keep recording until the driver is at rest (or [`STOP_WAIT`]),
/// so the deceleration is in the recording, then stop the stream.
/// A progress report outside the regular interval (the end of a measured direction, so
/// the live line shows it reach N/N); its rate is the mean since the start.
fn report_progress(
    opts: &mut MeasureOptions,
    writer: &RecordingWriter,
    start: Instant,
    phase: Phase,
    cycle: f64,
    error_deg: Option<f64>,
) {
    let (cycles, settle_cycles) = (opts.cycles, opts.settle_cycles);
    if let Some(cb) = opts.progress.as_mut() {
        let rows = writer.rows_pushed();
        let elapsed_s = start.elapsed().as_secs_f64();
        cb(&Progress {
            phase,
            cycle,
            cycles,
            settle_cycles,
            samples: rows,
            sample_rate_hz: if elapsed_s > 0.0 {
                rows as f64 / elapsed_s
            } else {
                0.0
            },
            gaps: writer.meta().counts.gaps,
            error_deg,
            elapsed_s,
        });
    }
}

fn finish_tail(
    bench: &mut (dyn Bench + Send),
    writer: &mut RecordingWriter,
    start: Instant,
) -> Result<(), RigError> {
    let deadline = Instant::now() + STOP_WAIT;
    let window_us = REST_WINDOW.as_micros() as u64;
    let mut batch = Vec::new();
    // (device time, angle) of the recent samples; rest is judged in device time.
    let mut window: std::collections::VecDeque<(u64, f64)> = Default::default();
    while Instant::now() < deadline {
        batch.clear();
        bench.poll_samples(POLL_INTERVAL, &mut batch)?;
        let host_time_s = start.elapsed().as_secs_f64();
        let mut at_rest = false;
        for s in &batch {
            writer.push(&Row {
                device_time_us: s.device_time_us,
                host_time_s,
                // The stop ramp is not part of a measured cycle.
                phase: Phase::Settle,
                driver_angle_deg: s.driver_angle_deg,
                values: &s.values,
                flags: s.flags,
            })?;
            window.push_back((s.device_time_us, s.driver_angle_deg));
            let oldest = window.front().map_or(0, |w| w.0);
            if s.device_time_us.saturating_sub(oldest) >= window_us {
                let (lo, hi) = window
                    .iter()
                    .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), w| {
                        (lo.min(w.1), hi.max(w.1))
                    });
                if hi - lo < REST_TOLERANCE_DEG {
                    at_rest = true;
                    break;
                }
            }
            while window
                .front()
                .is_some_and(|w| s.device_time_us.saturating_sub(w.0) > window_us)
            {
                window.pop_front();
            }
        }
        if at_rest {
            break;
        }
    }
    bench.stop_stream()?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Guards: the plan labels settle, forward and reverse by driver angle and asks for the
    /// turnaround and the end at the right angles.
    #[test]
    fn plan_phases_by_angle() {
        let mut plan = Plan {
            settle_deg: 360.0,
            measure_deg: 720.0,
            reverse: true,
            start: 0.0,
            turn: None,
            max_seen: f64::NEG_INFINITY,
        };
        assert!(matches!(plan.step(100.0), Step::Continue(Phase::Settle, _)));
        match plan.step(540.0) {
            Step::Continue(Phase::Forward, c) => assert!((c - 0.5).abs() < 1e-12),
            _ => panic!(),
        }
        // The forward phase runs PHASE_MARGIN_DEG past the last cycle, then runs out one
        // settle length before it turns.
        let m = PHASE_MARGIN_DEG;
        assert!(matches!(
            plan.step(1080.0 + m / 2.0),
            Step::Continue(Phase::Forward, _)
        ));
        match plan.step(1080.0 + m) {
            Step::Continue(Phase::Settle, c) => assert!((c - m / 360.0).abs() < 1e-12),
            _ => panic!(),
        }
        assert!(matches!(
            plan.step(1440.0 - 1.0),
            Step::Continue(Phase::Settle, _)
        ));
        assert!(matches!(plan.step(1440.0), Step::Reverse));
        plan.turn = Some(1440.0);
        // Overshoot while decelerating, then back over the run-out.
        let top = 1440.0 + 90.0;
        assert!(matches!(plan.step(top), Step::Continue(Phase::Settle, _)));
        // Halfway back to the cycles is half the settle, the overshoot included.
        match plan.step((top + 1080.0 + m) / 2.0) {
            Step::Continue(Phase::Settle, c) => assert!((c - 0.5).abs() < 1e-12, "{c}"),
            _ => panic!(),
        }
        // The reverse phase covers the forward cycles exactly (and the same margins).
        match plan.step(1080.0 + m) {
            Step::Continue(Phase::Reverse, c) => assert!(c.abs() < 1e-12),
            _ => panic!(),
        }
        match plan.step(540.0) {
            Step::Continue(Phase::Reverse, c) => assert!((c - 1.5).abs() < 1e-12),
            _ => panic!(),
        }
        assert!(matches!(
            plan.step(360.0 - m),
            Step::Continue(Phase::Reverse, _)
        ));
        assert!(matches!(plan.step(360.0 - m - 0.1), Step::Done));
    }
}
