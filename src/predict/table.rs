//! A prediction read back as a table of free intervals over the driver angle, for the
//! simulated benches' geometry plant (`sim-device … --prediction FILE`).
//!
//! Owns [`PlayTable`]: the follower's free turn each way at each predicted driver angle
//! (and a 1R1T follower's free region), interpolated linearly between them (periodic),
//! loaded from `prediction.json` with its format and class checked, with the load the
//! prediction was made under; and [`PredictedDeviation`], the predicted laws'
//! deviations from the target that `analyze --prediction` compares a run with. A bench at
//! 1 kHz looks up two numbers per reading instead of tracing meshes. It does not decide
//! where the follower is: the plant applies the load (`predict::law` says how each one
//! leaves it).

use std::f64::consts::TAU;
use std::path::{Path, PathBuf};

use serde::Deserialize;

use super::law::{FreeRegion, Load, RAYS};
use super::output::PREDICTION_FORMAT;

/// Error loading a [`PlayTable`].
#[derive(Debug, thiserror::Error)]
pub enum TableError {
    /// The file could not be read.
    #[error("{path}: {error}")]
    Io {
        /// The file.
        path: PathBuf,
        /// Why.
        error: std::io::Error,
    },
    /// Not a prediction, or not one the plant can use.
    #[error("{path}: {message}")]
    Format {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
}

#[derive(Deserialize)]
struct File {
    format: String,
    prediction: Body,
}

#[derive(Deserialize)]
struct Body {
    class: String,
    /// Absent in a file that names none: the default, a drag.
    #[serde(default = "drag_label")]
    load: String,
    samples: Vec<Row>,
    /// Absent in a prediction made before 2026-12-06.
    #[serde(default)]
    mechanism_digest: Option<String>,
}

fn drag_label() -> String {
    Load::Drag.label()
}

#[derive(Deserialize)]
struct Row {
    driver_deg: f64,
    target_deg: f64,
    forward_deg: f64,
    reverse_deg: f64,
    free_plus_deg: f64,
    free_minus_deg: f64,
    #[serde(default)]
    drive_lost: bool,
    /// 1R1T: the target height and the predicted ones, mm.
    #[serde(default)]
    target_mm: Option<f64>,
    #[serde(default)]
    forward_mm: Option<f64>,
    #[serde(default)]
    reverse_mm: Option<f64>,
    /// 1R1T: the free region's rays, mm in the plane of the lever.
    #[serde(default)]
    region_mm: Option<[f64; RAYS]>,
}

/// The rows of a prediction file, checked, and the digest of its mechanism if it says.
fn read(path: &Path) -> Result<(Load, Vec<Row>, Option<String>), TableError> {
    let text = std::fs::read_to_string(path).map_err(|error| TableError::Io {
        path: path.to_path_buf(),
        error,
    })?;
    let bad = |message: String| TableError::Format {
        path: path.to_path_buf(),
        message,
    };
    let mut file: File = serde_json::from_str(&text).map_err(|e| bad(e.to_string()))?;
    if file.format != PREDICTION_FORMAT {
        return Err(bad(format!(
            "format {:?}, expected {PREDICTION_FORMAT:?} (the output of mpc-rig simulate)",
            file.format
        )));
    }
    let slides = match file.prediction.class.as_str() {
        "1R" => false,
        "1R1T" => true,
        class => {
            return Err(bad(format!(
                "a {class} prediction; the geometry plant takes 1R and 1R1T predictions so far"
            )))
        }
    };
    let load =
        Load::parse(&file.prediction.load).map_err(|e| bad(format!("prediction.load: {e}")))?;
    if slides && load != Load::Drag {
        return Err(bad(format!(
            "prediction.load: {}, but a 1R1T prediction is made under the drag only",
            file.prediction.load
        )));
    }
    let rows = std::mem::take(&mut file.prediction.samples);
    let n = rows.len();
    if n == 0 {
        return Err(bad("no samples".to_string()));
    }
    for (i, r) in rows.iter().enumerate() {
        let expected = 360.0 * i as f64 / n as f64;
        if (r.driver_deg - expected).abs() > 1e-6 {
            return Err(bad(format!(
                "samples[{i}].driver_deg is {}, expected {expected} (evenly spaced from 0)",
                r.driver_deg
            )));
        }
        if !(r.free_plus_deg >= 0.0 && r.free_minus_deg >= 0.0) {
            return Err(bad(format!(
                "samples[{i}]: free turns must be ≥ 0, got {} and {}",
                r.free_plus_deg, r.free_minus_deg
            )));
        }
        if slides {
            let complete =
                r.target_mm.is_some() && r.forward_mm.is_some() && r.reverse_mm.is_some();
            match r.region_mm {
                Some(region) if complete && region.iter().all(|v| *v >= 0.0) => {}
                _ => {
                    return Err(bad(format!(
                        "samples[{i}]: a 1R1T sample needs target_mm, forward_mm, reverse_mm \
                         and region_mm (eight reaches ≥ 0), as mpc-rig simulate writes them"
                    )))
                }
            }
        }
    }
    Ok((load, rows, file.prediction.mechanism_digest))
}

/// Linear interpolation in a periodic table of n values at driver angles 2π·i/n.
fn periodic(values: &[f64], phi: f64) -> f64 {
    let (i, j, f) = periodic_between(values.len(), phi);
    values[i] + f * (values[j] - values[i])
}

/// Where driver angle `phi` (rad, any real) falls in a periodic table of `n` entries at
/// 2π·i/n: the entries before and after it and the fraction of the way between them.
fn periodic_between(n: usize, phi: f64) -> (usize, usize, f64) {
    let x = phi.rem_euclid(TAU) / TAU * n as f64;
    let i = (x.floor() as usize).min(n - 1);
    (i, (i + 1) % n, x - i as f64)
}

/// The predicted deviation of the follower from its target, driven forward and in
/// reverse, over the driver angle: what `analyze --prediction` compares a measurement
/// with.
#[derive(Debug, Clone, PartialEq)]
pub struct PredictedDeviation {
    forward: Vec<f64>,
    reverse: Vec<f64>,
    /// 1R1T: the height's, mm (forward, reverse).
    heights: Option<(Vec<f64>, Vec<f64>)>,
    lost_windows_deg: Vec<[f64; 2]>,
    /// See [`PlayTable::mechanism_digest`].
    mechanism_digest: Option<String>,
}

impl PredictedDeviation {
    /// Read `prediction.json` (as [`PlayTable::load`]).
    pub fn load(path: &Path) -> Result<PredictedDeviation, TableError> {
        let (_, rows, mechanism_digest) = read(path)?;
        let lost: Vec<bool> = rows.iter().map(|r| r.drive_lost).collect();
        let height = |f: fn(&Row) -> Option<f64>| -> Option<Vec<f64>> {
            rows.iter().map(|r| Some(f(r)? - r.target_mm?)).collect()
        };
        let heights = height(|r| r.forward_mm).zip(height(|r| r.reverse_mm));
        Ok(PredictedDeviation {
            forward: rows.iter().map(|r| r.forward_deg - r.target_deg).collect(),
            reverse: rows.iter().map(|r| r.reverse_deg - r.target_deg).collect(),
            heights,
            lost_windows_deg: super::lost_windows_deg(&lost),
            mechanism_digest,
        })
    }

