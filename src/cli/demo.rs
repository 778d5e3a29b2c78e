//! `r4d demo`: a built-in scene with known parameters, fitted from its video alone (see
//! `resonance4d::demo`).

use super::run_hooks::RunHooks;
use anyhow::{Context, Result};
use resonance4d::demo::{run_demo, DemoOptions, DemoRun, DemoScene, Recovery, Size};
use resonance4d::video_fit::report::{write_json, write_results};
use std::path::{Path, PathBuf};

/// Arguments of `r4d demo`.
#[derive(clap::Args, Debug)]
pub struct DemoArgs {
    /// The scene: plant (two jelly parts, E and density), metal (a cantilever bent past
    /// yield: E, nu, yield stress, density), sand (a slumping column: friction angle ...),
    /// foam (a pressed block: yield stress, plastic viscosity ...), plasticine (a blob
    /// thrown onto the floor), paste (a slumping column of PhysFlow's non_newtonian: E, yield
    /// stress, plastic viscosity) or fluid (a viscous drop spreading: bulk modulus as E,
    /// viscosity).
    #[arg(long, default_value = "plant")]
    scene: String,
    /// Run folder (the reference videos, the inputs as files, the fit's outputs and
    /// summary.json). Default: out/demo for the plant, out/demo-SCENE otherwise.
    #[arg(long)]
    out: Option<PathBuf>,
    /// --out holds an earlier demo run: remove its files first (without this a non-empty
    /// --out is refused; the default folder is always replaced when it holds a demo run).
    #[arg(long)]
    overwrite: bool,
    /// A smoke-test run: 4 candidates, 2 iterations, coarse profiles (seconds to a minute,
    /// not minutes; no accuracy).
    #[arg(long)]
    quick: bool,
    /// The test-size version of the scene (grid 16, a few hundred particles, 96 x 72 views:
    /// a fit in a minute or two instead of several).
    #[arg(long)]
    small: bool,
    /// Iterations (default: the scene's, 30-40).
    #[arg(long)]
    iters: Option<usize>,
    /// Latin hypercube candidates (default: the scene's, 16-24).
    #[arg(long)]
    candidates: Option<usize>,
    /// Skip the loss profiles and identifiability verdicts (faster; every parameter is then
    /// reported as not judged).
    #[arg(long)]
    no_profiles: bool,
    /// Seed of the initialisation.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Where the fit's simulation and reverse sweep run: cpu or wgpu (f32 on a GPU; the
    /// reference videos are always simulated on the CPU).
    #[arg(long, value_enum, default_value_t = super::BackendKind::Cpu)]
    backend: super::BackendKind,
    /// Print the GPU time of every kernel when the command ends (timestamp queries; the
    /// Vulkan backend measures it, the others say they cannot).
    #[arg(long)]
    profile: bool,
    /// LPIPS weights for the final report's metrics (as `r4d metrics --lpips-weights`).
    /// Repeatable. Default: $R4D_LPIPS_DIR.
    #[arg(long = "lpips-weights", value_name = "FILE")]
    lpips_weights: Vec<PathBuf>,
}

