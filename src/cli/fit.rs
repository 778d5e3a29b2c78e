//! `r4d fit`: fit the material parameters of every part to a reference video.

use super::run_hooks::RunHooks;
use anyhow::{bail, Context, Result};
use resonance4d::compute;
use resonance4d::video_fit::report::{write_json, write_results};
use resonance4d::video_fit::{run_fit, FitConfig, FitState, PartLabels, VideoProblem, View};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// Arguments of `r4d fit`.
#[derive(clap::Args, Debug, Clone, Serialize, Deserialize)]
pub struct FitArgs {
    /// The static 3DGS scene (INRIA PLY).
    #[arg(long)]
    scene: Option<PathBuf>,
    /// Simulation config: the project's TOML/JSON, or a PhysGaussian scene JSON (recognised
    /// by its keys). Its parts give each part's material and starting parameters.
    #[arg(long)]
    sim: Option<PathBuf>,
    /// Part labels: the JSON `r4d segment` writes (one label per Gaussian, -1 = static) or
    /// a PLY with a `part` property (the scene itself may carry it).
    #[arg(long)]
    parts: Option<PathBuf>,
    /// Cameras (r4d/reference JSON, INRIA cameras.json, nerfstudio transforms.json, COLMAP
    /// text).
    #[arg(long)]
    cameras: Option<PathBuf>,
    /// A dataset folder (PhysFlow's release, PhysDreamer, PAC-NeRF; see `r4d dataset
    /// inspect`): scene, particles, parts, physics, cameras and videos come from it.
    #[arg(long)]
    #[serde(default)]
    dataset: Option<PathBuf>,
    /// With --dataset: fit only the views of these cameras (name or index; repeatable).
    #[arg(long = "camera", value_name = "NAME|INDEX")]
    #[serde(default)]
    camera: Vec<String>,
    #[command(flatten)]
    #[serde(default)]
    dataset_opts: super::dataset::DatasetOptions,
    /// Reference video: an H.264 .mp4, a .npy (T, H, W, 3) float array or a folder of PNG
    /// frames (the formats of `r4d metrics`). Frame 0 shows the rest state. Repeatable: one per view, each with
    /// its --video-camera; the loss is summed over the views.
    #[arg(long)]
    #[serde(default, deserialize_with = "one_or_many")]
    video: Vec<PathBuf>,
    /// Index of each --video's camera in --cameras (default 0; one per --video, or one for
    /// all).
    #[arg(long)]
    #[serde(default, deserialize_with = "one_or_many")]
    video_camera: Vec<usize>,
    /// Frame rate of the video (default: an MP4's own rate, else the simulation's,
    /// 1 / frame_dt). Rendered frames are resampled linearly in time when it differs.
    #[arg(long)]
    fps: Option<f64>,
    /// Run folder: params.json, log.jsonl, checkpoint.json, the fitted video and diagnostics.
    #[arg(long)]
    out: Option<PathBuf>,
    /// Fit settings (TOML; see `docs/cli/fit.md`).
    #[arg(long)]
    config: Option<PathBuf>,
    /// Where the simulation, its reverse sweep and the rendering run: cpu (all cores, f64 by
    /// default), wgpu (WGSL on a GPU, f32; `R4D_WGPU_ADAPTER=name` picks an adapter) or
    /// reference (the single-threaded reference kernels; slow, for checking). The loss runs
    /// on the CPU either way.
    #[arg(long, value_enum, default_value_t = super::BackendKind::Cpu)]
    backend: super::BackendKind,
    /// Print the GPU time of every kernel when the command ends (timestamp queries; the
    /// Vulkan backend measures it, the others say they cannot).
    #[arg(long)]
    profile: bool,
    /// Particles (PLY x, y, z[, volume]); default: the sim config's particles.
    #[arg(long)]
    particles: Option<PathBuf>,
    /// Simulation link (link.json from `r4d prepare`); default: the labelled Gaussians are
    /// the particles, in scene order, in world coordinates.
    #[arg(long)]
    link: Option<PathBuf>,
    /// Image row of the w-t slice diagnostics (default: the reference's busiest row).
    #[arg(long)]
    row: Option<usize>,
    /// LPIPS weights for the final report's metrics (metrics.json): a safetensors file or a
    /// folder, as `r4d metrics --lpips-weights`. Repeatable. Default: $R4D_LPIPS_DIR.
    #[arg(long = "lpips-weights", value_name = "FILE")]
    #[serde(default)]
    lpips_weights: Vec<PathBuf>,
    /// Continue the killed run in this folder (its saved arguments are used; other inputs
    /// are ignored).
    #[arg(long)]
    #[serde(skip)]
    resume: Option<PathBuf>,
    /// Evaluate only shard I of N of the initialisation's candidates (index mod N = I) into
    /// OUT/shard-I-of-N/ and stop; `r4d merge OUT` ranks every shard's candidates and
    /// `r4d fit --resume OUT` then optimises from the best (see docs/cluster.md).
    #[arg(long)]
    #[serde(skip)]
    shard: Option<String>,
    /// OUT holds an earlier run of `r4d fit`: remove its files first, then fit from the
    /// start (without this a non-empty OUT is refused; `--resume OUT` continues it).
    #[arg(long, conflicts_with = "resume")]
    #[serde(skip)]
    overwrite: bool,
}

