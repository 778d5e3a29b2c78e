//! Row kernels of the separable SSIM filters, with a runtime-selected AVX2+FMA build.
//!
//! The hot loops of SSIM are short FIR filters over long contiguous rows: `out[e] =
//! sum_d taps[d] * rows[d][e]`, where `rows[d]` is a row of the input (the vertical pass) or
//! the same row shifted by `d` pixels (the horizontal pass). Each kernel is written once as
//! an `#[inline(always)]` generic function over blocks of contiguous values (which LLVM
//! vectorises), and instantiated twice: plain (the target's baseline, SSE2 on x86-64) and
//! inside a `#[target_feature(enable = "avx2,fma")]` function, chosen at runtime by
//! [`Isa::detect`]. Fused multiply-adds change rounding only (~1 ulp per operation).
//!
//! A block holds as many independent sums as it takes to hide the latency of a fused
//! multiply-add (4 cycles, 2 per cycle: 8 vector registers of sums), so the loops run at the
//! throughput of the FMA units instead of waiting on one chain. The block width does not
//! change any value: each sum still runs over the taps in order.

use crate::real::Real;

/// Values per block of the wide loops in f64 (twice as many in f32): 8 AVX registers of
/// independent sums, enough to cover the latency of a chain of fused multiply-adds.
const WIDE: usize = 32;

/// Values per block of the tails of the wide loops, and of the three-sum kernel in f64.
const NARROW: usize = 8;

/// Values per block of the three-sum kernel in f64 (twice as many in f32).
const L: usize = 16;

/// The instruction set the row kernels use.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Isa {
    /// The compilation target's baseline.
    Generic,
    /// x86-64 with AVX2 and FMA (detected at runtime).
    #[cfg(target_arch = "x86_64")]
    Avx2Fma,
}

impl Isa {
    /// The best instruction set of this CPU.
    pub(crate) fn detect() -> Isa {
        #[cfg(target_arch = "x86_64")]
        {
            if std::arch::is_x86_feature_detected!("avx2")
                && std::arch::is_x86_feature_detected!("fma")
            {
                return Isa::Avx2Fma;
            }
        }
        Isa::Generic
    }
}

#[inline(always)]
fn madd<S: Real, const FMA: bool>(a: S, b: S, c: S) -> S {
    if FMA {
        a.mul_add(b, c)
    } else {
        a * b + c
    }
}

