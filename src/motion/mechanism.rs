//! The follower motion stored in a `mechanism.json` (format `mpcmech-mechanism/1`,
//! docs/conventions.md): the target law a bench compares against.
//!
//! Reads only `class`, `motion.source` and `follower_motion`; everything else in the file
//! belongs to the synthesis module and is ignored here, so this keeps working as that
//! module adds fields.

use std::path::{Path, PathBuf};

use nalgebra::{Quaternion, UnitQuaternion, Vector3};
use serde_json::Value;

use super::{dense, DenseRow, Location, Motion, MotionClass, MotionError};

/// Name of the mechanism file inside a mechanism directory.
pub const MECHANISM_FILE: &str = "mechanism.json";

/// Default millimetres per model unit (a mechanism file's `scale_mm`, and the scale of a
/// target given as a motion file). Default 10: a follower curve of length 4π–6π units
/// becomes a part about 50–60 mm across, printable on any desktop printer and large enough
/// for 0.4 mm nozzles to render the contact curves. The one owner: synthesis, the simulated
/// benches and analysis all read it from here.
pub const DEFAULT_SCALE_MM: f64 = 10.0;

/// The mechanism file a path names (the path itself, or `MECHANISM_FILE` in a directory)
/// and its parsed JSON.
fn read(path: &Path) -> Result<(PathBuf, Value), MotionError> {
    let file: PathBuf = if path.is_dir() {
        path.join(MECHANISM_FILE)
    } else {
        path.to_path_buf()
    };
    let text = std::fs::read_to_string(&file).map_err(|source| MotionError::Io {
        path: file.clone(),
        source,
    })?;
    let doc: Value = serde_json::from_str(&text).map_err(|e| MotionError::Syntax {
        at: Location::new(Some(file.clone()), Some(e.line()), ""),
        message: e.to_string(),
    })?;
    Ok((file, doc))
}

/// The millimetres per model unit a mechanism file was designed at: its `scale_mm`, or
/// [`DEFAULT_SCALE_MM`] when the field is absent (files older than the field).
pub fn mechanism_scale_mm(path: &Path) -> Result<f64, MotionError> {
    let (file, doc) = read(path)?;
    match doc.get("scale_mm") {
        None => Ok(DEFAULT_SCALE_MM),
        Some(v) => v
            .as_f64()
            .filter(|s| s.is_finite() && *s > 0.0)
            .ok_or_else(|| MotionError::Invalid {
                at: Location::new(Some(file), None, "scale_mm"),
                message: format!("{v} is not a positive number of millimetres per model unit"),
            }),
    }
}

pub(crate) fn load(path: &Path) -> Result<Motion, MotionError> {
    let (file, doc) = read(path)?;
    let at = |field: &str| Location::new(Some(file.clone()), None, field);
    let invalid = |field: &str, message: String| MotionError::Invalid {
        at: at(field),
        message,
    };

    let class_text = doc
        .get("class")
        .and_then(Value::as_str)
        .ok_or_else(|| invalid("class", "missing or not a string".into()))?;
    let class: MotionClass = class_text.parse().map_err(|_| MotionError::UnknownClass {
        at: at("class"),
        found: class_text.to_string(),
    })?;
    let source = doc
        .get("motion")
        .and_then(|m| m.get("source"))
        .and_then(Value::as_str)
        .ok_or_else(|| invalid("motion.source", "missing or not a string".into()))?;
    let name = Path::new(source)
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| source.to_string());

    let rows_json = doc
        .get("follower_motion")
        .and_then(Value::as_array)
        .ok_or_else(|| invalid("follower_motion", "missing or not an array".into()))?;
    let mut rows = Vec::with_capacity(rows_json.len());
    for (i, r) in rows_json.iter().enumerate() {
        let field = |f: &str| format!("follower_motion[{i}].{f}");
        let numbers = |f: &str, n: usize| -> Result<Vec<f64>, MotionError> {
            let arr = r
                .get(f)
                .and_then(Value::as_array)
                .filter(|a| a.len() == n)
                .ok_or_else(|| invalid(&field(f), format!("expected an array of {n} numbers")))?;
            arr.iter()
                .map(|v| {
                    v.as_f64()
                        .ok_or_else(|| invalid(&field(f), format!("{v} is not a number")))
                })
                .collect()
        };
        let t = r
            .get("t")
            .and_then(Value::as_f64)
            .ok_or_else(|| invalid(&field("t"), "missing or not a number".into()))?;
        let q = numbers("rotation", 4)?;
        let tr = numbers("translation", 3)?;
        rows.push(DenseRow {
            t,
            // Norm and finiteness are checked by the dense builder.
            rotation: UnitQuaternion::new_unchecked(Quaternion::new(q[0], q[1], q[2], q[3])),
            translation: Vector3::new(tr[0], tr[1], tr[2]),
        });
    }
    dense::from_rows(
        class,
        &name,
        &rows,
        Some(file.clone()),
        &|i| format!("follower_motion[{i}]"),
        &[],
    )
}
