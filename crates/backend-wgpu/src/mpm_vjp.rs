//! The reverse stages of a substep on the device ([`MpmAdjointKernels`] for [`WgpuMpm`]), run
//! in the order `r4d_mpm::substep::reverse` gives by the one differentiable stepper
//! `r4d_mpm::adjoint::engine::KernelAdjoint` (so the checkpointing driver, the forward
//! re-run with its tape and the per-slot chain rule are the CPU's).
//!
//! One WGSL kernel per step (`r4d-shaders/wgsl/mpm/`), mirroring the per-particle and per-node VJP
//! functions of `r4d_mpm::adjoint`:
//!
//! * [`g2p_vjp`](MpmAdjointKernels::g2p_vjp): `g2p_vjp`, one thread per particle; node velocity
//!   adjoints scattered with float atomics (native or compare-exchange, as `p2g`);
//! * [`grid_update_vjp`](MpmAdjointKernels::grid_update_vjp): one thread per node, every grid
//!   boundary condition (the branch the forward pass took);
//! * [`p2g_vjp`](MpmAdjointKernels::p2g_vjp): `pack_info` (the particle constants in one
//!   record), `scatter_vjp` (one thread per particle gathering the node adjoints, no atomics),
//!   `stress_vjp` (the constitutive VJP in f32: fixed corotated in closed form, every other
//!   isotropic model as the CPU does it, the scalar model's Jacobian from dual numbers in
//!   `r4d-shaders/wgsl/lib/dual_model.wgsl`, the matrix part by divided differences; the
//!   regularisation threshold differs from the CPU's: see the kernel's header), then
//!   `particle_vjp` (particle conditions, RPIC damping, per-particle parameter adjoints);
//! * [`reduce_slots`](MpmAdjointKernels::reduce_slots): `reduce_slots`, a tree reduction per
//!   slot in workgroup memory, then one float atomic per slot and field.
//!
//! Between its own stages the backend keeps the position and F_elastic adjoints of
//! [`AdjointScratch`] in place (the kernels update them) and a private per-particle record
//! (`sbar`, 32 floats, plus the 8-float constant record `info`), allocated at the first
//! reverse substep and kept with the backend.
//!
//! A particle outside the grid is skipped by the transfers and gets a zero adjoint, as on the
//! CPU. Scattered sums follow the hardware's order: results are not bitwise reproducible.
//! Measured against the CPU backend in f32 (tests/adjoint.rs, 2142 particles, 3 frames x 20
//! substeps, every boundary condition kind): jelly within 1.2e-4 relative; metal, sand,
//! foam, plasticine within 5e-4, snow 1.1e-3 (6e-3 on a nearly cancelled gradient); the
//! initial F adjoint within 1.4e-4 except sand's 1.2e-2 (f32 near the Drucker-Prager apex)
//! and snow's 1.4e-3.

use crate::context::{GpuBuffer, WgpuError};
use crate::mpm::WgpuMpm;
use r4d_mpm::adjoint::engine::{AdjointScratch, MpmAdjointKernels, StateBufs};
use r4d_mpm::kernels::{Grid, GridBc, Particles, StepConsts};
use r4d_mpm::substep::{SubstepTables, Tape};

/// Floats per particle of the reverse sweep's private record (`SBAR_STRIDE` in
/// `r4d-shaders/wgsl/lib/transfer_vjp.wgsl`).
const SBAR_STRIDE: usize = 32;
/// Floats per particle of the constant record (`INFO_STRIDE` there).
const INFO_STRIDE: usize = 8;

/// The backend's private buffers of the reverse particle stage.
pub(crate) struct ReverseRecords {
    sbar: GpuBuffer<f32>,
    info: GpuBuffer<f32>,
}

/// Records a copy of a whole buffer.
fn copy_all<T>(enc: &mut wgpu::CommandEncoder, src: &GpuBuffer<T>, dst: &GpuBuffer<T>) {
    let bytes = src.bytes().min(dst.bytes());
    if bytes > 0 {
        enc.copy_buffer_to_buffer(&src.buffer, 0, &dst.buffer, 0, bytes);
    }
}

impl MpmAdjointKernels for WgpuMpm {
    fn g2p_vjp(
        &self,
        before: &StateBufs<Self>,
        tape: &Tape<Self>,
        g: &Grid<Self>,
        adj: &StateBufs<Self>,
        c: &StepConsts,
        s: &mut AdjointScratch<Self>,
    ) -> Result<(), WgpuError> {
        let np = before.x.len;
        let (cb, counts) = self.consts(c, np, g.n)?;
        let ctx = self.context();
        let mut enc = ctx.encoder();
        // The kernel turns the position and F adjoints into those of the old position and of
        // F_elastic in place, on the scratch's copies.
        copy_all(&mut enc, &adj.x, &s.x_bar);
        copy_all(&mut enc, &adj.f, &s.fe_bar);
        enc.clear_buffer(&s.grid_bar.buffer, 0, None);
        ctx.dispatch(
            &mut enc,
            &r4d_shaders::mpm::G2P_VJP,
            &[
                &cb.buffer,
                &counts.buffer,
                &g.nodes.buffer,
                &before.x.buffer,
                &tape.f_elastic.buffer,
                &s.x_bar.buffer,
                &adj.v.buffer,
                &adj.c.buffer,
                &s.fe_bar.buffer,
                &s.grid_bar.buffer,
            ],
            np as u32,
        )?;
        ctx.submit(enc);
        Ok(())
    }

