//! Where a quasi-static load leaves the follower, given how far it is free to move.
//!
//! Owns [`Load`] and the follower law under each, driven forward or in reverse:
//! - **drag** ([`drag`]), friction that opposes motion, the default. A dragged follower
//!   does not move unless a contact pushes it, so at each driver angle it stays where the
//!   previous angle left it, clamped into the free interval the parts allow there. Driven
//!   forward it ends up lagging on one side of its play, in reverse on the other: the two
//!   laws differ by the play.
//! - **a constant torque** larger than the joint's friction (a weight on an arm whose
//!   joint is not vertical, a return spring preloaded far beyond the stroke): the follower
//!   rests against the side of its free interval the torque pushes it to, whichever way
//!   the driver turns.
//! - **a spring** towards a rest angle (friction neglected beside it): the follower sits
//!   at the point of its free interval nearest the rest angle.
//!
//! A 1R1T follower both turns and slides, so its play is a region of the plane of its two
//! deviations ([`FreeRegion`], outlined by eight rays) and a drag moves it in that plane
//! ([`drag_plane`]); a torque or a spring about its axis would leave its height to
//! friction alone, which is not modelled, so it takes the drag only.
//!
//! The module works on deviations from the target law and knows no geometry.

/// A quasi-static load on the follower.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Load {
    /// Friction opposing motion.
    Drag,
    /// A constant torque about the joint axis in this sense (+1 counter-clockwise about
    /// +z, −1 clockwise), larger than the friction.
    Torque(f64),
    /// A spring pulling the follower towards this angle (degrees, unwrapped like the
    /// target).
    Spring(f64),
}

impl Load {
    /// How `prediction.json` and the command line name it.
    pub fn label(&self) -> String {
        match self {
            Load::Drag => "drag".to_string(),
            Load::Torque(s) if *s > 0.0 => "torque+".to_string(),
            Load::Torque(_) => "torque-".to_string(),
            Load::Spring(deg) => format!("spring:{deg}"),
        }
    }

    /// Parse `drag`, `torque+`, `torque-` or `spring:DEG`.
    pub fn parse(s: &str) -> Result<Load, String> {
        match s {
            "drag" => Ok(Load::Drag),
            "torque+" => Ok(Load::Torque(1.0)),
            "torque-" => Ok(Load::Torque(-1.0)),
            _ => match s.strip_prefix("spring:").map(str::parse::<f64>) {
                Some(Ok(deg)) if deg.is_finite() => Ok(Load::Spring(deg)),
                _ => Err(format!(
                    "`{s}` is not a load: drag, torque+, torque- or spring:DEG (the spring's \
                     rest angle of the follower, degrees)"
                )),
            },
        }
    }
}

/// Deviation of the follower from the target (rad) at each sample under `load`.
///
/// `target` is the target angle at each sample (used by the spring); the rest as
/// [`drag`].
pub fn under(
    load: Load,
    target: &[f64],
    step: &[f64],
    plus: &[f64],
    minus: &[f64],
    forward: bool,
) -> Vec<f64> {
    match load {
        Load::Drag => drag(step, plus, minus, forward),
        Load::Torque(sense) => (0..plus.len())
            .map(|i| if sense > 0.0 { plus[i] } else { -minus[i] })
            .collect(),
        Load::Spring(deg) => (0..plus.len())
            .map(|i| (deg.to_radians() - target[i]).clamp(-minus[i], plus[i]))
            .collect(),
    }
}

/// Deviation of the follower from the target (rad) at each sample, under drag.
///
/// `step[i]` is the target's change from sample i to i + 1 (the last wraps to sample 0 of
/// the next period); `plus[i]` and `minus[i]` bound the deviation at sample i to
/// [−minus, plus]. The sweep runs two periods from the target pose and returns the second,
/// so the start does not show. `forward` runs the driver forward (i increasing).
pub fn drag(step: &[f64], plus: &[f64], minus: &[f64], forward: bool) -> Vec<f64> {
    let n = step.len();
    assert!(
        plus.len() == n && minus.len() == n,
        "one free interval per sample"
    );
    let mut out = vec![0.0; n];
    if n == 0 {
        return out;
    }
    let mut e = 0.0f64;
    for k in 0..2 * n {
        let i = if forward {
            if k > 0 {
                // The follower stays put while the target moves on.
                e -= step[(k - 1) % n];
            }
            k % n
        } else {
            let i = n - 1 - k % n;
            if k > 0 {
                e += step[i];
            }
            i
        };
        e = e.clamp(-minus[i], plus[i]);
        if k >= n {
            out[i] = e;
        }
    }
    out
}

