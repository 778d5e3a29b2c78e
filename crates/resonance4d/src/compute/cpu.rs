//! The CPU backend as a [`Compute`]: all cores (rayon), f32 or f64.

use r4d_backend_cpu::splat::CpuSplat;
use r4d_backend_cpu::{CpuBackend, Par};
use r4d_optim::compute::{Compute, JobOut, MpmJob, Precision};
use r4d_optim::FitError;
use r4d_splat::{Renderer, SplatRenderer};

/// The CPU backend: `CpuBackend<T>` on all cores (rayon) and the CPU renderer.
#[derive(Clone, Copy, Debug, Default)]
pub struct CpuCompute;

impl Compute for CpuCompute {
    fn name(&self) -> &str {
        "cpu"
    }

    fn run_mpm(&self, precision: Precision, job: MpmJob<'_>) -> Result<JobOut, FitError> {
        match precision {
            Precision::F32 => job.run_on(CpuBackend::<f32>::with_par(Par::Rayon)),
            Precision::F64 => job.run_on(CpuBackend::<f64>::with_par(Par::Rayon)),
        }
    }

    fn with_renderer(
        &self,
        f: &mut dyn FnMut(&mut dyn Renderer) -> Result<(), FitError>,
    ) -> Result<(), FitError> {
        f(&mut SplatRenderer::new(CpuSplat))
    }
}
