//! Lifting 2D masks onto the Gaussians.
//!
//! For Gaussian `g` and class `c` (0 = background, `k + 1` = part `k`) the lifter sums, over
//! every view and pixel, the weight with which the renderer composites `g` into the pixel
//! (`alpha T`, [`r4d_splat::weights`]) times the mask's value of `c` at the pixel:
//!
//! ```text
//! W[g][c] = sum_views sum_pixels alpha_g(x) T_g(x) m_c(x)
//! ```
//!
//! (LUDVIG's uplifting of 2D features: occluded Gaussians get no weight, because `T` in
//! front of them is ~0, and a Gaussian's share of a pixel is what it contributes to the
//! image). A label map votes one-hot (`m_c = 1` for its class, nothing at ignored pixels); a
//! probability map votes `m_k = p_k` for the parts and `1 - sum p` for the background. Then
//! per Gaussian the class weights are normalised, `p_c = W[g][c] / sum_c W[g][c]`, and a
//! softmax at temperature `tau`, `softmax(p / tau)`, gives the class probabilities: the label
//! is the argmax (background -> -1, static) and the confidence its probability. A Gaussian no
//! pixel of any view sees (all `W = 0`) is labelled -1 with confidence 0 ("unobserved"; the
//! KNN pass in [`mod@crate::smooth`] gives it its neighbours' label).
//!
//! Cost per view: projection (colour is not needed, so SH is skipped), the depth sort and
//! tile binning of the renderer, then the forward compositing of every pixel, each composited
//! Gaussian adding to `M + 1` (probabilities) or 1 (labels) accumulators. Tile rows are
//! dealt round-robin to `min(threads, 8)` workers, each with its own f64 accumulator of
//! `8 (M + 1) N` bytes, summed in a fixed order at the end (results do not depend on
//! scheduling for a given worker count).

use crate::error::{Error, Result};
use crate::mask::{MaskData, MaskSource, IGNORE};
use crate::Par;
use r4d_splat::project::{self as pj, CamParams, GaussianIn, Projected};
use r4d_splat::raster;
use r4d_splat::weights::{tile_weights, WeightScratch};
use r4d_splat::{Camera, Gaussians, RasterizeMode};

/// Settings of the lift.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LiftConfig {
    /// Softmax temperature `tau` over the normalised class weights (which lie in [0, 1]);
    /// smaller is more confident. Default 0.1.
    pub temperature: f32,
    /// Rasterize mode of the renderer that made the scene (opacity compensation).
    pub mode: RasterizeMode,
    /// Parallelism.
    pub par: Par,
}

impl Default for LiftConfig {
    fn default() -> Self {
        LiftConfig {
            temperature: 0.1,
            mode: RasterizeMode::Classic,
            par: Par::Rayon,
        }
    }
}

/// The result of lifting: accumulated class weights and the per-Gaussian decision.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Lifted {
    /// Number of parts `M`.
    pub num_parts: usize,
    /// `W[g][c]`, `N x (M + 1)` row-major; column 0 is the background.
    pub class_weights: Vec<f64>,
    /// Label per Gaussian (-1: background/static or unobserved).
    pub labels: Vec<i32>,
    /// Softmax probability of the label (0 when unobserved).
    pub confidence: Vec<f32>,
}

impl Lifted {
    /// Sum of Gaussian `g`'s class weights (0: no view sees it).
    pub fn total_weight(&self, g: usize) -> f64 {
        let s = self.num_parts + 1;
        self.class_weights[g * s..(g + 1) * s].iter().sum()
    }

    /// Number of Gaussians no view sees.
    pub fn unobserved(&self) -> usize {
        (0..self.labels.len())
            .filter(|&g| self.total_weight(g) <= 0.0)
            .count()
    }
}

