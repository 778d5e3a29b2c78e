//! The automatic strategy (`strategy = "auto"` in `FIT.toml`, the default): which stages
//! run, with which settings and budget, decided from the fit's own problem — the free
//! parameters, the parts' materials and the budget — never from the true parameters, which
//! a fit does not know.
//!
//! [`resolve`] turns a config into the one that runs, with a reason per decision
//! ([`Decision`]); `r4d fit` prints them and writes them into `summary.json`. With
//! `strategy = "fixed"` the config runs as written. Under `auto`, a setting of
//! [`AUTO_KEYS`](super::config::AUTO_KEYS) written in `FIT.toml` is kept as written
//! (`pinned`), and a stage list (`stages = [...]`) is kept: the strategy then decides the
//! settings of the stages it lists.
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
    /// Decided from the problem ([`resolve`]), but for the settings `pinned`.
    #[default]
    Auto,
    /// As the config says.
    Fixed,
}

impl Strategy {
    /// Whether this is [`Strategy::Fixed`].
    pub fn is_fixed(&self) -> bool {
        *self == Strategy::Fixed
    }

    /// Whether this is [`Strategy::Auto`] (the default; kept out of the config's
    /// fingerprint).
    pub fn is_auto(&self) -> bool {
        *self == Strategy::Auto
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

/// A setting's value as `FIT.toml` writes it.
fn word<T: Serialize>(v: &T) -> String {
    match serde_json::to_value(v) {
        Ok(serde_json::Value::String(s)) => s,
        Ok(v) => v.to_string(),
        Err(_) => "?".into(),
    }
}

/// Collects decisions; a pinned setting keeps the config's value and says so.
struct Decide<'a> {
    cfg: &'a FitConfig,
    out: Vec<Decision>,
}

impl Decide<'_> {
    /// Records `setting = value` (applied by `apply`) unless it is pinned; then `shown`
    /// (the written value) is recorded instead and `apply` is not called.
    fn set(
        &mut self,
        c: &mut FitConfig,
        setting: &str,
        value: String,
        why: String,
        apply: impl FnOnce(&mut FitConfig),
        shown: impl FnOnce(&FitConfig) -> String,
    ) {
        if self.cfg.is_pinned(setting) {
            self.out.push(Decision {
                setting: setting.into(),
                value: shown(self.cfg),
                why: "as written (pinned)".into(),
            });
        } else {
            apply(c);
            self.out.push(Decision {
                setting: setting.into(),
                value,
                why,
            });
        }
    }
}

