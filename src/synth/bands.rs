//! The height bands: their layout, the candidate problem of each, which bands a
//! combination uses when some are left empty, what a 1R gap-filling band is asked for, and
//! what the 3R margin push asks of a chosen contact.
//!
//! Owns the band layout (band k is centred at s(k)·([`BAND_HEIGHT`] + [`BAND_GAP`]) with
//! s = 0, +1, −1, +2, −2, …, so that K bands are a prefix of K + 1 bands and growing K only
//! solves the new band), the skipping of empty bands (K counts curve pairs), the focus of
//! a gap-filling band (see `focus_of`) and a refinement (`refine_focus`), and the push's
//! asks (`push_asks`). It does not solve candidates (see `candidate`) or
//! run the search (see `search`).

use std::sync::Arc;

use super::candidate::{Candidate, OVERSAMPLE};
use super::closure::{nearest_facet_3d, Class, Facet, NormalCone};
use super::energy::{PairProblem, Push, Stage, W_CLOSURE, W_ROBUST};
use super::pose::PoseTrack;

/// Height of each band, model units. Default 1.0 (10 mm at the default scale): room for a
/// contact curve with some vertical waviness and for the swept cross-section.
pub const BAND_HEIGHT: f64 = 1.0;
/// Gap between bands, model units, unless `--band-gap` asks for another (see
/// [`SynthOptions::band_gap`](super::SynthOptions::band_gap)). Default 0.5 (5 mm): keeps
/// neighbouring swept contact surfaces apart, but leaves no room for a follower plate and
/// rim between two driver bands (see `docs/synthesis.md`, "Printable layouts").
pub const BAND_GAP: f64 = 0.5;
/// How many bands beyond K may be laid out when some are left empty (no candidate passed
/// the checks), so that K still counts curve pairs. Default 2: spherical-four-bar's band 5
/// had no usable candidate at d_x = 7.5 and 9, which used to end the search at that d_x
/// although band 6 had 9; skipping it, the default search accepts it at K = 6, d_x = 7.5.
pub const MAX_EMPTY_BANDS: usize = 2;

/// Widening of a gap-filling band's focus (see `focus_of`), as a share of the period on
/// each side of a gap. Default 0.01 (3.6 samples of 360): the arm must build up before the
/// gap, not at its edge.
pub const FOCUS_WIDEN: f64 = 0.01;
/// Widening of a refinement's focus (see `refine_focus`), as a share of the period on each
/// side of a gap. Default 0.03: with 0.01 (as a gap-filling band) half-turn-2to1 at K = 3,
/// d_x = 6 stayed at robust 0.948 (seed 2) and 0.998 (seed 4) at 4×; with 0.03 seed 4
/// closed and seed 2 reached 0.974.
pub const REFINE_WIDEN: f64 = 0.03;
/// How near a facet's plane a contact's ñ must lie to count as on the facet, for the 3R
/// margin push (see `push_asks`). 1e-9: the plane passes through three of the points
/// exactly, up to rounding; a point off it by more is inside the hull.
pub const ON_FACET: f64 = 1e-9;
/// Robust closure (share of samples) the previous combination must reach before the next 1R
/// band becomes a gap-filling band. Default 0.5: below it the gaps are too wide for the one
/// candidate a band contributes; aiming every band at the gaps (threshold 0) left 0–1 of 30
/// candidates usable in quarter-turn-dwell's bands 3 and 4.
pub const FOCUS_MIN_ROBUST: f64 = 0.5;

/// Height of each band of a 1R motion with dwells (see [`BandLayout::for_motion`]), model
/// units. Default 2.0 (20 mm at the default scale).
pub const DWELL_BAND_HEIGHT: f64 = 2.0;
/// Share of the period the follower must stand still for a 1R motion to count as one with
/// dwells. Default 0.02 (7 of 360 samples): a stop, not a turning point.
pub const DWELL_MIN_SHARE: f64 = 0.02;

/// The heights of the bands: band k is centred at s(k)·(height + gap), s = 0, +1, −1, +2, …
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BandLayout {
    /// Height of each band, model units.
    pub height: f64,
    /// Gap between neighbouring bands, model units.
    pub gap: f64,
}

