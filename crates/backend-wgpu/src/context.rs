//! The wgpu device, typed buffers with labels and sizes, compute dispatch and readback, and a
//! count of the device memory this backend has allocated (current and peak).
//!
//! Adapter choice: `R4D_WGPU_ADAPTER` (a substring of the adapter name) picks one; otherwise
//! the high-performance adapter wgpu suggests. Float atomics (`SHADER_FLOAT32_ATOMIC`) are
//! requested when the adapter has them; kernels that scatter then use native
//! `atomicAdd` on `atomic<f32>`, else a compare-exchange loop on the bit pattern (same result
//! up to the summation order, which atomics leave to the hardware either way: scattered sums
//! are not bitwise reproducible run to run on a GPU).

use bytemuck::Pod;
use r4d_shaders::Kernel;
use std::collections::HashMap;
use std::marker::PhantomData;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};

/// Errors of the wgpu backend.
#[derive(Debug, thiserror::Error)]
pub enum WgpuError {
    /// No adapter (GPU or software Vulkan) is available.
    #[error(
        "no wgpu adapter found{0}: install a GPU driver, or Mesa's software Vulkan driver \
         (Debian/Ubuntu: apt-get install mesa-vulkan-drivers libvulkan1)"
    )]
    NoAdapter(String),
    /// The device could not be created.
    #[error("wgpu device request failed: {0}")]
    Device(String),
    /// A buffer exceeds the device's storage-binding limit.
    #[error(
        "buffer '{label}' needs {bytes} bytes but this device binds at most {limit} bytes per \
         storage buffer; use fewer particles/Gaussians per run"
    )]
    TooLarge {
        /// Buffer label.
        label: String,
        /// Requested size.
        bytes: u64,
        /// The device limit.
        limit: u64,
    },
    /// Reading a buffer back failed.
    #[error("reading buffer '{0}' back from the device failed")]
    Readback(String),
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
}

/// The device and everything shared by the kernels.
pub struct WgpuContext {
    /// The device.
    pub device: wgpu::Device,
    /// Its queue.
    pub queue: wgpu::Queue,
    /// Adapter description.
    pub info: wgpu::AdapterInfo,
    /// True when kernels use native float atomics.
    pub float_atomics: bool,
    /// Device limits.
    pub limits: wgpu::Limits,
    in_use: Arc<AtomicU64>,
    peak: Arc<AtomicU64>,
    uploaded: Arc<AtomicU64>,
    downloaded: Arc<AtomicU64>,
    pipelines: Mutex<HashMap<&'static str, Arc<wgpu::ComputePipeline>>>,
}

/// A typed device buffer with its length and label.
pub struct GpuBuffer<T> {
    /// The wgpu buffer.
    pub buffer: wgpu::Buffer,
    /// Elements.
    pub len: usize,
    /// Label (for errors and memory reports).
    pub label: &'static str,
    bytes: u64,
    in_use: Arc<AtomicU64>,
    _t: PhantomData<T>,
}

impl<T> Drop for GpuBuffer<T> {
    fn drop(&mut self) {
        self.in_use.fetch_sub(self.bytes, Ordering::Relaxed);
    }
}

impl<T> GpuBuffer<T> {
    /// Size in bytes (at least 16: wgpu does not bind empty buffers).
    pub fn bytes(&self) -> u64 {
        self.bytes
    }
}

impl WgpuContext {
    /// Opens the default adapter (or the one named by `R4D_WGPU_ADAPTER`); native float
    /// atomics are used when the adapter has them, unless `R4D_WGPU_NO_FLOAT_ATOMICS` is set.
    pub fn new() -> Result<Self, WgpuError> {
        Self::with_float_atomics(std::env::var_os("R4D_WGPU_NO_FLOAT_ATOMICS").is_none())
    }

