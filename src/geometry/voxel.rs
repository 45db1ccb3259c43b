//! Regular voxel grids: exact Euclidean distance transforms and shortest free paths.
//!
//! Owns [`VoxelGrid`] (an axis-aligned lattice of voxel centres in mm), [`DistanceField`]
//! (one f32 per voxel with trilinear sampling), [`distance_transform`] (the exact distance
//! from every voxel centre to the nearest marked one, by the separable lower-envelope
//! method of Felzenszwalb and Huttenlocher, linear in the voxel count) and
//! [`shortest_path`] (A* over 26-connected voxels whose clearance is large enough, then
//! shortened to the fewest straight segments that keep it), and [`OnceValues`] (one f32 per
//! voxel computed the first time it is asked). It does not know what the marks or
//! obstacles are (`build` sweeps parts into grids).

use std::cmp::Ordering;
use std::collections::BinaryHeap;
use std::sync::atomic::{AtomicU32, Ordering as AtomicOrdering};

use rayon::prelude::*;

use super::mesh::Aabb;
use super::sdf::Vec3;

/// One f32 per cell, computed the first time a caller asks and kept: for values that cost a
/// mesh query each where most cells are never asked (the check's and the prediction's
/// distances near a part, asked along the contact strips only). Threads may race on a
/// cell; its value depends on the cell alone, so both store the same bits.
pub struct OnceValues {
    cells: Vec<AtomicU32>,
}

/// A cell of [`OnceValues`] not computed yet: a NaN no kept value has (those keep the one
/// NaN of `f32::NAN`).
const NOT_YET: u32 = u32::MAX;

impl OnceValues {
    /// `len` cells, none computed.
    pub fn new(len: usize) -> OnceValues {
        OnceValues {
            cells: (0..len).map(|_| AtomicU32::new(NOT_YET)).collect(),
        }
    }

    /// The value of cell `i`: `make`'s, the first time.
    pub fn get_or(&self, i: usize, make: impl FnOnce() -> f32) -> f32 {
        let bits = self.cells[i].load(AtomicOrdering::Relaxed);
        if bits != NOT_YET {
            return f32::from_bits(bits);
        }
        let v = make();
        let v = if v.is_nan() { f32::NAN } else { v };
        self.cells[i].store(v.to_bits(), AtomicOrdering::Relaxed);
        v
    }

    /// How many cells have been computed.
    pub fn computed(&self) -> usize {
        self.cells
            .iter()
            .filter(|c| c.load(AtomicOrdering::Relaxed) != NOT_YET)
            .count()
    }
}

/// A lattice of voxel centres: `origin` is the centre of voxel (0, 0, 0).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct VoxelGrid {
    /// Centre of voxel (0, 0, 0), mm.
    pub origin: Vec3,
    /// Voxel edge, mm.
    pub h: f64,
    /// Voxels per axis.
    pub n: [usize; 3],
}

impl VoxelGrid {
    /// The grid of `h`-mm voxels covering `bounds`.
    pub fn covering(bounds: Aabb, h: f64) -> VoxelGrid {
        let s = bounds.size();
        VoxelGrid {
            origin: Vec3::new(bounds.min[0], bounds.min[1], bounds.min[2]),
            h,
            n: [
                (s[0] / h).ceil() as usize + 1,
                (s[1] / h).ceil() as usize + 1,
                (s[2] / h).ceil() as usize + 1,
            ],
        }
    }

    /// Number of voxels.
    pub fn len(&self) -> usize {
        self.n[0] * self.n[1] * self.n[2]
    }

    /// No voxels.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Flat index of voxel (i, j, k).
    pub fn index(&self, i: [usize; 3]) -> usize {
        i[0] + self.n[0] * (i[1] + self.n[1] * i[2])
    }

