//! Fewer triangles for the same surface: half-edge collapses under a distance bound.
//!
//! Owns [`simplify`]. The mesher's triangles are about a third of a cell across wherever the
//! surface is, flat or not, so a part at 0.4 mm cells has millions of them: files of a
//! hundred megabytes and every later query (the check, the virtual prototype) paying for
//! each. A collapse moves one vertex onto a neighbour and drops the two faces of their edge.
//!
//! What it guarantees:
//! - **Vertices are the input's.** A collapse only removes a vertex; every vertex left is
//!   one the mesher placed, where it placed it.
//! - **A bound on the distance.** Each vertex carries the quadric of the planes of every
//!   input face merged into it, unweighted (Garland and Heckbert 1997), so the quadric's
//!   value at a point is the sum of the squared distances to those planes and bounds the
//!   largest of them. A collapse is made only if that sum stays within the tolerance's
//!   square: every vertex left lies within the tolerance of the plane of each input face
//!   it absorbed. (That bounds the faces' interiors only as far as those planes follow the
//!   surface between the vertices; `build::fidelity` measures what the faces end up at.)
//! - **Still a closed 2-manifold.** A collapse keeps the topology (the link condition: the
//!   two ends share no neighbour but the two faces' third corners, and neither of those is
//!   left with fewer than three faces), turns no face by more than [`SimplifyOptions::
//!   max_turn_deg`], makes no face thinner than [`SimplifyOptions::min_quality`] unless it
//!   was already, and no edge longer than [`SimplifyOptions::max_edge_mm`].
//! - **Deterministic.** Costs are computed on every thread, but collapses are made on one,
//!   in order of cost level and then of index.
//!
//! It does not guarantee that two sheets of the surface closer than the tolerance stay
//! apart; the build's bound, 0.01 mm, is an eightieth of the thinnest wall it means to
//! print (`build::dims::SLIVER_MM`). It does not mesh (`geometry::mesher`) nor check
//! (`Mesh::check`, which the callers run on its output).

use rayon::prelude::*;

use super::mesh::{cross, dot, norm, sub, Mesh};

/// What a simplification may do.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SimplifyOptions {
    /// Largest distance, mm, a vertex left may lie from the plane of any input face merged
    /// into it.
    pub tolerance_mm: f64,
    /// Largest turn of a face's normal in one collapse, degrees.
    pub max_turn_deg: f64,
    /// Smallest shape quality of a face a collapse makes (`quality`: 1 for an equilateral
    /// triangle, 0 for a flat one), unless the face it replaces was already worse.
    pub min_quality: f64,
    /// Longest edge a collapse may make, mm.
    pub max_edge_mm: f64,
}

impl SimplifyOptions {
    /// Within `tolerance_mm`, with the guards meant for parts meshed at 0.1–1 mm cells:
    /// - a face turns by at most 30° in one collapse (the bound keeps the surface within
    ///   the tolerance; this keeps a thin face from swinging across a narrow ridge);
    /// - no face of quality below 0.02 (about 115 times as long as it is high) unless the
    ///   face it replaces was already worse: the mesher makes faces down to 0.001 where the
    ///   surface passes next to a grid point, and at 0.1 a box's flat sides kept faces that
    ///   only a thinner face on the way could remove (an axis-aligned box at 0.5 mm cells
    ///   kept 2 248 of its 2 488 faces);
    /// - no edge longer than 2 mm (five default cells: the build's check and the virtual
    ///   prototype bound a face's reach by its longest edge; on half-turn-2to1's parts
    ///   2 mm kept 27 % of the triangles against 26 % with 5 mm).
    pub fn within(tolerance_mm: f64) -> SimplifyOptions {
        SimplifyOptions {
            tolerance_mm,
            max_turn_deg: 30.0,
            min_quality: 0.02,
            max_edge_mm: 2.0,
        }
    }
}

