//! The built-in demo (`r4d demo`): a procedurally generated two-part plant with known
//! parameters, rendered to a reference video and fitted back from scratch.
//!
//! The plant stands on a tiled floor in front of a striped wall: a stiff, light stem
//! (part 0) clamped at its base and a softer, heavier head (part 1). A sideways force acts
//! on the head's particles for the first substeps (a force impulse, so the head's mass and
//! with it the absolute density enter the motion, not only `E / density`), then the plant
//! sways under gravity. Every particle carries one Gaussian, coloured in a 3D checker so the
//! motion is visible inside the silhouette.
//!
//! [`run_demo`] renders the reference video from the true parameters, checks which
//! parameters the video determines (1-D loss profiles around the truth), initialises with a
//! Latin hypercube over `E` and density of both parts, fits with AdamW on the DMS loss, and
//! returns a [`DemoSummary`].

use crate::video_fit::fit::{run_fit, FitHooks, FitOutcome, Terms};
use crate::video_fit::params::{get, set};
use crate::video_fit::{FitConfig, FitError, Objective, ParamSpace, VideoProblem, View};
use r4d_mpm::{PartParams, ParticleSet, SimConfig};
use r4d_optim::ParamKind;
use r4d_splat::{Camera, Gaussians, RenderSettings, SimLink};
use serde::{Deserialize, Serialize};
use std::path::Path;
use std::time::Instant;

/// Size of the demo run.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct DemoOptions {
    /// AdamW iterations.
    pub iters: usize,
    /// Latin hypercube candidates.
    pub candidates: usize,
    /// Relative offsets of the identifiability profiles (0 = truth is always added).
    pub profile_offsets: Vec<f64>,
    /// Seed of the initialisation.
    pub seed: u64,
}

impl Default for DemoOptions {
    fn default() -> Self {
        DemoOptions {
            iters: 30,
            candidates: 16,
            profile_offsets: vec![-0.3, -0.15, -0.05, 0.05, 0.15, 0.3],
            seed: 0,
        }
    }
}

impl DemoOptions {
    /// A few-iteration version for smoke tests (minutes become seconds; no accuracy claim).
    pub fn quick() -> Self {
        DemoOptions {
            iters: 2,
            candidates: 4,
            profile_offsets: vec![-0.15, 0.15],
            seed: 0,
        }
    }
}

/// The true parameters of the demo's parts.
pub fn truth() -> Vec<PartParams> {
    let stem = PartParams {
        youngs_modulus_pa: 3e5,
        poisson_ratio: 0.3,
        density_kg_m3: 500.0,
        ..Default::default()
    };
    let head = PartParams {
        youngs_modulus_pa: 6e4,
        density_kg_m3: 1200.0,
        ..stem
    };
    vec![stem, head]
}

const N_GRID: usize = 24;
const FRAMES: usize = 16;

fn sim_config(parts: Vec<PartParams>) -> SimConfig {
    let text = r#"
[domain]
grid_lim = 1.0
n_grid = 24
[time]
substep_dt = 3.3333333333333335e-4
frame_dt = 0.025
frames = 16
[solver]
gravity = [0.0, 0.0, -9.8]
[[parts]]
material = "jelly"
[[parts]]
material = "jelly"
[[boundary]]
type = "bounding_box"
[[boundary]]
type = "cuboid"
point = [0.5, 0.5, 0.125]
size = [0.5, 0.5, 0.045]
velocity = [0.0, 0.0, 0.0]
[[boundary]]
type = "particle_impulse"
force = [0.5, 0.18, 0.0]
point = [0.5, 0.5, 0.53125]
size = [0.13, 0.13, 0.1]
num_dt = 30
"#;
    let mut c = SimConfig::parse(text, Path::new("demo.toml")).expect("the demo config parses");
    c.parts = parts;
    c
}

fn particles(dx: f64) -> ParticleSet {
    let shapes = [
        // Stem: 0.125 x 0.125 x 0.3125 m, clamped at the bottom.
        r4d_mpm::Shape::Box {
            min: [0.4375, 0.4375, 0.125],
            max: [0.5625, 0.5625, 0.4375],
            part: 0,
            per_cell: 2,
        },
        // Head: a 0.25 x 0.25 x 0.1875-m bulb on top, soft enough to wobble on its own.
        r4d_mpm::Shape::Box {
            min: [0.375, 0.375, 0.4375],
            max: [0.625, 0.625, 0.625],
            part: 1,
            per_cell: 2,
        },
    ];
    ParticleSet::from_shapes(&shapes, dx)
}

