//! Which items may lie near a point: a regular grid of cells round a set of boxed items,
//! each cell listing the items whose value can be below a reach anywhere in it, nearest
//! bound first.
//!
//! Owns [`CellLists`]: built once from each item's box and a caller's lower and upper
//! bounds of the item's value over a cell, it answers a point with the items of its cell
//! and their lower bounds, sorted so that a search for the least value can stop at the
//! first bound not below the best so far, and with an upper bound of the least value over
//! the cell, so that the search can start below its own limit. It does not know what the
//! items are or how their values are computed ([`super::sweep`] lists a sweep's pieces
//! with it), and it answers nothing beyond the reach: the caller falls back to its own
//! search there.

use rayon::prelude::*;

use super::mesh::Aabb;

/// Items near the cells of a grid, each cell's sorted by a lower bound of their value
/// over the cell (see the module's doc).
#[derive(Clone, Debug)]
pub struct CellLists {
    /// The corner of cell (0, 0, 0).
    min: [f64; 3],
    /// Cells per mm.
    per_mm: f64,
    dims: [usize; 3],
    /// Cell c's entries are `starts[c]..starts[c + 1]` of `items` and `lows`.
    starts: Vec<u32>,
    items: Vec<u32>,
    /// Each entry's lower bound, rounded down to f32: never above the item's value at any
    /// point of the cell.
    lows: Vec<f32>,
    /// Per cell, the least of its entries' upper bounds, rounded up to f32 (infinity for a
    /// cell without entries): never below the least value over the items at any point of
    /// the cell.
    highs: Vec<f32>,
    reach: f64,
}

/// What [`CellLists::near`] answers for a point.
#[derive(Clone, Copy, Debug)]
pub struct Near<'a> {
    /// The items listed in the point's cell.
    pub items: &'a [u32],
    /// Their lower bounds, smallest first.
    pub lows: &'a [f32],
    /// An upper bound of the least value over every item at the point (infinity when the
    /// cell lists none).
    pub high: f64,
}

/// An entry while the lists are made: cell, lower bound, upper bound, item.
type Entry = (u32, f32, f32, u32);

impl CellLists {
    /// The lists over cells of `cell` mm round `boxes` (item i has box i): an item is
    /// listed in a cell when its lower bound there is below `reach`. `bounds(i, cell)`
    /// gives a lower and an upper bound of item i's value at every point of the cell (the
    /// lower may be loose, down to 0; the upper up to infinity). The lower bound listed is
    /// the larger of the caller's and the cell's distance from the item's box, so an item's
    /// value must never be below its box's distance either. Ties of the lower bound are
    /// broken by the upper, smaller first, so that the search meets a near item early.
    /// Items with an empty box are never listed.
    pub fn new(
        boxes: &[Aabb],
        cell: f64,
        reach: f64,
        bounds: impl Fn(usize, &Aabb) -> (f64, f64) + Sync,
    ) -> CellLists {
        let all = boxes.iter().fold(Aabb::EMPTY, |b, x| b.union(x));
        let (min, dims, cell) = if all.min[0] <= all.max[0] {
            let grown = all.inflate(reach);
            let dims_at = |cell: f64| grown.size().map(|s| ((s / cell).ceil() as usize).max(1));
            let count = |d: [usize; 3]| d[0] as f64 * d[1] as f64 * d[2] as f64;
            // The grid spans the items' whole box: over a large part, coarser cells (the
            // lists hold for any size, only less tightly).
            let mut cell = cell;
            while count(dims_at(cell)) > MAX_CELLS as f64 {
                cell *= (count(dims_at(cell)) / MAX_CELLS as f64).cbrt().max(1.01);
            }
            (grown.min, dims_at(cell), cell)
        } else {
            ([0.0; 3], [0; 3], cell)
        };
        let cells = dims[0] * dims[1] * dims[2];
        let cell_box = |c: [usize; 3]| {
            let lo = [0, 1, 2].map(|k| min[k] + c[k] as f64 * cell);
            Aabb::new(lo, lo.map(|x| x + cell))
        };
        let mut entries: Vec<Entry> = boxes
            .par_iter()
            .enumerate()
            .flat_map_iter(|(i, b)| {
                let mut out = Vec::new();
                if b.min[0] > b.max[0] {
                    return out;
                }
                let g = b.inflate(reach);
                let lo = [0, 1, 2].map(|k| {
                    (((g.min[k] - min[k]) / cell).floor().max(0.0) as usize).min(dims[k] - 1)
                });
                let hi = [0, 1, 2].map(|k| {
                    (((g.max[k] - min[k]) / cell).floor().max(0.0) as usize).min(dims[k] - 1)
                });
                for z in lo[2]..=hi[2] {
                    for y in lo[1]..=hi[1] {
                        for x in lo[0]..=hi[0] {
                            let c = [x, y, z];
                            let cb = cell_box(c);
                            let (low, high) = bounds(i, &cb);
                            let low = cb.gap(b).max(low);
                            if low < reach {
                                let (low, high) = (round_down(low), round_up(high));
                                out.push((flat(dims, c) as u32, low, high, i as u32));
                            }
                        }
                    }
                }
                out
            })
            .collect();
        // A counting sort by cell, then each cell's few entries by bound.
        let mut starts = vec![0u32; cells + 1];
        for e in &entries {
            starts[e.0 as usize + 1] += 1;
        }
        for c in 0..cells {
            starts[c + 1] += starts[c];
        }
        let mut placed = vec![(0.0f32, 0.0f32, 0u32); entries.len()];
        let mut next = starts.clone();
        for e in entries.drain(..) {
            let at = &mut next[e.0 as usize];
            placed[*at as usize] = (e.1, e.2, e.3);
            *at += 1;
        }
        let mut slices = Vec::with_capacity(cells);
        let mut rest = placed.as_mut_slice();
        for c in 0..cells {
            let (this, more) = rest.split_at_mut((starts[c + 1] - starts[c]) as usize);
            slices.push(this);
            rest = more;
        }
        slices.par_iter_mut().for_each(|cell| {
            cell.sort_unstable_by(|a, b| {
                a.0.total_cmp(&b.0)
                    .then(a.1.total_cmp(&b.1))
                    .then(a.2.cmp(&b.2))
            })
        });
        let highs = (0..cells)
            .map(|c| {
                let at = starts[c] as usize..starts[c + 1] as usize;
                placed[at].iter().map(|e| e.1).fold(f32::INFINITY, f32::min)
            })
            .collect();
        CellLists {
            min,
            per_mm: 1.0 / cell,
            dims,
            starts,
            items: placed.iter().map(|e| e.2).collect(),
            lows: placed.iter().map(|e| e.0).collect(),
            highs,
            reach,
        }
    }