    /// Voxel (i, j, k) of a flat index.
    pub fn unflat(&self, f: usize) -> [usize; 3] {
        [
            f % self.n[0],
            (f / self.n[0]) % self.n[1],
            f / (self.n[0] * self.n[1]),
        ]
    }

    /// Centre of voxel (i, j, k).
    pub fn center(&self, i: [usize; 3]) -> Vec3 {
        self.origin + Vec3::new(i[0] as f64, i[1] as f64, i[2] as f64) * self.h
    }

    /// The voxel whose centre is nearest to `p`, if inside the grid.
    pub fn voxel_of(&self, p: Vec3) -> Option<[usize; 3]> {
        let q = (p - self.origin) / self.h;
        let mut out = [0usize; 3];
        for k in 0..3 {
            // The nearest centre is in the grid for q in (−½, n − ½) (NaN is not).
            if !(q[k] > -0.5 && q[k] < self.n[k] as f64 - 0.5) {
                return None;
            }
            // Rounded half away from zero, as `f64::round` does, without its call into libm
            // (a share of the build's check in perf): the truncation's remainder is exact.
            let t = q[k] as usize;
            out[k] = if q[k] - t as f64 >= 0.5 { t + 1 } else { t };
        }
        Some(out)
    }

    /// For every voxel, whether its cell meets the box of one of `triangles` (corners, mm);
    /// a box beyond the grid marks the voxels at its edge. Every point of every triangle in
    /// the grid then lies in a marked voxel, within half a diagonal of its centre, however
    /// large the triangles are: the build's check and the virtual prototype bound distances
    /// from the surface on that (simplified meshes have edges of up to 2 mm).
    pub fn marks_of_triangle_boxes(
        &self,
        triangles: impl IntoIterator<Item = [[f64; 3]; 3]>,
    ) -> Vec<bool> {
        let origin = [self.origin.x, self.origin.y, self.origin.z];
        // The nearest centre along axis k, clamped to the grid (as `voxel_of` rounds).
        let cell = |x: f64, k: usize| -> usize {
            (((x - origin[k]) / self.h + 0.5).floor().max(0.0) as usize).min(self.n[k] - 1)
        };
        let mut marks = vec![false; self.len()];
        for c in triangles {
            let lo = [0, 1, 2].map(|k| cell(c[0][k].min(c[1][k]).min(c[2][k]), k));
            let hi = [0, 1, 2].map(|k| cell(c[0][k].max(c[1][k]).max(c[2][k]), k));
            for z in lo[2]..=hi[2] {
                for y in lo[1]..=hi[1] {
                    for x in lo[0]..=hi[0] {
                        marks[self.index([x, y, z])] = true;
                    }
                }
            }
        }
        marks
    }
}

/// One f32 per voxel of a grid, sampled trilinearly between centres.
#[derive(Clone, Debug)]
pub struct DistanceField {
    /// The lattice.
    pub grid: VoxelGrid,
    /// Values, flat index order.
    pub values: Vec<f32>,
    /// Value returned outside the grid.
    pub outside: f32,
}

impl DistanceField {
    /// Trilinear sample at `p` (the `outside` value beyond the outermost centres).
    pub fn sample(&self, p: Vec3) -> f64 {
        let g = &self.grid;
        let q = (p - g.origin) / g.h;
        let mut i0 = [0usize; 3];
        let mut fr = [0.0f64; 3];
        for k in 0..3 {
            if !(q[k] >= 0.0 && q[k] <= (g.n[k] - 1) as f64) {
                return self.outside as f64;
            }
            let f = q[k].floor().min((g.n[k].max(2) - 2) as f64);
            i0[k] = f as usize;
            fr[k] = q[k] - f;
        }
        let v = |di: usize, dj: usize, dk: usize| -> f64 {
            self.values[g.index([i0[0] + di, i0[1] + dj, i0[2] + dk])] as f64
        };
        let lerp = |a: f64, b: f64, s: f64| a + (b - a) * s;
        let x00 = lerp(v(0, 0, 0), v(1, 0, 0), fr[0]);
        let x10 = lerp(v(0, 1, 0), v(1, 1, 0), fr[0]);
        let x01 = lerp(v(0, 0, 1), v(1, 0, 1), fr[0]);
        let x11 = lerp(v(0, 1, 1), v(1, 1, 1), fr[0]);
        lerp(lerp(x00, x10, fr[1]), lerp(x01, x11, fr[1]), fr[2])
    }

