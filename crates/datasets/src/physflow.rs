//! PhysFlow's release: `model/<dataset>/<scene>/` (`<dataset>` = `phys_dreamer` or `pacnerf`).
//!
//! What is read, and how (PhysFlow's `simulation.py`, `utils/*.py`):
//!
//! 1. **Physics config**: `--sim FILE`, else `<root>/config/<dataset>/<scene>_config.json` when
//!    the folder is `<root>/model/<dataset>/<scene>`, else `<scene>_config.json` in the folder
//!    ([`crate::physflow_config`]: scaled units, defaults, material ids).
//! 2. **Gaussians**: `point_cloud/iteration_<N>/point_cloud.ply` with the largest `N` (SH degree
//!    from the number of `f_rest_*` properties). Gaussians with opacity `<= opacity_threshold`
//!    (0.02) are dropped (not rendered).
//! 3. **Moving part**: with `moving_part_points.ply`, a Gaussian farther than `0.5 / n_grid`
//!    (`1.0 / n_grid` for a scene named `playdoh`) from every moving-part point, in the world
//!    frame, is not simulated and is rendered at rest ([`crate::moving`]). Without the file
//!    every kept Gaussian is simulated.
//! 4. **Normalisation** of the simulated Gaussians into the box centred at (1, 1, 1):
//!    `x_sim = scale * (R x_world - mean) + (1, 1, 1)` with `R` the product of the
//!    `rotation_degree`/`rotation_axis` rotations (applied in list order), `mean` the centre of
//!    the rotated points' bounding box and `scale = s / (largest side of that box)`, `s` PhysFlow's
//!    per-scene factor chosen by the scene's name (`cat` 0.7, `letter` 2.0, `cream` 0.8,
//!    `toothpaste` 0.6, `playdoh` 0.75, otherwise 1; PhysFlow tests its whole model path, we
//!    test the scene folder's name). Rendering maps back with the exact inverse (PhysFlow's
//!    `apply_inverse_rotations` applies the transposed rotations in forward order, which is
//!    the inverse only for a single rotation). `particle_filling` fills the interior with
//!    `r4d prepare`'s filler (filling particles are simulated, not rendered).
//! 5. **Particles**: volumes `dx^3 / (particles in the cell)` (PhysGaussian's estimate;
//!    uniform for sand, as PhysFlow's `get_particle_volume(uniform=sand)`), parts from
//!    `additional_material_params`.
//! 6. **`inpaint_points.ply`** (optional): more Gaussians, rendered as static background.
//! 7. **Cameras**: `cameras.json` (INRIA 3DGS: camera-to-world rotation and centre), capped at
//!    1920 pixels per side as PhysFlow's `get_camera_view` does. The view is
//!    `default_camera_index`.
//! 8. **Reference video**: an `.mp4` in the folder (H.264, at its own frame rate unless `--fps`;
//!    the first in natural order when there are several; `--key-frames` does not apply), else
//!    the frames of `images_generated/` (PNG or JPEG, in natural order, numbering checked) at
//!    `1 / frame_dt` unless `--fps` says otherwise. With `--key-frames K`, PhysFlow's own
//!    rule: keep the files whose index `i` has `i % (n / K) == 0` (PhysFlow's `n_key_frame`,
//!    8), spaced `11 x opt_frame_dt` of simulated
//!    time (PhysFlow renders an optimisation frame every `(1 + stage_num) x opt_frame_dt`,
//!    `stage_num = 10`). The camera is rescaled to the frames' size when the aspect ratios agree.
//! 9. **Ground truth**: `pcd/<k>.ply` (PAC-NeRF scenes) is the world-frame point cloud of frame
//!    `k - 1`.
//! 10. **Background**: white (PhysFlow's `--white_bg` default).

use crate::error::{DatasetError, Result};
use crate::physflow_config::{self, PhysFlowConfig};
use crate::video::{self, VideoSource};
use crate::{cameras, moving, Dataset, GroundTruth, Layout, LoadOptions, ViewSource};
use r4d_mpm::physgaussian::Import;
use r4d_mpm::ParticleSet;
use r4d_splat::{Gaussians, SimLink};
use std::path::{Path, PathBuf};

/// PhysFlow's per-scene normalisation factor (see the module docs).
pub fn scene_scaling(scene: &str) -> f64 {
    for (key, s) in [
        ("cat", 0.7),
        ("letter", 2.0),
        ("cream", 0.8),
        ("toothpaste", 0.6),
        ("playdoh", 0.75),
    ] {
        if scene.contains(key) {
            return s;
        }
    }
    1.0
}

