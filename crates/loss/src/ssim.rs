//! SSIM and MS-SSIM with pytorch-msssim's conventions, the 3DGS training-style same-padded
//! SSIM, and the gradient of SSIM with respect to the rendered video.
//!
//! Conventions (`tests/fixtures/loss/README.md`): an 11-tap Gaussian window with sigma 1.5
//! whose taps are evaluated and normalised **in float32** ([`GAUSS_11`]; their f64 sum is
//! 0.999999969, not 1), applied separably, first along rows (H) then columns (W), as a
//! "valid" filter (maps of `(H - 10) x (W - 10)`), or with [`Padding::Same`] after zero
//! padding of 5 px (maps of `H x W`). Per channel `mu_x = G*x`, `s_xx = G*(x x) - mu_x^2`,
//! `s_xy = G*(x y) - mu_x mu_y`, `C1 = 0.01^2`, `C2 = 0.03^2` (data range 1),
//! `ssim = (2 mu_x mu_y + C1)(2 s_xy + C2) / ((mu_x^2 + mu_y^2 + C1)(s_xx + s_yy + C2))`.
//! The SSIM of a video is the mean of each map, averaged over frames and channels.
//!
//! Where pytorch-msssim skips filtering along a side shorter than the window (with a
//! warning), this crate returns [`LossError::SmallerThanWindow`].
//!
//! Computation streams each frame row by row (a ring of `window` input rows, no full-frame
//! temporaries), in parallel over frames; the precision is the input's, or the one
//! [`SsimConfig::precision`] asks for.

use crate::error::{Input, LossError};
use crate::par;
use crate::real::Real;
use crate::rows::{self, Cotangents, Isa, Stats};
use crate::video::{check_grad_len, check_pair, Video};
use serde::{Deserialize, Serialize};

/// The 11-tap, sigma 1.5 Gaussian window as pytorch-msssim computes it in float32
/// (offsets -5..5).
pub const GAUSS_11: [f32; 11] = [
    0.001_028_380_4,
    0.007_598_758,
    0.036_000_773,
    0.109_360_69,
    0.213_005_53,
    0.266_011_72,
    0.213_005_53,
    0.109_360_69,
    0.036_000_773,
    0.007_598_758,
    0.001_028_380_4,
];

/// MS-SSIM weights of the five scales (pytorch-msssim's defaults).
pub const MS_SSIM_WEIGHTS: [f64; 5] = [0.0448, 0.2856, 0.3001, 0.2363, 0.1333];

/// Largest window the filters accept.
pub const MAX_WINDOW: usize = 31;

/// A Gaussian window of `size` taps (odd), evaluated and normalised in float32 as
/// pytorch-msssim's `_fspecial_gauss_1d` does: offsets `-size/2 .. size/2`,
/// `exp(-d^2 / (2 sigma^2))`, divided by the sum. For 11 taps and sigma 1.5 this is exactly
/// [`GAUSS_11`].
pub fn gaussian_window(size: usize, sigma: f32) -> Vec<f32> {
    if size == 11 && sigma == 1.5 {
        return GAUSS_11.to_vec();
    }
    let half = (size / 2) as f32;
    let denom = 2.0 * (sigma as f64 * sigma as f64) as f32;
    let g: Vec<f32> = (0..size)
        .map(|i| {
            let d = i as f32 - half;
            (-(d * d) / denom).exp()
        })
        .collect();
    let s: f32 = g.iter().sum();
    g.iter().map(|v| v / s).collect()
}

/// Border handling of the SSIM filter.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Padding {
    /// No padding; maps of `(H - w + 1) x (W - w + 1)` (pytorch-msssim).
    #[default]
    Valid,
    /// Zero padding of `w / 2` px on every side; maps of `H x W` (the 3DGS training code's
    /// `ssim()`; border statistics are pulled towards zero).
    Same,
}

/// Precision of the SSIM arithmetic.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Precision {
    /// The input video's scalar type.
    #[default]
    Input,
    /// `f32` (about 2x faster than f64; matches f64 SSIM to ~1e-6).
    F32,
    /// `f64`.
    F64,
}

/// Settings of SSIM.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SsimConfig {
    /// Window taps (odd, at most [`MAX_WINDOW`]).
    pub window: usize,
    /// Gaussian sigma in pixels.
    pub sigma: f32,
    /// `K1` of `C1 = (K1 * data_range)^2`, data range 1.
    pub k1: f64,
    /// `K2` of `C2 = (K2 * data_range)^2`.
    pub k2: f64,
    /// Valid (pytorch-msssim) or same (3DGS) filtering.
    pub padding: Padding,
    /// SSIM of the BT.601 gray frames (`0.299 R + 0.587 G + 0.114 B`) instead of the mean
    /// over RGB channels.
    pub gray: bool,
    /// Arithmetic precision.
    pub precision: Precision,
}

