//! PAC-NeRF's scene folders (`data/<scene>/all_data.json` of github.com/xuan-li/PAC-NeRF).
//!
//! * `all_data.json`: a list of `{"file_path": ".../r_<cam>_<frame>.png", "c2w": 3x4,
//!   "intrinsic": 3x3}`; `c2w` is camera-to-world in OpenGL axes, converted as
//!   [`crate::cameras`] documents (pixel centres at `+0.5`, as DVGO's rays). Frame `-1` is the
//!   camera's background image, `-2` an image whose alpha > 50 marks pixels to ignore (both
//!   reported, not used by the loss); frames `0, 1, ...` are the video. Every camera must have
//!   the same frames; the image size is read from the first frame. A `file_path` is resolved
//!   against the folder, then by its file name in the folder and in `data/`.
//! * Physics: `--sim FILE` or `<scene>_config.json` in the folder, in PhysFlow's dialect
//!   ([`crate::physflow_config`]; PhysFlow's `config/pacnerf/*.json` are made for these scenes).
//!   Its `frame_dt` is the video's frame interval unless `--fps` says otherwise (PAC-NeRF: 1/24 s
//!   by default, toothpaste 1/50).
//! * Gaussians: PAC-NeRF releases none; `point_cloud/iteration_<N>/point_cloud.ply` or
//!   `point_cloud.ply` in the folder (PhysFlow's reconstruction). Preprocessing and
//!   normalisation as for PhysFlow's release ([`crate::physflow`]); every kept Gaussian is
//!   simulated.
//! * Ground truth: `pcd/<k>.ply` as in PhysFlow's copy, when present.
//! * Background: white.

use crate::error::{DatasetError, Result};
use crate::physflow::{find_config, sim_setup};
use crate::video::VideoSource;
use crate::{cameras, physflow_config, Dataset, GroundTruth, Layout, LoadOptions, ViewSource};
use serde_json::Value;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// One camera's files.
#[derive(Clone, Debug, Default)]
pub struct PacCamera {
    /// Frames 0, 1, ... in order.
    pub frames: Vec<PathBuf>,
    /// The background image (frame -1).
    pub background: Option<PathBuf>,
    /// The ignore mask (frame -2).
    pub ignore: Option<PathBuf>,
    /// Camera-to-world (OpenGL) and intrinsics of the first entry.
    pub c2w: Vec<[f64; 4]>,
    /// `[fx, fy, cx, cy]`.
    pub k: [f64; 4],
}

fn matrix(v: &Value, key: &str, rows: usize, path: &Path, ctx: &str) -> Result<Vec<[f64; 4]>> {
    let bad = || {
        DatasetError::invalid(
            path,
            format!("{ctx}: '{key}' must be a {rows}x3 or {rows}x4 array of numbers"),
        )
    };
    let a = v.get(key).and_then(Value::as_array).ok_or_else(bad)?;
    if a.len() < rows {
        return Err(bad());
    }
    let mut out = Vec::new();
    for row in a.iter().take(rows) {
        let r = row.as_array().ok_or_else(bad)?;
        if r.len() < 3 {
            return Err(bad());
        }
        let mut m = [0.0; 4];
        for (j, x) in r.iter().take(4).enumerate() {
            m[j] = x.as_f64().filter(|x| x.is_finite()).ok_or_else(bad)?;
        }
        out.push(m);
    }
    Ok(out)
}

/// `r_<cam>_<frame>` of a file name.
fn cam_frame(path: &str) -> Option<(usize, i64)> {
    let stem = Path::new(path).file_stem()?.to_str()?;
    let rest = stem.strip_prefix("r_")?;
    let (c, f) = rest.split_once('_')?;
    Some((c.parse().ok()?, f.parse().ok()?))
}

fn resolve(dir: &Path, file_path: &str) -> Option<PathBuf> {
    let p = Path::new(file_path);
    let name = p.file_name()?;
    [dir.join(p), dir.join(name), dir.join("data").join(name)]
        .into_iter()
        .find(|c| c.is_file())
}

