//! The 3MF package and the GLB read by a reader that is not ours: Python `trimesh` (with
//! `networkx` and `lxml`, which its 3MF loader needs; `.ci/run` installs them). Skipped, with
//! a message saying why, when python3 or those packages are missing.

use std::path::Path;
use std::process::Command;

use mpc_rig::geometry::io::gltf::write_glb;
use mpc_rig::geometry::io::threemf::{write_3mf, Bed, Part};

use crate::support::scenes;

fn trimesh_available() -> Result<(), String> {
    match Command::new("python3")
        .args(["-c", "import trimesh, networkx, lxml"])
        .output()
    {
        Err(e) => Err(format!("python3 is not runnable ({e})")),
        Ok(o) if !o.status.success() => {
            Err("trimesh is not installed (pip install trimesh networkx lxml)".into())
        }
        Ok(_) => Ok(()),
    }
}

/// Guards that slicers' kind of reader finds every part: trimesh loads the package, names
/// each object as we did, counts its vertices and faces, finds it watertight with our
/// volume, and places it where our layout put it (inside the bed, on z = 0).
#[test]
fn trimesh_reads_the_package() {
    if let Err(why) = trimesh_available() {
        eprintln!("SKIPPED trimesh_reads_the_package: {why}");
        return;
    }
    let scene = scenes::mechanism_scene(4);
    let parts: Vec<Part> = scene
        .parts
        .iter()
        .map(|p| Part {
            name: &p.name,
            mesh: &p.mesh,
        })
        .collect();
    let tmp = tempfile::tempdir().unwrap();
    let path = tmp.path().join("mechanism.3mf");
    let bed = Bed::default();
    let offsets = write_3mf(&path, &parts, &bed).expect("written");
    let report = trimesh_report(&path);
    eprintln!("trimesh: {report}");
    assert_eq!(report["units"], "millimeter");
    let objects = report["objects"].as_array().unwrap();
    assert_eq!(objects.len(), parts.len());
    for (part, offset) in parts.iter().zip(&offsets) {
        let o = objects
            .iter()
            .find(|o| o["name"] == part.name)
            .unwrap_or_else(|| panic!("trimesh has no object named {}: {report}", part.name));
        assert_eq!(o["faces"], part.mesh.triangles.len(), "{}", part.name);
        assert_eq!(o["vertices"], part.mesh.vertices.len(), "{}", part.name);
        assert_eq!(o["watertight"], true, "{}", part.name);
        assert_eq!(o["winding_consistent"], true, "{}", part.name);
        let v = o["volume"].as_f64().unwrap();
        let want = part.mesh.volume();
        assert!(
            (v - want).abs() < 1e-5 * want,
            "{}: volume {v} vs {want}",
            part.name
        );
        let b = part.mesh.aabb();
        for k in 0..3 {
            let lo = o["bounds"][0][k].as_f64().unwrap();
            let hi = o["bounds"][1][k].as_f64().unwrap();
            assert!(
                (lo - (b.min[k] + offset[k])).abs() < 1e-4,
                "{} min {k}: {lo}",
                part.name
            );
            assert!(
                (hi - (b.max[k] + offset[k])).abs() < 1e-4,
                "{} max {k}: {hi}",
                part.name
            );
        }
        let lo = &o["bounds"][0];
        let hi = &o["bounds"][1];
        assert!(lo[0].as_f64().unwrap() >= 0.0 && lo[1].as_f64().unwrap() >= 0.0);
        assert!(
            hi[0].as_f64().unwrap() <= bed.size_mm[0] && hi[1].as_f64().unwrap() <= bed.size_mm[1]
        );
        assert!(
            lo[2].as_f64().unwrap().abs() < 1e-4,
            "{} rests on the bed",
            part.name
        );
    }
}

/// What `tests/support/trimesh_check.py` finds in `path`.
fn trimesh_report(path: &Path) -> serde_json::Value {
    let script = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/tests/support/trimesh_check.py"
    );
    let out = Command::new("python3")
        .arg(script)
        .arg(path)
        .output()
        .expect("python3 runs");
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "trimesh failed:\n{stdout}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_str(stdout.trim()).expect("the script prints JSON")
}

/// Guards the GLB's units and axes as a viewer sees them: trimesh places the three parts
/// (at their first pose) in metres with our +z as glTF's +y and our +y as glTF's −z, so
/// the scene spans x −0.025…0.055 m, y −0.018…0.007 m, z −0.025…0.025 m.
#[test]
fn trimesh_sees_the_glb_upright_in_metres() {
    if let Err(why) = trimesh_available() {
        eprintln!("SKIPPED trimesh_sees_the_glb_upright_in_metres: {why}");
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let path = tmp.path().join("assembly.glb");
    write_glb(&path, &scenes::mechanism_scene(72)).expect("written");
    let report = trimesh_report(&path);
    eprintln!("trimesh: {}", report["bounds"]);
    let names: Vec<&str> = report["objects"]
        .as_array()
        .unwrap()
        .iter()
        .map(|o| o["name"].as_str().unwrap())
        .collect();
    assert_eq!(names.len(), 3, "{names:?}");
    for want in ["support", "driver", "follower"] {
        assert!(
            names.iter().any(|n| n.starts_with(want)),
            "{want} in {names:?}"
        );
    }
    let want = [[-0.025, -0.018, -0.025], [0.055, 0.007, 0.025]];
    for (i, row) in want.iter().enumerate() {
        for (k, w) in row.iter().enumerate() {
            let got = report["bounds"][i][k].as_f64().unwrap();
            assert!((got - w).abs() < 1e-6, "bounds[{i}][{k}] = {got}, want {w}");
        }
    }
}
