//! The fit loop: simulation-driven initialisation, then AdamW on `xi = log(theta)` with bound
//! and gradient clipping; a record per iteration and a resumable checkpoint.

use super::budget::Budget;
use super::config::{FitConfig, InitSampler, InitScore, OptimizerKind, StageKind, STALL_DROP};
use super::problem::{Evaluation, Objective, VideoProblem};
use crate::descent::{self, keep_best, Rate, Stepper};
use crate::evaluator::{Evaluator, Graded};
use crate::record::{mix_json, DescentRun, Fingerprint, FlatProbe, Terms};
pub use crate::record::{FitState, IterRecord, StartResult};
use crate::restarts::{e_nu_from_k_g, k_g_from_e_nu, Restart, ShearRestarts};
use crate::sampling::{SamplingConfig, SamplingRound};
use crate::space::{part_summary, Granularity, ParamSpace};
use crate::valley::ValleyRound;
use crate::FitError;
use crate::{
    evaluate_candidate, Candidate, GradientSampling, InitOutcome, Initializer, LatinHypercubeInit,
    LogDomainOptimizer, LogGridInit, NaturalScaleInit, ParamKind, SearchSpace, TrustRegion,
    TrustRegionBfgs, ValleySearch,
};
use r4d_loss::bands::ReferenceVideo;
use r4d_loss::{ssim::ms_ssim, Video, VideoLoss};
use r4d_mpm::PartParams;
use rayon::prelude::*;
use std::sync::Arc;
use std::time::Instant;

/// One evaluation and step of the fit loop.
struct Step {
    ev: Evaluation,
    theta: Vec<f64>,
    gtheta: Vec<f64>,
    slots: Vec<PartParams>,
    grad_norm: f64,
    lr: f64,
    probes: Vec<FlatProbe>,
}

/// A fresh optimiser of `cfg.optimizer` at `theta`.
fn new_stepper(cfg: &FitConfig, space: &ParamSpace, theta: Vec<f64>) -> Result<Stepper, FitError> {
    Ok(match cfg.optimizer {
        OptimizerKind::Adam => Stepper::Adam(LogDomainOptimizer::new(
            theta,
            space.bounds(),
            cfg.adam(),
            (cfg.clip_norm > 0.0).then_some(cfg.clip_norm),
        )?),
        OptimizerKind::TrustBfgs => Stepper::Trust(TrustRegionBfgs::new(
            theta,
            space.bounds(),
            TrustRegion {
                initial_radius: cfg.lr,
                max_radius: (5.0 * cfg.lr).max(cfg.lr),
                min_radius: (1e-2 * cfg.lr).min(cfg.lr),
            },
        )?),
    })
}

/// Evaluates `opt`'s point and steps (the shared iteration, [`crate::descent::iterate`]),
/// then runs the flat-direction probes; iteration `iter` of `iters` (for the learning-rate
/// schedule).
fn iterate(
    obj: &Objective,
    space: &ParamSpace,
    base_slots: &[PartParams],
    opt: &mut Stepper,
    cfg: &FitConfig,
    (iter, iters): (usize, usize),
    lr_scale: f64,
) -> Result<Step, FitError> {
    let rate = Rate {
        schedule: cfg.lr_schedule,
        base: cfg.lr * lr_scale,
        iters,
    };
    let it = descent::iterate(space, base_slots, opt, rate, iter, |slots| {
        let (ev, g) = obj.value_and_grad(slots)?;
        let total = ev.total;
        Ok((ev, total, g))
    })?;
    let eval = ObjectiveEval {
        obj,
        space,
        base: base_slots,
    };
    let probes = flat_probes(&eval, space, &it.theta, &it.gtheta, it.loss, cfg.flat_probe);
    for (i, p) in &probes {
        if p.to != p.from {
            opt.set_theta(*i, p.to);
        }
    }
    Ok(Step {
        ev: it.eval,
        theta: it.theta,
        gtheta: it.gtheta,
        slots: it.slots,
        grad_norm: it.grad_norm,
        lr: it.lr,
        probes: probes.into_iter().map(|(_, p)| p).collect(),
    })
}

/// Stores the optimiser in the checkpoint state.
fn save(opt: &Stepper, state: &mut FitState) {
    match opt {
        Stepper::Adam(o) => state.optimizer = Some(o.clone()),
        Stepper::Trust(o) => state.trust = Some(o.clone()),
    }
}

/// Persists the state after an iteration or a round of a later stage (the valley search, the
/// restarts, gradient sampling): the optimiser goes into the checkpoint for it and out
/// again.
fn checkpoint_stage(
    opt: &Stepper,
    state: &mut FitState,
    hooks: &mut dyn FitHooks,
    (budget, evals): (&Budget, usize),
) {
    save(opt, state);
    budget.stamp(state, evals);
    hooks.on_checkpoint(state);
    state.optimizer = None;
    state.trust = None;
}

/// Loss and log-unit gradient (`theta dL/dtheta`) of every free parameter at `theta`; `None`
/// where the simulation fails (a wall to the searches, not an error of the fit).
fn loss_and_log_grad(
    obj: &Objective,
    space: &ParamSpace,
    base_slots: &[PartParams],
    theta: &[f64],
) -> Graded {
    let mut slots = base_slots.to_vec();
    space.apply(&mut slots, theta);
    let (ev, g) = obj.value_and_grad(&slots).ok()?;
    let g = space.gather(&g);
    Some((ev.total, g.iter().zip(theta).map(|(a, b)| a * b).collect()))
}

/// The video objective as the stages' [`Evaluator`]: a point is the logs of the free
/// parameters of `space`, applied to the `base` slots; a point whose simulation fails is a
/// wall (`f64::INFINITY`, no gradient).
struct ObjectiveEval<'a> {
    obj: &'a Objective<'a>,
    space: &'a ParamSpace,
    base: &'a [PartParams],
}

impl ObjectiveEval<'_> {
    /// The loss at the parameters `theta` (not logs).
    fn at_theta(&self, theta: &[f64]) -> f64 {
        let mut slots = self.base.to_vec();
        self.space.apply(&mut slots, theta);
        self.obj.value(&slots).map_or(f64::INFINITY, |e| e.total)
    }
}

impl Evaluator for ObjectiveEval<'_> {
    fn value(&self, x: &[f64]) -> f64 {
        self.at_theta(&x.iter().map(|v| v.exp()).collect::<Vec<_>>())
    }
    fn value_and_grad(&self, x: &[f64]) -> Graded {
        let theta: Vec<f64> = x.iter().map(|v| v.exp()).collect();
        loss_and_log_grad(self.obj, self.space, self.base, &theta)
    }
}

/// A shear restart's [`Evaluator`]: the logs of the free parameters other than the
/// restart's E and nu (`others`), which `full` completes into every free parameter.
struct RestartEval<'a, F: Fn(&[f64]) -> Vec<f64> + Sync> {
    eval: &'a ObjectiveEval<'a>,
    full: F,
    others: &'a [usize],
}

impl<F: Fn(&[f64]) -> Vec<f64> + Sync> Evaluator for RestartEval<'_, F> {
    fn value(&self, x: &[f64]) -> f64 {
        self.eval.at_theta(&(self.full)(x))
    }
    fn value_and_grad(&self, x: &[f64]) -> Graded {
        let e = self.eval;
        let (loss, g) = loss_and_log_grad(e.obj, e.space, e.base, &(self.full)(x))?;
        Some((loss, self.others.iter().map(|&i| g[i]).collect()))
    }
}

