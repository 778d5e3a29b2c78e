//! The DMS loss evaluated band by band: horizontal strips of every frame, so that a caller
//! can render, evaluate and differentiate one strip of the whole video at a time instead of
//! holding the rendered video (`T x H x W x 3`, ~400 MB in f32 for 16 frames at 1080p), its
//! gradient and the reference in memory at once.
//!
//! # Exactness
//!
//! Every term of [`crate::Dms`] is a mean over positions that can be split by rows:
//!
//! * L1: a mean over pixels; band `b` owns rows `own`.
//! * `1 - SSIM` with valid filtering (pytorch-msssim, the default): a mean over the SSIM map,
//!   whose row `r` reads image rows `r .. r + window`. A band owns map rows `own` and reads
//!   image rows `own.start .. own.end + window - 1` (its *halo* overlaps the next band).
//! * `L_mag`, `L_phase`: means (or, for `L_mag`, optionally a sum) over the entries of
//!   non-overlapping `ph x pw` patches cropped at the top-left; bands start on multiples of
//!   `ph`, so a band owns whole rows of patches.
//!
//! Each band's terms are weighted by its share of the positions, so the sum over bands of
//! [`BandedDms::band_terms`] is [`crate::Dms::terms`] of the whole video, and the sum of the
//! band gradients (added at their rows; halos overlap) is its gradient, both up to the
//! rounding of the sums. SSIM with same padding (the 3DGS style) reads zero padding at the
//! frame borders, which a band cannot see; it is refused ([`LossError::Config`]).
//!
//! # Compact reference
//!
//! [`ReferenceVideo`] keeps a reference loaded from 8-bit frames as bytes (a quarter of
//! f32, and exact: the loss sees the same `k / 255` values); a band is converted to the
//! compute type when it is evaluated.

use crate::dms::{DmsConfig, DmsTerms};
use crate::error::{Input, LossError};
use crate::real::Real;
use crate::spectral::{Reduction, Spectral, SpectralTerms};
use crate::ssim::{self, Padding};
use crate::video::{check_grad_len, Video};
use std::borrow::Cow;
use std::ops::Range;

/// A video of 8-bit values `k / 255`, `(T, H, W, 3)` like [`Video`].
#[derive(Clone, Debug, PartialEq)]
pub struct Video8 {
    frames: usize,
    height: usize,
    width: usize,
    data: Vec<u8>,
}

impl Video8 {
    /// A video from `(T, H, W, 3)` bytes (value `k` means `k / 255`); the length must be
    /// `frames * height * width * 3` and no side zero.
    pub fn new(
        frames: usize,
        height: usize,
        width: usize,
        data: Vec<u8>,
    ) -> Result<Video8, LossError> {
        crate::video::check_shape(Input::Reference, frames, height, width, data.len())?;
        Ok(Video8 {
            frames,
            height,
            width,
            data,
        })
    }

    /// The video of `video` when every value is exactly `k / 255` in f32 for an integer
    /// `k` (as the PNG reader stores 8-bit frames); `None` otherwise.
    pub fn from_exact(video: &Video<f32>) -> Option<Video8> {
        let mut data = Vec::with_capacity(video.data().len());
        for &v in video.data() {
            let k = (v * 255.0).round();
            if !(0.0..=255.0).contains(&k) || (k as u8) as f32 / 255.0 != v {
                return None;
            }
            data.push(k as u8);
        }
        Some(Video8 {
            frames: video.frames(),
            height: video.height(),
            width: video.width(),
            data,
        })
    }

    /// `video` rounded to the nearest `k / 255` (values clamped to `[0, 1]`).
    pub fn quantize(video: &Video<f32>) -> Video8 {
        Video8 {
            frames: video.frames(),
            height: video.height(),
            width: video.width(),
            data: video
                .data()
                .iter()
                .map(|v| (v.clamp(0.0, 1.0) * 255.0).round() as u8)
                .collect(),
        }
    }

    /// Number of frames.
    pub fn frames(&self) -> usize {
        self.frames
    }
    /// Rows per frame.
    pub fn height(&self) -> usize {
        self.height
    }
    /// Columns per frame.
    pub fn width(&self) -> usize {
        self.width
    }
    /// The bytes, `(T, H, W, 3)`.
    pub fn data(&self) -> &[u8] {
        &self.data
    }
}

/// A reference video as stored by [`BandedDms`]: bytes when the source is 8-bit, else f32.
/// `From<Video<f32>>` picks the compact form ([`ReferenceVideo::compact`]).
#[derive(Clone, Debug, PartialEq)]
pub enum ReferenceVideo {
    /// Float values.
    F32(Video<f32>),
    /// 8-bit values `k / 255`.
    U8(Video8),
}

