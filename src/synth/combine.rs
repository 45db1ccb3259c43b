//! Stage B: one candidate per band (paper §5.2.3), judged at every instant.
//!
//! Owns the closure of a combination ([`Pool`], from the candidates' per-instant views at
//! [`OVERSAMPLE`]× the sample density), the lexicographic [`Fitness`], and the way a
//! combination is chosen ([`combine`]): the genetic algorithm of `ga` over the sample
//! density, then, at the 4× density acceptance is judged at, the exact search when the
//! combinations are few ([`exact_limit`]) or a local search from the GA's best (replacing
//! one band's candidate, or two bands' at once). It
//! does not solve candidates or decide acceptance (see `search`).
//!
//! **Fitness** (compared lexicographically, better first):
//! 1. robust E_valiTime, higher (ours: the robust closure of `docs/conventions.md`);
//! 2. E_valiTime, higher (paper);
//! 3. robust E_maxDist, lower (ours);
//! 4. E_maxDist, lower (paper).
//!
//! The paper ranks by (2, 4). A sample that is robustly closed is closed (the robust hull
//! is that of a subset of the contacts), so robust validity is the binding requirement, and
//! ranking it first makes the search climb towards what acceptance asks. With the paper's
//! criteria first, a combination closed at every sample but robustly at 0.80 of them ranked
//! above one at 0.99 and 0.99. For 1R every valid design has E_maxDist = −1 exactly, so only
//! the validities separate 1R designs.
//!
//! **Why not the GA alone.** On the candidate pools of half-turn-2to1 (K = 3) and screw-bob
//! (K = 4) the GA's best was far from the best combination the pools held (robust E_valiTime
//! 0.62 against 0.87; 0.99 against a combination that closes at −0.068; see
//! `docs/synthesis.md`, "Combination"): its population converges within a few dozen
//! generations on plateaus of equal fitness.

use std::cmp::Ordering;

use rayon::prelude::*;

use super::candidate::OVERSAMPLE;
use super::closure::{self, Class, ClosureSummary, EPSILON};
use super::ga::{self, GaSettings};

/// Fitness of one combination (see the module doc for the order).
#[derive(Clone, Debug, PartialEq)]
pub struct Fitness {
    /// E_valiTime.
    pub vali_time: f64,
    /// Robust E_valiTime.
    pub robust_vali_time: f64,
    /// E_maxDist.
    pub max_dist: f64,
    /// Robust E_maxDist.
    pub robust_max_dist: f64,
}

impl Fitness {
    /// From a closure summary.
    pub fn of(s: &ClosureSummary) -> Self {
        Self {
            vali_time: s.vali_time,
            robust_vali_time: s.robust_vali_time,
            max_dist: s.max_dist,
            robust_max_dist: s.robust_max_dist,
        }
    }

    /// Lexicographic order: `Greater` means `self` is better.
    pub fn cmp_better(&self, o: &Self) -> Ordering {
        self.robust_vali_time
            .total_cmp(&o.robust_vali_time)
            .then(self.vali_time.total_cmp(&o.vali_time))
            .then(o.robust_max_dist.total_cmp(&self.robust_max_dist))
            .then(o.max_dist.total_cmp(&self.max_dist))
    }

    /// The least fitness that [`Fitness::closes`] at `margin`.
    pub fn closing(margin: f64) -> Self {
        Self {
            vali_time: 1.0,
            robust_vali_time: 1.0,
            max_dist: -margin,
            robust_max_dist: -margin,
        }
    }

    /// Closure at every instant, paper and robust, with E_maxDist ≤ −`margin` (both).
    pub fn closes(&self, margin: f64) -> bool {
        self.vali_time >= 1.0
            && self.robust_vali_time >= 1.0
            && self.max_dist <= -margin
            && self.robust_max_dist <= -margin
    }
}

/// One candidate as the combination sees it: per instant at [`OVERSAMPLE`]× the sample
/// density, ñ (None where it vanishes) and whether the contact counts for the robust closure.
pub type CandidateView<'a> = (&'a [Option<[f64; 3]>], &'a [bool]);

/// The usable candidates of every band, as the combination sees them.
pub struct Pool<'a> {
    /// Class.
    pub class: Class,
    /// Per band: the usable candidates' views.
    pub bands: Vec<Vec<CandidateView<'a>>>,
}

