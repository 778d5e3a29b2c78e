//! Eigen-decomposition of a symmetric 3x3 matrix by cyclic Jacobi rotations, one matrix at a
//! time ([`sym_eigen`]) or several side by side ([`sym_eigen_lanes`]).
//!
//! Both are the same code: [`sym_eigen`] is [`sym_eigen_lanes`] with one lane. Each lane's
//! arithmetic is independent of the others' (a lane whose iteration has converged is frozen
//! by exact no-op rotations), so a matrix gets bitwise the same result alone or in a batch.
//! Batches exist for speed: the rotations are a long chain of dependent square roots and
//! divisions, and a batch keeps several chains in flight (the compiler vectorises the lane
//! loops).

use crate::m3::{det, eye3, M3};
use crate::Real;

/// The six distinct entries of symmetric 3x3 matrices, one array of lanes each:
/// `[a00, a11, a22, a01, a02, a12]`.
type Sym<T, const L: usize> = [[T; L]; 6];

/// Rotation matrices, lane by lane: `v[row][col][lane]`.
type Rot<T, const L: usize> = [[[T; L]; 3]; 3];

/// One Jacobi rotation in the `(p, q)` plane of every lane (`pq`, `pr`, `qr`: the positions
/// of those off-diagonal entries in [`Sym`], `r` the third axis): `A <- J^T A J`,
/// `V <- V J` with the classic symmetric Schur rotation (Golub & Van Loan 8.4.2), which
/// zeroes `a_pq`. Only the entries the rotation changes are updated, in the form that keeps
/// round-off lowest (`a_pp - t a_pq`, `a_qq + t a_pq`). Lanes that are not `live`, and lanes
/// whose `a_pq` is below the smallest normal number, are left exactly as they are.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn rotate<T: Real, const L: usize>(
    a: &mut Sym<T, L>,
    v: &mut Rot<T, L>,
    live: &[bool; L],
    p: usize,
    q: usize,
    pq: usize,
    pr: usize,
    qr: usize,
) {
    let (zero, one, two) = (T::zero(), T::one(), T::c(2.0));
    let tiny = T::min_positive_value();
    // Beyond 2^64, 1 + tau^2 overflows (f32) and t is 0 in the limit; the GPU twin tests it
    // explicitly rather than relying on IEEE infinities.
    let huge = T::c(18446744073709551616.0);
    let mut c = [one; L];
    let mut sn = [zero; L];
    let mut t = [zero; L];
    let mut keep = [true; L];
    for l in 0..L {
        let apq = a[pq][l];
        let tau = (a[q][l] - a[p][l]) / (two * apq);
        // t = sign(tau) / (|tau| + sqrt(1 + tau^2)), the smaller root of t^2 + 2 tau t = 1;
        // written without branches so that the lanes vectorise.
        let sign = if tau >= zero { one } else { -one };
        let tl = sign / (tau.abs() + (one + tau * tau).sqrt());
        let rotate = live[l] & (apq.abs() > tiny) & (tau.abs() < huge);
        let tl = if rotate { tl } else { zero };
        let cl = one / (one + tl * tl).sqrt();
        keep[l] = !(live[l] & (apq.abs() > tiny));
        t[l] = tl;
        c[l] = cl;
        sn[l] = tl * cl;
    }
    for l in 0..L {
        let apq = a[pq][l];
        a[p][l] -= t[l] * apq;
        a[q][l] += t[l] * apq;
        a[pq][l] = if keep[l] { apq } else { zero };
        let (arp, arq) = (a[pr][l], a[qr][l]);
        a[pr][l] = c[l] * arp - sn[l] * arq;
        a[qr][l] = sn[l] * arp + c[l] * arq;
    }
    for row in v.iter_mut() {
        for l in 0..L {
            let (vp, vq) = (row[p][l], row[q][l]);
            row[p][l] = c[l] * vp - sn[l] * vq;
            row[q][l] = sn[l] * vp + c[l] * vq;
        }
    }
}

