//! Tile binning and front-to-back alpha compositing of one pixel, and its VJP, written once
//! for every backend (gsplat's conventions: pixel centres at `+0.5`, `s < 0` or
//! `alpha < 1/255` skipped, alpha capped at 0.999, exclusive stop at `T <= 1e-4`).

use crate::camera::consts;
use crate::project::{Projected, ProjectedGrad};
use crate::real::Real;

/// Per-tile lists of Gaussian indices, each sorted front to back (depth as f32, then index).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct TileBins {
    /// Tiles along x.
    pub tiles_x: u32,
    /// Tiles along y.
    pub tiles_y: u32,
    /// `offsets[t] .. offsets[t + 1]` indexes `ids` for tile `t = ty * tiles_x + tx`.
    pub offsets: Vec<u32>,
    /// Gaussian indices.
    pub ids: Vec<u32>,
}

impl TileBins {
    /// The Gaussians of tile `t`, front to back.
    pub fn tile(&self, t: usize) -> &[u32] {
        &self.ids[self.offsets[t] as usize..self.offsets[t + 1] as usize]
    }
}

/// The tile rectangle `[x0, x1) x [y0, y1)` a projected Gaussian touches (gsplat's rule).
pub fn tile_rect<T: Real>(p: &Projected<T>, tiles_x: u32, tiles_y: u32) -> [u32; 4] {
    let ts = consts::TILE as f64;
    let (u, v) = (p.mean2d[0].f64(), p.mean2d[1].f64());
    let (rx, ry) = (p.radii[0] as f64, p.radii[1] as f64);
    let cl = |a: f64, n: u32| a.clamp(0.0, n as f64) as u32;
    [
        cl(((u - rx) / ts).floor(), tiles_x),
        cl(((u + rx) / ts).ceil(), tiles_x),
        cl(((v - ry) / ts).floor(), tiles_y),
        cl(((v + ry) / ts).ceil(), tiles_y),
    ]
}

/// The depth sort order of visible Gaussians: by depth rounded to f32, ties by index.
pub fn depth_order<T: Real>(proj: &[Projected<T>]) -> Vec<u32> {
    let mut order: Vec<u32> = (0..proj.len() as u32)
        .filter(|&i| proj[i as usize].radii != [0, 0])
        .collect();
    order.sort_by(|&a, &b| {
        let (da, db) = (
            proj[a as usize].depth.f64() as f32,
            proj[b as usize].depth.f64() as f32,
        );
        da.total_cmp(&db).then(a.cmp(&b))
    });
    order
}

/// Bins Gaussians (in `order`, front to back) into `tiles_x * tiles_y` tiles.
pub fn bin_tiles<T: Real>(
    proj: &[Projected<T>],
    order: &[u32],
    width: u32,
    height: u32,
) -> TileBins {
    let tiles_x = width.div_ceil(consts::TILE);
    let tiles_y = height.div_ceil(consts::TILE);
    let nt = (tiles_x * tiles_y) as usize;
    let mut counts = vec![0u32; nt + 1];
    for &g in order {
        let [x0, x1, y0, y1] = tile_rect(&proj[g as usize], tiles_x, tiles_y);
        for ty in y0..y1 {
            for tx in x0..x1 {
                counts[(ty * tiles_x + tx) as usize + 1] += 1;
            }
        }
    }
    for t in 0..nt {
        counts[t + 1] += counts[t];
    }
    let offsets = counts;
    let mut fill = offsets.clone();
    let mut ids = vec![0u32; offsets[nt] as usize];
    for &g in order {
        let [x0, x1, y0, y1] = tile_rect(&proj[g as usize], tiles_x, tiles_y);
        for ty in y0..y1 {
            for tx in x0..x1 {
                let t = (ty * tiles_x + tx) as usize;
                ids[fill[t] as usize] = g;
                fill[t] += 1;
            }
        }
    }
    TileBins {
        tiles_x,
        tiles_y,
        offsets,
        ids,
    }
}

/// The result of compositing one pixel.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PixelOut<T> {
    /// Colour including the background.
    pub rgb: [T; 3],
    /// Accumulated opacity `1 - T_final`.
    pub alpha: T,
    /// Expected depth (0 where nothing was hit).
    pub depth: T,
    /// One past the tile-list position of the last Gaussian composited (0: none): with the
    /// final transmittance, what the VJP needs to walk the pixel back to front
    /// ([`trace_back`]) without compositing it again.
    pub last: u32,
}

