//! The layers of an LPIPS backbone on a band of rows: convolution + bias + ReLU (as
//! matrix products through `matrixmultiply`), max-pool, and the per-tap distance (unit
//! normalisation over channels, squared difference, linear head, summed over pixels).
//!
//! Feature maps are channel-major (`C x rows x W`, f32) and hold rows `row0..row0 + rows`
//! of their level; zero padding is applied only at the level's true borders, so a band's
//! rows equal the whole frame's.
//!
//! Every convolution runs as Winograd `F(m x m, k x k)` (see [`super::winograd`]): tiles of
//! the zero-padded input are transformed, multiplied by the transformed weights in
//! `alpha^2` GEMMs, and transformed back, chunk by chunk of tiles. AlexNet's first layer
//! (11x11, stride 4) is first rewritten as a stride-1 3x3 convolution over the
//! space-to-depth image (`super::input`).

use std::ops::Range;

use super::arch::ConvSpec;
use super::winograd::Transform;

/// A feature map band: rows `row0..row0 + rows` of a level, `c x rows x w`, f32.
#[derive(Clone, Debug)]
pub(crate) struct Band {
    pub c: usize,
    pub row0: usize,
    pub rows: usize,
    pub w: usize,
    pub data: Vec<f32>,
}

impl Band {
    fn plane(&self) -> usize {
        self.rows * self.w
    }
}

/// `C (m x n, row stride rsc) = A (m x k) B (k x n) + beta C`, single-threaded f32 GEMM.
///
/// # Safety
/// Every index the strides reach must lie inside the given slices (checked by the callers'
/// geometry and by debug assertions on the last element).
#[allow(clippy::too_many_arguments)]
fn gemm(
    m: usize,
    k: usize,
    n: usize,
    a: &[f32],
    (rsa, csa): (usize, usize),
    b: &[f32],
    (rsb, csb): (usize, usize),
    beta: f32,
    c: &mut [f32],
    rsc: usize,
) {
    if m == 0 || n == 0 {
        return;
    }
    assert!(
        (m - 1) * rsa + (k - 1) * csa < a.len(),
        "gemm: A out of bounds"
    );
    assert!(
        (k - 1) * rsb + (n - 1) * csb < b.len(),
        "gemm: B out of bounds"
    );
    assert!((m - 1) * rsc + n - 1 < c.len(), "gemm: C out of bounds");
    // SAFETY: the asserts above keep every element matrixmultiply reads or writes inside
    // the slices; `c` is borrowed mutably and does not alias `a` or `b`.
    unsafe {
        matrixmultiply::sgemm(
            m,
            k,
            n,
            1.0,
            a.as_ptr(),
            rsa as isize,
            csa as isize,
            b.as_ptr(),
            rsb as isize,
            csb as isize,
            beta,
            c.as_mut_ptr(),
            rsc as isize,
            1,
        );
    }
}

impl Band {
    /// Writes channel `c`, level row `y` (of a level `h` rows high), zero-padded by `pad`
    /// columns on both sides, into `dst`; zeros for rows outside the level or the band
    /// (the latter only feed outputs that are discarded).
    pub(crate) fn padded_row(&self, c: usize, y: isize, h: usize, pad: usize, dst: &mut [f32]) {
        dst.fill(0.0);
        if y < 0
            || y as usize >= h
            || (y as usize) < self.row0
            || y as usize >= self.row0 + self.rows
        {
            return;
        }
        let r = y as usize - self.row0;
        dst[pad..pad + self.w]
            .copy_from_slice(&self.data[c * self.plane() + r * self.w..][..self.w]);
    }
}

/// Target size of the Winograd chunk buffers, in f32 values (4 MiB each).
pub(crate) const WINOGRAD_CHUNK: usize = 4 << 20;