/// Which instants a fitness is computed over.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Density {
    /// The N samples of the period (every [`OVERSAMPLE`]-th view entry).
    Samples,
    /// Every view entry: [`OVERSAMPLE`]× the sample density, where acceptance is judged.
    Oversampled,
}

impl Density {
    fn step(self) -> usize {
        match self {
            Density::Samples => OVERSAMPLE,
            Density::Oversampled => 1,
        }
    }
}

/// Running closure figures of a combination over the instants seen so far. Every figure can
/// only get worse as more instants are seen, so a partial fitness bounds the final one from
/// above (see [`Pool::fitness_beating`]).
struct Tally {
    n: usize,
    invalid: usize,
    robust_invalid: usize,
    max_dist: f64,
    robust_max_dist: f64,
}

impl Tally {
    fn new(n: usize) -> Self {
        Self {
            n,
            invalid: 0,
            robust_invalid: 0,
            max_dist: f64::NEG_INFINITY,
            robust_max_dist: f64::NEG_INFINITY,
        }
    }
    fn add(&mut self, d: f64, r: f64) {
        self.invalid += (d >= -EPSILON) as usize;
        self.robust_invalid += (r >= -EPSILON) as usize;
        self.max_dist = self.max_dist.max(d);
        self.robust_max_dist = self.robust_max_dist.max(r);
    }
    /// The fitness as if no further instant failed (exact once every instant is seen; the
    /// same arithmetic as `ClosureSummary::from_dists`).
    fn fitness(&self) -> Fitness {
        let n = self.n.max(1) as f64;
        Fitness {
            vali_time: (self.n - self.invalid) as f64 / n,
            robust_vali_time: (self.n - self.robust_invalid) as f64 / n,
            max_dist: self.max_dist,
            robust_max_dist: self.robust_max_dist,
        }
    }
}

impl Pool<'_> {
    /// View entries per period.
    fn entries(&self) -> usize {
        self.bands[0][0].0.len()
    }

    /// dist and robust dist of `genome` at view entry `e`.
    fn dists_at(
        &self,
        genome: &[usize],
        e: usize,
        all: &mut Vec<[f64; 3]>,
        rob: &mut Vec<[f64; 3]>,
    ) -> (f64, f64) {
        all.clear();
        rob.clear();
        for (k, &g) in genome.iter().enumerate() {
            let (nt, r) = self.bands[k][g];
            if let Some(v) = nt[e] {
                all.push(v);
                if r[e] {
                    rob.push(v);
                }
            }
        }
        closure::signed_dists(self.class, all, rob)
    }

    /// Closure summary of a genome at the given density.
    pub fn summary(&self, genome: &[usize], density: Density) -> ClosureSummary {
        let step = density.step();
        let m = self.entries() / step;
        let (mut all, mut rob) = (Vec::new(), Vec::new());
        let (dist, rdist): (Vec<f64>, Vec<f64>) = (0..m)
            .map(|i| self.dists_at(genome, i * step, &mut all, &mut rob))
            .unzip();
        ClosureSummary::from_dists(dist, rdist)
    }

    /// Fitness of a genome at the given density.
    pub fn fitness(&self, genome: &[usize], density: Density) -> Fitness {
        let step = density.step();
        let m = self.entries() / step;
        self.fitness_beating(genome, step, 0..m, m, None)
            .expect("no bound to beat")
    }

    /// Fitness of `genome` over the `m` instants `order` (view entries `step·i`), or, as
    /// soon as it is certain to rank below `bound`, `Err` with the position in `order` that
    /// showed it: the running figures only get worse, so once the partial fitness ranks
    /// below the bound the final one does too. Instants where the bound's genome is
    /// tightest, put first in `order`, end most evaluations after a few instants.
    fn fitness_beating(
        &self,
        genome: &[usize],
        step: usize,
        order: impl IntoIterator<Item = usize>,
        m: usize,
        bound: Option<&Fitness>,
    ) -> Result<Fitness, usize> {
        let mut t = Tally::new(m);
        let (mut all, mut rob) = (Vec::with_capacity(genome.len()), Vec::new());
        for (pos, i) in order.into_iter().enumerate() {
            let (d, r) = self.dists_at(genome, i * step, &mut all, &mut rob);
            t.add(d, r);
            if let Some(b) = bound {
                if t.fitness().cmp_better(b) == Ordering::Less {
                    return Err(pos);
                }
            }
        }
        Ok(t.fitness())
    }

    /// The instants of a genome, tightest first (largest robust dist, then dist).
    fn tightest_first(&self, genome: &[usize], step: usize) -> Vec<usize> {
        let m = self.entries() / step;
        let (mut all, mut rob) = (Vec::new(), Vec::new());
        let mut d: Vec<(usize, (f64, f64))> = (0..m)
            .map(|i| (i, self.dists_at(genome, i * step, &mut all, &mut rob)))
            .collect();
        d.sort_by(|a, b| b.1 .1.total_cmp(&a.1 .1).then(b.1 .0.total_cmp(&a.1 .0)));
        d.into_iter().map(|(i, _)| i).collect()
    }

    /// Number of combinations (saturating).
    fn combinations(&self) -> usize {
        self.bands
            .iter()
            .fold(1usize, |acc, b| acc.saturating_mul(b.len()))
    }
}

