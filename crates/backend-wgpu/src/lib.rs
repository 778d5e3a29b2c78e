//! # r4d-backend-wgpu: the wgpu (WGSL compute) backend
//!
//! Kernels are WGSL files under `shaders/` (one source per kernel; `shaders/lib/` holds the
//! shared structs and math), preprocessed and validated by naga in `build.rs`, so a broken
//! shader fails `cargo build`; the build also writes each kernel's SPIR-V for a Vulkan/ash
//! path. See [`context`] for device selection and memory tracking.

pub mod context;
pub mod mpm;
pub mod mpm_vjp;
pub mod shaders;
pub mod splat;
pub mod testing;

pub use context::{GpuBuffer, WgpuContext, WgpuError};
pub use mpm::WgpuMpm;
