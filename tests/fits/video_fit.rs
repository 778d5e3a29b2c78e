//! The video fit: gradient of the whole pipeline (simulate -> render -> DMS)
//! against finite differences, a fit that lowers the loss and approaches the truth, resume
//! after an interruption, and a recovery from a Latin hypercube start.

use crate::common::video::{fit_config, jelly, small_problem};
use r4d_mpm::PartParams;
use resonance4d::video_fit::fit::{FitHooks, FitState, NoHooks};
use resonance4d::video_fit::{run_fit, Objective, Precision};

/// dL/dlog(theta) of E and density of both parts against central differences of the f64
/// simulation (relative step 1e-3). This checks the glue (frame indexing, time resampling,
/// the render VJP feeding the adjoint); each stage is checked in f64 to ~1e-6 in its own
/// crate. The renders here are f32 and the rasterizer has alpha and transmittance
/// thresholds, so the composed loss is smooth only to a few percent at this step (measured:
/// 0.2-4% for most entries, up to 10% for the weakest); a glue error (a frame off by one, a
/// missing factor) shows up far above the 12% allowed.
fn check_pipeline_gradient(fps_factor: f64, tol: f64) {
    let truth = [jelly(2e4, 800.0), jelly(8e3, 1500.0)];
    let mut p = small_problem(&truth, 5);
    let mut loss = fit_config(0).loss;
    loss.weights = r4d_loss::DmsWeights {
        l1: 1.0,
        spatial: 0.0,
        mag: 0.0,
        phase: 0.0,
    };
    if fps_factor != 1.0 {
        // Video frames between simulated frames: the renders are resampled in time.
        p.fps *= fps_factor;
        p.views[0].video = {
            let v = &p.views[0].video;
            r4d_loss::Video::from_frames(v.height(), v.width(), (0..4).map(|t| v.frame_f32(t)))
                .unwrap()
                .into()
        };
    }
    let start = [jelly(1.4e4, 1000.0), jelly(1.1e4, 1200.0)];
    let mut obj = Objective::new(&p, None, &loss, false).unwrap();
    if fps_factor != 1.0 {
        assert!(!obj.time_map().is_identity());
    }
    obj.precision = Precision::F64;
    let (ev, g) = obj.value_and_grad(&start).unwrap();
    assert!(ev.total > 0.0);
    let mut checked = 0;
    for part in 0..2 {
        for (name, analytic) in [
            ("E", g[part].youngs_modulus * start[part].youngs_modulus_pa),
            ("density", g[part].density * start[part].density_kg_m3),
        ] {
            let h: f64 = 1e-3;
            let at = |f: f64| {
                let mut q = start;
                match name {
                    "E" => q[part].youngs_modulus_pa *= f,
                    _ => q[part].density_kg_m3 *= f,
                }
                obj.value(&q).unwrap().total
            };
            // Mean of central differences at three steps: the f32 render noise differs
            // between steps and partly averages out.
            let fd = [1e-2, 3e-3, h]
                .iter()
                .map(|&h: &f64| (at(h.exp()) - at((-h).exp())) / (2.0 * h))
                .sum::<f64>()
                / 3.0;
            let rel = (analytic - fd).abs() / fd.abs().max(1e-12);
            eprintln!("part{part}.{name}: analytic {analytic:.6e} fd {fd:.6e} rel {rel:.2e}");
            assert!(
                rel < tol || (analytic - fd).abs() < 2e-6,
                "part{part}.{name}: analytic {analytic:e} vs finite difference {fd:e}"
            );
            if fd.abs() > 2e-5 {
                checked += 1;
            }
        }
    }
    assert!(checked >= 2, "too few non-negligible gradients checked");
}

#[test]
fn pipeline_gradient_matches_finite_differences() {
    check_pipeline_gradient(1.0, 0.12);
}

#[test]
fn pipeline_gradient_with_time_resampling() {
    // Fewer, interpolated frames: a smaller gradient against the same render noise.
    check_pipeline_gradient(0.75, 0.2);
}

/// The same problem in a world frame rotated, scaled and shifted against the simulation's
/// (scene and camera moved by the same similarity) must give the same loss and gradient:
/// checks the link's mapping of dL/dx and dL/dF back into simulation space.
#[test]
fn link_transform_leaves_loss_and_gradient_unchanged() {
    let truth = [jelly(2e4, 800.0), jelly(8e3, 1500.0)];
    let p = small_problem(&truth, 4);
    let start = [jelly(1.4e4, 1000.0), jelly(1.1e4, 1200.0)];
    let loss = fit_config(0).loss;
    let obj = Objective::new(&p, None, &loss, false).unwrap();
    let (ev, g) = obj.value_and_grad(&start).unwrap();
    let mut q = p.clone();
    let (c, s) = (0.6f64, 0.8f64);
    q.link.rotation = [[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]];
    q.link.scale = 2.5;
    q.link.centre = [0.1, -0.2, 0.05];
    q.link.shift = [0.3, 0.2, 0.1];
    let link = q.link.clone();
    for m in &mut q.scene.means {
        *m = link.to_world(m.map(|v| v as f64)).map(|v| v as f32);
    }
    for ls in &mut q.scene.log_scales {
        *ls = ls.map(|v| v - (2.5f32).ln());
    }
    // Rotation of the Gaussians: isotropic, nothing to rotate.
    let cam = &p.views[0].camera;
    let eye = link.to_world([0.55, -0.45, 0.55]);
    let target = link.to_world([0.5, 0.5, 0.42]);
    let up = {
        let a = link.to_world([0.0, 0.0, 1.0]);
        let o = link.to_world([0.0, 0.0, 0.0]);
        [a[0] - o[0], a[1] - o[1], a[2] - o[2]]
    };
    q.views[0].camera = r4d_splat::Camera::look_at(cam.width, cam.height, 45.0, eye, target, up);
    let obj2 = Objective::new(&q, None, &loss, false).unwrap();
    let (ev2, g2) = obj2.value_and_grad(&start).unwrap();
    assert!(
        (ev.total - ev2.total).abs() < 1e-3 * ev.total,
        "loss {} vs {} in the transformed frame",
        ev.total,
        ev2.total
    );
    for part in 0..2 {
        for (a, b) in [
            (g[part].youngs_modulus, g2[part].youngs_modulus),
            (g[part].density, g2[part].density),
        ] {
            assert!(
                (a - b).abs() <= 2e-2 * a.abs().max(b.abs()),
                "part {part}: gradient {a:e} vs {b:e} in the transformed frame"
            );
        }
    }
}

