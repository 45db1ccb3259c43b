//! Indexed triangle meshes in millimetres and the watertightness check every part must pass.
//!
//! Owns [`Mesh`] (vertices and counter-clockwise triangles, outward normals by the right-hand
//! rule), its measures (volume, area, bounding box, shells) and [`Mesh::check`], the edge
//! check printable output is held to: every undirected edge in exactly two faces, used once in
//! each direction; every vertex's faces forming one fan; no face with a repeated vertex or a
//! zero area; positive enclosed volume. Library validators have been seen to accept
//! non-manifold meshes (`shared/reference/geometry-crates.md`), so this check is our own and
//! looks at every edge. It does not build shapes (see `geometry::mesher`) nor read or write
//! files.

use rayon::prelude::*;
use rustc_hash::FxHashMap as HashMap;

/// Smallest face area, mm², below which a face counts as degenerate. Default 1e-10 mm²: the
/// mesher's smallest legitimate faces (slivers next to a grid vertex) are several orders
/// larger, and an STL stores f32 coordinates, which resolve ~1e-5 mm at 100 mm, so a face
/// below this would collapse on writing.
pub const MIN_FACE_AREA_MM2: f64 = 1e-10;

/// An indexed triangle mesh. Coordinates are millimetres; triangles list vertex indices
/// counter-clockwise seen from outside.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Mesh {
    /// Vertex positions, mm.
    pub vertices: Vec<[f64; 3]>,
    /// Triangles as indices into `vertices`.
    pub triangles: Vec<[u32; 3]>,
}

/// Axis-aligned bounding box, mm.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Aabb {
    /// Smallest x, y, z.
    pub min: [f64; 3],
    /// Largest x, y, z.
    pub max: [f64; 3],
}

impl Aabb {
    /// The empty box (min +∞, max −∞): the identity of [`Aabb::union`].
    pub const EMPTY: Aabb = Aabb {
        min: [f64::INFINITY; 3],
        max: [f64::NEG_INFINITY; 3],
    };

    /// The box from `min` to `max`.
    pub fn new(min: [f64; 3], max: [f64; 3]) -> Aabb {
        Aabb { min, max }
    }

    /// The smallest box holding every point of `points` ([`Aabb::EMPTY`] for none).
    pub fn around(points: impl IntoIterator<Item = [f64; 3]>) -> Aabb {
        points.into_iter().fold(Aabb::EMPTY, |mut b, p| {
            for (k, &x) in p.iter().enumerate() {
                b.min[k] = b.min[k].min(x);
                b.max[k] = b.max[k].max(x);
            }
            b
        })
    }

    /// The smallest box holding both.
    pub fn union(&self, o: &Aabb) -> Aabb {
        let mut out = *self;
        for k in 0..3 {
            out.min[k] = out.min[k].min(o.min[k]);
            out.max[k] = out.max[k].max(o.max[k]);
        }
        out
    }

    /// Grown by `r` on every side.
    pub fn inflate(&self, r: f64) -> Aabb {
        let mut out = *self;
        for k in 0..3 {
            out.min[k] -= r;
            out.max[k] += r;
        }
        out
    }

    /// Euclidean distance from `p` to the box, 0 inside.
    pub fn distance(&self, p: [f64; 3]) -> f64 {
        self.distance_squared(p).sqrt()
    }

    /// Euclidean distance between this box and `o`, 0 where they touch or overlap.
    pub fn gap(&self, o: &Aabb) -> f64 {
        let mut s = 0.0;
        for k in 0..3 {
            let d = (self.min[k] - o.max[k])
                .max(o.min[k] - self.max[k])
                .max(0.0);
            s += d * d;
        }
        s.sqrt()
    }

    /// The square of [`Aabb::distance`] (no square root: for comparisons).
    #[inline]
    pub fn distance_squared(&self, p: [f64; 3]) -> f64 {
        let mut s = 0.0;
        for (k, &x) in p.iter().enumerate() {
            let d = (self.min[k] - x).max(x - self.max[k]).max(0.0);
            s += d * d;
        }
        s
    }

