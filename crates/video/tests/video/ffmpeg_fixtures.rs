//! MP4 files written by another project's code (ffmpeg; `scripts/make_video_fixtures.sh`):
//! H.264 High profile with B-frames and an audio track, decoded and compared with ffmpeg's own
//! decode; a constrained-baseline file at 30000/1001 fps; and HEVC, MPEG-4 part 2 and
//! fragmented files, which must be typed errors that say what they are. Also, where ffmpeg is
//! installed, ffmpeg's decode of a file we wrote (skipped, and said so, where it is not).

use r4d_loss::metrics::psnr;
use r4d_loss::Video;
use r4d_video::{probe, read_mp4, write_mp4, VideoError};
use std::path::{Path, PathBuf};

fn fixture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures")
        .join(name)
}

#[test]
fn high_profile_with_b_frames_matches_ffmpegs_decode() {
    let p = fixture("x264_high_bframes.mp4");
    let info = probe(&p).unwrap();
    assert_eq!((info.width, info.height, info.frames), (160, 96, 12));
    assert!((info.fps - 25.0).abs() < 1e-9, "{}", info.fps);
    assert_eq!(info.profile, 100, "High profile");
    let ours: Video<f32> = read_mp4(&p, None).unwrap();
    let theirs: Video<f32> = r4d_loss::io::read_video(&fixture("x264_high_bframes")).unwrap();
    assert_eq!(theirs.frames(), 12);
    // Same frames in the same (display) order; the only differences are the YUV->RGB
    // conversions' chroma interpolation and rounding.
    let q = psnr(&ours, &theirs).unwrap();
    let worst = q
        .per_frame
        .iter()
        .map(|p| p.unwrap_or(f64::INFINITY))
        .fold(f64::INFINITY, f64::min);
    eprintln!("worst frame vs ffmpeg {worst:.2} dB");
    assert!(
        worst >= 45.0,
        "worst frame vs ffmpeg {worst:.2} dB (per frame {:?})",
        q.per_frame
    );
    // Frame t matches ffmpeg's frame t better than any other frame (display order).
    for t in 0..12 {
        let d = |u: usize| -> f64 {
            ours.frame(t)
                .iter()
                .zip(theirs.frame(u))
                .map(|(a, b)| ((a - b) as f64).powi(2))
                .sum()
        };
        let best = (0..12).min_by(|&a, &b| d(a).total_cmp(&d(b))).unwrap();
        assert_eq!(best, t, "frame {t} looks most like ffmpeg's frame {best}");
    }
}

#[test]
fn baseline_at_ntsc_rate() {
    let p = fixture("x264_baseline_30fps.mp4");
    let info = probe(&p).unwrap();
    assert_eq!((info.width, info.height, info.frames), (96, 64, 9));
    assert!((info.fps - 30000.0 / 1001.0).abs() < 1e-6, "{}", info.fps);
    let v: Video<f32> = read_mp4(&p, Some(&[0, 8])).unwrap();
    assert_eq!(v.frames(), 2);
}

#[test]
fn other_codecs_and_fragmented_files_say_what_they_are() {
    for (name, codec) in [("hevc.mp4", "hvc1"), ("mpeg4.mp4", "mp4v")] {
        let e = probe(&fixture(name)).unwrap_err();
        match &e {
            VideoError::Codec { codec: c, .. } => assert_eq!(c, codec),
            other => panic!("{name}: {other}"),
        }
        assert!(e.to_string().contains(name), "{e}");
    }
    let e = probe(&fixture("fragmented.mp4")).unwrap_err();
    assert!(e.to_string().contains("fragmented"), "{e}");
}

#[test]
fn ffmpeg_decodes_what_we_write() {
    let ok = std::process::Command::new("ffmpeg")
        .arg("-version")
        .output()
        .is_ok_and(|o| o.status.success());
    if !ok {
        eprintln!("SKIPPED ffmpeg_decodes_what_we_write: no ffmpeg on PATH (the cross-check needs it; the round trip through our own decoder is in tests/video/mp4.rs)");
        return;
    }
    let src: Video<f32> = r4d_loss::io::read_video(&fixture("x264_high_bframes")).unwrap();
    let dir = std::env::temp_dir().join(format!("r4d-ffmpeg-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let mp4 = dir.join("ours.mp4");
    write_mp4(&mp4, &src, 25.0).unwrap();
    let frames = dir.join("frames");
    std::fs::create_dir_all(&frames).unwrap();
    let st = std::process::Command::new("ffmpeg")
        .args(["-hide_banner", "-loglevel", "error", "-y", "-i"])
        .arg(&mp4)
        .args(["-pix_fmt", "rgb24"])
        .arg(frames.join("f_%03d.png"))
        .status()
        .unwrap();
    assert!(st.success(), "ffmpeg could not decode our MP4");
    let back: Video<f32> = r4d_loss::io::read_video(&frames).unwrap();
    assert_eq!(back.frames(), src.frames(), "ffmpeg sees every frame");
    let q = psnr(&back, &src).unwrap().whole_video.unwrap();
    eprintln!("ffmpeg's decode of our MP4: {q:.2} dB");
    assert!(q >= 35.0, "{q} dB");
    let _ = std::fs::remove_dir_all(&dir);
}