    /// As [`PlayTable::mechanism_digest`].
    pub fn mechanism_digest(&self) -> Option<&str> {
        self.mechanism_digest.as_deref()
    }

    /// The predicted − target of analysis channel `channel` at driver angle `phi_deg`:
    /// `rz` ([`at`](Self::at), degrees) or `tz` ([`height_at`](Self::height_at), mm);
    /// `None` for another channel or a 1R prediction's `tz`.
    pub fn of(&self, channel: &str, phi_deg: f64, forward: bool) -> Option<f64> {
        match channel {
            "rz" => Some(self.at(phi_deg, forward)),
            "tz" => self.height_at(phi_deg, forward),
            _ => None,
        }
    }

    /// Whether analysis channel `channel` has a prediction ([`of`](Self::of) gives a value):
    /// `rz` always, `tz` for a 1R1T prediction.
    pub fn predicts(&self, channel: &str) -> bool {
        channel == "rz" || (channel == "tz" && self.heights.is_some())
    }

    /// 1R1T: predicted − target height (mm) at driver angle `phi_deg`, driven forward or in
    /// reverse; `None` for a 1R prediction.
    pub fn height_at(&self, phi_deg: f64, forward: bool) -> Option<f64> {
        let (f, r) = self.heights.as_ref()?;
        Some(periodic(if forward { f } else { r }, phi_deg.to_radians()))
    }

