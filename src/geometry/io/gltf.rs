//! `assembly.glb`: a [`Scene`] as binary glTF 2.0 that any glTF viewer shows and plays.
//!
//! Owns the GLB container and the glTF document we write:
//! - **one mesh per part**: positions, unit normals and `u32` indices of the part's
//!   [`ShadedMesh`] (split at
//!   [`CREASE_ANGLE_DEG`](crate::geometry::shading::CREASE_ANGLE_DEG), so freeform contact
//!   surfaces shade smoothly and printed edges stay crisp);
//! - **one material per part**: its colour as the PBR base colour (linear RGBA, as
//!   [`ScenePart::color`](crate::geometry::ScenePart::color) is), non-metallic, roughness
//!   [`ROUGHNESS`]; `BLEND` when the colour is translucent;
//! - **one node per part**, holding its first pose, under one root node;
//! - **one animation** "period" when some part moves: for each moving part a rotation and a
//!   translation channel with LINEAR interpolation over the scene's key times. Consecutive
//!   quaternions are sign-aligned (glTF interpolates the short way) and the last key equals
//!   the first (the scene's contract, checked here), so a looping player shows no seam.
//!
//! **Units and axes.** The buffers hold the scene as it is, in millimetres with z up (frame R
//! of `docs/conventions.md`). The root node "assembly" scales by 0.001 (mm → m, glTF's unit)
//! and turns −90° about x (our +z becomes glTF's +y up, our +y points away from the default
//! camera), so viewers show the mechanism upright at its real size while every number in the
//! file stays the one `build` computed. The root node's `extras` say so.
//!
//! It does not decide what the parts are or how they move (that is `build`'s job), and it
//! writes no textures or cameras.

use std::fs::File;
use std::io::Write;
use std::path::{Path, PathBuf};

use serde_json::{json, Value};

use crate::geometry::scene::{Pose, Scene};
use crate::geometry::shading::{first_unfit, shade_scene, ShadedMesh};

/// PBR roughness of every material: 0.55 looks like printed PLA/PETG (satin, soft
/// highlights) under a viewer's default environment light.
pub const ROUGHNESS: f64 = 0.55;

/// Largest rotation between two consecutive keys of a part, degrees. LINEAR quaternion
/// interpolation goes the short way, so a step near 180° is ambiguous (and f32 rounding can
/// flip it); 150° keeps a clear margin. A mechanism sampled at the build's key count turns by
/// a few degrees per key.
pub const MAX_KEY_STEP_DEG: f64 = 150.0;

/// Tolerance on |q| − 1 for a pose's quaternion. Poses come from f64 computations that keep
/// |q| within 1e-12; anything past 1e-6 is a bug upstream, not rounding.
pub const UNIT_QUATERNION_TOL: f64 = 1e-6;

/// How far the last key of a moving part may be from its first: 0.01° and 0.001 mm, far
/// below what a viewer shows (0.01° moves a point 100 mm off the axis by 0.02 mm) and far
/// above the rounding of a periodic law evaluated at t = 0 and t = 1.
pub const LOOP_TOL_DEG: f64 = 0.01;
/// See [`LOOP_TOL_DEG`].
pub const LOOP_TOL_MM: f64 = 0.001;

/// Why a scene could not be written as GLB.
#[derive(Debug, thiserror::Error)]
pub enum GltfError {
    /// The file could not be created or written.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The system's reason.
        source: std::io::Error,
    },
    /// The scene cannot be written.
    #[error("{path}: {source}")]
    Scene {
        /// The file.
        path: PathBuf,
        /// What is wrong with the scene.
        source: SceneError,
    },
}