/// Parses `all_data.json` into cameras (by camera index).
pub fn read_all_data(dir: &Path) -> Result<BTreeMap<usize, PacCamera>> {
    let path = dir.join("all_data.json");
    parse_all_data(&crate::error::read_text(&path)?, dir)
}

/// [`read_all_data`] on the text of `dir/all_data.json` (images are looked up in `dir`).
pub fn parse_all_data(text: &str, dir: &Path) -> Result<BTreeMap<usize, PacCamera>> {
    let path = dir.join("all_data.json");
    let v: Value = serde_json::from_str(text)
        .map_err(|e| DatasetError::invalid(&path, format!("not JSON: {e}")))?;
    let list = v.as_array().ok_or_else(|| {
        DatasetError::invalid(&path, "expected a list of {file_path, c2w, intrinsic}")
    })?;
    let mut cams: BTreeMap<usize, PacCamera> = BTreeMap::new();
    let mut frames: BTreeMap<usize, BTreeMap<i64, PathBuf>> = BTreeMap::new();
    for (i, e) in list.iter().enumerate() {
        let ctx = format!("entry {i}");
        let fp = e
            .get("file_path")
            .and_then(Value::as_str)
            .ok_or_else(|| DatasetError::invalid(&path, format!("{ctx}: no 'file_path'")))?;
        let (cam, frame) = cam_frame(fp).ok_or_else(|| {
            DatasetError::invalid(
                &path,
                format!("{ctx}: file_path '{fp}' is not r_<cam>_<frame>.png"),
            )
        })?;
        if frame < -2 {
            return Err(DatasetError::invalid(
                &path,
                format!("{ctx}: frame {frame} (frames are -2, -1, 0, 1, ...)"),
            ));
        }
        let file = resolve(dir, fp).ok_or_else(|| {
            DatasetError::missing(
                dir.join(fp),
                format!("the image of {ctx} of {}", path.display()),
            )
        })?;
        let c2w = matrix(e, "c2w", 3, &path, &ctx)?;
        cameras::check_rotation(&c2w, &path, &ctx)?;
        let k = matrix(e, "intrinsic", 3, &path, &ctx)?;
        let entry = cams.entry(cam).or_insert_with(|| PacCamera {
            c2w: c2w.clone(),
            k: [k[0][0], k[1][1], k[0][2], k[1][2]],
            ..Default::default()
        });
        if frame >= 0 && entry.c2w != c2w {
            return Err(DatasetError::invalid(
                &path,
                format!(
                    "{ctx}: camera {cam} moves between frames (c2w differs); cameras must be fixed"
                ),
            ));
        }
        match frame {
            -1 => entry.background = Some(file),
            -2 => entry.ignore = Some(file),
            f => {
                if frames.entry(cam).or_default().insert(f, file).is_some() {
                    return Err(DatasetError::invalid(
                        &path,
                        format!("{ctx}: camera {cam} frame {f} listed twice"),
                    ));
                }
            }
        }
    }
    if cams.is_empty() {
        return Err(DatasetError::invalid(&path, "no entries"));
    }
    let mut count = None;
    for (cam, c) in cams.iter_mut() {
        let f = frames.remove(cam).unwrap_or_default();
        if let Some((i, (&fr, _))) = f.iter().enumerate().find(|(i, (&fr, _))| fr != *i as i64) {
            return Err(DatasetError::invalid(
                &path,
                format!("camera {cam}: frame {i} is missing (next listed: {fr})"),
            ));
        }
        c.frames = f.into_values().collect();
        match count {
            None => count = Some((cam, c.frames.len())),
            Some((c0, n)) if n != c.frames.len() => {
                return Err(DatasetError::invalid(
                    &path,
                    format!(
                        "camera {cam} has {} frames, camera {c0} has {n}: every camera must film the same frames",
                        c.frames.len()
                    ),
                ))
            }
            _ => {}
        }
    }
    Ok(cams)
}

