//! Settings of a video fit (`r4d fit --config FIT.toml`). Every key is optional.
//!
//! ```toml
//! iters = 40              # AdamW iterations
//! lr = 0.1                # learning rate in log units per step
//! lr_schedule = "cosine"  # or "constant"; cosine decays to 5% of lr
//! beta1 = 0.7
//! beta2 = 0.99
//! weight_decay = 0.0      # decoupled, on xi = log(theta)
//! clip_norm = 1.0         # gradient-norm clip in log space (0: off)
//! granularity = "part"    # "object" or "particle" (the paper's ablation)
//! checkpointing = "per_frame"  # "store_all", "every_n:K" or "nested:K"
//! precision = "f64"       # or "f32"
//! band_rows = 128         # rows per band of the band-wise loss (memory vs re-projection)
//! frames = 16             # video frames fitted (default: all)
//! checkpoint_every = 1    # iterations between checkpoints
//! flat_probe = 6          # points probed along a parameter whose gradient is exactly 0
//! optimizer = "adam"      # or "trust_bfgs" (first trust radius = lr)
//! multi_start = 1         # short fits from the best K candidates (1: off)
//! multi_start_iters = 5   # iterations of each
//! free = ["E", "density"] # free parameters of every part (default: by material)
//! # stages = ["init", "descent", "valley"]  # what runs, in order (default: what the tables
//! #                       # below turn on); a listed stage must be able to run
//! # budget = "15m"        # wall-clock budget of the whole fit (default: none)
//! # evals = 200           # evaluation budget of the whole fit (default: none)
//!
//! [valley]                # the valley search after the iterations (r4d_optim::valley)
//! evals = 0               # loss evaluations it may spend (0: off)
//!
//! [gradient_sampling]     # after the valley search (r4d_optim::sampling)
//! iters = 0               # iterations (0: off)
//! radius = 0.003          # of the sampled gradients, log units
//! samples = 3             # gradients sampled per iteration besides the point's
//!
//! [shear_restarts]        # after the valley search (r4d_optim::restarts)
//! points = 0              # restarts along constant bulk modulus (0: off)
//! factor = 0.8            # shear-modulus ratio between neighbouring restarts
//! part = 0                # whose E and nu move
//! inner_iters = 6         # gradient-sampling iterations over the rest at each restart
//!
//! [loss]                  # the DMS loss (r4d_loss::DmsConfig); ablations:
//! weights = { l1 = 0.0, spatial = 1.0, mag = 1.0, phase = 1.0 }
//! [loss.spectral]         # omitted keys take r4d_loss's defaults
//! phase_mask = 1e-3       # the fit's default (see default_loss)
//!
//! [init]                  # simulation-driven initialisation
//! enabled = true
//! candidates = 32         # Latin hypercube samples in log10 space
//! sampler = "latin_hypercube" # or "grid": a log10 grid of at most `candidates` points;
//!                              # or "natural": nu and the friction angle sampled uniformly
//! frames = 16             # frames simulated per candidate
//! seed = 0
//! top_k = 4
//!
//! [[parts]]               # per-part overrides
//! id = 0
//! free = ["E", "nu", "density"]
//! bounds = { E = [1e4, 1e6] }
//! ```

use crate::compute::Precision;
use crate::space::{check_free, default_free, Granularity};
use crate::FitError;
use crate::{AdamW, ParamKind, RestartsConfig, SamplingConfig, ValleyConfig};
use r4d_loss::DmsConfig;
use r4d_mpm::adjoint::checkpoint::Checkpointing;
use r4d_mpm::PartParams;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::Path;

pub use crate::LrSchedule;

/// The optimiser of a fit.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum OptimizerKind {
    /// AdamW on `log(theta)` (the paper's).
    #[default]
    Adam,
    /// Trust-region damped BFGS on `log(theta)` (`r4d_optim::TrustRegionBfgs`).
    TrustBfgs,
}

/// The simulation-driven initialisation (paper Sec. 3.3).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct InitConfig {
    /// Run it (otherwise the fit starts from the simulation config's parameters).
    pub enabled: bool,
    /// Latin hypercube candidates (the paper: 32).
    pub candidates: usize,
    /// Video frames simulated and compared per candidate (the paper: 16).
    pub frames: usize,
    /// Seed of the sampler.
    pub seed: u64,
    /// Best candidates kept in the log.
    pub top_k: usize,
    /// Also evaluate the simulation config's parameters as a candidate.
    pub include_start: bool,
    /// How candidates are sampled: `latin_hypercube` (default, the paper's; seeded) or
    /// `grid` (the centres of a log10 grid with at most `candidates` points; no seed). Not
    /// part of the checkpoint's fingerprint while the default.
    #[serde(skip_serializing_if = "InitSampler::is_default")]
    pub sampler: InitSampler,
    /// Rounds of candidates: each round after the first samples `candidates` more (a
    /// Latin hypercube) inside the box of the best ones so far
    /// ([`crate::video::fit::narrowed`]). Default 1. Not part of the checkpoint's
    /// fingerprint while 1.
    #[serde(skip_serializing_if = "is_one")]
    pub rounds: usize,
    /// How candidates are ranked: `ms_ssim` (default, the paper's: MS-SSIM against the
    /// reference, higher is better) or `loss` (the fit's own loss over the same frames; the
    /// candidate's score is the negated loss, so higher is still better). Not part of the
    /// checkpoint's fingerprint while the default.
    #[serde(skip_serializing_if = "InitScore::is_default")]
    pub score: InitScore,
}

/// How the initialisation ranks its candidates (`[init] score`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum InitScore {
    /// MS-SSIM of the candidate's video against the reference (the paper's choice).
    #[default]
    MsSsim,
    /// The fit's loss (negated, so that a higher score is better): candidates are ranked by
    /// what the iterations then minimise.
    Loss,
}

impl InitScore {
    /// Whether it is the default (MS-SSIM).
    pub fn is_default(&self) -> bool {
        *self == InitScore::MsSsim
    }
}

fn is_one(n: &usize) -> bool {
    *n == 1
}

fn is_zero(n: &usize) -> bool {
    *n == 0
}

fn is_zero_f64(v: &f64) -> bool {
    *v == 0.0
}

fn is_one_f64(v: &f64) -> bool {
    *v == 1.0
}

/// The relative fall of the descent's lowest loss that counts as progress for
/// [`FitConfig::stall`].
pub const STALL_DROP: f64 = 1e-4;

