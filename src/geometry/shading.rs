//! Shading normals: a mesh split along its creases, with one unit normal per vertex, as the
//! glTF export and the renders draw it.
//!
//! Owns [`ShadedMesh`] and the crease rule: at each face corner, the normal is the
//! angle-weighted mean of the normals of the faces around that vertex that lie within
//! [`CREASE_ANGLE_DEG`] of the face's own normal. Smooth freeform surfaces (swept plates,
//! grooves) then shade smoothly while box edges, bores and chamfers stay sharp; corners that
//! end up with the same normal share one output vertex. It does not change geometry: the
//! positions are the mesh's own, and the watertight mesh stays in [`Mesh`]. A scene's
//! shading is made once ([`shade_scene`]) and shared by the export and every picture.

use rustc_hash::FxHashMap as HashMap;

use rayon::prelude::*;

use super::mesh::Mesh;
use super::scene::{Scene, ScenePart};

/// Dihedral angle above which an edge is drawn sharp (normals split), degrees. 40°: a
/// freeform surface meshed at the build's resolution turns by a few degrees between
/// neighbouring faces (a 64-gon turns by 5.6°), while the edges of printed parts (box edges,
/// bores, plate rims) are 45° chamfers or sharper; 40° keeps both apart with margin.
pub const CREASE_ANGLE_DEG: f64 = 40.0;

/// A mesh ready to shade: positions duplicated where the normal splits.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ShadedMesh {
    /// Vertex positions, mm (copies of the source mesh's vertices).
    pub positions: Vec<[f64; 3]>,
    /// Unit normal per vertex.
    pub normals: Vec<[f64; 3]>,
    /// Triangles, counter-clockwise from outside, indices into `positions`.
    pub triangles: Vec<[u32; 3]>,
}

impl ShadedMesh {
    /// Split `mesh` along edges sharper than `crease_deg` (0 gives flat faces, 180 smooth
    /// everywhere). Degenerate faces take the smooth normal of their corners.
    pub fn new(mesh: &Mesh, crease_deg: f64) -> ShadedMesh {
        let nv = mesh.vertices.len();
        let face_normals: Vec<[f64; 3]> = (0..mesh.triangles.len())
            .map(|f| mesh.face_normal(f))
            .collect();
        // Faces around each vertex with the corner angle there (CSR layout).
        let mut start = vec![0usize; nv + 1];
        for t in &mesh.triangles {
            for &v in t {
                start[v as usize + 1] += 1;
            }
        }
        for i in 0..nv {
            start[i + 1] += start[i];
        }
        let mut fill = start.clone();
        let mut around = vec![(0u32, 0.0f64); start[nv]];
        for (f, t) in mesh.triangles.iter().enumerate() {
            let p = mesh.corners(f);
            for c in 0..3 {
                let v = t[c] as usize;
                around[fill[v]] = (f as u32, corner_angle(p[c], p[(c + 1) % 3], p[(c + 2) % 3]));
                fill[v] += 1;
            }
        }
        let cos_crease = crease_deg.to_radians().cos();
        let mut out = ShadedMesh {
            positions: Vec::with_capacity(nv),
            normals: Vec::with_capacity(nv),
            triangles: Vec::with_capacity(mesh.triangles.len()),
        };
        // (source vertex, normal bits) → output vertex.
        let mut index: HashMap<(u32, [u64; 3]), u32> =
            HashMap::with_capacity_and_hasher(nv * 2, Default::default());
        for (f, t) in mesh.triangles.iter().enumerate() {
            let nf = face_normals[f];
            let flat = nf == [0.0; 3];
            let mut tri = [0u32; 3];
            for (slot, &v) in tri.iter_mut().zip(t) {
                let mut sum = [0.0f64; 3];
                for &(g, w) in &around[start[v as usize]..start[v as usize + 1]] {
                    let ng = face_normals[g as usize];
                    if flat || dot(nf, ng) >= cos_crease {
                        for k in 0..3 {
                            sum[k] += w * ng[k];
                        }
                    }
                }
                let l = dot(sum, sum).sqrt();
                let n = if l > 0.0 {
                    [sum[0] / l, sum[1] / l, sum[2] / l]
                } else if !flat {
                    nf
                } else {
                    // Nothing around it has an area: any unit vector will do.
                    [0.0, 0.0, 1.0]
                };
                let key = (v, [n[0].to_bits(), n[1].to_bits(), n[2].to_bits()]);
                *slot = *index.entry(key).or_insert_with(|| {
                    out.positions.push(mesh.vertices[v as usize]);
                    out.normals.push(n);
                    (out.positions.len() - 1) as u32
                });
            }
            out.triangles.push(tri);
        }
        out
    }
}