/// SH DC coefficient of an RGB colour.
fn dc(c: [f32; 3]) -> [f32; 3] {
    c.map(|v| (v - 0.5) / 0.282_094_8)
}

fn scene(p: &ParticleSet, dx: f64) -> Gaussians {
    let mut g = Gaussians {
        sh_degree: 0,
        ..Default::default()
    };
    let sigma = (0.5 * dx / 2.0) as f32;
    let mut push = |m: [f32; 3], s: [f32; 3], q: [f32; 4], o: f32, c: [f32; 3]| {
        g.means.push(m);
        g.log_scales.push(s.map(f32::ln));
        g.quats.push(q);
        g.opacity_logits.push(o);
        g.sh.extend(dc(c));
    };
    let palettes = [
        [[0.16, 0.55, 0.22], [0.78, 0.86, 0.30]],
        [[0.86, 0.20, 0.36], [0.98, 0.78, 0.22]],
    ];
    for (x, &part) in p.x.iter().zip(&p.part) {
        let cell = x.map(|v| (v / 0.0625).floor() as i64);
        let odd = (cell[0] + cell[1] + cell[2]).rem_euclid(2) as usize;
        push(
            *x,
            [sigma; 3],
            [1.0, 0.0, 0.0, 0.0],
            3.0,
            palettes[part as usize][odd],
        );
    }
    // Static floor (grey tiles) and back wall (stripes): flat discs on a 0.03-m lattice.
    let step = 0.03f32;
    for i in 0..44 {
        for j in 0..34 {
            let (x, y) = (-0.15 + i as f32 * step, -0.05 + j as f32 * step);
            let tile = ((x / 0.125).floor() + (y / 0.125).floor()) as i64 & 1;
            let c = if tile == 0 { 0.55 } else { 0.72 };
            push(
                [x, y, 0.12],
                [0.022, 0.022, 0.003],
                [1.0, 0.0, 0.0, 0.0],
                4.0,
                [c, c, c * 0.95],
            );
        }
    }
    for i in 0..44 {
        for k in 0..30 {
            let (x, z) = (-0.15 + i as f32 * step, 0.125 + k as f32 * step);
            let stripe = (((x + z) / 0.1).floor() as i64) & 1;
            let c = if stripe == 0 {
                [0.62, 0.72, 0.90]
            } else {
                [0.93, 0.80, 0.86]
            };
            // Disc in the x-z plane: rotate z onto y (90 degrees about x).
            let h = std::f32::consts::FRAC_1_SQRT_2;
            push(
                [x, 0.95, z],
                [0.022, 0.022, 0.003],
                [h, h, 0.0, 0.0],
                4.0,
                c,
            );
        }
    }
    g
}

/// The demo's camera: 256 x 192 pixels, in front of the plant, slightly above.
pub fn camera() -> Camera {
    let mut c = Camera::look_at(
        256,
        192,
        40.0,
        [0.6, -0.33, 0.52],
        [0.5, 0.5, 0.32],
        [0.0, 0.0, 1.0],
    );
    c.name = "demo".into();
    c
}

/// The demo problem with its reference video rendered from [`truth`]; the config's parts
/// hold a deliberately wrong starting point (the initialisation replaces it).
pub fn problem() -> Result<VideoProblem, FitError> {
    let config = sim_config(truth());
    let dx = config.domain.dx();
    let particles = particles(dx);
    let scene = scene(&particles, dx);
    let mut link = SimLink::identity(scene.len());
    link.simulated = (0..particles.x.len() as u32).collect();
    let cam = camera();
    let placeholder = r4d_loss::Video::zeros(FRAMES, cam.height as usize, cam.width as usize);
    let mut p = VideoProblem {
        config,
        particles,
        scene,
        link,
        settings: RenderSettings {
            background: [0.93, 0.92, 0.86],
            ..Default::default()
        },
        views: vec![View {
            name: "demo reference".into(),
            camera: cam,
            video: placeholder.into(),
        }],
        fps: 40.0,
        gpu: None,
    };
    let obj = Objective::new(&p, None, &r4d_loss::DmsConfig::default(), false)?;
    let videos = obj.render(&truth())?;
    p.views[0].video = videos.into_iter().next().expect("one view").into();
    let mut start = truth();
    for s in &mut start {
        s.youngs_modulus_pa = 1e5;
        s.density_kg_m3 = 1000.0;
    }
    p.config.parts = start;
    debug_assert_eq!(N_GRID, p.config.domain.n_grid);
    Ok(p)
}