impl From<Video<f32>> for ReferenceVideo {
    fn from(v: Video<f32>) -> Self {
        ReferenceVideo::compact(v)
    }
}

impl<'r> From<ReferenceVideo> for Cow<'r, ReferenceVideo> {
    fn from(v: ReferenceVideo) -> Self {
        Cow::Owned(v)
    }
}

impl<'r> From<&'r ReferenceVideo> for Cow<'r, ReferenceVideo> {
    fn from(v: &'r ReferenceVideo) -> Self {
        Cow::Borrowed(v)
    }
}

impl ReferenceVideo {
    /// The most compact exact storage of `video`: bytes when every value is `k / 255`,
    /// else the f32 video itself.
    pub fn compact(video: Video<f32>) -> ReferenceVideo {
        match Video8::from_exact(&video) {
            Some(v8) => ReferenceVideo::U8(v8),
            None => ReferenceVideo::F32(video),
        }
    }

    /// Number of frames.
    pub fn frames(&self) -> usize {
        match self {
            ReferenceVideo::F32(v) => v.frames(),
            ReferenceVideo::U8(v) => v.frames,
        }
    }
    /// Rows per frame.
    pub fn height(&self) -> usize {
        match self {
            ReferenceVideo::F32(v) => v.height(),
            ReferenceVideo::U8(v) => v.height,
        }
    }
    /// Columns per frame.
    pub fn width(&self) -> usize {
        match self {
            ReferenceVideo::F32(v) => v.width(),
            ReferenceVideo::U8(v) => v.width,
        }
    }
    /// Bytes held.
    pub fn bytes(&self) -> usize {
        match self {
            ReferenceVideo::F32(v) => v.data().len() * 4,
            ReferenceVideo::U8(v) => v.data.len(),
        }
    }

    /// Rows `rows` of the first `frames` frames, in type `T`.
    pub fn rows<T: Real>(&self, frames: usize, rows: Range<usize>) -> Video<T> {
        let (h, w) = (self.height(), self.width());
        assert!(frames <= self.frames() && rows.end <= h && rows.start < rows.end);
        let (a, b) = (rows.start * w * 3, rows.end * w * 3);
        let flen = h * w * 3;
        let mut data = Vec::with_capacity(frames * (b - a));
        for t in 0..frames {
            match self {
                ReferenceVideo::F32(v) => data.extend(
                    v.data()[t * flen + a..t * flen + b]
                        .iter()
                        .map(|&x| T::c(x as f64)),
                ),
                ReferenceVideo::U8(v) => data.extend(
                    v.data[t * flen + a..t * flen + b]
                        .iter()
                        .map(|&k| T::c(k as f64 / 255.0)),
                ),
            }
        }
        Video::new(frames, rows.len(), w, data).expect("band shape")
    }

    /// The whole video in f32.
    pub fn to_f32(&self) -> Video<f32> {
        self.rows(self.frames(), 0..self.height())
    }

    /// Frame `t` in f32, `H * W * 3` values.
    pub fn frame_f32(&self, t: usize) -> Vec<f32> {
        let flen = self.height() * self.width() * 3;
        match self {
            ReferenceVideo::F32(v) => v.frame(t).to_vec(),
            ReferenceVideo::U8(v) => v.data[t * flen..(t + 1) * flen]
                .iter()
                .map(|&k| k as f32 / 255.0)
                .collect(),
        }
    }

    fn check_finite(&self) -> Result<(), LossError> {
        match self {
            ReferenceVideo::F32(v) => v.check_finite(Input::Reference),
            ReferenceVideo::U8(_) => Ok(()),
        }
    }
}

/// One band: the image rows to render and the rows it owns.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Band {
    /// Image rows the band reads: its own rows plus, with the SSIM term, the `window - 1`
    /// rows below them (clipped at the bottom).
    pub rows: Range<usize>,
    /// Rows whose L1 pixels, SSIM map rows and patches belong to the band.
    pub own: Range<usize>,
}

/// Per-band data: the band, its spectral plans and its share of each term.
#[derive(Clone, Debug)]
struct BandPlan {
    band: Band,
    spectral: Option<Spectral>,
    l1: f64,
    spatial: f64,
    spectral_share: f64,
}

