//! The virtual prototype: how the built parts move the follower (`mpc-rig simulate`).
//!
//! Owns [`predict`] and [`Prediction`]. From a mechanism and the meshes `mpc-rig build`
//! wrote for it, at every one of n driver angles (default [`DEFAULT_SAMPLES`]) it finds how
//! far the follower can turn from its design pose either way before the printed parts
//! touch (exactly by [`crossings`], for any follower moving about R's z axis; [`play`]'s
//! tracer would take one whose axis moved), then where a quasi-static load leaves it
//! driven forward and in reverse
//! ([`law`]). Where the free turn exceeds [`DRIVE_LOST_DEG`] the driver no longer holds the
//! follower: the instant is reported as `drive_lost`, the paper's dynamic form closure
//! failing on the parts as printed.
//!
//! It handles 1R mechanisms under a drag (friction that opposes motion, the default), a
//! constant torque or a spring ([`law::Load`]), and 1R1T mechanisms under a drag. A 1R1T
//! follower turns and slides, so its play is found along eight rays of the plane of its
//! two deviations (a turn, a slide and the screws between them, weighed by
//! [`SCREW_LEVER_MM`]), and the drag moves it within the region they outline. The
//! spherical joint (3R) is issue 15's next step, and [`predict`] says so instead of
//! guessing. It reads no serial port and does not build parts; `cli::simulate` writes its
//! files.

pub mod crossings;
pub mod law;
pub mod output;
pub mod play;
pub mod table;

use std::path::{Path, PathBuf};
use std::time::Instant;

use nalgebra::{Isometry3, Point3, UnitQuaternion};
use serde::{Deserialize, Serialize};

use crate::build::kinematics::Kinematics;
use crate::geometry::io::stl::{read_stl, StlError};
use crate::synth::closure::Class;
use crate::synth::mechanism::Mechanism;

use play::{free_along, FreeTurns, PartMotion, Query, Screw, Solid, SolidError};

/// Driver angles per period. 1 440 (every 0.25°): the issue's floor, four times the
/// mechanism file's 360 samples, so a loss of drive shorter than one file sample shows.
pub const DEFAULT_SAMPLES: usize = 1440;
/// Fewest driver angles accepted: the mechanism file's own 360.
pub const MIN_SAMPLES: usize = 360;
/// A follower free to turn more than this (both ways together) is not driven, degrees.
/// 5°: about ten times the play the default 0.2 mm clearance gives at the 20–40 mm levers
/// of the examples' contacts (0.2 mm / 30 mm ≈ 0.4° each way), and well under the cap.
pub const DRIVE_LOST_DEG: f64 = 5.0;
/// Largest free turn traced each way, degrees: twice [`DRIVE_LOST_DEG`], so a lost drive
/// is seen clearly and the trace stays short. A side that reaches it is free (no contact
/// holds the follower that way within the cap).
pub const FREE_CAP_DEG: f64 = 10.0;
/// The lever that weighs a 1R1T follower's turn against its slide, mm: a turn of δ rad
/// counts as `SCREW_LEVER_MM`·δ mm. 30 mm: the middle of the 20–40 mm levers the examples'
/// contacts act at, where a turn of δ moves the contact points about as far as a slide of
/// 30·δ mm. The rays of the free region are laid evenly in this plane (its two screws turn
/// 1 rad per 30 mm of slide), and a drag moves the follower to the region's nearest point
/// in it.
pub const SCREW_LEVER_MM: f64 = 30.0;
/// A 1R1T follower free to move farther than this along a ray and back, both ways
/// together in the plane of [`SCREW_LEVER_MM`], is not driven, mm: [`DRIVE_LOST_DEG`] at
/// that lever (2.6 mm), so a turn alone is judged as a 1R follower's is.
pub const DRIVE_LOST_MM: f64 = DRIVE_LOST_DEG * std::f64::consts::PI / 180.0 * SCREW_LEVER_MM;
/// Largest free motion traced along each ray of a 1R1T follower, mm in the plane of
/// [`SCREW_LEVER_MM`]: [`FREE_CAP_DEG`] at that lever (5.2 mm).
pub const FREE_CAP_MM: f64 = FREE_CAP_DEG * std::f64::consts::PI / 180.0 * SCREW_LEVER_MM;

