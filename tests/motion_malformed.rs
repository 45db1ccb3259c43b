//! Every malformed motion file in tests/data/motion produces the intended error, naming the
//! file, the line and the field; the files that are only suspicious load with the intended
//! warning.

use std::path::{Path, PathBuf};

use mpc_rig::motion::{Motion, MotionError, WarningKind};

fn data(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data/motion")
        .join(name)
}

/// Load a malformed file and return its error (panics if it loads).
fn error_of(name: &str) -> MotionError {
    let path = data(name);
    let result = if path.is_dir() {
        Motion::from_mechanism_file(&path)
    } else {
        Motion::from_file(&path)
    };
    match result {
        Ok(_) => panic!("{name} loaded but should be rejected"),
        Err(e) => e,
    }
}

/// Assert the whole message, with the test data folder left out of the path: it names the
/// file, the line where there is one, the field, what is wrong and what would be right, so a
/// change of wording is a visible diff here (issue 18).
#[track_caller]
fn assert_message(name: &str, err: &MotionError, expected: &str) {
    // `data("")` ends in the separator.
    let dir = data("").display().to_string();
    let msg = err.to_string();
    assert_eq!(msg.replacen(&dir, "", 1), expected, "{name}");
}

/// Guards the class check: an unknown class names the class field and its line.
#[test]
fn unknown_class() {
    let e = error_of("unknown-class.toml");
    assert!(matches!(e, MotionError::UnknownClass { ref found, .. } if found == "2R"));
    assert_message(
        "unknown-class.toml",
        &e,
        "unknown-class.toml:2: field `class`: unknown motion class \"2R\" (expected \"1R\", \
         \"1R1T\" or \"3R\")",
    );
}

/// Guards the time checks: outside [0, 1), going backwards, duplicated.
#[test]
fn bad_times() {
    let e = error_of("time-out-of-range.toml");
    assert!(matches!(e, MotionError::TimeOutOfRange { t, .. } if t == 1.0));
    assert_message(
        "time-out-of-range.toml",
        &e,
        "time-out-of-range.toml:10: field `key[1].t`: time t = 1 is outside one period [0, 1)",
    );

    let e = error_of("time-not-increasing.toml");
    assert!(matches!(e, MotionError::TimeNotIncreasing { .. }));
    assert_message(
        "time-not-increasing.toml",
        &e,
        "time-not-increasing.toml:13: field `key[2].t`: time t = 0.3 is not after the previous \
         keyframe's t = 0.6 (times must increase)",
    );

    let e = error_of("time-duplicated.toml");
    assert!(matches!(
        e,
        MotionError::DuplicateTime {
            previous_line: 10,
            ..
        }
    ));
    assert_message(
        "time-duplicated.toml",
        &e,
        "time-duplicated.toml:15: field `key[2].t`: time t = 0.5 is duplicated (the keyframe at \
         line 10 has the same time)",
    );

    let e = error_of("dense-times-not-increasing.csv");
    assert!(matches!(e, MotionError::TimeNotIncreasing { .. }));
    assert_message(
        "dense-times-not-increasing.csv",
        &e,
        "dense-times-not-increasing.csv:5: field `row 3.t`: time t = 0.2 is not after the \
         previous keyframe's t = 0.4 (times must increase)",
    );
}

/// Guards the number checks: NaN in TOML, words in CSV.
#[test]
fn non_numbers() {
    let e = error_of("non-finite.toml");
    assert!(matches!(e, MotionError::NonFinite { .. }));
    assert_message(
        "non-finite.toml",
        &e,
        "non-finite.toml:10: field `key[1].angle`: value NaN is not a finite number",
    );

    let e = error_of("dense-not-a-number.csv");
    assert!(matches!(e, MotionError::Invalid { .. }));
    assert_message(
        "dense-not-a-number.csv",
        &e,
        "dense-not-a-number.csv:5: field `qw`: \"zero\" is not a number",
    );
}