/// [`crate::Dms`] split into row bands (see the module docs): evaluate and differentiate one
/// band of the whole video at a time; the terms of all bands add up to the whole video's. The
/// reference is owned or borrowed (`'r`).
#[derive(Clone, Debug)]
pub struct BandedDms<'r> {
    config: DmsConfig,
    reference: Cow<'r, ReferenceVideo>,
    frames: usize,
    plans: Vec<BandPlan>,
}

impl<'r> BandedDms<'r> {
    /// The loss on the first `frames` frames of `reference`, in bands of about `band_rows`
    /// rows (rounded up to a multiple of the patch height; a last band shorter than a patch
    /// or the SSIM window joins the one before). Errors: the checks of [`crate::Dms::new`],
    /// `frames` beyond the reference, same-padding SSIM.
    pub fn new(
        reference: impl Into<Cow<'r, ReferenceVideo>>,
        frames: usize,
        config: DmsConfig,
        band_rows: usize,
    ) -> Result<Self, LossError> {
        let reference = reference.into();
        config.validate()?;
        reference.check_finite()?;
        if frames > reference.frames() || frames == 0 {
            return Err(LossError::Config(format!(
                "{frames} frames asked of a reference with {}",
                reference.frames()
            )));
        }
        let (h, w) = (reference.height(), reference.width());
        let wt = config.weights;
        let spatial_on = wt.spatial != 0.0;
        let spectral_on = wt.mag != 0.0 || wt.phase != 0.0;
        if spatial_on {
            if config.spatial.padding == Padding::Same {
                return Err(LossError::Config(
                    "band-wise evaluation needs valid SSIM filtering (the default); same \
                     padding reads the frame borders"
                        .into(),
                ));
            }
            config.spatial.check_size(Input::Reference, h, w)?;
        }
        let ph = config.spectral.patch[0];
        let whole = if spectral_on {
            Some(Spectral::new(config.spectral.clone(), frames, h, w)?)
        } else {
            None
        };
        let win = config.spatial.window;
        let step = band_rows.max(1).div_ceil(ph) * ph;
        let min_last = ph.max(if spatial_on { win } else { 1 });
        let mut owns: Vec<Range<usize>> = Vec::new();
        let mut a = 0;
        while a < h {
            let b = (a + step).min(h);
            owns.push(a..b);
            a = b;
        }
        if owns.len() > 1 && owns.last().is_some_and(|r| r.len() < min_last) {
            let last = owns.pop().expect("two bands");
            owns.last_mut().expect("one band").end = last.end;
        }
        let ssim_rows_total = if spatial_on { h + 1 - win } else { 1 };
        let entries_total = whole.as_ref().map_or(1, |s| s.entries()).max(1);
        let plans = owns
            .into_iter()
            .map(|own| {
                let rows = if spatial_on {
                    own.start..(own.end + win - 1).min(h)
                } else {
                    own.clone()
                };
                let spectral = if spectral_on && own.len() >= ph {
                    Some(Spectral::new(
                        config.spectral.clone(),
                        frames,
                        own.len(),
                        w,
                    )?)
                } else {
                    None
                };
                let entries = spectral.as_ref().map_or(0, |s| s.entries());
                Ok(BandPlan {
                    l1: own.len() as f64 / h as f64,
                    spatial: if spatial_on {
                        (rows.len() + 1 - win) as f64 / ssim_rows_total as f64
                    } else {
                        0.0
                    },
                    spectral_share: entries as f64 / entries_total as f64,
                    band: Band { rows, own },
                    spectral,
                })
            })
            .collect::<Result<Vec<_>, LossError>>()?;
        Ok(BandedDms {
            config,
            reference,
            frames,
            plans,
        })
    }

    /// The bands, top to bottom.
    pub fn bands(&self) -> impl ExactSizeIterator<Item = &Band> {
        self.plans.iter().map(|p| &p.band)
    }

    /// Number of bands.
    pub fn len(&self) -> usize {
        self.plans.len()
    }

    /// Always false (a video has at least one band).
    pub fn is_empty(&self) -> bool {
        self.plans.is_empty()
    }

    /// Frames evaluated.
    pub fn frames(&self) -> usize {
        self.frames
    }

    /// The configuration.
    pub fn config(&self) -> &DmsConfig {
        &self.config
    }

    /// The stored reference.
    pub fn reference(&self) -> &ReferenceVideo {
        &self.reference
    }

    /// Band `b`'s share of the terms, for `rendered` = rows `bands()[b].rows` of the first
    /// `frames()` frames. Summed over bands ([`DmsTerms::add`]) they give the whole video's
    /// terms.
    pub fn band_terms<T: Real>(
        &self,
        b: usize,
        rendered: &Video<T>,
    ) -> Result<DmsTerms, LossError> {
        self.eval(b, rendered, None)
    }

