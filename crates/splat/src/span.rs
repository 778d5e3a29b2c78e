//! One row of a tile composited at once: [`composite_span`] runs [`crate::raster::composite_pixel`]
//! for up to [`SPAN`] neighbouring pixels of a row together, evaluating each Gaussian's power
//! for all of them in one loop over contiguous lanes (which the compiler vectorises) and
//! skipping the Gaussian at once where no live pixel passes the power test. Each pixel that
//! does is then composited by exactly [`crate::raster::composite_pixel`]'s arithmetic, so every
//! result is bitwise that function's (and independent of how rows are scheduled).
//!
//! [`composite_span_f32`] is the f32 instance compiled for AVX2 where the processor has it
//! (detected at run time; no fused operations, so the same bits).

use crate::camera::consts;
use crate::falloff::falloff;
use crate::raster::{Contribution, PixelOut, TileSplats};
use crate::real::Real;

/// Pixels composited together: one row of a 16x16 tile.
pub const SPAN: usize = consts::TILE as usize;

/// Composites pixels `(i0 + l, j)` for `l < live.len()` where `live[l]` (the others are left
/// as they are) over `tile`, writing each pixel's [`PixelOut`] and final transmittance to
/// `out[l]` and, with `traces`, its composited Gaussians to `traces[l]` (cleared first):
/// bitwise [`crate::raster::composite_pixel`] of each pixel.
#[inline(always)]
pub fn composite_span<T: Real>(
    i0: u32,
    j: u32,
    live: &[bool],
    tile: &TileSplats<T>,
    background: &[T; 3],
    out: &mut [(PixelOut<T>, T); SPAN],
    mut traces: Option<&mut [Vec<Contribution<T>>; SPAN]>,
) {
    assert!(live.len() <= SPAN);
    let c = T::c;
    let zero = T::zero();
    let one = T::one();
    let half = c(0.5);
    let tmin = c(consts::T_MIN);
    let (amax, amin) = (c(consts::ALPHA_MAX), c(consts::ALPHA_MIN));
    let py = c(j as f64 + 0.5);
    let px: [T; SPAN] = std::array::from_fn(|l| c((i0 + l as u32) as f64 + 0.5));
    let mut alive = [false; SPAN];
    alive[..live.len()].copy_from_slice(live);
    let mut n_alive = alive.iter().filter(|&&a| a).count();
    if let Some(tr) = traces.as_deref_mut() {
        for (l, t) in tr.iter_mut().enumerate() {
            if alive[l] {
                t.clear();
            }
        }
    }
    let mut t = [one; SPAN];
    let mut rgb = [[zero; SPAN]; 3];
    let mut depth = [zero; SPAN];
    let mut last = [0u32; SPAN];
    let mut dx = [zero; SPAN];
    let mut s = [zero; SPAN];
    let mut hit = [false; SPAN];
    let mut g = [zero; SPAN];
    // Per lane, for the traces: composited, alpha, capped, transmittance in front.
    let mut took = [false; SPAN];
    let mut alphas = [zero; SPAN];
    let mut caps = [false; SPAN];
    let mut fronts = [zero; SPAN];
    for k in 0..tile.len() {
        if n_alive == 0 {
            break;
        }
        let m = tile.mean2d[k];
        let q = tile.conic[k];
        let cut = tile.s_cut[k];
        // The power of every lane and its test, as `raster::hit` evaluates them (the same
        // operations in the same order).
        let dy = m[1] - py;
        let qyy = q[2] * dy * dy;
        for l in 0..SPAN {
            dx[l] = m[0] - px[l];
            s[l] = half * (q[0] * dx[l] * dx[l] + qyy) + q[1] * dx[l] * dy;
        }
        let mut any = false;
        for l in 0..SPAN {
            hit[l] = alive[l] & !(s[l] < zero || s[l] > cut);
            any |= hit[l];
        }
        if !any {
            continue;
        }
        // The falloff of every lane (arithmetic alone in f32: vectorised, the same bits as
        // `raster::hit`'s); the lanes that did not pass are not read.
        for l in 0..SPAN {
            g[l] = falloff(s[l]);
        }
        // Alpha, the exclusive stop and the accumulation, lane by lane as selects.
        let (o, col, z) = (tile.opacity[k], tile.color[k], tile.depth[k]);
        let k1 = k as u32 + 1;
        let mut stopped = false;
        for l in 0..SPAN {
            let raw = o * g[l];
            let capped = raw > amax;
            let alpha = if capped { amax } else { raw };
            // As `raster::hit`'s `alpha < amin` test: a NaN alpha passes.
            #[allow(clippy::neg_cmp_op_on_partial_ord)]
            let ok = hit[l] & !(alpha < amin);
            let t_next = t[l] * (one - alpha);
            let stop = ok & (t_next <= tmin);
            let take = ok & !stop;
            let w = alpha * t[l];
            for ch in 0..3 {
                rgb[ch][l] = if take {
                    rgb[ch][l] + w * col[ch]
                } else {
                    rgb[ch][l]
                };
            }
            depth[l] = if take { depth[l] + w * z } else { depth[l] };
            last[l] = if take { k1 } else { last[l] };
            took[l] = take;
            alphas[l] = alpha;
            caps[l] = capped;
            fronts[l] = t[l];
            t[l] = if take { t_next } else { t[l] };
            alive[l] &= !stop;
            stopped |= stop;
        }
        if let Some(tr) = traces.as_deref_mut() {
            for l in 0..SPAN {
                if took[l] {
                    tr[l].push(Contribution {
                        k: k as u32,
                        alpha: alphas[l],
                        t: fronts[l],
                        g: g[l],
                        d: [dx[l], dy],
                        capped: caps[l],
                    });
                }
            }
        }
        if stopped {
            n_alive = alive.iter().filter(|&&a| a).count();
        }
    }
    for l in 0..live.len() {
        if !live[l] {
            continue;
        }
        let px_rgb: [T; 3] = std::array::from_fn(|ch| rgb[ch][l] + t[l] * background[ch]);
        let alpha = one - t[l];
        out[l] = (
            PixelOut {
                rgb: px_rgb,
                alpha,
                depth: depth[l] / alpha.max(c(1e-10)),
                last: last[l],
            },
            t[l],
        );
    }
}

/// [`composite_span`] in f32, compiled with AVX2 where the processor has it (detected at run
/// time): the same results.
#[inline]
pub fn composite_span_f32(
    i0: u32,
    j: u32,
    live: &[bool],
    tile: &TileSplats<f32>,
    background: &[f32; 3],
    out: &mut [(PixelOut<f32>, f32); SPAN],
    traces: Option<&mut [Vec<Contribution<f32>>; SPAN]>,
) {
    #[cfg(target_arch = "x86_64")]
    if std::is_x86_feature_detected!("avx2") {
        // SAFETY: the processor supports AVX2 (checked just above).
        return unsafe { composite_span_avx2(i0, j, live, tile, background, out, traces) };
    }
    composite_span(i0, j, live, tile, background, out, traces)
}

/// [`composite_span`] compiled with AVX2 enabled (same arithmetic: no fused operations).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn composite_span_avx2(
    i0: u32,
    j: u32,
    live: &[bool],
    tile: &TileSplats<f32>,
    background: &[f32; 3],
    out: &mut [(PixelOut<f32>, f32); SPAN],
    traces: Option<&mut [Vec<Contribution<f32>>; SPAN]>,
) {
    composite_span(i0, j, live, tile, background, out, traces)
}
