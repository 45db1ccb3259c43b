//! The recording folder and its sidecar stay true to what is on disk (issue 16), over the
//! simulated benches: one session per folder (locked; a finished recording is not
//! overwritten unless asked), a folder of its own for every run started without `-o`,
//! `analyze` refusing a sidecar that belongs to another CSV, and a full disk ending the run
//! as "disk full" with the motor stopped, the sidecar counting exactly the rows on disk and
//! no temporary file left.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

use mpc_rig::rig::recording::{Recording, RecordingError, LOCK_FILE, SIDECAR_FILE};
use mpc_rig::rig::session::{measure, EndReason, MeasureOptions, MeasureOutcome};
use mpc_rig::rig::sim::stepper::SimHandle;
use mpc_rig::rig::RigError;

use crate::support::bench::{self, dxl_sim, repo};
use crate::support::serial_group;

fn motion_path() -> PathBuf {
    repo("data/motions/half-turn-2to1.toml")
}

fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_mpc-rig"))
}

fn stepper_sim() -> SimHandle {
    bench::stepper_sim::<&str>("half-turn-2to1", &[])
}

/// A session of `cycles` at 60 rpm through `port` into `out` (a new default folder when
/// `None`).
fn options(rig: &str, port: &Path, out: Option<&Path>, cycles: u32) -> MeasureOptions {
    let mut o = bench::options(
        rig,
        vec![port.display().to_string()],
        "half-turn-2to1",
        out.unwrap_or(Path::new("unused")),
    );
    o.out_dir = out.map(Path::to_path_buf);
    o.speed_rpm = 60.0;
    o.cycles = cycles;
    o
}

fn run(rig: &str, port: &Path, out: &Path) -> MeasureOutcome {
    measure(&mut options(rig, port, Some(out), 1)).expect("session runs")
}

/// Guards one session per folder: while a session records into a folder a second one is
/// refused before it opens its port (the first finishes with every row), a finished
/// recording is refused as `-o`, and replaced only when asked (`replace`, `measure
/// --replace`), leaving one consistent recording.
#[test]
fn a_busy_or_taken_folder_is_refused() {
    let _serial = serial_group::real_time();
    let sim = stepper_sim();
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("rec");
    let first = {
        let (port, dir) = (sim.path().to_path_buf(), dir.clone());
        std::thread::spawn(move || {
            measure(&mut options("rigs/sim-stepper.toml", &port, Some(&dir), 2)).unwrap()
        })
    };
    let deadline = Instant::now() + Duration::from_secs(20);
    while !dir.join(LOCK_FILE).exists() {
        assert!(Instant::now() < deadline, "the first session never started");
        std::thread::sleep(Duration::from_millis(20));
    }
    let err = measure(&mut options(
        "rigs/sim-stepper.toml",
        sim.path(),
        Some(&dir),
        1,
    ))
    .expect_err("a second session into a busy folder is refused");
    assert!(
        matches!(err, RigError::Recording(RecordingError::Locked { .. })),
        "{err}"
    );
    let first = first.join().unwrap();
    assert_eq!(first.end, EndReason::Finished);
    let rec = Recording::load(&dir).unwrap();
    assert_eq!(rec.meta.counts.samples as usize, rec.len());
    assert!(
        !dir.join(LOCK_FILE).exists(),
        "the lock is removed at the end"
    );

    let err = measure(&mut options(
        "rigs/sim-stepper.toml",
        sim.path(),
        Some(&dir),
        1,
    ))
    .expect_err("a finished recording is not overwritten");
    assert_eq!(
        err.to_string().replace(&dir.display().to_string(), "DIR"),
        "DIR already holds a recording; choose another folder, or replace it explicitly \
         (measure --replace)"
    );
    let mut again = options("rigs/sim-stepper.toml", sim.path(), Some(&dir), 1);
    again.replace = true;
    let replaced = measure(&mut again).unwrap();
    assert_eq!(replaced.end, EndReason::Finished);
    let rec = Recording::load(&dir).unwrap();
    assert_eq!(rec.meta.started_at, replaced.meta.started_at);
    assert!(
        rec.len() < first.meta.counts.samples as usize,
        "one cycle, not two"
    );
}