/// Rays that outline a 1R1T follower's free region: a turn, a screw, a slide and the
/// other screw, each way, 45° apart in the plane of its deviations ([`FreeRegion`]).
pub const RAYS: usize = 8;

/// Where a 1R1T follower is free to be at one driver angle, around its design pose, in the
/// plane of its deviations (x: the turn times a lever, mm; y: the slide, mm): the star
/// polygon whose corner k lies on the ray at k·45° from +x, `reach[k]` from the design
/// pose.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FreeRegion {
    /// How far each ray is free, mm (≥ 0).
    pub reach: [f64; RAYS],
}

impl FreeRegion {
    /// Corner `k` (taken modulo [`RAYS`]).
    fn corner(&self, k: usize) -> [f64; 2] {
        // The rays' directions, exact on the axes.
        const DIRS: [[f64; 2]; RAYS] = {
            let c = std::f64::consts::FRAC_1_SQRT_2;
            [
                [1.0, 0.0],
                [c, c],
                [0.0, 1.0],
                [-c, c],
                [-1.0, 0.0],
                [-c, -c],
                [0.0, -1.0],
                [c, -c],
            ]
        };
        let [x, y] = DIRS[k % RAYS];
        [self.reach[k % RAYS] * x, self.reach[k % RAYS] * y]
    }

    /// Whether `e` is in the region: in the triangle of the design pose and the two
    /// corners of its sector.
    fn holds(&self, e: [f64; 2]) -> bool {
        if e == [0.0, 0.0] {
            return true;
        }
        let sector = std::f64::consts::TAU / RAYS as f64;
        let k =
            ((e[1].atan2(e[0]).rem_euclid(std::f64::consts::TAU) / sector) as usize).min(RAYS - 1);
        let (a, b) = (self.corner(k), self.corner(k + 1));
        let area = a[0] * b[1] - a[1] * b[0];
        // The origin is on the left of the corners' edge a → b; so must `e` be.
        let side = (b[0] - a[0]) * (e[1] - a[1]) - (b[1] - a[1]) * (e[0] - a[0]);
        area > 0.0 && side >= 0.0
    }

    /// The point of the region nearest `e`: `e` itself when the region holds it, else the
    /// nearest point of its outline.
    pub fn clamp(&self, e: [f64; 2]) -> [f64; 2] {
        if self.holds(e) {
            return e;
        }
        let mut best = ([0.0, 0.0], f64::INFINITY);
        for k in 0..RAYS {
            let (a, b) = (self.corner(k), self.corner(k + 1));
            let ab = [b[0] - a[0], b[1] - a[1]];
            let len2 = ab[0] * ab[0] + ab[1] * ab[1];
            let s = if len2 > 0.0 {
                (((e[0] - a[0]) * ab[0] + (e[1] - a[1]) * ab[1]) / len2).clamp(0.0, 1.0)
            } else {
                0.0
            };
            let p = [a[0] + s * ab[0], a[1] + s * ab[1]];
            let d2 = (e[0] - p[0]).powi(2) + (e[1] - p[1]).powi(2);
            if d2 < best.1 {
                best = (p, d2);
            }
        }
        best.0
    }
}

