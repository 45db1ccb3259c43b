//! How far a part's mesh lies from the solid it was meshed from: the mesh error that the
//! mesher's cell buys, measured on the mesh rather than estimated from the cell.
//!
//! Owns [`MeshError`] and [`mesh_error`]. At the centre of each face of a seeded sample
//! (where a flat face departs most from a curved surface through its corners), the
//! distance along the face's normal to the solid's surface: the first change of sign of
//! the solid's value along that line, bracketed and bisected. It needs only the sign of
//! the value, so it holds for solids whose value is a distance bound rather than a
//! distance (twisted sweeps, the driver's carve), and the distance along the normal is at
//! least the distance to the surface, so the figure errs high, never low. A face whose
//! line meets no surface within [`ERROR_REACH_CELLS`] cells is counted apart: where the
//! mesher trims slivers (the driver) its surface departs from the solid on purpose, and
//! material thinner than a cell may come out of the mesher thicker or not at all.
//!
//! The figures are given over every face measured and again over the faces away from
//! sharp edges ([`SHARP_TURN_DEG`]): marching tetrahedra cut a sharp edge off with facets
//! about a cell across, an error of a fraction of a cell that no smooth surface has, and
//! the two tell apart what the cell does on each (docs/build.md, "Mesh error").
//!
//! It does not decide the cell, nor judge the figure: the build reports it.

use std::collections::HashMap;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;

use crate::geometry::mesh::Mesh;
use crate::geometry::sdf::{Sdf, Vec3};

/// Faces sampled per part. 4 000: the sample's largest error is then among the worst 0.1 %
/// of the faces with 98 % odds (1 − 0.999⁴⁰⁰⁰), and its 99th percentile is that of the
/// mesh to a few per cent; every face of the driver would cost as much as its carve.
pub const ERROR_SAMPLES: usize = 4_000;
/// How far along a face's normal its surface is looked for, in mesher cells: the mesher
/// puts a vertex on a cell's edge and a face within a cell of the surface it crosses, so a
/// face farther than two cells from the solid's surface is not a meshing of that surface
/// (a trim's, or material thinner than a cell that the mesher widened).
pub const ERROR_REACH_CELLS: f64 = 2.0;
/// The bisection stops within this of the surface, mm: a hundredth of the 0.1 mm the
/// issue's resolution is judged by.
const ERROR_TOL_MM: f64 = 1e-3;
/// Seed of the sample (any fixed value: the same faces every build of the same mesh).
const ERROR_SEED: u64 = 14;
/// A face that some face within two rings of it turns from by more than this sits at a
/// sharp edge of the mesh, degrees. 40°: on a smooth surface meshed at 0.4 mm the faces
/// around one turn by up to about h/R ≈ 27° (the rims' 0.85 mm apex), while the facets
/// marching tetrahedra cut along a square edge turn 45° from the sides beside them.
pub const SHARP_TURN_DEG: f64 = 40.0;

/// The error of one mesh, over a sample of its faces (all zero: nothing measured).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct MeshError {
    /// Faces measured.
    pub samples: usize,
    /// Mean distance of a face centre from the solid's surface, mm, by area.
    pub mean_mm: f64,
    /// 99th percentile by area, mm: 99 % of the surface (as its faces' centres tell) lies
    /// within this of the solid.
    pub p99_mm: f64,
    /// Largest, mm, and the face centre that measured it.
    pub max_mm: f64,
    /// Where, mm.
    pub at: [f64; 3],
    /// Faces whose surface was not within reach (trimmed material, material thinner than
    /// a cell), not in the figures.
    pub off_surface: usize,
    /// The faces measured away from sharp edges (no face within two rings of them turns
    /// more than [`SHARP_TURN_DEG`]): how many, their 99th percentile and their largest,
    /// mm.
    pub smooth_samples: usize,
    /// See `smooth_samples`.
    pub smooth_p99_mm: f64,
    /// See `smooth_samples`.
    pub smooth_max_mm: f64,
}

