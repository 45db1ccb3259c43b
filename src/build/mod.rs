//! Printable parts from a mechanism: `mpc-rig build` (paper §5.3, and the bench hardware the
//! paper never had).
//!
//! ```text
//! mechanism.json ─► kinematics (law in mm) ─► shapes: rims + webs (follower), bands (driver)
//!                                              layout: hubs, joint, coupling, sensors, support
//!                                              connect: struts/posts through free space
//!                        parts: follower = rims ∪ webs ∪ struts ∪ hub … (shrunk c/2)
//!                               driver   = (bands ∪ struts ∪ hub) − sweep(rims ⊕ c/2) − bores
//!                               support  = base ∪ bosses ∪ pillar/arm or post/cup − holes
//!                        ─► mesher (closed 2-manifolds) ─► simplify (within 0.01 mm)
//!                        ─► check (edges, interference, gaps)
//!                        ─► files (STL, 3MF, GLB), renders, build.json / build.md
//! ```
//!
//! | module | owns |
//! |---|---|
//! | [`dims`] | every dimension with its reason |
//! | [`bench`](mod@bench) | which motor coupling and follower sensors, from a rig |
//! | [`kinematics`] | the parts' relative motion in mm, speed bounds |
//! | [`swept`] | coarse swept-volume fields and the exact swept distance |
//! | [`shapes`] | rims, webs, bands from the curve pairs |
//! | [`layout`] | hubs, joint, couplings, sensor features, support, by rule |
//! | [`connect`] | struts and posts planned through free space |
//! | [`segments`] | where the carve leaves a driver band in pieces |
//! | [`parts`] | the design and the three solids |
//! | [`check`] | interference and contact gaps over the period, mesh error |
//! | [`output`] | the output folder: STL, 3MF, GLB, pictures, build.json / build.md |
//!
//! It does not synthesize (`synth`), and knows meshes only through `geometry`.

pub mod bench;
pub mod check;
pub mod connect;
pub mod dims;
pub mod fidelity;
pub mod kinematics;
pub mod layout;
pub mod output;
pub mod parts;
pub mod segments;
pub mod shapes;
pub mod swept;

use std::sync::Arc;
use std::time::Instant;

use crate::geometry::mesh::{Mesh, MeshCheck};
use crate::geometry::mesher::{mesh_solid_trimmed, MeshProgress, MesherError};
use crate::geometry::sdf::{Sdf, Vec3};
use crate::geometry::simplify::{simplify, SimplifyOptions};
use crate::geometry::sweep::SweepError;
use crate::synth::closure::Class;
use crate::synth::mechanism::Mechanism;

pub use bench::Bench;
pub use check::CheckFigures;

