//! The measurement session against an in-memory fake bench that plugs in exactly like a
//! real backend: plan phases, complete and incomplete recordings, cancel, disconnect,
//! safety refusals, and determinism of the recorded data.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use mpc_rig::rig::backend::{Driver, Sample, SampleStream};
use mpc_rig::rig::config::RigConfig;
use mpc_rig::rig::recording::{Counts, DeviceInfo, Phase, Recording};
use mpc_rig::rig::session::{check_plan, run_session, EndReason, MeasureOptions, TargetSpec};
use mpc_rig::rig::RigError;

fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

fn motion_path() -> PathBuf {
    root().join("data/motions/half-turn-2to1.toml")
}

/// What the fake saw, for assertions after the session.
#[derive(Debug, Default, Clone)]
struct Log {
    enabled: bool,
    speed_rpm: f64,
    commands: Vec<String>,
    shutdowns: u32,
}

/// A bench simulated in memory, faster than real time: each poll delivers 20 ms of
/// 1 kHz samples of a motor ramping at 720 deg/s² to the commanded speed, with the
/// follower's AS5600 reading from the target law.
struct FakeBench {
    motion: mpc_rig::motion::Motion,
    log: Arc<Mutex<Log>>,
    t_us: u64,
    angle: f64,
    speed_dps: f64,
    target_dps: f64,
    streaming: bool,
    delivered: u64,
    /// Fail with a disconnect after this many samples.
    unplug_after: Option<u64>,
    /// Set the cancel flag after this many samples.
    cancel_after: Option<(u64, Arc<AtomicBool>)>,
}

impl FakeBench {
    fn new(log: Arc<Mutex<Log>>) -> FakeBench {
        FakeBench {
            motion: mpc_rig::motion::Motion::from_file(&motion_path()).unwrap(),
            log,
            t_us: 0,
            angle: 0.0,
            speed_dps: 0.0,
            target_dps: 0.0,
            streaming: false,
            delivered: 0,
            unplug_after: None,
            cancel_after: None,
        }
    }

    fn cmd(&self, c: &str) {
        self.log.lock().unwrap().commands.push(c.to_string());
    }
}

impl Driver for FakeBench {
    fn enable(&mut self) -> Result<(), RigError> {
        self.cmd("enable");
        self.log.lock().unwrap().enabled = true;
        Ok(())
    }
    fn disable(&mut self) -> Result<(), RigError> {
        self.cmd("disable");
        self.log.lock().unwrap().enabled = false;
        Ok(())
    }
    fn zero(&mut self) -> Result<(), RigError> {
        self.cmd("zero");
        self.angle = 0.0;
        Ok(())
    }
    fn run_at(&mut self, rpm: f64) -> Result<(), RigError> {
        self.cmd(&format!("run {rpm}"));
        self.target_dps = rpm * 6.0;
        self.log.lock().unwrap().speed_rpm = rpm;
        Ok(())
    }
    fn move_to(&mut self, _deg: f64) -> Result<(), RigError> {
        Err(RigError::Setup("not used".into()))
    }
    fn move_by(&mut self, _deg: f64) -> Result<(), RigError> {
        Err(RigError::Setup("not used".into()))
    }
    fn stop(&mut self) -> Result<(), RigError> {
        self.cmd("stop");
        self.target_dps = 0.0;
        self.log.lock().unwrap().speed_rpm = 0.0;
        Ok(())
    }
    fn estop(&mut self) -> Result<(), RigError> {
        self.cmd("estop");
        self.target_dps = 0.0;
        self.speed_dps = 0.0;
        Ok(())
    }
    fn position_deg(&mut self) -> Result<f64, RigError> {
        Ok(self.angle)
    }
    fn shutdown(&mut self) -> Result<(), RigError> {
        let mut l = self.log.lock().unwrap();
        l.shutdowns += 1;
        l.enabled = false;
        l.speed_rpm = 0.0;
        Ok(())
    }
}

