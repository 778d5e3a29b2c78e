//! Mask lifting (`r4d_segment::lift`) and the KNN pass (`r4d_segment::smooth`): time and peak
//! host memory.
//!
//! `cargo bench --bench segment [-- [--quick] [--once] [GAUSSIANS [VIEWS [WIDTH HEIGHT]]]]`
//! (default: 300 000 Gaussians, 8 views at 1920x1080; `--quick`: 30 000 Gaussians, 8 views
//! at 480x270; `--once`: one timed call per case instead of criterion's 10 samples). Cases,
//! on the rayon pool (all cores):
//!
//! * `lift/surfaces/labels`: the synthetic three-part scene (`r4d_segment::synthetic`: flat
//!   opaque Gaussians on surfaces, a few Gaussians per pixel as in a fitted capture), label
//!   masks ray-cast from the solids, cameras on a ring.
//! * `lift/volume/labels` and `lift/volume/probabilities`: the splat bench's volumetric ball
//!   (centres uniform in a unit ball, scales log-uniform in [0.003, 0.03], opacities
//!   sigmoid(U[-2, 4]): many translucent Gaussians per pixel, the expensive case), seen from
//!   distance 3 around it; masks split the ball's disc into three sectors, as labels or as
//!   three soft probability maps. `lift/volume/labels-summed`: the labels with the summed
//!   votes (`ViewVote::Sum`) instead of the default per-view confusion matrices, for the
//!   cost of the EM.
//! * `smooth/surfaces`, `smooth/volume`: the KNN pass (k 16, with the region prior) on the
//!   lift's outcome; `smooth-no-appearance/...`: without the prior's appearance term;
//!   `smooth-no-regions/...`: without the region prior.
//!
//! Each case prints the peak host memory of one call beyond its inputs (counting allocator).
//! The masks are handed over in memory (each view's mask is copied once per call, as a file
//! source would decode it).

use criterion::{BenchmarkId, Criterion};
use r4d_segment::lift::{lift, LiftConfig, ViewVote};
use r4d_segment::smooth::{smooth_lifted, SmoothConfig};
use r4d_segment::synthetic::{self, Rng};
use r4d_segment::{InMemoryMasks, Mask, MaskData};
use r4d_splat::{Camera, Gaussians};
use resonance4d::alloc::{peak_since, reset_peak, Counting};
use std::time::Duration;

#[global_allocator]
static GLOBAL: Counting = Counting;

/// The splat bench's volumetric ball.
fn ball(n: usize) -> Gaussians {
    let mut r = Rng(42);
    let mut g = Gaussians {
        sh_degree: 0,
        ..Default::default()
    };
    while g.len() < n {
        let p = [r.range(-1.0, 1.0), r.range(-1.0, 1.0), r.range(-1.0, 1.0)];
        if p.iter().map(|v| v * v).sum::<f64>() > 1.0 {
            continue;
        }
        g.means.push(p.map(|v| v as f32));
        let (lo, hi) = (0.003f64.ln(), 0.03f64.ln());
        g.log_scales.push([0; 3].map(|_| r.range(lo, hi) as f32));
        g.quats.push([
            r.range(-1.0, 1.0) as f32 + 1.5,
            r.range(-1.0, 1.0) as f32,
            r.range(-1.0, 1.0) as f32,
            r.range(-1.0, 1.0) as f32,
        ]);
        g.opacity_logits.push(r.range(-2.0, 4.0) as f32);
        g.sh.extend([0.0; 3]);
    }
    g
}

fn ball_cameras(views: usize, w: u32, h: u32) -> Vec<Camera> {
    (0..views)
        .map(|k| {
            let a = (360.0 * k as f64 / views as f64).to_radians();
            let eye = [3.0 * a.cos(), 3.0 * a.sin(), 0.5];
            Camera::look_at(w, h, 60.0, eye, [0.0; 3], [0.0, 0.0, 1.0])
        })
        .collect()
}

/// Three sectors of the ball's image disc: labels, or soft probabilities.
fn ball_masks(cams: &[Camera], soft: bool) -> InMemoryMasks {
    let masks = cams
        .iter()
        .map(|c| {
            let (w, h) = (c.width, c.height);
            let (cx, cy) = (w as f64 / 2.0, h as f64 / 2.0);
            let rad = 0.35 * w as f64;
            let mut labels = vec![0u16; (w * h) as usize];
            let mut probs = vec![0f32; (w * h * 3) as usize];
            for j in 0..h {
                for i in 0..w {
                    let (dx, dy) = (i as f64 + 0.5 - cx, j as f64 + 0.5 - cy);
                    if dx * dx + dy * dy > rad * rad {
                        continue;
                    }
                    let t = (dy.atan2(dx) + std::f64::consts::PI) / (2.0 * std::f64::consts::PI);
                    let k = ((3.0 * t) as usize).min(2);
                    let p = (j * w + i) as usize;
                    labels[p] = k as u16 + 1;
                    probs[3 * p + k] = 0.8;
                    probs[3 * p + (k + 1) % 3] = 0.1;
                }
            }
            Mask {
                origin: "bench".into(),
                width: w,
                height: h,
                data: if soft {
                    MaskData::Probabilities(probs)
                } else {
                    MaskData::Labels(labels)
                },
            }
        })
        .collect();
    InMemoryMasks {
        class_names: vec!["a".into(), "b".into(), "c".into()],
        masks,
    }
}