/// What is wrong with a scene to write.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum SceneError {
    /// The scene has no parts.
    #[error("the scene has no parts")]
    NoParts,
    /// A part has no triangles.
    #[error("part {part:?} has no triangles")]
    EmptyMesh {
        /// The part.
        part: String,
    },
    /// A triangle refers to a vertex the part's mesh does not have.
    #[error(
        "part {part:?}: triangle {triangle} refers to vertex {vertex}, but the mesh has {vertices}"
    )]
    BadIndex {
        /// The part.
        part: String,
        /// Index of the triangle.
        triangle: usize,
        /// The index out of range.
        vertex: u32,
        /// Number of vertices.
        vertices: usize,
    },
    /// A vertex, colour or pose has a value that is not finite.
    #[error("part {part:?}: {what} is not finite")]
    NotFinite {
        /// The part.
        part: String,
        /// Which value.
        what: String,
    },
    /// The key times are not finite, non-negative and strictly increasing (also in f32).
    #[error("key time {index} ({time_s} s) is not finite, non-negative and after the one before")]
    Times {
        /// Index of the offending time.
        index: usize,
        /// Its value, s.
        time_s: f64,
    },
    /// A part has neither one pose nor one per key time.
    #[error("part {part:?} has {poses} poses; it needs 1 (static) or one per key time ({keys})")]
    PoseCount {
        /// The part.
        part: String,
        /// Poses it has.
        poses: usize,
        /// Key times of the scene.
        keys: usize,
    },
    /// A pose's quaternion is not of unit length.
    #[error("part {part:?}, key {key}: rotation quaternion has length {norm}, not 1")]
    NotUnit {
        /// The part.
        part: String,
        /// The key.
        key: usize,
        /// Its length.
        norm: f64,
    },
    /// Two consecutive keys of a part are too far apart to interpolate unambiguously.
    #[error(
        "part {part:?} turns {angle_deg:.1}° from key {} to key {key}; at most {MAX_KEY_STEP_DEG}° \
         per key (add key times)",
        key - 1
    )]
    KeyStep {
        /// The part.
        part: String,
        /// The later key.
        key: usize,
        /// The rotation between them, degrees.
        angle_deg: f64,
    },
    /// A moving part's last key differs from its first, so a looping animation would jump.
    #[error(
        "part {part:?}: the last key is {angle_deg:.4}° and {offset_mm:.4} mm from the first; \
         a period must end where it began"
    )]
    NotLooping {
        /// The part.
        part: String,
        /// Rotation between the first and last pose, degrees.
        angle_deg: f64,
        /// Distance between their translations, mm.
        offset_mm: f64,
    },
    /// No shading made from a part's mesh was given for it.
    #[error("part {part:?}: no shading made from its mesh was given for it")]
    Shading {
        /// The part.
        part: String,
    },
    /// The binary data would exceed what a GLB can address (4 GiB).
    #[error("the scene needs {0} bytes of binary data, more than a GLB can hold")]
    TooLarge(u64),
}

/// Write `scene` as a GLB file at `path`.
pub fn write_glb(path: &Path, scene: &Scene) -> Result<(), GltfError> {
    write_bytes(path, glb_bytes(scene))
}

/// [`write_glb`] with the shading made already ([`shade_scene`] of `scene`).
pub fn write_glb_shaded(
    path: &Path,
    scene: &Scene,
    shaded: &[ShadedMesh],
) -> Result<(), GltfError> {
    write_bytes(path, glb_bytes_shaded(scene, shaded))
}

fn write_bytes(path: &Path, bytes: Result<Vec<u8>, SceneError>) -> Result<(), GltfError> {
    let bytes = bytes.map_err(|source| GltfError::Scene {
        path: path.to_path_buf(),
        source,
    })?;
    File::create(path)
        .and_then(|mut f| f.write_all(&bytes))
        .map_err(|source| GltfError::Io {
            path: path.to_path_buf(),
            source,
        })
}

/// The bytes of a GLB file of `scene` (see the module doc).
pub fn glb_bytes(scene: &Scene) -> Result<Vec<u8>, SceneError> {
    // Checked before shading, which indexes the meshes' vertices.
    check_scene(scene)?;
    encode(scene, &shade_scene(scene))
}

/// [`glb_bytes`] with the shading made already ([`shade_scene`] of `scene`).
pub fn glb_bytes_shaded(scene: &Scene, shaded: &[ShadedMesh]) -> Result<Vec<u8>, SceneError> {
    check_scene(scene)?;
    if let Some(part) = first_unfit(scene, shaded) {
        return Err(SceneError::Shading {
            part: part.name.clone(),
        });
    }
    encode(scene, shaded)
}