/// Stride-1 convolution + bias + ReLU of a band by Winograd `F(m x m, k x k)`: output rows
/// `out` (the input band holds every level row they need; `h_in` rows in the level).
/// The Winograd-domain weights `U[xi][co][ci] = (G w G^T)[xi]` of a stride-1 convolution
/// (`alpha^2 x Cout x Cin`), made once per band and used for both images.
pub(crate) fn winograd_weights(spec: &ConvSpec, weight: &[f32], tf: &Transform) -> Vec<f32> {
    let (k, a) = (spec.k, tf.alpha);
    let (cin, cout) = (spec.cin, spec.cout);
    let a2 = a * a;
    let g: Vec<f32> = tf.g.iter().map(|&x| x as f32).collect();
    let mut u = vec![0.0f32; a2 * cout * cin];
    let mut tmp = [0.0f32; 64];
    for co in 0..cout {
        for ci in 0..cin {
            let w = &weight[(co * cin + ci) * k * k..][..k * k];
            super::winograd::sandwich(&g, a, w, k, &mut tmp);
            for (xi, &v) in tmp[..a2].iter().enumerate() {
                u[(xi * cout + co) * cin + ci] = v;
            }
        }
    }
    u
}

/// Stride-1 convolution + bias + ReLU of a band by Winograd `F(m x m, k x k)`, with the
/// weights `u` from [`winograd_weights`]: output rows `out` (the input band holds every
/// level row they need; `h_in` rows in the level).
pub(crate) fn conv_winograd(
    spec: &ConvSpec,
    u: &[f32],
    bias: &[f32],
    x: &Band,
    h_in: usize,
    out: Range<usize>,
    tf: &Transform,
) -> Band {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: the CPU has AVX2, checked just above.
        return unsafe { conv_winograd_avx2(spec, u, bias, x, h_in, out, tf) };
    }
    conv_winograd_body(spec, u, bias, x, h_in, out, tf)
}

/// [`conv_winograd`] compiled for AVX2 (8-lane transforms; the same arithmetic, so the same
/// values, as the baseline build).
///
/// # Safety
/// The CPU must support AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn conv_winograd_avx2(
    spec: &ConvSpec,
    u: &[f32],
    bias: &[f32],
    x: &Band,
    h_in: usize,
    out: Range<usize>,
    tf: &Transform,
) -> Band {
    conv_winograd_body(spec, u, bias, x, h_in, out, tf)
}

