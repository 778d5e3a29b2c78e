//! A GPU through Vulkan (ash) as a [`Compute`].

use r4d_backend_vulkan::{VulkanBackend, VulkanEngine};
use r4d_mpm::adjoint::host::HostSim;
use r4d_mpm::DynSimulation;
use r4d_optim::compute::{simulation_on, Compute, Precision};
use r4d_optim::FitError;
use r4d_splat::{Renderer, SplatRenderer};
use std::sync::{Arc, Mutex};

/// A GPU through Vulkan directly (ash, `r4d-backend-vulkan`): `VulkanBackend` (f32) and the
/// Vulkan renderer (built once, reused by every render); the same recordings as wgpu.
pub struct VulkanCompute {
    engine: VulkanEngine,
    renderer: Mutex<Option<SplatRenderer<VulkanBackend>>>,
}

impl std::fmt::Debug for VulkanCompute {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("VulkanCompute")
            .field("device", &self.engine.device_name())
            .finish_non_exhaustive()
    }
}

impl VulkanCompute {
    /// On `engine`'s device.
    pub fn new(engine: VulkanEngine) -> Self {
        VulkanCompute {
            engine,
            renderer: Mutex::new(None),
        }
    }
}

impl Compute for VulkanCompute {
    fn name(&self) -> &str {
        "vulkan"
    }

    fn simulation(
        &self,
        _precision: Precision,
        sim: Arc<HostSim>,
    ) -> Result<Box<dyn DynSimulation>, FitError> {
        simulation_on(VulkanBackend::new(self.engine.clone()), sim)
    }

    fn with_renderer(
        &self,
        f: &mut dyn FnMut(&mut dyn Renderer) -> Result<(), FitError>,
    ) -> Result<(), FitError> {
        let mut guard = self
            .renderer
            .lock()
            .map_err(|_| FitError::backend_msg("vulkan", "the renderer panicked earlier"))?;
        let r = guard
            .get_or_insert_with(|| SplatRenderer::new(VulkanBackend::new(self.engine.clone())));
        f(r)
    }

    fn frames_on_device(&self) -> bool {
        true
    }

    fn reset_device_peak(&self) {
        self.engine.reset_peak();
    }

    fn set_profiling(&self, on: bool) -> Result<bool, FitError> {
        self.engine
            .set_profiling(on)
            .map_err(|e| FitError::backend("vulkan", e))
    }

    fn kernel_times(&self) -> Result<Vec<r4d_mpm::KernelTime>, FitError> {
        // Pending dispatches are timed once submitted.
        self.engine
            .finish()
            .map_err(|e| FitError::backend("vulkan", e))?;
        Ok(self.engine.kernel_times())
    }

    fn device_memory(&self) -> Option<r4d_mpm::MemoryUsage> {
        use r4d_gpu::GpuEngine;
        Some(self.engine.memory_usage())
    }
}