/// Guards the physical bounds (issue 16): finite values no mechanism can have — an angle
/// of 1e300°, a height of a million kilometres, an Euler angle of 1e300°, a dense row's
/// height — are refused with file, line and field, and keys a quarter turn apart within
/// 1e-300 of a period (an infinite velocity) are refused at the nearest key.
#[test]
fn non_physical_values() {
    let e = error_of("angle-not-physical.toml");
    assert!(matches!(e, MotionError::NotPhysical { .. }), "{e}");
    assert_message(
        "angle-not-physical.toml",
        &e,
        "angle-not-physical.toml:11: field `key[1].angle`: 1e300 deg is not a physical value (at \
         most ±360000 deg: 1000 turns)",
    );
    let e = error_of("height-not-physical.toml");
    assert_message(
        "height-not-physical.toml",
        &e,
        "height-not-physical.toml:12: field `key[1].height`: 1e11 model units is not a physical \
         value (at most ±1000 model units: 10 m at the default scale for a follower about one \
         unit in size)",
    );
    let e = error_of("euler-not-physical.toml");
    assert_message(
        "euler-not-physical.toml",
        &e,
        "euler-not-physical.toml:11: field `key[1].euler_zyx`: 1e300 deg is not a physical value \
         (at most ±360000 deg: 1000 turns)",
    );
    let e = error_of("dense-height-not-physical.csv");
    assert_message(
        "dense-height-not-physical.csv",
        &e,
        "dense-height-not-physical.csv:4: field `row 2.translation`: 5e9 model units is not a \
         physical value (at most ±1000 model units: 10 m at the default scale for a follower \
         about one unit in size)",
    );
    let e = error_of("keys-too-close.toml");
    assert_message(
        "keys-too-close.toml",
        &e,
        "keys-too-close.toml:5: field `motion (interpolated)`: the interpolated motion's velocity \
         or acceleration is not finite near t = 0.0000: keyframes too close in time for the \
         motion between them",
    );
}

/// Guards the size bound of keyframe specs (issue 16: 1.15 M keys in 65 MB took 2.4 GB
/// and, before the line index, minutes): a spec larger than `MAX_SPEC_BYTES` is refused
/// before it is parsed, naming the file and pointing to the dense format.
#[test]
fn oversized_spec_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("huge.toml");
    let key = "[[key]]\nt = 0.0\nangle = 0.0\n";
    let n = mpc_rig::motion::MAX_SPEC_BYTES / key.len() + 1;
    let text = format!("class = \"1R\"\n{}", key.repeat(n));
    std::fs::write(&path, text).unwrap();
    let e = Motion::from_file(&path).unwrap_err().to_string();
    assert_eq!(
        e.replacen(&path.display().to_string(), "huge.toml", 1),
        "huge.toml: 8388645 bytes is more than a keyframe spec may hold (8388608 bytes, over \
         100 000 keys); write data this dense as a .csv dense file (data/README.md)"
    );
}

/// Guards the quaternion norm rule: beyond 1e-3 is an error; within it, a warning.
#[test]
fn quaternion_norms() {
    let e = error_of("non-unit-quaternion.toml");
    assert!(
        matches!(e, MotionError::NonUnitQuaternion { norm, .. } if (norm - 1.25f64.sqrt()).abs() < 1e-12)
    );
    assert_message(
        "non-unit-quaternion.toml",
        &e,
        "non-unit-quaternion.toml:10: field `key[1].quaternion`: quaternion has norm 1.118034, \
         more than 0.001 away from 1 (give a unit quaternion [w, x, y, z])",
    );

    let m = Motion::from_file(&data("nearly-unit-quaternion.toml")).unwrap();
    let w = &m.warnings()[0];
    assert!(matches!(w.kind, WarningKind::QuaternionNormalized { .. }));
    assert_eq!(w.at.line, Some(10));
    assert_eq!(w.at.field, "key[1].quaternion");
    // Normalized: the keyframe is a unit quaternion.
    assert!((m.keyframes()[1].rotation.norm() - 1.0).abs() < 1e-15);
}