impl Default for SsimConfig {
    fn default() -> Self {
        SsimConfig {
            window: 11,
            sigma: 1.5,
            k1: 0.01,
            k2: 0.03,
            padding: Padding::Valid,
            gray: false,
            precision: Precision::Input,
        }
    }
}

impl SsimConfig {
    /// The 3DGS training code's same-padded SSIM.
    pub fn same_pad() -> Self {
        SsimConfig {
            padding: Padding::Same,
            ..Default::default()
        }
    }

    /// Checks the settings.
    pub fn validate(&self) -> Result<(), LossError> {
        if self.window % 2 == 0 || self.window == 0 || self.window > MAX_WINDOW {
            return Err(LossError::Config(format!(
                "SSIM window must be odd and at most {MAX_WINDOW}, got {}",
                self.window
            )));
        }
        if !(self.sigma > 0.0 && self.sigma.is_finite()) {
            return Err(LossError::Config(format!(
                "SSIM sigma must be positive, got {}",
                self.sigma
            )));
        }
        if !(self.k1 >= 0.0 && self.k2 > 0.0 && self.k1.is_finite() && self.k2.is_finite()) {
            return Err(LossError::Config(format!(
                "SSIM constants must be finite with K2 > 0, got K1 = {}, K2 = {}",
                self.k1, self.k2
            )));
        }
        Ok(())
    }

    fn pad(&self) -> usize {
        match self.padding {
            Padding::Valid => 0,
            Padding::Same => self.window / 2,
        }
    }

    /// Checks that frames of `height x width` are large enough for this window.
    pub(crate) fn check_size(
        &self,
        input: Input,
        height: usize,
        width: usize,
    ) -> Result<(), LossError> {
        let p = 2 * self.pad();
        if height + p < self.window || width + p < self.window {
            return Err(LossError::SmallerThanWindow {
                input,
                height,
                width,
                window: self.window,
            });
        }
        Ok(())
    }
}

/// SSIM of a video pair.
#[derive(Clone, Debug, PartialEq)]
pub struct SsimValue {
    /// Mean over frames and channels (pytorch-msssim's `size_average=True` value).
    pub mean: f64,
    /// Per frame, mean over channels.
    pub per_frame: Vec<f64>,
    /// Per frame and channel (`T x 3`, or `T x 1` for gray), the mean of each map.
    pub per_frame_channel: Vec<f64>,
    /// As `mean` with each per-frame-channel value clamped at 0 first (pytorch-msssim's
    /// `nonnegative_ssim=True`).
    pub nonnegative: f64,
}

/// SSIM of `rendered` against `reference`.
pub fn ssim<T: Real>(
    rendered: &Video<T>,
    reference: &Video<T>,
    cfg: &SsimConfig,
) -> Result<SsimValue, LossError> {
    check_pair(rendered, reference)?;
    cfg.validate()?;
    cfg.check_size(Input::Rendered, rendered.height(), rendered.width())?;
    Ok(ssim_dispatch(rendered, reference, cfg, None))
}

/// SSIM of `rendered` against `reference`, adding `scale * d SSIM / d rendered` to `grad`
/// (`(T, H, W, 3)`, the rendered video's layout). For the loss `w * (1 - SSIM)` pass
/// `scale = -w`.
pub fn ssim_grad_into<T: Real>(
    rendered: &Video<T>,
    reference: &Video<T>,
    cfg: &SsimConfig,
    scale: f64,
    grad: &mut [T],
) -> Result<SsimValue, LossError> {
    check_pair(rendered, reference)?;
    check_grad_len(rendered, grad)?;
    cfg.validate()?;
    cfg.check_size(Input::Rendered, rendered.height(), rendered.width())?;
    Ok(ssim_dispatch(rendered, reference, cfg, Some((scale, grad))))
}

/// Unchecked entry: picks the arithmetic precision.
pub(crate) fn ssim_dispatch<T: Real>(
    x: &Video<T>,
    y: &Video<T>,
    cfg: &SsimConfig,
    grad: Option<(f64, &mut [T])>,
) -> SsimValue {
    let use_f32 = match cfg.precision {
        Precision::Input => T::NAME == "f32",
        Precision::F32 => true,
        Precision::F64 => false,
    };
    if use_f32 {
        ssim_video::<T, f32>(x, y, cfg, grad)
    } else {
        ssim_video::<T, f64>(x, y, cfg, grad)
    }
}

