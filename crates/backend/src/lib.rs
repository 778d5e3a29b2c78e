//! # r4d-backend: the base of resonance4d's backend family
//!
//! A backend (the CPU in f32 or f64, a GPU engine through `r4d-gpu`) implements [`Backend`]
//! once: its buffer type, how bytes go in and out, its error and its memory accounting. The
//! simulator's kernels (`r4d_mpm::MpmKernels`, and `MpmAdjointKernels` for the reverse sweep)
//! and the renderer's (`r4d_splat::SplatKernels`) are traits on top of it, so one backend value
//! runs both, and a buffer the simulation wrote can be read by the rasterizer without leaving
//! the device.
//!
//! Host backends, whose buffers are `Vec<T>`, implement it with [`host_vec_backend!`]:
//!
//! ```
//! use r4d_backend::{Backend, MemoryUsage};
//!
//! /// A host backend that does nothing else.
//! struct Plain;
//!
//! impl Backend for Plain {
//!     r4d_backend::host_vec_backend!();
//!     fn name(&self) -> &'static str {
//!         "plain"
//!     }
//!     fn memory_usage(&self) -> MemoryUsage {
//!         MemoryUsage::default()
//!     }
//! }
//!
//! let b = Plain;
//! let mut buf = b.upload(&[1.0f32, 2.0, 3.0]).unwrap();
//! b.write(&mut buf, &[4.0, 5.0, 6.0]).unwrap();
//! assert_eq!(b.download(&buf).unwrap(), [4.0, 5.0, 6.0]);
//! assert_eq!(b.zeros::<u32>(2).unwrap(), [0, 0]);
//! ```

use bytemuck::Pod;

#[doc(hidden)]
pub use bytemuck;

/// Memory a backend has allocated, in bytes (for benches and `memory_plan` checks), and the
/// bytes it moved between host and device.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct MemoryUsage {
    /// Bytes currently allocated by the backend.
    pub bytes_in_use: u64,
    /// Highest value `bytes_in_use` has reached.
    pub peak_bytes: u64,
    /// Bytes copied from the host to the device since the backend was made (buffer writes,
    /// uploads, the uniforms and data blocks of recordings; 0 for host backends).
    pub uploaded_bytes: u64,
    /// Bytes copied from the device to the host since the backend was made (0 for host
    /// backends).
    pub downloaded_bytes: u64,
}

/// The base trait of the backend family: typed buffers owned by the backend, the copies in
/// and out of them, the backend's error and its memory accounting.
///
/// Everything above it (the simulation driver, the renderer, the fits) is written once,
/// generic over a backend; the kernel traits extending this one add the stages.
pub trait Backend: Sized + Send + Sync + 'static {
    /// A typed buffer owned by the backend (`Vec<T>` on the host, a device buffer on a GPU).
    type Buf<T: Pod + Send + Sync>: Send + Sync + 'static;
    /// Errors the backend can't prevent (device lost, out of memory, a failed readback).
    type Error: std::error::Error + Send + Sync + 'static;

    /// A short name for reports (`"cpu"`, `"reference"`, `"wgpu"`, `"vulkan"`).
    fn name(&self) -> &'static str;
    /// Copies host data into a new buffer.
    fn upload<T: Pod + Send + Sync>(&self, data: &[T]) -> Result<Self::Buf<T>, Self::Error>;
    /// A new zero-filled buffer of `len` elements.
    fn zeros<T: Pod + Send + Sync>(&self, len: usize) -> Result<Self::Buf<T>, Self::Error>;
    /// Copies a buffer back to the host.
    fn download<T: Pod + Send + Sync>(&self, buf: &Self::Buf<T>) -> Result<Vec<T>, Self::Error>;
    /// Brings a buffer back to the host, consuming it (a host backend hands its `Vec` over
    /// without a copy; the default downloads).
    fn download_owned<T: Pod + Send + Sync>(
        &self,
        buf: Self::Buf<T>,
    ) -> Result<Vec<T>, Self::Error> {
        self.download(&buf)
    }
    /// Overwrites a buffer with host data of the same length.
    fn write<T: Pod + Send + Sync>(
        &self,
        buf: &mut Self::Buf<T>,
        data: &[T],
    ) -> Result<(), Self::Error>;
    /// Copies `src` into `dst` (same length), on the backend.
    fn copy<T: Pod + Send + Sync>(
        &self,
        src: &Self::Buf<T>,
        dst: &mut Self::Buf<T>,
    ) -> Result<(), Self::Error>;
    /// Memory the backend has allocated and the bytes it moved.
    fn memory_usage(&self) -> MemoryUsage;
}