/// Labels and confidences from class weights (`N x (M + 1)`, background first): normalise,
/// softmax at `temperature`, argmax (ties: the lower class, background first).
pub fn classify(class_weights: &[f64], num_parts: usize, temperature: f32) -> (Vec<i32>, Vec<f32>) {
    let s = num_parts + 1;
    assert_eq!(class_weights.len() % s, 0, "N x (M + 1) weights");
    let inv_t = 1.0 / temperature as f64;
    class_weights
        .chunks_exact(s)
        .map(|row| {
            let total: f64 = row.iter().sum();
            if total.is_nan() || total <= 0.0 {
                return (-1, 0.0);
            }
            let (mut best, mut arg) = (row[0], 0);
            for (c, &w) in row.iter().enumerate().skip(1) {
                if w > best {
                    (best, arg) = (w, c);
                }
            }
            // softmax(p / tau)[arg] = 1 / sum_c exp((p_c - p_arg) / tau)
            let z: f64 = row
                .iter()
                .map(|&w| ((w - best) / total * inv_t).exp())
                .sum();
            (arg as i32 - 1, (1.0 / z) as f32)
        })
        .unzip()
}

fn check_config(cfg: &LiftConfig) -> Result<()> {
    if !(cfg.temperature.is_finite() && cfg.temperature > 0.0) {
        return Err(Error::Input(format!(
            "temperature {} (must be positive and finite)",
            cfg.temperature
        )));
    }
    Ok(())
}

/// Projects every Gaussian for the weights only (colour skipped: SH degree 0, zero
/// coefficients). Culled Gaussians get radii (0, 0).
pub fn project_for_weights(g: &Gaussians, cam: &CamParams<f32>, par: Par) -> Vec<Projected<f32>> {
    let one = |i: usize| {
        let gi = GaussianIn {
            mean: g.means[i],
            log_scale: g.log_scales[i],
            quat: g.quats[i],
            opacity_logit: g.opacity_logits[i],
            f: None,
        };
        pj::project(&gi, &[0.0; 3], 0, cam).unwrap_or_default()
    };
    match par {
        #[cfg(feature = "parallel")]
        Par::Rayon => {
            use rayon::prelude::*;
            (0..g.len())
                .into_par_iter()
                .with_min_len(1024)
                .map(one)
                .collect()
        }
        _ => (0..g.len()).map(one).collect(),
    }
}

fn depth_order(proj: &[Projected<f32>], par: Par) -> Vec<u32> {
    match par {
        #[cfg(feature = "parallel")]
        Par::Rayon => {
            use rayon::prelude::*;
            let mut order: Vec<u32> = (0..proj.len() as u32)
                .into_par_iter()
                .filter(|&i| proj[i as usize].radii != [0, 0])
                .collect();
            // The same order as `raster::depth_order` (f32 depth, then index).
            order.par_sort_unstable_by(|&a, &b| {
                proj[a as usize]
                    .depth
                    .total_cmp(&proj[b as usize].depth)
                    .then(a.cmp(&b))
            });
            order
        }
        _ => raster::depth_order(proj),
    }
}

/// Number of accumulators (workers) the lift uses.
pub fn workers(par: Par) -> usize {
    match par {
        #[cfg(feature = "parallel")]
        Par::Rayon => rayon::current_num_threads().clamp(1, 8),
        _ => 1,
    }
}

/// Lifts the masks of every camera onto the Gaussians (see the module docs). `masks` gives
/// one mask per camera, of the camera's size.
pub fn lift<S: MaskSource + ?Sized>(
    g: &Gaussians,
    cameras: &[Camera],
    masks: &mut S,
    cfg: &LiftConfig,
) -> Result<Lifted> {
    lift_with_progress(g, cameras, masks, cfg, |_| {})
}

