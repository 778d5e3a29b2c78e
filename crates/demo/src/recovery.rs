//! The recovery benchmark (`r4d bench-recovery`): random scenes of every material class
//! ([`crate::random`]), each fitted with the default settings under a fixed budget, scored on
//! the parameters the identifiability profile calls determined.
//!
//! For one scene ([`run_scene`]): the reference videos are rendered from the truth; the loss
//! profiles around the truth (1-D at +-5% and +-15%, 2-D at +-10% for every pair of free
//! parameters of a part, and along the stress-density scale at +-10%, [`crate::profiles`])
//! give the verdicts; the fit runs with
//! [`FitConfig::default`] (or the settings given, [`BenchSettings::fit`]; the default free
//! parameters and bounds of the material) and the budget; a determined parameter is *recovered* when it ends within [`TOLERANCE`] of the
//! truth (the friction angle: [`FRICTION_TOLERANCE_DEG`] degrees). A scene whose fit fails
//! is kept, with why. [`table`] aggregates per class: the recovered fraction, the
//! distribution of the errors, the wall times and the failures.

use crate::random::{self, Class, Load};
use crate::{profiles, FitHooks, Size};
use r4d_optim::space::get;
use r4d_optim::video::fit::run_fit;
use r4d_optim::video::{FitConfig, Strategy};
use r4d_optim::{Compute, FitError, ParamKind};
use serde::{Deserialize, Serialize};
use std::sync::Arc;
use std::time::Instant;

/// A determined parameter is recovered within this relative error.
pub const TOLERANCE: f64 = 0.10;

/// A determined friction angle is recovered within this many degrees.
pub const FRICTION_TOLERANCE_DEG: f64 = 5.0;

/// How every scene of a benchmark run is built and fitted (what a resumed run must match).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct BenchSettings {
    /// Scene size (`full`: up to ~2,000 particles, views up to 160x120; `small`: the CI's).
    pub size: Size,
    /// The fit's wall-clock budget (`"4m"`), or none.
    pub budget: Option<String>,
    /// The fit's evaluation budget, or none.
    pub evals: Option<usize>,
    /// The fit's settings (`None`: [`FitConfig::default`]); its free parameters and bounds
    /// are the materials' defaults, and the budget is the one above.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fit: Option<FitConfig>,
    /// The strategy of the settings that run (`fit`'s, else the default's): a run folder
    /// made while the default was another is not continued with this one. Folders that do
    /// not record it were made with the fixed defaults.
    #[serde(default = "fixed")]
    pub strategy: Strategy,
}

/// What a `bench.json` without `strategy` was made with.
fn fixed() -> Strategy {
    Strategy::Fixed
}

/// One free parameter's recovery.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ParamResult {
    /// `part0.E`, ...
    pub name: String,
    /// The kind (`E`, `nu`, ...).
    pub kind: String,
    /// True value.
    pub truth: f64,
    /// After the initialisation.
    pub init: f64,
    /// After the fit.
    pub fit: f64,
    /// `|fit - truth| / truth`; the friction angle: `|fit - truth|` in degrees.
    pub error: f64,
    /// The profile's verdict: the video determines it.
    pub determined: bool,
    /// Relative sensitivity of the profile (see [`crate::profiles`]).
    pub relative_sensitivity: f64,
    /// Within the tolerance.
    pub recovered: bool,
}

/// One scene's result (`scenes/<class>-<seed>.json` of a benchmark run).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SceneResult {
    /// The class.
    pub class: Class,
    /// The seed.
    pub seed: u64,
    /// The load.
    pub load: Load,
    /// One line on the scene.
    pub description: String,
    /// Simulated particles.
    pub particles: usize,
    /// Views.
    pub views: usize,
    /// The stages the fit ran, as `r4d fit` prints them.
    pub plan: String,
    /// Per free parameter.
    pub params: Vec<ParamResult>,
    /// Loss at the truth over the whole video.
    pub loss_truth: Option<f64>,
    /// The fit's lowest loss.
    pub loss_fit: Option<f64>,
    /// Simulations the fit ran.
    pub evals: usize,
    /// The fit ended because its budget was spent.
    pub budget_spent: bool,
    /// Wall time of the fit (s).
    pub fit_time_s: f64,
    /// Wall time of the profiles (s).
    pub profile_time_s: f64,
    /// Wall time of the scene (s).
    pub wall_time_s: f64,
    /// Why the scene failed (no fit result), when it did.
    pub failed: Option<String>,
}

