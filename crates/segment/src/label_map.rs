//! The label map the Gaussians' labels draw in a view: per pixel, the class with the largest
//! compositing weight `alpha T` (the renderer's own weights, [`r4d_splat::weights`]). Used for
//! the disagreement maps of `r4d segment` (where the lifted labels and a view's mask differ).

use crate::lift::project_for_weights;
use crate::Par;
use r4d_splat::project::CamParams;
use r4d_splat::raster;
use r4d_splat::weights::{tile_weights, WeightScratch};
use r4d_splat::{Camera, Gaussians, RasterizeMode};

/// The label map of `labels` (one per Gaussian, -1 static) seen by `cam`: 0 where static
/// Gaussians or nothing (accumulated alpha below one half) cover the pixel most, `k + 1`
/// where part `k` does. Labels outside `-1 .. num_parts` count as static.
pub fn label_map(
    g: &Gaussians,
    cam: &Camera,
    labels: &[i32],
    num_parts: usize,
    mode: RasterizeMode,
) -> Vec<u16> {
    let (w, h) = (cam.width, cam.height);
    let mut out = vec![0u16; (w as usize) * (h as usize)];
    if labels.len() != g.len() {
        return out;
    }
    let cp = CamParams::<f32>::new(cam, mode);
    let proj = project_for_weights(g, &cp, Par::Rayon);
    let order = raster::depth_order(&proj);
    let bins = raster::bin_tiles(&proj, &order, w, h);
    let s = num_parts + 1;
    let mut scratch = WeightScratch::<f32>::default();
    // tile_weights emits each pixel's Gaussians consecutively: accumulate, flush on change.
    let mut acc = vec![0f32; s];
    let mut cur: Option<usize> = None;
    let flush = |p: usize, acc: &mut [f32], out: &mut [u16]| {
        let alpha: f32 = acc.iter().sum();
        let mut best = 0;
        for (c, &x) in acc.iter().enumerate() {
            if x > acc[best] {
                best = c;
            }
        }
        out[p] = if alpha < 0.5 { 0 } else { best as u16 };
        acc.iter_mut().for_each(|x| *x = 0.0);
    };
    for ty in 0..bins.tiles_y {
        for tx in 0..bins.tiles_x {
            let ids = bins.tile((ty * bins.tiles_x + tx) as usize);
            tile_weights(&proj, ids, tx, ty, w, h, &mut scratch, |i, j, id, wt| {
                let p = (j * w + i) as usize;
                if cur != Some(p) {
                    if let Some(q) = cur {
                        flush(q, &mut acc, &mut out);
                    }
                    cur = Some(p);
                }
                let l = labels[id as usize];
                let c = if (0..num_parts as i32).contains(&l) {
                    l as usize + 1
                } else {
                    0
                };
                acc[c] += wt;
            });
        }
    }
    if let Some(q) = cur {
        flush(q, &mut acc, &mut out);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::synthetic;

    #[test]
    fn the_true_labels_draw_the_ray_cast_mask() {
        let scene = synthetic::three_parts(8000, 4);
        let cams = synthetic::ring_cameras(2, 160, 120);
        for cam in &cams {
            let drawn = label_map(
                &scene.gaussians,
                cam,
                &scene.truth,
                3,
                RasterizeMode::Classic,
            );
            let mask = scene.label_mask(cam);
            let same = drawn.iter().zip(&mask).filter(|(a, b)| a == b).count();
            let frac = same as f64 / mask.len() as f64;
            assert!(frac > 0.97, "{frac}");
            assert!(drawn.contains(&3));
        }
    }
}
