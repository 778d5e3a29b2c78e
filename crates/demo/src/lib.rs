//! The built-in demos (`r4d demo --scene plant|metal|sand|foam|plasticine|paste|fluid`): scenes
//! with known parameters, rendered to reference videos and fitted back from the videos alone.
//! Each scene is data, `configs/demo/<scene>.toml` (compiled in; [`scene_file`] builds it):
//!
//! * `plant` (default): a stiff stem and a soft heavy head (two jelly parts) pushed sideways.
//! * `metal`: a cantilever beam bent past yield by a push at its tip and released; it keeps a
//!   permanent bend.
//! * `sand`: a sand column slumping into a pile on a rough floor.
//! * `foam`: a foam block squeezed by a push on its top and released.
//! * `plasticine`: a plasticine blob thrown onto the floor.
//! * `paste`: a column of paste slumping under its own weight.
//! * `fluid`: a viscous drop landing and spreading.
//!
//! Every scene is a [`SceneSpec`]: the simulation with its true parameters, the cameras, the
//! free parameters and their bounds, and the parameter pairs whose 2-D loss profile is
//! reported. [`run_demo`] renders the reference videos from the truth, computes the loss
//! profiles around the truth and the identifiability verdicts ([`profiles`]), initialises with
//! a Latin hypercube over every free parameter, fits with AdamW on the DMS loss, and returns a
//! [`DemoSummary`]. [`Size::Small`] gives a few-second version of each scene for tests.

pub mod profiles;
pub mod random;
pub mod recovery;
pub mod scene_file;
pub mod stage;

use profiles::{Profile, Profile2d, Verdict};
use r4d_mpm::{PartParams, ParticleSet, SimConfig};
use r4d_optim::record::Terms;
use r4d_optim::space::get;
use r4d_optim::video::fit::{run_fit, FitHooks, FitOutcome};
use r4d_optim::video::{FitConfig, Objective, VideoProblem, View};
use r4d_optim::ParamKind;
use r4d_optim::{Compute, FitError};
use r4d_splat::{Camera, RenderSettings, SimLink};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::sync::Arc;
use std::time::Instant;

/// The built-in demo scenes.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum DemoScene {
    /// Two jelly parts: `E` and density of both.
    #[default]
    Plant,
    /// A metal cantilever bent past yield: `E`, `nu`, yield stress, density.
    Metal,
    /// A slumping sand column: `E`, `nu`, friction angle, density.
    Sand,
    /// A pressed foam block: `E`, `nu`, yield stress, plastic viscosity, density.
    Foam,
    /// A plasticine blob thrown onto the floor: `E`, `nu`, yield stress, density.
    Plasticine,
    /// A column of paste (`non_newtonian`) slumping: `E`, yield stress, plastic viscosity.
    Paste,
    /// A viscous drop (`fluid`) landing and spreading: `E` (the bulk modulus), viscosity.
    Fluid,
}

impl DemoScene {
    /// Every scene.
    pub const ALL: [DemoScene; 7] = [
        DemoScene::Plant,
        DemoScene::Metal,
        DemoScene::Sand,
        DemoScene::Foam,
        DemoScene::Plasticine,
        DemoScene::Paste,
        DemoScene::Fluid,
    ];

    /// The name on the command line.
    pub fn name(self) -> &'static str {
        match self {
            DemoScene::Plant => "plant",
            DemoScene::Metal => "metal",
            DemoScene::Sand => "sand",
            DemoScene::Foam => "foam",
            DemoScene::Plasticine => "plasticine",
            DemoScene::Paste => "paste",
            DemoScene::Fluid => "fluid",
        }
    }

    /// Parses a name (see [`DemoScene::name`]).
    pub fn parse(s: &str) -> Result<DemoScene, FitError> {
        DemoScene::ALL
            .into_iter()
            .find(|d| d.name().eq_ignore_ascii_case(s.trim()))
            .ok_or_else(|| {
                FitError::Input(format!(
                    "--scene '{s}': use one of plant, metal, sand, foam, plasticine, paste, fluid"
                ))
            })
    }

    /// The scene at `size`, built from its file (`configs/demo/<name>.toml`, compiled in;
    /// the tests build every scene at both sizes, so a built-in file that does not build is
    /// a bug).
    pub fn spec(self, size: Size) -> SceneSpec {
        scene_file::build(self, scene_file::text(self), &self.file(), size)
            .unwrap_or_else(|e| panic!("the built-in scene file {}: {e}", self.file()))
    }

    /// The path of the scene's file in the repository (`configs/demo/<name>.toml`).
    pub fn file(self) -> String {
        format!("configs/demo/{}.toml", self.name())
    }
}

