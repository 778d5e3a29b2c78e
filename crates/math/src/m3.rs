//! 3x3 matrices as row-major `[[T; 3]; 3]` arrays (`m[row][col]`): the one implementation of
//! the matrix arithmetic; [`crate::Mat3`]'s operators call these functions.

use crate::{Real, Vec3};

/// A row-major 3x3 matrix: `m[row][col]`.
pub type M3<T> = [[T; 3]; 3];

/// The zero matrix.
#[inline(always)]
pub fn zero3<T: Real>() -> M3<T> {
    [[T::zero(); 3]; 3]
}

/// The identity matrix.
#[inline(always)]
pub fn eye3<T: Real>() -> M3<T> {
    let (z, o) = (T::zero(), T::one());
    [[o, z, z], [z, o, z], [z, z, o]]
}

/// `a b`.
#[inline(always)]
pub fn mul<T: Real>(a: &M3<T>, b: &M3<T>) -> M3<T> {
    let mut m = zero3();
    for i in 0..3 {
        for j in 0..3 {
            m[i][j] = a[i][0] * b[0][j] + a[i][1] * b[1][j] + a[i][2] * b[2][j];
        }
    }
    m
}

/// `a^T`.
#[inline(always)]
pub fn transpose<T: Real>(a: &M3<T>) -> M3<T> {
    [
        [a[0][0], a[1][0], a[2][0]],
        [a[0][1], a[1][1], a[2][1]],
        [a[0][2], a[1][2], a[2][2]],
    ]
}

/// `a b^T`.
#[inline(always)]
pub fn mul_bt<T: Real>(a: &M3<T>, b: &M3<T>) -> M3<T> {
    mul(a, &transpose(b))
}

/// `a^T b`.
#[inline(always)]
pub fn mul_at<T: Real>(a: &M3<T>, b: &M3<T>) -> M3<T> {
    mul(&transpose(a), b)
}

/// `a + b`.
#[inline(always)]
pub fn add<T: Real>(a: &M3<T>, b: &M3<T>) -> M3<T> {
    let mut m = *a;
    for i in 0..3 {
        for j in 0..3 {
            m[i][j] += b[i][j];
        }
    }
    m
}

/// `a - b`.
#[inline(always)]
pub fn sub<T: Real>(a: &M3<T>, b: &M3<T>) -> M3<T> {
    let mut m = *a;
    for i in 0..3 {
        for j in 0..3 {
            m[i][j] -= b[i][j];
        }
    }
    m
}

/// `a s`.
#[inline(always)]
pub fn scaled<T: Real>(a: &M3<T>, s: T) -> M3<T> {
    // Written out: `array::map` is not always inlined, and an out-of-line call per row in a
    // per-node loop cost the reverse sweep 10-20% (measured by a microbench).
    let r = |i: usize| [a[i][0] * s, a[i][1] * s, a[i][2] * s];
    [r(0), r(1), r(2)]
}

/// `m v`.
#[inline(always)]
pub fn mat_vec<T: Real>(m: &M3<T>, v: &Vec3<T>) -> Vec3<T> {
    [
        m[0][0] * v[0] + m[0][1] * v[1] + m[0][2] * v[2],
        m[1][0] * v[0] + m[1][1] * v[1] + m[1][2] * v[2],
        m[2][0] * v[0] + m[2][1] * v[1] + m[2][2] * v[2],
    ]
}

/// `m^T v`.
#[inline(always)]
pub fn mat_t_vec<T: Real>(m: &M3<T>, v: &Vec3<T>) -> Vec3<T> {
    let c = |i: usize| m[0][i] * v[0] + m[1][i] * v[1] + m[2][i] * v[2];
    [c(0), c(1), c(2)]
}

/// Determinant.
#[inline(always)]
pub fn det<T: Real>(m: &M3<T>) -> T {
    m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
        - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
        + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0])
}

/// Adjugate (transpose of the cofactor matrix): `adj(m) m = det(m) I`.
#[inline(always)]
pub fn adjugate<T: Real>(k: &M3<T>) -> M3<T> {
    [
        [
            k[1][1] * k[2][2] - k[1][2] * k[2][1],
            k[0][2] * k[2][1] - k[0][1] * k[2][2],
            k[0][1] * k[1][2] - k[0][2] * k[1][1],
        ],
        [
            k[1][2] * k[2][0] - k[1][0] * k[2][2],
            k[0][0] * k[2][2] - k[0][2] * k[2][0],
            k[0][2] * k[1][0] - k[0][0] * k[1][2],
        ],
        [
            k[1][0] * k[2][1] - k[1][1] * k[2][0],
            k[0][1] * k[2][0] - k[0][0] * k[2][1],
            k[0][0] * k[1][1] - k[0][1] * k[1][0],
        ],
    ]
}

/// Converts a matrix between scalar types.
#[inline(always)]
pub fn cast3<A: Real, B: Real>(m: &M3<A>) -> M3<B> {
    let r = |i: usize| {
        [
            B::c(m[i][0].f64()),
            B::c(m[i][1].f64()),
            B::c(m[i][2].f64()),
        ]
    };
    [r(0), r(1), r(2)]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn products_transposes_and_the_adjugate_agree() {
        let a = [[1.0, 2.0, 0.5], [-1.0, 0.3, 2.0], [0.2, 0.1, 1.5]];
        let b = [[0.7, -0.2, 1.0], [0.4, 1.1, 0.0], [-0.3, 0.6, 0.9]];
        let ab = mul(&a, &b);
        for i in 0..3 {
            for j in 0..3 {
                let want: f64 = (0..3).map(|k| a[i][k] * b[k][j]).sum();
                assert!((ab[i][j] - want).abs() < 1e-15);
            }
        }
        assert_eq!(mul_bt(&a, &b), mul(&a, &transpose(&b)));
        assert_eq!(mul_at(&a, &b), mul(&transpose(&a), &b));
        let p = mul(&adjugate(&a), &a);
        let d = det(&a);
        for i in 0..3 {
            for j in 0..3 {
                let want = if i == j { d } else { 0.0 };
                assert!((p[i][j] - want).abs() < 1e-14, "{p:?}");
            }
        }
        assert_eq!(
            mat_t_vec(&a, &[1.0, 2.0, 3.0]),
            mat_vec(&transpose(&a), &[1.0, 2.0, 3.0])
        );
    }
}
