//! A video-fitting problem straight from a dataset folder ([`r4d_datasets`]).

use r4d_datasets::Dataset;
use r4d_optim::video::{VideoProblem, View};
use r4d_optim::{Compute, FitError};
use std::sync::Arc;

/// Builds the problem of a loaded dataset: its scene, particles, link and config, one view per
/// reference video (frames decoded here), simulated and rendered on `compute`. Every video
/// must have the same frame rate.
pub fn problem_from_dataset(
    ds: &Dataset,
    compute: Arc<dyn Compute>,
) -> Result<VideoProblem, FitError> {
    let (views, fps) = dataset_views(ds)?;
    problem_with_views(ds, views, fps, compute)
}

/// The dataset's scene, particles, link and config with the given views (videos at `fps`),
/// simulated and rendered on `compute`.
pub fn problem_with_views(
    ds: &Dataset,
    views: Vec<View>,
    fps: f64,
    compute: Arc<dyn Compute>,
) -> Result<VideoProblem, FitError> {
    let problem = VideoProblem {
        config: ds.config.clone(),
        particles: ds.particles.clone(),
        scene: ds.scene.clone(),
        link: ds.link.clone(),
        settings: r4d_splat::RenderSettings {
            background: ds.background,
            mode: Default::default(),
        },
        views,
        fps,
        compute,
    };
    problem.validate()?;
    Ok(problem)
}

/// The dataset's views with their videos decoded, and their common frame rate.
fn dataset_views(ds: &Dataset) -> Result<(Vec<View>, f64), FitError> {
    let first = ds
        .views
        .first()
        .ok_or_else(|| FitError::Input(format!("{}: no reference video", ds.dir.display())))?;
    let fps = first.video.fps;
    let mut views = Vec::with_capacity(ds.views.len());
    for v in &ds.views {
        if (v.video.fps - fps).abs() > 1e-9 * fps {
            return Err(FitError::Input(format!(
                "{}: {} fps, {}: {} fps: every view's video must have the same frame rate",
                first.video.path.display(),
                fps,
                v.video.path.display(),
                v.video.fps
            )));
        }
        let video = v
            .video
            .read_reference()
            .map_err(|e| FitError::Input(e.to_string()))?;
        views.push(View {
            name: format!("{} ({})", v.video.path.display(), v.camera.name),
            camera: v.camera.clone(),
            video,
        });
    }
    Ok((views, fps))
}
