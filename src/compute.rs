//! The backends as [`Compute`]s, the one place where the fits meet a concrete backend: the
//! CPU (all cores, f32 or f64) and a GPU through wgpu or through Vulkan (ash). Every fit, evaluation and benchmark
//! takes an `Arc<dyn Compute>`; the CLI picks it once from `--backend`.
//!
//! ```
//! use resonance4d::compute;
//! let cpu = compute::cpu();
//! assert_eq!(cpu.name(), "cpu");
//! ```

use r4d_backend_cpu::splat::CpuSplat;
use r4d_backend_cpu::{CpuBackend, Par};
use r4d_backend_vulkan::{VulkanEngine, VulkanMpm, VulkanSplat};
use r4d_backend_wgpu::{WgpuContext, WgpuSplat};
pub use r4d_optim::compute::{Compute, Precision, ReferenceCompute};
use r4d_optim::compute::{JobOut, MpmJob};
use r4d_optim::FitError;
use r4d_splat::{Renderer, SplatRenderer};
use std::sync::{Arc, Mutex};

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

/// A GPU through wgpu: `WgpuMpm` (f32, state and gradients on the device) and, by default,
/// the wgpu renderer (built once, reused by every render).
pub struct WgpuCompute {
    ctx: Arc<WgpuContext>,
    /// Render (and differentiate the renderer) on the GPU (default); `false`: on the CPU.
    pub render_on_gpu: bool,
    renderer: Mutex<Option<SplatRenderer<WgpuSplat>>>,
}

impl std::fmt::Debug for WgpuCompute {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("WgpuCompute")
            .field("render_on_gpu", &self.render_on_gpu)
            .finish_non_exhaustive()
    }
}

impl WgpuCompute {
    /// On the device of `ctx`.
    pub fn new(ctx: Arc<WgpuContext>) -> Self {
        WgpuCompute {
            ctx,
            render_on_gpu: true,
            renderer: Mutex::new(None),
        }
    }

    /// The device.
    pub fn context(&self) -> &Arc<WgpuContext> {
        &self.ctx
    }
}

impl Compute for WgpuCompute {
    fn name(&self) -> &str {
        "wgpu"
    }

    fn run_mpm(&self, _precision: Precision, job: MpmJob<'_>) -> Result<JobOut, FitError> {
        job.run_on(r4d_backend_wgpu::WgpuMpm::new(self.ctx.clone()))
    }

    fn with_renderer(
        &self,
        f: &mut dyn FnMut(&mut dyn Renderer) -> Result<(), FitError>,
    ) -> Result<(), FitError> {
        if !self.render_on_gpu {
            return f(&mut SplatRenderer::new(CpuSplat));
        }
        let mut guard = self
            .renderer
            .lock()
            .map_err(|_| FitError::backend_msg("wgpu", "the GPU renderer panicked earlier"))?;
        let r = guard.get_or_insert_with(|| SplatRenderer::new(WgpuSplat::new(self.ctx.clone())));
        f(r)
    }

    fn reset_device_peak(&self) {
        self.ctx.reset_peak();
    }

    fn device_peak_bytes(&self) -> Option<u64> {
        Some(self.ctx.peak_bytes())
    }
}

/// A GPU through Vulkan directly (ash, `r4d-backend-vulkan`): `VulkanMpm` (f32) and the
/// Vulkan renderer (built once, reused by every render); the same recordings as wgpu.
pub struct VulkanCompute {
    engine: VulkanEngine,
    renderer: Mutex<Option<SplatRenderer<VulkanSplat>>>,
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

    fn run_mpm(&self, _precision: Precision, job: MpmJob<'_>) -> Result<JobOut, FitError> {
        job.run_on(VulkanMpm::new(self.engine.clone()))
    }

    fn with_renderer(
        &self,
        f: &mut dyn FnMut(&mut dyn Renderer) -> Result<(), FitError>,
    ) -> Result<(), FitError> {
        let mut guard = self
            .renderer
            .lock()
            .map_err(|_| FitError::backend_msg("vulkan", "the renderer panicked earlier"))?;
        let r =
            guard.get_or_insert_with(|| SplatRenderer::new(VulkanSplat::new(self.engine.clone())));
        f(r)
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

    fn device_peak_bytes(&self) -> Option<u64> {
        use r4d_gpu::GpuEngine;
        Some(self.engine.memory_usage().peak_bytes)
    }
}

/// The CPU backend ([`CpuCompute`]).
pub fn cpu() -> Arc<dyn Compute> {
    Arc::new(CpuCompute)
}

/// The GPU of `ctx` ([`WgpuCompute`]).
pub fn wgpu(ctx: Arc<WgpuContext>) -> Arc<dyn Compute> {
    Arc::new(WgpuCompute::new(ctx))
}

/// The Vulkan device of `engine` ([`VulkanCompute`]).
pub fn vulkan(engine: VulkanEngine) -> Arc<dyn Compute> {
    Arc::new(VulkanCompute::new(engine))
}

/// The single-threaded reference kernels ([`ReferenceCompute`], the gradient oracle).
pub fn reference() -> Arc<dyn Compute> {
    Arc::new(ReferenceCompute)
}
