//! The singular value decomposition of a 3x3 matrix with PhysGaussian's sign conventions.

use crate::eigen::sym_eigen_lanes;
use crate::vec3::{cross, dot, norm, scale, sub};
use crate::{sym_eigen, Mat3, Real, Vec3, M3};

/// Singular value decomposition `F = U diag(sigma) V^T` of a 3x3 matrix.
///
/// Conventions (those of McAdams et al. 2011, which PhysGaussian's Warp `svd3` follows):
/// `U` and `V` are proper rotations (det = +1), `sigma[0] >= sigma[1] >= |sigma[2]|`, and
/// `sigma[2]` carries the sign of `det F` (it is negative for an inverted element).
#[derive(Clone, Copy, Debug, Default)]
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
/// The Jacobi iteration's stopping rule is [`sym_eigen`]'s. [`svd3_lanes`] computes several at
/// once with bitwise the same results.
#[inline]
pub fn svd3<T: Real>(f: Mat3<T>) -> Svd3<T> {
    let (_, v) = sym_eigen((f.transpose() * f).0);
    from_right_vectors(f, Mat3(v))
}

/// [`svd3`] of `L` matrices side by side (lane `l` of the result is bitwise `svd3(f[l])`):
/// the Jacobi iterations of the lanes run together ([`sym_eigen_lanes`]), which is several
/// times faster per matrix than one at a time.
#[inline(always)]
pub fn svd3_lanes<T: Real, const L: usize>(f: &[Mat3<T>; L]) -> [Svd3<T>; L] {
    let ata: [M3<T>; L] = std::array::from_fn(|l| (f[l].transpose() * f[l]).0);
    let (_, v) = sym_eigen_lanes(&ata);
    from_right_vectors_lanes(f, &v)
}

/// Number of matrices [`svd3_batch`] decomposes at once.
pub const SVD_BATCH: usize = 8;

/// [`svd3_lanes`] of [`SVD_BATCH`] matrices, compiled for the widest vector instructions the
/// processor has (AVX2 on x86-64 when present, detected at run time): bitwise the results of
/// [`svd3`] for each matrix, about three times faster per matrix than one at a time.
#[inline]
pub fn svd3_batch<T: Real>(f: &[Mat3<T>; SVD_BATCH]) -> [Svd3<T>; SVD_BATCH] {
    #[cfg(target_arch = "x86_64")]
    if std::is_x86_feature_detected!("avx2") {
        // SAFETY: the processor supports AVX2 (checked just above).
        return unsafe { svd3_batch_avx2(f) };
    }
    svd3_lanes(f)
}

/// [`svd3_lanes`] compiled with AVX2 enabled (same arithmetic: no fused operations).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn svd3_batch_avx2<T: Real>(f: &[Mat3<T>; SVD_BATCH]) -> [Svd3<T>; SVD_BATCH] {
    svd3_lanes(f)
}

/// The SVDs of `f`, [`SVD_BATCH`] at a time ([`svd3_batch`]; the remainder one by one),
/// written to `out` (the same length as `f`). Bitwise [`svd3`] of each matrix.
pub fn svd3_many<T: Real>(f: &[Mat3<T>], out: &mut [Svd3<T>]) {
    assert_eq!(f.len(), out.len(), "svd3_many: one output per matrix");
    let mut fc = f.chunks_exact(SVD_BATCH);
    let mut oc = out.chunks_exact_mut(SVD_BATCH);
    for (fb, ob) in (&mut fc).zip(&mut oc) {
        let fb: &[Mat3<T>; SVD_BATCH] = fb.try_into().expect("exact chunk");
        ob.copy_from_slice(&svd3_batch(fb));
    }
    for (fi, oi) in fc.remainder().iter().zip(oc.into_remainder()) {
        *oi = svd3(*fi);
    }
}

/// The SVD of `f` from its right singular vectors `vm` (a rotation, columns ordered by
/// descending singular value): `U` and the singular values by Gram-Schmidt QR of `F V`.
#[inline(always)]
fn from_right_vectors<T: Real>(f: Mat3<T>, vm: Mat3<T>) -> Svd3<T> {
    from_right_vectors_lanes(&[f], &[vm.0])[0]
}