/// What a simplification did.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SimplifyStats {
    /// Triangles before.
    pub triangles_before: usize,
    /// Triangles after.
    pub triangles_after: usize,
    /// Collapses made.
    pub collapses: usize,
    /// Vertices whose collapses passed the bound but no guard (topology, turn, shape,
    /// length), counted once per pass.
    pub refused: usize,
    /// Passes made.
    pub passes: usize,
}

/// Shape quality of a triangle: 4√3 · area / (sum of the squared edges), 1 for an
/// equilateral triangle and 0 for a flat one.
pub fn quality(a: [f64; 3], b: [f64; 3], c: [f64; 3]) -> f64 {
    let n = cross(sub(b, a), sub(c, a));
    let s = dot(sub(b, a), sub(b, a)) + dot(sub(c, b), sub(c, b)) + dot(sub(a, c), sub(a, c));
    if s > 0.0 {
        2.0 * 3f64.sqrt() * norm(n) / s
    } else {
        0.0
    }
}

/// A symmetric 4 × 4 quadric in its ten distinct entries: the sum over planes n·x + d = 0
/// (|n| = 1) of (n·x + d)².
#[derive(Clone, Copy, Debug, Default, PartialEq)]
struct Quadric([f64; 10]);

impl Quadric {
    fn plane(n: [f64; 3], d: f64) -> Quadric {
        let [a, b, c] = n;
        Quadric([
            a * a,
            a * b,
            a * c,
            a * d,
            b * b,
            b * c,
            b * d,
            c * c,
            c * d,
            d * d,
        ])
    }

    fn add(&mut self, o: &Quadric) {
        for (x, y) in self.0.iter_mut().zip(o.0.iter()) {
            *x += y;
        }
    }

    /// The sum of the squared distances of `p` from the planes.
    fn at(&self, p: [f64; 3]) -> f64 {
        let q = &self.0;
        let [x, y, z] = p;
        let v = x * (q[0] * x + 2.0 * (q[1] * y + q[2] * z + q[3]))
            + y * (q[4] * y + 2.0 * (q[5] * z + q[6]))
            + z * (q[7] * z + 2.0 * q[8])
            + q[9];
        v.max(0.0)
    }
}

/// Passes at most. Each pass collapses an independent set of vertices (no two whose faces
/// touch); half-turn-2to1's printable parts end after 11, by [`PASS_MIN_SHARE`].
const MAX_PASSES: usize = 24;

/// A pass that made fewer collapses than this share of the input's triangles is the last:
/// what further passes would remove is below a per cent of the triangles left.
const PASS_MIN_SHARE: f64 = 0.002;

struct State<'a> {
    pos: &'a [[f64; 3]],
    tris: Vec<[u32; 3]>,
    alive: Vec<bool>,
    vfaces: Vec<Vec<u32>>,
    quadric: Vec<Quadric>,
    /// Each vertex's cheapest collapse's cost, when last computed.
    cheapest: Vec<f64>,
    /// Vertices every guard refused, since their faces last changed.
    refused: Vec<bool>,
    opts: SimplifyOptions,
    cos_turn: f64,
    limit: f64,
    stats: SimplifyStats,
}

