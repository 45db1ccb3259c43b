//! Solid geometry for printable parts: triangle meshes in millimetres, their checks, and the
//! scenes that show parts moving.
//!
//! | module | owns |
//! |---|---|
//! | [`mesh`] | indexed triangle meshes, measures, the watertightness (edge) check |
//! | [`scene`] | parts with poses over one period, for animation and renders |
//! | [`sdf`] | implicit solids (signed distance bounds), primitives, CSG |
//! | [`sweep`] | sections swept along closed curves, the segment BVH |
//! | [`cell_lists`] | which boxed items may lie near a point: per-cell lists, nearest bound first |
//! | [`voxel`] | voxel grids, exact distance transforms, shortest free paths |
//! | [`mesher`] | implicit solid → closed 2-manifold mesh (marching tetrahedra, sparse blocks) |
//! | [`query`] | signed point–mesh distance (parry3d-f64, pseudo-normals), rays leaving a mesh |
//! | [`thickness`] | a mesh's wall thickness, face by face (rays along the inward normals) |
//! | [`primitive_meshes`] | closed meshes of boxes, UV spheres and tori, built directly |
//! | [`shading`] | crease-split vertex normals, as the GLB and the renders shade a mesh |
//! | [`simplify`] | fewer triangles within a distance bound (half-edge collapses) |
//! | [`io`] | files: binary STL, 3MF packages laid out on a bed, the animated GLB |
//! | [`render`] | shaded, anti-aliased PNG pictures of a scene at a key time |
//!
//! It does not know what a mechanism is: turning `mechanism.json` into parts is `build`'s
//! job; this module gives it shapes, meshes and files.

pub mod cell_lists;
pub mod io;
pub mod mesh;
pub mod mesher;
pub mod primitive_meshes;
pub mod query;
pub mod render;
pub mod scene;
pub mod sdf;
pub mod shading;
pub mod simplify;
pub mod sweep;
pub mod thickness;
pub mod voxel;

pub use mesh::{Aabb, Mesh, MeshCheck};
pub use scene::{Pose, Scene, ScenePart};