/// Largest number of combinations searched exhaustively, per class; beyond it the GA's best
/// is improved by a local search. Default 1R 2 000 000, 1R1T 200 000, 3R 20 000: a combined
/// closure evaluation costs about 10 ns per instant for 1R, 0.2 µs for 1R1T and 1 µs for
/// 3R (K ≈ 5), and most combinations are rejected within a few instants; the limits keep
/// the exact search within about a second on 2 cores (measured in `docs/synthesis.md`).
pub fn exact_limit(class: Class) -> usize {
    match class {
        Class::R1 => 2_000_000,
        Class::R1T1 => 200_000,
        Class::R3 => 20_000,
    }
}

/// Largest number of combinations searched exhaustively when the combination to beat
/// closes ([`improve`]): every combination is then dropped at the first instant where it
/// fails the closure or the margin to beat, which the tightest instants, taken first,
/// mostly show within a few. 2 000 000 for every class: figure-eight's 636 480 3R
/// combinations at K = 5 took 3.7 s on 2 cores, where the same pool's unclosed K = 4
/// searches took 1.6–2.1 s for 40 000–53 000 (each combination kept to many instants).
pub const EXACT_LIMIT_CLOSED: usize = 2_000_000;

/// The chosen combination.
#[derive(Clone, Debug)]
pub struct Combination {
    /// Candidate index per band, into the pool's lists.
    pub genome: Vec<usize>,
    /// Its fitness over the N samples (the paper's figures).
    pub at_samples: Fitness,
    /// Its fitness at [`OVERSAMPLE`]× the sample density (what acceptance judges).
    pub oversampled: Fitness,
    /// Whether every combination was searched (else: the GA and a local search).
    pub exact: bool,
}

/// Choose one candidate per band: the GA over the samples, then, over the oversampled
/// instants, the exact search when the pool holds at most [`exact_limit`] combinations or a
/// local search from the GA's best. `on_generation(g)` is called after each GA
/// generation; returning `false` stops early (cancellation), and then no further search runs.
pub fn combine(
    pool: &Pool,
    settings: GaSettings,
    on_generation: &mut dyn FnMut(usize) -> bool,
) -> Combination {
    let mut stopped = false;
    let ga = ga::run(pool, settings, &mut |g| {
        let go = on_generation(g);
        stopped |= !go;
        go
    });
    if stopped {
        let oversampled = pool.fitness(&ga.genome, Density::Oversampled);
        return Combination {
            at_samples: pool.fitness(&ga.genome, Density::Samples),
            genome: ga.genome,
            oversampled,
            exact: false,
        };
    }
    improve(pool, ga.genome, None)
}