/// What can stop a build.
#[derive(Debug, thiserror::Error)]
pub enum BuildError {
    /// An option is out of range.
    #[error("{option}: {message}")]
    BadOption {
        /// The option, as the user typed it.
        option: String,
        /// What is wrong.
        message: String,
    },
    /// The mechanism's follower law could not be rebuilt.
    #[error("the mechanism's follower_motion: {0}")]
    Motion(String),
    /// The rig cannot measure this class of mechanism.
    #[error("rig {rig:?} cannot measure a {} mechanism: it has no {missing}", class.label())]
    RigCannotMeasure {
        /// Rig name.
        rig: String,
        /// Class.
        class: Class,
        /// What is missing.
        missing: String,
    },
    /// No room for a connection.
    #[error(
        "cannot join {what}: {detail}. The design leaves no room for it: synthesize with \
         `mpc-rig synth --printable` (docs/build.md, \"Printable designs\")"
    )]
    NoRoom {
        /// What could not be joined.
        what: String,
        /// Why.
        detail: String,
    },
    /// No room for a connection in a design synthesized for printing already: another
    /// design is what can help, not the options.
    #[error(
        "cannot join {what}: {detail}. The design has the printable layout \
         (`mpc-rig synth --printable`) and still leaves no room for it: synthesize another \
         (`--seed`, or a larger `--dx`; docs/build.md, \"Printable designs\")"
    )]
    NoRoomInPrintable {
        /// What could not be joined.
        what: String,
        /// Why.
        detail: String,
    },
    /// A curve pair's samples cannot be swept into its rim or band.
    #[error(
        "the {what} of curve pair {pair} cannot be swept (frame i is sample i of the pair's \
         curve and normal): {source}"
    )]
    Sweep {
        /// `rim` (c², n²) or `band` (c¹, n¹).
        what: &'static str,
        /// The pair, from 1.
        pair: usize,
        /// Why.
        #[source]
        source: SweepError,
    },
    /// Meshing failed.
    #[error("meshing the {part}: {source}")]
    Mesh {
        /// Part.
        part: &'static str,
        /// Cause.
        #[source]
        source: MesherError,
    },
    /// A mesh is not a closed 2-manifold (a bug: the mesher guarantees it).
    #[error("the {part} mesh is not printable: {summary}")]
    NotManifold {
        /// Part.
        part: &'static str,
        /// What the edge check found.
        summary: String,
    },
    /// A part came out in several pieces that cannot be left out (follower pieces with
    /// contact surfaces, any piece of the support).
    #[error("the {part} is in {pieces} separate pieces ({detail})")]
    Disconnected {
        /// Part.
        part: &'static str,
        /// Pieces kept.
        pieces: usize,
        /// Which.
        detail: String,
    },
    /// The built parts collide, bind at a contact, or no longer close the follower with
    /// the contacts they keep.
    #[error("the built parts fail the check: {0}")]
    Interference(String),
}

/// Options of a build.
#[derive(Clone, Debug)]
pub struct BuildOptions {
    /// mm per model unit (the file's `scale_mm` when `None`).
    pub scale_mm: Option<f64>,
    /// Print clearance, mm.
    pub clearance_mm: f64,
    /// Mesher cell, mm.
    pub cell_mm: f64,
    /// How far the meshes may be simplified, mm (`geometry::simplify`; 0 keeps the
    /// mesher's triangles).
    pub simplify_mm: f64,
    /// The bench the parts are for.
    pub bench: Option<Bench>,
    /// Leave curve pair k (0-based) out: an experiment whose parts need not close.
    pub without_pair: Option<usize>,
    /// Skip the interference check's failure (still measured and reported): for
    /// experiments such as `without_pair`.
    pub allow_interference: bool,
}

impl Default for BuildOptions {
    fn default() -> Self {
        BuildOptions {
            scale_mm: None,
            clearance_mm: dims::DEFAULT_CLEARANCE_MM,
            cell_mm: dims::DEFAULT_CELL_MM,
            simplify_mm: dims::DEFAULT_SIMPLIFY_MM,
            bench: None,
            without_pair: None,
            allow_interference: false,
        }
    }
}

/// Range of the clearance option, mm: below 0 is meaningless; above 2 mm the parts rattle
/// far beyond any fit a printer needs.
pub const CLEARANCE_RANGE_MM: (f64, f64) = (0.0, 2.0);
/// Range of the mesher cell, mm: 0.1 mm is already finer than any nozzle; above 1 mm the
/// 0.85 mm apex radius of the rims is lost.
pub const CELL_RANGE_MM: (f64, f64) = (0.1, 1.0);
/// Range of the simplification bound, mm: 0 keeps the mesher's triangles; above 0.05 mm
/// the simplified surface alone would use half the 0.1 mm mesh-error budget and the
/// check's whole penetration tolerance (`check::PENETRATION_TOL_MM`).
pub const SIMPLIFY_RANGE_MM: (f64, f64) = (0.0, 0.05);
/// Range of the scale, mm per model unit: below 4 the rims and bands (mm-sized) no longer
/// fit between the 0.5-unit gaps of the bands; above 40 the parts outgrow desktop printers.
pub const SCALE_RANGE_MM: (f64, f64) = (4.0, 40.0);

