//! `r4d fit-trajectory`: fit part parameters to target particle trajectories.

use anyhow::{bail, Context, Result};
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use r4d_mpm::adjoint::checkpoint::Checkpointing;
use r4d_mpm::adjoint::trajectory_loss::TrajectoryLoss;
use r4d_mpm::ply::read_ply;
use r4d_optim::{AdamW, ParamKind};
use resonance4d::fit_trajectory::{
    fit_trajectory_resumable, FitError, FitOptions, FitState, Granularity, PartRecord,
};
use serde_json::json;
use std::io::IsTerminal;
use std::path::{Path, PathBuf};

/// Arguments of `r4d fit-trajectory`.
#[derive(clap::Args, Debug)]
pub struct FitTrajectoryArgs {
    /// The scene (for fitting, its part parameters are the starting point).
    #[command(flatten)]
    scene: super::scene::SceneArgs,
    /// Folder of target frames as `r4d simulate` writes them (frame_0001.ply, ...).
    #[arg(long)]
    target: PathBuf,
    /// Comma-separated free parameters: E, nu, yield_stress, plastic_viscosity,
    /// friction_angle, density, hardening (metal with `hardening = true`), softening
    /// (plasticine). A parameter a part's model does not read is refused.
    #[arg(long, default_value = "E")]
    params: String,
    /// Output folder: params.json and log.jsonl.
    #[arg(long)]
    out: PathBuf,
    /// Iterations.
    #[arg(long, default_value_t = 30)]
    iters: usize,
    /// Learning rate (log units per step); decays along a cosine to 5% over the run.
    #[arg(long, default_value_t = 0.3)]
    lr: f64,
    /// Adam's first-moment decay (0.5: little momentum, so a fit of a few log-parameters
    /// does not overshoot its minimum).
    #[arg(long, default_value_t = 0.5)]
    beta1: f64,
    /// Adam's second-moment decay.
    #[arg(long, default_value_t = 0.999)]
    beta2: f64,
    /// Loss: position (corresponding particles) or chamfer.
    #[arg(long, default_value = "position")]
    loss: String,
    /// Parameter granularity: part, object or particle (per-particle values are written to
    /// OUT/params_particles.ply).
    #[arg(long, default_value = "part")]
    granularity: String,
    /// Checkpointing: per-frame, store-all, every:N or nested:N (frame checkpoints, then every
    /// N substeps inside a frame during the backward pass).
    #[arg(long, default_value = "per-frame")]
    checkpointing: String,
    /// Number of frames to fit (default: all target frames the config's frames allow).
    #[arg(long)]
    frames: Option<usize>,
    /// Continue a killed run from OUT/checkpoint.json (written after every iteration).
    #[arg(long)]
    resume: bool,
    /// OUT holds an earlier run of `r4d fit-trajectory`: remove its files first, then fit
    /// from the start (without this or --resume a non-empty OUT is refused).
    #[arg(long, conflicts_with = "resume")]
    overwrite: bool,
    /// Where the simulation and its reverse sweep run: cpu (f64, all cores), wgpu (f32 on a
    /// GPU; `R4D_WGPU_ADAPTER=name` picks the adapter) or reference (f64, one core, the
    /// gradient oracle; slow).
    #[arg(long, value_enum, default_value_t = super::BackendKind::Cpu)]
    backend: super::BackendKind,
    /// Print the GPU time of every kernel when the command ends (timestamp queries; the
    /// Vulkan backend measures it, the others say they cannot).
    #[arg(long)]
    profile: bool,
}

fn read_targets(dir: &Path, max: usize) -> Result<Vec<Vec<[f32; 3]>>> {
    // A gap in the folder's frame_NNNN.ply numbering is an error, not the end of the targets.
    if let Ok(rd) = std::fs::read_dir(dir) {
        let listed: Vec<PathBuf> = rd
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| {
                p.file_name()
                    .and_then(|n| n.to_str())
                    .is_some_and(|n| n.starts_with("frame_") && n.ends_with(".ply"))
            })
            .collect();
        r4d_fsio::seq::check_numbering(&listed)?;
    }
    let mut out = Vec::new();
    for k in 1..=max {
        let f = dir.join(format!("frame_{k:04}.ply"));
        if !f.exists() {
            break;
        }
        let ply = read_ply(&f)?;
        let col = |n: &str| {
            ply.get(n)
                .with_context(|| format!("{}: missing property '{n}'", f.display()))
        };
        let (x, y, z) = (col("x")?, col("y")?, col("z")?);
        out.push((0..ply.count).map(|i| [x[i], y[i], z[i]]).collect());
    }
    if out.is_empty() {
        bail!(
            "{}: no target frames (expected frame_0001.ply, ...)",
            dir.display()
        );
    }
    Ok(out)
}

