//! The rotation factor of the polar decomposition `F = R S` and its VJP.
//!
//! `R` is computed in f64 as `U V^T` of [`svd3`], so `det R = +1` always: for `det F < 0` the
//! sign goes to the smallest singular value (PhysGaussian's SVD convention). The VJP solves
//! `(tr(S) I - S) y = m` (the skew part of `R^T dL/dR`) and returns `R [y]x`; the system is
//! singular only when two singular values sum to 0 (F of rank <= 1, or an inverted element
//! with `s_i = -s_j`), where the solve is regularised by clamping `|det|` at
//! `1e-12 tr(S)^3`.

use crate::m3::{adjugate, cast3, det, eye3, mat_vec, mul, mul_at, M3};
use crate::{svd3, Mat3, Real};

/// The rotation factor `R` of the polar decomposition `F = R S` (`det R = +1`); the identity
/// for a zero or non-finite `F`.
pub fn polar_rotation<T: Real>(f: &M3<T>) -> M3<T> {
    let f64m: Mat3<f64> = Mat3(cast3(f));
    if !f64m.is_finite() || f64m.frobenius() == 0.0 {
        return eye3();
    }
    cast3(&svd3(f64m).rotation().0)
}

/// VJP of [`polar_rotation`]: `dL/dF` from `dL/dR` (`r` is the forward result).
pub fn polar_rotation_vjp<T: Real>(f: &M3<T>, r: &M3<T>, g_r: &M3<T>) -> M3<T> {
    let (f, r, g): (M3<f64>, M3<f64>, M3<f64>) = (cast3(f), cast3(r), cast3(g_r));
    let s0 = mul_at(&r, &f);
    let mut s = s0;
    for i in 0..3 {
        for j in 0..3 {
            s[i][j] = 0.5 * (s0[i][j] + s0[j][i]);
        }
    }
    let m = mul_at(&r, &g);
    let mv = [m[2][1] - m[1][2], m[0][2] - m[2][0], m[1][0] - m[0][1]];
    let tr = s[0][0] + s[1][1] + s[2][2];
    let mut k = s.map(|row| row.map(|x| -x));
    for i in 0..3 {
        k[i][i] += tr;
    }
    let dk = det(&k);
    let floor = 1e-12 * tr.abs().powi(3).max(f64::MIN_POSITIVE);
    let dk = if dk.abs() < floor {
        floor.copysign(if dk == 0.0 { 1.0 } else { dk })
    } else {
        dk
    };
    // k is symmetric: inverse = adjugate / det.
    let y = mat_vec(&adjugate(&k), &mv).map(|x| x / dk);
    let yx = [[0.0, -y[2], y[1]], [y[2], 0.0, -y[0]], [-y[1], y[0], 0.0]];
    cast3(&mul(&r, &yx))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::m3::zero3;

    #[test]
    fn polar_rotation_is_a_rotation_and_its_vjp_matches_fd() {
        let mut seed = 3u64;
        let mut rnd = |lo: f64, hi: f64| {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            lo + (hi - lo) * ((seed >> 11) as f64 / (1u64 << 53) as f64)
        };
        for case in 0..20 {
            let mut f = eye3::<f64>();
            for row in f.iter_mut() {
                for v in row.iter_mut() {
                    *v = rnd(-1.0, 1.0) + *v * 0.5;
                }
            }
            if case == 0 {
                f = [[2.0, 0.0, 0.0], [0.0, 2.0, 0.0], [0.0, 0.0, 0.5]]; // repeated singular values
            }
            let rot = polar_rotation(&f);
            assert!((det(&rot) - 1.0).abs() < 1e-12, "det R");
            let s = mul_at(&rot, &f);
            for i in 0..3 {
                for j in 0..3 {
                    assert!((s[i][j] - s[j][i]).abs() < 1e-10, "S symmetric");
                }
            }
            if det(&f) <= 0.0 {
                continue; // sign convention: S has a negative eigenvalue, still a valid factor
            }
            let mut g = zero3::<f64>();
            for row in g.iter_mut() {
                for v in row.iter_mut() {
                    *v = rnd(-1.0, 1.0);
                }
            }
            let an = polar_rotation_vjp(&f, &rot, &g);
            let l = |f: &M3<f64>| {
                let r = polar_rotation(f);
                (0..9)
                    .map(|k| r[k / 3][k % 3] * g[k / 3][k % 3])
                    .sum::<f64>()
            };
            for a in 0..3 {
                for b in 0..3 {
                    let mut p = f;
                    p[a][b] += 1e-6;
                    let mut m = f;
                    m[a][b] -= 1e-6;
                    let fd = (l(&p) - l(&m)) / 2e-6;
                    assert!(
                        (fd - an[a][b]).abs() < 1e-6 * (1.0 + fd.abs()),
                        "{fd} vs {}",
                        an[a][b]
                    );
                }
            }
        }
    }
}
