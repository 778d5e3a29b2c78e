//! PhysDreamer's own scene folders (github.com/a1600012888/PhysDreamer; data on Hugging Face
//! `YunjinZhang/PhysDreamer`).
//!
//! * **Cameras**: `transforms_train.json` (`camera_angle_x`, `frames[].file_path`,
//!   `frames[].transform_matrix` camera-to-world in OpenGL axes; the focal length is
//!   `0.5 w / tan(camera_angle_x / 2)` for both axes, the image size is read from the image
//!   file, the principal point is the image centre), or COLMAP `sparse/0/{cameras,images}.txt`
//!   or `.bin` (PINHOLE, SIMPLE_PINHOLE or distortion-free models). Camera names are the image
//!   names.
//! * **Gaussians**: `point_cloud.ply`. With `clean_object_points.ply`, a Gaussian within 0.01
//!   (world) of one of its points is simulated, the others are static background; without it,
//!   every Gaussian is simulated. `internal_filled_points.ply` (optional) adds interior
//!   particles (simulated, not rendered).
//! * **Normalisation** (PhysDreamer's): over all coordinates of the simulated points (Gaussians
//!   and filling), `lo` = the smallest coordinate, `d` = largest - smallest;
//!   `x_sim = (x - lo + 0.25 d) / (1.8 d)`, so the object lies in `[0.14, 0.69]^3`.
//! * **Moving part**: with `moving_part_points.ply`, every particle farther than `0.5 / n_grid`
//!   (simulation box) from all its points is frozen: the grid node at the lower corner of its
//!   cell gets zero velocity every substep (`apply_grid_bc_w_freeze_pts`). The frozen nodes are
//!   merged into boxes and added as zero-velocity cuboid conditions ([`crate::moving`]).
//! * **Videos**: `videos/*.mp4` whose file name starts with a camera's image name (without
//!   extension), or sub-folders of `videos/` of PNG frames named the same way; if `videos/`
//!   holds PNG frames itself, its sorted first 60 and last 5 frames are the video (PhysDreamer's
//!   rule), filmed from camera 0 unless `--camera` picks another. Frame folders are 30 fps
//!   unless `--fps`; an MP4 plays at its own rate unless `--fps` (H.264 only, decoded by
//!   `r4d-video`; another codec is a typed error naming it).
//! * **Physics**: PhysDreamer's are Python configs; give one in PhysFlow's JSON dialect with
//!   `--sim` or as `<scene>_config.json` in the folder. Without one, PhysDreamer's set-up:
//!   jelly, `E` 1e5 Pa, `nu` 0.3, density 2000, no gravity, grid 64 over `[0, 1]^3`, 256
//!   substeps per 1/30 s frame, 14 frames, a bounding box; PhysDreamer drives the motion with a
//!   learned initial velocity, which is not part of the release: add a `particle_impulse`.
//! * **Background**: black.

use crate::error::{DatasetError, Result};
use crate::video::{self, VideoSource};
use crate::{
    cameras, moving, physflow_config, Dataset, GroundTruth, Layout, LoadOptions, ViewSource,
};
use r4d_mpm::{BoundaryCondition, ParticleSet};
use r4d_splat::{Camera, SimLink};
use serde_json::Value;
use std::path::{Path, PathBuf};

const DEFAULT_CONFIG: &str = r#"{"material": "jelly", "E": 0.01, "nu": 0.3, "density": 2000,
    "g": [0, 0, 0], "n_grid": 64, "grid_lim": 1.0, "substep_dt": 1.3020833333333333e-4,
    "frame_dt": 0.03333333333333333, "frame_num": 14, "opacity_threshold": 0.0,
    "boundary_conditions": [{"type": "bounding_box"}]}"#;

/// Cameras from `transforms_train.json`.
pub fn read_transforms(dir: &Path) -> Result<Vec<Camera>> {
    let path = dir.join("transforms_train.json");
    parse_transforms(&crate::error::read_text(&path)?, dir)
}

