//! The automatic strategy (`strategy = "auto"` in `FIT.toml`): which stages run, with which
//! settings and budget, decided from the fit's own problem — the free parameters, the parts'
//! materials and the budget — never from the true parameters, which a fit does not know.
//!
//! [`resolve`] turns a config into the one that runs, with a reason per decision
//! ([`Decision`]); `r4d fit` prints them and writes them into `summary.json`. With
//! `strategy = "fixed"` the config runs as written.
//!
//! What the automatic strategy decides, for `n` free parameters:
//! * **initialisation**: three rounds of `8 n` Latin hypercube candidates (24 to 64), the
//!   second and third inside the box of the best so far (`[init] rounds`), Poisson's ratio
//!   and the friction angle sampled uniformly (`sampler = "natural"`), ranked by the fit's
//!   own loss (`score = "loss"`): the default bounds span decades per parameter, the best of
//!   one round of candidates often lies in another basin, a log-uniform Poisson's ratio puts
//!   half the candidates below 0.07, and MS-SSIM scores most candidates of such a box within
//!   a few percent of 1 (measured on a random metal cantilever: the four best by MS-SSIM
//!   ended their short fits at losses 0.19-0.45 and the fit stalled at 60x the truth's loss;
//!   ranked by the loss, it reached the truth's);
//! * **multi-start**: with two or more parameters, short fits (8 iterations) from the 4 best
//!   candidates, the fit continuing from the lowest: a candidate's loss is not the loss its
//!   basin reaches;
//! * **spread seeds**: the multi-start's starts and the restarts' seeds are the best
//!   candidates at least 15% of a parameter's log bounds apart (`spread = 0.15`): the later
//!   rounds narrow around the best so far, so the best candidates cluster in one basin;
//! * **restarts on a stall**: a descent whose lowest loss has not fallen (by 0.01%) in `3 n`
//!   iterations (at least 8) starts again from the next start of the multi-start, then from
//!   the next candidates (`stall`): measured on random metal cantilevers, a stalled descent
//!   cycles through rejected trials and model restarts for the rest of the budget;
//! * **step**: the trust-region BFGS step (curvature-aware), whatever `optimizer` says:
//!   the loss's valleys along which two parameters trade off (`E` with density, `E` with
//!   `nu`) are curved and narrow, and AdamW creeps along them;
//! * **iterations**: with a budget (`budget`, `evals`) they run until it is spent;
//!   without one, `20 n` (at least 40);
//! * **flat probes**: on (6 values) when a parameter acts only on a branch of the return
//!   mapping (yield stress, plastic viscosity, friction angle, hardening, softening): its
//!   gradient is exactly zero where no particle is on that branch.
//!
//! The refining stages (valley search, shear restarts, gradient sampling) stay as the
//! config sets them.

use super::config::{FitConfig, OptimizerKind, StageKind, MAX_ITERS};
use crate::space::ParamSpace;
use crate::{FitError, ParamKind};
use r4d_mpm::PartParams;
use serde::{Deserialize, Serialize};

/// How the stages and their settings are chosen.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Strategy {
    /// As the config says.
    #[default]
    Fixed,
    /// Decided from the problem ([`resolve`]).
    Auto,
}

impl Strategy {
    /// Whether this is [`Strategy::Fixed`] (kept out of the config's fingerprint).
    pub fn is_fixed(&self) -> bool {
        *self == Strategy::Fixed
    }
}

/// One decision of the automatic strategy.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Decision {
    /// The setting (`init.candidates`, `optimizer`, ...).
    pub setting: String,
    /// Its value.
    pub value: String,
    /// Why.
    pub why: String,
}

/// The config that runs and the decisions that made it.
#[derive(Clone, Debug, PartialEq)]
pub struct Resolved {
    /// The config the stages run with.
    pub config: FitConfig,
    /// The automatic strategy's decisions (empty for `strategy = "fixed"`).
    pub decisions: Vec<Decision>,
}