/// SSIM of a video in compute precision `S`, in parallel over frames.
fn ssim_video<T: Real, S: Real>(
    x: &Video<T>,
    y: &Video<T>,
    cfg: &SsimConfig,
    grad: Option<(f64, &mut [T])>,
) -> SsimValue {
    let window = gaussian_window(cfg.window, cfg.sigma);
    // The 3DGS code's 2-D window is the outer product rounded to float32; in f64 its
    // rounding residual (~6e-8 relative) moves SSIM by up to ~1e-6 through the variance
    // cancellation, so it is applied as a correction. In f32 it is below round-off.
    let residual =
        (cfg.padding == Padding::Same && S::NAME == "f64").then(|| window_residual(&window));
    let taps: Vec<S> = window.iter().map(|&g| S::c(g as f64)).collect();
    let filter = Filter {
        isa: Isa::detect(),
        taps: &taps,
        residual: residual.as_deref(),
        c1: S::c(cfg.k1 * cfg.k1),
        c2: S::c(cfg.k2 * cfg.k2),
        want_cs: false,
    };
    let (nt, h, w) = (x.frames(), x.height(), x.width());
    let pad = cfg.pad();
    let ch = if cfg.gray { 1 } else { 3 };
    let (ho, wo) = (h + 2 * pad + 1 - cfg.window, w + 2 * pad + 1 - cfg.window);
    let flen = x.frame_len();
    let (scale, grad) = match grad {
        Some((s, g)) => (s, Some(g)),
        None => (0.0, None),
    };
    let u = S::c(scale / (nt * ch * ho * wo) as f64);
    let items: Vec<(usize, Option<&mut [T]>)> = match grad {
        Some(g) => g.chunks_mut(flen).map(Some).enumerate().collect(),
        None => (0..nt).map(|t| (t, None)).collect(),
    };
    let sums = par::map(items, |(t, g)| {
        let (fx, fy) = (x.frame(t), y.frame(t));
        let plane = PlaneShape { h, w, ch, pad };
        if cfg.gray {
            let gx = gray_plane::<T, S>(fx);
            let gy = gray_plane::<T, S>(fy);
            match g {
                Some(g) => {
                    let mut gg = vec![S::zero(); h * w];
                    let s = ssim_plane(&filter, &gx, &gy, plane, Some((u, &mut gg[..])));
                    for (px, &v) in g.chunks_exact_mut(3).zip(&gg) {
                        let v = v.f64();
                        px[0] += T::c(0.299 * v);
                        px[1] += T::c(0.587 * v);
                        px[2] += T::c(0.114 * v);
                    }
                    s
                }
                None => ssim_plane::<S, S>(&filter, &gx, &gy, plane, None),
            }
        } else {
            ssim_plane(&filter, fx, fy, plane, g.map(|g| (u, g)))
        }
    });
    let count = (ho * wo) as f64;
    let per_frame_channel: Vec<f64> = sums
        .iter()
        .flat_map(|s| s.ssim.iter().map(|v| v / count))
        .collect();
    let per_frame: Vec<f64> = per_frame_channel
        .chunks(ch)
        .map(|c| c.iter().sum::<f64>() / ch as f64)
        .collect();
    let n = per_frame_channel.len() as f64;
    SsimValue {
        mean: per_frame_channel.iter().sum::<f64>() / n,
        nonnegative: per_frame_channel.iter().map(|v| v.max(0.0)).sum::<f64>() / n,
        per_frame,
        per_frame_channel,
    }
}

/// `f32(g_a g_b) - g_a g_b` for every tap pair `(a, b)`, row-major: the rounding residual of
/// the float32 2-D window (each product of two f32 is exact in f64).
fn window_residual<S: Real>(g: &[f32]) -> Vec<S> {
    let mut r = Vec::with_capacity(g.len() * g.len());
    for &a in g {
        for &b in g {
            let exact = a as f64 * b as f64;
            r.push(S::c((a * b) as f64 - exact));
        }
    }
    r
}

/// BT.601 luma of a `(H, W, 3)` frame, computed in f64 and rounded to `S`.
pub(crate) fn gray_plane<T: Real, S: Real>(f: &[T]) -> Vec<S> {
    f.chunks_exact(3)
        .map(|p| S::c(0.299 * p[0].f64() + 0.587 * p[1].f64() + 0.114 * p[2].f64()))
        .collect()
}

