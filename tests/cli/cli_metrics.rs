//! `r4d metrics`: videos as PNG directories (8-bit, as `r4d render --frames` writes them) and
//! float32 `.npy`, against the loss goldens (`tests/fixtures/loss/`), and its errors.

use crate::common;

use common::fixture;
use r4d_loss::io::{write_npy, write_png_dir};
use r4d_loss::Video;
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::Command;

fn r4d(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_r4d"))
        .args(args)
        .env_remove("R4D_LPIPS_DIR")
        .output()
        .unwrap()
}

fn out_dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("r4d_cli_metrics_{}_{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn s(p: &Path) -> String {
    p.display().to_string()
}

fn golden(name: &str) -> Value {
    let g: Value =
        serde_json::from_str(&std::fs::read_to_string(fixture("loss/goldens.json")).unwrap())
            .unwrap();
    g["cases"]
        .as_array()
        .unwrap()
        .iter()
        .find(|c| c["name"] == name)
        .unwrap()
        .clone()
}

use common::loss_case_video as video;

fn metrics_json(reference: &Path, rendered: &Path) -> Value {
    let o = r4d(&[
        "metrics",
        "--reference",
        &s(reference),
        "--rendered",
        &s(rendered),
        "--json",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    serde_json::from_slice(&o.stdout).unwrap()
}

fn close(got: &Value, want: &Value, rtol: f64, what: &str) {
    let (g, w) = (got.as_f64().unwrap(), want.as_f64().unwrap());
    assert!(
        (g - w).abs() <= rtol * w.abs().max(1e-3),
        "{what}: got {g}, want {w}"
    );
}

#[test]
fn png_frame_directories_match_the_goldens() {
    // Case 2: 8-bit frames, 16 x 64 x 64; written exactly as PNG, with the GIF that
    // `r4d render --frames` writes beside them (ignored).
    let file = "case2_blobs_freq_2.0Hz_vs_3.0Hz.npz";
    let d = out_dir("png");
    let (rd, gd) = (d.join("rendered"), d.join("reference"));
    write_png_dir(&rd, &video(file, "rendered")).unwrap();
    write_png_dir(&gd, &video(file, "reference")).unwrap();
    std::fs::write(rd.join("animation.gif"), b"GIF89a").unwrap();
    let j = metrics_json(&gd, &rd);
    let g = golden("blobs_freq_2.0Hz_vs_3.0Hz");
    // The values k / 255 are stored as f32 (relative rounding 3e-8).
    close(&j["psnr"], &g["psnr_mean_of_frames"], 1e-6, "psnr");
    close(&j["psnr_video"], &g["psnr_whole_video"], 1e-6, "psnr_video");
    close(&j["ssim"], &g["ssim_pm"], 1e-6, "ssim");
    close(&j["l1"], &g["l1"], 1e-6, "l1");
    close(&j["dms_spatial"], &g["L_spatial"], 1e-5, "dms_spatial");
    close(&j["dms_mag"], &g["L_mag"], 1e-6, "dms_mag");
    close(&j["dms_phase"], &g["L_phase"], 1e-6, "dms_phase");
    close(&j["dms"], &g["L_DMS"], 1e-6, "dms");
    assert!(j["ms_ssim"].is_null());
    assert_eq!(j["ms_ssim_small_window"]["window"], 3);
    close(
        &j["ms_ssim_small_window"]["value"],
        &g["ms_ssim_small_win"]["value"],
        1e-6,
        "ms_ssim_small_window",
    );
    assert_eq!(j["frames"], 16);
    assert!(j["lpips"].is_null());
    // The table names every metric.
    let o = r4d(&["metrics", "--reference", &s(&gd), "--rendered", &s(&rd)]);
    assert!(o.status.success());
    let out = String::from_utf8_lossy(&o.stdout);
    for k in ["PSNR", "SSIM", "MS-SSIM", "L1", "DMS", "LPIPS"] {
        assert!(out.contains(k), "{k} missing from:\n{out}");
    }
}

#[test]
fn npy_videos_and_mixed_formats_match_the_goldens() {
    // Case 6 (192 x 192: standard MS-SSIM): reference as PNG frames, rendered as .npy.
    let file = "case6_large_uint8_blobs_2.0Hz_vs_2.5Hz.npz";
    let d = out_dir("npy");
    write_png_dir(&d.join("ref"), &video(file, "reference")).unwrap();
    write_npy(&d.join("rendered.npy"), &video(file, "rendered")).unwrap();
    let j = metrics_json(&d.join("ref"), &d.join("rendered.npy"));
    let g = golden("large_uint8_blobs_2.0Hz_vs_2.5Hz");
    close(&j["ms_ssim"], &g["ms_ssim"], 1e-6, "ms_ssim");
    close(&j["ssim"], &g["ssim_pm"], 1e-6, "ssim");
    close(&j["dms_phase"], &g["L_phase"], 1e-6, "dms_phase");
    assert!(j["ms_ssim_small_window"].is_null());
    // Case 7: float32 .npy both, 6 x 32 x 48.
    let file = "case7_small_perturbed.npz";
    write_npy(&d.join("a.npy"), &video(file, "reference")).unwrap();
    write_npy(&d.join("b.npy"), &video(file, "rendered")).unwrap();
    let j = metrics_json(&d.join("a.npy"), &d.join("b.npy"));
    let g = golden("small_perturbed");
    for (k, gk) in [
        ("psnr", "psnr_mean_of_frames"),
        ("psnr_video", "psnr_whole_video"),
        ("l1", "l1"),
        ("ssim", "ssim_pm"),
        ("dms_spatial", "L_spatial"),
        ("dms_mag", "L_mag"),
        ("dms_phase", "L_phase"),
        ("dms", "L_DMS"),
    ] {
        close(&j[k], &g[gk], 1e-8, k);
    }
    assert!(j["ms_ssim"].is_null() && j["ms_ssim_small_window"].is_null());
}

#[test]
fn identical_videos_have_null_psnr() {
    let file = "case3_identical.npz";
    let d = out_dir("identical");
    write_npy(&d.join("a.npy"), &video(file, "reference")).unwrap();
    let j = metrics_json(&d.join("a.npy"), &d.join("a.npy"));
    assert!(j["psnr"].is_null() && j["psnr_video"].is_null());
    assert_eq!(j["l1"], 0.0);
    assert_eq!(j["ssim"], 1.0);
}

#[test]
fn bad_input_exits_nonzero_naming_the_input() {
    let d = out_dir("bad");
    let file = "case7_small_perturbed.npz";
    let v = video(file, "reference");
    write_npy(&d.join("a.npy"), &v).unwrap();
    // Fewer frames.
    let short = Video::new(5, 32, 48, v.data()[..5 * 32 * 48 * 3].to_vec()).unwrap();
    write_npy(&d.join("short.npy"), &short).unwrap();
    let o = r4d(&[
        "metrics",
        "--reference",
        &s(&d.join("a.npy")),
        "--rendered",
        &s(&d.join("short.npy")),
    ]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success());
    assert!(
        err.contains("reference has 6 frames, rendered has 5"),
        "{err}"
    );
    assert!(err.contains("short.npy"), "{err}");
    // NaN.
    let mut nan = v.clone();
    nan.data_mut()[((2 * 32 + 1) * 48 + 4) * 3] = f32::NAN;
    write_npy(&d.join("nan.npy"), &nan).unwrap();
    let o = r4d(&[
        "metrics",
        "--reference",
        &s(&d.join("a.npy")),
        "--rendered",
        &s(&d.join("nan.npy")),
    ]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success());
    assert!(
        err.contains("nan.npy") && err.contains("NaN at frame 2, row 1, column 4"),
        "{err}"
    );
    // Missing file, and a directory without PNG frames.
    let o = r4d(&[
        "metrics",
        "--reference",
        &s(&d.join("missing.npy")),
        "--rendered",
        &s(&d.join("a.npy")),
    ]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && err.contains("missing.npy"), "{err}");
    std::fs::create_dir_all(d.join("empty")).unwrap();
    let o = r4d(&[
        "metrics",
        "--reference",
        &s(&d.join("a.npy")),
        "--rendered",
        &s(&d.join("empty")),
    ]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        !o.status.success() && err.contains("no .png frames"),
        "{err}"
    );
}

#[test]
fn single_frame_videos_report_image_metrics_and_null_dms_terms() {
    let file = "case7_small_perturbed.npz";
    let d = out_dir("single");
    let (a, b) = (video(file, "reference"), video(file, "rendered"));
    let one = |v: &Video<f32>| Video::new(1, 32, 48, v.frame(0).to_vec()).unwrap();
    write_npy(&d.join("a.npy"), &one(&a)).unwrap();
    write_npy(&d.join("b.npy"), &one(&b)).unwrap();
    let j = metrics_json(&d.join("a.npy"), &d.join("b.npy"));
    assert!(j["psnr"].as_f64().unwrap() > 0.0);
    assert!(j["ssim"].as_f64().is_some() && j["dms_spatial"].as_f64().is_some());
    assert!(j["dms_mag"].is_null() && j["dms_phase"].is_null() && j["dms"].is_null());
}

#[test]
fn metrics_trajectory_compares_simulated_sequences() {
    let a = out_dir("traj_a");
    let b = out_dir("traj_b");
    let cfg = Path::new(env!("CARGO_MANIFEST_DIR")).join("configs/jelly_drop.toml");
    for (dir, frames) in [(&a, "3"), (&b, "2")] {
        let o = r4d(&[
            "simulate",
            "--config",
            &s(&cfg),
            "--out",
            &s(dir),
            "--frames",
            frames,
        ]);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    }
    // A sequence against itself: zero distances, perfect F-score.
    let o = r4d(&[
        "metrics-trajectory",
        "--reference",
        &s(&a),
        "--simulated",
        &s(&a),
        "--json",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let v: Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(v["cd"], 0.0);
    assert_eq!(v["hd95"], 0.0);
    assert_eq!(v["fscore"], 1.0);
    assert_eq!(v["frames"], 4);
    assert_eq!(v["defaults"]["cd"], "cd_sq_sum");
    // Sequences of different lengths are refused with a message naming the frame counts.
    let o = r4d(&[
        "metrics-trajectory",
        "--reference",
        &s(&a),
        "--simulated",
        &s(&b),
    ]);
    assert!(!o.status.success());
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(e.contains("frames"), "{e}");
}
