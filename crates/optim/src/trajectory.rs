//! Fitting part parameters to target particle trajectories with exact adjoint gradients
//! (trajectory supervision; `r4d fit-trajectory` is its command line), on any
//! simulator backend.
//!
//! Each iteration runs the simulation forward with checkpoints, evaluates a
//! [`TrajectoryLoss`] at every frame against the targets, sweeps backward through every
//! substep (`r4d_mpm::adjoint`, the one driver `r4d_mpm::Simulation` on the backend) and
//! updates the free parameters with AdamW in the log domain — the iteration the video fit
//! runs too (`descent::iterate`: one parameter mapping, [`crate::space::ParamSpace`], one
//! step, one best-so-far rule, one error type). The caller picks the backend
//! ([`crate::compute::Compute`]; its simulation runs in f64 where it has a choice): the states
//! stay on the backend, only the positions of each frame come back for the loss and its
//! gradient goes back to the position adjoint on the backend.

use crate::compute::{Compute, Precision};
use crate::descent::{self, keep_best, Rate, Stepper};
use crate::space::{part_summary, ParamSpace};
use crate::{AdamW, LogDomainOptimizer, LrSchedule, ParamKind};
use r4d_mpm::adjoint::checkpoint::{value_and_grad, Checkpointing};
use r4d_mpm::adjoint::host::{HostSim, PhysParams};
use r4d_mpm::adjoint::trajectory_loss::TrajectoryLoss;
use r4d_mpm::simulation::AnyState;
use r4d_mpm::{DynSimulation, PartParams, ParticleSet, SimConfig};
use std::cell::RefCell;
use std::sync::Arc;
use std::time::Instant;

use crate::record::{mix_json, Fingerprint, Terms};
pub use crate::record::{FitState, IterRecord, PartRecord};
pub use crate::space::Granularity;
pub use crate::FitError;

/// The result of a fit.
#[derive(Clone, Debug, PartialEq)]
pub struct Fitted {
    /// Parameters per part (for per-particle fits: the geometric mean over each part's
    /// particles).
    pub parts: Vec<PartParams>,
    /// Per-particle parameters, for per-particle fits.
    pub per_particle: Option<Vec<PartParams>>,
}

/// Options of [`fit_trajectory`].
#[derive(Clone, Debug)]
pub struct FitOptions {
    /// Free parameters.
    pub params: Vec<ParamKind>,
    /// Iterations.
    pub iters: usize,
    /// AdamW settings; `adam.lr` is the base rate of `schedule`.
    pub adam: AdamW,
    /// Learning-rate schedule (default: cosine decay to 5% of `adam.lr`).
    pub schedule: LrSchedule,
    /// Gradient-norm clip in log space.
    pub clip_norm: Option<f64>,
    /// Loss.
    pub loss: TrajectoryLoss,
    /// Checkpointing of the reverse sweep.
    pub checkpointing: Checkpointing,
    /// Part or object parameters.
    pub granularity: Granularity,
}

impl Default for FitOptions {
    fn default() -> Self {
        FitOptions {
            params: vec![ParamKind::YoungsModulus],
            iters: 30,
            adam: AdamW {
                lr: 0.3,
                beta1: 0.5,
                ..Default::default()
            },
            clip_norm: Some(1.0),
            schedule: LrSchedule::Cosine,
            loss: TrajectoryLoss::Position,
            checkpointing: Checkpointing::PerFrame,
            granularity: Granularity::Part,
        }
    }
}

/// Fits the free parameters of `config`'s parts so that the simulation of `scene` follows
/// `targets` (positions at frames 1, 2, ...). The starting point is the config's parameters.
/// `on_iter` sees every iteration's record. Returns the parameters with the lowest loss
/// evaluated.
pub fn fit_trajectory(
    compute: &dyn Compute,
    config: &SimConfig,
    scene: &ParticleSet,
    targets: &[Vec<[f32; 3]>],
    opts: &FitOptions,
    on_iter: impl FnMut(&IterRecord),
) -> Result<Vec<PartParams>, FitError> {
    fit_trajectory_resumable(compute, config, scene, targets, opts, None, on_iter, |_| {})
        .map(|f| f.parts)
}

/// Per-part geometric means of per-particle parameters (`part` gives each particle's part).
fn part_means(config: &SimConfig, part: &[u32], values: &[PartParams]) -> Vec<PartParams> {
    part_summary(&config.parts, part, values)
}

