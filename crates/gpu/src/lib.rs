//! # r4d-gpu: GPU stages recorded once, executed by any engine
//!
//! vello's shape (`docs/STYLE.md`, "record once, execute per engine"): what a GPU stage
//! dispatches is written once, as a [`Recording`] of commands (dispatch a kernel of
//! `r4d-shaders` over bound buffers, clear, copy) over buffer handles; a [`GpuEngine`]
//! (wgpu today, Vulkan/ash next) allocates buffers, moves bytes and executes recordings, and
//! knows nothing about MPM.
//!
//! [`Gpu`] is one backend of the family ([`r4d_backend::Backend`]) for every engine: it
//! implements the simulator's kernel traits ([`r4d_mpm::MpmKernels`] forward,
//! [`r4d_mpm::adjoint::kernels::MpmAdjointKernels`] reverse) and the renderer's
//! ([`r4d_splat::SplatKernels`], forward and backward) once: a new GPU backend implements
//! [`GpuEngine`] (six methods) and gets the whole differentiable simulator (the stage order
//! of `r4d_mpm::substep`, the driver `r4d_mpm::Simulation`) and renderer
//! (`r4d_splat::SplatRenderer`), over one set of buffers.
//!
//! ```
//! use r4d_gpu::{Recording, Resource};
//! // A recording over some engine's buffer type (here plain byte vectors).
//! let (x, v) = (vec![0u8; 12], vec![0u8; 12]);
//! let mut r: Recording<'_, Vec<u8>> = Recording::new();
//! let k = r.uniform(&r4d_gpu::Counts::new(1, 0));
//! let (bx, bv) = (r.buf(&x), r.buf(&v));
//! r.copy(bx, bv, 12);
//! r.dispatch(&r4d_shaders::mpm::ADD_VJP, 3, &[k, bx, bv]);
//! assert_eq!(r.commands.len(), 2);
//! assert!(matches!(r.commands[1].bindings()[0], Resource::Uniform(0)));
//! ```

pub mod backend;
pub mod engine;
pub mod mpm;
pub mod mpm_vjp;
pub mod recording;
pub mod splat;

pub use backend::Gpu;
pub use engine::{GpuBuf, GpuEngine};
pub use mpm::Counts;
pub use recording::{Command, Recording, Resource};
pub use splat::SplatProjectParams;