/// Resolution of a scene.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Size {
    /// The demo (grid 24-32, about a thousand particles or more, 256 x 192 views).
    #[default]
    Full,
    /// The test version: grid 16, a few hundred particles, small views (seconds per fit in
    /// the optimised test profile).
    Small,
}

/// One demo scene: simulation, truth, cameras and what is fitted.
#[derive(Clone, Debug)]
pub struct SceneSpec {
    /// Which scene (a random scene of the recovery benchmark: the built-in scene of its
    /// material's look).
    pub scene: DemoScene,
    /// The scene's name in the views' names and the progress output.
    pub name: String,
    /// One line for the progress output.
    pub description: String,
    /// Simulation settings; `parts` hold the true parameters.
    pub config: SimConfig,
    /// The simulated particles.
    pub particles: ParticleSet,
    /// Names of the parts (`parts.json`).
    pub part_names: Vec<String>,
    /// Colours of the parts.
    pub palettes: Vec<stage::Palette>,
    /// Height of the visible floor (m).
    pub floor_z: f32,
    /// The views, rendered at the video's resolution.
    pub cameras: Vec<Camera>,
    /// The deliberately wrong parameters in the config before the initialisation.
    pub start: Vec<PartParams>,
    /// Free parameters per part.
    pub free: Vec<Vec<ParamKind>>,
    /// Bounds per part and parameter name.
    pub bounds: Vec<BTreeMap<String, [f64; 2]>>,
    /// Pairs `(part, a, b)` with a 2-D loss profile.
    pub pairs: Vec<(usize, ParamKind, ParamKind)>,
    /// The fit's defaults for this scene (free parameters and bounds filled in by
    /// [`SceneSpec::fit_config`]).
    pub fit: FitConfig,
    /// Relative offsets of the 1-D profiles (0 = truth is always added).
    pub profile_offsets: Vec<f64>,
    /// Relative offsets of each axis of the 2-D profiles.
    pub profile2d_offsets: Vec<f64>,
}

impl SceneSpec {
    /// The true parameters.
    pub fn truth(&self) -> Vec<PartParams> {
        self.config.parts.clone()
    }

    /// The problem with its reference videos rendered from the truth on `compute` (which
    /// the problem then keeps); the config's parts hold [`SceneSpec::start`] (the
    /// initialisation replaces them).
    pub fn problem(&self, compute: Arc<dyn Compute>) -> Result<VideoProblem, FitError> {
        let config = self.config.clone();
        let dx = config.domain.dx();
        let scene = stage::scene(&self.particles, dx, &self.palettes, self.floor_z);
        let mut link = SimLink::identity(scene.len());
        link.simulated = (0..self.particles.x.len() as u32).collect();
        let frames = config.time.frames;
        let views = self
            .cameras
            .iter()
            .map(|cam| View {
                name: format!("{} reference ({})", self.name, cam.name),
                camera: cam.clone(),
                video: r4d_loss::Video::zeros(frames, cam.height as usize, cam.width as usize)
                    .into(),
            })
            .collect();
        let mut p = VideoProblem {
            config,
            particles: self.particles.clone(),
            scene,
            link,
            settings: RenderSettings {
                background: [0.93, 0.92, 0.86],
                ..Default::default()
            },
            views,
            fps: 1.0 / (self.config.time.substeps() as f64 * self.config.time.substep_dt),
            compute,
        };
        let obj = Objective::new(&p, None, &r4d_loss::DmsConfig::default(), false)?;
        let videos = obj.render(&self.truth())?;
        for (v, video) in p.views.iter_mut().zip(videos) {
            v.video = video.into();
        }
        p.config.parts = self.start.clone();
        Ok(p)
    }

    /// The fit settings of this scene with `opts` applied.
    pub fn fit_config(&self, opts: &DemoOptions) -> FitConfig {
        let mut c = self.fit.clone();
        // Asked for: kept by the automatic strategy too.
        let pin = |c: FitConfig, key| if c.strategy.is_auto() { c.pin(key) } else { c };
        if let Some(i) = opts.iters {
            c.iters = i;
            c = pin(c, "iters");
        }
        if let Some(n) = opts.candidates {
            c.init.candidates = n;
            c = pin(c, "init.candidates");
        }
        c.init.seed = opts.seed;
        c.init.frames = c.init.frames.min(self.config.time.frames);
        c.free = None;
        c.parts = (0..self.free.len())
            .map(|id| r4d_optim::video::config::PartFit {
                id,
                free: Some(self.free[id].iter().map(|k| k.name().to_string()).collect()),
                bounds: self.bounds[id].clone(),
            })
            .collect();
        c
    }
}