/// Reads a PAC-NeRF scene folder (see the module docs).
pub fn load(dir: &Path, opts: &LoadOptions) -> Result<Dataset> {
    let name = crate::scene_name(dir);
    let pcams = read_all_data(dir)?;
    let config_file = find_config(dir, &name, opts.sim.as_deref())?;
    let cfg = physflow_config::load(&config_file)?;
    let mut warnings: Vec<String> = cfg
        .warnings
        .iter()
        .map(|w| format!("{}: {w}", config_file.display()))
        .collect();
    let gaussian_file = crate::latest_point_cloud(dir)
        .or_else(|| Some(dir.join("point_cloud.ply")).filter(|p| p.is_file()))
        .ok_or_else(|| {
            DatasetError::missing(
                dir.join("point_cloud.ply"),
                "a 3DGS scene (point_cloud.ply or point_cloud/iteration_<N>/point_cloud.ply): PAC-NeRF releases none; PhysFlow's release has one per scene",
            )
        })?;
    let gaussians = r4d_splat::ply::read_gaussians(&gaussian_file)?;
    let setup = sim_setup(
        &gaussians,
        &gaussian_file,
        &cfg,
        None,
        crate::physflow::scene_scaling(&name),
    )?;
    warnings.extend(setup.warnings.iter().cloned());
    let fps = opts.fps.unwrap_or(1.0 / cfg.extras.frame_dt);
    let mut cams = Vec::new();
    let mut views = Vec::new();
    for (i, (idx, pc)) in pcams.iter().enumerate() {
        let video_dir = pc
            .frames
            .first()
            .and_then(|f| f.parent())
            .unwrap_or(dir)
            .to_path_buf();
        let first = pc
            .frames
            .first()
            .or(pc.background.as_ref())
            .ok_or_else(|| {
                DatasetError::invalid(
                    dir.join("all_data.json"),
                    format!("camera {idx} has no image"),
                )
            })?;
        let (w, h) = crate::video::image_size(first)?;
        let cam = cameras::from_gl_c2w(format!("r_{idx}"), w, h, pc.k, &pc.c2w);
        cam.validate(&dir.join("all_data.json").display().to_string())
            .map_err(|m| DatasetError::invalid(dir.join("all_data.json"), m))?;
        if !pc.frames.is_empty() {
            let video = VideoSource::from_frames(
                &video_dir.join(format!("r_{idx}_*.png")),
                pc.frames.clone(),
                fps,
            )?;
            if (video.width, video.height) != (w, h) {
                return Err(DatasetError::invalid(
                    first,
                    "frame size differs from the camera's",
                ));
            }
            views.push(ViewSource {
                camera_index: i,
                camera: cam.clone(),
                video,
            });
        }
        cams.push(cam);
    }
    if pcams.values().any(|c| c.ignore.is_some()) {
        warnings.push("ignore masks (frame -2) are listed but not used by the loss".into());
    }
    Ok(Dataset {
        layout: Layout::PacNerf,
        dir: dir.to_path_buf(),
        name,
        config_file: Some(config_file),
        config: cfg.config.clone(),
        gaussian_file,
        gaussians_in_file: gaussians.len(),
        gaussians_after_opacity_filter: setup.after_filter,
        scene: setup.scene,
        particles: setup.particles,
        link: setup.link,
        cameras: cams,
        background: [1.0; 3],
        views,
        ground_truth: GroundTruth::from_pcd(dir)?,
        physflow: Some(cfg.extras.clone()),
        warnings,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn file_names() {
        assert_eq!(cam_frame("data/r_3_-1.png"), Some((3, -1)));
        assert_eq!(cam_frame("r_10_12.png"), Some((10, 12)));
        assert_eq!(cam_frame("frame_1.png"), None);
    }
}
