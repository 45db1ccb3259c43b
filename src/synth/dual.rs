//! Forward-mode automatic differentiation for the synthesis energies.
//!
//! Owns the [`Scalar`] trait the curve-pair model is written against, implemented for plain
//! `f64` (values only) and for [`Dual`] (value plus a fixed-size gradient over a *local* set
//! of design variables), and the small 3-vector type [`V3`] used by that generic code. It
//! does not know which design variables a gradient slot stands for: callers map local slots
//! to global variable indices (see `energy`).
//!
//! Gradients are exact (to round-off): no finite differences are used anywhere in the
//! optimizer's path; finite differences appear only in tests that check these gradients.

use std::ops::{Add, AddAssign, Div, Mul, Neg, Sub};

/// A real number the curve-pair model can be evaluated with: `f64` or a [`Dual`].
pub trait Scalar:
    Copy
    + Add<Output = Self>
    + Sub<Output = Self>
    + Mul<Output = Self>
    + Div<Output = Self>
    + Neg<Output = Self>
    + Add<f64, Output = Self>
    + Sub<f64, Output = Self>
    + Mul<f64, Output = Self>
    + AddAssign
{
    /// A constant (zero derivative).
    fn cst(v: f64) -> Self;
    /// The value part.
    fn val(self) -> f64;
    /// Square root.
    fn sqrt(self) -> Self;
    /// Sine.
    fn sin(self) -> Self;
    /// Cosine.
    fn cos(self) -> Self;
    /// Exponential.
    fn exp(self) -> Self;
    /// Natural logarithm.
    fn ln(self) -> Self;
}

impl Scalar for f64 {
    fn cst(v: f64) -> Self {
        v
    }
    fn val(self) -> f64 {
        self
    }
    fn sqrt(self) -> Self {
        f64::sqrt(self)
    }
    fn sin(self) -> Self {
        f64::sin(self)
    }
    fn cos(self) -> Self {
        f64::cos(self)
    }
    fn exp(self) -> Self {
        f64::exp(self)
    }
    fn ln(self) -> Self {
        f64::ln(self)
    }
}

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
    #[inline]
    fn chain(self, f: f64, df: f64) -> Self {
        let mut g = self.g;
        for x in g.iter_mut() {
            *x *= df;
        }
        Self { v: f, g }
    }
}

impl<const D: usize> Add for Dual<D> {
    type Output = Self;
    #[inline]
    fn add(mut self, o: Self) -> Self {
        self.v += o.v;
        for (a, b) in self.g.iter_mut().zip(o.g.iter()) {
            *a += b;
        }
        self
    }
}
impl<const D: usize> AddAssign for Dual<D> {
    #[inline]
    fn add_assign(&mut self, o: Self) {
        *self = *self + o;
    }
}
impl<const D: usize> Sub for Dual<D> {
    type Output = Self;
    #[inline]
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
    #[inline]
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
    #[inline]
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
    #[inline]
    fn neg(self) -> Self {
        self.chain(-self.v, -1.0)
    }
}
impl<const D: usize> Add<f64> for Dual<D> {
    type Output = Self;
    #[inline]
    fn add(mut self, o: f64) -> Self {
        self.v += o;
        self
    }
}
impl<const D: usize> Sub<f64> for Dual<D> {
    type Output = Self;
    #[inline]
    fn sub(mut self, o: f64) -> Self {
        self.v -= o;
        self
    }
}
impl<const D: usize> Mul<f64> for Dual<D> {
    type Output = Self;
    #[inline]
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

/// A 3-vector over any [`Scalar`].
#[derive(Clone, Copy, Debug)]
pub struct V3<S> {
    /// x
    pub x: S,
    /// y
    pub y: S,
    /// z
    pub z: S,
}

impl<S: Scalar> V3<S> {
    /// From components.
    pub fn new(x: S, y: S, z: S) -> Self {
        Self { x, y, z }
    }
    /// A constant vector.
    pub fn cst(v: [f64; 3]) -> Self {
        Self::new(S::cst(v[0]), S::cst(v[1]), S::cst(v[2]))
    }
    /// The zero vector.
    pub fn zero() -> Self {
        Self::cst([0.0; 3])
    }
    /// Dot product.
    pub fn dot(self, o: Self) -> S {
        self.x * o.x + self.y * o.y + self.z * o.z
    }
    /// Dot product with a constant vector.
    pub fn dotc(self, o: [f64; 3]) -> S {
        self.x * o[0] + self.y * o[1] + self.z * o[2]
    }
    /// Cross product.
    pub fn cross(self, o: Self) -> Self {
        Self::new(
            self.y * o.z - self.z * o.y,
            self.z * o.x - self.x * o.z,
            self.x * o.y - self.y * o.x,
        )
    }
    /// Squared norm.
    pub fn norm2(self) -> S {
        self.dot(self)
    }
    /// Norm.
    pub fn norm(self) -> S {
        self.norm2().sqrt()
    }
    /// Scaled by a scalar.
    pub fn scale(self, s: S) -> Self {
        Self::new(self.x * s, self.y * s, self.z * s)
    }
    /// Scaled by a constant.
    pub fn scalec(self, s: f64) -> Self {
        Self::new(self.x * s, self.y * s, self.z * s)
    }
    /// Unit vector (the caller guarantees a non-zero norm).
    pub fn unit(self) -> Self {
        let inv = S::cst(1.0) / self.norm();
        self.scale(inv)
    }
    /// Apply a constant 3×3 matrix (row-major).
    pub fn rot(self, m: &[[f64; 3]; 3]) -> Self {
        Self::new(self.dotc(m[0]), self.dotc(m[1]), self.dotc(m[2]))
    }
    /// Apply the transpose of a constant 3×3 matrix (row-major).
    pub fn rot_t(self, m: &[[f64; 3]; 3]) -> Self {
        Self::new(
            self.x * m[0][0] + self.y * m[1][0] + self.z * m[2][0],
            self.x * m[0][1] + self.y * m[1][1] + self.z * m[2][1],
            self.x * m[0][2] + self.y * m[1][2] + self.z * m[2][2],
        )
    }
    /// Values only.
    pub fn vals(self) -> [f64; 3] {
        [self.x.val(), self.y.val(), self.z.val()]
    }
}

impl<S: Scalar> Add for V3<S> {
    type Output = Self;
    fn add(self, o: Self) -> Self {
        Self::new(self.x + o.x, self.y + o.y, self.z + o.z)
    }
}
impl<S: Scalar> Sub for V3<S> {
    type Output = Self;
    fn sub(self, o: Self) -> Self {
        Self::new(self.x - o.x, self.y - o.y, self.z - o.z)
    }
}
impl<S: Scalar> Neg for V3<S> {
    type Output = Self;
    fn neg(self) -> Self {
        Self::new(-self.x, -self.y, -self.z)
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
