//! [`Mat3`]: a typed, row-major 3x3 matrix whose arithmetic is [`crate::m3`]'s.

use crate::m3;
use crate::{Real, Vec3};
use std::ops::{Add, Index, IndexMut, Mul, Neg, Sub};

/// A 3x3 matrix, row-major: `m.0[i][j]` is row `i`, column `j`; for a deformation gradient
/// `F[i][j] = dx_i / dX_j`.
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub struct Mat3<T>(pub [[T; 3]; 3]);

impl<T: Real> Mat3<T> {
    /// The zero matrix.
    #[inline(always)]
    pub fn zero() -> Self {
        Mat3(m3::zero3())
    }
    /// The identity.
    #[inline(always)]
    pub fn identity() -> Self {
        Mat3(m3::eye3())
    }
    /// A diagonal matrix.
    #[inline(always)]
    pub fn diag(d: Vec3<T>) -> Self {
        let z = T::zero();
        Mat3([[d[0], z, z], [z, d[1], z], [z, z, d[2]]])
    }
    /// From a row-major array of 9 entries.
    #[inline(always)]
    pub fn from_array(a: [T; 9]) -> Self {
        Mat3([[a[0], a[1], a[2]], [a[3], a[4], a[5]], [a[6], a[7], a[8]]])
    }
    /// To a row-major array of 9 entries.
    #[inline(always)]
    pub fn to_array(self) -> [T; 9] {
        let m = self.0;
        [
            m[0][0], m[0][1], m[0][2], m[1][0], m[1][1], m[1][2], m[2][0], m[2][1], m[2][2],
        ]
    }
    /// Outer product `a b^T`.
    #[inline(always)]
    pub fn outer(a: Vec3<T>, b: Vec3<T>) -> Self {
        Mat3([
            [a[0] * b[0], a[0] * b[1], a[0] * b[2]],
            [a[1] * b[0], a[1] * b[1], a[1] * b[2]],
            [a[2] * b[0], a[2] * b[1], a[2] * b[2]],
        ])
    }
    /// Transpose.
    #[inline(always)]
    pub fn transpose(self) -> Self {
        Mat3(m3::transpose(&self.0))
    }
    /// Determinant.
    #[inline(always)]
    pub fn det(self) -> T {
        m3::det(&self.0)
    }
    /// Trace.
    #[inline(always)]
    pub fn trace(self) -> T {
        self.0[0][0] + self.0[1][1] + self.0[2][2]
    }
    /// Matrix-vector product.
    #[inline(always)]
    pub fn mul_vec(self, v: Vec3<T>) -> Vec3<T> {
        m3::mat_vec(&self.0, &v)
    }
    /// Column `j`.
    #[inline(always)]
    pub fn col(self, j: usize) -> Vec3<T> {
        [self.0[0][j], self.0[1][j], self.0[2][j]]
    }
    /// Builds a matrix from its three columns.
    #[inline(always)]
    pub fn from_cols(a: Vec3<T>, b: Vec3<T>, c: Vec3<T>) -> Self {
        Mat3([[a[0], b[0], c[0]], [a[1], b[1], c[1]], [a[2], b[2], c[2]]])
    }
    /// `self * s`.
    #[inline(always)]
    pub fn scaled(self, s: T) -> Self {
        Mat3(m3::scaled(&self.0, s))
    }
    /// `self * diag(d)` (scales columns).
    #[inline(always)]
    pub fn mul_diag(self, d: Vec3<T>) -> Self {
        let r = |i: usize| {
            let r = self.0[i];
            [r[0] * d[0], r[1] * d[1], r[2] * d[2]]
        };
        Mat3([r(0), r(1), r(2)])
    }
    /// `(self + self^T) / 2`.
    #[inline(always)]
    pub fn sym(self) -> Self {
        (self + self.transpose()).scaled(T::c(0.5))
    }
    /// Frobenius norm.
    pub fn frobenius(self) -> T {
        self.to_array()
            .iter()
            .fold(T::zero(), |a, &x| a + x * x)
            .sqrt()
    }
    /// Converts the scalar type.
    pub fn cast<U: Real>(self) -> Mat3<U> {
        Mat3(m3::cast3(&self.0))
    }
    /// True when every entry is finite.
    pub fn is_finite(self) -> bool {
        self.to_array().iter().all(|x| x.is_finite())
    }
}

impl<T: Real> Add for Mat3<T> {
    type Output = Self;
    #[inline(always)]
    fn add(self, o: Self) -> Self {
        Mat3(m3::add(&self.0, &o.0))
    }
}
impl<T: Real> Sub for Mat3<T> {
    type Output = Self;
    #[inline(always)]
    fn sub(self, o: Self) -> Self {
        Mat3(m3::sub(&self.0, &o.0))
    }
}
impl<T: Real> Neg for Mat3<T> {
    type Output = Self;
    #[inline(always)]
    fn neg(self) -> Self {
        self.scaled(-T::one())
    }
}
impl<T: Real> Mul for Mat3<T> {
    type Output = Self;
    #[inline(always)]
    fn mul(self, o: Self) -> Self {
        Mat3(m3::mul(&self.0, &o.0))
    }
}
impl<T> Index<(usize, usize)> for Mat3<T> {
    type Output = T;
    #[inline(always)]
    fn index(&self, (i, j): (usize, usize)) -> &T {
        &self.0[i][j]
    }
}
impl<T> IndexMut<(usize, usize)> for Mat3<T> {
    #[inline(always)]
    fn index_mut(&mut self, (i, j): (usize, usize)) -> &mut T {
        &mut self.0[i][j]
    }
}