/// [`lift`], calling `progress(view)` after each view.
pub fn lift_with_progress<S: MaskSource + ?Sized>(
    g: &Gaussians,
    cameras: &[Camera],
    masks: &mut S,
    cfg: &LiftConfig,
    mut progress: impl FnMut(usize),
) -> Result<Lifted> {
    check_config(cfg)?;
    g.validate("scene")?;
    let m = masks.class_names().len();
    let s = m + 1;
    let n = g.len();
    let nw = workers(cfg.par);
    let mut accs = vec![vec![0f64; n * s]; nw];
    let mut scratch: Vec<WeightScratch<f32>> = vec![WeightScratch::default(); nw];
    for (v, cam) in cameras.iter().enumerate() {
        cam.validate(&format!("camera {v}")).map_err(Error::Input)?;
        let mask = masks.mask(v, cam)?;
        if (mask.width, mask.height) != (cam.width, cam.height) {
            return Err(Error::MaskSize {
                file: mask.origin,
                view: v,
                camera: cam.name.clone(),
                got_w: mask.width,
                got_h: mask.height,
                want_w: cam.width,
                want_h: cam.height,
            });
        }
        let px = (cam.width * cam.height) as usize;
        let ok = match &mask.data {
            MaskData::Labels(l) => l.len() == px,
            MaskData::Probabilities(p) => p.len() == px * m,
        };
        if !ok {
            return Err(Error::mask(
                &mask.origin,
                format!(
                    "pixel data does not fit {}x{} pixels and {m} classes",
                    cam.width, cam.height
                ),
            ));
        }
        let cp = CamParams::<f32>::new(cam, cfg.mode);
        let proj = project_for_weights(g, &cp, cfg.par);
        let order = depth_order(&proj, cfg.par);
        let bins = raster::bin_tiles(&proj, &order, cam.width, cam.height);
        let (w, h) = (cam.width, cam.height);
        let data = &mask.data;
        let (proj, bins) = (&proj, &bins);
        let work = |wk: usize, acc: &mut [f64], sc: &mut WeightScratch<f32>| {
            for ty in (wk as u32..bins.tiles_y).step_by(nw) {
                for tx in 0..bins.tiles_x {
                    let ids = bins.tile((ty * bins.tiles_x + tx) as usize);
                    match data {
                        MaskData::Labels(l) => {
                            tile_weights(proj, ids, tx, ty, w, h, sc, |i, j, id, wt| {
                                let c = l[(j * w + i) as usize];
                                if c != IGNORE {
                                    acc[id as usize * s + c as usize] += wt as f64;
                                }
                            })
                        }
                        MaskData::Probabilities(p) => {
                            tile_weights(proj, ids, tx, ty, w, h, sc, |i, j, id, wt| {
                                let k = (j * w + i) as usize * m;
                                let q = &p[k..k + m];
                                let a = &mut acc[id as usize * s..(id as usize + 1) * s];
                                let wt = wt as f64;
                                let parts: f32 = q.iter().sum();
                                a[0] += wt * (1.0 - parts).max(0.0) as f64;
                                for (ac, &qc) in a[1..].iter_mut().zip(q) {
                                    *ac += wt * qc as f64;
                                }
                            })
                        }
                    }
                }
            }
        };
        match cfg.par {
            #[cfg(feature = "parallel")]
            Par::Rayon if nw > 1 => {
                use rayon::prelude::*;
                accs.par_iter_mut()
                    .zip(scratch.par_iter_mut())
                    .enumerate()
                    .for_each(|(wk, (acc, sc))| work(wk, acc, sc));
            }
            _ => {
                for (wk, (acc, sc)) in accs.iter_mut().zip(scratch.iter_mut()).enumerate() {
                    work(wk, acc, sc);
                }
            }
        }
        progress(v);
    }
    let mut it = accs.into_iter();
    let mut class_weights = it.next().unwrap_or_default();
    for a in it {
        for (x, y) in class_weights.iter_mut().zip(a) {
            *x += y;
        }
    }
    let (labels, confidence) = classify(&class_weights, m, cfg.temperature);
    Ok(Lifted {
        num_parts: m,
        class_weights,
        labels,
        confidence,
    })
}
