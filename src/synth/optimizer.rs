//! SLSQP behind a small trait, with two backends.
//!
//! Owns [`Minimizer`], the pure-Rust backend [`SlsqpRs`] (the `slsqp` crate, default) and,
//! with the cargo feature `nlopt`, `NloptSlsqp` (NLopt's own SLSQP). Both see the same
//! objective and constraints with exact gradients from `energy`; the per-x evaluation is
//! cached because SLSQP asks for the objective and each constraint separately at the same
//! point. It does not judge results: SLSQP often ends with a round-off status next to the
//! optimum, so the caller accepts a result only after its own feasibility check
//! (`PairProblem::feasible`).

use std::cell::RefCell;

use super::energy::{Evaluation, PairProblem};

/// Relative objective change at which SLSQP stops. Default 1e-8: the objective is a sum
/// over 360 samples of order 10–1000, so this is far below anything that changes the
/// geometry visibly, and candidates converge within a few hundred evaluations.
pub const FTOL_REL: f64 = 1e-8;

/// Maximum SLSQP iterations (objective evaluations) per candidate. Default 400: measured
/// candidates converge in 60–250; the cap bounds the cost of a bad start.
pub const MAX_EVAL: usize = 400;

/// How an SLSQP run ended.
#[derive(Clone, Debug, PartialEq)]
pub enum SolveStatus {
    /// Converged (any tolerance reached).
    Converged,
    /// Stopped by the evaluation cap.
    MaxEval,
    /// Round-off limited (often right at the optimum: check feasibility).
    RoundOff,
    /// Failed otherwise.
    Failed(String),
}

/// Result of one SLSQP run.
#[derive(Clone, Debug)]
pub struct SolveResult {
    /// Final design.
    pub x: Vec<f64>,
    /// Final objective.
    pub f: f64,
    /// Status.
    pub status: SolveStatus,
    /// Objective evaluations used.
    pub evals: usize,
}

/// A constrained local minimizer.
pub trait Minimizer: Sync {
    /// Backend name for reports.
    fn name(&self) -> &'static str;
    /// Minimize the problem from `x0` with at most `max_eval` evaluations.
    fn minimize(&self, pb: &PairProblem, x0: &[f64], max_eval: usize) -> SolveResult;
}

/// Evaluation cache keyed by the exact design vector.
struct Cache<'a> {
    pb: &'a PairProblem,
    last: RefCell<Option<(Vec<f64>, Evaluation)>>,
    evals: RefCell<usize>,
}

impl<'a> Cache<'a> {
    fn new(pb: &'a PairProblem) -> Self {
        Self {
            pb,
            last: RefCell::new(None),
            evals: RefCell::new(0),
        }
    }
    fn with<R>(&self, x: &[f64], f: impl FnOnce(&Evaluation) -> R) -> R {
        let hit = matches!(&*self.last.borrow(), Some((lx, _)) if lx.as_slice() == x);
        if !hit {
            *self.evals.borrow_mut() += 1;
            let ev = self.pb.evaluate(x);
            *self.last.borrow_mut() = Some((x.to_vec(), ev));
        }
        let b = self.last.borrow();
        f(&b.as_ref().expect("cache filled above").1)
    }
    fn objective(&self, x: &[f64], g: Option<&mut [f64]>) -> f64 {
        self.with(x, |ev| {
            if let Some(g) = g {
                g.copy_from_slice(&ev.grad);
            }
            sanitize(ev.f)
        })
    }
    fn constraint(&self, c: usize, x: &[f64], g: Option<&mut [f64]>) -> f64 {
        self.with(x, |ev| {
            if let Some(g) = g {
                g.copy_from_slice(&ev.cons_grad[c]);
            }
            sanitize(ev.cons[c])
        })
    }
}

/// A non-finite value makes SLSQP's line search back off instead of propagating NaN.
fn sanitize(v: f64) -> f64 {
    if v.is_finite() {
        v
    } else {
        1.0e30
    }
}

/// The pure-Rust SLSQP (`slsqp` crate, a translation of NLopt's).
#[derive(Clone, Copy, Debug, Default)]
pub struct SlsqpRs;

impl Minimizer for SlsqpRs {
    fn name(&self) -> &'static str {
        "slsqp (pure Rust)"
    }
    fn minimize(&self, pb: &PairProblem, x0: &[f64], max_eval: usize) -> SolveResult {
        let cache = Cache::new(pb);
        let obj = |x: &[f64], g: Option<&mut [f64]>, _: &mut ()| cache.objective(x, g);
        let cons: Vec<_> = (0..pb.n_constraints())
            .map(|c| {
                let cache = &cache;
                move |x: &[f64], g: Option<&mut [f64]>, _: &mut ()| cache.constraint(c, x, g)
            })
            .collect();
        let tols = slsqp::StopTols {
            ftol_rel: FTOL_REL,
            ..Default::default()
        };
        let res = slsqp::minimize(obj, x0, &pb.bounds(), &cons, (), max_eval, Some(tols));
        let evals = *cache.evals.borrow();
        match res {
            Ok((s, x, f)) => SolveResult {
                x,
                f,
                status: if matches!(s, slsqp::SuccessStatus::MaxEvalReached) {
                    SolveStatus::MaxEval
                } else {
                    SolveStatus::Converged
                },
                evals,
            },
            Err((e, x, f)) => SolveResult {
                x,
                f,
                status: if matches!(e, slsqp::FailStatus::RoundoffLimited) {
                    SolveStatus::RoundOff
                } else {
                    SolveStatus::Failed(format!("{e:?}"))
                },
                evals,
            },
        }
    }
}

