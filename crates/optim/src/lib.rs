//! # r4d-optim: optimisation of physical parameters in the log domain
//!
//! The paper (Sec. 3.3) optimises `xi = log(theta)` for every free physical parameter, clips
//! `xi` to `[log l, log u]` after every step, clips the gradient norm and updates with AdamW.
//! With `theta = exp(xi)` the chain rule is `dL/dxi = theta dL/dtheta`.
//!
//! This crate works on a flat vector of positive parameters with bounds
//! ([`LogDomainOptimizer`]); mapping parts and parameter kinds to that vector is the caller's
//! business ([`ParamKind`] names the kinds and their default bounds).
//!
//! Still to come with the fitting issue: Latin hypercube initialisation and the `Initializer`
//! trait.
//!
//! ```
//! use r4d_optim::{AdamW, LogDomainOptimizer};
//! // Minimise (log theta - log 3)^2 from theta = 30.
//! let mut opt = LogDomainOptimizer::new(vec![30.0], vec![(1.0, 100.0)], AdamW { lr: 0.1, ..Default::default() }, None).unwrap();
//! for _ in 0..300 {
//!     let t = opt.theta()[0];
//!     let dl_dtheta = 2.0 * (t.ln() - 3f64.ln()) / t;
//!     opt.step(&[dl_dtheta]);
//! }
//! assert!((opt.theta()[0] - 3.0).abs() < 0.05);
//! ```

use serde::{Deserialize, Serialize};

/// Errors of this crate.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// A parameter or bound is not positive and finite, or lies outside its bounds.
    #[error("parameter {index}: {message}")]
    Invalid {
        /// Index in the parameter vector.
        index: usize,
        /// What is wrong.
        message: String,
    },
    /// An unknown parameter name.
    #[error("unknown parameter '{0}' (known: E, nu, yield_stress, plastic_viscosity, friction_angle, density)")]
    UnknownParam(String),
}

/// The learnable physical parameters of a part.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ParamKind {
    /// Young's modulus (Pa).
    #[serde(rename = "E")]
    YoungsModulus,
    /// Poisson's ratio.
    #[serde(rename = "nu")]
    PoissonRatio,
    /// Yield stress (Pa).
    YieldStress,
    /// Plastic viscosity (Pa s).
    PlasticViscosity,
    /// Friction angle (degrees).
    FrictionAngle,
    /// Density (kg/m^3).
    Density,
}

impl ParamKind {
    /// All kinds, in the paper's order.
    pub const ALL: [ParamKind; 6] = [
        ParamKind::YoungsModulus,
        ParamKind::PoissonRatio,
        ParamKind::YieldStress,
        ParamKind::PlasticViscosity,
        ParamKind::FrictionAngle,
        ParamKind::Density,
    ];
    /// The name used on the command line and in `params.json`.
    pub fn name(self) -> &'static str {
        match self {
            ParamKind::YoungsModulus => "E",
            ParamKind::PoissonRatio => "nu",
            ParamKind::YieldStress => "yield_stress",
            ParamKind::PlasticViscosity => "plastic_viscosity",
            ParamKind::FrictionAngle => "friction_angle",
            ParamKind::Density => "density",
        }
    }
    /// Parses a name (see [`ParamKind::name`]).
    pub fn parse(s: &str) -> Result<ParamKind, Error> {
        ParamKind::ALL
            .into_iter()
            .find(|k| k.name().eq_ignore_ascii_case(s.trim()))
            .ok_or_else(|| Error::UnknownParam(s.to_string()))
    }
    /// Default bounds (the paper's search ranges): E [1e3, 1e7] Pa, nu [0.01, 0.49],
    /// yield stress [1e2, 1e6] Pa, plastic viscosity [1e-2, 1e3] Pa s, friction angle
    /// [5, 60] degrees, density [1e2, 1e4] kg/m^3.
    pub fn default_bounds(self) -> (f64, f64) {
        match self {
            ParamKind::YoungsModulus => (1e3, 1e7),
            ParamKind::PoissonRatio => (0.01, 0.49),
            ParamKind::YieldStress => (1e2, 1e6),
            ParamKind::PlasticViscosity => (1e-2, 1e3),
            ParamKind::FrictionAngle => (5.0, 60.0),
            ParamKind::Density => (1e2, 1e4),
        }
    }
}

/// AdamW hyper-parameters.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct AdamW {
    /// Learning rate (in log units per step).
    pub lr: f64,
    /// First-moment decay.
    pub beta1: f64,
    /// Second-moment decay.
    pub beta2: f64,
    /// Denominator guard.
    pub eps: f64,
    /// Decoupled weight decay (applied to xi = log theta; 0 disables it).
    pub weight_decay: f64,
}