/// The error of `mesh` against `solid` (its own frame), meshed at `cell` mm: over
/// [`ERROR_SAMPLES`] faces drawn with a fixed seed, each with a chance in proportion to its
/// area (every face of a smaller mesh, weighted by its area), so that the figures are
/// shares of the surface, whatever the sizes of the faces.
///
/// By area, not by face: the mesher's faces are all about a third of a cell across, but
/// a simplified mesh (`geometry::simplify`) keeps many small faces at sharp edges and few
/// large ones on the flat, and a share of its faces is then no longer a share of its
/// surface. On half-turn-2to1's printable driver simplified to a quarter of its triangles,
/// 99 % of the faces drawn one by one were within 0.233 mm, and 99 % of the surface
/// within 0.112–0.133 mm (two builds). On the mesher's own faces the two readings were
/// 0.099 and 0.145 mm: other draws, whose 99th percentile rests on their 40 worst faces.
pub fn mesh_error(solid: &dyn Sdf, mesh: &Mesh, cell: f64) -> MeshError {
    let n = mesh.triangles.len();
    let every_face = n <= ERROR_SAMPLES;
    let mut faces: Vec<usize> = if every_face {
        (0..n).collect()
    } else {
        let areas: Vec<f64> = (0..n).into_par_iter().map(|i| mesh.face_area(i)).collect();
        let mut cumulative = Vec::with_capacity(n);
        let mut total = 0.0;
        for a in &areas {
            total += a;
            cumulative.push(total);
        }
        let mut rng = ChaCha8Rng::seed_from_u64(ERROR_SEED);
        (0..ERROR_SAMPLES)
            .map(|_| {
                let u = rng.random_range(0.0..total);
                cumulative.partition_point(|&c| c <= u).min(n - 1)
            })
            .collect()
    };
    // A face drawn by its area counts once; where every face is measured, by its area.
    let weight = |i: usize| if every_face { mesh.face_area(i) } else { 1.0 };
    // Neighbouring faces together: a solid that keeps work per region (the carve's
    // certificates) finds it again.
    let centre = |i: usize| Vec3::from(mesh.face_centre(i));
    faces.sort_by_key(|&i| {
        let c = centre(i);
        ([c.z, c.y, c.x].map(|x| (x / 2.0).floor() as i64), i)
    });
    let reach = ERROR_REACH_CELLS * cell;
    let found: Vec<Option<(f64, usize)>> = faces
        .par_iter()
        .map(|&i| {
            let nrm = mesh.face_normal(i);
            if nrm == [0.0; 3] {
                return None;
            }
            let x = centre(i);
            let n = Vec3::new(nrm[0], nrm[1], nrm[2]);
            along_normal(solid, x, n, reach).map(|d| (d, i))
        })
        .collect();
    let mut errors: Vec<(f64, usize)> = found.iter().flatten().copied().collect();
    let off_surface = found.len() - errors.len();
    errors.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
    let count = errors.len();
    if count == 0 {
        return MeshError {
            off_surface,
            ..MeshError::default()
        };
    }
    let (max_mm, worst) = errors[count - 1];
    let at = centre(worst);
    let sharp = sharp_faces(mesh, &errors.iter().map(|e| e.1).collect::<Vec<_>>());
    let weighted: Vec<(f64, f64)> = errors.iter().map(|&(e, i)| (e, weight(i))).collect();
    let smooth: Vec<(f64, f64)> = weighted
        .iter()
        .zip(&sharp)
        .filter(|(_, &sharp)| !sharp)
        .map(|(&e, _)| e)
        .collect();
    let total: f64 = weighted.iter().map(|e| e.1).sum();
    MeshError {
        samples: count,
        mean_mm: if total > 0.0 {
            weighted.iter().map(|e| e.0 * e.1).sum::<f64>() / total
        } else {
            0.0
        },
        p99_mm: percentile_99(&weighted),
        max_mm,
        at: [at.x, at.y, at.z],
        off_surface,
        smooth_samples: smooth.len(),
        smooth_p99_mm: percentile_99(&smooth),
        smooth_max_mm: smooth.last().map_or(0.0, |e| e.0),
    }
}

/// The 99th percentile of `sorted` (errors ascending, each with its weight): the smallest
/// error at or below which 99 % of the weight lies; 0 when empty.
fn percentile_99(sorted: &[(f64, f64)]) -> f64 {
    let total: f64 = sorted.iter().map(|e| e.1).sum();
    let mut below = 0.0;
    for &(e, w) in sorted {
        below += w;
        if below >= 0.99 * total {
            return e;
        }
    }
    sorted.last().map_or(0.0, |e| e.0)
}

