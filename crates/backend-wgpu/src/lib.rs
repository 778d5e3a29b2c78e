//! # r4d-backend-wgpu: the wgpu (WGSL compute) backend
//!
//! The kernels are `r4d-shaders`' typed constants (WGSL validated by naga at build time,
//! workgroup sizes and bindings reflected); this crate creates their pipelines, binds buffers
//! and records dispatches. [`mpm`] and [`mpm_vjp`] implement the simulator's forward and
//! reverse stages, [`splat`] the renderer's. See [`context`] for device selection and memory
//! tracking.

pub mod context;
pub mod mpm;
pub mod mpm_vjp;
pub mod shaders;
pub mod splat;
pub mod testing;

pub use context::{GpuBuffer, WgpuContext, WgpuError};
pub use mpm::WgpuMpm;
