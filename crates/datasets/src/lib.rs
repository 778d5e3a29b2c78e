//! # r4d-datasets: the datasets of the physics-from-video literature, read as released
//!
//! A dataset folder becomes the inputs of a fit ([`Dataset`]): the Gaussian scene, the simulated
//! particles with their parts, the simulation config in SI units (with the boundary conditions),
//! the link between the scene's frame and the simulation's normalised box, the cameras, the
//! reference videos with their frame rates, and ground truth where the dataset has it. Three
//! layouts are recognised ([`Layout`], [`detect`]):
//!
//! * [`Layout::PhysFlow`]: PhysFlow's release (`model/phys_dreamer/<scene>/`,
//!   `model/pacnerf/<scene>/`: `point_cloud/iteration_N/point_cloud.ply`, `cameras.json`,
//!   `moving_part_points.ply`, `inpaint_points.ply`, `images_generated/`, `pcd/`), with the
//!   physics config of PhysFlow's repository ([`physflow_config`]); see [`physflow`].
//! * [`Layout::PhysDreamer`]: PhysDreamer's own scene folders (`point_cloud.ply`,
//!   `transforms_train.json` or COLMAP `sparse/0`, `videos/`, `clean_object_points.ply`,
//!   `moving_part_points.ply`, `internal_filled_points.ply`); see [`physdreamer`].
//! * [`Layout::PacNerf`]: PAC-NeRF's `all_data.json` (11 OpenGL cameras, `r_<cam>_<frame>.png`
//!   videos); see [`pacnerf`].
//!
//! What each layout contains and how the original projects interpret it (read from their
//! public code) is documented on each module, with every place where we decide differently.
//! Every missing or inconsistent file is a [`DatasetError`] naming the file and the rule.
//!
//! ```no_run
//! let ds = r4d_datasets::load(std::path::Path::new("model/phys_dreamer/telephone"),
//!     &r4d_datasets::LoadOptions::default()).unwrap();
//! println!("{}", serde_json::to_string_pretty(&ds.summary()).unwrap());
//! ```

pub mod cameras;
pub mod error;
pub mod moving;
pub mod pacnerf;
pub mod physdreamer;
pub mod physflow;
pub mod physflow_config;
mod summary;
pub mod video;

pub use error::{DatasetError, Result};
pub use physflow_config::{PhysFlowConfig, PhysFlowExtras, PhysFlowUnits};
pub use video::VideoSource;

use r4d_mpm::{ParticleSet, SimConfig};
use r4d_splat::{Camera, Gaussians, SimLink};
use std::path::{Path, PathBuf};

/// The layouts the loaders read.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Layout {
    /// PhysFlow's release.
    PhysFlow,
    /// PhysDreamer's own release.
    PhysDreamer,
    /// PAC-NeRF's `all_data.json`.
    PacNerf,
}

impl Layout {
    /// The name used by `--format` and `dataset inspect` (`physflow`, `physdreamer`, `pacnerf`).
    pub fn name(self) -> &'static str {
        match self {
            Layout::PhysFlow => "physflow",
            Layout::PhysDreamer => "physdreamer",
            Layout::PacNerf => "pacnerf",
        }
    }
    /// Parses a `--format` value.
    pub fn parse(s: &str) -> Option<Layout> {
        match s {
            "physflow" => Some(Layout::PhysFlow),
            "physdreamer" => Some(Layout::PhysDreamer),
            "pacnerf" => Some(Layout::PacNerf),
            _ => None,
        }
    }
}

/// How to read a dataset folder.
#[derive(Clone, Debug, Default)]
pub struct LoadOptions {
    /// Force a layout instead of detecting it.
    pub format: Option<Layout>,
    /// The physics config (overrides the layout's search).
    pub sim: Option<PathBuf>,
    /// Frame rate of the reference videos (overrides the layout's).
    pub fps: Option<f64>,
    /// PhysFlow's key-frame subsampling of `images_generated/` (its `n_key_frame`, 8 there):
    /// see [`physflow`].
    pub key_frames: Option<usize>,
    /// Read a PhysFlow scene that has no reference video (to simulate or inspect it, not to
    /// fit it): [`Dataset::views`] is then empty. Without it a missing video is an error.
    pub video_optional: bool,
}

/// One supervised view: a reference video and the camera it was filmed from.
#[derive(Clone, Debug)]
pub struct ViewSource {
    /// Index of the camera in [`Dataset::cameras`].
    pub camera_index: usize,
    /// The camera, rescaled to the video's frame size when needed.
    pub camera: Camera,
    /// The video.
    pub video: VideoSource,
}

/// Ground truth for evaluation.
#[derive(Clone, Debug, Default)]
pub struct GroundTruth {
    /// Point clouds per frame, world frame (PhysFlow's `pcd/<k>.ply` = frame `k - 1`).
    pub point_clouds: Vec<PathBuf>,
}