/// The SSIM filter in compute precision `S`.
pub(crate) struct Filter<'a, S> {
    /// Row kernels' instruction set.
    pub isa: Isa,
    /// The 1-D window.
    pub taps: &'a [S],
    /// The 2-D window minus the outer product of `taps` (`n x n`, row-major), if any.
    pub residual: Option<&'a [S]>,
    /// `C1`.
    pub c1: S,
    /// `C2`.
    pub c2: S,
    /// Also sum the contrast-structure map (MS-SSIM).
    pub want_cs: bool,
}

/// Shape of one image for [`ssim_plane`].
#[derive(Clone, Copy, Debug)]
pub(crate) struct PlaneShape {
    /// Rows.
    pub h: usize,
    /// Columns.
    pub w: usize,
    /// Interleaved channels.
    pub ch: usize,
    /// Zero padding on every side.
    pub pad: usize,
}

/// Per-channel sums of one image's SSIM and contrast-structure maps.
#[derive(Clone, Debug)]
pub(crate) struct PlaneSums {
    /// Sum of the SSIM map per channel.
    pub ssim: Vec<f64>,
    /// Sum of the cs map per channel.
    pub cs: Vec<f64>,
}

/// SSIM of one image (`h x w x ch`, interleaved) in precision `S`, streaming rows: a ring of
/// `window` input rows (converted, zero-padded), the vertical pass of all five statistics in
/// one pass over the ring (products formed as the rows are read), the horizontal pass, the
/// output row's maps; with `grad = (u, g)` also
/// the cotangents (upstream `u` per map element) into a ring of `window` rows, their
/// transposed horizontal pass, and, once an input row has received every output row's
/// contribution, the transposed vertical pass added to `g`.
pub(crate) fn ssim_plane<T: Real, S: Real>(
    f: &Filter<'_, S>,
    x: &[T],
    y: &[T],
    shape: PlaneShape,
    mut grad: Option<(S, &mut [T])>,
) -> PlaneSums {
    let PlaneShape { w, ch, pad, .. } = shape;
    let n = f.taps.len();
    let wo = w + 2 * pad + 1 - n;
    // Output columns per tile: the rings of a tile (~130 rows) stay within ~400 KB (L2).
    let tile = (3072 / (ch * std::mem::size_of::<S>())).max(4 * n);
    let tiles = wo.div_ceil(tile);
    let mut sums = PlaneSums {
        ssim: vec![0.0; ch],
        cs: vec![0.0; ch],
    };
    for k in 0..tiles {
        // Even split of the output columns.
        let (c0, c1) = (k * wo / tiles, (k + 1) * wo / tiles);
        let g = grad.as_mut().map(|(u, g)| (*u, &mut **g));
        let s = ssim_tile(f, x, y, shape, (c0, c1), g);
        for c in 0..ch {
            sums.ssim[c] += s.ssim[c];
            sums.cs[c] += s.cs[c];
        }
    }
    sums
}