/// Kinds that act only on a branch of the return mapping (zero gradient off it).
fn is_branch(k: ParamKind) -> bool {
    !matches!(
        k,
        ParamKind::YoungsModulus | ParamKind::PoissonRatio | ParamKind::Density
    )
}

/// The config that runs for the parts `parts` (the fit's starting parameters): `cfg` itself
/// for `strategy = "fixed"`, else the automatic strategy's (see the module docs). A stage
/// list together with `strategy = "auto"` is refused: the one decides what the other lists.
pub fn resolve(cfg: &FitConfig, parts: &[PartParams]) -> Result<Resolved, FitError> {
    if cfg.strategy.is_fixed() {
        return Ok(Resolved {
            config: cfg.clone(),
            decisions: Vec::new(),
        });
    }
    if cfg.stages.is_some() {
        return Err(FitError::Input(
            "stages = [...] with strategy = \"auto\": the automatic strategy decides the stages; \
             remove `stages` or set strategy = \"fixed\""
                .into(),
        ));
    }
    let free = cfg.free_kinds(parts)?;
    let slots: Vec<u32> = (0..parts.len() as u32).collect();
    let space = ParamSpace::new(cfg.granularity, &free, &slots, |p, k| {
        cfg.bounds(parts, p, k)
    });
    let n = space.len();
    let mut c = cfg.clone();
    let mut out = Vec::new();
    let mut say = |setting: &str, value: String, why: String| {
        out.push(Decision {
            setting: setting.into(),
            value,
            why,
        })
    };
    let budget = cfg.budget.is_some() || cfg.evals.is_some();
    let per_slot = cfg.granularity != crate::video::Granularity::Particle;
    c.init.enabled = true;
    c.init.candidates = (8 * n).clamp(24, 64);
    c.init.rounds = 3;
    c.init.sampler = super::config::InitSampler::Natural;
    c.init.score = super::config::InitScore::Loss;
    say(
        "init",
        format!("3 rounds x {} candidates", c.init.candidates),
        format!(
            "{n} free parameter(s): 8 candidates each (24 to 64) per round; the second and \
             third rounds sample the box of the best so far; nu and the friction angle \
             uniformly, the rest log-uniformly; candidates ranked by the fit's loss"
        ),
    );
    if n >= 2 && per_slot {
        c.multi_start = 4;
        c.multi_start_iters = 8;
        say(
            "multi_start",
            "4 x 8 iterations".into(),
            "two or more parameters: the best candidates may lie in other basins".into(),
        );
    } else {
        c.multi_start = 1;
        say(
            "multi_start",
            "off".into(),
            if per_slot {
                "one parameter: a single start".into()
            } else {
                "per-particle fits start from the initialisation's best".into()
            },
        );
    }
    if per_slot {
        c.spread = 0.15;
        say(
            "spread",
            "0.15".into(),
            "the starts and restarts are the best candidates at least 15% of a parameter's log \
             bounds apart: the best of the narrowed rounds cluster in one basin"
                .into(),
        );
        c.stall = (3 * n).max(8);
        say(
            "stall",
            c.stall.to_string(),
            format!(
                "a descent whose lowest loss has not fallen (by 0.01%) in {} iterations (3 per \
                 parameter, at least 8) starts again from the next start or candidate: the \
                 budget goes to other basins, not to a stalled one",
                c.stall
            ),
        );
    }
    c.optimizer = OptimizerKind::TrustBfgs;
    say(
        "optimizer",
        "trust_bfgs".into(),
        "curvature-aware steps follow the curved valleys where parameters trade off".into(),
    );
    c.iters = if budget { MAX_ITERS } else { (20 * n).max(40) };
    say(
        "iters",
        if budget {
            "until the budget is spent".into()
        } else {
            c.iters.to_string()
        },
        if budget {
            format!(
                "the budget ({}) ends the fit",
                match (&cfg.budget, cfg.evals) {
                    (Some(b), Some(e)) => format!("{b} or {e} simulations"),
                    (Some(b), None) => b.clone(),
                    (None, Some(e)) => format!("{e} simulations"),
                    (None, None) => unreachable!("a budget is set"),
                }
            )
        } else {
            "no budget: 20 iterations per parameter (at least 40)".into()
        },
    );
    let branch: Vec<String> = space
        .entries
        .iter()
        .filter(|e| is_branch(e.kind))
        .map(|e| e.kind.name().to_string())
        .collect::<std::collections::BTreeSet<_>>()
        .into_iter()
        .collect();
    if !branch.is_empty() {
        if c.flat_probe == 0 {
            c.flat_probe = 6;
        }
        say(
            "flat_probe",
            c.flat_probe.to_string(),
            format!(
                "{} act(s) only where particles yield: the gradient is zero off that branch",
                branch.join(", ")
            ),
        );
    }
    c.stages = None;
    debug_assert!(c.plan().contains(&StageKind::Descent));
    c.validate()?;
    Ok(Resolved {
        config: c,
        decisions: out,
    })
}

