//! The files of a build: what a printer, a viewer and a person read.
//!
//! Owns the output folder's layout:
//!
//! | file | what |
//! |---|---|
//! | `driver.stl`, `follower.stl`, `support.stl` | each part alone, binary STL, mm, in its own frame |
//! | `mechanism.3mf` | the three parts laid out on a bed without overlap (model part `3D/3dmodel.model`) |
//! | `assembly.glb` | the assembled parts moving over one period (animated glTF) |
//! | `assembly-isometric.png`, `assembly-front.png` | the assembly at t = 0 |
//! | `driver.png`, `follower.png`, `support.png` | each part alone, isometric |
//! | `build.json` | format [`BUILD_FORMAT`]: options, bench, per-part and check figures, timings, peak memory |
//! | `build.md` | the same for a person, with the pictures |
//!
//! It does not make or check the parts (see [`super::build`]), and writes each format
//! through `geometry::io` / `geometry::render`.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use rayon::prelude::*;
use serde_json::json;

use super::fidelity::MeshError;
use super::kinematics::Kinematics;
use super::{BuildOptions, Built, Part};
use crate::geometry::io::gltf::{write_glb_shaded, GltfError};
use crate::geometry::io::stl::{write_stl, StlError};
use crate::geometry::io::threemf::{self, Bed, LayoutError, ThreeMfError};
use crate::geometry::render::{RenderError, RenderOptions, Renderer, View};
use crate::geometry::scene::{Pose, Scene, ScenePart};
use crate::geometry::shading::{shade_scene, ShadedMesh};
use crate::geometry::thickness::WallThickness;

/// The `format` of `build.json`.
pub const BUILD_FORMAT: &str = "mpcmech-build/2";

/// Duration of one period in `assembly.glb`, s: one driver turn in 4 s (15 rpm) is slow
/// enough to follow a contact by eye.
pub const ANIMATION_PERIOD_S: f64 = 4.0;

/// Keys of the animation over one period (the last equals the first): 121 keys, 3° of driver
/// per key, so linear interpolation between keys stays within a few hundredths of a mm of
/// the law at the parts' radii.
pub const ANIMATION_KEYS: usize = 121;

/// Part colours in pictures and the GLB (linear RGBA): driver orange, follower blue,
/// support grey, the usual colours of driving, driven and fixed links in mechanism drawings.
const DRIVER_RGBA: [f32; 4] = [0.85, 0.36, 0.08, 1.0];
const FOLLOWER_RGBA: [f32; 4] = [0.10, 0.33, 0.75, 1.0];
const SUPPORT_RGBA: [f32; 4] = [0.55, 0.55, 0.55, 1.0];