/// Where the physics config of a PhysFlow scene is (see the module docs).
pub fn find_config(dir: &Path, name: &str, sim: Option<&Path>) -> Result<PathBuf> {
    if let Some(s) = sim {
        return if s.is_file() {
            Ok(s.to_path_buf())
        } else {
            Err(DatasetError::missing(
                s,
                "the physics config given with --sim",
            ))
        };
    }
    let file = format!("{name}_config.json");
    let mut tried = Vec::new();
    if let Ok(abs) = dir.canonicalize() {
        if let (Some(dataset_dir), Some(dataset)) =
            (abs.parent(), abs.parent().and_then(|p| p.file_name()))
        {
            if let Some(model) = dataset_dir.parent() {
                if model.file_name().is_some_and(|m| m == "model") {
                    if let Some(root) = model.parent() {
                        let c = root.join("config").join(dataset).join(&file);
                        if c.is_file() {
                            return Ok(c);
                        }
                        tried.push(c);
                    }
                }
            }
        }
    }
    let c = dir.join(&file);
    if c.is_file() {
        return Ok(c);
    }
    tried.push(c);
    Err(DatasetError::missing(
        dir,
        format!(
            "the physics config: looked for {} (or pass --sim FILE)",
            tried
                .iter()
                .map(|p| p.display().to_string())
                .collect::<Vec<_>>()
                .join(" and ")
        ),
    ))
}

/// The simulated part of a scene (shared by the PhysFlow and PAC-NeRF loaders).
pub(crate) struct SimSetup {
    pub scene: Gaussians,
    pub link: SimLink,
    pub particles: ParticleSet,
    pub after_filter: usize,
    pub warnings: Vec<String>,
}

/// Opacity filter, moving-part rule, normalisation, filling, volumes and parts.
pub(crate) fn sim_setup(
    gaussians: &Gaussians,
    gaussian_file: &Path,
    cfg: &PhysFlowConfig,
    moving_points: Option<(&Path, f64)>,
    scaling: f64,
) -> Result<SimSetup> {
    let movable = match moving_points {
        Some((path, thres)) => {
            let pts = crate::read_points(path)?;
            if pts.is_empty() {
                return Err(DatasetError::invalid(path, "no moving-part points"));
            }
            let means: Vec<[f64; 3]> = gaussians
                .means
                .iter()
                .map(|m| m.map(|v| v as f64))
                .collect();
            Some(moving::within(&means, &pts, thres))
        }
        None => None,
    };
    let mut pre = cfg.prepare.clone();
    pre.scale = scaling;
    pre.grid_lim = cfg.config.domain.grid_lim;
    let what = format!("{} with {}", gaussian_file.display(), cfg.path.display());
    let p = r4d_splat::prepare_with(gaussians, &pre, movable.as_deref(), &what)?;
    let dx = cfg.config.domain.dx();
    let mut particles = ParticleSet {
        volume: r4d_mpm::scene::cell_volumes(&p.particles, dx),
        part: vec![0; p.particles.len()],
        x: p.particles,
    };
    let imp = Import {
        config: cfg.config.clone(),
        regions: cfg.regions.clone(),
        warnings: Vec::new(),
    };
    imp.apply_to_scene(&mut particles, false);
    Ok(SimSetup {
        after_filter: p.scene.len(),
        scene: p.scene,
        link: p.link,
        particles,
        warnings: p.warnings,
    })
}

/// Appends static Gaussians (e.g. `inpaint_points.ply`) to the scene.
pub(crate) fn append_static(
    scene: &mut Gaussians,
    link: &mut SimLink,
    extra: &Gaussians,
    path: &Path,
) -> Result<()> {
    if extra.sh_degree != scene.sh_degree {
        return Err(DatasetError::invalid(
            path,
            format!(
                "SH degree {} differs from the scene's {}",
                extra.sh_degree, scene.sh_degree
            ),
        ));
    }
    scene.means.extend_from_slice(&extra.means);
    scene.log_scales.extend_from_slice(&extra.log_scales);
    scene.quats.extend_from_slice(&extra.quats);
    scene
        .opacity_logits
        .extend_from_slice(&extra.opacity_logits);
    scene.sh.extend_from_slice(&extra.sh);
    link.scene_gaussians = scene.len();
    Ok(())
}

