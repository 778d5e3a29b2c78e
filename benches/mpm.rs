//! MPM substep benchmarks: one substep of a jelly block at 10k, 32k and 100k particles,
//! n_grid 64, dt 1e-4, on the CPU backend (all cores), the single-threaded reference, and the
//! wgpu backend when an adapter exists (32k and 100k; also its peak device memory).
//!
//! Reports time per substep; particle-substeps per second = particles / time. A counting
//! global allocator reports the peak host memory of each case after its run.

#![expect(
    missing_docs,
    reason = "criterion's macros generate undocumented public items"
)]

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use r4d_backend_cpu::CpuBackend;
use r4d_backend_wgpu::{WgpuBackend, WgpuContext};
use r4d_mpm::{
    reference::ReferenceBackend, BoundaryCondition, MpmKernels, PartParams, ParticleSet, Shape,
    SimConfig, Simulation, Simulator, Surface,
};
use resonance4d::alloc::{peak_since, reset_peak, Counting};
use std::sync::Arc;

#[global_allocator]
static GLOBAL: Counting = Counting;

/// A jelly cube of about `n` particles (8 per cell) in a 64^3 grid.
fn config(target: usize) -> SimConfig {
    let dx = 1.0 / 64.0;
    let cells = ((target as f64 / 8.0).cbrt()).round();
    let side = cells * dx;
    let lo = 0.5 - side / 2.0;
    SimConfig {
        domain: r4d_mpm::Domain {
            grid_lim: 1.0,
            n_grid: 64,
        },
        time: r4d_mpm::TimeConfig {
            substep_dt: 1e-4,
            frame_dt: None,
            substeps_per_frame: Some(1),
            frames: 1,
        },
        solver: Default::default(),
        parts: vec![PartParams {
            youngs_modulus_pa: 1e5,
            poisson_ratio: 0.3,
            density_kg_m3: 1000.0,
            ..Default::default()
        }],
        shapes: vec![Shape::Box {
            min: [lo, lo, 0.1],
            max: [lo + side, lo + side, 0.1 + side],
            part: 0,
            per_cell: 2,
        }],
        particles: None,
        boundary: vec![BoundaryCondition::BoundingBox {
            layers: 3,
            surface: Surface::Slip,
        }],
    }
}

fn bench_backend<B: MpmKernels>(
    c: &mut Criterion,
    name: &str,
    make: impl Fn() -> B,
    sync: impl Fn(&B),
    sizes: &[usize],
) {
    let mut group = c.benchmark_group(format!("substep/{name}"));
    group.sample_size(10);
    for &target in sizes {
        let cfg = config(target);
        let scene = ParticleSet::from_shapes(&cfg.shapes, cfg.domain.dx());
        let np = scene.len();
        let base = reset_peak();
        let sim = Simulation::new(make(), &cfg, scene, "bench").unwrap();
        let mut state = sim.init_state(&cfg.parts).unwrap();
        // Warm up: let the block fall a little so velocities and stresses are non-trivial.
        for _ in 0..20 {
            sim.step_substep(&mut state).unwrap();
        }
        group.throughput(Throughput::Elements(np as u64));
        group.bench_with_input(BenchmarkId::from_parameter(np), &np, |b, _| {
            b.iter(|| {
                sim.step_substep(&mut state).unwrap();
                sync(sim.backend());
            })
        });
        let peak = peak_since(base);
        let dev = sim.backend().memory_usage().peak_bytes;
        eprintln!(
            "substep/{name}/{np}: peak host memory {:.1} MiB ({:.0} B/particle){}",
            peak as f64 / 1048576.0,
            peak as f64 / np as f64,
            if dev > 0 {
                format!(", peak device memory {:.1} MiB", dev as f64 / 1048576.0)
            } else {
                String::new()
            }
        );
    }
    group.finish();
}

fn benches(c: &mut Criterion) {
    bench_backend(
        c,
        "cpu",
        CpuBackend::default,
        |_| {},
        &[10_000, 32_000, 100_000, 300_000],
    );
    bench_backend(c, "reference", ReferenceBackend::new, |_| {}, &[10_000]);
    // The wgpu backend on whatever adapter is present (on a machine without a GPU: lavapipe,
    // a software rasterizer; its figures say nothing about GPU speed). Each substep waits for
    // the device, so the time is the real execution time.
    match WgpuContext::new() {
        Ok(ctx) => {
            let ctx = Arc::new(ctx);
            eprintln!(
                "wgpu adapter: {} ({:?}, {:?})",
                ctx.info.name, ctx.info.device_type, ctx.info.backend
            );
            bench_backend(
                c,
                "wgpu",
                || WgpuBackend::new(ctx.clone()),
                |b: &WgpuBackend| {
                    let _ = b.engine().context().device.poll(wgpu::PollType::Wait {
                        submission_index: None,
                        timeout: None,
                    });
                },
                &[32_000, 100_000],
            );
        }
        Err(e) => eprintln!("substep/wgpu skipped: {e}"),
    }
    // The Vulkan engine on the first Vulkan device (the same device as wgpu's where both see
    // one; lavapipe here). Each substep is finished (submitted and waited for).
    match r4d_backend_vulkan::VulkanEngine::new() {
        Ok(e) => {
            eprintln!("vulkan device: {}", e.device_name());
            bench_backend(
                c,
                "vulkan",
                || r4d_backend_vulkan::VulkanBackend::new(e.clone()),
                |b: &r4d_backend_vulkan::VulkanBackend| {
                    let _ = b.engine().finish();
                },
                &[32_000, 100_000],
            );
        }
        Err(e) => eprintln!("substep/vulkan skipped: {e}"),
    }
}

criterion_group!(mpm, benches);
criterion_main!(mpm);