/// Size of a demo run (`None`: the scene's default).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct DemoOptions {
    /// AdamW iterations.
    pub iters: Option<usize>,
    /// Latin hypercube candidates.
    pub candidates: Option<usize>,
    /// Compute the loss profiles (1-D and 2-D) and the identifiability verdicts.
    pub profiles: bool,
    /// Seed of the initialisation.
    pub seed: u64,
    /// Few iterations, few candidates, coarse profiles: a smoke test, no accuracy claim.
    pub quick: bool,
}

impl DemoOptions {
    /// The full demo.
    pub fn full() -> Self {
        DemoOptions {
            profiles: true,
            ..Default::default()
        }
    }

    /// A few-iteration version for smoke tests (minutes become seconds; no accuracy claim).
    pub fn quick() -> Self {
        DemoOptions {
            iters: Some(2),
            candidates: Some(4),
            profiles: true,
            seed: 0,
            quick: true,
        }
    }
}

/// Recovery of one quantity.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Recovery {
    /// Part.
    pub part: usize,
    /// Quantity (`E`, `nu`, `yield_stress`, `plastic_viscosity`, `friction_angle`,
    /// `density`, or a ratio such as `E/density`).
    pub quantity: String,
    /// True value.
    pub truth: f64,
    /// After initialisation.
    pub init: f64,
    /// After fitting.
    pub fit: f64,
    /// `(fit - truth) / truth` (friction angle: also in degrees, see `fit_abs_error`).
    pub fit_rel_error: f64,
    /// `fit - truth`.
    pub fit_abs_error: f64,
    /// The profiles' verdict: the video determines this quantity. `false`: the fit's value
    /// is not a measurement (the table prints "not determined").
    pub identifiable: bool,
    /// The target tolerance of the quantity (relative; friction angle: degrees), when it
    /// has one.
    pub tolerance: Option<f64>,
    /// Within the tolerance (`None` when there is none or the quantity is not
    /// identifiable).
    pub within_tolerance: Option<bool>,
}

/// What `r4d demo` reports (`summary.json`).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct DemoSummary {
    /// The scene.
    pub scene: DemoScene,
    /// True parameters (`{"parts": [...]}`, the `params.json` schema).
    pub truth: serde_json::Value,
    /// After initialisation.
    pub init: serde_json::Value,
    /// After fitting.
    pub fit: serde_json::Value,
    /// Free parameter names (`part0.E`, ...).
    pub free: Vec<String>,
    /// Recovery per part and quantity.
    pub recovery: Vec<Recovery>,
    /// 1-D identifiability profiles.
    pub profiles: Vec<Profile>,
    /// 2-D profiles of the pairs that may trade off.
    pub profiles_2d: Vec<Profile2d>,
    /// Verdict per free parameter (and per determined combination).
    pub identifiability: Vec<Verdict>,
    /// Loss terms of the fitted parameters over the whole video (filled in by the caller
    /// that renders the results, see `video_fit::report::write_results`).
    pub final_loss: Option<Terms>,
    /// The evaluation metrics of the fitted video (PSNR, SSIM, MS-SSIM, LPIPS; `metrics.json`
    /// of the run folder), filled in like `final_loss`.
    #[serde(default)]
    pub metrics: Option<serde_json::Value>,
    /// The valley search's rounds, when the scene runs one (`valley.evals > 0`; the
    /// plasticine): loss before and after, parameters re-centred, evaluations.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub valley: Vec<r4d_optim::video::ValleyRound>,
    /// The restarts along constant bulk modulus, when the scene runs them
    /// (`shear_restarts.points > 0`; the full plasticine), in the order they ran.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub restarts: Vec<RestartRow>,
    /// Wall time of the whole demo (s).
    pub wall_time_s: f64,
    /// Wall time per phase (s): reference, profiles, fit (initialisation included).
    pub phase_times_s: BTreeMap<String, f64>,
    /// Options used.
    pub options: DemoOptions,
}

