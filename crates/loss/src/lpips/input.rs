//! The first layer's input: frame rows through the lpips scaling layer, and AlexNet's
//! strided first convolution rewritten as a stride-1 one.
//!
//! A `k x k` convolution with stride `s` and padding `p` equals a stride-1 `ceil(k/s)`
//! convolution without padding over the space-to-depth image, whose pixel `(R, X)` holds the
//! `s x s` block of input pixels starting at `(s R - p, s X - p)` as `Cin s^2` channels
//! (channel `(c s + sy) s + sx`), with the kernel regrouped the same way and zero-extended
//! to `s ceil(k/s)` taps. AlexNet's 11x11 stride-4 layer becomes a 3x3 convolution over 48
//! channels, which runs as Winograd like every other layer.

use std::ops::Range;

use super::arch::ConvSpec;
use super::layers::Band;
use super::Pixel;

/// The lpips package's scaling layer.
const SHIFT: [f32; 3] = [-0.030, -0.088, -0.188];
const SCALE: [f32; 3] = [0.458, 0.448, 0.450];

/// `[0, 1]` to `[-1, 1]`, then the scaling layer, in f32 as PyTorch evaluates it.
#[inline]
fn scaled<P: Pixel>(v: P, c: usize) -> f32 {
    (2.0 * v.unit() - 1.0 - SHIFT[c]) / SCALE[c]
}

/// The first convolution as it runs: stride 1, either the original or its space-to-depth
/// rewrite (`block` > 1).
#[derive(Clone, Debug)]
pub(crate) struct FirstLayer {
    /// The stride-1 convolution that runs (`pad` 0 for a rewrite).
    pub spec: ConvSpec,
    /// Its weights (OIHW).
    pub weight: Vec<f32>,
    /// The original stride (the space-to-depth block side); 1 when not rewritten.
    block: usize,
    /// The original padding.
    pad: usize,
}

impl FirstLayer {
    pub fn new(spec: &ConvSpec, weight: &[f32]) -> FirstLayer {
        let s = spec.stride;
        if s == 1 {
            return FirstLayer {
                spec: spec.clone(),
                weight: weight.to_vec(),
                block: 1,
                pad: spec.pad,
            };
        }
        let (k, cin, cout) = (spec.k, spec.cin, spec.cout);
        let k2 = k.div_ceil(s);
        let cin2 = cin * s * s;
        let mut w2 = vec![0.0f32; cout * cin2 * k2 * k2];
        for co in 0..cout {
            for c in 0..cin {
                for ky in 0..k {
                    for kx in 0..k {
                        let (yy, sy, xx, sx) = (ky / s, ky % s, kx / s, kx % s);
                        let c2 = (c * s + sy) * s + sx;
                        w2[((co * cin2 + c2) * k2 + yy) * k2 + xx] =
                            weight[((co * cin + c) * k + ky) * k + kx];
                    }
                }
            }
        }
        FirstLayer {
            spec: ConvSpec {
                cin: cin2,
                k: k2,
                stride: 1,
                pad: 0,
                ..spec.clone()
            },
            weight: w2,
            block: s,
            pad: spec.pad,
        }
    }

    /// The input band of `img` (`height x width x 3`) for output rows `out` of the layer,
    /// `w_out` columns wide: scaled frame rows `in_rows` (stride 1), or the space-to-depth
    /// rows `out.start..out.end + k - 1`. Returns the band and the height of its level.
    pub fn input<P: Pixel>(
        &self,
        img: &[P],
        height: usize,
        width: usize,
        out: &Range<usize>,
        w_out: usize,
        in_rows: &Range<usize>,
    ) -> (Band, usize) {
        if self.block == 1 {
            let rows = in_rows.len();
            let mut data = vec![0.0f32; 3 * rows * width];
            for c in 0..3 {
                for (r, y) in in_rows.clone().enumerate() {
                    let src = &img[y * width * 3..][..width * 3];
                    let dst = &mut data[(c * rows + r) * width..][..width];
                    for (x, d) in dst.iter_mut().enumerate() {
                        *d = scaled(src[x * 3 + c], c);
                    }
                }
            }
            let band = Band {
                c: 3,
                row0: in_rows.start,
                rows,
                w: width,
                data,
            };
            return (band, height);
        }
        let (s, k2, c2) = (self.block, self.spec.k, self.spec.cin);
        let rows = out.len() + k2 - 1;
        let w = w_out + k2 - 1;
        let mut data = vec![0.0f32; c2 * rows * w];
        for r in 0..rows {
            for sy in 0..s {
                let y = ((out.start + r) * s + sy) as isize - self.pad as isize;
                if y < 0 || y as usize >= height {
                    continue;
                }
                let src = &img[y as usize * width * 3..][..width * 3];
                for xb in 0..w {
                    for sx in 0..s {
                        let x = (xb * s + sx) as isize - self.pad as isize;
                        if x < 0 || x as usize >= width {
                            continue;
                        }
                        for c in 0..3 {
                            let ch = (c * s + sy) * s + sx;
                            data[(ch * rows + r) * w + xb] = scaled(src[x as usize * 3 + c], c);
                        }
                    }
                }
            }
        }
        let band = Band {
            c: c2,
            row0: out.start,
            rows,
            w,
            data,
        };
        (band, out.start + rows)
    }
}