    /// Centre.
    pub fn center(&self) -> [f64; 3] {
        [
            0.5 * (self.min[0] + self.max[0]),
            0.5 * (self.min[1] + self.max[1]),
            0.5 * (self.min[2] + self.max[2]),
        ]
    }

    /// Extent along x, y, z.
    pub fn size(&self) -> [f64; 3] {
        [
            self.max[0] - self.min[0],
            self.max[1] - self.min[1],
            self.max[2] - self.min[2],
        ]
    }
}

/// What [`Mesh::check`] found. A mesh is printable when [`MeshCheck::is_closed_manifold`].
#[derive(Clone, Debug, Default, PartialEq)]
pub struct MeshCheck {
    /// Triangles.
    pub triangles: usize,
    /// Vertices referenced by at least one triangle.
    pub vertices: usize,
    /// Undirected edges.
    pub edges: usize,
    /// Undirected edges used by exactly one face (holes).
    pub boundary_edges: usize,
    /// Undirected edges used by more than two faces.
    pub non_manifold_edges: usize,
    /// Undirected edges used by two faces in the same direction (flipped neighbour).
    pub misoriented_edges: usize,
    /// Vertices whose faces form more than one fan (two surfaces touching at a point).
    pub non_manifold_vertices: usize,
    /// Faces with a repeated vertex index or an area below [`MIN_FACE_AREA_MM2`].
    pub degenerate_faces: usize,
    /// Indices out of range.
    pub bad_indices: usize,
    /// Enclosed volume, mm³ (positive when the faces point outwards).
    pub volume_mm3: f64,
    /// Connected pieces (shells) by shared edges.
    pub shells: usize,
}

impl MeshCheck {
    /// Closed, consistently oriented 2-manifold with positive volume and no degenerate face.
    pub fn is_closed_manifold(&self) -> bool {
        self.triangles > 0
            && self.boundary_edges == 0
            && self.non_manifold_edges == 0
            && self.misoriented_edges == 0
            && self.non_manifold_vertices == 0
            && self.degenerate_faces == 0
            && self.bad_indices == 0
            && self.volume_mm3 > 0.0
    }

    /// One line for reports: "closed 2-manifold, 1 shell" or what is wrong.
    pub fn summary(&self) -> String {
        if self.is_closed_manifold() {
            return format!(
                "closed 2-manifold, {} shell{}",
                self.shells,
                if self.shells == 1 { "" } else { "s" }
            );
        }
        let mut parts = Vec::new();
        for (n, what) in [
            (self.boundary_edges, "boundary edges"),
            (self.non_manifold_edges, "non-manifold edges"),
            (self.misoriented_edges, "misoriented edges"),
            (self.non_manifold_vertices, "non-manifold vertices"),
            (self.degenerate_faces, "degenerate faces"),
            (self.bad_indices, "bad indices"),
        ] {
            if n > 0 {
                parts.push(format!("{n} {what}"));
            }
        }
        if self.triangles == 0 {
            parts.push("no triangles".into());
        }
        if self.volume_mm3 <= 0.0 {
            parts.push(format!("volume {:.3} mm³ not positive", self.volume_mm3));
        }
        parts.join(", ")
    }
}

/// One use of an undirected edge by a triangle: the edge's lower and higher vertex, the
/// triangle, and which of its edges it is (k: from corner k to corner k + 1 mod 3).
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub(crate) struct EdgeUse {
    /// Lower vertex index.
    pub lo: u32,
    /// Higher vertex index.
    pub hi: u32,
    /// Triangle index.
    pub triangle: u32,
    /// Edge k of the triangle.
    pub k: u8,
}

impl EdgeUse {
    /// Whether the triangle runs along the edge from its lower to its higher vertex.
    pub fn forward(&self, triangles: &[[u32; 3]]) -> bool {
        let t = triangles[self.triangle as usize];
        t[self.k as usize] < t[(self.k as usize + 1) % 3]
    }
}

