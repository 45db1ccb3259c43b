//! Where a quasi-static load leaves the follower, given how far it is free to turn.
//!
//! Owns [`drag`]: the follower law under a drag that opposes motion (friction in the joint,
//! the default load), driven forward or in reverse. A dragged follower does not move
//! unless a contact pushes it, so at each driver angle it stays where the previous angle
//! left it, clamped into the free interval the parts allow there. Driven forward it ends
//! up lagging on one side of its play, in reverse on the other: the two laws differ by the
//! play. The module works on deviations from the target law and knows no geometry.

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
