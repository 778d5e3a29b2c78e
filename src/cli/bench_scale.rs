//! `r4d bench-scale`: one full fit iteration at the paper's scale, per-stage time and peak
//! memory (see `resonance4d::bench_scale`).

use anyhow::{bail, Context, Result};
use resonance4d::bench_scale::{compute_bound_line, init_table, run, run_init, table, BenchScale};
use std::path::PathBuf;

/// Arguments of `r4d bench-scale` (defaults: the paper's scale).
#[derive(clap::Args, Debug)]
pub struct BenchScaleArgs {
    /// Where the simulation, rendering and their backward passes run: cpu or wgpu.
    #[arg(long, value_enum, default_value_t = super::BackendKind::Cpu)]
    backend: super::BackendKind,
    /// Print, besides the per-stage table, the forward simulation's throughput against a
    /// rough compute bound of this machine's cores (`cpu`), and the GPU time of every kernel
    /// when the command ends (timestamp queries; the Vulkan backend measures it, the others
    /// say they cannot).
    #[arg(long)]
    profile: bool,
    /// Cells per side of the simulated block (8 particles per cell; 23: 97 336 particles).
    #[arg(long, default_value_t = 23)]
    cells: usize,
    /// Total Gaussians (the block's particles plus static background).
    #[arg(long, default_value_t = 300_000)]
    gaussians: usize,
    /// Simulated frames (the video has one more, the rest frame).
    #[arg(long, default_value_t = 16)]
    frames: usize,
    /// Substeps per frame (dt 1e-4 s).
    #[arg(long, default_value_t = 400)]
    substeps: usize,
    /// Image size WxH.
    #[arg(long, default_value = "1920x1080")]
    resolution: String,
    /// Checkpointing of the reverse sweep: per_frame, store_all, every_n:K or nested:K.
    #[arg(long, default_value = "nested:20")]
    checkpointing: String,
    /// Rows per loss band (the loss, rendering and render VJP run band by band).
    #[arg(long, default_value_t = 128)]
    band_rows: usize,
    /// Reference video: `truth` (simulated at other parameters and rendered) or `rest` (the
    /// rest frame repeated; skips one forward simulation).
    #[arg(long, default_value = "truth")]
    reference: String,
    /// Time the simulation-driven initialisation with this many Latin hypercube candidates
    /// (the paper: 32), each simulating and scoring the benchmark's frames, instead of one
    /// fit iteration.
    #[arg(long, value_name = "CANDIDATES")]
    init: Option<usize>,
    /// Read every simulated frame back to the host and upload its deformation, instead of
    /// keeping frames on the GPU from the simulation to the rasterizer (the same numbers up
    /// to rounding; for comparing the bytes moved between host and device).
    #[arg(long)]
    frames_via_host: bool,
    /// Also write the measurement as JSON here.
    #[arg(long)]
    json: Option<PathBuf>,
}

/// Runs the command.
pub fn run_cmd(a: BenchScaleArgs) -> Result<()> {
    let (w, h) = a
        .resolution
        .split_once('x')
        .and_then(|(w, h)| Some((w.parse::<u32>().ok()?, h.parse::<u32>().ok()?)))
        .filter(|&(w, h)| w >= 16 && h >= 16)
        .with_context(|| {
            format!(
                "--resolution '{}': expected WxH, e.g. 1920x1080",
                a.resolution
            )
        })?;
    let reference_from_simulation = match a.reference.as_str() {
        "truth" => true,
        "rest" => false,
        o => bail!("--reference '{o}': truth or rest"),
    };
    let checkpointing = r4d_mpm::adjoint::checkpoint::Checkpointing::parse(&a.checkpointing)
        .map_err(|e| anyhow::anyhow!("--checkpointing: {e}"))?;
    let scale = BenchScale {
        cells: a.cells,
        gaussians: a.gaussians,
        frames: a.frames,
        substeps: a.substeps,
        width: w,
        height: h,
        checkpointing,
        band_rows: a.band_rows,
        reference_from_simulation,
        device_frames: !a.frames_via_host,
    };
    // Every size checked (names the flag) before the backend opens or anything is built.
    scale
        .validate()
        .map_err(|e| anyhow::anyhow!("--{}", e.to_string().replace(" = ", " ")))?;
    if let Some(n) = a.init {
        let max = r4d_optim::video::config::MAX_INIT_CANDIDATES;
        if !(1..=max).contains(&n) {
            bail!("--init {n}: candidates must lie in 1..={max} (MAX_INIT_CANDIDATES)");
        }
    }
    let backend = a.backend.compute()?;
    let _profile = super::profile::Profile::on_compute(&backend, a.profile)?;
    eprintln!(
        "bench-scale: building the scene and the reference video ({}) ...",
        a.reference
    );
    let heap: std::sync::Arc<dyn r4d_optim::HeapProbe> =
        std::sync::Arc::new(resonance4d::alloc::CountingProbe);
    if let Some(n) = a.init {
        let t = std::time::Instant::now();
        let mut done = 0usize;
        let mut progress = |c: &r4d_optim::Candidate| {
            done += 1;
            let what = match (c.score, &c.error) {
                (Some(s), _) => format!("MS-SSIM {s:.4}"),
                (None, Some(e)) => format!("failed: {e}"),
                (None, None) => "failed".into(),
            };
            eprintln!(
                "bench-scale: candidate {} done ({done}/{n}, {:.0} s): {what}",
                c.index,
                t.elapsed().as_secs_f64()
            );
        };
        let (_, report) = run_init(&scale, backend, Some(heap), n, &mut progress)?;
        println!("{}", init_table(&report));
        if let Some(path) = &a.json {
            let text = serde_json::to_string_pretty(&report)?;
            r4d_fsio::write_atomic(path, text.as_bytes())
                .with_context(|| format!("writing {}", path.display()))?;
        }
        return Ok(());
    }
    let (_, report) = run(&scale, backend, Some(heap))?;
    println!("{}", table(&report));
    if let (true, Some(b)) = (a.profile, &report.compute_bound) {
        println!("{}", compute_bound_line(b));
    }
    if let Some(path) = &a.json {
        let text = serde_json::to_string_pretty(&report)?;
        r4d_fsio::write_atomic(path, text.as_bytes())
            .with_context(|| format!("writing {}", path.display()))?;
    }
    Ok(())
}