/// Guards default folder names: two `measure` runs started together without `-o` (two
/// benches) record into two folders under `out/measure/`, each a consistent recording whose
/// device time never goes backwards (they interleaved their rows into one before).
#[test]
fn runs_without_an_output_folder_get_one_each() {
    let _serial = serial_group::real_time();
    let sims = [stepper_sim(), stepper_sim()];
    let cwd = tempfile::tempdir().unwrap();
    let children: Vec<_> = sims
        .iter()
        .map(|sim| {
            bin()
                .current_dir(cwd.path())
                .args(["measure", "--rig"])
                .arg(repo("rigs/sim-stepper.toml"))
                .arg("--port")
                .arg(sim.path())
                .arg("--motion")
                .arg(motion_path())
                .args(["--speed", "90", "--cycles", "1", "--no-analysis"])
                .spawn()
                .unwrap()
        })
        .collect();
    for mut c in children {
        assert!(c.wait().unwrap().success());
    }
    let parent = cwd.path().join("out/measure");
    let mut dirs: Vec<_> = std::fs::read_dir(&parent)
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    dirs.sort();
    assert_eq!(dirs.len(), 2, "{dirs:?}");
    for d in dirs {
        let rec = Recording::load(&d).unwrap();
        assert!(rec.meta.complete);
        assert!(
            rec.device_time_us.windows(2).all(|w| w[1] > w[0]),
            "{}: time goes backwards",
            d.display()
        );
    }
}

/// Guards `analyze` against a sidecar that is not its CSV's: a stepper run's sidecar on
/// another stepper run's CSV (same columns, 1 vs 2 cycles), a Dynamixel run's sidecar on a
/// stepper CSV, and a sidecar from before the fingerprint whose row count does not fit are
/// each refused with "does not belong"; the untouched recordings analyse.
#[test]
fn analyze_refuses_a_sidecar_of_another_run() {
    let _serial = serial_group::real_time();
    let sim = stepper_sim();
    let dxl = dxl_sim::<&str>("half-turn-2to1", &[]);
    let tmp = tempfile::tempdir().unwrap();
    let a = tmp.path().join("a");
    let b = tmp.path().join("b");
    let d = tmp.path().join("dxl");
    run("rigs/sim-stepper.toml", sim.path(), &a);
    measure(&mut options(
        "rigs/sim-stepper.toml",
        sim.path(),
        Some(&b),
        2,
    ))
    .unwrap();
    run("rigs/sim-dynamixel.toml", dxl.path(), &d);
    let analyze = |dir: &Path| bin().arg("analyze").arg(dir).output().unwrap();
    for dir in [&a, &b, &d] {
        let out = analyze(dir);
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
    }
    let swap = |csv_of: &Path, sidecar_of: &Path, name: &str| {
        let mixed = tmp.path().join(name);
        std::fs::create_dir(&mixed).unwrap();
        std::fs::copy(csv_of.join("recording.csv"), mixed.join("recording.csv")).unwrap();
        std::fs::copy(sidecar_of.join(SIDECAR_FILE), mixed.join(SIDECAR_FILE)).unwrap();
        mixed
    };
    for mixed in [swap(&a, &b, "a-with-b"), swap(&a, &d, "stepper-with-dxl")] {
        let out = analyze(&mixed);
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "{} analysed", mixed.display());
        assert!(stderr.contains("does not belong"), "{stderr}");
    }
    // A sidecar written before the fingerprint existed: the row count decides.
    let old = swap(&a, &b, "old-format");
    let text = std::fs::read_to_string(old.join(SIDECAR_FILE)).unwrap();
    let mut json: serde_json::Value = serde_json::from_str(&text).unwrap();
    json.as_object_mut().unwrap().remove("csv");
    std::fs::write(old.join(SIDECAR_FILE), json.to_string()).unwrap();
    let out = analyze(&old);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(
        stderr.contains("does not belong") && stderr.contains("rows"),
        "{stderr}"
    );
}