/// `out[e] = sum_d taps[d] * rows[d][e]` for every `e < out.len()`.
pub(crate) fn conv<S: Real>(isa: Isa, out: &mut [S], rows: &[&[S]], taps: &[S]) {
    debug_assert_eq!(rows.len(), taps.len());
    debug_assert!(rows.iter().all(|r| r.len() >= out.len()));
    match isa {
        Isa::Generic => conv_impl::<S, false>(out, rows, taps),
        #[cfg(target_arch = "x86_64")]
        // SAFETY: `Isa::Avx2Fma` is only produced by `Isa::detect` after checking that the
        // CPU supports AVX2 and FMA.
        Isa::Avx2Fma => unsafe { conv_avx2(out, rows, taps) },
    }
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn conv_avx2<S: Real>(out: &mut [S], rows: &[&[S]], taps: &[S]) {
    conv_impl::<S, true>(out, rows, taps)
}

#[inline(always)]
fn conv_impl<S: Real, const FMA: bool>(out: &mut [S], rows: &[&[S]], taps: &[S]) {
    let e = if std::mem::size_of::<S>() == 4 {
        conv_blocks::<S, FMA, { 2 * WIDE }>(out, rows, taps, 0)
    } else {
        conv_blocks::<S, FMA, WIDE>(out, rows, taps, 0)
    };
    let e = conv_blocks::<S, FMA, NARROW>(out, rows, taps, e);
    for (k, o) in out.iter_mut().enumerate().skip(e) {
        let mut a = S::zero();
        for (row, &g) in rows.iter().zip(taps) {
            a = madd::<S, FMA>(g, row[k], a);
        }
        *o = a;
    }
}

/// [`conv_impl`] over blocks of `B` values from `e` while a whole block fits; returns where
/// it stopped. Each value's sum runs over the taps in order, whatever `B`.
#[inline(always)]
fn conv_blocks<S: Real, const FMA: bool, const B: usize>(
    out: &mut [S],
    rows: &[&[S]],
    taps: &[S],
    mut e: usize,
) -> usize {
    let n = out.len();
    while e + B <= n {
        let mut acc = [S::zero(); B];
        for (row, &g) in rows.iter().zip(taps) {
            let r = &row[e..e + B];
            for l in 0..B {
                acc[l] = madd::<S, FMA>(g, r[l], acc[l]);
            }
        }
        out[e..e + B].copy_from_slice(&acc);
        e += B;
    }
    e
}

/// The vertical pass of the five statistics in one pass over the input rows:
/// `out[0][e] = sum_d taps[d] x[d][e]`, `out[1]` the same of `y`, `out[2]` of `x^2`,
/// `out[3]` of `y^2` and `out[4]` of `x y`, each product formed (and rounded) as its rows are
/// read, so only `x` and `y` are loaded: the same values as filtering stored product rows.
pub(crate) fn stats_vertical<S: Real>(
    isa: Isa,
    out: [&mut [S]; 5],
    x: &[&[S]],
    y: &[&[S]],
    taps: &[S],
) {
    debug_assert!(x.len() == taps.len() && y.len() == taps.len());
    debug_assert!(out.iter().all(|o| o.len() == out[0].len()));
    match isa {
        Isa::Generic => stats_vertical_impl::<S, false>(out, x, y, taps),
        #[cfg(target_arch = "x86_64")]
        // SAFETY: as in `conv`.
        Isa::Avx2Fma => unsafe { stats_vertical_avx2(out, x, y, taps) },
    }
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn stats_vertical_avx2<S: Real>(out: [&mut [S]; 5], x: &[&[S]], y: &[&[S]], taps: &[S]) {
    stats_vertical_impl::<S, true>(out, x, y, taps)
}

#[inline(always)]
fn stats_vertical_impl<S: Real, const FMA: bool>(
    mut out: [&mut [S]; 5],
    x: &[&[S]],
    y: &[&[S]],
    taps: &[S],
) {
    let e = if std::mem::size_of::<S>() == 4 {
        stats_blocks::<S, FMA, 16>(&mut out, x, y, taps, 0)
    } else {
        stats_blocks::<S, FMA, NARROW>(&mut out, x, y, taps, 0)
    };
    let e = stats_blocks::<S, FMA, NARROW>(&mut out, x, y, taps, e);
    stats_blocks::<S, FMA, 1>(&mut out, x, y, taps, e);
}

/// [`stats_vertical_impl`] over blocks of `B` values from `e` while a whole block fits;
/// returns where it stopped.
#[inline(always)]
fn stats_blocks<S: Real, const FMA: bool, const B: usize>(
    out: &mut [&mut [S]; 5],
    x: &[&[S]],
    y: &[&[S]],
    taps: &[S],
    mut e: usize,
) -> usize {
    let n = out[0].len();
    while e + B <= n {
        let mut acc = [[S::zero(); B]; 5];
        for ((xr, yr), &g) in x.iter().zip(y).zip(taps) {
            let (xr, yr) = (&xr[e..e + B], &yr[e..e + B]);
            for l in 0..B {
                let (a, b) = (xr[l], yr[l]);
                acc[0][l] = madd::<S, FMA>(g, a, acc[0][l]);
                acc[1][l] = madd::<S, FMA>(g, b, acc[1][l]);
                acc[2][l] = madd::<S, FMA>(g, a * a, acc[2][l]);
                acc[3][l] = madd::<S, FMA>(g, b * b, acc[3][l]);
                acc[4][l] = madd::<S, FMA>(g, a * b, acc[4][l]);
            }
        }
        for (o, a) in out.iter_mut().zip(&acc) {
            o[e..e + B].copy_from_slice(a);
        }
        e += B;
    }
    e
}

/// The transposed vertical pass of the SSIM gradient, fused with the chain rule through
/// the filtered quantities `x`, `x^2` and `x y`:
/// `out[e] = sum_d g_d a[d][e] + 2 x[e] sum_d g_d b[d][e] + y[e] sum_d g_d c[d][e]`.
pub(crate) fn conv3_combine<S: Real>(
    isa: Isa,
    out: &mut [S],
    abc: [&[&[S]]; 3],
    taps: &[S],
    x: &[S],
    y: &[S],
) {
    match isa {
        Isa::Generic => conv3_impl::<S, false>(out, abc, taps, x, y),
        #[cfg(target_arch = "x86_64")]
        // SAFETY: as in `conv`.
        Isa::Avx2Fma => unsafe { conv3_avx2(out, abc, taps, x, y) },
    }
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn conv3_avx2<S: Real>(out: &mut [S], abc: [&[&[S]]; 3], taps: &[S], x: &[S], y: &[S]) {
    conv3_impl::<S, true>(out, abc, taps, x, y)
}

#[inline(always)]
fn conv3_impl<S: Real, const FMA: bool>(
    out: &mut [S],
    abc: [&[&[S]]; 3],
    taps: &[S],
    x: &[S],
    y: &[S],
) {
    let e = if std::mem::size_of::<S>() == 4 {
        conv3_blocks::<S, FMA, { 2 * L }>(out, abc, taps, x, y, 0)
    } else {
        conv3_blocks::<S, FMA, L>(out, abc, taps, x, y, 0)
    };
    let e = conv3_blocks::<S, FMA, NARROW>(out, abc, taps, x, y, e);
    let two = S::one() + S::one();
    let [a, b, c] = abc;
    for k in e..out.len() {
        let (mut aa, mut bb, mut cc) = (S::zero(), S::zero(), S::zero());
        for d in 0..taps.len() {
            let g = taps[d];
            aa = madd::<S, FMA>(g, a[d][k], aa);
            bb = madd::<S, FMA>(g, b[d][k], bb);
            cc = madd::<S, FMA>(g, c[d][k], cc);
        }
        out[k] = madd::<S, FMA>(two * x[k], bb, madd::<S, FMA>(y[k], cc, aa));
    }
}

/// [`conv3_impl`] over blocks of `B` values from `e` while a whole block fits; returns where
/// it stopped.
#[inline(always)]
fn conv3_blocks<S: Real, const FMA: bool, const B: usize>(
    out: &mut [S],
    abc: [&[&[S]]; 3],
    taps: &[S],
    x: &[S],
    y: &[S],
    mut e: usize,
) -> usize {
    let n = out.len();
    let two = S::one() + S::one();
    let [a, b, c] = abc;
    while e + B <= n {
        let mut aa = [S::zero(); B];
        let mut bb = [S::zero(); B];
        let mut cc = [S::zero(); B];
        for d in 0..taps.len() {
            let g = taps[d];
            let (ra, rb, rc) = (&a[d][e..e + B], &b[d][e..e + B], &c[d][e..e + B]);
            for l in 0..B {
                aa[l] = madd::<S, FMA>(g, ra[l], aa[l]);
                bb[l] = madd::<S, FMA>(g, rb[l], bb[l]);
                cc[l] = madd::<S, FMA>(g, rc[l], cc[l]);
            }
        }
        let (xs, ys) = (&x[e..e + B], &y[e..e + B]);
        let o = &mut out[e..e + B];
        for l in 0..B {
            o[l] = madd::<S, FMA>(two * xs[l], bb[l], madd::<S, FMA>(ys[l], cc[l], aa[l]));
        }
        e += B;
    }
    e
}

/// The five filtered statistics of one output row: `mu_x, mu_y, E[x^2], E[y^2], E[x y]`.
pub(crate) struct Stats<'a, S> {
    pub mx: &'a [S],
    pub my: &'a [S],
    pub exx: &'a [S],
    pub eyy: &'a [S],
    pub exy: &'a [S],
}

/// Cotangent rows of the three statistics the rendered video enters: with respect to
/// `mu_x`, `E[x^2]` and `E[x y]`.
pub(crate) struct Cotangents<'a, S> {
    pub mx: &'a mut [S],
    pub exx: &'a mut [S],
    pub exy: &'a mut [S],
}

/// The SSIM and contrast-structure maps of one row; with `cot`, also `u * d ssim / d stat`.
pub(crate) fn ssim_row<S: Real>(
    isa: Isa,
    st: &Stats<'_, S>,
    c1: S,
    c2: S,
    ssim: &mut [S],
    cs: &mut [S],
    cot: Option<(S, Cotangents<'_, S>)>,
) {
    match isa {
        Isa::Generic => ssim_row_impl::<S, false>(st, c1, c2, ssim, cs, cot),
        #[cfg(target_arch = "x86_64")]
        // SAFETY: as in `conv`.
        Isa::Avx2Fma => unsafe { ssim_row_avx2(st, c1, c2, ssim, cs, cot) },
    }
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
unsafe fn ssim_row_avx2<S: Real>(
    st: &Stats<'_, S>,
    c1: S,
    c2: S,
    ssim: &mut [S],
    cs: &mut [S],
    cot: Option<(S, Cotangents<'_, S>)>,
) {
    ssim_row_impl::<S, true>(st, c1, c2, ssim, cs, cot)
}

/// Per element, with `sxx = E[x^2] - mx^2`, `sxy = E[xy] - mx my`:
/// `l = (2 mx my + C1) / (mx^2 + my^2 + C1)`, `cs = (2 sxy + C2) / (sxx + syy + C2)`,
/// `ssim = l cs`; derivatives
/// `d ssim/d mx = cs (2 my - 2 mx l) / B1 + l (2 mx cs - 2 my) / B2`,
/// `d ssim/d E[x^2] = -l cs / B2`, `d ssim/d E[xy] = 2 l / B2`.
#[inline(always)]
fn ssim_row_impl<S: Real, const FMA: bool>(
    st: &Stats<'_, S>,
    c1: S,
    c2: S,
    ssim: &mut [S],
    cs: &mut [S],
    cot: Option<(S, Cotangents<'_, S>)>,
) {
    let n = ssim.len();
    let two = S::one() + S::one();
    let (mx, my, exx, eyy, exy) = (
        &st.mx[..n],
        &st.my[..n],
        &st.exx[..n],
        &st.eyy[..n],
        &st.exy[..n],
    );
    let cs = &mut cs[..n];
    match cot {
        None => {
            for e in 0..n {
                let (a, b) = (mx[e], my[e]);
                let (aa, bb, ab) = (a * a, b * b, a * b);
                let l = (two * ab + c1) / (aa + bb + c1);
                let c = (two * (exy[e] - ab) + c2) / ((exx[e] - aa) + (eyy[e] - bb) + c2);
                cs[e] = c;
                ssim[e] = l * c;
            }
        }
        Some((u, cot)) => {
            let (gm, gxx, gxy) = (&mut cot.mx[..n], &mut cot.exx[..n], &mut cot.exy[..n]);
            for e in 0..n {
                let (a, b) = (mx[e], my[e]);
                let (aa, bb, ab) = (a * a, b * b, a * b);
                let b1 = aa + bb + c1;
                let b2 = (exx[e] - aa) + (eyy[e] - bb) + c2;
                let l = (two * ab + c1) / b1;
                let c = (two * (exy[e] - ab) + c2) / b2;
                cs[e] = c;
                ssim[e] = l * c;
                let ub2 = u / b2;
                gm[e] = u * c * (two * b - two * a * l) / b1 + l * ub2 * (two * a * c - two * b);
                gxx[e] = -(l * c) * ub2;
                gxy[e] = two * l * ub2;
            }
        }
    }
}