impl SceneResult {
    /// Determined parameters.
    pub fn determined(&self) -> usize {
        self.params.iter().filter(|p| p.determined).count()
    }

    /// Determined parameters recovered.
    pub fn recovered(&self) -> usize {
        self.params
            .iter()
            .filter(|p| p.determined && p.recovered)
            .count()
    }

    /// The file name of the result (`jelly-3.json`).
    pub fn file_name(class: Class, seed: u64) -> String {
        format!("{}-{seed}.json", class.name())
    }
}

/// Draws, profiles and fits the scene of `class` and `seed` (references simulated and
/// rendered on `reference`, the profiles and the fit on `fit`). A fit that fails on the
/// scene's parameters (a diverging simulation) is a failed scene with why; an error of the
/// backend or of the settings is returned.
pub fn run_scene(
    class: Class,
    seed: u64,
    settings: &BenchSettings,
    hooks: &mut dyn FitHooks,
    reference: Arc<dyn Compute>,
    fit: Arc<dyn Compute>,
) -> Result<SceneResult, FitError> {
    let t0 = Instant::now();
    let rs = random::scene(class, seed, settings.size);
    let spec = &rs.spec;
    let mut cfg = settings.fit.clone().unwrap_or_else(|| spec.fit.clone());
    cfg.init.frames = cfg.init.frames.min(spec.config.time.frames);
    cfg.budget = settings.budget.clone();
    cfg.evals = settings.evals;
    cfg.validate()?;
    let truth = spec.truth();
    let mut result = SceneResult {
        class,
        seed,
        load: rs.load,
        description: spec.description.clone(),
        particles: spec.particles.x.len(),
        views: spec.cameras.len(),
        plan: r4d_optim::video::strategy::resolve(&cfg, &spec.config.parts)?
            .config
            .describe_plan(),
        params: Vec::new(),
        loss_truth: None,
        loss_fit: None,
        evals: 0,
        budget_spent: false,
        fit_time_s: 0.0,
        profile_time_s: 0.0,
        wall_time_s: 0.0,
        failed: None,
    };
    let fail = |mut r: SceneResult, why: String| {
        r.failed = Some(why);
        r.wall_time_s = t0.elapsed().as_secs_f64();
        Ok(r)
    };
    let mut problem = match spec.problem(reference) {
        Ok(p) => p,
        Err(e) if e.is_divergence() => return fail(result, format!("the truth's video: {e}")),
        Err(e) => return Err(e),
    };
    problem.compute = fit;
    let t1 = Instant::now();
    let profiled =
        profiles::profiles(&problem, &cfg, &truth, &spec.profile_offsets).and_then(|p1| {
            let p2 = profiles::profiles_2d(
                &problem,
                &cfg,
                &truth,
                &spec.pairs,
                &spec.profile2d_offsets,
            )?;
            let scale = profiles::scale_profile(&problem, &cfg, &truth, &spec.profile2d_offsets)?;
            Ok((p1, p2, scale))
        });
    let (mut p1, p2, scale) = match profiled {
        Ok(p) => p,
        Err(e) if e.is_divergence() => return fail(result, format!("the profiles: {e}")),
        Err(e) => return Err(e),
    };
    let mut verdicts = profiles::verdicts(&mut p1, &p2);
    if let Some(s) = &scale {
        profiles::apply_scale(&mut verdicts, &mut p1, s);
    }
    result.profile_time_s = t1.elapsed().as_secs_f64();
    result.loss_truth = p1.first().and_then(|p| {
        p.factors
            .iter()
            .position(|&f| f == 1.0)
            .map(|i| p.losses[i])
    });
    let t2 = Instant::now();
    let outcome = match run_fit(&problem, &cfg, None, hooks) {
        Ok(o) => o,
        Err(e) if e.is_divergence() => return fail(result, format!("the fit: {e}")),
        Err(e) => return Err(e),
    };
    result.fit_time_s = t2.elapsed().as_secs_f64();
    result.loss_fit = outcome.best_loss;
    result.budget_spent = outcome.budget_spent;
    result.evals = outcome.evaluations;
    for (i, t) in truth.iter().enumerate() {
        for &k in &spec.free[i] {
            let name = format!("part{i}.{}", k.name());
            let (tv, fv) = (get(t, k), get(&outcome.parts[i], k));
            let (error, tol) = if k == ParamKind::FrictionAngle {
                ((fv - tv).abs(), FRICTION_TOLERANCE_DEG)
            } else {
                (((fv - tv) / tv).abs(), TOLERANCE)
            };
            let v = verdicts.iter().find(|v| v.name == name);
            result.params.push(ParamResult {
                name,
                kind: k.name().into(),
                truth: tv,
                init: get(&outcome.init_parts[i], k),
                fit: fv,
                error,
                determined: v.is_some_and(|v| v.identifiable),
                relative_sensitivity: v.map_or(0.0, |v| v.relative_sensitivity),
                recovered: error <= tol,
            });
        }
    }
    result.wall_time_s = t0.elapsed().as_secs_f64();
    Ok(result)
}