#[derive(Default)]
struct Collect {
    losses: Vec<f64>,
    states: Vec<FitState>,
}
impl FitHooks for Collect {
    fn on_event(&mut self, e: &resonance4d::video_fit::FitEvent<'_>) {
        if let resonance4d::video_fit::FitEvent::Iter(r) = e {
            self.losses.push(r.loss.total);
        }
    }
    fn on_checkpoint(&mut self, s: &FitState) {
        self.states.push(s.clone());
    }
}

#[test]
fn fit_lowers_the_loss_and_resume_continues_exactly() {
    let truth = [jelly(2e4, 800.0)];
    let mut p = small_problem(&truth, 5);
    p.config.parts = vec![jelly(6e4, 800.0)];
    let mut cfg = fit_config(6);
    cfg.free = Some(vec!["E".into()]);
    cfg.lr = 0.2;
    cfg.lr_schedule = resonance4d::video_fit::config::LrSchedule::Constant;
    // The loss at the truth is not 0: static patches have zero spectra on both sides, and
    // their phase entries count as disagreeing (the paper's definition).
    let floor = Objective::new(&p, None, &cfg.loss, false)
        .unwrap()
        .value(&truth)
        .unwrap()
        .total;
    let mut all = Collect::default();
    let full = run_fit(&p, &cfg, None, &mut all).unwrap();
    assert!(
        all.losses.last().unwrap() - floor < 0.5 * (all.losses[0] - floor),
        "losses {:?} (at the truth {floor})",
        all.losses
    );
    let e0 = (6e4f64 / 2e4).ln();
    let e1 = (full.parts[0].youngs_modulus_pa / 2e4).ln().abs();
    assert!(
        e1 < 0.5 * e0,
        "E {} (truth 2e4, start 6e4)",
        full.parts[0].youngs_modulus_pa
    );
    // Interrupted after 3 iterations, resumed from the JSON checkpoint.
    let ck = all.states[2].clone();
    assert_eq!(ck.iters_done, 3);
    let ck: FitState = serde_json::from_str(&serde_json::to_string(&ck).unwrap()).unwrap();
    let mut rest = Collect::default();
    let resumed = run_fit(&p, &cfg, Some(ck), &mut rest).unwrap();
    assert_eq!(rest.losses.len(), 3);
    for (a, b) in all.losses[3..].iter().zip(&rest.losses) {
        assert!((a - b).abs() <= 1e-9 * a.abs(), "loss {a} vs resumed {b}");
    }
    let (a, b) = (
        full.parts[0].youngs_modulus_pa,
        resumed.parts[0].youngs_modulus_pa,
    );
    assert!((a - b).abs() <= 1e-6 * a, "E {a} vs resumed {b}");
}

/// The valley search after the iterations (`[valley]`): it halves the loss's excess over
/// the truth's from where the iterations stopped within its budget, records its rounds, and a
/// fit killed after its first round resumes the search from the checkpoint to the same point.
#[test]
fn valley_search_lowers_the_loss_within_budget_and_resumes_exactly() {
    let truth = [jelly(2e4, 800.0)];
    let mut p = small_problem(&truth, 5);
    p.config.parts = vec![jelly(5e4, 600.0)];
    let mut cfg = fit_config(1);
    cfg.valley.evals = 40;
    let mut all = Collect::default();
    let full = run_fit(&p, &cfg, None, &mut all).unwrap();
    let v = full.valley.as_ref().expect("the valley search ran");
    assert!(v.evals <= 40, "{} evaluations", v.evals);
    assert!(!v.rounds.is_empty());
    // The loss at the truth is not 0 (static patches' phase entries, see above).
    let floor = Objective::new(&p, None, &cfg.loss, false)
        .unwrap()
        .value(&truth)
        .unwrap()
        .total;
    let after_iters = all.losses[0];
    let best = full.best_loss.unwrap();
    assert!(
        best - floor < 0.5 * (after_iters - floor),
        "valley search: {after_iters} -> {best}, at the truth {floor} ({:?})",
        v.rounds
    );
    let e0 = (5e4f64 / 600.0 / 25.0).ln().abs();
    let ratio = |q: &PartParams| q.youngs_modulus_pa / q.density_kg_m3;
    let e1 = (ratio(&full.parts[0]) / 25.0).ln().abs();
    // A loss minimiser, not a recovery guarantee: on this small scene the walk's doubling
    // step reaches a lower loss at E/density 8.9, closer to the truth than the start in log.
    assert!(
        e1 < e0,
        "E/density {} (truth 25, start 83); loss {after_iters} -> {best}, at the truth {floor}; {:?}",
        ratio(&full.parts[0]),
        v.rounds
    );
    // Its rounds are checkpointed; killed after the first, the fit resumes there.
    let ck = all
        .states
        .iter()
        .find(|s| s.valley.as_ref().is_some_and(|v| v.rounds.len() == 1))
        .expect("a checkpoint after the first round")
        .clone();
    let ck: FitState = serde_json::from_str(&serde_json::to_string(&ck).unwrap()).unwrap();
    let mut rest = Collect::default();
    let resumed = run_fit(&p, &cfg, Some(ck), &mut rest).unwrap();
    assert!(rest.losses.is_empty(), "no iteration is repeated");
    assert_eq!(resumed.best_loss, full.best_loss);
    assert_eq!(resumed.valley.unwrap().rounds, v.rounds);
    // A checkpoint of another valley budget is another fit.
    let mut other = cfg.clone();
    other.valley.evals = 41;
    let e = run_fit(&p, &other, Some(all.states[0].clone()), &mut NoHooks).unwrap_err();
    assert!(e.to_string().contains("fingerprint"), "{e}");
}

