//! Loss benchmarks: value + gradient of the DMS loss (`L_spatial + L_mag + L_phase`, f32
//! videos: SSIM in f32, the spectral terms in f64) for 16 frames at 1280x720 and 1920x1080,
//! plus its parts: the SSIM term alone, the spectral terms alone, and only the FFTs (and
//! transposes) of the spectral terms. Each case prints the peak host memory of one call
//! (counting allocator; the two input videos and the gradient buffer are allocated before
//! and not counted) and the share of the time spent in FFTs.
//!
//! `dms_banded` is the same loss evaluated as the video fit does it (`r4d_loss::bands`): 128-row
//! bands, an 8-bit reference, each band's rows copied out of the rendered video (the fit
//! renders them) and its gradient computed; the sum of the bands is the whole video's loss.
//!
//! `lpips` is LPIPS-Alex (and, with `R4D_BENCH_LPIPS_VGG=1`, LPIPS-VGG) of 16 frames at
//! 1920x1080, 8-bit frames generated one pair at a time as they are needed (`Lpips::stream`), so the
//! printed peak is the metric's own working memory plus the frames in flight. It needs the
//! converted weights (`scripts/lpips_weights.sh`; `$R4D_LPIPS_DIR` or `target/lpips`) and says
//! it skipped otherwise. `R4D_BENCH_LOSS=dms` or `=lpips` runs one group only.
//!
//! The videos: a smooth textured pattern translating by 1.5 px per frame (rendered) and
//! 2 px per frame (reference), values in [0, 1].

#![expect(
    missing_docs,
    reason = "criterion's macros generate undocumented public items"
)]

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion};
use r4d_loss::bands::{BandedDms, ReferenceVideo, Video8};
use r4d_loss::lpips::{Lpips, LpipsNet, WEIGHTS_DIR_ENV};
use r4d_loss::{Dms, DmsConfig, DmsTerms, DmsWeights, Loss, Spectral, SpectralConfig, Video};
use resonance4d::alloc::{peak_since, reset_peak, Counting};
use std::time::Instant;

#[global_allocator]
static GLOBAL: Counting = Counting;

/// The pattern's value at frame `t`, pixel `(y, x)`, channel `c`, in [0, 1].
fn pattern(t: usize, y: usize, x: usize, c: usize, speed: f32) -> f32 {
    let u = x as f32 - speed * t as f32;
    let v = 0.5
        + 0.25 * (u * 0.05 + c as f32).sin() * (y as f32 * 0.04).cos()
        + 0.15 * ((u + y as f32) * 0.13).sin();
    v.clamp(0.0, 1.0)
}

fn video(t: usize, h: usize, w: usize, speed: f32) -> Video<f32> {
    let mut data = Vec::with_capacity(t * h * w * 3);
    for f in 0..t {
        for y in 0..h {
            for x in 0..w {
                for c in 0..3 {
                    data.push(pattern(f, y, x, c, speed));
                }
            }
        }
    }
    Video::new(t, h, w, data).unwrap()
}

/// The band-wise loss over the whole video: every band's rows copied out, its terms and
/// gradient evaluated (the gradient of each band is dropped, as the fit hands it on).
fn banded(loss: &BandedDms, rendered: &Video<f32>) -> DmsTerms {
    let w = rendered.width();
    let mut terms = DmsTerms::default();
    let bands: Vec<_> = loss.bands().cloned().collect();
    for (b, band) in bands.iter().enumerate() {
        let r = &band.rows;
        let mut data = Vec::with_capacity(rendered.frames() * r.len() * w * 3);
        for t in 0..rendered.frames() {
            data.extend_from_slice(&rendered.frame(t)[r.start * w * 3..r.end * w * 3]);
        }
        let x = Video::new(rendered.frames(), r.len(), w, data).unwrap();
        let mut g = vec![0.0f32; x.data().len()];
        terms.add(&loss.band_terms_and_grad_into(b, &x, &mut g).unwrap());
    }
    terms
}

