//! MP4 on the command line: `r4d metrics` reads MP4 and converts frame rates (`--fps`).

use std::path::PathBuf;
use std::process::Command;

fn tmp(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("r4d_video_cli_{name}_{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn r4d(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_r4d"))
        .args(args)
        .output()
        .expect("run r4d")
}

/// A smooth moving blob, 12 frames of 64 x 96.
fn clip() -> r4d_loss::Video<f32> {
    let (h, w) = (64, 96);
    r4d_loss::Video::from_frames(
        h,
        w,
        (0..12).map(|t| {
            let mut f = vec![0f32; h * w * 3];
            for y in 0..h {
                for x in 0..w {
                    let dx = x as f32 - 20.0 - 4.0 * t as f32;
                    let dy = y as f32 - 32.0;
                    let a = (-(dx * dx + dy * dy) / 120.0).exp();
                    let c = [0.2 + 0.7 * a, 0.3 + 0.2 * a, 0.5 - 0.3 * a];
                    f[(y * w + x) * 3..][..3].copy_from_slice(&c);
                }
            }
            f
        }),
    )
    .unwrap()
}

fn metrics_json(args: &[&str]) -> serde_json::Value {
    let mut all = vec!["metrics", "--json"];
    all.extend_from_slice(args);
    let out = r4d(&all);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).unwrap()
}

#[test]
fn metrics_reads_mp4_and_converts_frame_rates() {
    let d = tmp("metrics");
    let v = clip();
    let frames = d.join("frames");
    r4d_loss::io::write_png_dir(&frames, &v).unwrap();
    let mp4 = d.join("clip.mp4");
    r4d_video::write_mp4(&mp4, &v, 30.0).unwrap();
    let (m, f) = (mp4.to_str().unwrap(), frames.to_str().unwrap());

    let j = metrics_json(&["--reference", m, "--rendered", f]);
    assert_eq!(j["frames"], 12);
    assert!(j["psnr"].as_f64().unwrap() >= 40.0, "{j}");

    // At 15 fps both become every other frame.
    let j = metrics_json(&[
        "--reference",
        m,
        "--rendered",
        f,
        "--fps",
        "15",
        "--rendered-fps",
        "30",
    ]);
    assert_eq!(j["frames"], 6);

    // The frame folder has no rate of its own.
    let out = r4d(&["metrics", "--reference", m, "--rendered", f, "--fps", "15"]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("--rendered-fps"), "{err}");

    // Known, different rates without --fps: refused with the way out.
    let out = r4d(&[
        "metrics",
        "--reference",
        m,
        "--rendered",
        f,
        "--rendered-fps",
        "25",
    ]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("--fps"), "{err}");
    let out = r4d(&["metrics", "--reference", m, "--rendered", f, "--fps", "0"]);
    assert!(!out.status.success());
}