/// A tmpfs of `size` bytes mounted at `mnt` in a user and mount namespace of its own
/// (`unshare -rm`), with `script` run inside; `None` when this machine does not allow it.
fn in_small_tmpfs(mnt: &Path, size: &str, script: &str, args: &[&Path]) -> Option<i32> {
    let probe = Command::new("unshare")
        .args([
            "-rm",
            "sh",
            "-c",
            "mount -t tmpfs -o size=64k tmpfs \"$1\"",
            "sh",
        ])
        .arg(mnt)
        .output()
        .ok()?;
    if !probe.status.success() {
        eprintln!(
            "skipped: cannot mount a small tmpfs with `unshare -rm` here ({})",
            String::from_utf8_lossy(&probe.stderr).trim()
        );
        return None;
    }
    let full = format!("mount -t tmpfs -o size={size} tmpfs \"$1\" && shift && {script}");
    let status = Command::new("unshare")
        .args(["-rm", "sh", "-c", &full, "sh"])
        .arg(mnt)
        .args(args)
        .status()
        .unwrap();
    status.code()
}

/// Guards the full disk (issue 16: end_reason null, more CSV rows than the sidecar counted,
/// an empty `recording.json.tmp` left): `measure` into a 128 KiB tmpfs stops the motor
/// (the simulated stepper ends disabled and still), exits 4 saying "disk full", and leaves a
/// recording whose sidecar says `disk full`, counts exactly the rows on disk (the reader's
/// fingerprint check passes) and no `.tmp` or lock file.
#[test]
fn a_full_disk_ends_the_run_truthfully() {
    let _serial = serial_group::real_time();
    let sim = stepper_sim();
    let tmp = tempfile::tempdir().unwrap();
    let mnt = tmp.path().join("small");
    let kept = tmp.path().join("kept");
    std::fs::create_dir_all(&mnt).unwrap();
    std::fs::create_dir_all(&kept).unwrap();
    // Inside: measure into the tmpfs, then copy what it left out before the mount goes.
    let script = "\"$1\" measure --rig \"$2\" --port \"$3\" --motion \"$4\" --speed 60 \
                  --cycles 6 --no-analysis -o \"$5/rec\" 2>\"$6/stderr\"; code=$?; \
                  cp -a \"$5/rec\" \"$6/\"; exit $code";
    let bin = PathBuf::from(env!("CARGO_BIN_EXE_mpc-rig"));
    let rig = repo("rigs/sim-stepper.toml");
    let motion = motion_path();
    let Some(code) = in_small_tmpfs(
        &mnt,
        "128k",
        script,
        &[&bin, &rig, sim.path(), &motion, &mnt, &kept],
    ) else {
        return;
    };
    let stderr = std::fs::read_to_string(kept.join("stderr")).unwrap();
    assert_eq!(
        code,
        i32::from(mpc_rig::cli::measure::EXIT_INCOMPLETE),
        "{stderr}"
    );
    assert!(stderr.contains("disk full"), "{stderr}");
    let rec_dir = kept.join("rec");
    let rec = Recording::load(&rec_dir).expect("the sidecar describes the CSV on disk");
    assert!(!rec.meta.complete);
    assert!(
        rec.meta
            .end_reason
            .as_deref()
            .is_some_and(|r| r.starts_with("disk full")),
        "{:?}",
        rec.meta.end_reason
    );
    assert_eq!(rec.meta.counts.samples as usize, rec.len());
    assert!(rec.len() > 500, "{} rows before the disk filled", rec.len());
    let left: Vec<_> = std::fs::read_dir(&rec_dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    assert!(
        left.iter()
            .all(|f| f == "recording.csv" || f == "recording.json"),
        "{left:?}"
    );
    std::thread::sleep(Duration::from_millis(100));
    let status = sim.stop().unwrap();
    assert!(!status.enabled && !status.moving, "{status:?}");
}