impl Default for AdamW {
    fn default() -> Self {
        AdamW {
            lr: 0.05,
            beta1: 0.9,
            beta2: 0.999,
            eps: 1e-8,
            weight_decay: 0.0,
        }
    }
}

/// AdamW on `xi = log(theta)` with bound and gradient-norm clipping. Serialisable, so a killed
/// run can resume with its moments.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct LogDomainOptimizer {
    xi: Vec<f64>,
    log_bounds: Vec<(f64, f64)>,
    m: Vec<f64>,
    v: Vec<f64>,
    t: u64,
    /// Hyper-parameters.
    pub adam: AdamW,
    /// Maximum norm of the gradient with respect to xi (`None`: no clipping).
    pub clip_norm: Option<f64>,
}

impl LogDomainOptimizer {
    /// Starts from positive `theta` within positive `bounds`.
    pub fn new(
        theta: Vec<f64>,
        bounds: Vec<(f64, f64)>,
        adam: AdamW,
        clip_norm: Option<f64>,
    ) -> Result<Self, Error> {
        assert_eq!(theta.len(), bounds.len(), "one bound per parameter");
        for (i, (&t, &(l, u))) in theta.iter().zip(&bounds).enumerate() {
            let bad = |m: String| {
                Err(Error::Invalid {
                    index: i,
                    message: m,
                })
            };
            if !(l.is_finite() && u.is_finite() && l > 0.0 && u >= l) {
                return bad(format!(
                    "bounds [{l}, {u}] must be positive, finite and ordered"
                ));
            }
            if !(t.is_finite() && t > 0.0) {
                return bad(format!("value {t} must be positive and finite"));
            }
        }
        let n = theta.len();
        Ok(LogDomainOptimizer {
            xi: theta
                .iter()
                .zip(&bounds)
                .map(|(t, (l, u))| t.ln().clamp(l.ln(), u.ln()))
                .collect(),
            log_bounds: bounds.iter().map(|(l, u)| (l.ln(), u.ln())).collect(),
            m: vec![0.0; n],
            v: vec![0.0; n],
            t: 0,
            adam,
            clip_norm,
        })
    }

    /// Current parameters `theta = exp(xi)`.
    pub fn theta(&self) -> Vec<f64> {
        self.xi.iter().map(|x| x.exp()).collect()
    }

    /// Steps taken.
    pub fn steps(&self) -> u64 {
        self.t
    }

    /// One AdamW step given `dL/dtheta`; returns the norm of `dL/dxi` before clipping.
    pub fn step(&mut self, grad_theta: &[f64]) -> f64 {
        assert_eq!(grad_theta.len(), self.xi.len());
        let mut g: Vec<f64> = grad_theta
            .iter()
            .zip(&self.xi)
            .map(|(g, x)| g * x.exp())
            .collect();
        let norm = g.iter().map(|x| x * x).sum::<f64>().sqrt();
        if let Some(c) = self.clip_norm {
            if norm > c && norm > 0.0 {
                g.iter_mut().for_each(|x| *x *= c / norm);
            }
        }
        self.t += 1;
        let a = self.adam;
        let (b1t, b2t) = (
            1.0 - a.beta1.powi(self.t as i32),
            1.0 - a.beta2.powi(self.t as i32),
        );
        for i in 0..self.xi.len() {
            self.m[i] = a.beta1 * self.m[i] + (1.0 - a.beta1) * g[i];
            self.v[i] = a.beta2 * self.v[i] + (1.0 - a.beta2) * g[i] * g[i];
            let (mh, vh) = (self.m[i] / b1t, self.v[i] / b2t);
            self.xi[i] -= a.lr * (mh / (vh.sqrt() + a.eps) + a.weight_decay * self.xi[i]);
            let (lo, hi) = self.log_bounds[i];
            self.xi[i] = self.xi[i].clamp(lo, hi);
        }
        norm
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn chain_rule_bounds_and_clipping() {
        let mut o = LogDomainOptimizer::new(
            vec![10.0, 0.3],
            vec![(1.0, 20.0), (0.01, 0.49)],
            AdamW::default(),
            Some(1.0),
        )
        .unwrap();
        // A huge gradient pushing theta[0] up: clipped, bounded at 20.
        for _ in 0..200 {
            let n = o.step(&[-1e6, 0.0]);
            assert!(n > 1.0);
        }
        assert!((o.theta()[0] - 20.0).abs() < 1e-9);
        assert!((o.theta()[1] - 0.3).abs() < 1e-12);
        assert!(
            LogDomainOptimizer::new(vec![-1.0], vec![(1.0, 2.0)], AdamW::default(), None).is_err()
        );
        assert_eq!(ParamKind::parse("nu").unwrap(), ParamKind::PoissonRatio);
        assert!(ParamKind::parse("poisson").is_err());
    }
}
