//! `r4d segment` end to end: files in, parts JSON + scene PLY with `part` + label renders out,
//! and the errors for bad masks.

use r4d_segment::mask::write_label_png;
use r4d_segment::synthetic::{self, accuracy};
use std::path::{Path, PathBuf};
use std::process::Command;

fn r4d(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_r4d"))
        .args(args)
        .output()
        .expect("run r4d")
}

fn tmp(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("r4d_segment_cli_{}_{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// Scene, cameras and label masks of the synthetic scene in `dir`; returns the truth.
fn inputs(dir: &Path) -> Vec<i32> {
    let scene = synthetic::three_parts(5000, 2);
    let cams = synthetic::ring_cameras(6, 160, 120);
    r4d_splat::ply::write_gaussians(&dir.join("scene.ply"), &scene.gaussians).unwrap();
    std::fs::write(
        dir.join("cameras.json"),
        serde_json::to_string(&serde_json::json!({ "cameras": cams })).unwrap(),
    )
    .unwrap();
    let masks = dir.join("masks");
    std::fs::create_dir_all(&masks).unwrap();
    std::fs::write(
        masks.join("classes.json"),
        r#"{"class_names": ["box", "ball", "post"]}"#,
    )
    .unwrap();
    for c in &cams {
        // Named after the camera's image: view_00.png, ...
        write_label_png(
            &masks.join(&c.name),
            c.width,
            c.height,
            &scene.label_mask(c),
        )
        .unwrap();
    }
    scene.truth
}

fn args(d: &Path, out: &str) -> Vec<String> {
    [
        "segment",
        "--scene",
        &d.join("scene.ply").display().to_string(),
        "--cameras",
        &d.join("cameras.json").display().to_string(),
        "--masks",
        &d.join("masks").display().to_string(),
        "--out",
        &d.join(out).display().to_string(),
    ]
    .iter()
    .map(|s| s.to_string())
    .collect()
}

fn run(a: &[String]) -> std::process::Output {
    let refs: Vec<&str> = a.iter().map(String::as_str).collect();
    r4d(&refs)
}

#[test]
fn segment_writes_parts_scene_and_views() {
    let d = tmp("ok");
    let truth = inputs(&d);
    let mut a = args(&d, "out/parts.json");
    a.extend(["--k".into(), "16".into()]);
    let o = run(&a);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let text = std::fs::read_to_string(d.join("out/parts.json")).unwrap();
    let v: serde_json::Value = serde_json::from_str(&text).unwrap();
    let keys: Vec<&String> = v.as_object().unwrap().keys().collect();
    assert_eq!(keys.len(), 5, "exactly the contract's keys: {keys:?}");
    assert_eq!(v["num_parts"], 3);
    assert_eq!(v["class_names"], serde_json::json!(["box", "ball", "post"]));
    let labels: Vec<i32> = serde_json::from_value(v["labels"].clone()).unwrap();
    let conf: Vec<f32> = serde_json::from_value(v["confidence"].clone()).unwrap();
    let counts: Vec<usize> = serde_json::from_value(v["counts"].clone()).unwrap();
    assert_eq!(labels.len(), truth.len());
    assert_eq!(conf.len(), truth.len());
    assert!(conf.iter().all(|c| (0.0..=1.0).contains(c)));
    for (k, &c) in counts.iter().enumerate() {
        assert_eq!(c, labels.iter().filter(|&&l| l == k as i32).count());
    }
    let acc = accuracy(&labels, &truth);
    assert!(acc > 0.97, "{acc}");
    // The fit reads both files.
    let from_json = resonance4d::video_fit::PartLabels::load(&d.join("out/parts.json")).unwrap();
    assert_eq!(from_json.labels, labels);
    let from_ply = resonance4d::video_fit::PartLabels::load(&d.join("out/parts.ply")).unwrap();
    assert_eq!(from_ply.labels, labels);
    assert_eq!(from_ply.num_parts, 3);
    // The PLY is the scene plus `part`.
    let scene = r4d_splat::ply::read_gaussians(&d.join("out/parts.ply")).unwrap();
    let orig = r4d_splat::ply::read_gaussians(&d.join("scene.ply")).unwrap();
    assert_eq!(scene, orig);
    // One render per camera: labels | mask | disagreement (black where they agree: almost
    // everywhere with clean masks).
    for v in 0..6 {
        let p = d.join(format!("out/parts_views/view_{v:04}.png"));
        let img = image::open(&p).unwrap().to_rgb8();
        assert_eq!((img.width(), img.height()), (480, 120), "{}", p.display());
        let black = (320..480)
            .flat_map(|i| (0..120).map(move |j| (i, j)))
            .filter(|&(i, j)| img.get_pixel(i, j).0 == [0, 0, 0])
            .count();
        assert!(
            black as f64 > 0.95 * 160.0 * 120.0,
            "{black} agreeing pixels"
        );
    }
}

#[test]
fn segment_bad_masks_name_the_file() {
    let d = tmp("bad");
    inputs(&d);
    let masks = d.join("masks");
    // A view without a mask.
    std::fs::rename(masks.join("view_03.png"), d.join("away.png")).unwrap();
    let o = run(&args(&d, "parts.json"));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success());
    assert!(
        err.contains("no mask for camera 3") && err.contains("view_03.png"),
        "{err}"
    );
    // A mask of another size.
    write_label_png(&masks.join("view_03.png"), 80, 60, &vec![0; 4800]).unwrap();
    let o = run(&args(&d, "parts.json"));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success());
    assert!(
        err.contains("view_03.png") && err.contains("80x60") && err.contains("160x120"),
        "{err}"
    );
    // A label naming no class.
    let mut l = vec![0u16; 160 * 120];
    l[160 * 60 + 80] = 4;
    write_label_png(&masks.join("view_03.png"), 160, 120, &l).unwrap();
    let o = run(&args(&d, "parts.json"));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success());
    assert!(
        err.contains("view_03.png") && err.contains("label 4") && err.contains("(80, 60)"),
        "{err}"
    );
    assert!(!d.join("parts.json").exists());
    // Region prior and appearance settings out of range: named before any work.
    for (flag, v) in [
        ("--region-tau", "-1"),
        ("--region-power", "NaN"),
        ("--region-power", "100"),
        ("--region-static-power", "-2"),
        ("--region-static-power", "65"),
        ("--appearance", "1.5"),
        ("--appearance", "-0.1"),
        ("--appearance", "inf"),
    ] {
        let mut a = args(&d, "parts.json");
        a.push(format!("{flag}={v}"));
        let o = run(&a);
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success());
        assert!(err.contains(flag), "{flag} {v}: {err}");
    }
    // --out must be the JSON file.
    let o = run(&args(&d, "parts.ply"));
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("JSON"));
}
