//! Fitting part parameters to a reference video (the paper's main job): simulation-driven
//! initialisation, then part-level AdamW in the log domain on the DMS loss, differentiated
//! through the renderer and the simulator.
//!
//! * [`problem`]: the scene, particles, parts, cameras and reference videos, and the
//!   differentiable [`Objective`] (simulate -> render -> DMS -> reverse sweep).
//! * [`params`]: the free-parameter vector and its mapping onto parts.
//! * [`config`]: the fit's settings (`FIT.toml`).
//! * [`fit`]: the loop: initialisation, iterations, logs, checkpoints and resume.
//!
//! The simulation and its reverse sweep run on the CPU (`KernelAdjoint<CpuBackend<T>>`, all cores, f64 by
//! default) or, with [`VideoProblem::gpu`], on a GPU (`KernelAdjoint<WgpuMpm>`, the same stepper,
//! f32, state and gradients on the device; positions and F are read back once per frame);
//! rendering, its VJP and the loss run on the CPU (the GPU renderer's backward exists but is
//! not used by the fit yet).

pub mod config;
pub mod dataset;
pub mod eval;
pub mod fit;
pub mod params;
pub mod parts;
pub mod problem;
pub mod report;

pub use config::{FitConfig, InitConfig, OptimizerKind};
pub use dataset::{problem_from_dataset, problem_with_views};
pub use fit::{run_fit, FitHooks, FitOutcome, FitState, IterRecord, StartResult};
pub use params::{Granularity, ParamSpace};
pub use parts::PartLabels;
pub use problem::{
    Evaluation, GpuHandle, Objective, Precision, StageProfile, TimeMap, VideoProblem, View,
};

/// Errors of video fitting.
#[derive(Debug, thiserror::Error)]
pub enum FitError {
    /// The simulator refused the setup or parameters.
    #[error(transparent)]
    Mpm(#[from] r4d_mpm::Error),
    /// The renderer refused the scene, a camera or a deformation (e.g. a simulation that
    /// exploded to non-finite positions).
    #[error(transparent)]
    Splat(#[from] r4d_splat::Error),
    /// The loss refused the videos.
    #[error(transparent)]
    Loss(#[from] r4d_loss::LossError),
    /// The optimiser refused a value or bound.
    #[error(transparent)]
    Optim(#[from] r4d_optim::Error),
    /// Inputs that do not fit together.
    #[error("{0}")]
    Input(String),
    /// A loss or gradient became NaN or infinite.
    #[error("{0} is not finite (the simulation may have exploded: try smaller substeps or tighter bounds)")]
    NonFinite(String),
    /// The simulation exploded: a particle left the grid or became non-finite.
    #[error("the simulation exploded at {0} (try smaller substeps or tighter parameter bounds)")]
    Exploded(String),
    /// The GPU backend failed (no adapter, a device error, an unsupported material).
    #[error("wgpu backend: {0}")]
    Gpu(String),
    /// A checkpoint that does not belong to this run.
    #[error("cannot resume: {0}")]
    Resume(String),
}