    /// The smaller of two fields on the same grid, voxel by voxel (distance to the union).
    pub fn min(&self, other: &DistanceField) -> DistanceField {
        assert_eq!(self.grid, other.grid, "fields on different grids");
        DistanceField {
            grid: self.grid,
            values: self
                .values
                .iter()
                .zip(&other.values)
                .map(|(a, b)| a.min(*b))
                .collect(),
            outside: self.outside.min(other.outside),
        }
    }

    /// The value at voxel (i, j, k).
    pub fn at(&self, i: [usize; 3]) -> f64 {
        self.values[self.grid.index(i)] as f64
    }
}

/// Squared distance, in voxels², along one line: the lower envelope of parabolas rooted at
/// the finite entries of `f` (Felzenszwalb & Huttenlocher, "Distance Transforms of Sampled
/// Functions", 2012). `v` and `z` are scratch of length n and n + 1.
fn envelope_1d(f: &[f64], out: &mut [f64], v: &mut [usize], z: &mut [f64]) {
    let n = f.len();
    let mut k: isize = -1;
    for q in 0..n {
        if !f[q].is_finite() {
            continue;
        }
        loop {
            if k < 0 {
                k = 0;
                v[0] = q;
                z[0] = f64::NEG_INFINITY;
                z[1] = f64::INFINITY;
                break;
            }
            let p = v[k as usize];
            let s = ((f[q] + (q * q) as f64) - (f[p] + (p * p) as f64)) / (2.0 * (q - p) as f64);
            if s <= z[k as usize] {
                k -= 1;
                continue;
            }
            k += 1;
            v[k as usize] = q;
            z[k as usize] = s;
            z[k as usize + 1] = f64::INFINITY;
            break;
        }
    }
    if k < 0 {
        out.iter_mut().for_each(|o| *o = f64::INFINITY);
        return;
    }
    let mut j = 0usize;
    for (q, o) in out.iter_mut().enumerate() {
        while z[j + 1] < q as f64 {
            j += 1;
        }
        let p = v[j];
        let d = q as f64 - p as f64;
        *o = d * d + f[p];
    }
}

/// Distance in mm from every voxel centre to the nearest marked voxel centre (`marks[i]`
/// true); `f32::INFINITY` everywhere when nothing is marked.
pub fn distance_transform(grid: &VoxelGrid, marks: &[bool]) -> Vec<f32> {
    let [nx, ny, nz] = grid.n;
    let mut d: Vec<f64> = marks
        .iter()
        .map(|&m| if m { 0.0 } else { f64::INFINITY })
        .collect();
    // Pass along x: lines are contiguous.
    d.par_chunks_mut(nx).for_each(|line| {
        let f = line.to_vec();
        let (mut v, mut z) = (vec![0usize; nx], vec![0.0f64; nx + 1]);
        envelope_1d(&f, line, &mut v, &mut z);
    });
    // Along y, then z: gather each line, transform, scatter (planes in parallel for y).
    d.par_chunks_mut(nx * ny).for_each(|plane| {
        let mut f = vec![0.0; ny];
        let mut out = vec![0.0; ny];
        let (mut v, mut z) = (vec![0usize; ny], vec![0.0f64; ny + 1]);
        for i in 0..nx {
            for j in 0..ny {
                f[j] = plane[i + nx * j];
            }
            envelope_1d(&f, &mut out, &mut v, &mut z);
            for j in 0..ny {
                plane[i + nx * j] = out[j];
            }
        }
    });
    let plane = nx * ny;
    let columns: Vec<Vec<f64>> = (0..plane)
        .into_par_iter()
        .map(|c| {
            let f: Vec<f64> = (0..nz).map(|k| d[c + plane * k]).collect();
            let mut out = vec![0.0; nz];
            let (mut v, mut z) = (vec![0usize; nz], vec![0.0f64; nz + 1]);
            envelope_1d(&f, &mut out, &mut v, &mut z);
            out
        })
        .collect();
    let mut res = vec![0.0f32; d.len()];
    for (c, col) in columns.iter().enumerate() {
        for (k, &x) in col.iter().enumerate() {
            res[c + plane * k] = (x.sqrt() * grid.h) as f32;
        }
    }
    res
}