/// Eigenvalues (descending) and eigenvectors (the columns of a proper rotation, `det = +1`)
/// of the symmetric matrix `a`, by cyclic Jacobi: [`sym_eigen_lanes`] with one lane.
///
/// The iteration stops when the off-diagonal mass is below `T::epsilon()^2` relative to the
/// diagonal's (or below the smallest normal number), after at most 12 sweeps; 3x3 Jacobi
/// converges quadratically, 3-4 sweeps is usual. `a` is read as the symmetric matrix whose
/// off-diagonal entries are the averages of `a`'s two triangles.
#[inline]
pub fn sym_eigen<T: Real>(a: M3<T>) -> ([T; 3], M3<T>) {
    let (lam, v) = sym_eigen_lanes(&[a]);
    (lam[0], v[0])
}

/// [`sym_eigen`] of `L` matrices side by side: lane `l` of the result is bitwise
/// `sym_eigen(a[l])`. Every lane runs until its own stopping rule holds (the batch until all
/// do); each rotation updates only the five entries it changes and sets the one it
/// annihilates to zero.
#[inline(always)]
pub fn sym_eigen_lanes<T: Real, const L: usize>(a: &[M3<T>; L]) -> ([[T; 3]; L], [M3<T>; L]) {
    let (zero, one, half) = (T::zero(), T::one(), T::c(0.5));
    let mut s: Sym<T, L> = [[zero; L]; 6];
    for l in 0..L {
        let m = &a[l];
        s[0][l] = m[0][0];
        s[1][l] = m[1][1];
        s[2][l] = m[2][2];
        s[3][l] = half * (m[0][1] + m[1][0]);
        s[4][l] = half * (m[0][2] + m[2][0]);
        s[5][l] = half * (m[1][2] + m[2][1]);
    }
    let mut v: Rot<T, L> = [[[zero; L]; 3]; 3];
    for i in 0..3 {
        v[i][i] = [one; L];
    }
    let eps2 = T::epsilon() * T::epsilon();
    let tiny = T::min_positive_value();
    let mut live = [true; L];
    for _sweep in 0..12 {
        let mut any = false;
        for l in 0..L {
            let off = s[3][l] * s[3][l] + s[4][l] * s[4][l] + s[5][l] * s[5][l];
            let diag = s[0][l] * s[0][l] + s[1][l] * s[1][l] + s[2][l] * s[2][l];
            live[l] = live[l] && !(off <= eps2 * diag || off <= tiny);
            any |= live[l];
        }
        if !any {
            break;
        }
        // Pairs (0, 1), (0, 2), (1, 2); the third axis's entries follow.
        rotate(&mut s, &mut v, &live, 0, 1, 3, 4, 5);
        rotate(&mut s, &mut v, &live, 0, 2, 4, 3, 5);
        rotate(&mut s, &mut v, &live, 1, 2, 5, 3, 4);
    }
    let mut lams = [[zero; 3]; L];
    let mut vs = [eye3::<T>(); L];
    for l in 0..L {
        let mut vl: M3<T> = std::array::from_fn(|i| std::array::from_fn(|j| v[i][j][l]));
        let (lam, vl) = sort_and_orient([s[0][l], s[1][l], s[2][l]], &mut vl);
        lams[l] = lam;
        vs[l] = vl;
    }
    (lams, vs)
}

/// Sorts eigenvalues descending together with the columns of `v`, then makes `v` a proper
/// rotation.
#[inline(always)]
fn sort_and_orient<T: Real>(mut lam: [T; 3], v: &mut M3<T>) -> ([T; 3], M3<T>) {
    let swap = |lam: &mut [T; 3], v: &mut M3<T>, i: usize, j: usize| {
        lam.swap(i, j);
        for row in v.iter_mut() {
            row.swap(i, j);
        }
    };
    if lam[0] < lam[1] {
        swap(&mut lam, v, 0, 1);
    }
    if lam[0] < lam[2] {
        swap(&mut lam, v, 0, 2);
    }
    if lam[1] < lam[2] {
        swap(&mut lam, v, 1, 2);
    }
    // Make V a proper rotation.
    if det(v) < T::zero() {
        for row in v.iter_mut() {
            row[2] = -row[2];
        }
    }
    (lam, *v)
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