/// The GLB of a checked scene and its shading.
fn encode(scene: &Scene, shaded: &[ShadedMesh]) -> Result<Vec<u8>, SceneError> {
    let mut bin = Bin::default();
    let mut meshes = Vec::new();
    let mut materials = Vec::new();
    let mut nodes = vec![Value::Null]; // the root, filled in below
    for (i, (part, shaded)) in scene.parts.iter().zip(shaded).enumerate() {
        let positions: Vec<f32> = shaded
            .positions
            .iter()
            .flatten()
            .map(|&x| x as f32)
            .collect();
        let normals: Vec<f32> = shaded.normals.iter().flatten().map(|&x| x as f32).collect();
        let indices: Vec<u32> = shaded.triangles.iter().flatten().copied().collect();
        let pos = bin.floats(&positions, Kind::Vec3, Some(ARRAY_BUFFER), true);
        let nor = bin.floats(&normals, Kind::Vec3, Some(ARRAY_BUFFER), false);
        let idx = bin.indices(&indices);
        meshes.push(json!({
            "name": part.name,
            "primitives": [{
                "attributes": { "POSITION": pos, "NORMAL": nor },
                "indices": idx,
                "material": i,
                "mode": 4,
            }],
        }));
        let [r, g, b, a] = part.color.map(f64::from);
        let mut material = json!({
            "name": part.name,
            "pbrMetallicRoughness": {
                "baseColorFactor": [r, g, b, a],
                "metallicFactor": 0.0,
                "roughnessFactor": ROUGHNESS,
            },
        });
        if a < 1.0 {
            material["alphaMode"] = json!("BLEND");
        }
        materials.push(material);
        let pose = part.pose(0);
        let mut node = json!({ "name": part.name, "mesh": i });
        let q = pose.rotation;
        if q != Pose::IDENTITY.rotation {
            node["rotation"] = json!([q[1], q[2], q[3], q[0]]);
        }
        if pose.translation != [0.0; 3] {
            node["translation"] = json!(pose.translation);
        }
        nodes.push(node);
    }
    let h = std::f64::consts::FRAC_1_SQRT_2;
    nodes[0] = json!({
        "name": "assembly",
        "children": (1..=scene.parts.len()).collect::<Vec<_>>(),
        "rotation": [-h, 0.0, 0.0, h],
        "scale": [0.001, 0.001, 0.001],
        "extras": {
            "units": "part meshes and translations are in millimetres; this node scales them to metres",
            "axes": "the mechanism's frame is z-up; this node turns it to glTF's y-up",
        },
    });
    let mut doc = json!({
        "asset": {
            "version": "2.0",
            "generator": concat!("mpc-rig ", env!("CARGO_PKG_VERSION")),
        },
        "scene": 0,
        "scenes": [{ "name": "mechanism", "nodes": [0] }],
        "nodes": nodes,
        "meshes": meshes,
        "materials": materials,
    });
    let moving: Vec<usize> = (0..scene.parts.len())
        .filter(|&i| scene.parts[i].poses.len() > 1)
        .collect();
    if !moving.is_empty() {
        let times: Vec<f32> = scene.times_s.iter().map(|&t| t as f32).collect();
        let input = bin.floats(&times, Kind::Scalar, None, true);
        let (mut samplers, mut channels) = (Vec::new(), Vec::new());
        for &i in &moving {
            let part = &scene.parts[i];
            let mut rotations = Vec::with_capacity(4 * times.len());
            let mut prev = [0.0f64; 4];
            for (k, p) in part.poses.iter().enumerate() {
                let n = norm4(p.rotation);
                let mut q = p.rotation.map(|x| x / n);
                if k > 0 && dot4(q, prev) < 0.0 {
                    q = q.map(|x| -x);
                }
                prev = q;
                rotations.extend([q[1], q[2], q[3], q[0]].map(|x| x as f32));
            }
            let translations: Vec<f32> = part
                .poses
                .iter()
                .flat_map(|p| p.translation.map(|x| x as f32))
                .collect();
            let rot = bin.floats(&rotations, Kind::Vec4, None, false);
            let tra = bin.floats(&translations, Kind::Vec3, None, false);
            for (output, path) in [(rot, "rotation"), (tra, "translation")] {
                channels.push(json!({
                    "sampler": samplers.len(),
                    "target": { "node": i + 1, "path": path },
                }));
                samplers
                    .push(json!({ "input": input, "output": output, "interpolation": "LINEAR" }));
            }
        }
        doc["animations"] =
            json!([{ "name": "period", "samplers": samplers, "channels": channels }]);
    }
    let bin_len = bin.data.len() as u64;
    doc["buffers"] = json!([{ "byteLength": bin_len }]);
    doc["bufferViews"] = Value::Array(bin.views);
    doc["accessors"] = Value::Array(bin.accessors);
    let mut json_bytes = serde_json::to_vec(&doc).expect("a JSON value serializes");
    pad(&mut json_bytes, b' ');
    let mut data = bin.data;
    pad(&mut data, 0);
    let total = 12 + 8 + json_bytes.len() as u64 + 8 + data.len() as u64;
    let total32 = u32::try_from(total).map_err(|_| SceneError::TooLarge(total))?;
    let mut out = Vec::with_capacity(total as usize);
    out.extend_from_slice(b"glTF");
    out.extend_from_slice(&2u32.to_le_bytes());
    out.extend_from_slice(&total32.to_le_bytes());
    out.extend_from_slice(&(json_bytes.len() as u32).to_le_bytes());
    out.extend_from_slice(b"JSON");
    out.extend_from_slice(&json_bytes);
    out.extend_from_slice(&(data.len() as u32).to_le_bytes());
    out.extend_from_slice(b"BIN\0");
    out.extend_from_slice(&data);
    Ok(out)
}

