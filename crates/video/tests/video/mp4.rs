//! MP4 write and read: round trips (PSNR >= 40 dB), frame selection, frame rates, odd sizes,
//! and the typed errors of files that are not H.264 MP4.

use r4d_loss::metrics::psnr;
use r4d_loss::Video;
use r4d_video::{probe, read_mp4, read_video, write_mp4, Mp4Writer, VideoError};
use std::path::PathBuf;

/// A render-like clip: coloured Gaussian blobs drifting over a vertical gradient.
fn clip(frames: usize, h: usize, w: usize) -> Video<f32> {
    let blobs = [
        ([0.9f32, 0.2, 0.1], 0.30, 0.35, 0.12),
        ([0.1, 0.7, 0.3], 0.65, 0.55, 0.18),
        ([0.2, 0.3, 0.95], 0.45, 0.70, 0.09),
    ];
    Video::from_frames(
        h,
        w,
        (0..frames).map(|t| {
            let mut f = vec![0f32; h * w * 3];
            for y in 0..h {
                for x in 0..w {
                    let (u, v) = (x as f32 / w as f32, y as f32 / h as f32);
                    let mut c = [0.15 + 0.5 * v, 0.2 + 0.3 * v, 0.35];
                    for (k, (col, cx, cy, r)) in blobs.iter().enumerate() {
                        let s = 0.02 * t as f32 * (k as f32 + 1.0);
                        let d2 = (u - cx - s).powi(2) + (v - cy + 0.5 * s).powi(2);
                        let a = 0.9 * (-d2 / (2.0 * r * r)).exp();
                        for i in 0..3 {
                            c[i] = c[i] * (1.0 - a) + col[i] * a;
                        }
                    }
                    f[(y * w + x) * 3..][..3].copy_from_slice(&c);
                }
            }
            f
        }),
    )
    .unwrap()
}

