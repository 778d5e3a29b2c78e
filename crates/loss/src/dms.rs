//! Dual-domain Motion Supervision: `L_DMS = L_spatial + L_mag + L_phase` (Section 3.1 of the
//! paper), with configurable term weights, plus the simple losses L1 and 1 - SSIM.

use crate::error::{Input, LossError};
use crate::metrics;
use crate::real::Real;
use crate::spectral::{Spectral, SpectralConfig, SpectralTerms};
use crate::ssim::{self, SsimConfig};
use crate::video::{check_grad_len, check_rendered, Video};
use crate::Loss;
use serde::{Deserialize, Serialize};

/// Weights of the terms of [`Dms`]; a term with weight 0 is not evaluated.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct DmsWeights {
    /// Mean absolute error (the paper's L1 ablation).
    pub l1: f64,
    /// `L_spatial = 1 - SSIM`.
    pub spatial: f64,
    /// `L_mag`.
    pub mag: f64,
    /// `L_phase`.
    pub phase: f64,
}

impl Default for DmsWeights {
    /// The paper's `L_spatial + L_mag + L_phase`.
    fn default() -> Self {
        DmsWeights {
            l1: 0.0,
            spatial: 1.0,
            mag: 1.0,
            phase: 1.0,
        }
    }
}

/// The paper's loss ablation (Table of Section 4): spatial term alone or with the spectral
/// ("FFT") terms.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Ablation {
    /// L1 only.
    L1,
    /// 1 - SSIM only.
    Ssim,
    /// L1 + L_mag + L_phase.
    L1Fft,
    /// 1 - SSIM + L_mag + L_phase (= DMS).
    SsimFft,
}

impl DmsWeights {
    /// The weights of an ablation row.
    pub fn ablation(a: Ablation) -> Self {
        let (l1, spatial, fft) = match a {
            Ablation::L1 => (1.0, 0.0, 0.0),
            Ablation::Ssim => (0.0, 1.0, 0.0),
            Ablation::L1Fft => (1.0, 0.0, 1.0),
            Ablation::SsimFft => (0.0, 1.0, 1.0),
        };
        DmsWeights {
            l1,
            spatial,
            mag: fft,
            phase: fft,
        }
    }
}

/// The largest loss weight: each term is at most a few units, so a weighted sum stays far
/// from overflow (and from swamping the other terms by more than the float precision).
pub const MAX_WEIGHT: f64 = 1e6;

/// Settings of [`Dms`]: term weights, the SSIM of `L_spatial` and the spectral terms. The
/// default is the paper's loss with the README's conventions.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct DmsConfig {
    /// Term weights.
    pub weights: DmsWeights,
    /// SSIM of `L_spatial` (pytorch-msssim by default; [`SsimConfig::same_pad`] for the
    /// 3DGS style, `gray: true` for SSIM of the gray frames).
    pub spatial: SsimConfig,
    /// Patches, DFT normalisation, reduction, eps, phase mask.
    pub spectral: SpectralConfig,
}

impl DmsConfig {
    /// The configuration of an ablation row (README conventions otherwise).
    pub fn ablation(a: Ablation) -> Self {
        DmsConfig {
            weights: DmsWeights::ablation(a),
            ..Default::default()
        }
    }

    /// Checks the settings.
    pub fn validate(&self) -> Result<(), LossError> {
        let w = &self.weights;
        for (name, v) in [
            ("l1", w.l1),
            ("spatial", w.spatial),
            ("mag", w.mag),
            ("phase", w.phase),
        ] {
            if !(v.is_finite() && (0.0..=MAX_WEIGHT).contains(&v)) {
                return Err(LossError::Config(format!(
                    "weight {name} is {v}: weights lie in [0, {MAX_WEIGHT:e}] (larger ones overflow the loss)"
                )));
            }
        }
        if [w.l1, w.spatial, w.mag, w.phase].iter().all(|&v| v == 0.0) {
            return Err(LossError::Config(
                "every loss weight (l1, spatial, mag, phase) is 0: the loss would be 0 for any parameters"
                    .into(),
            ));
        }
        self.spatial.validate()?;
        self.spectral.validate()
    }
}

/// The terms of one evaluation: unweighted values (`None` where the weight is 0 and the
/// term was not evaluated) and the weighted total.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct DmsTerms {
    /// Mean absolute error.
    pub l1: Option<f64>,
    /// `1 - SSIM`.
    pub spatial: Option<f64>,
    /// `L_mag`.
    pub mag: Option<f64>,
    /// `L_phase`.
    pub phase: Option<f64>,
    /// Weighted sum of the evaluated terms.
    pub total: f64,
    /// Spectral entries the phase mask removed.
    pub masked: usize,
}

/// The DMS loss (and its ablations) against a fixed reference video.
#[derive(Clone, Debug)]
pub struct Dms<T: Real = f32> {
    reference: Video<T>,
    config: DmsConfig,
    spectral: Option<Spectral>,
}

impl<T: Real> Dms<T> {
    /// The loss against `reference`; builds the FFT plans once. Checks the reference (finite,
    /// at least 2 frames and one patch when the spectral terms are on, at least one window).
    pub fn new(reference: Video<T>, config: DmsConfig) -> Result<Self, LossError> {
        config.validate()?;
        reference.check_finite(Input::Reference)?;
        let w = &config.weights;
        let spectral = if w.mag != 0.0 || w.phase != 0.0 {
            Some(Spectral::new(
                config.spectral.clone(),
                reference.frames(),
                reference.height(),
                reference.width(),
            )?)
        } else {
            None
        };
        if w.spatial != 0.0 {
            config
                .spatial
                .check_size(Input::Reference, reference.height(), reference.width())?;
        }
        Ok(Dms {
            reference,
            config,
            spectral,
        })
    }