/// Everything [`run_demo`] produced.
pub struct DemoRun {
    /// The scene.
    pub spec: SceneSpec,
    /// The problem (reference videos included).
    pub problem: VideoProblem,
    /// The fit settings.
    pub config: FitConfig,
    /// The fit's result.
    pub outcome: FitOutcome,
    /// The summary.
    pub summary: DemoSummary,
}

/// Target tolerance of a quantity (issue targets): yield stress 10%, friction angle 2
/// degrees, plastic viscosity, hardening and softening 20%, `E` and density 10%; none for
/// Poisson's ratio.
pub fn tolerance(k: ParamKind) -> Option<f64> {
    match k {
        ParamKind::YieldStress | ParamKind::YoungsModulus | ParamKind::Density => Some(0.10),
        ParamKind::PlasticViscosity | ParamKind::Hardening | ParamKind::Softening => Some(0.20),
        ParamKind::FrictionAngle => Some(2.0),
        ParamKind::PoissonRatio => None,
    }
}

/// The recovery rows of `fit` against `truth`: every free parameter of every part, then
/// `E/density` (the elastic wave speed squared, which a video determines even when the
/// absolute scale is not).
pub fn recovery(
    spec: &SceneSpec,
    init: &[PartParams],
    fit: &[PartParams],
    verdicts: &[Verdict],
) -> Vec<Recovery> {
    let truth = spec.truth();
    let mut out = Vec::new();
    let ident = |name: &str| verdicts.iter().any(|v| v.name == name && v.identifiable);
    for (i, t) in truth.iter().enumerate() {
        for &k in &spec.free[i] {
            let (tv, f) = (get(t, k), get(&fit[i], k));
            let name = format!("part{i}.{}", k.name());
            let identifiable = ident(&name);
            let tol = tolerance(k);
            let err = if k == ParamKind::FrictionAngle {
                (f - tv).abs()
            } else {
                ((f - tv) / tv).abs()
            };
            out.push(Recovery {
                part: i,
                quantity: k.name().into(),
                truth: tv,
                init: get(&init[i], k),
                fit: f,
                fit_rel_error: (f - tv) / tv,
                fit_abs_error: f - tv,
                identifiable,
                tolerance: tol,
                within_tolerance: tol.filter(|_| identifiable).map(|t| err <= t),
            });
        }
        let free = &spec.free[i];
        if free.contains(&ParamKind::YoungsModulus) && free.contains(&ParamKind::Density) {
            let r = |p: &PartParams| p.youngs_modulus_pa / p.density_kg_m3;
            let (tv, f) = (r(t), r(&fit[i]));
            let name = format!("part{i}.E/density");
            let identifiable = ident(&name);
            out.push(Recovery {
                part: i,
                quantity: "E/density".into(),
                truth: tv,
                init: r(&init[i]),
                fit: f,
                fit_rel_error: (f - tv) / tv,
                fit_abs_error: f - tv,
                identifiable,
                tolerance: Some(0.10),
                within_tolerance: identifiable.then_some(((f - tv) / tv).abs() <= 0.10),
            });
        }
    }
    out
}