/// Error of [`predict`].
#[derive(Debug, thiserror::Error)]
pub enum PredictError {
    /// The mechanism's class is not handled yet.
    #[error(
        "simulate handles 1R and 1R1T mechanisms so far; this one is {}: its spherical joint \
         needs the free rotation about every axis, which is not built yet",
        class.label()
    )]
    Class {
        /// The mechanism's class.
        class: Class,
    },
    /// A part's mesh is missing or unreadable.
    #[error("{0}. Build the parts first: mpc-rig build MECHANISM")]
    Stl(#[from] StlError),
    /// The parts were built from another mechanism than the one given.
    #[error(
        "{}: these parts were built from another mechanism than the one given (build.json \
         records the mechanism digest {}…, the mechanism's is {}…), perhaps one synthesized \
         into the same folder since. Build them again: mpc-rig build MECHANISM",
        parts.display(),
        Mechanism::short_digest(built_from),
        Mechanism::short_digest(this)
    )]
    OtherMechanism {
        /// The parts' folder.
        parts: PathBuf,
        /// The digest `build.json` records.
        built_from: String,
        /// The mechanism's own.
        this: String,
    },
    /// `build.json` is missing or unreadable.
    #[error("{path}: {message}. Build the parts first: mpc-rig build MECHANISM")]
    Build {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
    /// A mesh cannot be queried.
    #[error(transparent)]
    Solid(#[from] SolidError),
    /// The law could not be rebuilt from the mechanism.
    #[error(transparent)]
    Law(#[from] crate::build::BuildError),
    /// An option is out of range.
    #[error("{option}: {message}")]
    BadOption {
        /// The option as typed.
        option: String,
        /// What is wrong.
        message: String,
    },
}

/// What `build.json` says about the parts that matters here.
#[derive(Debug, Clone, Deserialize)]
pub struct BuiltParts {
    /// Millimetres per model unit the parts were built at.
    pub scale_mm: f64,
    /// Print clearance, mm.
    pub clearance_mm: f64,
    /// Curve pair left out (1-based), for an experiment.
    #[serde(default)]
    pub without_pair: Option<usize>,
    /// The build's check: which design contacts the parts keep.
    pub check: BuiltCheck,
    /// [`Mechanism::digest`] of the mechanism the parts were built from (builds before
    /// 2026-12-06 have none, and are taken on trust).
    #[serde(default)]
    pub mechanism_digest: Option<String>,
    /// Whether the build found the parts printable.
    #[serde(default)]
    pub printable: bool,
    /// Why not, when they are not.
    #[serde(default)]
    pub problems: Vec<String>,
    /// Figures of each part.
    #[serde(default)]
    pub parts: Vec<BuiltPart>,
}

/// One part's figures as the build reported them.
#[derive(Debug, Clone, Deserialize)]
pub struct BuiltPart {
    /// `driver`, `follower` or `support`.
    pub name: String,
    /// Triangles of its mesh.
    pub triangles: usize,
    /// Volume, mm³.
    pub volume_mm3: f64,
    /// Corners of its bounding box in its own frame, mm.
    pub bbox_min_mm: [f64; 3],
    /// See `bbox_min_mm`.
    pub bbox_max_mm: [f64; 3],
    /// Its walls as the build measured them (builds before 2026-12-06 have none).
    #[serde(default)]
    pub walls: Option<BuiltWalls>,
    /// How far its mesh lies from its solid (builds before 2026-12-06 have none).
    #[serde(default)]
    pub mesh_error: Option<BuiltMeshError>,
}

/// A part's walls as `build.json` gives them (`build`'s wall thickness estimate).
#[derive(Debug, Clone, Deserialize)]
pub struct BuiltWalls {
    /// The thinnest wall measured, mm (none within the rays' reach).
    pub min_mm: Option<f64>,
    /// Walls thinner than this count as thin, mm.
    pub thin_below_mm: f64,
    /// Surface over thin walls, mm².
    pub thin_area_mm2: f64,
    /// Surface measured, mm².
    pub area_mm2: f64,
}

/// A part's mesh error as `build.json` gives it (`build::fidelity`).
#[derive(Debug, Clone, Deserialize)]
pub struct BuiltMeshError {
    /// 99th percentile over the faces sampled, mm.
    pub p99_mm: f64,
    /// Largest, mm.
    pub max_mm: f64,
}

/// The part of the build's check read here.
#[derive(Debug, Clone, Deserialize)]
pub struct BuiltCheck {
    /// Per curve pair in the parts.
    pub gaps: Vec<BuiltGap>,
    /// The deepest vertex of each part inside another over the period.
    #[serde(default)]
    pub penetrations: Vec<BuiltPenetration>,
}

/// How deep one part enters another over the period, as the build's check found it.
#[derive(Debug, Clone, Deserialize)]
pub struct BuiltPenetration {
    /// Which parts, e.g. `follower into driver`.
    pub what: String,
    /// Depth, mm.
    pub depth_mm: f64,
}

/// One curve pair's contact as the build's check found it.
#[derive(Debug, Clone, Deserialize)]
pub struct BuiltGap {
    /// Curve pair, 1-based.
    pub pair: usize,
    /// The smallest gap between the built surfaces at the design contact, mm (0 in files
    /// without the field).
    #[serde(default)]
    pub min_mm: f64,
    /// Windows `[first, last]` of sample times (fractions of the period) where the built
    /// parts do not keep the contact; `first > last` wraps past t = 1.
    #[serde(default)]
    pub lost_t: Vec<[f64; 2]>,
}

impl BuiltParts {
    /// Whether the parts keep curve pair `k`'s (0-based) contact at time `t`: the pair is
    /// in the parts and no lost window holds `t`.
    pub fn keeps(&self, k: usize, t: f64) -> bool {
        /// Slack on window ends, in fractions of a period (the times are i / n exactly
        /// up to rounding in the JSON).
        const EDGE: f64 = 1e-9;
        let Some(g) = self.check.gaps.iter().find(|g| g.pair == k + 1) else {
            return false;
        };
        !g.lost_t.iter().any(|&[a, b]| {
            if a <= b {
                t >= a - EDGE && t <= b + EDGE
            } else {
                t >= a - EDGE || t <= b + EDGE
            }
        })
    }

    /// Whether these parts (in `dir`) were built from the mechanism of digest `this`
    /// ([`Mechanism::digest`]): an error when `build.json` records another.
    pub fn built_from(&self, this: &str, dir: &Path) -> Result<(), PredictError> {
        match Mechanism::other_than(self.mechanism_digest.as_deref(), Some(this)) {
            Some((built_from, this)) => Err(PredictError::OtherMechanism {
                parts: dir.to_path_buf(),
                built_from: built_from.to_string(),
                this: this.to_string(),
            }),
            None => Ok(()),
        }
    }

    /// Read `dir/build.json`.
    pub fn load(dir: &Path) -> Result<BuiltParts, PredictError> {
        let path = dir.join("build.json");
        let text = std::fs::read_to_string(&path).map_err(|e| PredictError::Build {
            path: path.clone(),
            message: e.to_string(),
        })?;
        serde_json::from_str(&text).map_err(|e| PredictError::Build {
            path,
            message: e.to_string(),
        })
    }
}

/// Options of [`predict`].
#[derive(Debug, Clone, PartialEq)]
pub struct PredictOptions {
    /// Driver angles per period.
    pub samples: usize,
    /// The load on the follower.
    pub load: law::Load,
}

impl Default for PredictOptions {
    fn default() -> Self {
        PredictOptions {
            samples: DEFAULT_SAMPLES,
            load: law::Load::Drag,
        }
    }
}

/// The follower at one driver angle.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Sample {
    /// Driver angle within the period, degrees.
    pub driver_deg: f64,
    /// Target follower angle, degrees (unwrapped over the period).
    pub target_deg: f64,
    /// Predicted follower angle driven forward, degrees.
    pub forward_deg: f64,
    /// Predicted follower angle driven in reverse, degrees.
    pub reverse_deg: f64,
    /// Free turn from the design pose, positive sense, degrees (capped at
    /// [`FREE_CAP_DEG`]).
    pub free_plus_deg: f64,
    /// Free turn from the design pose, negative sense, degrees (a magnitude, capped).
    pub free_minus_deg: f64,
    /// The whole free interval, degrees.
    pub play_deg: f64,
    /// The play exceeds [`DRIVE_LOST_DEG`]: the driver does not hold the follower.
    pub drive_lost: bool,
    /// The paper's dist(t) from the mechanism file at the nearest file sample, with the
    /// curve pairs the parts have (> 0: the design contacts do not hold the follower).
    pub file_dist: f64,
    /// 1R1T: the target height along the joint axis, mm.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub target_mm: Option<f64>,
    /// 1R1T: the predicted height driven forward, mm.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub forward_mm: Option<f64>,
    /// 1R1T: the predicted height driven in reverse, mm.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub reverse_mm: Option<f64>,
    /// 1R1T: free slide from the design pose along +z, mm (capped at [`FREE_CAP_MM`]).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub free_up_mm: Option<f64>,
    /// 1R1T: free slide along −z, mm (a magnitude, capped).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub free_down_mm: Option<f64>,
    /// 1R1T: the whole free slide, mm.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub slide_play_mm: Option<f64>,
    /// 1R1T: the larger whole free motion along either screw, mm in the plane of
    /// [`SCREW_LEVER_MM`].
    #[serde(skip_serializing_if = "Option::is_none")]
    pub screw_play_mm: Option<f64>,
    /// 1R1T: the free region, how far each of its eight rays reaches, mm in the plane of
    /// [`SCREW_LEVER_MM`] (ray k at k·45° from the positive turn towards the upward slide;
    /// [`law::FreeRegion`]).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub region_mm: Option<[f64; law::RAYS]>,
}

/// A figure and the driver angle where it occurs.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Worst {
    /// The figure, degrees.
    pub deg: f64,
    /// Where, driver degrees.
    pub driver_deg: f64,
}

