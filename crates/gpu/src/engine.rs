//! What a GPU engine implements: buffers, bytes in and out, and the execution of a
//! [`Recording`].

use crate::recording::Recording;
use bytemuck::Pod;
use r4d_mpm::kernels::MemoryUsage;
use std::marker::PhantomData;

/// A GPU engine (wgpu, Vulkan): owns the device, allocates untyped buffers and executes
/// recordings in order. Everything a stage dispatches is in the recording; an engine knows no
/// kernel by name.
pub trait GpuEngine: Send + Sync + 'static {
    /// A device buffer (storage, copy source and destination).
    type Raw: Send + Sync;
    /// Errors the engine can't prevent (no device, out of memory, a failed readback).
    type Error: std::error::Error + Send + Sync + 'static;

    /// A short name for reports (`"wgpu"`).
    fn name(&self) -> &'static str;
    /// A zero-filled buffer of at least `bytes` bytes (`label` names it in errors and memory
    /// reports).
    fn alloc(&self, label: &'static str, bytes: u64) -> Result<Self::Raw, Self::Error>;
    /// Overwrites the start of a buffer, ordered after the commands executed so far.
    fn write(&self, raw: &Self::Raw, data: &[u8]) -> Result<(), Self::Error>;
    /// Reads the first `bytes` bytes of a buffer back, after everything executed so far.
    fn read(&self, raw: &Self::Raw, bytes: u64) -> Result<Vec<u8>, Self::Error>;
    /// Executes a recording (commands in order; uniforms and data blocks live until it ends).
    fn execute(&self, rec: Recording<'_, Self::Raw>) -> Result<(), Self::Error>;
    /// Device memory this engine has allocated.
    fn memory_usage(&self) -> MemoryUsage;
}

/// A typed buffer of an engine: its raw buffer and element count.
pub struct GpuBuf<E: GpuEngine, T> {
    /// The engine's buffer.
    pub raw: E::Raw,
    /// Elements.
    pub len: usize,
    _t: PhantomData<fn() -> T>,
}

impl<E: GpuEngine, T: Pod> GpuBuf<E, T> {
    /// A zero-filled buffer of `len` elements.
    pub fn zeros(e: &E, label: &'static str, len: usize) -> Result<Self, E::Error> {
        Ok(GpuBuf {
            raw: e.alloc(label, Self::bytes_for(len))?,
            len,
            _t: PhantomData,
        })
    }

    /// A zero-filled buffer of `len` elements with room for `capacity >= len` (a kernel that
    /// binds a runtime-sized array needs at least one element even when `len` is 0).
    pub fn zeros_with_capacity(
        e: &E,
        label: &'static str,
        len: usize,
        capacity: usize,
    ) -> Result<Self, E::Error> {
        Ok(GpuBuf {
            raw: e.alloc(label, Self::bytes_for(capacity.max(len)))?,
            len,
            _t: PhantomData,
        })
    }

    /// A buffer holding `data`.
    pub fn upload(e: &E, label: &'static str, data: &[T]) -> Result<Self, E::Error> {
        let b = Self::zeros(e, label, data.len())?;
        if !data.is_empty() {
            e.write(&b.raw, bytemuck::cast_slice(data))?;
        }
        Ok(b)
    }

    /// The contents.
    pub fn download(&self, e: &E) -> Result<Vec<T>, E::Error> {
        if self.len == 0 {
            return Ok(Vec::new());
        }
        let bytes = e.read(&self.raw, self.bytes())?;
        let mut out = vec![T::zeroed(); self.len];
        // The engine returns exactly the bytes asked for.
        bytemuck::cast_slice_mut::<T, u8>(&mut out).copy_from_slice(&bytes);
        Ok(out)
    }

    /// Bytes of the elements (`len * size_of::<T>()`).
    pub fn bytes(&self) -> u64 {
        (self.len * std::mem::size_of::<T>()) as u64
    }

    fn bytes_for(len: usize) -> u64 {
        (len * std::mem::size_of::<T>()) as u64
    }
}