/// [`read_transforms`] on the text of `dir/transforms_train.json` (images are looked up in
/// `dir`).
pub fn parse_transforms(text: &str, dir: &Path) -> Result<Vec<Camera>> {
    let path = dir.join("transforms_train.json");
    let v: Value = serde_json::from_str(text)
        .map_err(|e| DatasetError::invalid(&path, format!("not JSON: {e}")))?;
    let angle = v.get("camera_angle_x").and_then(Value::as_f64);
    let frames = v
        .get("frames")
        .and_then(Value::as_array)
        .ok_or_else(|| DatasetError::invalid(&path, "no 'frames' list"))?;
    let mut out = Vec::new();
    for (i, f) in frames.iter().enumerate() {
        let ctx = format!("frames[{i}]");
        let fp = f
            .get("file_path")
            .and_then(Value::as_str)
            .ok_or_else(|| DatasetError::invalid(&path, format!("{ctx}: no 'file_path'")))?;
        let base = dir.join(fp);
        let img = [
            base.clone(),
            base.with_extension("png"),
            base.with_extension("jpg"),
        ]
        .into_iter()
        .find(|p| p.is_file())
        .ok_or_else(|| {
            DatasetError::missing(&base, format!("the image of {ctx} of {}", path.display()))
        })?;
        let (w, h) = video::image_size(&img)?;
        let m = f
            .get("transform_matrix")
            .and_then(Value::as_array)
            .filter(|r| r.len() >= 3)
            .and_then(|rows| {
                rows.iter()
                    .take(3)
                    .map(|r| {
                        let r = r.as_array().filter(|r| r.len() == 4)?;
                        let mut o = [0.0; 4];
                        for (j, x) in r.iter().enumerate() {
                            o[j] = x.as_f64().filter(|x| x.is_finite())?;
                        }
                        Some(o)
                    })
                    .collect::<Option<Vec<[f64; 4]>>>()
            })
            .ok_or_else(|| {
                DatasetError::invalid(
                    &path,
                    format!("{ctx}: 'transform_matrix' must be 4x4 numbers"),
                )
            })?;
        cameras::check_rotation(&m, &path, &ctx)?;
        let fl = match (
            f.get("fl_x").or(v.get("fl_x")).and_then(Value::as_f64),
            f.get("camera_angle_x").and_then(Value::as_f64).or(angle),
        ) {
            (Some(fl), _) => fl,
            (None, Some(a)) if a > 0.0 && a < std::f64::consts::PI => {
                0.5 * w as f64 / (0.5 * a).tan()
            }
            (None, Some(a)) => {
                return Err(DatasetError::invalid(
                    &path,
                    format!("camera_angle_x = {a} (radians, in (0, pi))"),
                ))
            }
            (None, None) => return Err(DatasetError::invalid(&path, "no 'camera_angle_x'")),
        };
        let name = img
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        let cam = cameras::from_gl_c2w(name, w, h, [fl, fl, 0.5 * w as f64, 0.5 * h as f64], &m);
        cam.validate(&path.display().to_string())
            .map_err(|e| DatasetError::invalid(&path, e))?;
        out.push(cam);
    }
    if out.is_empty() {
        return Err(DatasetError::invalid(&path, "no cameras"));
    }
    Ok(out)
}

/// Cameras from COLMAP `sparse/0` (text or binary).
pub fn read_colmap(dir: &Path) -> Result<Vec<Camera>> {
    let sp = dir.join("sparse/0");
    let (c, i) = if sp.join("cameras.txt").is_file() && sp.join("images.txt").is_file() {
        (
            crate::error::read_text(&sp.join("cameras.txt"))?,
            crate::error::read_text(&sp.join("images.txt"))?,
        )
    } else if sp.join("cameras.bin").is_file() && sp.join("images.bin").is_file() {
        cameras::colmap_bin_to_text(&sp.join("cameras.bin"), &sp.join("images.bin"))?
    } else {
        return Err(DatasetError::missing(
            &sp,
            "cameras.txt + images.txt or cameras.bin + images.bin",
        ));
    };
    let set = r4d_splat::camera_io::parse_colmap(&c, &i, &sp.display().to_string())?;
    if set.cameras.is_empty() {
        return Err(DatasetError::invalid(&sp, "no images"));
    }
    for cam in &set.cameras {
        cam.validate(&sp.display().to_string())
            .map_err(|e| DatasetError::invalid(&sp, e))?;
    }
    Ok(set.cameras)
}

fn stem(name: &str) -> &str {
    Path::new(name)
        .file_stem()
        .and_then(|s| s.to_str())
        .unwrap_or(name)
}