/// The loss terms of an evaluation, summed over its views.
pub fn terms_of(ev: &Evaluation) -> Terms {
    let mean = |f: &dyn Fn(&r4d_loss::DmsTerms) -> Option<f64>| {
        let v: Vec<f64> = ev.views.iter().filter_map(f).collect();
        (!v.is_empty()).then(|| v.iter().sum::<f64>())
    };
    Terms {
        total: ev.total,
        l1: mean(&|t| t.l1),
        spatial: mean(&|t| t.spatial),
        mag: mean(&|t| t.mag),
        phase: mean(&|t| t.phase),
    }
}

/// The kinds that act only through a branch of the return mapping: their gradient is exactly
/// zero while no particle is on that branch.
fn branch_kind(k: ParamKind) -> bool {
    matches!(
        k,
        ParamKind::YieldStress
            | ParamKind::PlasticViscosity
            | ParamKind::FrictionAngle
            | ParamKind::Hardening
            | ParamKind::Softening
    )
}

/// The flat-direction probes of one iteration (see [`FitConfig::flat_probe`]): for every
/// part-level branch parameter with an exactly-zero gradient, `points` log-spaced values
/// across its bounds (evaluated in parallel through `eval`); returns the probes and the best
/// values.
fn flat_probes(
    eval: &ObjectiveEval,
    space: &ParamSpace,
    theta: &[f64],
    gtheta: &[f64],
    loss: f64,
    points: usize,
) -> Vec<(usize, FlatProbe)> {
    if points < 2 || space.granularity == Granularity::Particle {
        return Vec::new();
    }
    let flat: Vec<usize> = (0..theta.len())
        .filter(|&i| gtheta[i] == 0.0 && branch_kind(space.entries[i].kind))
        .collect();
    // Only when something else moves the loss (a zero gradient everywhere is a minimum or a
    // scene without motion, not a flat direction).
    if flat.is_empty() || flat.len() == theta.len() {
        return Vec::new();
    }
    let names = space.names();
    let mut out = Vec::new();
    for i in flat {
        let (lo, hi) = space.entries[i].bounds;
        let values: Vec<f64> = (0..points)
            .map(|j| lo * (hi / lo).powf(j as f64 / (points - 1) as f64))
            .collect();
        // At the parameters themselves (not through their logs: the same points as the
        // iteration's, bit for bit).
        let losses: Vec<f64> = values
            .par_iter()
            .map(|&v| {
                let mut t = theta.to_vec();
                t[i] = v;
                eval.at_theta(&t)
            })
            .collect();
        let mut best = (loss, theta[i]);
        // A probed point that fails (e.g. an unstable run) is a wall, never the best.
        for (v, l) in values.iter().zip(losses) {
            if l < best.0 {
                best = (l, *v);
            }
        }
        out.push((
            i,
            FlatProbe {
                name: names[i].clone(),
                from: theta[i],
                to: best.1,
                loss_from: loss,
                loss_best: best.0,
            },
        ));
    }
    out
}