/// `bufferView.target` for vertex attributes.
const ARRAY_BUFFER: u32 = 34962;
/// `bufferView.target` for indices.
const ELEMENT_ARRAY_BUFFER: u32 = 34963;
/// `accessor.componentType` values.
const FLOAT: u32 = 5126;
const UNSIGNED_INT: u32 = 5125;

/// `accessor.type` of the float accessors we write.
#[derive(Clone, Copy)]
enum Kind {
    Scalar,
    Vec3,
    Vec4,
}

/// The binary chunk being assembled, with its buffer views and accessors.
#[derive(Default)]
struct Bin {
    data: Vec<u8>,
    views: Vec<Value>,
    accessors: Vec<Value>,
}

impl Bin {
    fn view(&mut self, bytes: &[u8], target: Option<u32>) -> usize {
        pad(&mut self.data, 0);
        let mut v =
            json!({ "buffer": 0, "byteOffset": self.data.len(), "byteLength": bytes.len() });
        if let Some(t) = target {
            v["target"] = json!(t);
        }
        self.data.extend_from_slice(bytes);
        self.views.push(v);
        self.views.len() - 1
    }

    /// An accessor over `values` grouped as `kind`, with its per-component bounds when
    /// `bounds`.
    fn floats(&mut self, values: &[f32], kind: Kind, target: Option<u32>, bounds: bool) -> usize {
        let (comps, kind) = match kind {
            Kind::Scalar => (1, "SCALAR"),
            Kind::Vec3 => (3, "VEC3"),
            Kind::Vec4 => (4, "VEC4"),
        };
        let bytes: Vec<u8> = values.iter().flat_map(|x| x.to_le_bytes()).collect();
        let view = self.view(&bytes, target);
        let mut a = json!({
            "bufferView": view,
            "componentType": FLOAT,
            "count": values.len() / comps,
            "type": kind,
        });
        if bounds {
            let mut min = vec![f32::INFINITY; comps];
            let mut max = vec![f32::NEG_INFINITY; comps];
            for chunk in values.chunks_exact(comps) {
                for k in 0..comps {
                    min[k] = min[k].min(chunk[k]);
                    max[k] = max[k].max(chunk[k]);
                }
            }
            a["min"] = json!(min);
            a["max"] = json!(max);
        }
        self.accessors.push(a);
        self.accessors.len() - 1
    }

    fn indices(&mut self, values: &[u32]) -> usize {
        let bytes: Vec<u8> = values.iter().flat_map(|x| x.to_le_bytes()).collect();
        let view = self.view(&bytes, Some(ELEMENT_ARRAY_BUFFER));
        self.accessors.push(json!({
            "bufferView": view,
            "componentType": UNSIGNED_INT,
            "count": values.len(),
            "type": "SCALAR",
        }));
        self.accessors.len() - 1
    }
}

/// Pad to a multiple of 4 bytes (GLB chunks and accessor offsets need it).
fn pad(v: &mut Vec<u8>, with: u8) {
    while v.len() % 4 != 0 {
        v.push(with);
    }
}

fn dot4(a: [f64; 4], b: [f64; 4]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2] + a[3] * b[3]
}

fn norm4(a: [f64; 4]) -> f64 {
    dot4(a, a).sqrt()
}

/// Rotation angle between two unit quaternions, degrees.
fn angle_between_deg(a: [f64; 4], b: [f64; 4]) -> f64 {
    2.0 * dot4(a, b).abs().min(1.0).acos().to_degrees()
}