/// Simplify the closed mesh `mesh` as `opts` allow: see the module doc. The result has the
/// same shells and the same orientation; its vertices are a subset of `mesh`'s. The
/// guards assume a closed 2-manifold (the mesher's guarantee; [`Mesh::check`] is what
/// tells, and costs a second on a part): another mesh comes back without a panic but with
/// no promise, and one with an index out of range comes back as it is.
pub fn simplify(mesh: &Mesh, opts: &SimplifyOptions) -> (Mesh, SimplifyStats) {
    let nv_in = mesh.vertices.len();
    if mesh
        .triangles
        .iter()
        .flatten()
        .any(|&v| v as usize >= nv_in)
    {
        let n = mesh.triangles.len();
        let stats = SimplifyStats {
            triangles_before: n,
            triangles_after: n,
            ..SimplifyStats::default()
        };
        return (mesh.clone(), stats);
    }
    // The vertices renumbered in the order the triangles first use them, so that the
    // vertices of neighbouring faces lie near each other in memory: the mesher numbers
    // them block by block as its threads finish, and on screw-bob's driver (3.1 M
    // triangles) simplifying in that order took 9.2 s against 4.6 s in this one.
    let mut new_of = vec![u32::MAX; mesh.vertices.len()];
    let mut old_of: Vec<u32> = Vec::with_capacity(mesh.vertices.len());
    let tris: Vec<[u32; 3]> = mesh
        .triangles
        .iter()
        .map(|t| {
            t.map(|v| {
                if new_of[v as usize] == u32::MAX {
                    new_of[v as usize] = old_of.len() as u32;
                    old_of.push(v);
                }
                new_of[v as usize]
            })
        })
        .collect();
    drop(new_of);
    let nv = old_of.len();
    // Planes through a point near the mesh, so that the quadrics' terms stay small next
    // to the tolerance's square.
    let origin = mesh.aabb().center();
    let pos: Vec<[f64; 3]> = old_of
        .iter()
        .map(|&v| sub(mesh.vertices[v as usize], origin))
        .collect();
    let mut vfaces: Vec<Vec<u32>> = vec![Vec::new(); nv];
    let mut quadric = vec![Quadric::default(); nv];
    for (i, t) in tris.iter().enumerate() {
        let [a, b, c] = t.map(|v| pos[v as usize]);
        let n = cross(sub(b, a), sub(c, a));
        let l = norm(n);
        let q = if l > 0.0 {
            let n = [n[0] / l, n[1] / l, n[2] / l];
            Quadric::plane(n, -dot(n, a))
        } else {
            Quadric::default()
        };
        for &v in t {
            vfaces[v as usize].push(i as u32);
            quadric[v as usize].add(&q);
        }
    }
    let mut s = State {
        pos: &pos,
        tris,
        alive: vec![true; mesh.triangles.len()],
        vfaces,
        quadric,
        cheapest: vec![f64::INFINITY; nv],
        refused: vec![false; nv],
        opts: *opts,
        cos_turn: opts.max_turn_deg.to_radians().cos(),
        limit: opts.tolerance_mm * opts.tolerance_mm,
        stats: SimplifyStats {
            triangles_before: mesh.triangles.len(),
            ..SimplifyStats::default()
        },
    };
    let mut dirty = vec![true; nv];
    for _ in 0..MAX_PASSES {
        let made = s.pass(&mut dirty);
        s.stats.passes += 1;
        if (made as f64) < PASS_MIN_SHARE * mesh.triangles.len() as f64 {
            break;
        }
    }
    // Compact.
    let mut remap = vec![u32::MAX; nv];
    let mut out = Mesh::default();
    for (t, &alive) in s.tris.iter().zip(&s.alive) {
        if !alive {
            continue;
        }
        let mut tri = [0u32; 3];
        for (k, &v) in t.iter().enumerate() {
            if remap[v as usize] == u32::MAX {
                remap[v as usize] = out.vertices.len() as u32;
                out.vertices
                    .push(mesh.vertices[old_of[v as usize] as usize]);
            }
            tri[k] = remap[v as usize];
        }
        out.triangles.push(tri);
    }
    s.stats.triangles_after = out.triangles.len();
    (out, s.stats)
}