/// Reads a PhysFlow scene folder (see the module docs).
pub fn load(dir: &Path, opts: &LoadOptions) -> Result<Dataset> {
    let name = crate::scene_name(dir);
    let config_file = find_config(dir, &name, opts.sim.as_deref())?;
    let cfg = physflow_config::load(&config_file)?;
    let mut warnings = cfg
        .warnings
        .iter()
        .map(|w| format!("{}: {w}", config_file.display()))
        .collect::<Vec<_>>();
    let gaussian_file = crate::latest_point_cloud(dir).ok_or_else(|| {
        DatasetError::missing(
            dir.join("point_cloud"),
            "iteration_<N>/point_cloud.ply (the 3DGS scene)",
        )
    })?;
    let gaussians = r4d_splat::ply::read_gaussians(&gaussian_file)?;
    let n_grid = cfg.config.domain.n_grid as f64;
    let thres = if name.contains("playdoh") { 1.0 } else { 0.5 } / n_grid;
    let moving_file = dir.join("moving_part_points.ply");
    let moving = moving_file
        .is_file()
        .then_some((moving_file.as_path(), thres));
    let setup = sim_setup(
        &gaussians,
        &gaussian_file,
        &cfg,
        moving,
        scene_scaling(&name),
    )?;
    warnings.extend(setup.warnings.iter().cloned());
    let (mut scene, mut link) = (setup.scene, setup.link);
    let inpaint = dir.join("inpaint_points.ply");
    if inpaint.is_file() {
        let extra = r4d_splat::ply::read_gaussians(&inpaint)?;
        append_static(&mut scene, &mut link, &extra, &inpaint)?;
    }
    let cam_file = dir.join("cameras.json");
    if !cam_file.is_file() {
        return Err(DatasetError::missing(
            &cam_file,
            "the INRIA 3DGS camera list",
        ));
    }
    let cams: Vec<_> = r4d_splat::load_cameras(&cam_file)?
        .cameras
        .iter()
        .map(|c| cameras::cap_size(c, 1920))
        .collect();
    let cam_index = cfg.extras.default_camera_index.max(0) as usize;
    if cam_index >= cams.len() {
        return Err(DatasetError::invalid(
            &config_file,
            format!(
                "default_camera_index {cam_index}: {} has {} cameras",
                cam_file.display(),
                cams.len()
            ),
        ));
    }
    let video = match reference_video(dir, &cfg, opts, &mut warnings) {
        Err(DatasetError::Missing { .. }) if opts.video_optional => None,
        r => Some(r?),
    };
    let views = match video {
        Some(video) => vec![ViewSource {
            camera_index: cam_index,
            camera: cameras::fit_to_video(
                &cams[cam_index],
                video.width,
                video.height,
                &video.path,
            )?,
            video,
        }],
        None => Vec::new(),
    };
    Ok(Dataset {
        layout: Layout::PhysFlow,
        dir: dir.to_path_buf(),
        name,
        config_file: Some(config_file),
        config: cfg.config.clone(),
        gaussian_file,
        gaussians_in_file: gaussians.len(),
        gaussians_after_opacity_filter: setup.after_filter,
        scene,
        particles: setup.particles,
        link,
        cameras: cams,
        background: [1.0; 3],
        views,
        ground_truth: GroundTruth::from_pcd(dir)?,
        physflow: Some(cfg.extras.clone()),
        warnings,
    })
}

/// The reference video of a PhysFlow scene (see the module docs, item 8).
fn reference_video(
    dir: &Path,
    cfg: &PhysFlowConfig,
    opts: &LoadOptions,
    warnings: &mut Vec<String>,
) -> Result<VideoSource> {
    let mp4s: Vec<PathBuf> = std::fs::read_dir(dir)
        .map_err(|source| DatasetError::Io {
            path: dir.to_path_buf(),
            source,
        })?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.is_file() && p.extension().is_some_and(|e| e.eq_ignore_ascii_case("mp4")))
        .collect();
    let mut mp4s = mp4s;
    r4d_fsio::seq::sort_natural(&mut mp4s);
    let gen = dir.join("images_generated");
    if let Some(m) = mp4s.first() {
        if mp4s.len() > 1 {
            warnings.push(format!(
                "{}: {} MP4 files in the scene folder; the first in natural order is the reference video",
                dir.display(),
                mp4s.len()
            ));
        }
        if opts.key_frames.is_some() {
            warnings.push(format!(
                "{}: --key-frames applies to images_generated/ frames; the MP4 is used whole",
                m.display()
            ));
        }
        return VideoSource::from_mp4(m, opts.fps);
    }
    if !gen.is_dir() {
        return Err(DatasetError::missing(
            &gen,
            "the reference video (an .mp4 in the scene folder or frames in images_generated/)",
        ));
    }
    let mut files = video::frame_files(&gen)?;
    let mut fps = opts.fps.unwrap_or(1.0 / cfg.extras.frame_dt);
    if let Some(k) = opts.key_frames {
        if k > files.len() {
            return Err(DatasetError::invalid(
                &gen,
                format!(
                    "--key-frames {k}: more key frames than the {} frames in the folder",
                    files.len()
                ),
            ));
        }
        let idx = video::key_frame_indices(files.len(), k);
        files = idx.into_iter().map(|i| files[i].clone()).collect();
        if opts.fps.is_none() {
            fps = 1.0 / (11.0 * cfg.extras.opt_frame_dt);
        }
    }
    VideoSource::from_frames(&gen, files, fps)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scalings_by_scene_name() {
        assert_eq!(scene_scaling("cat"), 0.7);
        assert_eq!(scene_scaling("toothpaste"), 0.6);
        assert_eq!(scene_scaling("telephone"), 1.0);
        assert_eq!(scene_scaling("carnation"), 1.0);
    }
}
