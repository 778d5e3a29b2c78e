//! `r4d simulate`: run a simulation from a config and write frames.

use super::paths::{claim_dir, Existing, Io};
use super::BackendKind;
use anyhow::{Context, Result};
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use r4d_backend_cpu::CpuBackend;
use r4d_mpm::{
    ply::write_ply, reference::ReferenceBackend, MpmKernels, ParticleSet, SimConfig, Simulation,
    Simulator,
};
use serde_json::json;
use std::io::IsTerminal;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Arguments of `r4d simulate`.
#[derive(clap::Args, Debug)]
pub struct SimulateArgs {
    /// The scene (for fitting, its part parameters are the starting point).
    #[command(flatten)]
    scene: super::scene::SceneArgs,
    /// Output folder for frame_NNNN.ply and summary.json.
    #[arg(long)]
    out: PathBuf,
    /// Compute backend.
    #[arg(long, value_enum, default_value_t = BackendKind::Cpu)]
    backend: BackendKind,
    /// Print the GPU time of every kernel when the command ends (timestamp queries; the
    /// Vulkan backend measures it, the others say they cannot).
    #[arg(long)]
    profile: bool,
    /// Also write the deformation gradient as f00..f22 (fij = F_ij = dx_i / dX_j).
    #[arg(long)]
    write_f: bool,
    /// Override the number of frames.
    #[arg(long)]
    frames: Option<usize>,
    /// Continue a killed run from OUT/state.r4d (the state after the last written frame,
    /// saved after every frame); frames already on disk are kept.
    #[arg(long)]
    resume: bool,
    /// OUT holds an earlier run of `r4d simulate`: remove its files first, then simulate
    /// from the start (without this or --resume a non-empty OUT is refused).
    #[arg(long, conflicts_with = "resume")]
    overwrite: bool,
}

/// Runs the command.
pub fn run(a: SimulateArgs) -> Result<()> {
    a.scene.inputs(Io::new()).output("--out", &a.out).check()?;
    let loaded = a.scene.load()?;
    let mut config = loaded.config;
    if let Some(f) = a.frames {
        config.time.frames = f;
        // The same budget as the config's `frames`, before anything is written.
        config.time.validate(&format!("--frames {f}"))?;
    }
    let (scene, source, warnings) = (loaded.scene, loaded.source, loaded.warnings);
    let vulkan = matches!(a.backend, BackendKind::Vulkan);
    let _unmeasured = super::profile::Profile::unsupported(a.backend.name(), a.profile && !vulkan);
    match a.backend {
        BackendKind::Cpu => simulate(CpuBackend::default(), &a, config, scene, &source, &warnings),
        BackendKind::Reference => simulate(
            ReferenceBackend::new(),
            &a,
            config,
            scene,
            &source,
            &warnings,
        ),
        BackendKind::Wgpu => {
            let ctx = r4d_backend_wgpu::WgpuContext::new()?;
            eprintln!("wgpu adapter: {} ({:?})", ctx.info.name, ctx.info.backend);
            let backend = r4d_backend_wgpu::WgpuBackend::new(std::sync::Arc::new(ctx));
            simulate(backend, &a, config, scene, &source, &warnings)
        }
        BackendKind::Vulkan => {
            let e = r4d_backend_vulkan::VulkanEngine::new()
                .map_err(|e| anyhow::anyhow!("--backend vulkan: {e}"))?;
            eprintln!("vulkan device: {}", e.device_name());
            let _profile = super::profile::Profile::on_vulkan(&e, a.profile)?;
            let backend = r4d_backend_vulkan::VulkanBackend::new(e);
            simulate(backend, &a, config, scene, &source, &warnings)
        }
    }
}

fn write_frame(dir: &Path, k: usize, x: &[[f32; 3]], f: Option<&[[f32; 9]]>) -> Result<()> {
    let cols: Vec<Vec<f32>> = (0..3).map(|a| x.iter().map(|p| p[a]).collect()).collect();
    let mut names = vec!["x", "y", "z"];
    let mut data: Vec<Vec<f32>> = cols;
    const F_NAMES: [&str; 9] = [
        "f00", "f01", "f02", "f10", "f11", "f12", "f20", "f21", "f22",
    ];
    if let Some(f) = f {
        for (e, name) in F_NAMES.iter().enumerate() {
            names.push(name);
            data.push(f.iter().map(|m| m[e]).collect());
        }
    }
    let refs: Vec<&[f32]> = data.iter().map(|c| c.as_slice()).collect();
    write_ply(&dir.join(format!("frame_{k:04}.ply")), &names, &refs)?;
    Ok(())
}

