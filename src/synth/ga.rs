//! The genetic algorithm of stage B (paper §5.2.3): one candidate index per height band.
//!
//! Owns the genome, the generational loop (truncation selection, one-point crossover,
//! per-gene mutation, elitism), a fitness cache, and parallel fitness evaluation
//! (deterministic: results are collected in population order). Fitness is that of
//! `combine` over the N samples. It does not solve candidates, search combinations
//! exhaustively or decide acceptance (see `combine` and `search`).

use std::cmp::Ordering;
use std::collections::HashMap;

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;

use super::combine::{Density, Fitness, Pool};

/// Population size. Default 48: with truncation to 12 parents this keeps enough diversity
/// for K ≤ 6 bands of 30 candidates, and 48 × 300 fitness evaluations (most of them cache
/// hits once the population converges) cost well under a second for K ≤ 6.
pub const POPULATION: usize = 48;
/// Fraction of the population kept as parents (truncation selection). Default 0.25.
pub const TRUNCATION: f64 = 0.25;
/// Per-gene mutation probability, as a multiple of 1/K. Default 1.0 (one gene per child on
/// average: the classic "bit-flip" rate for an index encoding).
pub const MUTATION_PER_GENOME: f64 = 1.0;
/// Generations. Default 300 (supplementary notes).
pub const GENERATIONS: usize = 300;
/// Stop early after this many generations without improvement of the best. Default 100.
pub const STALL_GENERATIONS: usize = 100;

/// Result of a GA run.
#[derive(Clone, Debug)]
pub struct GaResult {
    /// Best genome (candidate index per band, into the pool's lists).
    pub genome: Vec<usize>,
    /// Its fitness.
    pub fitness: Fitness,
    /// Generations run.
    pub generations: usize,
    /// Distinct genomes evaluated.
    pub evaluated: usize,
}

/// GA settings.
#[derive(Clone, Copy, Debug)]
pub struct GaSettings {
    /// Population size.
    pub population: usize,
    /// Generations.
    pub generations: usize,
    /// Seed.
    pub seed: u64,
}