/// How the initialisation samples its candidates (`[init] sampler`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum InitSampler {
    /// A seeded Latin hypercube in log10 space ([`crate::LatinHypercubeInit`]).
    #[default]
    LatinHypercube,
    /// The centres of a regular log10 grid ([`crate::LogGridInit`]).
    Grid,
    /// A seeded Latin hypercube, log-uniform over the parameters that span decades and
    /// uniform over Poisson's ratio and the friction angle ([`crate::NaturalScaleInit`]).
    Natural,
}

impl InitSampler {
    /// Whether it is the default (Latin hypercube).
    pub fn is_default(&self) -> bool {
        *self == InitSampler::LatinHypercube
    }
}

impl Default for InitConfig {
    fn default() -> Self {
        InitConfig {
            enabled: true,
            candidates: 32,
            frames: 16,
            seed: 0,
            top_k: 4,
            include_start: false,
            sampler: InitSampler::LatinHypercube,
            rounds: 1,
            score: InitScore::MsSsim,
        }
    }
}

/// Per-part overrides.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PartFit {
    /// Part index.
    pub id: usize,
    /// Free parameters of this part.
    pub free: Option<Vec<String>>,
    /// Bounds per parameter name, `[lo, hi]`.
    pub bounds: BTreeMap<String, [f64; 2]>,
}

/// A stage of the video fit (`stages = [...]`); each stage's settings are in its own table.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum StageKind {
    /// The simulation-driven initialisation (`[init]`).
    Init,
    /// Short fits from the best candidates (`multi_start`, `multi_start_iters`).
    MultiStart,
    /// The gradient iterations (`iters`, `optimizer`, `lr`, ...).
    Descent,
    /// The valley search (`[valley]`).
    Valley,
    /// Restarts along constant bulk modulus (`[shear_restarts]`).
    ShearRestarts,
    /// Gradient sampling (`[gradient_sampling]`).
    GradientSampling,
}

impl StageKind {
    /// Every stage, in the order the fit runs them when `stages` is not given.
    pub const ALL: [StageKind; 6] = [
        StageKind::Init,
        StageKind::MultiStart,
        StageKind::Descent,
        StageKind::Valley,
        StageKind::ShearRestarts,
        StageKind::GradientSampling,
    ];

    /// The name in `stages` (`init`, `multi_start`, ...).
    pub fn name(self) -> &'static str {
        match self {
            StageKind::Init => "init",
            StageKind::MultiStart => "multi_start",
            StageKind::Descent => "descent",
            StageKind::Valley => "valley",
            StageKind::ShearRestarts => "shear_restarts",
            StageKind::GradientSampling => "gradient_sampling",
        }
    }

    /// Whether it refines the point the descent reached (runs after it, in any order).
    pub fn after_descent(self) -> bool {
        matches!(
            self,
            StageKind::Valley | StageKind::ShearRestarts | StageKind::GradientSampling
        )
    }
}

/// The settings the automatic strategy decides (`strategy = "auto"`), each named as in
/// `FIT.toml`; `pinned` keeps any of them as written.
pub const AUTO_KEYS: &[&str] = &[
    "iters",
    "optimizer",
    "flat_probe",
    "multi_start",
    "multi_start_iters",
    "spread",
    "stall",
    "init.enabled",
    "init.candidates",
    "init.rounds",
    "init.sampler",
    "init.score",
];

/// The keys of [`AUTO_KEYS`] that `table` (a `FIT.toml`) writes.
fn written_keys(table: &toml::Table) -> Vec<String> {
    AUTO_KEYS
        .iter()
        .filter(|k| match k.split_once('.') {
            Some((t, key)) => table
                .get(t)
                .and_then(|v| v.as_table())
                .is_some_and(|t| t.contains_key(key)),
            None => table.contains_key(**k),
        })
        .map(|k| k.to_string())
        .collect()
}