/// [`ssim_plane`] for the output columns `cols` (padded coordinates) of the image: the
/// input columns `cols.0 .. cols.1 + window - 1`; gradients add to the columns the tile
/// reads, so tiles of one image run one after the other.
fn ssim_tile<T: Real, S: Real>(
    f: &Filter<'_, S>,
    x: &[T],
    y: &[T],
    shape: PlaneShape,
    cols: (usize, usize),
    mut grad: Option<(S, &mut [T])>,
) -> PlaneSums {
    let PlaneShape { h, w, ch, pad } = shape;
    let (isa, taps) = (f.isa, f.taps);
    let n = taps.len();
    let hp = h + 2 * pad;
    let ho = hp + 1 - n;
    let wo = cols.1 - cols.0;
    let wi = wo + n - 1;
    let (li, lo) = (wi * ch, wo * ch);
    let rl = w * ch; // real (unpadded) row length
                     // Real columns the tile reads, and where they go in a ring row.
    let (r0, r1) = (cols.0.max(pad) - pad, (cols.0 + wi).min(pad + w) - pad);
    let off = (r0 + pad - cols.0) * ch;
    let span = (r0 * ch, r1 * ch);
    // Input rings: x, y, and with the 2-D residual xx, yy, xy (the vertical pass forms the
    // products itself).
    let products = f.residual.is_some();
    let mut ring: [Vec<S>; 5] =
        std::array::from_fn(|q| vec![S::zero(); if q < 2 || products { n * li } else { 0 }]);
    let mut v: [Vec<S>; 5] = std::array::from_fn(|_| vec![S::zero(); li]);
    let mut m: [Vec<S>; 5] = std::array::from_fn(|_| vec![S::zero(); lo]);
    let mut corr = vec![S::zero(); if f.residual.is_some() { li } else { 0 }];
    let mut srow = vec![S::zero(); lo];
    let mut csrow = vec![S::zero(); lo];
    let with_grad = grad.is_some();
    let gl = if with_grad { 1 } else { 0 };
    // Cotangent rings: rows zero-padded by (n - 1) ch on both sides for the transposed
    // horizontal pass.
    let cpad = (n - 1) * ch;
    let cl = lo + 2 * cpad;
    let mut cring: [Vec<S>; 3] = std::array::from_fn(|_| vec![S::zero(); gl * n * cl]);
    let mut uring: [Vec<S>; 3] = std::array::from_fn(|_| vec![S::zero(); gl * n * li]);
    let mut fin = Finalize {
        zero_row: vec![S::zero(); gl * cl.max(li)],
        grow: vec![S::zero(); gl * li],
        corr: [(); 3].map(|_| vec![S::zero(); if f.residual.is_some() { gl * li } else { 0 }]),
        tmp: vec![S::zero(); if f.residual.is_some() { gl * li } else { 0 }],
    };
    let mut sums = PlaneSums {
        ssim: vec![0.0; ch],
        cs: vec![0.0; ch],
    };

    let load = |ring: &mut [Vec<S>; 5], i: usize| {
        let s = (i % n) * li;
        for q in 0..2 {
            let src = if q == 0 { x } else { y };
            let row = &mut ring[q][s..s + li];
            if i < pad || i >= pad + h {
                row.fill(S::zero());
            } else {
                let r = i - pad;
                let len = span.1 - span.0;
                row[..off].fill(S::zero());
                row[off + len..].fill(S::zero());
                for (d, s) in row[off..off + len]
                    .iter_mut()
                    .zip(&src[r * rl + span.0..r * rl + span.1])
                {
                    *d = S::c(s.f64());
                }
            }
        }
        if !products {
            return;
        }
        let [rx, ry, rxx, ryy, rxy] = ring;
        let (rx, ry) = (&rx[s..s + li], &ry[s..s + li]);
        for e in 0..li {
            rxx[s + e] = rx[e] * rx[e];
            ryy[s + e] = ry[e] * ry[e];
            rxy[s + e] = rx[e] * ry[e];
        }
    };

    let empty: [&[S]; MAX_WINDOW] = [&[]; MAX_WINDOW];
    for i in 0..n - 1 {
        load(&mut ring, i);
    }
    for o in 0..ho {
        load(&mut ring, o + n - 1);
        // Vertical pass: v_q = sum_d g_d q[o + d] for q = x, y, xx, yy, xy.
        let (mut xrows, mut yrows) = (empty, empty);
        for d in 0..n {
            let s = ((o + d) % n) * li;
            xrows[d] = &ring[0][s..s + li];
            yrows[d] = &ring[1][s..s + li];
        }
        let [v0, v1, v2, v3, v4] = &mut v;
        rows::stats_vertical(isa, [v0, v1, v2, v3, v4], &xrows[..n], &yrows[..n], taps);
        // Horizontal pass: m_q[e] = sum_d g_d v_q[e + d ch].
        for q in 0..5 {
            let mut rows = empty;
            for d in 0..n {
                rows[d] = &v[q][d * ch..];
            }
            rows::conv(isa, &mut m[q], &rows[..n], taps);
            // 2-D residual: m_q[e] += sum_{a,b} r_ab q[o + a][e + b ch].
            if let Some(res) = f.residual {
                for a in 0..n {
                    let s = ((o + a) % n) * li;
                    let mut rows = empty;
                    for b in 0..n {
                        rows[b] = &ring[q][s + b * ch..s + li];
                    }
                    rows::conv(isa, &mut corr[..lo], &rows[..n], &res[a * n..(a + 1) * n]);
                    for (mv, c) in m[q].iter_mut().zip(&corr) {
                        *mv += *c;
                    }
                }
            }
        }
        let [mx, my, exx, eyy, exy] = &m;
        let st = Stats {
            mx,
            my,
            exx,
            eyy,
            exy,
        };
        let slot = (o % n) * cl;
        let cots = match &mut grad {
            Some((u, _)) => {
                let [a, b, c] = &mut cring;
                let r = slot + cpad..slot + cpad + lo;
                Some((
                    *u,
                    Cotangents {
                        mx: &mut a[r.clone()],
                        exx: &mut b[r.clone()],
                        exy: &mut c[r],
                    },
                ))
            }
            None => None,
        };
        rows::ssim_row(isa, &st, f.c1, f.c2, &mut srow, &mut csrow, cots);
        channel_sums(&srow, ch, &mut sums.ssim);
        if f.want_cs {
            channel_sums(&csrow, ch, &mut sums.cs);
        }
        if with_grad {
            // Transposed horizontal pass: u_q[f] = sum_d g_d cot_q[f - d ch].
            let s = (o % n) * li;
            for q in 0..3 {
                let mut rows = empty;
                for d in 0..n {
                    rows[d] = &cring[q][slot + (n - 1 - d) * ch..slot + cl];
                }
                rows::conv(isa, &mut uring[q][s..s + li], &rows[..n], taps);
            }
            fin.row(f, o, ho, n, li, &ring, &uring, &cring, cl);
            write_grad_row(o, shape, (off, span), &fin.grow, &mut grad);
        }
    }
    if with_grad {
        for i in ho..hp {
            fin.row(f, i, ho, n, li, &ring, &uring, &cring, cl);
            write_grad_row(i, shape, (off, span), &fin.grow, &mut grad);
        }
    }
    sums
}

