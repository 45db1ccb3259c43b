//! Where the carve leaves a driver band in pieces, found before anything is meshed.
//!
//! Owns [`band_segments`]: a band is sampled on a grid in its own coordinates (frame index
//! along the curve × depth u × width v of its section); a sample is material when the rims'
//! swept volume, grown by half the clearance, leaves at least [`BRIDGE_MM`] of it there.
//! Samples are connected to their six grid neighbours (the loop of frames closes), and each
//! connected set is one piece of the carved band: a rim that passes through the band at an
//! instant when it is not in contact there cuts it crosswise. The driver's struts are then
//! planned per piece (`parts`), so that every piece is joined to the hub.
//!
//! It does not plan struts and does not decide what a piece is for.

use rayon::prelude::*;

use crate::geometry::sdf::Vec3;
use crate::geometry::sweep::{Frame, Section, Sweep};

/// Spacing of the samples across a band's section, mm: under a third of the narrowest cut
/// a rim makes (its width, 3.2 mm), so no cut falls between two samples.
const SECTION_STEP_MM: f64 = 0.8;
/// The samples keep this far inside the section's outline, mm.
const SECTION_INSET_MM: f64 = 0.4;
/// How far inside the carve a sample must lie to count as material, mm: half the sliver
/// the driver's mesh leaves out ([`super::dims::SLIVER_MM`]), so a chain of such samples
/// has about a sliver's thickness of material around it and thinner material does not
/// join two samples.
pub const BRIDGE_MM: f64 = 0.5 * super::dims::SLIVER_MM;

/// One piece of a carved band.
#[derive(Clone, Debug, PartialEq)]
pub struct Segment {
    /// Frames (indices into the band's frames) holding material of this piece, ascending.
    pub frames: Vec<usize>,
    /// Per frame of `frames`, the piece's sample deepest behind the contact surface (lowest
    /// u, then nearest the section's middle): where a strut can take root.
    pub roots: Vec<Vec3>,
    /// Every sample of the piece (for marking it joined).
    pub samples: Vec<Vec3>,
}

/// The pieces of `band` that survive a carve whose swept distance at a point is `carve(p)`
/// (already reduced by half the clearance; material survives where it is ≥ [`BRIDGE_MM`]),
/// largest first. A band the carve leaves whole is one segment holding every frame.
pub fn band_segments(band: &Sweep, carve: &(dyn Fn(Vec3) -> f64 + Sync)) -> Vec<Segment> {
    let frames = band.frames();
    let n = frames.len();
    let (u_min, u_max, half_width) = match band.section() {
        Section::RoundedRect {
            u_min,
            u_max,
            half_width,
            ..
        } => (u_min, u_max, half_width),
        Section::HalfEllipse { a, b } => (-a, 0.0, b),
    };
    let us = samples_across(u_min, u_max);
    let vs = samples_across(-half_width, half_width);
    let (nu, nv) = (us.len(), vs.len());
    let per_frame = nu * nv;
    let axes: Vec<(Vec3, Vec3)> = (0..n).map(|i| section_axes(frames, i)).collect();
    let point = |i: usize, a: usize, b: usize| {
        let (u, v) = axes[i];
        frames[i].o + u * us[a] + v * vs[b]
    };
    let solid: Vec<bool> = (0..n * per_frame)
        .into_par_iter()
        .map(|c| {
            let (i, r) = (c / per_frame, c % per_frame);
            carve(point(i, r / nv, r % nv)) >= BRIDGE_MM
        })
        .collect();
    // Connected sets by flood fill over the six neighbours.
    let mut label = vec![usize::MAX; solid.len()];
    let mut sizes = Vec::new();
    for start in 0..solid.len() {
        if !solid[start] || label[start] != usize::MAX {
            continue;
        }
        let id = sizes.len();
        let mut stack = vec![start];
        label[start] = id;
        let mut size = 0;
        while let Some(c) = stack.pop() {
            size += 1;
            let (i, r) = (c / per_frame, c % per_frame);
            let (a, b) = (r / nv, r % nv);
            let mut next = vec![
                ((i + 1) % n) * per_frame + r,
                ((i + n - 1) % n) * per_frame + r,
            ];
            if a > 0 {
                next.push(c - nv);
            }
            if a + 1 < nu {
                next.push(c + nv);
            }
            if b > 0 {
                next.push(c - 1);
            }
            if b + 1 < nv {
                next.push(c + 1);
            }
            for m in next {
                if solid[m] && label[m] == usize::MAX {
                    label[m] = id;
                    stack.push(m);
                }
            }
        }
        sizes.push(size);
    }
    let mut segments: Vec<Segment> = (0..sizes.len())
        .map(|_| Segment {
            frames: Vec::new(),
            roots: Vec::new(),
            samples: Vec::new(),
        })
        .collect();
    let mid = 0.5 * (nv as f64 - 1.0);
    for i in 0..n {
        // Per piece present in this frame: its deepest, most central sample.
        let mut best: Vec<Option<(usize, f64, usize, usize)>> = vec![None; sizes.len()];
        for a in 0..nu {
            for b in 0..nv {
                let c = i * per_frame + a * nv + b;
                let id = label[c];
                if id == usize::MAX {
                    continue;
                }
                segments[id].samples.push(point(i, a, b));
                let key = (a, (b as f64 - mid).abs());
                if best[id].is_none_or(|(ba, bd, _, _)| (key.0, key.1) < (ba, bd)) {
                    best[id] = Some((a, key.1, a, b));
                }
            }
        }
        for (id, b) in best.into_iter().enumerate() {
            if let Some((_, _, a, b)) = b {
                segments[id].frames.push(i);
                segments[id].roots.push(point(i, a, b));
            }
        }
    }
    let mut order: Vec<usize> = (0..segments.len()).collect();
    order.sort_by(|&x, &y| sizes[y].cmp(&sizes[x]));
    order.into_iter().map(|k| segments[k].clone()).collect()
}