/// Everything [`glb_bytes`] needs from a scene, checked up front.
fn check_scene(scene: &Scene) -> Result<(), SceneError> {
    if scene.parts.is_empty() {
        return Err(SceneError::NoParts);
    }
    let keys = scene.times_s.len();
    for (i, &t) in scene.times_s.iter().enumerate() {
        let ok =
            t.is_finite() && t >= 0.0 && (i == 0 || (t as f32) > (scene.times_s[i - 1] as f32));
        if !ok {
            return Err(SceneError::Times {
                index: i,
                time_s: t,
            });
        }
    }
    for part in &scene.parts {
        let name = || part.name.clone();
        let not_finite = |what: String| SceneError::NotFinite { part: name(), what };
        if part.mesh.triangles.is_empty() {
            return Err(SceneError::EmptyMesh { part: name() });
        }
        let nv = part.mesh.vertices.len();
        for (i, t) in part.mesh.triangles.iter().enumerate() {
            if let Some(&v) = t.iter().find(|&&v| v as usize >= nv) {
                return Err(SceneError::BadIndex {
                    part: name(),
                    triangle: i,
                    vertex: v,
                    vertices: nv,
                });
            }
        }
        if let Some(v) = part
            .mesh
            .vertices
            .iter()
            .position(|v| v.iter().any(|x| !x.is_finite()))
        {
            return Err(not_finite(format!("vertex {v}")));
        }
        if part.color.iter().any(|c| !c.is_finite()) {
            return Err(not_finite("the colour".into()));
        }
        let moving = part.poses.len() > 1;
        if part.poses.is_empty() || (moving && part.poses.len() != keys) {
            return Err(SceneError::PoseCount {
                part: name(),
                poses: part.poses.len(),
                keys,
            });
        }
        for (k, p) in part.poses.iter().enumerate() {
            if p.rotation
                .iter()
                .chain(&p.translation)
                .any(|x| !x.is_finite())
            {
                return Err(not_finite(format!("pose {k}")));
            }
            let n = norm4(p.rotation);
            if (n - 1.0).abs() > UNIT_QUATERNION_TOL {
                return Err(SceneError::NotUnit {
                    part: name(),
                    key: k,
                    norm: n,
                });
            }
            if k > 0 {
                let angle_deg = angle_between_deg(part.poses[k - 1].rotation, p.rotation);
                if angle_deg > MAX_KEY_STEP_DEG {
                    return Err(SceneError::KeyStep {
                        part: name(),
                        key: k,
                        angle_deg,
                    });
                }
            }
        }
        if moving {
            let (a, b) = (part.poses[0], part.poses[keys - 1]);
            let angle_deg = angle_between_deg(a.rotation, b.rotation);
            let d = [0, 1, 2].map(|k| a.translation[k] - b.translation[k]);
            let offset_mm = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
            if angle_deg > LOOP_TOL_DEG || offset_mm > LOOP_TOL_MM {
                return Err(SceneError::NotLooping {
                    part: name(),
                    angle_deg,
                    offset_mm,
                });
            }
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::primitive_meshes::{cuboid, uv_sphere};
    use crate::geometry::scene::ScenePart;

    fn turn_z(deg: f64) -> Pose {
        let h = deg.to_radians() / 2.0;
        Pose {
            rotation: [h.cos(), 0.0, 0.0, h.sin()],
            translation: [0.0; 3],
        }
    }

    /// A scene of a static box and a sphere turning once about z in `keys` steps.
    fn scene(keys: usize) -> Scene {
        let times_s: Vec<f64> = (0..=keys).map(|k| k as f64 * 0.1).collect();
        Scene {
            parts: vec![
                ScenePart {
                    name: "support".into(),
                    mesh: cuboid([-10.0, -10.0, -2.0], [10.0, 10.0, 0.0]),
                    color: [0.5, 0.5, 0.5, 1.0],
                    poses: vec![Pose::IDENTITY],
                },
                ScenePart {
                    name: "driver".into(),
                    mesh: uv_sphere([5.0, 0.0, 5.0], 3.0, 16, 8),
                    color: [0.8, 0.3, 0.1, 1.0],
                    poses: (0..=keys)
                        .map(|k| turn_z(360.0 * k as f64 / keys as f64))
                        .collect(),
                },
            ],
            times_s,
        }
    }

    /// Guards shading made once (`build` shares it with the pictures): the bytes are those
    /// [`glb_bytes`] writes, and shading of another mesh is refused, naming the part.
    #[test]
    fn shading_made_once_gives_the_same_bytes_and_must_fit() {
        let s = scene(12);
        let shaded = shade_scene(&s);
        assert_eq!(
            glb_bytes_shaded(&s, &shaded).unwrap(),
            glb_bytes(&s).unwrap()
        );
        let swapped = [shaded[1].clone(), shaded[0].clone()];
        assert_eq!(
            glb_bytes_shaded(&s, &swapped).unwrap_err().to_string(),
            "part \"support\": no shading made from its mesh was given for it"
        );
    }

    /// The container is a GLB 2 whose length fields add up, with a JSON chunk that names the
    /// parts, scales the root to metres and animates only the moving part.
    #[test]
    fn container_and_document() {
        let b = glb_bytes(&scene(12)).unwrap();
        assert_eq!(&b[..4], b"glTF");
        assert_eq!(u32::from_le_bytes(b[4..8].try_into().unwrap()), 2);
        assert_eq!(
            u32::from_le_bytes(b[8..12].try_into().unwrap()) as usize,
            b.len()
        );
        let jlen = u32::from_le_bytes(b[12..16].try_into().unwrap()) as usize;
        assert_eq!(&b[16..20], b"JSON");
        let doc: Value = serde_json::from_slice(&b[20..20 + jlen]).unwrap();
        assert_eq!(&b[20 + jlen + 4..20 + jlen + 8], b"BIN\0");
        assert_eq!(doc["nodes"][0]["scale"], json!([0.001, 0.001, 0.001]));
        assert_eq!(doc["nodes"][1]["name"], "support");
        let channels = doc["animations"][0]["channels"].as_array().unwrap();
        assert_eq!(channels.len(), 2);
        assert!(channels.iter().all(|c| c["target"]["node"] == 2));
    }

    /// Quaternions are written sign-continuous: a full turn in 12 keys ends at −q₀, so the
    /// player interpolates every step forwards by 30°.
    #[test]
    fn quaternions_are_sign_aligned() {
        let b = glb_bytes(&scene(12)).unwrap();
        let jlen = u32::from_le_bytes(b[12..16].try_into().unwrap()) as usize;
        let doc: Value = serde_json::from_slice(&b[20..20 + jlen]).unwrap();
        let bin = &b[20 + jlen + 8..];
        let acc = doc["animations"][0]["samplers"][0]["output"]
            .as_u64()
            .unwrap() as usize;
        let view =
            &doc["bufferViews"][doc["accessors"][acc]["bufferView"].as_u64().unwrap() as usize];
        let off = view["byteOffset"].as_u64().unwrap() as usize;
        let q: Vec<f32> = (0..13 * 4)
            .map(|i| f32::from_le_bytes(bin[off + 4 * i..off + 4 * i + 4].try_into().unwrap()))
            .collect();
        for k in 1..13 {
            let d: f32 = (0..4).map(|c| q[4 * k + c] * q[4 * (k - 1) + c]).sum();
            assert!((d - 15f32.to_radians().cos()).abs() < 1e-6, "key {k}: {d}");
        }
        assert!((q[48 + 3] + 1.0).abs() < 1e-6, "last w = {}", q[51]);
    }

    /// Scenes that cannot be written are refused with the reason: poses not matching the
    /// keys, a step too large to interpolate, a period that does not close, times that do
    /// not increase, a quaternion that is not unit.
    #[test]
    fn bad_scenes_are_refused() {
        let mut s = scene(12);
        s.parts[1].poses.pop();
        assert!(matches!(
            glb_bytes(&s),
            Err(SceneError::PoseCount {
                poses: 12,
                keys: 13,
                ..
            })
        ));

        let e = glb_bytes(&scene(2)).unwrap_err();
        assert_eq!(
            e.to_string(),
            "part \"driver\" turns 180.0° from key 0 to key 1; at most 150° per key (add key times)"
        );

        let mut s = scene(12);
        s.parts[1].poses[12] = turn_z(1.0);
        assert!(matches!(glb_bytes(&s), Err(SceneError::NotLooping { .. })));

        let mut s = scene(12);
        s.times_s[5] = s.times_s[4];
        assert_eq!(
            glb_bytes(&s),
            Err(SceneError::Times {
                index: 5,
                time_s: 0.4
            })
        );

        let mut s = scene(12);
        s.parts[0].poses[0].rotation = [1.0, 0.1, 0.0, 0.0];
        assert!(matches!(
            glb_bytes(&s),
            Err(SceneError::NotUnit { key: 0, .. })
        ));
    }
}
