//! Where a fit runs: the [`Compute`] trait a backend implements once (its simulation and its
//! renderer), so that everything of this crate — the video objective, the trajectory fit, a
//! forward simulation for evaluation — runs on it without naming it.
//!
//! A backend hands out its [`Simulation`] behind a trait object ([`DynSimulation`]); the
//! drivers of this crate run it:
//!
//! ```
//! use r4d_mpm::adjoint::host::HostSim;
//! use r4d_mpm::reference::ReferenceBackend;
//! use r4d_mpm::DynSimulation;
//! use r4d_optim::compute::{simulation_on, Compute, Precision};
//! use r4d_optim::FitError;
//! use r4d_splat::{reference::ReferenceSplat, Renderer, SplatRenderer};
//! use std::sync::Arc;
//!
//! /// The single-threaded reference kernels (the gradient oracle).
//! #[derive(Debug)]
//! struct Oracle;
//!
//! impl Compute for Oracle {
//!     fn name(&self) -> &str {
//!         "reference"
//!     }
//!     fn simulation(
//!         &self,
//!         precision: Precision,
//!         sim: Arc<HostSim>,
//!     ) -> Result<Box<dyn DynSimulation>, FitError> {
//!         match precision {
//!             Precision::F32 => simulation_on(ReferenceBackend::<f32>::in_scalar(), sim),
//!             Precision::F64 => simulation_on(ReferenceBackend::<f64>::in_scalar(), sim),
//!         }
//!     }
//!     fn with_renderer(
//!         &self,
//!         f: &mut dyn FnMut(&mut dyn Renderer) -> Result<(), FitError>,
//!     ) -> Result<(), FitError> {
//!         f(&mut SplatRenderer::new(ReferenceSplat))
//!     }
//! }
//! # let _ = Oracle;
//! ```
//! ([`ReferenceCompute`] is that implementation.)

use crate::FitError;
use r4d_mpm::adjoint::host::HostSim;
use r4d_mpm::adjoint::kernels::MpmAdjointKernels;
use r4d_mpm::{DynSimulation, PartParams, Simulation};
use r4d_splat::{Camera, Deformation, Gaussians, Image, RenderSettings, Renderer};
use serde::{Deserialize, Serialize};
use std::sync::Arc;

/// Floating-point type of the simulation and its reverse sweep, where the backend has a
/// choice (the CPU backends; a GPU simulates in f32).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Precision {
    /// Single precision (faster; gradients agree with f64 to a few 1e-3 relative).
    F32,
    /// Double precision (default).
    #[default]
    F64,
}

/// A compute backend for the fits: its MPM kernels and its renderer.
///
/// Implement [`Compute::simulation`] by building a [`Simulation`] on your kernels,
/// [`Compute::with_renderer`] by calling `f` with your renderer.
pub trait Compute: Send + Sync + std::fmt::Debug {
    /// A short name for messages and reports (`"cpu"`, `"wgpu"`, ...).
    fn name(&self) -> &str;
    /// The simulation of `sim` on this backend's kernels, in `precision` where the backend
    /// has a choice.
    fn simulation(
        &self,
        precision: Precision,
        sim: Arc<HostSim>,
    ) -> Result<Box<dyn DynSimulation>, FitError>;
    /// Calls `f` with this backend's renderer.
    fn with_renderer(
        &self,
        f: &mut dyn FnMut(&mut dyn Renderer) -> Result<(), FitError>,
    ) -> Result<(), FitError>;
    /// Renders `scene` (deformed by `deform` when given) from `cam` with this backend's
    /// renderer.
    fn render(
        &self,
        scene: &Gaussians,
        deform: Option<&Deformation>,
        cam: &Camera,
        settings: &RenderSettings,
    ) -> Result<Image, FitError> {
        let mut img = None;
        self.with_renderer(&mut |r| {
            img = Some(r.render(scene, deform, cam, settings)?);
            Ok(())
        })?;
        img.ok_or_else(|| {
            FitError::backend_msg(self.name(), "with_renderer did not call the renderer")
        })
    }
    /// Whether simulated frames can stay on the device between the simulation and the
    /// renderer: the renderer is of the same backend type as the simulation, so it binds the
    /// simulation's buffers ([`DynSimulation::frame_buffers`],
    /// [`Renderer::prepare_frame_linked`]). `false` (the default) reads each frame back to the
    /// host and uploads its deformation.
    fn frames_on_device(&self) -> bool {
        false
    }
    /// Starts a new device-memory peak ([`Compute::device_peak_bytes`]).
    fn reset_device_peak(&self) {}
    /// Turns per-kernel GPU timing on or off (`--profile`); returns whether this backend
    /// measures it (GPU timestamp queries: the Vulkan backend; `false` elsewhere).
    fn set_profiling(&self, _on: bool) -> Result<bool, FitError> {
        Ok(false)
    }
    /// GPU time per kernel since profiling was turned on, slowest first (empty where it is
    /// not measured).
    fn kernel_times(&self) -> Result<Vec<r4d_mpm::KernelTime>, FitError> {
        Ok(Vec::new())
    }
    /// The device's peak of allocated bytes since [`Compute::reset_device_peak`]; `None` for
    /// host backends (their memory is the process heap).
    fn device_peak_bytes(&self) -> Option<u64> {
        self.device_memory().map(|m| m.peak_bytes)
    }
    /// The device's memory accounting: bytes in use, their peak, and the bytes copied between
    /// host and device so far; `None` for host backends.
    fn device_memory(&self) -> Option<r4d_mpm::MemoryUsage> {
        None
    }
}

