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

/// Assert the message names `file:line` (or just the file when `line` is None) and
/// contains every fragment.
fn assert_message(name: &str, err: &MotionError, line: Option<usize>, fragments: &[&str]) {
    let msg = err.to_string();
    let place = match line {
        Some(l) => format!("{name}:{l}:"),
        None => format!("{name}:"),
    };
    assert!(
        msg.contains(&place),
        "{name}: expected {place:?} in {msg:?}"
    );
    for f in fragments {
        assert!(msg.contains(f), "{name}: expected {f:?} in {msg:?}");
    }
}

/// Guards the class check: an unknown class names the class field and its line.
#[test]
fn unknown_class() {
    let e = error_of("unknown-class.toml");
    assert!(matches!(e, MotionError::UnknownClass { ref found, .. } if found == "2R"));
    assert_message(
        "unknown-class.toml",
        &e,
        Some(2),
        &["field `class`", "\"2R\""],
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
        Some(10),
        &["key[1].t", "[0, 1)"],
    );

    let e = error_of("time-not-increasing.toml");
    assert!(matches!(e, MotionError::TimeNotIncreasing { .. }));
    assert_message(
        "time-not-increasing.toml",
        &e,
        Some(13),
        &["key[2].t", "t = 0.6"],
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
        Some(15),
        &["key[2].t", "duplicated"],
    );

    let e = error_of("dense-times-not-increasing.csv");
    assert!(matches!(e, MotionError::TimeNotIncreasing { .. }));
    assert_message("dense-times-not-increasing.csv", &e, Some(5), &["row 3.t"]);
}

