//! The dense CSV format, for motions from CAD or motion capture, and dense rows in general.
//!
//! ```text
//! # class = 3R
//! # name = nod          (optional; default: the file name without extension)
//! t,qw,qx,qy,qz,tx,ty,tz
//! 0.0,1,0,0,0,0,0,0
//! 0.0027777,0.99999,0.0012,0,0,0,0,0
//! ...
//! ```
//!
//! Lines starting with `#` are comments; comments before the header may carry `class` and
//! `name` as `key = value` (or `key: value`). The first eight columns are fixed; further
//! columns (for instance the derivatives `motion sample --derivatives` writes) are ignored.
//! Times increase within `[0, 1)`; poses are validated against the class exactly like
//! keyframes (translation only along z for 1R1T, none for 1R and 3R; 1R/1R1T rotations about
//! z only). Dense rows are interpolated by periodic cubic splines (the angle of 1R/1R1T with
//! [`super::AngleScheme::Spline`]), so their derivatives are smooth and accurate.

use std::path::{Path, PathBuf};

use nalgebra::Vector3;

use super::angle::AngleScheme;
use super::build::{finite, unit_quaternion, Assembly, NetRotation, RawKey};
use super::{DenseRow, Location, Motion, MotionClass, MotionError, MotionWarning};

/// The fixed leading columns of a dense file.
pub const COLUMNS: [&str; 8] = ["t", "qw", "qx", "qy", "qz", "tx", "ty", "tz"];

/// Parse and validate a dense CSV motion.
pub fn parse_csv(text: &str, path: Option<&Path>) -> Result<Motion, MotionError> {
    let file = path.map(Path::to_path_buf);
    let at = |line: Option<usize>, field: &str| Location::new(file.clone(), line, field);

    // Header comments.
    let mut class: Option<(MotionClass, usize)> = None;
    let mut name: Option<String> = None;
    for (i, raw) in text.lines().enumerate() {
        let line = raw.trim();
        if line.is_empty() {
            continue;
        }
        let Some(comment) = line.strip_prefix('#') else {
            break;
        };
        let Some((k, v)) = comment.split_once('=').or_else(|| comment.split_once(':')) else {
            continue;
        };
        let (k, v) = (k.trim().to_ascii_lowercase(), v.trim());
        match k.as_str() {
            "class" => {
                let c = v.parse().map_err(|_| MotionError::UnknownClass {
                    at: at(Some(i + 1), "class"),
                    found: v.to_string(),
                })?;
                class = Some((c, i + 1));
            }
            "name" if !v.is_empty() => name = Some(v.to_string()),
            _ => {}
        }
    }
    let Some((class, _)) = class else {
        return Err(MotionError::Invalid {
            at: at(Some(1), "class"),
            message: "a dense CSV motion must start with a comment line `# class = 1R` \
                      (or 1R1T, 3R)"
                .into(),
        });
    };
    let name = name.unwrap_or_else(|| {
        path.and_then(Path::file_stem)
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|| "motion".into())
    });

    let mut reader = csv::ReaderBuilder::new()
        .comment(Some(b'#'))
        .trim(csv::Trim::All)
        .has_headers(true)
        .from_reader(text.as_bytes());
    let syntax = |e: csv::Error| {
        let line = e.position().map(|p| p.line() as usize);
        MotionError::Syntax {
            at: at(line, ""),
            message: match e.kind() {
                csv::ErrorKind::UnequalLengths {
                    expected_len, len, ..
                } => format!("row has {len} columns, the header has {expected_len}"),
                _ => e.to_string(),
            },
        }
    };
    let headers = reader.headers().map_err(syntax)?.clone();
    // The first line that is neither blank nor a comment.
    let header_line = text
        .lines()
        .position(|l| !l.trim().is_empty() && !l.trim_start().starts_with('#'))
        .map_or(1, |i| i + 1);
    let found: Vec<String> = headers.iter().map(str::to_ascii_lowercase).collect();
    if found.len() < COLUMNS.len() || found[..COLUMNS.len()] != COLUMNS {
        return Err(MotionError::Invalid {
            at: at(Some(header_line.max(1)), "header"),
            message: format!(
                "header must start with `{}`, found `{}`",
                COLUMNS.join(","),
                headers.iter().collect::<Vec<_>>().join(",")
            ),
        });
    }

    let mut rows = Vec::new();
    let mut lines = Vec::new();
    let mut warnings: Vec<MotionWarning> = Vec::new();
    for record in reader.records() {
        let record = record.map_err(syntax)?;
        let line = record.position().map(|p| p.line() as usize);
        let mut v = [0.0; 8];
        for (c, name) in COLUMNS.iter().enumerate() {
            let cell = record.get(c).unwrap_or("");
            v[c] = cell.parse::<f64>().map_err(|_| MotionError::Invalid {
                at: at(line, name),
                message: format!("{cell:?} is not a number"),
            })?;
            finite(v[c], || at(line, name))?;
        }
        let rotation = unit_quaternion(
            [v[1], v[2], v[3], v[4]],
            &|| at(line, "qw,qx,qy,qz"),
            &mut warnings,
        )?;
        rows.push(DenseRow {
            t: v[0],
            rotation,
            translation: Vector3::new(v[5], v[6], v[7]),
        });
        lines.push(line.unwrap_or(0));
    }
    from_rows(
        class,
        &name,
        &rows,
        file,
        &|i| format!("row {}", i + 1),
        &lines,
    )
    .map(|mut m| {
        warnings.append(&mut m.warnings);
        m.warnings = warnings;
        m
    })
}