impl Default for BandLayout {
    fn default() -> Self {
        Self {
            height: BAND_HEIGHT,
            gap: BAND_GAP,
        }
    }
}

/// Whether a motion gets the dwell treatment: a 1R motion whose follower stands still over
/// at least [`DWELL_MIN_SHARE`] of the period.
pub fn dwell_1r(class: Class, poses: &PoseTrack) -> bool {
    class == Class::R1 && poses.still_share() >= DWELL_MIN_SHARE
}

impl BandLayout {
    /// The layout for a motion with bands `gap` apart: taller bands ([`DWELL_BAND_HEIGHT`])
    /// for a 1R motion with dwells ([`dwell_1r`]), else [`BAND_HEIGHT`].
    pub fn for_motion(class: Class, poses: &PoseTrack, gap: f64) -> Self {
        let height = if dwell_1r(class, poses) {
            DWELL_BAND_HEIGHT
        } else {
            BAND_HEIGHT
        };
        Self { height, gap }
    }

    /// Band k's [z_min, z_max].
    pub fn band(&self, k: usize) -> (f64, f64) {
        let s = if k == 0 {
            0.0
        } else if k % 2 == 1 {
            k.div_ceil(2) as f64
        } else {
            -((k / 2) as f64)
        };
        let c = s * (self.height + self.gap);
        (c - 0.5 * self.height, c + 0.5 * self.height)
    }
}

/// The candidate problem of band `b`.
pub fn band_problem(
    class: Class,
    poses: &Arc<PoseTrack>,
    dx: f64,
    layout: BandLayout,
    b: usize,
    cone: NormalCone,
) -> PairProblem {
    PairProblem {
        class,
        poses: poses.clone(),
        dx,
        band: layout.band(b),
        vary: None,
        w_closure: W_CLOSURE,
        w_robust: W_ROBUST,
        cone,
        focus: None,
        push: None,
        stage: Stage::Full,
        axis_room: None,
        rim: None,
    }
}

/// Per sample i, whether the chosen 1R contacts lack a robust contact pushing in + and in −
/// at some instant of the 4× check from tᵢ up to tᵢ₊₁, widened by `widen` of the period on
/// each side; `None` when nothing is missing.
fn gaps(chosen: &[Candidate], n: usize, widen: f64) -> Option<Vec<[bool; 2]>> {
    let drives = |c: &Candidate, e: usize, s: f64| {
        c.robust.get(e).copied().unwrap_or(false)
            && c.ntilde
                .get(e)
                .copied()
                .flatten()
                .is_some_and(|v| v[0] * s > 0.0)
    };
    let lack: Vec<[bool; 2]> = (0..n)
        .map(|i| {
            [1.0, -1.0].map(|s| {
                (OVERSAMPLE * i..OVERSAMPLE * (i + 1))
                    .any(|e| !chosen.iter().any(|c| drives(c, e, s)))
            })
        })
        .collect();
    if lack.iter().all(|l| !l[0] && !l[1]) {
        return None;
    }
    let w = ((widen * n as f64).round() as usize).min(n / 2);
    Some(
        (0..n)
            .map(|i| {
                (0..=2 * w).fold([false; 2], |acc, d| {
                    let l = lack[(i + n + d - w) % n];
                    [acc[0] || l[0], acc[1] || l[1]]
                })
            })
            .collect(),
    )
}

/// Per-sample torque signs that a gap-filling 1R band is asked for (see
/// [`W_FOCUS`](super::energy::W_FOCUS)): the samples where the chosen candidates lack a
/// robust contact of one sign (see `gaps`), widened by [`FOCUS_WIDEN`] of the period on each
/// side. Where both signs are missing, even-indexed candidates are asked for + and
/// odd-indexed for −. Returns the (even, odd) arrays, or `None` when nothing is missing.
pub(super) fn focus_of(chosen: &[Candidate], n: usize) -> Option<Focus> {
    let gaps = gaps(chosen, n, FOCUS_WIDEN)?;
    let (mut even, mut odd) = (vec![0.0; n], vec![0.0; n]);
    for (i, g) in gaps.iter().enumerate() {
        (even[i], odd[i]) = match g {
            [true, true] => (1.0, -1.0),
            [true, false] => (1.0, 1.0),
            [false, true] => (-1.0, -1.0),
            [false, false] => (0.0, 0.0),
        };
    }
    Some((Arc::new(even), Arc::new(odd)))
}

