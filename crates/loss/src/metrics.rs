//! Pixel metrics: L1, MSE and PSNR (data range 1), per frame and over the whole video.

use crate::error::LossError;
use crate::par;
use crate::real::Real;
use crate::video::{check_grad_len, check_pair, Video};

/// Mean absolute error over every value.
pub fn l1<T: Real>(rendered: &Video<T>, reference: &Video<T>) -> Result<f64, LossError> {
    check_pair(rendered, reference)?;
    Ok(sum_abs(rendered, reference) / rendered.data().len() as f64)
}

pub(crate) fn sum_abs<T: Real>(x: &Video<T>, y: &Video<T>) -> f64 {
    par::map((0..x.frames()).collect(), |t| {
        x.frame(t)
            .iter()
            .zip(y.frame(t))
            .map(|(a, b)| (a.f64() - b.f64()).abs())
            .sum::<f64>()
    })
    .iter()
    .sum()
}

/// Adds `scale * d L1 / d rendered` to `grad`: `scale * sign(x - y) / n`, with
/// `sign(0) = 0` (PyTorch's subgradient). Returns L1.
pub(crate) fn l1_grad_into<T: Real>(x: &Video<T>, y: &Video<T>, scale: f64, grad: &mut [T]) -> f64 {
    let n = x.data().len() as f64;
    let c = scale / n;
    let flen = x.frame_len();
    let items: Vec<(usize, &mut [T])> = grad.chunks_mut(flen).enumerate().collect();
    let sums = par::map(items, |(t, g)| {
        let mut s = 0.0;
        for ((gv, a), b) in g.iter_mut().zip(x.frame(t)).zip(y.frame(t)) {
            let d = a.f64() - b.f64();
            s += d.abs();
            if d != 0.0 {
                *gv += T::c(c * d.signum());
            }
        }
        s
    });
    sums.iter().sum::<f64>() / n
}

/// L1 with its gradient: adds `scale * dL1/d rendered` to `grad`.
pub fn l1_grad<T: Real>(
    rendered: &Video<T>,
    reference: &Video<T>,
    scale: f64,
    grad: &mut [T],
) -> Result<f64, LossError> {
    check_pair(rendered, reference)?;
    check_grad_len(rendered, grad)?;
    Ok(l1_grad_into(rendered, reference, scale, grad))
}

/// PSNR of a video pair (data range 1). `None` stands for an infinite PSNR (MSE = 0).
#[derive(Clone, Debug, PartialEq)]
pub struct Psnr {
    /// `10 log10(1 / MSE_t)` per frame, MSE over the frame's `3 H W` values.
    pub per_frame: Vec<Option<f64>>,
    /// Mean of `per_frame` (PhysDreamer's evaluation); `None` if any frame is infinite.
    pub mean_of_frames: Option<f64>,
    /// `10 log10(1 / MSE)` over the whole video.
    pub whole_video: Option<f64>,
    /// MSE over the whole video.
    pub mse: f64,
    /// MSE per frame.
    pub mse_per_frame: Vec<f64>,
}

fn psnr_of(mse: f64) -> Option<f64> {
    (mse > 0.0).then(|| 10.0 * (1.0 / mse).log10())
}

/// PSNR per frame, its mean over frames, and over the whole video.
pub fn psnr<T: Real>(rendered: &Video<T>, reference: &Video<T>) -> Result<Psnr, LossError> {
    check_pair(rendered, reference)?;
    let flen = rendered.frame_len() as f64;
    let sse = par::map((0..rendered.frames()).collect(), |t| {
        rendered
            .frame(t)
            .iter()
            .zip(reference.frame(t))
            .map(|(a, b)| {
                let d = a.f64() - b.f64();
                d * d
            })
            .sum::<f64>()
    });
    let mse_per_frame: Vec<f64> = sse.iter().map(|s| s / flen).collect();
    let per_frame: Vec<Option<f64>> = mse_per_frame.iter().map(|&m| psnr_of(m)).collect();
    let mean_of_frames = per_frame
        .iter()
        .copied()
        .sum::<Option<f64>>()
        .map(|s| s / per_frame.len() as f64);
    let mse = sse.iter().sum::<f64>() / rendered.data().len() as f64;
    Ok(Psnr {
        per_frame,
        mean_of_frames,
        whole_video: psnr_of(mse),
        mse,
        mse_per_frame,
    })
}

