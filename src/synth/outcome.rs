//! How a synthesis run ends: [`Outcome`].
//!
//! Owns the three ends of a search: a design that meets the acceptance criteria, a search
//! that ran out of (K, d_x) without one, and a search stopped by the user. The last two are
//! results, not errors: they carry the best design reached (marked `solve.partial`), which a
//! user inspects or keeps. Errors are requests that cannot be served (`error::SynthError`).
//! It does not decide acceptance (see `search`).

use super::mechanism::Mechanism;

/// How a synthesis run ended, with the design it ended with.
#[derive(Clone, Debug)]
pub enum Outcome {
    /// A design that meets the acceptance criteria (`solve.accepted`).
    Accepted(Mechanism),
    /// No tried (K, d_x) gave an accepted design.
    Infeasible {
        /// Best figures reached, the worst samples and what to try.
        reason: String,
        /// The best design reached (not accepted, marked partial); `None` when no
        /// combination could be scored (too few bands with usable candidates).
        best: Option<Mechanism>,
    },
    /// Stopped by the user (Ctrl-C).
    Cancelled {
        /// The best design so far (not accepted, marked partial), if any.
        best: Option<Mechanism>,
    },
}

impl Outcome {
    /// The accepted design, or the best one reached.
    pub fn mechanism(&self) -> Option<&Mechanism> {
        match self {
            Outcome::Accepted(m) => Some(m),
            Outcome::Infeasible { best, .. } | Outcome::Cancelled { best } => best.as_ref(),
        }
    }

    /// [`Self::mechanism`], owned.
    pub fn into_mechanism(self) -> Option<Mechanism> {
        match self {
            Outcome::Accepted(m) => Some(m),
            Outcome::Infeasible { best, .. } | Outcome::Cancelled { best } => best,
        }
    }

    /// The status in a few words: "accepted", "not accepted" or "cancelled".
    pub fn status(&self) -> &'static str {
        match self {
            Outcome::Accepted(_) => "accepted",
            Outcome::Infeasible { .. } => "not accepted",
            Outcome::Cancelled { .. } => "cancelled",
        }
    }
}
