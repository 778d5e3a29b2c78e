//! `r4d fit`: fit the material parameters of every part to a reference video.

use super::run_hooks::RunHooks;
use anyhow::{bail, Context, Result};
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
    /// Reference video: a .npy (T, H, W, 3) float array or a folder of PNG frames (the format
    /// of `r4d metrics`). Frame 0 shows the rest state.
    #[arg(long)]
    video: Option<PathBuf>,
    /// Index of the video's camera in --cameras.
    #[arg(long, default_value_t = 0)]
    video_camera: usize,
    /// Frame rate of the video (default: the simulation's, 1 / frame_dt). Rendered frames are
    /// resampled linearly in time when it differs.
    #[arg(long)]
    fps: Option<f64>,
    /// Run folder: params.json, log.jsonl, checkpoint.json, the fitted video and diagnostics.
    #[arg(long)]
    out: Option<PathBuf>,
    /// Fit settings (TOML; see the README's `r4d fit` section).
    #[arg(long)]
    config: Option<PathBuf>,
    /// Where the simulation and its reverse sweep run: cpu (all cores, f64 by default) or
    /// wgpu (WGSL on a GPU, f32; `R4D_WGPU_ADAPTER=name` picks an adapter). Rendering and the
    /// loss run on the CPU either way.
    #[arg(long, default_value = "cpu")]
    backend: String,
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
}

fn need<'a>(v: &'a Option<PathBuf>, flag: &str) -> Result<&'a PathBuf> {
    v.as_ref()
        .with_context(|| format!("{flag} is required (or --resume DIR)"))
}

fn is_physgaussian(path: &Path) -> bool {
    path.extension().is_some_and(|e| e == "json")
        && std::fs::read_to_string(path)
            .ok()
            .and_then(|t| serde_json::from_str::<serde_json::Value>(&t).ok())
            .is_some_and(|v| v.get("time").is_none() && v.get("n_grid").is_some())
}

/// The GPU to simulate on for `--backend`: `None` for cpu.
pub fn gpu_for(backend: &str) -> Result<Option<resonance4d::video_fit::GpuHandle>> {
    match backend {
        "cpu" => Ok(None),
        "wgpu" => {
            let ctx = r4d_backend_wgpu::context::WgpuContext::new()
                .map_err(|e| anyhow::anyhow!("--backend wgpu: {e}"))?;
            Ok(Some(resonance4d::video_fit::GpuHandle(
                std::sync::Arc::new(ctx),
            )))
        }
        o => bail!("--backend: unknown '{o}' (cpu, wgpu)"),
    }
}