/// What a fit reports as it goes, one variant per stage's unit of progress
/// ([`FitHooks::on_event`]).
#[derive(Clone, Copy, Debug)]
#[non_exhaustive]
pub enum FitEvent<'a> {
    /// An initialisation candidate was evaluated.
    Candidate(&'a Candidate),
    /// The initialisation finished (`names`: the searched parameters).
    Init {
        /// The ranked candidates.
        outcome: &'a InitOutcome,
        /// The searched parameters, the order of each candidate's `theta`.
        names: &'a [String],
    },
    /// A start of a multi-start finished.
    Start(&'a StartResult),
    /// An iteration of the descent finished.
    Iter(&'a IterRecord),
    /// The descent stalled (`stall` iterations without its lowest loss falling by
    /// [`super::config::STALL_DROP`]) and starts again from another seed.
    Stalled {
        /// The iteration after which it restarts.
        iter: usize,
        /// The lowest loss of the run that stalled.
        lowest: f64,
        /// The seed it restarts from (1: the second-best start, ...).
        seed: usize,
        /// The seed's parameters (in the order of `names`).
        theta: &'a [f64],
        /// The fit's free parameters.
        names: &'a [String],
    },
    /// An iteration's evaluation diverged (the simulation exploded, a value became
    /// non-finite): the step is rejected ([`MAX_DIVERGED`]).
    Diverged {
        /// The iteration.
        iter: usize,
        /// What diverged.
        error: &'a str,
        /// The point the descent goes on from, when it went back to the best point (in the
        /// order of the fit's free parameters); `None`: the trust region shrank instead.
        retreat: Option<&'a [f64]>,
        /// Whether this was the last divergence the descent takes in a row: it ends here.
        ends: bool,
        /// The fit's free parameters.
        names: &'a [String],
    },
    /// A round of the valley search finished.
    Valley {
        /// The round.
        round: &'a ValleyRound,
        /// The free parameters.
        names: &'a [String],
        /// The accepted point after it.
        theta: &'a [f64],
    },
    /// An iteration of gradient sampling finished (inside a shear restart too: then `names`
    /// are the parameters it re-fits).
    Sampling {
        /// The iteration.
        round: &'a SamplingRound,
        /// The parameters it moves.
        names: &'a [String],
        /// The point after it.
        theta: &'a [f64],
    },
    /// A restart along constant bulk modulus finished.
    Restart {
        /// The restart.
        restart: &'a Restart,
        /// The free parameters, the order of [`Restart::theta`].
        names: &'a [String],
    },
}

/// Callbacks of [`run_fit`]: progress ([`FitEvent`]), checkpoints and heap measurement.
pub trait FitHooks {
    /// A stage reported progress.
    fn on_event(&mut self, _e: &FitEvent<'_>) {}
    /// A checkpoint to persist.
    fn on_checkpoint(&mut self, _s: &FitState) {}
    /// Measures heap peaks (the stage profile, [`IterRecord::peak_host_bytes`]); `None`:
    /// they are reported as 0.
    fn heap(&self) -> Option<std::sync::Arc<dyn crate::HeapProbe>> {
        None
    }
}

/// Hooks that do nothing.
pub struct NoHooks;
impl FitHooks for NoHooks {}

/// The result of [`run_fit`].
#[derive(Clone, Debug)]
pub struct FitOutcome {
    /// The free parameters.
    pub space: ParamSpace,
    /// Parameters per part at the start of the iterations (after initialisation).
    pub init_parts: Vec<PartParams>,
    /// Fitted parameters per part (per-particle fits: geometric means).
    pub parts: Vec<PartParams>,
    /// Fitted parameters per slot (= `parts` unless per particle).
    pub slots: Vec<PartParams>,
    /// Lowest loss evaluated (the returned parameters' loss); `None` without iterations.
    pub best_loss: Option<f64>,
    /// The initialisation's result.
    pub init: Option<InitOutcome>,
    /// The valley search, when it ran (`valley.evals > 0`).
    pub valley: Option<ValleySearch>,
    /// Gradient sampling, when it ran (`gradient_sampling.iters > 0`).
    pub sampling: Option<GradientSampling>,
    /// The restarts along constant bulk modulus, when they ran (`shear_restarts.points > 0`).
    pub restarts: Option<ShearRestarts>,
    /// Whether the fit's budget (`budget`, `evals`) was spent when it ended: a stage may have
    /// stopped early (resume with a larger budget to go on).
    pub budget_spent: bool,
    /// Simulations run over every sitting of the fit (the initialisation's candidates
    /// included; earlier sittings counted when the fit had an evaluation budget).
    pub evaluations: usize,
    /// The automatic strategy's decisions (`strategy = "auto"`; empty otherwise).
    pub decisions: Vec<super::strategy::Decision>,
}

/// MS-SSIM of rendered videos against the problem's references (mean over views), with the
/// smaller-window fallback for frames under 161 px (see [`r4d_loss::MsSsimConfig::largest_window`]).
pub fn ms_ssim_score(problem: &VideoProblem, rendered: &[Video<f32>]) -> Result<f64, FitError> {
    let mut sum = 0.0;
    for (v, r) in problem.views.iter().zip(rendered) {
        let reference = Video::from_frames(
            v.video.height(),
            v.video.width(),
            (0..r.frames()).map(|t| v.video.frame_f32(t)),
        )?;
        let cfg = super::problem::ms_ssim_config(&v.name, r.height(), r.width())?;
        sum += ms_ssim(r, &reference, &cfg)?.mean;
    }
    Ok(sum / rendered.len().max(1) as f64)
}

/// The initialisation's search space: part-level (object-level for object fits) entries of
/// the free kinds.
fn init_space(cfg: &FitConfig, parts: &[PartParams]) -> Result<ParamSpace, FitError> {
    let free = cfg.free_kinds(parts)?;
    let g = if cfg.granularity == Granularity::Object {
        Granularity::Object
    } else {
        Granularity::Part
    };
    let ids: Vec<u32> = (0..parts.len() as u32).collect();
    Ok(ParamSpace::new(g, &free, &ids, |p, k| {
        cfg.bounds(parts, p, k)
    }))
}

/// The initialisation's objective (first `init.frames` frames), search space and sampler.
fn init_setup<'a>(
    problem: &'a VideoProblem,
    cfg: &FitConfig,
) -> Result<
    (
        ParamSpace,
        Objective<'a>,
        SearchSpace,
        Box<dyn Initializer + Send>,
    ),
    FitError,
> {
    let parts = &problem.config.parts;
    let space = init_space(cfg, parts)?;
    let mut obj = Objective::new(problem, Some(cfg.init.frames), &cfg.loss, false)?;
    obj.precision = cfg.precision;
    obj.set_band_rows(cfg.band_rows)?;
    let search = SearchSpace {
        names: space.names(),
        bounds: space.bounds(),
    };
    let include = if cfg.init.include_start {
        vec![space.values(parts)]
    } else {
        Vec::new()
    };
    let lhs = |seed: u64, include: Vec<Vec<f64>>| LatinHypercubeInit {
        candidates: cfg.init.candidates,
        seed,
        top_k: cfg.init.top_k,
        parallel: true,
        max_concurrent: Some(obj.init_concurrency()),
        include,
    };
    let init: Box<dyn Initializer + Send> = match cfg.init.sampler {
        InitSampler::LatinHypercube => Box::new(lhs(cfg.init.seed, include)),
        InitSampler::Natural => Box::new(NaturalScaleInit {
            lhs: lhs(cfg.init.seed, include),
            linear: natural_scale(&space),
        }),
        InitSampler::Grid => Box::new(LogGridInit {
            candidates: cfg.init.candidates,
            top_k: cfg.init.top_k,
            parallel: true,
            max_concurrent: Some(obj.init_concurrency()),
            include,
        }),
    };
    Ok((space, obj, search, init))
}

/// The initialisation's score of the candidate `theta` (`[init] score`): its MS-SSIM, or
/// its negated loss.
fn score_candidate(
    problem: &VideoProblem,
    obj: &Objective,
    space: &ParamSpace,
    theta: &[f64],
    score: InitScore,
) -> Result<f64, String> {
    let mut slots = problem.config.parts.clone();
    space.apply(&mut slots, theta);
    match score {
        InitScore::MsSsim => obj.ms_ssim(&slots),
        InitScore::Loss => obj.value(&slots).map(|e| -e.total),
    }
    .map_err(|e| e.to_string())
}

/// Simulation-driven initialisation: Latin hypercube candidates in log10 space, each
/// simulated for `init.frames` frames and scored by MS-SSIM against the reference. With
/// `[init] rounds = R > 1`, each further round samples as many Latin hypercube candidates
/// again inside the box of the best ones so far ([`narrowed`]); the outcome ranks every
/// round's candidates together (indices continue across rounds). The settings are those
/// [`run_fit`] runs with ([`super::strategy::resolve`]).
pub fn initialize(
    problem: &VideoProblem,
    cfg: &FitConfig,
    hooks: &mut dyn FitHooks,
) -> Result<(ParamSpace, InitOutcome), FitError> {
    let resolved = super::strategy::resolve(cfg, &problem.config.parts)?;
    let cfg = &resolved.config;
    let (space, obj, search, init) = init_setup(problem, cfg)?;
    let evaluate =
        |_i: usize, theta: &[f64]| score_candidate(problem, &obj, &space, theta, cfg.init.score);
    let mut outcome = init_round(&*init, &search, &evaluate, 0, hooks)?;
    // Further rounds sample on the natural scale with the natural sampler, else in log10.
    let linear = match cfg.init.sampler {
        InitSampler::Natural => natural_scale(&space),
        _ => vec![false; search.dims()],
    };
    for round in 1..cfg.init.rounds.max(1) {
        let inner = narrowed(&search, &outcome, cfg.init.candidates, &linear);
        let next = NaturalScaleInit {
            lhs: LatinHypercubeInit {
                candidates: cfg.init.candidates,
                seed: cfg.init.seed.wrapping_add(round as u64),
                top_k: cfg.init.top_k,
                parallel: true,
                max_concurrent: Some(obj.init_concurrency()),
                include: Vec::new(),
            },
            linear: linear.clone(),
        };
        let offset = outcome.candidates.len();
        let more = init_round(&next, &inner, &evaluate, offset, hooks)?;
        let mut all = std::mem::take(&mut outcome.candidates);
        all.extend(more.candidates.into_iter().map(|mut c| {
            c.index += offset;
            c
        }));
        outcome = InitOutcome::from_candidates(all, cfg.init.top_k)
            .map_err(|e| FitError::Input(format!("initialisation: {e}")))?;
    }
    hooks.on_event(&FitEvent::Init {
        outcome: &outcome,
        names: &search.names,
    });
    Ok((space, outcome))
}

/// One round of the initialisation: `init`'s candidates over `search`, evaluated by
/// `evaluate`, each reported to `hooks` as it finishes with its index moved by `offset`.
fn init_round(
    init: &dyn Initializer,
    search: &SearchSpace,
    evaluate: &crate::Evaluate<'_>,
    offset: usize,
    hooks: &mut dyn FitHooks,
) -> Result<InitOutcome, FitError> {
    let (tx, rx) = std::sync::mpsc::channel::<Candidate>();
    let tx = std::sync::Mutex::new(tx);
    std::thread::scope(|s| {
        let h = s.spawn(|| {
            init.initialize_with(search, evaluate, &|c: &Candidate| {
                let mut c = c.clone();
                c.index += offset;
                let _ = tx.lock().map(|t| t.send(c));
            })
        });
        // Forward the candidates to the hooks on this thread as they finish.
        loop {
            match rx.recv_timeout(std::time::Duration::from_millis(50)) {
                Ok(c) => hooks.on_event(&FitEvent::Candidate(&c)),
                Err(_) if h.is_finished() => break,
                Err(_) => {}
            }
        }
        while let Ok(c) = rx.try_recv() {
            hooks.on_event(&FitEvent::Candidate(&c));
        }
        h.join().expect("initialisation thread")
    })
    .map_err(FitError::from)
}

/// Per parameter of `space`: sampled on a linear scale ([`NaturalScaleInit::is_linear`]).
fn natural_scale(space: &ParamSpace) -> Vec<bool> {
    space
        .entries
        .iter()
        .map(|e| NaturalScaleInit::is_linear(e.kind))
        .collect()
}

/// The box of a further initialisation round: per parameter (in log10 space, or linear where
/// `linear` says) the range of the best `max(3, candidates / 8)` candidates so far, widened
/// on each side by a quarter of that range or a twentieth of the whole bounds, whichever is
/// larger, and kept inside the bounds.
pub fn narrowed(
    search: &SearchSpace,
    outcome: &InitOutcome,
    candidates: usize,
    linear: &[bool],
) -> SearchSpace {
    let elites: Vec<&Vec<f64>> = outcome
        .ranking
        .iter()
        .take((candidates / 8).max(3))
        .map(|&i| &outcome.candidates[i].theta)
        .collect();
    let bounds = search
        .bounds
        .iter()
        .enumerate()
        .map(|(d, &(lo, hi))| {
            let lin = linear.get(d).copied().unwrap_or(false);
            type Map = fn(f64) -> f64;
            let (to, from): (Map, Map) = if lin {
                (|v| v, |v| v)
            } else {
                (f64::log10, |v| 10f64.powf(v))
            };
            let (l0, h0) = (to(lo), to(hi));
            let (mut a, mut b) = (f64::INFINITY, f64::NEG_INFINITY);
            for t in &elites {
                let v = to(t[d]);
                a = a.min(v);
                b = b.max(v);
            }
            if !(a.is_finite() && b.is_finite()) {
                return (lo, hi);
            }
            let m = (0.25 * (b - a)).max(0.05 * (h0 - l0));
            (
                from((a - m).max(l0)).clamp(lo, hi),
                from((b + m).min(h0)).clamp(lo, hi),
            )
        })
        .collect();
    SearchSpace {
        names: search.names.clone(),
        bounds,
    }
}

/// One shard of the initialisation (for a cluster): the candidates whose index is
/// `shard mod of`, evaluated exactly as [`initialize`] evaluates them. Returns the search
/// space (the free parameters' names and bounds), the number of candidates in all shards, and
/// this shard's candidates.
/// [`InitOutcome::from_candidates`] on the union of every shard's candidates (in index order)
/// gives what [`initialize`] gives.
pub fn initialize_shard(
    problem: &VideoProblem,
    cfg: &FitConfig,
    (shard, of): (usize, usize),
    hooks: &mut dyn FitHooks,
) -> Result<(SearchSpace, usize, Vec<Candidate>), FitError> {
    if of == 0 || shard >= of {
        return Err(FitError::Input(format!(
            "shard {shard} of {of}: need 0 <= I < N"
        )));
    }
    let resolved = super::strategy::resolve(cfg, &problem.config.parts)?;
    let cfg = &resolved.config;
    if cfg.init.rounds > 1 {
        return Err(FitError::Input(format!(
            "[init] rounds = {}{}: a further round samples around the best candidates of the \
             earlier ones, so the initialisation cannot be split into shards; write rounds = 1 \
             in the fit settings' [init] table to use --shard",
            cfg.init.rounds,
            if cfg.strategy.is_auto() && !cfg.is_pinned("init.rounds") {
                " (the automatic strategy's)"
            } else {
                ""
            }
        )));
    }
    let (space, obj, search, init) = init_setup(problem, cfg)?;
    let points = init
        .candidates(&search)
        .map_err(|e| FitError::Input(format!("initialisation: {e}")))?;
    let total = points.len();
    let mine: Vec<(usize, Vec<f64>)> = points
        .into_iter()
        .enumerate()
        .filter(|(i, _)| i % of == shard)
        .collect();
    let evaluate =
        |_i: usize, theta: &[f64]| score_candidate(problem, &obj, &space, theta, cfg.init.score);
    let candidates: Vec<Candidate> = mine
        .into_par_iter()
        .map(|(index, theta)| evaluate_candidate(index, theta, &evaluate))
        .collect();
    for c in &candidates {
        hooks.on_event(&FitEvent::Candidate(c));
    }
    Ok((search, total, candidates))
}

/// The fingerprint of a video fit ([`FitState::fingerprint`]): the simulation settings and
/// starting parameters, the particles and their parts, the scene, the link, the render
/// settings, every view's camera and reference video, the frame rate, and every fit setting
/// as the automatic strategy resolves them ([`super::strategy::resolve`]) but `iters`
/// (raising it extends a finished run). The backend is not part of it.
pub fn fingerprint(problem: &VideoProblem, cfg: &FitConfig) -> String {
    let mut f = Fingerprint::new();
    f.text("video fit");
    mix_json(&mut f, &problem.config);
    let p = &problem.particles;
    f.points(&p.x);
    f.f32s(&p.volume);
    f.u32s(&p.part);
    let g = &problem.scene;
    f.word(u64::from(g.sh_degree));
    f.points(&g.means);
    f.points(&g.log_scales);
    f.word(g.quats.len() as u64);
    for q in &g.quats {
        f.f32s(q);
    }
    f.f32s(&g.opacity_logits);
    f.f32s(&g.sh);
    mix_json(&mut f, &problem.link);
    f.text(&format!("{:?}", problem.settings));
    f.word(problem.views.len() as u64);
    for v in &problem.views {
        mix_json(&mut f, &v.camera);
        f.word(v.video.frames() as u64);
        f.word(v.video.height() as u64);
        f.word(v.video.width() as u64);
        match &v.video {
            ReferenceVideo::F32(x) => f.f32s(x.data()),
            ReferenceVideo::U8(x) => f.bytes(x.data()),
        }
    }
    f.word(problem.fps.to_bits());
    // The settings that run (resolving is idempotent, so a resolved config prints the same).
    let mut settings = super::strategy::resolve(cfg, &problem.config.parts)
        .map_or_else(|_| cfg.clone(), |r| r.config);
    settings.iters = 0;
    settings.budget = None;
    settings.evals = None;
    if let Some(p) = &mut settings.pinned {
        p.retain(|k| k != "iters");
    }
    mix_json(&mut f, &settings);
    f.finish()
}

/// Runs a whole fit of `problem` with `cfg`, continuing from `resume` when given (a state
/// written by this fit: [`FitState::check`] refuses one of other inputs or settings).
pub fn run_fit(
    problem: &VideoProblem,
    cfg: &FitConfig,
    resume: Option<FitState>,
    hooks: &mut dyn FitHooks,
) -> Result<FitOutcome, FitError> {
    run_fit_with_loss(problem, cfg, Arc::new(cfg.loss.clone()), resume, hooks)
}

/// [`run_fit`] on any video loss instead of `cfg.loss` (the DMS): the iterations minimise
/// `loss` ([`VideoLoss`]; the initialisation still scores candidates by MS-SSIM). A resumed
/// state is checked against `cfg`, not against `loss`: resume with the loss it started with.
pub fn run_fit_with_loss(
    problem: &VideoProblem,
    cfg: &FitConfig,
    loss: Arc<dyn VideoLoss>,
    resume: Option<FitState>,
    hooks: &mut dyn FitHooks,
) -> Result<FitOutcome, FitError> {
    cfg.validate()?;
    let resolved = super::strategy::resolve(cfg, &problem.config.parts)?;
    let cfg = &resolved.config;
    let fit_span = hooks.heap().map(|h| h.start());
    let per_particle = cfg.granularity == Granularity::Particle;
    let mut obj = Objective::with_loss(problem, cfg.frames, loss, per_particle)?;
    obj.heap = hooks.heap();
    obj.checkpointing = cfg.checkpointing()?;
    obj.precision = cfg.precision;
    obj.set_band_rows(cfg.band_rows)?;
    let slot_parts = obj.slot_parts();
    let free = cfg.free_kinds(&problem.config.parts)?;
    let space = ParamSpace::new(cfg.granularity, &free, &slot_parts, |p, k| {
        cfg.bounds(&problem.config.parts, p, k)
    });
    let plan = cfg.plan();
    let runs = |k: StageKind| plan.contains(&k);
    if runs(StageKind::ShearRestarts) {
        // Refused before any simulation runs.
        restart_entries(&space, cfg)?;
    }
    if space.is_empty() {
        return Err(FitError::Input("no free parameter to fit".into()));
    }
    let names = space.names();
    let print = fingerprint(problem, cfg);
    let mut state = match resume {
        Some(s) => {
            s.check(&space, &print)?;
            s
        }
        None => FitState::new(names.clone(), print),
    };
    let mut budget = Budget::new(&cfg.budget, cfg.evals, &state)?;
    // Starting point: the config's parts, replaced by the initialisation's best candidate.
    let mut base_parts = problem.config.parts.clone();
    if runs(StageKind::Init) {
        let ispace = init_space(cfg, &problem.config.parts)?;
        let outcome = match state.init.take() {
            Some(o) => {
                if o.best.len() != ispace.len()
                    || o.candidates.iter().any(|c| c.theta.len() != ispace.len())
                {
                    return Err(FitError::Resume(format!(
                        "the checkpoint's initialisation searched {} parameters, this fit's searches {}",
                        o.best.len(),
                        ispace.len()
                    )));
                }
                o
            }
            None => {
                let (_, o) = initialize(problem, cfg, hooks)?;
                budget.add_evals(o.candidates.len());
                o
            }
        };
        ispace.apply(&mut base_parts, &outcome.best);
        state.init = Some(outcome);
        if state.optimizer.is_none() && state.trust.is_none() {
            budget.stamp(&mut state, obj.evaluations());
            hooks.on_checkpoint(&state);
        }
    }
    let mut base_slots: Vec<PartParams> =
        slot_parts.iter().map(|&p| base_parts[p as usize]).collect();
    // Multi-start: a short fit from each of the best candidates; the main fit continues from
    // the lowest loss any of them reached (recomputed identically on resume).
    if let (true, Some(outcome)) = (runs(StageKind::MultiStart), state.init.clone()) {
        let ispace = init_space(cfg, &problem.config.parts)?;
        let k = cfg.multi_start.min(outcome.ranking.len());
        let order = seed_order(&outcome, &ispace.bounds(), cfg.spread);
        while state.starts.len() < k && state.iters_done == 0 {
            if budget.spent(obj.evaluations()) {
                break;
            }
            let c = &outcome.candidates[order[state.starts.len()]];
            let mut parts = problem.config.parts.clone();
            ispace.apply(&mut parts, &c.theta);
            let slots0: Vec<PartParams> = slot_parts.iter().map(|&p| parts[p as usize]).collect();
            let mut o = new_stepper(cfg, &space, space.values(&slots0))?;
            let mut best: Option<(f64, Vec<f64>)> = None;
            let mut failed = None;
            for it in 0..cfg.multi_start_iters {
                if budget.spent(obj.evaluations()) {
                    break;
                }
                // A start whose simulation diverges ends there; the others go on.
                match iterate(
                    &obj,
                    &space,
                    &slots0,
                    &mut o,
                    cfg,
                    (it, cfg.multi_start_iters),
                    1.0,
                ) {
                    Ok(st) => keep_best(&mut best, st.ev.total, &st.theta),
                    Err(e) if e.is_divergence() => {
                        failed = Some(format!("iteration {it}: {e}"));
                        break;
                    }
                    Err(e) => return Err(e),
                }
            }
            let (loss, theta) = best.unwrap_or((f64::MAX, space.values(&slots0)));
            let r = StartResult {
                candidate: c.index,
                score: c.score,
                loss,
                theta,
                failed,
            };
            hooks.on_event(&FitEvent::Start(&r));
            state.starts.push(r);
            budget.stamp(&mut state, obj.evaluations());
            hooks.on_checkpoint(&state);
        }
        if let Some(b) = state
            .starts
            .iter()
            .filter(|r| r.loss < f64::MAX)
            .min_by(|a, b| a.loss.total_cmp(&b.loss))
        {
            space.apply(&mut base_slots, &b.theta);
            base_parts = part_summary(&base_parts, &slot_parts, &base_slots);
            if state.best.is_none() {
                state.best = Some((b.loss, b.theta.clone()));
            }
        }
    }
    let init_parts = base_parts.clone();
    let mut opt = match (cfg.optimizer, state.optimizer.take(), state.trust.take()) {
        (OptimizerKind::Adam, Some(o), _) => Stepper::Adam(o),
        (OptimizerKind::TrustBfgs, _, Some(o)) => Stepper::Trust(o),
        (kind, a, t) if a.is_some() || t.is_some() => {
            return Err(FitError::Resume(format!(
                "the checkpoint holds the state of another optimizer than '{}' (optimizer = ...)",
                match kind {
                    OptimizerKind::Adam => "adam",
                    OptimizerKind::TrustBfgs => "trust_bfgs",
                }
            )))
        }
        _ => new_stepper(cfg, &space, space.values(&base_slots))?,
    };
    let peak = || fit_span.as_ref().map_or(0, |s| s.peak());
    // Without the descent no iteration runs (the refining stages start from the best point
    // so far, else the starting point).
    let iters = if runs(StageKind::Descent) {
        cfg.iters
    } else {
        0
    };
    for iter in state.iters_done..iters {
        if budget.spent(obj.evaluations())
            || (cfg.descent_share < 1.0 && budget.spent_share(obj.evaluations(), cfg.descent_share))
        {
            // The iterations since the last checkpoint are kept.
            if state.iters_done % cfg.checkpoint_every != 0 {
                checkpoint_stage(&opt, &mut state, hooks, (&budget, obj.evaluations()));
            }
            break;
        }
        if consecutive_divergences(&state.diverged, iter) >= MAX_DIVERGED {
            // Nothing near the best point evaluates: the refining stages go on from there.
            break;
        }
        let start = Instant::now();
        let lr_scale = 0.5f64.powi(state.diverged.len().min(60) as i32);
        let st = match iterate(
            &obj,
            &space,
            &base_slots,
            &mut opt,
            cfg,
            (iter, cfg.iters),
            lr_scale,
        ) {
            Ok(st) => st,
            Err(e) if e.is_divergence() => {
                // A rejected step, not the end of the fit.
                state.diverged.push(iter);
                let retreat = reject_diverged(&mut opt, &state, cfg, &space, &base_slots)?;
                let run = consecutive_divergences(&state.diverged, iter + 1);
                hooks.on_event(&FitEvent::Diverged {
                    iter,
                    error: &e.to_string(),
                    retreat: retreat.as_deref(),
                    ends: run >= MAX_DIVERGED,
                    names: &names,
                });
                state.iters_done = iter + 1;
                if state.iters_done % cfg.checkpoint_every == 0
                    || state.iters_done == iters
                    || run >= MAX_DIVERGED
                {
                    checkpoint_stage(&opt, &mut state, hooks, (&budget, obj.evaluations()));
                }
                continue;
            }
            Err(e) => return Err(e),
        };
        let (ev, theta, gtheta) = (&st.ev, &st.theta, &st.gtheta);
        keep_best(&mut state.best, ev.total, theta);
        let restart = if cfg.stall > 0 {
            stall_check(&mut state, iter, ev.total, cfg.stall)
        } else {
            None
        };
        let mut rec = IterRecord::new(
            iter,
            terms_of(ev),
            &names,
            theta,
            gtheta,
            (st.grad_norm, st.lr),
            &part_summary(&base_parts, &slot_parts, &st.slots),
            (start.elapsed().as_secs_f64(), peak()),
        );
        rec.probes = st.probes;
        hooks.on_event(&FitEvent::Iter(&rec));
        if let Some(lowest) = restart {
            let seeds = stall_seeds(&state, cfg, &problem.config.parts, &space, &slot_parts)?;
            let run = state.descent.as_mut().expect("a run is recorded");
            if let Some(theta) = seeds.get(run.seed + 1) {
                run.seed += 1;
                run.lowest = None;
                run.since = iter + 1;
                run.stalls.push(iter);
                hooks.on_event(&FitEvent::Stalled {
                    iter,
                    lowest,
                    seed: run.seed,
                    theta,
                    names: &names,
                });
                opt = new_stepper(cfg, &space, theta.clone())?;
            }
        }
        state.iters_done = iter + 1;
        if state.iters_done % cfg.checkpoint_every == 0 || state.iters_done == iters {
            checkpoint_stage(&opt, &mut state, hooks, (&budget, obj.evaluations()));
        }
    }
    // The refining stages in the plan's order; a finished stage's state is in the
    // checkpoint, so a resumed fit passes it without evaluating and continues inside the
    // stage it stopped in.
    let ctx = StageCtx {
        obj: &obj,
        space: &space,
        base: &base_slots,
        opt: &opt,
        cfg,
        budget: &budget,
    };
    for &k in plan.iter().filter(|k| k.after_descent()) {
        match k {
            StageKind::Valley => valley_search(&ctx, &mut state, hooks)?,
            StageKind::ShearRestarts => shear_restarts(&ctx, &mut state, hooks)?,
            StageKind::GradientSampling => gradient_sampling(&ctx, &mut state, hooks)?,
            StageKind::Init | StageKind::MultiStart | StageKind::Descent => {}
        }
    }
    let theta = match &state.best {
        Some((_, t)) => t.clone(),
        None => opt.theta(),
    };
    let mut slots = base_slots.clone();
    space.apply(&mut slots, &theta);
    Ok(FitOutcome {
        parts: part_summary(&base_parts, &slot_parts, &slots),
        slots,
        init_parts,
        best_loss: state.best.as_ref().map(|b| b.0),
        init: state.init,
        valley: state.valley,
        sampling: state.sampling,
        restarts: state.restarts,
        budget_spent: budget.spent(obj.evaluations()),
        evaluations: budget.evals(obj.evaluations()),
        decisions: resolved.decisions,
        space,
    })
}

/// Consecutive diverged iterations of the descent after which it ends (the refining stages
/// go on from the best point). Each divergence is a rejected step: AdamW goes back to the
/// best point with its learning rate halved for the rest of the descent; the trust region
/// shrinks its radius (or, when its accepted point itself diverged, starts again at the best
/// point).
pub const MAX_DIVERGED: usize = 3;

/// How many of the iterations just before `iter` diverged in a row (`diverged` in order).
fn consecutive_divergences(diverged: &[usize], iter: usize) -> usize {
    let mut n = 0;
    for &d in diverged.iter().rev() {
        if d + n + 1 == iter {
            n += 1;
        } else {
            break;
        }
    }
    n
}

/// Rejects the step whose evaluation diverged: AdamW restarts at the best point so far (its
/// learning rate follows from the count of divergences); the trust region counts a rejected
/// trial, unless the point that diverged is its accepted one (moved there by a probe or a
/// restart), when it restarts at the best point. Returns the point the descent goes on
/// from when it moved there.
fn reject_diverged(
    opt: &mut Stepper,
    state: &FitState,
    cfg: &FitConfig,
    space: &ParamSpace,
    base_slots: &[PartParams],
) -> Result<Option<Vec<f64>>, FitError> {
    let best = match &state.best {
        Some((_, t)) => t.clone(),
        None => space.values(base_slots),
    };
    if let Stepper::Trust(o) = opt {
        if o.theta() != o.accepted_theta() {
            let n = best.len();
            o.step(f64::INFINITY, &vec![f64::NAN; n]);
            return Ok(None);
        }
    }
    *opt = new_stepper(cfg, space, best.clone())?;
    Ok(Some(best))
}

/// Records the descent's iteration `iter` at loss `loss` in its current run; the run's
/// lowest loss when the run has stalled (`stall` iterations without falling by
/// [`STALL_DROP`]).
fn stall_check(state: &mut FitState, iter: usize, loss: f64, stall: usize) -> Option<f64> {
    let run = state.descent.get_or_insert(DescentRun {
        seed: 0,
        lowest: None,
        since: iter,
        stalls: Vec::new(),
    });
    match run.lowest {
        Some(l) if !(loss.is_finite() && loss < l * (1.0 - STALL_DROP)) => {
            (iter + 1 - run.since >= stall).then_some(l)
        }
        _ if loss.is_finite() => {
            run.lowest = Some(loss);
            run.since = iter;
            None
        }
        _ => None,
    }
}

/// The scored candidates of `outcome` in the order the multi-start and the stall restarts
/// take them: by score; with `spread > 0` each next one the best-scored candidate whose
/// largest difference to every one taken before, over the parameters in units of each
/// parameter's log `bounds`, is at least `spread`, then the rest by score.
pub fn seed_order(outcome: &InitOutcome, bounds: &[(f64, f64)], spread: f64) -> Vec<usize> {
    if spread <= 0.0 {
        return outcome.ranking.clone();
    }
    let unit = |theta: &[f64]| -> Vec<f64> {
        theta
            .iter()
            .zip(bounds)
            .map(|(v, (lo, hi))| {
                let w = (hi / lo).ln();
                if w > 0.0 {
                    (v / lo).ln() / w
                } else {
                    0.0
                }
            })
            .collect()
    };
    let mut taken: Vec<(usize, Vec<f64>)> = Vec::new();
    let mut rest = Vec::new();
    for &i in &outcome.ranking {
        let u = unit(&outcome.candidates[i].theta);
        let far = taken.iter().all(|(_, t)| {
            t.iter()
                .zip(&u)
                .map(|(a, b)| (a - b).abs())
                .fold(0.0, f64::max)
                >= spread
        });
        if far {
            taken.push((i, u));
        } else {
            rest.push(i);
        }
    }
    taken.into_iter().map(|(i, _)| i).chain(rest).collect()
}

/// The seeds of the descent's runs, in order: the multi-start's starts by the loss they
/// reached (failed ones left out), then the initialisation's other candidates in
/// [`seed_order`] (each as the fit's free parameters over `slot_parts`); seed 0 is where the descent began.
fn stall_seeds(
    state: &FitState,
    cfg: &FitConfig,
    parts: &[PartParams],
    space: &ParamSpace,
    slot_parts: &[u32],
) -> Result<Vec<Vec<f64>>, FitError> {
    let Some(init) = &state.init else {
        return Ok(Vec::new());
    };
    let mut starts: Vec<&StartResult> = state.starts.iter().filter(|r| r.loss < f64::MAX).collect();
    starts.sort_by(|a, b| a.loss.total_cmp(&b.loss));
    let mut seeds: Vec<Vec<f64>> = starts.iter().map(|r| r.theta.clone()).collect();
    let ispace = init_space(cfg, parts)?;
    let started: Vec<usize> = state.starts.iter().map(|r| r.candidate).collect();
    for i in seed_order(init, &ispace.bounds(), cfg.spread) {
        let c = &init.candidates[i];
        if c.score.is_none() || started.contains(&c.index) {
            continue;
        }
        let mut p = parts.to_vec();
        ispace.apply(&mut p, &c.theta);
        let slots: Vec<PartParams> = slot_parts.iter().map(|&s| p[s as usize]).collect();
        seeds.push(space.values(&slots));
    }
    Ok(seeds)
}

/// What a refining stage works with: the objective over the free parameters (applied to
/// the `base` slots), the optimiser's point, the settings and the fit's budget. A stage
/// reads the best point so far from the [`FitState`], keeps its own state there, and
/// reports through [`FitEvent`].
#[derive(Clone, Copy)]
struct StageCtx<'a> {
    obj: &'a Objective<'a>,
    space: &'a ParamSpace,
    base: &'a [PartParams],
    opt: &'a Stepper,
    cfg: &'a FitConfig,
    budget: &'a Budget,
}

impl<'a> StageCtx<'a> {
    /// The objective as the stages' [`Evaluator`].
    fn eval(&self) -> ObjectiveEval<'a> {
        ObjectiveEval {
            obj: self.obj,
            space: self.space,
            base: self.base,
        }
    }
}

