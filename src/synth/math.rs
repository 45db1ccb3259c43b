//! The math vocabulary of synthesis, in one place (as parry's `math`).
//!
//! Owns the number trait [`Scalar`] the curve-pair model is written against (plain `f64`
//! here, dual numbers in `dual`), the 3-vector [`V3`] over it, row-major 3×3 matrices
//! ([`Mat3`]) with the driver's rotation [`rz`], and the conversions between quaternions and
//! matrices. The few nalgebra types synthesis needs (quaternions and vectors at the motion's
//! boundary, dense matrices for least-squares fits) are re-exported from here, so every
//! module of `synth` names its linear algebra through `math`. Plain `[f64; 3]` arrays are
//! the storage form (files, poses, constants); computations on them go through [`V3`]
//! (`V3::from(a)`, `.vals()`). It does not differentiate (see `dual`) or evaluate splines
//! (see `bspline`).

use std::ops::{Add, AddAssign, Div, Mul, Neg, Sub};

pub use nalgebra::{DMatrix, DVector, Matrix3, Quaternion, UnitQuaternion, Vector3};

/// A row-major 3×3 matrix: `m[r][c]`.
pub type Mat3 = [[f64; 3]; 3];

/// The rotation Rz(a) about +z.
pub fn rz(a: f64) -> Mat3 {
    let (s, c) = a.sin_cos();
    [[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]
}

/// The rotation matrix of a unit quaternion.
pub fn mat3_of(q: &UnitQuaternion<f64>) -> Mat3 {
    let m: Matrix3<f64> = *q.to_rotation_matrix().matrix();
    std::array::from_fn(|r| std::array::from_fn(|c| m[(r, c)]))
}

/// The unit quaternion of a rotation matrix.
pub fn quaternion_of(m: &Mat3) -> UnitQuaternion<f64> {
    UnitQuaternion::from_matrix(&Matrix3::from_fn(|r, c| m[r][c]))
}

/// The rotation matrix of a quaternion stored as [w, x, y, z] (normalized first).
pub fn mat3_of_wxyz(q: [f64; 4]) -> Mat3 {
    let [w, x, y, z] = q;
    mat3_of(&UnitQuaternion::from_quaternion(Quaternion::new(
        w, x, y, z,
    )))
}

/// A real number the curve-pair model can be evaluated with: `f64` or a
/// [`Dual`](super::dual::Dual).
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

// Every method and operator of `V3` is `#[inline(always)]`: on a `Dual<10>` a call copies
// its 264-byte operands, and LLVM left these as calls (a tenth of synthesis in `memmove`;
// measured in docs/synthesis.md, "Measured after inlining the jets").
impl<S: Scalar> V3<S> {
    /// From components.
    #[inline(always)]
    pub fn new(x: S, y: S, z: S) -> Self {
        Self { x, y, z }
    }
    /// A constant vector.
    #[inline(always)]
    pub fn cst(v: [f64; 3]) -> Self {
        Self::new(S::cst(v[0]), S::cst(v[1]), S::cst(v[2]))
    }
    /// The zero vector.
    #[inline(always)]
    pub fn zero() -> Self {
        Self::cst([0.0; 3])
    }
    /// Dot product.
    #[inline(always)]
    pub fn dot(self, o: Self) -> S {
        self.x * o.x + self.y * o.y + self.z * o.z
    }
    /// Dot product with a constant vector.
    #[inline(always)]
    pub fn dotc(self, o: [f64; 3]) -> S {
        self.x * o[0] + self.y * o[1] + self.z * o[2]
    }
    /// Cross product.
    #[inline(always)]
    pub fn cross(self, o: Self) -> Self {
        Self::new(
            self.y * o.z - self.z * o.y,
            self.z * o.x - self.x * o.z,
            self.x * o.y - self.y * o.x,
        )
    }
    /// Squared norm.
    #[inline(always)]
    pub fn norm2(self) -> S {
        self.dot(self)
    }
    /// Norm.
    #[inline(always)]
    pub fn norm(self) -> S {
        self.norm2().sqrt()
    }
    /// Scaled by a scalar.
    #[inline(always)]
    pub fn scale(self, s: S) -> Self {
        Self::new(self.x * s, self.y * s, self.z * s)
    }
    /// Scaled by a constant.
    #[inline(always)]
    pub fn scalec(self, s: f64) -> Self {
        Self::new(self.x * s, self.y * s, self.z * s)
    }
    /// Unit vector (the caller guarantees a non-zero norm).
    #[inline(always)]
    pub fn unit(self) -> Self {
        let inv = S::cst(1.0) / self.norm();
        self.scale(inv)
    }
    /// Apply a constant rotation (or any 3×3 matrix).
    #[inline(always)]
    pub fn rot(self, m: &Mat3) -> Self {
        Self::new(self.dotc(m[0]), self.dotc(m[1]), self.dotc(m[2]))
    }
    /// Apply the transpose of a constant 3×3 matrix (the inverse of a rotation).
    #[inline(always)]
    pub fn rot_t(self, m: &Mat3) -> Self {
        Self::new(
            self.x * m[0][0] + self.y * m[1][0] + self.z * m[2][0],
            self.x * m[0][1] + self.y * m[1][1] + self.z * m[2][1],
            self.x * m[0][2] + self.y * m[1][2] + self.z * m[2][2],
        )
    }
    /// Values only.
    #[inline(always)]
    pub fn vals(self) -> [f64; 3] {
        [self.x.val(), self.y.val(), self.z.val()]
    }
}

impl<S: Scalar> Add for V3<S> {
    type Output = Self;
    #[inline(always)]
    fn add(self, o: Self) -> Self {
        Self::new(self.x + o.x, self.y + o.y, self.z + o.z)
    }
}
impl<S: Scalar> Sub for V3<S> {
    type Output = Self;
    #[inline(always)]
    fn sub(self, o: Self) -> Self {
        Self::new(self.x - o.x, self.y - o.y, self.z - o.z)
    }
}
impl<S: Scalar> Neg for V3<S> {
    type Output = Self;
    #[inline(always)]
    fn neg(self) -> Self {
        Self::new(-self.x, -self.y, -self.z)
    }
}

impl From<[f64; 3]> for V3<f64> {
    fn from(v: [f64; 3]) -> Self {
        Self::cst(v)
    }
}

impl From<V3<f64>> for [f64; 3] {
    fn from(v: V3<f64>) -> Self {
        v.vals()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Guards the conversions between quaternions and matrices: a quaternion stored as
    /// [w, x, y, z] gives the matrix nalgebra rotates with, [`rz`] is that of a turn about z,
    /// and matrix → quaternion → matrix is the identity.
    #[test]
    fn quaternion_and_matrix_conversions_agree() {
        let q = UnitQuaternion::from_euler_angles(0.3, -0.7, 1.9);
        let m = mat3_of(&q);
        let v = Vector3::new(0.2, -1.5, 0.8);
        let want = q * v;
        let got = V3::<f64>::cst([v.x, v.y, v.z]).rot(&m).vals();
        for a in 0..3 {
            assert!((got[a] - want[a]).abs() < 1e-12);
        }
        let qv = q.quaternion();
        let m2 = mat3_of_wxyz([qv.w, qv.i, qv.j, qv.k]);
        let back = mat3_of(&quaternion_of(&m));
        let turn = mat3_of(&UnitQuaternion::from_axis_angle(&Vector3::z_axis(), 0.4));
        for r in 0..3 {
            for c in 0..3 {
                assert!((m2[r][c] - m[r][c]).abs() < 1e-12);
                assert!((back[r][c] - m[r][c]).abs() < 1e-12);
                assert!((rz(0.4)[r][c] - turn[r][c]).abs() < 1e-12);
            }
        }
        // rot_t undoes rot.
        let u = V3::<f64>::cst([1.0, 2.0, 3.0]);
        let w = u.rot(&m).rot_t(&m).vals();
        assert!((w[0] - 1.0).abs() + (w[1] - 2.0).abs() + (w[2] - 3.0).abs() < 1e-12);
    }
}
