//! Where a quasi-static load leaves the follower, given how far it is free to turn.
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
