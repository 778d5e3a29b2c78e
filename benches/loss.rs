//! Loss benchmarks: value + gradient of the DMS loss (`L_spatial + L_mag + L_phase`, f32
//! videos: SSIM in f32, the spectral terms in f64) for 16 frames at 1280x720 and 1920x1080,
//! plus its parts: the SSIM term alone, the spectral terms alone, and only the FFTs (and
//! transposes) of the spectral terms. Each case prints the peak host memory of one call
//! (counting allocator; the two input videos and the gradient buffer are allocated before
//! and not counted) and the share of the time spent in FFTs.
//!
//! The videos: a smooth textured pattern translating by 1.5 px per frame (rendered) and
//! 2 px per frame (reference), values in [0, 1].

#![expect(
    missing_docs,
    reason = "criterion's macros generate undocumented public items"
)]

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion};
use r4d_loss::{Dms, DmsConfig, DmsWeights, Loss, Spectral, SpectralConfig, Video};
use resonance4d::alloc::{peak_since, reset_peak, Counting};
use std::time::Instant;

#[global_allocator]
static GLOBAL: Counting = Counting;

fn video(t: usize, h: usize, w: usize, speed: f32) -> Video<f32> {
    let mut data = Vec::with_capacity(t * h * w * 3);
    for f in 0..t {
        for y in 0..h {
            for x in 0..w {
                let u = x as f32 - speed * f as f32;
                for c in 0..3 {
                    let v = 0.5
                        + 0.25 * (u * 0.05 + c as f32).sin() * (y as f32 * 0.04).cos()
                        + 0.15 * ((u + y as f32) * 0.13).sin();
                    data.push(v.clamp(0.0, 1.0));
                }
            }
        }
    }
    Video::new(t, h, w, data).unwrap()
}

fn mean_seconds(mut f: impl FnMut(), n: usize) -> f64 {
    f();
    let t0 = Instant::now();
    for _ in 0..n {
        f();
    }
    t0.elapsed().as_secs_f64() / n as f64
}

fn bench_dms(c: &mut Criterion) {
    let mut group = c.benchmark_group("dms_value_and_grad");
    group.sample_size(10);
    for (w, h) in [(1280, 720), (1920, 1080)] {
        let frames = 16;
        let label = format!("{frames}x{w}x{h}");
        let reference = video(frames, h, w, 2.0);
        let rendered = video(frames, h, w, 1.5);
        let mut grad = vec![0.0f32; rendered.data().len()];
        let full = Dms::new(reference.clone(), DmsConfig::default()).unwrap();
        let only = |weights: DmsWeights| {
            Dms::new(
                reference.clone(),
                DmsConfig {
                    weights,
                    ..Default::default()
                },
            )
            .unwrap()
        };
        let spatial = only(DmsWeights {
            l1: 0.0,
            spatial: 1.0,
            mag: 0.0,
            phase: 0.0,
        });
        let spectral = only(DmsWeights {
            l1: 0.0,
            spatial: 0.0,
            mag: 1.0,
            phase: 1.0,
        });
        let plans = Spectral::new(SpectralConfig::default(), frames, h, w).unwrap();

        // Peak memory of one call, and the time split.
        let base = reset_peak();
        let terms = full.terms_and_grad_into(&rendered, &mut grad).unwrap();
        let peak = peak_since(base);
        let t_full = mean_seconds(|| drop(full.value_and_grad_into(&rendered, &mut grad)), 2);
        let t_spatial = mean_seconds(
            || drop(spatial.value_and_grad_into(&rendered, &mut grad)),
            2,
        );
        let t_spectral = mean_seconds(
            || drop(spectral.value_and_grad_into(&rendered, &mut grad)),
            2,
        );
        let t_fft = mean_seconds(|| plans.transforms_only(true), 2);
        println!(
            "dms {label}: total {:.3} s (SSIM term {:.3} s, spectral terms {:.3} s, of which \
             FFTs {:.3} s = {:.0}% of the total); peak memory of one call {:.1} MiB \
             (the videos: {:.1} MiB each); terms {:?}",
            t_full,
            t_spatial,
            t_spectral,
            t_fft,
            100.0 * t_fft / t_full,
            peak as f64 / (1 << 20) as f64,
            (rendered.data().len() * 4) as f64 / (1 << 20) as f64,
            terms
        );

        group.bench_with_input(BenchmarkId::new("dms", &label), &(), |b, _| {
            b.iter(|| full.value_and_grad_into(&rendered, &mut grad).unwrap())
        });
        group.bench_with_input(BenchmarkId::new("ssim_term", &label), &(), |b, _| {
            b.iter(|| spatial.value_and_grad_into(&rendered, &mut grad).unwrap())
        });
        group.bench_with_input(BenchmarkId::new("spectral_terms", &label), &(), |b, _| {
            b.iter(|| spectral.value_and_grad_into(&rendered, &mut grad).unwrap())
        });
        group.bench_with_input(BenchmarkId::new("ffts_only", &label), &(), |b, _| {
            b.iter(|| plans.transforms_only(true))
        });
    }
    group.finish();
}

criterion_group!(benches, bench_dms);
criterion_main!(benches);