/// Settings of a video fit.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct FitConfig {
    /// `auto` (default): the settings of [`AUTO_KEYS`] are decided from the problem
    /// ([`crate::video::strategy`]), except those `pinned`; `fixed`: every setting as
    /// written. Not part of the checkpoint's fingerprint while `auto`.
    #[serde(skip_serializing_if = "super::strategy::Strategy::is_auto")]
    pub strategy: super::strategy::Strategy,
    /// Under `strategy = "auto"`: the settings (of [`AUTO_KEYS`]) kept as written instead of
    /// decided. [`FitConfig::load`] sets it to those the file writes, unless the file lists
    /// `pinned` itself (a saved config does); `None` (a config built in code): none. Not
    /// part of the checkpoint's fingerprint while `None`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub pinned: Option<Vec<String>>,
    /// The stages that run, in order: `init`, `multi_start`, `descent` (in that order when
    /// listed), then any of `valley`, `shear_restarts`, `gradient_sampling` in the order
    /// listed. Unlisted stages do not run; a listed one must be able to (its budget above
    /// zero, `[init] enabled`). Without it ([`FitConfig::plan`]), every stage whose settings
    /// turn it on, in the order above. Not part of the checkpoint's fingerprint while unset.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub stages: Option<Vec<StageKind>>,
    /// A wall-clock budget for the whole fit (`"15m"`, `"1h30m"`, `"900s"`): once spent, no
    /// new iteration or round starts and the fit ends with the lowest point so far
    /// ([`crate::video::budget`]). Counted over every sitting of a resumed fit; not part of
    /// the fingerprint (a larger budget extends a finished fit).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub budget: Option<String>,
    /// An evaluation budget for the whole fit (simulations run, the initialisation's
    /// candidates included), like `budget`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub evals: Option<usize>,
    /// AdamW iterations.
    pub iters: usize,
    /// Learning rate (log units per step).
    pub lr: f64,
    /// Schedule of the learning rate.
    pub lr_schedule: LrSchedule,
    /// Adam's first-moment decay.
    pub beta1: f64,
    /// Adam's second-moment decay.
    pub beta2: f64,
    /// Adam's denominator guard.
    pub eps: f64,
    /// Decoupled weight decay on `xi = log(theta)`.
    pub weight_decay: f64,
    /// Gradient-norm clip in log space (0: none).
    pub clip_norm: f64,
    /// Part (default), object or particle parameters.
    pub granularity: Granularity,
    /// `per_frame` (default), `store_all`, `every_n:K` or `nested:K` (frame checkpoints,
    /// then every `K` substeps inside a frame during the backward pass).
    pub checkpointing: String,
    /// Precision of the simulation.
    pub precision: Precision,
    /// Rows per band of the band-wise loss evaluation (rounded up to a multiple of 16):
    /// smaller bands hold less memory, larger ones project the Gaussians fewer times; the
    /// loss is the same.
    pub band_rows: usize,
    /// Video frames fitted (default: all).
    pub frames: Option<usize>,
    /// Iterations between checkpoints.
    pub checkpoint_every: usize,
    /// Free parameters of every part (default: by material, see
    /// [`default_free`]).
    pub free: Option<Vec<String>>,
    /// The loss (default: [`default_loss`]).
    pub loss: DmsConfig,
    /// Initialisation.
    pub init: InitConfig,
    /// Per-part overrides.
    pub parts: Vec<PartFit>,
    /// Flat-direction probe: when the gradient of a yield stress, plastic viscosity,
    /// friction angle, hardening or softening coefficient is exactly zero at an iteration (no particle is on the branch of the
    /// return mapping it acts through, e.g. a yield stress so high that nothing yields), the
    /// loss is evaluated at this many log-spaced values across the parameter's bounds, the
    /// others fixed, and the parameter jumps to the best one when that lowers the loss
    /// (its Adam moments restart). 0: off. Default 6 (see `docs/fitting-measurements.md`).
    pub flat_probe: usize,
    /// Multi-start: the best this-many initialisation candidates each get a short fit of
    /// `multi_start_iters` iterations (extra to `iters`); the fit continues from the lowest
    /// loss any of them reached. 1: off (the best candidate only). Part and object fits
    /// with the initialisation only.
    pub multi_start: usize,
    /// Iterations of each short fit of a multi-start.
    pub multi_start_iters: usize,
    /// Restarts of the descent where it stalls: when its lowest loss has not fallen by
    /// [`STALL_DROP`] (0.01%: no new low) in this many iterations, the descent starts again from the next
    /// seed — the multi-start's other starts by the loss they reached, then the further
    /// initialisation candidates by score (see `spread`) — and the fit's result is the lowest point of all
    /// its runs. 0: off (the default). Part and object fits with the initialisation only.
    /// Not part of the checkpoint's fingerprint while 0.
    #[serde(skip_serializing_if = "is_zero")]
    pub stall: usize,
    /// How far apart the seeds of the multi-start and of the stall restarts are: with
    /// `spread > 0` each next seed is the best-scored candidate at least `spread` away from
    /// every seed taken before (the largest difference over the parameters, in units of each
    /// parameter's log bounds), then the rest by score; 0 (the default): by score only. The
    /// best candidates of a narrowed round cluster in one basin, and a wrong one then holds
    /// every start. Not part of the checkpoint's fingerprint while 0.
    #[serde(skip_serializing_if = "is_zero_f64")]
    pub spread: f64,
    /// The share of the fit's budget (`budget`, `evals`) after which the descent ends and
    /// the refining stages (valley search, shear restarts, gradient sampling) get the rest;
    /// 1 (the default): the descent may spend all of it. Without a budget: no effect. Not
    /// part of the checkpoint's fingerprint while 1.
    #[serde(skip_serializing_if = "is_one_f64")]
    pub descent_share: f64,
    /// The step: `adam` (AdamW, the paper's) or `trust_bfgs` (a trust-region quasi-Newton
    /// step, `r4d_optim::TrustRegionBfgs`, whose first radius is `lr`).
    pub optimizer: OptimizerKind,
    /// The valley search after the iterations ([`crate::valley`]): a derivative-free walk
    /// along the shallow parameters with the sharp ones re-centred at every point, for
    /// losses whose minimum lies along a curved valley between V-shaped walls (the full-size
    /// plasticine demo, `docs/fitting-measurements.md`). Off unless `valley.evals > 0`; part and object
    /// fits only. Not part of the checkpoint's fingerprint while off.
    #[serde(skip_serializing_if = "ValleyConfig::is_off")]
    pub valley: ValleyConfig,
    /// Gradient sampling after the valley search ([`crate::sampling`]): steps against the
    /// minimum-norm element of exact gradients sampled around the point, which follows a
    /// narrow V-shaped trench that runs diagonally to the parameters. Off unless
    /// `gradient_sampling.iters > 0`; part and object fits only. Not part of the
    /// checkpoint's fingerprint while off.
    #[serde(skip_serializing_if = "SamplingConfig::is_off")]
    pub gradient_sampling: SamplingConfig,
    /// Restarts along constant bulk modulus after the valley search ([`crate::restarts`]):
    /// a profile of the loss over a part's shear modulus, each restart's other free
    /// parameters re-fitted by gradient sampling (its `radius`, `samples`, `step` and `seed`
    /// from `[gradient_sampling]`). Off unless `shear_restarts.points > 0`; part and object
    /// fits only. Not part of the checkpoint's fingerprint while off.
    #[serde(skip_serializing_if = "RestartsConfig::is_off")]
    pub shear_restarts: RestartsConfig,
}

impl Default for FitConfig {
    fn default() -> Self {
        FitConfig {
            strategy: Default::default(),
            pinned: None,
            stages: None,
            budget: None,
            evals: None,
            iters: 40,
            lr: 0.1,
            lr_schedule: LrSchedule::Cosine,
            beta1: 0.7,
            beta2: 0.99,
            eps: 1e-8,
            weight_decay: 0.0,
            clip_norm: 1.0,
            granularity: Granularity::Part,
            checkpointing: "per_frame".into(),
            precision: Precision::F64,
            band_rows: super::problem::DEFAULT_BAND_ROWS,
            frames: None,
            checkpoint_every: 1,
            free: None,
            loss: default_loss(),
            init: InitConfig::default(),
            parts: Vec::new(),
            flat_probe: 6,
            multi_start: 1,
            multi_start_iters: 5,
            stall: 0,
            spread: 0.0,
            descent_share: 1.0,
            optimizer: OptimizerKind::Adam,
            valley: ValleyConfig::default(),
            gradient_sampling: SamplingConfig::default(),
            shear_restarts: RestartsConfig::default(),
        }
    }
}

/// The paper's DMS loss with a phase mask of 1e-3: entries where either spectrum is (near)
/// zero carry no phase gradient (without it a patch the fit moves but the reference keeps
/// still gives gradients of order `1 / eps`; see `r4d_loss::spectral`). A `[loss.spectral]`
/// table in `FIT.toml` starts from the library's defaults (no mask) for the keys it omits;
/// `phase_mask = 0.0` switches the mask off.
pub fn default_loss() -> DmsConfig {
    let mut c = DmsConfig::default();
    c.spectral.phase_mask = Some(1e-3);
    c
}