/// Gradient sampling after the iterations (`[gradient_sampling]`): its iterations never
/// raise the loss, the fit returns the lowest point, and a fit killed after its first
/// iteration resumes from the checkpoint to the same rounds; another setting is another fit.
#[test]
fn gradient_sampling_descends_records_its_rounds_and_resumes_exactly() {
    let truth = [jelly(2e4, 800.0)];
    let mut p = small_problem(&truth, 5);
    p.config.parts = vec![jelly(5e4, 600.0)];
    let mut cfg = fit_config(1);
    cfg.gradient_sampling.iters = 3;
    let mut all = Collect::default();
    let full = run_fit(&p, &cfg, None, &mut all).unwrap();
    let s = full.sampling.as_ref().expect("gradient sampling ran");
    assert_eq!(s.rounds.len(), 3, "{:?}", s.rounds);
    assert!(
        s.rounds.iter().all(|r| r.loss_after <= r.loss_before),
        "{:?}",
        s.rounds
    );
    assert!(
        s.rounds.iter().any(|r| r.step > 0.0),
        "no step accepted: {:?}",
        s.rounds
    );
    let after_iters = all.losses[0];
    let best = full.best_loss.unwrap();
    assert!(
        best < after_iters,
        "{after_iters} -> {best}: {:?}",
        s.rounds
    );
    assert_eq!(best, s.loss);
    let ck = all
        .states
        .iter()
        .find(|st| st.sampling.as_ref().is_some_and(|v| v.rounds.len() == 1))
        .expect("a checkpoint after the first iteration")
        .clone();
    let ck: FitState = serde_json::from_str(&serde_json::to_string(&ck).unwrap()).unwrap();
    let mut rest = Collect::default();
    let resumed = run_fit(&p, &cfg, Some(ck), &mut rest).unwrap();
    assert!(rest.losses.is_empty(), "no iteration is repeated");
    assert_eq!(resumed.best_loss, full.best_loss);
    assert_eq!(resumed.sampling.unwrap().rounds, s.rounds);
    let mut other = cfg.clone();
    other.gradient_sampling.radius = 0.004;
    let e = run_fit(&p, &other, Some(all.states[0].clone()), &mut NoHooks).unwrap_err();
    assert!(e.to_string().contains("fingerprint"), "{e}");
}

/// `stages` decides what runs: with the initialisation and the valley search configured but
/// unlisted, neither runs, and gradient sampling runs straight after the descent; a listed
/// stage that cannot run is refused before any simulation.
#[test]
fn the_stage_list_decides_what_runs() {
    use resonance4d::video_fit::StageKind;
    let truth = [jelly(2e4, 800.0)];
    let mut p = small_problem(&truth, 4);
    p.config.parts = vec![jelly(5e4, 600.0)];
    let mut cfg = fit_config(1);
    cfg.init.enabled = true;
    cfg.init.candidates = 2;
    cfg.valley.evals = 40;
    cfg.gradient_sampling.iters = 2;
    cfg.stages = Some(vec![StageKind::Descent, StageKind::GradientSampling]);
    let mut all = Collect::default();
    let out = run_fit(&p, &cfg, None, &mut all).unwrap();
    assert!(out.init.is_none(), "the initialisation is not listed");
    assert!(out.valley.is_none(), "the valley search is not listed");
    assert_eq!(out.sampling.expect("listed").rounds.len(), 2);
    assert_eq!(all.losses.len(), 1, "one descent iteration");
    let mut off = cfg.clone();
    off.stages = Some(vec![StageKind::Descent, StageKind::ShearRestarts]);
    let e = run_fit(&p, &off, None, &mut NoHooks).unwrap_err();
    assert!(
        e.to_string()
            .contains("'shear_restarts' is listed but cannot run"),
        "{e}"
    );
}

/// The fit's evaluation budget (`evals`): the descent stops once it is spent, the checkpoint
/// keeps what was spent, and a resumed fit with a larger budget ends where an uninterrupted
/// fit with that budget ends; an unreadable wall-clock budget is refused by its key.
#[test]
fn an_evaluation_budget_stops_the_fit_and_a_larger_one_extends_it() {
    let truth = [jelly(2e4, 800.0)];
    let mut p = small_problem(&truth, 4);
    p.config.parts = vec![jelly(5e4, 600.0)];
    let mut cfg = fit_config(10);
    cfg.evals = Some(3);
    let mut first = Collect::default();
    let out = run_fit(&p, &cfg, None, &mut first).unwrap();
    assert!(out.budget_spent, "the budget ended it");
    assert_eq!(first.losses.len(), 3, "three evaluations, three iterations");
    let last = first.states.last().expect("a checkpoint").clone();
    assert_eq!((last.iters_done, last.evals_done), (3, 3));
    cfg.evals = Some(5);
    let mut rest = Collect::default();
    let resumed = run_fit(&p, &cfg, Some(last), &mut rest).unwrap();
    assert_eq!(rest.losses.len(), 2, "the two evaluations left");
    let whole = run_fit(&p, &cfg, None, &mut NoHooks).unwrap();
    assert!(whole.budget_spent && resumed.budget_spent);
    assert_eq!(resumed.best_loss, whole.best_loss);
    assert_eq!(resumed.parts, whole.parts);
    cfg.budget = Some("soon".into());
    let e = run_fit(&p, &cfg, None, &mut NoHooks).unwrap_err();
    assert!(e.to_string().contains("budget = 'soon'"), "{e}");
    // With `descent_share`, the descent ends at that share of the budget and the valley
    // search after it spends the rest.
    cfg.budget = None;
    cfg.evals = Some(12);
    cfg.descent_share = 0.5;
    cfg.valley.evals = 1000;
    let mut shared = Collect::default();
    let out = run_fit(&p, &cfg, None, &mut shared).unwrap();
    assert_eq!(shared.losses.len(), 6, "the descent's six iterations");
    let valley = out.valley.expect("the valley search ran");
    assert!(valley.evals > 0 && valley.evals <= 6, "{}", valley.evals);
    assert_eq!(out.evaluations, 6 + valley.evals);
    cfg.descent_share = 1.5;
    let e = run_fit(&p, &cfg, None, &mut NoHooks).unwrap_err();
    assert!(e.to_string().contains("descent_share"), "{e}");
}