    /// The driver angles (first and last sample, degrees) where the prediction says the
    /// parts lose the drive (`drive_lost`).
    pub fn lost_windows_deg(&self) -> &[[f64; 2]] {
        &self.lost_windows_deg
    }

    /// Predicted − target (degrees) at driver angle `phi_deg` (any real), driven forward
    /// (`forward`) or in reverse.
    pub fn at(&self, phi_deg: f64, forward: bool) -> f64 {
        let v = if forward {
            &self.forward
        } else {
            &self.reverse
        };
        periodic(v, phi_deg.to_radians())
    }
}

/// The free turn of the follower each way, over one period of the driver, rad.
#[derive(Debug, Clone, PartialEq)]
pub struct PlayTable {
    /// At driver angle 2π·i/n, the positive-sense free turn.
    plus: Vec<f64>,
    /// At driver angle 2π·i/n, the negative-sense free turn (a magnitude).
    minus: Vec<f64>,
    /// The load the prediction was made under, for the plant to apply the same.
    load: Load,
    /// 1R1T: at driver angle 2π·i/n, the free region's rays, mm in the plane of
    /// [`super::SCREW_LEVER_MM`].
    regions: Option<Vec<[f64; RAYS]>>,
    /// See [`PlayTable::mechanism_digest`].
    mechanism_digest: Option<String>,
}

impl PlayTable {
    /// A table from free turns at n evenly spaced driver angles from 0 (rad), under
    /// `load`.
    pub fn new(plus: Vec<f64>, minus: Vec<f64>, load: Load) -> PlayTable {
        assert!(
            plus.len() == minus.len() && !plus.is_empty(),
            "one free interval per angle, at least one"
        );
        PlayTable {
            plus,
            minus,
            load,
            regions: None,
            mechanism_digest: None,
        }
    }

    /// A 1R1T table: as [`PlayTable::new`] under a drag, with the free region (mm in the
    /// plane of [`super::SCREW_LEVER_MM`]) at each angle.
    pub fn with_regions(plus: Vec<f64>, minus: Vec<f64>, regions: Vec<[f64; RAYS]>) -> PlayTable {
        assert!(regions.len() == plus.len(), "one free region per angle");
        PlayTable {
            regions: Some(regions),
            ..PlayTable::new(plus, minus, Load::Drag)
        }
    }

    /// Whether the table is a 1R1T prediction's (it has free regions).
    pub fn slides(&self) -> bool {
        self.regions.is_some()
    }

    /// 1R1T: the free region at driver angle `phi` (rad, any real), each ray linear
    /// between the table's angles; `None` for a 1R table.
    pub fn region_at(&self, phi: f64) -> Option<FreeRegion> {
        let regions = self.regions.as_ref()?;
        let (i, j, f) = periodic_between(regions.len(), phi);
        let (a, b) = (&regions[i], &regions[j]);
        Some(FreeRegion {
            reach: std::array::from_fn(|k| a[k] + f * (b[k] - a[k])),
        })
    }

    /// The load the prediction was made under.
    pub fn load_applied(&self) -> Load {
        self.load
    }

    /// Read `prediction.json` (format [`PREDICTION_FORMAT`], a 1R prediction with evenly
    /// spaced driver angles from 0).
    pub fn load(path: &Path) -> Result<PlayTable, TableError> {
        let (load, rows, digest) = read(path)?;
        let plus = rows.iter().map(|r| r.free_plus_deg.to_radians()).collect();
        let minus = rows.iter().map(|r| r.free_minus_deg.to_radians()).collect();
        // `read` checked that a 1R1T prediction has every region.
        let regions: Option<Vec<[f64; RAYS]>> = rows.iter().map(|r| r.region_mm).collect();
        let table = match regions {
            Some(regions) => PlayTable::with_regions(plus, minus, regions),
            None => PlayTable::new(plus, minus, load),
        };
        Ok(PlayTable {
            mechanism_digest: digest,
            ..table
        })
    }

    /// The [`Mechanism::digest`](crate::synth::mechanism::Mechanism::digest) of the
    /// mechanism the prediction was made for, when its file says (since 2026-12-06).
    pub fn mechanism_digest(&self) -> Option<&str> {
        self.mechanism_digest.as_deref()
    }