/// Every edge use of the triangles `keep` accepts, sorted so the uses of one undirected
/// edge come together, in triangle order: group them with
/// `chunk_by(|a, b| (a.lo, a.hi) == (b.lo, b.hi))`. The one edge table of the mesh check
/// and of the distance queries' pseudo-normals (`query`).
pub(crate) fn edge_uses(
    triangles: &[[u32; 3]],
    keep: impl Fn(&[u32; 3]) -> bool + Sync,
) -> Vec<EdgeUse> {
    let mut uses: Vec<EdgeUse> = triangles
        .par_iter()
        .enumerate()
        .filter(|(_, t)| keep(t))
        .flat_map_iter(|(i, t)| {
            (0..3).map(move |k| {
                let (a, b) = (t[k], t[(k + 1) % 3]);
                EdgeUse {
                    lo: a.min(b),
                    hi: a.max(b),
                    triangle: i as u32,
                    k: k as u8,
                }
            })
        })
        .collect();
    uses.par_sort_unstable();
    uses
}

/// `a − b`. These four are the array-vector helpers of the mesh code (`Mesh` stores plain
/// `[f64; 3]`); `geometry::simplify` uses them too.
pub(crate) fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}
/// `a × b`.
pub(crate) fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}
/// `a · b`.
pub(crate) fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}
/// `|a|`.
pub(crate) fn norm(a: [f64; 3]) -> f64 {
    dot(a, a).sqrt()
}

impl Mesh {
    /// Number of triangles.
    pub fn len(&self) -> usize {
        self.triangles.len()
    }

    /// No triangles.
    pub fn is_empty(&self) -> bool {
        self.triangles.is_empty()
    }

    /// The three corners of triangle `i`.
    pub fn corners(&self, i: usize) -> [[f64; 3]; 3] {
        let t = self.triangles[i];
        [
            self.vertices[t[0] as usize],
            self.vertices[t[1] as usize],
            self.vertices[t[2] as usize],
        ]
    }

    /// Unit normal of triangle `i` (right-hand rule), or zero for a degenerate face.
    pub fn face_normal(&self, i: usize) -> [f64; 3] {
        let [a, b, c] = self.corners(i);
        let n = cross(sub(b, a), sub(c, a));
        let l = norm(n);
        if l > 0.0 {
            [n[0] / l, n[1] / l, n[2] / l]
        } else {
            [0.0; 3]
        }
    }

    /// Signed enclosed volume, mm³ (divergence theorem; positive for outward faces of a
    /// closed mesh).
    pub fn volume(&self) -> f64 {
        (0..self.triangles.len())
            .map(|i| {
                let [a, b, c] = self.corners(i);
                dot(a, cross(b, c))
            })
            .sum::<f64>()
            / 6.0
    }

    /// Surface area, mm².
    pub fn area(&self) -> f64 {
        (0..self.triangles.len()).map(|i| self.face_area(i)).sum()
    }

    /// Area of triangle `i`, mm².
    pub fn face_area(&self, i: usize) -> f64 {
        let [a, b, c] = self.corners(i);
        0.5 * norm(cross(sub(b, a), sub(c, a)))
    }

    /// Centre (centroid) of triangle `i`.
    pub fn face_centre(&self, i: usize) -> [f64; 3] {
        let [a, b, c] = self.corners(i);
        [0, 1, 2].map(|k| (a[k] + b[k] + c[k]) / 3.0)
    }

    /// Bounding box of the vertices (all zero for an empty mesh).
    pub fn aabb(&self) -> Aabb {
        if self.vertices.is_empty() {
            return Aabb {
                min: [0.0; 3],
                max: [0.0; 3],
            };
        }
        Aabb::around(self.vertices.iter().copied())
    }

    /// Apply `f` to every vertex (a rigid motion keeps the mesh valid; a reflection would
    /// turn it inside out).
    pub fn map_vertices(&mut self, f: impl Fn([f64; 3]) -> [f64; 3]) {
        for v in &mut self.vertices {
            *v = f(*v);
        }
    }