    /// As [`BandedDms::band_terms`], and writes band `b`'s share of `d total / d rendered`
    /// to `grad` (the band video's layout, overwritten).
    pub fn band_terms_and_grad_into<T: Real>(
        &self,
        b: usize,
        rendered: &Video<T>,
        grad: &mut [T],
    ) -> Result<DmsTerms, LossError> {
        check_grad_len(rendered, grad)?;
        grad.fill(T::zero());
        self.eval(b, rendered, Some(grad))
    }

    fn eval<T: Real>(
        &self,
        b: usize,
        x: &Video<T>,
        mut grad: Option<&mut [T]>,
    ) -> Result<DmsTerms, LossError> {
        let plan = self
            .plans
            .get(b)
            .ok_or_else(|| LossError::Config(format!("band {b} of {}", self.plans.len())))?;
        let band = &plan.band;
        let w = self.reference.width();
        if (x.frames(), x.height(), x.width()) != (self.frames, band.rows.len(), w) {
            return Err(LossError::FrameSize {
                reference: (band.rows.len(), w),
                rendered: (x.height(), x.width()),
            });
        }
        x.check_finite(Input::Rendered)?;
        let y: Video<T> = self.reference.rows(self.frames, band.rows.clone());
        let wt = self.config.weights;
        let mut terms = DmsTerms::default();
        if wt.l1 != 0.0 {
            // Mean over the whole video's values: this band's own rows only.
            let n_total = (self.frames * self.reference.height() * w * 3) as f64;
            let own = band.own.len() * w * 3;
            let c = wt.l1 / n_total;
            let mut s = 0.0;
            for t in 0..self.frames {
                let (fx, fy) = (&x.frame(t)[..own], &y.frame(t)[..own]);
                match grad.as_deref_mut() {
                    Some(g) => {
                        let gf = &mut g[t * x.frame_len()..t * x.frame_len() + own];
                        for ((gv, a), bb) in gf.iter_mut().zip(fx).zip(fy) {
                            let d = a.f64() - bb.f64();
                            s += d.abs();
                            if d != 0.0 {
                                *gv += T::c(c * d.signum());
                            }
                        }
                    }
                    None => {
                        s += fx
                            .iter()
                            .zip(fy)
                            .map(|(a, bb)| (a.f64() - bb.f64()).abs())
                            .sum::<f64>()
                    }
                }
            }
            let v = s / n_total;
            debug_assert!(plan.l1 > 0.0);
            terms.l1 = Some(v);
            terms.total += wt.l1 * v;
        }
        if wt.spatial != 0.0 {
            let f = plan.spatial;
            let s = ssim::ssim_dispatch(
                x,
                &y,
                &self.config.spatial,
                grad.as_deref_mut().map(|g| (-wt.spatial * f, g)),
            );
            let v = f * (1.0 - s.mean);
            terms.spatial = Some(v);
            terms.total += wt.spatial * v;
        }
        if wt.mag != 0.0 || wt.phase != 0.0 {
            let f = plan.spectral_share;
            let (mag, phase, masked) = match &plan.spectral {
                Some(sp) => {
                    let mf = match self.config.spectral.mag_reduction {
                        Reduction::Mean => f,
                        Reduction::Sum => 1.0,
                    };
                    let SpectralTerms {
                        mag, phase, masked, ..
                    } = sp.run(x, &y, grad.map(|g| (wt.mag * mf, wt.phase * f, g)));
                    (mf * mag, f * phase, masked)
                }
                None => (0.0, 0.0, 0),
            };
            terms.masked = masked;
            if wt.mag != 0.0 {
                terms.mag = Some(mag);
                terms.total += wt.mag * mag;
            }
            if wt.phase != 0.0 {
                terms.phase = Some(phase);
                terms.total += wt.phase * phase;
            }
        }
        Ok(terms)
    }
}

impl DmsTerms {
    /// Adds `other` term by term (for band shares, [`BandedDms`]).
    pub fn add(&mut self, other: &DmsTerms) {
        let sum = |a: Option<f64>, b: Option<f64>| match (a, b) {
            (None, None) => None,
            (a, b) => Some(a.unwrap_or(0.0) + b.unwrap_or(0.0)),
        };
        self.l1 = sum(self.l1, other.l1);
        self.spatial = sum(self.spatial, other.spatial);
        self.mag = sum(self.mag, other.mag);
        self.phase = sum(self.phase, other.phase);
        self.total += other.total;
        self.masked += other.masked;
    }
}