/// Reads a value or a list of values (invocation.json of runs made before a flag became
/// repeatable held a single value).
fn one_or_many<'de, D, T>(d: D) -> std::result::Result<Vec<T>, D::Error>
where
    D: serde::Deserializer<'de>,
    T: serde::Deserialize<'de>,
{
    #[derive(Deserialize)]
    #[serde(untagged)]
    enum OneOrMany<T> {
        Many(Vec<T>),
        One(T),
    }
    Ok(match Option::<OneOrMany<T>>::deserialize(d)? {
        Some(OneOrMany::Many(v)) => v,
        Some(OneOrMany::One(x)) => vec![x],
        None => Vec::new(),
    })
}

fn need<'a>(v: &'a Option<PathBuf>, flag: &str) -> Result<&'a PathBuf> {
    v.as_ref()
        .with_context(|| format!("{flag} is required (or --resume DIR)"))
}

fn is_physgaussian(path: &Path) -> bool {
    path.extension().is_some_and(|e| e == "json")
        && r4d_fsio::read_to_string_bounded(path, r4d_fsio::MAX_TEXT_BYTES)
            .ok()
            .and_then(|t| serde_json::from_str::<serde_json::Value>(&t).ok())
            .is_some_and(|v| v.get("time").is_none() && v.get("n_grid").is_some())
}

/// The views of `--video` / `--video-camera` pairs over the cameras of `cams_path`.
fn video_views(a: &FitArgs, cams_path: &Path) -> Result<(Vec<View>, r4d_splat::CameraSet)> {
    let set = r4d_splat::load_cameras(cams_path)?;
    if a.video_camera.len() > 1 && a.video_camera.len() != a.video.len() {
        bail!(
            "--video-camera is given {} times for {} --video: give one per video (or one for all)",
            a.video_camera.len(),
            a.video.len()
        );
    }
    let mut views = Vec::new();
    for (i, path) in a.video.iter().enumerate() {
        let k = a
            .video_camera
            .get(i)
            .or(a.video_camera.first())
            .copied()
            .unwrap_or(0);
        let camera = set
            .cameras
            .get(k)
            .with_context(|| {
                format!(
                    "--video-camera {k}: {} has {} camera(s)",
                    cams_path.display(),
                    set.cameras.len()
                )
            })?
            .clone();
        // 8-bit frames are kept as bytes (a quarter of f32, exact).
        let video = if r4d_video::is_mp4(path) {
            r4d_video::read_mp4_reference(path, None)?
        } else {
            r4d_loss::io::read_video::<f32>(path)?.into()
        };
        views.push(View {
            name: path.display().to_string(),
            camera,
            video,
        });
    }
    Ok((views, set))
}

