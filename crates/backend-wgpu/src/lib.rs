//! # r4d-backend-wgpu: the wgpu (WGSL compute) engine
//!
//! The kernels are `r4d-shaders`' typed constants (WGSL validated by naga at build time,
//! workgroup sizes and bindings reflected) and what each stage dispatches is recorded once in
//! `r4d-gpu`; this crate is the engine that executes those recordings on a wgpu device
//! ([`engine`]: pipelines, bind groups, one submission per recording). [`WgpuMpm`] is the
//! simulator's kernels on it (forward and reverse), [`WgpuSplat`] the renderer's. See
//! [`context`] for device selection and memory tracking.
//!
//! ```no_run
//! use std::sync::Arc;
//! use r4d_backend_wgpu::{WgpuContext, WgpuMpm, WgpuSplat};
//! let ctx = Arc::new(WgpuContext::new()?); // R4D_WGPU_ADAPTER picks an adapter by name
//! let mpm = WgpuMpm::new(ctx.clone()); // r4d_mpm::MpmKernels + MpmAdjointKernels
//! let splat = WgpuSplat::new(ctx); // r4d_splat::SplatKernels
//! # Ok::<(), r4d_backend_wgpu::WgpuError>(())
//! ```

pub mod context;
pub mod engine;
pub mod shaders;
pub mod testing;

pub use context::{GpuBuffer, WgpuContext, WgpuError};
pub use engine::{WgpuEngine, WgpuMpm, WgpuSplat};
