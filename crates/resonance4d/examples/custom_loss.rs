//! A loss of your own in the video fit: mean squared error instead of the paper's DMS, recovering
//! a jelly block's stiffness: `cargo run --release -p resonance4d --example custom_loss`

use resonance4d::loss::{bands::ReferenceVideo, BandedLoss, DmsTerms, LossError, VideoLoss};
use resonance4d::prelude::*;
use std::{ops::Range, sync::Arc};

/// Mean squared error over the frames the fit evaluates (one band: whole frames).
#[derive(Debug)]
struct Mse;
struct BandedMse<'r>(&'r ReferenceVideo, usize);

impl VideoLoss for Mse {
    fn banded<'r>(
        &self,
        reference: &'r ReferenceVideo,
        frames: usize,
        _band_rows: usize,
    ) -> Result<Box<dyn BandedLoss + 'r>, LossError> {
        Ok(Box::new(BandedMse(reference, frames)))
    }
}

impl BandedLoss for BandedMse<'_> {
    fn frames(&self) -> usize {
        self.1
    }
    fn band_rows(&self) -> Vec<Range<usize>> {
        std::iter::once(0..self.0.height()).collect()
    }
    fn band_terms_and_grad_into(
        &self,
        _b: usize,
        rendered: &Video<f32>,
        grad: &mut [f32],
    ) -> Result<DmsTerms, LossError> {
        let reference: Video<f32> = self.0.rows(self.1, 0..self.0.height());
        let n = rendered.data().len() as f64;
        let mut total = 0.0;
        for ((g, &x), &y) in grad.iter_mut().zip(rendered.data()).zip(reference.data()) {
            let d = (x - y) as f64;
            total += d * d / n;
            *g = (2.0 * d / n) as f32;
        }
        Ok(DmsTerms {
            total,
            ..Default::default()
        })
    }
}

/// Runs the example.
pub fn main() -> Result<(), Box<dyn std::error::Error>> {
    let text = include_str!("jelly_on_floor.toml");
    let mut config = SimConfig::parse(text, "jelly_on_floor.toml".as_ref())?;
    let truth = config.parts.clone();
    config.parts[0].youngs_modulus_pa *= 0.4; // where the fit starts
    let (eye, target) = ([0.5, -0.3, 0.6], [0.5, 0.5, 0.35]);
    let camera = Camera::look_at(64, 48, 40.0, eye, target, [0.0, 0.0, 1.0]);
    let problem = ProblemBuilder::new(config)
        .camera(camera)
        .background([0.93, 0.92, 0.86])
        .rendered_from(&truth)?;
    let mut fit = FitConfig {
        // As written here: the automatic strategy would decide the stages and their budgets.
        strategy: Strategy::Fixed,
        iters: 25,
        free: Some(vec!["E".into()]),
        ..Default::default()
    };
    fit.init.enabled = false;
    let outcome = run_fit_with_loss(&problem, &fit, Arc::new(Mse), None, &mut NoHooks)?;
    let e_true = truth[0].youngs_modulus_pa;
    let e = outcome.parts[0].youngs_modulus_pa;
    println!(
        "MSE fit: E truth {e_true:.0} Pa, start {:.0}, fit {e:.0}",
        0.4 * e_true
    );
    assert!((e / e_true - 1.0).abs() < 0.05, "E off by more than 5%");
    Ok(())
}