/// Runs a demo: reference videos (simulated and rendered on `reference`; the `r4d` binary
/// passes the CPU in f64 whatever `--backend` says), profiles, initialisation and fit
/// (simulated and rendered on `fit`).
pub fn run_demo(
    scene: DemoScene,
    size: Size,
    opts: &DemoOptions,
    hooks: &mut dyn FitHooks,
    reference: Arc<dyn Compute>,
    fit: Arc<dyn Compute>,
) -> Result<DemoRun, FitError> {
    let t0 = Instant::now();
    let mut times = BTreeMap::new();
    let mut spec = scene.spec(size);
    if opts.quick {
        spec.profile_offsets = vec![-0.15, 0.15];
        spec.profile2d_offsets = vec![-0.15, 0.15];
    }
    let mut problem = spec.problem(reference)?;
    problem.compute = fit;
    times.insert("reference".to_string(), t0.elapsed().as_secs_f64());
    let cfg = spec.fit_config(opts);
    let truth = spec.truth();
    let t1 = Instant::now();
    let (mut profiles, profiles_2d) = if opts.profiles {
        let p1 = profiles::profiles(&problem, &cfg, &truth, &spec.profile_offsets)?;
        let p2 =
            profiles::profiles_2d(&problem, &cfg, &truth, &spec.pairs, &spec.profile2d_offsets)?;
        (p1, p2)
    } else {
        (Vec::new(), Vec::new())
    };
    let verdicts = profiles::verdicts(&mut profiles, &profiles_2d);
    times.insert("profiles".to_string(), t1.elapsed().as_secs_f64());
    let t2 = Instant::now();
    let outcome = run_fit(&problem, &cfg, None, hooks)?;
    times.insert("fit".to_string(), t2.elapsed().as_secs_f64());
    let recovery = recovery(&spec, &outcome.init_parts, &outcome.parts, &verdicts);
    let pj = r4d_eval::report::params_json;
    let summary = DemoSummary {
        scene,
        truth: pj(&truth),
        init: pj(&outcome.init_parts),
        fit: pj(&outcome.parts),
        free: outcome.space.names(),
        recovery,
        profiles,
        profiles_2d,
        identifiability: verdicts,
        final_loss: None,
        metrics: None,
        valley: outcome
            .valley
            .as_ref()
            .map(|v| v.rounds.clone())
            .unwrap_or_default(),
        restarts: outcome
            .restarts
            .as_ref()
            .map(|r| {
                r.done
                    .iter()
                    .map(|x| RestartRow {
                        k: x.k,
                        e: x.e,
                        nu: x.nu,
                        loss: x.loss,
                    })
                    .collect()
            })
            .unwrap_or_default(),
        wall_time_s: t0.elapsed().as_secs_f64(),
        phase_times_s: times,
        options: opts.clone(),
    };
    Ok(DemoRun {
        spec,
        problem,
        config: cfg,
        outcome,
        summary,
    })
}

/// One restart along constant bulk modulus in `summary.json`: the power `k` of the shear
/// modulus factor it started at, its `E` and `nu`, and the loss its inner search ended at.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RestartRow {
    /// Power of `shear_restarts.factor`.
    pub k: i32,
    /// Young's modulus of the restart (Pa).
    pub e: f64,
    /// Poisson's ratio of the restart.
    pub nu: f64,
    /// Loss after the inner search (the profile's value).
    pub loss: f64,
}

/// Force per particle (N) that gives acceleration `a` (m/s^2) to a particle of density `rho`
/// at grid `n_grid` (2 particles per cell per axis, volume `(dx / 2)^3`): the scenes' pushes
/// are body-force densities, so the small and full versions of a scene are loaded alike.
fn push_force(a: [f64; 3], rho: f64, n_grid: usize) -> [f64; 3] {
    let v = (0.5 / n_grid as f64).powi(3);
    a.map(|x| x * rho * v)
}

/// The stage's simulation: a unit box of `n_grid` cells per side with its bounding box,
/// gravity along -z, `frames` frames of 0.025 s in substeps of `substep_dt`, the parts
/// `parts`, and `boundaries` (more `[[boundary]]` tables, TOML) after the bounding box.
fn stage_config(
    n_grid: usize,
    substep_dt: f64,
    frames: usize,
    parts: Vec<PartParams>,
    boundaries: &str,
) -> SimConfig {
    let materials: String = parts
        .iter()
        .map(|p| format!("[[parts]]\nmaterial = \"{}\"\n", p.material.name()))
        .collect();
    let text = format!(
        "[domain]\ngrid_lim = 1.0\nn_grid = {n_grid}\n[time]\nsubstep_dt = {substep_dt:e}\n\
         frame_dt = 0.025\nframes = {frames}\n[solver]\ngravity = [0.0, 0.0, -9.8]\n{materials}\
         [[boundary]]\ntype = \"bounding_box\"\n{boundaries}"
    );
    sim_config(&text, parts)
}

/// The floor: a surface collider at height `z` facing up, `surface` being a config surface
/// kind and its settings (`surface = "sticky"`, or `surface = "friction"` and `friction`).
fn floor_collider(z: f64, surface: &str) -> String {
    format!(
        "[[boundary]]\ntype = \"surface_collider\"\npoint = [0.0, 0.0, {z}]\n\
         normal = [0.0, 0.0, 1.0]\n{surface}\n"
    )
}

/// A simulation config from TOML text with `parts` as its parts (the scene files' configs
/// are fixed text, so a parse error is a bug).
fn sim_config(text: &str, parts: Vec<PartParams>) -> SimConfig {
    let mut c = SimConfig::parse(text, std::path::Path::new("demo.toml"))
        .expect("a demo scene's config parses");
    c.parts = parts;
    c
}