/// The demo's fit settings: `E` and density of both parts free, bounds one decade around
/// plausible values, the paper's DMS loss (spatial and spectral terms).
pub fn fit_config(opts: &DemoOptions) -> FitConfig {
    let mut c = FitConfig {
        iters: opts.iters,
        lr: 0.15,
        beta1: 0.6,
        precision: crate::video_fit::Precision::F32,
        free: Some(vec!["E".into(), "density".into()]),
        ..Default::default()
    };
    // Static patches have zero spectra on both sides; without a mask their phase entries
    // add a constant and, where the fit moves a patch the reference keeps still, gradients
    // of order 1 / eps (see r4d_loss::spectral).
    c.loss.spectral.phase_mask = Some(1e-3);
    c.init.candidates = opts.candidates;
    c.init.frames = FRAMES;
    c.init.seed = opts.seed;
    c.parts = (0..2)
        .map(|id| crate::video_fit::config::PartFit {
            id,
            free: None,
            bounds: [
                ("E".to_string(), [1e4, 1e6]),
                ("density".to_string(), [200.0, 3000.0]),
            ]
            .into_iter()
            .collect(),
        })
        .collect();
    c
}

/// A 1-D loss profile around the truth.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Profile {
    /// Parameter name (e.g. `part1.density`).
    pub name: String,
    /// Factors applied to the true value (1 included).
    pub factors: Vec<f64>,
    /// Loss at each factor.
    pub losses: Vec<f64>,
    /// Mean loss increase at the two smallest nonzero offsets, relative to the largest such
    /// increase over all parameters.
    pub relative_sensitivity: f64,
    /// The profile has its minimum at the truth and rises on both sides by more than 5% of
    /// the most sensitive parameter's rise.
    pub identifiable: bool,
}

/// Loss profiles of every free parameter around `truth` (one forward run per point).
pub fn profiles(
    problem: &VideoProblem,
    cfg: &FitConfig,
    truth: &[PartParams],
    offsets: &[f64],
) -> Result<Vec<Profile>, FitError> {
    let obj = Objective::new(problem, cfg.frames, &cfg.loss, false)?;
    let free = cfg.free_kinds(truth)?;
    let ids: Vec<u32> = (0..truth.len() as u32).collect();
    let space = ParamSpace::new(cfg.granularity, &free, &ids, |p, k| cfg.bounds(p, k));
    let mut factors: Vec<f64> = offsets.iter().map(|o| 1.0 + o).collect();
    factors.push(1.0);
    factors.sort_by(f64::total_cmp);
    factors.dedup();
    let base = obj.value(truth)?.total;
    let mut out = Vec::new();
    for (i, name) in space.names().into_iter().enumerate() {
        let e = &space.entries[i];
        let losses = factors
            .iter()
            .map(|&f| {
                if f == 1.0 {
                    return Ok(base);
                }
                let mut p = truth.to_vec();
                let s = e.slot.expect("part-level profile");
                set(&mut p[s], e.kind, get(&truth[s], e.kind) * f);
                Ok(obj.value(&p)?.total)
            })
            .collect::<Result<Vec<f64>, FitError>>()?;
        out.push(Profile {
            name,
            factors: factors.clone(),
            losses,
            relative_sensitivity: 0.0,
            identifiable: false,
        });
    }
    // Sensitivity: the rise at the nearest offsets on each side.
    let one = factors.iter().position(|&f| f == 1.0).expect("truth point");
    let rise = |p: &Profile| -> (f64, f64) {
        let lo = if one > 0 {
            p.losses[one - 1] - p.losses[one]
        } else {
            0.0
        };
        let hi = p.losses.get(one + 1).map_or(0.0, |l| l - p.losses[one]);
        (lo, hi)
    };
    let max_rise = out
        .iter()
        .map(|p| {
            let (a, b) = rise(p);
            0.5 * (a + b)
        })
        .fold(0.0f64, f64::max);
    for p in &mut out {
        let (a, b) = rise(p);
        let min_at_truth = p.losses.iter().all(|&l| l >= p.losses[one]);
        p.relative_sensitivity = if max_rise > 0.0 {
            0.5 * (a + b) / max_rise
        } else {
            0.0
        };
        p.identifiable = min_at_truth && a > 0.05 * max_rise && b > 0.05 * max_rise;
    }
    Ok(out)
}

