//! How thick a closed mesh's material is: at each face, the distance from the face's centre
//! along its inward normal to where that line leaves the material, the ray test that mesh
//! tools' and slicers' thickness analyses make.
//!
//! Owns [`WallThickness`] and [`wall_thickness`]. The figure is per face, so it is an
//! estimate: a wall thinner than the faces are wide can fall between two centres, and at a
//! sharp convex edge the faces a little away from it see the material narrowing towards
//! the edge, as a nozzle does there too. A wall is material between two faces that look
//! (nearly) away from each other; three kinds of face are not measured:
//! - faces without area, which have no normal;
//! - faces whose ray leaves through a face turned more than [`WALL_MAX_ANGLE_DEG`] from
//!   the ray: the two meet at an edge of the part, and the material between them widens
//!   away from it, however short the ray. Marching tetrahedra cut every square edge of a
//!   solid into facets about a cell wide at 45° to both sides, and each facet's ray leaves
//!   through the next side within about a cell (half-turn-2to1's support at 0.5 mm cells:
//!   0.3–0.6 mm "walls" under 300 such facets along the base's edges and holes, where the
//!   base is 5 mm thick);
//! - faces whose ray leaves through a face that touches them (shares a corner): the face
//!   sits on a fold of the mesh a fraction of a cell across, where the mesher cut a sharp
//!   edge into small facets turned every way (on that design's follower, 111 faces
//!   measured walls below 0.01 mm this way, 0.07 mm² in all).
//!
//! The faces left out at edges and folds are counted, with their area.
//!
//! It does not decide what is too thin (the caller gives the bound) nor what a part is.

use rayon::prelude::*;

use super::mesh::Mesh;
use super::query::MeshQuery;

/// How far inside its face a ray starts, mm: far below any wall a printer makes, and far
/// above the round-off of coordinates of a few hundred mm (about 1e-13 mm), so the ray does
/// not meet its own face.
const START_INSIDE_MM: f64 = 1e-6;

/// Largest angle between a face's ray and the normal of the face it leaves through for the
/// two to bound a wall, degrees. 30°: a plate's two sides are at 0°, and a wedge up to 30°
/// across is thin for a long way from its edge (at 1 mm from the edge of a 30° wedge the
/// material is 0.54 mm thick), while the 45° facets the mesher leaves at square edges and
/// the 90° of a square edge itself are edges, not walls.
pub const WALL_MAX_ANGLE_DEG: f64 = 30.0;

/// The walls of one mesh, as its faces measure them.
#[derive(Clone, Debug, PartialEq)]
pub struct WallThickness {
    /// The thinnest wall measured, mm; `None` when every face's wall is thicker than
    /// `reach_mm` (rays are not followed farther).
    pub min_mm: Option<f64>,
    /// Where: the centre of the face that measured it, mm (zero when `min_mm` is `None`).
    pub at: [f64; 3],
    /// The bound below which a wall counts as thin, mm.
    pub thin_below_mm: f64,
    /// Area of the faces whose wall is thinner than `thin_below_mm`, mm².
    pub thin_area_mm2: f64,
    /// Area of every face measured, mm².
    pub area_mm2: f64,
    /// Faces not measured because their ray left through a face at an edge of the part or
    /// on a fold of the mesh (see the module doc).
    pub edge_faces: usize,
    /// Their area, mm².
    pub edge_area_mm2: f64,
    /// How far each ray was followed, mm.
    pub reach_mm: f64,
}

impl WallThickness {
    /// The share of the surface over thin walls (0 for a mesh without area).
    pub fn thin_share(&self) -> f64 {
        if self.area_mm2 > 0.0 {
            self.thin_area_mm2 / self.area_mm2
        } else {
            0.0
        }
    }
}