    fn grid_update_vjp(
        &self,
        tape: &Tape<Self>,
        n: usize,
        bcs: &GpuBuffer<GridBc>,
        c: &StepConsts,
        s: &mut AdjointScratch<Self>,
    ) -> Result<(), WgpuError> {
        let (cb, counts) = self.consts(c, 0, n)?;
        let ctx = self.context();
        let mut enc = ctx.encoder();
        ctx.dispatch(
            &mut enc,
            &r4d_shaders::mpm::GRID_UPDATE_VJP,
            &[
                &cb.buffer,
                &counts.buffer,
                &bcs.buffer,
                &tape.grid_in.buffer,
                &s.grid_bar.buffer,
                &s.grid_in_bar.buffer,
            ],
            (n * n * n) as u32,
        )?;
        ctx.submit(enc);
        Ok(())
    }

    fn p2g_vjp(
        &self,
        p: &Particles<Self>,
        before: &StateBufs<Self>,
        tape: &Tape<Self>,
        t: &SubstepTables<Self>,
        n: usize,
        c: &StepConsts,
        s: &mut AdjointScratch<Self>,
        adj: &mut StateBufs<Self>,
    ) -> Result<(), WgpuError> {
        let np = p.count;
        let mut records = self.reverse_records.lock().expect("reverse records");
        if records
            .as_ref()
            .is_none_or(|r| r.info.len != INFO_STRIDE * np)
        {
            let ctx = self.context();
            *records = Some(ReverseRecords {
                sbar: ctx.zeros("adjoint particle records", SBAR_STRIDE * np)?,
                info: ctx.zeros("adjoint particle constants", INFO_STRIDE * np)?,
            });
        }
        let r = records.as_ref().expect("allocated above");
        let (cb, counts) = self.consts(c, np, n)?;
        let ctx = self.context();
        let (c, k) = (&cb.buffer, &counts.buffer);
        let mut enc = ctx.encoder();
        ctx.dispatch(
            &mut enc,
            &r4d_shaders::mpm::PACK_INFO,
            &[
                k,
                &p.x0.buffer,
                &p.vol0.buffer,
                &p.mass.buffer,
                &p.part.buffer,
                &r.info.buffer,
            ],
            np as u32,
        )?;
        ctx.dispatch(
            &mut enc,
            &r4d_shaders::mpm::SCATTER_VJP,
            &[
                c,
                k,
                &before.x.buffer,
                &tape.v1.buffer,
                &before.c.buffer,
                &r.info.buffer,
                &p.stress.buffer,
                &s.grid_in_bar.buffer,
                &r.sbar.buffer,
            ],
            np as u32,
        )?;
        // F_elastic's adjoint becomes F_trial's, the plastic state's after the substep
        // becomes the one before it.
        copy_all(&mut enc, &s.fe_bar, &adj.f);
        ctx.dispatch(
            &mut enc,
            &r4d_shaders::mpm::STRESS_VJP,
            &[
                c,
                k,
                &t.parts.buffer,
                &r.info.buffer,
                &before.f.buffer,
                &before.plastic.buffer,
                &r.sbar.buffer,
                &adj.f.buffer,
                &adj.plastic.buffer,
            ],
            np as u32,
        )?;
        copy_all(&mut enc, &s.x_bar, &adj.x);
        ctx.dispatch(
            &mut enc,
            &r4d_shaders::mpm::PARTICLE_VJP,
            &[
                c,
                k,
                &r.sbar.buffer,
                &r.info.buffer,
                &t.particle_bcs.buffer,
                &adj.x.buffer,
                &adj.v.buffer,
                &adj.c.buffer,
                &adj.plastic.buffer,
                &s.pgrad.buffer,
            ],
            np as u32,
        )?;
        ctx.submit(enc);
        Ok(())
    }

    fn reduce_slots(
        &self,
        pgrad: &GpuBuffer<[f32; 5]>,
        slot: &GpuBuffer<u32>,
        grad: &mut GpuBuffer<[f32; 5]>,
    ) -> Result<(), WgpuError> {
        let counts = self.counts(pgrad.len, 0)?;
        let ctx = self.context();
        let mut enc = ctx.encoder();
        ctx.dispatch(
            &mut enc,
            &r4d_shaders::mpm::REDUCE_SLOTS,
            &[&counts.buffer, &pgrad.buffer, &slot.buffer, &grad.buffer],
            pgrad.len as u32,
        )?;
        ctx.submit(enc);
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn record_strides_match_the_shaders() {
        let src = r4d_shaders::mpm::SCATTER_VJP.wgsl;
        assert!(src.contains(&format!(
            "const SBAR_STRIDE: u32 = {}u;",
            super::SBAR_STRIDE
        )));
        assert!(src.contains(&format!(
            "const INFO_STRIDE: u32 = {}u;",
            super::INFO_STRIDE
        )));
    }
}