/// Implements the buffer methods of [`Backend`] for a host backend whose buffers are `Vec<T>`
/// and whose error is [`std::convert::Infallible`] (the reference and CPU backends). Use
/// inside the `impl Backend for ...` block; `name` and `memory_usage` remain to write.
#[macro_export]
macro_rules! host_vec_backend {
    () => {
        type Buf<E: $crate::bytemuck::Pod + Send + Sync> = Vec<E>;
        type Error = std::convert::Infallible;

        fn upload<E: $crate::bytemuck::Pod + Send + Sync>(
            &self,
            data: &[E],
        ) -> Result<Vec<E>, std::convert::Infallible> {
            Ok(data.to_vec())
        }
        fn zeros<E: $crate::bytemuck::Pod + Send + Sync>(
            &self,
            len: usize,
        ) -> Result<Vec<E>, std::convert::Infallible> {
            Ok(vec![E::zeroed(); len])
        }
        fn download<E: $crate::bytemuck::Pod + Send + Sync>(
            &self,
            buf: &Vec<E>,
        ) -> Result<Vec<E>, std::convert::Infallible> {
            Ok(buf.clone())
        }
        fn download_owned<E: $crate::bytemuck::Pod + Send + Sync>(
            &self,
            buf: Vec<E>,
        ) -> Result<Vec<E>, std::convert::Infallible> {
            Ok(buf)
        }
        fn write<E: $crate::bytemuck::Pod + Send + Sync>(
            &self,
            buf: &mut Vec<E>,
            data: &[E],
        ) -> Result<(), std::convert::Infallible> {
            buf.copy_from_slice(data);
            Ok(())
        }
        fn copy<E: $crate::bytemuck::Pod + Send + Sync>(
            &self,
            src: &Vec<E>,
            dst: &mut Vec<E>,
        ) -> Result<(), std::convert::Infallible> {
            dst.copy_from_slice(src);
            Ok(())
        }
    };
}

/// A buffer of some backend with its element type erased: how a buffer crosses an
/// object-safe interface (a simulation behind `dyn`, a renderer behind `dyn`) without leaving
/// the device. [`AnyBuf::get`] gives it back to a backend of the same type and element type.
pub struct AnyBuf {
    buf: Box<dyn std::any::Any + Send + Sync>,
    len: usize,
    backend: &'static str,
}

impl std::fmt::Debug for AnyBuf {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("AnyBuf")
            .field("backend", &self.backend)
            .field("len", &self.len)
            .finish_non_exhaustive()
    }
}

impl AnyBuf {
    /// Erases the type of `buf`, a buffer of `len` elements of backend `b`.
    pub fn new<B: Backend, T: Pod + Send + Sync>(b: &B, buf: B::Buf<T>, len: usize) -> AnyBuf {
        AnyBuf {
            buf: Box::new(buf),
            len,
            backend: b.name(),
        }
    }

    /// The buffer, when it is a `B::Buf<T>` (`None`: another backend or element type).
    pub fn get<B: Backend, T: Pod + Send + Sync>(&self) -> Option<&B::Buf<T>> {
        self.buf.downcast_ref()
    }

    /// The buffer, mutably, when it is a `B::Buf<T>`.
    pub fn get_mut<B: Backend, T: Pod + Send + Sync>(&mut self) -> Option<&mut B::Buf<T>> {
        self.buf.downcast_mut()
    }

    /// Elements.
    pub fn len(&self) -> usize {
        self.len
    }

    /// Whether it holds no element.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// The name of the backend that made it (for error messages).
    pub fn backend(&self) -> &'static str {
        self.backend
    }
}