/// A length and the driver angle where it occurs.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct WorstMm {
    /// The figure, mm.
    pub mm: f64,
    /// Where, driver degrees.
    pub driver_deg: f64,
}

/// The prediction over one period.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Prediction {
    /// Mechanism class label.
    pub class: String,
    /// [`Mechanism::digest`] of the mechanism predicted: the geometry plant refuses the
    /// prediction for another mechanism's target.
    pub mechanism_digest: String,
    /// Load model.
    pub load: String,
    /// Print clearance of the parts, mm.
    pub clearance_mm: f64,
    /// Curve pair the parts leave out, if any.
    pub without_pair: Option<usize>,
    /// One per driver angle.
    pub samples: Vec<Sample>,
    /// Largest play.
    pub worst_play: Worst,
    /// Largest |predicted − target| of either direction.
    pub worst_deviation: Worst,
    /// Driver-angle windows `[from, to]` (degrees) where the drive is lost.
    pub drive_lost_windows: Vec<[f64; 2]>,
    /// Deepest overlap of the parts at the design pose, mm (their meshes' interference),
    /// and where, among the vertices that would otherwise stop the follower: such vertices
    /// are left out of the free-turn test. Since 2026-12-07 an overlap no vertex would stop
    /// the follower at is not measured (the build's check measures interference).
    pub overlap_mm: f64,
    /// Where the overlap is, driver degrees.
    pub overlap_driver_deg: f64,
    /// Vertices tested: driver, follower.
    pub vertices: [usize; 2],
    /// Point–mesh distance queries made.
    pub queries: u64,
    /// Wall time of the free-turn tracing, s.
    pub seconds: f64,
    /// The parts' drive against the paper's closure computed from the file with the same
    /// curve pairs.
    pub closure: ClosureAgreement,
    /// The same against the closure of only the contacts the build's check found the parts
    /// keep (`build.json` `check.gaps[].lost_t`).
    pub kept_closure: ClosureAgreement,
    /// 1R1T: the figures of the slide and the screws.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub slide: Option<SlideFigures>,
}