impl FitArgs {
    /// The dataset folder of `--dataset`, if given.
    pub(crate) fn dataset_dir(&self) -> Option<&Path> {
        self.dataset.as_deref()
    }

    /// Every input path with its flag, and `--out` (`None` for it: not an input).
    fn paths_mut(&mut self) -> Vec<(Option<&'static str>, &mut PathBuf)> {
        let mut v = Vec::new();
        for (flag, p) in [
            ("--scene", &mut self.scene),
            ("--sim", &mut self.sim),
            ("--parts", &mut self.parts),
            ("--cameras", &mut self.cameras),
            ("--dataset", &mut self.dataset),
            ("--config", &mut self.config),
            ("--particles", &mut self.particles),
            ("--link", &mut self.link),
        ] {
            if let Some(p) = p.as_mut() {
                v.push((Some(flag), p));
            }
        }
        v.extend(self.video.iter_mut().map(|p| (Some("--video"), p)));
        v.extend(
            self.lpips_weights
                .iter_mut()
                .map(|p| (Some("--lpips-weights"), p)),
        );
        if let Some(p) = self.out.as_mut() {
            v.push((None, p));
        }
        v
    }

    /// The arguments as a run folder's `invocation.json` stores them: every path absolute,
    /// so that the run resumes and evaluates from any working directory.
    fn with_absolute_paths(&self) -> Result<FitArgs> {
        let mut a = self.clone();
        for (flag, p) in a.paths_mut() {
            *p = std::path::absolute(&*p).with_context(|| {
                format!(
                    "{} {}: no absolute path",
                    flag.unwrap_or("--out"),
                    p.display()
                )
            })?;
        }
        Ok(a)
    }

    /// Resolves the paths of arguments read from `inv` (a run folder's `invocation.json`):
    /// absolute paths stay; a relative one (written by an older r4d, relative to the
    /// directory that fit ran in) is taken from the working directory where it exists there,
    /// else from the run folder; one found in neither is an error naming the file and flag.
    pub(crate) fn resolve_saved_paths(&mut self, inv: &Path) -> Result<()> {
        let run_dir = inv.parent().unwrap_or(Path::new(".")).to_path_buf();
        for (flag, p) in self.paths_mut() {
            let Some(flag) = flag else { continue };
            if p.is_absolute() || p.exists() {
                continue;
            }
            let in_run = run_dir.join(&*p);
            if !in_run.exists() {
                bail!(
                    "{}: {flag} {}: found neither from the working directory nor from the run folder {} (the fit that wrote it ran elsewhere: run from that directory)",
                    inv.display(),
                    p.display(),
                    run_dir.display()
                );
            }
            *p = in_run;
        }
        Ok(())
    }
}

/// The common frame rate of the MP4s among `videos` (`None` when there are none); MP4s at
/// different rates need `--fps`.
fn mp4_fps(videos: &[PathBuf]) -> Result<Option<f64>> {
    let mut found: Option<(f64, &PathBuf)> = None;
    for v in videos {
        if let Some(f) = r4d_video::video_fps(v)? {
            match found {
                Some((g, w)) if (f - g).abs() > 1e-9 * g => bail!(
                    "--video {} is {f} fps, --video {} is {g} fps: give --fps (every view is fitted at one frame rate)",
                    v.display(),
                    w.display()
                ),
                None => found = Some((f, v)),
                _ => {}
            }
        }
    }
    Ok(found.map(|f| f.0))
}