/// Every metric of a video pair, as `r4d metrics` prints them. A metric the frames do not
/// allow is `None`, with the reason in `notes`.
#[derive(Clone, Debug, PartialEq)]
pub struct Report {
    /// Frames.
    pub frames: usize,
    /// Rows per frame.
    pub height: usize,
    /// Columns per frame.
    pub width: usize,
    /// PSNR per frame, mean over frames, whole video.
    pub psnr: Psnr,
    /// Mean absolute error.
    pub l1: f64,
    /// SSIM (pytorch-msssim, f64 arithmetic).
    pub ssim: Option<crate::ssim::SsimValue>,
    /// MS-SSIM with the standard 11-tap window (frames > 160 px).
    pub ms_ssim: Option<crate::ssim::MsSsimValue>,
    /// For smaller frames, MS-SSIM with the largest window that fits (window, value).
    pub ms_ssim_small_window: Option<(usize, crate::ssim::MsSsimValue)>,
    /// DMS terms with the paper's settings (`L_spatial = 1 - ssim`).
    pub dms_spatial: Option<f64>,
    /// `L_mag`.
    pub dms_mag: Option<f64>,
    /// `L_phase`.
    pub dms_phase: Option<f64>,
    /// Why a metric is missing.
    pub notes: Vec<String>,
}

impl Report {
    /// `L_DMS = L_spatial + L_mag + L_phase` when all three are defined.
    pub fn dms(&self) -> Option<f64> {
        Some(self.dms_spatial? + self.dms_mag? + self.dms_phase?)
    }
}

/// Computes every metric of `rendered` against `reference` (SSIM arithmetic in f64). Errors
/// on different shapes or non-finite values; metrics the frame size or count does not allow
/// are `None` with a note.
pub fn report<T: Real>(rendered: &Video<T>, reference: &Video<T>) -> Result<Report, LossError> {
    use crate::spectral::{Spectral, SpectralConfig};
    use crate::ssim::{self, MsSsimConfig, Precision, SsimConfig};
    check_pair(rendered, reference)?;
    let (t, h, w) = (rendered.frames(), rendered.height(), rendered.width());
    let mut notes = Vec::new();
    let cfg = SsimConfig {
        precision: Precision::F64,
        ..Default::default()
    };
    let ssim = match ssim::ssim(rendered, reference, &cfg) {
        Ok(s) => Some(s),
        Err(e) => {
            notes.push(format!("SSIM undefined: {e}"));
            None
        }
    };
    let (mut ms, mut ms_small) = (None, None);
    match ssim::ms_ssim(rendered, reference, &MsSsimConfig::default()) {
        Ok(v) => ms = Some(v),
        Err(LossError::TooSmallForMsSsim { .. }) => {
            notes.push(format!(
                "MS-SSIM undefined: frames of {h}x{w} (HxW); the 11-tap window needs both sides > 160 px"
            ));
            if let Some(c) = MsSsimConfig::largest_window(h.min(w)) {
                ms_small = Some((c.window, ssim::ms_ssim(rendered, reference, &c)?));
            }
        }
        Err(e) => return Err(e),
    }
    let (mut mag, mut phase) = (None, None);
    match Spectral::new(SpectralConfig::default(), t, h, w) {
        Ok(sp) => {
            let s = sp.evaluate(rendered, reference)?;
            mag = Some(s.mag);
            phase = Some(s.phase);
        }
        Err(e) => notes.push(format!(
            "DMS spectral terms undefined: {}",
            e.to_string().trim_start_matches("reference: ")
        )),
    }
    Ok(Report {
        frames: t,
        height: h,
        width: w,
        psnr: psnr(rendered, reference)?,
        l1: l1(rendered, reference)?,
        dms_spatial: ssim.as_ref().map(|s| 1.0 - s.mean),
        ssim,
        ms_ssim: ms,
        ms_ssim_small_window: ms_small,
        dms_mag: mag,
        dms_phase: phase,
        notes,
    })
}
