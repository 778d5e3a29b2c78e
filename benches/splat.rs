//! Renderer benchmarks: forward (`render`) and forward + backward (`render_vjp`, which re-runs
//! projection and binning) of 100k and 300k Gaussians (SH degree 3, deformed by a per-Gaussian
//! F as in a simulated frame) at 1280x720 and 1920x1080, on the rayon CPU backend and, when an
//! adapter exists, on the wgpu backend (forward and backward both in WGSL).
//!
//! The synthetic scene: centres uniform in a ball of radius 1, scales log-uniform in
//! [0.003, 0.03], opacities sigmoid(U[-2, 4]), seen from distance 3 with a 60 degree field of
//! view, so the object fills most of the frame like a captured object does. Each case prints
//! its tile intersections and the peak host memory (counting allocator) of one call; the wgpu
//! cases also print the peak device memory of one forward and one forward + backward (the
//! backend's own accounting of its buffers, `WgpuContext::peak_bytes`).
//!
//! `R4D_BENCH_SPLAT_SIZES=N@WxH[,N@WxH...]` replaces the four cases (e.g. a reduced size on
//! Mesa's lavapipe, a CPU emulation of Vulkan: `R4D_BENCH_SPLAT_SIZES=20000@320x180 cargo
//! bench --bench splat -- splat_wgpu`).

#![expect(
    missing_docs,
    reason = "criterion's macros generate undocumented public items"
)]

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion};
use r4d_backend_cpu::CpuBackend;
use r4d_backend_wgpu::{WgpuBackend, WgpuContext};
use r4d_splat::{Camera, Deformation, Gaussians, RenderSettings, Renderer, SplatRenderer};
use resonance4d::alloc::{peak_since, reset_peak, Counting};
use std::sync::Arc;

#[global_allocator]
static GLOBAL: Counting = Counting;

struct Rng(u64);
impl Rng {
    fn next(&mut self) -> f32 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        ((z ^ (z >> 31)) >> 40) as f32 / (1u64 << 24) as f32
    }
    fn range(&mut self, a: f32, b: f32) -> f32 {
        a + (b - a) * self.next()
    }
}

