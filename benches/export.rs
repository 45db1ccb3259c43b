//! Benchmark: the file outputs and renders of a part with about a million triangles (a torus
//! of 1000 × 500 quads, 1 000 000 triangles) — write and read times and file sizes of the
//! binary STL, the 3MF package and the animated GLB (the torus turning once in 360 keys next
//! to a static plate), and the time of shaded renders at the default size.
//!
//! Prints seconds per step, file sizes and the process's peak resident memory (`VmHWM`)
//! after each step (it only grows). Run with `cargo bench --bench export`.

use std::time::Instant;

use mpc_rig::geometry::io::gltf::write_glb;
use mpc_rig::geometry::io::stl::{read_stl, write_stl};
use mpc_rig::geometry::io::threemf::{read_3mf, write_3mf, Bed, Part};
use mpc_rig::geometry::primitive_meshes::{cuboid, torus};
use mpc_rig::geometry::render::{RenderOptions, Renderer, View};
use mpc_rig::geometry::{Pose, Scene, ScenePart};

#[path = "support/process.rs"]
mod process;

fn step<T>(what: &str, f: impl FnOnce() -> T) -> T {
    let t = Instant::now();
    let out = f();
    println!(
        "{what:<34} {:>8.3} s   peak RSS {:>6.0} MB",
        t.elapsed().as_secs_f64(),
        process::peak_rss_mb().unwrap_or(f64::NAN)
    );
    out
}

fn size_mb(path: &std::path::Path) -> f64 {
    std::fs::metadata(path).map_or(f64::NAN, |m| m.len() as f64 / 1e6)
}

fn main() {
    let dir = tempfile::tempdir().expect("a temporary directory");
    let mesh = step("build torus mesh", || {
        torus([0.0; 3], 60.0, 20.0, 1000, 500)
    });
    println!(
        "mesh: {} triangles, {} vertices",
        mesh.triangles.len(),
        mesh.vertices.len()
    );

    let stl = dir.path().join("part.stl");
    step("STL write", || {
        write_stl(&stl, &mesh, "torus").expect("STL written")
    });
    println!("STL size: {:.1} MB", size_mb(&stl));
    let back = step("STL read (welding)", || read_stl(&stl).expect("STL read"));
    assert_eq!(back.triangles.len(), mesh.triangles.len());
    drop(back);

    let plate = cuboid([-90.0, -90.0, -30.0], [90.0, 90.0, -25.0]);
    let threemf = dir.path().join("parts.3mf");
    let parts = [
        Part {
            name: "torus",
            mesh: &mesh,
        },
        Part {
            name: "plate",
            mesh: &plate,
        },
    ];
    let bed = Bed {
        size_mm: [400.0, 400.0],
        ..Bed::default()
    };
    step("3MF write", || {
        write_3mf(&threemf, &parts, &bed).expect("3MF written")
    });
    println!("3MF size: {:.1} MB", size_mb(&threemf));
    let model = step("3MF read", || read_3mf(&threemf).expect("3MF read"));
    assert_eq!(model.objects[0].mesh.triangles.len(), mesh.triangles.len());
    drop(model);

    let keys = 360;
    let turn = |k: usize| {
        let h = std::f64::consts::PI * k as f64 / keys as f64;
        Pose {
            rotation: [h.cos(), 0.0, 0.0, h.sin()],
            translation: [0.0; 3],
        }
    };
    let scene = Scene {
        parts: vec![
            ScenePart {
                name: "plate".into(),
                mesh: plate.clone(),
                color: [0.55, 0.56, 0.58, 1.0],
                poses: vec![Pose::IDENTITY],
            },
            ScenePart {
                name: "torus".into(),
                mesh,
                color: [0.9, 0.35, 0.08, 1.0],
                poses: (0..=keys).map(turn).collect(),
            },
        ],
        times_s: (0..=keys).map(|k| k as f64 / keys as f64 * 2.0).collect(),
    };
    let glb = dir.path().join("assembly.glb");
    step("GLB write (361 keys)", || {
        write_glb(&glb, &scene).expect("GLB written")
    });
    println!("GLB size: {:.1} MB", size_mb(&glb));

    let renderer = step("render: shading meshes", || {
        Renderer::new(&scene, RenderOptions::default()).expect("renderable")
    });
    for view in [View::Isometric, View::Top] {
        let img = step(&format!("render {} 1200×900 at 3×", view.name()), || {
            renderer.render(90, view).expect("rendered")
        });
        let png = dir.path().join(format!("{}.png", view.name()));
        step("PNG write", || img.write_png(&png).expect("PNG written"));
        println!("PNG size: {:.2} MB", size_mb(&png));
    }
}