/// The single-threaded reference kernels of `r4d-mpm` and `r4d-splat` (the gradient oracle;
/// slow, for checking and for builds with no backend crate).
#[derive(Clone, Copy, Debug, Default)]
pub struct ReferenceCompute;

impl Compute for ReferenceCompute {
    fn name(&self) -> &str {
        "reference"
    }

    fn simulation(
        &self,
        precision: Precision,
        sim: Arc<HostSim>,
    ) -> Result<Box<dyn DynSimulation>, FitError> {
        use r4d_mpm::reference::ReferenceBackend;
        match precision {
            Precision::F32 => simulation_on(ReferenceBackend::<f32>::in_scalar(), sim),
            Precision::F64 => simulation_on(ReferenceBackend::<f64>::in_scalar(), sim),
        }
    }

    fn with_renderer(
        &self,
        f: &mut dyn FnMut(&mut dyn Renderer) -> Result<(), FitError>,
    ) -> Result<(), FitError> {
        f(&mut r4d_splat::SplatRenderer::new(
            r4d_splat::reference::ReferenceSplat,
        ))
    }
}

/// The simulation of `sim` on kernels `b`, boxed for [`Compute::simulation`].
pub fn simulation_on<B: MpmAdjointKernels>(
    b: B,
    sim: Arc<HostSim>,
) -> Result<Box<dyn DynSimulation>, FitError> {
    let name = b.name();
    Ok(Box::new(
        Simulation::with_host(b, sim).map_err(|e| FitError::backend(name, e))?,
    ))
}

/// Receives frame `j`'s positions of a forward simulation ([`simulate_frames`]).
pub type FrameSink<'a> = dyn FnMut(usize, &[[f64; 3]]) -> Result<(), FitError> + 'a;

/// Simulates `frames` frames of `sim` with the parameters `slots` (one per parameter slot) on
/// `compute`'s kernels, the same substeps as every fit: `on_frame(j, x)` gets frame `j`'s
/// positions (simulation space) for `j = 0..=frames`; an error it returns stops the run.
pub fn simulate_frames(
    compute: &dyn Compute,
    precision: Precision,
    sim: &HostSim,
    slots: &[PartParams],
    frames: usize,
    on_frame: &mut FrameSink<'_>,
) -> Result<(), FitError> {
    if slots.len() != sim.slots() {
        return Err(FitError::Input(format!(
            "{} parameter sets for a simulation with {} parameter slots",
            slots.len(),
            sim.slots()
        )));
    }
    let d = compute.simulation(precision, Arc::new(sim.clone()))?;
    let err = |e| FitError::sim(d.backend_name(), e);
    let params = d.params(slots);
    let mut s = d.init(&params, &vec![[0.0; 3]; sim.len()]).map_err(err)?;
    let spf = sim.setup.substeps_per_frame as u64;
    on_frame(0, &d.positions_f64(&s).map_err(err)?)?;
    let mut k = 0u64;
    for f in 1..=frames {
        for _ in 0..spf {
            d.step(&mut s, &params, k).map_err(err)?;
            k += 1;
        }
        on_frame(f, &d.positions_f64(&s).map_err(err)?)?;
    }
    Ok(())
}