/// The wall under each face of `mesh` (closed, outward faces; `query` prepared from the same
/// mesh), each ray followed up to `reach_mm`: the thinnest, where, and the area of the faces
/// over walls thinner than `thin_below_mm` (at most `reach_mm`).
pub fn wall_thickness(
    query: &MeshQuery,
    mesh: &Mesh,
    thin_below_mm: f64,
    reach_mm: f64,
) -> WallThickness {
    debug_assert!(thin_below_mm <= reach_mm);
    let facing = WALL_MAX_ANGLE_DEG.to_radians().cos();
    let face = |i: usize| {
        let n = mesh.face_normal(i);
        if n == [0.0; 3] {
            return None;
        }
        let centre = mesh.face_centre(i);
        let inward = n.map(|x| -x);
        let origin = [0, 1, 2].map(|k| centre[k] + inward[k] * START_INSIDE_MM);
        let wall = match query.exit_along(origin, inward, reach_mm) {
            Some((t, out)) => {
                let out = out as usize;
                let m = mesh.face_normal(out);
                let along = m[0] * inward[0] + m[1] * inward[1] + m[2] * inward[2];
                if touches(mesh, i, out) || along < facing {
                    Wall::Edge
                } else {
                    Wall::Measured(t + START_INSIDE_MM)
                }
            }
            None => Wall::Beyond,
        };
        Some((i, mesh.face_area(i), wall))
    };
    // Summed in fixed runs of faces, the runs in order, so that the areas are the same to
    // the last bit in every run of the command (rayon's own fold groups faces as its
    // threads happen to split the work).
    let n = mesh.triangles.len();
    let tally = (0..n.div_ceil(TALLY_RUN))
        .into_par_iter()
        .map(|r| {
            (r * TALLY_RUN..((r + 1) * TALLY_RUN).min(n))
                .filter_map(face)
                .fold(Tally::default(), |acc, (i, area, wall)| {
                    acc.add(i, area, wall, thin_below_mm)
                })
        })
        .collect::<Vec<Tally>>()
        .into_iter()
        .fold(Tally::default(), Tally::merge);
    let Tally {
        min,
        at,
        thin_area,
        area,
        edge_faces,
        edge_area,
    } = tally;
    let found = min.is_finite();
    WallThickness {
        min_mm: found.then_some(min),
        at: if found {
            mesh.face_centre(at)
        } else {
            [0.0; 3]
        },
        thin_below_mm,
        thin_area_mm2: thin_area,
        area_mm2: area,
        edge_faces,
        edge_area_mm2: edge_area,
        reach_mm,
    }
}

/// The thinner of two (wall, face) figures, the lower face index among equals, so the
/// result does not depend on how the faces were shared out.
fn thinner(a: (f64, usize), b: (f64, usize)) -> (f64, usize) {
    if b.0 < a.0 || (b.0 == a.0 && b.1 < a.1) {
        b
    } else {
        a
    }
}

/// Whether faces `i` and `j` share a corner (or are the same face).
fn touches(mesh: &Mesh, i: usize, j: usize) -> bool {
    let (a, b) = (mesh.triangles[i], mesh.triangles[j]);
    a.iter().any(|v| b.contains(v))
}

/// What one face's ray found.
#[derive(Clone, Copy, Debug)]
enum Wall {
    /// The wall's thickness, mm.
    Measured(f64),
    /// Thicker than the reach.
    Beyond,
    /// The ray left through a face at an edge or on a fold: not a wall.
    Edge,
}

/// Faces per run of [`wall_thickness`]'s sums: enough that the runs' sums cost nothing
/// beside the rays.
const TALLY_RUN: usize = 4096;

/// The faces' figures, summed over a share of them.
#[derive(Clone, Copy, Debug)]
struct Tally {
    /// Thinnest wall so far and its face ([`thinner`]).
    min: f64,
    at: usize,
    thin_area: f64,
    area: f64,
    edge_faces: usize,
    edge_area: f64,
}

impl Default for Tally {
    fn default() -> Self {
        Tally {
            min: f64::INFINITY,
            at: usize::MAX,
            thin_area: 0.0,
            area: 0.0,
            edge_faces: 0,
            edge_area: 0.0,
        }
    }
}