/// Loads a fit straight from a dataset folder (`--dataset`); --sim, --fps, --parts,
/// --cameras with --video override the dataset's.
/// Returns the problem and whether its config is in PhysFlow's dialect (then `params.json`
/// also carries PhysFlow's units).
fn load_dataset_problem(a: &FitArgs, dir: &Path) -> Result<(VideoProblem, bool)> {
    for (flag, given) in [
        ("--scene", a.scene.is_some()),
        ("--particles", a.particles.is_some()),
        ("--link", a.link.is_some()),
    ] {
        if given {
            bail!("{flag} cannot be combined with --dataset (the dataset defines the scene, its particles and their link)");
        }
    }
    let opts = a.dataset_opts.load_options(a.sim.as_ref(), a.fps)?;
    let mut ds = r4d_datasets::load(dir, &opts)?;
    for w in &ds.warnings {
        eprintln!("note: {w}");
    }
    ds.select_views(&a.camera)?;
    let mut problem = if a.video.is_empty() {
        resonance4d::video_fit::problem_from_dataset(&ds, compute::cpu())?
    } else {
        let cams = need(&a.cameras, "--cameras (with --video)")?;
        let fps = match a.fps {
            Some(f) => Some(f),
            None => mp4_fps(&a.video)?.or(ds.views.first().map(|v| v.video.fps)),
        };
        let fps = fps.context("--fps is required with --video when the dataset has no video")?;
        resonance4d::video_fit::problem_with_views(
            &ds,
            video_views(a, cams)?.0,
            fps,
            compute::cpu(),
        )?
    };
    if let Some(p) = &a.parts {
        assign_parts(
            &PartLabels::load(p)?,
            p,
            (
                "the dataset's scene (after its opacity filter)",
                problem.scene.len(),
            ),
            &problem.link,
            &mut problem.particles,
            &mut problem.config,
            "the dataset's physics config",
        )?;
    }
    problem.validate()?;
    note_small_frames(&problem);
    Ok((problem, ds.physflow.is_some()))
}

/// Gives every particle the part of its Gaussian's label (`labels` has one per Gaussian of
/// `scene`, named with its size) and, when the labels name more parts than `config`, adds
/// copies of the last part.
fn assign_parts(
    labels: &PartLabels,
    labels_path: &Path,
    (scene_what, scene_len): (&str, usize),
    link: &r4d_splat::SimLink,
    particles: &mut r4d_mpm::ParticleSet,
    config: &mut r4d_mpm::SimConfig,
    config_what: &str,
) -> Result<()> {
    if labels.labels.len() != scene_len {
        bail!(
            "{}: {} labels but {scene_what} has {scene_len} Gaussians",
            labels_path.display(),
            labels.labels.len(),
        );
    }
    particles.part = labels
        .particle_parts(link, &particles.x)
        .with_context(|| format!("assigning parts from {}", labels_path.display()))?;
    if config.parts.len() < labels.num_parts {
        let last = *config
            .parts
            .last()
            .context("the simulation config has no part")?;
        eprintln!(
            "warning: {config_what} has {} part(s), the labels {}: the missing parts start from the last part's parameters",
            config.parts.len(),
            labels.num_parts
        );
        config.parts.resize(labels.num_parts, last);
    }
    Ok(())
}

fn note_small_frames(problem: &VideoProblem) {
    let side = problem
        .views
        .iter()
        .map(|v| v.camera.width.min(v.camera.height) as usize)
        .min()
        .unwrap_or(0);
    if side <= 160 {
        if let Some(c) = r4d_loss::MsSsimConfig::largest_window(side) {
            eprintln!(
                "note: frames of {side} px on their short side are too small for the standard MS-SSIM (11-tap window, > 160 px); the initialisation scores candidates with a {}-tap window (r4d_loss::MsSsimConfig::largest_window)",
                c.window
            );
        }
    }
}

