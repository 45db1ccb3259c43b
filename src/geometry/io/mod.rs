//! Files that carry finished parts to printers, slicers and viewers.
//!
//! | module | owns |
//! |---|---|
//! | [`stl`] | binary STL: write (mm, f32, facet normals), read (welding exact duplicates) |
//! | [`threemf`] | 3MF packages: several named objects laid out on a bed; a reader |
//! | [`gltf`] | `assembly.glb`: binary glTF 2.0 of a [`Scene`](super::Scene) with its animation |
//!
//! Every writer takes meshes in millimetres as [`Mesh`](super::Mesh) and scenes as
//! [`Scene`](super::Scene); every error is typed and names the file and what is wrong. This
//! module does not check meshes (that is [`Mesh::check`](super::Mesh::check)) nor decide
//! which parts to write (that is `build`'s job).

pub mod gltf;
pub mod stl;
pub mod threemf;
