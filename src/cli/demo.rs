//! `r4d demo`: the built-in two-part plant, fitted from scratch (see `resonance4d::demo`).

use super::run_hooks::{param_table, RunHooks};
use anyhow::{Context, Result};
use resonance4d::demo::{run_demo, DemoOptions};
use resonance4d::video_fit::report::{write_json, write_results};
use std::path::PathBuf;

/// Arguments of `r4d demo`.
#[derive(clap::Args, Debug)]
pub struct DemoArgs {
    /// Run folder (the reference video, the inputs as files, the fit's outputs and
    /// summary.json).
    #[arg(long, default_value = "out/demo")]
    out: PathBuf,
    /// A smoke-test run: 4 candidates, 2 iterations (seconds, not minutes; no accuracy).
    #[arg(long)]
    quick: bool,
    /// AdamW iterations (default 30).
    #[arg(long)]
    iters: Option<usize>,
    /// Latin hypercube candidates (default 16).
    #[arg(long)]
    candidates: Option<usize>,
    /// Seed of the initialisation.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Where the fit's simulation and reverse sweep run: cpu or wgpu (f32 on a GPU; the
    /// reference video is always simulated on the CPU).
    #[arg(long, default_value = "cpu")]
    backend: String,
    /// LPIPS weights for the final report's metrics (as `r4d metrics --lpips-weights`).
    /// Repeatable. Default: $R4D_LPIPS_DIR.
    #[arg(long = "lpips-weights", value_name = "FILE")]
    lpips_weights: Vec<PathBuf>,
}

/// Runs the command.
pub fn run(a: DemoArgs) -> Result<()> {
    let t_start = std::time::Instant::now();
    let mut opts = if a.quick {
        DemoOptions::quick()
    } else {
        DemoOptions::default()
    };
    if let Some(i) = a.iters {
        opts.iters = i;
    }
    if let Some(c) = a.candidates {
        opts.candidates = c;
    }
    opts.seed = a.seed;
    let lpips = r4d_loss::lpips::load_all(&a.lpips_weights).context("--lpips-weights")?;
    let out = a.out.clone();
    std::fs::create_dir_all(&out).with_context(|| format!("creating {}", out.display()))?;
    eprintln!(
        "demo: a two-part plant (stiff stem, soft heavy head), 16 frames at 256x192; fitting E and density of both parts from {} Latin hypercube candidates and {} iterations",
        opts.candidates, opts.iters
    );
    let cfg = resonance4d::demo::fit_config(&opts);
    let mut hooks = RunHooks::new(&out, &cfg, None)?;
    let gpu = super::fit::gpu_for(&a.backend)?;
    let mut run = run_demo(&opts, &mut hooks, gpu)?;
    hooks.finish()?;
    let files = write_results(
        &out,
        &run.problem,
        &run.config,
        &run.outcome,
        &hooks.log,
        None,
        &lpips,
    )?;
    run.summary.final_loss = Some(files.final_terms.clone());
    run.summary.metrics = Some(files.metrics.clone());
    run.summary.wall_time_s = t_start.elapsed().as_secs_f64();
    // The inputs, so `r4d fit` can be run on them.
    let p = &run.problem;
    let inputs = out.join("inputs");
    std::fs::create_dir_all(&inputs)?;
    r4d_splat::ply::write_gaussians(&inputs.join("scene.ply"), &p.scene)?;
    r4d_loss::io::write_npy(&inputs.join("reference.npy"), &p.views[0].video.to_f32())?;
    // TOML: the clamp's end time is +infinity, which JSON cannot hold.
    let mut sim = p.config.clone();
    sim.particles = Some("particles.ply".into());
    std::fs::write(inputs.join("sim.toml"), toml::to_string(&sim)?)?;
    write_json(
        &inputs.join("cameras.json"),
        &serde_json::json!({
            "background": p.settings.background,
            "rasterize_mode": "classic",
            "cameras": [p.views[0].camera],
        }),
    )?;
    let mut labels = vec![-1i32; p.scene.len()];
    for (s, &g) in p.link.simulated.iter().enumerate() {
        labels[g as usize] = p.particles.part[s] as i32;
    }
    write_json(
        &inputs.join("parts.json"),
        &resonance4d::video_fit::PartLabels {
            num_parts: 2,
            class_names: vec!["stem".into(), "head".into()],
            labels,
            ..Default::default()
        },
    )?;
    let particles_path = inputs.join("particles.ply");
    let cols: Vec<Vec<f32>> = (0..3)
        .map(|k| p.particles.x.iter().map(|x| x[k]).collect())
        .chain(std::iter::once(p.particles.volume.clone()))
        .collect();
    let refs: Vec<&[f32]> = cols.iter().map(|c| c.as_slice()).collect();
    r4d_mpm::ply::write_ply(&particles_path, &["x", "y", "z", "volume"], &refs)?;
    write_json(&out.join("summary.json"), &run.summary)?;
    let truth = resonance4d::demo::truth();
    println!();
    println!(
        "{}",
        param_table(&run.outcome.init_parts, &run.outcome.parts, Some(&truth))
    );
    println!("identifiability (loss profiles around the truth):");
    for pr in &run.summary.profiles {
        println!(
            "  {:<16} relative sensitivity {:>6.3}  {}",
            pr.name,
            pr.relative_sensitivity,
            if pr.identifiable {
                "identifiable"
            } else {
                "NOT identifiable from this video"
            }
        );
    }
    println!("{}", super::fit::metrics_line(&files.metrics));
    let t = &files.final_terms;
    println!(
        "final loss {:.4e} (1-SSIM {:.4e}, mag {:.4e}, phase {:.4e}); wall time {:.1} s",
        t.total,
        t.spatial.unwrap_or(f64::NAN),
        t.mag.unwrap_or(f64::NAN),
        t.phase.unwrap_or(f64::NAN),
        run.summary.wall_time_s
    );
    println!(
        "run folder: {} (summary.json, params.json, side_by_side.gif and .mp4, loss_curve.png, inputs/)",
        out.display()
    );
    Ok(())
}
