//! [`VulkanEngine`]: `r4d_gpu::GpuEngine` on Vulkan. Recordings are appended to one pending
//! command buffer: per command a compute dispatch (its pipeline, a descriptor set of the
//! bound buffers), a fill (clear) or a copy, with a full memory barrier after each. Buffer
//! writes go through host-visible staging buffers appended the same way. A read submits the
//! pending command buffer, once, and waits for it: a simulated frame (hundreds of substeps,
//! thousands of dispatches) is one queue submission, ended by the frame's position readback.
//! Transient buffers, descriptor pools and buffers dropped meanwhile are freed after the wait
//! (more than 256 MiB of them submit early).

use crate::device::{Device, VkBuffer};
use crate::profile::Profiler;
use crate::VulkanError;
use ash::vk;
use gpu_allocator::MemoryLocation;
use r4d_gpu::{Command, GpuEngine, Recording, Resource};
use r4d_mpm::kernels::{KernelTime, MemoryUsage};
use std::sync::atomic::Ordering;
use std::sync::{Arc, Mutex};

/// The command pool and fence of the engine's submissions, and the command buffer being
/// recorded: recordings, writes and clears are appended to it; a read (or enough transient
/// memory) submits it, once, and waits.
struct Submitter {
    pool: vk::CommandPool,
    fence: vk::Fence,
    /// The command buffer being recorded (begun), if any.
    cb: Option<vk::CommandBuffer>,
    /// Transient buffers its commands use (uniforms, data blocks, scratch, staging).
    keep: Vec<VkBuffer>,
    /// Their bytes.
    keep_bytes: u64,
    /// Descriptor pools of its dispatches.
    pools: Vec<vk::DescriptorPool>,
    /// Per-kernel timing, when on ([`VulkanEngine::set_profiling`]).
    profiler: Option<Profiler>,
}

/// The timestamps a recording may write: the profiler, the first pair of the recording's
/// dispatches and how many of them are timed.
type Timing<'a> = Option<(&'a Profiler, usize, usize)>;

/// Transient bytes (and dropped buffers) a pending command buffer may hold before it is
/// submitted without waiting for a read.
const FLUSH_BYTES: u64 = 256 << 20;

struct Inner {
    dev: Arc<Device>,
    submit: Mutex<Submitter>,
}

impl Drop for Inner {
    fn drop(&mut self) {
        let dev = self.dev.clone();
        let s = self.submit.get_mut().unwrap_or_else(|e| e.into_inner());
        let _ = flush_locked(&dev, s);
        if let Some(p) = s.profiler.take() {
            p.destroy(&dev.device);
        }
        // SAFETY: every submission was waited for; the pool's command buffers are freed.
        unsafe {
            self.dev.device.destroy_fence(s.fence, None);
            self.dev.device.destroy_command_pool(s.pool, None);
        }
    }
}

/// A Vulkan device as an engine of `r4d-gpu` recordings (cheap to clone: a shared handle).
#[derive(Clone)]
pub struct VulkanEngine {
    inner: Arc<Inner>,
}

impl std::fmt::Debug for VulkanEngine {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("VulkanEngine")
            .field("device", &self.inner.dev.name)
            .finish_non_exhaustive()
    }
}

fn vk_err(what: &'static str) -> impl Fn(vk::Result) -> VulkanError {
    move |result| VulkanError::Vk { what, result }
}

impl VulkanEngine {
    /// The engine on the preferred device (`R4D_VULKAN_DEVICE=name` or `=index` picks one);
    /// native float atomics where the device has them, unless `R4D_VULKAN_NO_FLOAT_ATOMICS`
    /// is set.
    pub fn new() -> Result<Self, VulkanError> {
        Self::with_float_atomics(std::env::var_os("R4D_VULKAN_NO_FLOAT_ATOMICS").is_none())
    }

