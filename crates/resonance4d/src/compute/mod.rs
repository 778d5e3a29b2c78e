//! The backends as [`Compute`]s, the one place where the fits meet a concrete backend: the
//! CPU (all cores, f32 or f64; feature `cpu`) and a GPU through wgpu (feature `wgpu`) or through
//! Vulkan (ash; feature `vulkan`). Every fit, evaluation and benchmark
//! takes an `Arc<dyn Compute>`; the CLI picks it once from `--backend`.
//!
//! ```
//! use resonance4d::compute;
//! let cpu = compute::cpu();
//! assert_eq!(cpu.name(), "cpu");
//! ```

#[cfg(feature = "cpu")]
mod cpu;
#[cfg(feature = "vulkan")]
mod vulkan;
#[cfg(feature = "wgpu")]
mod wgpu;

#[cfg(feature = "cpu")]
pub use cpu::CpuCompute;
pub use r4d_optim::compute::{Compute, Precision, ReferenceCompute};
#[cfg(feature = "vulkan")]
pub use vulkan::VulkanCompute;
#[cfg(feature = "wgpu")]
pub use wgpu::WgpuCompute;

use std::sync::Arc;

/// The CPU backend ([`CpuCompute`]).
#[cfg(feature = "cpu")]
pub fn cpu() -> Arc<dyn Compute> {
    Arc::new(CpuCompute)
}

/// The GPU of `ctx` ([`WgpuCompute`]).
#[cfg(feature = "wgpu")]
pub fn wgpu(ctx: Arc<r4d_backend_wgpu::WgpuContext>) -> Arc<dyn Compute> {
    Arc::new(WgpuCompute::new(ctx))
}

/// The Vulkan device of `engine` ([`VulkanCompute`]).
#[cfg(feature = "vulkan")]
pub fn vulkan(engine: r4d_backend_vulkan::VulkanEngine) -> Arc<dyn Compute> {
    Arc::new(VulkanCompute::new(engine))
}

/// The single-threaded reference kernels ([`ReferenceCompute`], the gradient oracle).
pub fn reference() -> Arc<dyn Compute> {
    Arc::new(ReferenceCompute)
}