/// Restarts along constant bulk modulus (`[shear_restarts]`): each restart keeps the
/// starting point's bulk modulus at a shear modulus `factor^k` times its own, the sequence
/// follows the profile, the fit returns the lowest point seen, a fit killed inside a
/// restart resumes to the same restarts, and a fit without `nu` free is refused naming it.
#[test]
fn shear_restarts_keep_the_bulk_modulus_follow_the_profile_and_resume_exactly() {
    use resonance4d::video_fit::ShearRestarts;
    let truth = [jelly(2e4, 800.0)];
    let mut p = small_problem(&truth, 5);
    p.config.parts = vec![jelly(3e4, 700.0)];
    let mut cfg = fit_config(1);
    cfg.free = Some(vec!["E".into(), "nu".into(), "density".into()]);
    cfg.shear_restarts.points = 2;
    cfg.shear_restarts.inner_iters = 2;
    let mut all = Collect::default();
    let full = run_fit(&p, &cfg, None, &mut all).unwrap();
    let r: &ShearRestarts = full.restarts.as_ref().expect("the restarts ran");
    assert_eq!(r.done.len(), 2, "{:?}", r.done);
    let bulk = |e: f64, nu: f64| e / (3.0 * (1.0 - 2.0 * nu));
    let shear = |e: f64, nu: f64| e / (2.0 * (1.0 + nu));
    let (e0, nu0) = (r.origin[0], r.origin[1]);
    for x in &r.done {
        assert!(
            (bulk(x.e, x.nu) / bulk(e0, nu0) - 1.0).abs() < 1e-9,
            "{x:?}"
        );
        let g = shear(x.e, x.nu) / shear(e0, nu0);
        assert!(
            (g / 0.8f64.powi(x.k) - 1.0).abs() < 1e-9,
            "k {} ratio {g}",
            x.k
        );
        assert_eq!((x.theta[0], x.theta[1]), (x.e, x.nu));
        assert!(x.loss <= x.inner.as_ref().unwrap().rounds[0].loss_before);
    }
    // The second restart's k follows the first one's profile value.
    let first = &r.done[0];
    assert_eq!(first.k, 1);
    let expected = if first.loss < r.origin_loss { 2 } else { -1 };
    assert_eq!(r.done[1].k, expected, "{:?}", r.done);
    let best = full.best_loss.unwrap();
    let lowest = r.done.iter().map(|x| x.loss).fold(r.origin_loss, f64::min);
    assert!(best <= lowest, "{best} vs {lowest}");
    // Killed inside the second restart, the fit resumes to the same restarts.
    let ck = all
        .states
        .iter()
        .find(|st| {
            st.restarts
                .as_ref()
                .is_some_and(|x| x.done.len() == 1 && x.current.is_some())
        })
        .expect("a checkpoint inside the second restart")
        .clone();
    let ck: FitState = serde_json::from_str(&serde_json::to_string(&ck).unwrap()).unwrap();
    let mut rest = Collect::default();
    let resumed = run_fit(&p, &cfg, Some(ck), &mut rest).unwrap();
    assert!(rest.losses.is_empty(), "no iteration is repeated");
    assert_eq!(resumed.restarts.as_ref().unwrap().done, r.done);
    assert_eq!(resumed.best_loss, full.best_loss);
    let mut no_nu = cfg.clone();
    no_nu.free = Some(vec!["E".into(), "density".into()]);
    let mut before = Collect::default();
    let e = run_fit(&p, &no_nu, None, &mut before).unwrap_err();
    assert!(
        e.to_string().contains("shear_restarts") && e.to_string().contains("nu"),
        "{e}"
    );
    assert!(before.losses.is_empty(), "refused before the iterations");
}

/// From a Latin hypercube start over E and density (two decades each) the fit recovers
/// E/density of a small block within 10%.
#[test]
fn fit_from_latin_hypercube_start_recovers_e_over_density() {
    let truth = [jelly(2e4, 800.0)];
    let mut p = small_problem(&truth, 6);
    p.config.parts = vec![jelly(1e5, 1000.0)];
    let mut cfg = fit_config(20);
    cfg.init.enabled = true;
    cfg.init.candidates = 12;
    cfg.init.frames = 7;
    cfg.parts.push(resonance4d::video_fit::config::PartFit {
        id: 0,
        free: None,
        bounds: [
            ("E".to_string(), [2e3, 2e5]),
            ("density".to_string(), [100.0, 10000.0]),
        ]
        .into_iter()
        .collect(),
    });
    let out = run_fit(&p, &cfg, None, &mut NoHooks).unwrap();
    let ratio = |q: &PartParams| q.youngs_modulus_pa / q.density_kg_m3;
    let err = (ratio(&out.parts[0]) / ratio(&truth[0]) - 1.0).abs();
    let init = (ratio(&out.init_parts[0]) / ratio(&truth[0]) - 1.0).abs();
    eprintln!(
        "E {:.4e} density {:.1}; E/density error {:.2}% (after initialisation {:.1}%)",
        out.parts[0].youngs_modulus_pa,
        out.parts[0].density_kg_m3,
        100.0 * err,
        100.0 * init
    );
    assert!(err < 0.1, "E/density off by {:.1}%", 100.0 * err);
}

