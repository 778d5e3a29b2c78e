//! [`r4d_mpm::MpmKernels`] on wgpu: particles and grid live in device buffers; the host sees
//! them only through `download`. One WGSL kernel per stage (`r4d-shaders/wgsl/mpm/`), mirroring the
//! per-particle and per-node functions of `r4d_mpm::transfer` and `r4d_mpm::constitutive`:
//!
//! * `particle_bcs`: one thread per particle;
//! * `p2g`: clear the grid, `p2g_stress` (return mapping and stress, one thread per
//!   particle), then `p2g` (the scatter with float atomics, native or compare-exchange);
//! * `grid_update`: one thread per node, every boundary condition in order;
//! * `g2p`: one thread per particle, then `health` (one thread) keeps the first problem of
//!   the substep, lowest particle index, as the CPU backends do.
//!
//! Scattered sums are added in the order the hardware runs the atomics, so results differ
//! from the CPU backend by rounding (not bitwise reproducible run to run); the conformance
//! tests bound the difference.

use crate::context::{GpuBuffer, WgpuContext, WgpuError};
use bytemuck::{Pod, Zeroable};
use r4d_mpm::kernels::{Grid, GridBc, MemoryUsage, MpmKernels, ParticleBc, Particles, StepConsts};
use r4d_mpm::PartConsts;
use std::sync::{Arc, Mutex};

/// Per-dispatch sizes (`Counts` in `r4d-shaders/wgsl/lib/structs.wgsl`).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct Counts {
    /// Particles.
    pub particles: u32,
    /// Grid nodes per axis.
    pub n_grid: u32,
    /// Padding.
    pub _pad: [u32; 2],
}

/// The wgpu MPM backend.
pub struct WgpuMpm {
    ctx: Arc<WgpuContext>,
    scratch: Mutex<Option<GpuBuffer<u32>>>,
    pub(crate) reverse_records: Mutex<Option<crate::mpm_vjp::ReverseRecords>>,
}

impl WgpuMpm {
    /// A backend on a device.
    pub fn new(ctx: Arc<WgpuContext>) -> Self {
        WgpuMpm {
            ctx,
            scratch: Mutex::new(None),
            reverse_records: Mutex::new(None),
        }
    }

    /// The device.
    pub fn context(&self) -> &Arc<WgpuContext> {
        &self.ctx
    }

    /// The uniforms of a dispatch: the substep's constants and the sizes.
    pub(crate) fn consts(
        &self,
        c: &StepConsts,
        particles: usize,
        n: usize,
    ) -> Result<(GpuBuffer<StepConsts>, GpuBuffer<Counts>), WgpuError> {
        Ok((
            self.ctx.uniform("StepConsts", c)?,
            self.counts(particles, n)?,
        ))
    }

    /// The sizes uniform of a dispatch.
    pub(crate) fn counts(
        &self,
        particles: usize,
        n: usize,
    ) -> Result<GpuBuffer<Counts>, WgpuError> {
        self.ctx.uniform(
            "Counts",
            &Counts {
                particles: particles as u32,
                n_grid: n as u32,
                _pad: [0; 2],
            },
        )
    }
}

impl MpmKernels for WgpuMpm {
    type Scalar = f32;
    type Buf<T: Pod + Send + Sync> = GpuBuffer<T>;
    type Error = WgpuError;