/// Why the files of a build could not be written.
#[derive(Debug, thiserror::Error)]
pub enum OutputError {
    /// The folder or a text file could not be written.
    #[error("{path}: {source}")]
    Io {
        /// The file or folder.
        path: PathBuf,
        /// The system's reason.
        source: std::io::Error,
    },
    /// An STL file.
    #[error(transparent)]
    Stl(#[from] StlError),
    /// The 3MF package.
    #[error(transparent)]
    ThreeMf(#[from] ThreeMfError),
    /// The GLB file.
    #[error(transparent)]
    Gltf(#[from] GltfError),
    /// A picture.
    #[error(transparent)]
    Render(#[from] RenderError),
}

/// What [`write()`] wrote.
#[derive(Clone, Debug)]
pub struct Written {
    /// Every file, in the order of the table above.
    pub files: Vec<PathBuf>,
    /// The bed the 3MF was laid out on, mm.
    pub bed_mm: [f64; 2],
    /// Why the default bed was not used, when it was not.
    pub bed_note: Option<String>,
    /// Seconds spent writing the files and rendering the pictures (`files` in
    /// `build.json`'s timings).
    pub files_s: f64,
}

fn color(name: &str) -> [f32; 4] {
    match name {
        "driver" => DRIVER_RGBA,
        "follower" => FOLLOWER_RGBA,
        _ => SUPPORT_RGBA,
    }
}

fn pose_of(iso: &nalgebra::Isometry3<f64>) -> Pose {
    let q = iso.rotation.quaternion();
    Pose {
        rotation: [q.w, q.i, q.j, q.k],
        translation: [iso.translation.x, iso.translation.y, iso.translation.z],
    }
}

/// The assembled parts over one period, in the support's frame R (mm): the driver and the
/// follower posed by `kin`, anything else static.
pub fn scene(kin: &Kinematics, parts: &[Part]) -> Scene {
    let times: Vec<f64> = (0..ANIMATION_KEYS)
        .map(|i| i as f64 / (ANIMATION_KEYS - 1) as f64)
        .collect();
    let parts = parts
        .iter()
        .map(|p| {
            let poses = match p.name {
                // t = 1 is evaluated as t = 0 so the loop closes exactly.
                "driver" => times
                    .iter()
                    .map(|&t| pose_of(&kin.driver(t % 1.0)))
                    .collect(),
                "follower" => times
                    .iter()
                    .map(|&t| pose_of(&kin.follower(t % 1.0)))
                    .collect(),
                _ => vec![Pose::IDENTITY],
            };
            ScenePart {
                name: p.name.to_string(),
                mesh: p.mesh.clone(),
                color: color(p.name),
                poses,
            }
        })
        .collect();
    Scene {
        parts,
        times_s: times.iter().map(|t| t * ANIMATION_PERIOD_S).collect(),
    }
}

/// Lay the parts out on the default bed, or on the smallest square bed that holds them when
/// they do not fit it (said in the note).
fn write_package(path: &Path, parts: &[Part]) -> Result<([f64; 2], Option<String>), OutputError> {
    let items: Vec<threemf::Part> = parts
        .iter()
        .map(|p| threemf::Part {
            name: p.name,
            mesh: &p.mesh,
        })
        .collect();
    let bed = Bed::default();
    match threemf::layout(&items, &bed) {
        Ok(_) => {
            threemf::write_3mf(path, &items, &bed)?;
            Ok((bed.size_mm, None))
        }
        Err(LayoutError::BedTooSmall { needed, .. }) => {
            let side = needed[0].max(needed[1]).ceil();
            let big = Bed {
                size_mm: [side, side],
                ..bed
            };
            threemf::write_3mf(path, &items, &big)?;
            let note = format!(
                "the parts need {:.0} × {:.0} mm side by side, more than the {:.0} × {:.0} mm \
                 bed: print them one at a time from the STL files, or use a bed of at least \
                 {side:.0} × {side:.0} mm",
                needed[0], needed[1], bed.size_mm[0], bed.size_mm[1]
            );
            Ok(([side, side], Some(note)))
        }
        Err(LayoutError::PartTooLarge { name, size, .. }) => {
            // Three parts side by side fit a square of three times the largest footprint
            // side, gaps included (the gap is far below a part's side).
            let largest = parts
                .iter()
                .map(|p| {
                    let s = p.mesh.aabb().size();
                    s[0].max(s[1])
                })
                .fold(0.0, f64::max);
            let side = (largest + bed.gap_mm).ceil() * parts.len().max(1) as f64;
            let big = Bed {
                size_mm: [side, side],
                ..bed
            };
            threemf::write_3mf(path, &items, &big)?;
            let note = format!(
                "the {name} alone is {:.0} × {:.0} mm, larger than the {:.0} × {:.0} mm bed",
                size[0], size[1], bed.size_mm[0], bed.size_mm[1]
            );
            Ok(([side, side], Some(note)))
        }
        Err(source) => Err(ThreeMfError::Layout {
            path: path.to_path_buf(),
            source,
        }
        .into()),
    }
}

/// Write every file of `built` into `out` (created if missing). `mechanism` is the file the
/// parts were built from (recorded in `build.json`).
pub fn write(
    built: &Built,
    mechanism: &Path,
    opts: &BuildOptions,
    out: &Path,
    progress: &dyn Fn(&str),
) -> Result<Written, OutputError> {
    std::fs::create_dir_all(out).map_err(|source| OutputError::Io {
        path: out.to_path_buf(),
        source,
    })?;
    let started = std::time::Instant::now();
    let mut files = Vec::new();
    progress("writing STL, 3MF and GLB");
    let stls: Vec<PathBuf> = built
        .parts
        .iter()
        .map(|p| out.join(format!("{}.stl", p.name)))
        .collect();
    let package = out.join("mechanism.3mf");
    let glb = out.join("assembly.glb");
    // The printer's files and the viewer's are independent: written side by side (each
    // is one thread's work: a zip stream, a shading per part, a file write).
    let (printed, viewed) = rayon::join(
        || -> Result<_, OutputError> {
            for (p, path) in built.parts.iter().zip(&stls) {
                write_stl(path, &p.mesh, p.name)?;
            }
            write_package(&package, &built.parts)
        },
        || -> Result<_, OutputError> {
            let scene = scene(&built.design.kin, &built.parts);
            // One shading of each part serves the GLB and every picture.
            let shaded = shade_scene(&scene);
            write_glb_shaded(&glb, &scene, &shaded)?;
            Ok((scene, shaded))
        },
    );
    let (bed_mm, bed_note) = printed?;
    let (scene, shaded) = viewed?;
    files.extend(stls);
    files.push(package);
    files.push(glb);

    progress("rendering pictures");
    let alone: Vec<Scene> = scene
        .parts
        .iter()
        .map(|part| Scene {
            parts: vec![ScenePart {
                poses: vec![Pose::IDENTITY],
                ..part.clone()
            }],
            times_s: vec![0.0],
        })
        .collect();
    // (file, scene, its shading, view): the assembly from two sides, each part alone.
    let mut pictures: Vec<(PathBuf, &Scene, &[ShadedMesh], View)> = [View::Isometric, View::Front]
        .into_iter()
        .map(|view| {
            let path = out.join(format!("assembly-{}.png", view.name()));
            (path, &scene, &shaded[..], view)
        })
        .collect();
    for (k, one) in alone.iter().enumerate() {
        let path = out.join(format!("{}.png", one.parts[0].name));
        pictures.push((path, one, std::slice::from_ref(&shaded[k]), View::Isometric));
    }
    pictures
        .par_iter()
        .map(|(path, scene, shaded, view)| -> Result<(), OutputError> {
            Renderer::with_shading(scene, shaded, RenderOptions::default())?
                .render(0, *view)?
                .write_png(path)?;
            Ok(())
        })
        .collect::<Result<(), OutputError>>()?;
    files.extend(pictures.into_iter().map(|p| p.0));

    // After the renders, the last large allocations of a build.
    let peak_mb = peak_resident_mb();
    let files_s = started.elapsed().as_secs_f64();
    let mut timings = built.timings.clone();
    timings.push(("files".to_string(), files_s));
    let summary = Summary {
        built,
        mechanism,
        opts,
        bed_mm,
        bed_note: bed_note.as_deref(),
        timings,
        peak_mb,
    };
    let json_path = out.join("build.json");
    let text = serde_json::to_string_pretty(&summary_json(&summary))
        .expect("a JSON value always serializes");
    write_text(&json_path, &(text + "\n"))?;
    files.push(json_path);
    let md_path = out.join("build.md");
    write_text(&md_path, &summary_md(&summary))?;
    files.push(md_path);
    Ok(Written {
        files,
        bed_mm,
        bed_note,
        files_s,
    })
}

/// The process's peak resident memory so far, MB (`VmHWM` of `/proc/self/status`); `None`
/// where the system does not say (not Linux). In `demo` it includes what ran before the build.
fn peak_resident_mb() -> Option<f64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let kb: f64 = status
        .lines()
        .find_map(|l| l.strip_prefix("VmHWM:"))?
        .trim()
        .trim_end_matches("kB")
        .trim()
        .parse()
        .ok()?;
    Some(kb / 1024.0)
}

fn write_text(path: &Path, text: &str) -> Result<(), OutputError> {
    std::fs::write(path, text).map_err(|source| OutputError::Io {
        path: path.to_path_buf(),
        source,
    })
}

/// What `build.json` and `build.md` report: the build and what writing its files found.
struct Summary<'a> {
    built: &'a Built,
    mechanism: &'a Path,
    opts: &'a BuildOptions,
    bed_mm: [f64; 2],
    bed_note: Option<&'a str>,
    /// The build's stages and the files'.
    timings: Vec<(String, f64)>,
    peak_mb: Option<f64>,
}

fn summary_json(summary: &Summary) -> serde_json::Value {
    let &Summary {
        built,
        mechanism,
        opts,
        bed_mm,
        bed_note,
        ref timings,
        peak_mb,
    } = summary;
    let kin = &built.design.kin;
    let f = &built.figures;
    json!({
        "format": BUILD_FORMAT,
        "mechanism": mechanism.display().to_string(),
        "mechanism_digest": built.mechanism_digest,
        "class": kin.class().label(),
        "scale_mm": kin.scale_mm(),
        "dx_mm": kin.dx_mm(),
        "clearance_mm": opts.clearance_mm,
        "cell_mm": opts.cell_mm,
        "simplify_mm": opts.simplify_mm,
        "without_pair": opts.without_pair.map(|k| k + 1),
        "bench": built.design.layout.bench.to_string(),
        "parts": built.parts.iter().enumerate().map(|(i, p)| {
            let c = &p.check;
            let b = p.mesh.aabb();
            json!({
                "name": p.name,
                "file": format!("{}.stl", p.name),
                "triangles": c.triangles,
                "triangles_meshed": p.meshed_triangles,
                "volume_mm3": c.volume_mm3,
                "closed_manifold": c.is_closed_manifold(),
                "bbox_min_mm": b.min,
                "bbox_max_mm": b.max,
                "dropped_fragments_mm3": p.dropped,
                "pieces_mm3": p.pieces,
                "walls": f.walls.get(i).map(|w| json!({
                    "min_mm": w.min_mm,
                    "at_mm": w.at,
                    "thin_below_mm": w.thin_below_mm,
                    "thin_area_mm2": w.thin_area_mm2,
                    "area_mm2": w.area_mm2,
                    "edge_faces": w.edge_faces,
                    "edge_area_mm2": w.edge_area_mm2,
                    "reach_mm": w.reach_mm,
                })),
                "mesh_error": json!({
                    "samples": p.error.samples,
                    "mean_mm": p.error.mean_mm,
                    "p99_mm": p.error.p99_mm,
                    "max_mm": p.error.max_mm,
                    "at_mm": p.error.at,
                    "off_surface": p.error.off_surface,
                    "smooth_samples": p.error.smooth_samples,
                    "smooth_p99_mm": p.error.smooth_p99_mm,
                    "smooth_max_mm": p.error.smooth_max_mm,
                }),
                "seconds": p.seconds,
                "simplify_seconds": p.simplify_seconds,
            })
        }).collect::<Vec<_>>(),
        "printable": built.printable(),
        "problems": built.problems,
        "bed_mm": bed_mm,
        "bed_note": bed_note,
        "check": {
            "times": f.times,
            "penetrations": f.penetrations.iter().map(|p| json!({
                "what": p.what, "depth_mm": p.depth_mm, "t": p.t,
            })).collect::<Vec<_>>(),
            "gaps": f.gaps.iter().map(|g| json!({
                "pair": g.pair, "min_mm": g.min_mm, "min_t": g.min_t, "max_mm": g.max_mm,
                "mean_kept_mm": finite(g.mean_mm), "lost_fraction": g.lost_fraction,
                "lost_t": g.lost,
                "cut_by": g.cut_by.iter().map(|(rim, f)| json!({"rim": rim, "fraction": f})).collect::<Vec<_>>(),
            })).collect::<Vec<_>>(),
            "closure": {
                "max_dist": f.closure.max_dist, "worst_t": f.closure.worst_t,
                "robust_max_dist": f.closure.robust_max_dist,
                "robust_worst_t": f.closure.robust_worst_t,
                "robust_required": f.closure.robust_required,
                "instants_with_lost_contacts": f.closure.instants_with_lost_contacts,
                "samples": f.closure.samples,
            },
            "failure": f.failure(),
        },
        "timings_s": timings.iter().map(|(w, s)| json!({"stage": w, "seconds": s})).collect::<Vec<_>>(),
        "peak_memory_mb": peak_mb,
    })
}

/// A part's walls in words: `thinnest 0.62 mm at (12.0, -3.5, 40.2) mm; 1.3 % of the
/// surface (85 mm²) over walls thinner than 0.8 mm`.
pub fn walls_text(w: &WallThickness) -> String {
    let thinnest = match w.min_mm {
        Some(m) => format!(
            "thinnest {} at ({:.1}, {:.1}, {:.1}) mm",
            if m < 0.01 {
                "below 0.01 mm".to_string()
            } else {
                format!("{m:.2} mm")
            },
            w.at[0],
            w.at[1],
            w.at[2]
        ),
        None => format!("every wall thicker than {} mm", w.reach_mm),
    };
    format!(
        "{thinnest}; {:.1} % of the surface ({:.0} mm²) over walls thinner than {} mm",
        100.0 * w.thin_share(),
        w.thin_area_mm2,
        w.thin_below_mm
    )
}

/// A part's mesh error in words: `mean 0.008 mm, 99 % within 0.098 mm, largest 0.772 mm
/// at (18.9, 53.0, -47.3) mm (3993 faces; 7 more farther than 2 cells); away from sharp
/// edges (3700 faces) 99 % within 0.050 mm, largest 0.081 mm`.
pub fn mesh_error_text(e: &MeshError) -> String {
    let off = if e.off_surface > 0 {
        format!(
            "; {} more farther than {} cells",
            e.off_surface,
            super::fidelity::ERROR_REACH_CELLS
        )
    } else {
        String::new()
    };
    format!(
        "mean {:.3} mm, 99 % within {:.3} mm, largest {:.3} mm at ({:.1}, {:.1}, {:.1}) mm \
         ({} faces{off}); away from sharp edges ({} faces) 99 % within {:.3} mm, largest \
         {:.3} mm",
        e.mean_mm,
        e.p99_mm,
        e.max_mm,
        e.at[0],
        e.at[1],
        e.at[2],
        e.samples,
        e.smooth_samples,
        e.smooth_p99_mm,
        e.smooth_max_mm
    )
}

/// `t 0.120–0.180, 0.700–0.710` or `none`.
fn lost_windows_text(w: &[[f64; 2]]) -> String {
    if w.is_empty() {
        return "none".into();
    }
    w.iter()
        .map(|[a, b]| format!("{a:.3}–{b:.3}"))
        .collect::<Vec<_>>()
        .join(", ")
}

/// `1 (60.3 %), 3 (8.1 %)` or `none`.
fn cut_by_text(c: &[(usize, f64)]) -> String {
    if c.is_empty() {
        return "none".into();
    }
    c.iter()
        .map(|(rim, f)| format!("{rim} ({:.1} %)", 100.0 * f))
        .collect::<Vec<_>>()
        .join(", ")
}

/// The left-out fragments for people: pieces of at least [`CRUMB_MM3`] with their volumes,
/// then how many crumbs (mesh slivers and the shells of tiny voids) there are.
fn left_out_text(volumes: &[f64]) -> String {
    let mut big: Vec<f64> = volumes
        .iter()
        .copied()
        .filter(|v| v.abs() >= CRUMB_MM3)
        .collect();
    big.sort_by(|a, b| b.total_cmp(a));
    let crumbs = volumes.len() - big.len();
    let mut parts = Vec::new();
    if !big.is_empty() {
        parts.push(format!(
            "{} piece{} ({} mm³)",
            big.len(),
            if big.len() == 1 { "" } else { "s" },
            big.iter()
                .map(|v| format!("{v:.0}"))
                .collect::<Vec<_>>()
                .join(", ")
        ));
    }
    if crumbs > 0 {
        parts.push(format!("{crumbs} crumbs under {CRUMB_MM3} mm³"));
    }
    parts.join(" and ")
}

/// Loose shells smaller than this are crumbs, counted but not listed, mm³.
pub const CRUMB_MM3: f64 = 1.0;

/// A curve pair's row of `build.md`'s contact-gap table.
fn gap_row(g: &super::check::PairGap) -> String {
    format!(
        "| {} | {:.3} | {:.4} | {:.3} | {} | {:.1} % | {} | {} |",
        g.pair,
        g.min_mm,
        g.min_t,
        g.max_mm,
        // No contact kept at any instant (a band no strut reaches): no mean.
        finite(g.mean_mm).map_or("–".to_string(), |m| format!("{m:.3}")),
        100.0 * g.lost_fraction,
        lost_windows_text(&g.lost),
        cut_by_text(&g.cut_by)
    )
}

/// JSON has no NaN: an undefined figure is null.
fn finite(x: f64) -> Option<f64> {
    x.is_finite().then_some(x)
}

fn summary_md(summary: &Summary) -> String {
    let &Summary {
        built,
        mechanism,
        opts,
        bed_mm,
        bed_note,
        ref timings,
        peak_mb,
    } = summary;
    let kin = &built.design.kin;
    let f = &built.figures;
    let mut s = String::new();
    let _ = writeln!(s, "# Parts of {}\n", mechanism.display());
    let _ = writeln!(
        s,
        "{} mechanism, {} mm per model unit, d_x = {:.1} mm, print clearance {} mm, \
         mesher cell {} mm, {}; bench: {}.\n",
        kin.class().label(),
        kin.scale_mm(),
        kin.dx_mm(),
        opts.clearance_mm,
        opts.cell_mm,
        if opts.simplify_mm > 0.0 {
            format!("simplified within {} mm", opts.simplify_mm)
        } else {
            "not simplified".to_string()
        },
        built.design.layout.bench
    );
    if let Some(k) = opts.without_pair {
        let _ = writeln!(
            s,
            "**Curve pair {} left out** (an experiment: these parts need not close).\n",
            k + 1
        );
    }
    if !built.printable() {
        let _ = writeln!(s, "**Not printable as it is:**\n");
        for p in &built.problems {
            let _ = writeln!(s, "- {p}");
        }
        let _ = writeln!(s);
    }
    let _ = writeln!(s, "![assembly](assembly-isometric.png)\n");
    let _ = writeln!(
        s,
        "| part | triangles (the mesher's) | volume mm³ | size mm | mesh |"
    );
    let _ = writeln!(s, "|---|---:|---:|---|---|");
    for p in &built.parts {
        let c = &p.check;
        let b = p.mesh.aabb().size();
        let _ = writeln!(
            s,
            "| [{n}]({n}.stl) | {} ({}) | {:.0} | {:.0} × {:.0} × {:.0} | {} |",
            c.triangles,
            p.meshed_triangles,
            c.volume_mm3,
            b[0],
            b[1],
            b[2],
            c.summary(),
            n = p.name
        );
    }
    let _ = writeln!(
        s,
        "\nWalls, measured under every face along its inward normal (an estimate: a wall \
         thinner than the faces are wide can fall between two of them):\n"
    );
    for (p, w) in built.parts.iter().zip(&built.figures.walls) {
        let _ = writeln!(s, "- {}: {}", p.name, walls_text(w));
    }
    let _ = writeln!(
        s,
        "\nMesh error: how far the faces' centres lie from the solid they were meshed from, \
         along their normals, over {} faces drawn at random per part, each with a chance in \
         proportion to its area (so the shares are shares of the surface):\n",
        super::fidelity::ERROR_SAMPLES
    );
    for p in &built.parts {
        let _ = writeln!(s, "- {}: {}", p.name, mesh_error_text(&p.error));
    }
    for p in built.parts.iter().filter(|p| !p.dropped.is_empty()) {
        let _ = writeln!(
            s,
            "\nLeft out of the {}: {}{}.",
            p.name,
            left_out_text(&p.dropped),
            match p.name {
                "driver" => {
                    ": pieces of band the rims' sweep cuts off where no strut reaches them; \
                     the contacts they would carry count as lost below"
                }
                "follower" => ": pieces of web the driver's sweep cuts off",
                _ => "",
            }
        );
    }
    let _ = writeln!(
        s,
        "\n`mechanism.3mf` lays the parts out on a {:.0} × {:.0} mm bed.",
        bed_mm[0], bed_mm[1]
    );
    if let Some(n) = bed_note {
        let _ = writeln!(s, "Note: {n}.");
    }
    let _ = writeln!(
        s,
        "\n## Interference and contact gaps ({} instants per period)\n",
        f.times
    );
    let _ = writeln!(s, "| parts | deepest penetration mm | at t |");
    let _ = writeln!(s, "|---|---:|---:|");
    for p in &f.penetrations {
        let _ = writeln!(s, "| {} | {:.3} | {:.4} |", p.what, p.depth_mm, p.t);
    }
    let _ = writeln!(
        s,
        "\n| curve pair | gap min mm | at t | max mm | mean kept mm | contact lost | lost over t | cut by the rim of pair |"
    );
    let _ = writeln!(s, "|---:|---:|---:|---:|---:|---:|---|---|");
    for g in &f.gaps {
        let _ = writeln!(s, "{}", gap_row(g));
    }
    let c = &f.closure;
    let _ = writeln!(
        s,
        "\nA contact is lost where its gap exceeds the clearance by more than {} mm (the carve \
         took the driver's material there). With the contacts the parts keep ({} of {} \
         instants lose one or more), E_maxDist = {} (worst at t = {:.4}) and robust \
         E_maxDist = {} (worst at t = {:.4}){}; closure needs ≤ −{}.",
        super::check::GAP_TOL_MM,
        c.instants_with_lost_contacts,
        c.samples,
        crate::synth::closure::dist_text(c.max_dist),
        c.worst_t,
        crate::synth::closure::dist_text(c.robust_max_dist),
        c.robust_worst_t,
        if c.robust_required {
            ""
        } else {
            ", reported only (the design does not hold robust closure)"
        },
        crate::synth::closure::EPSILON
    );
    match f.failure() {
        None => {
            let _ = writeln!(s, "\nThe check passes.");
        }
        Some(why) => {
            let _ = writeln!(s, "\n**The check fails:** {why}.");
        }
    }
    let _ = writeln!(s, "\n## Parts\n");
    for p in &built.parts {
        let _ = writeln!(s, "![{n}]({n}.png)", n = p.name);
    }
    let _ = writeln!(s, "\n## Time\n");
    for (w, t) in timings {
        let _ = writeln!(s, "- {w}: {t:.1} s");
    }
    if let Some(mb) = peak_mb {
        let _ = writeln!(
            s,
            "\nPeak memory: {mb:.0} MB (resident, the whole process)."
        );
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Guards the reading of the peak memory: after 64 MB were written to, the process's
    /// peak is at least that (on Linux, where `/proc/self/status` says it).
    #[test]
    fn peak_memory_counts_what_was_touched() {
        if !Path::new("/proc/self/status").exists() {
            assert_eq!(peak_resident_mb(), None);
            return;
        }
        let block = vec![1u8; 64 << 20];
        std::hint::black_box(&block);
        let mb = peak_resident_mb().expect("Linux says its peak");
        assert!(mb >= 64.0, "{mb} MB");
    }

    /// Guards the words a part's walls are told in (the command's line and build.md's
    /// list): a wall below a hundredth of a millimetre is not given to the micron, and a
    /// part whose walls are all thicker than the rays reach says so.
    #[test]
    fn walls_are_told_in_words() {
        let mut w = WallThickness {
            min_mm: Some(0.004),
            at: [12.04, -3.46, 40.24],
            thin_below_mm: 0.8,
            thin_area_mm2: 85.2,
            area_mm2: 6540.0,
            edge_faces: 3,
            edge_area_mm2: 1.0,
            reach_mm: 5.0,
        };
        assert_eq!(
            walls_text(&w),
            "thinnest below 0.01 mm at (12.0, -3.5, 40.2) mm; 1.3 % of the surface (85 mm²) \
             over walls thinner than 0.8 mm"
        );
        w.min_mm = Some(0.623);
        assert!(walls_text(&w).starts_with("thinnest 0.62 mm at"));
        (w.min_mm, w.thin_area_mm2) = (None, 0.0);
        assert_eq!(
            walls_text(&w),
            "every wall thicker than 5 mm; 0.0 % of the surface (0 mm²) over walls thinner \
             than 0.8 mm"
        );
    }

    /// Guards the words a part's mesh error is told in, with and without faces off the
    /// solid's surface.
    #[test]
    fn mesh_error_is_told_in_words() {
        let mut e = MeshError {
            samples: 3993,
            mean_mm: 0.0081,
            p99_mm: 0.0984,
            max_mm: 0.7723,
            at: [18.94, 53.01, -47.33],
            off_surface: 7,
            smooth_samples: 3700,
            smooth_p99_mm: 0.0502,
            smooth_max_mm: 0.0814,
        };
        assert_eq!(
            mesh_error_text(&e),
            "mean 0.008 mm, 99 % within 0.098 mm, largest 0.772 mm at (18.9, 53.0, -47.3) mm \
             (3993 faces; 7 more farther than 2 cells); away from sharp edges (3700 faces) \
             99 % within 0.050 mm, largest 0.081 mm"
        );
        e.off_surface = 0;
        assert!(mesh_error_text(&e).contains("(3993 faces); away"));
    }

    /// Guards the gap table's row of a pair that keeps no contact (screw-bob's band 6,
    /// which no strut reached, wrote "NaN" for its mean): a dash, the rest as usual.
    #[test]
    fn a_pair_that_keeps_no_contact_has_no_mean_gap() {
        let g = crate::build::check::PairGap {
            pair: 6,
            min_mm: 2.822,
            min_t: 0.0333,
            max_mm: 23.988,
            mean_mm: f64::NAN,
            lost: vec![[0.0, 0.997]],
            lost_fraction: 1.0,
            cut_by: vec![(6, 0.092)],
        };
        assert_eq!(
            gap_row(&g),
            "| 6 | 2.822 | 0.0333 | 23.988 | – | 100.0 % | 0.000–0.997 | 6 (9.2 %) |"
        );
        let kept = crate::build::check::PairGap {
            mean_mm: 0.2214,
            ..g
        };
        assert!(gap_row(&kept).contains("| 23.988 | 0.221 | 100.0 % |"));
    }

    /// Guards the left-out line of `build.md`: pieces listed largest first with volumes,
    /// crumbs (slivers and the shells of tiny voids, volume about ±0) only counted.
    #[test]
    fn left_out_pieces_are_listed_and_crumbs_counted() {
        assert_eq!(
            left_out_text(&[699.4, 0.0, 4723.0, -0.003, 1147.2, 0.2]),
            "3 pieces (4723, 1147, 699 mm³) and 3 crumbs under 1 mm³"
        );
        assert_eq!(left_out_text(&[546.0]), "1 piece (546 mm³)");
        assert_eq!(left_out_text(&[0.0, -0.0]), "2 crumbs under 1 mm³");
        assert_eq!(
            cut_by_text(&[(1, 0.603), (3, 0.081)]),
            "1 (60.3 %), 3 (8.1 %)"
        );
    }
    use crate::geometry::io::gltf::glb_bytes;
    use crate::geometry::primitive_meshes;
    use crate::synth::mechanism::Mechanism;

    fn test_kinematics() -> Kinematics {
        let file = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("tests/data/mechanism/half-turn-2to1/mechanism.json");
        let mech = Mechanism::load(&file).expect("the test mechanism loads");
        Kinematics::new(&mech, 10.0).expect("its law rebuilds")
    }

    /// Guards the package when parts outgrow the default bed: it is still written, on a bed
    /// that holds them without overlap, and the note says why (whole text).
    #[test]
    fn parts_larger_than_the_bed_get_a_larger_bed_and_a_note() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("mechanism.3mf");
        let part = |name, w| {
            let mesh = primitive_meshes::cuboid([0.0; 3], [w, 40.0, 10.0]);
            Part {
                name,
                check: mesh.check(),
                mesh,
                dropped: Vec::new(),
                pieces: Vec::new(),
                meshed_triangles: 12,
                seconds: 0.0,
                simplify_seconds: 0.0,
                error: MeshError::default(),
                error_seconds: 0.0,
            }
        };
        let parts = [
            part("driver", 250.0),
            part("follower", 60.0),
            part("support", 90.0),
        ];
        let (bed, note) = write_package(&path, &parts).expect("written");
        assert_eq!(bed, [765.0, 765.0]);
        assert_eq!(
            note.as_deref(),
            Some("the driver alone is 250 × 40 mm, larger than the 200 × 200 mm bed")
        );
        let model = threemf::read_3mf(&path).expect("our reader reads it back");
        assert_eq!(model.objects.len(), 3);
    }

    /// Guards the animation the GLB carries: driver and follower have one pose per key, the
    /// support one; the loop closes (last key = first) and the GLB writer's own scene checks
    /// (unit quaternions, at most 150° per key, a closed loop) accept it.
    #[test]
    fn assembly_scene_loops_and_is_a_valid_glb() {
        let kin = test_kinematics();
        let mesh = primitive_meshes::cuboid([0.0; 3], [10.0, 10.0, 10.0]);
        let parts: Vec<Part> = ["driver", "follower", "support"]
            .into_iter()
            .map(|name| Part {
                name,
                mesh: mesh.clone(),
                check: mesh.check(),
                dropped: Vec::new(),
                pieces: Vec::new(),
                meshed_triangles: 12,
                seconds: 0.0,
                simplify_seconds: 0.0,
                error: MeshError::default(),
                error_seconds: 0.0,
            })
            .collect();
        let scene = scene(&kin, &parts);
        assert_eq!(scene.times_s.len(), ANIMATION_KEYS);
        assert_eq!(scene.times_s.last().copied(), Some(ANIMATION_PERIOD_S));
        let counts: Vec<usize> = scene.parts.iter().map(|p| p.poses.len()).collect();
        assert_eq!(counts, vec![ANIMATION_KEYS, ANIMATION_KEYS, 1]);
        for p in &scene.parts[..2] {
            assert_eq!(p.poses.first(), p.poses.last(), "{}", p.name);
        }
        glb_bytes(&scene).expect("the GLB writer accepts the scene");
    }
}
