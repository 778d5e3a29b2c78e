//! The layers of an LPIPS backbone on a band of rows: convolution + bias + ReLU (as
//! matrix products through `matrixmultiply`), max-pool, and the per-tap distance (unit
//! normalisation over channels, squared difference, linear head, summed over pixels).
//!
//! Feature maps are channel-major (`C x rows x W`, f32) and hold rows `row0..row0 + rows`
//! of their level; zero padding is applied only at the level's true borders, so a band's
//! rows equal the whole frame's.
//!
//! Convolutions with stride 1 are `k x k` accumulated products `W[:, :, ky, kx] (Cout x
//! Cin)` times the zero-padded input shifted by `(ky, kx)`: with the input padded to width
//! `Wp = W + 2p`, that shifted input is a plain strided matrix (`Cin x n`), so no im2col
//! copy is made; the output has `Wp - Wout` spare columns per row, dropped when bias and
//! ReLU are applied. Other convolutions (AlexNet's first, stride 4, three input channels)
//! build im2col columns in chunks of output rows.

use std::ops::Range;

use super::arch::ConvSpec;

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

    /// The value at channel `c`, level row `y`, column `x`; zero outside the level (padding),
    /// which must not be outside the band.
    #[inline]
    fn get(&self, c: usize, y: isize, x: isize, level_rows: usize) -> f32 {
        if y < 0 || x < 0 || y as usize >= level_rows || x as usize >= self.w {
            return 0.0;
        }
        let r = y as usize - self.row0;
        debug_assert!(r < self.rows, "row {y} outside the band");
        self.data[c * self.plane() + r * self.w + x as usize]
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

/// Adds the bias and applies ReLU to `cout x rows x wp` values, keeping the first `w` of
/// each row: the result is `cout x rows x w`, compacted in place.
fn bias_relu_compact(data: &mut Vec<f32>, bias: &[f32], rows: usize, wp: usize, w: usize) {
    let cout = bias.len();
    let mut dst = 0;
    for (co, &b) in bias.iter().enumerate() {
        for r in 0..rows {
            let src = (co * rows + r) * wp;
            for x in 0..w {
                let v = data[src + x] + b;
                data[dst] = if v > 0.0 { v } else { 0.0 };
                dst += 1;
            }
        }
    }
    debug_assert_eq!(dst, cout * rows * w);
    data.truncate(dst);
    data.shrink_to_fit();
}

/// Target size of one im2col chunk, in f32 values (8 MiB).
const IM2COL_CHUNK: usize = 2 << 20;

/// Convolution + bias + ReLU by im2col, for any stride: output rows `out` (of a level
/// `w_out` wide) from the input level of `h_in x w_in` read through `src(c, y, x)` (zero
/// outside the level is the caller's job).
#[allow(clippy::too_many_arguments)]
pub(crate) fn conv_im2col(
    spec: &ConvSpec,
    weight: &[f32],
    bias: &[f32],
    out: Range<usize>,
    w_out: usize,
    src: impl Fn(usize, isize, isize) -> f32,
) -> Band {
    let (k, s, p) = (spec.k, spec.stride, spec.pad as isize);
    let kk = spec.cin * k * k;
    let rows = out.len();
    let mut data = vec![0.0f32; spec.cout * rows * w_out];
    let chunk_rows = (IM2COL_CHUNK / (kk * w_out).max(1)).clamp(1, rows.max(1));
    let mut cols = vec![0.0f32; kk * chunk_rows * w_out];
    let mut r = 0;
    while r < rows {
        let nr = chunk_rows.min(rows - r);
        let n = nr * w_out;
        for ci in 0..spec.cin {
            for ky in 0..k {
                for kx in 0..k {
                    let row = (ci * k + ky) * k + kx;
                    let dst = &mut cols[row * n..(row + 1) * n];
                    for rr in 0..nr {
                        let y = ((out.start + r + rr) * s) as isize - p + ky as isize;
                        for x in 0..w_out {
                            dst[rr * w_out + x] = src(ci, y, (x * s) as isize - p + kx as isize);
                        }
                    }
                }
            }
        }
        gemm(
            spec.cout,
            kk,
            n,
            weight,
            (kk, 1),
            &cols[..kk * n],
            (n, 1),
            0.0,
            &mut data[r * w_out..],
            rows * w_out,
        );
        r += nr;
    }
    bias_relu_compact(&mut data, bias, rows, w_out, w_out);
    Band {
        c: spec.cout,
        row0: out.start,
        rows,
        w: w_out,
        data,
    }
}

/// Convolution + bias + ReLU of a band (`h_in` rows in its level): output rows `out`.
/// Stride-1 convolutions use shifted products over a zero-padded copy; others im2col.
pub(crate) fn conv(
    spec: &ConvSpec,
    weight: &[f32],
    bias: &[f32],
    x: &Band,
    h_in: usize,
    out: Range<usize>,
) -> Band {
    debug_assert_eq!(x.c, spec.cin);
    let (k, p) = (spec.k, spec.pad);
    if spec.stride != 1 {
        let w_out = (x.w + 2 * p - k) / spec.stride + 1;
        return conv_im2col(spec, weight, bias, out, w_out, |c, y, xx| {
            x.get(c, y, xx, h_in)
        });
    }
    let rows = out.len();
    let wp = x.w + 2 * p;
    let w_out = wp - k + 1;
    let prow = rows + k - 1;
    // Zero-padded input: row i is level row out.start - p + i.
    let mut padded = vec![0.0f32; spec.cin * prow * wp];
    for c in 0..spec.cin {
        for i in 0..prow {
            let y = (out.start + i) as isize - p as isize;
            if y < 0 || y as usize >= h_in {
                continue;
            }
            let r = y as usize - x.row0;
            assert!(r < x.rows, "conv: level row {y} is not in the band");
            let s = &x.data[c * x.plane() + r * x.w..][..x.w];
            padded[(c * prow + i) * wp + p..][..x.w].copy_from_slice(s);
        }
    }
    let mut data = vec![0.0f32; spec.cout * rows * wp];
    let n = (rows - 1) * wp + w_out;
    let kk = k * k;
    for ky in 0..k {
        for kx in 0..k {
            let tap = ky * k + kx;
            gemm(
                spec.cout,
                spec.cin,
                n,
                &weight[tap..],
                (spec.cin * kk, kk),
                &padded[ky * wp + kx..],
                (prow * wp, 1),
                if tap == 0 { 0.0 } else { 1.0 },
                &mut data,
                rows * wp,
            );
        }
    }
    drop(padded);
    bias_relu_compact(&mut data, bias, rows, wp, w_out);
    Band {
        c: spec.cout,
        row0: out.start,
        rows,
        w: w_out,
        data,
    }
}

/// Max-pool (`k x k`, stride `s`, no padding) of a band: output rows `out`.
pub(crate) fn max_pool(x: &Band, k: usize, s: usize, out: Range<usize>) -> Band {
    let w_out = (x.w - k) / s + 1;
    let rows = out.len();
    let mut data = vec![0.0f32; x.c * rows * w_out];
    for c in 0..x.c {
        let plane = &x.data[c * x.plane()..(c + 1) * x.plane()];
        for (r, y) in out.clone().enumerate() {
            let r0 = y * s - x.row0;
            assert!(r0 + k <= x.rows, "max_pool: rows outside the band");
            let dst = &mut data[(c * rows + r) * w_out..][..w_out];
            for (xo, d) in dst.iter_mut().enumerate() {
                let mut m = f32::NEG_INFINITY;
                for dy in 0..k {
                    let row = &plane[(r0 + dy) * x.w + xo * s..][..k];
                    for &v in row {
                        if v > m || v.is_nan() {
                            m = v;
                        }
                    }
                }
                *d = m;
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