/// Per chosen 1R contact, the torque signs a refinement of it is asked for (see
/// [`W_FOCUS`](super::energy::W_FOCUS)): at the samples where the combination lacks a robust
/// contact of some sign (see `gaps`, widened by [`REFINE_WIDEN`] of the period on each
/// side), the contacts that push in that sign there without the arm to count are asked for
/// it. `None` for a contact asked for nothing; an empty list when nothing is missing.
pub(super) fn refine_focus(chosen: &[Candidate], n: usize) -> Vec<Option<Arc<Vec<f64>>>> {
    let Some(gaps) = gaps(chosen, n, REFINE_WIDEN) else {
        return Vec::new();
    };
    let sign = |c: &Candidate, i: usize| c.ntilde[OVERSAMPLE * i].map_or(0.0, |v| v[0].signum());
    chosen
        .iter()
        .map(|c| {
            let ask: Vec<f64> = (0..n)
                .map(|i| match sign(c, i) {
                    s if s > 0.0 && gaps[i][0] => 1.0,
                    s if s < 0.0 && gaps[i][1] => -1.0,
                    _ => 0.0,
                })
                .collect();
            ask.iter().any(|a| *a != 0.0).then(|| Arc::new(ask))
        })
        .collect()
}

/// Per chosen 3R contact, what the margin push asks of it (see
/// [`Push`](super::energy::Push)): at every instant of the 4× check where the hull of the
/// chosen contacts' ñ holds the origin less than `goal` deep, the contacts on the facet
/// nearest the origin (within [`ON_FACET`] of its plane) are asked to move out along its
/// normal, at the sample nearest that instant (the thinnest instant's facet when several
/// map to one sample). `None` for a contact asked for nothing. Instants where the origin
/// is not inside (not closed) ask nothing: the push widens a margin, it does not close.
pub(super) fn push_asks(
    chosen: &[Candidate],
    n: usize,
    goal: f64,
    weight: f64,
) -> Vec<Option<Arc<Push>>> {
    let mut asked: Vec<Vec<Option<Facet>>> = vec![vec![None; n]; chosen.len()];
    let entries = chosen.first().map_or(0, |c| c.ntilde.len());
    let (mut pts, mut who) = (Vec::new(), Vec::new());
    for e in 0..entries {
        pts.clear();
        who.clear();
        for (j, c) in chosen.iter().enumerate() {
            if let (Some(v), true) = (c.ntilde[e], c.robust[e]) {
                pts.push(v);
                who.push(j);
            }
        }
        let Some(f) = nearest_facet_3d(&pts).filter(|f| f.depth < goal) else {
            continue;
        };
        let i = (e + OVERSAMPLE / 2) / OVERSAMPLE % n;
        for (v, &j) in pts.iter().zip(&who) {
            let out = v[0] * f.u[0] + v[1] * f.u[1] + v[2] * f.u[2];
            let on = out >= f.depth - ON_FACET;
            if on && asked[j][i].is_none_or(|a| f.depth < a.depth) {
                asked[j][i] = Some(f);
            }
        }
    }
    asked
        .into_iter()
        .map(|a| {
            a.iter().any(Option::is_some).then(|| {
                Arc::new(Push {
                    goal,
                    weight,
                    dirs: a.iter().map(|f| f.map(|f| f.u)).collect(),
                })
            })
        })
        .collect()
}

/// A gap-filling band's per-sample torque signs for its even- and odd-indexed candidates.
pub(super) type Focus = (Arc<Vec<f64>>, Arc<Vec<f64>>);

/// The usable candidates of the first `k` bands that have any (fewer when there are not
/// enough), and the usable counts of every band laid out up to the last one used (0 for a
/// band left empty), as shown in the attempt's summary.
pub(super) fn used_bands(bands: &[Vec<Candidate>], k: usize) -> (Vec<Vec<&Candidate>>, Vec<usize>) {
    let all: Vec<Vec<&Candidate>> = bands
        .iter()
        .map(|b| b.iter().filter(|c| c.valid).collect())
        .collect();
    let mut shown = 0;
    let mut valid = Vec::new();
    for (i, v) in all.iter().enumerate() {
        if valid.len() == k {
            break;
        }
        shown = i + 1;
        if !v.is_empty() {
            valid.push(v.clone());
        }
    }
    let counts = all[..shown].iter().map(|v| v.len()).collect();
    (valid, counts)
}