/// Loads every input into a problem; the flag says whether the parameters are also to be
/// written in PhysFlow's units (a dataset whose physics config is in PhysFlow's dialect).
pub fn load_problem(a: &FitArgs) -> Result<(VideoProblem, bool)> {
    if let Some(dir) = &a.dataset {
        return load_dataset_problem(a, dir);
    }
    let scene_path = need(&a.scene, "--scene")?;
    let sim_path = need(&a.sim, "--sim")?;
    let parts_path = need(&a.parts, "--parts")?;
    let cams_path = need(&a.cameras, "--cameras")?;
    if a.video.is_empty() {
        bail!("--video is required (or --dataset DIR, or --resume DIR)");
    }
    let scene = r4d_splat::ply::read_gaussians(scene_path)?;
    let loaded = super::scene::load(sim_path, is_physgaussian(sim_path), a.particles.as_ref())?;
    let mut config = loaded.config;
    let mut particles = loaded.scene;
    let labels = PartLabels::load(parts_path)?;
    let link = match &a.link {
        Some(p) => r4d_splat::SimLink::load(p)?,
        None => labels.identity_link(),
    };
    assign_parts(
        &labels,
        parts_path,
        (&scene_path.display().to_string(), scene.len()),
        &link,
        &mut particles,
        &mut config,
        &sim_path.display().to_string(),
    )?;
    let (views, set) = video_views(a, cams_path)?;
    let t = &config.time;
    let frame_dt = t.substeps() as f64 * t.substep_dt;
    let fps = match a.fps {
        Some(f) => f,
        None => mp4_fps(&a.video)?.unwrap_or(1.0 / frame_dt),
    };
    let problem = VideoProblem {
        config,
        particles,
        scene,
        link,
        settings: r4d_splat::RenderSettings {
            background: set.background.unwrap_or([0.0; 3]),
            mode: set.mode.unwrap_or_default(),
        },
        views,
        fps,
        compute: compute::cpu(),
    };
    problem.validate()?;
    note_small_frames(&problem);
    Ok((problem, false))
}

/// `--shard`: evaluates this shard's initialisation candidates into `OUT/shard-I-of-N/`.
fn run_init_shard(a: &FitArgs, spec: &str) -> Result<()> {
    let shard = super::ablate::parse_shard(spec)?;
    if a.resume.is_some() {
        bail!("--shard cannot be combined with --resume (merge the shards, then resume)");
    }
    let out = need(&a.out, "--out")?.clone();
    io(a, &out).check()?;
    let cfg = match &a.config {
        Some(p) => FitConfig::load(p)?,
        None => FitConfig::default(),
    };
    let (mut problem, _) = load_problem(a)?;
    // The settings that run (the automatic strategy's), which the shard's record holds for
    // `r4d merge`.
    let run_cfg = r4d_optim::video::strategy::resolve(&cfg, &problem.config.parts)?.config;
    if !run_cfg.init.enabled {
        bail!("--shard splits the initialisation's candidates, and [init] enabled = false in the fit settings");
    }
    problem.compute = a.backend.compute()?;
    let dir = out.join(format!("shard-{}-of-{}", shard.i, shard.n));
    std::fs::create_dir_all(&dir).with_context(|| format!("creating {}", dir.display()))?;
    // The run the merged shards continue: these arguments without --shard.
    let mut whole = a.with_absolute_paths()?;
    whole.shard = None;
    write_json(&out.join("invocation.json"), &whole)?;
    write_json(&out.join("fit_config.json"), &cfg)?;
    let mut hooks = resonance4d::video_fit::fit::NoHooks;
    let (search, total, candidates) = resonance4d::video_fit::fit::initialize_shard(
        &problem,
        &cfg,
        (shard.i, shard.n),
        &mut hooks,
    )?;
    let rec = serde_json::json!({
        "kind": "init",
        "fingerprint": resonance4d::video_fit::fingerprint(&problem, &cfg),
        "shard": shard.i,
        "of": shard.n,
        "names": search.names,
        "bounds": search.bounds,
        "total": total,
        "top_k": run_cfg.init.top_k,
        "fit_config": run_cfg,
        "candidates": candidates,
    });
    write_json(&dir.join("shard.json"), &rec)?;
    let best = candidates
        .iter()
        .filter_map(|c| c.score.map(|s| (s, c.index)))
        .max_by(|a, b| a.0.total_cmp(&b.0));
    eprintln!(
        "initialisation shard {}/{}: {} of {} candidates{}; combine the shards with `r4d merge {}`",
        shard.i,
        shard.n,
        candidates.len(),
        total,
        best.map_or(String::new(), |(s, i)| format!(
            ", best #{i} {}",
            super::run_hooks::score_text(s)
        )),
        out.display()
    );
    Ok(())
}

