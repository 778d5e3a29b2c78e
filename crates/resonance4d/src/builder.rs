//! Builders for the common paths: a simulated scene seen by cameras, its reference videos and
//! the video fit's problem.
//!
//! ```
//! use resonance4d::prelude::*;
//! # let text = "[domain]\nn_grid = 16\n[time]\nsubstep_dt = 1e-3\nframe_dt = 0.02\nframes = 3\n\
//! # [[parts]]\nmaterial = \"jelly\"\n[[shapes]]\nkind = \"box\"\nmin = [0.4, 0.4, 0.5]\n\
//! # max = [0.6, 0.6, 0.7]\n[[boundary]]\ntype = \"bounding_box\"\n";
//! let config = SimConfig::parse(text, "jelly.toml".as_ref())?;
//! let truth = config.parts.clone();
//! let camera = Camera::look_at(32, 24, 40.0, [0.5, -0.5, 0.6], [0.5, 0.5, 0.5], [0.0, 0.0, 1.0]);
//! let problem = ProblemBuilder::new(config).camera(camera).rendered_from(&truth)?;
//! assert_eq!(problem.views[0].video.frames(), 3);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

use crate::compute::Compute;
use r4d_loss::Video;
use r4d_mpm::{PartParams, ParticleSet, SimConfig};
use r4d_optim::video::{Objective, VideoProblem, View};
use r4d_optim::FitError;
use r4d_splat::{Camera, Gaussians, RenderSettings, SimLink};
use std::sync::Arc;

/// Builds a [`VideoProblem`]: the config's shapes as particles, one Gaussian per particle
/// (a two-colour 3D checker, so motion inside the silhouette shows) unless
/// [`ProblemBuilder::gaussians`] gives the scene, and one view per camera.
pub struct ProblemBuilder {
    config: SimConfig,
    particles: ParticleSet,
    scene: Option<(Gaussians, SimLink)>,
    views: Vec<(Camera, Option<Video<f32>>)>,
    settings: RenderSettings,
    compute: Option<Arc<dyn Compute>>,
}

impl ProblemBuilder {
    /// From a config whose `shapes` make the particles.
    pub fn new(config: SimConfig) -> Self {
        let particles = ParticleSet::from_shapes(&config.shapes, config.domain.dx());
        ProblemBuilder {
            config,
            particles,
            scene: None,
            views: Vec::new(),
            settings: RenderSettings::default(),
            compute: None,
        }
    }

    /// The particles (instead of the config's shapes).
    pub fn particles(mut self, particles: ParticleSet) -> Self {
        self.particles = particles;
        self
    }

    /// The scene's Gaussians and which of them follow which particles.
    pub fn gaussians(mut self, scene: Gaussians, link: SimLink) -> Self {
        self.scene = Some((scene, link));
        self
    }

    /// A view whose reference video is rendered by [`ProblemBuilder::rendered_from`].
    pub fn camera(mut self, camera: Camera) -> Self {
        self.views.push((camera, None));
        self
    }

    /// A view with its reference video (`(T, H, W, 3)` at the camera's size).
    pub fn view(mut self, camera: Camera, video: Video<f32>) -> Self {
        self.views.push((camera, Some(video)));
        self
    }

    /// The background colour (default black).
    pub fn background(mut self, rgb: [f32; 3]) -> Self {
        self.settings.background = rgb;
        self
    }

    /// Where it simulates and renders (default: the CPU backend with the `cpu` feature, else
    /// the reference kernels).
    pub fn compute(mut self, compute: Arc<dyn Compute>) -> Self {
        self.compute = Some(compute);
        self
    }

    /// The problem; views given by [`ProblemBuilder::camera`] hold black videos.
    pub fn build(self) -> Result<VideoProblem, FitError> {
        let dx = self.config.domain.dx() as f32;
        let (scene, link) = self.scene.unwrap_or_else(|| {
            let mut g = Gaussians::default();
            for x in &self.particles.x {
                let odd = x.iter().map(|v| (v / 0.0625).floor() as i64).sum::<i64>() & 1;
                let rgb = [[0.86, 0.20, 0.36], [0.98, 0.78, 0.22]][odd as usize];
                g.push_rgb(*x, [0.25 * dx; 3], [1.0, 0.0, 0.0, 0.0], 0.95, rgb);
            }
            let n = g.len();
            (g, SimLink::identity(n))
        });
        // The config's and the cameras' limits before any video is allocated.
        self.config
            .validate("the problem's config")
            .map_err(|e| FitError::Input(e.to_string()))?;
        for (k, (camera, _)) in self.views.iter().enumerate() {
            camera
                .validate(&format!("view {k}'s camera"))
                .map_err(FitError::Input)?;
        }
        let t = &self.config.time;
        let frames = t.frames;
        let views = self
            .views
            .into_iter()
            .enumerate()
            .map(|(k, (camera, video))| View {
                name: format!("view {k}"),
                video: video
                    .unwrap_or_else(|| {
                        Video::zeros(frames, camera.height as usize, camera.width as usize)
                    })
                    .into(),
                camera,
            })
            .collect();
        let fps = 1.0 / (t.substeps() as f64 * t.substep_dt);
        let compute = self.compute.unwrap_or_else(default_compute);
        let p = VideoProblem {
            config: self.config,
            particles: self.particles,
            scene,
            link,
            settings: self.settings,
            views,
            fps,
            compute,
        };
        p.validate()?;
        Ok(p)
    }

    /// The problem with every view's reference video rendered from `truth` (the parameters
    /// of each part); the config's own parameters stay the fit's start.
    pub fn rendered_from(self, truth: &[PartParams]) -> Result<VideoProblem, FitError> {
        let mut p = self.build()?;
        let videos = Objective::builder(&p).build()?.render(truth)?;
        for (v, video) in p.views.iter_mut().zip(videos) {
            v.video = video.into();
        }
        Ok(p)
    }
}

#[cfg(feature = "cpu")]
fn default_compute() -> Arc<dyn Compute> {
    crate::compute::cpu()
}

#[cfg(not(feature = "cpu"))]
fn default_compute() -> Arc<dyn Compute> {
    crate::compute::reference()
}
