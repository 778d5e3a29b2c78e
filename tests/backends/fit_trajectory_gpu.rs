//! `fit_trajectory` on the wgpu backend (and on the Vulkan engine) (f32, `Simulation<WgpuBackend>`) against the CPU backend (f64,
//! `Simulation<CpuBackend<f64>>`): the first iteration's loss and gradient agree to 1e-3 relative and the
//! fitted parameters to 1% (the CPU-vs-wgpu bound). Skipped without an adapter unless
//! `R4D_REQUIRE_GPU=1`.

use crate::common;

use common::fixture;
use r4d_backend_cpu::CpuBackend;
use r4d_mpm::{ParticleSet, SimConfig, Simulation, Simulator};
use resonance4d::compute::{self, Compute};
use resonance4d::fit_trajectory::{fit_trajectory, FitOptions, IterRecord};

/// Simulates `cfg` on the CPU backend (as `r4d simulate` does) and returns frames 1 ...
fn targets(cfg: &SimConfig, scene: &ParticleSet) -> Vec<Vec<[f32; 3]>> {
    let mut sim = Simulation::new(CpuBackend::default(), cfg, scene.clone(), "target").unwrap();
    let mut st = sim.init_state(&cfg.parts).unwrap();
    (0..cfg.time.frames)
        .map(|_| {
            sim.step_frame(&mut st, &cfg.parts).unwrap();
            sim.positions(&st).unwrap()
        })
        .collect()
}

fn rel(a: f64, b: f64) -> f64 {
    (a - b).abs() / a.abs().max(b.abs()).max(1e-300)
}

#[test]
#[cfg_attr(
    not(r4d_gpu),
    ignore = "no GPU adapter expected here (no Vulkan driver found at build time): install mesa-vulkan-drivers libvulkan1, or build with R4D_REQUIRE_GPU=1"
)]
fn wgpu_fit_matches_the_cpu_fit() {
    let Some(ctx) = common::gpu::wgpu("wgpu_fit_matches_the_cpu_fit") else {
        return;
    };
    gpu_fit_matches_the_cpu_fit(compute::wgpu((*ctx).clone()));
}

/// The same on the Vulkan engine (ash): the recordings of wgpu, executed through Vulkan.
#[test]
#[cfg_attr(
    not(r4d_gpu),
    ignore = "no GPU adapter expected here (no Vulkan driver found at build time): install mesa-vulkan-drivers libvulkan1, or build with R4D_REQUIRE_GPU=1"
)]
fn vulkan_fit_matches_the_cpu_fit() {
    let Some(e) = common::gpu::vulkan("vulkan_fit_matches_the_cpu_fit") else {
        return;
    };
    gpu_fit_matches_the_cpu_fit(compute::vulkan(e.clone()));
    r4d_backend_vulkan::testing::assert_validation_clean(&e, "vulkan_fit_matches_the_cpu_fit");
}

