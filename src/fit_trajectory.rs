//! The trajectory fit (`r4d fit-trajectory`): the algorithm is [`r4d_optim::trajectory`],
//! generic over the simulator's kernels; this facade picks the backend ([`FitBackend`]).

use r4d_backend_cpu::{CpuBackend, Par};
use r4d_backend_wgpu::{WgpuContext, WgpuMpm};
use r4d_mpm::reference::ReferenceBackend;
use r4d_mpm::{PartParams, ParticleSet, SimConfig};
pub use r4d_optim::trajectory::{
    FitCheckpoint, FitError, FitOptions, Fitted, Granularity, IterLog, PartRecord,
};
use std::sync::Arc;

/// Where the simulation and its reverse sweep run.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum FitBackend {
    /// f64 on the CPU, all cores (`CpuBackend<f64>`).
    #[default]
    Cpu,
    /// f32 on a GPU through wgpu (`WgpuMpm`); the adapter is chosen as by
    /// [`WgpuContext::new`] (`R4D_WGPU_ADAPTER`).
    Wgpu,
    /// f64 on one core, the reference kernels (`ReferenceBackend<f64>`, the gradient oracle;
    /// slow, for checking).
    Reference,
}

/// [`r4d_optim::trajectory::fit_trajectory`] on `backend`.
pub fn fit_trajectory(
    backend: FitBackend,
    config: &SimConfig,
    scene: &ParticleSet,
    targets: &[Vec<[f32; 3]>],
    opts: &FitOptions,
    on_iter: impl FnMut(&IterLog),
) -> Result<Vec<PartParams>, FitError> {
    fit_trajectory_resumable(backend, config, scene, targets, opts, None, on_iter, |_| {})
        .map(|f| f.parts)
}

/// [`r4d_optim::trajectory::fit_trajectory_resumable`] on `backend`.
#[allow(clippy::too_many_arguments)]
pub fn fit_trajectory_resumable(
    backend: FitBackend,
    config: &SimConfig,
    scene: &ParticleSet,
    targets: &[Vec<[f32; 3]>],
    opts: &FitOptions,
    resume: Option<FitCheckpoint>,
    on_iter: impl FnMut(&IterLog),
    on_checkpoint: impl FnMut(&FitCheckpoint),
) -> Result<Fitted, FitError> {
    use r4d_optim::trajectory::fit_trajectory_resumable as fit;
    match backend {
        FitBackend::Cpu => fit(
            CpuBackend::<f64>::with_par(Par::Rayon),
            config,
            scene,
            targets,
            opts,
            resume,
            on_iter,
            on_checkpoint,
        ),
        FitBackend::Reference => fit(
            ReferenceBackend::<f64>::in_scalar(),
            config,
            scene,
            targets,
            opts,
            resume,
            on_iter,
            on_checkpoint,
        ),
        FitBackend::Wgpu => {
            let ctx = WgpuContext::new().map_err(|e| FitError::Backend(Box::new(e)))?;
            fit(
                WgpuMpm::new(Arc::new(ctx)),
                config,
                scene,
                targets,
                opts,
                resume,
                on_iter,
                on_checkpoint,
            )
        }
    }
}
