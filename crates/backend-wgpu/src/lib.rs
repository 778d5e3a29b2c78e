//! # r4d-backend-wgpu: the wgpu (WGSL compute) engine
//!
//! The kernels are `r4d-shaders`' typed constants (WGSL validated by naga at build time,
//! workgroup sizes and bindings reflected) and what each stage dispatches is recorded once in
//! `r4d-gpu`; this crate is the engine that executes those recordings on a wgpu device
//! ([`engine`]: pipelines, bind groups, one submission per recording). [`WgpuBackend`] is the
//! backend on it: the simulator's kernels (forward and reverse) and the renderer's, over one
//! set of device buffers. See [`context`] for device selection and memory tracking.
//!
//! ```no_run
//! use std::sync::Arc;
//! use r4d_backend_wgpu::{WgpuBackend, WgpuContext};
//! let ctx = Arc::new(WgpuContext::new()?); // R4D_WGPU_ADAPTER picks an adapter by name
//! // r4d_backend::Backend + r4d_mpm::MpmKernels + MpmAdjointKernels + r4d_splat::SplatKernels
//! let gpu = WgpuBackend::new(ctx);
//! # Ok::<(), r4d_backend_wgpu::WgpuError>(())
//! ```

pub mod context;
pub mod engine;
pub mod shaders;
pub mod testing;

pub use context::{GpuBuffer, WgpuContext, WgpuError};
pub use engine::{WgpuBackend, WgpuEngine};
