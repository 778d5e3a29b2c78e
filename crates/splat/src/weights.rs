//! Per-Gaussian compositing weights: for every pixel, which Gaussians the forward pass
//! composites and with what weight `w_k = alpha_k T_k` (alpha times the transmittance in front
//! of the Gaussian), front to back. This is what mask lifting (`r4d-segment`) accumulates: the
//! share of a pixel's colour that comes from each Gaussian.
//!
//! There is no second copy of the compositing rule here: [`pixel_weights`] runs
//! [`composite_pixel`] with its trace (the record the VJP replays) and reports each entry of
//! the trace, so the thresholds (`s < 0`, `alpha < 1/255`, the 0.999 cap, the stop at
//! `T <= 1e-4`) are the renderer's by construction. The weights of a pixel sum to its
//! accumulated opacity `1 - T_final` (a telescoping sum), up to rounding.
//!
//! Scheduling is the caller's: [`tile_weights`] handles one tile (a parallel caller deals
//! tiles to workers, each with its own [`WeightScratch`]); [`image_weights`] is the
//! single-threaded whole-image version, for tests and small images.

use crate::camera::consts;
use crate::project::Projected;
use crate::raster::{composite_pixel, Contribution, TileBins, TileSplats};
use crate::real::Real;

/// Buffers one worker reuses across tiles: the gathered tile and a pixel's trace.
#[derive(Clone, Debug, Default)]
pub struct WeightScratch<T> {
    /// The current tile's Gaussians, front to back.
    pub tile: TileSplats<T>,
    /// The current pixel's composited Gaussians.
    pub trace: Vec<Contribution<T>>,
}

/// Composites pixel `(i, j)` over its tile's Gaussians exactly as [`composite_pixel`] does and
/// calls `emit(id, alpha * T)` for every Gaussian it composites, front to back (`id` indexes
/// the scene). Returns the pixel's accumulated opacity `1 - T_final`.
pub fn pixel_weights<T: Real>(
    i: u32,
    j: u32,
    tile: &TileSplats<T>,
    trace: &mut Vec<Contribution<T>>,
    mut emit: impl FnMut(u32, T),
) -> T {
    trace.clear();
    let (px, _) = composite_pixel(i, j, tile, &[T::zero(); 3], Some(trace));
    for c in trace.iter() {
        emit(tile.ids[c.k as usize], c.alpha * c.t);
    }
    px.alpha
}

/// The weights of every pixel of tile `(tx, ty)`: gathers the tile's Gaussians (`ids`, front
/// to back, as [`TileBins::tile`] lists them) into `scratch`, then for each pixel of the tile
/// inside the `width x height` image, row by row, calls `emit(i, j, id, weight)` for each
/// composited Gaussian. Pixels of an empty tile are skipped.
#[expect(
    clippy::too_many_arguments,
    reason = "a tile, its image and the scratch: the kernel's inputs, kept flat like the raster functions"
)]
pub fn tile_weights<T: Real>(
    proj: &[Projected<T>],
    ids: &[u32],
    tx: u32,
    ty: u32,
    width: u32,
    height: u32,
    scratch: &mut WeightScratch<T>,
    mut emit: impl FnMut(u32, u32, u32, T),
) {
    if ids.is_empty() {
        return;
    }
    let ts = consts::TILE;
    scratch.tile.gather(ids, proj);
    let WeightScratch { tile, trace } = scratch;
    for j in ty * ts..((ty + 1) * ts).min(height) {
        for i in tx * ts..((tx + 1) * ts).min(width) {
            pixel_weights(i, j, tile, trace, |id, w| emit(i, j, id, w));
        }
    }
}

/// The weights of every pixel of an image, as lists: pixel `p = j * width + i` has the
/// entries `offsets[p] .. offsets[p + 1]` of `ids` and `weights`, front to back.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PixelWeights<T> {
    /// Image width.
    pub width: u32,
    /// Image height.
    pub height: u32,
    /// `width * height + 1` offsets into `ids` and `weights`.
    pub offsets: Vec<u32>,
    /// Gaussian indices.
    pub ids: Vec<u32>,
    /// Weights `alpha * T`.
    pub weights: Vec<T>,
}

impl<T: Real> PixelWeights<T> {
    /// The `(id, weight)` entries of pixel `(i, j)`, front to back.
    pub fn pixel(&self, i: u32, j: u32) -> impl Iterator<Item = (u32, T)> + '_ {
        let p = (j * self.width + i) as usize;
        let r = self.offsets[p] as usize..self.offsets[p + 1] as usize;
        self.ids[r.clone()]
            .iter()
            .copied()
            .zip(self.weights[r].iter().copied())
    }
}

