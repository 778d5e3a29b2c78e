//! Command-line interface: argument parsing and backend selection at runtime.

mod ablate;
mod bench_recovery;
mod bench_scale;
mod checkpoint;
mod dataset;
mod demo;
mod eval;
mod fit;
mod fit_trajectory;
mod metrics;
mod metrics_trajectory;
mod npy;
mod numeric;
mod paths;
mod prepare;
mod profile;
mod render;
mod run_hooks;
mod scene;
mod segment;
mod simulate;

use clap::{Parser, Subcommand, ValueEnum};

/// resonance4d: physically simulated 4D Gaussian scenes from video.
#[derive(Parser, Debug)]
#[command(name = "r4d", version, about)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Run an MPM simulation and write one PLY per frame.
    Simulate(simulate::SimulateArgs),
    /// The built-in demo: a two-part plant rendered from known parameters, fitted back.
    Demo(demo::DemoArgs),
    /// Fit the material parameters of every part to a reference video.
    Fit(fit::FitArgs),
    /// Fit part parameters to target particle trajectories (exact adjoint gradients).
    FitTrajectory(fit_trajectory::FitTrajectoryArgs),
    /// Render a 3DGS scene, one simulated frame of it, or a whole simulated sequence.
    Render(render::RenderArgs),
    /// Preprocess a captured 3DGS scene into simulation particles (PhysGaussian's keys).
    Prepare(prepare::PrepareArgs),
    /// PSNR, SSIM, MS-SSIM, L1 and the DMS loss terms of a rendered video against a reference.
    Metrics(metrics::MetricsArgs),
    /// Chamfer distance, HD95 and F-score between simulated and reference point sequences.
    MetricsTrajectory(metrics_trajectory::MetricsTrajectoryArgs),
    /// Lift 2D segmentation masks onto the Gaussians: the part labels `r4d fit --parts` reads.
    Segment(segment::SegmentArgs),
    /// One full fit iteration at the paper's scale: per-stage time and peak memory.
    BenchScale(bench_scale::BenchScaleArgs),
    /// The recovery benchmark: random scenes of every material class fitted with the
    /// default settings; the fraction of the determined parameters recovered, per class.
    BenchRecovery(bench_recovery::BenchRecoveryArgs),
    /// Dataset folders (PhysFlow's release, PhysDreamer, PAC-NeRF): `dataset inspect DIR`.
    Dataset(dataset::DatasetArgs),
    /// The paper's evaluation of a fit's run folder: videos at 30 fps (MS-SSIM, PSNR, LPIPS),
    /// peak memory, and Chamfer / HD95 / F-score where the dataset has ground truth.
    Eval(eval::EvalArgs),
    /// The paper's ablations (Tables 4-7) on a dataset: every variant fitted and evaluated;
    /// `--shard I/N` for a cluster.
    Ablate(ablate::AblateArgs),
    /// Combine the shards of `r4d ablate --shard` into OUT/ablation.json.
    Merge(ablate::MergeArgs),
}

/// Compute backend: the one `--backend` of every command (`simulate`, `render`, `fit`,
/// `demo`, `bench-scale`, `fit-trajectory`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum BackendKind {
    /// Multi-threaded CPU backend (rayon).
    Cpu,
    /// Single-threaded reference kernels (slow; for checking).
    Reference,
    /// wgpu (WGSL compute on Vulkan, Metal or DX12; `R4D_WGPU_ADAPTER` picks an adapter).
    Wgpu,
    /// Vulkan directly (ash; the same kernels as SPIR-V; `R4D_VULKAN_DEVICE` picks a device).
    Vulkan,
}

impl BackendKind {
    /// The backend for the fits, evaluations and benchmarks (a wgpu device is opened here).
    pub fn compute(self) -> anyhow::Result<std::sync::Arc<dyn resonance4d::compute::Compute>> {
        use resonance4d::compute;
        Ok(match self {
            BackendKind::Cpu => compute::cpu(),
            BackendKind::Reference => compute::reference(),
            BackendKind::Wgpu => {
                let ctx = r4d_backend_wgpu::context::WgpuContext::new()
                    .map_err(|e| anyhow::anyhow!("--backend wgpu: {e}"))?;
                compute::wgpu(std::sync::Arc::new(ctx))
            }
            BackendKind::Vulkan => compute::vulkan(
                r4d_backend_vulkan::VulkanEngine::new()
                    .map_err(|e| anyhow::anyhow!("--backend vulkan: {e}"))?,
            ),
        })
    }

    /// The flag's value.
    pub fn name(self) -> &'static str {
        match self {
            BackendKind::Cpu => "cpu",
            BackendKind::Reference => "reference",
            BackendKind::Wgpu => "wgpu",
            BackendKind::Vulkan => "vulkan",
        }
    }
}

/// Entry point.
pub fn main() -> std::process::ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Simulate(a) => simulate::run(a),
        Command::Demo(a) => demo::run(a),
        Command::BenchScale(a) => bench_scale::run_cmd(a),
        Command::BenchRecovery(a) => bench_recovery::run(a),
        Command::Fit(a) => fit::run(a),
        Command::FitTrajectory(a) => fit_trajectory::run(a),
        Command::Render(a) => render::run(a),
        Command::Prepare(a) => prepare::run(a),
        Command::Metrics(a) => metrics::run(a),
        Command::MetricsTrajectory(a) => metrics_trajectory::run(a),
        Command::Segment(a) => segment::run(a),
        Command::Dataset(a) => dataset::run(a),
        Command::Eval(a) => eval::run(a),
        Command::Ablate(a) => ablate::run(a),
        Command::Merge(a) => ablate::run_merge(a),
    };
    match result {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            std::process::ExitCode::FAILURE
        }
    }
}
