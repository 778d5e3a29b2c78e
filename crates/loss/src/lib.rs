//! # r4d-loss: video losses and metrics with exact gradients
//!
//! Losses of a rendered video against a fixed reference video, with their value and their
//! gradient with respect to the rendered video, and the evaluation metrics:
//!
//! * [`Dms`]: Dual-domain Motion Supervision (Section 3.1 of the paper),
//!   `L_spatial + L_mag + L_phase`, with every ambiguity of the paper fixed as
//!   `tests/fixtures/loss/README.md` does and each choice configurable ([`DmsConfig`]:
//!   patch size, DFT normalisation, reduction, eps, a phase mask, the SSIM flavour, term
//!   weights including the paper's ablation [`Ablation`]).
//! * [`L1Loss`], [`SsimLoss`] (`1 - SSIM`, pytorch-msssim's valid filtering or the 3DGS
//!   training code's same padding).
//! * Metrics: [`metrics::psnr`] (per frame, mean over frames, whole video),
//!   [`metrics::l1`], [`ssim::ssim`], [`ssim::ms_ssim`] (5 scales, pytorch-msssim's pooling
//!   and its > 160 px rule, with a documented smaller-window fallback).
//! * [`bands`]: the DMS loss band by band (rows of every frame), exactly equal to the whole
//!   video's, with a compact 8-bit reference: for paper-scale videos that do not fit in memory.
//! * [`io`]: videos as directories of PNG frames or float32 `.npy` `(T, H, W, 3)`.
//! * [`trajectory`]: point-trajectory metrics.
//! * [`lpips`]: LPIPS v0.1 with AlexNet or VGG16 backbones, as the official `lpips` package
//!   computes it, from weights files (safetensors; `scripts/lpips_weights.sh` makes them).
//!
//! A [`Video`] is `(T, H, W, 3)` values (row 0 at the top, RGB interleaved) in `f32` or
//! `f64` ([`Real`]); gradients come back in the same layout. Every quantity is computed in
//! f64 except SSIM, which runs in the input's precision unless [`SsimConfig::precision`] asks
//! otherwise; the spectral terms are always f64 (see [`spectral`] for why). Work is spread
//! over frames (SSIM) and rows of patches (spectral terms) with rayon when the default
//! feature `parallel` is on; results do not depend on the thread count.
//!
//! Bad input — different sizes or frame counts, fewer than 2 frames for the spectral terms,
//! frames smaller than a patch or the SSIM window, NaN — is a [`LossError`] naming the
//! input.
//!
//! ## Example
//!
//! ```
//! use r4d_loss::{Dms, DmsConfig, Loss, Video};
//! // Two 4-frame 32x32 videos: a bright square moving right, and the same square static.
//! let video = |speed: usize| {
//!     let mut v = Video::<f32>::zeros(4, 32, 32);
//!     for t in 0..4 {
//!         for y in 8..16 {
//!             for x in 8 + speed * t..16 + speed * t {
//!                 v.frame_mut(t)[(y * 32 + x) * 3..(y * 32 + x) * 3 + 3].fill(0.8);
//!             }
//!         }
//!     }
//!     v
//! };
//! let loss = Dms::new(video(2), DmsConfig::default()).unwrap();
//! let terms = loss.terms(&video(2)).unwrap();
//! assert!(terms.spatial.unwrap().abs() < 1e-12 && terms.mag.unwrap() == 0.0);
//! let (value, grad) = loss.value_and_grad(&video(1)).unwrap();
//! assert!(value > terms.total);
//! assert_eq!(grad.data().len(), 4 * 32 * 32 * 3);
//! ```

pub mod banded_loss;
pub mod bands;
pub mod dms;
mod entries;
mod error;
/// PNG folders and `.npy` videos ([`r4d_frames::io`]).
pub use r4d_frames::io;
pub mod lpips;
pub mod metrics;
mod par;
mod real;
mod real_fft;
mod rows;
pub mod spectral;
pub mod ssim;
pub mod trajectory;
mod video;

pub use banded_loss::{BandedLoss, VideoLoss};
pub use dms::{Ablation, Dms, DmsConfig, DmsTerms, DmsWeights, L1Loss, SsimLoss};
pub use error::{Input, LossError};
pub use r4d_frames::{FrameError, Video};
pub use real::Real;
pub use spectral::{FftNorm, Reduction, Spectral, SpectralConfig, SpectralTerms};
pub use ssim::{MsSsimConfig, Padding, Precision, SsimConfig};

/// A loss of a rendered video against a reference fixed at construction: its value and its
/// gradient with respect to the rendered video.
pub trait Loss<T: Real> {
    /// The loss of `rendered`.
    fn value(&self, rendered: &Video<T>) -> Result<f64, LossError>;

    /// The loss of `rendered`; writes `dL/d rendered` to `grad` (`(T, H, W, 3)`, the
    /// rendered video's layout; overwritten).
    fn value_and_grad_into(&self, rendered: &Video<T>, grad: &mut [T]) -> Result<f64, LossError>;

    /// The loss of `rendered` and `dL/d rendered` as a new video.
    fn value_and_grad(&self, rendered: &Video<T>) -> Result<(f64, Video<T>), LossError> {
        let mut g = Video::zeros(rendered.frames(), rendered.height(), rendered.width());
        let v = self.value_and_grad_into(rendered, g.data_mut())?;
        Ok((v, g))
    }
}

#[cfg(test)]
mod tests;
