//! Dispatch overhead of the GPU engines: one recording of `N` tiny dispatches (the 64-float
//! `mpm_add_vjp` kernel, one workgroup each, a uniform and two buffers bound) executed and
//! waited for by a 4-byte read, on wgpu and on the Vulkan engine (the same recording through
//! `r4d_gpu::GpuEngine`). The time per dispatch is what a kernel costs beyond its own work:
//! recording, descriptor sets, barriers, submission; an MPM substep has 4-9 dispatches, a
//! reverse substep about as many, so at a few microseconds each it is noise on a real GPU.
//!
//! * `dispatch/{wgpu,vulkan}/N` for `N` = 100 and 10 000 (`R4D_BENCH_DISPATCHES=100,10000`);
//! * `R4D_BENCH_DISPATCH_BACKENDS=wgpu,vulkan` picks the engines.
//!
//! Without a GPU both run on whatever Vulkan driver exists (lavapipe in CI: CPU emulation,
//! figures comparable between the engines only). `cargo bench --bench dispatch`.

#![expect(
    missing_docs,
    reason = "criterion's macros generate undocumented public items"
)]

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use r4d_gpu::{Counts, GpuBuf, GpuEngine, Recording};
use std::sync::Arc;

fn env_list(key: &str, default: &str) -> Vec<String> {
    std::env::var(key)
        .unwrap_or_else(|_| default.into())
        .split(',')
        .map(|s| s.trim().to_string())
        .filter(|s| !s.is_empty())
        .collect()
}

/// Executes `n` dispatches in one recording and waits for them (a read).
fn run<E: GpuEngine>(e: &E, src: &GpuBuf<E, f32>, dst: &GpuBuf<E, f32>, n: usize) {
    let mut r = Recording::new();
    let bind = [
        r.uniform(&Counts::new(src.len, 0)),
        r.buf(&src.raw),
        r.buf(&dst.raw),
    ];
    for _ in 0..n {
        r.dispatch(&r4d_shaders::mpm::ADD_VJP, src.len as u32, &bind);
    }
    e.execute(r).expect("executing the recording");
    e.read(&dst.raw, 4).expect("reading back");
}

fn bench_engine<E: GpuEngine>(c: &mut Criterion, name: &str, e: &E) {
    let src = GpuBuf::upload(e, "dispatch bench src", &[1.0f32; 64]).expect("upload");
    let dst = GpuBuf::<E, f32>::zeros(e, "dispatch bench dst", 64).expect("alloc");
    let sizes: Vec<usize> = env_list("R4D_BENCH_DISPATCHES", "100,10000")
        .iter()
        .map(|s| s.parse().expect("R4D_BENCH_DISPATCHES: counts"))
        .collect();
    // The first run builds the pipeline.
    run(e, &src, &dst, 1);
    let mut g = c.benchmark_group(format!("dispatch/{name}"));
    g.sample_size(10);
    for n in sizes {
        g.throughput(Throughput::Elements(n as u64));
        g.bench_function(BenchmarkId::from_parameter(n), |b| {
            b.iter(|| run(e, &src, &dst, n))
        });
    }
    g.finish();
    // Every dispatch ran: dst grew by one per dispatch.
    let v: Vec<f32> = bytemuck::cast_slice(&e.read(&dst.raw, 4).expect("read")).to_vec();
    assert!(v[0] >= 1.0, "the dispatches did not run");
}

fn benches(c: &mut Criterion) {
    let backends = env_list("R4D_BENCH_DISPATCH_BACKENDS", "wgpu,vulkan");
    if backends.iter().any(|b| b == "wgpu") {
        match r4d_backend_wgpu::WgpuContext::new() {
            Ok(ctx) => {
                eprintln!("wgpu adapter: {} ({:?})", ctx.info.name, ctx.info.backend);
                let e = r4d_backend_wgpu::WgpuEngine::new(Arc::new(ctx));
                bench_engine(c, "wgpu", &e);
            }
            Err(e) => eprintln!("dispatch/wgpu skipped: {e}"),
        }
    }
    if backends.iter().any(|b| b == "vulkan") {
        match r4d_backend_vulkan::VulkanEngine::new() {
            Ok(e) => {
                eprintln!("vulkan device: {}", e.device_name());
                bench_engine(c, "vulkan", &e);
            }
            Err(e) => eprintln!("dispatch/vulkan skipped: {e}"),
        }
    }
}

criterion_group!(dispatch, benches);
criterion_main!(dispatch);
