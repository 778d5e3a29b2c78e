//! # resonance4d
//!
//! Physically simulated 4D Gaussian scenes from video: a differentiable MLS-MPM simulator
//! ([`mpm`]) with backends behind traits ([`backend_cpu`]; `backend_wgpu`, `backend_vulkan`
//! with their features), the differentiable renderer ([`splat`]), the video losses and metrics
//! ([`loss`]), the fits ([`optim`]: log-domain optimisation, the trajectory and the video fit,
//! generic over the backend) and, with the `eval` feature, their evaluation and reports
//! (`eval`) and the built-in demos (`demo`). The backends meet the fits as
//! [`compute::Compute`]s ([`compute`]); [`prelude`] holds what a program usually needs.
//!
//! Features: `cpu` (default: the CPU backend), `wgpu`, `vulkan` (GPU backends), `segment`
//! (part labels from 2D masks), `video` (MP4), `datasets` (PhysFlow, PhysDreamer, PAC-NeRF
//! folders), `eval` (the paper's evaluation, reports and plots, the demos, `bench_scale`).
//! With `default-features = false, features = ["cpu"]` no CLI, plotting, GPU or codec crate is
//! compiled in. The `r4d` program is the repository's root package.
//!
//! Simulate a block of jelly dropped onto a floor and read where its particles are:
//!
//! ```
//! use resonance4d::prelude::*;
//!
//! let config = SimConfig::parse(
//!     r#"
//! [domain]
//! n_grid = 16
//! [time]
//! substep_dt = 1e-3
//! substeps_per_frame = 10
//! frames = 3
//! [[parts]]
//! material = "jelly"
//! youngs_modulus_pa = 2e4
//! [[shapes]]
//! kind = "box"
//! min = [0.4, 0.4, 0.5]
//! max = [0.6, 0.6, 0.7]
//! [[boundary]]
//! type = "bounding_box"
//! "#,
//!     std::path::Path::new("jelly.toml"),
//! )?;
//! let particles = ParticleSet::from_shapes(&config.shapes, config.domain.dx());
//! let mut sim = Simulation::new(CpuBackend::<f32>::default(), &config, particles, "jelly")?;
//! let mut state = sim.init_state(&config.parts)?;
//! for _ in 0..config.time.frames {
//!     sim.step_frame(&mut state, &config.parts)?;
//! }
//! let x = sim.positions(&state)?;
//! assert!(x.iter().all(|p| p[2] < 0.7));
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

pub mod alloc;
pub mod builder;
pub mod compute;
pub mod fit_trajectory;
pub mod prelude;
pub mod video_fit;

#[cfg(feature = "eval")]
pub use r4d_eval::bench_scale;
#[cfg(feature = "eval")]
pub use r4d_eval::diagnostics as fit_diagnostics;

/// The backend family's base trait ([`backend::Backend`]: buffers, transfers, errors, memory
/// accounting) that the simulator's and the renderer's kernel traits extend.
pub use r4d_backend as backend;
#[cfg(feature = "cpu")]
pub use r4d_backend_cpu as backend_cpu;
#[cfg(feature = "vulkan")]
pub use r4d_backend_vulkan as backend_vulkan;
#[cfg(feature = "wgpu")]
pub use r4d_backend_wgpu as backend_wgpu;
/// The backend conformance suite (`r4d-conformance`): any [`compute::Compute`] against the CPU.
#[cfg(feature = "cpu")]
pub use r4d_conformance as conformance;
#[cfg(feature = "datasets")]
pub use r4d_datasets as datasets;
#[cfg(feature = "eval")]
pub use r4d_demo as demo;
#[cfg(feature = "eval")]
pub use r4d_eval as eval;
pub use r4d_loss as loss;
pub use r4d_mpm as mpm;
pub use r4d_optim as optim;
#[cfg(feature = "segment")]
pub use r4d_segment as segment;
pub use r4d_splat as splat;
#[cfg(feature = "video")]
pub use r4d_video as video;