/// One printed part.
#[derive(Clone, Debug)]
pub struct Part {
    /// "driver", "follower", "support".
    pub name: &'static str,
    /// The mesh in the part's own frame, mm.
    pub mesh: Mesh,
    /// What [`Mesh::check`] found on `mesh`, kept so that the reports do not check again
    /// (1.5 s for each of a fine build's parts).
    pub check: MeshCheck,
    /// Loose fragments left out, with their volume in mm³: pieces of web cut off by the
    /// driver's sweep (follower), pieces of band the carve isolates and no strut reaches
    /// (driver; the check counts the contacts they would carry as lost).
    pub dropped: Vec<f64>,
    /// When the part is in several pieces it cannot do without (not printable as one
    /// part; see `Loose`), each piece's volume in mm³, largest first; empty when it is one
    /// piece.
    pub pieces: Vec<f64>,
    /// Triangles the mesher made, before simplification.
    pub meshed_triangles: usize,
    /// Seconds spent meshing it (simplification included).
    pub seconds: f64,
    /// Seconds of those spent simplifying the mesh.
    pub simplify_seconds: f64,
    /// How far the mesh lies from the solid it was meshed from (`fidelity`).
    pub error: fidelity::MeshError,
    /// Seconds spent measuring that.
    pub error_seconds: f64,
}

/// A finished build.
pub struct Built {
    /// The design (for simulation and reports).
    pub design: parts::Design,
    /// Driver, follower, support.
    pub parts: Vec<Part>,
    /// Interference and gap figures.
    pub figures: CheckFigures,
    /// Seconds per stage.
    pub timings: Vec<(String, f64)>,
    /// Why the parts are not printable as they are (a part in several pieces, a failed
    /// check), worded for the user; empty when they are. The parts are still returned so
    /// they can be written and looked at.
    pub problems: Vec<String>,
    /// The mechanism's [`Mechanism::digest`]: `build.json` records it, and `simulate`
    /// refuses parts whose mechanism is not the one it is given.
    pub mechanism_digest: String,
}

impl Built {
    /// Printable: every part in one piece and the check passed (or not enforced).
    pub fn printable(&self) -> bool {
        self.problems.is_empty()
    }
}

fn in_range(option: &str, v: f64, r: (f64, f64)) -> Result<(), BuildError> {
    if v.is_finite() && v >= r.0 && v <= r.1 {
        Ok(())
    } else {
        Err(BuildError::BadOption {
            option: option.into(),
            message: format!("{v} is outside {}–{}", r.0, r.1),
        })
    }
}

impl BuildOptions {
    /// Refuse a clearance or mesher cell outside its range, naming the option: what a
    /// caller that builds later (`demo`, after minutes of synthesis) checks first.
    pub fn check_ranges(&self) -> Result<(), BuildError> {
        in_range("--clearance", self.clearance_mm, CLEARANCE_RANGE_MM)?;
        in_range("--cell-mm", self.cell_mm, CELL_RANGE_MM)?;
        in_range("--simplify-mm", self.simplify_mm, SIMPLIFY_RANGE_MM)
    }
}