/// Parses parameter names (case-insensitive): an unknown name is an error with the closest
/// known name, and a parameter named twice (`free = ["E", "E"]`, or `E` and `e`) is an error.
fn kinds(names: &[String], what: &str) -> Result<Vec<ParamKind>, FitError> {
    let mut out: Vec<ParamKind> = Vec::with_capacity(names.len());
    for (i, n) in names.iter().enumerate() {
        let k = parse_kind(n, what)?;
        if let Some(j) = out.iter().position(|&o| o == k) {
            return Err(FitError::Input(format!(
                "{what}: parameter {} given twice (`{}` and `{n}`, entries {j} and {i})",
                k.name(),
                names[j]
            )));
        }
        out.push(k);
    }
    Ok(out)
}

/// Parses one parameter name; an unknown one names the closest known name.
fn parse_kind(n: &str, what: &str) -> Result<ParamKind, FitError> {
    ParamKind::parse(n).map_err(|e| {
        let all: Vec<&str> = ParamKind::ALL.iter().map(|k| k.name()).collect();
        let hint = r4d_mpm::strict::suggest(n, &all)
            .map(|s| format!(": did you mean `{s}`?"))
            .unwrap_or_default();
        FitError::Input(format!("{what}: {e}{hint} (known: {})", all.join(", ")))
    })
}

/// The kinds of a part override's `bounds` keys; a parameter bounded twice (`E` and `e`) is an
/// error.
fn bound_kinds(p: &PartFit) -> Result<Vec<(ParamKind, &String)>, FitError> {
    let mut out: Vec<(ParamKind, &String)> = Vec::with_capacity(p.bounds.len());
    for n in p.bounds.keys() {
        let k = parse_kind(n, &format!("parts id {}: bounds", p.id))?;
        if let Some((_, first)) = out.iter().find(|(o, _)| *o == k) {
            return Err(FitError::Input(format!(
                "parts id {}: bounds of {} given twice (`{first}` and `{n}`)",
                p.id,
                k.name()
            )));
        }
        out.push((k, n));
    }
    Ok(out)
}

/// Bounds for a parameter that is not free would be ignored: an error naming the key.
fn check_bounds_are_free(p: &PartFit, free: &[ParamKind], whence: &str) -> Result<(), FitError> {
    for (k, n) in bound_kinds(p)? {
        if !free.contains(&k) {
            let list: Vec<&str> = free.iter().map(|k| k.name()).collect();
            return Err(FitError::Input(format!(
                "parts id {}: bounds.{n}: {} is not a free parameter of part {} (free, {whence}: \
                 {}): remove its bounds or add it to free",
                p.id,
                k.name(),
                p.id,
                if list.is_empty() {
                    "none".to_string()
                } else {
                    list.join(", ")
                }
            )));
        }
    }
    Ok(())
}

/// The most Latin hypercube candidates an initialisation may evaluate (`[init] candidates`,
/// `r4d demo --candidates`).
pub const MAX_INIT_CANDIDATES: usize = 10_000;

/// The most frames an initialisation may simulate in all: `[init] candidates x [init] frames`.
pub const MAX_INIT_FRAME_EVALS: u64 = 1_000_000;

/// The most iterations a fit may ask for (`iters`, `r4d demo --iters`).
pub const MAX_ITERS: usize = 1_000_000;

/// The most rounds of initialisation candidates (`[init] rounds`).
pub const MAX_INIT_ROUNDS: usize = 16;

/// Checks a candidate count against [`MAX_INIT_CANDIDATES`]; the message starts with
/// `candidates = N` (callers prefix the key or flag).
pub fn check_candidates(n: usize) -> Result<(), String> {
    if n > MAX_INIT_CANDIDATES {
        return Err(format!(
            "candidates = {n}: at most {MAX_INIT_CANDIDATES} (MAX_INIT_CANDIDATES)"
        ));
    }
    Ok(())
}

/// Checks an iteration count against [`MAX_ITERS`]; the message starts with `iters = N`.
pub fn check_iters(n: usize) -> Result<(), String> {
    if n > MAX_ITERS {
        return Err(format!("iters = {n}: at most {MAX_ITERS} (MAX_ITERS)"));
    }
    Ok(())
}

impl FitConfig {
    /// The stages this fit runs, in order: `stages` when given, else every stage whose
    /// settings turn it on (`[init] enabled`, `multi_start > 1`, the descent always,
    /// `[valley] evals`, `[shear_restarts] points`, `[gradient_sampling] iters` above zero) in
    /// the order of [`StageKind::ALL`].
    pub fn plan(&self) -> Vec<StageKind> {
        if let Some(s) = &self.stages {
            return s.clone();
        }
        StageKind::ALL
            .into_iter()
            .filter(|&k| match k {
                StageKind::Init => self.init.enabled,
                StageKind::MultiStart => self.multi_start > 1,
                StageKind::Descent => true,
                StageKind::Valley => !self.valley.is_off(),
                StageKind::ShearRestarts => !self.shear_restarts.is_off(),
                StageKind::GradientSampling => !self.gradient_sampling.is_off(),
            })
            .collect()
    }

    /// The plan in words, one stage after the other with its budget
    /// (`init (32 candidates x 16 frames) -> descent (40 iterations, adam)`).
    pub fn describe_plan(&self) -> String {
        self.plan()
            .iter()
            .map(|&k| {
                let budget = match k {
                    StageKind::Init if self.init.rounds > 1 => format!(
                        "{} rounds x {} candidates x {} frames",
                        self.init.rounds, self.init.candidates, self.init.frames
                    ),
                    StageKind::Init => format!(
                        "{} candidates x {} frames",
                        self.init.candidates, self.init.frames
                    ),
                    StageKind::MultiStart => format!(
                        "{} starts x {} iterations",
                        self.multi_start, self.multi_start_iters
                    ),
                    StageKind::Descent => format!(
                        "{}, {}{}",
                        if self.iters == MAX_ITERS {
                            "until the budget".to_string()
                        } else {
                            format!("{} iterations", self.iters)
                        },
                        match self.optimizer {
                            OptimizerKind::Adam => "adam",
                            OptimizerKind::TrustBfgs => "trust_bfgs",
                        },
                        if self.stall > 0 {
                            format!(
                                ", restarted after {} iterations without progress",
                                self.stall
                            )
                        } else {
                            String::new()
                        }
                    ),
                    StageKind::Valley => format!("{} evaluations", self.valley.evals),
                    StageKind::ShearRestarts => format!("{} points", self.shear_restarts.points),
                    StageKind::GradientSampling => {
                        format!("{} iterations", self.gradient_sampling.iters)
                    }
                };
                format!("{} ({budget})", k.name())
            })
            .collect::<Vec<_>>()
            .join(" -> ")
            + &match (&self.budget, self.evals) {
                (Some(b), Some(n)) => format!("; budget {b} or {n} evaluations"),
                (Some(b), None) => format!("; budget {b}"),
                (None, Some(n)) => format!("; budget {n} evaluations"),
                (None, None) => String::new(),
            }
    }