impl GroundTruth {
    /// PhysFlow's `DIR/pcd/1.ply, 2.ply, ..., n.ply` (none without `pcd/`). The numbers
    /// must run from 1 without a gap: a missing file is an error naming it, not a silently
    /// shorter ground truth.
    pub fn from_pcd(dir: &Path) -> Result<GroundTruth> {
        let pcd = dir.join("pcd");
        if !pcd.is_dir() {
            return Ok(GroundTruth::default());
        }
        let rd = std::fs::read_dir(&pcd).map_err(|source| DatasetError::Io {
            path: pcd.clone(),
            source,
        })?;
        let mut numbers: Vec<u64> = Vec::new();
        for e in rd.filter_map(|e| e.ok()) {
            let p = e.path();
            if !p.extension().is_some_and(|x| x.eq_ignore_ascii_case("ply")) {
                continue;
            }
            let n = p
                .file_stem()
                .and_then(|s| s.to_str())
                .and_then(|s| s.parse::<u64>().ok())
                .filter(|&n| n >= 1)
                .ok_or_else(|| {
                    DatasetError::invalid(
                        &p,
                        "ground-truth point clouds are named 1.ply, 2.ply, ... (frame k - 1)",
                    )
                })?;
            numbers.push(n);
        }
        numbers.sort_unstable();
        for (i, &n) in numbers.iter().enumerate() {
            let want = i as u64 + 1;
            if n != want {
                return Err(DatasetError::missing(
                    pcd.join(format!("{want}.ply")),
                    format!(
                        "ground-truth frame {} (pcd/ holds up to {}.ply)",
                        want - 1,
                        numbers.last().copied().unwrap_or(0)
                    ),
                ));
            }
        }
        Ok(GroundTruth {
            point_clouds: numbers
                .iter()
                .map(|k| pcd.join(format!("{k}.ply")))
                .collect(),
        })
    }
}

/// A dataset folder read and interpreted: everything a fit needs.
#[derive(Clone, Debug)]
pub struct Dataset {
    /// The layout.
    pub layout: Layout,
    /// The folder.
    pub dir: PathBuf,
    /// The scene name (the folder's name).
    pub name: String,
    /// The physics config used, when there was a file.
    pub config_file: Option<PathBuf>,
    /// The simulation in SI units, with one part per material region.
    pub config: SimConfig,
    /// The Gaussian file read.
    pub gaussian_file: PathBuf,
    /// Gaussians in that file.
    pub gaussians_in_file: usize,
    /// Gaussians left after the opacity filter.
    pub gaussians_after_opacity_filter: usize,
    /// The rendered scene (after the filter, plus extra static Gaussians such as
    /// `inpaint_points.ply`), world frame.
    pub scene: Gaussians,
    /// The simulated particles (simulation space), with part ids and volumes.
    pub particles: ParticleSet,
    /// Which Gaussians the particles move, and the world-to-simulation map.
    pub link: SimLink,
    /// Every camera of the dataset.
    pub cameras: Vec<Camera>,
    /// Background colour the dataset's renders use.
    pub background: [f32; 3],
    /// The supervised views.
    pub views: Vec<ViewSource>,
    /// Evaluation ground truth.
    pub ground_truth: GroundTruth,
    /// PhysFlow's own keys, for PhysFlow configs.
    pub physflow: Option<PhysFlowExtras>,
    /// Interpretations the user should know about.
    pub warnings: Vec<String>,
}

impl Dataset {
    /// Gaussians rendered unchanged (not moved by a particle).
    pub fn static_gaussians(&self) -> usize {
        self.scene.len() - self.link.simulated.len()
    }

    /// Keeps the views whose camera matches one of `selectors` (a camera name, or its index in
    /// [`Dataset::cameras`]); an empty list keeps every view.
    pub fn select_views(&mut self, selectors: &[String]) -> Result<()> {
        if selectors.is_empty() {
            return Ok(());
        }
        let mut keep = Vec::new();
        for s in selectors {
            let idx = match s.parse::<usize>() {
                Ok(i) if i < self.cameras.len() => i,
                _ => self
                    .cameras
                    .iter()
                    .position(|c| {
                        c.name == *s
                            || Path::new(&c.name)
                                .file_stem()
                                .is_some_and(|n| n == s.as_str())
                    })
                    .ok_or_else(|| {
                        DatasetError::invalid(
                            &self.dir,
                            format!(
                                "--camera {s}: no such camera ({} cameras: {})",
                                self.cameras.len(),
                                self.cameras
                                    .iter()
                                    .take(12)
                                    .map(|c| c.name.as_str())
                                    .collect::<Vec<_>>()
                                    .join(", ")
                            ),
                        )
                    })?,
            };
            let v = self
                .views
                .iter()
                .find(|v| v.camera_index == idx)
                .ok_or_else(|| {
                    DatasetError::invalid(
                        &self.dir,
                        format!(
                            "--camera {s}: camera '{}' has no reference video",
                            self.cameras[idx].name
                        ),
                    )
                })?;
            if !keep.iter().any(|k: &ViewSource| k.camera_index == idx) {
                keep.push(v.clone());
            }
        }
        self.views = keep;
        Ok(())
    }