/// The figures of a 1R1T prediction beyond the turn's.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct SlideFigures {
    /// [`SCREW_LEVER_MM`], which weighs the turn against the slide.
    pub lever_mm: f64,
    /// Largest whole free slide.
    pub worst_slide_play: WorstMm,
    /// Largest whole free motion along a screw (mm in the plane of the lever).
    pub worst_screw_play: WorstMm,
    /// Largest |predicted − target| height of either direction.
    pub worst_height_deviation: WorstMm,
}

/// How the predicted loss of drive agrees with the paper's dynamic form closure computed
/// from the mechanism file (with the pair the parts leave out left out too), at the
/// file's sample times: dist(t) > 0 means no contact set holds the follower there.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub struct ClosureAgreement {
    /// File samples where dist(t) > 0 and the parts lose the drive.
    pub lost_both: usize,
    /// Where dist(t) > 0 but the parts still hold the follower (something other than the
    /// design contacts holds it, or the play stays under the threshold).
    pub lost_by_file_only: usize,
    /// Where dist(t) ≤ 0 but the parts lose the drive (contacts the build lost, or
    /// play from the clearance above the threshold).
    pub lost_by_parts_only: usize,
    /// Where both hold.
    pub held_both: usize,
}

/// The windows (first and last sample, driver degrees) of the runs of `true` in per-angle
/// `drive_lost` flags evenly spaced over a period from 0.
pub fn lost_windows_deg(flags: &[bool]) -> Vec<[f64; 2]> {
    crate::build::check::windows(flags)
        .into_iter()
        .map(|[a, b]| [a * 360.0, b * 360.0])
        .collect()
}

/// Drive-lost windows (driver degrees) as a person reads them: `290.5–292.25°, 359.75–0.25°`.
/// The one wording of `simulate`, `demo`, `analyze` and the report. The samples are
/// [`PredictOptions::samples`] per period (0.25° apart at the default 1 440), so bounds get
/// the two decimals that resolves, without trailing zeros: one decimal had written 292.25°
/// as 292.2° in the report while `simulate` wrote 292.25°.
pub fn lost_windows_text(windows: &[[f64; 2]]) -> String {
    let deg = |v: f64| {
        let s = format!("{v:.2}");
        let s = s.trim_end_matches('0').trim_end_matches('.');
        if s == "-0" {
            "0".to_string()
        } else {
            s.to_string()
        }
    };
    windows
        .iter()
        .map(|&[a, b]| format!("{}–{}°", deg(a), deg(b)))
        .collect::<Vec<_>>()
        .join(", ")
}

