//! Forward + backward (reverse sweep) of the MPM adjoint: time and peak host memory for each
//! checkpointing strategy, next to `memory_plan`'s prediction.
//!
//! `cargo bench --bench adjoint [-- PARTICLES FRAMES SUBSTEPS_PER_FRAME]` (defaults: 10 000
//! particles, 2 frames of 50 substeps, n_grid 64, f32), for the single-threaded host
//! reference backend and the parallel CPU backend (`CpuBackend`, all cores), both through the
//! generic stepper `Simulation`.
//! The paper's scale (16 frames x 400 substeps, 10k and 100k particles) takes an hour on a
//! 2-core machine: `cargo bench --bench adjoint -- 100000 16 400 --parallel-only`.
//! `--parallel-only` skips the single-threaded host stepper, `--only store-all|per-frame|every-n|nested`
//! measures one strategy; a strategy whose
//! `memory_plan` exceeds 60% of the machine's memory is skipped (its plan is still printed).

use r4d_backend_cpu::{CpuBackend, Par};
use r4d_mpm::adjoint::checkpoint::{memory_plan, value_and_grad, Checkpointing, Differentiable};
use r4d_mpm::adjoint::host::{HostSim, PhysParams};
use r4d_mpm::adjoint::kernels::MpmAdjointKernels;
use r4d_mpm::reference::ReferenceBackend;
use r4d_mpm::simulation::infallible;
use r4d_mpm::Simulation;
use r4d_mpm::{
    BoundaryCondition, Domain, PartParams, ParticleSet, Shape, SimConfig, Surface, TimeConfig,
};
use resonance4d::alloc::{peak_since, reset_peak, Counting};
use std::convert::Infallible;
use std::time::Instant;

#[global_allocator]
static GLOBAL: Counting = Counting;

fn main() {
    let raw: Vec<String> = std::env::args().skip(1).collect();
    let parallel_only = raw.iter().any(|a| a == "--parallel-only");
    // `--only store-all|per-frame|every-n|nested` measures one strategy.
    let only = raw
        .iter()
        .position(|a| a == "--only")
        .and_then(|i| raw.get(i + 1).cloned());
    let args: Vec<usize> = raw.iter().filter_map(|a| a.parse().ok()).collect();
    let target = args.first().copied().unwrap_or(10_000);
    let frames = args.get(1).copied().unwrap_or(2);
    let spf = args.get(2).copied().unwrap_or(50) as u32;
    let n = 64;
    let dx = 1.0 / n as f64;
    let side = ((target as f64 / 8.0).cbrt()).round() * dx;
    let cfg = SimConfig {
        domain: Domain {
            grid_lim: 1.0,
            n_grid: n,
        },
        time: TimeConfig {
            substep_dt: 1e-4,
            frame_dt: None,
            substeps_per_frame: Some(spf),
            frames,
        },
        solver: Default::default(),
        parts: vec![PartParams {
            youngs_modulus_pa: 1e5,
            poisson_ratio: 0.3,
            ..Default::default()
        }],
        shapes: vec![Shape::Box {
            min: [0.5 - side / 2.0, 0.5 - side / 2.0, 0.1],
            max: [0.5 + side / 2.0, 0.5 + side / 2.0, 0.1 + side],
            part: 0,
            per_cell: 2,
        }],
        particles: None,
        boundary: vec![BoundaryCondition::BoundingBox {
            layers: 3,
            surface: Surface::Slip,
        }],
    };
    let scene = ParticleSet::from_shapes(&cfg.shapes, dx);
    let np = scene.len();
    let sim = HostSim::new(&cfg, &scene).unwrap();
    let params = vec![PhysParams::<f32>::of(&cfg.parts[0])];
    let substeps = frames as u64 * spf as u64;
    println!("adjoint bench: {np} particles, n_grid {n}, {frames} frames x {spf} substeps, f32");
    println!("| stepper | strategy | forward (s) | forward+backward (s) | backward/forward | peak measured (MiB) | memory_plan (MiB) |");
    println!("|---|---|---|---|---|---|---|");
    if !parallel_only {
        measure(
            "host (1 thread)",
            &|| infallible(Simulation::with_host(ReferenceBackend::new(), &sim)),
            &params,
            substeps,
            spf,
            np,
            n,
            only.as_deref(),
        );
    }
    measure(
        "parallel CPU",
        &|| infallible(Simulation::with_host(CpuBackend::new(Par::Rayon), &sim)),
        &params,
        substeps,
        spf,
        np,
        n,
        only.as_deref(),
    );
}