/// The fingerprint of a trajectory fit ([`FitState::fingerprint`]): the simulation settings
/// and starting parameters, the particles, the targets and every option but `iters`.
pub fn fingerprint(
    config: &SimConfig,
    scene: &ParticleSet,
    targets: &[Vec<[f32; 3]>],
    opts: &FitOptions,
) -> String {
    let mut f = Fingerprint::new();
    f.text("trajectory fit");
    mix_json(&mut f, config);
    f.points(&scene.x);
    f.f32s(&scene.volume);
    f.u32s(&scene.part);
    f.word(targets.len() as u64);
    for t in targets {
        f.points(t);
    }
    let mut o = opts.clone();
    o.iters = 0;
    f.text(&format!("{o:?}"));
    f.finish()
}

/// [`fit_trajectory`] that starts from `resume` when given (a state this fit wrote:
/// [`FitState::check`] refuses one of other inputs or options) and hands a [`FitState`] to
/// `on_checkpoint` after every iteration (to be written to disk, [`FitState::to_json`]).
#[allow(clippy::too_many_arguments)]
pub fn fit_trajectory_resumable(
    compute: &dyn Compute,
    config: &SimConfig,
    scene: &ParticleSet,
    targets: &[Vec<[f32; 3]>],
    opts: &FitOptions,
    resume: Option<FitState>,
    mut on_iter: impl FnMut(&IterRecord),
    mut on_checkpoint: impl FnMut(&FitState),
) -> Result<Fitted, FitError> {
    if targets.is_empty() {
        return Err(FitError::Input("no target frames".into()));
    }
    opts.adam.validate()?;
    if opts.loss == TrajectoryLoss::Position {
        if let Some((f, t)) = targets
            .iter()
            .enumerate()
            .find(|(_, t)| t.len() != scene.len())
        {
            return Err(FitError::Input(format!(
                "target frame {} has {} points but the simulation has {} particles; the position loss needs corresponding particles (use the chamfer loss)",
                f + 1,
                t.len(),
                scene.len()
            )));
        }
    }
    let per_particle = opts.granularity == Granularity::Particle;
    let sim = if per_particle {
        HostSim::new(config, scene)?.per_particle()
    } else {
        HostSim::new(config, scene)?
    };
    let stepper = compute.simulation(Precision::F64, Arc::new(sim.clone()))?;
    let backend_error = |e| FitError::sim(stepper.backend_name(), e);
    // Parameter values per slot: per part, or per particle.
    let base: Vec<PartParams> = if per_particle {
        scene
            .part
            .iter()
            .map(|&p| config.parts[p as usize])
            .collect()
    } else {
        config.parts.clone()
    };
    let slot_parts: Vec<u32> = if per_particle {
        scene.part.clone()
    } else {
        (0..config.parts.len() as u32).collect()
    };
    let summarize = |values: &[PartParams]| {
        if per_particle {
            part_means(config, &scene.part, values)
        } else {
            values.to_vec()
        }
    };
    // The free parameters (one mapping for every fit): `opts.params` of every slot, or of
    // the whole object, in the order given.
    let free = vec![opts.params.clone(); config.parts.len()];
    crate::space::check_free(&config.parts, &free, opts.granularity).map_err(FitError::Input)?;
    let mut space = ParamSpace::new(opts.granularity, &free, &slot_parts, |_, k| {
        k.default_bounds()
    });
    space.entries.sort_by_key(|e| {
        (
            e.slot,
            opts.params.iter().position(|&k| k == e.kind).unwrap_or(0),
        )
    });
    let theta = space.values(&base);
    let names = space.names();
    let mut state = match resume {
        Some(s) => {
            s.check(&space, &fingerprint(config, scene, targets, opts))?;
            s
        }
        None => FitState::new(names.clone(), fingerprint(config, scene, targets, opts)),
    };
    let opt = match state.optimizer.take() {
        Some(o) => o,
        None => LogDomainOptimizer::new(theta, space.bounds(), opts.adam, opts.clip_norm)?,
    };
    let mut opt = Stepper::Adam(opt);
    let spf = sim.setup.substeps_per_frame;
    let frames = targets.len().min(config.time.frames.max(1));
    let substeps = frames as u64 * spf as u64;
    let rate = Rate {
        schedule: opts.schedule,
        base: opts.adam.lr,
        iters: opts.iters,
    };
    for iter in state.iters_done..opts.iters {
        let start = Instant::now();
        let it = descent::iterate(&space, &base, &mut opt, rate, iter, |slots| {
            let sweep = Sweep {
                sim: &sim,
                parts: slots,
                targets,
                loss: opts.loss,
                checkpointing: opts.checkpointing,
                frames,
                spf,
                substeps,
            };
            let (loss, grad) = sweep.run(&*stepper).map_err(backend_error)?;
            Ok(((), loss, grad))
        })?;
        keep_best(&mut state.best, it.loss, &it.theta);
        on_iter(&IterRecord::new(
            iter,
            Terms {
                total: it.loss,
                ..Terms::default()
            },
            &names,
            &it.theta,
            &it.gtheta,
            (it.grad_norm, it.lr),
            &summarize(&it.slots),
            (start.elapsed().as_secs_f64(), 0),
        ));
        state.iters_done = iter + 1;
        if let Stepper::Adam(optimizer) = &opt {
            state.optimizer = Some(optimizer.clone());
            on_checkpoint(&state);
            state.optimizer = None;
        }
    }
    let theta = match &state.best {
        Some((_, t)) => t.clone(),
        None => opt.theta(),
    };
    let mut values = base.clone();
    space.apply(&mut values, &theta);
    Ok(Fitted {
        parts: summarize(&values),
        per_particle: per_particle.then_some(values),
    })
}
/// One evaluation of the loss and of its parameter gradient (per slot, with the yield stress
/// gradient of the initial state).
struct Sweep<'a> {
    sim: &'a HostSim,
    parts: &'a [PartParams],
    targets: &'a [Vec<[f32; 3]>],
    loss: TrajectoryLoss,
    checkpointing: Checkpointing,
    frames: usize,
    spf: u32,
    substeps: u64,
}