impl Prediction {
    /// The drive-lost windows as a person reads them ([`lost_windows_text`]).
    pub fn lost_windows_text(&self) -> String {
        lost_windows_text(&self.drive_lost_windows)
    }
}

impl ClosureAgreement {
    /// Count the file samples (dist per sample) against the prediction's samples nearest
    /// in time.
    fn count(dist: &[f64], samples: &[Sample]) -> ClosureAgreement {
        let mut c = ClosureAgreement {
            lost_both: 0,
            lost_by_file_only: 0,
            lost_by_parts_only: 0,
            held_both: 0,
        };
        let (m, n) = (dist.len(), samples.len());
        for (i, d) in dist.iter().enumerate() {
            let j = (i * n + m / 2) / m % n;
            match (*d > 0.0, samples[j].drive_lost) {
                (true, true) => c.lost_both += 1,
                (true, false) => c.lost_by_file_only += 1,
                (false, true) => c.lost_by_parts_only += 1,
                (false, false) => c.held_both += 1,
            }
        }
        c
    }
}

/// The parts' motion for [`play`]: the build's kinematics, with the reach bounds a 1R
/// follower and the driver have.
struct PartsMotion<'a>(&'a Kinematics);

impl PartMotion for PartsMotion<'_> {
    fn follower(&self, t: f64) -> Isometry3<f64> {
        self.0.follower(t)
    }
    fn driver(&self, t: f64) -> Isometry3<f64> {
        self.0.driver(t)
    }
    fn follower_speed(&self, q: &Point3<f64>) -> f64 {
        self.0.speed_follower_point_in_driver(q.coords)
    }
    fn driver_speed(&self, p: &Point3<f64>) -> f64 {
        self.0.speed_driver_point_in_follower(p.coords)
    }
    fn follower_reach(&self, q: &Point3<f64>) -> f64 {
        q.coords.norm() + self.0.translation_max_mm()
    }
    fn driver_reach(&self, p: &Point3<f64>) -> f64 {
        self.0.dx_mm() + p.coords.xy().norm()
    }
}

/// Signed turn about +z from `a` to `b`, rad, in (−π, π].
fn turn_about_z(a: &UnitQuaternion<f64>, b: &UnitQuaternion<f64>) -> f64 {
    let d = b * a.inverse();
    let axis = d.axis().map_or(0.0, |ax| ax.z.signum());
    axis * d.angle()
}

/// The motions a 1R1T follower's play is traced along, in the order of the rays of
/// [`law::FreeRegion`] (line k gives ray k its plus side and ray k + 4 its minus side): a
/// turn (rad), a screw at 45° in the plane of [`SCREW_LEVER_MM`], a slide and the other
/// screw (mm in that plane); and the factor from each one's unit to mm in the plane.
fn plane_lines() -> [(Screw, f64, f64); 4] {
    let c = std::f64::consts::FRAC_1_SQRT_2;
    let screw = |sense: f64| Screw {
        spin: sense * c / SCREW_LEVER_MM,
        slide: c,
    };
    [
        (Screw::TURN, FREE_CAP_DEG.to_radians(), SCREW_LEVER_MM),
        (screw(1.0), FREE_CAP_MM, 1.0),
        (Screw::SLIDE, FREE_CAP_MM, 1.0),
        (screw(-1.0), FREE_CAP_MM, 1.0),
    ]
}

/// The free regions of a 1R1T follower per sample, from the free motions along
/// [`plane_lines`].
fn free_regions(lines: &[FreeTurns]) -> Vec<law::FreeRegion> {
    let scale = plane_lines().map(|l| l.2);
    (0..lines[0].plus.len())
        .map(|i| {
            let mut reach = [0.0; law::RAYS];
            for k in 0..4 {
                reach[k] = lines[k].plus[i] * scale[k];
                reach[k + 4] = lines[k].minus[i] * scale[k];
            }
            law::FreeRegion { reach }
        })
        .collect()
}

/// A 1R1T follower's law along its axis: per sample, the target height (mm), the
/// predicted deviations from it driven forward and in reverse (mm), and the free region.
struct Plane {
    height: Vec<f64>,
    forward: Vec<f64>,
    reverse: Vec<f64>,
    regions: Vec<law::FreeRegion>,
}

