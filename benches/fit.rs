//! One full fit iteration at a small scale: the demo's two-part plant (1 836 particles,
//! 2 816 static Gaussians, 16 frames x 75 substeps, 256 x 192): simulate with checkpoints,
//! render every frame, DMS, render VJPs and the reverse sweep through every substep — the
//! work of one AdamW iteration of `r4d demo` — in f32 and f64, with the peak host memory of
//! one iteration (counting allocator; the problem itself is built before and not counted).
//! Also the forward-only evaluation an initialisation candidate costs.

#![expect(
    missing_docs,
    reason = "criterion's macros generate undocumented public items"
)]

use criterion::{criterion_group, criterion_main, Criterion};
use resonance4d::alloc::{peak_since, reset_peak, Counting};
use resonance4d::video_fit::{Objective, Precision};

#[global_allocator]
static GLOBAL: Counting = Counting;

fn bench_fit_iteration(c: &mut Criterion) {
    let spec = resonance4d::demo::DemoScene::Plant.spec(resonance4d::demo::Size::Full);
    let problem = spec
        .problem(resonance4d::compute::cpu())
        .expect("demo problem");
    let cfg = spec.fit_config(&Default::default());
    let start = problem.config.parts.clone();
    let mut group = c.benchmark_group("fit_iteration_demo");
    group.sample_size(10);
    for (label, precision) in [("f32", Precision::F32), ("f64", Precision::F64)] {
        let mut obj = Objective::new(&problem, None, &cfg.loss, false).expect("objective");
        obj.precision = precision;
        let base = reset_peak();
        let (ev, _) = obj.value_and_grad(&start).expect("iteration");
        let peak = peak_since(base);
        println!(
            "fit iteration ({label}): loss {:.4}, peak host memory {:.1} MiB",
            ev.total,
            peak as f64 / (1 << 20) as f64
        );
        group.bench_function(format!("value_and_grad_{label}"), |b| {
            b.iter(|| obj.value_and_grad(&start).expect("iteration"))
        });
        group.bench_function(format!("forward_only_{label}"), |b| {
            b.iter(|| obj.value(&start).expect("evaluation"))
        });
    }
    group.finish();
}

criterion_group!(benches, bench_fit_iteration);
criterion_main!(benches);
