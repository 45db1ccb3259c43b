//! Integration tests of the shipped example motions and of the paths between formats:
//! keyframe spec → samples → dense CSV → Motion, and samples → mechanism.json → Motion.

use std::path::{Path, PathBuf};

use mpc_rig::motion::{DenseRow, Motion, MotionClass, DEFAULT_SAMPLES};

fn motions_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("data/motions")
}

fn example_files() -> Vec<PathBuf> {
    let mut files: Vec<PathBuf> = std::fs::read_dir(motions_dir())
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "toml" || e == "csv"))
        .collect();
    files.sort();
    files
}

/// Guards the shipped examples: every file in data/motions loads without errors or
/// warnings, is periodic, and passes through its keyframes exactly.
#[test]
fn every_example_loads_cleanly_and_hits_its_keyframes() {
    let files = example_files();
    assert!(files.len() >= 2, "examples missing: {files:?}");
    for f in files {
        let m = Motion::from_file(&f).unwrap_or_else(|e| panic!("{}: {e}", f.display()));
        assert!(
            m.warnings().is_empty(),
            "{}: {:?}",
            f.display(),
            m.warnings()
        );
        for k in m.keyframes() {
            let s = m.sample(k.t);
            assert!(
                s.rotation.angle_to(&k.rotation) < 1e-12,
                "{} misses keyframe at t = {}",
                f.display(),
                k.t
            );
            assert!((s.translation - k.translation).norm() < 1e-12);
        }
        // Periodic (as rotations: quaternions may flip sign, angles gain whole turns).
        for i in 0..10 {
            let t = f64::from(i) / 10.0 + 0.013;
            let (a, b) = (m.sample(t), m.sample(t + 1.0));
            assert!(a.rotation.angle_to(&b.rotation) < 1e-9);
            assert!((a.angular_velocity - b.angular_velocity).norm() < 1e-8);
        }
    }
}