#[inline(always)]
fn conv_winograd_body(
    spec: &ConvSpec,
    u: &[f32],
    bias: &[f32],
    x: &Band,
    h_in: usize,
    out: Range<usize>,
    tf: &Transform,
) -> Band {
    assert!(spec.stride == 1 && tf.r == spec.k && x.c == spec.cin && tf.alpha <= 8);
    let (m, k, p, a) = (tf.m, spec.k, spec.pad, tf.alpha);
    let (cin, cout) = (spec.cin, spec.cout);
    let a2 = a * a;
    assert_eq!(u.len(), a2 * cout * cin);
    let rows = out.len();
    let w_out = x.w + 2 * p - k + 1;
    let (n_ty, n_tx) = (rows.div_ceil(m), w_out.div_ceil(m));
    let tiles = n_ty * n_tx;
    let f = |v: &[f64]| v.iter().map(|&x| x as f32).collect::<Vec<f32>>();
    let (at, bt) = (f(&tf.at), f(&tf.bt));
    // Zero-padded input: row i = level row out.start - p + i, column j = level column j - p;
    // whole tiles (outputs past the band's end read zeros and are dropped).
    let prow = n_ty * m + k - 1;
    let wp = (n_tx * m + k - 1).max(x.w + 2 * p);
    let mut padded = vec![0.0f32; cin * prow * wp];
    for c in 0..cin {
        for i in 0..prow {
            let y = out.start as isize - p as isize + i as isize;
            x.padded_row(
                c,
                y,
                h_in,
                p,
                &mut padded[(c * prow + i) * wp..][..x.w + 2 * p],
            );
        }
    }
    let mut data = vec![0.0f32; cout * rows * w_out];
    let chunk = (WINOGRAD_CHUNK / (a2 * cin.max(cout))).clamp(16, tiles.max(16));
    let cap = chunk.min(tiles);
    let mut v = vec![0.0f32; a2 * cin * cap];
    let mut mm = vec![0.0f32; a2 * cout * cap];
    // Per-channel scratch: gathered tiles and the half-transformed ones (alpha^2 x tiles).
    let mut d = vec![0.0f32; a2 * cap];
    let mut e = vec![0.0f32; a2 * cap];
    let mut t0 = 0;
    while t0 < tiles {
        let nt = chunk.min(tiles - t0);
        // Runs of consecutive tiles in one tile row: (first tile in the chunk, count, row
        // and column of the first tile's origin).
        let mut runs = Vec::new();
        let mut t = t0;
        while t < t0 + nt {
            let (ty, tx) = (t / n_tx, t % n_tx);
            let len = (n_tx - tx).min(t0 + nt - t);
            runs.push((t - t0, len, ty * m, tx * m));
            t += len;
        }
        // Input transform, vectorised over tiles: V = B^T d B per channel.
        for c in 0..cin {
            let plane = &padded[c * prow * wp..][..prow * wp];
            for i in 0..a {
                for j in 0..a {
                    let dst = &mut d[(i * a + j) * nt..][..nt];
                    for &(ts, len, y0, x0) in &runs {
                        let src = plane[(y0 + i) * wp + x0 + j..].iter().step_by(m);
                        for (val, &x) in dst[ts..ts + len].iter_mut().zip(src) {
                            *val = x;
                        }
                    }
                }
            }
            // e[i][xc] = sum_j B^T[xc][j] d[i][j]
            for i in 0..a {
                for xc in 0..a {
                    let dst = &mut e[(i * a + xc) * nt..][..nt];
                    lincomb(
                        dst,
                        (0..a).map(|j| (bt[xc * a + j], &d[(i * a + j) * nt..][..nt])),
                    );
                }
            }
            // V[xr][xc] = sum_i B^T[xr][i] e[i][xc]
            for xr in 0..a {
                for xc in 0..a {
                    let dst = &mut v[((xr * a + xc) * cin + c) * nt..][..nt];
                    lincomb(
                        dst,
                        (0..a).map(|i| (bt[xr * a + i], &e[(i * a + xc) * nt..][..nt])),
                    );
                }
            }
        }
        for xi in 0..a2 {
            gemm(
                cout,
                cin,
                nt,
                &u[xi * cout * cin..],
                (cin, 1),
                &v[xi * cin * nt..],
                (nt, 1),
                0.0,
                &mut mm[xi * cout * nt..],
                nt,
            );
        }
        // Output transform, vectorised over tiles: Y = A^T M A, + bias, ReLU, scattered.
        for (co, &b) in bias.iter().enumerate() {
            // e[i][xc] = sum_xr A^T[i][xr] M[xr][xc]
            for i in 0..m {
                for xc in 0..a {
                    let dst = &mut e[(i * a + xc) * nt..][..nt];
                    lincomb(
                        dst,
                        (0..a).map(|xr| {
                            (
                                at[i * a + xr],
                                &mm[((xr * a + xc) * cout + co) * nt..][..nt],
                            )
                        }),
                    );
                }
            }
            let out_plane = &mut data[co * rows * w_out..][..rows * w_out];
            for i in 0..m {
                for j in 0..m {
                    // y[i][j] = sum_xc A^T[j][xc] e[i][xc]
                    let y = &mut d[..nt];
                    y.fill(b);
                    for xc in 0..a {
                        axpy(y, at[j * a + xc], &e[(i * a + xc) * nt..][..nt]);
                    }
                    for &(ts, len, y0, x0) in &runs {
                        if y0 + i >= rows || x0 + j >= w_out {
                            continue;
                        }
                        let n = (w_out - x0 - j).div_ceil(m).min(len);
                        let row = &mut out_plane[(y0 + i) * w_out + x0 + j..];
                        for (o, &val) in row.iter_mut().step_by(m).zip(&y[ts..ts + n]) {
                            *o = val.max(0.0);
                        }
                    }
                }
            }
        }
        t0 += nt;
    }
    Band {
        c: cout,
        row0: out.start,
        rows,
        w: w_out,
        data,
    }
}