/// Runs the command.
pub fn run(a: FitTrajectoryArgs) -> Result<()> {
    a.scene
        .inputs(super::paths::Io::new())
        .input("--target", &a.target)
        .output("--out", &a.out)
        .check()?;
    let loaded = a.scene.load()?;
    let mut config = loaded.config;
    if let Some(f) = a.frames {
        config.time.frames = f;
        // The same budget as the config's `frames`, before anything is written.
        config.time.validate(&format!("--frames {f}"))?;
    }
    r4d_optim::video::config::check_iters(a.iters).map_err(|m| anyhow::anyhow!("--{m}"))?;
    let params = a
        .params
        .split(',')
        .filter(|s| !s.trim().is_empty())
        .map(ParamKind::parse)
        .collect::<Result<Vec<_>, _>>()?;
    if params.is_empty() {
        bail!("--params: name at least one parameter");
    }
    let loss = match a.loss.as_str() {
        "position" => TrajectoryLoss::Position,
        "chamfer" => TrajectoryLoss::Chamfer,
        o => bail!("--loss: unknown loss '{o}' (position, chamfer)"),
    };
    let granularity = match a.granularity.as_str() {
        "part" => Granularity::Part,
        "object" => Granularity::Object,
        "particle" => Granularity::Particle,
        o => bail!("--granularity: unknown '{o}' (part, object, particle)"),
    };
    let checkpointing = Checkpointing::parse(&a.checkpointing)
        .map_err(|e| anyhow::anyhow!("--checkpointing: {e}"))?;
    // The optimiser's settings, checked as `fit` checks FIT.toml's (one validation path)
    // before anything is written.
    let adam = AdamW {
        lr: a.lr,
        beta1: a.beta1,
        beta2: a.beta2,
        ..Default::default()
    };
    adam.validate().map_err(|e| anyhow::anyhow!("--{e}"))?;
    let backend = a.backend.compute()?;
    let _profile = super::profile::Profile::on_compute(&backend, a.profile)?;
    let targets = read_targets(&a.target, config.time.frames)?;
    super::paths::claim_dir(
        "--out",
        &a.out,
        "fit-trajectory",
        &["checkpoint.json", "params.json", "log.jsonl"],
        super::paths::Existing::from_flags(a.resume, a.overwrite),
    )?;
    let log_path = a.out.join("log.jsonl");
    let ck_path = a.out.join("checkpoint.json");
    let resume: Option<FitState> = if a.resume {
        super::checkpoint::read(&ck_path)?
    } else {
        None
    };
    if let Some(ck) = &resume {
        eprintln!(
            "resuming after iteration {} from {}",
            ck.iters_done,
            ck_path.display()
        );
    }
    let mut log =
        super::run_hooks::open_log(&log_path, resume.as_ref().map_or(0, |s| s.iters_done))?;
    let bar = if std::io::stderr().is_terminal() {
        ProgressBar::new(a.iters as u64)
    } else {
        ProgressBar::with_draw_target(Some(a.iters as u64), ProgressDrawTarget::hidden())
    };
    bar.set_style(
        ProgressStyle::with_template("{bar:40} iter {pos}/{len} [{elapsed} < {eta}] {msg}")
            .expect("valid template"),
    );
    let opts = FitOptions {
        params,
        iters: a.iters,
        adam,
        loss,
        checkpointing,
        granularity,
        ..Default::default()
    };
    let mut io_error = None;
    let mut ck_error = None;
    if let Some(ck) = &resume {
        bar.set_position(ck.iters_done as u64);
    }
    let save = |ck: &FitState| super::checkpoint::write(&ck_path, ck);
    let fitted = fit_trajectory_resumable(
        &*backend,
        &config,
        &loaded.scene,
        &targets,
        &opts,
        resume,
        |it| {
            bar.inc(1);
            bar.set_message(format!("loss {:.3e}", it.loss.total));
            if let Err(e) = super::run_hooks::append_record(&mut log, it) {
                io_error.get_or_insert(e);
            }
        },
        |ck| {
            if let Err(e) = save(ck) {
                ck_error.get_or_insert(e);
            }
        },
    )
    .map_err(|e| match e {
        e @ FitError::Backend { .. } => {
            anyhow::Error::new(e).context(format!("--backend {}", a.backend.name()))
        }
        e @ FitError::Resume(_) => {
            anyhow::Error::new(e).context(format!("--resume: {}", ck_path.display()))
        }
        e => e.into(),
    })?;
    if let Some(e) = ck_error {
        return Err(e).with_context(|| format!("writing {}", ck_path.display()));
    }
    bar.finish_and_clear();
    if let Some(e) = io_error {
        return Err(e).with_context(|| format!("writing {}", log_path.display()));
    }
    if let Some(per) = &fitted.per_particle {
        let x = &loaded.scene.x;
        let col = |f: &dyn Fn(&r4d_mpm::PartParams) -> f64| -> Vec<f32> {
            per.iter().map(|p| f(p) as f32).collect()
        };
        let cols: Vec<Vec<f32>> = vec![
            x.iter().map(|p| p[0]).collect(),
            x.iter().map(|p| p[1]).collect(),
            x.iter().map(|p| p[2]).collect(),
            loaded.scene.part.iter().map(|&p| p as f32).collect(),
            col(&|p| p.youngs_modulus_pa),
            col(&|p| p.poisson_ratio),
            col(&|p| p.density_kg_m3),
            col(&|p| p.yield_stress_pa),
            col(&|p| p.plastic_viscosity_pa_s),
            col(&|p| p.friction_angle_deg),
        ];
        let refs: Vec<&[f32]> = cols.iter().map(|c| c.as_slice()).collect();
        let names = [
            "x",
            "y",
            "z",
            "part",
            "E",
            "nu",
            "density",
            "yield_stress",
            "plastic_viscosity",
            "friction_angle",
        ];
        let path = a.out.join("params_particles.ply");
        r4d_mpm::ply::write_ply(&path, &names, &refs)?;
    }
    let records: Vec<PartRecord> = fitted
        .parts
        .iter()
        .enumerate()
        .map(|(i, p)| PartRecord::of(i, p))
        .collect();
    let path = a.out.join("params.json");
    r4d_fsio::write_atomic(
        &path,
        (serde_json::to_string_pretty(&json!({ "parts": records }))? + "\n").as_bytes(),
    )
    .with_context(|| format!("writing {}", path.display()))?;
    println!(
        "fitted parameters: {}; log: {}",
        path.display(),
        log_path.display()
    );
    Ok(())
}