/// Runs the command.
pub fn run(a: DemoArgs) -> Result<()> {
    let t_start = std::time::Instant::now();
    let scene = DemoScene::parse(&a.scene)?;
    // Counts are bounded before anything is loaded or written.
    if let Some(n) = a.candidates {
        r4d_optim::video::config::check_candidates(n).map_err(|m| anyhow::anyhow!("--{m}"))?;
    }
    if let Some(n) = a.iters {
        r4d_optim::video::config::check_iters(n).map_err(|m| anyhow::anyhow!("--{m}"))?;
    }
    let mut opts = if a.quick {
        DemoOptions::quick()
    } else {
        DemoOptions::full()
    };
    if a.iters.is_some() {
        opts.iters = a.iters;
    }
    if a.candidates.is_some() {
        opts.candidates = a.candidates;
    }
    if a.no_profiles {
        opts.profiles = false;
    }
    opts.seed = a.seed;
    let lpips = r4d_loss::lpips::load_all(&a.lpips_weights).context("--lpips-weights")?;
    let backend = a.backend.compute()?;
    let _profile = super::profile::Profile::on_compute(&backend, a.profile)?;
    let out = a.out.clone().unwrap_or_else(|| match scene {
        DemoScene::Plant => PathBuf::from("out/demo"),
        s => PathBuf::from(format!("out/demo-{}", s.name())),
    });
    super::paths::Io::new()
        .inputs("--lpips-weights", &a.lpips_weights)
        .output("--out", &out)
        .check()?;
    // The default folder belongs to the demo: an earlier demo run there is replaced.
    let replace = a.overwrite || a.out.is_none();
    super::paths::claim_dir(
        "--out",
        &out,
        "demo",
        &["summary.json", "log.jsonl"],
        super::paths::Existing::from_flags(false, replace),
    )?;
    let size = if a.small { Size::Small } else { Size::Full };
    let spec = scene.spec(size);
    let cfg = spec.fit_config(&opts);
    eprintln!(
        "demo: {}; {} Latin hypercube candidates, {} iterations",
        spec.description, cfg.init.candidates, cfg.iters
    );
    let mut hooks = RunHooks::new(&out, &cfg, None)?;
    let mut run = run_demo(
        scene,
        size,
        &opts,
        &mut hooks,
        resonance4d::compute::cpu(),
        backend,
    )?;
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
    write_inputs(&out.join("inputs"), &run)?;
    write_json(&out.join("summary.json"), &run.summary)?;
    println!();
    println!("{}", recovery_table(&run.summary.recovery));
    if run.summary.identifiability.is_empty() {
        println!("identifiability: not judged (--no-profiles)");
    } else {
        println!("identifiability (loss profiles around the truth):");
        for v in &run.summary.identifiability {
            println!(
                "  {:<26} {:<16} {}",
                v.name,
                if v.identifiable {
                    "identifiable"
                } else {
                    "NOT determined"
                },
                v.reason
            );
        }
        for q in &run.summary.profiles_2d {
            println!(
                "  2-D {} vs {}: marginal shares {:.2} / {:.2}{}",
                q.a,
                q.b,
                q.marginal_share[0],
                q.marginal_share[1],
                if q.trade_off { " (trade-off)" } else { "" }
            );
        }
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
    let gifs = if run.problem.views.len() > 1 {
        "view_K/side_by_side.gif and .mp4"
    } else {
        "side_by_side.gif and .mp4"
    };
    println!(
        "run folder: {} (summary.json, params.json, {gifs}, loss_curve.png, inputs/)",
        out.display()
    );
    Ok(())
}

/// The recovery table: truth, start, fit and error per quantity; a quantity the profiles do
/// not call identifiable is printed as "not determined" instead of an error.
pub fn recovery_table(rows: &[Recovery]) -> String {
    use std::fmt::Write as _;
    let mut s = String::new();
    let _ = writeln!(
        s,
        "{:<5} {:<18} {:>11} {:>11} {:>11} {:>15} {:>8}",
        "part", "quantity", "truth", "init", "fit", "fit error", "target"
    );
    for r in rows {
        let degrees = r.quantity == "friction_angle";
        let err = if !r.identifiable {
            "not determined".to_string()
        } else if degrees {
            format!("{:+.2} deg", r.fit_abs_error)
        } else {
            format!("{:+.2}%", 100.0 * r.fit_rel_error)
        };
        let target = match (r.tolerance, r.within_tolerance) {
            (Some(t), Some(ok)) => {
                let t = if degrees {
                    format!("{t:.0} deg")
                } else {
                    format!("{:.0}%", 100.0 * t)
                };
                format!("{t} {}", if ok { "ok" } else { "MISS" })
            }
            _ => "-".into(),
        };
        let _ = writeln!(
            s,
            "{:<5} {:<18} {:>11.4e} {:>11.4e} {:>11.4e} {:>15} {:>8}",
            r.part, r.quantity, r.truth, r.init, r.fit, err, target
        );
    }
    s
}

/// The demo's inputs as files, so `r4d fit` can be run on them: scene, particles, parts,
/// simulation, cameras and one reference video per view (`reference.npy` for one view,
/// `reference_K.npy` for several).
fn write_inputs(inputs: &Path, run: &DemoRun) -> Result<()> {
    let p = &run.problem;
    std::fs::create_dir_all(inputs)?;
    r4d_splat::ply::write_gaussians(&inputs.join("scene.ply"), &p.scene)?;
    for (k, v) in p.views.iter().enumerate() {
        let name = if p.views.len() == 1 {
            "reference.npy".to_string()
        } else {
            format!("reference_{k}.npy")
        };
        r4d_loss::io::write_npy(&inputs.join(name), &v.video.to_f32())?;
    }
    // TOML: the clamp's end time is +infinity, which JSON cannot hold.
    let mut sim = p.config.clone();
    sim.particles = Some("particles.ply".into());
    let sim_path = inputs.join("sim.toml");
    r4d_fsio::write_atomic(&sim_path, toml::to_string(&sim)?.as_bytes())
        .with_context(|| format!("writing {}", sim_path.display()))?;
    let cams: Vec<_> = p.views.iter().map(|v| v.camera.clone()).collect();
    write_json(
        &inputs.join("cameras.json"),
        &serde_json::json!({
            "background": p.settings.background,
            "rasterize_mode": "classic",
            "cameras": cams,
        }),
    )?;
    let mut labels = vec![-1i32; p.scene.len()];
    for (s, &g) in p.link.simulated.iter().enumerate() {
        labels[g as usize] = p.particles.part[s] as i32;
    }
    write_json(
        &inputs.join("parts.json"),
        &resonance4d::video_fit::PartLabels {
            num_parts: run.spec.part_names.len(),
            class_names: run.spec.part_names.clone(),
            labels,
            ..Default::default()
        },
    )?;
    let cols: Vec<Vec<f32>> = (0..3)
        .map(|k| p.particles.x.iter().map(|x| x[k]).collect())
        .chain(std::iter::once(p.particles.volume.clone()))
        .collect();
    let refs: Vec<&[f32]> = cols.iter().map(|c| c.as_slice()).collect();
    r4d_mpm::ply::write_ply(
        &inputs.join("particles.ply"),
        &["x", "y", "z", "volume"],
        &refs,
    )?;
    Ok(())
}