/// NLopt's SLSQP (cargo feature `nlopt`).
#[cfg(feature = "nlopt")]
#[derive(Clone, Copy, Debug, Default)]
pub struct NloptSlsqp;

#[cfg(feature = "nlopt")]
impl Minimizer for NloptSlsqp {
    fn name(&self) -> &'static str {
        "NLopt SLSQP"
    }
    fn minimize(&self, pb: &PairProblem, x0: &[f64], max_eval: usize) -> SolveResult {
        use nlopt::{Algorithm, Nlopt, Target};
        let cache = Cache::new(pb);
        let obj = |x: &[f64], g: Option<&mut [f64]>, _: &mut ()| cache.objective(x, g);
        let mut opt = Nlopt::new(Algorithm::Slsqp, x0.len(), obj, Target::Minimize, ());
        let b = pb.bounds();
        let lo: Vec<f64> = b.iter().map(|v| v.0).collect();
        let hi: Vec<f64> = b.iter().map(|v| v.1).collect();
        let mut setup = || -> Result<(), nlopt::FailState> {
            opt.set_lower_bounds(&lo)?;
            opt.set_upper_bounds(&hi)?;
            opt.set_maxeval(max_eval as u32)?;
            opt.set_ftol_rel(FTOL_REL)?;
            for c in 0..pb.n_constraints() {
                let cache = &cache;
                opt.add_inequality_constraint(
                    move |x: &[f64], g: Option<&mut [f64]>, _: &mut ()| cache.constraint(c, x, g),
                    (),
                    0.0,
                )?;
            }
            Ok(())
        };
        if let Err(e) = setup() {
            return SolveResult {
                x: x0.to_vec(),
                f: f64::NAN,
                status: SolveStatus::Failed(format!("NLopt setup: {e:?}")),
                evals: 0,
            };
        }
        let mut x = x0.to_vec();
        let res = opt.optimize(&mut x);
        let evals = *cache.evals.borrow();
        match res {
            Ok((s, f)) => SolveResult {
                x,
                f,
                status: if matches!(s, nlopt::SuccessState::MaxEvalReached) {
                    SolveStatus::MaxEval
                } else {
                    SolveStatus::Converged
                },
                evals,
            },
            Err((e, f)) => SolveResult {
                x,
                f,
                status: if matches!(e, nlopt::FailState::RoundoffLimited) {
                    SolveStatus::RoundOff
                } else {
                    SolveStatus::Failed(format!("{e:?}"))
                },
                evals,
            },
        }
    }
}

/// The backend selected at build time: NLopt with the `nlopt` feature, else pure Rust.
pub fn default_minimizer() -> &'static dyn Minimizer {
    #[cfg(feature = "nlopt")]
    {
        &NloptSlsqp
    }
    #[cfg(not(feature = "nlopt"))]
    {
        &SlsqpRs
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::synth::candidate::{initial_guess, tests::problem_1r};

    /// Guards the pure-Rust backend on a small 1R candidate: it lowers the objective from
    /// the initial guess and ends feasible (within the acceptance tolerance).
    #[test]
    fn slsqp_rs_improves_a_small_candidate_feasibly() {
        let pb = problem_1r(48);
        let x0 = initial_guess(&pb, 3, 0, 0);
        let f0 = pb.evaluate(&x0).f;
        let r = SlsqpRs.minimize(&pb, &x0, 150);
        assert!(r.f.is_finite() && r.f < f0, "{} !< {f0}", r.f);
        let ev = pb.evaluate(&r.x);
        assert!(pb.feasible(&r.x, &ev, 1e-6), "{:?}", ev.cons_exact);
    }

    /// Guards that both SLSQP backends (pure Rust and NLopt, feature `nlopt`) agree on the
    /// same candidate problem from the same start.
    #[cfg(feature = "nlopt")]
    #[test]
    fn slsqp_backends_agree() {
        let pb = problem_1r(48);
        let x0 = initial_guess(&pb, 3, 0, 0);
        let a = SlsqpRs.minimize(&pb, &x0, 60);
        let b = NloptSlsqp.minimize(&pb, &x0, 60);
        assert!(
            (a.f - b.f).abs() <= 1e-6 * (1.0 + a.f.abs()),
            "pure Rust {} vs NLopt {}",
            a.f,
            b.f
        );
        let dx =
            a.x.iter()
                .zip(&b.x)
                .map(|(p, q)| (p - q).abs())
                .fold(0.0, f64::max);
        assert!(dx < 1e-6, "designs differ by {dx}");
    }
}
