//! The scalar type of the renderer's math (`f32` for rendering, `f64` for finite-difference
//! checks) and the small fixed-size linear algebra it needs.

use num_traits::Float;
use std::fmt::Debug;
use std::ops::{AddAssign, MulAssign, SubAssign};

/// A floating-point scalar: `f32` or `f64`.
pub trait Real:
    Float + Default + Debug + Send + Sync + AddAssign + SubAssign + MulAssign + 'static
{
    /// Converts from `f64` (rounding for `f32`).
    fn c(x: f64) -> Self;
    /// Converts to `f64`.
    fn f64(self) -> f64;
}

impl Real for f32 {
    fn c(x: f64) -> Self {
        x as f32
    }
    fn f64(self) -> f64 {
        self as f64
    }
}

impl Real for f64 {
    fn c(x: f64) -> Self {
        x
    }
    fn f64(self) -> f64 {
        self
    }
}

/// A 3-vector.
pub type V3<T> = [T; 3];
/// A row-major 3x3 matrix: `m[row][col]`.
pub type M3<T> = [[T; 3]; 3];

/// The zero matrix.
pub fn zero3<T: Real>() -> M3<T> {
    [[T::zero(); 3]; 3]
}

/// The identity matrix.
pub fn eye3<T: Real>() -> M3<T> {
    let mut m = zero3();
    for i in 0..3 {
        m[i][i] = T::one();
    }
    m
}

/// `a b`.
pub fn mul<T: Real>(a: &M3<T>, b: &M3<T>) -> M3<T> {
    let mut m = zero3();
    for i in 0..3 {
        for j in 0..3 {
            for k in 0..3 {
                m[i][j] += a[i][k] * b[k][j];
            }
        }
    }
    m
}

/// `a^T`.
pub fn transpose<T: Real>(a: &M3<T>) -> M3<T> {
    let mut m = zero3();
    for i in 0..3 {
        for j in 0..3 {
            m[i][j] = a[j][i];
        }
    }
    m
}

/// `a b^T`.
pub fn mul_bt<T: Real>(a: &M3<T>, b: &M3<T>) -> M3<T> {
    mul(a, &transpose(b))
}

/// `a^T b`.
pub fn mul_at<T: Real>(a: &M3<T>, b: &M3<T>) -> M3<T> {
    mul(&transpose(a), b)
}

/// `a + b`.
pub fn add<T: Real>(a: &M3<T>, b: &M3<T>) -> M3<T> {
    let mut m = *a;
    for i in 0..3 {
        for j in 0..3 {
            m[i][j] += b[i][j];
        }
    }
    m
}

/// `m v`.
pub fn mat_vec<T: Real>(m: &M3<T>, v: &V3<T>) -> V3<T> {
    [0, 1, 2].map(|i| m[i][0] * v[0] + m[i][1] * v[1] + m[i][2] * v[2])
}

/// `m^T v`.
pub fn mat_t_vec<T: Real>(m: &M3<T>, v: &V3<T>) -> V3<T> {
    [0, 1, 2].map(|i| m[0][i] * v[0] + m[1][i] * v[1] + m[2][i] * v[2])
}

/// `a . b`.
pub fn dot<T: Real>(a: &V3<T>, b: &V3<T>) -> T {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// `a x b`.
pub fn cross<T: Real>(a: &V3<T>, b: &V3<T>) -> V3<T> {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

/// Determinant.
pub fn det<T: Real>(m: &M3<T>) -> T {
    m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
        - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
        + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0])
}

/// Converts a matrix between scalar types.
pub fn cast3<A: Real, B: Real>(m: &M3<A>) -> M3<B> {
    m.map(|r| r.map(|x| B::c(x.f64())))
}

/// Converts a vector between scalar types.
pub fn castv<A: Real, B: Real>(v: &V3<A>) -> V3<B> {
    v.map(|x| B::c(x.f64()))
}