/// The files and folders a fit reads, and its run folder.
fn io(a: &FitArgs, out: &Path) -> super::paths::Io {
    super::paths::Io::new()
        .input_opt("--scene", a.scene.as_deref())
        .input_opt("--sim", a.sim.as_deref())
        .input_opt("--parts", a.parts.as_deref())
        .input_opt("--cameras", a.cameras.as_deref())
        .input_opt("--dataset", a.dataset.as_deref())
        .inputs("--video", &a.video)
        .input_opt("--config", a.config.as_deref())
        .input_opt("--particles", a.particles.as_deref())
        .input_opt("--link", a.link.as_deref())
        .inputs("--lpips-weights", &a.lpips_weights)
        .output("--out", out)
}

/// Runs the command.
pub fn run(a: FitArgs) -> Result<()> {
    if let Some(spec) = a.shard.clone() {
        return run_init_shard(&a, &spec);
    }
    let resuming = a.resume.is_some();
    let overwrite = a.overwrite;
    let (a, out, resume) = match &a.resume {
        Some(dir) => {
            let inv = dir.join("invocation.json");
            let text = r4d_fsio::read_to_string_bounded(&inv, r4d_fsio::MAX_TEXT_BYTES)
                .with_context(|| format!("--resume: reading {}", inv.display()))?;
            let mut saved: FitArgs = serde_json::from_str(&text)
                .with_context(|| format!("{}: not an r4d fit invocation", inv.display()))?;
            saved.resolve_saved_paths(&inv)?;
            saved.out = Some(dir.clone());
            let ck = dir.join("checkpoint.json");
            // No checkpoint yet (killed during the initialisation) starts over; an unreadable
            // one (damaged, not UTF-8, no permission) is an error, never a silent restart
            // that overwrites the run.
            let state: Option<FitState> = super::checkpoint::read(&ck)?;
            (saved, dir.clone(), state)
        }
        None => {
            let out = need(&a.out, "--out")?.clone();
            (a, out, None)
        }
    };
    // The dataset options act only on a dataset: given without one they would be ignored.
    if a.dataset.is_none() {
        for (flag, given) in [
            ("--key-frames", a.dataset_opts.key_frames.is_some()),
            ("--format", a.dataset_opts.format.is_some()),
        ] {
            if given {
                bail!("{flag} applies only to --dataset: give --dataset DIR or drop {flag}");
            }
        }
    }
    io(&a, &out).check()?;
    let backend = a.backend.compute()?;
    let _profile = super::profile::Profile::on_compute(&backend, a.profile)?;
    // Loaded (and checked) before the fit, used by its final report.
    let lpips = r4d_loss::lpips::load_all(&a.lpips_weights).context("--lpips-weights")?;
    let mut cfg = match &a.config {
        Some(p) => FitConfig::load(p)?,
        None => FitConfig::default(),
    };
    if resuming {
        // A resumed run continues with the settings it started with (saved in the run
        // folder); an edited FIT.toml is refused, not silently used.
        let saved = out.join("fit_config.json");
        if let Ok(text) = r4d_fsio::read_to_string_bounded(&saved, r4d_fsio::MAX_TEXT_BYTES) {
            let was: FitConfig = serde_json::from_str(&text)
                .with_context(|| format!("{}: not a fit configuration", saved.display()))?;
            // Pinning `iters` (writing it where the automatic strategy chose it) is part of
            // raising it.
            let unpin_iters = |c: &FitConfig| {
                let mut c = c.clone();
                if let Some(p) = &mut c.pinned {
                    p.retain(|k| k != "iters");
                }
                serde_json::to_value(&c)
            };
            let (now_v, was_v) = (unpin_iters(&cfg)?, unpin_iters(&was)?);
            let differ: Vec<String> = match (now_v.as_object(), was_v.as_object()) {
                (Some(n), Some(w)) => n
                    .iter()
                    .filter(|(k, v)| w.get(*k) != Some(*v))
                    .map(|(k, _)| k.clone())
                    .collect(),
                _ => vec!["(the whole file)".into()],
            };
            // Raising `iters` extends a run (the documented way to continue one); any other
            // change would silently make a different fit.
            if differ.iter().any(|k| k != "iters") {
                bail!(
                    "--resume: the fit settings{} differ from those the run started with ({}: {}); only iters may change on resume: restore the others, or start a new run with --out",
                    a.config
                        .as_ref()
                        .map(|p| format!(" in {}", p.display()))
                        .unwrap_or_default(),
                    saved.display(),
                    differ.join(", ")
                );
            }
            if cfg.iters != was.iters {
                eprintln!("note: --resume: iters {} -> {}", was.iters, cfg.iters);
            }
            cfg = FitConfig {
                iters: cfg.iters,
                pinned: cfg.pinned.clone(),
                ..was
            };
        }
    }
    let (mut problem, physflow_units) = load_problem(&a)?;
    // The fitted video is written at the end: a frame rate it cannot have is refused now.
    if !(problem.fps.is_finite() && problem.fps > 0.0 && problem.fps <= r4d_video::MAX_FPS) {
        bail!(
            "the fit's frame rate {} ({}) must lie in (0, {}] fps, the range of the fitted video",
            problem.fps,
            if a.fps.is_some() {
                "--fps"
            } else {
                "the reference video's, or 1 / frame_dt of the physics config"
            },
            r4d_video::MAX_FPS
        );
    }
    problem.compute = backend;
    if let Some(row) = a.row {
        let h = problem
            .views
            .iter()
            .map(|v| v.camera.height as usize)
            .min()
            .unwrap_or(0);
        if row >= h {
            bail!("--row {row}: the views are {h} rows high (rows 0..{h})");
        }
    }
    super::paths::claim_dir(
        if resuming { "--resume" } else { "--out" },
        &out,
        "fit",
        &["invocation.json", "checkpoint.json"],
        if resuming {
            super::paths::Existing::Resume
        } else {
            super::paths::Existing::from_flags(false, overwrite)
        },
    )?;
    write_json(&out.join("invocation.json"), &a.with_absolute_paths()?)?;
    write_json(&out.join("fit_config.json"), &cfg)?;
    if let Some(s) = &resume {
        eprintln!(
            "resuming {} after iteration {}",
            out.display(),
            s.iters_done
        );
    }
    // The automatic strategy's plan, printed before anything runs (run_fit resolves the
    // same plan from the same inputs).
    let resolved = r4d_optim::video::strategy::resolve(&cfg, &problem.config.parts)?;
    eprintln!(
        "fit: {}{}",
        resolved.config.describe_plan(),
        if !resolved.decisions.is_empty() {
            " (strategy = \"auto\"):"
        } else if cfg.stages.is_some() {
            " (stages from the fit settings)"
        } else {
            ""
        }
    );
    if !resolved.decisions.is_empty() {
        eprintln!(
            "{}",
            r4d_optim::video::strategy::describe(&resolved.decisions)
        );
    }
    let mut hooks = RunHooks::new(&out, &cfg, resume.as_ref())?;
    let outcome = run_fit(&problem, &cfg, resume, &mut hooks).map_err(|e| match e {
        e @ resonance4d::video_fit::FitError::Resume(_) => anyhow::Error::new(e).context(format!(
            "--resume: {}",
            out.join("checkpoint.json").display()
        )),
        e => e.into(),
    })?;
    hooks.finish()?;
    if outcome.budget_spent {
        eprintln!(
            "note: the fit's budget is spent ({}): it ended with the lowest point so far; \
             raise it and --resume {} to go on",
            match (&cfg.budget, cfg.evals) {
                (Some(b), Some(n)) => format!("budget = \"{b}\", evals = {n}"),
                (Some(b), None) => format!("budget = \"{b}\""),
                (None, Some(n)) => format!("evals = {n}"),
                (None, None) => String::new(),
            },
            out.display()
        );
    }
    let files = write_results(&out, &problem, &cfg, &outcome, &hooks.log, a.row, &lpips)?;
    write_json(
        &out.join("summary.json"),
        &serde_json::json!({
            "strategy": if cfg.strategy.is_fixed() { "fixed" } else { "auto" },
            "plan": resolved.config.plan().iter().map(|k| k.name()).collect::<Vec<_>>(),
            "plan_text": resolved.config.describe_plan(),
            "decisions": outcome.decisions,
            "best_loss": outcome.best_loss,
            "evaluations": outcome.evaluations,
            "budget_spent": outcome.budget_spent,
        }),
    )?;
    if physflow_units {
        add_physflow_units(&files.params, &outcome.parts)?;
    }
    println!(
        "{}",
        super::run_hooks::param_table(
            &outcome.init_parts,
            &outcome.parts,
            &outcome.space,
            &hooks.log
        )
    );
    println!("{}", metrics_line(&files.metrics));
    println!(
        "final loss {:.4e}; parameters: {}; run folder: {}",
        files.final_terms.total,
        files.params.display(),
        out.display()
    );
    Ok(())
}