/// Restarts where the descent stalls (`stall`): each restart begins at the next seed (the
/// multi-start's second start first), the fit's result is the lowest point of all runs,
/// and a fit killed after a restart resumes inside the new run to the same end.
#[test]
fn a_stalled_descent_restarts_from_the_next_seed_and_resumes_exactly() {
    use resonance4d::video_fit::{FitEvent, OptimizerKind};
    #[derive(Default)]
    struct Stalls {
        inner: Collect,
        stalls: Vec<(usize, f64, usize, Vec<f64>)>,
    }
    impl FitHooks for Stalls {
        fn on_event(&mut self, e: &FitEvent<'_>) {
            self.inner.on_event(e);
            if let FitEvent::Stalled {
                iter,
                lowest,
                seed,
                theta,
                ..
            } = *e
            {
                self.stalls.push((iter, lowest, seed, theta.to_vec()));
            }
        }
        fn on_checkpoint(&mut self, s: &FitState) {
            self.inner.on_checkpoint(s);
        }
    }
    let truth = [jelly(2e4, 800.0)];
    let mut p = small_problem(&truth, 4);
    p.config.parts = vec![jelly(1e5, 1000.0)];
    let mut cfg = fit_config(9);
    cfg.optimizer = OptimizerKind::TrustBfgs;
    cfg.init.enabled = true;
    cfg.init.candidates = 6;
    cfg.init.frames = 3;
    cfg.multi_start = 2;
    cfg.multi_start_iters = 1;
    cfg.stall = 2;
    let mut all = Stalls::default();
    let full = run_fit(&p, &cfg, None, &mut all).unwrap();
    assert!(!all.stalls.is_empty(), "losses {:?}", all.inner.losses);
    let last = all.inner.states.last().unwrap();
    let run = last.descent.as_ref().unwrap();
    assert_eq!(
        run.stalls,
        all.stalls.iter().map(|s| s.0).collect::<Vec<_>>()
    );
    // The first restart begins at the multi-start's other start.
    let mut starts = last.starts.clone();
    starts.sort_by(|a, b| a.loss.total_cmp(&b.loss));
    assert_eq!(all.stalls[0].2, 1);
    assert_eq!(all.stalls[0].3, starts[1].theta);
    // The result is the lowest loss of every run and start.
    let lowest = all
        .inner
        .losses
        .iter()
        .chain(starts.iter().map(|s| &s.loss))
        .fold(f64::INFINITY, |a, &b| a.min(b));
    assert_eq!(full.best_loss, Some(lowest));
    // Killed at the checkpoint after the first restart, the fit resumes to the same end.
    let at = all.stalls[0].0 + 1;
    let ck = all
        .inner
        .states
        .iter()
        .find(|s| s.iters_done == at)
        .unwrap()
        .clone();
    let ck: FitState = serde_json::from_str(&serde_json::to_string(&ck).unwrap()).unwrap();
    let mut rest = Collect::default();
    let resumed = run_fit(&p, &cfg, Some(ck), &mut rest).unwrap();
    assert_eq!(rest.losses, all.inner.losses[at..]);
    assert_eq!(resumed.best_loss, full.best_loss);
    assert_eq!(resumed.parts, full.parts);
}

/// The initialisation ranked by the fit's own loss (`[init] score = "loss"`) over three
/// rounds: every candidate's score is minus the loss at its parameters over the
/// initialisation's frames (none where the simulation fails), the later rounds' candidates
/// lie inside the bounds, and the best
/// candidate is the one with the lowest loss of all rounds.
#[test]
fn the_loss_ranked_initialisation_scores_every_round_by_the_loss() {
    use resonance4d::video_fit::fit::initialize;
    use resonance4d::video_fit::{InitSampler, InitScore};
    let truth = [jelly(2e4, 800.0)];
    let mut p = small_problem(&truth, 4);
    p.config.parts = vec![jelly(1e5, 1000.0)];
    let mut cfg = fit_config(0);
    cfg.init.enabled = true;
    cfg.init.candidates = 6;
    cfg.init.frames = 3;
    cfg.init.rounds = 3;
    cfg.init.score = InitScore::Loss;
    cfg.init.sampler = InitSampler::Natural;
    let (space, out) = initialize(&p, &cfg, &mut NoHooks).unwrap();
    assert_eq!(out.candidates.len(), 18);
    let obj = Objective::new(&p, Some(3), &cfg.loss, false).unwrap();
    let bounds = space.bounds();
    let mut lowest = f64::INFINITY;
    for c in &out.candidates {
        for (v, (lo, hi)) in c.theta.iter().zip(&bounds) {
            assert!(v >= lo && v <= hi, "{:?} outside {bounds:?}", c.theta);
        }
        let mut parts = p.config.parts.clone();
        space.apply(&mut parts, &c.theta);
        match (obj.value(&parts), c.score) {
            (Ok(e), score) => {
                assert_eq!(score, Some(-e.total), "candidate {}", c.index);
                lowest = lowest.min(e.total);
            }
            // A candidate whose simulation fails (too stiff for the substep) has no score.
            (Err(_), score) => assert_eq!(score, None, "candidate {}", c.index),
        }
    }
    assert!(lowest.is_finite());
    let best = &out.candidates[out.ranking[0]];
    assert_eq!(best.score, Some(-lowest));
    assert_eq!(best.theta, out.best);
}

