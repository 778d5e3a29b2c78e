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
use crate::video::check_grad_len;
use r4d_frames::Video;
pub use r4d_frames::{ReferenceVideo, Video8};
use std::borrow::Cow;
use std::ops::Range;

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