/// Build the parts of `mech`.
pub fn build(
    mech: &Mechanism,
    opts: &BuildOptions,
    progress: &dyn Fn(&str),
) -> Result<Built, BuildError> {
    let scale = opts.scale_mm.unwrap_or(mech.scale_mm);
    in_range("--scale-mm", scale, SCALE_RANGE_MM)?;
    opts.check_ranges()?;
    if let Some(k) = opts.without_pair {
        if k >= mech.curve_pairs.len() {
            return Err(BuildError::BadOption {
                option: "--without-pair".into(),
                message: format!(
                    "pair {} does not exist (the mechanism has {})",
                    k + 1,
                    mech.curve_pairs.len()
                ),
            });
        }
    }
    let mut timings = Vec::new();
    let t0 = Instant::now();
    let kin = Arc::new(kinematics::Kinematics::new(mech, scale)?);
    let bench = opts
        .bench
        .clone()
        .unwrap_or_else(|| Bench::default_for(mech.class));
    let design = parts::design(mech, kin, &bench, opts, progress).map_err(|e| match e {
        BuildError::NoRoom { what, detail } if mech.solve.printable_layout() => {
            BuildError::NoRoomInPrintable { what, detail }
        }
        e => e,
    })?;
    timings.push(("design".to_string(), t0.elapsed().as_secs_f64()));

    let mut out = Vec::new();
    {
        progress("meshing the follower");
        let f = design.follower_solid();
        let mut anchors: Vec<Vec3> = design
            .rims
            .iter()
            .flat_map(|r| {
                r.frames()
                    .iter()
                    .step_by(10)
                    .map(|fr| fr.o - fr.u * (0.5 * dims::RIM_DEPTH_MM))
            })
            .collect();
        // The rule-placed features (hub, column, magnet cap, flange, pad, ball) are not
        // to be lost either: a magnet cap the column does not reach was once dropped as a
        // crumb of web, and the follower called printable without its magnet.
        // A feature's cover centres lie on its faces as often as inside it (a cylinder's
        // on its end faces), so points half a ball's radius from each centre towards the
        // eight corners are tried too.
        let corners: Vec<Vec3> = [-1.0, 1.0]
            .into_iter()
            .flat_map(|x| [-1.0, 1.0].into_iter().map(move |y| (x, y)))
            .flat_map(|(x, y)| [-1.0, 1.0].map(|z| Vec3::new(x, y, z).normalize()))
            .collect();
        let corners = &corners;
        anchors.extend(
            design
                .follower_pieces
                .cover
                .iter()
                .flat_map(|b| {
                    let half = 0.5 * b.radius;
                    b.centers.iter().flat_map(move |&c| {
                        std::iter::once(c).chain(corners.iter().map(move |d| c + d * half))
                    })
                })
                .filter(|&p| f.dist(p) < -FEATURE_ANCHOR_DEPTH_MM),
        );
        out.push(mesh_part(
            "follower",
            &f,
            Loose::Anchored(&anchors),
            opts,
            None,
            progress,
        )?);
    }
    {
        progress("carving and meshing the driver");
        let d = design.driver_solid();
        // Every piece but the largest is one the carve isolated and no strut reached
        // (`parts` joins all the others).
        out.push(mesh_part(
            "driver",
            &d,
            Loose::LeaveOut,
            opts,
            Some(dims::SLIVER_MM),
            progress,
        )?);
    }
    {
        progress("meshing the support");
        let s = design.support_solid();
        out.push(mesh_part(
            "support",
            &s,
            Loose::Whole,
            opts,
            None,
            progress,
        )?);
    }
    // Order: driver, follower, support.
    out.swap(0, 1);
    for p in &out {
        timings.push((format!("mesh {}", p.name), p.seconds));
    }
    timings.push((
        "mesh error".to_string(),
        out.iter().map(|p| p.error_seconds).sum(),
    ));
    progress("checking interference over the period");
    let t1 = Instant::now();
    let figures = check::run(&design, mech, &out[0].mesh, &out[1].mesh, &out[2].mesh);
    timings.push(("check".to_string(), t1.elapsed().as_secs_f64()));
    let mut problems: Vec<String> = out
        .iter()
        .filter(|p| p.pieces.len() > 1)
        .map(|p| {
            BuildError::Disconnected {
                part: p.name,
                pieces: p.pieces.len(),
                detail: format!(
                    "volumes {} mm³",
                    p.pieces
                        .iter()
                        .map(|v| format!("{v:.0}"))
                        .collect::<Vec<_>>()
                        .join(", ")
                ),
            }
            .to_string()
        })
        .collect();
    if !opts.allow_interference {
        if let Some(msg) = figures.failure() {
            problems.push(BuildError::Interference(msg).to_string());
        }
    }
    Ok(Built {
        design,
        parts: out,
        figures,
        timings,
        problems,
        mechanism_digest: mech.digest(),
    })
}