    /// Checks an explicit `stages` list: no stage twice, `init`, `multi_start`, `descent` in
    /// that order and before the refining stages, and every listed stage able to run.
    fn check_stages(&self) -> Result<(), FitError> {
        let Some(list) = &self.stages else {
            return Ok(());
        };
        let bad = |m: String| Err(FitError::Input(format!("stages: {m}")));
        if list.is_empty() {
            return bad("empty: list at least one stage (or leave `stages` out)".into());
        }
        for (i, k) in list.iter().enumerate() {
            if list[..i].contains(k) {
                return bad(format!("'{}' is listed twice", k.name()));
            }
        }
        let rank = |k: StageKind| match k {
            StageKind::Init => 0,
            StageKind::MultiStart => 1,
            StageKind::Descent => 2,
            _ => 3,
        };
        for w in list.windows(2) {
            if rank(w[0]) > rank(w[1]) || (rank(w[0]) == rank(w[1]) && rank(w[0]) < 3) {
                return bad(format!(
                    "'{}' cannot run after '{}' (init, multi_start and descent come in that \
                     order, before valley, shear_restarts and gradient_sampling)",
                    w[1].name(),
                    w[0].name()
                ));
            }
        }
        for &k in list {
            let off = match k {
                StageKind::Init => (!self.init.enabled).then_some("[init] enabled = false"),
                StageKind::MultiStart => {
                    (self.multi_start < 2).then_some("multi_start < 2 (it needs 2 or more starts)")
                }
                StageKind::Descent => (self.iters == 0).then_some("iters = 0"),
                StageKind::Valley => self.valley.is_off().then_some("[valley] evals = 0"),
                StageKind::ShearRestarts => self
                    .shear_restarts
                    .is_off()
                    .then_some("[shear_restarts] points = 0"),
                StageKind::GradientSampling => self
                    .gradient_sampling
                    .is_off()
                    .then_some("[gradient_sampling] iters = 0"),
            };
            if let Some(why) = off {
                return bad(format!("'{}' is listed but cannot run: {why}", k.name()));
            }
        }
        Ok(())
    }

    /// Reads a TOML file (decoded by `r4d_mpm::strict`: an unknown key at any depth names its
    /// path and the closest known key) and validates it.
    pub fn load(path: &Path) -> Result<FitConfig, FitError> {
        let text = r4d_fsio::read_to_string_bounded(path, r4d_fsio::MAX_TEXT_BYTES)
            .map_err(|e| FitError::Input(format!("{}: {e}", path.display())))?;
        let mut c: FitConfig = r4d_mpm::strict::decode(&text, r4d_mpm::strict::Format::Toml)
            .map_err(|e| FitError::Input(format!("{}: {e}", path.display())))?;
        if !c.strategy.is_fixed() && c.pinned.is_none() {
            // Decoded above, so the text is valid TOML.
            let table: toml::Table = text
                .parse()
                .map_err(|e| FitError::Input(format!("{}: {e}", path.display())))?;
            c.pinned = Some(written_keys(&table));
        }
        c.validate()
            .map_err(|e| FitError::Input(format!("{}: {e}", path.display())))?;
        Ok(c)
    }

    /// Whether the automatic strategy keeps `key` (one of [`AUTO_KEYS`]) as written.
    pub fn is_pinned(&self, key: &str) -> bool {
        self.pinned
            .as_ref()
            .is_some_and(|p| p.iter().any(|k| k == key))
    }

    /// The config with `key` (one of [`AUTO_KEYS`]) added to `pinned`: the automatic
    /// strategy keeps its value as set.
    pub fn pin(mut self, key: &str) -> Self {
        let p = self.pinned.get_or_insert_with(Vec::new);
        if !p.iter().any(|k| k == key) {
            p.push(key.to_string());
            p.sort();
        }
        self
    }