/// The valley search ([`crate::valley`]) from the lowest loss the iterations reached (the
/// optimiser's point without iterations), checkpointed after every round; a resumed fit
/// continues the search in the checkpoint. Its points are evaluated in parallel, loss only.
fn valley_search(
    ctx: &StageCtx,
    state: &mut FitState,
    hooks: &mut dyn FitHooks,
) -> Result<(), FitError> {
    let StageCtx {
        obj,
        space,
        base: _,
        opt,
        cfg,
        budget,
    } = *ctx;
    let names = space.names();
    let mut search = match state.valley.take() {
        Some(s) => s,
        None => {
            let (loss, theta) = match &state.best {
                Some((l, t)) => (Some(*l), t.clone()),
                None => (None, opt.theta()),
            };
            ValleySearch::new(&theta, loss, &space.bounds(), &cfg.valley)
                .map_err(|e| FitError::Input(format!("the valley search's starting point: {e}")))?
        }
    };
    let eval = ctx.eval();
    while !search.done && search.evals < cfg.valley.evals && !budget.spent(obj.evaluations()) {
        let left = (cfg.valley.evals - search.evals)
            .min(budget.evals_left(obj.evaluations()).unwrap_or(usize::MAX));
        let Some(round) = search.round(&cfg.valley, left, &eval) else {
            break;
        };
        if let Some(l) = search.loss() {
            keep_best(&mut state.best, l, &search.theta());
        }
        hooks.on_event(&FitEvent::Valley {
            round: &round,
            names: &names,
            theta: &search.theta(),
        });
        state.valley = Some(search.clone());
        checkpoint_stage(opt, state, hooks, (budget, obj.evaluations()));
    }
    state.valley = Some(search);
    Ok(())
}