    /// Like [`Self::new`]; `allow = false` runs the compare-exchange scatter even where the
    /// device has float atomics (tests cover both paths).
    pub fn with_float_atomics(allow: bool) -> Result<Self, VulkanError> {
        let wanted = std::env::var("R4D_VULKAN_DEVICE").ok();
        let dev = Device::new(wanted.as_deref(), allow)?;
        Self::on(dev)
    }

    /// The engine's command pool and fence on `dev`.
    fn on(dev: Arc<Device>) -> Result<Self, VulkanError> {
        let d = &dev.device;
        // SAFETY: valid create infos; destroyed in Inner's Drop.
        let (pool, fence) = unsafe {
            let pool = d
                .create_command_pool(
                    &vk::CommandPoolCreateInfo::default()
                        .queue_family_index(dev.queue_family)
                        .flags(vk::CommandPoolCreateFlags::TRANSIENT),
                    None,
                )
                .map_err(vk_err("vkCreateCommandPool"))?;
            let fence = d
                .create_fence(&vk::FenceCreateInfo::default(), None)
                .map_err(vk_err("vkCreateFence"))?;
            (pool, fence)
        };
        Ok(VulkanEngine {
            inner: Arc::new(Inner {
                dev,
                submit: Mutex::new(Submitter {
                    pool,
                    fence,
                    cb: None,
                    keep: Vec::new(),
                    keep_bytes: 0,
                    pools: Vec::new(),
                    profiler: None,
                }),
            }),
        })
    }

    /// The engine on a device the host application created and keeps (embedding in a Vulkan
    /// renderer: the same device, memory and queue; see `examples/embed.rs`). The engine's
    /// own objects (buffers, pipelines, pools) are destroyed with it; the instance and device
    /// are not.
    ///
    /// # Safety
    /// The handles must be valid and belong together, the device must outlive the engine and
    /// everything made from it, and the host must not use the queue while an engine call is
    /// running (Vulkan queues are externally synchronised; the engine submits only inside its
    /// calls and waits before returning from a read or [`VulkanEngine::finish`]).
    pub unsafe fn from_host(host: crate::HostDevice) -> Result<Self, VulkanError> {
        let dev = Device::from_host(host)?;
        Self::on(dev)
    }

    /// A buffer of the host application's, for the engine's kernels to bind (with
    /// [`r4d_gpu::GpuBuf`]'s `raw` field, or in a recording). Buffers the engine creates
    /// are shared the other way with [`VkBuffer::handle`].
    ///
    /// # Safety
    /// `buffer` must belong to this engine's device, hold at least `size` bytes, have been
    /// created with storage-buffer and transfer usage and bound to memory, and stay alive
    /// until the engine is done with it (its next read, or [`VulkanEngine::finish`]).
    pub unsafe fn import_buffer(&self, buffer: vk::Buffer, size: u64) -> VkBuffer {
        // SAFETY: the caller's contract, passed on.
        unsafe { VkBuffer::import(&self.inner.dev, buffer, size) }
    }

    /// Submits everything recorded so far and waits for it (a read does the same).
    pub fn finish(&self) -> Result<(), VulkanError> {
        self.flush()
    }

    /// The device's name.
    pub fn device_name(&self) -> &str {
        &self.inner.dev.name
    }

    /// Restarts the peak of [`GpuEngine::memory_usage`] at the bytes in use now.
    pub fn reset_peak(&self) {
        let d = &self.inner.dev;
        d.peak
            .store(d.in_use.load(Ordering::Relaxed), Ordering::Relaxed);
    }

    /// Warnings and errors the Khronos validation layer reported on this device so far
    /// (`R4D_VULKAN_VALIDATION=1` enables the layer; 0 otherwise).
    pub fn validation_messages(&self) -> usize {
        self.inner.dev.validation_messages()
    }

    /// Whether scatter kernels use native float atomics (`VK_EXT_shader_atomic_float`).
    pub fn float_atomics(&self) -> bool {
        self.inner.dev.float_atomics
    }