/// Adds the per-channel sums (in f64) of an interleaved row to `out`.
fn channel_sums<S: Real>(row: &[S], ch: usize, out: &mut [f64]) {
    match ch {
        3 => channel_sums_n::<S, 24>(row, ch, out),
        _ => channel_sums_n::<S, 8>(row, ch, out),
    }
}

/// Blocks of `B` values (a multiple of `ch`) into `B` independent accumulators.
fn channel_sums_n<S: Real, const B: usize>(row: &[S], ch: usize, out: &mut [f64]) {
    let mut acc = [0.0f64; B];
    let mut blocks = row.chunks_exact(B);
    for b in &mut blocks {
        for k in 0..B {
            acc[k] += b[k].f64();
        }
    }
    for (k, v) in acc.iter().enumerate() {
        out[k % ch] += v;
    }
    for (k, v) in blocks.remainder().iter().enumerate() {
        out[k % ch] += v.f64();
    }
}

/// Buffers of the transposed vertical pass.
struct Finalize<S> {
    zero_row: Vec<S>,
    grow: Vec<S>,
    corr: [Vec<S>; 3],
    tmp: Vec<S>,
}

impl<S: Real> Finalize<S> {
    /// The gradient of padded input row `i` into `grow`: the transposed vertical pass over
    /// the transposed-horizontal cotangent rows of output rows `i - n + 1 ..= i`, combined
    /// through `x`, `x^2`, `x y`; plus the transposed 2-D residual.
    #[allow(clippy::too_many_arguments)]
    fn row(
        &mut self,
        f: &Filter<'_, S>,
        i: usize,
        ho: usize,
        n: usize,
        li: usize,
        ring: &[Vec<S>; 5],
        uring: &[Vec<S>; 3],
        cring: &[Vec<S>; 3],
        cl: usize,
    ) {
        let mut abc: [[&[S]; MAX_WINDOW]; 3] = [[&[]; MAX_WINDOW]; 3];
        let zero = &self.zero_row[..];
        for d in 0..n {
            let valid = i >= d && i - d < ho;
            for q in 0..3 {
                abc[q][d] = if valid {
                    let s = ((i - d) % n) * li;
                    &uring[q][s..s + li]
                } else {
                    zero
                };
            }
        }
        let s = (i % n) * li;
        let (x, y) = (&ring[0][s..s + li], &ring[1][s..s + li]);
        rows::conv3_combine(
            f.isa,
            &mut self.grow,
            [&abc[0][..n], &abc[1][..n], &abc[2][..n]],
            f.taps,
            x,
            y,
        );
        if let Some(res) = f.residual {
            // q_bar[i][f] += sum_{a,b} r_ab cot_q[i - a][f - b ch].
            let ch = (cl - li) / (n - 1);
            for q in 0..3 {
                self.corr[q].fill(S::zero());
                for a in 0..n {
                    if i < a || i - a >= ho {
                        continue;
                    }
                    let slot = ((i - a) % n) * cl;
                    let mut rows: [&[S]; MAX_WINDOW] = [&[]; MAX_WINDOW];
                    for b in 0..n {
                        rows[b] = &cring[q][slot + (n - 1 - b) * ch..slot + cl];
                    }
                    rows::conv(f.isa, &mut self.tmp, &rows[..n], &res[a * n..(a + 1) * n]);
                    for (c, t) in self.corr[q].iter_mut().zip(&self.tmp) {
                        *c += *t;
                    }
                }
            }
            let two = S::one() + S::one();
            for e in 0..li {
                self.grow[e] +=
                    self.corr[0][e] + two * x[e] * self.corr[1][e] + y[e] * self.corr[2][e];
            }
        }
    }
}