#[derive(Clone, Copy, PartialEq)]
struct Open {
    f: f64,
    node: usize,
}
impl Eq for Open {}
impl Ord for Open {
    fn cmp(&self, o: &Self) -> Ordering {
        o.f.total_cmp(&self.f).then(self.node.cmp(&o.node))
    }
}
impl PartialOrd for Open {
    fn partial_cmp(&self, o: &Self) -> Option<Ordering> {
        Some(self.cmp(o))
    }
}

/// What a path search may use.
pub struct PathQuery<'a> {
    /// Clearance of every voxel (mm): the distance to the nearest obstacle.
    pub clearance: &'a DistanceField,
    /// Voxels with clearance below this are blocked.
    pub min_clearance: f64,
    /// Clearance beyond which a voxel costs no more than plain length; below it a step costs
    /// up to three times its length, so paths keep away from obstacles when they can.
    pub comfortable: f64,
    /// Start voxels (any one will do).
    pub sources: &'a [[usize; 3]],
    /// Whether a voxel is a goal.
    pub is_goal: &'a (dyn Fn([usize; 3]) -> bool + Sync),
    /// A lower bound of the remaining length (mm) from a voxel to the goal (0 is valid).
    pub heuristic: &'a (dyn Fn(Vec3) -> f64 + Sync),
}

/// The cheapest 26-connected path of free voxels from a source to a goal, as voxel centres,
/// shortened to the fewest straight segments whose points all keep `min_clearance`; `None`
/// when the goal cannot be reached.
pub fn shortest_path(q: &PathQuery<'_>) -> Option<Vec<Vec3>> {
    let g = q.clearance.grid;
    let free = |i: [usize; 3]| q.clearance.at(i) >= q.min_clearance;
    let weight = |i: [usize; 3]| {
        let c = q.clearance.at(i);
        if c >= q.comfortable {
            1.0
        } else {
            1.0 + 2.0 * (q.comfortable - c) / (q.comfortable - q.min_clearance).max(1e-9)
        }
    };
    let mut cost = vec![f64::INFINITY; g.len()];
    let mut from = vec![usize::MAX; g.len()];
    let mut heap = BinaryHeap::new();
    for &s in q.sources {
        if !free(s) {
            continue;
        }
        let i = g.index(s);
        cost[i] = 0.0;
        heap.push(Open {
            f: (q.heuristic)(g.center(s)),
            node: i,
        });
    }
    let mut goal = None;
    while let Some(Open { node, f }) = heap.pop() {
        let here = g.unflat(node);
        if f > cost[node] + (q.heuristic)(g.center(here)) + 1e-9 {
            continue;
        }
        if (q.is_goal)(here) {
            goal = Some(node);
            break;
        }
        for dk in -1i64..=1 {
            for dj in -1i64..=1 {
                for di in -1i64..=1 {
                    if di == 0 && dj == 0 && dk == 0 {
                        continue;
                    }
                    let nb = [
                        here[0] as i64 + di,
                        here[1] as i64 + dj,
                        here[2] as i64 + dk,
                    ];
                    if (0..3).any(|k| nb[k] < 0 || nb[k] >= g.n[k] as i64) {
                        continue;
                    }
                    let nb = [nb[0] as usize, nb[1] as usize, nb[2] as usize];
                    if !free(nb) {
                        continue;
                    }
                    let len = ((di * di + dj * dj + dk * dk) as f64).sqrt() * g.h;
                    let c = cost[node] + len * 0.5 * (weight(here) + weight(nb));
                    let j = g.index(nb);
                    if c < cost[j] {
                        cost[j] = c;
                        from[j] = node;
                        heap.push(Open {
                            f: c + (q.heuristic)(g.center(nb)),
                            node: j,
                        });
                    }
                }
            }
        }
    }
    let mut node = goal?;
    let mut path = vec![g.center(g.unflat(node))];
    while from[node] != usize::MAX {
        node = from[node];
        path.push(g.center(g.unflat(node)));
    }
    path.reverse();
    Some(shorten(&path, q.clearance, q.min_clearance))
}

