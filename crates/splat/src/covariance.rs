//! 3D covariances: from log-scales and a quaternion (`Sigma = R diag(exp s)^2 R^T`), deformed
//! by a deformation gradient (`Sigma' = F Sigma F^T`), and the polar rotation of `F` that
//! rotates the SH lobes; each with its VJP.
//!
//! The polar factor `R` of `F = R S` is computed in f64 from the eigen-decomposition of
//! `F^T F` (cyclic Jacobi), with `det R = +1` always: for `det F < 0` the sign goes to the
//! smallest singular value, as in the SVD convention of PhysGaussian and the reference. Its
//! VJP solves `(tr(S) I - S) y = m` (the skew part of `R^T dL/dR`) and returns `R [y]x`; the
//! system is singular only when two singular values sum to 0 (F of rank <= 1, or an inverted
//! element with `s_i = -s_j`), where the solve is regularised by clamping `|det|` at
//! `1e-12 tr(S)^3`.

use crate::real::*;

/// Rotation matrix of a unit quaternion `(w, x, y, z)`.
pub fn quat_to_rot<T: Real>(q: &[T; 4]) -> M3<T> {
    let (w, x, y, z) = (q[0], q[1], q[2], q[3]);
    let (one, two) = (T::one(), T::c(2.0));
    [
        [
            one - two * (y * y + z * z),
            two * (x * y - w * z),
            two * (x * z + w * y),
        ],
        [
            two * (x * y + w * z),
            one - two * (x * x + z * z),
            two * (y * z - w * x),
        ],
        [
            two * (x * z - w * y),
            two * (y * z + w * x),
            one - two * (x * x + y * y),
        ],
    ]
}

/// VJP of [`quat_to_rot`]: `dL/dq` (unit `q` treated as free) from `dL/dR`.
pub fn quat_to_rot_vjp<T: Real>(q: &[T; 4], g: &M3<T>) -> [T; 4] {
    let (w, x, y, z) = (q[0], q[1], q[2], q[3]);
    let t = T::c(2.0);
    let f = T::c(4.0);
    let gw =
        t * (-z * g[0][1] + y * g[0][2] + z * g[1][0] - x * g[1][2] - y * g[2][0] + x * g[2][1]);
    let gx = t
        * (y * g[0][1] + z * g[0][2] + y * g[1][0] - w * g[1][2] + z * g[2][0] + w * g[2][1])
        - f * x * (g[1][1] + g[2][2]);
    let gy = t
        * (x * g[0][1] + w * g[0][2] + x * g[1][0] + z * g[1][2] - w * g[2][0] + z * g[2][1])
        - f * y * (g[0][0] + g[2][2]);
    let gz = t
        * (-w * g[0][1] + x * g[0][2] + w * g[1][0] + y * g[1][2] + x * g[2][0] + y * g[2][1])
        - f * z * (g[0][0] + g[1][1]);
    [gw, gx, gy, gz]
}

/// `Sigma = R diag(exp(log_scale))^2 R^T` with `R` from the normalised quaternion.
pub fn covariance<T: Real>(log_scale: &V3<T>, quat: &[T; 4]) -> M3<T> {
    let n = (quat[0] * quat[0] + quat[1] * quat[1] + quat[2] * quat[2] + quat[3] * quat[3]).sqrt();
    let q = quat.map(|v| v / n);
    let r = quat_to_rot(&q);
    let s = log_scale.map(|v| v.exp());
    let mut m = r;
    for i in 0..3 {
        for j in 0..3 {
            m[i][j] = r[i][j] * s[j];
        }
    }
    mul_bt(&m, &m)
}

/// VJP of [`covariance`]: `(dL/dlog_scale, dL/dquat)` from `dL/dSigma` (any matrix; its
/// symmetric part is what matters).
pub fn covariance_vjp<T: Real>(
    log_scale: &V3<T>,
    quat: &[T; 4],
    g_sigma: &M3<T>,
) -> (V3<T>, [T; 4]) {
    let n = (quat[0] * quat[0] + quat[1] * quat[1] + quat[2] * quat[2] + quat[3] * quat[3]).sqrt();
    let q = quat.map(|v| v / n);
    let r = quat_to_rot(&q);
    let s = log_scale.map(|v| v.exp());
    let mut m = r;
    for i in 0..3 {
        for j in 0..3 {
            m[i][j] = r[i][j] * s[j];
        }
    }
    // Sigma = M M^T: dL/dM = (G + G^T) M.
    let gs = add(g_sigma, &transpose(g_sigma));
    let g_m = mul(&gs, &m);
    let mut g_r = zero3();
    let mut g_ls = [T::zero(); 3];
    for i in 0..3 {
        for j in 0..3 {
            g_r[i][j] = g_m[i][j] * s[j];
            g_ls[j] += g_m[i][j] * r[i][j] * s[j];
        }
    }
    let g_qn = quat_to_rot_vjp(&q, &g_r);
    let dot = (0..4).fold(T::zero(), |a, i| a + g_qn[i] * q[i]);
    let g_q = [0, 1, 2, 3].map(|i| (g_qn[i] - q[i] * dot) / n);
    (g_ls, g_q)
}

