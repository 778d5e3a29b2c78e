//! Real spherical harmonics up to degree 3 with the INRIA / gsplat ordering and signs, and
//! their derivatives with respect to the (unit) direction.

use crate::real::{Real, V3};

/// The degree-0 SH basis constant `1 / (2 sqrt(pi))`: colour = `SH_C0 c + 0.5`.
pub const SH_C0: f64 = 0.282_094_791_773_878_14;
const C0: f64 = SH_C0;
const C1: f64 = 0.488_602_511_902_919_9;
const C2A: f64 = 1.092_548_430_592_079_2;
const C6: f64 = 0.315_391_565_252_520_05;
const C8: f64 = 0.546_274_215_296_039_6;
const C9: f64 = 0.590_043_589_926_643_5;
const C10: f64 = 2.890_611_442_640_554;
const C11: f64 = 0.457_045_799_464_465_8;
const C12: f64 = 0.373_176_332_590_115_4;
const C14: f64 = 1.445_305_721_320_277;

/// The basis `Y_0 .. Y_{K-1}` at the unit direction `d` (entries past `K` are 0), and, when
/// `grad` is given, `dY_k / dd` (with `d` treated as a free 3-vector).
pub fn basis<T: Real>(degree: u32, d: &V3<T>, grad: Option<&mut [V3<T>; 16]>) -> [T; 16] {
    let c = T::c;
    let (x, y, z) = (d[0], d[1], d[2]);
    let mut b = [T::zero(); 16];
    let z0 = T::zero();
    let mut g = [[z0; 3]; 16];
    b[0] = c(C0);
    if degree >= 1 {
        b[1] = -c(C1) * y;
        b[2] = c(C1) * z;
        b[3] = -c(C1) * x;
        g[1] = [z0, -c(C1), z0];
        g[2] = [z0, z0, c(C1)];
        g[3] = [-c(C1), z0, z0];
    }
    if degree >= 2 {
        let (xx, yy, zz) = (x * x, y * y, z * z);
        b[4] = c(C2A) * x * y;
        b[5] = -c(C2A) * y * z;
        b[6] = c(C6) * (c(2.0) * zz - xx - yy);
        b[7] = -c(C2A) * x * z;
        b[8] = c(C8) * (xx - yy);
        g[4] = [c(C2A) * y, c(C2A) * x, z0];
        g[5] = [z0, -c(C2A) * z, -c(C2A) * y];
        g[6] = [-c(2.0 * C6) * x, -c(2.0 * C6) * y, c(4.0 * C6) * z];
        g[7] = [-c(C2A) * z, z0, -c(C2A) * x];
        g[8] = [c(2.0 * C8) * x, -c(2.0 * C8) * y, z0];
    }
    if degree >= 3 {
        let (xx, yy, zz) = (x * x, y * y, z * z);
        let three = c(3.0);
        b[9] = -c(C9) * y * (three * xx - yy);
        b[10] = c(C10) * x * y * z;
        b[11] = -c(C11) * y * (c(4.0) * zz - xx - yy);
        b[12] = c(C12) * z * (c(2.0) * zz - three * xx - three * yy);
        b[13] = -c(C11) * x * (c(4.0) * zz - xx - yy);
        b[14] = c(C14) * z * (xx - yy);
        b[15] = -c(C9) * x * (xx - three * yy);
        g[9] = [-c(6.0 * C9) * x * y, -c(C9) * (three * xx - three * yy), z0];
        g[10] = [c(C10) * y * z, c(C10) * x * z, c(C10) * x * y];
        g[11] = [
            c(2.0 * C11) * x * y,
            -c(C11) * (c(4.0) * zz - xx - three * yy),
            -c(8.0 * C11) * y * z,
        ];
        g[12] = [
            -c(6.0 * C12) * x * z,
            -c(6.0 * C12) * y * z,
            c(C12) * (c(6.0) * zz - three * xx - three * yy),
        ];
        g[13] = [
            -c(C11) * (c(4.0) * zz - three * xx - yy),
            c(2.0 * C11) * x * y,
            -c(8.0 * C11) * x * z,
        ];
        g[14] = [
            c(2.0 * C14) * x * z,
            -c(2.0 * C14) * y * z,
            c(C14) * (xx - yy),
        ];
        g[15] = [-c(C9) * (three * xx - three * yy), c(6.0 * C9) * x * y, z0];
    }
    if let Some(out) = grad {
        *out = g;
    }
    b
}

/// Colour from SH: `max(sum_k Y_k(normalize(dir)) sh[k][c] + 0.5, 0)`; `sh` is `[k][c]`.
pub fn eval<T: Real>(degree: u32, sh: &[T], dir: &V3<T>) -> [T; 3] {
    let n = (dir[0] * dir[0] + dir[1] * dir[1] + dir[2] * dir[2]).sqrt();
    let d = if n > T::zero() {
        dir.map(|v| v / n)
    } else {
        [T::zero(); 3]
    };
    let b = basis(degree, &d, None);
    let k = ((degree + 1) * (degree + 1)) as usize;
    let mut col = [T::c(0.5); 3];
    for kk in 0..k {
        for ch in 0..3 {
            col[ch] += b[kk] * sh[kk * 3 + ch];
        }
    }
    col.map(|v| v.max(T::zero()))
}

/// VJP of [`eval`]: adds `dL/dsh` into `d_sh` (`[k][c]`) and returns `dL/ddir` (through the
/// normalisation). `d_col` is `dL/dcolour`.
pub fn eval_vjp<T: Real>(
    degree: u32,
    sh: &[T],
    dir: &V3<T>,
    d_col: &[T; 3],
    d_sh: &mut [T],
) -> V3<T> {
    let n = (dir[0] * dir[0] + dir[1] * dir[1] + dir[2] * dir[2]).sqrt();
    if n <= T::zero() {
        return [T::zero(); 3];
    }
    let d = dir.map(|v| v / n);
    let mut gb = [[T::zero(); 3]; 16];
    let b = basis(degree, &d, Some(&mut gb));
    let k = ((degree + 1) * (degree + 1)) as usize;
    // Colour before the clamp: gradient passes where it is >= 0 (torch.clamp_min).
    let mut raw = [T::c(0.5); 3];
    for kk in 0..k {
        for ch in 0..3 {
            raw[ch] += b[kk] * sh[kk * 3 + ch];
        }
    }
    let g = [0, 1, 2].map(|ch| {
        if raw[ch] >= T::zero() {
            d_col[ch]
        } else {
            T::zero()
        }
    });
    let mut d_d = [T::zero(); 3];
    for kk in 0..k {
        let mut w = T::zero();
        for ch in 0..3 {
            d_sh[kk * 3 + ch] += b[kk] * g[ch];
            w += sh[kk * 3 + ch] * g[ch];
        }
        for a in 0..3 {
            d_d[a] += w * gb[kk][a];
        }
    }
    // Through d = dir / |dir|.
    let dd = d[0] * d_d[0] + d[1] * d_d[1] + d[2] * d_d[2];
    [0, 1, 2].map(|a| (d_d[a] - d[a] * dd) / n)
}