/// Adds `physflow: {E, nu, density, yield_stress, plastic_viscosity}` (PhysFlow's config
/// units) to every part of `params.json`.
fn add_physflow_units(path: &Path, parts: &[r4d_mpm::PartParams]) -> Result<()> {
    let text = r4d_fsio::read_to_string_bounded(path, r4d_fsio::MAX_TEXT_BYTES)
        .with_context(|| format!("reading {}", path.display()))?;
    let mut v: serde_json::Value = serde_json::from_str(&text)?;
    if let Some(list) = v["parts"].as_array_mut() {
        for (rec, p) in list.iter_mut().zip(parts) {
            rec["physflow"] = serde_json::to_value(r4d_datasets::PhysFlowUnits::from_si(p))?;
        }
    }
    write_json(path, &v)?;
    Ok(())
}

/// One line per view of the final report's metrics (`metrics.json`).
pub(crate) fn metrics_line(metrics: &serde_json::Value) -> String {
    let f = |v: &serde_json::Value, digits: usize| match v.as_f64() {
        Some(x) => format!("{x:.digits$}"),
        None => "n/a".into(),
    };
    let mut lines = Vec::new();
    for m in metrics["views"].as_array().into_iter().flatten() {
        let ms = if m["ms_ssim"].is_null() {
            format!(
                "{} ({}-tap window)",
                f(&m["ms_ssim_small_window"]["value"], 4),
                m["ms_ssim_small_window"]["window"]
            )
        } else {
            f(&m["ms_ssim"], 4)
        };
        let psnr = if m["psnr"].is_null() {
            format!(
                "{} (whole video; a frame is identical)",
                f(&m["psnr_video"], 2)
            )
        } else {
            f(&m["psnr"], 2)
        };
        lines.push(format!(
            "view {}: PSNR {} dB, SSIM {}, MS-SSIM {}, LPIPS-alex {}, LPIPS-vgg {}",
            m["view"],
            psnr,
            f(&m["ssim"], 4),
            ms,
            f(&m["lpips_alex"], 4),
            f(&m["lpips_vgg"], 4)
        ));
    }
    lines.join("\n")
}
