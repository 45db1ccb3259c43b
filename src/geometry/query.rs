//! Signed distance from a point to a closed triangle mesh: the one point–mesh query the
//! build's check and the virtual prototype both measure parts with.
//!
//! Owns [`MeshQuery`]: parry3d-f64's BVH over the mesh with pseudo-normals
//! (`TriMeshFlags::ORIENTED`), so a projection also says inside or outside. It does not
//! decide what is near enough to query (the callers keep their own coarse grids).

use parry3d_f64::math::Vector as PVec;
use parry3d_f64::query::PointQuery;
use parry3d_f64::shape::{TriMesh, TriMeshFlags};

use super::mesh::Mesh;

/// A closed mesh ready for signed-distance queries.
pub struct MeshQuery {
    tri: TriMesh,
}

impl MeshQuery {
    /// Prepare `mesh` (mm, in its own frame); parry's reason when it refuses it (an
    /// empty mesh, say).
    pub fn new(mesh: &Mesh) -> Result<MeshQuery, String> {
        let verts: Vec<PVec> = mesh
            .vertices
            .iter()
            .map(|v| PVec::new(v[0], v[1], v[2]))
            .collect();
        let tri = TriMesh::with_flags(verts, mesh.triangles.clone(), TriMeshFlags::ORIENTED)
            .map_err(|e| e.to_string())?;
        Ok(MeshQuery { tri })
    }

    /// Distance from `p` to the surface, mm, negative inside.
    pub fn signed(&self, p: [f64; 3]) -> f64 {
        let pr = self
            .tri
            .project_local_point(PVec::new(p[0], p[1], p[2]), false);
        signed_from(&pr, p)
    }

    /// [`signed`](Self::signed) when the surface is within `max_mm` of `p`, `None` when it
    /// is farther (either side): the search prunes every part of the mesh beyond
    /// `max_mm`, so ruling a point out costs a fraction of a full query.
    pub fn signed_within(&self, p: [f64; 3], max_mm: f64) -> Option<f64> {
        self.tri
            .project_local_point_with_max_dist(PVec::new(p[0], p[1], p[2]), false, max_mm)
            .map(|pr| signed_from(&pr, p))
    }
}

/// The signed distance a projection of `p` gives.
fn signed_from(pr: &parry3d_f64::query::PointProjection, p: [f64; 3]) -> f64 {
    let d =
        ((pr.point.x - p[0]).powi(2) + (pr.point.y - p[1]).powi(2) + (pr.point.z - p[2]).powi(2))
            .sqrt();
    if pr.is_inside {
        -d
    } else {
        d
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::primitive_meshes::cuboid;

    /// Guards the sign and the size: a point 1 mm outside a face reads +1, the centre of a
    /// 4 mm cube reads −2.
    #[test]
    fn distances_are_signed_negative_inside() {
        let q = MeshQuery::new(&cuboid([0.0; 3], [4.0; 3])).unwrap();
        assert!((q.signed([5.0, 2.0, 2.0]) - 1.0).abs() < 1e-12);
        assert!((q.signed([2.0, 2.0, 2.0]) + 2.0).abs() < 1e-12);
    }

    /// Guards the bounded query: the signed distance where the surface is within the
    /// bound (outside and inside), nothing where it is farther on either side.
    #[test]
    fn a_bounded_query_answers_only_within_its_bound() {
        let q = MeshQuery::new(&cuboid([0.0; 3], [4.0; 3])).unwrap();
        let near = q.signed_within([5.0, 2.0, 2.0], 1.5).unwrap();
        assert!((near - 1.0).abs() < 1e-12, "{near}");
        let inside = q.signed_within([2.0, 2.0, 0.5], 1.0).unwrap();
        assert!((inside + 0.5).abs() < 1e-12, "{inside}");
        assert_eq!(q.signed_within([7.0, 2.0, 2.0], 2.5), None);
        assert_eq!(q.signed_within([2.0, 2.0, 2.0], 1.5), None);
    }
}