/// `F Sigma F^T`.
pub fn deform_covariance<T: Real>(f: &M3<T>, sigma: &M3<T>) -> M3<T> {
    mul_bt(&mul(f, sigma), f)
}

/// VJP of [`deform_covariance`]: `(dL/dSigma, dL/dF)` from `dL/dSigma'`.
pub fn deform_covariance_vjp<T: Real>(f: &M3<T>, sigma: &M3<T>, g: &M3<T>) -> (M3<T>, M3<T>) {
    let g_sigma = mul(&mul_at(f, g), f);
    // d/dF tr(G^T F S F^T) = G F S^T + G^T F S.
    let g_f = add(&mul_bt(&mul(g, f), sigma), &mul(&mul_at(g, f), sigma));
    // mul_at(g, f) = g^T f.
    (g_sigma, g_f)
}

/// Symmetric 3x3 eigen-decomposition by cyclic Jacobi: eigenvalues descending and the
/// eigenvectors as the columns of a proper rotation.
pub(crate) fn sym_eigen(mut a: M3<f64>) -> ([f64; 3], M3<f64>) {
    let mut v = eye3::<f64>();
    let scale = a.iter().flatten().fold(0.0f64, |m, x| m.max(x.abs()));
    for _ in 0..60 {
        let off = a[0][1] * a[0][1] + a[0][2] * a[0][2] + a[1][2] * a[1][2];
        if off <= (1e-30 * scale * scale).max(f64::MIN_POSITIVE) {
            break;
        }
        for (p, q) in [(0, 1), (0, 2), (1, 2)] {
            if a[p][q] == 0.0 {
                continue;
            }
            let theta = (a[q][q] - a[p][p]) / (2.0 * a[p][q]);
            let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
            let c = 1.0 / (t * t + 1.0).sqrt();
            let s = t * c;
            for k in 0..3 {
                let (akp, akq) = (a[k][p], a[k][q]);
                a[k][p] = c * akp - s * akq;
                a[k][q] = s * akp + c * akq;
            }
            for k in 0..3 {
                let (apk, aqk) = (a[p][k], a[q][k]);
                a[p][k] = c * apk - s * aqk;
                a[q][k] = s * apk + c * aqk;
            }
            for k in 0..3 {
                let (vkp, vkq) = (v[k][p], v[k][q]);
                v[k][p] = c * vkp - s * vkq;
                v[k][q] = s * vkp + c * vkq;
            }
        }
    }
    let mut idx = [0usize, 1, 2];
    idx.sort_by(|&i, &j| a[j][j].total_cmp(&a[i][i]));
    let lam = idx.map(|i| a[i][i]);
    let mut vs = zero3::<f64>();
    for (c, &i) in idx.iter().enumerate() {
        for r in 0..3 {
            vs[r][c] = v[r][i];
        }
    }
    if det(&vs) < 0.0 {
        for r in 0..3 {
            vs[r][2] = -vs[r][2];
        }
    }
    (lam, vs)
}

/// The rotation factor `R` of the polar decomposition `F = R S` (`det R = +1`).
pub fn polar_rotation<T: Real>(f: &M3<T>) -> M3<T> {
    let f64m: M3<f64> = cast3(f);
    let (lam, v) = sym_eigen(mul_at(&f64m, &f64m));
    let sig = lam.map(|l| l.max(0.0).sqrt());
    if sig[0].is_nan() || sig[0] <= 0.0 || !sig[0].is_finite() {
        return eye3();
    }
    let col = |m: &M3<f64>, c: usize| [m[0][c], m[1][c], m[2][c]];
    let fv = |c: usize| mat_vec(&f64m, &col(&v, c));
    let norm = |a: [f64; 3]| (a[0] * a[0] + a[1] * a[1] + a[2] * a[2]).sqrt();
    let u0 = fv(0).map(|x| x / sig[0]);
    let mut u1 = fv(1);
    let d = dot(&u1, &u0);
    for i in 0..3 {
        u1[i] -= d * u0[i];
    }
    let n1 = norm(u1);
    let u1 = if n1 > 1e-12 * sig[0] {
        u1.map(|x| x / n1)
    } else {
        // Rank 1: any unit vector orthogonal to u0.
        let a = if u0[0].abs() < 0.9 {
            [1.0, 0.0, 0.0]
        } else {
            [0.0, 1.0, 0.0]
        };
        let c = cross(&u0, &a);
        let nc = norm(c);
        c.map(|x| x / nc)
    };
    let u2 = cross(&u0, &u1);
    let u = [0, 1, 2].map(|r| [u0[r], u1[r], u2[r]]);
    cast3(&mul_bt(&u, &v))
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
    let adj = [
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
    ];
    let y = mat_vec(&adj, &mv).map(|x| x / dk);
    let yx = [[0.0, -y[2], y[1]], [y[2], 0.0, -y[0]], [-y[1], y[0], 0.0]];
    cast3(&mul(&r, &yx))
}
