//! The video objective's loss as a trait: [`BandedLoss`] (a loss evaluated band by band, whose
//! shares add up to the whole video's) and [`VideoLoss`] (what makes one per view). The
//! paper's DMS is both ([`DmsConfig`] makes [`BandedDms`]); another loss plugs into the video
//! fit by implementing them. Every [`BandedDms`] is also a whole-video [`Loss`].

use crate::bands::{BandedDms, ReferenceVideo};
use crate::dms::{DmsConfig, DmsTerms};
use crate::error::LossError;
use crate::video::{check_grad_len, Video};
use crate::Loss;
use std::ops::Range;

/// A video loss evaluated in row bands: each band of the whole video alone, the shares of all
/// bands adding up ([`DmsTerms::add`]) to the whole video's terms, and their gradients (added
/// over the rows where bands overlap) to the whole video's gradient.
pub trait BandedLoss: Send + Sync {
    /// Frames evaluated.
    fn frames(&self) -> usize;
    /// The image rows each band reads, top to bottom (bands may overlap).
    fn band_rows(&self) -> Vec<Range<usize>>;
    /// Band `b`'s share of the terms for `rendered`: rows `band_rows()[b]` of the first
    /// `frames()` frames. By default [`BandedLoss::band_terms_and_grad_into`] with the
    /// gradient discarded; a loss whose value alone is cheaper overrides it.
    fn band_terms(&self, b: usize, rendered: &Video<f32>) -> Result<DmsTerms, LossError> {
        let mut grad = vec![0.0; rendered.data().len()];
        self.band_terms_and_grad_into(b, rendered, &mut grad)
    }
    /// As [`BandedLoss::band_terms`], and writes band `b`'s share of `d total / d rendered`
    /// to `grad` (the band video's layout, overwritten).
    fn band_terms_and_grad_into(
        &self,
        b: usize,
        rendered: &Video<f32>,
        grad: &mut [f32],
    ) -> Result<DmsTerms, LossError>;
}

/// Makes the [`BandedLoss`] of one view against its reference video (the video objective
/// makes one per view, and again when its band height changes).
pub trait VideoLoss: Send + Sync + std::fmt::Debug {
    /// The loss on the first `frames` frames of `reference`, in bands of about `band_rows`
    /// rows.
    fn banded<'r>(
        &self,
        reference: &'r ReferenceVideo,
        frames: usize,
        band_rows: usize,
    ) -> Result<Box<dyn BandedLoss + 'r>, LossError>;
}

impl VideoLoss for DmsConfig {
    fn banded<'r>(
        &self,
        reference: &'r ReferenceVideo,
        frames: usize,
        band_rows: usize,
    ) -> Result<Box<dyn BandedLoss + 'r>, LossError> {
        Ok(Box::new(BandedDms::new(
            reference,
            frames,
            self.clone(),
            band_rows,
        )?))
    }
}

impl BandedLoss for BandedDms<'_> {
    fn frames(&self) -> usize {
        BandedDms::frames(self)
    }

    fn band_rows(&self) -> Vec<Range<usize>> {
        self.bands().map(|b| b.rows.clone()).collect()
    }

    fn band_terms(&self, b: usize, rendered: &Video<f32>) -> Result<DmsTerms, LossError> {
        BandedDms::band_terms(self, b, rendered)
    }

    fn band_terms_and_grad_into(
        &self,
        b: usize,
        rendered: &Video<f32>,
        grad: &mut [f32],
    ) -> Result<DmsTerms, LossError> {
        BandedDms::band_terms_and_grad_into(self, b, rendered, grad)
    }
}

/// The whole video's terms (and, with `grad`, its gradient) from the bands of `loss`.
pub fn whole_video_terms(
    loss: &dyn BandedLoss,
    rendered: &Video<f32>,
    mut grad: Option<&mut [f32]>,
) -> Result<DmsTerms, LossError> {
    let (t, h, w) = (loss.frames(), rendered.height(), rendered.width());
    if rendered.frames() != t {
        return Err(LossError::Config(format!(
            "{} rendered frames for a loss over {t}",
            rendered.frames()
        )));
    }
    if let Some(g) = grad.as_deref_mut() {
        check_grad_len(rendered, g)?;
        g.fill(0.0);
    }
    let mut terms = DmsTerms::default();
    for (b, rows) in loss.band_rows().into_iter().enumerate() {
        if rows.end > h {
            return Err(LossError::Config(format!(
                "band {b} reads rows {rows:?} of a {h}-row video"
            )));
        }
        let row_len = w * 3;
        let band = Video::from_frames(
            rows.len(),
            w,
            (0..t).map(|k| &rendered.frame(k)[rows.start * row_len..rows.end * row_len]),
        )?;
        let share = match grad.as_deref_mut() {
            None => loss.band_terms(b, &band)?,
            Some(g) => {
                let mut gb = vec![0.0f32; band.data().len()];
                let share = loss.band_terms_and_grad_into(b, &band, &mut gb)?;
                let fl = h * row_len;
                for k in 0..t {
                    let dst = &mut g[k * fl + rows.start * row_len..k * fl + rows.end * row_len];
                    let src = &gb[k * rows.len() * row_len..(k + 1) * rows.len() * row_len];
                    for (d, s) in dst.iter_mut().zip(src) {
                        *d += s;
                    }
                }
                share
            }
        };
        terms.add(&share);
    }
    Ok(terms)
}

impl Loss<f32> for BandedDms<'_> {
    fn value(&self, rendered: &Video<f32>) -> Result<f64, LossError> {
        whole_video_terms(self, rendered, None).map(|t| t.total)
    }

    fn value_and_grad_into(
        &self,
        rendered: &Video<f32>,
        grad: &mut [f32],
    ) -> Result<f64, LossError> {
        whole_video_terms(self, rendered, Some(grad)).map(|t| t.total)
    }
}
