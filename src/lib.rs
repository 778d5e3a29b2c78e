//! # resonance4d
//!
//! Physically simulated 4D Gaussian scenes from video: a differentiable MLS-MPM simulator
//! ([`mpm`]) with backends behind traits ([`backend_cpu`] today; wgpu and Vulkan later),
//! log-domain optimisation ([`optim`]), the differentiable renderer ([`splat`]) and the video
//! losses and metrics ([`loss`]). The binary `r4d` wires everything up; this facade
//! re-exports the crates for embedding and holds the pipelines that combine them
//! ([`fit_trajectory`]).

pub mod alloc;
pub mod bench_scale;
pub mod demo;
pub mod fit_diagnostics;
pub mod fit_trajectory;
pub mod video_fit;

pub use r4d_backend_cpu as backend_cpu;
pub use r4d_backend_wgpu as backend_wgpu;
pub use r4d_loss as loss;
pub use r4d_mpm as mpm;
pub use r4d_optim as optim;
pub use r4d_splat as splat;