#[allow(clippy::too_many_arguments)]
fn measure<B>(
    label: &str,
    make: &dyn Fn() -> Simulation<B>,
    params: &Vec<PhysParams<f32>>,
    substeps: u64,
    spf: u32,
    np: usize,
    n: usize,
    only: Option<&str>,
) where
    B: MpmAdjointKernels<Scalar = f32, Error = Infallible>,
{
    for strategy in [
        Checkpointing::StoreAll,
        Checkpointing::PerFrame,
        Checkpointing::EveryN(((substeps as f64).sqrt().round() as u32).max(1)),
        Checkpointing::Nested(((spf as f64).sqrt().round() as u32).max(1)),
    ] {
        let name = match strategy {
            Checkpointing::StoreAll => "store-all",
            Checkpointing::PerFrame => "per-frame",
            Checkpointing::EveryN(_) => "every-n",
            Checkpointing::Nested(_) => "nested",
        };
        if only.is_some_and(|o| o != name) {
            continue;
        }
        let plan = memory_plan(np as u64, n as u64, substeps, spf, strategy, 4).peak_bytes as f64
            / 1048576.0;
        if plan > 0.6 * machine_memory_mib() {
            println!("| {label} | {strategy:?} | - | - | - | skipped | {plan:.1} |");
            continue;
        }
        // The stepper's working buffers (grids, tape, adjoint scratch) count in the peak.
        let base = reset_peak();
        let stepper = &make();
        let init = infallible(stepper.init(params, &vec![[0.0f32; 3]; np]));
        // Forward only, for the ratio.
        let t0 = Instant::now();
        let mut s = infallible(stepper.clone_state(&init));
        for k in 0..substeps {
            infallible(stepper.step(&mut s, params, k));
        }
        let fwd = t0.elapsed().as_secs_f64();
        drop(s);
        let t1 = Instant::now();
        let b = stepper.backend();
        let (_, _, g) = infallible(value_and_grad(
            stepper,
            &init,
            params,
            substeps,
            spf,
            strategy,
            infallible(stepper.zero_grad()),
            |_, s| {
                let x = infallible(b.download(&s.x));
                x.iter().map(|p| p[2] as f64).sum::<f64>()
            },
            |_, _, adj| {
                let mut x = infallible(b.download(&adj.x));
                x.iter_mut().for_each(|a| a[2] += 1.0);
                infallible(b.write(&mut adj.x, &x));
            },
        ));
        let total = t1.elapsed().as_secs_f64();
        let peak = peak_since(base) as f64 / 1048576.0;
        let g = infallible(stepper.grad_to_host(&g, params));
        assert!(g[0].youngs_modulus.is_finite());
        println!(
            "| {label} | {strategy:?} | {fwd:.2} | {total:.2} | {:.2} | {peak:.1} | {plan:.1} |",
            (total - fwd) / fwd
        );
    }
}

/// Total memory of this machine in MiB (`/proc/meminfo`; 16 GiB where it cannot be read).
fn machine_memory_mib() -> f64 {
    std::fs::read_to_string("/proc/meminfo")
        .ok()
        .and_then(|m| {
            m.lines()
                .find(|l| l.starts_with("MemTotal:"))
                .and_then(|l| l.split_whitespace().nth(1))
                .and_then(|kb| kb.parse::<f64>().ok())
        })
        .map(|kb| kb / 1024.0)
        .unwrap_or(16384.0)
}
