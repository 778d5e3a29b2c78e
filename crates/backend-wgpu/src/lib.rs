//! # r4d-backend-wgpu: the wgpu (WGSL compute) backend
//!
//! The kernels are `r4d-shaders`' typed constants (WGSL validated by naga at build time,
//! workgroup sizes and bindings reflected); this crate creates their pipelines, binds buffers
//! and records dispatches. [`engine`] executes `r4d-gpu`'s recordings (the simulator's
//! forward and reverse stages, written once for every GPU engine: [`WgpuMpm`]); [`splat`]
//! implements the renderer's stages. See [`context`] for device selection and memory
//! tracking.

pub mod context;
pub mod engine;
pub mod shaders;
pub mod splat;
pub mod testing;

pub use context::{GpuBuffer, WgpuContext, WgpuError};
pub use engine::{WgpuEngine, WgpuMpm};