    /// Move by `d` mm.
    pub fn translate(&mut self, d: [f64; 3]) {
        self.map_vertices(|v| [v[0] + d[0], v[1] + d[1], v[2] + d[2]]);
    }

    /// Append `other`'s vertices and triangles (no welding: the result has one more shell
    /// for each of `other`'s).
    pub fn append(&mut self, other: &Mesh) {
        let base = self.vertices.len() as u32;
        self.vertices.extend_from_slice(&other.vertices);
        self.triangles.extend(
            other
                .triangles
                .iter()
                .map(|t| [t[0] + base, t[1] + base, t[2] + base]),
        );
    }

    /// The mesh split into its connected pieces (shells), each with its own vertices.
    pub fn shells(&self) -> Vec<Mesh> {
        let nv = self.vertices.len();
        let mut parent: Vec<usize> = (0..nv).collect();
        fn find(p: &mut [usize], mut i: usize) -> usize {
            while p[i] != i {
                p[i] = p[p[i]];
                i = p[i];
            }
            i
        }
        for t in &self.triangles {
            for (a, b) in [(t[0], t[1]), (t[1], t[2])] {
                let (ra, rb) = (find(&mut parent, a as usize), find(&mut parent, b as usize));
                parent[ra] = rb;
            }
        }
        let mut shell_of_root: HashMap<usize, usize> = HashMap::default();
        let mut out: Vec<Mesh> = Vec::new();
        let mut remap: Vec<u32> = vec![u32::MAX; nv];
        for t in &self.triangles {
            let root = find(&mut parent, t[0] as usize);
            let s = *shell_of_root.entry(root).or_insert_with(|| {
                out.push(Mesh::default());
                out.len() - 1
            });
            let m = &mut out[s];
            let mut tri = [0u32; 3];
            for (k, &v) in t.iter().enumerate() {
                if remap[v as usize] == u32::MAX {
                    m.vertices.push(self.vertices[v as usize]);
                    remap[v as usize] = (m.vertices.len() - 1) as u32;
                }
                tri[k] = remap[v as usize];
            }
            m.triangles.push(tri);
        }
        out
    }

    /// Whether `p` lies inside this closed mesh: the parity of crossings of a ray from `p`
    /// (in a fixed direction off every axis, so it misses edges and vertices in practice).
    pub fn contains(&self, p: [f64; 3]) -> bool {
        let d = [0.577_215_664_9, 0.312_829_455_4, 0.754_877_666_2];
        let mut crossings = 0usize;
        for i in 0..self.triangles.len() {
            let [a, b, c] = self.corners(i);
            // Möller–Trumbore.
            let e1 = sub(b, a);
            let e2 = sub(c, a);
            let h = cross(d, e2);
            let det = dot(e1, h);
            if det.abs() < 1e-14 {
                continue;
            }
            let f = 1.0 / det;
            let s = sub(p, a);
            let u = f * dot(s, h);
            if !(0.0..=1.0).contains(&u) {
                continue;
            }
            let q = cross(s, e1);
            let v = f * dot(d, q);
            if v < 0.0 || u + v > 1.0 {
                continue;
            }
            if f * dot(e2, q) > 0.0 {
                crossings += 1;
            }
        }
        crossings % 2 == 1
    }