/// The videos of `videos/` with their camera indices (see the module docs).
fn find_videos(
    dir: &Path,
    cams: &[Camera],
    fps: f64,
    fps_given: Option<f64>,
    warnings: &mut Vec<String>,
) -> Result<Vec<(usize, VideoSource)>> {
    let vdir = dir.join("videos");
    if !vdir.is_dir() {
        return Err(DatasetError::missing(
            &vdir,
            "the captured videos (videos/*.mp4 or PNG frames)",
        ));
    }
    let mut entries: Vec<PathBuf> = std::fs::read_dir(&vdir)
        .map_err(|source| DatasetError::Io {
            path: vdir.clone(),
            source,
        })?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .collect();
    r4d_fsio::seq::sort_natural(&mut entries);
    let camera_of = |p: &Path| -> Option<usize> {
        let name = p.file_name()?.to_str()?;
        // The longest matching image name wins (frame_0001 vs frame_00011...).
        cams.iter()
            .enumerate()
            .filter(|(_, c)| name.starts_with(stem(&c.name)))
            .max_by_key(|(_, c)| stem(&c.name).len())
            .map(|(i, _)| i)
    };
    let mut out = Vec::new();
    for e in &entries {
        if e.is_dir() {
            if let Some(c) = camera_of(e) {
                let files = video::frame_files(e)?;
                out.push((c, VideoSource::from_frames(e, files, fps)?));
            }
        } else if e.extension().is_some_and(|x| x.eq_ignore_ascii_case("mp4")) {
            match camera_of(e) {
                Some(c) => out.push((c, VideoSource::from_mp4(e, fps_given)?)),
                None => warnings.push(format!(
                    "{}: its name starts with no camera's image name; skipped",
                    e.display()
                )),
            }
        }
    }
    if out.is_empty() {
        let files = video::frame_files(&vdir)?;
        if !files.is_empty() {
            let n = files.len();
            let pick: Vec<PathBuf> = if n > 65 {
                files[..60].iter().chain(&files[n - 5..]).cloned().collect()
            } else {
                files
            };
            warnings.push(format!(
                "{}: PNG frames name no camera; camera 0 ({}) assumed",
                vdir.display(),
                cams[0].name
            ));
            out.push((0, VideoSource::from_frames(&vdir, pick, fps)?));
        }
    }
    if out.is_empty() {
        return Err(DatasetError::missing(
            &vdir,
            "a video whose name starts with a camera's image name",
        ));
    }
    Ok(out)
}