fn scene(n: usize) -> (Gaussians, Deformation) {
    let mut r = Rng(42);
    let mut g = Gaussians {
        sh_degree: 3,
        ..Default::default()
    };
    let mut d = Deformation::default();
    while g.len() < n {
        let p = [r.range(-1.0, 1.0), r.range(-1.0, 1.0), r.range(-1.0, 1.0)];
        if p.iter().map(|v| v * v).sum::<f32>() > 1.0 {
            continue;
        }
        g.means.push(p);
        let (lo, hi) = (0.003f32.ln(), 0.03f32.ln());
        g.log_scales
            .push([r.range(lo, hi), r.range(lo, hi), r.range(lo, hi)]);
        g.quats.push([
            r.range(-1.0, 1.0),
            r.range(-1.0, 1.0),
            r.range(-1.0, 1.0),
            r.range(-1.0, 1.0) + 1.5,
        ]);
        g.opacity_logits.push(r.range(-2.0, 4.0));
        for _ in 0..48 {
            g.sh.push(r.range(-0.3, 0.3));
        }
        // A simulated frame: displaced centres and F near identity.
        d.means.push(p.map(|v| v + r.range(-0.01, 0.01)));
        let mut f = [[1.0f32, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
        for row in f.iter_mut() {
            for v in row.iter_mut() {
                *v += r.range(-0.1, 0.1);
            }
        }
        d.f.push(f);
    }
    (g, d)
}

/// The cases (Gaussians, width, height): `R4D_BENCH_SPLAT_SIZES` or the default four.
fn cases() -> Vec<(usize, u32, u32)> {
    let Ok(spec) = std::env::var("R4D_BENCH_SPLAT_SIZES") else {
        return vec![
            (100_000, 1280, 720),
            (100_000, 1920, 1080),
            (300_000, 1280, 720),
            (300_000, 1920, 1080),
        ];
    };
    spec.split(',')
        .map(|c| {
            let parse = || -> Option<(usize, u32, u32)> {
                let (n, size) = c.trim().split_once('@')?;
                let (w, h) = size.split_once('x')?;
                Some((n.parse().ok()?, w.parse().ok()?, h.parse().ok()?))
            };
            parse().unwrap_or_else(|| {
                panic!("R4D_BENCH_SPLAT_SIZES: '{c}' is not N@WxH (e.g. 20000@320x180)")
            })
        })
        .collect()
}

fn bench(c: &mut Criterion) {
    let cases = cases();
    let mut group = c.benchmark_group("splat");
    group.sample_size(10);
    let mut scenes: Vec<(usize, Gaussians, Deformation)> = Vec::new();
    for &(n, _, _) in &cases {
        if !scenes.iter().any(|s| s.0 == n) {
            let (g, d) = scene(n);
            scenes.push((n, g, d));
        }
    }
    let scene_of = |n: usize| {
        let s = scenes.iter().find(|s| s.0 == n).expect("built above");
        (&s.1, &s.2)
    };
    for &(n, w, h) in &cases {
        let (g, d) = scene_of(n);
        let cam = Camera::look_at(w, h, 60.0, [0.0, -3.0, 0.5], [0.0; 3], [0.0, 0.0, 1.0]);
        let set = RenderSettings::default();
        let mut r = SplatRenderer::new(CpuBackend::default());
        let id = format!("{n}/{w}x{h}");
        let base = reset_peak();
        r.render(g, Some(d), &cam, &set).unwrap();
        let fwd_peak = peak_since(base);
        let stats = r.stats;
        let d_rgb = vec![1e-3f32; (w * h * 3) as usize];
        let base = reset_peak();
        r.render_vjp(g, Some(d), &cam, &set, &d_rgb).unwrap();
        let bwd_peak = peak_since(base);
        println!(
            "splat {id}: {} visible, {} tile intersections, peak host memory: forward {:.1} MiB, forward+backward {:.1} MiB",
            stats.visible.unwrap_or(0),
            stats.intersections,
            fwd_peak as f64 / 1048576.0,
            bwd_peak as f64 / 1048576.0
        );
        group.bench_function(BenchmarkId::new("forward", &id), |b| {
            b.iter(|| r.render(g, Some(d), &cam, &set).unwrap())
        });
        group.bench_function(BenchmarkId::new("forward_backward", &id), |b| {
            b.iter(|| r.render_vjp(g, Some(d), &cam, &set, &d_rgb).unwrap())
        });
    }
    group.finish();
    // The wgpu renderer on whatever adapter is present (without a GPU: lavapipe, a software
    // rasterizer, whose figures say nothing about GPU speed). `render` downloads the image and
    // `render_vjp` the gradients, so the times include the device work.
    let ctx = match WgpuContext::new() {
        Ok(c) => Arc::new(c),
        Err(e) => {
            eprintln!("splat/wgpu skipped: {e}");
            return;
        }
    };
    eprintln!(
        "wgpu adapter: {} ({:?})",
        ctx.info.name, ctx.info.device_type
    );
    bench_gpu_renderer(
        c,
        "splat_wgpu",
        &cases,
        &scenes,
        || WgpuBackend::new(ctx.clone()),
        || ctx.reset_peak(),
        || ctx.peak_bytes(),
    );
    // The same renderer on the Vulkan engine (the same recordings through ash).
    match r4d_backend_vulkan::VulkanEngine::new() {
        Ok(e) => {
            eprintln!("vulkan device: {}", e.device_name());
            bench_gpu_renderer(
                c,
                "splat_vulkan",
                &cases,
                &scenes,
                || r4d_backend_vulkan::VulkanBackend::new(e.clone()),
                || e.reset_peak(),
                || {
                    use r4d_gpu::GpuEngine;
                    e.memory_usage().peak_bytes
                },
            );
        }
        Err(e) => eprintln!("splat/vulkan skipped: {e}"),
    }
}

/// Forward and forward+backward renders of `cases` on a GPU renderer made by `make`, with
/// its device memory peaks.
fn bench_gpu_renderer<B: r4d_splat::SplatKernels>(
    c: &mut Criterion,
    name: &str,
    cases: &[(usize, u32, u32)],
    scenes: &[(usize, Gaussians, Deformation)],
    make: impl Fn() -> B,
    reset_device_peak: impl Fn(),
    device_peak: impl Fn() -> u64,
) {
    let scene_of = |n: usize| {
        let s = scenes.iter().find(|s| s.0 == n).expect("built above");
        (&s.1, &s.2)
    };
    let mut group = c.benchmark_group(name);
    group.sample_size(10);
    for &(n, w, h) in cases {
        let (g, d) = scene_of(n);
        let cam = Camera::look_at(w, h, 60.0, [0.0, -3.0, 0.5], [0.0; 3], [0.0, 0.0, 1.0]);
        let set = RenderSettings::default();
        let mut r = SplatRenderer::new(make());
        let id = format!("{n}/{w}x{h}");
        // A first call builds the pipelines.
        r.render(g, Some(d), &cam, &set).unwrap();
        reset_device_peak();
        let base = reset_peak();
        r.render(g, Some(d), &cam, &set).unwrap();
        let (fwd_dev, fwd_host) = (device_peak(), peak_since(base));
        let d_rgb = vec![1e-3f32; (w * h * 3) as usize];
        r.render_vjp(g, Some(d), &cam, &set, &d_rgb).unwrap();
        reset_device_peak();
        let base = reset_peak();
        r.render_vjp(g, Some(d), &cam, &set, &d_rgb).unwrap();
        let (bwd_dev, bwd_host) = (device_peak(), peak_since(base));
        let mib = |b: u64| b as f64 / 1048576.0;
        println!(
            "{name} {id}: {} visible, {} tile intersections; peak device memory: forward \
             {:.1} MiB, forward+backward {:.1} MiB; peak host memory: forward {:.1} MiB, \
             forward+backward {:.1} MiB",
            r.stats.visible.unwrap_or(0),
            r.stats.intersections,
            mib(fwd_dev),
            mib(bwd_dev),
            mib(fwd_host as u64),
            mib(bwd_host as u64)
        );
        group.bench_function(BenchmarkId::new("forward", &id), |b| {
            b.iter(|| r.render(g, Some(d), &cam, &set).unwrap())
        });
        group.bench_function(BenchmarkId::new("forward_backward", &id), |b| {
            b.iter(|| r.render_vjp(g, Some(d), &cam, &set, &d_rgb).unwrap())
        });
    }
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