impl State<'_> {
    /// The neighbours of `v`, from its faces: in a closed 2-manifold each is the next
    /// corner after `v` in exactly one of them.
    fn ring(&self, v: u32, out: &mut Vec<u32>) {
        out.clear();
        out.extend(
            self.vfaces[v as usize]
                .iter()
                .map(|&f| next_after(&self.tris[f as usize], v)),
        );
    }

    fn cost(&self, from: u32, to: u32) -> f64 {
        let p = self.pos[to as usize];
        self.quadric[from as usize].at(p) + self.quadric[to as usize].at(p)
    }

    /// The cost of the cheapest collapse of `v` onto a neighbour, or +∞.
    fn best(&self, v: u32) -> f64 {
        self.vfaces[v as usize]
            .iter()
            .map(|&f| self.cost(v, next_after(&self.tris[f as usize], v)))
            .fold(f64::INFINITY, f64::min)
    }

    /// One pass: the vertices' cheapest collapses within the bound, in order of cost level
    /// (`cost_level`), each made unless a collapse of this pass changed its faces or its
    /// target's, or a guard refuses it (then its next target in order of cost is tried).
    /// `dirty` holds the vertices whose faces or neighbours changed since their cost was
    /// computed, and is left holding those this pass changed; a vertex every guard
    /// refused is not tried again until then. Returns the collapses made.
    fn pass(&mut self, dirty: &mut [bool]) -> usize {
        let fresh: Vec<(u32, f64)> = (0..self.vfaces.len() as u32)
            .into_par_iter()
            .filter(|&v| dirty[v as usize])
            .map(|v| (v, self.best(v)))
            .collect();
        for (v, c) in fresh {
            self.cheapest[v as usize] = c;
            self.refused[v as usize] = false;
        }
        dirty.iter_mut().for_each(|d| *d = false);
        let mut order: Vec<(u8, u32)> = self
            .cheapest
            .iter()
            .enumerate()
            .filter(|&(v, &c)| c <= self.limit && !self.refused[v])
            .map(|(v, &c)| (cost_level(c / self.limit), v as u32))
            .collect();
        order.par_sort_unstable();
        let mut made = 0;
        let mut ring = Vec::with_capacity(16);
        let mut ring_to = Vec::with_capacity(16);
        let mut targets: Vec<(f64, u32)> = Vec::with_capacity(16);
        for &(_, v) in &order {
            if dirty[v as usize] || self.vfaces[v as usize].is_empty() {
                continue;
            }
            self.ring(v, &mut ring);
            targets.clear();
            targets.extend(
                ring.iter()
                    .map(|&w| (self.cost(v, w), w))
                    .filter(|&(c, _)| c <= self.limit),
            );
            targets.sort_unstable_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
            let mut skipped = false;
            let mut chosen = None;
            for &(_, w) in &targets {
                if dirty[w as usize] {
                    skipped = true;
                } else if self.collapse_allowed(v, w, &mut ring_to) {
                    chosen = Some(w);
                    break;
                }
            }
            let Some(w) = chosen else {
                if !skipped {
                    self.refused[v as usize] = true;
                    self.stats.refused += 1;
                }
                continue;
            };
            self.collapse(v, w);
            self.cheapest[v as usize] = f64::INFINITY;
            made += 1;
            dirty[w as usize] = true;
            for &u in &ring {
                dirty[u as usize] = true;
            }
        }
        self.stats.collapses += made;
        made
    }

    fn collapse_allowed(&self, a: u32, b: u32, ring_b: &mut Vec<u32>) -> bool {
        let fa = &self.vfaces[a as usize];
        // The two faces of the edge and their third corners.
        let mut shared = [u32::MAX; 2];
        let mut n_shared = 0;
        for &f in fa {
            let t = self.tris[f as usize];
            if t.contains(&b) {
                if n_shared == 2 {
                    return false;
                }
                shared[n_shared] = t.into_iter().find(|&w| w != a && w != b).unwrap_or(a);
                n_shared += 1;
            }
        }
        if n_shared != 2 || shared[0] == shared[1] {
            return false;
        }
        for &o in &shared {
            if self.vfaces[o as usize].len() <= 3 {
                return false;
            }
        }
        // The link condition.
        self.ring(b, ring_b);
        for &f in fa {
            for &w in &self.tris[f as usize] {
                if w != a && w != b && !shared.contains(&w) && ring_b.contains(&w) {
                    return false;
                }
            }
        }
        // The faces that stay, with `a` moved to `b`.
        let pb = self.pos[b as usize];
        for &f in fa {
            let t = self.tris[f as usize];
            if t.contains(&b) {
                continue;
            }
            let old = t.map(|w| self.pos[w as usize]);
            let new = t.map(|w| if w == a { pb } else { self.pos[w as usize] });
            let n_old = cross(sub(old[1], old[0]), sub(old[2], old[0]));
            let n_new = cross(sub(new[1], new[0]), sub(new[2], new[0]));
            let (l_old, l_new) = (norm(n_old), norm(n_new));
            if l_new <= 0.0 || dot(n_old, n_new) < self.cos_turn * l_old * l_new {
                return false;
            }
            let q_new = quality(new[0], new[1], new[2]);
            if q_new < self.opts.min_quality && q_new < quality(old[0], old[1], old[2]) {
                return false;
            }
            if t.iter()
                .any(|&w| w != a && norm(sub(self.pos[w as usize], pb)) > self.opts.max_edge_mm)
            {
                return false;
            }
        }
        true
    }

    fn collapse(&mut self, a: u32, b: u32) {
        let fa = std::mem::take(&mut self.vfaces[a as usize]);
        for &f in &fa {
            let t = &mut self.tris[f as usize];
            if t.contains(&b) {
                self.alive[f as usize] = false;
                let t = *t;
                for &w in &t {
                    if w != a {
                        let list = &mut self.vfaces[w as usize];
                        if let Some(i) = list.iter().position(|&g| g == f) {
                            list.swap_remove(i);
                        }
                    }
                }
            } else {
                for w in t.iter_mut() {
                    if *w == a {
                        *w = b;
                    }
                }
                self.vfaces[b as usize].push(f);
            }
        }
        let qa = self.quadric[a as usize];
        self.quadric[b as usize].add(&qa);
    }
}

