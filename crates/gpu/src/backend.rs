//! [`Gpu`]: one backend value per engine, the base trait of the family
//! ([`r4d_backend::Backend`]) implemented once for every [`GpuEngine`]. The simulator's kernels
//! ([`crate::mpm`], [`crate::mpm_vjp`]) and the renderer's ([`crate::splat`]) are implemented
//! on the same type, so a buffer the simulation wrote is one the rasterizer can bind.

use crate::engine::{GpuBuf, GpuEngine};
use crate::recording::Recording;
use bytemuck::Pod;
use r4d_backend::{Backend, MemoryUsage};
use std::sync::Mutex;

/// The GPU backend on engine `E` (wgpu, Vulkan): buffers, transfers and memory accounting
/// from the engine, every MPM, MPM-adjoint, splat and splat-adjoint stage recorded once in
/// this crate.
pub struct Gpu<E: GpuEngine> {
    pub(crate) engine: E,
    /// `g2p`'s per-substep problem record (`1 + 2 particles` words, first armed to `u32::MAX`).
    pub(crate) health_scratch: Mutex<Option<GpuBuf<E, u32>>>,
    /// The reverse particle stage's private records (see [`crate::mpm_vjp`]).
    pub(crate) reverse_records: Mutex<Option<crate::mpm_vjp::ReverseRecords<E>>>,
}

impl<E: GpuEngine> Gpu<E> {
    /// The backend on an engine (anything that converts into one, such as a wgpu context).
    pub fn new(engine: impl Into<E>) -> Self {
        Gpu {
            engine: engine.into(),
            health_scratch: Mutex::new(None),
            reverse_records: Mutex::new(None),
        }
    }

    /// The engine.
    pub fn engine(&self) -> &E {
        &self.engine
    }
}

/// The name of an element type, as a buffer label.
pub(crate) fn label<T>() -> &'static str {
    std::any::type_name::<T>()
}

impl<E: GpuEngine> Backend for Gpu<E> {
    type Buf<T: Pod + Send + Sync> = GpuBuf<E, T>;
    type Error = E::Error;

    fn name(&self) -> &'static str {
        self.engine.name()
    }

    fn upload<T: Pod + Send + Sync>(&self, data: &[T]) -> Result<GpuBuf<E, T>, E::Error> {
        GpuBuf::upload(&self.engine, label::<T>(), data)
    }

    /// Allocated with room for at least one element, so that even an empty buffer satisfies
    /// the minimum binding size of a runtime-sized array.
    fn zeros<T: Pod + Send + Sync>(&self, len: usize) -> Result<GpuBuf<E, T>, E::Error> {
        GpuBuf::zeros_with_capacity(&self.engine, label::<T>(), len, len.max(1))
    }

    fn download<T: Pod + Send + Sync>(&self, buf: &GpuBuf<E, T>) -> Result<Vec<T>, E::Error> {
        buf.download(&self.engine)
    }

    fn write<T: Pod + Send + Sync>(
        &self,
        buf: &mut GpuBuf<E, T>,
        data: &[T],
    ) -> Result<(), E::Error> {
        assert_eq!(buf.len, data.len(), "write: same length");
        if data.is_empty() {
            return Ok(());
        }
        self.engine.write(&buf.raw, bytemuck::cast_slice(data))
    }

    fn copy<T: Pod + Send + Sync>(
        &self,
        src: &GpuBuf<E, T>,
        dst: &mut GpuBuf<E, T>,
    ) -> Result<(), E::Error> {
        let mut r = Recording::new();
        let (s, d) = (r.buf(&src.raw), r.buf(&dst.raw));
        r.copy(s, d, src.bytes().min(dst.bytes()));
        self.engine.execute(r)
    }

    fn memory_usage(&self) -> MemoryUsage {
        self.engine.memory_usage()
    }
}