/// The decisions as lines (`setting = value: why`).
pub fn describe(decisions: &[Decision]) -> String {
    decisions
        .iter()
        .map(|d| format!("  {} = {}: {}", d.setting, d.value, d.why))
        .collect::<Vec<_>>()
        .join("\n")
}

#[cfg(test)]
mod tests {
    use super::*;
    use r4d_mpm::Material;

    fn part(material: Material) -> PartParams {
        PartParams {
            material,
            ..Default::default()
        }
    }

    /// A fixed config runs as written; the automatic one scales the initialisation with the
    /// free parameters, turns the multi-start and the trust-region step on, runs until the
    /// budget when there is one, and names the branch parameters it probes.
    #[test]
    fn auto_decides_from_the_free_parameters_and_the_budget() {
        let fixed = FitConfig::default();
        let r = resolve(&fixed, &[part(Material::Jelly)]).unwrap();
        assert_eq!(r.config, fixed);
        assert!(r.decisions.is_empty());

        let auto = FitConfig {
            strategy: Strategy::Auto,
            optimizer: OptimizerKind::Adam,
            ..Default::default()
        };
        let r = resolve(&auto, &[part(Material::Jelly)]).unwrap();
        assert_eq!((r.config.init.candidates, r.config.init.rounds), (24, 3));
        assert_eq!(r.config.init.score, super::super::config::InitScore::Loss);
        assert_eq!((r.config.multi_start, r.config.multi_start_iters), (4, 8));
        assert_eq!(r.config.stall, 9);
        assert_eq!(r.config.spread, 0.15);
        assert_eq!(r.config.optimizer, OptimizerKind::TrustBfgs);
        assert_eq!(r.config.iters, 60);
        assert!(!r.decisions.iter().any(|d| d.setting == "flat_probe"));

        let budgeted = FitConfig {
            budget: Some("4m".into()),
            ..auto.clone()
        };
        let r = resolve(&budgeted, &[part(Material::Foam), part(Material::Jelly)]).unwrap();
        // Foam: E, nu, yield stress, plastic viscosity, density; jelly: E, nu, density.
        assert_eq!(r.config.init.candidates, 64);
        assert_eq!(r.config.iters, MAX_ITERS);
        let probe = r
            .decisions
            .iter()
            .find(|d| d.setting == "flat_probe")
            .unwrap();
        assert!(
            probe.why.contains("yield_stress") && probe.why.contains("plastic_viscosity"),
            "{probe:?}"
        );
        assert!(describe(&r.decisions).contains("until the budget is spent"));

        let listed = FitConfig {
            stages: Some(vec![StageKind::Init, StageKind::Descent]),
            ..auto
        };
        let e = resolve(&listed, &[part(Material::Jelly)]).unwrap_err();
        assert!(e.to_string().contains("stages"), "{e}");
        assert!(listed.validate().is_err());
    }
}