    /// Turns per-kernel GPU timing on (timestamp queries around every dispatch; see
    /// [`VulkanEngine::kernel_times`]) or off. Returns whether the device can measure it
    /// (a queue family without timestamps cannot; profiling then stays off). Turning it on
    /// starts the totals afresh.
    pub fn set_profiling(&self, on: bool) -> Result<bool, VulkanError> {
        let dev = &self.inner.dev;
        let mut guard = self.inner.submit.lock().unwrap_or_else(|e| e.into_inner());
        flush_locked(dev, &mut guard)?;
        if let Some(p) = guard.profiler.take() {
            p.destroy(&dev.device);
        }
        if on {
            guard.profiler =
                Profiler::new(&dev.device, dev.timestamp_period_ns, dev.timestamp_bits)?;
            return Ok(guard.profiler.is_some());
        }
        Ok(false)
    }

    /// GPU time per kernel since profiling was turned on, slowest first (empty when it is
    /// off). Dispatches still pending are counted once submitted (after the next read or
    /// [`VulkanEngine::finish`]).
    pub fn kernel_times(&self) -> Vec<KernelTime> {
        let guard = self.inner.submit.lock().unwrap_or_else(|e| e.into_inner());
        guard
            .profiler
            .as_ref()
            .map(Profiler::times)
            .unwrap_or_default()
    }

    /// Whether the device is a CPU implementation (lavapipe, SwiftShader).
    pub fn is_cpu(&self) -> bool {
        self.inner.dev.kind == vk::PhysicalDeviceType::CPU
    }