/// Bands with at least one usable candidate.
pub(super) fn usable_bands(bands: &[Vec<Candidate>]) -> usize {
    bands.iter().filter(|b| b.iter().any(|c| c.valid)).count()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 1R candidate for `focus_of` tests: per sample, ñ sign (+1/−1) and robustness (the
    /// same at the instants between samples).
    fn contact_1r(signs: &[(f64, bool)]) -> Candidate {
        Candidate {
            band: 0,
            slab: [-0.5, 0.5],
            index: 0,
            x: Vec::new(),
            f: 0.0,
            status: crate::synth::optimizer::SolveStatus::Converged,
            valid: true,
            reason: None,
            residual_deg: 0.0,
            ntilde: signs
                .iter()
                .flat_map(|&(s, _)| [Some([s, 0.0, 0.0]); OVERSAMPLE])
                .collect(),
            robust: signs.iter().flat_map(|&(_, r)| [r; OVERSAMPLE]).collect(),
            evals: 0,
            vary: None,
        }
    }

    /// A 3R candidate for `push_asks` tests: the same ñ at every instant of `n` samples,
    /// except that it vanishes at the instants nearest the samples in `lost`.
    fn contact_3r(v: [f64; 3], n: usize, lost: std::ops::Range<usize>) -> Candidate {
        let mut c = contact_1r(&vec![(1.0, true); n]);
        c.ntilde = (0..n * OVERSAMPLE)
            .map(|e| (!lost.contains(&((e + OVERSAMPLE / 2) / OVERSAMPLE % n))).then_some(v))
            .collect();
        c
    }

    /// Guards what the 3R margin push asks: where the hull's nearest facet is shallower
    /// than the goal, its contacts (and only they) are asked to move out along its normal
    /// at every sample; a goal the hull already reaches asks nothing; where a contact is
    /// lost the hull has no interior and nothing is asked there.
    #[test]
    fn push_asks_the_contacts_of_the_nearest_facet_where_it_is_shallow() {
        let n = 8;
        let chosen = [
            contact_3r([1.0, 0.0, -0.1], n, 0..0),
            contact_3r([-0.5, 0.8, -0.1], n, 0..0),
            contact_3r([-0.5, -0.8, -0.1], n, 0..0),
            contact_3r([0.0, 0.0, 1.0], n, 3..5),
        ];
        let asks = push_asks(&chosen, n, 0.2, 50.0);
        for (j, a) in asks.iter().enumerate().take(3) {
            let a = a
                .as_ref()
                .unwrap_or_else(|| panic!("contact {j} is on the facet"));
            assert_eq!((a.goal, a.weight), (0.2, 50.0));
            for (i, d) in a.dirs.iter().enumerate() {
                if (3..5).contains(&i) {
                    assert_eq!(*d, None, "sample {i}: no interior, nothing to widen");
                } else {
                    let u = d.unwrap_or_else(|| panic!("contact {j}, sample {i}"));
                    assert!((u[2] + 1.0).abs() < 1e-12, "{u:?}");
                }
            }
        }
        assert!(asks[3].is_none(), "the apex is not on the nearest facet");
        assert!(push_asks(&chosen, n, 0.05, 50.0)
            .iter()
            .all(Option::is_none));
    }

    /// Guards the skipping of empty bands: K counts bands with usable candidates, an empty
    /// band is passed over (and shown as 0), and too few usable bands are reported as such.
    #[test]
    fn empty_bands_are_skipped_and_k_counts_curve_pairs() {
        let band = |usable: usize| -> Vec<Candidate> {
            (0..3)
                .map(|i| {
                    let mut c = contact_1r(&[(1.0, true)]);
                    c.valid = i < usable;
                    c
                })
                .collect()
        };
        let bands = vec![band(2), band(0), band(3), band(1)];
        let lens = |v: &Vec<Vec<&Candidate>>| v.iter().map(|b| b.len()).collect::<Vec<_>>();
        let (v, counts) = used_bands(&bands, 2);
        assert_eq!((lens(&v), counts), (vec![2, 3], vec![2, 0, 3]));
        let (v, counts) = used_bands(&bands, 3);
        assert_eq!((lens(&v), counts), (vec![2, 3, 1], vec![2, 0, 3, 1]));
        let (v, counts) = used_bands(&bands, 4);
        assert_eq!((lens(&v), counts), (vec![2, 3, 1], vec![2, 0, 3, 1]));
        assert_eq!(usable_bands(&bands), 3);
    }

    /// Guards the gap-filling focus: a band is asked for + where no chosen contact drives
    /// robustly in +, for − where none drives in −, for either sign by candidate parity where
    /// both are missing, widened by `FOCUS_WIDEN` of the period; nothing is asked when
    /// robust closure holds everywhere.
    #[test]
    fn gap_filling_focus_asks_for_the_missing_sign() {
        let n = 200;
        let w = (FOCUS_WIDEN * n as f64).round() as usize;
        assert_eq!(w, 2);
        // Contact a: robust + everywhere except 50..60; contact b: robust − everywhere except
        // 55..70 (non-robust + there).
        let a: Vec<_> = (0..n).map(|i| (1.0, !(50..60).contains(&i))).collect();
        let b: Vec<_> = (0..n)
            .map(|i| {
                if (55..70).contains(&i) {
                    (1.0, false)
                } else {
                    (-1.0, true)
                }
            })
            .collect();
        let (even, odd) = focus_of(&[contact_1r(&a), contact_1r(&b)], n).expect("gaps");
        for i in 0..n {
            let lack_p = (50 - w..60 + w).contains(&i);
            let lack_m = (55 - w..70 + w).contains(&i);
            let (e, o) = match (lack_p, lack_m) {
                (true, true) => (1.0, -1.0),
                (true, false) => (1.0, 1.0),
                (false, true) => (-1.0, -1.0),
                (false, false) => (0.0, 0.0),
            };
            assert_eq!((even[i], odd[i]), (e, o), "sample {i}");
        }
        let full: Vec<_> = (0..n).map(|_| (1.0, true)).collect();
        let neg: Vec<_> = (0..n).map(|_| (-1.0, true)).collect();
        assert!(focus_of(&[contact_1r(&full), contact_1r(&neg)], n).is_none());
    }

    /// Guards the refinement focus: a contact is asked for a sign only where the combination
    /// lacks a robust contact of that sign (widened by `REFINE_WIDEN`) and it already pushes
    /// that way; a contact pushing the other way there is not asked; a gap between two
    /// samples (at an instant of the 4× check only) counts; nothing is asked when closure
    /// holds at every instant.
    #[test]
    fn refinement_asks_contacts_for_the_sign_they_push_where_it_lacks() {
        let n = 200;
        let w = (REFINE_WIDEN * n as f64).round() as usize;
        assert_eq!(w, 6);
        // a: robust + everywhere; b: robust − except 100..110, where it pushes − weakly;
        // c: robust + everywhere, pushing − nowhere.
        let a: Vec<_> = (0..n).map(|_| (1.0, true)).collect();
        let b: Vec<_> = (0..n).map(|i| (-1.0, !(100..110).contains(&i))).collect();
        let asks = refine_focus(&[contact_1r(&a), contact_1r(&b), contact_1r(&a)], n);
        assert_eq!(asks.len(), 3);
        assert!(asks[0].is_none() && asks[2].is_none(), "{asks:?}");
        let ask_b = asks[1].as_ref().expect("b is asked");
        for (i, v) in ask_b.iter().enumerate() {
            let want = if (100 - w..110 + w).contains(&i) {
                -1.0
            } else {
                0.0
            };
            assert_eq!(*v, want, "sample {i}");
        }
        // Closed at every sample but not at one instant between samples 30 and 31.
        let mut c = contact_1r(&b.iter().map(|_| (-1.0, true)).collect::<Vec<_>>());
        c.robust[OVERSAMPLE * 30 + 1] = false;
        let asks = refine_focus(&[contact_1r(&a), c.clone()], n);
        let ask = asks[1]
            .as_ref()
            .expect("the instant between samples counts");
        assert_eq!(ask[30], -1.0);
        assert_eq!(ask[30 + w + 1], 0.0);
        c.robust[OVERSAMPLE * 30 + 1] = true;
        assert!(refine_focus(&[contact_1r(&a), c], n).is_empty());
    }

    /// Guards the band layout: bands are disjoint, equal height, and K bands are a prefix of
    /// K + 1 bands.
    #[test]
    fn bands_are_disjoint_and_nested() {
        let dwell = BandLayout {
            height: DWELL_BAND_HEIGHT,
            gap: BAND_GAP,
        };
        for l in [BandLayout::default(), dwell] {
            let b: Vec<_> = (0..7).map(|k| l.band(k)).collect();
            for i in 0..7 {
                assert!((b[i].1 - b[i].0 - l.height).abs() < 1e-12);
                for j in i + 1..7 {
                    assert!(b[i].1 + l.gap - 1e-12 <= b[j].0 || b[j].1 + l.gap - 1e-12 <= b[i].0);
                }
            }
            assert_eq!(b[0], (-0.5 * l.height, 0.5 * l.height));
        }
    }

    /// Guards that the layout uses the gap it is given, for plain and dwell layouts: band k
    /// is centred at s(k)·(height + gap), neighbouring bands are exactly `gap` apart, and the
    /// default layout is the one with [`BAND_GAP`].
    #[test]
    fn band_layout_uses_the_gap() {
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("data/motions");
        for (name, height) in [
            ("half-turn-2to1", BAND_HEIGHT),
            ("quarter-turn-dwell", DWELL_BAND_HEIGHT),
        ] {
            let motion =
                crate::motion::Motion::from_file(&dir.join(format!("{name}.toml"))).unwrap();
            let poses = PoseTrack::from_motion(&motion, 360);
            let class: Class = motion.class().into();
            assert_eq!(
                BandLayout::for_motion(class, &poses, BAND_GAP),
                BandLayout {
                    height,
                    gap: BAND_GAP
                }
            );
            for gap in [0.0, 1.5, 5.0] {
                let l = BandLayout::for_motion(class, &poses, gap);
                assert_eq!((l.height, l.gap), (height, gap), "{name}");
                // Bands 0, 1, 3 are stacked upwards, 0, 2, 4 downwards.
                for (lo, hi) in [(0, 1), (1, 3), (2, 0), (4, 2)] {
                    let (a, b) = (l.band(lo), l.band(hi));
                    assert!(
                        (b.0 - a.1 - gap).abs() < 1e-12,
                        "{name} gap {gap}: {a:?} {b:?}"
                    );
                }
                let s3 = 2.0;
                assert!((l.band(3).0 + l.band(3).1 - 2.0 * s3 * (height + gap)).abs() < 1e-12);
            }
        }
        assert_eq!(BandLayout::default().gap, BAND_GAP);
    }

    /// Guards the dwell detection: of the example motions only quarter-turn-dwell (four
    /// dwells, 40 % of the period) stands still and gets the dwell layout; no sample of the
    /// others is still (pick-and-place's pauses are spline keys, not a standstill).
    #[test]
    fn only_the_dwell_example_gets_the_dwell_layout() {
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("data/motions");
        let mut seen = 0;
        for e in std::fs::read_dir(dir).unwrap() {
            let path = e.unwrap().path();
            let motion = crate::motion::Motion::from_file(&path).unwrap();
            let poses = PoseTrack::from_motion(&motion, 360);
            let class: Class = motion.class().into();
            let layout = BandLayout::for_motion(class, &poses, BAND_GAP);
            if motion.name() == "quarter-turn-dwell" {
                let share = poses.still_share();
                assert!((share - 0.4).abs() < 0.02, "{share}");
                assert_eq!(layout.height, DWELL_BAND_HEIGHT);
            } else {
                assert_eq!(layout, BandLayout::default(), "{}", motion.name());
                assert_eq!(poses.still_share(), 0.0, "{}", motion.name());
            }
            seen += 1;
        }
        assert_eq!(seen, 9);
    }
}