/// Gradient sampling ([`crate::sampling`]) from the lowest loss reached so far (the
/// iterations' and the valley search's), checkpointed after every iteration; a resumed fit
/// continues it. The sampled gradients and the line search's points run in parallel.
fn gradient_sampling(
    ctx: &StageCtx,
    state: &mut FitState,
    hooks: &mut dyn FitHooks,
) -> Result<(), FitError> {
    let StageCtx {
        obj,
        space,
        base: base_slots,
        opt,
        cfg,
        budget,
    } = *ctx;
    let names = space.names();
    let mut search = match state.sampling.take() {
        Some(s) => s,
        None => {
            let (loss, theta) = best_or_evaluate(obj, space, base_slots, opt, state)?;
            GradientSampling::new(&theta, loss, &space.bounds(), &cfg.gradient_sampling)
                .map_err(|e| FitError::Input(format!("gradient sampling's starting point: {e}")))?
        }
    };
    let eval = ctx.eval();
    while !budget.spent(obj.evaluations()) {
        let Some(round) = search.round(&cfg.gradient_sampling, &eval) else {
            break;
        };
        keep_best(&mut state.best, search.loss, &search.theta());
        hooks.on_event(&FitEvent::Sampling {
            round: &round,
            names: &names,
            theta: &search.theta(),
        });
        state.sampling = Some(search.clone());
        checkpoint_stage(opt, state, hooks, (budget, obj.evaluations()));
    }
    state.sampling = Some(search);
    Ok(())
}