fn tmp(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("r4d-video-{}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d.join(name)
}

fn crop(v: &Video<f32>, h: usize, w: usize) -> Video<f32> {
    Video::from_frames(
        h,
        w,
        (0..v.frames()).map(|t| {
            let f = v.frame(t);
            (0..h)
                .flat_map(|y| f[y * v.width() * 3..][..w * 3].to_vec())
                .collect::<Vec<f32>>()
        }),
    )
    .unwrap()
}

#[test]
fn round_trip_keeps_40_db_frame_count_and_rate() {
    let v = clip(24, 96, 128);
    let p = tmp("rt.mp4");
    write_mp4(&p, &v, 30.0).unwrap();
    let info = probe(&p).unwrap();
    assert_eq!((info.width, info.height, info.frames), (128, 96, 24));
    assert_eq!(info.fps, 30.0);
    assert_eq!(info.profile, 66, "baseline");
    let back: Video<f32> = read_mp4(&p, None).unwrap();
    let q = psnr(&back, &v).unwrap();
    let worst = q
        .per_frame
        .iter()
        .map(|p| p.unwrap())
        .fold(f64::INFINITY, f64::min);
    eprintln!(
        "round trip: {:.2} dB (worst frame {worst:.2} dB), {} bytes",
        q.whole_video.unwrap(),
        std::fs::metadata(&p).unwrap().len()
    );
    assert!(worst >= 40.0, "worst frame {worst} dB");
    // Decoded values are 8-bit.
    assert!(back
        .data()
        .iter()
        .all(|x| (x * 255.0).round() / 255.0 == *x));
    // The generic reader dispatches on the extension.
    let again: Video<f32> = read_video(&p).unwrap();
    assert_eq!(again.data(), back.data());
    assert!(!PathBuf::from(format!("{}.part", p.display())).exists());
}

#[test]
fn selected_frames_equal_the_full_decode() {
    let v = clip(20, 64, 64);
    let p = tmp("sel.mp4");
    write_mp4(&p, &v, 24.0).unwrap();
    let all: Video<f32> = read_mp4(&p, None).unwrap();
    let some: Video<f32> = read_mp4(&p, Some(&[0, 7, 19])).unwrap();
    assert_eq!(some.frames(), 3);
    for (k, t) in [0, 7, 19].into_iter().enumerate() {
        assert_eq!(some.frame(k), all.frame(t));
    }
    let e = read_mp4::<f32>(&p, Some(&[3, 20])).unwrap_err();
    assert!(
        matches!(e, VideoError::Frames { .. }) && e.to_string().contains("20 frames"),
        "{e}"
    );
    let e = read_mp4::<f32>(&p, Some(&[5, 3])).unwrap_err();
    assert!(e.to_string().contains("increasing"), "{e}");
    assert_eq!(probe(&p).unwrap().fps, 24.0);
}

#[test]
fn odd_sizes_are_padded_and_rates_kept() {
    let v = clip(5, 97, 161);
    let p = tmp("odd.mp4");
    let fps = 1.0 / 0.0417;
    write_mp4(&p, &v, fps).unwrap();
    let info = probe(&p).unwrap();
    assert_eq!((info.width, info.height), (162, 98));
    assert!((info.fps - fps).abs() < 1e-2, "{}", info.fps);
    let back: Video<f32> = read_mp4(&p, None).unwrap();
    let q = psnr(&crop(&back, 97, 161), &v)
        .unwrap()
        .whole_video
        .unwrap();
    assert!(q >= 40.0, "{q} dB");
}

#[test]
fn tiny_frames_are_padded_to_the_encoders_minimum() {
    let v = clip(3, 5, 8);
    let p = tmp("tiny.mp4");
    write_mp4(&p, &v, 12.0).unwrap();
    let info = probe(&p).unwrap();
    assert_eq!((info.width, info.height, info.frames), (16, 16, 3));
}

#[test]
fn writer_refuses_bad_frames_and_rates() {
    let p = tmp("bad.mp4");
    assert!(Mp4Writer::create(&p, 16, 16, 0.0).is_err());
    assert!(Mp4Writer::create(&p, 16, 16, f64::NAN).is_err());
    assert!(matches!(
        Mp4Writer::create(&p, 100_000, 16, 30.0),
        Err(VideoError::Limit { .. })
    ));
    assert!(Mp4Writer::create(&p, 4000, 16, 30.0)
        .unwrap_err()
        .to_string()
        .contains("3840x2160"));
    let mut w = Mp4Writer::create(&p, 16, 16, 30.0).unwrap();
    assert!(w.push(&[0.5; 10]).unwrap_err().to_string().contains("768"));
    let e = w.finish().unwrap_err();
    assert!(e.to_string().contains("no frames"), "{e}");
    assert!(!p.exists());
}

fn find(hay: &[u8], needle: &[u8], from: usize) -> usize {
    from + hay[from..]
        .windows(needle.len())
        .position(|w| w == needle)
        .unwrap()
}

#[test]
fn other_codecs_and_broken_files_are_typed_errors() {
    let v = clip(3, 32, 32);
    let p = tmp("codec.mp4");
    write_mp4(&p, &v, 30.0).unwrap();
    let good = std::fs::read(&p).unwrap();

    // The track's sample entry renamed to HEVC.
    let mut hevc = good.clone();
    let at = find(&hevc, b"avc1", find(&hevc, b"stsd", 0));
    hevc[at..at + 4].copy_from_slice(b"hvc1");
    let q = tmp("hevc.mp4");
    std::fs::write(&q, &hevc).unwrap();
    let e = probe(&q).unwrap_err();
    assert!(
        matches!(&e, VideoError::Codec { codec, .. } if codec == "hvc1"),
        "{e}"
    );
    assert!(
        e.to_string().contains("hevc.mp4") && e.to_string().contains("only H.264"),
        "{e}"
    );

    // Not an MP4 at all.
    std::fs::write(&q, b"\x89PNG\r\n\x1a\n0000000000000000").unwrap();
    let e = probe(&q).unwrap_err();
    assert!(matches!(e, VideoError::Container { .. }), "{e}");

    // Every truncation of the file is an error, never a panic (the first frame's bytes are at
    // the end, so a cut anywhere loses either the tables or a sample).
    for cut in (0..good.len()).step_by(7) {
        std::fs::write(&q, &good[..cut]).unwrap();
        assert!(read_mp4::<f32>(&q, None).is_err(), "cut at {cut}");
    }

    // Corrupt table bytes: an error or a decode, never a panic or a huge allocation.
    let moov = find(&good, b"moov", 0);
    let mdat = find(&good, b"mdat", moov);
    let mut state = 0x9e3779b97f4a7c15u64;
    for _ in 0..400 {
        state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        let i = moov + (state >> 33) as usize % (mdat - moov);
        let mut bad = good.clone();
        bad[i] = (state >> 17) as u8;
        std::fs::write(&q, &bad).unwrap();
        let _ = probe(&q);
    }
}

#[test]
fn corrupt_h264_payloads_are_errors_or_frames_never_crashes() {
    let v = clip(6, 64, 96);
    let p = tmp("payload.mp4");
    write_mp4(&p, &v, 30.0).unwrap();
    let good = std::fs::read(&p).unwrap();
    let mdat = find(&good, b"mdat", 0) + 4;
    let q = tmp("payload_bad.mp4");
    let mut state = 0x2545_f491_4f6c_dd1du64;
    let (mut ok, mut err) = (0, 0);
    for round in 0..300 {
        let mut bad = good.clone();
        // 1 to 8 random bytes of the coded frames changed.
        for _ in 0..1 + round % 8 {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            let i = mdat + (state >> 20) as usize % (good.len() - mdat);
            bad[i] = (state >> 8) as u8;
        }
        std::fs::write(&q, &bad).unwrap();
        match read_mp4::<f32>(&q, None) {
            Ok(v) => {
                assert_eq!(v.frames(), 6);
                assert!(v.data().iter().all(|x| (0.0..=1.0).contains(x)));
                ok += 1;
            }
            Err(_) => err += 1,
        }
    }
    eprintln!("corrupted payloads: {ok} decoded, {err} typed errors");
}

#[test]
fn frame_sizes_from_the_container_are_bounded_before_decoding() {
    // A valid file whose sample entry claims 8192 x 8192 frames: 12 of them as f32 are
    // 9.7 GB, over MAX_DECODED_BYTES, so the read is refused before a frame is decoded or
    // a buffer of that size allocated; the header itself is within MAX_SIDE.
    let v = clip(12, 16, 16);
    let p = tmp("claims_8k.mp4");
    write_mp4(&p, &v, 30.0).unwrap();
    let mut bytes = std::fs::read(&p).unwrap();
    let at = find(&bytes, b"avc1", find(&bytes, b"stsd", 0)) + 4 + 24;
    bytes[at..at + 4].copy_from_slice(&[0x20, 0x00, 0x20, 0x00]);
    std::fs::write(&p, &bytes).unwrap();
    let info = probe(&p).unwrap();
    assert_eq!((info.width, info.height, info.frames), (8192, 8192, 12));
    let e = read_mp4::<f32>(&p, None).unwrap_err();
    assert!(
        matches!(&e, VideoError::Limit { limit, .. } if *limit == r4d_video::MAX_DECODED_BYTES),
        "{e}"
    );
    assert!(e.to_string().contains("claims_8k.mp4"), "{e}");
    // One side over MAX_SIDE is refused from the header.
    bytes[at..at + 2].copy_from_slice(&[0x40, 0x00]);
    std::fs::write(&p, &bytes).unwrap();
    assert!(matches!(probe(&p), Err(VideoError::Limit { .. })));
}