    /// The reference video.
    pub fn reference(&self) -> &Video<T> {
        &self.reference
    }

    /// The configuration.
    pub fn config(&self) -> &DmsConfig {
        &self.config
    }

    /// Every term with a nonzero weight.
    pub fn terms(&self, rendered: &Video<T>) -> Result<DmsTerms, LossError> {
        self.eval(rendered, None)
    }

    /// Every term with a nonzero weight; writes `d total / d rendered` to `grad`
    /// (`(T, H, W, 3)`, overwritten).
    pub fn terms_and_grad_into(
        &self,
        rendered: &Video<T>,
        grad: &mut [T],
    ) -> Result<DmsTerms, LossError> {
        check_grad_len(rendered, grad)?;
        grad.fill(T::zero());
        self.eval(rendered, Some(grad))
    }

    fn eval(&self, x: &Video<T>, mut grad: Option<&mut [T]>) -> Result<DmsTerms, LossError> {
        let y = &self.reference;
        check_rendered(x, y)?;
        let w = self.config.weights;
        let mut terms = DmsTerms::default();
        if w.l1 != 0.0 {
            let v = match grad.as_deref_mut() {
                Some(g) => metrics::l1_grad_into(x, y, w.l1, g),
                None => metrics::sum_abs(x, y) / x.data().len() as f64,
            };
            terms.l1 = Some(v);
            terms.total += w.l1 * v;
        }
        if w.spatial != 0.0 {
            let s = ssim::ssim_dispatch(
                x,
                y,
                &self.config.spatial,
                grad.as_deref_mut().map(|g| (-w.spatial, g)),
            );
            terms.spatial = Some(1.0 - s.mean);
            terms.total += w.spatial * (1.0 - s.mean);
        }
        if let Some(sp) = &self.spectral {
            let SpectralTerms {
                mag, phase, masked, ..
            } = sp.run(x, y, grad.map(|g| (w.mag, w.phase, g)));
            terms.masked = masked;
            if w.mag != 0.0 {
                terms.mag = Some(mag);
                terms.total += w.mag * mag;
            }
            if w.phase != 0.0 {
                terms.phase = Some(phase);
                terms.total += w.phase * phase;
            }
        }
        Ok(terms)
    }
}

impl<T: Real> Loss<T> for Dms<T> {
    fn value(&self, rendered: &Video<T>) -> Result<f64, LossError> {
        Ok(self.terms(rendered)?.total)
    }

    fn value_and_grad_into(&self, rendered: &Video<T>, grad: &mut [T]) -> Result<f64, LossError> {
        Ok(self.terms_and_grad_into(rendered, grad)?.total)
    }
}

/// Mean absolute error against a fixed reference.
#[derive(Clone, Debug)]
pub struct L1Loss<T: Real = f32> {
    reference: Video<T>,
}

impl<T: Real> L1Loss<T> {
    /// The loss against `reference`.
    pub fn new(reference: Video<T>) -> Result<Self, LossError> {
        reference.check_finite(Input::Reference)?;
        Ok(L1Loss { reference })
    }
}

impl<T: Real> Loss<T> for L1Loss<T> {
    fn value(&self, rendered: &Video<T>) -> Result<f64, LossError> {
        check_rendered(rendered, &self.reference)?;
        Ok(metrics::sum_abs(rendered, &self.reference) / rendered.data().len() as f64)
    }

    fn value_and_grad_into(&self, rendered: &Video<T>, grad: &mut [T]) -> Result<f64, LossError> {
        check_rendered(rendered, &self.reference)?;
        check_grad_len(rendered, grad)?;
        grad.fill(T::zero());
        Ok(metrics::l1_grad_into(rendered, &self.reference, 1.0, grad))
    }
}

/// `1 - SSIM` against a fixed reference (pytorch-msssim by default, or the 3DGS style).
#[derive(Clone, Debug)]
pub struct SsimLoss<T: Real = f32> {
    reference: Video<T>,
    config: SsimConfig,
}

impl<T: Real> SsimLoss<T> {
    /// The loss against `reference`.
    pub fn new(reference: Video<T>, config: SsimConfig) -> Result<Self, LossError> {
        config.validate()?;
        reference.check_finite(Input::Reference)?;
        config.check_size(Input::Reference, reference.height(), reference.width())?;
        Ok(SsimLoss { reference, config })
    }
}

impl<T: Real> Loss<T> for SsimLoss<T> {
    fn value(&self, rendered: &Video<T>) -> Result<f64, LossError> {
        check_rendered(rendered, &self.reference)?;
        Ok(1.0 - ssim::ssim_dispatch(rendered, &self.reference, &self.config, None).mean)
    }

    fn value_and_grad_into(&self, rendered: &Video<T>, grad: &mut [T]) -> Result<f64, LossError> {
        check_grad_len(rendered, grad)?;
        grad.fill(T::zero());
        check_rendered(rendered, &self.reference)?;
        let s = ssim::ssim_dispatch(rendered, &self.reference, &self.config, Some((-1.0, grad)));
        Ok(1.0 - s.mean)
    }
}