/// The lowest point so far (every free parameter) and its loss; without one, the
/// optimiser's point, evaluated.
fn best_or_evaluate(
    obj: &Objective,
    space: &ParamSpace,
    base_slots: &[PartParams],
    opt: &Stepper,
    state: &FitState,
) -> Result<(f64, Vec<f64>), FitError> {
    Ok(match &state.best {
        Some((l, t)) => (*l, t.clone()),
        None => {
            let theta = opt.theta();
            let mut slots = base_slots.to_vec();
            space.apply(&mut slots, &theta);
            (obj.value(&slots)?.total, theta)
        }
    })
}

/// The entries of `shear_restarts.part`'s `E` and `nu` and the other free parameters;
/// refused, naming what is free, unless both are free and something else is.
fn restart_entries(
    space: &ParamSpace,
    cfg: &FitConfig,
) -> Result<(usize, usize, Vec<usize>), FitError> {
    let part = cfg.shear_restarts.part as usize;
    let find = |kind: ParamKind| {
        space
            .entries
            .iter()
            .position(|e| e.kind == kind && e.slot.is_none_or(|s| s == part))
    };
    let (Some(ie), Some(inu)) = (
        find(ParamKind::YoungsModulus),
        find(ParamKind::PoissonRatio),
    ) else {
        return Err(FitError::Input(format!(
            "shear_restarts: part {part}'s E and nu must both be free (free: {})",
            space.names().join(", ")
        )));
    };
    let others: Vec<usize> = (0..space.len()).filter(|&i| i != ie && i != inu).collect();
    if others.is_empty() {
        return Err(FitError::Input(
            "shear_restarts: needs a free parameter besides E and nu to re-fit at each restart"
                .into(),
        ));
    }
    Ok((ie, inu, others))
}