/// Reads a PhysDreamer scene folder (see the module docs).
pub fn load(dir: &Path, opts: &LoadOptions) -> Result<Dataset> {
    let name = crate::scene_name(dir);
    let mut warnings = Vec::new();
    let cfg_file = match &opts.sim {
        Some(s) => Some(crate::physflow::find_config(dir, &name, Some(s))?),
        None => Some(dir.join(format!("{name}_config.json"))).filter(|p| p.is_file()),
    };
    let cfg = match &cfg_file {
        Some(f) => physflow_config::load(f)?,
        None => {
            warnings.push(
                "no physics config (--sim or <scene>_config.json): PhysDreamer's set-up is used (jelly, E 1e5 Pa, nu 0.3, density 2000, grid 64, 256 substeps per 1/30 s, bounding box; no driving force)".into(),
            );
            let mut c =
                physflow_config::decode(DEFAULT_CONFIG, Path::new("<PhysDreamer defaults>"))?;
            c.config.time.substeps_per_frame = Some(256);
            c
        }
    };
    warnings.extend(
        cfg.warnings
            .iter()
            .map(|w| format!("{}: {w}", cfg.path.display())),
    );
    let gaussian_file = dir.join("point_cloud.ply");
    let all = r4d_splat::ply::read_gaussians(&gaussian_file)?;
    let thr = cfg.prepare.opacity_threshold;
    let kept: Vec<usize> = (0..all.len())
        .filter(|&i| 1.0 / (1.0 + (-(all.opacity_logits[i] as f64)).exp()) > thr)
        .collect();
    let scene = all.select(&kept);
    let means: Vec<[f64; 3]> = scene.means.iter().map(|m| m.map(|v| v as f64)).collect();
    let clean = dir.join("clean_object_points.ply");
    let simulated: Vec<u32> = if clean.is_file() {
        let pts = crate::read_points(&clean)?;
        let near = moving::within(&means, &pts, 0.01);
        (0..scene.len() as u32)
            .filter(|&i| near[i as usize])
            .collect()
    } else {
        (0..scene.len() as u32).collect()
    };
    if simulated.is_empty() {
        return Err(DatasetError::invalid(
            &clean,
            "no Gaussian lies within 0.01 of a clean-object point",
        ));
    }
    let filled_file = dir.join("internal_filled_points.ply");
    let filled: Vec<[f64; 3]> = if filled_file.is_file() {
        crate::read_points(&filled_file)?
    } else {
        Vec::new()
    };
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for p in simulated.iter().map(|&i| &means[i as usize]).chain(&filled) {
        for &v in p {
            lo = lo.min(v);
            hi = hi.max(v);
        }
    }
    let d = if hi > lo { hi - lo } else { 1.0 };
    let link = SimLink {
        scene_gaussians: scene.len(),
        simulated: simulated.clone(),
        filled: filled.len(),
        rotation: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
        centre: [lo - 0.25 * d; 3],
        scale: 1.0 / (1.8 * d),
        shift: [0.0; 3],
    };
    let x: Vec<[f32; 3]> = simulated
        .iter()
        .map(|&i| means[i as usize])
        .chain(filled.iter().copied())
        .map(|p| link.to_sim(p).map(|v| v as f32))
        .collect();
    let mut config = cfg.config.clone();
    let dx = config.domain.dx();
    let n = config.domain.n_grid;
    let moving_file = dir.join("moving_part_points.ply");
    if moving_file.is_file() {
        let pts: Vec<[f64; 3]> = crate::read_points(&moving_file)?
            .into_iter()
            .map(|p| link.to_sim(p))
            .collect();
        let xs: Vec<[f64; 3]> = x.iter().map(|p| p.map(|v| v as f64)).collect();
        let near = moving::within(&xs, &pts, 0.5 / n as f64);
        let mut nodes = Vec::new();
        for (p, &m) in xs.iter().zip(&near) {
            if !m {
                let c = p.map(|v| (v / dx).floor());
                if c.iter().all(|&c| c >= 0.0 && c < n as f64) {
                    nodes.push(c.map(|c| c as u32));
                }
            }
        }
        let boxes = moving::freeze_boxes(&nodes);
        if boxes.len() > 4096 {
            return Err(DatasetError::invalid(
                &moving_file,
                format!(
                    "the frozen grid nodes form {} boxes (limit 4096)",
                    boxes.len()
                ),
            ));
        }
        for (blo, bhi) in boxes {
            let point = [0, 1, 2].map(|a| 0.5 * (blo[a] + bhi[a]) as f64 * dx);
            let size = [0, 1, 2].map(|a| (0.5 * (bhi[a] - blo[a]) as f64 + 0.5) * dx);
            config.boundary.push(BoundaryCondition::Cuboid {
                point,
                size,
                velocity: [0.0; 3],
                start_time: 0.0,
                end_time: f64::INFINITY,
                reset: false,
            });
        }
    }
    let mut particles = ParticleSet {
        volume: r4d_mpm::scene::cell_volumes(&x, dx),
        part: vec![0; x.len()],
        x,
    };
    r4d_mpm::physgaussian::Import {
        config: config.clone(),
        regions: cfg.regions.clone(),
        warnings: Vec::new(),
    }
    .apply_to_scene(&mut particles, false);
    let cams = if dir.join("transforms_train.json").is_file() {
        read_transforms(dir)?
    } else {
        read_colmap(dir)?
    };
    let fps = opts.fps.unwrap_or(30.0);
    let mut views = Vec::new();
    for (ci, video) in find_videos(dir, &cams, fps, opts.fps, &mut warnings)? {
        let camera = cameras::fit_to_video(&cams[ci], video.width, video.height, &video.path)?;
        views.push(ViewSource {
            camera_index: ci,
            camera,
            video,
        });
    }
    let has_config = cfg_file.is_some();
    Ok(Dataset {
        layout: Layout::PhysDreamer,
        dir: dir.to_path_buf(),
        name,
        config_file: cfg_file,
        config,
        gaussian_file,
        gaussians_in_file: all.len(),
        gaussians_after_opacity_filter: scene.len(),
        scene,
        particles,
        link,
        cameras: cams,
        background: [0.0; 3],
        views,
        ground_truth: GroundTruth::default(),
        physflow: has_config.then(|| cfg.extras.clone()),
        warnings,
    })
}
