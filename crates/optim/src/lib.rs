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
//! ## Initialisation
//!
//! The fit starts from the paper's simulation-driven initialisation ([`Initializer`],
//! implemented by [`LatinHypercubeInit`]): `N = 32` candidates from a seeded Latin hypercube
//! ([`latin_hypercube`]) are mapped log-uniformly into the bounds of a [`SearchSpace`]
//! ([`log_space`]); the caller simulates each and scores it against the reference video
//! (higher is better, e.g. MS-SSIM). Candidates whose simulation fails (an error or a NaN
//! score) are recorded and skipped; the [`InitOutcome`] ranks the rest and its
//! [`InitOutcome::best`] is the starting point of the gradient-based fit. Candidates are
//! evaluated in parallel with rayon, and the outcome does not depend on it.
//!
//! ```
//! use r4d_optim::{Initializer, LatinHypercubeInit, SearchSpace};
//! // Maximise -(log10 theta - 2)^2 over [1, 1e4]: the peak is at theta = 100.
//! let space = SearchSpace::new(vec!["E".into()], vec![(1.0, 1e4)]).unwrap();
//! let init = LatinHypercubeInit { candidates: 32, seed: 1, ..Default::default() };
//! let out = init
//!     .initialize(&space, &|_index, theta| Ok(-(theta[0].log10() - 2.0).powi(2)))
//!     .unwrap();
//! // 32 strata of 4/32 decades each: the one holding the peak puts a candidate that close.
//! assert!((out.best[0].log10() - 2.0).abs() < 4.0 / 32.0);
//! assert_eq!(out.ranking.len(), 32);
//! assert_eq!(out.top_k.len(), 4);
//! ```
//!
//! ## Fitting
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

pub mod compute;
mod descent;
mod error;
pub mod evaluator;
mod heap;
mod init;
mod lhs;
pub mod record;
pub mod restarts;
pub mod sampling;
pub mod space;
pub mod trajectory;
mod trust_bfgs;
pub mod valley;
pub mod video;

pub use compute::{Compute, Precision, ReferenceCompute};
pub use error::FitError;
pub use evaluator::{Evaluator, FnEvaluator, Graded};
pub use heap::{HeapProbe, HeapSpan};
pub use init::{
    evaluate_candidate, Candidate, Evaluate, InitOutcome, Initializer, LatinHypercubeInit,
    LogGridInit, NaturalScaleInit, SearchSpace,
};
pub use lhs::{latin_hypercube, log_space, SplitMix64};
pub use restarts::{Restart, RestartsConfig, ShearRestarts};
pub use sampling::{GradientSampling, SamplingConfig};
pub use trust_bfgs::{TrustRegion, TrustRegionBfgs};
pub use valley::{ValleyConfig, ValleySearch};

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
    /// A hyper-parameter out of its range (the message names it and the range).
    #[error("{0}")]
    Setting(String),
    /// An unknown parameter name.
    #[error("unknown parameter '{0}' (known: E, nu, yield_stress, plastic_viscosity, friction_angle, density, hardening, softening)")]
    UnknownParam(String),
    /// A search-space bound is not positive, finite and ordered.
    #[error("parameter '{name}': search bounds [{lo}, {hi}] must be positive, finite and ordered (lo <= hi)")]
    InvalidBounds {
        /// The parameter's name.
        name: String,
        /// Lower bound.
        lo: f64,
        /// Upper bound.
        hi: f64,
    },
    /// The search space is malformed (names and bounds differ in number, or a name repeats).
    #[error("search space: {0}")]
    InvalidSpace(String),
    /// An extra initialisation candidate ([`LatinHypercubeInit::include`]) does not fit the
    /// search space.
    #[error("included initialisation candidate {position}: {message}")]
    InvalidInclude {
        /// Position in `include`.
        position: usize,
        /// What is wrong, naming the parameter.
        message: String,
    },
    /// There is nothing to evaluate (no samples and no included candidates).
    #[error("no initialisation candidates (candidates = 0 and nothing included)")]
    NoCandidates,
    /// Every initialisation candidate failed to evaluate.
    #[error("all {count} initialisation candidates failed; first failure (candidate {index}): {message}")]
    AllCandidatesFailed {
        /// Number of candidates.
        count: usize,
        /// Index of the first (lowest-index) failed candidate.
        index: usize,
        /// Its error message.
        message: String,
    },
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
    /// Metal's hardening coefficient xi (dimensionless; the part needs `hardening = true`).
    Hardening,
    /// Plasticine's softening rate (Pa per unit plastic strain).
    Softening,
}