/// Guards the number checks: NaN in TOML, words in CSV.
#[test]
fn non_numbers() {
    let e = error_of("non-finite.toml");
    assert!(matches!(e, MotionError::NonFinite { .. }));
    assert_message(
        "non-finite.toml",
        &e,
        Some(10),
        &["key[1].angle", "not a finite number"],
    );

    let e = error_of("dense-not-a-number.csv");
    assert!(matches!(e, MotionError::Invalid { .. }));
    assert_message(
        "dense-not-a-number.csv",
        &e,
        Some(5),
        &["field `qw`", "\"zero\""],
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
        Some(11),
        &["key[1].angle", "1e300 deg", "not a physical value"],
    );
    let e = error_of("height-not-physical.toml");
    assert_message(
        "height-not-physical.toml",
        &e,
        Some(12),
        &["key[1].height", "1e11 model units"],
    );
    let e = error_of("euler-not-physical.toml");
    assert_message(
        "euler-not-physical.toml",
        &e,
        Some(11),
        &["key[1].euler_zyx", "not a physical value"],
    );
    let e = error_of("dense-height-not-physical.csv");
    assert_message(
        "dense-height-not-physical.csv",
        &e,
        Some(4),
        &["row 2.translation", "5e9 model units"],
    );
    let e = error_of("keys-too-close.toml");
    assert_message(
        "keys-too-close.toml",
        &e,
        Some(5),
        &["not finite", "too close in time"],
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
    assert!(e.contains("huge.toml:"), "{e}");
    assert!(e.contains("dense file"), "{e}");
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
        Some(10),
        &["key[1].quaternion", "1.118034"],
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
        Some(11),
        &["key[1].translation", "class 3R"],
    );

    let e = error_of("height-in-1r.toml");
    assert!(matches!(e, MotionError::TranslationNotAllowed { .. }));
    assert_message(
        "height-in-1r.toml",
        &e,
        Some(11),
        &["key[1].height", "class 1R"],
    );

    let e = error_of("dense-translation-in-1r.csv");
    assert!(matches!(e, MotionError::TranslationNotAllowed { .. }));
    assert_message(
        "dense-translation-in-1r.csv",
        &e,
        Some(5),
        &["row 3.translation"],
    );

    let e = error_of("off-axis-1r.toml");
    assert!(
        matches!(e, MotionError::RotationOffAxis { tilt_deg, .. } if (tilt_deg - 10.0).abs() < 1e-6)
    );
    assert_message(
        "off-axis-1r.toml",
        &e,
        Some(9),
        &["key[1].rotation", "z axis"],
    );

    let e = error_of("dense-off-axis-1r1t.csv");
    assert!(matches!(e, MotionError::RotationOffAxis { .. }));
    assert_message(
        "dense-off-axis-1r1t.csv",
        &e,
        Some(4),
        &["row 2.rotation", "class 1R1T"],
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
        Some(4),
        &["net_rotation", "whole number of turns"],
    );

    let e = error_of("timing-not-whole-turns.toml");
    assert!(matches!(e, MotionError::NotWholeTurns { .. }));
    assert_message(
        "timing-not-whole-turns.toml",
        &e,
        Some(5),
        &["timing.segments"],
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
    assert_message("too-few-3r.toml", &e, None, &["field `key`", "at least 3"]);

    let e = error_of("too-few-oscillation.toml");
    assert!(matches!(
        e,
        MotionError::TooFewKeyframes {
            found: 1,
            needed: 2,
            ..
        }
    ));
    assert_message("too-few-oscillation.toml", &e, None, &["oscillation"]);
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
        Some(10),
        &["unknown field `anlge`"],
    );

    let e = error_of("syntax-error.toml");
    assert!(matches!(e, MotionError::Syntax { .. }));
    assert_message("syntax-error.toml", &e, Some(6), &[]);

    let e = error_of("two-orientation-forms.toml");
    assert_message(
        "two-orientation-forms.toml",
        &e,
        Some(5),
        &["key[0]", "several forms"],
    );

    let e = error_of("missing-height.toml");
    assert_message(
        "missing-height.toml",
        &e,
        Some(10),
        &["key[1]", "missing `height`"],
    );

    let e = error_of("dense-no-class.csv");
    assert_message("dense-no-class.csv", &e, Some(1), &["# class = 1R"]);

    let e = error_of("dense-bad-header.csv");
    assert_message(
        "dense-bad-header.csv",
        &e,
        Some(2),
        &["header must start with"],
    );

    let e = error_of("dense-short-row.csv");
    assert!(matches!(e, MotionError::Syntax { .. }));
    assert_message("dense-short-row.csv", &e, Some(4), &["5 columns"]);

    let e = error_of("dense-too-sparse.csv");
    assert_message(
        "dense-too-sparse.csv",
        &e,
        Some(5),
        &["row 2.rotation", "too sparse"],
    );

    let e = error_of("mechanism-bad-rotation");
    assert_message(
        "mechanism.json",
        &e,
        None,
        &["follower_motion[1].rotation", "4 numbers"],
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

/// Guards the CLI edge: `motion check` on a malformed file exits non-zero with one message
/// naming file, line and field; on a good file it exits 0.
#[test]
fn cli_check_reports_errors() {
    let out = assert_cmd::Command::cargo_bin("mpc-rig")
        .unwrap()
        .args(["motion", "check"])
        .arg(data("off-axis-1r.toml"))
        .output()
        .unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("off-axis-1r.toml:9: field `key[1].rotation`"),
        "{err}"
    );

    let good = Path::new(env!("CARGO_MANIFEST_DIR")).join("data/motions/half-turn-2to1.toml");
    let out = assert_cmd::Command::cargo_bin("mpc-rig")
        .unwrap()
        .args(["motion", "check"])
        .arg(&good)
        .output()
        .unwrap();
    assert!(out.status.success());
    assert!(String::from_utf8_lossy(&out.stdout).contains("1R \"half-turn-2to1\""));

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
    assert!(m.warnings()[0]
        .to_string()
        .contains("large-acceleration.toml:"));
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
        Some(10),
        &["key[1]", "175.0°"],
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
    assert!(e.to_string().contains("garbage.toml"));

    let empty = dir.path().join("empty.csv");
    std::fs::write(&empty, "").unwrap();
    let e = Motion::from_file(&empty).unwrap_err();
    assert!(e.to_string().contains("empty.csv"), "{e}");

    let empty = dir.path().join("empty.toml");
    std::fs::write(&empty, "").unwrap();
    let e = Motion::from_file(&empty).unwrap_err();
    assert!(e.to_string().contains("empty.toml"), "{e}");

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
