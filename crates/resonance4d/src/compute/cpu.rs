//! The CPU backend as a [`Compute`]: all cores (rayon), f32 or f64.

use r4d_backend_cpu::{CpuBackend, Par};
use r4d_mpm::adjoint::host::HostSim;
use r4d_mpm::DynSimulation;
use r4d_optim::compute::{simulation_on, Compute, Precision};
use r4d_optim::FitError;
use r4d_splat::{Renderer, SplatRenderer};
use std::sync::Arc;

/// The CPU backend: `CpuBackend<T>` on all cores (rayon) and the CPU renderer.
#[derive(Clone, Copy, Debug, Default)]
pub struct CpuCompute;

impl Compute for CpuCompute {
    fn name(&self) -> &str {
        "cpu"
    }

    fn simulation(
        &self,
        precision: Precision,
        sim: Arc<HostSim>,
    ) -> Result<Box<dyn DynSimulation>, FitError> {
        match precision {
            Precision::F32 => simulation_on(CpuBackend::<f32>::with_par(Par::Rayon), sim),
            Precision::F64 => simulation_on(CpuBackend::<f64>::with_par(Par::Rayon), sim),
        }
    }

    fn with_renderer(
        &self,
        f: &mut dyn FnMut(&mut dyn Renderer) -> Result<(), FitError>,
    ) -> Result<(), FitError> {
        f(&mut SplatRenderer::new(CpuBackend::default()))
    }
}
