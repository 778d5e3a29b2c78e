//! # r4d-backend-vulkan: the Vulkan engine of `r4d-gpu`'s recordings (ash)
//!
//! A second [`r4d_gpu::GpuEngine`] beside wgpu's: the same recordings (every MPM stage
//! forward and reverse, every splatting stage), executed through Vulkan directly. Kernels are
//! the SPIR-V that `r4d-shaders` compiles from the WGSL ([`r4d_shaders::Kernel::spirv_words`]),
//! their descriptor set layouts come from the reflected [`r4d_shaders::Kernel::bindings`],
//! device memory is sub-allocated by `gpu-allocator`. So the simulator and the renderer on
//! Vulkan are one backend, [`VulkanBackend`]: `r4d_gpu::Gpu` over this engine, nothing
//! written twice.
//!
//! Recordings are appended to one pending command buffer (a compute dispatch, fill or copy
//! per command, a full memory barrier between commands); a read submits it and waits, so a
//! simulated frame is one queue submission, not one per substep.
//! Scatter kernels use native float atomics where the device has `VK_EXT_shader_atomic_float`
//! (buffer float32 add) and their compare-exchange variants elsewhere
//! (`R4D_VULKAN_NO_FLOAT_ATOMICS` forces the latter). `R4D_VULKAN_DEVICE=name` (or an index) picks a device; otherwise discrete GPUs come
//! first, then integrated, virtual and CPU devices (Mesa's lavapipe, which the tests use
//! where there is no GPU).

mod device;
mod engine;
mod profile;
pub mod testing;

pub use ash;
pub use device::VkBuffer;
pub use engine::VulkanEngine;

/// The backend on Vulkan: the simulator's kernels (forward and reverse) and the renderer's
/// (forward and backward) over one set of device buffers.
pub type VulkanBackend = r4d_gpu::Gpu<VulkanEngine>;

/// A Vulkan device the host application created and keeps (embedding: the engine shares
/// the application's instance, device and a queue; [`VulkanEngine::from_host`]).
pub struct HostDevice {
    /// The loader the instance came from.
    pub entry: ash::Entry,
    /// The application's instance (Vulkan 1.1 or later).
    pub instance: ash::Instance,
    /// The physical device of `device`.
    pub physical_device: ash::vk::PhysicalDevice,
    /// The application's device.
    pub device: ash::Device,
    /// A queue family with compute.
    pub queue_family: u32,
    /// The queue of that family the engine submits to.
    pub queue_index: u32,
    /// Whether the device was created with `VK_EXT_shader_atomic_float` and its
    /// `shaderBufferFloat32AtomicAdd` feature enabled (then scatter kernels use native float
    /// atomics; otherwise their compare-exchange variants).
    pub float_atomics: bool,
}

/// Errors of the Vulkan engine.
#[derive(Debug, thiserror::Error)]
pub enum VulkanError {
    /// The Vulkan loader (`libvulkan`) could not be opened.
    #[error(
        "no Vulkan loader: {0} (install a Vulkan driver, e.g. mesa-vulkan-drivers and libvulkan1)"
    )]
    NoLoader(String),
    /// No device qualifies.
    #[error("no Vulkan device{0}")]
    NoDevice(String),
    /// A Vulkan call failed.
    #[error("{what} failed: {result}")]
    Vk {
        /// The call.
        what: &'static str,
        /// Its result code.
        result: ash::vk::Result,
    },
    /// A buffer could not be allocated.
    #[error("cannot allocate {bytes} bytes for '{label}' on the Vulkan device: {message}")]
    OutOfMemory {
        /// The buffer's label.
        label: String,
        /// Bytes asked for.
        bytes: u64,
        /// The allocator's message.
        message: String,
    },
    /// The allocator could not be created.
    #[error("Vulkan memory allocator: {0}")]
    Alloc(String),
    /// A host access to a buffer that is not host-visible (an engine bug).
    #[error("a Vulkan buffer is not host-visible")]
    NotMapped,
    /// A dispatch bound another number of buffers than the kernel declares (a bug).
    #[error("kernel '{kernel}' binds {expected} buffers, the dispatch gave {given}")]
    Bindings {
        /// The kernel.
        kernel: &'static str,
        /// Buffers given.
        given: usize,
        /// Bindings the kernel's entry point uses.
        expected: usize,
    },
    /// The device is being torn down.
    #[error("the Vulkan device is gone")]
    Lost,
}
