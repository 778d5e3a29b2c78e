//! The trajectory fit (`r4d fit-trajectory`): the algorithm is [`r4d_optim::trajectory`],
//! generic over the simulator's kernels; it runs on any [`Compute`] ([`crate::compute`]).

use r4d_mpm::{PartParams, ParticleSet, SimConfig};
use r4d_optim::compute::fit_trajectory_on;
pub use r4d_optim::trajectory::{
    FitOptions, FitState, Fitted, Granularity, IterRecord, PartRecord,
};
pub use r4d_optim::{Compute, FitError};

/// [`r4d_optim::trajectory::fit_trajectory`] on `compute`.
pub fn fit_trajectory(
    compute: &dyn Compute,
    config: &SimConfig,
    scene: &ParticleSet,
    targets: &[Vec<[f32; 3]>],
    opts: &FitOptions,
    on_iter: impl FnMut(&IterRecord),
) -> Result<Vec<PartParams>, FitError> {
    fit_trajectory_resumable(compute, config, scene, targets, opts, None, on_iter, |_| {})
        .map(|f| f.parts)
}

/// [`r4d_optim::trajectory::fit_trajectory_resumable`] on `compute`.
#[allow(clippy::too_many_arguments)]
pub fn fit_trajectory_resumable(
    compute: &dyn Compute,
    config: &SimConfig,
    scene: &ParticleSet,
    targets: &[Vec<[f32; 3]>],
    opts: &FitOptions,
    resume: Option<FitState>,
    mut on_iter: impl FnMut(&IterRecord),
    mut on_checkpoint: impl FnMut(&FitState),
) -> Result<Fitted, FitError> {
    fit_trajectory_on(
        compute,
        config,
        scene,
        targets,
        opts,
        resume,
        &mut on_iter,
        &mut on_checkpoint,
    )
}