impl SampleStream for FakeBench {
    fn value_count(&self) -> usize {
        1
    }
    fn start_stream(&mut self, rate_hz: f64) -> Result<(), RigError> {
        assert_eq!(rate_hz, 1000.0);
        self.streaming = true;
        Ok(())
    }
    fn stop_stream(&mut self) -> Result<(), RigError> {
        self.streaming = false;
        Ok(())
    }
    fn poll_samples(&mut self, _t: Duration, out: &mut Vec<Sample>) -> Result<(), RigError> {
        if !self.streaming {
            return Ok(());
        }
        for _ in 0..20 {
            if let Some(n) = self.unplug_after {
                if self.delivered >= n {
                    return Err(RigError::Disconnected {
                        path: "/dev/fake".into(),
                        message: "unplugged".into(),
                    });
                }
            }
            if let Some((n, flag)) = &self.cancel_after {
                if self.delivered >= *n {
                    flag.store(true, Ordering::Relaxed);
                }
            }
            let dt = 1e-3;
            let accel = 720.0 * dt;
            let dv = (self.target_dps - self.speed_dps).clamp(-accel, accel);
            self.speed_dps += dv;
            self.angle += self.speed_dps * dt;
            self.t_us += 1000;
            let theta = self.motion.angle_z(self.angle / 360.0).unwrap()[0];
            let counts = (theta / std::f64::consts::TAU * 4096.0)
                .round()
                .rem_euclid(4096.0);
            out.push(Sample {
                device_time_us: self.t_us,
                driver_angle_deg: self.angle,
                values: vec![counts],
                flags: 0,
                host_instant: None,
            });
            self.delivered += 1;
        }
        Ok(())
    }
    fn counts(&self) -> Counts {
        Counts {
            samples: self.delivered,
            ..Counts::default()
        }
    }
    fn device_info(&self) -> DeviceInfo {
        DeviceInfo {
            backend: "fake".into(),
            ..DeviceInfo::default()
        }
    }
}

fn options(dir: &Path, reverse: bool) -> MeasureOptions {
    MeasureOptions {
        rig_path: root().join("rigs/sim-stepper.toml"),
        ports: vec![],
        target: TargetSpec::Motion(motion_path()),
        speed_rpm: 60.0,
        cycles: 2,
        settle_cycles: 1,
        reverse,
        out_dir: Some(dir.to_path_buf()),
        replace: false,
        cancel: Arc::new(AtomicBool::new(false)),
        progress: None,
        live: None,
    }
}

fn rig() -> RigConfig {
    RigConfig::load(&root().join("rigs/sim-stepper.toml")).unwrap()
}

/// Guards: a full forward+reverse session records settle, forward and reverse phases in
/// order, each measured direction spanning the planned cycles, a complete sidecar, and the
/// bench ends stopped and shut down.
#[test]
fn full_session_records_all_phases_and_ends_stopped() {
    let dir = tempfile::tempdir().unwrap();
    let log = Arc::new(Mutex::new(Log::default()));
    let mut bench = FakeBench::new(log.clone());
    let mut opts = options(dir.path(), true);
    let target = opts.target.load().unwrap();
    let out = run_session(&mut bench, &rig(), &target, &mut opts).unwrap();
    assert!(out.complete, "{:?}", out.end);
    assert_eq!(out.end, EndReason::Finished);
    let rec = Recording::load(dir.path()).unwrap();
    assert!(rec.meta.complete);
    assert_eq!(rec.meta.target.name, "half-turn-2to1");
    assert_eq!(rec.meta.target.sha256.len(), 64);
    let first = |p: Phase| rec.phase.iter().position(|&x| x == p).unwrap();
    assert!(first(Phase::Settle) < first(Phase::Forward));
    assert!(first(Phase::Forward) < first(Phase::Reverse));
    let span = |p: Phase| {
        let a: Vec<f64> = rec
            .phase
            .iter()
            .zip(&rec.driver_angle_deg)
            .filter(|(&x, _)| x == p)
            .map(|(_, &a)| a)
            .collect();
        a.iter().cloned().fold(f64::MIN, f64::max) - a.iter().cloned().fold(f64::MAX, f64::min)
    };
    // The measured cycles plus the phase margin on each side.
    let want = 720.0 + 2.0 * mpc_rig::rig::session::PHASE_MARGIN_DEG;
    assert!(
        (span(Phase::Forward) - want).abs() < 2.0,
        "{}",
        span(Phase::Forward)
    );
    assert!(
        (span(Phase::Reverse) - want).abs() < 2.0,
        "{}",
        span(Phase::Reverse)
    );
    // Both directions measure the same driver revolutions (issue 20: reverse cycles
    // started wherever the reversal ramp ended, so they straddled the analysis's cycles).
    let bounds = |p: Phase| {
        let a = rec
            .phase
            .iter()
            .zip(&rec.driver_angle_deg)
            .filter(|(&x, _)| x == p)
            .map(|(_, &a)| a);
        (
            a.clone().fold(f64::MAX, f64::min),
            a.fold(f64::MIN, f64::max),
        )
    };
    let (f, r) = (bounds(Phase::Forward), bounds(Phase::Reverse));
    assert!(
        (f.0 - r.0).abs() < 2.0 && (f.1 - r.1).abs() < 2.0,
        "forward {f:?}, reverse {r:?}"
    );
    let l = log.lock().unwrap();
    assert_eq!(l.shutdowns, 1);
    assert_eq!(l.speed_rpm, 0.0);
    assert!(l
        .commands
        .starts_with(&["zero".into(), "enable".into(), "run 60".into()]));
    assert!(l.commands.contains(&"run -60".to_string()));
    // The driver came to rest before the stream was stopped: the last rows are still.
    let n = rec.len();
    assert!((rec.driver_angle_deg[n - 1] - rec.driver_angle_deg[n - 20]).abs() < 0.05);
}