    /// The edge check: see the module doc and [`MeshCheck`].
    pub fn check(&self) -> MeshCheck {
        let nv = self.vertices.len();
        let mut out = MeshCheck {
            triangles: self.triangles.len(),
            ..MeshCheck::default()
        };
        let mut used = vec![false; nv];
        let mut good_faces = Vec::with_capacity(self.triangles.len());
        for (i, t) in self.triangles.iter().enumerate() {
            if t.iter().any(|&v| v as usize >= nv) {
                out.bad_indices += 1;
                continue;
            }
            for &v in t {
                used[v as usize] = true;
            }
            let [a, b, c] = self.corners(i);
            if t[0] == t[1]
                || t[1] == t[2]
                || t[0] == t[2]
                || 0.5 * norm(cross(sub(b, a), sub(c, a))) < MIN_FACE_AREA_MM2
            {
                out.degenerate_faces += 1;
            }
            good_faces.push(i);
        }
        out.vertices = used.iter().filter(|&&u| u).count();
        // Each undirected edge's uses, lo→hi (forward) and hi→lo.
        let uses = edge_uses(&self.triangles, |t| t.iter().all(|&v| (v as usize) < nv));
        for group in uses.chunk_by(|a, b| (a.lo, a.hi) == (b.lo, b.hi)) {
            out.edges += 1;
            let fwd = group.iter().filter(|u| u.forward(&self.triangles)).count();
            match group.len() {
                1 => out.boundary_edges += 1,
                2 if fwd == 1 => {}
                2 => out.misoriented_edges += 1,
                _ => out.non_manifold_edges += 1,
            }
        }
        out.volume_mm3 = if out.bad_indices == 0 {
            self.volume()
        } else {
            0.0
        };
        out.non_manifold_vertices = self.count_non_manifold_vertices(&good_faces);
        out.shells = self.count_shells(&good_faces);
        out
    }

    /// Vertices whose incident faces do not form a single fan (connected through edges that
    /// contain the vertex).
    fn count_non_manifold_vertices(&self, faces: &[usize]) -> usize {
        let nv = self.vertices.len();
        // Faces around each vertex (CSR layout).
        let mut start = vec![0u32; nv + 1];
        for &f in faces {
            for &v in &self.triangles[f] {
                start[v as usize + 1] += 1;
            }
        }
        for i in 0..nv {
            start[i + 1] += start[i];
        }
        let mut fill = start.clone();
        let mut around = vec![0u32; start[nv] as usize];
        for &f in faces {
            for &v in &self.triangles[f] {
                around[fill[v as usize] as usize] = f as u32;
                fill[v as usize] += 1;
            }
        }
        let mut bad = 0;
        for v in 0..nv {
            let fs = &around[start[v] as usize..start[v + 1] as usize];
            if fs.len() < 2 {
                continue;
            }
            // Union-find over this vertex's faces: two faces join when they share the edge
            // (v, w) for some other vertex w.
            let mut parent: Vec<usize> = (0..fs.len()).collect();
            fn find(p: &mut [usize], mut i: usize) -> usize {
                while p[i] != i {
                    p[i] = p[p[i]];
                    i = p[i];
                }
                i
            }
            let mut by_other: HashMap<u32, usize> = HashMap::default();
            for (j, &f) in fs.iter().enumerate() {
                for &w in &self.triangles[f as usize] {
                    if w as usize == v {
                        continue;
                    }
                    if let Some(&k) = by_other.get(&w) {
                        let (a, b) = (find(&mut parent, j), find(&mut parent, k));
                        parent[a] = b;
                    } else {
                        by_other.insert(w, j);
                    }
                }
            }
            let roots = (0..fs.len()).filter(|&j| find(&mut parent, j) == j).count();
            if roots > 1 {
                bad += 1;
            }
        }
        bad
    }