/// A loop's section axes at frame `i`: u (the frame's u orthogonalized against the
/// tangent, which the central difference of the neighbouring frames gives) and v = t × u.
pub fn section_axes(frames: &[Frame], i: usize) -> (Vec3, Vec3) {
    let n = frames.len();
    let t = (frames[(i + 1) % n].o - frames[(i + n - 1) % n].o).normalize();
    let u = (frames[i].u - t * frames[i].u.dot(&t)).normalize();
    (u, t.cross(&u))
}

/// Sample positions across `[lo, hi]`, inset by [`SECTION_INSET_MM`], at most
/// [`SECTION_STEP_MM`] apart (at least one, in the middle).
fn samples_across(lo: f64, hi: f64) -> Vec<f64> {
    let (a, b) = (lo + SECTION_INSET_MM, hi - SECTION_INSET_MM);
    if b <= a {
        return vec![0.5 * (lo + hi)];
    }
    let k = ((b - a) / SECTION_STEP_MM).ceil() as usize;
    (0..=k).map(|j| a + (b - a) * j as f64 / k as f64).collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::build::shapes::BAND;

    /// A band on a circle of radius 30 mm in the xy plane, normals outward.
    fn ring() -> Sweep {
        let frames = (0..240)
            .map(|i| {
                let a = std::f64::consts::TAU * i as f64 / 240.0;
                let d = Vec3::new(a.cos(), a.sin(), 0.0);
                Frame { o: d * 30.0, u: d }
            })
            .collect();
        Sweep::new(frames, BAND).unwrap()
    }

    /// Guards the piece count: an uncut band is one segment with every frame; two slots
    /// through the whole section leave two pieces, each holding exactly the frames between
    /// the slots, with roots in the deepest row (behind the contact surface).
    #[test]
    fn slots_through_a_band_leave_the_pieces_between_them() {
        let band = ring();
        let whole = band_segments(&band, &|_| 10.0);
        assert_eq!(whole.len(), 1);
        assert_eq!(whole[0].frames.len(), 240);
        // Slots 4 mm wide through the whole section, around the +x and the +y axis.
        let carve = |p: Vec3| {
            let in_slot = (p.y.abs() < 2.0 && p.x > 0.0) || (p.x.abs() < 2.0 && p.y > 0.0);
            if in_slot {
                -1.0
            } else {
                5.0
            }
        };
        let pieces = band_segments(&band, &carve);
        assert_eq!(
            pieces.len(),
            2,
            "{:?}",
            pieces.iter().map(|s| s.frames.len()).collect::<Vec<_>>()
        );
        // The larger piece spans the 270° arc, the smaller the 90° arc (less the slots).
        let angle = |i: usize| 360.0 * i as f64 / 240.0;
        assert!(pieces[0]
            .frames
            .iter()
            .all(|&i| angle(i) > 90.0 && angle(i) < 360.0));
        assert!(pieces[1]
            .frames
            .iter()
            .all(|&i| angle(i) > 0.0 && angle(i) < 90.0));
        assert!(pieces[0].frames.len() > 2 * pieces[1].frames.len());
        for s in &pieces {
            assert_eq!(s.frames.len(), s.roots.len());
            for r in &s.roots {
                let depth = 30.0 - r.xy().norm();
                let deepest = -(-crate::build::dims::BAND_DEPTH_MM + SECTION_INSET_MM);
                assert!((depth - deepest).abs() < 1e-6, "root depth {depth}");
            }
        }
    }

    /// Guards determinism and a thin bridge: material thinner than [`BRIDGE_MM`] does not
    /// join two pieces.
    #[test]
    fn a_bridge_thinner_than_the_limit_does_not_join() {
        let band = ring();
        // A slot around +x that leaves material only where the carve says 0.3 mm.
        let carve = |p: Vec3| {
            if p.y.abs() < 2.0 && p.x > 0.0 {
                0.3
            } else {
                5.0
            }
        };
        let a = band_segments(&band, &carve);
        let b = band_segments(&band, &carve);
        assert_eq!(a, b);
        // One slot in a ring leaves one piece (an arc), not joined across the slot.
        assert_eq!(a.len(), 1);
        assert!(a[0].frames.len() < 240);
        assert!(!a[0].frames.contains(&0));
    }
}
