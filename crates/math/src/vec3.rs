//! 3-vectors as plain `[T; 3]` arrays, passed by value (they are `Copy`).

use crate::Real;

/// A 3-vector.
pub type Vec3<T> = [T; 3];

/// Dot product.
#[inline(always)]
pub fn dot<T: Real>(a: Vec3<T>, b: Vec3<T>) -> T {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}
/// Euclidean norm.
#[inline(always)]
pub fn norm<T: Real>(a: Vec3<T>) -> T {
    dot(a, a).sqrt()
}
/// Cross product.
#[inline(always)]
pub fn cross<T: Real>(a: Vec3<T>, b: Vec3<T>) -> Vec3<T> {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}
/// `a * s`.
#[inline(always)]
pub fn scale<T: Real>(a: Vec3<T>, s: T) -> Vec3<T> {
    [a[0] * s, a[1] * s, a[2] * s]
}
/// `a + b`.
#[inline(always)]
pub fn add<T: Real>(a: Vec3<T>, b: Vec3<T>) -> Vec3<T> {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}
/// `a - b`.
#[inline(always)]
pub fn sub<T: Real>(a: Vec3<T>, b: Vec3<T>) -> Vec3<T> {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}
/// Converts a vector between scalar types.
#[inline(always)]
pub fn cast<A: Real, B: Real>(v: Vec3<A>) -> Vec3<B> {
    [B::c(v[0].f64()), B::c(v[1].f64()), B::c(v[2].f64())]
}
