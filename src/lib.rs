//! # resonance4d
//!
//! Physically simulated 4D Gaussian scenes from video: a differentiable MLS-MPM simulator
//! ([`mpm`]) with backends behind traits ([`backend_cpu`], [`backend_wgpu`]), the
//! differentiable renderer ([`splat`]), the video losses and metrics ([`loss`]), the fits
//! ([`optim`]: log-domain optimisation, the trajectory and the video fit, generic over the
//! backend), their evaluation and reports ([`eval`]) and the built-in demos ([`demo`]). The
//! binary `r4d` wires everything up; this facade re-exports the crates for embedding, makes
//! the backends [`compute::Compute`]s ([`compute`]) and keeps the fits' historical paths
//! ([`fit_trajectory`], [`video_fit`]).
//!
//! ```no_run
//! use resonance4d::{compute, demo};
//! // The plant demo's problem, its reference videos rendered on the CPU backend.
//! let spec = demo::DemoScene::Plant.spec(demo::Size::Small);
//! let problem = spec.problem(compute::cpu())?;
//! let obj = resonance4d::video_fit::Objective::new(&problem, None, &Default::default(), false)?;
//! let (loss, grad) = obj.value_and_grad(&spec.start)?;
//! println!("loss {} dL/dE of part 0: {:e}", loss.total, grad[0].youngs_modulus);
//! # Ok::<(), resonance4d::optim::FitError>(())
//! ```

pub mod alloc;
pub mod compute;
pub mod fit_trajectory;
pub mod video_fit;

pub use r4d_eval::bench_scale;
pub use r4d_eval::diagnostics as fit_diagnostics;

pub use r4d_backend_cpu as backend_cpu;
pub use r4d_backend_wgpu as backend_wgpu;
pub use r4d_demo as demo;
pub use r4d_eval as eval;
pub use r4d_loss as loss;
pub use r4d_mpm as mpm;
pub use r4d_optim as optim;
pub use r4d_splat as splat;
