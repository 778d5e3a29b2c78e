//! The video fit on the GPU engines against the CPU (the small problem of
//! `tests/fits/video_fit.rs`): loss, every parameter gradient and a short fit.

use crate::common::video::{fit_config, jelly, small_problem};
use resonance4d::video_fit::fit::NoHooks;
use resonance4d::video_fit::{run_fit, Objective, Precision};

/// The video fit on the GPU: simulation and reverse sweep (`Simulation<WgpuBackend>`, f32), rendering and
/// render VJP (`WgpuBackend`), the loss on the CPU. Loss and every parameter gradient agree with
/// the CPU's f32 run, and a few fit iterations reach the same parameters within 1% (the
/// bound).
#[test]
#[cfg_attr(
    not(r4d_gpu),
    ignore = "no GPU adapter expected here (no Vulkan driver found at build time): install mesa-vulkan-drivers libvulkan1, or build with R4D_REQUIRE_GPU=1"
)]
fn gpu_simulation_matches_the_cpu_in_the_video_fit() {
    let Some(ctx) = crate::common::gpu::wgpu("gpu_video_fit") else {
        return;
    };
    let wgpu = resonance4d::compute::WgpuCompute::new((*ctx).clone());
    assert!(
        wgpu.render_on_gpu,
        "the wgpu backend renders on the GPU by default"
    );
    video_fit_parity(std::sync::Arc::new(wgpu), "wgpu");
}

/// The same video-fit parity on the Vulkan engine (`VulkanBackend`, `VulkanBackend`), under the
/// validation layer in CI.
#[test]
#[cfg_attr(
    not(r4d_gpu),
    ignore = "no GPU adapter expected here (no Vulkan driver found at build time): install mesa-vulkan-drivers libvulkan1, or build with R4D_REQUIRE_GPU=1"
)]
fn vulkan_simulation_matches_the_cpu_in_the_video_fit() {
    let Some(engine) = crate::common::gpu::vulkan("vulkan_video_fit") else {
        return;
    };
    video_fit_parity(resonance4d::compute::vulkan(engine.clone()), "vulkan");
    r4d_backend_vulkan::testing::assert_validation_clean(&engine, "vulkan_video_fit");
}

/// Loss, gradients and a 3-iteration fit of `compute` against the CPU's f32 run.
fn video_fit_parity(compute: std::sync::Arc<dyn resonance4d::compute::Compute>, name: &str) {
    let truth = [jelly(2e4, 800.0), jelly(8e3, 1500.0)];
    let mut p = small_problem(&truth, 3);
    let start = [jelly(1.4e4, 1000.0), jelly(1.1e4, 1200.0)];
    let loss = fit_config(0).loss;
    let mut cpu = Objective::new(&p, None, &loss, false).unwrap();
    cpu.precision = Precision::F32;
    let (ev, g) = cpu.value_and_grad(&start).unwrap();
    p.compute = compute;
    let gpu = Objective::new(&p, None, &loss, false).unwrap();
    assert_eq!(gpu.compute.name(), name);
    let (ev2, g2) = gpu.value_and_grad(&start).unwrap();
    let prof = gpu.profile();
    assert!(prof.device_peak_bytes.unwrap_or(0) > 0, "{prof:?}");
    let (up, down) = (prof.host_to_device_bytes, prof.device_to_host_bytes);
    eprintln!("{name}: moved {up:?} bytes up, {down:?} down in one evaluation");
    assert!(up.unwrap_or(0) > 0 && down.unwrap_or(0) > 0, "{prof:?}");
    eprintln!("loss cpu {} gpu {}", ev.total, ev2.total);
    assert!((ev.total - ev2.total).abs() <= 1e-3 * ev.total);
    for part in 0..2 {
        for (a, b) in [
            (g[part].youngs_modulus, g2[part].youngs_modulus),
            (g[part].density, g2[part].density),
        ] {
            eprintln!("part {part}: gradient cpu {a:e} gpu {b:e}");
            assert!(
                (a - b).abs() <= 1e-2 * a.abs().max(b.abs()),
                "part {part}: gradient {a:e} on the CPU, {b:e} on the GPU"
            );
        }
    }
    let mut cfg = fit_config(3);
    cfg.precision = Precision::F32;
    p.config.parts = start.to_vec();
    let on_gpu = run_fit(&p, &cfg, None, &mut NoHooks).unwrap();
    p.compute = resonance4d::compute::cpu();
    let on_cpu = run_fit(&p, &cfg, None, &mut NoHooks).unwrap();
    for part in 0..2 {
        for (a, b) in [
            (
                on_cpu.parts[part].youngs_modulus_pa,
                on_gpu.parts[part].youngs_modulus_pa,
            ),
            (
                on_cpu.parts[part].density_kg_m3,
                on_gpu.parts[part].density_kg_m3,
            ),
        ] {
            assert!(
                (a - b).abs() <= 1e-2 * a,
                "part {part}: {a} on the CPU, {b} on the GPU"
            );
        }
    }
}
