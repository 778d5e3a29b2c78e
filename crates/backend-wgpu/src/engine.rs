//! The wgpu engine of `r4d-gpu`'s recordings ([`GpuEngine`] for [`WgpuEngine`]): buffers are
//! [`GpuBuffer`]s of the context (labelled, counted in its memory report), a recording
//! becomes one command encoder (one compute pass per dispatch, bind groups from the kernels'
//! reflected layouts) and one queue submission.
//!
//! [`WgpuBackend`] is the backend on it (the simulator's and the renderer's kernels): their
//! stages are recorded once in `r4d_gpu` (`Gpu`), so nothing here knows a kernel.

use crate::context::{GpuBuffer, WgpuContext, WgpuError};
use r4d_gpu::{Command, GpuEngine, Recording, Resource};
use r4d_mpm::kernels::MemoryUsage;
use std::sync::Arc;

/// The backend on wgpu: the simulator's kernels (forward and reverse) and the renderer's
/// (forward and backward) over one set of device buffers.
pub type WgpuBackend = r4d_gpu::Gpu<WgpuEngine>;

/// A wgpu device as an engine of recordings.
#[derive(Clone)]
pub struct WgpuEngine {
    ctx: Arc<WgpuContext>,
}

impl WgpuEngine {
    /// The engine of a device.
    pub fn new(ctx: Arc<WgpuContext>) -> Self {
        WgpuEngine { ctx }
    }

    /// The device.
    pub fn context(&self) -> &Arc<WgpuContext> {
        &self.ctx
    }
}

impl From<Arc<WgpuContext>> for WgpuEngine {
    fn from(ctx: Arc<WgpuContext>) -> Self {
        WgpuEngine::new(ctx)
    }
}

impl GpuEngine for WgpuEngine {
    type Raw = GpuBuffer<u8>;
    type Error = WgpuError;

    fn name(&self) -> &'static str {
        "wgpu"
    }

    fn alloc(&self, label: &'static str, bytes: u64) -> Result<GpuBuffer<u8>, WgpuError> {
        self.ctx.zeros(label, bytes as usize)
    }

    fn write(&self, raw: &GpuBuffer<u8>, data: &[u8]) -> Result<(), WgpuError> {
        self.ctx.write(raw, data);
        Ok(())
    }

    fn read(&self, raw: &GpuBuffer<u8>, bytes: u64) -> Result<Vec<u8>, WgpuError> {
        let mut v = self.ctx.download(raw)?;
        v.truncate(bytes as usize);
        Ok(v)
    }

    fn execute(&self, rec: Recording<'_, GpuBuffer<u8>>) -> Result<(), WgpuError> {
        let ctx = &self.ctx;
        let uniforms = rec
            .uniforms
            .iter()
            .map(|u| ctx.uniform_bytes("recording uniform", u))
            .collect::<Result<Vec<_>, _>>()?;
        let data = rec
            .data
            .iter()
            .map(|d| ctx.upload("recording data", d))
            .collect::<Result<Vec<_>, _>>()?;
        let scratch = rec
            .scratch
            .iter()
            .map(|&b| ctx.zeros::<u8>("recording scratch", b as usize))
            .collect::<Result<Vec<_>, _>>()?;
        let buf = |r: &Resource| -> &wgpu::Buffer {
            match *r {
                Resource::Buffer(i) => &rec.buffers[i].buffer,
                Resource::Uniform(i) => &uniforms[i].buffer,
                Resource::Data(i) => &data[i].buffer,
                Resource::Scratch(i) => &scratch[i].buffer,
            }
        };
        let mut enc = ctx.encoder();
        for c in &rec.commands {
            match c {
                Command::Dispatch {
                    kernel,
                    groups,
                    bindings,
                } => {
                    let bufs: Vec<&wgpu::Buffer> = bindings.iter().map(buf).collect();
                    ctx.dispatch_groups(&mut enc, kernel, &bufs, *groups)?;
                }
                Command::Clear(r) => enc.clear_buffer(buf(r), 0, None),
                Command::Copy {
                    src,
                    src_offset,
                    dst,
                    dst_offset,
                    bytes,
                } => {
                    enc.copy_buffer_to_buffer(buf(src), *src_offset, buf(dst), *dst_offset, *bytes)
                }
            }
        }
        ctx.submit(enc);
        Ok(())
    }

    fn memory_usage(&self) -> MemoryUsage {
        MemoryUsage {
            bytes_in_use: self.ctx.bytes_in_use(),
            peak_bytes: self.ctx.peak_bytes(),
            uploaded_bytes: self.ctx.uploaded_bytes(),
            downloaded_bytes: self.ctx.downloaded_bytes(),
        }
    }
}
