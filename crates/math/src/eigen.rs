//! Eigen-decomposition of a symmetric 3x3 matrix by cyclic Jacobi rotations.

use crate::m3::{det, eye3, M3};
use crate::Real;

/// Eigenvalues (descending) and eigenvectors (the columns of a proper rotation, `det = +1`)
/// of the symmetric matrix `a`, by cyclic Jacobi.
///
/// The iteration stops when the off-diagonal mass is below `T::epsilon()^2` relative to the
/// diagonal's (or below the smallest normal number), after at most 12 sweeps; 3x3 Jacobi
/// converges quadratically, 4-5 sweeps is usual. Only the upper and lower triangles'
/// average matters for a matrix that is symmetric up to rounding.
pub fn sym_eigen<T: Real>(a: M3<T>) -> ([T; 3], M3<T>) {
    let mut s = a;
    let mut v = eye3::<T>();
    let eps = T::epsilon();
    let tiny = T::min_positive_value();
    for _sweep in 0..12 {
        let off = s[0][1] * s[0][1] + s[0][2] * s[0][2] + s[1][2] * s[1][2];
        let diag = s[0][0] * s[0][0] + s[1][1] * s[1][1] + s[2][2] * s[2][2];
        if off <= eps * eps * diag || off <= tiny {
            break;
        }
        for &(p, q) in &[(0usize, 1usize), (0, 2), (1, 2)] {
            let apq = s[p][q];
            if apq.abs() <= tiny {
                continue;
            }
            // Classic symmetric Schur rotation (Golub & Van Loan 8.4.2).
            let tau = (s[q][q] - s[p][p]) / (T::c(2.0) * apq);
            let t = if tau >= T::zero() {
                T::one() / (tau + (T::one() + tau * tau).sqrt())
            } else {
                -T::one() / (-tau + (T::one() + tau * tau).sqrt())
            };
            let c = T::one() / (T::one() + t * t).sqrt();
            let sn = t * c;
            // S <- J^T S J with J the rotation in the (p, q) plane.
            for k in 0..3 {
                let skp = s[k][p];
                let skq = s[k][q];
                s[k][p] = c * skp - sn * skq;
                s[k][q] = sn * skp + c * skq;
            }
            for k in 0..3 {
                let spk = s[p][k];
                let sqk = s[q][k];
                s[p][k] = c * spk - sn * sqk;
                s[q][k] = sn * spk + c * sqk;
            }
            for row in v.iter_mut() {
                let vp = row[p];
                let vq = row[q];
                row[p] = c * vp - sn * vq;
                row[q] = sn * vp + c * vq;
            }
        }
    }
    // Sort eigenvalues descending together with the columns of V.
    let mut lam = [s[0][0], s[1][1], s[2][2]];
    let swap = |lam: &mut [T; 3], v: &mut M3<T>, i: usize, j: usize| {
        lam.swap(i, j);
        for row in v.iter_mut() {
            row.swap(i, j);
        }
    };
    if lam[0] < lam[1] {
        swap(&mut lam, &mut v, 0, 1);
    }
    if lam[0] < lam[2] {
        swap(&mut lam, &mut v, 0, 2);
    }
    if lam[1] < lam[2] {
        swap(&mut lam, &mut v, 1, 2);
    }
    // Make V a proper rotation.
    if det(&v) < T::zero() {
        for row in v.iter_mut() {
            row[2] = -row[2];
        }
    }
    (lam, v)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::m3::{mul, mul_bt};

    #[test]
    fn reconstructs_symmetric_matrices_with_sorted_eigenvalues() {
        let mut seed = 99u64;
        let mut rnd = || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((seed >> 11) as f64 / (1u64 << 53) as f64) * 2.0 - 1.0
        };
        for case in 0..500 {
            let b: M3<f64> = std::array::from_fn(|_| std::array::from_fn(|_| rnd()));
            let a = if case % 7 == 0 {
                eye3()
            } else {
                mul_bt(&b, &b)
            };
            let (lam, v) = sym_eigen(a);
            assert!(lam[0] >= lam[1] && lam[1] >= lam[2], "{lam:?}");
            assert!((det(&v) - 1.0).abs() < 1e-12);
            let d = [[lam[0], 0.0, 0.0], [0.0, lam[1], 0.0], [0.0, 0.0, lam[2]]];
            let r = mul_bt(&mul(&v, &d), &v);
            for i in 0..3 {
                for j in 0..3 {
                    assert!((r[i][j] - a[i][j]).abs() < 1e-12, "{a:?} {r:?}");
                }
            }
        }
    }
}
