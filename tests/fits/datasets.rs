//! Dataset loaders on the fixtures of `scripts/make_dataset_fixtures.py`, whose
//! `expected.json` holds what an independent implementation of each layout's conventions (the
//! script's) says: counts, the moving-part rule, unit scaling, PhysFlow's normalisation, and
//! the pixel coordinates of known points in every camera convention. Then `dataset inspect
//! --json`, typed errors, and a multi-view fit from a dataset folder.

use crate::common;

use r4d_datasets::{load, Dataset, LoadOptions};
use std::path::{Path, PathBuf};
use std::process::Command;

fn ds_fixture(rel: &str) -> PathBuf {
    common::fixture("datasets").join(rel)
}

const PHYSFLOW: &str = "physflow/model/phys_dreamer/toyphone";
const PACNERF: &str = "pacnerf/toyball";
const PHYSDREAMER: &str = "physdreamer/toyplant";
const PHYSDREAMER_COLMAP: &str = "physdreamer/toyplant_colmap";

fn expected(dir: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(dir.join("expected.json")).unwrap()).unwrap()
}

pub(crate) fn tmp(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("r4d_datasets_{name}_{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

pub(crate) fn r4d(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_r4d"))
        .args(args)
        .output()
        .expect("run r4d")
}

/// Projects `p` through a loaded camera (the renderer's convention: OpenCV axes, `u = fx x / z
/// + cx` with pixel centres at +0.5).
fn project(ds: &Dataset, camera: &str, p: [f64; 3]) -> [f64; 2] {
    let cam = ds
        .cameras
        .iter()
        .find(|c| c.name == camera)
        .unwrap_or_else(|| panic!("no camera {camera}"));
    let r = cam.rotation();
    let t = cam.translation();
    let q: [f64; 3] = [0, 1, 2].map(|i| r[i][0] * p[0] + r[i][1] * p[1] + r[i][2] * p[2] + t[i]);
    [cam.fx * q[0] / q[2] + cam.cx, cam.fy * q[1] / q[2] + cam.cy]
}

fn check_projections(ds: &Dataset, exp: &serde_json::Value) {
    let list = exp["projections"].as_array().unwrap();
    assert!(!list.is_empty());
    for e in list {
        let p: Vec<f64> = serde_json::from_value(e["point"].clone()).unwrap();
        let want: Vec<f64> = serde_json::from_value(e["pixel"].clone()).unwrap();
        let got = project(ds, e["camera"].as_str().unwrap(), [p[0], p[1], p[2]]);
        for a in 0..2 {
            assert!(
                (got[a] - want[a]).abs() < 1e-6,
                "{}: camera {} point {p:?}: pixel {got:?}, the layout's convention says {want:?}",
                ds.dir.display(),
                e["camera"]
            );
        }
    }
}

fn check_counts(ds: &Dataset, exp: &serde_json::Value) {
    assert_eq!(ds.layout.name(), exp["layout"].as_str().unwrap());
    assert_eq!(
        ds.gaussians_in_file as u64,
        exp["gaussians_in_file"].as_u64().unwrap()
    );
    assert_eq!(
        ds.particles.len() as u64,
        exp["simulated_particles"].as_u64().unwrap()
    );
    assert_eq!(
        ds.static_gaussians() as u64,
        exp["static_gaussians"].as_u64().unwrap()
    );
    let v = &ds.views[0].video;
    assert_eq!(v.frames as u64, exp["video_frames"].as_u64().unwrap());
    assert!(
        (v.fps - exp["fps"].as_f64().unwrap()).abs() < 1e-9,
        "fps {}",
        v.fps
    );
}

#[test]
fn physflow_release_is_read_as_physflow_reads_it() {
    let dir = ds_fixture(PHYSFLOW);
    let exp = expected(&dir);
    let ds = load(&dir, &LoadOptions::default()).unwrap();
    check_counts(&ds, &exp);
    // The largest point_cloud/iteration_N is taken (iteration_30 holds 10 Gaussians).
    assert!(ds.gaussian_file.ends_with("iteration_7000/point_cloud.ply"));
    assert_eq!(
        ds.gaussians_after_opacity_filter as u64,
        exp["gaussians_after_opacity_filter"].as_u64().unwrap()
    );
    // The config was found where PhysFlow's repository keeps it: <root>/config/<dataset>/.
    assert!(ds
        .config_file
        .as_ref()
        .unwrap()
        .ends_with("config/phys_dreamer/toyphone_config.json"));
    // Unit scaling: E x 1e7; density as written.
    let p = &ds.config.parts[0];
    assert!((p.youngs_modulus_pa - exp["E_Pa"].as_f64().unwrap()).abs() < 1e-6);
    assert_eq!(p.density_kg_m3, exp["density_kg_m3"].as_f64().unwrap());
    assert_eq!(
        ds.config.time.substeps() as u64,
        exp["substeps_per_frame"].as_u64().unwrap()
    );
    // Normalisation (PhysFlow's pre-rotation, bounding-box centre, largest side, (1, 1, 1)).
    let n = &exp["normalisation"];
    let rot: Vec<Vec<f64>> = serde_json::from_value(n["rotation"].clone()).unwrap();
    for i in 0..3 {
        for j in 0..3 {
            // PhysFlow's rotation uses pi = 3.1415926: entries agree to ~3e-8.
            assert!(
                (ds.link.rotation[i][j] - rot[i][j]).abs() < 1e-7,
                "rotation {i}{j}"
            );
        }
    }
    let mean: Vec<f64> = serde_json::from_value(n["mean"].clone()).unwrap();
    for a in 0..3 {
        assert!((ds.link.centre[a] - mean[a]).abs() < 1e-6, "mean {a}");
    }
    let scale = n["scale"].as_f64().unwrap();
    assert!(
        (ds.link.scale / scale - 1.0).abs() < 1e-6,
        "scale {} vs {scale}",
        ds.link.scale
    );
    assert_eq!(ds.link.shift, [1.0; 3]);
    // ... and its inverse: every particle maps back onto its Gaussian.
    for (s, &g) in ds.link.simulated.iter().enumerate() {
        let x = ds.particles.x[s].map(|v| v as f64);
        let w = ds.link.to_world(x);
        let m = ds.scene.means[g as usize];
        for a in 0..3 {
            assert!(
                (w[a] - m[a] as f64).abs() < 1e-6,
                "particle {s}: {w:?} vs {m:?}"
            );
        }
        // Inside the simulation box, centred at (1, 1, 1).
        assert!(x.iter().all(|&v| v > 0.4 && v < 1.6), "{x:?}");
    }
    // inpaint_points.ply: two more static Gaussians at the end of the scene.
    assert_eq!(ds.scene.len(), ds.gaussians_after_opacity_filter + 2);
    assert_eq!(ds.background, [1.0; 3]);
    assert_eq!(ds.ground_truth.point_clouds.len(), 2);
    check_projections(&ds, &exp);
}

#[test]
fn physflow_moving_part_rule_is_strict_at_half_a_cell() {
    let dir = ds_fixture(PHYSFLOW);
    let ds = load(&dir, &LoadOptions::default()).unwrap();
    // The fixture puts one Gaussian at 0.98 x (0.5 / n_grid) from the moving part (simulated)
    // and one at 1.02 x (static): they are the last two of the file.
    let n = ds.gaussians_in_file;
    let scene_index =
        |file_index: usize| file_index - (ds.gaussians_in_file - ds.gaussians_after_opacity_filter);
    let sim: std::collections::HashSet<u32> = ds.link.simulated.iter().copied().collect();
    assert!(
        sim.contains(&(scene_index(n - 2) as u32)),
        "the Gaussian inside the threshold is simulated"
    );
    assert!(
        !sim.contains(&(scene_index(n - 1) as u32)),
        "the one outside is static"
    );
}

#[test]
fn physflow_key_frames_follow_physflows_rule() {
    let dir = ds_fixture(PHYSFLOW);
    let opts = LoadOptions {
        key_frames: Some(4),
        ..Default::default()
    };
    let ds = load(&dir, &opts).unwrap();
    let v = &ds.views[0].video;
    // 12 files, 4 key frames: every 3rd file; spaced 11 x opt_frame_dt = 0.22 s.
    assert_eq!(v.frames, 4);
    assert!(v.files[1].ends_with("003.png"));
    assert!((v.fps - 1.0 / 0.22).abs() < 1e-9);
}

#[test]
fn pacnerf_cameras_follow_dvgo_and_every_camera_is_a_view() {
    let dir = ds_fixture(PACNERF);
    let exp = expected(&dir);
    let ds = load(&dir, &LoadOptions::default()).unwrap();
    check_counts(&ds, &exp);
    assert_eq!(ds.cameras.len() as u64, exp["cameras"].as_u64().unwrap());
    assert_eq!(ds.views.len(), ds.cameras.len());
    assert!((ds.config.parts[0].youngs_modulus_pa - exp["E_Pa"].as_f64().unwrap()).abs() < 1e-6);
    assert_eq!(ds.config.solver.gravity, [0.0, -9.8, 0.0]);
    assert!(!exp["ground_truth"].as_bool().unwrap() && ds.ground_truth.point_clouds.is_empty());
    check_projections(&ds, &exp);
    // --camera selects views by name or index.
    let mut d2 = ds.clone();
    d2.select_views(&["r_2".into(), "0".into()]).unwrap();
    assert_eq!(
        d2.views.iter().map(|v| v.camera_index).collect::<Vec<_>>(),
        vec![2, 0]
    );
    let e = d2.select_views(&["r_9".into()]).unwrap_err().to_string();
    assert!(e.contains("r_9"), "{e}");
}

#[test]
fn physdreamer_transforms_and_colmap_binary_give_the_same_cameras() {
    let dir = ds_fixture(PHYSDREAMER);
    let exp = expected(&dir);
    let ds = load(&dir, &LoadOptions::default()).unwrap();
    check_counts(&ds, &exp);
    assert_eq!(ds.views.len() as u64, exp["views"].as_u64().unwrap());
    check_projections(&ds, &exp);
    let dc = load(&ds_fixture(PHYSDREAMER_COLMAP), &LoadOptions::default()).unwrap();
    check_projections(&dc, &expected(&ds_fixture(PHYSDREAMER_COLMAP)));
    assert_eq!(ds.cameras.len(), dc.cameras.len());
    for (a, b) in ds.cameras.iter().zip(&dc.cameras) {
        assert_eq!(a.name, b.name);
        for i in 0..4 {
            for j in 0..4 {
                assert!((a.world_to_camera[i][j] - b.world_to_camera[i][j]).abs() < 1e-9);
            }
        }
        assert!((a.fx - b.fx).abs() < 1e-9 && (a.cx - b.cx).abs() < 1e-12);
    }
    // PhysDreamer's normalisation puts the object in [0.14, 0.69]^3; the frozen (far from the
    // moving part) particles' cells become zero-velocity boxes.
    for x in &ds.particles.x {
        assert!(x.iter().all(|&v| v > 0.13 && v < 0.70), "{x:?}");
    }
    let frozen = ds
        .config
        .boundary
        .iter()
        .filter(|b| matches!(b, r4d_mpm::BoundaryCondition::Cuboid { .. }))
        .count();
    assert!(frozen > 0, "the pot's cells are frozen");
    assert_eq!(ds.background, [0.0; 3]);
}

#[test]
fn inspect_json_has_the_contract_keys_for_every_layout() {
    for rel in [PHYSFLOW, PACNERF, PHYSDREAMER, PHYSDREAMER_COLMAP] {
        let dir = ds_fixture(rel);
        let out = r4d(&["dataset", "inspect", dir.to_str().unwrap(), "--json"]);
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
        for k in [
            "layout",
            "gaussians_in_file",
            "gaussians_after_opacity_filter",
            "simulated_particles",
            "static_gaussians",
            "normalisation",
            "parts",
            "cameras",
            "videos",
            "substep_dt",
            "frame_dt",
            "ground_truth",
        ] {
            assert!(v.get(k).is_some(), "{rel}: no '{k}'");
        }
        for k in ["rotation", "mean", "scale", "shift", "formula"] {
            assert!(
                v["normalisation"].get(k).is_some(),
                "{rel}: normalisation.{k}"
            );
        }
        for k in [
            "id",
            "material",
            "particles",
            "E_Pa",
            "nu",
            "density_kg_m3",
            "yield_stress_Pa",
            "plastic_viscosity_Pa_s",
            "friction_angle_deg",
        ] {
            assert!(v["parts"][0].get(k).is_some(), "{rel}: parts[0].{k}");
        }
        for k in ["name", "width", "height", "fx", "fy"] {
            assert!(v["cameras"][0].get(k).is_some(), "{rel}: cameras[0].{k}");
        }
        for k in ["path", "frames", "fps", "width", "height", "camera"] {
            assert!(v["videos"][0].get(k).is_some(), "{rel}: videos[0].{k}");
        }
        let exp = expected(&dir);
        assert_eq!(v["layout"], exp["layout"]);
        assert_eq!(v["simulated_particles"], exp["simulated_particles"]);
        // The text report runs too.
        let out = r4d(&["dataset", "inspect", dir.to_str().unwrap()]);
        assert!(out.status.success());
    }
}

#[test]
fn broken_folders_are_typed_errors_naming_the_file() {
    let base = tmp("broken");
    // A PAC-NeRF camera missing a frame file.
    let d = base.join("toyball");
    common::copy_dir(&ds_fixture(PACNERF), &d);
    std::fs::remove_file(d.join("data/r_1_3.png")).unwrap();
    let e = load(&d, &LoadOptions::default()).unwrap_err().to_string();
    assert!(e.contains("r_1_3.png"), "{e}");
    // No physics config.
    let d = base.join("toyball2");
    common::copy_dir(&ds_fixture(PACNERF), &d);
    std::fs::remove_file(d.join("toyball_config.json")).unwrap();
    let e = load(&d, &LoadOptions::default()).unwrap_err().to_string();
    assert!(
        e.contains("toyball2_config.json") && e.contains("--sim"),
        "{e}"
    );
    // A config key PhysFlow would not accept.
    let d = base.join("toyball3");
    common::copy_dir(&ds_fixture(PACNERF), &d);
    std::fs::write(
        d.join("toyball3_config.json"),
        r#"{"material": "honey", "g": [0, -9.8, 0]}"#,
    )
    .unwrap();
    let e = load(&d, &LoadOptions::default()).unwrap_err().to_string();
    assert!(
        e.contains("toyball3_config.json") && e.contains("honey"),
        "{e}"
    );
    // A camera whose frames disagree with the others.
    let d = base.join("toyball4");
    common::copy_dir(&ds_fixture(PACNERF), &d);
    std::fs::rename(
        d.join("toyball_config.json"),
        d.join("toyball4_config.json"),
    )
    .unwrap();
    let text = std::fs::read_to_string(d.join("all_data.json")).unwrap();
    let mut v: Vec<serde_json::Value> = serde_json::from_str(&text).unwrap();
    v.retain(|e| e["file_path"] != "data/r_2_5.png");
    std::fs::write(d.join("all_data.json"), serde_json::to_string(&v).unwrap()).unwrap();
    let e = load(&d, &LoadOptions::default()).unwrap_err().to_string();
    assert!(e.contains("all_data.json") && e.contains("camera 2"), "{e}");
    // Not a dataset folder; --format forcing a layout whose files are absent.
    let e = load(&base, &LoadOptions::default())
        .unwrap_err()
        .to_string();
    assert!(e.contains("not a dataset folder"), "{e}");
    let opts = LoadOptions {
        format: Some(r4d_datasets::Layout::PhysFlow),
        ..Default::default()
    };
    let e = load(&ds_fixture(PACNERF), &opts).unwrap_err().to_string();
    assert!(e.contains("point_cloud"), "{e}");
    // A fit that asks for more frames than the video has, and nothing written before.
    let out_dir = base.join("run");
    let cfg = base.join("fit.toml");
    std::fs::write(
        &cfg,
        "strategy = \"fixed\"\niters = 1\nframes = 40\n[init]\nenabled = false\n",
    )
    .unwrap();
    let out = r4d(&[
        "fit",
        "--dataset",
        ds_fixture(PACNERF).to_str().unwrap(),
        "--camera",
        "r_7",
        "--config",
        cfg.to_str().unwrap(),
        "--out",
        out_dir.to_str().unwrap(),
    ]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("--camera r_7"), "{err}");
    assert!(
        !out_dir.exists(),
        "nothing is written before the inputs validate"
    );
}

/// Renders the dataset's views with its own config's parameters into its video files (the
/// fixtures' frames are test patterns).
pub(crate) fn render_references(ds: &Dataset) {
    let problem =
        resonance4d::video_fit::problem_from_dataset(ds, resonance4d::compute::cpu()).unwrap();
    let obj = resonance4d::video_fit::Objective::new(
        &problem,
        None,
        &r4d_loss::DmsConfig::default(),
        false,
    )
    .unwrap();
    let videos = obj.render(&problem.config.parts).unwrap();
    for (view, video) in ds.views.iter().zip(&videos) {
        assert_eq!(video.frames(), view.video.files.len());
        for (t, file) in view.video.files.iter().enumerate() {
            let bytes: Vec<u8> = video
                .frame(t)
                .iter()
                .map(|&v| (v.clamp(0.0, 1.0) * 255.0).round() as u8)
                .collect();
            image::save_buffer(
                file,
                &bytes,
                video.width() as u32,
                video.height() as u32,
                image::ExtendedColorType::Rgb8,
            )
            .unwrap();
        }
    }
}

#[test]
fn multi_view_fit_from_a_pacnerf_folder_recovers_youngs_modulus() {
    let base = tmp("fit");
    let d = base.join("toyball");
    common::copy_dir(&ds_fixture(PACNERF), &d);
    let truth = load(&d, &LoadOptions::default()).unwrap();
    assert_eq!(truth.views.len(), 3);
    render_references(&truth);
    // Start from E 2.5x the truth (a --sim config), fit E on the three views.
    let text = std::fs::read_to_string(d.join("toyball_config.json")).unwrap();
    let mut cfg: serde_json::Value = serde_json::from_str(&text).unwrap();
    cfg["E"] = serde_json::json!(0.0125);
    let sim = base.join("start_config.json");
    std::fs::write(&sim, cfg.to_string()).unwrap();
    let fit_toml = base.join("fit.toml");
    std::fs::write(
        &fit_toml,
        "strategy = \"fixed\"\niters = 25\nlr = 0.15\nfree = [\"E\"]\n[init]\nenabled = false\n",
    )
    .unwrap();
    let run = base.join("run");
    let out = r4d(&[
        "fit",
        "--dataset",
        d.to_str().unwrap(),
        "--sim",
        sim.to_str().unwrap(),
        "--config",
        fit_toml.to_str().unwrap(),
        "--out",
        run.to_str().unwrap(),
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let params: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(run.join("params.json")).unwrap()).unwrap();
    let e = params["parts"][0]["E"].as_f64().unwrap();
    let e_true = truth.config.parts[0].youngs_modulus_pa;
    assert!(
        (e / e_true - 1.0).abs() < 0.05,
        "fitted E {e:.4e} Pa, truth {e_true:.4e} Pa (start {:.4e})",
        2.5 * e_true
    );
    // PhysFlow's units next to SI, ready to paste into its config.
    let pf = params["parts"][0]["physflow"]["E"].as_f64().unwrap();
    assert!((pf - e / 1e7).abs() < 1e-15);
    assert_eq!(
        std::fs::read_dir(&run)
            .unwrap()
            .filter(|e| e
                .as_ref()
                .unwrap()
                .file_name()
                .to_string_lossy()
                .starts_with("view_"))
            .count(),
        3,
        "one diagnostics folder per view"
    );
    check_eval(&d, &run, e_true);
}

/// The frames of a video folder written as an H.264 MP4 at `fps`.
fn frames_to_mp4(frames: &Path, mp4: &Path, fps: f64) -> r4d_loss::Video<f32> {
    let v: r4d_loss::Video<f32> = r4d_loss::io::read_video(frames).unwrap();
    r4d_video::write_mp4(mp4, &v, fps).unwrap();
    v
}

#[test]
fn mp4_videos_are_read_where_the_layouts_put_them() {
    // PhysFlow: an MP4 in the scene folder wins over images_generated/, at its own rate.
    let dir = tmp("physflow_mp4").join("toyphone");
    common::copy_dir(&ds_fixture(PHYSFLOW), &dir);
    let src = frames_to_mp4(
        &dir.join("images_generated"),
        &dir.join("toyphone.mp4"),
        24.0,
    );
    let sim = ds_fixture("physflow/config/phys_dreamer/toyphone_config.json");
    let opts = LoadOptions {
        sim: Some(sim.clone()),
        ..Default::default()
    };
    let ds = load(&dir, &opts).unwrap();
    let v = &ds.views[0].video;
    assert!(v.path.ends_with("toyphone.mp4"), "{}", v.path.display());
    assert_eq!((v.frames, v.fps), (src.frames(), 24.0));
    // The fixture's frames are per-pixel colour codes (no chroma subsampling survives them),
    // so check order, not fidelity: decoded frame t is nearest to source frame t.
    let decoded = v.read().unwrap();
    assert_eq!(decoded.frames(), src.frames());
    for t in 0..src.frames() {
        let d = |u: usize| -> f64 {
            decoded
                .frame(t)
                .iter()
                .zip(src.frame(u))
                .map(|(a, b)| ((a - b) as f64).powi(2))
                .sum()
        };
        let best = (0..src.frames())
            .min_by(|&a, &b| d(a).total_cmp(&d(b)))
            .unwrap();
        assert_eq!(best, t);
    }
    // --fps overrides the file's rate.
    let ds = load(
        &dir,
        &LoadOptions {
            sim: Some(sim.clone()),
            fps: Some(30.0),
            ..Default::default()
        },
    )
    .unwrap();
    assert_eq!(ds.views[0].video.fps, 30.0);

    // PhysDreamer: videos/<image name>*.mp4 matched to its camera by prefix.
    let dir = tmp("physdreamer_mp4").join("toyplant");
    common::copy_dir(&ds_fixture(PHYSDREAMER), &dir);
    let vdir = dir.join("videos");
    for take in ["frame_00001_take1", "frame_00002_take1"] {
        frames_to_mp4(&vdir.join(take), &vdir.join(format!("{take}.mp4")), 30.0);
        std::fs::remove_dir_all(vdir.join(take)).unwrap();
    }
    let ds = load(&dir, &LoadOptions::default()).unwrap();
    assert_eq!(ds.views.len(), 2);
    for v in &ds.views {
        let stem = v
            .video
            .path
            .file_stem()
            .unwrap()
            .to_str()
            .unwrap()
            .to_string();
        assert!(
            stem.starts_with(v.camera.name.trim_end_matches(".png")),
            "{stem} vs {}",
            v.camera.name
        );
        assert_eq!(v.video.fps, 30.0);
    }
    let out = r4d(&["dataset", "inspect", dir.to_str().unwrap(), "--json"]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let j: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert!(j["videos"][0]["path"].as_str().unwrap().ends_with(".mp4"));

    // Another codec in videos/ is a typed error naming the file and the codec.
    let bad = vdir.join("frame_00001_take1.mp4");
    let mut bytes = std::fs::read(&bad).unwrap();
    let stsd = bytes.windows(4).position(|w| w == b"stsd").unwrap();
    let at = stsd + bytes[stsd..].windows(4).position(|w| w == b"avc1").unwrap();
    bytes[at..at + 4].copy_from_slice(b"av01");
    std::fs::write(&bad, bytes).unwrap();
    let e = load(&dir, &LoadOptions::default()).unwrap_err().to_string();
    assert!(
        e.contains("frame_00001_take1.mp4") && e.contains("av01"),
        "{e}"
    );
}

pub(crate) fn json_of(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

pub(crate) fn run_ok(args: &[&str]) -> std::process::Output {
    let out = r4d(args);
    assert!(
        out.status.success(),
        "r4d {args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    out
}

/// `r4d eval` on the fitted PAC-NeRF run: its video numbers are `r4d metrics`' on the frames it
/// wrote, its 30 fps references are the nearest source frames, and its trajectory numbers are
/// `r4d metrics-trajectory`'s on the point clouds; ground truth made by simulating the true
/// parameters gives Chamfer 0 for a run holding the truth.
fn check_eval(d: &Path, run: &Path, e_true: f64) {
    // Ground truth: first a placeholder, so that eval simulates trajectories; then the true
    // parameters' trajectory (from a copy of the run holding the truth) replaces it.
    let pcd = d.join("pcd");
    std::fs::create_dir_all(&pcd).unwrap();
    let ds = load(d, &LoadOptions::default()).unwrap();
    let n_gt = 6;
    for k in 1..=n_gt {
        std::fs::copy(d.join("point_cloud.ply"), pcd.join(format!("{k}.ply"))).unwrap();
    }
    let truth_run = run.with_file_name("truth_run");
    common::copy_dir(run, &truth_run);
    let mut params = json_of(&run.join("params.json"));
    params["parts"][0]["E"] = serde_json::json!(e_true);
    std::fs::write(truth_run.join("params.json"), params.to_string()).unwrap();
    run_ok(&["eval", truth_run.to_str().unwrap()]);
    for k in 1..=n_gt {
        std::fs::copy(
            truth_run.join(format!("eval/trajectory/frame_{:04}.ply", k - 1)),
            pcd.join(format!("{k}.ply")),
        )
        .unwrap();
    }
    run_ok(&["eval", truth_run.to_str().unwrap()]);
    let truth = json_of(&truth_run.join("eval.json"));
    assert_eq!(truth["chamfer"].as_f64(), Some(0.0), "{truth}");
    assert_eq!(truth["f_score"].as_f64(), Some(1.0));

    // The fitted run.
    let out = run_ok(&[
        "eval",
        run.to_str().unwrap(),
        "--json",
        run.join("e.json").to_str().unwrap(),
    ]);
    let table = String::from_utf8_lossy(&out.stdout);
    assert!(
        table.contains("MS-SSIM") && table.contains("Chamfer"),
        "{table}"
    );
    let ev = json_of(&run.join("e.json"));
    for key in [
        "ms_ssim",
        "psnr",
        "lpips_alex",
        "lpips_vgg",
        "peak_memory_bytes",
        "chamfer",
        "hd95",
        "f_score",
        "fps",
        "frames",
    ] {
        assert!(ev.get(key).is_some(), "eval.json lacks {key}: {ev}");
    }
    assert_eq!(ev["fps"].as_f64(), Some(30.0));
    assert_eq!(ev["views"].as_array().unwrap().len(), 3);
    assert!(ev["chamfer"].as_f64().unwrap() < 1e-3, "{ev}");

    // 30 fps references: the nearest source frames.
    let src_fps = ds.views[0].video.fps;
    let src = ds.views[0].video.read().unwrap();
    let conv: r4d_loss::Video<f32> =
        r4d_loss::io::read_video(&run.join("eval/view_0/reference")).unwrap();
    assert_eq!(conv.frames(), ev["frames"].as_u64().unwrap() as usize);
    assert_eq!(
        conv.frames(),
        ((src.frames() - 1) as f64 * 30.0 / src_fps).floor() as usize + 1
    );
    for k in 0..conv.frames() {
        let j = ((k as f64 * src_fps / 30.0).round() as usize).min(src.frames() - 1);
        assert_eq!(
            conv.frame(k),
            src.frame(j),
            "30 fps frame {k} is source frame {j}"
        );
    }

    // Video numbers = `r4d metrics` on the frames eval measured.
    let m = run_ok(&[
        "metrics",
        "--json",
        "--reference",
        run.join("eval/view_0/reference").to_str().unwrap(),
        "--rendered",
        run.join("eval/view_0/rendered").to_str().unwrap(),
    ]);
    let m: serde_json::Value = serde_json::from_slice(&m.stdout).unwrap();
    let v0 = &ev["views"][0];
    for key in ["psnr", "ssim", "ms_ssim"] {
        assert_eq!(
            m[key], v0[key],
            "{key}: metrics {} vs eval {}",
            m[key], v0[key]
        );
    }
    assert_eq!(
        m["ms_ssim_small_window"]["value"],
        v0["ms_ssim_small_window"]["value"]
    );

    // Trajectory numbers = `r4d metrics-trajectory` on the same point clouds (ground truth
    // renamed so that name order is frame order).
    let gt_sorted = run.join("gt_sorted");
    std::fs::create_dir_all(&gt_sorted).unwrap();
    for k in 1..=n_gt {
        std::fs::copy(
            pcd.join(format!("{k}.ply")),
            gt_sorted.join(format!("{k:04}.ply")),
        )
        .unwrap();
    }
    let t = run_ok(&[
        "metrics-trajectory",
        "--json",
        "--tau",
        "0.04",
        "--reference",
        gt_sorted.to_str().unwrap(),
        "--simulated",
        run.join("eval/trajectory").to_str().unwrap(),
    ]);
    let t: serde_json::Value = serde_json::from_slice(&t.stdout).unwrap();
    assert_eq!(t["cd"], ev["chamfer"]);
    assert_eq!(t["hd95"], ev["hd95"]);
    assert_eq!(t["fscore"], ev["f_score"]);

    // A run folder whose parameters do not fit the scene is refused, naming the file.
    let other = run.with_file_name("other_run");
    common::copy_dir(run, &other);
    let mut p = json_of(&other.join("params.json"));
    p["parts"][0]["material"] = serde_json::json!("sand");
    std::fs::write(other.join("params.json"), p.to_string()).unwrap();
    let out = r4d(&["eval", other.to_str().unwrap()]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("params.json") && err.contains("another scene"),
        "{err}"
    );
    let out = r4d(&["eval", d.to_str().unwrap()]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("invocation.json"));

    // A gap in the ground truth is an error naming the missing file, not a shorter truth.
    std::fs::remove_file(pcd.join("3.ply")).unwrap();
    let out = r4d(&["eval", run.to_str().unwrap()]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("3.ply"), "{err}");
}