/// Run the GA. `on_generation(g)` is called after each generation; returning `false`
/// stops early (cancellation).
pub fn run(pool: &Pool, s: GaSettings, on_generation: &mut dyn FnMut(usize) -> bool) -> GaResult {
    let k = pool.bands.len();
    let sizes: Vec<usize> = pool.bands.iter().map(|b| b.len()).collect();
    let mut rng = ChaCha8Rng::seed_from_u64(s.seed);
    let mut cache: HashMap<Vec<usize>, Fitness> = HashMap::new();
    let mut pop: Vec<Vec<usize>> = (0..s.population.max(2))
        .map(|_| sizes.iter().map(|&m| rng.random_range(0..m)).collect())
        .collect();
    let n_parents = ((s.population as f64 * TRUNCATION).ceil() as usize).clamp(1, s.population);
    let p_mut = (MUTATION_PER_GENOME / k as f64).min(1.0);
    let mut best: Option<(Vec<usize>, Fitness)> = None;
    let mut stall = 0;
    let mut gens = 0;
    for gen in 0..s.generations.max(1) {
        gens = gen + 1;
        // Evaluate new genomes in parallel (order preserved → deterministic).
        let mut fresh: Vec<Vec<usize>> = pop
            .iter()
            .filter(|g| !cache.contains_key(*g))
            .cloned()
            .collect();
        fresh.sort();
        fresh.dedup();
        let fits: Vec<Fitness> = fresh
            .par_iter()
            .map(|g| pool.fitness(g, Density::Samples))
            .collect();
        for (g, f) in fresh.into_iter().zip(fits) {
            cache.insert(g, f);
        }
        // Rank (stable sort on fitness, then genome for full determinism).
        pop.sort_by(|a, b| cache[b].cmp_better(&cache[a]).then(a.cmp(b)));
        let improved = match &best {
            None => true,
            Some((_, bf)) => cache[&pop[0]].cmp_better(bf) == Ordering::Greater,
        };
        if improved {
            best = Some((pop[0].clone(), cache[&pop[0]].clone()));
            stall = 0;
        } else {
            stall += 1;
        }
        if !on_generation(gen) || stall >= STALL_GENERATIONS {
            break;
        }
        // Next generation: parents survive (elitism), children fill the rest.
        let parents: Vec<Vec<usize>> = pop[..n_parents].to_vec();
        let mut next = parents.clone();
        while next.len() < s.population {
            let a = &parents[rng.random_range(0..parents.len())];
            let b = &parents[rng.random_range(0..parents.len())];
            let cut = if k > 1 { rng.random_range(1..k) } else { 0 };
            let mut child: Vec<usize> = a[..cut].iter().chain(b[cut..].iter()).cloned().collect();
            for (gi, gene) in child.iter_mut().enumerate() {
                if rng.random_bool(p_mut) {
                    *gene = rng.random_range(0..sizes[gi]);
                }
            }
            next.push(child);
        }
        pop = next;
    }
    let (genome, fitness) = best.expect("at least one generation ran");
    GaResult {
        genome,
        fitness,
        generations: gens,
        evaluated: cache.len(),
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::synth::closure::Class;

    /// One candidate's views (ñ, robust) at every instant.
    pub(crate) type OwnedCandidate = (Vec<Option<[f64; 3]>>, Vec<bool>);

    /// A 1R pool of 3 bands × 10 candidates (20 samples) where only one combination closes
    /// robustly at every sample.
    pub(crate) fn pool_data() -> Vec<Vec<OwnedCandidate>> {
        let n = 20;
        let over = crate::synth::candidate::OVERSAMPLE;
        let mut bands = Vec::new();
        for band in 0..3 {
            let mut cands = Vec::new();
            for c in 0..10 {
                // Candidate c of band 0 pushes + everywhere; band 1's candidate 7 pushes −
                // everywhere; band 2's candidate 3 is robust everywhere with sign −.
                let sign = match (band, c) {
                    (0, 4) => 1.0,
                    (1, 7) | (2, 3) => -1.0,
                    _ => {
                        if c % 2 == 0 {
                            1.0
                        } else {
                            -1.0
                        }
                    }
                };
                let nt = (0..n * over)
                    .map(|e| {
                        let i = e / over;
                        let s = if (band, c) == (0, 4)
                            || (band, c) == (1, 7)
                            || (band, c) == (2, 3)
                            || i < n / 2
                        {
                            sign
                        } else {
                            -sign
                        };
                        Some([s, 0.0, 0.0])
                    })
                    .collect();
                let rob = (0..n * over)
                    .map(|e| (band, c) == (0, 4) || (band, c) == (2, 3) || (e / over) % 3 == 0)
                    .collect();
                cands.push((nt, rob));
            }
            bands.push(cands);
        }
        bands
    }

    /// Guards that the GA finds the single robust combination and that two runs with the
    /// same seed agree (rayon evaluates fitness in parallel).
    #[test]
    fn ga_finds_robust_combination_deterministically() {
        let data = pool_data();
        let pool = Pool {
            class: Class::R1,
            bands: data
                .iter()
                .map(|b| {
                    b.iter()
                        .map(|(n, r)| (n.as_slice(), r.as_slice()))
                        .collect()
                })
                .collect(),
        };
        let s = GaSettings {
            population: 24,
            generations: 200,
            seed: 5,
        };
        let a = run(&pool, s, &mut |_| true);
        let b = run(&pool, s, &mut |_| true);
        assert_eq!(a.genome, b.genome);
        assert_eq!(a.fitness, b.fitness);
        assert_eq!(a.fitness.vali_time, 1.0);
        assert_eq!(a.fitness.robust_vali_time, 1.0);
        assert_eq!(a.genome[0], 4);
        assert_eq!(a.genome[2], 3);
    }
}