/// Loads every input into a problem.
pub fn load_problem(a: &FitArgs) -> Result<VideoProblem> {
    let scene_path = need(&a.scene, "--scene")?;
    let sim_path = need(&a.sim, "--sim")?;
    let parts_path = need(&a.parts, "--parts")?;
    let cams_path = need(&a.cameras, "--cameras")?;
    let video_path = need(&a.video, "--video")?;
    let scene = r4d_splat::ply::read_gaussians(scene_path)?;
    let loaded = super::scene::load(sim_path, is_physgaussian(sim_path), a.particles.as_ref())?;
    let mut config = loaded.config;
    let mut particles = loaded.scene;
    let labels = PartLabels::load(parts_path)?;
    let link = match &a.link {
        Some(p) => r4d_splat::SimLink::load(p)?,
        None => labels.identity_link(),
    };
    if labels.labels.len() != scene.len() {
        bail!(
            "{}: {} labels but {} has {} Gaussians",
            parts_path.display(),
            labels.labels.len(),
            scene_path.display(),
            scene.len()
        );
    }
    particles.part = labels
        .particle_parts(&link, &particles.x)
        .with_context(|| format!("assigning parts from {}", parts_path.display()))?;
    if config.parts.len() < labels.num_parts {
        let last = *config
            .parts
            .last()
            .context("the simulation config has no part")?;
        eprintln!(
            "warning: {} has {} part(s), the labels {}: the missing parts start from the last part's parameters",
            sim_path.display(),
            config.parts.len(),
            labels.num_parts
        );
        config.parts.resize(labels.num_parts, last);
    }
    let set = r4d_splat::load_cameras(cams_path)?;
    let camera = set
        .cameras
        .get(a.video_camera)
        .with_context(|| {
            format!(
                "--video-camera {}: {} has {} camera(s)",
                a.video_camera,
                cams_path.display(),
                set.cameras.len()
            )
        })?
        .clone();
    let video = r4d_loss::io::read_video::<f32>(video_path)?;
    let t = &config.time;
    let frame_dt = t.substeps() as f64 * t.substep_dt;
    let fps = a.fps.unwrap_or(1.0 / frame_dt);
    let problem = VideoProblem {
        config,
        particles,
        scene,
        link,
        settings: r4d_splat::RenderSettings {
            background: set.background.unwrap_or([0.0; 3]),
            mode: set.mode.unwrap_or_default(),
        },
        views: vec![View {
            name: video_path.display().to_string(),
            camera,
            // 8-bit frames are kept as bytes (a quarter of f32, exact).
            video: video.into(),
        }],
        fps,
        gpu: None,
    };
    problem.validate()?;
    let side = problem.views[0]
        .camera
        .width
        .min(problem.views[0].camera.height) as usize;
    if side <= 160 {
        if let Some(c) = r4d_loss::MsSsimConfig::largest_window(side) {
            eprintln!(
                "note: frames of {side} px on their short side are too small for the standard MS-SSIM (11-tap window, > 160 px); the initialisation scores candidates with a {}-tap window (r4d_loss::MsSsimConfig::largest_window)",
                c.window
            );
        }
    }
    Ok(problem)
}

/// Runs the command.
pub fn run(a: FitArgs) -> Result<()> {
    let (a, out, resume) = match &a.resume {
        Some(dir) => {
            let inv = dir.join("invocation.json");
            let text = std::fs::read_to_string(&inv)
                .with_context(|| format!("--resume: reading {}", inv.display()))?;
            let saved: FitArgs = serde_json::from_str(&text)
                .with_context(|| format!("{}: not an r4d fit invocation", inv.display()))?;
            let ck = dir.join("checkpoint.json");
            let state: Option<FitState> = match std::fs::read_to_string(&ck) {
                Ok(t) => Some(
                    serde_json::from_str(&t)
                        .with_context(|| format!("{}: not a fit checkpoint", ck.display()))?,
                ),
                Err(_) => None,
            };
            (saved, dir.clone(), state)
        }
        None => {
            let out = need(&a.out, "--out")?.clone();
            (a, out, None)
        }
    };
    let gpu = gpu_for(&a.backend)?;
    // Loaded (and checked) before the fit, used by its final report.
    let lpips = r4d_loss::lpips::load_all(&a.lpips_weights).context("--lpips-weights")?;
    let cfg = match &a.config {
        Some(p) => FitConfig::load(p)?,
        None => FitConfig::default(),
    };
    let mut problem = load_problem(&a)?;
    problem.gpu = gpu;
    std::fs::create_dir_all(&out).with_context(|| format!("creating {}", out.display()))?;
    write_json(&out.join("invocation.json"), &a)?;
    write_json(&out.join("fit_config.json"), &cfg)?;
    if let Some(s) = &resume {
        eprintln!(
            "resuming {} after iteration {}",
            out.display(),
            s.iters_done
        );
    }
    let mut hooks = RunHooks::new(&out, &cfg, resume.as_ref())?;
    let outcome = run_fit(&problem, &cfg, resume, &mut hooks)?;
    hooks.finish()?;
    let files = write_results(&out, &problem, &cfg, &outcome, &hooks.log, a.row, &lpips)?;
    println!(
        "{}",
        super::run_hooks::param_table(&outcome.init_parts, &outcome.parts, None)
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
