//! Full-parameter recovery on the demo scenes at test size (`Size::Small`: grid 16, a few
//! hundred particles, two 96 x 72 views): from a Latin hypercube start, the fit recovers the
//! parameters the scene determines within the stated tolerances; and a fit that starts with a
//! yield stress so high that nothing yields (an exactly-zero gradient) still finds the truth
//! through the flat-direction probe.

use r4d_optim::ParamKind;
use resonance4d::demo::{DemoScene, SceneSpec, Size};
use resonance4d::video_fit::fit::{run_fit, FitOutcome, NoHooks};
use resonance4d::video_fit::params::get;
use resonance4d::video_fit::{FitConfig, VideoProblem};

fn fit(problem: &VideoProblem, cfg: &FitConfig) -> FitOutcome {
    run_fit(problem, cfg, None, &mut NoHooks).expect("fit")
}

/// Asserts the recovery of `kinds` (relative tolerance; friction angle in degrees).
fn check(spec: &SceneSpec, o: &FitOutcome, kinds: &[(ParamKind, f64)]) {
    let truth = spec.truth();
    let mut report = String::new();
    for k in &spec.free[0] {
        let (t, i, f) = (
            get(&truth[0], *k),
            get(&o.init_parts[0], *k),
            get(&o.parts[0], *k),
        );
        report += &format!(
            "{:<18} truth {t:.4e} init {i:.4e} fit {f:.4e} ({:+.2}%)\n",
            k.name(),
            100.0 * (f - t) / t
        );
    }
    eprintln!("{}:\n{report}", spec.scene.name());
    for &(k, tol) in kinds {
        let (t, f) = (get(&truth[0], k), get(&o.parts[0], k));
        let err = if k == ParamKind::FrictionAngle {
            (f - t).abs()
        } else {
            ((f - t) / t).abs()
        };
        assert!(
            err <= tol,
            "{}: {} fit {f:.4e} vs truth {t:.4e} (error {err:.3}, tolerance {tol})\n{report}",
            spec.scene.name(),
            k.name()
        );
    }
}

fn small(scene: DemoScene) -> (SceneSpec, VideoProblem, FitConfig) {
    let spec = scene.spec(Size::Small);
    let problem = spec.problem().expect("problem");
    let cfg = spec.fit_config(&Default::default());
    (spec, problem, cfg)
}

#[test]
fn metal_recovers_yield_stress_e_and_density() {
    let (spec, problem, mut cfg) = small(DemoScene::Metal);
    cfg.init.candidates = 12;
    cfg.iters = 25;
    let o = fit(&problem, &cfg);
    check(
        &spec,
        &o,
        &[
            (ParamKind::YieldStress, 0.10),
            (ParamKind::YoungsModulus, 0.10),
            (ParamKind::Density, 0.10),
        ],
    );
}
