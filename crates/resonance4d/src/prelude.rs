//! What a program embedding resonance4d usually needs, in one `use`:
//!
//! ```
//! use resonance4d::prelude::*;
//! let jelly = PartParams { material: Material::Jelly, ..Default::default() };
//! assert!(jelly.validate("jelly").is_ok());
//! ```
//!
//! The card's four interfaces are here: [`Simulator`] (the MPM simulation on any backend),
//! [`Renderer`] (Gaussian splatting), [`Loss`] (DMS, SSIM, L1) and [`Initializer`] (the Latin
//! hypercube, a log grid), with the types they take.

pub use crate::builder::ProblemBuilder;
pub use crate::compute::{Compute, Precision};
pub use r4d_loss::{Dms, DmsConfig, L1Loss, Loss, SsimLoss, Video};
pub use r4d_mpm::adjoint::host::HostSim;
pub use r4d_mpm::{
    Backend, BoundaryCondition, DynSimulation, Material, MpmKernels, PartParams, ParticleSet,
    Shape, SimConfig, SimState, Simulation, Simulator, State, Surface,
};
pub use r4d_optim::video::fit::NoHooks;
pub use r4d_optim::video::{
    run_fit, run_fit_with_loss, FitConfig, FitOutcome, Objective, Strategy, VideoProblem, View,
};
pub use r4d_optim::{FitError, Initializer, LatinHypercubeInit, LogGridInit, ParamKind};
pub use r4d_splat::{
    Camera, Gaussians, RenderSettings, Renderer, SimLink, SplatKernels, SplatRenderer,
};

#[cfg(feature = "cpu")]
pub use r4d_backend_cpu::CpuBackend;
#[cfg(feature = "vulkan")]
pub use r4d_backend_vulkan::VulkanEngine;
#[cfg(feature = "wgpu")]
pub use r4d_backend_wgpu::WgpuContext;