/// Per-particle parameter slots (the paper's ablation): the per-particle gradients of a part
/// sum to the part's gradient.
#[test]
fn per_particle_gradients_sum_to_the_part_gradient() {
    let truth = [jelly(2e4, 800.0), jelly(8e3, 1500.0)];
    let p = small_problem(&truth, 3);
    let start = [jelly(1.4e4, 1000.0), jelly(1.1e4, 1200.0)];
    let loss = fit_config(0).loss;
    let parts = Objective::new(&p, None, &loss, false).unwrap();
    let (ev, g) = parts.value_and_grad(&start).unwrap();
    let per = Objective::new(&p, None, &loss, true).unwrap();
    let slots: Vec<PartParams> = per
        .slot_parts()
        .iter()
        .map(|&k| start[k as usize])
        .collect();
    assert_eq!(slots.len(), p.particles.x.len());
    let (ev2, gp) = per.value_and_grad(&slots).unwrap();
    assert!((ev.total - ev2.total).abs() <= 1e-12 * ev.total);
    for part in 0..2 {
        let sum = |f: &dyn Fn(&r4d_mpm::adjoint::host::PhysParams<f64>) -> f64| -> f64 {
            gp.iter()
                .zip(per.slot_parts())
                .filter(|(_, k)| *k as usize == part)
                .map(|(g, _)| f(g))
                .sum()
        };
        let e = sum(&|g| g.youngs_modulus);
        let r = sum(&|g| g.density);
        assert!((e - g[part].youngs_modulus).abs() <= 1e-6 * g[part].youngs_modulus.abs());
        assert!((r - g[part].density).abs() <= 1e-6 * g[part].density.abs());
    }
}

/// The nested checkpointing (frame boundaries, then every n substeps inside a frame) re-runs
/// the same substeps from the same states: the gradient equals the per-frame strategy's.
#[test]
fn nested_checkpointing_gives_the_per_frame_gradient() {
    let truth = [jelly(2e4, 800.0), jelly(8e3, 1500.0)];
    let p = small_problem(&truth, 3);
    let start = [jelly(1.4e4, 1000.0), jelly(1.1e4, 1200.0)];
    let loss = fit_config(0).loss;
    let mut a = Objective::new(&p, None, &loss, false).unwrap();
    let (ev, g) = a.value_and_grad(&start).unwrap();
    a.checkpointing = r4d_mpm::adjoint::checkpoint::Checkpointing::Nested(5);
    let (ev2, g2) = a.value_and_grad(&start).unwrap();
    assert_eq!(ev.total, ev2.total);
    for part in 0..2 {
        assert_eq!(g[part].youngs_modulus, g2[part].youngs_modulus);
        assert_eq!(g[part].density, g2[part].density);
    }
}

/// The loss evaluated in row bands (one projection per frame, band-wise DMS) gives the
/// whole-frame loss and gradient: 16-row bands against one band covering the 64-row frame.
#[test]
fn row_bands_give_the_whole_frame_loss_and_gradient() {
    let truth = [jelly(2e4, 800.0), jelly(8e3, 1500.0)];
    let p = small_problem(&truth, 3);
    let start = [jelly(1.4e4, 1000.0), jelly(1.1e4, 1200.0)];
    let loss = fit_config(0).loss;
    let mut a = Objective::new(&p, None, &loss, false).unwrap();
    a.set_band_rows(64).unwrap();
    let (ev, g) = a.value_and_grad(&start).unwrap();
    assert_eq!(a.profile().bands, 1);
    a.set_band_rows(16).unwrap();
    let (ev2, g2) = a.value_and_grad(&start).unwrap();
    let prof = a.profile();
    assert_eq!(prof.bands, 4);
    assert!(prof.render_s > 0.0 && prof.loss_s > 0.0 && prof.render_vjp_s > 0.0);
    let rel = |x: f64, y: f64| (x - y).abs() / y.abs().max(1e-30);
    assert!(
        rel(ev2.total, ev.total) < 1e-5,
        "{} vs {}",
        ev2.total,
        ev.total
    );
    for part in 0..2 {
        for (x, y) in [
            (g2[part].youngs_modulus, g[part].youngs_modulus),
            (g2[part].density, g[part].density),
        ] {
            // f32 sums: the bands add their gradients in another order.
            assert!(rel(x, y) < 1e-3, "part {part}: {x} vs {y}");
        }
    }
    let v = a.value(&start).unwrap();
    assert!(rel(v.total, ev.total) < 1e-5);
}

/// With no room to keep prepared frames (`frame_cache_bytes = 0`) every band projects its
/// frames again and pulls its VJP through the projection at once: the same loss, the same
/// gradient up to the order of the f32 sums; with room for one frame, a mix of both.
#[test]
fn frames_prepared_per_band_give_the_kept_frames_loss_and_gradient() {
    let truth = [jelly(2e4, 800.0), jelly(8e3, 1500.0)];
    let p = small_problem(&truth, 3);
    let start = [jelly(1.4e4, 1000.0), jelly(1.1e4, 1200.0)];
    let loss = fit_config(0).loss;
    let mut a = Objective::new(&p, None, &loss, false).unwrap();
    a.set_band_rows(16).unwrap();
    let (ev, g) = a.value_and_grad(&start).unwrap();
    let rel = |x: f64, y: f64| (x - y).abs() / y.abs().max(1e-30);
    for budget in [0, 1] {
        a.frame_cache_bytes = Some(budget);
        let (ev2, g2) = a.value_and_grad(&start).unwrap();
        assert_eq!(
            ev2.total, ev.total,
            "budget {budget}: the forward is unchanged"
        );
        for part in 0..2 {
            for (x, y) in [
                (g2[part].youngs_modulus, g[part].youngs_modulus),
                (g2[part].density, g[part].density),
            ] {
                assert!(rel(x, y) < 1e-4, "budget {budget}, part {part}: {x} vs {y}");
            }
        }
    }
}

/// A parts file may name a part no particle belongs to (the last one empty: `r4d segment`
/// can write such a file): that part is a parameter slot with a zero gradient, and a fit runs
/// (it used to index past the gradient).
#[test]
fn an_empty_last_part_is_a_slot_with_zero_gradient() {
    let truth = [jelly(2e4, 800.0), jelly(8e3, 1500.0)];
    let mut p = small_problem(&truth, 3);
    p.config.parts.push(jelly(5e3, 900.0));
    let start = [
        jelly(1.4e4, 1000.0),
        jelly(1.1e4, 1200.0),
        jelly(5e3, 900.0),
    ];
    let obj = Objective::new(&p, None, &fit_config(0).loss, false).unwrap();
    assert_eq!(obj.slot_parts(), vec![0, 1, 2]);
    let (_, g) = obj.value_and_grad(&start).unwrap();
    assert_eq!(g.len(), 3);
    assert!(g[0].youngs_modulus != 0.0 && g[1].density != 0.0);
    assert_eq!(g[2].youngs_modulus, 0.0);
    assert_eq!(g[2].density, 0.0);
    p.config.parts = start.to_vec();
    let out = run_fit(&p, &fit_config(1), None, &mut NoHooks).unwrap();
    assert_eq!(out.parts.len(), 3);
}

