//! MPM adjoint benchmarks: one substep's reverse sweep (`Differentiable::step_vjp`) and, for
//! the ratio, the same stepper's forward substep (`Differentiable::step`), of a jelly block
//! (8 particles per cell, E 1e5 Pa, nu 0.3) at 10k and 100k particles, n_grid 64, dt 1e-4,
//! f32, slip bounding box, on
//!
//! * `adjoint_substep/cpu/{forward,backward}/N`: the parallel CPU adjoint
//!   (`Simulation<CpuBackend<f32>>`, all cores);
//! * `adjoint_substep/wgpu/{forward,backward}/N`: the device adjoint
//!   (`Simulation<WgpuBackend>`, the same stepper) when a wgpu adapter exists; every call waits
//!   for the device, so times are execution times;
//! * `adjoint_substep/vulkan/{forward,backward}/N`: the same on the Vulkan engine
//!   (`Simulation<VulkanBackend>`; each call ends with `VulkanEngine::finish`).
//!
//! The input of every timed call is the same: the state after 20 warm-up substeps (run on
//! the CPU, uploaded for wgpu) and, for the backward, an adjoint seeded as by a loss on the
//! final heights and velocities (`x_z` bar = 1, `v_z` bar = 0.01). Copying them back before
//! each call is not timed (`iter_custom`). The backward re-runs its substep's forward from
//! the checkpoint (as the checkpointed driver does), so backward / forward >= 1.
//!
//! Each case prints, before criterion runs it, the peak host memory of its first call above
//! what was live before the call (counting allocator; the first call is where the pooled
//! grids of the CPU stepper grow), next to the host memory held by the simulator and the
//! states; the wgpu cases also print the device memory peak of their second call (the first
//! builds the pipelines): `WgpuContext::peak_bytes`, every live buffer of the backend, the
//! stepper's scratch and grids and the bench's states included.
//!
//! Environment:
//! * `R4D_BENCH_MPM_SIZES=10648,97336` replaces the particle counts (each rounded to a cube
//!   of 8 particles per cell; on Mesa's lavapipe, a CPU emulation of Vulkan, use small ones:
//!   `R4D_BENCH_MPM_SIZES=4000`);
//! * `R4D_BENCH_MPM_BACKENDS=cpu,wgpu,vulkan` picks the steppers (criterion's name filter skips the
//!   timing but not a backend's setup, which on lavapipe compiles the pipelines).
//!
//! `cargo bench --bench mpm_backward [-- [--quick] [FILTER]]`.

#![expect(
    missing_docs,
    reason = "criterion's macros generate undocumented public items"
)]

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use r4d_backend_cpu::{CpuBackend, Par};
use r4d_backend_vulkan::{VulkanBackend, VulkanEngine};
use r4d_backend_wgpu::{WgpuBackend, WgpuContext};
use r4d_gpu::GpuEngine;
use r4d_mpm::adjoint::checkpoint::Differentiable;
use r4d_mpm::adjoint::host::{HostSim, HostState, PhysParams};
use r4d_mpm::adjoint::kernels::MpmAdjointKernels;
use r4d_mpm::simulation::infallible;
use r4d_mpm::{
    BoundaryCondition, Domain, PartParams, ParticleSet, Shape, SimConfig, Surface, TimeConfig,
};
use r4d_mpm::{Simulation, State};
use resonance4d::alloc::{peak_since, reset_peak, Counting, LIVE};
use std::sync::atomic::Ordering;
use std::sync::Arc;
use std::time::{Duration, Instant};

#[global_allocator]
static GLOBAL: Counting = Counting;

/// Warm-up substeps before the measured one.
const WARMUP: u64 = 20;

