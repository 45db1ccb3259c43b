//! `assembly.glb` read by readers that are not our writer: the `gltf` crate loads it back
//! (nodes, meshes, materials, the animation, every number), and the Khronos glTF validator
//! (npm `gltf-validator`, installed by `.ci/run` into `scripts/gltf-validate/`) finds no
//! error in it. The validator test skips, saying why, when node or the package is missing.

use std::path::Path;
use std::process::Command;

use gltf::animation::util::ReadOutputs;
use gltf::animation::Property;
use gltf::buffer::Source;
use mpc_rig::geometry::io::gltf::{glb_bytes, write_glb};
use mpc_rig::geometry::{Mesh, Scene};

use crate::support::scenes;

/// Keys of the test scene: 5° of driver turn per key.
const KEYS: usize = 72;

/// Guards the whole document: the root node scales mm to m and holds one node per part in
/// order; each part's mesh, welded back from the GLB's positions, is the part's closed mesh
/// with its volume (so split normals kept the topology), with unit normals; each material
/// carries the part's colour; the animation has a rotation and a translation channel per
/// moving part, LINEAR, whose keys are the scene's times and poses.
#[test]
fn glb_loads_with_the_gltf_crate() {
    let scene = scenes::mechanism_scene(KEYS);
    let bytes = glb_bytes(&scene).expect("the scene is writable");
    let glb = gltf::Gltf::from_slice(&bytes).expect("the gltf crate reads the GLB");
    let blob = glb.blob.as_deref().expect("a BIN chunk");
    let buffers = |b: gltf::Buffer<'_>| match b.source() {
        Source::Bin => Some(blob),
        Source::Uri(_) => None,
    };
    let doc = &glb.document;
    let root = doc
        .default_scene()
        .expect("a default scene")
        .nodes()
        .next()
        .unwrap();
    assert_eq!(root.name(), Some("assembly"));
    let (_, _, scale) = root.transform().decomposed();
    assert_eq!(scale, [0.001; 3]);
    let children: Vec<_> = root.children().collect();
    assert_eq!(children.len(), scene.parts.len());
    for (node, part) in children.iter().zip(&scene.parts) {
        assert_eq!(node.name(), Some(part.name.as_str()));
        let mesh = node.mesh().expect("a part node has a mesh");
        let prim = mesh.primitives().next().unwrap();
        let pbr = prim.material().pbr_metallic_roughness();
        assert_eq!(pbr.base_color_factor(), part.color);
        let reader = prim.reader(buffers);
        let positions: Vec<[f32; 3]> = reader.read_positions().unwrap().collect();
        let normals: Vec<[f32; 3]> = reader.read_normals().unwrap().collect();
        let indices: Vec<u32> = reader.read_indices().unwrap().into_u32().collect();
        assert_eq!(normals.len(), positions.len());
        for n in &normals {
            let l = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
            assert!((l - 1.0).abs() < 1e-6, "normal {n:?}");
        }
        let welded = weld(&positions, &indices);
        let check = welded.check();
        assert!(
            check.is_closed_manifold(),
            "{}: {}",
            part.name,
            check.summary()
        );
        assert_eq!(welded.triangles.len(), part.mesh.triangles.len());
        let rel = (check.volume_mm3 - part.mesh.volume()).abs() / part.mesh.volume();
        assert!(
            rel < 1e-6,
            "{}: volume {} vs {}",
            part.name,
            check.volume_mm3,
            part.mesh.volume()
        );
    }
    let anims: Vec<_> = doc.animations().collect();
    assert_eq!(anims.len(), 1);
    let channels: Vec<_> = anims[0].channels().collect();
    assert_eq!(
        channels.len(),
        4,
        "rotation + translation for the driver and the follower"
    );
    for ch in &channels {
        assert_eq!(
            ch.sampler().interpolation(),
            gltf::animation::Interpolation::Linear
        );
        let node = ch.target().node();
        let part = scene
            .parts
            .iter()
            .find(|p| Some(p.name.as_str()) == node.name())
            .expect("the channel targets a part");
        let reader = ch.reader(buffers);
        let times: Vec<f32> = reader.read_inputs().unwrap().collect();
        let want: Vec<f32> = scene.times_s.iter().map(|&t| t as f32).collect();
        assert_eq!(times, want);
        match (ch.target().property(), reader.read_outputs().unwrap()) {
            (Property::Rotation, ReadOutputs::Rotations(r)) => {
                for (k, q) in r.into_f32().enumerate() {
                    let p = part.poses[k].rotation; // [w, x, y, z]
                    let d = f64::from(q[3]) * p[0]
                        + f64::from(q[0]) * p[1]
                        + f64::from(q[1]) * p[2]
                        + f64::from(q[2]) * p[3];
                    assert!(
                        d.abs() > 1.0 - 1e-6,
                        "{} key {k}: {q:?} vs {p:?}",
                        part.name
                    );
                }
            }
            (Property::Translation, ReadOutputs::Translations(t)) => {
                for (k, v) in t.enumerate() {
                    let p = part.poses[k].translation;
                    for c in 0..3 {
                        assert!(
                            (f64::from(v[c]) - p[c]).abs() < 1e-5,
                            "{} key {k}",
                            part.name
                        );
                    }
                }
            }
            (p, _) => panic!("unexpected channel {p:?}"),
        }
    }
}

