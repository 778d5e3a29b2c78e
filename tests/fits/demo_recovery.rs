//! Full-parameter recovery on the demo scenes at test size (`Size::Small`: grid 16, a few
//! hundred particles, two 96 x 72 views): from a Latin hypercube start, the fit recovers the
//! parameters the scene determines within the stated tolerances; and a fit that starts with a
//! yield stress so high that nothing yields (an exactly-zero gradient) still finds the truth
//! through the flat-direction probe, which it cannot without it.

use r4d_optim::ParamKind;
use resonance4d::demo::{DemoScene, SceneSpec, Size};
use resonance4d::video_fit::fit::{run_fit, FitEvent, FitHooks, FitOutcome, IterRecord, NoHooks};
use resonance4d::video_fit::params::get;
use resonance4d::video_fit::{FitConfig, VideoProblem};

/// The recovery table of a fit, one line per free parameter.
fn report(spec: &SceneSpec, o: &FitOutcome) -> String {
    let truth = spec.truth();
    let mut s = String::new();
    for k in &spec.free[0] {
        let (t, i, f) = (
            get(&truth[0], *k),
            get(&o.init_parts[0], *k),
            get(&o.parts[0], *k),
        );
        s += &format!(
            "{:<18} truth {t:.4e} init {i:.4e} fit {f:.4e} ({:+.2}%)\n",
            k.name(),
            100.0 * (f - t) / t
        );
    }
    s
}

/// Asserts the recovery of `kinds` (relative tolerance; friction angle in degrees).
fn check(spec: &SceneSpec, o: &FitOutcome, kinds: &[(ParamKind, f64)]) {
    let truth = spec.truth();
    let table = report(spec, o);
    eprintln!("{}:\n{table}", spec.scene.name());
    for &(k, tol) in kinds {
        let (t, f) = (get(&truth[0], k), get(&o.parts[0], k));
        let err = if k == ParamKind::FrictionAngle {
            (f - t).abs()
        } else {
            ((f - t) / t).abs()
        };
        assert!(
            err <= tol,
            "{}: {} fit {f:.4e} vs truth {t:.4e} (error {err:.3}, tolerance {tol})\n{table}",
            spec.scene.name(),
            k.name()
        );
    }
}

fn small(scene: DemoScene) -> (SceneSpec, VideoProblem, FitConfig) {
    let spec = scene.spec(Size::Small);
    let problem = spec.problem(resonance4d::compute::cpu()).expect("problem");
    let mut cfg = spec.fit_config(&Default::default());
    // The metal's five free parameters (hardening among them) need the scene's 64 candidates:
    // from 24 the fit settled in a local minimum at nu -44%, hardening -44%
    // (docs/fitting-measurements.md).
    // The paste and the fluid keep their 16: from 12 the best candidate started the paste at
    // E -45%, yield stress -56%, viscosity +104%, and 16 iterations ended at -11%, -24%, +56%.
    if !matches!(
        scene,
        DemoScene::Metal | DemoScene::Paste | DemoScene::Fluid
    ) {
        cfg.init.candidates = 12;
    }
    // Iterations up to where the fit's result settles (it returns the lowest loss it evaluated;
    // the trust radius's cosine schedule spans the iterations), measured: the foam's yield
    // stress and viscosity come within their tolerances only at iteration 28 of 30; the
    // metal's largest checked error is its hardening's, -8.5% with 18 iterations (-8.0% with
    // 30); the plasticine ends where the multi-start before the iterations left it (8 and 30
    // give the same fit); the sand's friction angle is within 0.2 degree with 10 (and 30).
    cfg.iters = match scene {
        DemoScene::Foam => 30,
        DemoScene::Metal => 18,
        DemoScene::Sand => 10,
        DemoScene::Plasticine => 8,
        DemoScene::Plant => 30,
        // Measured: the paste's three parameters are within 3%, 3% and 6% from iteration 15
        // (within 0.1% at 30); the fluid's two within 3% from iteration 5.
        DemoScene::Paste => 20,
        DemoScene::Fluid => 10,
    };
    (spec, problem, cfg)
}

fn fit_small(scene: DemoScene) -> (SceneSpec, FitOutcome) {
    let (spec, problem, cfg) = small(scene);
    let o = run_fit(&problem, &cfg, None, &mut NoHooks).expect("fit");
    (spec, o)
}