    /// Checks the values.
    pub fn validate(&self) -> Result<(), FitError> {
        let bad = |m: String| Err(FitError::Input(m));
        // lr, beta1, beta2, eps, weight_decay: the one check every command uses.
        self.adam()
            .validate()
            .map_err(|e| FitError::Input(e.to_string()))?;
        if !(self.clip_norm.is_finite() && self.clip_norm >= 0.0) {
            return bad(format!("clip_norm = {} must be >= 0", self.clip_norm));
        }
        if self.band_rows == 0 {
            return bad("band_rows = 0: at least 1 (rounded up to 16)".into());
        }
        if self.checkpoint_every == 0 {
            return bad("checkpoint_every must be at least 1".into());
        }
        for k in self.pinned.iter().flatten() {
            if !AUTO_KEYS.contains(&k.as_str()) {
                return bad(r4d_mpm::strict::unknown_value("pinned", k, AUTO_KEYS));
            }
        }
        self.check_stages()?;
        if let Some(b) = &self.budget {
            super::budget::parse_duration(b)
                .map_err(|e| FitError::Input(format!("budget = {e}")))?;
        }
        if self.evals == Some(0) {
            return bad("evals = 0: the fit's evaluation budget must be at least 1".into());
        }
        let runs = |k: StageKind| self.plan().contains(&k);
        if !(1..=MAX_INIT_ROUNDS).contains(&self.init.rounds) {
            return bad(format!(
                "init.rounds = {}: must be in 1..={MAX_INIT_ROUNDS} (MAX_INIT_ROUNDS)",
                self.init.rounds
            ));
        }
        if runs(StageKind::Init) && self.init.candidates == 0 {
            return bad("init.candidates must be at least 1".into());
        }
        check_candidates(self.init.candidates).map_err(|m| FitError::Input(format!("init.{m}")))?;
        let evals = (self.init.candidates as u64)
            .saturating_mul(self.init.frames as u64)
            .saturating_mul(self.init.rounds as u64);
        if runs(StageKind::Init) && evals > MAX_INIT_FRAME_EVALS {
            return bad(format!(
                "init.candidates x init.frames x init.rounds = {} x {} x {} = {evals} simulated \
                 frames, more than the {MAX_INIT_FRAME_EVALS} an initialisation may simulate \
                 (MAX_INIT_FRAME_EVALS)",
                self.init.candidates, self.init.frames, self.init.rounds
            ));
        }
        check_iters(self.iters).map_err(FitError::Input)?;
        if self.flat_probe == 1 || self.flat_probe > 64 {
            return bad(format!(
                "flat_probe = {}: 0 (off) or 2..=64 points",
                self.flat_probe
            ));
        }
        if self.multi_start == 0 || self.multi_start > 64 {
            return bad(format!(
                "multi_start = {}: 1 (off) to 64 starts",
                self.multi_start
            ));
        }
        self.valley.validate().map_err(FitError::Input)?;
        if !self.valley.is_off() && self.granularity == Granularity::Particle {
            return bad("valley.evals > 0: part and object fits only".into());
        }
        self.gradient_sampling.validate().map_err(FitError::Input)?;
        if !self.gradient_sampling.is_off() && self.granularity == Granularity::Particle {
            return bad("gradient_sampling.iters > 0: part and object fits only".into());
        }
        self.shear_restarts.validate().map_err(FitError::Input)?;
        if !self.shear_restarts.is_off() && self.granularity == Granularity::Particle {
            return bad("shear_restarts.points > 0: part and object fits only".into());
        }
        if runs(StageKind::MultiStart) {
            if !runs(StageKind::Init) {
                return bad("multi_start > 1 needs the initialisation (init.enabled)".into());
            }
            if self.granularity == Granularity::Particle {
                return bad("multi_start > 1: part and object fits only".into());
            }
            if self.multi_start_iters == 0 {
                return bad("multi_start_iters must be at least 1".into());
            }
        }
        if !(self.descent_share.is_finite()
            && self.descent_share > 0.0
            && self.descent_share <= 1.0)
        {
            return bad(format!(
                "descent_share = {}: must be in (0, 1] (a share of the budget)",
                self.descent_share
            ));
        }
        if !(self.spread.is_finite() && (0.0..1.0).contains(&self.spread)) {
            return bad(format!(
                "spread = {}: must be in [0, 1) (a share of each parameter's log bounds)",
                self.spread
            ));
        }
        if self.stall > 0 {
            if !runs(StageKind::Init) || !runs(StageKind::Descent) {
                return bad(format!(
                    "stall = {}: restarting a stalled descent needs the initialisation and the \
                     descent (its seeds are the initialisation's candidates)",
                    self.stall
                ));
            }
            if self.granularity == Granularity::Particle {
                return bad(format!("stall = {}: part and object fits only", self.stall));
            }
        }
        if self.init.frames < 2 {
            return bad("init.frames must be at least 2".into());
        }
        if let Some(f) = self.frames.filter(|&f| f < 2) {
            return bad(format!(
                "frames = {f}: at least 2 (the loss compares motion between frames)"
            ));
        }
        let mut ids: Vec<usize> = self.parts.iter().map(|p| p.id).collect();
        ids.sort_unstable();
        if let Some(w) = ids.windows(2).find(|w| w[0] == w[1]) {
            return bad(format!("[[parts]] id {} appears twice", w[0]));
        }
        self.checkpointing()?;
        if let Some(f) = &self.free {
            kinds(f, "free")?;
        }
        for p in &self.parts {
            let free = match (&p.free, &self.free) {
                (Some(f), _) => Some((kinds(f, &format!("parts id {}: free", p.id))?, "its free")),
                (None, Some(f)) => Some((kinds(f, "free")?, "the top-level free")),
                (None, None) => None,
            };
            bound_kinds(p)?;
            if let Some((free, whence)) = &free {
                check_bounds_are_free(p, free, whence)?;
            }
            for (n, [lo, hi]) in &p.bounds {
                if !(lo.is_finite() && hi.is_finite() && *lo > 0.0 && hi >= lo) {
                    return bad(format!(
                        "parts id {}: bounds of {n} [{lo}, {hi}] must be positive and ordered",
                        p.id
                    ));
                }
            }
            // Each end must be a valid value of its parameter (the simulator's own rule and
            // `PARAM_LIMITS`), or every candidate beyond it would fail after simulating.
            for (k, n) in bound_kinds(p)? {
                for v in p.bounds[n] {
                    let mut q = PartParams::default();
                    crate::space::set(&mut q, k, v);
                    q.validate(&format!("parts id {}: bounds of {n}", p.id))
                        .map_err(|e| FitError::Input(e.to_string()))?;
                }
            }
        }
        self.loss
            .validate()
            .map_err(|e| FitError::Input(format!("loss: {e}")))
    }

    /// The checkpointing strategy.
    pub fn checkpointing(&self) -> Result<Checkpointing, FitError> {
        Checkpointing::parse(&self.checkpointing).map_err(FitError::Input)
    }

    /// AdamW settings.
    pub fn adam(&self) -> AdamW {
        AdamW {
            lr: self.lr,
            beta1: self.beta1,
            beta2: self.beta2,
            eps: self.eps,
            weight_decay: self.weight_decay,
        }
    }

    /// Free kinds of every part.
    pub fn free_kinds(&self, parts: &[PartParams]) -> Result<Vec<Vec<ParamKind>>, FitError> {
        if let Some(o) = self.parts.iter().find(|o| o.id >= parts.len()) {
            return Err(FitError::Input(format!(
                "[[parts]] id {}: the simulation has {} part(s) (ids 0..={})",
                o.id,
                parts.len(),
                parts.len().saturating_sub(1)
            )));
        }
        parts
            .iter()
            .enumerate()
            .map(|(i, p)| {
                match self
                    .parts
                    .iter()
                    .find(|o| o.id == i)
                    .and_then(|o| o.free.as_ref())
                    .or(self.free.as_ref())
                {
                    Some(names) => kinds(names, &format!("part {i}")),
                    None => Ok(default_free(p)),
                }
            })
            .collect::<Result<Vec<_>, FitError>>()
            .and_then(|free| {
                for o in &self.parts {
                    let whence = match (&o.free, &self.free) {
                        (Some(_), _) => "its free",
                        (None, Some(_)) => "the top-level free",
                        (None, None) => "by its material",
                    };
                    check_bounds_are_free(o, &free[o.id], whence)?;
                }
                check_free(parts, &free, self.granularity)
                    .map_err(FitError::Input)
                    .map(|()| free)
            })
    }