/// [`from_right_vectors`] of `L` matrices side by side, lane by lane in structure-of-arrays
/// form so that the compiler vectorises the lane loops (the products, the square roots and
/// the divisions of every lane run together). Each lane's arithmetic is exactly the one-lane
/// arithmetic; the rare fallback for a rank-deficient `F` runs lane by lane afterwards.
#[inline(always)]
fn from_right_vectors_lanes<T: Real, const L: usize>(
    f: &[Mat3<T>; L],
    vm: &[M3<T>; L],
) -> [Svd3<T>; L] {
    let (zero, one) = (T::zero(), T::one());
    let tiny = T::min_positive_value();
    let eps = T::epsilon();
    // B = F V (b[row][col][lane]); QR by Gram-Schmidt: U = Q (a rotation), sigma = diag(R).
    let mut b = [[[zero; L]; 3]; 3];
    for (r, br) in b.iter_mut().enumerate() {
        for (c, brc) in br.iter_mut().enumerate() {
            for (l, x) in brc.iter_mut().enumerate() {
                let (fr, v) = (&f[l].0[r], &vm[l]);
                *x = fr[0] * v[0][c] + fr[1] * v[1][c] + fr[2] * v[2][c];
            }
        }
    }
    let col = |c: usize, l: usize| [b[0][c][l], b[1][c][l], b[2][c][l]];
    let mut n0 = [zero; L];
    let mut u0 = [[zero; L]; 3];
    let mut n1 = [zero; L];
    let mut u1 = [[zero; L]; 3];
    let mut regular = [true; L];
    for l in 0..L {
        let (b0, b1) = (col(0, l), col(1, l));
        n0[l] = norm(b0);
        let inv0 = one / n0[l];
        let u = if n0[l] > tiny {
            scale(b0, inv0)
        } else {
            [one, zero, zero]
        };
        let w = sub(b1, scale(u, dot(u, b1)));
        n1[l] = norm(w);
        regular[l] = n1[l] > eps * n0[l].max(one) * T::c(1e-3) && n1[l] > tiny;
        let inv1 = one / n1[l];
        for a in 0..3 {
            u0[a][l] = u[a];
            u1[a][l] = w[a] * inv1;
        }
    }
    for l in 0..L {
        if !regular[l] {
            let o = any_orthogonal([u0[0][l], u0[1][l], u0[2][l]]);
            for a in 0..3 {
                u1[a][l] = o[a];
            }
        }
    }
    std::array::from_fn(|l| {
        let u0 = [u0[0][l], u0[1][l], u0[2][l]];
        let u1 = [u1[0][l], u1[1][l], u1[2][l]];
        let u2 = cross(u0, u1);
        let s2 = dot(u2, col(2, l));
        Svd3 {
            u: Mat3::from_cols(u0, u1, u2),
            sigma: [n0[l], dot(u1, col(1, l)), s2],
            v: Mat3(vm[l]),
        }
    })
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
    fn batches_give_bitwise_the_single_results() {
        let mut seed = 7u64;
        let mut rnd = || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((seed >> 11) as f64 / (1u64 << 53) as f64) * 2.0 - 1.0
        };
        // Mixed: near identity, general, rank-deficient, inverted, exactly diagonal.
        let f: Vec<Mat3<f32>> = (0..37)
            .map(|i| match i % 5 {
                0 => {
                    Mat3::identity()
                        + Mat3::from_array(std::array::from_fn(|_| 1e-3 * rnd() as f32))
                }
                1 => Mat3::from_array(std::array::from_fn(|_| rnd() as f32)),
                2 => Mat3::from_array([1.0, 2.0, 3.0, 2.0, 4.0, 6.0, 1.0, 0.0, 1.0]),
                3 => Mat3::diag([1.0, -1.0, 0.5]),
                _ => Mat3::identity(),
            })
            .collect();
        let mut out = vec![svd3(Mat3::<f32>::zero()); f.len()];
        svd3_many(&f, &mut out);
        for (fi, b) in f.iter().zip(&out) {
            let a = svd3(*fi);
            assert_eq!(
                a.u.to_array().map(f32::to_bits),
                b.u.to_array().map(f32::to_bits)
            );
            assert_eq!(
                a.v.to_array().map(f32::to_bits),
                b.v.to_array().map(f32::to_bits)
            );
            assert_eq!(a.sigma.map(f32::to_bits), b.sigma.map(f32::to_bits));
        }
        let fd: Vec<Mat3<f64>> = f.iter().map(|m| m.cast()).collect();
        let mut outd = vec![svd3(Mat3::<f64>::zero()); fd.len()];
        svd3_many(&fd, &mut outd);
        for (fi, b) in fd.iter().zip(&outd) {
            let a = svd3(*fi);
            assert_eq!(
                a.u.to_array().map(f64::to_bits),
                b.u.to_array().map(f64::to_bits)
            );
            assert_eq!(
                a.v.to_array().map(f64::to_bits),
                b.v.to_array().map(f64::to_bits)
            );
            assert_eq!(a.sigma.map(f64::to_bits), b.sigma.map(f64::to_bits));
        }
        // The portable lanes (what runs without AVX2) give the same bits too.
        let first: &[Mat3<f32>; SVD_BATCH] = f[..SVD_BATCH].try_into().unwrap();
        for (fi, b) in first.iter().zip(svd3_lanes(first)) {
            let a = svd3(*fi);
            assert_eq!(
                a.u.to_array().map(f32::to_bits),
                b.u.to_array().map(f32::to_bits)
            );
            assert_eq!(a.sigma.map(f32::to_bits), b.sigma.map(f32::to_bits));
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
