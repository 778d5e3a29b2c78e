//! Fitting part parameters to a reference video (the paper's main job): simulation-driven
//! initialisation, then part-level AdamW in the log domain on the DMS loss, differentiated
//! through the renderer and the simulator.
//!
//! * [`problem`]: the scene, particles, parts, cameras and reference videos, and the
//!   differentiable [`Objective`] (simulate -> render -> DMS -> reverse sweep).
//! * [`config`]: the fit's settings (`FIT.toml`).
//! * [`fit`]: the loop: initialisation, iterations, logs, checkpoints and resume.
//!
//! The simulation, its reverse sweep and the rendering run on the problem's backend
//! ([`VideoProblem::compute`], any [`crate::compute::Compute`]): the one stepper
//! `Simulation<B>` over that backend's kernels, positions and F read back once per frame;
//! the loss runs on the host, band by band.

pub mod budget;
pub mod config;
pub mod fit;
pub mod problem;
pub mod strategy;

pub use crate::restarts::{Restart, RestartsConfig, ShearRestarts};
pub use crate::sampling::{GradientSampling, SamplingConfig, SamplingRound};
pub use crate::space::{Granularity, ParamSpace};
pub use crate::valley::{ValleyConfig, ValleyRound, ValleySearch};
pub use config::{
    FitConfig, InitConfig, InitSampler, InitScore, OptimizerKind, StageKind, AUTO_KEYS,
};
pub use fit::{
    fingerprint, run_fit, run_fit_with_loss, FitEvent, FitHooks, FitOutcome, FitState, IterRecord,
    StartResult,
};
pub use problem::{
    Evaluation, Objective, ObjectiveBuilder, StageProfile, TimeMap, VideoProblem, View,
    INIT_MEMORY_BUDGET_BYTES,
};
pub use strategy::Strategy;