/// The best combination reachable from `start` over the oversampled instants: the exact
/// search when the pool holds at most [`exact_limit`] combinations (or
/// [`EXACT_LIMIT_CLOSED`], when the combination to beat closes), else a local search from
/// `start` (no GA: for a start that is already good, such as a combination that closed
/// with one band more). With `need`, the exact search looks only for combinations that
/// beat it (dropping every other at the first instant that shows it below) and returns
/// `start` when none does; the local search climbs from `start` as without it.
pub fn improve(pool: &Pool, start: Vec<usize>, need: Option<&Fitness>) -> Combination {
    let start_fit = pool.fitness(&start, Density::Oversampled);
    let bound = match need {
        Some(n) if n.cmp_better(&start_fit) == Ordering::Greater => n.clone(),
        _ => start_fit.clone(),
    };
    let limit = if bound.closes(EPSILON) {
        EXACT_LIMIT_CLOSED.max(exact_limit(pool.class))
    } else {
        exact_limit(pool.class)
    };
    let exact = pool.combinations() <= limit;
    let t0 = std::time::Instant::now();
    let (genome, oversampled) = if exact {
        exact_search(pool, start, start_fit, &bound)
    } else {
        local_search(pool, start, start_fit)
    };
    tracing::debug!(
        combinations = pool.combinations(),
        exact,
        seconds = t0.elapsed().as_secs_f64(),
        robust_vali_time = oversampled.robust_vali_time,
        "combination searched"
    );
    Combination {
        at_samples: pool.fitness(&genome, Density::Samples),
        genome,
        oversampled,
        exact,
    }
}

/// Every combination, over the oversampled instants: the best one that beats `bound` (the
/// first in index order among equals, whatever the thread count), or `start` if none does.
/// Combinations are split by their first band's candidate; each part prunes against the
/// best it has found, beginning with `bound`.
fn exact_search(
    pool: &Pool,
    start: Vec<usize>,
    start_fit: Fitness,
    bound: &Fitness,
) -> (Vec<usize>, Fitness) {
    let step = 1;
    let start_order = pool.tightest_first(&start, step);
    let sizes: Vec<usize> = pool.bands.iter().map(Vec::len).collect();
    let best = (0..sizes[0])
        .into_par_iter()
        .map(|first| {
            let mut best: Option<(Vec<usize>, Fitness)> = None;
            let mut g = vec![0; sizes.len()];
            g[0] = first;
            // The instant that ruled out the last combination is asked first of the next,
            // which differs from it in one band (mostly the last): the bands it keeps
            // mostly fail there again. The order changes which instants are evaluated,
            // never a combination's verdict (its figures are the same in any order).
            let mut order = start_order.clone();
            loop {
                let bound = best.as_ref().map_or(bound, |b| &b.1);
                let m = order.len();
                match pool.fitness_beating(&g, step, order.iter().copied(), m, Some(bound)) {
                    Ok(f) => {
                        if f.cmp_better(bound) == Ordering::Greater {
                            best = Some((g.clone(), f));
                        }
                    }
                    Err(pos) => order.swap(0, pos),
                }
                // Next combination with this first candidate (odometer over bands 1..).
                let mut b = sizes.len() - 1;
                loop {
                    if b == 0 {
                        return best;
                    }
                    g[b] += 1;
                    if g[b] < sizes[b] {
                        break;
                    }
                    g[b] = 0;
                    b -= 1;
                }
            }
        })
        .collect::<Vec<_>>()
        .into_iter()
        .flatten()
        .fold(None::<(Vec<usize>, Fitness)>, |acc, c| match acc {
            Some(a) if c.1.cmp_better(&a.1) != Ordering::Greater => Some(a),
            _ => Some(c),
        });
    match best {
        Some(b) if b.1.cmp_better(&start_fit) == Ordering::Greater => b,
        _ => (start, start_fit),
    }
}

/// Most bands a move of [`local_search`] changes at once.
const MOVE_BANDS: usize = 2;

/// Steepest ascent over the oversampled instants: replace one band's candidate by the one
/// that improves the fitness most; when no single replacement improves, two bands'
/// candidates at once ([`MOVE_BANDS`]), going back to single replacements after every
/// move, until no move improves. A closed combination is judged by its margin, the
/// closure distance at its tightest instant, and one band alone often cannot lower that
/// instant without raising another, where two can. (Three at once was measured and not
/// kept: docs/synthesis.md, "Measured after the margin search".)
fn local_search(pool: &Pool, mut g: Vec<usize>, mut fit: Fitness) -> (Vec<usize>, Fitness) {
    let step = 1;
    'improve: loop {
        let order = pool.tightest_first(&g, step);
        for size in 1..=MOVE_BANDS.min(g.len()) {
            if let Some((h, f)) = best_move(pool, &g, &fit, &order, &moves(pool, &g, size)) {
                (g, fit) = (h, f);
                continue 'improve;
            }
        }
        return (g, fit);
    }
}

/// A change of a genome: (band, candidate) replacements.
type Move = Vec<(usize, usize)>;