/// Single-threaded weights of every pixel (`proj` and `bins` as the reference renderer's
/// `project` and `bin_tiles` produce them).
pub fn image_weights<T: Real>(
    proj: &[Projected<T>],
    bins: &TileBins,
    width: u32,
    height: u32,
) -> PixelWeights<T> {
    let mut lists: Vec<Vec<(u32, T)>> = vec![Vec::new(); (width * height) as usize];
    let mut scratch = WeightScratch::default();
    for ty in 0..bins.tiles_y {
        for tx in 0..bins.tiles_x {
            let ids = bins.tile((ty * bins.tiles_x + tx) as usize);
            tile_weights(
                proj,
                ids,
                tx,
                ty,
                width,
                height,
                &mut scratch,
                |i, j, id, w| lists[(j * width + i) as usize].push((id, w)),
            );
        }
    }
    let mut out = PixelWeights {
        width,
        height,
        offsets: Vec::with_capacity(lists.len() + 1),
        ..Default::default()
    };
    out.offsets.push(0);
    for l in lists {
        for (id, w) in l {
            out.ids.push(id);
            out.weights.push(w);
        }
        out.offsets.push(out.ids.len() as u32);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::{Camera, RasterizeMode, RenderSettings};
    use crate::gaussians::Gaussians;
    use crate::project::CamParams;
    use crate::reference::{self, Scene};

    fn scene(n: usize, seed: u64) -> Gaussians {
        let mut s = seed;
        let mut r = move |a: f32, b: f32| {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            a + (b - a) * ((s >> 40) as f32 / (1u64 << 24) as f32)
        };
        let mut g = Gaussians::default();
        for _ in 0..n {
            g.means.push([r(-0.6, 0.6), r(-0.6, 0.6), r(-0.4, 0.4)]);
            g.log_scales
                .push([r(-3.0, -1.6), r(-3.0, -1.6), r(-3.0, -1.6)]);
            g.quats
                .push([r(0.2, 1.0), r(-1.0, 1.0), r(-1.0, 1.0), r(-1.0, 1.0)]);
            g.opacity_logits.push(r(-1.0, 4.0));
            g.sh.extend([r(-1.0, 1.0), r(-1.0, 1.0), r(-1.0, 1.0)]);
        }
        g
    }

    /// The weights of each pixel sum to its alpha, and weighting each Gaussian's colour by
    /// them (plus `T_final` times the background) gives the rendered colour: same Gaussians,
    /// same order, same weights as the renderer.
    #[test]
    fn weights_reproduce_composite_pixel() {
        for (mode, seed) in [(RasterizeMode::Classic, 3), (RasterizeMode::Antialiased, 4)] {
            let g = scene(300, seed);
            let cam = Camera::look_at(45, 37, 60.0, [0.3, -2.5, 0.4], [0.0; 3], [0.0, 0.0, 1.0]);
            let settings = RenderSettings {
                background: [0.2, 0.5, 0.9],
                mode,
            };
            let s = Scene::<f64>::new(&g, None);
            let (img, proj) = reference::render(&s, &cam, &settings);
            let cp = CamParams::<f64>::new(&cam, mode);
            let bins = reference::bin_tiles(&proj, &cp);
            let pw = image_weights(&proj, &bins, cam.width, cam.height);
            let (mut covered, mut max_len) = (0, 0);
            for j in 0..cam.height {
                for i in 0..cam.width {
                    let k = (j * cam.width + i) as usize;
                    let (mut sum, mut rgb, mut n) = (0.0, [0.0; 3], 0);
                    for (id, w) in pw.pixel(i, j) {
                        assert!(w > 0.0 && w <= 1.0, "weight {w}");
                        sum += w;
                        for c in 0..3 {
                            rgb[c] += w * proj[id as usize].color[c];
                        }
                        n += 1;
                    }
                    assert!(
                        (sum - img.alpha[k]).abs() < 1e-12,
                        "pixel ({i}, {j}): weights sum to {sum}, alpha {}",
                        img.alpha[k]
                    );
                    for c in 0..3 {
                        let want = img.rgb[3 * k + c];
                        let got = rgb[c] + (1.0 - sum) * settings.background[c] as f64;
                        assert!((got - want).abs() < 1e-9, "pixel ({i}, {j}) channel {c}");
                    }
                    covered += (n > 0) as usize;
                    max_len = max_len.max(n);
                }
            }
            // The scene must exercise the rule: most pixels covered, some by many Gaussians.
            assert!(covered > (cam.width * cam.height) as usize / 2, "{covered}");
            assert!(max_len > 10, "{max_len}");
        }
    }

    /// The f32 weights match the f64 ones (the same rule in either precision).
    #[test]
    fn f32_weights_match_f64() {
        fn total<T: Real>(g: &Gaussians, cam: &Camera) -> f64 {
            let s = Scene::<T>::new(g, None);
            let cp = CamParams::<T>::new(cam, RasterizeMode::Classic);
            let proj = reference::project(&s, &cp);
            let bins = reference::bin_tiles(&proj, &cp);
            let w = image_weights(&proj, &bins, cam.width, cam.height);
            w.weights.iter().map(|w| w.f64()).sum()
        }
        let g = scene(200, 9);
        let cam = Camera::look_at(32, 32, 60.0, [0.0, -2.5, 0.0], [0.0; 3], [0.0, 0.0, 1.0]);
        let (t64, t32) = (total::<f64>(&g, &cam), total::<f32>(&g, &cam));
        assert!(t64 > 10.0, "{t64}");
        assert!((t64 - t32).abs() < 1e-4 * t64, "{t64} vs {t32}");
    }
}