    /// The `dataset inspect --json` report (keys documented in `docs/cli/data.md`).
    pub fn summary(&self) -> serde_json::Value {
        summary::summary(self)
    }
}

/// Detects the layout of `dir`: `all_data.json` -> PAC-NeRF; `cameras.json` with a
/// `point_cloud/` folder -> PhysFlow; `point_cloud.ply` with `transforms_train.json` or
/// `sparse/0` -> PhysDreamer.
pub fn detect(dir: &Path) -> Result<Layout> {
    if !dir.is_dir() {
        return Err(DatasetError::missing(dir, "a dataset folder"));
    }
    if dir.join("all_data.json").is_file() {
        return Ok(Layout::PacNerf);
    }
    if dir.join("cameras.json").is_file() && dir.join("point_cloud").is_dir() {
        return Ok(Layout::PhysFlow);
    }
    if dir.join("point_cloud.ply").is_file()
        && (dir.join("transforms_train.json").is_file() || dir.join("sparse/0").is_dir())
    {
        return Ok(Layout::PhysDreamer);
    }
    Err(DatasetError::UnknownLayout {
        path: dir.to_path_buf(),
        why: "expected all_data.json (PAC-NeRF), cameras.json + point_cloud/ (PhysFlow's \
              release) or point_cloud.ply + transforms_train.json or sparse/0 (PhysDreamer); \
              --format physflow|physdreamer|pacnerf forces one"
            .into(),
    })
}

/// Reads a dataset folder (layout detected unless [`LoadOptions::format`] says).
pub fn load(dir: &Path, opts: &LoadOptions) -> Result<Dataset> {
    if let Some(f) = opts.fps {
        if !(f.is_finite() && f > 0.0 && f <= 10_000.0) {
            return Err(DatasetError::invalid(
                dir,
                format!("--fps {f}: must be in (0, 10000]"),
            ));
        }
    }
    if opts.key_frames == Some(0) {
        return Err(DatasetError::invalid(dir, "--key-frames 0: must be >= 1"));
    }
    let layout = match opts.format {
        Some(l) => l,
        None => detect(dir)?,
    };
    let ds = match layout {
        Layout::PhysFlow => physflow::load(dir, opts)?,
        Layout::PhysDreamer => physdreamer::load(dir, opts)?,
        Layout::PacNerf => pacnerf::load(dir, opts)?,
    };
    ds.particles.validate(
        &ds.dir.display().to_string(),
        ds.config.domain.dx(),
        ds.config.domain.n_grid,
        ds.config.parts.len(),
    )?;
    Ok(ds)
}

/// The folder's name.
pub(crate) fn scene_name(dir: &Path) -> String {
    dir.canonicalize()
        .ok()
        .and_then(|d| d.file_name().map(|n| n.to_string_lossy().into_owned()))
        .or_else(|| dir.file_name().map(|n| n.to_string_lossy().into_owned()))
        .unwrap_or_default()
}

/// `point_cloud/iteration_<N>/point_cloud.ply` with the largest `N`, as the 3DGS/PhysFlow
/// loaders take it.
pub(crate) fn latest_point_cloud(dir: &Path) -> Option<PathBuf> {
    let pc = dir.join("point_cloud");
    let rd = std::fs::read_dir(&pc).ok()?;
    rd.filter_map(|e| e.ok())
        .filter_map(|e| {
            let name = e.file_name().to_string_lossy().into_owned();
            let n: u64 = name.strip_prefix("iteration_")?.parse().ok()?;
            let f = e.path().join("point_cloud.ply");
            f.is_file().then_some((n, f))
        })
        .max_by_key(|(n, _)| *n)
        .map(|(_, f)| f)
}

/// Reads the positions of a point PLY (x, y, z), checked finite.
pub fn read_points(path: &Path) -> Result<Vec<[f64; 3]>> {
    let ply = r4d_ply::read_ply(path)?;
    let col = |n: &str| {
        ply.get(n)
            .ok_or_else(|| DatasetError::invalid(path, format!("no '{n}' property")))
    };
    let (x, y, z) = (col("x")?, col("y")?, col("z")?);
    let pts: Vec<[f64; 3]> = (0..x.len())
        .map(|i| [x[i] as f64, y[i] as f64, z[i] as f64])
        .collect();
    if let Some(i) = pts.iter().position(|p| p.iter().any(|v| !v.is_finite())) {
        return Err(DatasetError::invalid(
            path,
            format!("point {i} is not finite"),
        ));
    }
    Ok(pts)
}