impl ParamKind {
    /// All kinds: the paper's six in its order, then the hardening laws' coefficients.
    pub const ALL: [ParamKind; 8] = [
        ParamKind::YoungsModulus,
        ParamKind::PoissonRatio,
        ParamKind::YieldStress,
        ParamKind::PlasticViscosity,
        ParamKind::FrictionAngle,
        ParamKind::Density,
        ParamKind::Hardening,
        ParamKind::Softening,
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
            ParamKind::Hardening => "hardening",
            ParamKind::Softening => "softening",
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
    /// [5, 60] degrees, density [1e2, 1e4] kg/m^3; metal's hardening xi [1e-3, 0.9] (the
    /// yield stress grows by `2 mu xi` per unit plastic strain; linearised, PhysGaussian's
    /// explicit update multiplies a perturbation of the yield stress by `-xi` at every
    /// substep in which a particle keeps yielding, so above 1 the gradient grows
    /// geometrically: measured 2e147 after 3 200 substeps at xi = 1.41, `docs/fitting-measurements.md`),
    /// plasticine's softening
    /// [1, 1e6] Pa per unit plastic strain (the yield stress range: from negligible to
    /// softening completely within a unit of strain).
    pub fn default_bounds(self) -> (f64, f64) {
        match self {
            ParamKind::YoungsModulus => (1e3, 1e7),
            ParamKind::PoissonRatio => (0.01, 0.49),
            ParamKind::YieldStress => (1e2, 1e6),
            ParamKind::PlasticViscosity => (1e-2, 1e3),
            ParamKind::FrictionAngle => (5.0, 60.0),
            ParamKind::Density => (1e2, 1e4),
            ParamKind::Hardening => (1e-3, 0.9),
            ParamKind::Softening => (1.0, 1e6),
        }
    }

    /// The default bounds for a part of `material`: [`ParamKind::default_bounds`], except
    /// Poisson's ratio of PhysFlow's nearly incompressible `newtonian` (its scenes use 0.499 to
    /// 0.4995), [0.3, 0.4999].
    pub fn default_bounds_for(self, material: r4d_mpm::Material) -> (f64, f64) {
        match (self, material) {
            (ParamKind::PoissonRatio, r4d_mpm::Material::Newtonian) => (0.3, 0.4999),
            _ => self.default_bounds(),
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

impl AdamW {
    /// Checks the hyper-parameters (the one check every command and every resumed state goes
    /// through): `lr` positive and finite, `beta1` and `beta2` in `[0, 1)`, `eps` positive
    /// and finite, `weight_decay` finite and not negative.
    pub fn validate(&self) -> Result<(), Error> {
        let bad = |m: String| Err(Error::Setting(m));
        if !(self.lr.is_finite() && self.lr > 0.0) {
            return bad(format!("lr = {} must be positive and finite", self.lr));
        }
        for (n, b) in [("beta1", self.beta1), ("beta2", self.beta2)] {
            if !(0.0..1.0).contains(&b) {
                return bad(format!("{n} = {b} must be in [0, 1)"));
            }
        }
        if !(self.eps.is_finite() && self.eps > 0.0) {
            return bad(format!("eps = {} must be positive and finite", self.eps));
        }
        if !(self.weight_decay.is_finite() && self.weight_decay >= 0.0) {
            return bad(format!(
                "weight_decay = {} must be >= 0 and finite",
                self.weight_decay
            ));
        }
        Ok(())
    }
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
        if theta.len() != bounds.len() {
            return Err(Error::Invalid {
                index: theta.len().min(bounds.len()),
                message: format!(
                    "{} values for {} bounds: one bound per parameter",
                    theta.len(),
                    bounds.len()
                ),
            });
        }
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
        adam.validate()?;
        if let Some(c) = clip_norm {
            if !(c.is_finite() && c > 0.0) {
                return Err(Error::Setting(format!(
                    "clip_norm = {c} must be positive and finite (or no clipping)"
                )));
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

    /// Checks a state read back (a checkpoint) before it is stepped: `n` parameters, every
    /// vector that long, values finite, inside ordered bounds, second moments not negative,
    /// hyper-parameters valid. A damaged or foreign checkpoint is an error here, not a panic
    /// or silent garbage later.
    pub fn validate(&self, n: usize) -> Result<(), Error> {
        let lens = [
            self.xi.len(),
            self.log_bounds.len(),
            self.m.len(),
            self.v.len(),
        ];
        if let Some(&bad) = lens.iter().find(|&&l| l != n) {
            return Err(Error::Invalid {
                index: bad.min(n),
                message: format!(
                    "the optimiser state holds vectors of {lens:?} entries (parameters, bounds, moments), this fit has {n} parameters"
                ),
            });
        }
        for i in 0..n {
            let (lo, hi) = self.log_bounds[i];
            let ok = lo.is_finite()
                && hi.is_finite()
                && lo <= hi
                && self.xi[i].is_finite()
                && (lo..=hi).contains(&self.xi[i])
                && self.m[i].is_finite()
                && self.v[i].is_finite()
                && self.v[i] >= 0.0;
            if !ok {
                return Err(Error::Invalid {
                    index: i,
                    message: format!(
                        "damaged optimiser state: log value {}, log bounds [{lo}, {hi}], moments {} and {}",
                        self.xi[i], self.m[i], self.v[i]
                    ),
                });
            }
        }
        self.adam.validate()?;
        if let Some(c) = self.clip_norm {
            if !(c.is_finite() && c > 0.0) {
                return Err(Error::Setting(format!(
                    "clip_norm = {c} must be positive and finite (or no clipping)"
                )));
            }
        }
        Ok(())
    }

    /// Moves parameter `i` to `value` (clamped to its bounds) and forgets its moments: the
    /// next steps treat it as freshly started. Used when a fit jumps along a direction whose
    /// gradient is exactly zero (a flat-direction probe); an index out of range is ignored.
    pub fn set_theta(&mut self, i: usize, value: f64) {
        if i >= self.xi.len() || value.is_nan() || value <= 0.0 {
            return;
        }
        let (lo, hi) = self.log_bounds[i];
        self.xi[i] = value.ln().clamp(lo, hi);
        self.m[i] = 0.0;
        self.v[i] = 0.0;
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
        // Saturating: a step count read from a damaged checkpoint must not overflow.
        self.t = self.t.saturating_add(1);
        let t = self.t.min(i32::MAX as u64) as i32;
        let a = self.adam;
        let (b1t, b2t) = (1.0 - a.beta1.powi(t), 1.0 - a.beta2.powi(t));
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

/// Learning-rate schedule of a fit (one for every fit: `FIT.toml`'s `lr_schedule`, the
/// trajectory fit's [`trajectory::FitOptions::schedule`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum LrSchedule {
    /// The same rate every iteration.
    Constant,
    /// Cosine decay from `lr` to 5% of it over the run (default), so Adam settles.
    #[default]
    Cosine,
}

impl LrSchedule {
    /// The rate of iteration `iter` (0-based) of `iters`, from the base rate `lr`.
    ///
    /// ```
    /// use r4d_optim::LrSchedule;
    /// assert_eq!(LrSchedule::Cosine.lr(0.3, 0, 10), 0.3);
    /// assert!((LrSchedule::Cosine.lr(0.3, 10, 10) - 0.015).abs() < 1e-12);
    /// assert_eq!(LrSchedule::Constant.lr(0.3, 7, 10), 0.3);
    /// ```
    pub fn lr(self, lr: f64, iter: usize, iters: usize) -> f64 {
        match self {
            LrSchedule::Constant => lr,
            LrSchedule::Cosine => {
                let p = iter as f64 / iters.max(1) as f64;
                lr * (0.05 + 0.95 * 0.5 * (1.0 + (std::f64::consts::PI * p).cos()))
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A checkpoint's optimiser is checked before it is stepped (a vector of the
    /// wrong length used to hit an `assert!`), and the hyper-parameters go through the one
    /// check every command uses.
    #[test]
    fn damaged_states_and_bad_settings_are_errors() {
        let o = LogDomainOptimizer::new(
            vec![1.0, 2.0],
            vec![(0.1, 10.0), (0.1, 10.0)],
            AdamW::default(),
            Some(1.0),
        )
        .unwrap();
        o.validate(2).unwrap();
        assert!(o.validate(3).is_err());
        let mut j = serde_json::to_value(&o).unwrap();
        j["m"] = serde_json::json!([0.0]);
        let short: LogDomainOptimizer = serde_json::from_value(j.clone()).unwrap();
        assert!(short.validate(2).is_err());
        j["m"] = serde_json::json!([0.0, 0.0]);
        j["xi"] = serde_json::json!([0.0, 50.0]);
        let outside: LogDomainOptimizer = serde_json::from_value(j).unwrap();
        assert!(outside.validate(2).is_err());
        let bad = AdamW {
            beta1: 1.5,
            ..Default::default()
        };
        assert!(bad.validate().unwrap_err().to_string().contains("beta1"));
        assert!(LogDomainOptimizer::new(vec![1.0], vec![(0.1, 10.0)], bad, None).is_err());
        assert!(
            LogDomainOptimizer::new(vec![1.0, 2.0], vec![(0.1, 10.0)], AdamW::default(), None)
                .is_err(),
            "one bound per parameter is an error, not an assert"
        );
        let t = TrustRegionBfgs::new(
            vec![1.0, 2.0],
            vec![(0.1, 10.0), (0.1, 10.0)],
            TrustRegion {
                initial_radius: 0.1,
                max_radius: 0.5,
                min_radius: 0.01,
            },
        )
        .unwrap();
        t.validate(2).unwrap();
        assert!(t.validate(1).is_err());
    }

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

    /// Asserts `a == b` within `tol` relative to max(1, |b|).
    fn close(a: f64, b: f64, tol: f64, what: &str) {
        assert!(
            (a - b).abs() <= tol * b.abs().max(1.0),
            "{what}: {a} vs {b}"
        );
    }

    #[test]
    fn adamw_two_steps_by_hand() {
        // lr 0.1, beta1 0.9, beta2 0.999, eps 1e-8, weight decay 0.01, no clipping.
        // theta0 = [2, 4]: xi0 = [ln 2, ln 4] = [0.6931471805599453, 1.3862943611198906].
        // Bounds: [0.5, 8] and [1, 4.5]; ln 4.5 = 1.5040773967762742.
        let adam = AdamW {
            lr: 0.1,
            beta1: 0.9,
            beta2: 0.999,
            eps: 1e-8,
            weight_decay: 0.01,
        };
        let mut o =
            LogDomainOptimizer::new(vec![2.0, 4.0], vec![(0.5, 8.0), (1.0, 4.5)], adam, None)
                .unwrap();

        // Step 1: g_theta = [1.5, -0.4], g_xi = g_theta * theta = [3, -1.6];
        // returned norm |g_xi| = sqrt(9 + 2.56) = sqrt(11.56) = 3.4.
        let n1 = o.step(&[1.5, -0.4]);
        close(n1, 3.4, 1e-15, "norm 1");
        // Bias corrections: 1 - 0.9 = 0.1, 1 - 0.999 = 0.001.
        // p0: m = 0.1 * 3 = 0.3, v = 0.001 * 9 = 0.009; m^ = 3, v^ = 9;
        //     m^ / (sqrt v^ + eps) = 3 / (3 + 1e-8) = 0.9999999966666667;
        //     decay lr * wd * xi: inside the bracket wd * xi0 = 0.006931471805599453;
        //     xi1 = 0.6931471805599453 - 0.1 * (0.9999999966666667 + 0.006931471805599453)
        //         = 0.5924540337127187 (inside [ln 0.5, ln 8]).
        // p1: m = -0.16, v = 0.00256; m^ = -1.6, v^ = 2.56;
        //     ratio = -1.6 / (1.6 + 1e-8) = -0.99999999375; wd * xi0 = 0.013862943611198907;
        //     xi1 = 1.3862943611198906 - 0.1 * (-0.99999999375 + 0.013862943611198907)
        //         = 1.4849080661337708 (inside [0, ln 4.5]).
        close(o.xi[0], 0.5924540337127187, 1e-14, "xi1[0]");
        close(o.xi[1], 1.4849080661337708, 1e-14, "xi1[1]");
        close(o.m[0], 0.3, 1e-14, "m1[0]");
        close(o.v[1], 0.00256, 1e-14, "v1[1]");
        let t1 = o.theta();
        close(t1[0], 1.80842090029581, 1e-13, "theta1[0]");
        close(t1[1], 4.414559546595623, 1e-13, "theta1[1]");

        // Step 2: choose g_theta so that g_xi = g_theta * theta1 = [1, -2];
        // returned norm sqrt(1 + 4) = sqrt 5.
        let n2 = o.step(&[1.0 / t1[0], -2.0 / t1[1]]);
        close(n2, 5f64.sqrt(), 1e-14, "norm 2");
        // Bias corrections: 1 - 0.9^2 = 0.19, 1 - 0.999^2 = 0.001999.
        // p0: m = 0.9 * 0.3 + 0.1 * 1 = 0.37, v = 0.999 * 0.009 + 0.001 * 1 = 0.009991;
        //     m^ = 0.37 / 0.19 = 1.9473684210526319, v^ = 0.009991 / 0.001999 = 4.99799899949982;
        //     ratio = 1.9473684210526319 / (2.2356204...+ 1e-8) = 0.8710639468280398;
        //     wd * xi1 = 0.005924540337127186;
        //     xi2 = 0.5924540337127187 - 0.1 * (0.8710639468280398 + 0.005924540337127186)
        //         = 0.504755184996202.
        // p1: m = 0.9 * -0.16 + 0.1 * -2 = -0.344, v = 0.999 * 0.00256 + 0.001 * 4 = 0.00655744;
        //     m^ = -1.810526315789474, v^ = 3.2803601800900926;
        //     ratio = -0.9996410304514594; wd * xi1 = 0.014849080661337707;
        //     xi2 = 1.4849080661337708 - 0.1 * (-0.9996410304514594 + 0.014849080661337707)
        //         = 1.583387261112783 > ln 4.5: clamped to 1.5040773967762742 (theta = 4.5).
        close(o.m[0], 0.37, 1e-14, "m2[0]");
        close(o.v[0], 0.009991, 1e-14, "v2[0]");
        close(o.m[1], -0.344, 1e-14, "m2[1]");
        close(o.v[1], 0.00655744, 1e-14, "v2[1]");
        close(o.xi[0], 0.504755184996202, 1e-14, "xi2[0]");
        assert_eq!(o.xi[1], 4.5f64.ln(), "xi2[1] clamped to the upper bound");
        close(o.theta()[0], 1.656579915195519, 1e-13, "theta2[0]");
        close(o.theta()[1], 4.5, 1e-15, "theta2[1]");
        assert_eq!(o.steps(), 2);
    }

    #[test]
    fn gradient_norm_clipping_scales_to_the_clip_norm() {
        // theta = 1 (xi = 0) so g_xi = g_theta; no weight decay so xi moves by Adam alone.
        let bounds = vec![(1e-3, 1e3), (1e-3, 1e3)];
        let adam = AdamW {
            lr: 0.1,
            ..Default::default()
        };
        let mut clipped =
            LogDomainOptimizer::new(vec![1.0, 1.0], bounds.clone(), adam, Some(1.0)).unwrap();
        let mut free = LogDomainOptimizer::new(vec![1.0, 1.0], bounds.clone(), adam, None).unwrap();
        // g_xi = [3, -4], |g_xi| = 5 > 1: scaled by 1/5 to [0.6, -0.8] (norm 1).
        let n = clipped.step(&[3.0, -4.0]);
        assert_eq!(n, 5.0, "the returned norm is the pre-clip norm");
        assert_eq!(free.step(&[3.0, -4.0]), 5.0);
        // The moments saw the clipped gradient: m = 0.1 g, v = 0.001 g^2.
        close(clipped.m[0], 0.06, 1e-15, "m[0]");
        close(clipped.m[1], -0.08, 1e-15, "m[1]");
        close(clipped.v[0], 0.001 * 0.36, 1e-15, "v[0]");
        close(clipped.v[1], 0.001 * 0.64, 1e-15, "v[1]");
        // First Adam step: m^ / sqrt v^ = sign(g), so the step is unchanged in direction and
        // (up to eps) in size: xi = -lr * g / (|g| + eps).
        close(clipped.xi[0], -0.1 * 0.6 / (0.6 + 1e-8), 1e-15, "xi[0]");
        close(clipped.xi[1], 0.1 * 0.8 / (0.8 + 1e-8), 1e-15, "xi[1]");
        for i in 0..2 {
            close(clipped.xi[i], free.xi[i], 1e-7, "clipped vs free step");
        }
        // With a large eps the first step shows the magnitudes: g / (|g| + 1) with the clipped
        // g is 0.6 / 1.6 = 0.375 and -0.8 / 1.8 = -0.4444...
        let big_eps = AdamW { eps: 1.0, ..adam };
        let mut o =
            LogDomainOptimizer::new(vec![1.0, 1.0], bounds.clone(), big_eps, Some(1.0)).unwrap();
        o.step(&[3.0, -4.0]);
        close(o.xi[0], -0.1 * 0.375, 1e-15, "xi[0] (eps 1)");
        close(o.xi[1], 0.1 * 0.8 / 1.8, 1e-15, "xi[1] (eps 1)");
        // Below the clip norm nothing changes: g = [0.3, -0.4], norm 0.5.
        let mut a =
            LogDomainOptimizer::new(vec![1.0, 1.0], bounds.clone(), big_eps, Some(1.0)).unwrap();
        let mut b = LogDomainOptimizer::new(vec![1.0, 1.0], bounds, big_eps, None).unwrap();
        close(a.step(&[0.3, -0.4]), 0.5, 1e-15, "norm below clip");
        b.step(&[0.3, -0.4]);
        assert_eq!(a.xi, b.xi);
        assert_eq!(a.m, b.m);
    }
}