/// Adds the real (unpadded) part of padded gradient row `i` to the output;
/// `(off, (a, b))`: the real row's values `a..b` are at `off..` in `row`.
fn write_grad_row<T: Real, S: Real>(
    i: usize,
    shape: PlaneShape,
    (off, (a, b)): (usize, (usize, usize)),
    row: &[S],
    grad: &mut Option<(S, &mut [T])>,
) {
    let PlaneShape { h, w, ch, pad } = shape;
    if i < pad || i >= pad + h {
        return;
    }
    if let Some((_, g)) = grad {
        let r = i - pad;
        let rl = w * ch;
        for (d, s) in g[r * rl + a..r * rl + b]
            .iter_mut()
            .zip(&row[off..off + (b - a)])
        {
            *d += T::c(s.f64());
        }
    }
}

/// Settings of MS-SSIM.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct MsSsimConfig {
    /// Window taps (odd).
    pub window: usize,
    /// Gaussian sigma.
    pub sigma: f32,
    /// Weights of the scales, finest first.
    pub weights: Vec<f64>,
}

impl Default for MsSsimConfig {
    fn default() -> Self {
        MsSsimConfig {
            window: 11,
            sigma: 1.5,
            weights: MS_SSIM_WEIGHTS.to_vec(),
        }
    }
}

impl MsSsimConfig {
    /// The documented fallback for frames too small for the standard 11-tap window: the
    /// largest odd window `w` with `min_side > (w - 1) * 16` (pytorch-msssim's assertion),
    /// sigma still 1.5; `None` below 33 px (no window of 3 or more fits).
    pub fn largest_window(min_side: usize) -> Option<MsSsimConfig> {
        let mut w = 11;
        while w >= 3 {
            if min_side > (w - 1) * 16 {
                return Some(MsSsimConfig {
                    window: w,
                    ..Default::default()
                });
            }
            w -= 2;
        }
        None
    }
}

/// MS-SSIM of a video pair.
#[derive(Clone, Debug, PartialEq)]
pub struct MsSsimValue {
    /// Mean over frames and channels.
    pub mean: f64,
    /// Per frame, mean over channels.
    pub per_frame: Vec<f64>,
}

