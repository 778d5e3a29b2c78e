//! # r4d-splat: differentiable 3D Gaussian splatting with gsplat's conventions
//!
//! Renders INRIA-format 3DGS scenes, optionally deformed per Gaussian by a simulation
//! (PhysGaussian: `Sigma' = F Sigma F^T`, SH evaluated at `R^T d` with `F = R S`), and
//! differentiates the image with respect to every raw parameter and `F`. The conventions
//! (camera, projection with the 0.3 px low-pass, culling, SH basis, depth sort, compositing
//! thresholds) are gsplat 1.5.3's, as `tests/fixtures/splat/README.md` states them.
//!
//! Activations applied to the stored (raw) values: scale `exp(s)`, rotation from the
//! normalised quaternion `(w, x, y, z)`, opacity `sigmoid(o)`, colour
//! `max(sum_k Y_k sh_k + 0.5, 0)`.
//!
//! ## Layers
//!
//! * Math, once: [`project`] (per Gaussian), [`raster`] (binning, per pixel; [`span`]: a
//!   row of a tile at once, bitwise the same), [`sh`],
//!   [`covariance`] (and their VJPs), generic over `f32`/`f64`.
//! * Kernel trait: [`SplatKernels`] (project, bin_tiles, rasterize, rasterize_vjp,
//!   project_vjp over backend buffers); [`reference::ReferenceSplat`] is the single-threaded
//!   reference, `r4d_backend_cpu::CpuBackend` the parallel one.
//! * [`Renderer`], implemented once by [`SplatRenderer`] for every backend; [`frame`]:
//!   one frame projected, sorted and binned once, then rendered and differentiated in row
//!   bands.
//! * Inputs: [`ply`] (INRIA 3DGS PLY), [`camera_io`] (r4d/reference JSON, INRIA
//!   `cameras.json`, nerfstudio `transforms.json`, COLMAP text).
//!
//! ## Example
//!
//! ```
//! use r4d_splat::{reference::ReferenceSplat, Camera, Gaussians, RenderSettings, Renderer,
//!     SplatRenderer};
//! let g = Gaussians {
//!     sh_degree: 0,
//!     means: vec![[0.0, 0.0, 0.0]],
//!     log_scales: vec![[-2.0; 3]],
//!     quats: vec![[1.0, 0.0, 0.0, 0.0]],
//!     opacity_logits: vec![2.0],
//!     sh: vec![1.0, 0.0, 0.0], // red
//! };
//! let cam = Camera::look_at(32, 24, 60.0, [0.0, -3.0, 0.0], [0.0; 3], [0.0, 0.0, 1.0]);
//! let mut r = SplatRenderer::new(ReferenceSplat);
//! let img = r.render(&g, None, &cam, &RenderSettings::default()).unwrap();
//! let centre = (12 * 32 + 16) * 3;
//! assert!(img.rgb[centre] > 0.5 && img.rgb[centre + 1] < 0.5);
//! ```

pub mod camera;
pub mod camera_io;
pub mod covariance;
pub mod error;
pub mod falloff;
pub mod frame;
pub mod gaussians;
pub mod kernels;
pub mod link;
pub mod ply;
pub mod prepare;
pub mod project;
pub mod raster;
pub mod real;
pub mod reference;
pub mod renderer;
pub mod scene_handle;
pub mod sh;
pub mod span;
pub mod weights;

pub use camera::{Camera, RasterizeMode, RenderSettings};
pub use camera_io::{load_cameras, CameraSet};
pub use error::{Error, Result};
pub use frame::PreparedFrame;
pub use gaussians::{Deformation, GaussianGrads, Gaussians};
pub use kernels::{AnyBuf, Backend, CameraConsts, LinkConsts, SplatKernels};
pub use link::SimLink;
pub use prepare::{prepare, prepare_with, PrepareConfig, Prepared};
pub use renderer::{Image, RenderStats, RenderTape, Renderer, SplatRenderer};
pub use scene_handle::SceneHandle;

#[cfg(test)]
mod tests;