/// A frame rate that maps the video onto an absurd number of simulated frames is refused
/// when the objective is made (it used to plan ~6e8 frames), and a damaged checkpoint is a
/// resume error, not a panic or a silent restart.
#[test]
fn absurd_frame_rates_and_damaged_checkpoints_are_refused() {
    let truth = [jelly(2e4, 800.0), jelly(8e3, 1500.0)];
    let mut p = small_problem(&truth, 3);
    let fps = p.fps;
    p.fps = 1e-6;
    let e = Objective::new(&p, None, &fit_config(0).loss, false)
        .err()
        .expect("refused");
    assert!(e.to_string().contains("simulated frames"), "{e}");
    p.fps = fps;
    struct Keep(Option<FitState>);
    impl FitHooks for Keep {
        fn on_checkpoint(&mut self, s: &FitState) {
            self.0 = Some(s.clone());
        }
    }
    let mut keep = Keep(None);
    let cfg = fit_config(1);
    run_fit(&p, &cfg, None, &mut keep).unwrap();
    let state = keep.0.expect("a checkpoint");
    let mut j = serde_json::to_value(&state).unwrap();
    j["optimizer"]["xi"] = serde_json::json!([1.0]);
    let damaged: FitState = serde_json::from_value(j).unwrap();
    let cfg2 = fit_config(2);
    let e = run_fit(&p, &cfg2, Some(damaged), &mut NoHooks).expect_err("refused");
    assert!(e.to_string().contains("cannot resume"), "{e}");
    // The intact checkpoint resumes.
    run_fit(&p, &cfg2, Some(state), &mut NoHooks).unwrap();
}

/// Another loss plugs into the objective through `r4d_loss::VideoLoss` / `BandedLoss`: a loss
/// that is the DMS scaled by 3 gives 3x the DMS objective's value and gradient (the objective
/// evaluates, differentiates and pulls back whatever loss it is given).
#[test]
fn the_objective_runs_any_banded_loss() {
    use r4d_loss::bands::ReferenceVideo;
    use r4d_loss::{BandedLoss, DmsConfig, DmsTerms, LossError, Video, VideoLoss};
    use std::ops::Range;

    #[derive(Debug)]
    struct Tripled(DmsConfig);
    struct TripledBands<'r>(Box<dyn BandedLoss + 'r>);
    fn triple(mut t: DmsTerms) -> DmsTerms {
        t.total *= 3.0;
        t
    }
    impl BandedLoss for TripledBands<'_> {
        fn frames(&self) -> usize {
            self.0.frames()
        }
        fn band_rows(&self) -> Vec<Range<usize>> {
            self.0.band_rows()
        }
        fn band_terms(&self, b: usize, x: &Video<f32>) -> Result<DmsTerms, LossError> {
            self.0.band_terms(b, x).map(triple)
        }
        fn band_terms_and_grad_into(
            &self,
            b: usize,
            x: &Video<f32>,
            g: &mut [f32],
        ) -> Result<DmsTerms, LossError> {
            let t = self.0.band_terms_and_grad_into(b, x, g)?;
            g.iter_mut().for_each(|v| *v *= 3.0);
            Ok(triple(t))
        }
    }
    impl VideoLoss for Tripled {
        fn banded<'r>(
            &self,
            reference: &'r ReferenceVideo,
            frames: usize,
            band_rows: usize,
        ) -> Result<Box<dyn BandedLoss + 'r>, LossError> {
            Ok(Box::new(TripledBands(
                self.0.banded(reference, frames, band_rows)?,
            )))
        }
    }

    let truth = [jelly(2e4, 800.0), jelly(8e3, 1500.0)];
    let p = small_problem(&truth, 3);
    let start = [jelly(1.4e4, 1000.0), jelly(1.1e4, 1200.0)];
    let dms = fit_config(0).loss;
    let a = Objective::new(&p, None, &dms, false).unwrap();
    let b = Objective::with_loss(&p, None, std::sync::Arc::new(Tripled(dms)), false).unwrap();
    let (ev, g) = a.value_and_grad(&start).unwrap();
    let (ev3, g3) = b.value_and_grad(&start).unwrap();
    let rel = |x: f64, y: f64| (x - y).abs() / y.abs().max(1e-30);
    assert!(ev.total > 0.0);
    assert!(
        rel(ev3.total, 3.0 * ev.total) < 1e-12,
        "{} vs 3 x {}",
        ev3.total,
        ev.total
    );
    for part in 0..2 {
        for (x, y) in [
            (g3[part].youngs_modulus, g[part].youngs_modulus),
            (g3[part].density, g[part].density),
        ] {
            assert!(
                y != 0.0 && rel(x, 3.0 * y) < 1e-5,
                "part {part}: {x} vs 3 x {y}"
            );
        }
    }
}