/// Guards the paper's Fig. 11 timing: with the driver turning uniformly, the follower's
/// first half-turn takes twice as long as the second, and it never turns backwards.
#[test]
fn half_turn_two_to_one_has_the_papers_timing() {
    let m = Motion::from_file(&motions_dir().join("half-turn-2to1.toml")).unwrap();
    assert_eq!(m.class(), MotionClass::R1);
    assert_eq!(m.net_turns(), 1);
    // Find when θ crosses π by bisection on the monotone law.
    let (mut lo, mut hi) = (0.0, 1.0);
    for _ in 0..60 {
        let mid = 0.5 * (lo + hi);
        if m.angle_z(mid).unwrap()[0] < std::f64::consts::PI {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    let first = lo;
    let ratio = first / (1.0 - first);
    assert!((ratio - 2.0).abs() < 1e-9, "timing ratio {ratio}");
    assert!(m.samples(3600).iter().all(|s| s.angular_velocity.z > 0.0));
}

/// Guards the dense path: sampling a keyframe motion, writing it as CSV and reading it
/// back reproduces the law closely between the samples (the spline through 360 samples).
#[test]
fn dense_csv_round_trip_reproduces_the_law() {
    let dir = tempfile::tempdir().unwrap();
    for f in example_files() {
        let m = Motion::from_file(&f).unwrap();
        let csv = dir.path().join(format!("{}.csv", m.name()));
        let samples = m.samples(DEFAULT_SAMPLES);
        mpc_rig::motion::dense::write_csv(std::fs::File::create(&csv).unwrap(), &m, &samples, true)
            .unwrap();
        let back = Motion::from_file(&csv).unwrap();
        assert_eq!(back.class(), m.class());
        assert_eq!(back.name(), m.name());
        assert_eq!(back.net_turns(), m.net_turns());
        let worst = (0..1000)
            .map(|i| {
                let t = (f64::from(i) + 0.5) / 1000.0;
                m.sample(t).rotation.angle_to(&back.sample(t).rotation)
            })
            .fold(0.0, f64::max);
        assert!(
            worst < 1e-5,
            "{}: worst rotation error {worst} rad",
            f.display()
        );
    }
}

/// Guards `from_mechanism_file`: the follower motion stored in a mechanism.json (directory
/// or file path) gives back the law, with the name from `motion.source`; fields it does not
/// own are ignored.
#[test]
fn mechanism_file_round_trip() {
    let dir = tempfile::tempdir().unwrap();
    let m = Motion::from_file(&motions_dir().join("figure-eight.toml")).unwrap();
    let rows: Vec<serde_json::Value> = m
        .samples(DEFAULT_SAMPLES)
        .iter()
        .map(|s| {
            let q = s.rotation;
            serde_json::json!({"t": s.t, "rotation": [q.w, q.i, q.j, q.k], "translation": [0.0, 0.0, 0.0]})
        })
        .collect();
    let doc = serde_json::json!({
        "format": "mpcmech-mechanism/1",
        "class": "3R",
        "driver_offset": 9.0,
        "samples": DEFAULT_SAMPLES,
        "motion": {"source": "data/motions/figure-eight.toml", "extra": 1},
        "follower_motion": rows,
        "curve_pairs": [],
    });
    std::fs::write(
        dir.path().join("mechanism.json"),
        serde_json::to_string(&doc).unwrap(),
    )
    .unwrap();
    for path in [dir.path().to_path_buf(), dir.path().join("mechanism.json")] {
        let back = Motion::from_mechanism_file(&path).unwrap();
        assert_eq!(back.name(), "figure-eight");
        assert_eq!(back.class(), MotionClass::R3);
        assert_eq!(back.keyframes().len(), DEFAULT_SAMPLES);
        let t = 0.123_456;
        assert!(m.sample(t).rotation.angle_to(&back.sample(t).rotation) < 1e-5);
    }
}

/// Guards the scale a mechanism file's figures are read at (`motion check`/`show`): its
/// `scale_mm`, the default when a file predates the field, and a whole error naming the
/// file and field for a scale that is not a positive number.
#[test]
fn mechanism_scale_is_the_files_own() {
    use mpc_rig::motion::{mechanism_scale_mm, DEFAULT_SCALE_MM};
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("mechanism.json");
    let write = |doc: serde_json::Value| std::fs::write(&path, doc.to_string()).unwrap();
    write(serde_json::json!({"class": "1R", "scale_mm": 12.5}));
    assert_eq!(mechanism_scale_mm(dir.path()).unwrap(), 12.5);
    write(serde_json::json!({"class": "1R"}));
    assert_eq!(mechanism_scale_mm(&path).unwrap(), DEFAULT_SCALE_MM);
    write(serde_json::json!({"class": "1R", "scale_mm": -3}));
    assert_eq!(
        mechanism_scale_mm(&path).unwrap_err().to_string(),
        format!(
            "{}: field `scale_mm`: -3 is not a positive number of millimetres per model unit",
            path.display()
        )
    );
}

/// Guards `from_dense` for 1R: a full-turn law given as rows with wrapped quaternions is
/// unwrapped into one net turn and sampled continuously across the period boundary.
#[test]
fn from_dense_unwraps_a_full_turn() {
    let n = 72;
    let rows: Vec<DenseRow> = (0..n)
        .map(|i| {
            let t = f64::from(i) / f64::from(n);
            let th = std::f64::consts::TAU * t + 0.3 * (std::f64::consts::TAU * t).sin();
            DenseRow {
                t,
                rotation: nalgebra::UnitQuaternion::from_axis_angle(
                    &nalgebra::Vector3::z_axis(),
                    th,
                ),
                translation: nalgebra::Vector3::zeros(),
            }
        })
        .collect();
    let m = Motion::from_dense(MotionClass::R1, "wobble-turn", &rows).unwrap();
    assert_eq!(m.net_turns(), 1);
    let a = m.angle_z(0.999_999).unwrap()[0];
    let b = m.angle_z(1.000_001).unwrap()[0];
    assert!((b - a).abs() < 1e-4);
    let t = 0.41;
    let exact = std::f64::consts::TAU * t + 0.3 * (std::f64::consts::TAU * t).sin();
    assert!((m.angle_z(t).unwrap()[0] - exact).abs() < 1e-5);
}

/// Guards the derivative contract of `sample` on every example: ω and dω/dt (and for
/// translations v and a) agree with central finite differences of the sampled poses.
#[test]
fn sampled_derivatives_match_finite_differences() {
    for f in example_files() {
        let m = Motion::from_file(&f).unwrap();
        let e = 1e-6;
        for i in 0..97 {
            let t = f64::from(i) / 97.0 + 0.0031;
            let s = m.sample(t);
            let (p, q) = (m.sample(t + e), m.sample(t - e));
            let w = (p.rotation * q.rotation.inverse()).scaled_axis() / (2.0 * e);
            let tol = |x: f64| 1e-4 * (1.0 + x);
            assert!(
                (w - s.angular_velocity).norm() < tol(w.norm()),
                "{} ω at {t}",
                f.display()
            );
            let a = (p.angular_velocity - q.angular_velocity) / (2.0 * e);
            assert!(
                (a - s.angular_acceleration).norm() < tol(a.norm()),
                "{} dω at {t}",
                f.display()
            );
            let v = (p.translation - q.translation) / (2.0 * e);
            assert!((v - s.velocity).norm() < tol(v.norm()));
            let acc = (p.velocity - q.velocity) / (2.0 * e);
            assert!((acc - s.acceleration).norm() < tol(acc.norm()));
        }
    }
}

/// Guards determinism: two loads of the same file give bit-identical samples.
#[test]
fn loading_is_deterministic() {
    for f in example_files() {
        let (a, b) = (
            Motion::from_file(&f).unwrap(),
            Motion::from_file(&f).unwrap(),
        );
        for s in 0..50 {
            let t = f64::from(s) / 50.0;
            assert_eq!(a.sample(t).rotation, b.sample(t).rotation);
            assert_eq!(
                a.sample(t).angular_acceleration,
                b.sample(t).angular_acceleration
            );
        }
    }
}

/// Guards `motion sample` and `motion show` end to end: the CSV on stdout has a header and
/// N rows and reads back as a motion; show writes PNG and SVG files.
#[test]
fn cli_sample_and_show() {
    let file = motions_dir().join("screw-bob.toml");
    let out = assert_cmd::Command::cargo_bin("mpc-rig")
        .unwrap()
        .args(["motion", "sample", "-n", "36"])
        .arg(&file)
        .output()
        .unwrap();
    assert!(out.status.success());
    let text = String::from_utf8(out.stdout).unwrap();
    assert!(text.starts_with("# class = 1R1T\n# name = screw-bob\nt,qw,qx,qy,qz,tx,ty,tz\n"));
    assert_eq!(text.lines().count(), 3 + 36);
    let back = mpc_rig::motion::dense::parse_csv(&text, None).unwrap();
    assert_eq!(back.keyframes().len(), 36);

    let dir = tempfile::tempdir().unwrap();
    let out = assert_cmd::Command::cargo_bin("mpc-rig")
        .unwrap()
        .args(["motion", "show", "-o"])
        .arg(dir.path())
        .arg(&file)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(dir.path().join("screw-bob-height.png").exists());
    assert!(dir.path().join("screw-bob-angle.svg").exists());
}

/// Guards `motion sample -o` into a folder that does not exist yet (issue 20: `motion
/// show -o` created it, `motion sample -o` failed): both create it.
#[test]
fn cli_sample_creates_the_output_folder() {
    let file = motions_dir().join("screw-bob.toml");
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("new/deeper/screw-bob.csv");
    let out = assert_cmd::Command::cargo_bin("mpc-rig")
        .unwrap()
        .args(["motion", "sample", "-n", "36", "--output"])
        .arg(&csv)
        .arg(&file)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert_eq!(
        std::fs::read_to_string(&csv).unwrap().lines().count(),
        3 + 36
    );
}

/// Guards `-q` (issue 20: it still printed the list of files written): `motion show -q`
/// writes its figures and prints nothing; without `-q` it lists them.
#[test]
fn cli_show_quiet_prints_no_file_list() {
    let file = motions_dir().join("screw-bob.toml");
    let dir = tempfile::tempdir().unwrap();
    let run = |quiet: bool| {
        let mut cmd = assert_cmd::Command::cargo_bin("mpc-rig").unwrap();
        if quiet {
            cmd.arg("-q");
        }
        cmd.args(["motion", "show", "-o"])
            .arg(dir.path())
            .arg(&file)
            .output()
            .unwrap()
    };
    let out = run(true);
    assert!(out.status.success());
    assert_eq!(String::from_utf8_lossy(&out.stdout), "");
    assert_eq!(String::from_utf8_lossy(&out.stderr), "");
    assert!(dir.path().join("screw-bob-height.png").exists());
    let out = run(false);
    assert!(String::from_utf8_lossy(&out.stdout).contains("screw-bob-height.png"));
}
