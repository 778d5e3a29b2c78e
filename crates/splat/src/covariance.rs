//! 3D covariances: from log-scales and a quaternion (`Sigma = R diag(exp s)^2 R^T`), deformed
//! by a deformation gradient (`Sigma' = F Sigma F^T`), and the polar rotation of `F` that
//! rotates the SH lobes; each with its VJP.
//!
//! The polar factor `R` of `F = R S` and its VJP are `r4d_math::polar` (shared with the
//! simulator's SVD; `det R = +1` always, PhysGaussian's sign convention).

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

pub use r4d_math::{polar_rotation, polar_rotation_vjp};