    /// Connected pieces through shared vertices.
    fn count_shells(&self, faces: &[usize]) -> usize {
        let nv = self.vertices.len();
        let mut parent: Vec<usize> = (0..nv).collect();
        fn find(p: &mut [usize], mut i: usize) -> usize {
            while p[i] != i {
                p[i] = p[p[i]];
                i = p[i];
            }
            i
        }
        let mut used = vec![false; nv];
        for &f in faces {
            let t = self.triangles[f];
            for &v in &t {
                used[v as usize] = true;
            }
            for (a, b) in [(t[0], t[1]), (t[1], t[2])] {
                let (ra, rb) = (find(&mut parent, a as usize), find(&mut parent, b as usize));
                parent[ra] = rb;
            }
        }
        (0..nv)
            .filter(|&v| used[v] && find(&mut parent, v) == v)
            .count()
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// A closed axis-aligned box with outward faces, `size` mm, corner at the origin.
    pub(crate) fn cube(size: f64) -> Mesh {
        let s = size;
        let vertices = vec![
            [0.0, 0.0, 0.0],
            [s, 0.0, 0.0],
            [s, s, 0.0],
            [0.0, s, 0.0],
            [0.0, 0.0, s],
            [s, 0.0, s],
            [s, s, s],
            [0.0, s, s],
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

    /// A closed cube passes with its exact volume and one shell.
    #[test]
    fn cube_is_a_closed_manifold() {
        let c = cube(2.0).check();
        assert!(c.is_closed_manifold(), "{}", c.summary());
        assert_eq!((c.edges, c.shells, c.vertices), (18, 1, 8));
        assert!((c.volume_mm3 - 8.0).abs() < 1e-12);
        assert_eq!(cube(2.0).area(), 24.0);
    }

    /// Each defect the check promises to catch is counted: a hole, a flipped face, an edge
    /// shared by four faces, a pinched vertex, a degenerate face, inside-out orientation.
    #[test]
    fn each_defect_is_counted() {
        let mut hole = cube(1.0);
        hole.triangles.pop();
        let c = hole.check();
        assert_eq!(c.boundary_edges, 3);
        assert!(!c.is_closed_manifold());

        let mut flipped = cube(1.0);
        flipped.triangles[0].swap(1, 2);
        let c = flipped.check();
        assert_eq!(c.misoriented_edges, 3);

        // Two cubes sharing one edge: that edge has four faces.
        let mut two = cube(1.0);
        let mut other = cube(1.0);
        other.translate([1.0, 1.0, 0.0]);
        two.append(&other);
        weld(&mut two);
        let c = two.check();
        assert_eq!(c.non_manifold_edges, 1, "{c:?}");

        // Two cubes sharing one corner: edges fine, the corner is pinched.
        let mut corner = cube(1.0);
        let mut other = cube(1.0);
        other.translate([1.0, 1.0, 1.0]);
        corner.append(&other);
        weld(&mut corner);
        let c = corner.check();
        assert_eq!((c.non_manifold_edges, c.non_manifold_vertices), (0, 1));
        assert_eq!(c.shells, 1);

        let mut degenerate = cube(1.0);
        degenerate.triangles.push([0, 0, 1]);
        assert_eq!(degenerate.check().degenerate_faces, 1);

        let mut inside_out = cube(1.0);
        for t in &mut inside_out.triangles {
            t.swap(1, 2);
        }
        let c = inside_out.check();
        assert_eq!(c.misoriented_edges, 0);
        assert!(c.volume_mm3 < 0.0 && !c.is_closed_manifold());
        assert_eq!(c.summary(), "volume -1.000 mm³ not positive");
    }

    /// Two separate cubes are two shells, and still a closed manifold.
    #[test]
    fn shells_are_counted() {
        let mut two = cube(1.0);
        let mut other = cube(1.0);
        other.translate([3.0, 0.0, 0.0]);
        two.append(&other);
        let c = two.check();
        assert!(c.is_closed_manifold());
        assert_eq!(c.shells, 2);
        assert_eq!(c.summary(), "closed 2-manifold, 2 shells");
        let parts = two.shells();
        assert_eq!(parts.len(), 2);
        assert!(parts.iter().all(|m| m.check().is_closed_manifold()));
        assert!(two.contains([3.5, 0.5, 0.5]) && two.contains([0.5, 0.5, 0.5]));
        assert!(!two.contains([2.0, 0.5, 0.5]) && !two.contains([0.5, 0.5, 1.5]));
    }

    /// Merge vertices at identical positions (test helper).
    fn weld(m: &mut Mesh) {
        let mut map: HashMap<[u64; 3], u32> = HashMap::default();
        let mut verts = Vec::new();
        let mut remap = Vec::new();
        for v in &m.vertices {
            let key = [v[0].to_bits(), v[1].to_bits(), v[2].to_bits()];
            let id = *map.entry(key).or_insert_with(|| {
                verts.push(*v);
                (verts.len() - 1) as u32
            });
            remap.push(id);
        }
        m.vertices = verts;
        for t in &mut m.triangles {
            for v in t.iter_mut() {
                *v = remap[*v as usize];
            }
        }
    }
}