/// One class's row of the benchmark's table.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ClassRow {
    /// The class.
    pub class: Class,
    /// Scenes with a result (failed ones included).
    pub scenes: usize,
    /// Scenes whose fit failed.
    pub failed: usize,
    /// Determined parameters over the scenes that did not fail.
    pub determined: usize,
    /// Of those, recovered.
    pub recovered: usize,
    /// `recovered / determined` (`None` without determined parameters).
    pub rate: Option<f64>,
    /// Quartiles (25%, 50%, 75%) and the largest of the determined parameters' errors
    /// (relative; the friction angle's in degrees / 50, so 5 degrees counts as 10%).
    pub error_quartiles: Option<[f64; 4]>,
    /// Per scene: recovered of determined (`"3/4"`), in seed order.
    pub per_scene: Vec<String>,
    /// Median and largest wall time of a scene's fit (s).
    pub fit_time_s: Option<[f64; 2]>,
    /// The failed scenes with why.
    pub failures: Vec<String>,
}

/// The error on the common scale of the table: relative, the friction angle's degrees
/// scaled so that its tolerance matches [`TOLERANCE`].
fn scaled_error(p: &ParamResult) -> f64 {
    if p.kind == ParamKind::FrictionAngle.name() {
        p.error * TOLERANCE / FRICTION_TOLERANCE_DEG
    } else {
        p.error
    }
}

/// The value at fraction `q` of sorted `v` (nearest rank).
fn quantile(v: &[f64], q: f64) -> f64 {
    let i = ((v.len() as f64 - 1.0) * q).round() as usize;
    v[i.min(v.len() - 1)]
}

/// The table of `results`, one row per class present, in [`Class::ALL`]'s order.
pub fn table(results: &[SceneResult]) -> Vec<ClassRow> {
    Class::ALL
        .into_iter()
        .filter_map(|class| {
            let mut rs: Vec<&SceneResult> = results.iter().filter(|r| r.class == class).collect();
            if rs.is_empty() {
                return None;
            }
            rs.sort_by_key(|r| r.seed);
            let ok: Vec<&&SceneResult> = rs.iter().filter(|r| r.failed.is_none()).collect();
            let determined: usize = ok.iter().map(|r| r.determined()).sum();
            let recovered: usize = ok.iter().map(|r| r.recovered()).sum();
            let mut errs: Vec<f64> = ok
                .iter()
                .flat_map(|r| r.params.iter().filter(|p| p.determined).map(scaled_error))
                .collect();
            errs.sort_by(f64::total_cmp);
            let mut times: Vec<f64> = ok.iter().map(|r| r.fit_time_s).collect();
            times.sort_by(f64::total_cmp);
            Some(ClassRow {
                class,
                scenes: rs.len(),
                failed: rs.len() - ok.len(),
                determined,
                recovered,
                rate: (determined > 0).then(|| recovered as f64 / determined as f64),
                error_quartiles: (!errs.is_empty()).then(|| {
                    [
                        quantile(&errs, 0.25),
                        quantile(&errs, 0.5),
                        quantile(&errs, 0.75),
                        errs[errs.len() - 1],
                    ]
                }),
                per_scene: rs
                    .iter()
                    .map(|r| match r.failed {
                        Some(_) => "failed".to_string(),
                        None => format!("{}/{}", r.recovered(), r.determined()),
                    })
                    .collect(),
                fit_time_s: (!times.is_empty())
                    .then(|| [quantile(&times, 0.5), times[times.len() - 1]]),
                failures: rs
                    .iter()
                    .filter_map(|r| {
                        r.failed
                            .as_ref()
                            .map(|w| format!("{}-{}: {w}", class.name(), r.seed))
                    })
                    .collect(),
            })
        })
        .collect()
}