    /// The items of `p`'s cell, their lower bounds (smallest first) and an upper bound of
    /// the least value over all items at `p`: every item whose value at `p` can be below
    /// [`CellLists::reach`] is among them. `None` outside the grid (where every item's box
    /// is farther than the reach).
    #[inline]
    pub fn near(&self, p: [f64; 3]) -> Option<Near<'_>> {
        let mut c = [0usize; 3];
        for k in 0..3 {
            let x = (p[k] - self.min[k]) * self.per_mm;
            // Written so that a NaN falls outside too. Truncation is the floor for x ≥ 0
            // (and no call to libm's `floor`, which the query's profile showed); a point
            // put in the neighbouring cell by round-off is within the bounds' slack of it.
            if !(x >= 0.0 && x < self.dims[k] as f64) {
                return None;
            }
            c[k] = x as usize;
        }
        let i = flat(self.dims, c);
        let (a, b) = (self.starts[i] as usize, self.starts[i + 1] as usize);
        Some(Near {
            items: &self.items[a..b],
            lows: &self.lows[a..b],
            high: f64::from(self.highs[i]),
        })
    }

    /// Below this value, a cell's list holds every item that can reach it.
    pub fn reach(&self) -> f64 {
        self.reach
    }

    /// How many entries all the lists hold.
    pub fn entries(&self) -> usize {
        self.items.len()
    }

    /// How many cells the grid has.
    pub fn cells(&self) -> usize {
        self.dims[0] * self.dims[1] * self.dims[2]
    }
}

/// Cell `c`'s index in a grid of `dims` cells, x fastest.
fn flat(dims: [usize; 3], c: [usize; 3]) -> usize {
    (c[2] * dims[1] + c[1]) * dims[0] + c[0]
}

/// Most cells a grid holds (two u32 per cell, 32 MiB): a box over the lists' reach of
/// 2²² cells of 1 mm is 161 mm on every side; a larger one takes coarser cells.
const MAX_CELLS: usize = 1 << 22;

/// Round-off a bound may carry from being computed over a cell rather than at the point,
/// mm: far below any resolution, far above f64 round-off at part scale.
const BOUND_SLACK_MM: f64 = 1e-9;

/// `x` less [`BOUND_SLACK_MM`], as an f32 never above it (0 stays 0).
fn round_down(x: f64) -> f32 {
    let x = (x - BOUND_SLACK_MM).max(0.0);
    let f = x as f32;
    if f as f64 > x {
        f32::from_bits(f.to_bits() - 1)
    } else {
        f
    }
}