/// Relative error of one quantity.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Recovery {
    /// Part.
    pub part: usize,
    /// Quantity (`E`, `density`, `E/density`).
    pub quantity: String,
    /// True value.
    pub truth: f64,
    /// After initialisation.
    pub init: f64,
    /// After fitting.
    pub fit: f64,
    /// `(fit - truth) / truth`.
    pub fit_rel_error: f64,
    /// Whether the profiles call the quantity identifiable (`E/density`: always reported).
    pub identifiable: bool,
}

/// What `r4d demo` reports (`summary.json`).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct DemoSummary {
    /// True parameters (`{"parts": [...]}`, the `params.json` schema).
    pub truth: serde_json::Value,
    /// After initialisation.
    pub init: serde_json::Value,
    /// After fitting.
    pub fit: serde_json::Value,
    /// Recovery per part and quantity.
    pub recovery: Vec<Recovery>,
    /// Identifiability profiles.
    pub profiles: Vec<Profile>,
    /// Loss terms of the fitted parameters over the whole video (filled in by the caller
    /// that renders the results, see `video_fit::report::write_results`).
    pub final_loss: Option<Terms>,
    /// The evaluation metrics of the fitted video (PSNR, SSIM, MS-SSIM, LPIPS; `metrics.json`
    /// of the run folder), filled in like `final_loss`.
    #[serde(default)]
    pub metrics: Option<serde_json::Value>,
    /// Wall time of the whole demo (s).
    pub wall_time_s: f64,
    /// Wall time per phase (s): reference, profiles, fit (initialisation included).
    pub phase_times_s: std::collections::BTreeMap<String, f64>,
    /// Options used.
    pub options: DemoOptions,
}

/// Everything [`run_demo`] produced.
pub struct DemoRun {
    /// The problem (reference video included).
    pub problem: VideoProblem,
    /// The fit settings.
    pub config: FitConfig,
    /// The fit's result.
    pub outcome: FitOutcome,
    /// The summary.
    pub summary: DemoSummary,
}

/// Runs the demo: reference video (always simulated on the CPU), profiles, initialisation and
/// fit (simulated on `gpu` when given).
pub fn run_demo(
    opts: &DemoOptions,
    hooks: &mut dyn FitHooks,
    gpu: Option<crate::video_fit::GpuHandle>,
) -> Result<DemoRun, FitError> {
    let t0 = Instant::now();
    let mut times = std::collections::BTreeMap::new();
    let mut problem = problem()?;
    problem.gpu = gpu;
    times.insert("reference".to_string(), t0.elapsed().as_secs_f64());
    let cfg = fit_config(opts);
    let t1 = Instant::now();
    let truth = truth();
    let profiles = profiles(&problem, &cfg, &truth, &opts.profile_offsets)?;
    times.insert("profiles".to_string(), t1.elapsed().as_secs_f64());
    let t2 = Instant::now();
    let outcome = run_fit(&problem, &cfg, None, hooks)?;
    times.insert("fit".to_string(), t2.elapsed().as_secs_f64());
    let ident = |part: usize, k: &str| {
        profiles
            .iter()
            .any(|p| p.name == format!("part{part}.{k}") && p.identifiable)
    };
    let mut recovery = Vec::new();
    type Q = (&'static str, fn(&PartParams) -> f64);
    let qs: [Q; 3] = [
        ("E", |p| get(p, ParamKind::YoungsModulus)),
        ("density", |p| get(p, ParamKind::Density)),
        ("E/density", |p| p.youngs_modulus_pa / p.density_kg_m3),
    ];
    for (i, t) in truth.iter().enumerate() {
        for (name, f) in qs {
            let tv = f(t);
            recovery.push(Recovery {
                part: i,
                quantity: name.into(),
                truth: tv,
                init: f(&outcome.init_parts[i]),
                fit: f(&outcome.parts[i]),
                fit_rel_error: (f(&outcome.parts[i]) - tv) / tv,
                identifiable: name == "E/density" || ident(i, name),
            });
        }
    }
    let pj = crate::video_fit::report::params_json;
    let summary = DemoSummary {
        truth: pj(&truth),
        init: pj(&outcome.init_parts),
        fit: pj(&outcome.parts),
        recovery,
        profiles,
        final_loss: None,
        metrics: None,
        wall_time_s: t0.elapsed().as_secs_f64(),
        phase_times_s: times,
        options: opts.clone(),
    };
    Ok(DemoRun {
        problem,
        config: cfg,
        outcome,
        summary,
    })
}