/// The initialisation's score, computed frame by frame as the simulation produces the frames
/// (`Objective::ms_ssim`), is bitwise the MS-SSIM of the whole rendered videos, with the
/// simulated frames one per video frame and with video frames between simulated frames.
#[test]
fn streamed_ms_ssim_equals_the_score_of_the_rendered_videos() {
    use resonance4d::video_fit::fit::ms_ssim_score;
    let truth = [jelly(2e4, 800.0), jelly(8e3, 1500.0)];
    let start = [jelly(1.4e4, 1000.0), jelly(1.1e4, 1200.0)];
    for fps_factor in [1.0, 1.5] {
        let mut p = small_problem(&truth, 5);
        if fps_factor != 1.0 {
            p.fps *= fps_factor;
        }
        let obj = Objective::new(&p, None, &fit_config(0).loss, false).unwrap();
        assert_eq!(obj.time_map().is_identity(), fps_factor == 1.0);
        let whole = ms_ssim_score(&p, &obj.render(&start).unwrap()).unwrap();
        let streamed = obj.ms_ssim(&start).unwrap();
        assert!(whole > 0.0 && whole < 1.0, "{whole}");
        assert_eq!(streamed.to_bits(), whole.to_bits(), "{streamed} vs {whole}");
        // A different candidate scores differently (the score is not a constant).
        assert_ne!(obj.ms_ssim(&truth).unwrap(), streamed);
    }
}

/// A descent step onto parameters whose simulation explodes is a rejected step, not the end
/// of the fit: AdamW goes back to the best point with half the learning rate and goes on (and
/// a fit killed after the divergence resumes to the same end); a descent whose every point
/// diverges ends after `MAX_DIVERGED` in a row instead of looping.
#[test]
fn a_diverging_step_is_rejected_and_the_fit_goes_on() {
    use resonance4d::video_fit::fit::MAX_DIVERGED;
    use resonance4d::video_fit::FitEvent;
    #[derive(Default)]
    struct Diverged {
        inner: Collect,
        lrs: Vec<(usize, f64)>,
        diverged: Vec<(usize, Option<Vec<f64>>, bool)>,
    }
    impl FitHooks for Diverged {
        fn on_event(&mut self, e: &FitEvent<'_>) {
            self.inner.on_event(e);
            match e {
                FitEvent::Iter(r) => self.lrs.push((r.iter, r.lr)),
                FitEvent::Diverged {
                    iter,
                    retreat,
                    ends,
                    ..
                } => self
                    .diverged
                    .push((*iter, retreat.map(<[f64]>::to_vec), *ends)),
                _ => {}
            }
        }
        fn on_checkpoint(&mut self, s: &FitState) {
            self.inner.on_checkpoint(s);
        }
    }
    let truth = [jelly(2e4, 800.0)];
    let mut p = small_problem(&truth, 4);
    let mut cfg = fit_config(4);
    cfg.free = Some(vec!["E".into()]);
    cfg.parts.push(resonance4d::video_fit::config::PartFit {
        id: 0,
        free: None,
        bounds: [("E".to_string(), [1e3, 1e9])].into(),
    });
    cfg.lr_schedule = resonance4d::video_fit::config::LrSchedule::Constant;
    cfg.flat_probe = 0;
    // The stiffness at which this scene's explicit substeps explode (dt 1e-3, dx 1/16).
    let obj = Objective::new(&p, None, &cfg.loss, false).unwrap();
    let explodes = (1..16)
        .map(|k| 2e4 * 2f64.powi(k))
        .find(|&e| match obj.value(&[jelly(e, 800.0)]) {
            Ok(_) => false,
            Err(err) => {
                assert!(err.is_divergence(), "{err}");
                true
            }
        })
        .expect("a stiffness below 1e9 that explodes");
    drop(obj);
    // From a third of the truth the gradient raises E; AdamW's first step is the learning
    // rate in log units: past the explosion.
    let start = 2e4 / 3.0;
    p.config.parts = vec![jelly(start, 800.0)];
    cfg.lr = (explodes / start).ln() + 0.3;
    let mut all = Diverged::default();
    let full = run_fit(&p, &cfg, None, &mut all).unwrap();
    assert_eq!(all.diverged.len(), 1, "{:?}", all.diverged);
    let (iter, retreat, ends) = all.diverged[0].clone();
    assert_eq!(iter, 1);
    assert!(!ends);
    // Back to the best point (the start, the only point evaluated), half the rate after.
    let back = retreat.expect("AdamW goes back to the best point");
    assert!((back[0] - start).abs() <= 1e-9 * start, "{back:?}");
    assert_eq!(all.lrs.iter().map(|r| r.0).collect::<Vec<_>>(), [0, 2, 3]);
    assert_eq!(all.lrs[0].1, cfg.lr);
    assert_eq!(all.lrs[1].1, 0.5 * cfg.lr);
    let last = all.inner.states.last().unwrap();
    assert_eq!(last.diverged, [1]);
    assert_eq!(last.iters_done, 4);
    // Iteration 2 evaluates the best point again (its gradient starts the new descent) and
    // iteration 3 the step from there.
    let losses = &all.inner.losses;
    assert_eq!(losses[1], losses[0]);
    assert!(
        losses[2].is_finite() && losses[2] != losses[0],
        "{losses:?}"
    );
    let lowest = losses.iter().fold(f64::INFINITY, |a, &b| a.min(b));
    assert_eq!(full.best_loss, Some(lowest));
    // Killed right after the divergence, the fit resumes to the same end.
    let ck = all
        .inner
        .states
        .iter()
        .find(|s| s.iters_done == 2)
        .unwrap()
        .clone();
    let ck: FitState = serde_json::from_str(&serde_json::to_string(&ck).unwrap()).unwrap();
    let mut rest = Collect::default();
    let resumed = run_fit(&p, &cfg, Some(ck), &mut rest).unwrap();
    assert_eq!(rest.losses, all.inner.losses[1..]);
    assert_eq!(resumed.parts, full.parts);

    // Every point diverges (the start itself): the descent ends after MAX_DIVERGED.
    p.config.parts = vec![jelly(explodes, 800.0)];
    let mut none = Diverged::default();
    let o = run_fit(&p, &cfg, None, &mut none).unwrap();
    assert_eq!(none.diverged.len(), MAX_DIVERGED);
    assert!(
        none.diverged.last().unwrap().2,
        "the last one ends the descent"
    );
    assert!(none.inner.losses.is_empty());
    assert_eq!(o.best_loss, None);
    assert_eq!(none.inner.states.last().unwrap().iters_done, MAX_DIVERGED);
}