    /// Appends commands to the pending command buffer (begun on first use); `keep`: the
    /// transient buffers and descriptor pool they use, kept until the submission ends;
    /// `timed`: the kernels of the dispatches to time while profiling (in order; the
    /// closure gets where their timestamps go).
    fn record(
        &self,
        keep: Vec<VkBuffer>,
        pool: Option<vk::DescriptorPool>,
        timed: &[&'static str],
        record: impl FnOnce(&ash::Device, vk::CommandBuffer, Timing<'_>) -> Result<(), VulkanError>,
    ) -> Result<(), VulkanError> {
        let dev = &self.inner.dev;
        let d = &dev.device;
        let mut guard = self.inner.submit.lock().unwrap_or_else(|e| e.into_inner());
        let s = &mut *guard;
        // A full query pool submits what is pending first.
        if s.cb.is_some() && s.profiler.as_ref().is_some_and(|p| p.room() < timed.len()) {
            flush_locked(dev, s)?;
        }
        let cb = match s.cb {
            Some(cb) => cb,
            None => {
                // SAFETY: the pool is used under the lock only.
                let cb = unsafe {
                    d.allocate_command_buffers(
                        &vk::CommandBufferAllocateInfo::default()
                            .command_pool(s.pool)
                            .level(vk::CommandBufferLevel::PRIMARY)
                            .command_buffer_count(1),
                    )
                }
                .map_err(vk_err("vkAllocateCommandBuffers"))?[0];
                // SAFETY: a fresh command buffer.
                unsafe {
                    d.begin_command_buffer(
                        cb,
                        &vk::CommandBufferBeginInfo::default()
                            .flags(vk::CommandBufferUsageFlags::ONE_TIME_SUBMIT),
                    )
                }
                .map_err(vk_err("vkBeginCommandBuffer"))?;
                if let Some(p) = &s.profiler {
                    p.begin(d, cb);
                }
                s.cb = Some(cb);
                cb
            }
        };
        s.keep_bytes += keep.iter().map(|b| b.size).sum::<u64>();
        s.keep.extend(keep);
        s.pools.extend(pool);
        let timing = match &mut s.profiler {
            Some(p) if !timed.is_empty() => {
                let (base, n) = (p.pending.len(), timed.len().min(p.room()));
                p.pending.extend_from_slice(&timed[..n]);
                Some((base, n))
            }
            _ => None,
        };
        let r = record(
            d,
            cb,
            timing.and_then(|(base, n)| s.profiler.as_ref().map(|p| (p, base, n))),
        );
        // Bounded transient memory: a long run of recordings without a read is submitted
        // on its own.
        if r.is_ok() && s.keep_bytes + dev.graveyard_bytes.load(Ordering::Relaxed) > FLUSH_BYTES {
            return flush_locked(dev, s);
        }
        r
    }

    /// Submits the pending command buffer and waits for it (nothing to do without one).
    fn flush(&self) -> Result<(), VulkanError> {
        let mut guard = self.inner.submit.lock().unwrap_or_else(|e| e.into_inner());
        flush_locked(&self.inner.dev, &mut guard)
    }

    /// A host-visible buffer holding `data`.
    fn host_buffer(&self, label: &str, data: &[u8]) -> Result<VkBuffer, VulkanError> {
        self.inner
            .dev
            .uploaded
            .fetch_add(data.len() as u64, Ordering::Relaxed);
        let b = self
            .inner
            .dev
            .buffer(label, data.len() as u64, MemoryLocation::CpuToGpu, false)?;
        b.mapped(|m| m[..data.len()].copy_from_slice(data))?;
        Ok(b)
    }
}

/// Ends, submits and waits for the pending command buffer of `s`, then frees what it used
/// (transient buffers, descriptor pools, buffers dropped meanwhile).
fn flush_locked(dev: &Device, s: &mut Submitter) -> Result<(), VulkanError> {
    let Some(cb) = s.cb.take() else {
        dev.collect();
        return Ok(());
    };
    let d = &dev.device;
    // SAFETY: cb is recording; the fence is unsignalled; everything the commands use is in
    // `s.keep`, the engine's buffers or the graveyard, all alive until the wait returns.
    let result = unsafe {
        (|| {
            // Make the results visible to host reads of mapped memory.
            let barrier = vk::MemoryBarrier::default()
                .src_access_mask(vk::AccessFlags::SHADER_WRITE | vk::AccessFlags::TRANSFER_WRITE)
                .dst_access_mask(vk::AccessFlags::HOST_READ);
            d.cmd_pipeline_barrier(
                cb,
                vk::PipelineStageFlags::COMPUTE_SHADER | vk::PipelineStageFlags::TRANSFER,
                vk::PipelineStageFlags::HOST,
                vk::DependencyFlags::empty(),
                &[barrier],
                &[],
                &[],
            );
            d.end_command_buffer(cb)
                .map_err(vk_err("vkEndCommandBuffer"))?;
            let cbs = [cb];
            let submit = [vk::SubmitInfo::default().command_buffers(&cbs)];
            {
                let q = dev.queue.lock().unwrap_or_else(|e| e.into_inner());
                d.queue_submit(*q, &submit, s.fence)
                    .map_err(vk_err("vkQueueSubmit"))?;
            }
            d.wait_for_fences(&[s.fence], true, u64::MAX)
                .map_err(vk_err("vkWaitForFences"))?;
            d.reset_fences(&[s.fence]).map_err(vk_err("vkResetFences"))
        })()
    };
    // The timestamps of a completed submission are read before anything else is recorded.
    let result = match (&mut s.profiler, result) {
        (Some(p), Ok(())) => p.resolve(d),
        (Some(p), Err(e)) => {
            p.pending.clear();
            Err(e)
        }
        (None, r) => r,
    };
    // SAFETY: the submission ended (or never started): nothing uses these any more.
    unsafe {
        if result.is_err() {
            let _ = d.device_wait_idle();
        }
        d.free_command_buffers(s.pool, &[cb]);
        for p in s.pools.drain(..) {
            d.destroy_descriptor_pool(p, None);
        }
    }
    s.keep.clear();
    s.keep_bytes = 0;
    dev.collect();
    result
}

/// A barrier between two commands of a recording: every shader or transfer write before it
/// is visible to every shader or transfer access after it.
fn full_barrier(d: &ash::Device, cb: vk::CommandBuffer) {
    let barrier = vk::MemoryBarrier::default()
        .src_access_mask(vk::AccessFlags::SHADER_WRITE | vk::AccessFlags::TRANSFER_WRITE)
        .dst_access_mask(
            vk::AccessFlags::SHADER_READ
                | vk::AccessFlags::SHADER_WRITE
                | vk::AccessFlags::UNIFORM_READ
                | vk::AccessFlags::TRANSFER_READ
                | vk::AccessFlags::TRANSFER_WRITE,
        );
    let stages = vk::PipelineStageFlags::COMPUTE_SHADER | vk::PipelineStageFlags::TRANSFER;
    // SAFETY: cb is recording.
    unsafe {
        d.cmd_pipeline_barrier(
            cb,
            stages,
            stages,
            vk::DependencyFlags::empty(),
            &[barrier],
            &[],
            &[],
        );
    }
}

impl GpuEngine for VulkanEngine {
    type Raw = VkBuffer;
    type Error = VulkanError;

    fn name(&self) -> &'static str {
        "vulkan"
    }

    fn alloc(&self, label: &'static str, bytes: u64) -> Result<VkBuffer, VulkanError> {
        let b = self
            .inner
            .dev
            .buffer(label, bytes, MemoryLocation::GpuOnly, true)?;
        let (buf, size) = (b.buffer, b.size);
        self.record(Vec::new(), None, &[], |d, cb, _| {
            // SAFETY: cb is recording; the buffer is alive until the submission ends.
            unsafe { d.cmd_fill_buffer(cb, buf, 0, size, 0) };
            Ok(())
        })?;
        Ok(b)
    }

    fn write(&self, raw: &VkBuffer, data: &[u8]) -> Result<(), VulkanError> {
        if data.is_empty() {
            return Ok(());
        }
        let staging = self.host_buffer("staging upload", data)?;
        let (src, dst, bytes) = (staging.buffer, raw.buffer, data.len() as u64);
        let size = raw.size;
        self.record(vec![staging], None, &[], |d, cb, _| {
            full_barrier(d, cb);
            // SAFETY: both buffers are alive until the submission ends; bytes fit both.
            unsafe {
                d.cmd_copy_buffer(
                    cb,
                    src,
                    dst,
                    &[vk::BufferCopy::default().size(bytes.min(size))],
                )
            };
            Ok(())
        })
    }

    fn read(&self, raw: &VkBuffer, bytes: u64) -> Result<Vec<u8>, VulkanError> {
        let bytes = bytes.min(raw.size);
        let staging =
            self.inner
                .dev
                .buffer("staging readback", bytes, MemoryLocation::GpuToCpu, false)?;
        let (src, dst) = (raw.buffer, staging.buffer);
        if bytes > 0 {
            self.record(Vec::new(), None, &[], |d, cb, _| {
                full_barrier(d, cb);
                // SAFETY: both buffers are alive until the submission ends.
                unsafe {
                    d.cmd_copy_buffer(cb, src, dst, &[vk::BufferCopy::default().size(bytes)])
                };
                Ok(())
            })?;
        }
        // Everything recorded so far runs now (the one submission of a frame).
        self.flush()?;
        self.inner
            .dev
            .downloaded
            .fetch_add(bytes, Ordering::Relaxed);
        staging.mapped(|m| m[..bytes as usize].to_vec())
    }

    fn execute(&self, rec: Recording<'_, VkBuffer>) -> Result<(), VulkanError> {
        let dev = &self.inner.dev;
        let uniforms = rec
            .uniforms
            .iter()
            .map(|u| self.host_buffer("recording uniform", u))
            .collect::<Result<Vec<_>, _>>()?;
        let data = rec
            .data
            .iter()
            .map(|u| self.host_buffer("recording data", u))
            .collect::<Result<Vec<_>, _>>()?;
        let scratch = rec
            .scratch
            .iter()
            .map(|&b| dev.buffer("recording scratch", b, MemoryLocation::GpuOnly, false))
            .collect::<Result<Vec<_>, _>>()?;
        // Handles and sizes only: the transient buffers move to the pending submission.
        let h = |b: &VkBuffer| (b.buffer, b.size);
        let (hu, hd, hs): (Vec<_>, Vec<_>, Vec<_>) = (
            uniforms.iter().map(h).collect(),
            data.iter().map(h).collect(),
            scratch.iter().map(h).collect(),
        );
        let buf = |r: &Resource| -> (vk::Buffer, u64) {
            match *r {
                Resource::Buffer(i) => h(rec.buffers[i]),
                Resource::Uniform(i) => hu[i],
                Resource::Data(i) => hd[i],
                Resource::Scratch(i) => hs[i],
            }
        };
        // Pipelines and one descriptor set per dispatch, from one pool for the recording.
        let mut dispatches = Vec::new();
        let mut names = Vec::new();
        let (mut n_uniform, mut n_storage) = (0u32, 0u32);
        for c in &rec.commands {
            if let Command::Dispatch {
                kernel, bindings, ..
            } = c
            {
                let k = kernel.variant(dev.float_atomics);
                if bindings.len() != k.bindings.len() {
                    return Err(VulkanError::Bindings {
                        kernel: k.name,
                        given: bindings.len(),
                        expected: k.bindings.len(),
                    });
                }
                for b in k.bindings {
                    match b.kind {
                        r4d_shaders::BindingKind::Uniform => n_uniform += 1,
                        r4d_shaders::BindingKind::Storage { .. } => n_storage += 1,
                    }
                }
                dispatches.push(dev.pipeline(k)?);
                names.push(k.name);
            }
        }
        let d = &dev.device;
        let mut sizes = Vec::new();
        if n_uniform > 0 {
            sizes.push(
                vk::DescriptorPoolSize::default()
                    .ty(vk::DescriptorType::UNIFORM_BUFFER)
                    .descriptor_count(n_uniform),
            );
        }
        if n_storage > 0 {
            sizes.push(
                vk::DescriptorPoolSize::default()
                    .ty(vk::DescriptorType::STORAGE_BUFFER)
                    .descriptor_count(n_storage),
            );
        }
        let mut pool = if dispatches.is_empty() {
            vk::DescriptorPool::null()
        } else {
            // SAFETY: valid create info; destroyed below after the submission ended.
            unsafe {
                d.create_descriptor_pool(
                    &vk::DescriptorPoolCreateInfo::default()
                        .max_sets(dispatches.len() as u32)
                        .pool_sizes(&sizes),
                    None,
                )
            }
            .map_err(vk_err("vkCreateDescriptorPool"))?
        };
        let result = (|| {
            let mut sets = Vec::with_capacity(dispatches.len());
            let mut j = 0;
            for c in &rec.commands {
                let Command::Dispatch { bindings, .. } = c else {
                    continue;
                };
                let p = &dispatches[j];
                j += 1;
                let layouts = [p.set_layout];
                // SAFETY: the pool has room for one set per dispatch.
                let set = unsafe {
                    d.allocate_descriptor_sets(
                        &vk::DescriptorSetAllocateInfo::default()
                            .descriptor_pool(pool)
                            .set_layouts(&layouts),
                    )
                }
                .map_err(vk_err("vkAllocateDescriptorSets"))?[0];
                let kernel_bindings = match c {
                    Command::Dispatch { kernel, .. } => kernel.variant(dev.float_atomics).bindings,
                    _ => &[],
                };
                let infos: Vec<[vk::DescriptorBufferInfo; 1]> = bindings
                    .iter()
                    .map(|r| {
                        [vk::DescriptorBufferInfo::default()
                            .buffer(buf(r).0)
                            .offset(0)
                            .range(vk::WHOLE_SIZE)]
                    })
                    .collect();
                let writes: Vec<vk::WriteDescriptorSet> = infos
                    .iter()
                    .zip(kernel_bindings)
                    .enumerate()
                    .map(|(i, (info, b))| {
                        vk::WriteDescriptorSet::default()
                            .dst_set(set)
                            .dst_binding(i as u32)
                            .descriptor_type(match b.kind {
                                r4d_shaders::BindingKind::Uniform => {
                                    vk::DescriptorType::UNIFORM_BUFFER
                                }
                                r4d_shaders::BindingKind::Storage { .. } => {
                                    vk::DescriptorType::STORAGE_BUFFER
                                }
                            })
                            .buffer_info(info)
                    })
                    .collect();
                // SAFETY: the set and buffers are valid.
                unsafe { d.update_descriptor_sets(&writes, &[]) };
                sets.push(set);
            }
            let mut keep = uniforms;
            keep.extend(data);
            keep.extend(scratch);
            let owned_pool = (pool != vk::DescriptorPool::null()).then_some(pool);
            pool = vk::DescriptorPool::null();
            self.record(keep, owned_pool, &names, |d, cb, timing| {
                // Scratch buffers start at zero.
                for &(b, size) in &hs {
                    // SAFETY: cb is recording; the buffer outlives the submission.
                    unsafe { d.cmd_fill_buffer(cb, b, 0, size, 0) };
                }
                full_barrier(d, cb);
                let mut j = 0;
                for c in &rec.commands {
                    match c {
                        Command::Dispatch { groups, .. } => {
                            let p = &dispatches[j];
                            let stamp = timing.filter(|t| j < t.2);
                            if let Some((prof, base, _)) = stamp {
                                prof.stamp(d, cb, base + j, false);
                            }
                            // SAFETY: pipeline, layout and set are valid and compatible.
                            unsafe {
                                d.cmd_bind_pipeline(cb, vk::PipelineBindPoint::COMPUTE, p.pipeline);
                                d.cmd_bind_descriptor_sets(
                                    cb,
                                    vk::PipelineBindPoint::COMPUTE,
                                    p.layout,
                                    0,
                                    &[sets[j]],
                                    &[],
                                );
                                d.cmd_dispatch(cb, groups[0], groups[1], groups[2]);
                            }
                            if let Some((prof, base, _)) = stamp {
                                prof.stamp(d, cb, base + j, true);
                            }
                            j += 1;
                        }
                        Command::Clear(r) => {
                            let (b, size) = buf(r);
                            // SAFETY: the buffer outlives the submission.
                            unsafe { d.cmd_fill_buffer(cb, b, 0, size, 0) };
                        }
                        Command::Copy {
                            src,
                            src_offset,
                            dst,
                            dst_offset,
                            bytes,
                        } => {
                            if *bytes > 0 {
                                // SAFETY: both buffers outlive the submission; the recording
                                // keeps copies inside them.
                                unsafe {
                                    d.cmd_copy_buffer(
                                        cb,
                                        buf(src).0,
                                        buf(dst).0,
                                        &[vk::BufferCopy::default()
                                            .src_offset(*src_offset)
                                            .dst_offset(*dst_offset)
                                            .size(*bytes)],
                                    )
                                };
                            }
                        }
                    }
                    full_barrier(d, cb);
                }
                Ok(())
            })
        })();
        if pool != vk::DescriptorPool::null() {
            // SAFETY: the submission has ended (or never started).
            unsafe { d.destroy_descriptor_pool(pool, None) };
        }
        result
    }

    fn memory_usage(&self) -> MemoryUsage {
        MemoryUsage {
            bytes_in_use: self.inner.dev.in_use.load(Ordering::Relaxed),
            peak_bytes: self.inner.dev.peak.load(Ordering::Relaxed),
            uploaded_bytes: self.inner.dev.uploaded.load(Ordering::Relaxed),
            downloaded_bytes: self.inner.dev.downloaded.load(Ordering::Relaxed),
        }
    }
}