/// Guards the class constraints: translation in pure-rotation classes, off-axis rotation
/// in 1R/1R1T, in both keyframe specs and dense files.
#[test]
fn class_constraints() {
    let e = error_of("translation-in-3r.toml");
    assert!(matches!(e, MotionError::TranslationNotAllowed { .. }));
    assert_message(
        "translation-in-3r.toml",
        &e,
        "translation-in-3r.toml:11: field `key[1].translation`: translation [0.0, 0.0, 1.5] is \
         not allowed in class 3R (a pure-rotation class: the joint centre stays at the origin)",
    );

    let e = error_of("height-in-1r.toml");
    assert!(matches!(e, MotionError::TranslationNotAllowed { .. }));
    assert_message(
        "height-in-1r.toml",
        &e,
        "height-in-1r.toml:11: field `key[1].height`: translation [0.0, 0.0, 2.0] is not allowed \
         in class 1R (`height` belongs to 1R1T motions; this class does not translate)",
    );

    let e = error_of("dense-translation-in-1r.csv");
    assert!(matches!(e, MotionError::TranslationNotAllowed { .. }));
    assert_message(
        "dense-translation-in-1r.csv",
        &e,
        "dense-translation-in-1r.csv:5: field `row 3.translation`: translation [0.5, 0.0, 0.0] is \
         not allowed in class 1R (a pure-rotation class: the joint centre stays at the origin)",
    );

    let e = error_of("off-axis-1r.toml");
    assert!(
        matches!(e, MotionError::RotationOffAxis { tilt_deg, .. } if (tilt_deg - 10.0).abs() < 1e-6)
    );
    assert_message(
        "off-axis-1r.toml",
        &e,
        "off-axis-1r.toml:9: field `key[1].rotation`: rotation tilts the z axis by 10.0000°; \
         class 1R turns only about the z axis",
    );

    let e = error_of("dense-off-axis-1r1t.csv");
    assert!(matches!(e, MotionError::RotationOffAxis { .. }));
    assert_message(
        "dense-off-axis-1r1t.csv",
        &e,
        "dense-off-axis-1r1t.csv:4: field `row 2.rotation`: rotation tilts the z axis by \
         10.0000°; class 1R1T turns only about the z axis",
    );
}

/// Guards the whole-turn rule for `net_rotation` and for timing segments.
#[test]
fn net_rotation_must_be_whole_turns() {
    let e = error_of("not-whole-turns.toml");
    assert!(matches!(e, MotionError::NotWholeTurns { degrees, .. } if degrees == 270.0));
    assert_message(
        "not-whole-turns.toml",
        &e,
        "not-whole-turns.toml:4: field `net_rotation`: net rotation 270° over one period is not a \
         whole number of turns (use a multiple of 360°: 0 for an oscillation, ±360° for one full \
         turn)",
    );

    let e = error_of("timing-not-whole-turns.toml");
    assert!(matches!(e, MotionError::NotWholeTurns { .. }));
    assert_message(
        "timing-not-whole-turns.toml",
        &e,
        "timing-not-whole-turns.toml:5: field `timing.segments`: net rotation 270° over one \
         period is not a whole number of turns (use a multiple of 360°: 0 for an oscillation, \
         ±360° for one full turn)",
    );
}

/// Guards the key-count rule of each scheme.
#[test]
fn too_few_keyframes() {
    let e = error_of("too-few-3r.toml");
    assert!(matches!(
        e,
        MotionError::TooFewKeyframes {
            found: 2,
            needed: 3,
            ..
        }
    ));
    assert_message(
        "too-few-3r.toml",
        &e,
        "too-few-3r.toml: field `key`: 2 keyframe(s), but a 3R motion needs at least 3: a \
         periodic spline through fewer than three orientations only retraces one arc back and \
         forth",
    );

    let e = error_of("too-few-oscillation.toml");
    assert!(matches!(
        e,
        MotionError::TooFewKeyframes {
            found: 1,
            needed: 2,
            ..
        }
    ));
    assert_message(
        "too-few-oscillation.toml",
        &e,
        "too-few-oscillation.toml: field `key`: 1 keyframe(s), but a 1R motion needs at least 2: \
         an oscillation (net rotation 0) needs two keyframes to move at all",
    );
}