/// For each of `faces`, whether a face within two rings of it (sharing a corner with it or
/// with a face that does) turns from it by more than [`SHARP_TURN_DEG`] (a face without a
/// normal counts as sharp). Two rings, not one: along a rounded square edge the mesher
/// leaves a strip of facets a face or two wide, whose middle faces meet only each other.
fn sharp_faces(mesh: &Mesh, faces: &[usize]) -> Vec<bool> {
    let own: Vec<Vec<u32>> = faces.iter().map(|&f| mesh.triangles[f].to_vec()).collect();
    let ring1 = touching(mesh, &own);
    let corners: Vec<Vec<u32>> = ring1
        .iter()
        .map(|ring| {
            let mut v: Vec<u32> = ring.iter().flat_map(|&t| mesh.triangles[t]).collect();
            v.sort_unstable();
            v.dedup();
            v
        })
        .collect();
    let ring2 = touching(mesh, &corners);
    let limit = SHARP_TURN_DEG.to_radians().cos();
    faces
        .iter()
        .zip(&ring2)
        .map(|(&f, ring)| {
            let n = mesh.face_normal(f);
            n == [0.0; 3]
                || ring.iter().any(|&t| {
                    let m = mesh.face_normal(t);
                    n[0] * m[0] + n[1] * m[1] + n[2] * m[2] < limit
                })
        })
        .collect()
}

/// For each set of vertices in `sets`, the faces of `mesh` with a corner in it (one pass
/// over the mesh).
fn touching(mesh: &Mesh, sets: &[Vec<u32>]) -> Vec<Vec<usize>> {
    let mut at_vertex: HashMap<u32, Vec<usize>> = HashMap::new();
    for (k, set) in sets.iter().enumerate() {
        for &v in set {
            at_vertex.entry(v).or_default().push(k);
        }
    }
    let pairs: Vec<(usize, usize)> = (0..mesh.triangles.len())
        .into_par_iter()
        .flat_map_iter(|t| {
            let mut ks: Vec<usize> = mesh.triangles[t]
                .iter()
                .filter_map(|v| at_vertex.get(v))
                .flatten()
                .copied()
                .collect();
            ks.sort_unstable();
            ks.dedup();
            ks.into_iter().map(move |k| (k, t))
        })
        .collect();
    let mut out = vec![Vec::new(); sets.len()];
    for (k, t) in pairs {
        out[k].push(t);
    }
    out
}