    /// Free turns (plus, minus) at driver angle `phi` (rad, any real), linear between
    /// the table's angles.
    pub fn at(&self, phi: f64) -> (f64, f64) {
        (periodic(&self.plus, phi), periodic(&self.minus, phi))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Guards the lookup: exact at the table's angles, linear between, periodic across 2π
    /// and for negative angles.
    #[test]
    fn free_turns_interpolate_around_the_period() {
        let t = PlayTable::new(
            vec![0.0, 0.4, 0.8, 0.4],
            vec![1.0, 1.0, 2.0, 2.0],
            Load::Drag,
        );
        let q = TAU / 4.0;
        assert_eq!(t.at(0.0), (0.0, 1.0));
        assert_eq!(t.at(q), (0.4, 1.0));
        let (p, m) = t.at(1.5 * q);
        assert!((p - 0.6).abs() < 1e-12 && (m - 1.5).abs() < 1e-12);
        let (p, _) = t.at(3.5 * q);
        assert!((p - 0.2).abs() < 1e-12, "wraps to the first angle: {p}");
        let (p, _) = t.at(-0.5 * q + 3.0 * TAU);
        assert!((p - 0.2).abs() < 1e-12, "{p}");
    }

    /// Guards what a wrong file gets: a prediction of another class, or a 1R1T one without
    /// its free region, is refused with the file and the reason.
    #[test]
    fn a_prediction_of_another_class_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("prediction.json");
        std::fs::write(
            &path,
            format!(
                r#"{{"format": "{PREDICTION_FORMAT}", "prediction": {{"class": "3R", "samples": []}}}}"#
            ),
        )
        .unwrap();
        let e = PlayTable::load(&path).unwrap_err().to_string();
        assert_eq!(
            e,
            format!(
                "{}: a 3R prediction; the geometry plant takes 1R and 1R1T predictions so far",
                path.display()
            )
        );
        // A 1R1T prediction without its free region (a file older than the region, or
        // edited) is refused too, naming the sample and what it lacks.
        std::fs::write(
            &path,
            format!(
                r#"{{"format": "{PREDICTION_FORMAT}", "prediction": {{"class": "1R1T",
                    "samples": [{{"driver_deg": 0, "target_deg": 0, "forward_deg": 0,
                    "reverse_deg": 0, "free_plus_deg": 0.1, "free_minus_deg": 0.1,
                    "target_mm": 0, "forward_mm": 0, "reverse_mm": 0}}]}}}}"#
            ),
        )
        .unwrap();
        assert_eq!(
            PlayTable::load(&path).unwrap_err().to_string(),
            format!(
                "{}: samples[0]: a 1R1T sample needs target_mm, forward_mm, reverse_mm and \
                 region_mm (eight reaches ≥ 0), as mpc-rig simulate writes them",
                path.display()
            )
        );
    }

    /// Guards the drive-lost windows a report quotes: the runs of `drive_lost` rows, in
    /// driver degrees, a run across 360° as one window (first > last), and none when no
    /// row is lost.
    #[test]
    fn drive_lost_rows_become_windows_in_driver_degrees() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("prediction.json");
        let write = |lost: &dyn Fn(usize) -> bool| {
            let rows: Vec<String> = (0..8)
                .map(|i| {
                    format!(
                        r#"{{"driver_deg": {}, "target_deg": 0, "forward_deg": 0, "reverse_deg": 0,
                            "free_plus_deg": 1, "free_minus_deg": 1, "drive_lost": {}}}"#,
                        45 * i,
                        lost(i)
                    )
                })
                .collect();
            std::fs::write(
                &path,
                format!(
                    r#"{{"format": "{PREDICTION_FORMAT}", "prediction": {{"class": "1R",
                        "samples": [{}]}}}}"#,
                    rows.join(",")
                ),
            )
            .unwrap();
            PredictedDeviation::load(&path).unwrap()
        };
        let p = write(&|i| i == 2 || i == 3 || i == 7 || i == 0);
        assert_eq!(p.lost_windows_deg(), &[[90.0, 135.0], [315.0, 0.0]]);
        assert!(write(&|_| false).lost_windows_deg().is_empty());
    }
}