/// Guards structural mistakes: misspelt fields, syntax errors, conflicting or missing
/// fields, bad CSV headers and rows, missing class comment.
#[test]
fn structural_mistakes() {
    let e = error_of("unknown-field.toml");
    assert!(matches!(e, MotionError::Syntax { .. }));
    assert_message(
        "unknown-field.toml",
        &e,
        "unknown-field.toml:10: unknown field `anlge`, expected one of `t`, `angle`, `height`, \
         `translation`, `quaternion`, `axis`, `euler_zyx`, `azimuth`, `elevation`, `roll`",
    );

    let e = error_of("syntax-error.toml");
    assert!(matches!(e, MotionError::Syntax { .. }));
    assert_message(
        "syntax-error.toml",
        &e,
        "syntax-error.toml:6: unclosed array, expected `]`",
    );

    let e = error_of("two-orientation-forms.toml");
    assert_message(
        "two-orientation-forms.toml",
        &e,
        "two-orientation-forms.toml:5: field `key[0]`: orientation given in several forms \
         (quaternion, euler_zyx); use exactly one",
    );

    let e = error_of("missing-height.toml");
    assert_message(
        "missing-height.toml",
        &e,
        "missing-height.toml:10: field `key[1]`: missing `height` (position along z) for a 1R1T \
         keyframe",
    );

    let e = error_of("dense-no-class.csv");
    assert_message(
        "dense-no-class.csv",
        &e,
        "dense-no-class.csv:1: field `class`: a dense CSV motion must start with a comment line \
         `# class = 1R` (or 1R1T, 3R)",
    );

    let e = error_of("dense-bad-header.csv");
    assert_message(
        "dense-bad-header.csv",
        &e,
        "dense-bad-header.csv:2: field `header`: header must start with `t,qw,qx,qy,qz,tx,ty,tz`, \
         found `t,qx,qy,qz,qw,tx,ty,tz`",
    );

    let e = error_of("dense-short-row.csv");
    assert!(matches!(e, MotionError::Syntax { .. }));
    assert_message(
        "dense-short-row.csv",
        &e,
        "dense-short-row.csv:4: row has 5 columns, the header has 8",
    );

    let e = error_of("dense-too-sparse.csv");
    assert_message(
        "dense-too-sparse.csv",
        &e,
        "dense-too-sparse.csv:5: field `row 2.rotation`: turns 120.00° about z since the previous \
         row (more than 90°): the samples are too sparse to tell which way the follower turns",
    );

    let e = error_of("mechanism-bad-rotation");
    assert_message(
        "mechanism-bad-rotation",
        &e,
        "mechanism-bad-rotation/mechanism.json: field `follower_motion[1].rotation`: expected \
         an array of 4 numbers",
    );
}

/// Guards the synthesizability warnings: a 3R tilt beyond 45° loads, with one warning that
/// names the worst time.
#[test]
fn large_tilt_is_a_warning() {
    let m = Motion::from_file(&data("large-tilt.toml")).unwrap();
    let tilt: Vec<_> = m
        .warnings()
        .iter()
        .filter_map(|w| match w.kind {
            WarningKind::LargeTilt { tilt_deg, .. } => Some(tilt_deg),
            _ => None,
        })
        .collect();
    assert_eq!(tilt.len(), 1);
    assert!(tilt[0] > 70.0);
}

