//! The one evaluation interface of a fit's stages ([`Evaluator`]): the loss, or the loss and
//! its gradient, at points of the free parameters in the log domain (`x = ln theta`), one at a
//! time or as a batch evaluated in parallel. The valley search ([`crate::ValleySearch`]),
//! gradient sampling ([`crate::GradientSampling`]) and the restarts along constant bulk
//! modulus take one; the video fit implements it over its objective, tests over closures
//! ([`FnEvaluator`]).
//!
//! ```
//! use r4d_optim::evaluator::{Evaluator, FnEvaluator};
//! let bowl = FnEvaluator::with_grad(
//!     |x: &[f64]| x.iter().map(|v| v * v).sum(),
//!     |x: &[f64]| Some((x.iter().map(|v| v * v).sum(), x.iter().map(|v| 2.0 * v).collect())),
//! );
//! assert_eq!(bowl.values(&[vec![1.0, 2.0], vec![0.0, 0.0]]), [5.0, 0.0]);
//! assert_eq!(bowl.value_and_grad(&[1.0]).unwrap().1, [2.0]);
//! ```

use rayon::prelude::*;

/// A point's loss and log-unit gradient, `None` where its simulation failed (a wall).
pub type Graded = Option<(f64, Vec<f64>)>;

/// What a fit stage evaluates: the loss at points `x` (logs of the free parameters). A point
/// whose simulation fails is a wall of the landscape, not an error of the fit: its loss is
/// `f64::INFINITY` and its gradient `None`.
pub trait Evaluator: Sync {
    /// The loss at `x` (`f64::INFINITY` where it fails).
    fn value(&self, x: &[f64]) -> f64;
    /// The loss and its gradient with respect to `x` (`None` where it fails).
    fn value_and_grad(&self, x: &[f64]) -> Graded;
    /// The losses of a batch, in order (by default in parallel on rayon's current pool).
    fn values(&self, xs: &[Vec<f64>]) -> Vec<f64> {
        xs.par_iter().map(|x| self.value(x)).collect()
    }
    /// The losses and gradients of a batch, in order (by default in parallel).
    fn values_and_grads(&self, xs: &[Vec<f64>]) -> Vec<Graded> {
        xs.par_iter().map(|x| self.value_and_grad(x)).collect()
    }
}

/// An [`Evaluator`] from closures: a loss and, optionally, its gradient (without one every
/// gradient is `None`).
pub struct FnEvaluator<V, G = fn(&[f64]) -> Graded> {
    value: V,
    grad: G,
}

impl<V: Fn(&[f64]) -> f64 + Sync> FnEvaluator<V> {
    /// A loss without a gradient.
    pub fn new(value: V) -> Self {
        FnEvaluator {
            value,
            grad: |_: &[f64]| None,
        }
    }
}

impl<V: Fn(&[f64]) -> f64 + Sync, G: Fn(&[f64]) -> Graded + Sync> FnEvaluator<V, G> {
    /// A loss and its gradient (`value_and_grad` returns both).
    pub fn with_grad(value: V, value_and_grad: G) -> Self {
        FnEvaluator {
            value,
            grad: value_and_grad,
        }
    }
}

impl<V: Fn(&[f64]) -> f64 + Sync, G: Fn(&[f64]) -> Graded + Sync> Evaluator for FnEvaluator<V, G> {
    fn value(&self, x: &[f64]) -> f64 {
        (self.value)(x)
    }
    fn value_and_grad(&self, x: &[f64]) -> Graded {
        (self.grad)(x)
    }
}