/// Cost levels a pass sorts the collapses into, a factor of 4 apart, below the cheapest of
/// which every cost counts as none. Within a level vertices go in the mesher's order, which
/// keeps neighbours near each other in memory: sorting by the cost itself sent each
/// collapse to another part of the mesh and made a pass twice as slow (half-turn-2to1's
/// driver, 2.7 M triangles), for a result within a per cent of the triangles.
const COST_LEVELS: u8 = 8;

/// The level of a cost, as a share of the bound's (at most 1): 0 for a share below
/// 4^−(COST_LEVELS − 1), then one level per factor of 4 up to `COST_LEVELS - 1`.
fn cost_level(share: f64) -> u8 {
    let l = (COST_LEVELS - 1) as f64 + share.log(4.0).ceil();
    l.clamp(0.0, (COST_LEVELS - 1) as f64) as u8
}

/// The corner after `v` in the triangle `t` (which holds `v`), counter-clockwise.
fn next_after(t: &[u32; 3], v: u32) -> u32 {
    if t[0] == v {
        t[1]
    } else if t[1] == v {
        t[2]
    } else {
        t[0]
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geometry::mesher::mesh_solid;
    use crate::geometry::primitive_meshes::cuboid;
    use crate::geometry::sdf::{Cuboid, Sdf, Vec3};

    /// A hollow ball (radii 5 and 4 mm: a wall 1 mm thick, which the 0.4 mm cells resolve
    /// everywhere) meshed at 0.4 mm cells.
    fn hollow_ball() -> Mesh {
        let c = Vec3::new(0.13, 0.21, 0.37);
        let f = move |p: Vec3| {
            let r = (p - c).norm();
            (r - 5.0).max(4.0 - r)
        };
        let b = crate::geometry::mesh::Aabb::new([-5.5; 3], [5.7; 3]);
        mesh_solid(&f, b, 0.4).expect("meshed")
    }

    /// How far a point lies from the nearer of the hollow ball's two spheres, mm.
    fn off_ball(p: [f64; 3]) -> f64 {
        let r = (Vec3::from(p) - Vec3::new(0.13, 0.21, 0.37)).norm();
        (r - 5.0).abs().min((r - 4.0).abs())
    }

    /// Guards the promises of the module doc on a curved surface with a thin wall: the
    /// result is a closed 2-manifold with fewer than half the faces, its vertices are the
    /// input's, its enclosed volume moves by less than the tolerance times the area, and
    /// no face's centre lies farther from the true spheres than the mesher's own worst face
    /// plus the tolerance (so the wall's two sides stay apart).
    #[test]
    fn a_hollow_ball_keeps_its_surface_within_the_tolerance() {
        let mesh = hollow_ball();
        let tol = 0.01;
        let (out, stats) = simplify(&mesh, &SimplifyOptions::within(tol));
        let check = out.check();
        assert!(check.is_closed_manifold(), "{}", check.summary());
        assert_eq!(out.shells().len(), 2);
        assert_eq!(stats.triangles_before, mesh.len());
        assert_eq!(stats.triangles_after, out.len());
        assert!(out.len() * 2 < mesh.len(), "{stats:?}");
        let input: std::collections::HashSet<[u64; 3]> =
            mesh.vertices.iter().map(|v| v.map(f64::to_bits)).collect();
        assert!(out
            .vertices
            .iter()
            .all(|v| input.contains(&v.map(f64::to_bits))));
        let area = mesh.area();
        assert!(
            (out.volume() - mesh.volume()).abs() < tol * area,
            "{} against {}",
            out.volume(),
            mesh.volume()
        );
        let worst = |m: &Mesh| {
            (0..m.len())
                .map(|i| off_ball(m.face_centre(i)))
                .fold(0.0, f64::max)
        };
        let (before, after) = (worst(&mesh), worst(&out));
        assert!(after <= before + tol, "{after} against {before}");
    }

    /// Guards the flat case and the edges: a tilted box meshed at 0.5 mm keeps less than a
    /// third of its faces, and its volume, its box and its faces' distance from the true
    /// box within the tolerance of the mesher's (the bound keeps the planes of the faces
    /// on both sides of an edge, so the edges' facets stay where they were).
    #[test]
    fn a_meshed_box_keeps_its_volume_and_edges() {
        let cube = Cuboid {
            center: Vec3::new(0.13, 0.27, 0.31),
            half: Vec3::new(3.03, 2.07, 1.41),
            rotation: nalgebra::Rotation3::from_euler_angles(0.3, 0.2, 0.1),
        };
        let mesh = mesh_solid(&|p| cube.dist(p), cube.bounds(), 0.5).unwrap();
        let tol = 0.01;
        let (out, _) = simplify(&mesh, &SimplifyOptions::within(tol));
        assert!(out.check().is_closed_manifold());
        assert!(
            out.len() * 3 < mesh.len(),
            "{} of {}",
            out.len(),
            mesh.len()
        );
        assert!((out.volume() - mesh.volume()).abs() < tol * mesh.area());
        let (a, b) = (out.aabb(), mesh.aabb());
        for k in 0..3 {
            assert!((a.min[k] - b.min[k]).abs() <= tol && (a.max[k] - b.max[k]).abs() <= tol);
        }
        // No face's centre farther from the box than the mesher's worst plus the bound.
        let worst = |m: &Mesh| {
            (0..m.len())
                .map(|i| cube.dist(Vec3::from(m.face_centre(i))).abs())
                .fold(0.0, f64::max)
        };
        assert!(worst(&out) <= worst(&mesh) + tol);
    }

    /// Guards the topology guards: a closed mesh too small to lose a vertex (a box of 12
    /// triangles, whose every collapse would fold it flat) comes out unchanged.
    #[test]
    fn a_minimal_box_is_left_as_it_is() {
        let mesh = cuboid([0.0; 3], [1.0, 2.0, 3.0]);
        let (out, stats) = simplify(&mesh, &SimplifyOptions::within(0.05));
        assert_eq!(stats.collapses, 0);
        assert_eq!(out.triangles.len(), mesh.triangles.len());
        assert!((out.volume() - 6.0).abs() < 1e-12);
    }

    /// Guards input that is not a closed 2-manifold: no panic on an empty mesh, two boxes
    /// sharing an edge (four faces on it) or a box with a face left out (each still fails
    /// the check after), and an index out of range comes back as it was.
    #[test]
    fn meshes_that_are_not_closed_manifolds_do_not_panic() {
        let opts = SimplifyOptions::within(0.05);
        let a = cuboid([0.0; 3], [1.0; 3]);
        let mut b = cuboid([1.0, 1.0, 0.0], [2.0, 2.0, 1.0]);
        // Weld b's corner column at (1, 1) onto a's, so the boxes share that edge.
        let weld = |m: &Mesh, p: [f64; 3]| m.vertices.iter().position(|&v| v == p).unwrap();
        let mut shared = a.clone();
        for z in [0.0, 1.0] {
            let (from, to) = (weld(&b, [1.0, 1.0, z]), weld(&a, [1.0, 1.0, z]));
            b.vertices[from] = [9.0; 3];
            for t in &mut b.triangles {
                for v in t.iter_mut() {
                    if *v as usize == from {
                        *v = (to + 1000) as u32;
                    }
                }
            }
        }
        let base = shared.vertices.len() as u32;
        shared.vertices.extend_from_slice(&b.vertices);
        shared.triangles.extend(
            b.triangles
                .iter()
                .map(|t| t.map(|v| if v >= 1000 { v - 1000 } else { v + base })),
        );
        let mut open = a.clone();
        open.triangles.pop();
        let mut bad = a.clone();
        bad.triangles[0][0] = 99;
        let (out, stats) = simplify(&bad, &opts);
        assert_eq!((out, stats.collapses), (bad, 0));
        for m in [Mesh::default(), shared, open] {
            assert!(!m.check().is_closed_manifold());
            let (out, _) = simplify(&m, &opts);
            assert!(!out.check().is_closed_manifold());
        }
    }

    /// Guards determinism: the costs are computed on several threads, the collapses on
    /// one, so two runs give the same mesh to the bit.
    #[test]
    fn two_runs_agree() {
        let mesh = hollow_ball();
        let opts = SimplifyOptions::within(0.02);
        assert_eq!(simplify(&mesh, &opts), simplify(&mesh, &opts));
    }

    /// Guards the tolerance's meaning at its two ends: at 0 only coplanar faces merge
    /// (the curved ball keeps nearly every face), and a larger tolerance never keeps more
    /// faces than a smaller one.
    #[test]
    fn the_tolerance_orders_the_results() {
        let mesh = hollow_ball();
        let count = |tol: f64| simplify(&mesh, &SimplifyOptions::within(tol)).0.len();
        let (zero, fine, coarse) = (count(0.0), count(0.005), count(0.02));
        assert!(zero * 10 > mesh.len() * 9, "{zero} of {}", mesh.len());
        assert!(zero > fine && fine > coarse, "{zero}, {fine}, {coarse}");
    }

    /// Guards the shape measure: 1 for an equilateral triangle, 0 for a flat one.
    #[test]
    fn quality_is_one_for_equilateral_and_zero_for_flat() {
        let h = 3f64.sqrt() / 2.0;
        assert!((quality([0.0; 3], [1.0, 0.0, 0.0], [0.5, h, 0.0]) - 1.0).abs() < 1e-12);
        assert_eq!(quality([0.0; 3], [1.0, 0.0, 0.0], [2.0, 0.0, 0.0]), 0.0);
    }
}