/// A jelly cube of about `target` particles (8 per cell) in a 64^3 grid.
fn config(target: usize) -> SimConfig {
    let dx = 1.0 / 64.0;
    let side = ((target as f64 / 8.0).cbrt()).round().max(1.0) * dx;
    let lo = 0.5 - side / 2.0;
    SimConfig {
        domain: Domain {
            grid_lim: 1.0,
            n_grid: 64,
        },
        time: TimeConfig {
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

/// Comma-separated list from the environment, or `default`.
fn env_list(name: &str, default: &str) -> Vec<String> {
    std::env::var(name)
        .unwrap_or_else(|_| default.to_string())
        .split(',')
        .map(|s| s.trim().to_string())
        .filter(|s| !s.is_empty())
        .collect()
}

/// The particle counts: `R4D_BENCH_MPM_SIZES` or 10k and 100k.
fn sizes() -> Vec<usize> {
    env_list("R4D_BENCH_MPM_SIZES", "10000,100000")
        .iter()
        .map(|s| {
            s.parse().unwrap_or_else(|_| {
                panic!("R4D_BENCH_MPM_SIZES: '{s}' is not a particle count (e.g. 10648,97336)")
            })
        })
        .collect()
}

fn mib(b: u64) -> f64 {
    b as f64 / 1048576.0
}

fn live() -> u64 {
    LIVE.load(Ordering::Relaxed) as u64
}

/// One size: the simulator, its parameters, the warmed-up state and the adjoint seed.
struct Case {
    sim: HostSim,
    params: Vec<PhysParams<f32>>,
    before: HostState<f32>,
    adj: HostState<f32>,
}

impl Case {
    fn new(target: usize) -> Case {
        let cfg = config(target);
        let scene = ParticleSet::from_shapes(&cfg.shapes, cfg.domain.dx());
        let sim = HostSim::new(&cfg, &scene).expect("bench scene");
        let params = vec![PhysParams::<f32>::of(&cfg.parts[0])];
        let np = sim.len();
        let before = {
            let warm = infallible(Simulation::with_host(
                CpuBackend::<f32>::with_par(Par::Rayon),
                &sim,
            ));
            let mut s = infallible(warm.init(&params, &vec![[0.0f32; 3]; np]));
            for k in 0..WARMUP {
                infallible(warm.step(&mut s, &params, k));
            }
            infallible(s.download(warm.backend()))
        };
        let mut adj = HostState::<f32>::zeros(np);
        for p in 0..np {
            adj.x[p][2] = 1.0;
            adj.v[p][2] = 0.01;
        }
        Case {
            sim,
            params,
            before,
            adj,
        }
    }
}

/// Times `call` on fresh inputs: `prepare` (untimed) returns them, `call` consumes them and
/// returns once the work is done.
fn time_calls<I>(iters: u64, mut prepare: impl FnMut() -> I, mut call: impl FnMut(I)) -> Duration {
    let mut total = Duration::ZERO;
    for _ in 0..iters {
        let input = prepare();
        let t = Instant::now();
        call(input);
        total += t.elapsed();
    }
    total
}

fn bench_cpu(c: &mut Criterion, cases: &[Case]) {
    let mut group = c.benchmark_group("adjoint_substep/cpu");
    group.sample_size(10);
    for case in cases {
        let np = case.sim.len();
        let stepper = infallible(Simulation::with_host(
            CpuBackend::<f32>::with_par(Par::Rayon),
            &case.sim,
        ));
        let b = stepper.backend();
        let up = |h: &HostState<f32>| infallible(State::upload(b, h));
        let before = up(&case.before);
        let k = WARMUP;
        // First calls, measured: peak above what is live before each.
        let mut s = up(&case.before);
        let base = reset_peak();
        infallible(stepper.step(&mut s, &case.params, k));
        let fwd_peak = peak_since(base) as u64;
        let mut adj = up(&case.adj);
        let mut grad = infallible(stepper.zero_grad());
        let held = live();
        let base = reset_peak();
        infallible(stepper.step_vjp(&before, &case.params, k, &mut adj, &mut grad));
        let bwd_peak = peak_since(base) as u64;
        let g = infallible(stepper.grad_to_host(&grad, &case.params));
        assert!(g[0].youngs_modulus.is_finite(), "non-finite gradient");
        drop((s, adj));
        for (what, peak) in [("forward", fwd_peak), ("backward", bwd_peak)] {
            println!(
                "adjoint_substep/cpu/{what}/{np}: peak host memory of one call {:.1} MiB \
                 ({peak} B, {:.0} B/particle) above {:.1} MiB live before it (simulators, \
                 states, pooled grids)",
                mib(peak),
                peak as f64 / np as f64,
                mib(held)
            );
        }
        group.throughput(Throughput::Elements(np as u64));
        group.bench_function(BenchmarkId::new("forward", np), |b| {
            b.iter_custom(|iters| {
                time_calls(
                    iters,
                    || up(&case.before),
                    |mut s| infallible(stepper.step(&mut s, &case.params, k)),
                )
            })
        });
        group.bench_function(BenchmarkId::new("backward", np), |b| {
            b.iter_custom(|iters| {
                time_calls(
                    iters,
                    || up(&case.adj),
                    |mut adj| {
                        infallible(stepper.step_vjp(&before, &case.params, k, &mut adj, &mut grad))
                    },
                )
            })
        });
    }
    group.finish();
}

fn bench_wgpu(c: &mut Criterion, cases: &[Case]) {
    // Whatever adapter is present (without a GPU: lavapipe, a software rasterizer, whose
    // figures say nothing about GPU speed).
    let ctx = match WgpuContext::new() {
        Ok(ctx) => Arc::new(ctx),
        Err(e) => {
            eprintln!("adjoint_substep/wgpu skipped: {e}");
            return;
        }
    };
    eprintln!(
        "wgpu adapter: {} ({:?}, {:?})",
        ctx.info.name, ctx.info.device_type, ctx.info.backend
    );
    let wait = || {
        let _ = ctx.device.poll(wgpu::PollType::Wait {
            submission_index: None,
            timeout: None,
        });
    };
    let dev = Device {
        name: "wgpu",
        wait: &wait,
        reset_peak: &|| ctx.reset_peak(),
        peak_bytes: &|| ctx.peak_bytes(),
    };
    bench_device(c, cases, &dev, || WgpuBackend::new(ctx.clone()));
}

fn bench_vulkan(c: &mut Criterion, cases: &[Case]) {
    let engine = match VulkanEngine::new() {
        Ok(e) => e,
        Err(e) => {
            eprintln!("adjoint_substep/vulkan skipped: {e}");
            return;
        }
    };
    eprintln!("vulkan device: {}", engine.device_name());
    let dev = Device {
        name: "vulkan",
        wait: &|| engine.finish().expect("vulkan submission"),
        reset_peak: &|| engine.reset_peak(),
        peak_bytes: &|| engine.memory_usage().peak_bytes,
    };
    bench_device(c, cases, &dev, || VulkanBackend::new(engine.clone()));
}

/// A GPU engine as the bench drives it: waiting for its work and its memory peak.
struct Device<'a> {
    name: &'static str,
    wait: &'a dyn Fn(),
    reset_peak: &'a dyn Fn(),
    peak_bytes: &'a dyn Fn() -> u64,
}

/// The device adjoint (`Simulation` over a GPU backend's kernels): the same cases and
/// measurements on every GPU engine.
fn bench_device<B: MpmAdjointKernels<Scalar = f32>>(
    c: &mut Criterion,
    cases: &[Case],
    dev: &Device,
    make: impl Fn() -> B,
) {
    let wait = dev.wait;
    let name = dev.name;
    let mut group = c.benchmark_group(format!("adjoint_substep/{name}"));
    group.sample_size(10);
    for case in cases {
        let np = case.sim.len();
        let stepper = match Simulation::with_host(make(), &case.sim) {
            Ok(s) => s,
            Err(e) => {
                eprintln!("adjoint_substep/{name}/{np} skipped: {e}");
                continue;
            }
        };
        let b = stepper.backend();
        let before = State::upload(b, &case.before).expect("uploading the state");
        let adj0 = State::upload(b, &case.adj).expect("uploading the adjoint");
        let mut grad = stepper.zero_grad().expect("device gradient");
        let k = WARMUP;
        // First calls build the pipelines; the measured ones are the second.
        let mut s = stepper.clone_state(&before).unwrap();
        stepper.step(&mut s, &case.params, k).unwrap();
        let mut adj = stepper.clone_state(&adj0).unwrap();
        stepper
            .step_vjp(&before, &case.params, k, &mut adj, &mut grad)
            .unwrap();
        wait();
        let mut peaks = Vec::new();
        for backward in [false, true] {
            let mut s = stepper.clone_state(&before).unwrap();
            let mut adj = stepper.clone_state(&adj0).unwrap();
            wait();
            (dev.reset_peak)();
            let base = reset_peak();
            if backward {
                stepper
                    .step_vjp(&before, &case.params, k, &mut adj, &mut grad)
                    .unwrap();
            } else {
                stepper.step(&mut s, &case.params, k).unwrap();
            }
            wait();
            peaks.push((peak_since(base) as u64, (dev.peak_bytes)()));
        }
        let g = stepper
            .grad_to_host(&grad, &case.params)
            .expect("downloading the gradient");
        assert!(g[0].youngs_modulus.is_finite(), "non-finite gradient");
        for (what, (host, dev)) in ["forward", "backward"].into_iter().zip(peaks) {
            println!(
                "adjoint_substep/{name}/{what}/{np}: peak device memory {:.1} MiB ({dev} B, \
                 {:.0} B/particle: every live buffer of the backend, i.e. the stepper's scratch \
                 and grids and the bench's checkpoint, adjoint seed and working copies), peak \
                 host memory of one call {:.2} MiB ({host} B)",
                mib(dev),
                dev as f64 / np as f64,
                mib(host)
            );
        }
        group.throughput(Throughput::Elements(np as u64));
        group.bench_function(BenchmarkId::new("forward", np), |b| {
            b.iter_custom(|iters| {
                time_calls(
                    iters,
                    || {
                        let s = stepper.clone_state(&before).unwrap();
                        wait();
                        s
                    },
                    |mut s| {
                        stepper.step(&mut s, &case.params, k).unwrap();
                        wait();
                    },
                )
            })
        });
        group.bench_function(BenchmarkId::new("backward", np), |b| {
            b.iter_custom(|iters| {
                time_calls(
                    iters,
                    || {
                        let a = stepper.clone_state(&adj0).unwrap();
                        wait();
                        a
                    },
                    |mut adj| {
                        stepper
                            .step_vjp(&before, &case.params, k, &mut adj, &mut grad)
                            .unwrap();
                        wait();
                    },
                )
            })
        });
    }
    group.finish();
}

fn benches(c: &mut Criterion) {
    let backends = env_list("R4D_BENCH_MPM_BACKENDS", "cpu,wgpu,vulkan");
    let cases: Vec<Case> = sizes().into_iter().map(Case::new).collect();
    if backends.iter().any(|b| b == "cpu") {
        bench_cpu(c, &cases);
    }
    if backends.iter().any(|b| b == "wgpu") {
        bench_wgpu(c, &cases);
    }
    if backends.iter().any(|b| b == "vulkan") {
        bench_vulkan(c, &cases);
    }
}

criterion_group!(mpm_backward, benches);
criterion_main!(mpm_backward);