/// A rule-placed feature's cover centre this deep inside the follower anchors the shell
/// that holds it, mm: 0.5, more than the mesher moves a surface at the default 0.4 mm
/// cell (its error is below 0.1 mm there), so the point is inside the mesh too. At
/// coarser cells a feature thinner than that may go unanchored, as a web crumb does.
const FEATURE_ANCHOR_DEPTH_MM: f64 = 0.5;

/// Seconds between two progress lines of a part's meshing, at least: the driver's carve
/// takes two to three minutes at 0.4 mm cells and said nothing in between, so a person
/// could not tell it from a hang; a line every 20 s shows it moving without filling the
/// terminal.
const MESH_PROGRESS_EVERY_S: f64 = 20.0;

/// What to do with the shells of a part beyond its largest.
enum Loose<'a> {
    /// Drop those that hold none of these functional points; more than one shell holding
    /// them makes the part "in pieces" (follower: plates cut off would be an error).
    Anchored(&'a [Vec3]),
    /// Drop them all (driver: pieces of band no strut reaches; the check counts their
    /// contacts as lost).
    LeaveOut,
    /// Keep every one of [`output::CRUMB_MM3`] or more, making the part "in pieces"
    /// (support: nothing of it is expected to come loose).
    Whole,
}

/// Mesh one part (leaving out material thinner than `sliver`, when given: see
/// [`mesh_solid_trimmed`]), simplify it as `opts` says, check it, and sort out loose
/// shells as `loose` says.
fn mesh_part(
    name: &'static str,
    solid: &dyn Sdf,
    loose: Loose<'_>,
    opts: &BuildOptions,
    sliver: Option<f64>,
    progress: &dyn Fn(&str),
) -> Result<Part, BuildError> {
    let cell = opts.cell_mm;
    let t = Instant::now();
    let f = |p: Vec3| solid.dist(p);
    let mut last_line = t;
    let mut report = |r: MeshProgress| {
        if last_line.elapsed().as_secs_f64() >= MESH_PROGRESS_EVERY_S && r.done < r.known {
            last_line = Instant::now();
            progress(&format!(
                "  {name}: {} of {} blocks near the surface ({:.0} %), {:.0} s",
                r.done,
                r.known,
                100.0 * r.done as f64 / r.known as f64,
                t.elapsed().as_secs_f64()
            ));
        }
    };
    let mesh = mesh_solid_trimmed(&f, solid.bounds(), cell, sliver, &mut report)
        .map_err(|source| BuildError::Mesh { part: name, source })?;
    let meshed_triangles = mesh.len();
    let t_simplify = Instant::now();
    let mesh = if opts.simplify_mm > 0.0 {
        simplify(&mesh, &SimplifyOptions::within(opts.simplify_mm)).0
    } else {
        mesh
    };
    let simplify_seconds = t_simplify.elapsed().as_secs_f64();
    let check = mesh.check();
    if !check.is_closed_manifold() {
        return Err(BuildError::NotManifold {
            part: name,
            summary: check.summary(),
        });
    }
    let mut shells = mesh.shells();
    let mut dropped = Vec::new();
    let (mesh, check, pieces) = if shells.len() > 1 {
        shells.sort_by(|a, b| b.volume().total_cmp(&a.volume()));
        let keep = |m: &Mesh| match loose {
            Loose::Anchored(anchors) => anchors.iter().any(|a| m.contains([a.x, a.y, a.z])),
            Loose::LeaveOut => false,
            Loose::Whole => m.volume() >= output::CRUMB_MM3,
        };
        let mut kept = Vec::new();
        for (i, s) in shells.into_iter().enumerate() {
            if i == 0 || keep(&s) {
                kept.push(s);
            } else {
                dropped.push(s.volume());
            }
        }
        // Several pieces carry contact surfaces: keep them all (the caller reports the
        // part as not printable, and its files show where it comes apart).
        let pieces = if kept.len() > 1 {
            kept.iter().map(Mesh::volume).collect()
        } else {
            Vec::new()
        };
        let mut mesh = Mesh::default();
        for s in &kept {
            mesh.append(s);
        }
        let check = mesh.check();
        (mesh, check, pieces)
    } else {
        (mesh, check, Vec::new())
    };
    let seconds = t.elapsed().as_secs_f64();
    let t = Instant::now();
    let error = fidelity::mesh_error(solid, &mesh, cell);
    Ok(Part {
        name,
        mesh,
        check,
        dropped,
        pieces,
        meshed_triangles,
        seconds,
        simplify_seconds,
        error,
        error_seconds: t.elapsed().as_secs_f64(),
    })
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// The small 1R mechanism of `tests/data` the build's unit tests share.
    pub(crate) fn test_mechanism() -> Mechanism {
        let file = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("tests/data/mechanism/half-turn-2to1/mechanism.json");
        Mechanism::load(&file).expect("the test mechanism loads")
    }

    /// The printable 1R design of `tests/data` (`demo`'s half-turn-2to1: `synth
    /// --printable`, seed 1, K = 6, d_x = 7.5), whose parts the build can join.
    pub(crate) fn printable_mechanism() -> Mechanism {
        let file = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("tests/data/mechanism/half-turn-2to1-printable/mechanism.json");
        Mechanism::load(&file).expect("the printable test mechanism loads")
    }

    /// [`test_mechanism`] and its motion at 10 mm per unit.
    pub(crate) fn half_turn() -> (Mechanism, kinematics::Kinematics) {
        let mech = test_mechanism();
        let kin = kinematics::Kinematics::new(&mech, 10.0).expect("its law rebuilds");
        (mech, kin)
    }

    /// Guards which advice a design without room gets: the default layout is told to
    /// synthesize with `--printable`, a design that has that layout to synthesize another
    /// (the two test mechanisms: `synth` defaults, and `synth --printable`).
    #[test]
    fn a_printable_design_without_room_is_told_to_try_another() {
        assert!(!test_mechanism().solve.printable_layout());
        assert!(printable_mechanism().solve.printable_layout());
        let e = BuildError::NoRoomInPrintable {
            what: "plate 5 (curve pair 5)".into(),
            detail: "all 180 rays leaving it come within 2.5 mm of the other part's moving \
                     contact surfaces, so no strut can start there"
                .into(),
        };
        assert_eq!(
            e.to_string(),
            "cannot join plate 5 (curve pair 5): all 180 rays leaving it come within 2.5 mm of \
             the other part's moving contact surfaces, so no strut can start there. The design \
             has the printable layout (`mpc-rig synth --printable`) and still leaves no room \
             for it: synthesize another (`--seed`, or a larger `--dx`; docs/build.md, \
             \"Printable designs\")"
        );
    }

    /// Guards the option errors, whole: each names the option as typed and its range, and
    /// comes before any work.
    #[test]
    fn options_out_of_range_are_refused_whole() {
        let mech = test_mechanism();
        let cases = [
            (
                BuildOptions {
                    clearance_mm: 5.0,
                    ..BuildOptions::default()
                },
                "--clearance: 5 is outside 0–2",
            ),
            (
                BuildOptions {
                    scale_mm: Some(f64::NAN),
                    ..BuildOptions::default()
                },
                "--scale-mm: NaN is outside 4–40",
            ),
            (
                BuildOptions {
                    cell_mm: 0.01,
                    ..BuildOptions::default()
                },
                "--cell-mm: 0.01 is outside 0.1–1",
            ),
            (
                BuildOptions {
                    simplify_mm: 0.1,
                    ..BuildOptions::default()
                },
                "--simplify-mm: 0.1 is outside 0–0.05",
            ),
            (
                BuildOptions {
                    without_pair: Some(9),
                    ..BuildOptions::default()
                },
                "--without-pair: pair 10 does not exist (the mechanism has 4)",
            ),
        ];
        for (opts, want) in cases {
            let err = build(&mech, &opts, &|_| {}).err().expect("refused");
            assert_eq!(err.to_string(), want);
        }
    }
}