/// Deviation of a dragged 1R1T follower from the target at each sample, in the plane of
/// [`FreeRegion`] (mm, mm): [`drag`] with both joint coordinates at once. The follower
/// stays where the previous angle left it while the target moves on, and a region that no
/// longer holds it pushes it to its nearest point (friction at the contacts opposing
/// their motion, the turn weighed by the region's lever).
pub fn drag_plane(step: &[[f64; 2]], regions: &[FreeRegion], forward: bool) -> Vec<[f64; 2]> {
    let n = step.len();
    assert!(regions.len() == n, "one free region per sample");
    let mut out = vec![[0.0; 2]; n];
    let mut e = [0.0f64; 2];
    for k in 0..2 * n {
        let i = if forward {
            if k > 0 {
                let s = step[(k - 1) % n];
                e = [e[0] - s[0], e[1] - s[1]];
            }
            k % n
        } else {
            let i = n - 1 - k % n;
            if k > 0 {
                e = [e[0] + step[i][0], e[1] + step[i][1]];
            }
            i
        };
        e = regions[i].clamp(e);
        if k >= n {
            out[i] = e;
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Guards the sides a dragged follower rests on: with a target that only advances and
    /// the same play everywhere, driving forward leaves the follower lagging by the whole
    /// free interval behind it (−minus), and reverse leaves it ahead by `plus`; the two laws
    /// differ by the play.
    #[test]
    fn a_dragged_follower_lags_by_its_play() {
        let n = 100;
        let step = vec![0.01; n];
        let plus = vec![0.003; n];
        let minus = vec![0.002; n];
        let f = drag(&step, &plus, &minus, true);
        let r = drag(&step, &plus, &minus, false);
        for i in 0..n {
            assert!((f[i] + 0.002).abs() < 1e-15, "{}", f[i]);
            assert!((r[i] - 0.003).abs() < 1e-15, "{}", r[i]);
        }
    }

    /// Guards the other loads: a torque puts the follower against the side it pushes to
    /// whichever way the driver turns, and a spring puts it at the point of its free
    /// interval nearest the rest angle (inside the interval: at the rest angle itself).
    #[test]
    fn a_torque_or_a_spring_sets_the_side_whatever_the_direction() {
        let target = [0.0, 0.1, 0.2, 0.3];
        let step = [0.1, 0.1, 0.1, -0.3];
        let plus = [0.05; 4];
        let minus = [0.02; 4];
        for forward in [true, false] {
            let t = under(Load::Torque(1.0), &target, &step, &plus, &minus, forward);
            assert_eq!(t, vec![0.05; 4]);
            let t = under(Load::Torque(-1.0), &target, &step, &plus, &minus, forward);
            assert_eq!(t, vec![-0.02; 4]);
            let rest = 0.21f64;
            let s = under(
                Load::Spring(rest.to_degrees()),
                &target,
                &step,
                &plus,
                &minus,
                forward,
            );
            assert_eq!(s[0], 0.05);
            assert_eq!(s[1], 0.05);
            assert!((s[2] - 0.01).abs() < 1e-12, "{}", s[2]);
            assert_eq!(s[3], -0.02);
        }
    }

    /// Guards the load's spelling on the command line and in the file, and the error for
    /// a bad one (whole text).
    #[test]
    fn loads_parse_and_print_back() {
        for s in ["drag", "torque+", "torque-", "spring:12.5"] {
            assert_eq!(Load::parse(s).unwrap().label(), s);
        }
        assert_eq!(
            Load::parse("spring:x").unwrap_err(),
            "`spring:x` is not a load: drag, torque+, torque- or spring:DEG (the spring's \
             rest angle of the follower, degrees)"
        );
    }

    /// Guards the free region's outline: a point inside stays where it is, a point beyond a
    /// corner goes to the corner, one beyond an edge to its foot on the edge, and a region
    /// with no room takes everything to the design pose.
    #[test]
    fn a_free_region_clamps_to_its_nearest_point() {
        let c = std::f64::consts::FRAC_1_SQRT_2;
        // A square of half-side 1 drawn by its corners (rays 1, 3, 5, 7 at √2) and the
        // middles of its sides (rays 0, 2, 4, 6 at 1).
        let mut reach = [1.0; RAYS];
        for k in [1, 3, 5, 7] {
            reach[k] = 2f64.sqrt();
        }
        let square = FreeRegion { reach };
        let near =
            |a: [f64; 2], b: [f64; 2]| (a[0] - b[0]).abs() < 1e-12 && (a[1] - b[1]).abs() < 1e-12;
        assert_eq!(square.clamp([0.3, -0.9]), [0.3, -0.9]);
        assert_eq!(square.clamp([0.0, 0.0]), [0.0, 0.0]);
        assert!(
            near(square.clamp([3.0, 2.5]), [1.0, 1.0]),
            "{:?}",
            square.clamp([3.0, 2.5])
        );
        assert!(near(square.clamp([-4.0, 0.5]), [-1.0, 0.5]));
        assert!(near(square.clamp([0.2, -1.5]), [0.2, -1.0]));
        // A region free only along +x (the other rays blocked): a thin spike.
        let mut reach = [0.0; RAYS];
        reach[0] = 0.5;
        let spike = FreeRegion { reach };
        assert!(near(spike.clamp([2.0, 0.0]), [0.5, 0.0]));
        assert!(near(spike.clamp([0.3, 1.0]), [0.3, 0.0]));
        assert!(near(spike.clamp([-1.0, c]), [0.0, 0.0]));
        let none = FreeRegion { reach: [0.0; RAYS] };
        assert_eq!(none.clamp([0.1, 0.2]), [0.0, 0.0]);
    }

    /// Guards the drag in the plane: a target that only turns leaves the follower lagging
    /// by the region's reach behind it, as the 1-D drag does, and its height untouched; a
    /// target that screws leaves it in the corner of the region behind its motion; the
    /// forward and reverse laws lie on opposite sides.
    #[test]
    fn a_dragged_follower_lags_in_the_plane_of_its_play() {
        let n = 50;
        let c = std::f64::consts::FRAC_1_SQRT_2;
        let reach = [0.3, 0.2, 0.4, 0.2, 0.25, 0.2, 0.4, 0.2];
        let regions = vec![FreeRegion { reach }; n];
        // Regular: the corners behind and ahead of a 45° screw hold it.
        let octagon = vec![FreeRegion { reach: [0.2; RAYS] }; n];
        let turn = vec![[0.05, 0.0]; n];
        let f = drag_plane(&turn, &regions, true);
        let r = drag_plane(&turn, &regions, false);
        for i in 0..n {
            assert_eq!(f[i], [-0.25, 0.0]);
            assert_eq!(r[i], [0.3, 0.0]);
        }
        // The 1-D drag agrees on the turn alone.
        let one = drag(&[0.05; 50], &[0.3; 50], &[0.25; 50], true);
        assert_eq!(one[7], f[7][0]);
        let screw = vec![[0.05 * c, 0.05 * c]; n];
        let f = drag_plane(&screw, &octagon, true);
        let r = drag_plane(&screw, &octagon, false);
        for i in 0..n {
            let (want_f, want_r) = ([-0.2 * c, -0.2 * c], [0.2 * c, 0.2 * c]);
            assert!(
                (f[i][0] - want_f[0]).abs() < 1e-12 && (f[i][1] - want_f[1]).abs() < 1e-12,
                "{:?}",
                f[i]
            );
            assert!(
                (r[i][0] - want_r[0]).abs() < 1e-12 && (r[i][1] - want_r[1]).abs() < 1e-12,
                "{:?}",
                r[i]
            );
        }
    }

    /// Guards the dwell: where the target stops, the follower stays where it was as long
    /// as the free interval holds it, and a free interval that narrows pushes it along.
    #[test]
    fn a_follower_stays_put_in_a_dwell_until_pushed() {
        // Rises for 3 samples, dwells for 3, then the play narrows to 0.
        let step = [0.1, 0.1, 0.1, 0.0, 0.0, 0.0, -0.3];
        let plus = [0.05, 0.05, 0.05, 0.05, 0.05, 0.0, 0.05];
        let minus = [0.05, 0.05, 0.05, 0.05, 0.05, 0.0, 0.05];
        let f = drag(&step, &plus, &minus, true);
        assert_eq!(f[3], -0.05);
        assert_eq!(f[4], -0.05);
        assert_eq!(f[5], 0.0);
        assert_eq!(f[6], 0.0);
    }
}