/// Validate and interpolate dense rows. `field` names row i in messages; `lines` (may be
/// empty) gives each row's line.
pub(crate) fn from_rows(
    class: MotionClass,
    name: &str,
    rows: &[DenseRow],
    file: Option<PathBuf>,
    field: &dyn Fn(usize) -> String,
    lines: &[usize],
) -> Result<Motion, MotionError> {
    let line = |i: usize| lines.get(i).copied().filter(|&l| l > 0);
    let mut keys = Vec::with_capacity(rows.len());
    for (i, r) in rows.iter().enumerate() {
        let at = |f: &str| Location::new(file.clone(), line(i), format!("{}.{f}", field(i)));
        let q = r.rotation.quaternion();
        for v in q.coords.iter() {
            finite(*v, || at("rotation"))?;
        }
        for v in r.translation.iter() {
            finite(*v, || at("translation"))?;
        }
        let norm = q.norm();
        if (norm - 1.0).abs() > super::QUATERNION_NORM_TOLERANCE {
            return Err(MotionError::NonUnitQuaternion {
                at: at("rotation"),
                norm,
                tolerance: super::QUATERNION_NORM_TOLERANCE,
            });
        }
        keys.push(RawKey {
            t: r.t,
            rotation: nalgebra::UnitQuaternion::new_normalize(*q),
            translation: r.translation,
            angle: None,
            line: line(i),
            field: field(i),
        });
    }
    Assembly {
        class,
        name: if name.trim().is_empty() {
            "motion".into()
        } else {
            name.trim().into()
        },
        file: file.clone(),
        keys,
        net: NetRotation::FromSamples,
        scheme: AngleScheme::Spline,
        warnings: Vec::new(),
        list_at: Location::new(file, None, "rows"),
    }
    .finish()
}

/// Write samples as a dense CSV (the format [`parse_csv`] reads), optionally with the
/// derivative columns `wx,wy,wz,ax,ay,az,vx,vy,vz,lx,ly,lz` (angular velocity, angular
/// acceleration, velocity, acceleration; per period and per period²).
pub fn write_csv<W: std::io::Write>(
    out: W,
    motion: &Motion,
    samples: &[super::PoseSample],
    derivatives: bool,
) -> std::io::Result<()> {
    use std::io::Write;
    let mut out = std::io::BufWriter::new(out);
    writeln!(out, "# class = {}", motion.class())?;
    writeln!(out, "# name = {}", motion.name())?;
    write!(out, "{}", COLUMNS.join(","))?;
    if derivatives {
        write!(out, ",wx,wy,wz,ax,ay,az,vx,vy,vz,lx,ly,lz")?;
    }
    writeln!(out)?;
    for s in samples {
        let q = s.rotation;
        let tr = s.translation;
        write!(
            out,
            "{},{},{},{},{},{},{},{}",
            s.t, q.w, q.i, q.j, q.k, tr.x, tr.y, tr.z
        )?;
        if derivatives {
            for v in [
                s.angular_velocity,
                s.angular_acceleration,
                s.velocity,
                s.acceleration,
            ] {
                write!(out, ",{},{},{}", v.x, v.y, v.z)?;
            }
        }
        writeln!(out)?;
    }
    out.flush()
}