/// The config that runs for the parts `parts` (the fit's starting parameters): `cfg` itself
/// for `strategy = "fixed"`, else the automatic strategy's (see the module docs). A setting
/// named in `pinned` keeps its value; a stage list (`stages`) is kept, and the strategy then
/// decides the settings of the stages it lists.
pub fn resolve(cfg: &FitConfig, parts: &[PartParams]) -> Result<Resolved, FitError> {
    if cfg.strategy.is_fixed() {
        return Ok(Resolved {
            config: cfg.clone(),
            decisions: Vec::new(),
        });
    }
    let free = cfg.free_kinds(parts)?;
    let slots: Vec<u32> = (0..parts.len() as u32).collect();
    let space = ParamSpace::new(cfg.granularity, &free, &slots, |p, k| {
        cfg.bounds(parts, p, k)
    });
    let n = space.len();
    let mut c = cfg.clone();
    let mut d = Decide {
        cfg,
        out: Vec::new(),
    };
    let listed = |k: StageKind| cfg.stages.as_ref().is_none_or(|s| s.contains(&k));
    let budget = cfg.budget.is_some() || cfg.evals.is_some();
    let per_slot = cfg.granularity != crate::video::Granularity::Particle;
    if listed(StageKind::Init) {
        d.set(
            &mut c,
            "init.enabled",
            "true".into(),
            "the default bounds span decades per parameter: the start is searched for".into(),
            |c| c.init.enabled = true,
            |c| c.init.enabled.to_string(),
        );
    }
    let init = listed(StageKind::Init) && c.init.enabled;
    if init {
        // The initialisation always completes: under an evaluation budget it gets at most
        // half of it, the rest going to the descent.
        let share = cfg.evals.map(|e| (e / 2).max(1));
        let mut cand = (8 * n).clamp(24, 64);
        let mut rounds = 3;
        let mut why = format!("{n} free parameter(s): 8 candidates each (24 to 64) per round");
        if let Some(s) = share.filter(|&s| s < 3 * cand) {
            rounds = if s >= 3 * 8 { 3 } else { 1 };
            cand = (s / rounds).max(1);
            why = format!(
                "{n} free parameter(s): 8 candidates each (24 to 64) per round, cut to half the \
                 budget of {} simulations ({s})",
                cfg.evals.unwrap_or(0)
            );
        }
        d.set(
            &mut c,
            "init.candidates",
            cand.to_string(),
            why,
            |c| c.init.candidates = cand,
            |c| c.init.candidates.to_string(),
        );
        d.set(
            &mut c,
            "init.rounds",
            rounds.to_string(),
            if rounds > 1 {
                "the second and third rounds sample the box of the best so far".into()
            } else {
                "a budget too small for three rounds of 8".into()
            },
            move |c| c.init.rounds = rounds,
            |c| c.init.rounds.to_string(),
        );
        d.set(
            &mut c,
            "init.sampler",
            "natural".into(),
            "nu and the friction angle uniformly, the rest log-uniformly".into(),
            |c| c.init.sampler = super::config::InitSampler::Natural,
            |c| word(&c.init.sampler),
        );
        d.set(
            &mut c,
            "init.score",
            "loss".into(),
            "candidates ranked by the fit's own loss: MS-SSIM scores most of them within a \
             few percent of 1"
                .into(),
            |c| c.init.score = super::config::InitScore::Loss,
            |c| word(&c.init.score),
        );
    }
    let seeded = init && per_slot;
    let multi = seeded
        && listed(StageKind::MultiStart)
        && (n >= 2
            || cfg
                .stages
                .as_ref()
                .is_some_and(|s| s.contains(&StageKind::MultiStart)));
    let (ms, ms_why) = if multi {
        (
            4,
            "the best candidates may lie in other basins: short fits (8 iterations) from 4"
                .to_string(),
        )
    } else {
        (
            1,
            if !seeded {
                "no initialisation (or a per-particle fit) to start from".into()
            } else if n < 2 {
                "one parameter: a single start".into()
            } else {
                "not in stages".into()
            },
        )
    };
    d.set(
        &mut c,
        "multi_start",
        if ms > 1 { "4".into() } else { "1 (off)".into() },
        ms_why,
        |c| c.multi_start = ms,
        |c| c.multi_start.to_string(),
    );
    if multi {
        d.set(
            &mut c,
            "multi_start_iters",
            "8".into(),
            "each start's short fit".into(),
            |c| c.multi_start_iters = 8,
            |c| c.multi_start_iters.to_string(),
        );
    }
    if seeded {
        d.set(
            &mut c,
            "spread",
            "0.15".into(),
            "the starts and restarts are the best candidates at least 15% of a parameter's \
             log bounds apart: the best of the narrowed rounds cluster in one basin"
                .into(),
            |c| c.spread = 0.15,
            |c| c.spread.to_string(),
        );
        let stall = (3 * n).max(8);
        d.set(
            &mut c,
            "stall",
            stall.to_string(),
            format!(
                "a descent whose lowest loss has not fallen (by 0.01%) in {stall} iterations (3 \
                 per parameter, at least 8) starts again from the next start or candidate: \
                 the budget goes to other basins, not to a stalled one"
            ),
            |c| c.stall = stall,
            |c| c.stall.to_string(),
        );
    }
    d.set(
        &mut c,
        "optimizer",
        "trust_bfgs".into(),
        "curvature-aware steps follow the curved valleys where parameters trade off".into(),
        |c| c.optimizer = OptimizerKind::TrustBfgs,
        |c| word(&c.optimizer),
    );
    let iters = if budget { MAX_ITERS } else { (20 * n).max(40) };
    d.set(
        &mut c,
        "iters",
        if budget {
            "until the budget is spent".into()
        } else {
            iters.to_string()
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
        |c| c.iters = iters,
        |c| c.iters.to_string(),
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
        let probe = if cfg.flat_probe == 0 {
            6
        } else {
            cfg.flat_probe
        };
        d.set(
            &mut c,
            "flat_probe",
            probe.to_string(),
            format!(
                "{} act(s) only where particles yield: the gradient is zero off that branch",
                branch.join(", ")
            ),
            |c| c.flat_probe = probe,
            |c| c.flat_probe.to_string(),
        );
    }
    let out = d.out;
    debug_assert!(!listed(StageKind::Descent) || c.plan().contains(&StageKind::Descent));
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
        let fixed = FitConfig {
            strategy: Strategy::Fixed,
            ..Default::default()
        };
        let r = resolve(&fixed, &[part(Material::Jelly)]).unwrap();
        assert_eq!(r.config, fixed);
        assert!(r.decisions.is_empty());

        let auto = FitConfig {
            optimizer: OptimizerKind::Adam,
            ..Default::default()
        };
        assert_eq!(auto.strategy, Strategy::Auto, "the default");
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

        // An evaluation budget: the initialisation (which always completes) gets half.
        let small = |evals| {
            let c = FitConfig {
                evals: Some(evals),
                ..auto.clone()
            };
            let r = resolve(&c, &[part(Material::Jelly)]).unwrap().config;
            (r.init.rounds, r.init.candidates)
        };
        assert_eq!(small(250), (3, 24));
        assert_eq!(small(100), (3, 16));
        assert_eq!(small(36), (1, 18));
        assert_eq!(small(1), (1, 1));
    }

    /// Pinned settings keep their written values (and say so); a stage list is kept and
    /// only its stages' settings are decided; without an initialisation nothing that needs
    /// one is turned on.
    #[test]
    fn pinned_settings_and_a_stage_list_are_kept() {
        let jelly = [part(Material::Jelly)];
        let pinned = FitConfig {
            iters: 7,
            optimizer: OptimizerKind::Adam,
            ..Default::default()
        }
        .pin("iters")
        .pin("optimizer");
        let r = resolve(&pinned, &jelly).unwrap();
        assert_eq!(
            (r.config.iters, r.config.optimizer),
            (7, OptimizerKind::Adam)
        );
        assert_eq!(r.config.init.rounds, 3, "not pinned: decided");
        let iters = r.decisions.iter().find(|d| d.setting == "iters").unwrap();
        assert_eq!(
            (iters.value.as_str(), iters.why.as_str()),
            ("7", "as written (pinned)")
        );
        let opt = r
            .decisions
            .iter()
            .find(|d| d.setting == "optimizer")
            .unwrap();
        assert_eq!(opt.value, "adam");

        let no_init = FitConfig {
            init: super::super::config::InitConfig {
                enabled: false,
                ..Default::default()
            },
            ..Default::default()
        }
        .pin("init.enabled");
        let r = resolve(&no_init, &jelly).unwrap();
        assert!(!r.config.init.enabled);
        assert_eq!((r.config.multi_start, r.config.stall), (1, 0));
        assert_eq!(r.config.optimizer, OptimizerKind::TrustBfgs);

        let listed = FitConfig {
            stages: Some(vec![StageKind::Init, StageKind::Descent]),
            ..Default::default()
        };
        let r = resolve(&listed, &jelly).unwrap();
        assert_eq!(r.config.stages, listed.stages);
        assert_eq!(r.config.plan(), vec![StageKind::Init, StageKind::Descent]);
        assert_eq!(r.config.multi_start, 1, "not listed: off");
        assert_eq!(r.config.stall, 9);

        let bad = FitConfig::default().pin("lr");
        let e = bad.validate().unwrap_err().to_string();
        assert!(e.contains("pinned") && e.contains("`lr`"), "{e}");
    }
}