/// Guards the CLI edge, whole texts: `motion check` on a malformed file exits 1 with one
/// message naming file, line and field; on a good file it exits 0 with a summary that gives
/// heights in model units and mm and rates per period and per second at `--speed` (issue
/// 20).
#[test]
fn cli_check_reports_errors() {
    let check = |args: &[&str]| {
        assert_cmd::Command::cargo_bin("mpc-rig")
            .unwrap()
            .current_dir(env!("CARGO_MANIFEST_DIR"))
            .args(["motion", "check"])
            .args(args)
            .output()
            .unwrap()
    };
    let out = check(&["tests/data/motion/off-axis-1r.toml"]);
    assert_eq!(out.status.code(), Some(1));
    assert_eq!(
        String::from_utf8_lossy(&out.stderr),
        "error: tests/data/motion/off-axis-1r.toml:9: field `key[1].rotation`: rotation tilts \
         the z axis by 10.0000°; class 1R turns only about the z axis\n\
         error: 1 of 1 motion file(s) invalid\n"
    );

    let out = check(&["data/motions/half-turn-2to1.toml"]);
    assert!(out.status.success());
    assert_eq!(
        String::from_utf8_lossy(&out.stdout),
        "ok: data/motions/half-turn-2to1.toml — 1R \"half-turn-2to1\", 2 keyframe(s), net 1 \
         turn(s), angle 0.0°..359.7° (monotone scheme), max |ω| 11.96 rad/period (343°/s), max \
         |ω'| 50.2 rad/period² (719°/s²), 0 warning(s)\n  \
         at the bench: one period (a driver turn) = 2 s at 30 rpm\n"
    );
    let out = check(&[
        "data/motions/screw-bob.toml",
        "--speed",
        "60",
        "--scale-mm",
        "5",
    ]);
    assert!(out.status.success());
    assert_eq!(
        String::from_utf8_lossy(&out.stdout),
        "ok: data/motions/screw-bob.toml — 1R1T \"screw-bob\", 4 keyframe(s), net 0 turn(s), \
         angle -45.0°..45.0° (monotone scheme), height 0.000..1.500 model units (0.0..7.5 mm), \
         max |dh/dt| 4.50 units/period (22.5 mm/s), max |ω| 4.75 rad/period (272°/s), max \
         |ω'| 49.5 rad/period² (2837°/s²), 0 warning(s)\n  \
         at the bench: 1 model unit = 5 mm; one period (a driver turn) = 1 s at 60 rpm\n"
    );
    let out = check(&["data/motions/screw-bob.toml", "--speed", "0"]);
    assert_eq!(out.status.code(), Some(2));
    assert_eq!(
        String::from_utf8_lossy(&out.stderr),
        "error: invalid value '0' for '--speed <RPM>': `0` is not a positive number\n\n\
         For more information, try '--help'.\n"
    );

    // --strict turns warnings into exit code 3 (2 is clap's usage error).
    let out = assert_cmd::Command::cargo_bin("mpc-rig")
        .unwrap()
        .args(["motion", "check", "--strict"])
        .arg(data("large-tilt.toml"))
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(3));
}

/// Guards the acceleration warning: a fast swing loads, with one warning naming the
/// magnitude beyond the documented threshold.
#[test]
fn large_angular_acceleration_is_a_warning() {
    let m = Motion::from_file(&data("large-acceleration.toml")).unwrap();
    let found: Vec<f64> = m
        .warnings()
        .iter()
        .filter_map(|w| match w.kind {
            WarningKind::LargeAngularAcceleration { value, .. } => Some(value),
            _ => None,
        })
        .collect();
    assert_eq!(found.len(), 1);
    assert!(found[0] > mpc_rig::motion::MAX_ANGULAR_ACCELERATION);
    assert_eq!(
        m.warnings()[0]
            .to_string()
            .replacen(&data("").display().to_string(), "", 1),
        "large-acceleration.toml:14: field `motion (interpolated)`: angular acceleration 1547.8 \
         rad/period² at t = 0.1118 (beyond 600; the conjugate curves will be highly curved)"
    );
}

/// Guards the 3R key step limit: nearly opposite consecutive orientations are rejected at
/// the second key's line.
#[test]
fn three_r_step_too_large() {
    let e = error_of("step-too-large-3r.toml");
    assert!(matches!(e, MotionError::Invalid { .. }));
    assert_message(
        "step-too-large-3r.toml",
        &e,
        "step-too-large-3r.toml:10: field `key[1]`: orientation is 175.0° away from the previous \
         keyframe (at most 170°: the way round is ambiguous; add a keyframe in between)",
    );
}