/// `x` plus [`BOUND_SLACK_MM`], as an f32 never below it.
fn round_up(x: f64) -> f32 {
    let x = x + BOUND_SLACK_MM;
    let f = x as f32;
    if (f as f64) < x {
        f32::from_bits(f.to_bits() + 1)
    } else {
        f
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Guards the lists' promise: items are points, valued by their distance, in boxes a
    /// little larger, with bounds from the cell's nearest and farthest points. At random
    /// points every item nearer than the reach is listed, with a bound not above its value,
    /// the bounds come smallest first, and the cell's upper bound is not below the least
    /// value.
    #[test]
    fn every_item_within_reach_is_listed_with_bounds_that_hold() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(12345);
        let mut rnd = move || rng.random::<f64>();
        let points: Vec<[f64; 3]> = (0..60)
            .map(|_| [rnd() * 20.0, rnd() * 20.0, rnd() * 20.0])
            .collect();
        let dist = |a: [f64; 3], b: [f64; 3]| {
            ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
        };
        let boxes: Vec<Aabb> = points
            .iter()
            .map(|&c| Aabb::new(c, c).inflate(0.3))
            .collect();
        let reach = 3.0;
        let lists = CellLists::new(&boxes, 1.0, reach, |i, cell| {
            let c = points[i];
            let far = [0, 1, 2].map(|k| {
                if c[k] - cell.min[k] > cell.max[k] - c[k] {
                    cell.min[k]
                } else {
                    cell.max[k]
                }
            });
            (cell.distance(c), dist(c, far))
        });
        assert!(lists.entries() > 0);
        let mut with_high = 0;
        for _ in 0..20_000 {
            let p = [rnd() * 30.0 - 5.0, rnd() * 30.0 - 5.0, rnd() * 30.0 - 5.0];
            let value = |i: usize| dist(points[i], p);
            let near: Vec<usize> = (0..points.len()).filter(|&i| value(i) < reach).collect();
            match lists.near(p) {
                None => assert!(near.is_empty(), "{p:?} outside the grid, {near:?} near"),
                Some(Near { items, lows, high }) => {
                    for &i in &near {
                        let at = items.iter().position(|&j| j as usize == i);
                        let at = at.unwrap_or_else(|| panic!("{i} not listed at {p:?}"));
                        assert!(f64::from(lows[at]) <= value(i));
                    }
                    assert!(lows.windows(2).all(|w| w[0] <= w[1]));
                    let least = (0..points.len()).map(value).fold(f64::INFINITY, f64::min);
                    assert!(
                        high >= least,
                        "{high} below the least value {least} at {p:?}"
                    );
                    with_high += usize::from(high.is_finite());
                }
            }
        }
        assert!(with_high > 5_000, "{with_high} points with an upper bound");
    }

    /// Guards the grid's size over a large box: items 2 m apart get no more than
    /// [`MAX_CELLS`] cells, and every item is still listed where it is near.
    #[test]
    fn a_large_box_takes_coarser_cells() {
        let boxes = [
            Aabb::new([0.0; 3], [1.0; 3]),
            Aabb::new([2000.0, 1500.0, 900.0], [2001.0, 1501.0, 901.0]),
        ];
        let lists = CellLists::new(&boxes, 1.0, 3.0, |_, _| (0.0, f64::INFINITY));
        assert!(lists.cells() <= MAX_CELLS, "{} cells", lists.cells());
        for (i, p) in [(0, [0.5; 3]), (1, [2002.5, 1500.5, 900.5])] {
            let near = lists.near(p).unwrap();
            assert!(near.items.contains(&i), "{i} not listed at {p:?}");
        }
    }

    /// Guards that a caller's bound tightens the lists: an item whose bound is at the reach
    /// everywhere is listed nowhere, and no grid is made for no items.
    #[test]
    fn a_caller_bound_at_the_reach_lists_nothing() {
        let boxes = [Aabb::new([0.0; 3], [1.0; 3])];
        let lists = CellLists::new(&boxes, 0.5, 2.0, |_, _| (2.0, 3.0));
        assert_eq!(lists.entries(), 0);
        let near = lists.near([0.5; 3]).unwrap();
        assert_eq!((near.items.len(), near.high), (0, f64::INFINITY));
        let none = CellLists::new(&[], 0.5, 2.0, |_, _| (0.0, f64::INFINITY));
        assert!(none.near([0.0; 3]).is_none());
    }
}