fn mib(b: usize) -> f64 {
    b as f64 / 1048576.0
}

fn main() {
    let raw: Vec<String> = std::env::args().skip(1).collect();
    let quick = raw.iter().any(|a| a == "--quick");
    let once = raw.iter().any(|a| a == "--once");
    let nums: Vec<usize> = raw.iter().filter_map(|a| a.parse().ok()).collect();
    let (n0, v0, w0, h0) = if quick {
        (30_000, 8, 480, 270)
    } else {
        (300_000, 8, 1920, 1080)
    };
    let n = nums.first().copied().unwrap_or(n0);
    let views = nums.get(1).copied().unwrap_or(v0);
    let w = nums.get(2).copied().unwrap_or(w0) as u32;
    let h = nums.get(3).copied().unwrap_or(h0) as u32;
    eprintln!(
        "segment bench: {n} Gaussians, {views} views at {w}x{h}, {} threads",
        rayon::current_num_threads()
    );
    let mut c = Criterion::default();
    let mut group = c.benchmark_group("segment");
    group
        .sample_size(10)
        .warm_up_time(Duration::from_secs(1))
        .measurement_time(Duration::from_secs(5));
    let cfg = LiftConfig::default();
    let smooth_cfg = SmoothConfig::default();
    let id = format!("{n}/{views}x{w}x{h}");

    let scene = synthetic::three_parts(n, 1);
    let surf_cams = synthetic::ring_cameras(views, w, h);
    let surf_masks = scene.masks(&surf_cams);
    let vol = ball(n);
    let vol_cams = ball_cameras(views, w, h);
    let sum = LiftConfig {
        vote: ViewVote::Sum,
        ..cfg
    };
    let cases = [
        (
            "surfaces",
            "labels",
            &scene.gaussians,
            &surf_cams,
            surf_masks,
            cfg,
        ),
        (
            "volume",
            "labels",
            &vol,
            &vol_cams,
            ball_masks(&vol_cams, false),
            cfg,
        ),
        (
            "volume",
            "labels-summed",
            &vol,
            &vol_cams,
            ball_masks(&vol_cams, false),
            sum,
        ),
        (
            "volume",
            "probabilities",
            &vol,
            &vol_cams,
            ball_masks(&vol_cams, true),
            cfg,
        ),
    ];
    let mut lifted = Vec::new();
    for (scene_name, kind, g, cams, mut masks, cfg) in cases {
        let base = reset_peak();
        let t = std::time::Instant::now();
        let l = lift(g, cams, &mut masks, &cfg).unwrap();
        let first = t.elapsed().as_secs_f64();
        println!(
            "lift/{scene_name}/{kind} {id}: {} Gaussians, first call {first:.2} s, peak host memory {:.1} MiB (masks {:.1} MiB held besides)",
            g.len(),
            mib(peak_since(base)),
            mib(masks
                .masks
                .iter()
                .map(|m| match &m.data {
                    MaskData::Labels(l) => 2 * l.len(),
                    MaskData::Probabilities(p) => 4 * p.len(),
                })
                .sum())
        );
        if !once {
            group.bench_function(
                BenchmarkId::new(format!("lift/{scene_name}/{kind}"), &id),
                |b| b.iter(|| lift(g, cams, &mut masks, &cfg).unwrap()),
            );
        }
        if kind == "labels" {
            lifted.push((scene_name, g, l));
        }
    }
    let no_regions = SmoothConfig {
        region_tau: 0.0,
        ..smooth_cfg
    };
    let no_appearance = SmoothConfig {
        appearance: 0.0,
        ..smooth_cfg
    };
    for (scene_name, g, l) in lifted {
        for (case, sc) in [
            ("smooth", &smooth_cfg),
            ("smooth-no-appearance", &no_appearance),
            ("smooth-no-regions", &no_regions),
        ] {
            let base = reset_peak();
            let t = std::time::Instant::now();
            smooth_lifted(g, &l, cfg.temperature, sc).unwrap();
            println!(
                "{case}/{scene_name} {}: first call {:.2} s, peak host memory {:.1} MiB",
                g.len(),
                t.elapsed().as_secs_f64(),
                mib(peak_since(base))
            );
            if once {
                continue;
            }
            group.bench_function(
                BenchmarkId::new(format!("{case}/{scene_name}"), g.len()),
                |b| b.iter(|| smooth_lifted(g, &l, cfg.temperature, sc).unwrap()),
            );
        }
    }
    group.finish();
    c.final_summary();
}
