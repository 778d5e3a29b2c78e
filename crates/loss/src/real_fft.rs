//! Unnormalised DFTs of batches of real rows of one length `n`: forward, real to the
//! `n / 2 + 1` non-negative frequencies, and its inverse, complex (a Hermitian spectrum's
//! non-negative half) to real.
//!
//! For even `n` each row costs one complex FFT of `n / 2` (rustfft, the whole batch in one
//! call) and a pass of twiddles: the even samples are the real parts and the odd samples the
//! imaginary parts of a half-length signal `z`, `E[k] = (Z[k] + conj Z[n/2 - k]) / 2`,
//! `O[k] = (Z[k] - conj Z[n/2 - k]) / 2i` and `X[k] = E[k] + w^k O[k]`, `w = e^(-2 pi i / n)`;
//! the inverse undoes each step. Odd `n` uses a complex FFT of `n` with zero imaginary
//! parts. Rows never mix: a row of zeros gives exactly zeros, in both directions.

use rustfft::num_complex::Complex;
use rustfft::{Fft, FftPlanner};
use std::sync::Arc;

type C64 = Complex<f64>;

/// Forward and inverse real DFTs of rows of `n` values.
#[derive(Clone)]
pub(crate) struct RealFft {
    n: usize,
    /// Complex FFT of `n / 2` (even `n`) or `n` (odd), forward and inverse.
    forward: Arc<dyn Fft<f64>>,
    inverse: Arc<dyn Fft<f64>>,
    /// `e^(-2 pi i k / n)` for `k < n / 2` (even `n`).
    twiddles: Vec<C64>,
}

impl RealFft {
    /// Plans for rows of `n` values (`n >= 1`).
    pub(crate) fn new(n: usize, planner: &mut FftPlanner<f64>) -> Self {
        let len = if n % 2 == 0 { n / 2 } else { n };
        let twiddles = if n % 2 == 0 {
            (0..n / 2)
                .map(|k| {
                    let a = -2.0 * std::f64::consts::PI * k as f64 / n as f64;
                    C64::new(a.cos(), a.sin())
                })
                .collect()
        } else {
            Vec::new()
        };
        RealFft {
            n,
            forward: planner.plan_fft_forward(len),
            inverse: planner.plan_fft_inverse(len),
            twiddles,
        }
    }

    /// Spectrum values per row, `n / 2 + 1`.
    pub(crate) fn bins(&self) -> usize {
        self.n / 2 + 1
    }

    /// Complex values per row of the work buffer the transforms take.
    pub(crate) fn buffer_len(&self) -> usize {
        self.forward.len()
    }

    /// Scratch the transforms take (complex values).
    pub(crate) fn scratch_len(&self) -> usize {
        self.forward
            .get_inplace_scratch_len()
            .max(self.inverse.get_inplace_scratch_len())
    }

    /// `X[r][k] = sum_j x[r][j] e^(-2 pi i j k / n)`, `k <= n / 2`, for every row `r` of `x`
    /// (rows of `n`) into `out` (rows of [`RealFft::bins`]); `buf` holds at least
    /// `rows * buffer_len` values.
    pub(crate) fn forward(&self, x: &[f64], out: &mut [C64], buf: &mut [C64], scratch: &mut [C64]) {
        let (n, nb) = (self.n, self.bins());
        let rows = x.len() / n;
        let m = self.forward.len();
        let buf = &mut buf[..rows * m];
        if n % 2 == 1 {
            for (b, &v) in buf.iter_mut().zip(x) {
                *b = C64::new(v, 0.0);
            }
            self.forward.process_with_scratch(buf, scratch);
            for (o, b) in out.chunks_exact_mut(nb).zip(buf.chunks_exact(m)) {
                o.copy_from_slice(&b[..nb]);
            }
            return;
        }
        for (b, p) in buf.iter_mut().zip(x.chunks_exact(2)) {
            *b = C64::new(p[0], p[1]);
        }
        self.forward.process_with_scratch(buf, scratch);
        for (o, z) in out.chunks_exact_mut(nb).zip(buf.chunks_exact(m)) {
            o[0] = C64::new(z[0].re + z[0].im, 0.0);
            o[m] = C64::new(z[0].re - z[0].im, 0.0);
            for k in 1..m {
                let (a, b) = (z[k], z[m - k].conj());
                let e = (a + b) * 0.5;
                // (a - b) / 2i.
                let d = a - b;
                let od = C64::new(0.5 * d.im, -0.5 * d.re);
                o[k] = e + self.twiddles[k] * od;
            }
        }
    }