/// MS-SSIM (pytorch-msssim's `ms_ssim`, frames as the batch), computed in f64: at scales
/// 1..4 the mean contrast-structure `cs` per frame and channel (relu'd), then a 2x2 average
/// pool (a side of odd length gets one zero sample in front, `count_include_pad`); at the
/// last scale the mean SSIM (relu'd); the product of each to its weight per channel, averaged
/// over channels and frames. Frames must have both sides `> (window - 1) * 2^(scales - 1)`
/// (160 px for the standard 11-tap window), as the library asserts (with 2^4 whatever the
/// number of weights); [`MsSsimConfig::largest_window`] gives the smaller-window fallback.
pub fn ms_ssim<T: Real>(
    rendered: &Video<T>,
    reference: &Video<T>,
    cfg: &MsSsimConfig,
) -> Result<MsSsimValue, LossError> {
    check_pair(rendered, reference)?;
    SsimConfig {
        window: cfg.window,
        sigma: cfg.sigma,
        ..Default::default()
    }
    .validate()?;
    if cfg.weights.is_empty() {
        return Err(LossError::Config(
            "MS-SSIM needs at least one weight".into(),
        ));
    }
    let (h, w) = (rendered.height(), rendered.width());
    let min_side = (cfg.window - 1) * 16;
    let min_side = min_side.max((cfg.window - 1) << (cfg.weights.len() - 1));
    if h.min(w) <= min_side {
        return Err(LossError::TooSmallForMsSsim {
            input: Input::Rendered,
            height: h,
            width: w,
            window: cfg.window,
            min_side_exclusive: min_side,
        });
    }
    let taps: Vec<f64> = gaussian_window(cfg.window, cfg.sigma)
        .iter()
        .map(|&g| g as f64)
        .collect();
    let filter = Filter {
        isa: Isa::detect(),
        taps: &taps,
        residual: None,
        c1: 1e-4,
        c2: 9e-4,
        want_cs: true,
    };
    let levels = cfg.weights.len();
    let per_frame = par::map((0..rendered.frames()).collect(), |t| {
        let mut x: Vec<f64> = rendered.frame(t).iter().map(|v| v.f64()).collect();
        let mut y: Vec<f64> = reference.frame(t).iter().map(|v| v.f64()).collect();
        let (mut hh, mut ww) = (h, w);
        let mut value = [1.0f64; 3];
        for (level, &weight) in cfg.weights.iter().enumerate() {
            let shape = PlaneShape {
                h: hh,
                w: ww,
                ch: 3,
                pad: 0,
            };
            let s = ssim_plane::<f64, f64>(&filter, &x, &y, shape, None);
            let count = ((hh + 1 - cfg.window) * (ww + 1 - cfg.window)) as f64;
            for c in 0..3 {
                let v = if level + 1 < levels {
                    s.cs[c]
                } else {
                    s.ssim[c]
                } / count;
                value[c] *= v.max(0.0).powf(weight);
            }
            if level + 1 < levels {
                let (nh, nw);
                (x, nh, nw) = avg_pool2(&x, hh, ww);
                (y, _, _) = avg_pool2(&y, hh, ww);
                (hh, ww) = (nh, nw);
            }
        }
        value.iter().sum::<f64>() / 3.0
    });
    Ok(MsSsimValue {
        mean: per_frame.iter().sum::<f64>() / per_frame.len() as f64,
        per_frame,
    })
}

/// PyTorch's `avg_pool2d(kernel_size=2, stride=2, padding=(h % 2, w % 2))` with
/// `count_include_pad=True` on an `h x w x 3` image: an odd side gets one zero sample in
/// front (and the last window ends at the last sample); every window is divided by 4.
fn avg_pool2(img: &[f64], h: usize, w: usize) -> (Vec<f64>, usize, usize) {
    let (ph, pw) = (h % 2, w % 2);
    let (oh, ow) = ((h + 2 * ph - 2) / 2 + 1, (w + 2 * pw - 2) / 2 + 1);
    let mut out = vec![0.0; oh * ow * 3];
    let at = |r: isize, c: isize, k: usize| -> f64 {
        if r < 0 || c < 0 || r >= h as isize || c >= w as isize {
            0.0
        } else {
            img[(r as usize * w + c as usize) * 3 + k]
        }
    };
    for i in 0..oh {
        for j in 0..ow {
            let (r0, c0) = (2 * i as isize - ph as isize, 2 * j as isize - pw as isize);
            for k in 0..3 {
                let s =
                    at(r0, c0, k) + at(r0, c0 + 1, k) + at(r0 + 1, c0, k) + at(r0 + 1, c0 + 1, k);
                out[(i * ow + j) * 3 + k] = s / 4.0;
            }
        }
    }
    (out, oh, ow)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn window_is_pytorch_msssims_float32_taps() {
        // The README's values (pytorch-msssim's float32 window printed as f64).
        let want = [
            0.0010283803567290306,
            0.0075987582094967365,
            0.036000773310661316,
            0.10936068743467331,
            0.21300552785396576,
            0.26601171493530273,
        ];
        for (i, w) in want.iter().enumerate() {
            assert_eq!(GAUSS_11[i] as f64, *w);
            assert_eq!(GAUSS_11[10 - i] as f64, *w);
        }
        let s64: f64 = GAUSS_11.iter().map(|&v| v as f64).sum();
        assert!((s64 - 0.999999969266355).abs() < 1e-15, "{s64}");
        // Rust's f32 `exp` rounds differently from PyTorch's for some taps (1 ulp), so the
        // 11-tap window is a table, not recomputed.
        assert_eq!(gaussian_window(11, 1.5), GAUSS_11.to_vec());
    }

    #[test]
    fn largest_window_follows_the_assertion() {
        assert_eq!(MsSsimConfig::largest_window(64).unwrap().window, 3);
        assert_eq!(MsSsimConfig::largest_window(72).unwrap().window, 5);
        assert_eq!(MsSsimConfig::largest_window(96).unwrap().window, 5);
        assert_eq!(MsSsimConfig::largest_window(161).unwrap().window, 11);
        assert!(MsSsimConfig::largest_window(32).is_none());
    }
}