/// The fingerprint a run's `state.r4d` carries: the config (its frame count excepted: a
/// resumed run may simulate more frames), the particles, the backend and `--write-f`.
fn fingerprint(config: &SimConfig, scene: &ParticleSet, backend: &str, write_f: bool) -> String {
    let mut f = r4d_fsio::Fingerprint::new();
    f.text("simulate");
    let mut c = config.clone();
    c.time.frames = 0;
    f.text(&serde_json::to_string(&c).unwrap_or_default());
    f.points(&scene.x);
    f.f32s(&scene.volume);
    f.u32s(&scene.part);
    f.text(backend);
    f.word(u64::from(write_f));
    f.finish()
}

fn simulate<B: MpmKernels>(
    backend: B,
    a: &SimulateArgs,
    config: SimConfig,
    scene: ParticleSet,
    source: &str,
    warnings: &[String],
) -> Result<()> {
    claim_dir(
        "--out",
        &a.out,
        "simulate",
        &["state.r4d", "summary.json", "frame_0000.ply"],
        Existing::from_flags(a.resume, a.overwrite),
    )?;
    let n = scene.len();
    let backend_name = backend.name();
    let print = fingerprint(&config, &scene, backend_name, a.write_f);
    let mut sim = Simulation::new(backend, &config, scene, source)?;
    let params = config.parts.clone();
    let snap_path = a.out.join("state.r4d");
    let resumed = a.resume && snap_path.exists();
    let mut state = if resumed {
        let snap = r4d_mpm::Snapshot::read(&snap_path, n, &print)?;
        eprintln!(
            "resuming after frame {} from {}",
            snap.frame,
            snap_path.display()
        );
        sim.restore(&snap, &params)?
    } else {
        sim.init_state(&params)?
    };
    let first_frame = state.frame;
    let frames = config.time.frames;
    let spf = sim.setup().substeps_per_frame;
    let bar = if std::io::stderr().is_terminal() {
        ProgressBar::new(frames as u64)
    } else {
        ProgressBar::with_draw_target(Some(frames as u64), ProgressDrawTarget::hidden())
    };
    bar.set_style(
        ProgressStyle::with_template("{bar:40} frame {pos}/{len} [{elapsed} < {eta}] {msg}")
            .expect("valid template"),
    );
    let start = Instant::now();
    let write = |sim: &Simulation<B>, state: &r4d_mpm::SimState<B>, k: usize| -> Result<()> {
        let x = sim.positions(state)?;
        let f = if a.write_f {
            Some(sim.deformation_gradients(state)?)
        } else {
            None
        };
        write_frame(&a.out, k, &x, f.as_deref())
    };
    if !resumed {
        write(&sim, &state, 0)?;
    }
    bar.set_position(first_frame as u64);
    let mut error = None;
    for k in first_frame + 1..=frames {
        if let Err(e) = sim.step_frame(&mut state, &params) {
            error = Some(e);
            break;
        }
        write(&sim, &state, k)?;
        let mut snap = sim.snapshot(&state)?;
        snap.fingerprint.clone_from(&print);
        snap.write(&snap_path)?;
        bar.inc(1);
    }
    bar.finish_and_clear();
    let wall = start.elapsed().as_secs_f64();
    let done = state.frame;
    // Substeps run by this invocation (a resumed run started after `first_frame`).
    let run_substeps = state.substep - first_frame as u64 * spf as u64;
    let summary = json!({
        "config": config,
        "config_file": a.scene.config,
        "physgaussian": a.scene.physgaussian,
        "particles_file": a.scene.particles,
        "backend": backend_name,
        "particles": n,
        "frames": done + 1,
        "frames_simulated": done,
        "resumed_after_frame": resumed.then_some(first_frame),
        "substeps_per_frame": spf,
        "substeps": state.substep,
        "substep_dt": config.time.substep_dt,
        "simulated_time_s": state.time_s,
        "wall_time_s": wall,
        "particle_substeps_per_s": if wall > 0.0 { n as f64 * run_substeps as f64 / wall } else { 0.0 },
        "write_f": a.write_f,
        "warnings": warnings,
        "error": error.as_ref().map(|e| e.to_string()),
    });
    let sp = a.out.join("summary.json");
    r4d_fsio::write_atomic(
        &sp,
        (serde_json::to_string_pretty(&summary)? + "\n").as_bytes(),
    )
    .with_context(|| format!("writing {}", sp.display()))?;
    if let Some(e) = error {
        return Err(
            anyhow::Error::new(e).context(format!("frames 0..={done} are in {}", a.out.display()))
        );
    }
    println!(
        "wrote {} frames of {n} particles to {} ({:.1} s, {:.2e} particle-substeps/s); summary: {}",
        done + 1,
        a.out.display(),
        wall,
        n as f64 * run_substeps as f64 / wall.max(1e-9),
        sp.display()
    );
    Ok(())
}