/// Guards the live progress at the end of each measured direction (issue 20: forward
/// stopped at 2.56/3 on the live line): both directions are reported at N/N cycles.
#[test]
fn progress_reports_each_direction_complete() {
    let dir = tempfile::tempdir().unwrap();
    let log = Arc::new(Mutex::new(Log::default()));
    let mut bench = FakeBench::new(log);
    let mut opts = options(dir.path(), true);
    let seen = Arc::new(Mutex::new(Vec::new()));
    let sink = seen.clone();
    opts.progress = Some(Box::new(move |p: &mpc_rig::rig::session::Progress| {
        sink.lock().unwrap().push((p.phase, p.cycle));
    }));
    let target = opts.target.load().unwrap();
    let out = run_session(&mut bench, &rig(), &target, &mut opts).unwrap();
    assert!(out.complete);
    let seen = seen.lock().unwrap();
    for ph in [Phase::Forward, Phase::Reverse] {
        assert!(
            seen.iter().any(|&(p, c)| p == ph && c == 2.0),
            "{ph:?} never reported at 2/2: {seen:?}"
        );
    }
}

/// Guards: an unplug mid-run keeps an analyzable recording marked incomplete, with the
/// reason, and still shuts the bench down.
#[test]
fn unplug_mid_run_keeps_incomplete_recording() {
    let dir = tempfile::tempdir().unwrap();
    let log = Arc::new(Mutex::new(Log::default()));
    let mut bench = FakeBench::new(log.clone());
    bench.unplug_after = Some(1500);
    let mut opts = options(dir.path(), false);
    let target = opts.target.load().unwrap();
    let out = run_session(&mut bench, &rig(), &target, &mut opts).unwrap();
    assert!(!out.complete);
    assert!(matches!(&out.end, EndReason::Disconnected(m) if m.contains("unplugged")));
    let rec = Recording::load(dir.path()).unwrap();
    assert!(!rec.meta.complete);
    assert!(rec
        .meta
        .end_reason
        .as_deref()
        .unwrap()
        .starts_with("disconnected"));
    assert_eq!(rec.len(), 1500);
    assert_eq!(rec.meta.counts.samples, 1500);
    assert_eq!(log.lock().unwrap().shutdowns, 1);
}

/// Guards: Ctrl-C (the cancel flag) stops the driver, keeps the samples up to the stop
/// and marks the recording cancelled and incomplete.
#[test]
fn cancel_stops_and_marks_incomplete() {
    let dir = tempfile::tempdir().unwrap();
    let log = Arc::new(Mutex::new(Log::default()));
    let mut bench = FakeBench::new(log.clone());
    let mut opts = options(dir.path(), false);
    bench.cancel_after = Some((800, opts.cancel.clone()));
    let target = opts.target.load().unwrap();
    let out = run_session(&mut bench, &rig(), &target, &mut opts).unwrap();
    assert_eq!(out.end, EndReason::Cancelled);
    let rec = Recording::load(dir.path()).unwrap();
    assert!(!rec.meta.complete);
    assert_eq!(rec.meta.end_reason.as_deref(), Some("cancelled"));
    assert!(log.lock().unwrap().commands.contains(&"stop".to_string()));
    assert!(rec.len() >= 800);
}

/// Guards: plans beyond the rig's safety limits are refused before any hardware is used.
#[test]
fn unsafe_plans_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let mut opts = options(dir.path(), false);
    opts.speed_rpm = 500.0;
    let err = check_plan(&rig(), &opts).unwrap_err().to_string();
    assert_eq!(
        err,
        "refused: 500 rpm exceeds safety.max_speed_rpm = 120 of rig `sim-stepper`"
    );
    opts.speed_rpm = 1.0;
    opts.cycles = 20;
    let err = check_plan(&rig(), &opts).unwrap_err().to_string();
    assert_eq!(
        err,
        "refused: the plan takes about 1512 s, more than safety.max_run_s = 600 s; use fewer \
         cycles or a higher speed"
    );
}

/// Guards: two sessions on the same (deterministic) bench record the same samples — the
/// session adds no nondeterminism besides host timestamps.
#[test]
fn two_runs_record_the_same_samples() {
    let run = || {
        let dir = tempfile::tempdir().unwrap();
        let mut bench = FakeBench::new(Arc::new(Mutex::new(Log::default())));
        let mut opts = options(dir.path(), false);
        let target = opts.target.load().unwrap();
        run_session(&mut bench, &rig(), &target, &mut opts).unwrap();
        let rec = Recording::load(dir.path()).unwrap();
        (
            rec.device_time_us,
            rec.driver_angle_deg,
            rec.sensors,
            rec.phase,
        )
    };
    assert!(run() == run(), "two runs recorded different samples");
}