/// Max-pool (`k x k`, stride `s`, no padding) of a band: output rows `out`. (Inputs are
/// ReLU outputs, never NaN.)
pub(crate) fn max_pool(x: &Band, k: usize, s: usize, out: Range<usize>) -> Band {
    let w_out = (x.w - k) / s + 1;
    let rows = out.len();
    let mut data = vec![0.0f32; x.c * rows * w_out];
    let mut colmax = vec![0.0f32; x.w];
    for c in 0..x.c {
        let plane = &x.data[c * x.plane()..(c + 1) * x.plane()];
        for (r, y) in out.clone().enumerate() {
            let r0 = y * s - x.row0;
            assert!(r0 + k <= x.rows, "max_pool: rows outside the band");
            // Maximum over the window's rows, then over its columns.
            colmax.copy_from_slice(&plane[r0 * x.w..][..x.w]);
            for dy in 1..k {
                for (m, &v) in colmax.iter_mut().zip(&plane[(r0 + dy) * x.w..][..x.w]) {
                    *m = m.max(v);
                }
            }
            let dst = &mut data[(c * rows + r) * w_out..][..w_out];
            for (xo, d) in dst.iter_mut().enumerate() {
                *d = colmax[xo * s..xo * s + k]
                    .iter()
                    .fold(f32::NEG_INFINITY, |m, &v| m.max(v));
            }
        }
    }
    Band {
        c: x.c,
        row0: out.start,
        rows,
        w: w_out,
        data,
    }
}

/// The lpips package's `normalize_tensor` epsilon.
const EPS: f32 = 1e-10;

/// `sum over pixels of rows `owned` of head . (a / (|a| + eps) - b / (|b| + eps))^2`, the
/// norms over channels per pixel, in f32 per pixel as PyTorch, summed in f64.
pub(crate) fn tap_distance(a: &Band, b: &Band, head: &[f32], owned: Range<usize>) -> f64 {
    if owned.is_empty() {
        return 0.0;
    }
    debug_assert!(a.row0 == b.row0 && a.rows == b.rows && a.w == b.w && a.c == head.len());
    let off = (owned.start - a.row0) * a.w;
    let n = owned.len() * a.w;
    let plane = a.plane();
    let mut na = vec![0.0f32; n];
    let mut nb = vec![0.0f32; n];
    for c in 0..a.c {
        let pa = &a.data[c * plane + off..][..n];
        let pb = &b.data[c * plane + off..][..n];
        for i in 0..n {
            na[i] += pa[i] * pa[i];
            nb[i] += pb[i] * pb[i];
        }
    }
    for v in na.iter_mut().chain(nb.iter_mut()) {
        *v = 1.0 / (v.sqrt() + EPS);
    }
    let mut acc = vec![0.0f32; n];
    for (c, &wc) in head.iter().enumerate() {
        let pa = &a.data[c * plane + off..][..n];
        let pb = &b.data[c * plane + off..][..n];
        for i in 0..n {
            let d = pa[i] * na[i] - pb[i] * nb[i];
            acc[i] += wc * (d * d);
        }
    }
    acc.iter().map(|&v| v as f64).sum()
}

/// `dst = sum coef * src` over the terms with a non-zero coefficient (the transforms are
/// sparse).
#[inline(always)]
fn lincomb<'a>(dst: &mut [f32], terms: impl Iterator<Item = (f32, &'a [f32])>) {
    let mut first = true;
    for (coef, src) in terms {
        if coef == 0.0 {
            continue;
        }
        if first {
            for (d, &s) in dst.iter_mut().zip(src) {
                *d = coef * s;
            }
            first = false;
        } else {
            axpy(dst, coef, src);
        }
    }
    if first {
        dst.fill(0.0);
    }
}

/// `dst += coef * src` (skipped for a zero coefficient: the transforms are sparse).
#[inline(always)]
fn axpy(dst: &mut [f32], coef: f32, src: &[f32]) {
    if coef == 0.0 {
        return;
    }
    for (d, &s) in dst.iter_mut().zip(src) {
        *d += coef * s;
    }
}