/// Greedy string pulling: from each kept point, jump to the farthest later point reachable
/// by a straight segment that keeps the clearance (sampled every quarter voxel).
fn shorten(path: &[Vec3], field: &DistanceField, min_clearance: f64) -> Vec<Vec3> {
    let step = 0.25 * field.grid.h;
    let visible = |a: Vec3, b: Vec3| {
        let n = ((b - a).norm() / step).ceil().max(1.0) as usize;
        (0..=n).all(|s| field.sample(a + (b - a) * (s as f64 / n as f64)) >= min_clearance)
    };
    let mut out = vec![path[0]];
    let mut i = 0;
    while i + 1 < path.len() {
        let mut j = path.len() - 1;
        while j > i + 1 && !visible(path[i], path[j]) {
            j -= 1;
        }
        out.push(path[j]);
        i = j;
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Guards the marks the distance bounds rest on: points all over a triangle much
    /// longer than a voxel lie in marked voxels, voxels beyond its box are not marked, and
    /// a triangle beyond the grid marks the edge of the grid.
    #[test]
    fn a_long_triangle_marks_every_voxel_its_points_lie_in() {
        let grid = VoxelGrid::covering(Aabb::new([0.0; 3], [10.0, 4.0, 4.0]), 1.0);
        let t = [[0.2, 0.3, 0.4], [9.7, 1.1, 2.9], [4.4, 3.6, 0.6]];
        let marks = grid.marks_of_triangle_boxes([t]);
        for (u, v) in [
            (0.1, 0.1),
            (0.5, 0.2),
            (0.2, 0.7),
            (0.45, 0.45),
            (0.9, 0.05),
        ] {
            let p = Vec3::from(t[0]) * (1.0 - u - v) + Vec3::from(t[1]) * u + Vec3::from(t[2]) * v;
            let i = grid.voxel_of(p).expect("in the grid");
            assert!(marks[grid.index(i)], "{p:?}");
        }
        // Only the voxels of the box: none beyond x = 10 or at z = 4 (the box ends at 2.9).
        assert!(!marks[grid.index([0, 0, 4])]);
        // A triangle beyond the grid marks the voxel at its edge, without a panic.
        let out =
            grid.marks_of_triangle_boxes([[[20.0, 1.0, 1.0], [21.0, 1.0, 1.0], [20.0, 2.0, 1.0]]]);
        assert!(out[grid.index([10, 1, 1])]);
    }

    /// Guards `voxel_of`'s rounding without libm: the voxel is the one `f64::round` picks,
    /// halves, the largest double below a half, both ends of the grid, beyond them and NaN
    /// included.
    #[test]
    fn voxel_of_rounds_as_round_does() {
        // At the origin with 1 mm voxels a point's coordinate is its q to the bit.
        let g = VoxelGrid {
            origin: Vec3::zeros(),
            h: 1.0,
            n: [7, 1, 300],
        };
        let by_round = |p: Vec3| -> Option<[usize; 3]> {
            let q = (p - g.origin) / g.h;
            let mut out = [0usize; 3];
            for k in 0..3 {
                let r = q[k].round();
                if !(r >= 0.0 && (r as usize) < g.n[k]) {
                    return None;
                }
                out[k] = r as usize;
            }
            Some(out)
        };
        let below_half = 0.5 - f64::EPSILON / 4.0;
        let mut qs: Vec<f64> = vec![f64::NAN, f64::INFINITY, f64::NEG_INFINITY, below_half];
        for i in -3..305 {
            for f in [0.0, 0.25, 0.5, -0.5, below_half, -below_half, 0.999_999] {
                qs.push(f64::from(i) + f);
            }
        }
        let mut seen = 0;
        for &q in &qs {
            for k in 0..3 {
                let mut p = g.origin + Vec3::new(0.1, 0.1, 0.1) * g.h;
                p[k] = g.origin[k] + q * g.h;
                assert_eq!(g.voxel_of(p), by_round(p), "q = {q:e} along {k}");
                seen += usize::from(by_round(p).is_some());
            }
        }
        assert!(seen > 2000, "{seen} points inside");
    }

    /// The transform equals brute force over all marks on a random sparse pattern.
    #[test]
    fn distance_transform_is_exact() {
        let g = VoxelGrid {
            origin: Vec3::zeros(),
            h: 0.5,
            n: [13, 9, 7],
        };
        let marks: Vec<bool> = (0..g.len()).map(|i| (i * 7919) % 61 == 3).collect();
        let d = distance_transform(&g, &marks);
        let marked: Vec<Vec3> = (0..g.len())
            .filter(|&i| marks[i])
            .map(|i| g.center(g.unflat(i)))
            .collect();
        for (i, &di) in d.iter().enumerate() {
            let c = g.center(g.unflat(i));
            let brute = marked
                .iter()
                .map(|m| (m - c).norm())
                .fold(f64::INFINITY, f64::min);
            assert!((di as f64 - brute).abs() < 1e-5, "voxel {i}");
        }
    }

    /// A path around a wall goes around it, keeps its clearance, and is a few straight
    /// segments; with the gap closed there is no path.
    #[test]
    fn path_goes_around_a_wall() {
        let g = VoxelGrid {
            origin: Vec3::zeros(),
            h: 1.0,
            n: [40, 40, 3],
        };
        // A wall at x = 20 for y < 30.
        let wall = |open: bool| {
            let marks: Vec<bool> = (0..g.len())
                .map(|i| {
                    let v = g.unflat(i);
                    v[0] == 20 && (!open || v[1] < 30)
                })
                .collect();
            DistanceField {
                grid: g,
                values: distance_transform(&g, &marks),
                outside: 0.0,
            }
        };
        let field = wall(true);
        let goal = |v: [usize; 3]| v[0] == 35 && v[1] == 5;
        let h = |p: Vec3| (p - Vec3::new(35.0, 5.0, p.z)).norm();
        let q = PathQuery {
            clearance: &field,
            min_clearance: 2.0,
            comfortable: 4.0,
            sources: &[[5, 5, 1]],
            is_goal: &goal,
            heuristic: &h,
        };
        let p = shortest_path(&q).expect("a way round");
        assert!(p.len() <= 5, "{p:?}");
        assert!(
            p.iter().any(|v| v.y >= 31.5),
            "passes above the wall: {p:?}"
        );
        for w in p.windows(2) {
            for s in 0..=20 {
                let x = w[0] + (w[1] - w[0]) * (s as f64 / 20.0);
                assert!(field.sample(x) >= 2.0 - 1e-9);
            }
        }
        let closed = wall(false);
        let q = PathQuery {
            clearance: &closed,
            ..q
        };
        assert!(shortest_path(&q).is_none());
    }
}