/// The Gaussians of one tile, front to back, gathered into contiguous arrays (the pixels of a
/// tile all walk the same list), with each Gaussian's cut-off exponent: a Gaussian is skipped
/// without evaluating `exp` where `s > ln(255 o) + 1e-3`, which implies `alpha < 1/255` with
/// room to spare for rounding, so results equal the plain test's.
#[derive(Clone, Debug, Default)]
pub struct TileSplats<T> {
    /// Gaussian indices.
    pub ids: Vec<u32>,
    /// Centres.
    pub mean2d: Vec<[T; 2]>,
    /// Conics.
    pub conic: Vec<[T; 3]>,
    /// Opacities.
    pub opacity: Vec<T>,
    /// `ln(255 o) + 1e-3`.
    pub s_cut: Vec<T>,
    /// Colours.
    pub color: Vec<[T; 3]>,
    /// Depths.
    pub depth: Vec<T>,
}

impl<T: Real> TileSplats<T> {
    /// Refills from a tile's id list (buffers are reused).
    pub fn gather(&mut self, ids: &[u32], proj: &[Projected<T>]) {
        self.ids.clear();
        self.mean2d.clear();
        self.conic.clear();
        self.opacity.clear();
        self.s_cut.clear();
        self.color.clear();
        self.depth.clear();
        let k255 = T::c(255.0);
        let margin = T::c(1e-3);
        for &id in ids {
            let p = &proj[id as usize];
            self.ids.push(id);
            self.mean2d.push(p.mean2d);
            self.conic.push(p.conic);
            self.opacity.push(p.opacity);
            self.s_cut.push((k255 * p.opacity).ln() + margin);
            self.color.push(p.color);
            self.depth.push(p.depth);
        }
    }

    /// Number of Gaussians.
    pub fn len(&self) -> usize {
        self.ids.len()
    }

    /// True when empty.
    pub fn is_empty(&self) -> bool {
        self.ids.is_empty()
    }
}

/// One composited contribution, kept for the VJP.
#[derive(Clone, Copy, Debug, Default)]
pub struct Contribution<T> {
    /// Index into the tile's lists.
    pub k: u32,
    /// Alpha at this pixel.
    pub alpha: T,
    /// Transmittance before this Gaussian.
    pub t: T,
    /// `exp(-s)`.
    pub g: T,
    /// Offsets `(u - px, v - py)`.
    pub d: [T; 2],
    /// Alpha hit the 0.999 cap (no gradient through opacity and shape).
    pub capped: bool,
}

/// Composites pixel `(i, j)` over its tile's Gaussians; pushes each composited Gaussian onto
/// `trace` when given. Returns the pixel and the final transmittance.
pub fn composite_pixel<T: Real>(
    i: u32,
    j: u32,
    tile: &TileSplats<T>,
    background: &[T; 3],
    mut trace: Option<&mut Vec<Contribution<T>>>,
) -> (PixelOut<T>, T) {
    let c = T::c;
    let (px, py) = (c(i as f64 + 0.5), c(j as f64 + 0.5));
    let tmin = c(consts::T_MIN);
    let mut t = T::one();
    let mut rgb = [T::zero(); 3];
    let mut depth = T::zero();
    let mut last = 0u32;
    for k in 0..tile.len() {
        let Some(h) = hit(tile, k, px, py) else {
            continue;
        };
        let (alpha, g, capped, [dx, dy]) = (h.alpha, h.g, h.capped, h.d);
        let t_next = t * (T::one() - alpha);
        if t_next <= tmin {
            break;
        }
        last = k as u32 + 1;
        let w = alpha * t;
        let col = tile.color[k];
        for ch in 0..3 {
            rgb[ch] += w * col[ch];
        }
        depth += w * tile.depth[k];
        if let Some(tr) = trace.as_deref_mut() {
            tr.push(Contribution {
                k: k as u32,
                alpha,
                t,
                g,
                d: [dx, dy],
                capped,
            });
        }
        t = t_next;
    }
    for ch in 0..3 {
        rgb[ch] += t * background[ch];
    }
    let alpha = T::one() - t;
    let depth = depth / alpha.max(c(1e-10));
    (
        PixelOut {
            rgb,
            alpha,
            depth,
            last,
        },
        t,
    )
}

