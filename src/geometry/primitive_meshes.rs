//! Closed triangle meshes of simple solids, built directly rather than through the mesher
//! from implicit solids (`sdf`): boxes, UV spheres and tori.
//!
//! Owns the three constructors. Each result is a closed, consistently oriented 2-manifold
//! (it passes [`Mesh::check`]) with outward counter-clockwise faces, so exports, renders and
//! their tests have known solids with known volumes to work on. It does not build a
//! mechanism's parts (that is `build`'s job) and knows no implicit surfaces.

use std::f64::consts::TAU;

use super::mesh::Mesh;

/// A box from corner `min` to corner `max` (mm), 12 triangles. `min < max` on every axis.
pub fn cuboid(min: [f64; 3], max: [f64; 3]) -> Mesh {
    let [x0, y0, z0] = min;
    let [x1, y1, z1] = max;
    let vertices = vec![
        [x0, y0, z0],
        [x1, y0, z0],
        [x1, y1, z0],
        [x0, y1, z0],
        [x0, y0, z1],
        [x1, y0, z1],
        [x1, y1, z1],
        [x0, y1, z1],
    ];
    let triangles = vec![
        [0, 2, 1],
        [0, 3, 2],
        [4, 5, 6],
        [4, 6, 7],
        [0, 1, 5],
        [0, 5, 4],
        [1, 2, 6],
        [1, 6, 5],
        [2, 3, 7],
        [2, 7, 6],
        [3, 0, 4],
        [3, 4, 7],
    ];
    Mesh {
        vertices,
        triangles,
    }
}

/// A sphere of `radius` mm about `center`: `segments` ≥ 3 meridians, `rings` ≥ 2 latitude
/// bands, one vertex at each pole; 2·segments·(rings − 1) triangles.
pub fn uv_sphere(center: [f64; 3], radius: f64, segments: u32, rings: u32) -> Mesh {
    assert!(
        segments >= 3 && rings >= 2,
        "uv_sphere needs segments ≥ 3, rings ≥ 2"
    );
    let mut vertices = vec![[center[0], center[1], center[2] - radius]];
    for r in 1..rings {
        let polar = std::f64::consts::PI * f64::from(r) / f64::from(rings);
        let (z, rho) = (-radius * polar.cos(), radius * polar.sin());
        for s in 0..segments {
            let a = TAU * f64::from(s) / f64::from(segments);
            vertices.push([
                center[0] + rho * a.cos(),
                center[1] + rho * a.sin(),
                center[2] + z,
            ]);
        }
    }
    vertices.push([center[0], center[1], center[2] + radius]);
    let south = 0u32;
    let north = vertices.len() as u32 - 1;
    let ring = |r: u32, s: u32| 1 + (r - 1) * segments + s % segments;
    let mut triangles = Vec::new();
    for s in 0..segments {
        // Seen from outside (below), the south cap turns clockwise in x-y.
        triangles.push([south, ring(1, s + 1), ring(1, s)]);
        triangles.push([north, ring(rings - 1, s), ring(rings - 1, s + 1)]);
    }
    for r in 1..rings - 1 {
        for s in 0..segments {
            let (a, b) = (ring(r, s), ring(r, s + 1));
            let (c, d) = (ring(r + 1, s), ring(r + 1, s + 1));
            triangles.push([a, b, d]);
            triangles.push([a, d, c]);
        }
    }
    Mesh {
        vertices,
        triangles,
    }
}

/// A torus about the z axis through `center`: tube centre circle of radius `major` mm, tube
/// radius `minor` < `major` mm; `segments` ≥ 3 around the axis, `sides` ≥ 3 around the tube;
/// 2·segments·sides triangles.
pub fn torus(center: [f64; 3], major: f64, minor: f64, segments: u32, sides: u32) -> Mesh {
    assert!(
        segments >= 3 && sides >= 3 && minor < major,
        "torus needs segments, sides ≥ 3 and minor < major"
    );
    let mut vertices = Vec::with_capacity((segments * sides) as usize);
    for s in 0..segments {
        let a = TAU * f64::from(s) / f64::from(segments);
        for k in 0..sides {
            let b = TAU * f64::from(k) / f64::from(sides);
            let rho = major + minor * b.cos();
            vertices.push([
                center[0] + rho * a.cos(),
                center[1] + rho * a.sin(),
                center[2] + minor * b.sin(),
            ]);
        }
    }
    let id = |s: u32, k: u32| (s % segments) * sides + k % sides;
    let mut triangles = Vec::with_capacity(2 * vertices.len());
    for s in 0..segments {
        for k in 0..sides {
            let (a, b) = (id(s, k), id(s + 1, k));
            let (c, d) = (id(s, k + 1), id(s + 1, k + 1));
            triangles.push([a, b, d]);
            triangles.push([a, d, c]);
        }
    }
    Mesh {
        vertices,
        triangles,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::PI;

    /// A box is a closed manifold with its exact volume, wherever it is.
    #[test]
    fn cuboid_is_closed_with_its_volume() {
        let c = cuboid([-1.0, 2.0, 3.0], [1.0, 5.0, 7.0]).check();
        assert!(c.is_closed_manifold(), "{}", c.summary());
        assert!((c.volume_mm3 - 24.0).abs() < 1e-12);
    }

    /// A UV sphere is one closed shell pointing outwards, with the volume of its inscribed
    /// polyhedron: below 4/3·π·r³, and within 1 % of it at 64 × 32.
    #[test]
    fn uv_sphere_is_closed_and_close_to_the_sphere() {
        let m = uv_sphere([1.0, -2.0, 0.5], 3.0, 64, 32);
        let c = m.check();
        assert!(c.is_closed_manifold(), "{}", c.summary());
        assert_eq!((c.shells, c.triangles), (1, 2 * 64 * 31));
        let exact = 4.0 / 3.0 * PI * 27.0;
        assert!(
            c.volume_mm3 < exact && c.volume_mm3 > 0.99 * exact,
            "{}",
            c.volume_mm3
        );
    }

    /// A torus is one closed shell with volume near 2π²·R·r² (inscribed, so below it).
    #[test]
    fn torus_is_closed_and_close_to_the_torus() {
        let c = torus([0.0; 3], 10.0, 3.0, 96, 48).check();
        assert!(c.is_closed_manifold(), "{}", c.summary());
        assert_eq!(c.shells, 1);
        let exact = 2.0 * PI * PI * 10.0 * 9.0;
        assert!(
            c.volume_mm3 < exact && c.volume_mm3 > 0.99 * exact,
            "{}",
            c.volume_mm3
        );
    }
}