    /// Bounds of `kind` for `part` of `parts` (the fit's starting parameters): the override
    /// when `[[parts]]` gives one, else the default for the part's material
    /// ([`ParamKind::default_bounds_for`]) widened to hold the part's starting value, so that a
    /// default never moves a value the inputs give (PhysFlow's `nu = 0.4995`, a density of
    /// 2e4). For the object (`part` = `None`): the default, widened to hold every part's value.
    pub fn bounds(&self, parts: &[PartParams], part: Option<usize>, kind: ParamKind) -> (f64, f64) {
        let given = part
            .and_then(|i| self.parts.iter().find(|o| o.id == i))
            .and_then(|o| {
                o.bounds
                    .iter()
                    .find(|(n, _)| ParamKind::parse(n).ok() == Some(kind))
            })
            .map(|(_, b)| (b[0], b[1]));
        if let Some(b) = given {
            return b;
        }
        let starts: Vec<&PartParams> = match part {
            Some(i) => parts.get(i).into_iter().collect(),
            None => parts.iter().collect(),
        };
        let (mut lo, mut hi) = match starts.as_slice() {
            [p] => kind.default_bounds_for(p.material),
            _ => kind.default_bounds(),
        };
        for p in starts {
            let v = crate::space::get(p, kind);
            if v.is_finite() && v > 0.0 {
                lo = lo.min(v);
                hi = hi.max(v);
            }
        }
        (lo, hi)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A default never moves a starting value the inputs give; an override is kept as given.
    #[test]
    fn default_bounds_hold_the_starting_values() {
        let newtonian = PartParams {
            material: r4d_mpm::Material::Newtonian,
            poisson_ratio: 0.4995,
            density_kg_m3: 2e4,
            ..Default::default()
        };
        let jelly = PartParams {
            poisson_ratio: 0.3,
            ..Default::default()
        };
        let parts = [newtonian, jelly];
        let c = FitConfig::default();
        assert_eq!(
            c.bounds(&parts, Some(0), ParamKind::PoissonRatio),
            (0.3, 0.4999)
        );
        assert_eq!(
            c.bounds(&parts, Some(1), ParamKind::PoissonRatio),
            (0.01, 0.49)
        );
        assert_eq!(c.bounds(&parts, Some(0), ParamKind::Density), (1e2, 2e4));
        assert_eq!(c.bounds(&parts, None, ParamKind::Density), (1e2, 2e4));
        let mut given = FitConfig::default();
        given.parts.push(PartFit {
            id: 0,
            free: None,
            bounds: [("density".to_string(), [500.0, 1500.0])].into(),
        });
        assert_eq!(
            given.bounds(&parts, Some(0), ParamKind::Density),
            (500.0, 1500.0)
        );
    }

    /// Settings that used to be silently changed or ignored are errors.
    #[test]
    fn silent_settings_are_refused() {
        let ok = FitConfig::default();
        ok.validate().unwrap();
        let frames0 = FitConfig {
            frames: Some(0),
            ..Default::default()
        };
        assert!(frames0
            .validate()
            .unwrap_err()
            .to_string()
            .contains("frames = 0"));
        let mut zero = FitConfig::default();
        zero.loss.weights = r4d_loss::DmsWeights {
            l1: 0.0,
            spatial: 0.0,
            mag: 0.0,
            phase: 0.0,
        };
        assert!(zero.validate().is_err(), "all-zero loss weights");
        let part = |id| PartFit {
            id,
            free: None,
            bounds: Default::default(),
        };
        let twice = FitConfig {
            parts: vec![part(0), part(0)],
            ..Default::default()
        };
        assert!(twice.validate().unwrap_err().to_string().contains("twice"));
        let unknown = FitConfig {
            parts: vec![part(5)],
            ..Default::default()
        };
        unknown.validate().unwrap();
        let e = unknown
            .free_kinds(&[PartParams::default(), PartParams::default()])
            .unwrap_err()
            .to_string();
        assert!(e.contains("id 5") && e.contains("2 part"), "{e}");
        let bad_ck = FitConfig {
            checkpointing: "every:0".into(),
            ..Default::default()
        };
        assert!(bad_ck.validate().is_err());
    }

    /// `[gradient_sampling]`: parsed from TOML, refused naming its key, unknown keys
    /// refused, particle fits refused.
    #[test]
    fn gradient_sampling_settings_parse_and_bad_ones_are_refused() {
        let parse = |t: &str| toml::from_str::<FitConfig>(t);
        let c = parse("[gradient_sampling]\niters = 12\nradius = 0.01\n").unwrap();
        assert_eq!(
            (c.gradient_sampling.iters, c.gradient_sampling.radius),
            (12, 0.01)
        );
        assert!(parse("[gradient_sampling]\niters = 1\nwidth = 2.0\n").is_err());
        let e = parse("[gradient_sampling]\niters = 2\nsamples = 0\n")
            .unwrap()
            .validate()
            .unwrap_err()
            .to_string();
        assert!(e.contains("gradient_sampling.samples"), "{e}");
        let e = parse("granularity = \"particle\"\n[gradient_sampling]\niters = 2\n")
            .unwrap()
            .validate()
            .unwrap_err()
            .to_string();
        assert!(e.contains("gradient_sampling"), "{e}");
        let off = serde_json::to_string(&FitConfig::default()).unwrap();
        assert!(!off.contains("gradient_sampling"), "{off}");
    }

    /// `[valley]`: parsed from TOML, refused naming its key, unknown keys refused, and
    /// off unless `evals > 0` (then not part of the serialised settings, so a fit's
    /// fingerprint does not change with it).
    #[test]
    fn stage_lists_parse_order_and_refuse_what_cannot_run() {
        let parse = |t: &str| toml::from_str::<FitConfig>(t);
        // Without a list: the stages the settings turn on, in the fixed order.
        let mut c = FitConfig::default();
        assert_eq!(c.plan(), [StageKind::Init, StageKind::Descent]);
        c.valley.evals = 100;
        c.gradient_sampling.iters = 3;
        c.multi_start = 2;
        assert_eq!(
            c.plan(),
            [
                StageKind::Init,
                StageKind::MultiStart,
                StageKind::Descent,
                StageKind::Valley,
                StageKind::GradientSampling
            ]
        );
        // A list: refining stages in any order after the descent.
        let c = parse(
            "stages = [\"init\", \"descent\", \"gradient_sampling\", \"valley\"]\n\
             [valley]\nevals = 100\n[gradient_sampling]\niters = 3\n",
        )
        .unwrap();
        c.validate().unwrap();
        assert_eq!(c.plan()[2], StageKind::GradientSampling);
        let refused = |t: &str, want: &str| {
            let e = parse(t).unwrap().validate().unwrap_err().to_string();
            assert!(e.contains(want), "{t}: {e}");
        };
        refused(
            "stages = [\"descent\", \"valley\"]\n",
            "'valley' is listed but cannot run: [valley] evals = 0",
        );
        refused(
            "stages = [\"descent\", \"init\"]\n",
            "'init' cannot run after 'descent'",
        );
        refused(
            "stages = [\"descent\", \"descent\"]\n",
            "'descent' is listed twice",
        );
        refused("stages = []\n", "stages: empty");
        refused("iters = 0\nstages = [\"descent\"]\n", "iters = 0");
        refused(
            "stages = [\"multi_start\", \"descent\"]\nmulti_start = 2\n",
            "needs the initialisation",
        );
        refused("stages = [\"init\", \"multi_start\"]\n", "multi_start < 2");
        assert!(parse("stages = [\"anneal\"]\n").is_err());
        // Unset, it is not serialised: a default config's fingerprint is unchanged.
        assert!(!toml::to_string(&FitConfig::default())
            .unwrap()
            .contains("stages"));
    }

    /// Under the automatic strategy, the decided settings a file writes are pinned, a saved
    /// config's own `pinned` list survives a round trip, and a fixed file pins nothing.
    #[test]
    fn a_loaded_file_pins_the_decided_settings_it_writes() {
        let dir = std::env::temp_dir().join(format!("r4d-pins-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let load = |name: &str, text: &str| {
            let p = dir.join(name);
            std::fs::write(&p, text).unwrap();
            FitConfig::load(&p)
        };
        let c = load(
            "a.toml",
            "iters = 5
lr = 0.2
[init]
candidates = 9
frames = 4
",
        )
        .unwrap();
        assert_eq!(
            c.pinned.as_deref(),
            Some(&["iters".to_string(), "init.candidates".to_string()][..])
        );
        assert!(c.is_pinned("iters") && !c.is_pinned("init.rounds"));
        // A saved config: its list, not its keys (toml writes every key).
        let saved = toml::to_string(&c).unwrap();
        assert!(!saved.contains("strategy"), "auto is the default: {saved}");
        assert_eq!(load("b.toml", &saved).unwrap().pinned, c.pinned);
        let fixed = load("c.toml", "strategy = \"fixed\"\niters = 5\n").unwrap();
        assert_eq!(fixed.pinned, None);
        assert!(toml::to_string(&fixed)
            .unwrap()
            .contains("strategy = \"fixed\""));
        let e = load("d.toml", "pinned = [\"iter\"]\n")
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("d.toml") && e.contains("`iter`") && e.contains("iters"),
            "{e}"
        );
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn init_sampler_parses_and_stays_out_of_the_default_fingerprint() {
        let parse = |t: &str| toml::from_str::<FitConfig>(t);
        let c = parse("[init]\nsampler = \"grid\"\ncandidates = 9\n").unwrap();
        assert_eq!(c.init.sampler, InitSampler::Grid);
        assert!(parse("[init]\nsampler = \"sobol\"\n").is_err());
        // The default is not serialised, so a default config's fingerprint is unchanged.
        let text = toml::to_string(&FitConfig::default()).unwrap();
        assert!(!text.contains("sampler"), "{text}");
        assert!(toml::to_string(&c).unwrap().contains("sampler = \"grid\""));
    }

    #[test]
    fn valley_settings_parse_and_bad_ones_are_refused() {
        let parse = |t: &str| toml::from_str::<FitConfig>(t);
        let c = parse("[valley]\nevals = 150\nsweeps = 1\n").unwrap();
        assert_eq!((c.valley.evals, c.valley.sweeps), (150, 1));
        c.validate().unwrap();
        assert!(parse("[valley]\nevals = 1\nsharpness = 2.0\n").is_err());
        let e = parse("[valley]\nevals = 10\nprobe = -1.0\n")
            .unwrap()
            .validate()
            .unwrap_err()
            .to_string();
        assert!(e.contains("valley.probe"), "{e}");
        let e = parse("granularity = \"particle\"\n[valley]\nevals = 10\n")
            .unwrap()
            .validate()
            .unwrap_err()
            .to_string();
        assert!(e.contains("valley"), "{e}");
        let off = serde_json::to_string(&FitConfig::default()).unwrap();
        assert!(!off.contains("valley"), "{off}");
    }

    /// A free parameter named twice, a bound given twice, a bound for a parameter that is not
    /// free, or a misspelt name is an error naming the key (never silently ignored).
    #[test]
    fn free_parameters_and_bounds_are_checked_against_each_other() {
        let parse = |t: &str| toml::from_str::<FitConfig>(t).unwrap();
        let e = parse("free = [\"E\", \"E\"]\n")
            .validate()
            .unwrap_err()
            .to_string();
        assert!(e.contains("free: parameter E given twice"), "{e}");
        let e = parse("free = [\"E\", \"density\", \"e\"]\n")
            .validate()
            .unwrap_err()
            .to_string();
        assert!(e.contains("given twice"), "{e}");
        let e = parse("[[parts]]\nid = 0\nfree = [\"nu\", \"nu\"]\n")
            .validate()
            .unwrap_err()
            .to_string();
        assert!(e.contains("parts id 0: free") && e.contains("twice"), "{e}");
        let e = parse("free = [\"densty\"]\n")
            .validate()
            .unwrap_err()
            .to_string();
        assert!(e.contains("did you mean `density`?"), "{e}");
        let e = parse("free = [\"E\"]\n[[parts]]\nid = 0\nbounds = { nu = [0.1, 0.4] }\n")
            .validate()
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("bounds.nu") && e.contains("not a free parameter of part 0"),
            "{e}"
        );
        let e = parse("[[parts]]\nid = 0\nbounds = { E = [1e4, 1e6], e = [1e3, 1e5] }\n")
            .validate()
            .unwrap_err()
            .to_string();
        assert!(e.contains("bounds of E given twice"), "{e}");
        // Bounds outside the values the simulator accepts are refused by name and limit.
        for (b, limit) in [
            ("E = [1e3, 1e20]", "1e13"),
            ("density = [1e-9, 1e3]", "1e-6"),
            ("nu = [0.1, 0.6]", "(-1, 0.5)"),
        ] {
            let e = parse(&format!("[[parts]]\nid = 0\nbounds = {{ {b} }}\n"))
                .validate()
                .unwrap_err()
                .to_string();
            assert!(
                e.contains("parts id 0: bounds of") && e.contains(limit),
                "{b}: {e}"
            );
        }
        // Free by material (jelly: E, nu, density): bounds of its yield stress are refused
        // when the free kinds are resolved.
        let c = parse("[[parts]]\nid = 0\nbounds = { yield_stress = [1e3, 1e5] }\n");
        c.validate().unwrap();
        let e = c
            .free_kinds(&[PartParams::default()])
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("bounds.yield_stress") && e.contains("by its material"),
            "{e}"
        );
        let ok = parse("free = [\"E\"]\n[[parts]]\nid = 0\nbounds = { E = [1e4, 1e6] }\n");
        ok.validate().unwrap();
        ok.free_kinds(&[PartParams::default()]).unwrap();
    }
}