/// Restarts along constant bulk modulus ([`crate::restarts`]) from the lowest point so far:
/// at each, `E` and `nu` of `shear_restarts.part` fixed, gradient sampling over the other
/// free parameters; checkpointed after every inner iteration, resumed where it stopped.
fn shear_restarts(
    ctx: &StageCtx,
    state: &mut FitState,
    hooks: &mut dyn FitHooks,
) -> Result<(), FitError> {
    let StageCtx {
        obj,
        space,
        base: base_slots,
        opt,
        cfg,
        budget,
    } = *ctx;
    let rc = &cfg.shear_restarts;
    let names = space.names();
    let (ie, inu, others) = restart_entries(space, cfg)?;
    let bounds = space.bounds();
    let sub_bounds: Vec<(f64, f64)> = others.iter().map(|&i| bounds[i]).collect();
    let sub_names: Vec<String> = others.iter().map(|&i| names[i].clone()).collect();
    let inner = SamplingConfig {
        iters: rc.inner_iters,
        ..cfg.gradient_sampling
    };
    let mut st = match state.restarts.take() {
        Some(s) => s,
        None => {
            let (loss, theta) = best_or_evaluate(obj, space, base_slots, opt, state)?;
            ShearRestarts::new(theta, loss)
        }
    };
    let origin = st.origin.clone();
    let (k0, g0) = k_g_from_e_nu(origin[ie], origin[inu]);
    let e_nu = |k: i32| {
        let (e, nu) = e_nu_from_k_g(k0, g0 * rc.factor.powi(k));
        (
            e.clamp(bounds[ie].0, bounds[ie].1),
            nu.clamp(bounds[inu].0, bounds[inu].1),
        )
    };
    // Every free parameter from the restart's E and nu and the others' logs.
    let full = |(e, nu): (f64, f64), sub_log: &[f64]| {
        let mut t = origin.clone();
        t[ie] = e;
        t[inu] = nu;
        for (&i, v) in others.iter().zip(sub_log) {
            t[i] = v.exp();
        }
        t
    };
    let slots_of = |theta: &[f64]| {
        let mut slots = base_slots.to_vec();
        space.apply(&mut slots, theta);
        slots
    };
    loop {
        let (k, mut gs) = match st.current.take() {
            Some(c) => c,
            None => {
                let Some(k) = st.next_k(rc) else { break };
                let sub_log: Vec<f64> = others.iter().map(|&i| origin[i].ln()).collect();
                let theta = full(e_nu(k), &sub_log);
                let loss = obj
                    .value(&slots_of(&theta))
                    .map_or(f64::INFINITY, |e| e.total);
                if !loss.is_finite() {
                    // A restart whose simulation fails is a wall of the profile.
                    let (e, nu) = e_nu(k);
                    let r = Restart {
                        k,
                        e,
                        nu,
                        loss,
                        theta,
                        inner: None,
                    };
                    hooks.on_event(&FitEvent::Restart {
                        restart: &r,
                        names: &names,
                    });
                    st.done.push(r);
                    continue;
                }
                let sub: Vec<f64> = others.iter().map(|&i| theta[i]).collect();
                let gs = GradientSampling::new(&sub, loss, &sub_bounds, &inner).map_err(|e| {
                    FitError::Input(format!("shear restart {k}'s starting point: {e}"))
                })?;
                (k, gs)
            }
        };
        let at = e_nu(k);
        let whole = ctx.eval();
        let eval = RestartEval {
            eval: &whole,
            full: |p: &[f64]| full(at, p),
            others: &others,
        };
        while !budget.spent(obj.evaluations()) {
            let Some(round) = gs.round(&inner, &eval) else {
                break;
            };
            hooks.on_event(&FitEvent::Sampling {
                round: &round,
                names: &sub_names,
                theta: &gs.theta(),
            });
            st.current = Some((k, gs.clone()));
            state.restarts = Some(st.clone());
            checkpoint_stage(opt, state, hooks, (budget, obj.evaluations()));
        }
        let r = Restart {
            k,
            e: at.0,
            nu: at.1,
            loss: gs.loss,
            theta: full(at, &gs.x),
            inner: Some(gs),
        };
        hooks.on_event(&FitEvent::Restart {
            restart: &r,
            names: &names,
        });
        keep_best(&mut state.best, r.loss, &r.theta);
        st.done.push(r);
        st.current = None;
        state.restarts = Some(st.clone());
        checkpoint_stage(opt, state, hooks, (budget, obj.evaluations()));
    }
    state.restarts = Some(st);
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A scored candidate with `E` and density.
    fn cand(index: usize, e: f64, rho: f64, score: f64) -> Candidate {
        Candidate {
            index,
            theta: vec![e, rho],
            score: Some(score),
            error: None,
        }
    }

    /// Spread seeds: by score, skipping candidates within `spread` (max norm in the unit box
    /// of the log bounds) of a seed taken before, those coming last; 0: by score only.
    #[test]
    fn seeds_are_taken_by_score_at_least_spread_apart() {
        // Bounds of 4 and 2 decades: E 1e3..1e7, density 1e2..1e4.
        let bounds = [(1e3, 1e7), (1e2, 1e4)];
        let outcome = InitOutcome::from_candidates(
            vec![
                cand(0, 1e5, 1e3, 0.9),
                // 0.1 decade of E from #0 (0.025 of its bounds): the same basin.
                cand(1, 1.26e5, 1e3, 0.8),
                // One decade of E from #0 (0.25 of its bounds).
                cand(2, 1e6, 1e3, 0.7),
                // 0.4 decade of density from #0 (0.2 of its bounds) and far from #2.
                cand(3, 1e5, 2.5e3, 0.6),
                cand(4, 1e3, 1e2, f64::NAN),
            ],
            4,
        )
        .unwrap();
        assert_eq!(seed_order(&outcome, &bounds, 0.0), vec![0, 1, 2, 3]);
        assert_eq!(seed_order(&outcome, &bounds, 0.15), vec![0, 2, 3, 1]);
        assert_eq!(seed_order(&outcome, &bounds, 0.22), vec![0, 2, 1, 3]);
    }

    /// A further round's box holds the best candidates, widened, and stays in the bounds.
    #[test]
    fn a_further_round_samples_around_the_best_candidates() {
        let search = SearchSpace::new(
            vec!["E".into(), "density".into()],
            vec![(1e3, 1e7), (1e2, 1e4)],
        )
        .unwrap();
        let outcome = InitOutcome::from_candidates(
            vec![
                cand(0, 1e5, 1e3, 0.9),
                cand(1, 2e5, 2e3, 0.8),
                cand(2, 1e6, 1.5e2, 0.7),
                cand(3, 1e3, 1e4, 0.1),
            ],
            4,
        )
        .unwrap();
        let b = narrowed(&search, &outcome, 16, &[false, false]).bounds;
        // The best three: E in [1e5, 1e6] (1 decade, margin 0.25), density in [150, 2000].
        assert!((b[0].0 - 10f64.powf(4.75)).abs() / b[0].0 < 1e-9, "{b:?}");
        assert!((b[0].1 - 10f64.powf(6.25)).abs() / b[0].1 < 1e-9, "{b:?}");
        assert!(
            b[1].0 >= 1e2 && b[1].0 < 150.0 && b[1].1 > 2e3 && b[1].1 < 1e4,
            "{b:?}"
        );
        // A single elite point: the box is a twentieth of the bounds on each side.
        let one = InitOutcome::from_candidates(vec![cand(0, 1e7, 1e2, 1.0)], 1).unwrap();
        let b = narrowed(&search, &one, 8, &[false, false]).bounds;
        assert_eq!(b[0].1, 1e7);
        assert!((b[0].0 - 10f64.powf(6.8)).abs() / b[0].0 < 1e-9, "{b:?}");
        assert_eq!(b[1].0, 1e2);
    }
}
