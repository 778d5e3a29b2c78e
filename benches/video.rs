//! MP4 decoding: a 1080p H.264 clip (written once by our own encoder, QP 12-20, so heavier
//! than a typical camera file) decoded to RGB f32 frames (as `metrics` reads a video) and to
//! 8-bit RGB (as the fit stores a reference video). Reports frames per second (`Throughput::Elements` = frames) and, from the counting
//! allocator, the decoder's peak host memory. Also the encoder's speed at the same size.
//!
//! Target: >= 60 frames/s at 1080p on 2 cores.

#![expect(
    missing_docs,
    reason = "criterion's macros generate undocumented public items"
)]

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use r4d_video::{write_mp4, Mp4Frames};
use resonance4d::alloc::{peak_since, reset_peak, Counting};
use std::path::Path;

#[global_allocator]
static GLOBAL: Counting = Counting;

const FRAMES: usize = 30;
const W: usize = 1920;
const H: usize = 1080;

/// A moving, textured scene: drifting colour blobs over a gradient with fine stripes, so
/// that motion compensation and residuals both do work.
fn clip() -> r4d_loss::Video<f32> {
    r4d_loss::Video::from_frames(
        H,
        W,
        (0..FRAMES).map(|t| {
            let mut f = vec![0f32; H * W * 3];
            for y in 0..H {
                for x in 0..W {
                    let (u, v) = (x as f32 / W as f32, y as f32 / H as f32);
                    let stripe = 0.05 * ((x + 3 * t) as f32 * 0.7).sin() * ((y as f32) * 0.3).cos();
                    let mut c = [0.2 + 0.5 * v + stripe, 0.25 + 0.3 * u, 0.4 - stripe];
                    for k in 0..4 {
                        let cx = 0.2 + 0.2 * k as f32 + 0.004 * t as f32 * (k as f32 + 1.0);
                        let cy = 0.5 + 0.2 * ((k as f32) - 1.5) * 0.5;
                        let d2 = (u - cx).powi(2) + (v - cy).powi(2);
                        let a = 0.85 * (-d2 / 0.004).exp();
                        let col = [
                            [0.9, 0.2, 0.1],
                            [0.1, 0.8, 0.3],
                            [0.2, 0.3, 0.9],
                            [0.9, 0.9, 0.2],
                        ][k];
                        for i in 0..3 {
                            c[i] = c[i] * (1.0 - a) + col[i] * a;
                        }
                    }
                    f[(y * W + x) * 3..][..3].copy_from_slice(&c);
                }
            }
            f
        }),
    )
    .expect("clip")
}

fn decode_all(path: &Path, buf: &mut [f32]) -> usize {
    let mut frames = Mp4Frames::open(path).expect("open");
    let mut n = 0;
    while frames.next_frame(buf).expect("decode") {
        n += 1;
    }
    n
}

fn decode_all_rgb8(path: &Path, buf: &mut [u8]) -> usize {
    let mut frames = Mp4Frames::open(path).expect("open");
    let mut n = 0;
    while frames.next_frame_rgb8(buf).expect("decode") {
        n += 1;
    }
    n
}

fn bench_video(c: &mut Criterion) {
    let dir = std::env::temp_dir().join(format!("r4d-bench-video-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let path = dir.join("clip_1080p.mp4");
    let video = clip();

    let mut g = c.benchmark_group("mp4_1080p");
    g.sample_size(10);
    g.throughput(Throughput::Elements(FRAMES as u64));
    g.bench_function("encode", |b| {
        b.iter(|| write_mp4(&path, &video, 30.0).expect("encode"))
    });
    write_mp4(&path, &video, 30.0).expect("encode");
    let bytes = std::fs::metadata(&path).map(|m| m.len()).unwrap_or(0);
    let mut buf = vec![0f32; W * H * 3];
    let mark = reset_peak();
    assert_eq!(decode_all(&path, &mut buf), FRAMES);
    let peak = peak_since(mark);
    g.bench_function("decode_rgb_f32", |b| b.iter(|| decode_all(&path, &mut buf)));
    let mut bytes8 = vec![0u8; W * H * 3];
    g.bench_function("decode_rgb8", |b| {
        b.iter(|| decode_all_rgb8(&path, &mut bytes8))
    });
    g.finish();
    eprintln!(
        "mp4_1080p: {FRAMES} frames, {:.1} MB file ({:.1} Mbit/s at 30 fps); peak Rust-side memory while decoding {:.1} MB (OpenH264's C++ buffers are not counted)",
        bytes as f64 / 1e6,
        bytes as f64 * 8.0 / 1e6 / (FRAMES as f64 / 30.0),
        peak as f64 / 1e6
    );
    let _ = std::fs::remove_dir_all(&dir);
}

criterion_group!(benches, bench_video);
criterion_main!(benches);
