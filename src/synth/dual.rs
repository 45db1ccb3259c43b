//! Forward-mode automatic differentiation for the synthesis energies.
//!
//! Owns [`Dual`] (value plus a fixed-size gradient over a *local* set of design variables)
//! and its implementation of [`Scalar`], the number trait of `math` that the curve-pair
//! model is written against. It does not know which design variables a gradient slot stands
//! for: callers map local slots to global variable indices (see `energy`).
//!
//! Gradients are exact (to round-off): no finite differences are used anywhere in the
//! optimizer's path; finite differences appear only in tests that check these gradients.

use std::ops::{Add, AddAssign, Div, Mul, Neg, Sub};

use super::math::Scalar;

/// A dual number: value `v` and gradient `g` over `D` local variables.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Dual<const D: usize> {
    /// Value.
    pub v: f64,
    /// Partial derivatives with respect to the local variables.
    pub g: [f64; D],
}

impl<const D: usize> Dual<D> {
    /// The `i`-th independent variable with value `v`.
    pub fn var(v: f64, i: usize) -> Self {
        let mut g = [0.0; D];
        g[i] = 1.0;
        Self { v, g }
    }
    /// Chain rule for a unary function with value `f` and derivative `df` at `self.v`.
    #[inline(always)]
    fn chain(self, f: f64, df: f64) -> Self {
        let mut g = self.g;
        for x in g.iter_mut() {
            *x *= df;
        }
        Self { v: f, g }
    }
}

// The operators are `#[inline(always)]` for the same reason as `V3`'s methods (see `math`).
impl<const D: usize> Add for Dual<D> {
    type Output = Self;
    #[inline(always)]
    fn add(mut self, o: Self) -> Self {
        self.v += o.v;
        for (a, b) in self.g.iter_mut().zip(o.g.iter()) {
            *a += b;
        }
        self
    }
}
impl<const D: usize> AddAssign for Dual<D> {
    #[inline(always)]
    fn add_assign(&mut self, o: Self) {
        *self = *self + o;
    }
}
impl<const D: usize> Sub for Dual<D> {
    type Output = Self;
    #[inline(always)]
    fn sub(mut self, o: Self) -> Self {
        self.v -= o.v;
        for (a, b) in self.g.iter_mut().zip(o.g.iter()) {
            *a -= b;
        }
        self
    }
}
impl<const D: usize> Mul for Dual<D> {
    type Output = Self;
    #[inline(always)]
    fn mul(self, o: Self) -> Self {
        let mut g = [0.0; D];
        for ((r, a), b) in g.iter_mut().zip(self.g.iter()).zip(o.g.iter()) {
            *r = a * o.v + b * self.v;
        }
        Self { v: self.v * o.v, g }
    }
}
impl<const D: usize> Div for Dual<D> {
    type Output = Self;
    #[inline(always)]
    fn div(self, o: Self) -> Self {
        let inv = 1.0 / o.v;
        let q = self.v * inv;
        let mut g = [0.0; D];
        for ((r, a), b) in g.iter_mut().zip(self.g.iter()).zip(o.g.iter()) {
            *r = (a - q * b) * inv;
        }
        Self { v: q, g }
    }
}
impl<const D: usize> Neg for Dual<D> {
    type Output = Self;
    #[inline(always)]
    fn neg(self) -> Self {
        self.chain(-self.v, -1.0)
    }
}
impl<const D: usize> Add<f64> for Dual<D> {
    type Output = Self;
    #[inline(always)]
    fn add(mut self, o: f64) -> Self {
        self.v += o;
        self
    }
}
impl<const D: usize> Sub<f64> for Dual<D> {
    type Output = Self;
    #[inline(always)]
    fn sub(mut self, o: f64) -> Self {
        self.v -= o;
        self
    }
}
impl<const D: usize> Mul<f64> for Dual<D> {
    type Output = Self;
    #[inline(always)]
    fn mul(self, o: f64) -> Self {
        self.chain(self.v * o, o)
    }
}

impl<const D: usize> Scalar for Dual<D> {
    fn cst(v: f64) -> Self {
        Self { v, g: [0.0; D] }
    }
    fn val(self) -> f64 {
        self.v
    }
    fn sqrt(self) -> Self {
        let s = self.v.sqrt();
        self.chain(s, 0.5 / s)
    }
    fn sin(self) -> Self {
        self.chain(self.v.sin(), self.v.cos())
    }
    fn cos(self) -> Self {
        self.chain(self.v.cos(), -self.v.sin())
    }
    fn exp(self) -> Self {
        let e = self.v.exp();
        self.chain(e, e)
    }
    fn ln(self) -> Self {
        self.chain(self.v.ln(), 1.0 / self.v)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Guards the dual-number rules: d/dx of a composite expression equals the analytic
    /// derivative.
    #[test]
    fn dual_chain_rule_matches_analytic_derivative() {
        let x = Dual::<2>::var(0.7, 0);
        let y = Dual::<2>::var(1.3, 1);
        // f = sin(x*y) / sqrt(x + y) + exp(x) * ln(y) - y*2
        let f = (x * y).sin() / (x + y).sqrt() + x.exp() * y.ln() - y * 2.0;
        let (xv, yv) = (0.7f64, 1.3f64);
        let s = (xv + yv).sqrt();
        let dfdx =
            (xv * yv).cos() * yv / s - 0.5 * (xv * yv).sin() / (s * s * s) + xv.exp() * yv.ln();
        let dfdy =
            (xv * yv).cos() * xv / s - 0.5 * (xv * yv).sin() / (s * s * s) + xv.exp() / yv - 2.0;
        assert!((f.g[0] - dfdx).abs() < 1e-12, "{} vs {}", f.g[0], dfdx);
        assert!((f.g[1] - dfdy).abs() < 1e-12, "{} vs {}", f.g[1], dfdy);
    }
}