/// Guards robustness: a file that is not text, and an empty file, are errors (not panics)
/// naming the file.
#[test]
fn garbage_files_are_errors() {
    let dir = tempfile::tempdir().unwrap();
    let bin = dir.path().join("garbage.toml");
    std::fs::write(&bin, [0xff_u8, 0xfe, 0x00, 0x80, 0x13]).unwrap();
    let e = Motion::from_file(&bin).unwrap_err();
    assert!(matches!(e, MotionError::Io { .. }));
    let in_dir = |e: MotionError| {
        e.to_string()
            .replacen(&format!("{}/", dir.path().display()), "", 1)
    };
    assert_eq!(in_dir(e), "cannot read motion file garbage.toml");

    let empty = dir.path().join("empty.csv");
    std::fs::write(&empty, "").unwrap();
    assert_eq!(
        in_dir(Motion::from_file(&empty).unwrap_err()),
        "empty.csv:1: field `class`: a dense CSV motion must start with a comment line \
         `# class = 1R` (or 1R1T, 3R)"
    );

    let empty = dir.path().join("empty.toml");
    std::fs::write(&empty, "").unwrap();
    assert_eq!(
        in_dir(Motion::from_file(&empty).unwrap_err()),
        "empty.toml:1: missing field `class`"
    );

    let other = dir.path().join("motion.yaml");
    std::fs::write(&other, "class: 1R").unwrap();
    assert!(matches!(
        Motion::from_file(&other).unwrap_err(),
        MotionError::UnknownFormat { .. }
    ));
}

/// Guards "bad input never panics": thousands of seeded random mutations of the shipped
/// examples (TOML) and of a dense file (CSV) — replaced, deleted and duplicated characters
/// and lines, digits swapped for signs and exponents — all end in `Ok` or a typed error,
/// and every error message names the file.
#[test]
fn mutated_files_never_panic() {
    use rand::{Rng, SeedableRng};
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(2024);
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("data/motions");
    let mut sources: Vec<(String, String)> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "toml"))
        .map(|p| (std::fs::read_to_string(&p).unwrap(), "m.toml".to_string()))
        .collect();
    let m = Motion::from_file(&dir.join("figure-eight.toml")).unwrap();
    let mut csv = Vec::new();
    mpc_rig::motion::dense::write_csv(&mut csv, &m, &m.samples(24), false).unwrap();
    sources.push((String::from_utf8(csv).unwrap(), "m.csv".to_string()));
    sources.sort();
    const ALPHABET: &[u8] = b"0123456789.-+eE[]{}=,\"#\n abcnaninf";
    let mut outcomes = [0usize; 2];
    for round in 0..3000 {
        let (text, name) = &sources[round % sources.len()];
        let mut bytes = text.clone().into_bytes();
        for _ in 0..rng.random_range(1..6) {
            if bytes.is_empty() {
                break;
            }
            let i = rng.random_range(0..bytes.len());
            match rng.random_range(0..4) {
                0 => bytes[i] = ALPHABET[rng.random_range(0..ALPHABET.len())],
                1 => {
                    bytes.remove(i);
                }
                2 => bytes.insert(i, ALPHABET[rng.random_range(0..ALPHABET.len())]),
                _ => {
                    // Duplicate or drop a whole line.
                    let text = String::from_utf8_lossy(&bytes).into_owned();
                    let mut lines: Vec<&str> = text.lines().collect();
                    let j = rng
                        .random_range(0..lines.len().max(1))
                        .min(lines.len().saturating_sub(1));
                    if !lines.is_empty() {
                        if rng.random_bool(0.5) {
                            lines.insert(j, lines[j]);
                        } else {
                            lines.remove(j);
                        }
                    }
                    bytes = lines.join("\n").into_bytes();
                }
            }
        }
        let text = String::from_utf8_lossy(&bytes).into_owned();
        let path = Path::new(name);
        let result = if name.ends_with(".csv") {
            mpc_rig::motion::dense::parse_csv(&text, Some(path))
        } else {
            mpc_rig::motion::spec::parse_spec(&text, Some(path))
        };
        match result {
            Ok(m) => {
                outcomes[0] += 1;
                let s = m.sample(0.37);
                assert!(s.rotation.coords.iter().all(|x| x.is_finite()), "{text}");
            }
            Err(e) => {
                outcomes[1] += 1;
                assert!(e.to_string().contains(name.as_str()), "{e}");
            }
        }
    }
    // Both outcomes occur: the mutations are neither all harmless nor all fatal.
    assert!(outcomes[0] > 100 && outcomes[1] > 100, "{outcomes:?}");
}