    fn name(&self) -> &'static str {
        "wgpu"
    }

    fn upload<T: Pod + Send + Sync>(&self, data: &[T]) -> Result<GpuBuffer<T>, WgpuError> {
        self.ctx.upload(std::any::type_name::<T>(), data)
    }

    fn zeros<T: Pod + Send + Sync>(&self, len: usize) -> Result<GpuBuffer<T>, WgpuError> {
        self.ctx.zeros(std::any::type_name::<T>(), len)
    }

    fn download<T: Pod + Send + Sync>(&self, buf: &GpuBuffer<T>) -> Result<Vec<T>, WgpuError> {
        self.ctx.download(buf)
    }

    fn write<T: Pod + Send + Sync>(
        &self,
        buf: &mut GpuBuffer<T>,
        data: &[T],
    ) -> Result<(), WgpuError> {
        assert_eq!(buf.len, data.len(), "write: same length");
        self.ctx.write(buf, data);
        Ok(())
    }

    fn copy<T: Pod + Send + Sync>(
        &self,
        src: &GpuBuffer<T>,
        dst: &mut GpuBuffer<T>,
    ) -> Result<(), WgpuError> {
        let bytes = src.bytes().min(dst.bytes());
        if bytes > 0 {
            let mut enc = self.ctx.encoder();
            enc.copy_buffer_to_buffer(&src.buffer, 0, &dst.buffer, 0, bytes);
            self.ctx.submit(enc);
        }
        Ok(())
    }

    fn accumulate<const N: usize>(
        &self,
        dst: &mut GpuBuffer<[f32; N]>,
        add: &[[f32; N]],
    ) -> Result<(), WgpuError> {
        assert_eq!(dst.len, add.len(), "accumulate: same length");
        if add.is_empty() {
            return Ok(());
        }
        let src: GpuBuffer<[f32; N]> = self.ctx.upload("adjoint increment", add)?;
        let counts = self.counts(N * add.len(), 0)?;
        let mut enc = self.ctx.encoder();
        self.ctx.dispatch(
            &mut enc,
            &r4d_shaders::mpm::ADD_VJP,
            &[&counts.buffer, &src.buffer, &dst.buffer],
            (N * add.len()) as u32,
        )?;
        self.ctx.submit(enc);
        Ok(())
    }

    fn particle_bcs(
        &self,
        p: &mut Particles<Self>,
        bcs: &GpuBuffer<ParticleBc>,
        c: &StepConsts,
    ) -> Result<(), WgpuError> {
        if c.n_particle_bcs == 0 {
            return Ok(());
        }
        let (cb, counts) = self.consts(c, p.count, c.n_grid as usize)?;
        let mut enc = self.ctx.encoder();
        self.ctx.dispatch(
            &mut enc,
            &r4d_shaders::mpm::PARTICLE_BCS,
            &[
                &cb.buffer,
                &counts.buffer,
                &bcs.buffer,
                &p.x0.buffer,
                &p.mass.buffer,
                &p.v.buffer,
            ],
            p.count as u32,
        )?;
        self.ctx.submit(enc);
        Ok(())
    }

    fn p2g(
        &self,
        p: &mut Particles<Self>,
        parts: &GpuBuffer<PartConsts>,
        // The f32 kernels read the material constants from `parts` (the same values).
        _mats: &GpuBuffer<[f32; 4]>,
        g: &mut Grid<Self>,
        c: &StepConsts,
    ) -> Result<(), WgpuError> {
        let (cb, counts) = self.consts(c, p.count, g.n)?;
        let mut enc = self.ctx.encoder();
        enc.clear_buffer(&g.nodes.buffer, 0, None);
        self.ctx.dispatch(
            &mut enc,
            &r4d_shaders::mpm::P2G_STRESS,
            &[
                &cb.buffer,
                &counts.buffer,
                &parts.buffer,
                &p.part.buffer,
                &p.vol0.buffer,
                &p.c.buffer,
                &p.f.buffer,
                &p.plastic.buffer,
                &p.stress.buffer,
            ],
            p.count as u32,
        )?;
        self.ctx.dispatch(
            &mut enc,
            &r4d_shaders::mpm::P2G,
            &[
                &cb.buffer,
                &counts.buffer,
                &p.x.buffer,
                &p.v.buffer,
                &p.c.buffer,
                &p.mass.buffer,
                &p.stress.buffer,
                &g.nodes.buffer,
            ],
            p.count as u32,
        )?;
        self.ctx.submit(enc);
        Ok(())
    }

    fn grid_update(
        &self,
        g: &mut Grid<Self>,
        bcs: &GpuBuffer<GridBc>,
        c: &StepConsts,
    ) -> Result<(), WgpuError> {
        let (cb, counts) = self.consts(c, 0, g.n)?;
        let mut enc = self.ctx.encoder();
        self.ctx.dispatch(
            &mut enc,
            &r4d_shaders::mpm::GRID_UPDATE,
            &[&cb.buffer, &counts.buffer, &bcs.buffer, &g.nodes.buffer],
            (g.n * g.n * g.n) as u32,
        )?;
        self.ctx.submit(enc);
        Ok(())
    }

    fn g2p(
        &self,
        p: &mut Particles<Self>,
        g: &mut Grid<Self>,
        c: &StepConsts,
    ) -> Result<(), WgpuError> {
        let mut scratch = self.scratch.lock().expect("scratch");
        if scratch.as_ref().is_none_or(|s| s.len < 1 + 2 * p.count) {
            let mut init = vec![0u32; 1 + 2 * p.count];
            init[0] = u32::MAX;
            *scratch = Some(self.ctx.upload("health scratch", &init)?);
        }
        let scratch = scratch.as_ref().expect("allocated");
        let (cb, counts) = self.consts(c, p.count, g.n)?;
        let mut enc = self.ctx.encoder();
        self.ctx.dispatch(
            &mut enc,
            &r4d_shaders::mpm::G2P,
            &[
                &cb.buffer,
                &counts.buffer,
                &g.nodes.buffer,
                &p.x.buffer,
                &p.v.buffer,
                &p.c.buffer,
                &p.f.buffer,
                &scratch.buffer,
            ],
            p.count as u32,
        )?;
        self.ctx.dispatch(
            &mut enc,
            &r4d_shaders::mpm::HEALTH,
            &[&cb.buffer, &scratch.buffer, &g.health.buffer],
            1,
        )?;
        self.ctx.submit(enc);
        Ok(())
    }

    fn memory_usage(&self) -> MemoryUsage {
        MemoryUsage {
            bytes_in_use: self.ctx.bytes_in_use(),
            peak_bytes: self.ctx.peak_bytes(),
        }
    }
}