    /// `x[r][j] = sum_k X[r][k] e^(2 pi i j k / n)` over every `k < n`, with the negative
    /// frequencies `X[n - k] = conj X[k]`, for every row of `spec` (rows of
    /// [`RealFft::bins`]) into `x` (rows of `n`); the imaginary parts of `X[0]` and (even
    /// `n`) `X[n / 2]` are ignored, i.e. `x` is the real part of the full inverse DFT.
    /// `buf` holds at least `rows * buffer_len` values.
    pub(crate) fn inverse(
        &self,
        spec: &[C64],
        x: &mut [f64],
        buf: &mut [C64],
        scratch: &mut [C64],
    ) {
        let (n, nb) = (self.n, self.bins());
        let rows = spec.len() / nb;
        let m = self.inverse.len();
        let buf = &mut buf[..rows * m];
        if n % 2 == 1 {
            for (b, s) in buf.chunks_exact_mut(m).zip(spec.chunks_exact(nb)) {
                b[0] = C64::new(s[0].re, 0.0);
                for k in 1..nb {
                    b[k] = s[k];
                    b[n - k] = s[k].conj();
                }
            }
            self.inverse.process_with_scratch(buf, scratch);
            for (v, b) in x.iter_mut().zip(buf.iter()) {
                *v = b.re;
            }
            return;
        }
        for (b, s) in buf.chunks_exact_mut(m).zip(spec.chunks_exact(nb)) {
            // E2 = X[k] + conj X[m - k] = 2 E[k], O2 = (X[k] - conj X[m - k]) / w^k = 2 O[k],
            // Z[k] = E2 + i O2.
            let (x0, xm) = (s[0].re, s[m].re);
            b[0] = C64::new(x0 + xm, x0 - xm);
            for k in 1..m {
                let (a, c) = (s[k], s[m - k].conj());
                let e = a + c;
                let o = (a - c) * self.twiddles[k].conj();
                b[k] = C64::new(e.re - o.im, e.im + o.re);
            }
        }
        self.inverse.process_with_scratch(buf, scratch);
        for (p, z) in x.chunks_exact_mut(2).zip(buf.iter()) {
            p[0] = z.re;
            p[1] = z.im;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The direct sums, for rows of every length 1..=17.
    #[test]
    fn forward_and_inverse_match_the_direct_sums() {
        let mut planner = FftPlanner::new();
        for n in 1..=17usize {
            let f = RealFft::new(n, &mut planner);
            let rows = 3;
            let x: Vec<f64> = (0..rows * n)
                .map(|i| ((i * 7919) % 97) as f64 / 97.0 - 0.4)
                .collect();
            let nb = f.bins();
            let mut spec = vec![C64::default(); rows * nb];
            let mut buf = vec![C64::default(); rows * f.buffer_len()];
            let mut scratch = vec![C64::default(); f.scratch_len()];
            f.forward(&x, &mut spec, &mut buf, &mut scratch);
            let w = |j: usize, k: usize, sign: f64| {
                let a = sign * 2.0 * std::f64::consts::PI * ((j * k) % n) as f64 / n as f64;
                C64::new(a.cos(), a.sin())
            };
            for r in 0..rows {
                for k in 0..nb {
                    let want: C64 = (0..n).map(|j| x[r * n + j] * w(j, k, -1.0)).sum();
                    let got = spec[r * nb + k];
                    assert!(
                        (got - want).norm() < 1e-13,
                        "n {n} row {r} k {k}: {got} vs {want}"
                    );
                }
            }
            // The inverse of an arbitrary half spectrum: the real part of the full sum over
            // its Hermitian extension.
            let half: Vec<C64> = (0..rows * nb)
                .map(|i| C64::new((i % 5) as f64 - 2.0, (i % 3) as f64 * 0.7 - 0.5))
                .collect();
            let mut back = vec![0.0; rows * n];
            f.inverse(&half, &mut back, &mut buf, &mut scratch);
            for r in 0..rows {
                let full = |k: usize| {
                    if k < nb {
                        half[r * nb + k]
                    } else {
                        half[r * nb + n - k].conj()
                    }
                };
                for j in 0..n {
                    let want: f64 = (0..n).map(|k| (full(k) * w(j, k, 1.0)).re).sum();
                    let got = back[r * n + j];
                    assert!(
                        (got - want).abs() < 1e-12,
                        "n {n} row {r} j {j}: {got} vs {want}"
                    );
                }
            }
            // Zero rows stay exactly zero.
            let zeros = vec![0.0; rows * n];
            f.forward(&zeros, &mut spec, &mut buf, &mut scratch);
            assert!(spec.iter().all(|c| c.re == 0.0 && c.im == 0.0));
        }
    }
}