fn mean_seconds(mut f: impl FnMut(), n: usize) -> f64 {
    f();
    let t0 = Instant::now();
    for _ in 0..n {
        f();
    }
    t0.elapsed().as_secs_f64() / n as f64
}

fn only(group: &str) -> bool {
    std::env::var("R4D_BENCH_LOSS").map_or(true, |g| g == group)
}

/// One `(H, W, 3)` 8-bit frame of [`video`]'s pattern (videos to evaluate are 8-bit).
fn frame(t: usize, h: usize, w: usize, speed: f32) -> Vec<u8> {
    let mut data = Vec::with_capacity(h * w * 3);
    for y in 0..h {
        for x in 0..w {
            for c in 0..3 {
                data.push((pattern(t, y, x, c, speed) * 255.0).round() as u8);
            }
        }
    }
    data
}

fn bench_lpips(c: &mut Criterion) {
    if !only("lpips") {
        return;
    }
    let dir = std::env::var_os(WEIGHTS_DIR_ENV)
        .map(std::path::PathBuf::from)
        .unwrap_or_else(|| std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("target/lpips"));
    let mut nets = vec![LpipsNet::Alex];
    if std::env::var("R4D_BENCH_LPIPS_VGG").is_ok_and(|v| v == "1") {
        nets.push(LpipsNet::Vgg);
    }
    let mut group = c.benchmark_group("lpips");
    group.sample_size(10);
    for net in nets {
        let path = dir.join(format!("{}.safetensors", net.name()));
        let m = match Lpips::from_file(&path, Some(net)) {
            Ok(m) => m,
            Err(e) => {
                println!("lpips-{net}: skipped ({e}; run scripts/lpips_weights.sh)");
                continue;
            }
        };
        let (frames, w, h) = (16, 1920, 1080);
        let run = || {
            m.stream(frames, h, w, |t| {
                Ok((frame(t, h, w, 1.5), frame(t, h, w, 2.0)))
            })
            .unwrap()
        };
        let base = reset_peak();
        let t0 = Instant::now();
        let v = run();
        let secs = t0.elapsed().as_secs_f64();
        let peak = peak_since(base);
        println!(
            "lpips-{net} {frames}x{w}x{h}: {secs:.2} s ({:.3} s per frame pair, {} band(s) per \
             frame, {} threads), peak memory {:.1} MiB (frames generated on demand, {:.1} MiB \
             per pair); mean {:.6}",
            secs / frames as f64,
            m.bands_for(h, w).unwrap(),
            rayon::current_num_threads(),
            peak as f64 / (1 << 20) as f64,
            (2 * h * w * 3) as f64 / (1 << 20) as f64,
            v.mean
        );
        let label = format!("{net}_{frames}x{w}x{h}");
        group.bench_with_input(BenchmarkId::new("stream", &label), &(), |b, _| b.iter(run));
    }
    group.finish();
}

fn bench_dms(c: &mut Criterion) {
    if !only("dms") {
        return;
    }
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

        let reference8 = ReferenceVideo::U8(Video8::quantize(&reference));
        let bands = BandedDms::new(reference8, frames, DmsConfig::default(), 128).unwrap();
        let base = reset_peak();
        let terms_b = banded(&bands, &rendered);
        let peak_b = peak_since(base);
        let t_banded = mean_seconds(
            || {
                banded(&bands, &rendered);
            },
            2,
        );
        println!(
            "dms {label} in {} bands of 128 rows, 8-bit reference ({:.1} MiB): {:.3} s, peak \
             memory of one call {:.1} MiB; total {:.6} (whole video, f32 reference: {:.6})",
            bands.len(),
            bands.reference().bytes() as f64 / (1 << 20) as f64,
            t_banded,
            peak_b as f64 / (1 << 20) as f64,
            terms_b.total,
            terms.total
        );

        group.bench_with_input(BenchmarkId::new("dms_banded", &label), &(), |b, _| {
            b.iter(|| banded(&bands, &rendered))
        });
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

criterion_group!(benches, bench_dms, bench_lpips);
criterion_main!(benches);