/// The table as Markdown (BENCHMARKS.md's form).
pub fn markdown(rows: &[ClassRow]) -> String {
    let mut s = String::from(
        "| class | scenes | failed | determined | recovered | rate | error 25/50/75% | worst | fit time median/max (s) | per scene |\n\
         |---|---|---|---|---|---|---|---|---|---|\n",
    );
    let pct = |v: f64| format!("{:.1}%", 100.0 * v);
    for r in rows {
        let (q, worst) = match r.error_quartiles {
            Some(q) => (
                format!("{} / {} / {}", pct(q[0]), pct(q[1]), pct(q[2])),
                pct(q[3]),
            ),
            None => ("-".into(), "-".into()),
        };
        s += &format!(
            "| {} | {} | {} | {} | {} | {} | {} | {} | {} | {} |\n",
            r.class.name(),
            r.scenes,
            r.failed,
            r.determined,
            r.recovered,
            r.rate.map_or("-".into(), pct),
            q,
            worst,
            r.fit_time_s
                .map_or("-".into(), |t| format!("{:.0} / {:.0}", t[0], t[1])),
            r.per_scene.join(" "),
        );
    }
    for r in rows {
        for f in &r.failures {
            s += &format!("\nfailed: {f}");
        }
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    fn param(kind: &str, error: f64, determined: bool) -> ParamResult {
        ParamResult {
            name: format!("part0.{kind}"),
            kind: kind.into(),
            truth: 1.0,
            init: 1.0,
            fit: 1.0,
            error,
            determined,
            relative_sensitivity: 1.0,
            recovered: error <= if kind == "friction_angle" { 5.0 } else { 0.1 },
        }
    }

    fn scene(class: Class, seed: u64, params: Vec<ParamResult>, failed: bool) -> SceneResult {
        SceneResult {
            class,
            seed,
            load: Load::Drop,
            description: String::new(),
            particles: 1,
            views: 1,
            plan: String::new(),
            params,
            loss_truth: None,
            loss_fit: None,
            evals: 0,
            budget_spent: false,
            fit_time_s: seed as f64,
            profile_time_s: 0.0,
            wall_time_s: 0.0,
            failed: failed.then(|| "exploded".into()),
        }
    }

    /// The table counts only determined parameters of scenes that did not fail, scales the
    /// friction angle's degrees onto the relative scale and lists the failures.
    #[test]
    fn the_table_counts_determined_parameters_only() {
        let rs = vec![
            scene(
                Class::Sand,
                1,
                vec![
                    param("E", 0.5, false),
                    param("friction_angle", 2.5, true),
                    param("density", 0.2, true),
                ],
                false,
            ),
            scene(Class::Sand, 0, vec![param("density", 0.01, true)], false),
            scene(Class::Sand, 2, vec![param("density", 0.01, true)], true),
        ];
        let t = table(&rs);
        assert_eq!(t.len(), 1);
        let r = &t[0];
        assert_eq!(
            (r.scenes, r.failed, r.determined, r.recovered),
            (3, 1, 3, 2)
        );
        assert_eq!(r.per_scene, vec!["1/1", "1/2", "failed"]);
        let q = r.error_quartiles.unwrap();
        assert!((q[1] - 0.05).abs() < 1e-12, "{q:?}");
        assert!((q[3] - 0.2).abs() < 1e-12, "{q:?}");
        assert_eq!(r.failures, vec!["sand-2: exploded"]);
        let md = markdown(&t);
        assert!(md.contains("| sand | 3 | 1 | 3 | 2 | 66.7% |"), "{md}");
    }
}