fn gpu_fit_matches_the_cpu_fit(gpu: std::sync::Arc<dyn Compute>) {
    // The sagging beam of tests/fits/fit_trajectory.rs, over two frames, from E 10x off (as there).
    let mut truth = SimConfig::load(&fixture("fit/beam.toml")).unwrap();
    truth.time.frames = 2;
    let scene = ParticleSet::from_shapes(&truth.shapes, truth.domain.dx());
    let target = targets(&truth, &scene);
    let mut start = truth.clone();
    start.parts[0].youngs_modulus_pa = 2e6;
    let run = |backend: &dyn Compute| {
        let opts = FitOptions {
            iters: 4,
            ..Default::default()
        };
        let mut log: Vec<IterRecord> = Vec::new();
        let t = std::time::Instant::now();
        let fitted = fit_trajectory(backend, &start, &scene, &target, &opts, |it| {
            eprintln!(
                "{backend:?} iter {}: loss {:.6e} |grad| {:.6e} E {:.1}",
                it.iter, it.loss.total, it.grad_norm, it.parts[0].e
            );
            log.push(it.clone());
        })
        .unwrap();
        eprintln!("{backend:?}: {:.1} s", t.elapsed().as_secs_f64());
        (fitted, log)
    };
    let (cpu, cpu_log) = run(&*compute::cpu());
    let (gpu, gpu_log) = run(&*gpu);
    let (l0, g0) = (rel(cpu_log[0].loss.total, gpu_log[0].loss.total), {
        rel(cpu_log[0].grad_norm, gpu_log[0].grad_norm)
    });
    eprintln!("first iteration: loss rel {l0:.2e}, gradient rel {g0:.2e}");
    assert!(
        l0 < 1e-3,
        "loss {} vs {}",
        cpu_log[0].loss.total,
        gpu_log[0].loss.total
    );
    assert!(
        g0 < 1e-3,
        "gradient {} vs {}",
        cpu_log[0].grad_norm,
        gpu_log[0].grad_norm
    );
    // The same step direction (Adam's first step is about lr * sign(gradient)).
    assert!(rel(cpu_log[1].parts[0].e, gpu_log[1].parts[0].e) < 1e-2);
    let (ec, eg) = (cpu[0].youngs_modulus_pa, gpu[0].youngs_modulus_pa);
    eprintln!(
        "fitted E: cpu {ec:.1}, wgpu {eg:.1}: {:.2e} relative",
        rel(ec, eg)
    );
    assert!(rel(ec, eg) < 1e-2, "fitted E: cpu {ec}, wgpu {eg}");
    assert!(ec < 2e6 && eg < 2e6, "the fits moved toward the true 2e5");
}

/// The yield stress gradient (through the initial state, `HostSim::init_vjp` on the downloaded
/// adjoint) of a metal beam that yields under its own weight.
#[test]
#[cfg_attr(
    not(r4d_gpu),
    ignore = "no GPU adapter expected here (no Vulkan driver found at build time): install mesa-vulkan-drivers libvulkan1, or build with R4D_REQUIRE_GPU=1"
)]
fn wgpu_yield_stress_gradient_matches_the_cpu() {
    let Some(ctx) = common::gpu::wgpu("wgpu_yield_stress_gradient_matches_the_cpu") else {
        return;
    };
    let gpu = compute::wgpu((*ctx).clone());
    let mut truth = SimConfig::load(&fixture("fit/beam.toml")).unwrap();
    truth.time.frames = 2;
    truth.parts[0].material = r4d_mpm::Material::Metal;
    truth.parts[0].yield_stress_pa = 30.0;
    let scene = ParticleSet::from_shapes(&truth.shapes, truth.domain.dx());
    let target = targets(&truth, &scene);
    let mut start = truth.clone();
    start.parts[0].yield_stress_pa = 120.0;
    let first = |backend: &dyn Compute| {
        let opts = FitOptions {
            params: vec![r4d_optim::ParamKind::YieldStress],
            iters: 1,
            ..Default::default()
        };
        let mut log: Vec<IterRecord> = Vec::new();
        fit_trajectory(backend, &start, &scene, &target, &opts, |it| {
            log.push(it.clone())
        })
        .unwrap();
        eprintln!(
            "{backend:?}: loss {:.6e} |grad| {:.6e}",
            log[0].loss.total, log[0].grad_norm
        );
        (log[0].loss.total, log[0].grad_norm)
    };
    let (lc, gc) = first(&*compute::cpu());
    let (lg, gg) = first(&*gpu);
    eprintln!(
        "yield stress: loss rel {:.2e}, gradient rel {:.2e}",
        rel(lc, lg),
        rel(gc, gg)
    );
    assert!(gc > 0.0, "the beam yields: the yield stress has a gradient");
    assert!(rel(lc, lg) < 1e-3, "loss {lc} vs {lg}");
    assert!(rel(gc, gg) < 1e-3, "gradient {gc} vs {gg}");
}