/// The largest of `f` over `samples`, and where (the first sample when nothing is above 0).
fn worst_of(samples: &[Sample], f: impl Fn(&Sample) -> f64) -> (f64, f64) {
    samples.iter().fold((0.0, 0.0), |w, s| {
        let v = f(s);
        if v > w.0 {
            (v, s.driver_deg)
        } else {
            w
        }
    })
}

/// Predict how the parts in `parts_dir` (built from `mech`) move the follower.
pub fn predict(
    mech: &Mechanism,
    parts_dir: &Path,
    opts: &PredictOptions,
) -> Result<Prediction, PredictError> {
    let slides = match mech.class {
        Class::R1 => false,
        Class::R1T1 => true,
        Class::R3 => return Err(PredictError::Class { class: mech.class }),
    };
    if slides && opts.load != law::Load::Drag {
        return Err(PredictError::BadOption {
            option: format!("--load {}", opts.load.label()),
            message: "a 1R1T follower takes the drag only so far: a torque or a spring about \
                      its axis leaves its height to friction alone, which is not modelled"
                .to_string(),
        });
    }
    if opts.samples < MIN_SAMPLES {
        return Err(PredictError::BadOption {
            option: format!("--samples {}", opts.samples),
            message: format!("at least {MIN_SAMPLES} driver angles per period"),
        });
    }
    let built = BuiltParts::load(parts_dir)?;
    // Serializes the whole mechanism (0.8 MB for the demo's): once.
    let digest = mech.digest();
    built.built_from(&digest, parts_dir)?;
    let kin = Kinematics::new(mech, built.scale_mm)?;
    // Each part is read and prepared on its own thread: reading the STL and building
    // parry's BVH are serial inside. On the demo's parts `simulate` went from 55.6 to
    // 48.4 s wall (2026-12-05). The driver's parry hierarchy is made only if the tracer
    // asks for it: the crossings ask the driver a few exact distances, from its clusters
    // (`Solid::signed_near`). The follower's distance grid and its bins, which the
    // crossings ask for, are made beside its hierarchy (the tracer, needed only for a
    // follower whose axis moves, makes the driver's grid itself).
    let read = |part: &str| read_stl(&parts_dir.join(format!("{part}.stl")));
    let (driver, follower) = rayon::join(
        || -> Result<Solid, PredictError> {
            Ok(Solid::with_query(
                &read("driver")?,
                "driver",
                Query::WhenAsked,
            )?)
        },
        || -> Result<(Solid, crossings::Bins), PredictError> {
            Ok(Solid::with_query_beside(
                &read("follower")?,
                "follower",
                |f| {
                    f.prepare_bounds();
                    crossings::Bins::new(f)
                },
            )?)
        },
    );
    let (driver, (follower, bins)) = (driver?, follower?);
    let n = opts.samples;
    let motions: Vec<(Screw, f64)> = if slides {
        plane_lines().iter().map(|l| (l.0, l.1)).collect()
    } else {
        vec![(Screw::TURN, FREE_CAP_DEG.to_radians())]
    };
    let started = Instant::now();
    // A follower moving about R's z axis has its free motions found exactly by
    // `crossings`; the tracer takes any other.
    let motion = PartsMotion(&kin);
    let bins = Some(&bins);
    let lines = crossings::free_along_binned(&motion, &driver, &follower, bins, n, &motions)
        .unwrap_or_else(|| free_along(&motion, &driver, &follower, n, &motions));
    let seconds = started.elapsed().as_secs_f64();
    let free = &lines[0];

    // The target law as steps between samples, and unwrapped from its first pose.
    let poses: Vec<Isometry3<f64>> = (0..=n).map(|i| kin.follower(i as f64 / n as f64)).collect();
    let step: Vec<f64> = (0..n)
        .map(|i| turn_about_z(&poses[i].rotation, &poses[i + 1].rotation))
        .collect();
    let mut target = Vec::with_capacity(n);
    let mut angle = turn_about_z(&UnitQuaternion::identity(), &poses[0].rotation);
    for s in &step {
        target.push(angle);
        angle += s;
    }
    let (fwd, rev, plane) = if slides {
        // Deviations in the plane of the lever: the turn's times the lever, the slide's.
        let height: Vec<f64> = poses.iter().map(|p| p.translation.z).collect();
        let plane_step: Vec<[f64; 2]> = (0..n)
            .map(|i| [step[i] * SCREW_LEVER_MM, height[i + 1] - height[i]])
            .collect();
        let regions = free_regions(&lines);
        let fwd = law::drag_plane(&plane_step, &regions, true);
        let rev = law::drag_plane(&plane_step, &regions, false);
        let turn = |e: &[[f64; 2]]| e.iter().map(|d| d[0] / SCREW_LEVER_MM).collect();
        let plane = Plane {
            height,
            forward: fwd.iter().map(|d| d[1]).collect(),
            reverse: rev.iter().map(|d| d[1]).collect(),
            regions,
        };
        (turn(&fwd), turn(&rev), Some(plane))
    } else {
        let fwd = law::under(opts.load, &target, &step, &free.plus, &free.minus, true);
        let rev = law::under(opts.load, &target, &step, &free.plus, &free.minus, false);
        (fwd, rev, None)
    };
    let mut samples: Vec<Sample> = (0..n)
        .map(|i| {
            let play = (free.plus[i] + free.minus[i]).to_degrees();
            let mut s = Sample {
                driver_deg: 360.0 * i as f64 / n as f64,
                target_deg: target[i].to_degrees(),
                forward_deg: (target[i] + fwd[i]).to_degrees(),
                reverse_deg: (target[i] + rev[i]).to_degrees(),
                free_plus_deg: free.plus[i].to_degrees(),
                free_minus_deg: free.minus[i].to_degrees(),
                play_deg: play,
                drive_lost: play > DRIVE_LOST_DEG,
                file_dist: 0.0,
                target_mm: None,
                forward_mm: None,
                reverse_mm: None,
                free_up_mm: None,
                free_down_mm: None,
                slide_play_mm: None,
                screw_play_mm: None,
                region_mm: None,
            };
            if let Some(p) = &plane {
                let r = p.regions[i].reach;
                // Both ways together along each of the region's four lines.
                let line = |k: usize| r[k] + r[k + 4];
                s.drive_lost = (0..4).any(|k| line(k) > DRIVE_LOST_MM);
                s.target_mm = Some(p.height[i]);
                s.forward_mm = Some(p.height[i] + p.forward[i]);
                s.reverse_mm = Some(p.height[i] + p.reverse[i]);
                s.free_up_mm = Some(r[2]);
                s.free_down_mm = Some(r[6]);
                s.slide_play_mm = Some(line(2));
                s.screw_play_mm = Some(line(1).max(line(3)));
                s.region_mm = Some(r);
            }
            s
        })
        .collect();
    let worst = |f: &dyn Fn(&Sample) -> f64| {
        let (deg, driver_deg) = worst_of(&samples, f);
        Worst { deg, driver_deg }
    };
    let worst_mm = |f: &dyn Fn(&Sample) -> f64| {
        let (mm, driver_deg) = worst_of(&samples, f);
        WorstMm { mm, driver_deg }
    };
    let worst_play = worst(&|s| s.play_deg);
    let worst_deviation = worst(&|s| {
        (s.forward_deg - s.target_deg)
            .abs()
            .max((s.reverse_deg - s.target_deg).abs())
    });
    let slide = slides.then(|| SlideFigures {
        lever_mm: SCREW_LEVER_MM,
        worst_slide_play: worst_mm(&|s| s.slide_play_mm.unwrap_or(0.0)),
        worst_screw_play: worst_mm(&|s| s.screw_play_mm.unwrap_or(0.0)),
        worst_height_deviation: worst_mm(&|s| match (s.target_mm, s.forward_mm, s.reverse_mm) {
            (Some(t), Some(f), Some(r)) => (f - t).abs().max((r - t).abs()),
            _ => 0.0,
        }),
    });
    let flags: Vec<bool> = samples.iter().map(|s| s.drive_lost).collect();
    let drive_lost_windows = lost_windows_deg(&flags);
    let skip = built.without_pair.map(|k| k.saturating_sub(1));
    let file = mech.closure_with(|k, _| Some(k) != skip);
    let m = mech.samples;
    let kept = mech.closure_with(|k, i| built.keeps(k, i as f64 / m as f64));
    for (j, s) in samples.iter_mut().enumerate() {
        s.file_dist = file.dist[(j * m + n / 2) / n % m];
    }
    let closure = ClosureAgreement::count(&file.dist, &samples);
    let kept_closure = ClosureAgreement::count(&kept.dist, &samples);
    Ok(Prediction {
        class: mech.class.label().to_string(),
        mechanism_digest: digest,
        load: opts.load.label(),
        clearance_mm: built.clearance_mm,
        without_pair: built.without_pair,
        samples,
        worst_play,
        worst_deviation,
        drive_lost_windows,
        overlap_mm: free.overlap_mm,
        overlap_driver_deg: free.overlap_t * 360.0,
        vertices: [driver.vertex_count(), follower.vertex_count()],
        queries: free.queries,
        seconds,
        closure,
        kept_closure,
        slide,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector3;

    /// Guards the refusal of stale parts: `build.json` recording another mechanism's
    /// digest is an error that says so (whole text), its own digest or none (a build from
    /// before digests) is accepted, and a mechanism changed in one figure has another
    /// digest.
    #[test]
    fn parts_of_another_mechanism_are_refused() {
        let path = Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("tests/data/mechanism/half-turn-2to1-printable/mechanism.json");
        let mech = Mechanism::load(&path).unwrap();
        let built_with = |digest: Option<String>| -> BuiltParts {
            let mut built: BuiltParts = serde_json::from_str(
                r#"{"scale_mm": 10, "clearance_mm": 0.2, "check": {"gaps": []}}"#,
            )
            .unwrap();
            built.mechanism_digest = digest;
            built
        };
        let dir = Path::new("out/parts");
        built_with(None).built_from(&mech.digest(), dir).unwrap();
        built_with(Some(mech.digest()))
            .built_from(&mech.digest(), dir)
            .unwrap();

        let mut other = mech.clone();
        other.driver_offset += 0.1;
        assert_ne!(other.digest(), mech.digest());
        // As `synth` writes it and `build` or `simulate` reads it back.
        let saved: Mechanism =
            serde_json::from_str(&serde_json::to_string_pretty(&mech).unwrap()).unwrap();
        assert_eq!(
            saved.digest(),
            mech.digest(),
            "a saved mechanism keeps its digest"
        );
        let err = built_with(Some(other.digest()))
            .built_from(&mech.digest(), dir)
            .unwrap_err();
        assert_eq!(
            err.to_string(),
            format!(
                "out/parts: these parts were built from another mechanism than the one given \
                 (build.json records the mechanism digest {}…, the mechanism's is {}…), \
                 perhaps one synthesized into the same folder since. Build them again: \
                 mpc-rig build MECHANISM",
                &other.digest()[..12],
                &mech.digest()[..12]
            )
        );
    }

    /// Guards the one wording of drive-lost windows: bounds to the samples' 0.25° without
    /// trailing zeros, a window across 0° as it is, nothing for no window.
    #[test]
    fn drive_lost_windows_read_to_the_sample() {
        assert_eq!(
            lost_windows_text(&[[290.5, 292.25], [359.75, 0.25], [10.0, 12.0]]),
            "290.5–292.25°, 359.75–0.25°, 10–12°"
        );
        assert_eq!(lost_windows_text(&[]), "");
    }

    /// Guards the glue between the traced motions and the free region: line k of
    /// [`plane_lines`], per unit of its parameter and divided by its factor to mm, moves the
    /// follower along ray k of [`law::FreeRegion`] (k·45° in the plane of the turn times
    /// [`SCREW_LEVER_MM`] and the slide), by 1 mm; and [`free_regions`] puts each line's
    /// plus side on ray k and its minus side on ray k + 4, in mm.
    #[test]
    fn the_traced_lines_are_the_free_region_s_rays() {
        for (k, (screw, cap, factor)) in plane_lines().into_iter().enumerate() {
            let a = k as f64 * std::f64::consts::FRAC_PI_4;
            // A turn's parameter is in rad, and one rad moves `factor` mm along its ray.
            let step = [screw.spin * SCREW_LEVER_MM / factor, screw.slide / factor];
            assert!((step[0] - a.cos()).abs() < 1e-12, "line {k}: {step:?}");
            assert!((step[1] - a.sin()).abs() < 1e-12, "line {k}: {step:?}");
            assert!(
                (cap * factor - FREE_CAP_MM).abs() < 1e-9,
                "line {k}: cap {cap}"
            );
        }
        let line = |plus: f64, minus: f64| FreeTurns {
            plus: vec![plus],
            minus: vec![minus],
            overlap_mm: 0.0,
            overlap_t: 0.0,
            queries: 0,
        };
        let regions = free_regions(&[
            line(0.01, 0.02),
            line(0.3, 0.4),
            line(0.5, 0.6),
            line(0.7, 0.8),
        ]);
        let want = [0.3, 0.3, 0.5, 0.7, 0.6, 0.4, 0.6, 0.8];
        for (k, (got, want)) in regions[0].reach.iter().zip(want).enumerate() {
            assert!((got - want).abs() < 1e-12, "ray {k}: {got} vs {want}");
        }
    }

    /// Guards the sign of the target's steps: a turn of +0.3 rad about +z reads +0.3, and
    /// one about −z reads −0.3.
    #[test]
    fn turns_about_z_are_signed() {
        let a = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), 1.0);
        let b = UnitQuaternion::from_axis_angle(&Vector3::z_axis(), 1.3);
        assert!((turn_about_z(&a, &b) - 0.3).abs() < 1e-12);
        assert!((turn_about_z(&b, &a) + 0.3).abs() < 1e-12);
        assert_eq!(turn_about_z(&a, &a), 0.0);
    }
}