#[test]
fn metal_recovers_e_yield_stress_hardening_and_density() {
    let (spec, o) = fit_small(DemoScene::Metal);
    check(
        &spec,
        &o,
        &[
            (ParamKind::YoungsModulus, 0.10),
            (ParamKind::YieldStress, 0.10),
            (ParamKind::Hardening, 0.20),
            (ParamKind::Density, 0.10),
        ],
    );
}

#[test]
fn sand_recovers_its_friction_angle() {
    // Gravity is the only load: E and density trade off (only E / density could be
    // determined, and the pile barely depends on it), so only the friction angle is checked.
    let (spec, o) = fit_small(DemoScene::Sand);
    check(&spec, &o, &[(ParamKind::FrictionAngle, 2.0)]);
}

#[test]
fn foam_recovers_yield_stress_and_plastic_viscosity() {
    let (spec, o) = fit_small(DemoScene::Foam);
    check(
        &spec,
        &o,
        &[
            (ParamKind::YieldStress, 0.10),
            (ParamKind::PlasticViscosity, 0.20),
            (ParamKind::Density, 0.10),
        ],
    );
}

#[test]
fn plasticine_recovers_yield_stress_softening_and_density() {
    let (spec, o) = fit_small(DemoScene::Plasticine);
    check(
        &spec,
        &o,
        &[
            (ParamKind::YieldStress, 0.10),
            (ParamKind::Softening, 0.20),
            (ParamKind::Density, 0.10),
        ],
    );
}

/// Records the probes of every iteration.
#[derive(Default)]
struct Probes(Vec<IterRecord>);
impl FitHooks for Probes {
    fn on_event(&mut self, e: &FitEvent<'_>) {
        if let FitEvent::Iter(r) = e {
            self.0.push((*r).clone());
        }
    }
}

#[test]
fn a_yield_stress_so_high_that_nothing_yields_is_still_recovered() {
    let (spec, mut problem, mut cfg) = small(DemoScene::Metal);
    // No initialisation; the other parameters start at the truth, the yield stress at its
    // upper bound (3x the truth), where no particle yields: its gradient is exactly zero.
    cfg.init.enabled = false;
    cfg.iters = 12;
    let hi = spec.bounds[0]["yield_stress"][1];
    problem.config.parts = spec.truth();
    problem.config.parts[0].yield_stress_pa = hi;
    // Without the probe the yield stress never moves.
    let mut off = cfg.clone();
    off.flat_probe = 0;
    off.iters = 3;
    let mut rec = Probes::default();
    let o = run_fit(&problem, &off, None, &mut rec).expect("fit");
    assert_eq!(
        rec.0[0].grad_log["part0.yield_stress"], 0.0,
        "nothing yields"
    );
    assert!(
        (o.parts[0].yield_stress_pa / hi - 1.0).abs() < 1e-9,
        "{}",
        report(&spec, &o)
    );
    // With it the fit finds the truth.
    let mut rec = Probes::default();
    let o = run_fit(&problem, &cfg, None, &mut rec).expect("fit");
    assert!(
        rec.0.iter().any(|r| !r.probes.is_empty()),
        "no flat-direction probe ran"
    );
    check(&spec, &o, &[(ParamKind::YieldStress, 0.10)]);
}

#[test]
fn paste_recovers_e_yield_stress_and_plastic_viscosity() {
    // PhysFlow's `non_newtonian` slumping under its own weight (density fixed: gravity is
    // the only load).
    let (spec, o) = fit_small(DemoScene::Paste);
    check(
        &spec,
        &o,
        &[
            (ParamKind::YoungsModulus, 0.10),
            (ParamKind::YieldStress, 0.10),
            (ParamKind::PlasticViscosity, 0.20),
        ],
    );
}

#[test]
fn fluid_recovers_its_bulk_modulus_and_viscosity() {
    // The weakly compressible fluid landing and spreading: `E` stands for the bulk modulus.
    let (spec, o) = fit_small(DemoScene::Fluid);
    check(
        &spec,
        &o,
        &[
            (ParamKind::YoungsModulus, 0.10),
            (ParamKind::PlasticViscosity, 0.20),
        ],
    );
}
