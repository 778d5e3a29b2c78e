//! Trust in a mask pixel by its distance to the nearest label boundary.
//!
//! Segmenters are wrong near boundaries by a few pixels: a pixel `d` pixels from the nearest
//! pixel of another label is trusted with `b = min(1, d / min(d0, t))`, where `d0` is
//! [`LiftConfig::boundary_px`](crate::LiftConfig::boundary_px) and `t` the **local
//! thickness** of the pixel's own region (the largest distance within `d0` pixels, in the same
//! label). A wide region's pixels reach full trust `d0` pixels inside; a part only a few
//! pixels wide (a stem) keeps full trust along its middle line (`t` is its half width), so
//! thin parts are not discounted away, while the broad background next to them is.
//!
//! Distances are chamfer distances (steps 1 and sqrt 2, two passes) from the pixel centre to
//! the boundary: a pixel with a 4-neighbour of another label is 0.5 away. [`IGNORE`] pixels
//! form a label of their own. Cost: a few passes over the image, `8 H W` bytes.

use crate::mask::IGNORE;

/// Chamfer distance of every pixel to the nearest label boundary (0.5 for a pixel with a
/// 4-neighbour of another label; `f32::MAX` where the image has one label only).
pub fn boundary_distance(labels: &[u16], width: usize, height: usize) -> Vec<f32> {
    let (w, h) = (width, height);
    let mut d = vec![f32::MAX; w * h];
    for y in 0..h {
        for x in 0..w {
            let l = labels[y * w + x];
            let differs = (x > 0 && labels[y * w + x - 1] != l)
                || (x + 1 < w && labels[y * w + x + 1] != l)
                || (y > 0 && labels[(y - 1) * w + x] != l)
                || (y + 1 < h && labels[(y + 1) * w + x] != l);
            if differs {
                d[y * w + x] = 0.5;
            }
        }
    }
    const S2: f32 = std::f32::consts::SQRT_2;
    let relax = |d: &mut [f32], p: usize, q: usize, step: f32| {
        let c = d[q] + step;
        if c < d[p] {
            d[p] = c;
        }
    };
    for y in 0..h {
        for x in 0..w {
            let p = y * w + x;
            if x > 0 {
                relax(&mut d, p, p - 1, 1.0);
            }
            if y > 0 {
                relax(&mut d, p, p - w, 1.0);
                if x > 0 {
                    relax(&mut d, p, p - w - 1, S2);
                }
                if x + 1 < w {
                    relax(&mut d, p, p - w + 1, S2);
                }
            }
        }
    }
    for y in (0..h).rev() {
        for x in (0..w).rev() {
            let p = y * w + x;
            if x + 1 < w {
                relax(&mut d, p, p + 1, 1.0);
            }
            if y + 1 < h {
                relax(&mut d, p, p + w, 1.0);
                if x + 1 < w {
                    relax(&mut d, p, p + w + 1, S2);
                }
                if x > 0 {
                    relax(&mut d, p, p + w - 1, S2);
                }
            }
        }
    }
    d
}

/// The trust `b` of every pixel (module docs) for the label map `labels`; `d0 <= 0` gives 1
/// everywhere.
pub fn boundary_trust(labels: &[u16], width: usize, height: usize, d0: f32) -> Vec<f32> {
    let n = width * height;
    if d0 <= 0.0 || n == 0 {
        return vec![1.0; n];
    }
    let d = boundary_distance(labels, width, height);
    let r = d0.ceil() as usize;
    // Local thickness: the largest distance within `r` pixels in the same label, separably
    // (rows, then columns of the row maxima).
    let (w, h) = (width, height);
    let mut rows = vec![0f32; n];
    for y in 0..h {
        for x in 0..w {
            let l = labels[y * w + x];
            let mut m = d[y * w + x];
            for xx in x.saturating_sub(r)..(x + r + 1).min(w) {
                if labels[y * w + xx] == l {
                    m = m.max(d[y * w + xx]);
                }
            }
            rows[y * w + x] = m;
        }
    }
    let mut out = vec![1f32; n];
    for y in 0..h {
        for x in 0..w {
            let l = labels[y * w + x];
            let mut t = rows[y * w + x];
            for yy in y.saturating_sub(r)..(y + r + 1).min(h) {
                if labels[yy * w + x] == l {
                    t = t.max(rows[yy * w + x]);
                }
            }
            let dd = d[y * w + x];
            out[y * w + x] = if l == IGNORE {
                0.0
            } else {
                (dd / d0.min(t)).min(1.0)
            };
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn thin_parts_keep_their_middle_and_wide_regions_their_inside() {
        // A 3-pixel-wide vertical stripe (label 1) on a wide background (0).
        let (w, h) = (30usize, 20usize);
        let mut l = vec![0u16; w * h];
        for y in 0..h {
            for x in 14..17 {
                l[y * w + x] = 1;
            }
        }
        let d = boundary_distance(&l, w, h);
        assert_eq!(d[10 * w + 14], 0.5);
        assert_eq!(d[10 * w + 15], 1.5);
        assert_eq!(d[10 * w + 13], 0.5);
        assert_eq!(d[10 * w + 10], 3.5);
        let b = boundary_trust(&l, w, h, 3.0);
        // The stripe's middle: fully trusted; its edges: 0.5 / 1.5.
        assert_eq!(b[10 * w + 15], 1.0);
        assert!((b[10 * w + 14] - 1.0 / 3.0).abs() < 1e-6);
        // The background next to it: 0.5 / 3; three pixels away: full.
        assert!((b[10 * w + 13] - 0.5 / 3.0).abs() < 1e-6);
        assert_eq!(b[10 * w + 10], 1.0);
        assert!(boundary_trust(&l, w, h, 0.0).iter().all(|&v| v == 1.0));
        // One label only: full trust everywhere.
        let one = vec![2u16; w * h];
        assert!(boundary_trust(&one, w, h, 3.0).iter().all(|&v| v == 1.0));
    }
}