/// Weld the GLB's split vertices back by position.
fn weld(positions: &[[f32; 3]], indices: &[u32]) -> Mesh {
    let mut index = std::collections::HashMap::new();
    let mut mesh = Mesh::default();
    let remap: Vec<u32> = positions
        .iter()
        .map(|p| {
            *index.entry(p.map(f32::to_bits)).or_insert_with(|| {
                mesh.vertices.push(p.map(f64::from));
                (mesh.vertices.len() - 1) as u32
            })
        })
        .collect();
    mesh.triangles = indices
        .chunks_exact(3)
        .map(|t| {
            [
                remap[t[0] as usize],
                remap[t[1] as usize],
                remap[t[2] as usize],
            ]
        })
        .collect();
    mesh
}

/// Why the Khronos validator cannot run here, if it cannot.
fn validator_missing(dir: &Path) -> Option<String> {
    match Command::new("node").arg("--version").output() {
        Err(e) => return Some(format!("node is not runnable ({e})")),
        Ok(o) if !o.status.success() => return Some("node --version failed".into()),
        Ok(_) => {}
    }
    if !dir.join("node_modules/gltf-validator").is_dir() {
        return Some(format!(
            "the validator is not installed (cd {} && npm ci)",
            dir.display()
        ));
    }
    None
}

/// Guards that the GLB of a moving scene passes the Khronos glTF validator with zero errors
/// (warnings and infos are printed).
#[test]
fn glb_passes_the_khronos_validator() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("scripts/gltf-validate");
    if let Some(why) = validator_missing(&dir) {
        eprintln!("SKIPPED glb_passes_the_khronos_validator: {why}");
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let path = tmp.path().join("assembly.glb");
    write_glb(&path, &scenes::mechanism_scene(KEYS)).expect("written");
    let report = validate(&dir, &path);
    assert_eq!(report["errors"], 0, "validator report: {report:#}");
}

/// A static scene (no animation) passes too.
#[test]
fn static_glb_passes_the_khronos_validator() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("scripts/gltf-validate");
    if let Some(why) = validator_missing(&dir) {
        eprintln!("SKIPPED static_glb_passes_the_khronos_validator: {why}");
        return;
    }
    let mut scene: Scene = scenes::mechanism_scene(KEYS);
    for p in &mut scene.parts {
        p.poses.truncate(1);
    }
    let tmp = tempfile::tempdir().unwrap();
    let path = tmp.path().join("static.glb");
    write_glb(&path, &scene).expect("written");
    let report = validate(&dir, &path);
    assert_eq!(report["errors"], 0, "validator report: {report:#}");
}

/// Run the validator on `path` and return its JSON report, printing every message.
fn validate(dir: &Path, path: &Path) -> serde_json::Value {
    let out = Command::new("node")
        .arg(dir.join("validate.js"))
        .arg(path)
        .output()
        .expect("node runs");
    let stdout = String::from_utf8_lossy(&out.stdout);
    let report: serde_json::Value = serde_json::from_str(stdout.trim()).unwrap_or_else(|e| {
        panic!(
            "validator output is not a report ({e}):\n{stdout}\n{}",
            String::from_utf8_lossy(&out.stderr)
        )
    });
    for m in report["messages"].as_array().into_iter().flatten() {
        eprintln!("gltf-validator: {}", m.as_str().unwrap_or_default());
    }
    eprintln!(
        "gltf-validator: {} errors, {} warnings, {} infos, {} hints",
        report["errors"], report["warnings"], report["infos"], report["hints"]
    );
    report
}