impl Sweep<'_> {
    /// One evaluation on any backend. The loss of each frame is evaluated in f64 on the
    /// downloaded positions during the forward pass; its gradient is kept and added to the
    /// position adjoint on the backend when the reverse sweep reaches the frame.
    fn run(&self, d: &dyn DynSimulation) -> Result<(f64, Vec<PhysParams<f64>>), r4d_mpm::Error> {
        let (sim, targets, loss_kind) = (self.sim, self.targets, self.loss);
        let phys = d.params(self.parts);
        let init = d.init(&phys, &vec![[0.0; 3]; sim.len()])?;
        let scale = 1.0 / self.frames as f64;
        let error: RefCell<Option<r4d_mpm::Error>> = RefCell::new(None);
        // Each frame's position gradient, from the forward pass to its reverse hook.
        let frame_grads: RefCell<Vec<Option<Vec<[f64; 3]>>>> =
            RefCell::new(vec![None; self.frames + 1]);
        // The loss at frame `f` of the state `s` and its (scaled) gradient.
        let eval = |f: usize, s: &AnyState| -> Option<(f64, Vec<[f64; 3]>)> {
            let x = match d.positions_f64(s) {
                Ok(v) => v,
                Err(e) => {
                    error.borrow_mut().get_or_insert(e);
                    return None;
                }
            };
            let mut g = vec![[0.0f64; 3]; x.len()];
            let l = loss_kind.value_and_grad(&x, &targets[f - 1], &mut g);
            let g = g.iter().map(|gp| gp.map(|v| scale * v)).collect();
            Some((scale * l, g))
        };
        let (loss, adj0, grad) = value_and_grad(
            d,
            &init,
            &phys,
            self.substeps,
            self.spf,
            self.checkpointing,
            d.zero_grad()?,
            |f, s| match eval(f, s) {
                Some((l, g)) => {
                    frame_grads.borrow_mut()[f] = Some(g);
                    l
                }
                None => f64::NAN,
            },
            |f, s, adj| {
                let cached = frame_grads.borrow_mut()[f].take();
                let Some(g) = cached.or_else(|| eval(f, s).map(|(_, g)| g)) else {
                    return;
                };
                if let Err(e) = d.add_to_x(adj, &g) {
                    error.borrow_mut().get_or_insert(e);
                }
            },
        )?;
        if let Some(e) = error.into_inner() {
            return Err(e);
        }
        Ok((loss, d.gradient(&grad, &adj0, &phys)?))
    }
}