impl Tally {
    fn add(mut self, i: usize, area: f64, wall: Wall, thin_below: f64) -> Tally {
        match wall {
            Wall::Edge => {
                self.edge_faces += 1;
                self.edge_area += area;
            }
            Wall::Beyond => self.area += area,
            Wall::Measured(w) => {
                self.area += area;
                if w < thin_below {
                    self.thin_area += area;
                }
                (self.min, self.at) = thinner((self.min, self.at), (w, i));
            }
        }
        self
    }

    fn merge(self, o: Tally) -> Tally {
        let (min, at) = thinner((self.min, self.at), (o.min, o.at));
        Tally {
            min,
            at,
            thin_area: self.thin_area + o.thin_area,
            area: self.area + o.area,
            edge_faces: self.edge_faces + o.edge_faces,
            edge_area: self.edge_area + o.edge_area,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::primitive_meshes::{cuboid, uv_sphere};

    fn walls(mesh: &Mesh, thin_below: f64, reach: f64) -> WallThickness {
        wall_thickness(&MeshQuery::new(mesh).unwrap(), mesh, thin_below, reach)
    }

    /// Guards the ray test on a plate with a known answer: a 20 × 10 × 0.5 mm plate is
    /// 0.5 mm thick under its two large faces (their 400 mm² are thin below 0.8 mm), 10 mm
    /// across from its long sides and 20 mm from its short ones.
    #[test]
    fn a_plate_is_as_thick_as_it_is_and_its_large_faces_are_thin() {
        let plate = cuboid([0.0, 0.0, 0.0], [20.0, 10.0, 0.5]);
        let w = walls(&plate, 0.8, 30.0);
        assert!((w.min_mm.unwrap() - 0.5).abs() < 1e-9, "{w:?}");
        assert!((w.at[2] - 0.0).abs() < 1e-9 || (w.at[2] - 0.5).abs() < 1e-9);
        assert!((w.thin_area_mm2 - 400.0).abs() < 1e-6, "{w:?}");
        assert!((w.area_mm2 - plate.area()).abs() < 1e-6);
        // Below 0.5 mm nothing is thin; the reach bounds what is seen.
        assert_eq!(walls(&plate, 0.4, 30.0).thin_area_mm2, 0.0);
        let short = walls(&plate, 0.4, 0.4);
        assert_eq!(short.min_mm, None);
        assert_eq!(short.at, [0.0; 3]);
    }

    /// Guards that the rays leave through the far side and not through the faces they pass
    /// on the way: through a sphere of radius 5 every face's wall is a chord along the
    /// face's normal, close to the diameter (the mesh's faces are flat, so a little less).
    #[test]
    fn a_sphere_is_a_diameter_thick() {
        let ball = uv_sphere([1.0, 2.0, 3.0], 5.0, 48, 24);
        let w = walls(&ball, 0.8, 20.0);
        let min = w.min_mm.unwrap();
        assert!(min > 9.8 && min <= 10.0, "{w:?}");
        assert_eq!(w.thin_area_mm2, 0.0);
    }

    /// Guards that the sums are the same to the last bit however the threads split the
    /// faces: one thread and three, on a sphere of 57 k faces (rayon's own fold gave
    /// the support of half-turn-2to1 areas 10⁻¹⁰ mm² apart from run to run).
    #[test]
    fn the_sums_do_not_depend_on_the_threads() {
        let ball = uv_sphere([1.0, 2.0, 3.0], 5.0, 240, 120);
        let on = |threads: usize| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap()
                .install(|| walls(&ball, 20.0, 20.0))
        };
        let (one, three) = (on(1), on(3));
        assert!(one.area_mm2 > 300.0, "{one:?}");
        for (a, b) in [
            (one.area_mm2, three.area_mm2),
            (one.thin_area_mm2, three.thin_area_mm2),
            (one.edge_area_mm2, three.edge_area_mm2),
        ] {
            assert_eq!(a.to_bits(), b.to_bits(), "{one:?} {three:?}");
        }
    }

    /// A prism `length` mm long along y over the convex polygon `poly` of the xz plane,
    /// faces turned outwards.
    fn prism(poly: &[[f64; 2]], length: f64) -> Mesh {
        let n = poly.len() as u32;
        let mut vertices = Vec::new();
        for y in [0.0, length] {
            for &[x, z] in poly {
                vertices.push([x, y, z]);
            }
        }
        let mut triangles = Vec::new();
        for i in 1..n - 1 {
            triangles.push([0, i, i + 1]);
            triangles.push([n, n + i + 1, n + i]);
        }
        for i in 0..n {
            let j = (i + 1) % n;
            triangles.push([i, i + n, j + n]);
            triangles.push([i, j + n, j]);
        }
        let mut m = Mesh {
            vertices,
            triangles,
        };
        if m.volume() < 0.0 {
            for t in &mut m.triangles {
                t.swap(1, 2);
            }
        }
        m
    }

    /// Guards the edge rule: along a square edge the two sides are edges of the part, not
    /// walls, however short the rays between them. A prism over a right isosceles triangle
    /// (legs 2 mm) measures no wall under its three long sides (each side's ray leaves
    /// through another at 45°); only its end caps, 20 mm apart, are walls.
    #[test]
    fn the_sides_of_a_square_edge_are_not_walls() {
        let p = prism(&[[0.0, 0.0], [2.0, 0.0], [0.0, 2.0]], 20.0);
        assert!(p.check().is_closed_manifold());
        let w = walls(&p, 0.8, 30.0);
        assert!((w.min_mm.unwrap() - 20.0).abs() < 1e-9, "{w:?}");
        assert_eq!(w.edge_faces, 6, "{w:?}");
        assert!((w.edge_area_mm2 + w.area_mm2 - p.area()).abs() < 1e-9);
        assert_eq!(w.thin_area_mm2, 0.0);
    }

    /// Guards that a knife edge is thin: a 20° wedge 2 mm across its back, cut off 0.2 mm
    /// across near its edge, has its two long sides facing each other within 20°, so they
    /// bound a wall, thinner towards the edge. Of each side's two faces, the one whose
    /// centre lies nearer the edge measures the wall two thirds of the way from the back,
    /// where the sides are 0.8 mm apart across the wedge; along the face's normal, 10° off
    /// that, the ray meets the other side, 20° off, after 0.8·cos 10° / cos 20° mm.
    #[test]
    fn a_knife_edge_is_a_thin_wall() {
        let depth = 0.9 / (10f64.to_radians()).tan();
        let p = prism(
            &[[0.0, -1.0], [depth, -0.1], [depth, 0.1], [0.0, 1.0]],
            20.0,
        );
        assert!(p.check().is_closed_manifold());
        let w = walls(&p, 1.0, 30.0);
        let min = w.min_mm.unwrap();
        let expected = 0.8 * 10f64.to_radians().cos() / 20f64.to_radians().cos();
        assert!(
            (min - expected).abs() < 1e-9,
            "{min} against {expected}: {w:?}"
        );
        // The two faces nearer the edge, one per side and each half of its side, are thin
        // below 1 mm.
        let side = (depth * depth + 0.9 * 0.9).sqrt();
        assert!(
            (w.thin_area_mm2 - 2.0 * 0.5 * 20.0 * side).abs() < 1e-9,
            "{w:?}"
        );
    }

    /// Guards a hollow part: a 10 mm box with a 9 mm void inside (its faces turned
    /// inwards) has 0.5 mm walls everywhere, so all of its outer and inner surface is thin.
    #[test]
    fn a_hollow_box_has_thin_walls_all_round() {
        let mut shell = cuboid([0.0; 3], [10.0; 3]);
        let mut void = cuboid([0.5; 3], [9.5; 3]);
        for t in &mut void.triangles {
            t.swap(1, 2);
        }
        shell.append(&void);
        let w = walls(&shell, 0.8, 30.0);
        assert!((w.min_mm.unwrap() - 0.5).abs() < 1e-9, "{w:?}");
        assert!((w.thin_share() - 1.0).abs() < 1e-12, "{w:?}");
    }
}