    /// Like [`Self::new`]; `allow = false` forces the compare-exchange scatter even where the
    /// adapter has float atomics (tests use it to cover both paths).
    pub fn with_float_atomics(allow: bool) -> Result<Self, WgpuError> {
        let instance =
            wgpu::Instance::new(wgpu::InstanceDescriptor::new_without_display_handle_from_env());
        let wanted = std::env::var("R4D_WGPU_ADAPTER").ok();
        let adapter = match &wanted {
            Some(name) => pollster::block_on(instance.enumerate_adapters(wgpu::Backends::all()))
                .into_iter()
                .find(|a| a.get_info().name.contains(name.as_str()))
                .ok_or_else(|| {
                    WgpuError::NoAdapter(format!(" matching R4D_WGPU_ADAPTER={name}"))
                })?,
            None => pollster::block_on(instance.request_adapter(&wgpu::RequestAdapterOptions {
                power_preference: wgpu::PowerPreference::HighPerformance,
                force_fallback_adapter: false,
                compatible_surface: None,
                apply_limit_buckets: false,
            }))
            .map_err(|e| WgpuError::NoAdapter(format!(" ({e})")))?,
        };
        let info = adapter.get_info();
        let float_atomics = adapter
            .features()
            .contains(wgpu::Features::SHADER_FLOAT32_ATOMIC)
            && allow;
        let mut features = wgpu::Features::empty();
        if float_atomics {
            features |= wgpu::Features::SHADER_FLOAT32_ATOMIC;
        }
        let limits = adapter.limits();
        let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
            label: Some("r4d"),
            required_features: features,
            required_limits: limits.clone(),
            experimental_features: wgpu::ExperimentalFeatures::default(),
            memory_hints: wgpu::MemoryHints::Performance,
            trace: wgpu::Trace::Off,
        }))
        .map_err(|e| WgpuError::Device(e.to_string()))?;
        Ok(WgpuContext {
            device,
            queue,
            info,
            float_atomics,
            limits,
            in_use: Arc::new(AtomicU64::new(0)),
            peak: Arc::new(AtomicU64::new(0)),
            uploaded: Arc::new(AtomicU64::new(0)),
            downloaded: Arc::new(AtomicU64::new(0)),
            pipelines: Mutex::new(HashMap::new()),
        })
    }

    /// Bytes of device buffers currently allocated by this backend.
    pub fn bytes_in_use(&self) -> u64 {
        self.in_use.load(Ordering::Relaxed)
    }

    /// Highest [`Self::bytes_in_use`] since creation or the last [`Self::reset_peak`].
    pub fn peak_bytes(&self) -> u64 {
        self.peak.load(Ordering::Relaxed)
    }

    /// Bytes written from the host to device buffers since the context was made.
    pub fn uploaded_bytes(&self) -> u64 {
        self.uploaded.load(Ordering::Relaxed)
    }

    /// Bytes read back from device buffers since the context was made.
    pub fn downloaded_bytes(&self) -> u64 {
        self.downloaded.load(Ordering::Relaxed)
    }

    /// Restarts the peak count from the current usage.
    pub fn reset_peak(&self) {
        self.peak.store(self.bytes_in_use(), Ordering::Relaxed);
    }

    fn alloc<T>(
        &self,
        label: &'static str,
        len: usize,
        usage: wgpu::BufferUsages,
    ) -> Result<GpuBuffer<T>, WgpuError> {
        let bytes = ((len * std::mem::size_of::<T>()) as u64)
            .max(16)
            .next_multiple_of(4);
        let limit = self.limits.max_storage_buffer_binding_size;
        if usage.contains(wgpu::BufferUsages::STORAGE) && bytes > limit {
            return Err(WgpuError::TooLarge {
                label: label.to_string(),
                bytes,
                limit,
            });
        }
        let buffer = self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some(label),
            size: bytes,
            usage,
            mapped_at_creation: false,
        });
        let now = self.in_use.fetch_add(bytes, Ordering::Relaxed) + bytes;
        self.peak.fetch_max(now, Ordering::Relaxed);
        Ok(GpuBuffer {
            buffer,
            len,
            label,
            bytes,
            in_use: self.in_use.clone(),
            _t: PhantomData,
        })
    }

    /// A zero-filled storage buffer of `len` elements.
    pub fn zeros<T: Pod>(
        &self,
        label: &'static str,
        len: usize,
    ) -> Result<GpuBuffer<T>, WgpuError> {
        // wgpu zero-initialises new buffers.
        self.alloc(
            label,
            len,
            wgpu::BufferUsages::STORAGE
                | wgpu::BufferUsages::COPY_SRC
                | wgpu::BufferUsages::COPY_DST,
        )
    }

    /// A storage buffer holding `data`.
    pub fn upload<T: Pod>(
        &self,
        label: &'static str,
        data: &[T],
    ) -> Result<GpuBuffer<T>, WgpuError> {
        let b = self.zeros(label, data.len())?;
        self.write(&b, data);
        Ok(b)
    }

    /// Overwrites the start of a buffer with `data`.
    pub fn write<T: Pod>(&self, b: &GpuBuffer<T>, data: &[T]) {
        let bytes: &[u8] = bytemuck::cast_slice(data);
        if bytes.is_empty() {
            return;
        }
        self.uploaded
            .fetch_add(bytes.len() as u64, Ordering::Relaxed);
        if bytes.len() % 4 == 0 {
            self.queue.write_buffer(&b.buffer, 0, bytes);
        } else {
            let mut padded = bytes.to_vec();
            padded.resize(bytes.len().next_multiple_of(4), 0);
            self.queue.write_buffer(&b.buffer, 0, &padded);
        }
    }

    /// A uniform buffer holding one record.
    pub fn uniform<T: Pod>(
        &self,
        label: &'static str,
        value: &T,
    ) -> Result<GpuBuffer<T>, WgpuError> {
        let b = self.alloc(
            label,
            1,
            wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
        )?;
        self.queue
            .write_buffer(&b.buffer, 0, bytemuck::bytes_of(value));
        self.uploaded
            .fetch_add(std::mem::size_of::<T>() as u64, Ordering::Relaxed);
        Ok(b)
    }

    /// A uniform buffer holding `bytes` (padded to 16 bytes).
    pub fn uniform_bytes(
        &self,
        label: &'static str,
        bytes: &[u8],
    ) -> Result<GpuBuffer<u8>, WgpuError> {
        let b = self.alloc::<u8>(
            label,
            bytes.len().next_multiple_of(16),
            wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
        )?;
        self.write(&b, bytes);
        Ok(b)
    }

    /// Copies a buffer back to the host (waits for all submitted work).
    pub fn download<T: Pod>(&self, b: &GpuBuffer<T>) -> Result<Vec<T>, WgpuError> {
        let n = b.len * std::mem::size_of::<T>();
        if n == 0 {
            return Ok(Vec::new());
        }
        let size = (n as u64).next_multiple_of(4);
        self.downloaded.fetch_add(n as u64, Ordering::Relaxed);
        let staging = self.alloc::<u8>(
            "readback",
            size as usize,
            wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
        )?;
        let mut enc = self.device.create_command_encoder(&Default::default());
        enc.copy_buffer_to_buffer(&b.buffer, 0, &staging.buffer, 0, size);
        self.queue.submit([enc.finish()]);
        let (tx, rx) = std::sync::mpsc::channel();
        staging.buffer.map_async(wgpu::MapMode::Read, .., move |r| {
            let _ = tx.send(r);
        });
        self.device
            .poll(wgpu::PollType::Wait {
                submission_index: None,
                timeout: None,
            })
            .map_err(|_| WgpuError::Readback(b.label.to_string()))?;
        rx.recv()
            .ok()
            .and_then(|r| r.ok())
            .ok_or_else(|| WgpuError::Readback(b.label.to_string()))?;
        let view = staging
            .buffer
            .get_mapped_range(..)
            .map_err(|_| WgpuError::Readback(b.label.to_string()))?;
        let mut out = vec![T::zeroed(); b.len];
        bytemuck::cast_slice_mut::<T, u8>(&mut out).copy_from_slice(&view[..n]);
        drop(view);
        staging.buffer.unmap();
        Ok(out)
    }

    /// The pipeline of a kernel (built once); scatter kernels run their compare-exchange
    /// variant where the device has no float atomics.
    pub fn pipeline(&self, kernel: &'static Kernel) -> Arc<wgpu::ComputePipeline> {
        let k = kernel.variant(self.float_atomics);
        let mut cache = self.pipelines.lock().unwrap_or_else(|e| e.into_inner());
        if let Some(p) = cache.get(k.name) {
            return p.clone();
        }
        let module = self
            .device
            .create_shader_module(wgpu::ShaderModuleDescriptor {
                label: Some(k.name),
                source: wgpu::ShaderSource::Wgsl(k.wgsl.into()),
            });
        let p = Arc::new(
            self.device
                .create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                    label: Some(k.name),
                    layout: None,
                    module: &module,
                    entry_point: Some("main"),
                    compilation_options: Default::default(),
                    cache: None,
                }),
        );
        cache.insert(k.name, p.clone());
        p
    }

    /// Records one dispatch of `kernel` over `threads` invocations (workgroups of the
    /// kernel's reflected size, split over y beyond 65535 groups), with `buffers` bound at
    /// bindings 0, 1, ... of group 0.
    pub fn dispatch(
        &self,
        enc: &mut wgpu::CommandEncoder,
        kernel: &'static Kernel,
        buffers: &[&wgpu::Buffer],
        threads: u32,
    ) -> Result<(), WgpuError> {
        if threads == 0 {
            return Ok(());
        }
        let groups = threads.div_ceil(kernel.threads_per_group());
        let (x, y) = if groups <= 65535 {
            (groups, 1)
        } else {
            (65535, groups.div_ceil(65535))
        };
        self.dispatch_groups(enc, kernel, buffers, [x, y, 1])
    }

    /// Records one dispatch of `kernel` over a grid of workgroups.
    pub fn dispatch_groups(
        &self,
        enc: &mut wgpu::CommandEncoder,
        kernel: &'static Kernel,
        buffers: &[&wgpu::Buffer],
        groups: [u32; 3],
    ) -> Result<(), WgpuError> {
        if buffers.len() != kernel.bindings.len() {
            return Err(WgpuError::Bindings {
                kernel: kernel.name,
                given: buffers.len(),
                expected: kernel.bindings.len(),
            });
        }
        if groups.contains(&0) {
            return Ok(());
        }
        let p = self.pipeline(kernel);
        let layout = p.get_bind_group_layout(0);
        let entries: Vec<wgpu::BindGroupEntry> = buffers
            .iter()
            .enumerate()
            .map(|(i, b)| wgpu::BindGroupEntry {
                binding: i as u32,
                resource: b.as_entire_binding(),
            })
            .collect();
        let bg = self.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some(kernel.name),
            layout: &layout,
            entries: &entries,
        });
        let mut pass = enc.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some(kernel.name),
            timestamp_writes: None,
        });
        pass.set_pipeline(&p);
        pass.set_bind_group(0, &bg, &[]);
        pass.dispatch_workgroups(groups[0], groups[1], groups[2]);
        Ok(())
    }

    /// A new command encoder.
    pub fn encoder(&self) -> wgpu::CommandEncoder {
        self.device.create_command_encoder(&Default::default())
    }

    /// Submits recorded work.
    pub fn submit(&self, enc: wgpu::CommandEncoder) {
        self.queue.submit([enc.finish()]);
    }
}
