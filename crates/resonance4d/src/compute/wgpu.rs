//! A GPU through wgpu as a [`Compute`].

use r4d_backend_cpu::CpuBackend;
use r4d_backend_wgpu::{WgpuBackend, WgpuContext};
use r4d_mpm::adjoint::host::HostSim;
use r4d_mpm::DynSimulation;
use r4d_optim::compute::{simulation_on, Compute, Precision};
use r4d_optim::FitError;
use r4d_splat::{Renderer, SplatRenderer};
use std::sync::{Arc, Mutex};

/// A GPU through wgpu: `WgpuBackend` (f32, state and gradients on the device) and, by default,
/// the wgpu renderer (built once, reused by every render).
pub struct WgpuCompute {
    ctx: Arc<WgpuContext>,
    /// Render (and differentiate the renderer) on the GPU (default); `false`: on the CPU.
    pub render_on_gpu: bool,
    renderer: Mutex<Option<SplatRenderer<WgpuBackend>>>,
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

    fn simulation(
        &self,
        _precision: Precision,
        sim: Arc<HostSim>,
    ) -> Result<Box<dyn DynSimulation>, FitError> {
        simulation_on(r4d_backend_wgpu::WgpuBackend::new(self.ctx.clone()), sim)
    }

    fn with_renderer(
        &self,
        f: &mut dyn FnMut(&mut dyn Renderer) -> Result<(), FitError>,
    ) -> Result<(), FitError> {
        if !self.render_on_gpu {
            return f(&mut SplatRenderer::new(CpuBackend::default()));
        }
        let mut guard = self
            .renderer
            .lock()
            .map_err(|_| FitError::backend_msg("wgpu", "the GPU renderer panicked earlier"))?;
        let r = guard.get_or_insert_with(|| SplatRenderer::new(WgpuBackend::new(self.ctx.clone())));
        f(r)
    }

    fn frames_on_device(&self) -> bool {
        self.render_on_gpu
    }

    fn reset_device_peak(&self) {
        self.ctx.reset_peak();
    }

    fn device_memory(&self) -> Option<r4d_mpm::MemoryUsage> {
        Some(r4d_mpm::MemoryUsage {
            bytes_in_use: self.ctx.bytes_in_use(),
            peak_bytes: self.ctx.peak_bytes(),
            uploaded_bytes: self.ctx.uploaded_bytes(),
            downloaded_bytes: self.ctx.downloaded_bytes(),
        })
    }
}