impl ShadedMesh {
    /// Whether this can be `mesh`'s shading: a triangle for each of its triangles, and a
    /// vertex for each of its vertices at least (a cheap test for shading made elsewhere).
    pub fn fits(&self, mesh: &Mesh) -> bool {
        self.triangles.len() == mesh.triangles.len()
            && self.positions.len() >= mesh.vertices.len()
            && self.normals.len() == self.positions.len()
    }
}

/// The first part of `scene` that `shaded` (one shading per part, in order) has no fitting
/// shading for ([`ShadedMesh::fits`]), if any: what a writer or renderer handed shading
/// made elsewhere refuses.
pub fn first_unfit<'s>(scene: &'s Scene, shaded: &[ShadedMesh]) -> Option<&'s ScenePart> {
    scene
        .parts
        .iter()
        .enumerate()
        .find(|(i, part)| !shaded.get(*i).is_some_and(|s| s.fits(&part.mesh)))
        .map(|(_, part)| part)
}

/// The shading of every part of `scene` at [`CREASE_ANGLE_DEG`], in the parts' order, the
/// parts in parallel: made once, it serves the glTF export and every render of the scene
/// (a fine build's driver takes 1.5 s).
pub fn shade_scene(scene: &Scene) -> Vec<ShadedMesh> {
    scene
        .parts
        .par_iter()
        .map(|p| ShadedMesh::new(&p.mesh, CREASE_ANGLE_DEG))
        .collect()
}

fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// Angle at corner `a` of triangle (a, b, c), radians (0 when an adjacent edge is empty).
fn corner_angle(a: [f64; 3], b: [f64; 3], c: [f64; 3]) -> f64 {
    let (u, v) = (sub(b, a), sub(c, a));
    let l = (dot(u, u) * dot(v, v)).sqrt();
    if l > 0.0 {
        (dot(u, v) / l).clamp(-1.0, 1.0).acos()
    } else {
        0.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::primitive_meshes::{cuboid, uv_sphere};

    /// A box splits at every edge: 24 vertices (4 per side), each normal along an axis.
    #[test]
    fn box_edges_are_sharp() {
        let s = ShadedMesh::new(&cuboid([0.0; 3], [1.0, 2.0, 3.0]), CREASE_ANGLE_DEG);
        assert_eq!((s.positions.len(), s.triangles.len()), (24, 12));
        for n in &s.normals {
            let mut a: Vec<f64> = n.iter().map(|x| x.abs()).collect();
            a.sort_by(f64::total_cmp);
            assert_eq!(a, [0.0, 0.0, 1.0], "{n:?}");
        }
    }

    /// A finely meshed sphere is smooth: no vertex is split, and every normal points along
    /// the radius within a degree.
    #[test]
    fn sphere_is_smooth() {
        let m = uv_sphere([1.0, 2.0, 3.0], 5.0, 48, 24);
        let s = ShadedMesh::new(&m, CREASE_ANGLE_DEG);
        assert_eq!(s.positions.len(), m.vertices.len());
        for (p, n) in s.positions.iter().zip(&s.normals) {
            let r = sub(*p, [1.0, 2.0, 3.0]);
            let c = dot(r, *n) / dot(r, r).sqrt();
            assert!(c > 1f64.to_radians().cos(), "{p:?} {n:?}");
        }
    }

    /// With a zero crease angle every corner carries its own face's normal, and the
    /// triangles' corners keep their positions.
    #[test]
    fn zero_crease_is_flat() {
        let m = uv_sphere([0.0; 3], 1.0, 8, 4);
        let s = ShadedMesh::new(&m, 0.0);
        assert_eq!(s.triangles.len(), m.triangles.len());
        for (f, t) in s.triangles.iter().enumerate() {
            for (&v, &w) in t.iter().zip(&m.triangles[f]) {
                assert_eq!(s.positions[v as usize], m.vertices[w as usize]);
                assert!(dot(s.normals[v as usize], m.face_normal(f)) > 1.0 - 1e-12);
            }
        }
    }
}