/// Distance from `x` along the line through it with direction `n` (unit) to the first
/// change of sign of `solid`'s value, looking towards the surface (against `n` where
/// `x` is outside, along it inside) up to `reach` mm; `None` beyond. Within
/// [`ERROR_TOL_MM`].
fn along_normal(solid: &dyn Sdf, x: Vec3, n: Vec3, reach: f64) -> Option<f64> {
    let f0 = solid.dist(x);
    if f0 == 0.0 {
        return Some(0.0);
    }
    let dir = if f0 > 0.0 { -n } else { n };
    let outside = f0 > 0.0;
    let crossed = |s: f64| (solid.dist(x + dir * s) > 0.0) != outside;
    // The value is at most the distance, so nothing changes sign nearer than |f0|.
    let mut lo = 0.0;
    let mut hi = (1.5 * f0.abs()).max(ERROR_TOL_MM).min(reach);
    while !crossed(hi) {
        if hi >= reach {
            return None;
        }
        lo = hi;
        hi = (2.0 * hi).min(reach);
    }
    while hi - lo > ERROR_TOL_MM {
        let mid = 0.5 * (lo + hi);
        if crossed(mid) {
            hi = mid;
        } else {
            lo = mid;
        }
    }
    Some(0.5 * (lo + hi))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::mesher::mesh_solid;
    use crate::geometry::primitive_meshes::uv_sphere;
    use crate::geometry::sdf::Sphere;

    /// Guards the measure against a closed form: a UV sphere of radius 10 with 32
    /// meridians and 16 rings has flat faces whose centres lie inside the true sphere by
    /// 10 − |centre|; the figures are those depths (largest at the widest faces).
    #[test]
    fn a_faceted_sphere_is_as_far_inside_as_its_face_centres() {
        let mesh = uv_sphere([0.0; 3], 10.0, 32, 16);
        let ball = Sphere {
            center: Vec3::zeros(),
            radius: 10.0,
        };
        let e = mesh_error(&ball, &mesh, 1.0);
        let depths: Vec<f64> = (0..mesh.triangles.len())
            .map(|i| {
                let [a, b, c] = mesh.corners(i);
                let m = [0, 1, 2].map(|k| (a[k] + b[k] + c[k]) / 3.0);
                10.0 - (m[0] * m[0] + m[1] * m[1] + m[2] * m[2]).sqrt()
            })
            .collect();
        let max = depths.iter().copied().fold(0.0, f64::max);
        // Along the face's normal, not the radius: a little more than the depth.
        assert!(e.max_mm >= max - ERROR_TOL_MM, "{e:?} against {max}");
        assert!(e.max_mm < max * 1.1 + ERROR_TOL_MM, "{e:?} against {max}");
        assert_eq!(e.samples, mesh.triangles.len());
        assert_eq!(e.off_surface, 0);
        // Rings and meridians 11.25° apart: faces two rings apart turn by well under 40°,
        // no sharp edge.
        assert_eq!(e.smooth_samples, e.samples);
        assert_eq!(e.smooth_max_mm, e.max_mm);
    }

    /// Guards the percentile's weights: it is the error below which 99 % of the weight
    /// (the area) lies, so one large face outweighs many small ones.
    #[test]
    fn the_percentile_is_a_share_of_the_weight() {
        assert_eq!(percentile_99(&[]), 0.0);
        assert_eq!(percentile_99(&[(0.01, 99.0), (0.5, 1.0)]), 0.01);
        assert_eq!(percentile_99(&[(0.01, 98.0), (0.5, 2.0)]), 0.5);
        let small_faces_bad: Vec<(f64, f64)> = (0..50)
            .map(|_| (0.001, 1.0))
            .chain((0..50).map(|_| (0.3, 0.001)))
            .collect();
        assert_eq!(percentile_99(&small_faces_bad), 0.001);
    }

    /// Guards the split between smooth surface and sharp edges: a box meshed at 0.5 mm is
    /// exact on its flat faces and off by up to a fraction of a cell on the facets cut
    /// across its edges; the smooth figures see the former only.
    #[test]
    fn a_box_is_exact_away_from_its_edges() {
        let cube = crate::geometry::sdf::Cuboid {
            center: Vec3::new(0.1, 0.2, 0.3),
            half: Vec3::new(3.0, 2.0, 1.5),
            rotation: nalgebra::Rotation3::identity(),
        };
        let mesh = mesh_solid(&|p| cube.dist(p), cube.bounds(), 0.5).unwrap();
        let e = mesh_error(&cube, &mesh, 0.5);
        assert!(e.smooth_max_mm < ERROR_TOL_MM, "{e:?}");
        assert!(e.max_mm > 0.05, "{e:?}");
        assert!(
            e.smooth_samples > 0 && e.smooth_samples < e.samples,
            "{e:?}"
        );
    }

    /// Guards the measure on the mesher's own output: a sphere of radius 3 meshed at
    /// 0.5 mm cells lies within 0.05 mm of the true one, and halving the cell at least
    /// halves the largest error (it shrinks with the cell's square on a smooth surface).
    #[test]
    fn the_mesher_error_shrinks_with_the_cell() {
        let ball = Sphere {
            center: Vec3::new(0.1, 0.2, 0.3),
            radius: 3.0,
        };
        let mesh = |h: f64| mesh_solid(&|p| ball.dist(p), ball.bounds(), h).unwrap();
        let coarse = mesh_error(&ball, &mesh(0.5), 0.5);
        let fine = mesh_error(&ball, &mesh(0.25), 0.25);
        assert!(coarse.max_mm < 0.05, "{coarse:?}");
        assert!(
            fine.max_mm < 0.5 * coarse.max_mm,
            "{fine:?} against {coarse:?}"
        );
        assert!(coarse.mean_mm < coarse.p99_mm && coarse.p99_mm <= coarse.max_mm);
    }
}