/// A Gaussian that passes the per-pixel tests: its alpha (capped), `exp(-s)`, whether the
/// cap applied, and the offsets `(u - px, v - py)`.
struct Hit<T> {
    alpha: T,
    g: T,
    capped: bool,
    d: [T; 2],
}

/// The per-Gaussian rule of compositing, once for [`composite_pixel`] and [`trace_back`]
/// (evaluated for a row of pixels at once, with the same operations, by
/// [`crate::span::composite_span`], and mirrored by `r4d-shaders`' `lib/composite.wgsl`): skipped when the power is negative
/// or above the cut-off, or when the capped alpha is below 1/255.
#[inline(always)]
fn hit<T: Real>(tile: &TileSplats<T>, k: usize, px: T, py: T) -> Option<Hit<T>> {
    let (amax, amin) = (T::c(consts::ALPHA_MAX), T::c(consts::ALPHA_MIN));
    let m = tile.mean2d[k];
    let q = tile.conic[k];
    let dx = m[0] - px;
    let dy = m[1] - py;
    let s = T::c(0.5) * (q[0] * dx * dx + q[2] * dy * dy) + q[1] * dx * dy;
    if s < T::zero() || s > tile.s_cut[k] {
        return None;
    }
    let g = crate::falloff::falloff(s);
    let raw = tile.opacity[k] * g;
    let capped = raw > amax;
    let alpha = if capped { amax } else { raw };
    if alpha < amin {
        return None;
    }
    Some(Hit {
        alpha,
        g,
        capped,
        d: [dx, dy],
    })
}

/// Rebuilds pixel `(i, j)`'s composited contributions (front to back, as
/// [`composite_pixel`]'s trace) from what its forward pass kept: the final transmittance
/// `t_final` and [`PixelOut::last`]. Walks the tile's Gaussians back to front from `last`,
/// recovering the transmittance in front of each as `T / (1 - alpha)` (gsplat's and the GPU
/// kernel's recursion), so the VJP does not composite the pixel again.
pub fn trace_back<T: Real>(
    i: u32,
    j: u32,
    tile: &TileSplats<T>,
    t_final: T,
    last: u32,
    trace: &mut Vec<Contribution<T>>,
) {
    trace.clear();
    let (px, py) = (T::c(i as f64 + 0.5), T::c(j as f64 + 0.5));
    let mut t = t_final;
    for k in (0..(last as usize).min(tile.len())).rev() {
        let Some(h) = hit(tile, k, px, py) else {
            continue;
        };
        t = t / (T::one() - h.alpha);
        trace.push(Contribution {
            k: k as u32,
            alpha: h.alpha,
            t,
            g: h.g,
            d: h.d,
            capped: h.capped,
        });
    }
    trace.reverse();
}

/// VJP of [`composite_pixel`] for the colour output: `trace` is the forward's list and
/// `t_final` its final transmittance; `emit(id, grad)` receives each Gaussian's gradient.
pub fn composite_pixel_vjp<T: Real>(
    trace: &[Contribution<T>],
    t_final: T,
    tile: &TileSplats<T>,
    background: &[T; 3],
    d_rgb: &[T; 3],
    mut emit: impl FnMut(u32, &ProjectedGrad<T>),
) {
    let dotc = |a: &[T; 3], b: &[T; 3]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
    let half = T::c(0.5);
    // Sum over everything behind the current Gaussian (and the background) of its share.
    let mut behind = t_final * dotc(d_rgb, background);
    for e in trace.iter().rev() {
        let k = e.k as usize;
        let q = tile.conic[k];
        let w = e.alpha * e.t;
        let gc = dotc(d_rgb, &tile.color[k]);
        let d_alpha = e.t * gc - behind / (T::one() - e.alpha);
        behind += w * gc;
        let mut gr = ProjectedGrad {
            color: d_rgb.map(|v| v * w),
            ..Default::default()
        };
        if !e.capped {
            gr.opacity = d_alpha * e.g;
            let d_s = -d_alpha * e.alpha;
            let [dx, dy] = e.d;
            gr.mean2d = [d_s * (q[0] * dx + q[1] * dy), d_s * (q[2] * dy + q[1] * dx)];
            gr.conic = [d_s * half * dx * dx, d_s * dx * dy, d_s * half * dy * dy];
        }
        emit(tile.ids[k], &gr);
    }
}
