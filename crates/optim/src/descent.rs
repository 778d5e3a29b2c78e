//! One iteration of gradient descent, shared by every fit (the trajectory fit and the video
//! fit): the optimiser's point is written into the parameter slots, evaluated (loss and the
//! per-slot gradient, by whatever the fit minimises), checked, mapped to the free parameters,
//! and the optimiser steps with the scheduled learning rate. The lowest loss evaluated is
//! kept ([`Best`]): Adam's momentum can carry the last iterate past the minimum.

use crate::space::ParamSpace;
use crate::{FitError, LogDomainOptimizer, LrSchedule, TrustRegionBfgs};
use r4d_mpm::adjoint::host::PhysParams;
use r4d_mpm::PartParams;

/// The optimiser a fit steps with: AdamW in the log domain, or the trust-region damped BFGS.
#[derive(Clone, Debug)]
pub(crate) enum Stepper {
    Adam(LogDomainOptimizer),
    Trust(TrustRegionBfgs),
}

impl Stepper {
    /// The current point.
    pub fn theta(&self) -> Vec<f64> {
        match self {
            Stepper::Adam(o) => o.theta(),
            Stepper::Trust(o) => o.theta(),
        }
    }

    /// One step from the loss and `dL/dtheta` at [`Stepper::theta`] (`lr`: Adam's rate);
    /// returns the gradient norm in the log domain before clipping.
    pub fn step(&mut self, loss: f64, g: &[f64], lr: f64) -> f64 {
        match self {
            Stepper::Adam(o) => {
                o.adam.lr = lr;
                o.step(g)
            }
            Stepper::Trust(o) => o.step(loss, g),
        }
    }

    /// Moves one coordinate (the flat-direction probes).
    pub fn set_theta(&mut self, i: usize, v: f64) {
        match self {
            Stepper::Adam(o) => o.set_theta(i, v),
            Stepper::Trust(o) => o.set_theta(i, v),
        }
    }
}

/// The learning-rate schedule of a fit: `schedule` from `base` over `iters` iterations.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Rate {
    pub schedule: LrSchedule,
    pub base: f64,
    pub iters: usize,
}

/// What one iteration evaluated and did.
#[derive(Clone, Debug)]
pub(crate) struct Iterate<E> {
    /// The fit's own evaluation (the video fit: its loss terms).
    pub eval: E,
    /// The loss at `theta`.
    pub loss: f64,
    /// The point evaluated.
    pub theta: Vec<f64>,
    /// `dL/dtheta` there.
    pub gtheta: Vec<f64>,
    /// The per-slot parameters evaluated.
    pub slots: Vec<PartParams>,
    /// Norm of the log-domain gradient before clipping.
    pub grad_norm: f64,
    /// The learning rate of the step taken.
    pub lr: f64,
}

/// Iteration `iter`: evaluates `opt`'s point through `evaluate` (the per-slot parameters ->
/// the fit's evaluation, its loss, and the per-slot gradient), then steps. A non-finite loss
/// or gradient is [`FitError::NonFinite`] and nothing is stepped.
pub(crate) fn iterate<E>(
    space: &ParamSpace,
    base_slots: &[PartParams],
    opt: &mut Stepper,
    rate: Rate,
    iter: usize,
    evaluate: impl FnOnce(&[PartParams]) -> Result<(E, f64, Vec<PhysParams<f64>>), FitError>,
) -> Result<Iterate<E>, FitError> {
    let theta = opt.theta();
    let mut slots = base_slots.to_vec();
    space.apply(&mut slots, &theta);
    let (eval, loss, g) = evaluate(&slots)?;
    let gtheta = space.gather(&g);
    if !loss.is_finite() || gtheta.iter().any(|x| !x.is_finite()) {
        return Err(FitError::NonFinite(format!(
            "iteration {iter}: the loss or its gradient"
        )));
    }
    let lr = rate.schedule.lr(rate.base, iter, rate.iters);
    let grad_norm = opt.step(loss, &gtheta, lr);
    Ok(Iterate {
        eval,
        loss,
        theta,
        gtheta,
        slots,
        grad_norm,
        lr,
    })
}

/// Keeps the lowest loss evaluated and what it was evaluated at.
pub(crate) fn keep_best<T: Clone>(best: &mut Option<(f64, T)>, loss: f64, at: &T) {
    if best.as_ref().is_none_or(|(l, _)| loss < *l) {
        *best = Some((loss, at.clone()));
    }
}
