//! The singular value decomposition of a 3x3 matrix with PhysGaussian's sign conventions.

use crate::vec3::{cross, dot, norm, scale, sub};
use crate::{sym_eigen, Mat3, Real, Vec3};

/// Singular value decomposition `F = U diag(sigma) V^T` of a 3x3 matrix.
///
/// Conventions (those of McAdams et al. 2011, which PhysGaussian's Warp `svd3` follows):
/// `U` and `V` are proper rotations (det = +1), `sigma[0] >= sigma[1] >= |sigma[2]|`, and
/// `sigma[2]` carries the sign of `det F` (it is negative for an inverted element).
#[derive(Clone, Copy, Debug)]
pub struct Svd3<T> {
    /// Left rotation.
    pub u: Mat3<T>,
    /// Singular values, see the type docs for order and sign.
    pub sigma: Vec3<T>,
    /// Right rotation.
    pub v: Mat3<T>,
}

impl<T: Real> Svd3<T> {
    /// Reassembles `U diag(s) V^T` with other singular values.
    #[inline(always)]
    pub fn compose(&self, s: Vec3<T>) -> Mat3<T> {
        self.u.mul_diag(s) * self.v.transpose()
    }
    /// The rotation `U V^T` (the polar rotation of `F`).
    #[inline(always)]
    pub fn rotation(&self) -> Mat3<T> {
        self.u * self.v.transpose()
    }
}

/// Computes the SVD of `f`: [`sym_eigen`] of `F^T F` for `V`, then a Gram-Schmidt QR of `F V`
/// for `U` (robust when `F` is rank-deficient: `U` stays a rotation).
///
/// The Jacobi iteration's stopping rule is [`sym_eigen`]'s.
pub fn svd3<T: Real>(f: Mat3<T>) -> Svd3<T> {
    let (_, v) = sym_eigen((f.transpose() * f).0);
    let vm = Mat3(v);
    let tiny = T::min_positive_value();
    let eps = T::epsilon();
    // B = F V; QR by Gram-Schmidt: U = Q (a rotation), sigma = diag(R).
    let b = f * vm;
    let b0 = b.col(0);
    let b1 = b.col(1);
    let b2 = b.col(2);
    let n0 = norm(b0);
    let u0 = if n0 > tiny {
        scale(b0, T::one() / n0)
    } else {
        [T::one(), T::zero(), T::zero()]
    };
    let r01 = dot(u0, b1);
    let w1 = sub(b1, scale(u0, r01));
    let n1 = norm(w1);
    let u1 = if n1 > eps * n0.max(T::one()) * T::c(1e-3) && n1 > tiny {
        scale(w1, T::one() / n1)
    } else {
        any_orthogonal(u0)
    };
    let u2 = cross(u0, u1);
    let s2 = dot(u2, b2);
    Svd3 {
        u: Mat3::from_cols(u0, u1, u2),
        sigma: [n0, dot(u1, b1), s2],
        v: vm,
    }
}

/// A unit vector orthogonal to the unit vector `a`.
fn any_orthogonal<T: Real>(a: Vec3<T>) -> Vec3<T> {
    let e = if a[0].abs() < T::c(0.6) {
        [T::one(), T::zero(), T::zero()]
    } else {
        [T::zero(), T::one(), T::zero()]
    };
    let w = sub(e, scale(a, dot(a, e)));
    scale(w, T::one() / norm(w))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn check(f: Mat3<f64>, tol: f64) {
        let s = svd3(f);
        let r = s.compose(s.sigma);
        assert!(
            (r - f).frobenius() <= tol * f.frobenius().max(1.0),
            "{f:?} -> {s:?}"
        );
        assert!((s.u.det() - 1.0).abs() < 1e-9);
        assert!((s.v.det() - 1.0).abs() < 1e-9);
        assert!((s.u.transpose() * s.u - Mat3::identity()).frobenius() < 1e-9);
        assert!(s.sigma[0] >= s.sigma[1] - 1e-12 && s.sigma[1] >= s.sigma[2].abs() - 1e-12);
        assert_eq!(s.sigma[2] < 0.0, f.det() < 0.0, "{f:?} {s:?}");
    }

    #[test]
    fn svd_reconstructs_general_degenerate_and_inverted_matrices() {
        check(Mat3::identity(), 1e-12);
        check(Mat3::zero(), 1e-12);
        check(Mat3::diag([2.0, 2.0, 2.0]), 1e-12);
        check(Mat3::diag([1.0, -1.0, 1.0]), 1e-12);
        check(Mat3::diag([3.0, 1e-9, 0.0]), 1e-12);
        check(
            Mat3::from_array([1.0, 2.0, 3.0, 2.0, 4.0, 6.0, 1.0, 0.0, 1.0]),
            1e-12,
        );
        let mut seed = 12345u64;
        let mut rnd = || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((seed >> 11) as f64 / (1u64 << 53) as f64) * 2.0 - 1.0
        };
        for _ in 0..2000 {
            let f = Mat3::from_array(std::array::from_fn(|_| rnd()));
            check(f, 1e-11);
            let near = Mat3::identity() + Mat3::from_array(std::array::from_fn(|_| 1e-4 * rnd()));
            check(near, 1e-12);
        }
    }

    #[test]
    fn svd_f32_is_accurate_near_identity() {
        let f = Mat3::<f32>::from_array([1.001, 0.002, 0.0, -0.001, 0.999, 0.0005, 0.0, 0.0, 1.0]);
        let s = svd3(f);
        let r = s.compose(s.sigma);
        assert!((r - f).frobenius() < 1e-6);
    }
}