/// Every replacement of `size` bands' candidates at once (each by another candidate).
fn moves(pool: &Pool, g: &[usize], size: usize) -> Vec<Move> {
    let mut out = Vec::new();
    let mut partial: Move = Vec::with_capacity(size);
    extend_moves(pool, g, size, 0, &mut partial, &mut out);
    out
}

/// [`moves`]' recursion: bands from `from` on complete `partial`.
fn extend_moves(
    pool: &Pool,
    g: &[usize],
    size: usize,
    from: usize,
    partial: &mut Move,
    out: &mut Vec<Move>,
) {
    if partial.len() == size {
        out.push(partial.clone());
        return;
    }
    for b in from..g.len() {
        for j in (0..pool.bands[b].len()).filter(|&j| j != g[b]) {
            partial.push((b, j));
            extend_moves(pool, g, size, b + 1, partial, out);
            partial.pop();
        }
    }
}

/// The move that improves `g`'s fitness `fit` most (the first in `moves` among equals,
/// whatever the thread count), if any does.
fn best_move(
    pool: &Pool,
    g: &[usize],
    fit: &Fitness,
    order: &[usize],
    moves: &[Move],
) -> Option<(Vec<usize>, Fitness)> {
    moves
        .par_iter()
        .filter_map(|m| {
            let mut h = g.to_vec();
            for &(b, j) in m {
                h[b] = j;
            }
            pool.fitness_beating(&h, 1, order.iter().copied(), order.len(), Some(fit))
                .ok()
                .filter(|f| f.cmp_better(fit) == Ordering::Greater)
                .map(|f| (h, f))
        })
        .collect::<Vec<_>>()
        .into_iter()
        .fold(None::<(Vec<usize>, Fitness)>, |acc, c| match acc {
            Some(a) if c.1.cmp_better(&a.1) != Ordering::Greater => Some(a),
            _ => Some(c),
        })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::synth::ga::tests::{pool_data, OwnedCandidate};
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    fn f(v: f64, rv: f64, m: f64, rm: f64) -> Fitness {
        Fitness {
            vali_time: v,
            robust_vali_time: rv,
            max_dist: m,
            robust_max_dist: rm,
        }
    }

    fn pool_of(class: Class, data: &[Vec<OwnedCandidate>]) -> Pool<'_> {
        Pool {
            class,
            bands: data
                .iter()
                .map(|b| {
                    b.iter()
                        .map(|(n, r)| (n.as_slice(), r.as_slice()))
                        .collect()
                })
                .collect(),
        }
    }

    /// A seeded random 1R1T pool: `bands` × `m` candidates, `n` samples; ñ are unit 2-D
    /// vectors wandering smoothly, robust flags off on a random stretch per candidate.
    fn random_pool(seed: u64, bands: usize, m: usize, n: usize) -> Vec<Vec<OwnedCandidate>> {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        (0..bands)
            .map(|_| {
                (0..m)
                    .map(|_| {
                        let (a0, rate) = (rng.random_range(0.0..6.3), rng.random_range(-9.0..9.0));
                        let (off0, off_len) = (rng.random_range(0..n), rng.random_range(0..n / 3));
                        let e = n * OVERSAMPLE;
                        let nt = (0..e)
                            .map(|i| {
                                let a = a0 + rate * i as f64 / e as f64;
                                Some([a.cos(), a.sin(), 0.0])
                            })
                            .collect();
                        let rob = (0..e)
                            .map(|i| (i / OVERSAMPLE + n - off0) % n >= off_len)
                            .collect();
                        (nt, rob)
                    })
                    .collect()
            })
            .collect()
    }

    /// Every combination of a pool, in index order.
    fn all_genomes(pool: &Pool) -> Vec<Vec<usize>> {
        let mut out = vec![vec![]];
        for b in &pool.bands {
            out = out
                .into_iter()
                .flat_map(|g| {
                    (0..b.len()).map(move |j| {
                        let mut h = g.clone();
                        h.push(j);
                        h
                    })
                })
                .collect();
        }
        out
    }

    /// Guards the lexicographic fitness order: robust validity first, then validity, then
    /// the lower (more negative) robust maximum distance, then the paper's one.
    #[test]
    fn fitness_ordering_is_robust_first_and_lexicographic() {
        use Ordering::*;
        assert_eq!(
            f(0.9, 0.9, 0.5, 9.0).cmp_better(&f(1.0, 0.8, -1.0, -1.0)),
            Greater
        );
        assert_eq!(
            f(1.0, 1.0, -0.1, -0.1).cmp_better(&f(0.9, 1.0, -1.0, -1.0)),
            Greater
        );
        assert_eq!(
            f(1.0, 1.0, 5.0, -0.3).cmp_better(&f(1.0, 1.0, -1.0, -0.2)),
            Greater
        );
        assert_eq!(
            f(1.0, 1.0, -0.5, -1.0).cmp_better(&f(1.0, 1.0, -0.4, -1.0)),
            Greater
        );
        assert_eq!(
            f(1.0, 1.0, -1.0, -0.5).cmp_better(&f(1.0, 1.0, -1.0, -0.5)),
            Equal
        );
        assert!(f(1.0, 1.0, -0.03, -0.03).closes(EPSILON));
        assert!(!f(1.0, 1.0, -0.03, -0.03).closes(0.05));
        assert!(!f(1.0, 0.99, -1.0, -1.0).closes(EPSILON));
    }

    /// Guards the pruned evaluation: a genome is dropped only when its full fitness ranks
    /// below the bound, and what it returns otherwise is the full fitness.
    #[test]
    fn pruned_fitness_drops_only_genomes_below_the_bound() {
        let data = random_pool(3, 3, 5, 30);
        let pool = pool_of(Class::R1T1, &data);
        let genomes = all_genomes(&pool);
        let m = pool.entries();
        let mut dropped = 0;
        for bound_g in genomes.iter().step_by(7) {
            let bound = pool.fitness(bound_g, Density::Oversampled);
            let order = pool.tightest_first(bound_g, 1);
            for g in &genomes {
                let full = pool.fitness(g, Density::Oversampled);
                match pool
                    .fitness_beating(g, 1, order.iter().copied(), m, Some(&bound))
                    .ok()
                {
                    None => {
                        dropped += 1;
                        assert_eq!(full.cmp_better(&bound), Ordering::Less, "{g:?}");
                    }
                    Some(got) => assert_eq!(got, full, "{g:?}"),
                }
            }
        }
        assert!(dropped > 0, "nothing was pruned: the test proves nothing");
    }

    /// Guards the exact search: on seeded random 1R1T pools it finds the best combination a
    /// brute-force evaluation of every combination finds (the first in index order among
    /// equals), with one thread or two, and the summary at the oversampled density agrees
    /// with the fitness.
    #[test]
    fn exact_search_finds_the_best_combination() {
        for seed in 0..4 {
            let data = random_pool(seed, 3, 6, 40);
            let pool = pool_of(Class::R1T1, &data);
            let mut want: Option<(Vec<usize>, Fitness)> = None;
            for g in all_genomes(&pool) {
                let fit = pool.fitness(&g, Density::Oversampled);
                if want
                    .as_ref()
                    .is_none_or(|w| fit.cmp_better(&w.1) == Ordering::Greater)
                {
                    want = Some((g, fit));
                }
            }
            let want = want.unwrap();
            let start = vec![0; 3];
            let start_fit = pool.fitness(&start, Density::Oversampled);
            for threads in [1, 2] {
                let tp = rayon::ThreadPoolBuilder::new()
                    .num_threads(threads)
                    .build()
                    .unwrap();
                let got = tp
                    .install(|| exact_search(&pool, start.clone(), start_fit.clone(), &start_fit));
                assert_eq!(got.1, want.1, "seed {seed}, {threads} threads");
                if want.1 != start_fit {
                    assert_eq!(got.0, want.0, "seed {seed}, {threads} threads");
                }
            }
            let s = pool.summary(&want.0, Density::Oversampled);
            assert_eq!(Fitness::of(&s), want.1);
        }
    }

    /// Guards `improve`'s `need`: it comes back with the pool's best combination when that
    /// beats the need, and with its start when nothing does.
    #[test]
    fn improve_finds_what_beats_the_need_or_returns_its_start() {
        for seed in 0..4 {
            let data = random_pool(seed, 3, 6, 40);
            let pool = pool_of(Class::R1T1, &data);
            let best = all_genomes(&pool)
                .iter()
                .map(|g| pool.fitness(g, Density::Oversampled))
                .max_by(|a, b| a.cmp_better(b))
                .unwrap();
            let start = vec![0; 3];
            let just_below = Fitness {
                robust_max_dist: best.robust_max_dist + 1e-9,
                ..best.clone()
            };
            let c = improve(&pool, start.clone(), Some(&just_below));
            assert_eq!(c.oversampled, best, "seed {seed}");
            let just_above = Fitness {
                robust_max_dist: best.robust_max_dist - 1e-9,
                ..best.clone()
            };
            let c = improve(&pool, start.clone(), Some(&just_above));
            assert_eq!(c.genome, start, "seed {seed}");
        }
    }

    /// Guards the local search: its result is at least as good as its start and no
    /// replacement of one band's candidate, or of two bands' at once, improves it; and
    /// the pairs matter: on some of these pools the single replacements alone stop where a
    /// pair improves.
    #[test]
    fn local_search_ends_where_no_single_or_pair_replacement_improves() {
        let mut pairs_mattered = 0;
        for seed in 0..12 {
            let data = random_pool(seed, 4, 5, 40);
            let pool = pool_of(Class::R1T1, &data);
            let start = vec![1, 2, 3, 4];
            let start_fit = pool.fitness(&start, Density::Oversampled);
            let (g, fit) = local_search(&pool, start.clone(), start_fit.clone());
            assert_ne!(fit.cmp_better(&start_fit), Ordering::Less);
            assert_eq!(fit, pool.fitness(&g, Density::Oversampled));
            for m in moves(&pool, &g, 1).iter().chain(&moves(&pool, &g, 2)) {
                let mut h = g.clone();
                for &(b, j) in m {
                    h[b] = j;
                }
                let fh = pool.fitness(&h, Density::Oversampled);
                assert_ne!(
                    fh.cmp_better(&fit),
                    Ordering::Greater,
                    "seed {seed}: {h:?} beats {g:?}"
                );
            }
            // Single replacements alone, from the same start.
            let (mut g1, mut f1) = (start, start_fit);
            while let Some((h, f)) = best_move(
                &pool,
                &g1,
                &f1,
                &pool.tightest_first(&g1, 1),
                &moves(&pool, &g1, 1),
            ) {
                (g1, f1) = (h, f);
            }
            let order = pool.tightest_first(&g1, 1);
            if best_move(&pool, &g1, &f1, &order, &moves(&pool, &g1, 2)).is_some() {
                pairs_mattered += 1;
            }
        }
        assert!(
            pairs_mattered > 0,
            "no pool where a pair improves a single-move optimum"
        );
    }

    /// Guards the oversampled judgement: a combination closed at every sample but not at an
    /// instant between two samples closes at the sample density and not at 4×, which is the
    /// density `combine` reports as `oversampled` and acceptance reads.
    #[test]
    fn a_gap_between_samples_fails_the_oversampled_check() {
        let e = 20 * OVERSAMPLE;
        let push = |s: f64| (vec![Some([s, 0.0, 0.0]); e], vec![true; e]);
        let mut weak = push(-1.0);
        weak.1[OVERSAMPLE * 7 + 2] = false;
        let data = vec![vec![push(1.0)], vec![weak]];
        let pool = pool_of(Class::R1, &data);
        let at_samples = pool.fitness(&[0, 0], Density::Samples);
        let over = pool.fitness(&[0, 0], Density::Oversampled);
        assert!(at_samples.closes(EPSILON), "{at_samples:?}");
        assert!(!over.closes(EPSILON), "{over:?}");
        assert_eq!(over.robust_vali_time, 1.0 - 1.0 / e as f64);
        let settings = GaSettings {
            population: 2,
            generations: 1,
            seed: 1,
        };
        let c = combine(&pool, settings, &mut |_| true);
        assert_eq!((c.at_samples, c.oversampled), (at_samples, over));
    }

    /// Guards `combine` on the GA's test pool: it finds the single combination that closes
    /// robustly at every instant, searching exhaustively (30 combinations).
    #[test]
    fn combine_finds_the_robust_combination() {
        let data = pool_data();
        let pool = pool_of(Class::R1, &data);
        let settings = GaSettings {
            population: 4,
            generations: 2,
            seed: 5,
        };
        let c = combine(&pool, settings, &mut |_| true);
        assert!(c.exact);
        assert_eq!((c.genome[0], c.genome[2]), (4, 3));
        assert!(c.oversampled.closes(EPSILON) && c.at_samples.closes(EPSILON));
    }
}
