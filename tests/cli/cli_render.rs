//! `r4d render` and `r4d prepare`: raw output against the gsplat golden, the simulation link
//! end to end (prepare -> simulate -> render), sequences, and errors.

use crate::common;

use common::{fixture, parse_npy, read_npy};
use std::path::PathBuf;
use std::process::Command;

fn r4d(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_r4d"))
        .args(args)
        .output()
        .unwrap()
}

fn out_dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("r4d_cli_render_{}_{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn s(p: &std::path::Path) -> String {
    p.display().to_string()
}

fn ok(o: &std::process::Output) {
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
}

#[test]
fn render_writes_png_and_raw_npy_matching_gsplat() {
    let d = out_dir("single");
    let f = fixture("splat/sh3_shell_bg");
    ok(&r4d(&[
        "render",
        "--scene",
        &s(&f.join("scene.ply")),
        "--camera",
        &s(&f.join("cameras.json")),
        "--camera-index",
        "1",
        "--out",
        &s(&d.join("img.png")),
        "--out-raw",
        &s(&d.join("img.npy")),
    ]));
    let raw = read_npy(&d.join("img.npy"));
    let want = read_npy(&f.join("cam1_rgb.npy"));
    assert_eq!(raw.shape, want.shape);
    let mean: f64 = raw
        .data
        .iter()
        .zip(&want.data)
        .map(|(a, b)| (a - b).abs())
        .sum::<f64>()
        / raw.data.len() as f64;
    assert!(mean < 1e-5, "mean abs error {mean}");
    let png = std::fs::read(d.join("img.png")).unwrap();
    assert_eq!(&png[1..4], b"PNG");
    // A camera index past the file is a clear error.
    let o = r4d(&[
        "render",
        "--scene",
        &s(&f.join("scene.ply")),
        "--camera",
        &s(&f.join("cameras.json")),
        "--camera-index",
        "7",
        "--out",
        &s(&d.join("x.png")),
    ]);
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("camera index 7"));
}

/// The wgpu backend writes the same image as the CPU.
#[test]
#[cfg_attr(
    not(r4d_gpu),
    ignore = "no GPU adapter expected here (no Vulkan driver found at build time): install mesa-vulkan-drivers libvulkan1, or build with R4D_REQUIRE_GPU=1"
)]
fn render_on_wgpu_writes_the_cpus_image() {
    let d = out_dir("single_wgpu");
    let f = fixture("splat/sh3_shell_bg");
    let render = |backend: &str, name: &str| {
        ok(&r4d(&[
            "render",
            "--scene",
            &s(&f.join("scene.ply")),
            "--camera",
            &s(&f.join("cameras.json")),
            "--camera-index",
            "1",
            "--out",
            &s(&d.join(format!("{name}.png"))),
            "--out-raw",
            &s(&d.join(format!("{name}.npy"))),
            "--backend",
            backend,
        ]));
        read_npy(&d.join(format!("{name}.npy")))
    };
    let raw = render("cpu", "cpu");
    let gpu = render("wgpu", "gpu");
    let m: f64 = gpu
        .data
        .iter()
        .zip(&raw.data)
        .map(|(a, b)| (a - b).abs())
        .sum::<f64>()
        / raw.data.len() as f64;
    assert!(m < 1e-5, "wgpu vs cpu mean abs error {m}");
}

#[test]
fn prepare_simulate_render_round_trip() {
    let d = out_dir("link");
    let f = fixture("splat/sh0_basic");
    let cfg = d.join("pg.json");
    // Rotation about x, a crop that leaves part of the scene static, normalisation to a
    // region of 0.8 around (1, 1, 1) in a 2 m domain.
    std::fs::write(
        &cfg,
        r#"{"material": "jelly", "E": 2e5, "nu": 0.3, "density": 1000.0, "g": [0.0, 0.0, -9.8],
            "grid_lim": 2.0, "n_grid": 32, "substep_dt": 1e-4, "frame_dt": 0.01, "frame_num": 3,
            "boundary_conditions": [{"type": "bounding_box"}],
            "opacity_threshold": 0.05, "rotation_degree": [90.0], "rotation_axis": [0],
            "sim_area": [-2.0, 2.0, -2.0, 2.0, -2.0, 0.2], "scale": 0.8}"#,
    )
    .unwrap();
    let prep = d.join("prep");
    ok(&r4d(&[
        "prepare",
        "--scene",
        &s(&f.join("scene.ply")),
        "--config",
        &s(&cfg),
        "--out",
        &s(&prep),
    ]));
    let link: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(prep.join("link.json")).unwrap()).unwrap();
    let simulated = link["simulated"].as_array().unwrap().len();
    let kept = link["scene_gaussians"].as_u64().unwrap() as usize;
    assert!(simulated > 100 && simulated < kept, "{simulated} of {kept}");
    let sim = d.join("sim");
    ok(&r4d(&[
        "simulate",
        "--config",
        &s(&cfg),
        "--physgaussian",
        "--particles",
        &s(&prep.join("particles.ply")),
        "--out",
        &s(&sim),
        "--write-f",
    ]));
    let cams = s(&f.join("cameras.json"));
    let render = |extra: &[&str], name: &str| {
        let mut a = vec![
            "render",
            "--scene",
            &*Box::leak(s(&prep.join("scene.ply")).into_boxed_str()),
            "--camera",
            &cams,
            "--out",
        ];
        let png = s(&d.join(format!("{name}.png")));
        let npy = s(&d.join(format!("{name}.npy")));
        a.push(Box::leak(png.into_boxed_str()));
        a.push("--out-raw");
        a.push(Box::leak(npy.clone().into_boxed_str()));
        a.extend_from_slice(extra);
        ok(&r4d(&a));
        parse_npy(&std::fs::read(npy).unwrap()).data
    };
    let rest = render(&[], "rest");
    // Frame 0 is the initial state: mapped back through the link it renders the scene.
    let f0 = s(&sim.join("frame_0000.ply"));
    let link_s = s(&prep.join("link.json"));
    let frame0 = render(&["--frame", &f0, "--link", &link_s], "frame0");
    let max0 = rest
        .iter()
        .zip(&frame0)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max);
    assert!(max0 < 1e-4, "frame 0 differs from the scene by {max0}");
    // After three frames of falling, the simulated part has moved.
    let f3 = s(&sim.join("frame_0003.ply"));
    let frame3 = render(&["--frame", &f3, "--link", &link_s], "frame3");
    let max3 = rest
        .iter()
        .zip(&frame3)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max);
    assert!(max3 > 1e-2, "frame 3 equals the rest scene ({max3})");
    // Without the link the particle count does not match the scene: a clear error.
    let o = r4d(&[
        "render",
        "--scene",
        &s(&prep.join("scene.ply")),
        "--camera",
        &cams,
        "--frame",
        &f3,
        "--out",
        &s(&d.join("bad.png")),
    ]);
    assert!(!o.status.success());
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(
        e.contains("frame_0003.ply") && e.contains("particles"),
        "{e}"
    );
    // The whole sequence.
    let seq = d.join("seq");
    ok(&r4d(&[
        "render",
        "--scene",
        &s(&prep.join("scene.ply")),
        "--camera",
        &cams,
        "--frames",
        &s(&sim),
        "--link",
        &link_s,
        "--out",
        &s(&seq),
    ]));
    for k in 0..4 {
        assert!(seq.join(format!("frame_{k:04}.png")).exists());
    }
    let gif = std::fs::read(seq.join("animation.gif")).unwrap();
    assert_eq!(&gif[..3], b"GIF");
}
