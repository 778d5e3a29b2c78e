//! The reverse stages of a substep on any GPU engine ([`MpmAdjointKernels`] for [`Gpu`]), run
//! in the order `r4d_mpm::substep::reverse` gives by the one differentiable stepper
//! `r4d_mpm::Simulation` (so the checkpointing driver, the forward
//! re-run with its tape and the per-slot chain rule are the CPU's).
//!
//! One recording per stage of `r4d-shaders`' kernels (`wgsl/mpm/`), mirroring the per-particle and per-node VJP
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
//! Measured on wgpu against the CPU backend in f32 (tests/backends/adjoint_conformance.rs, 2142 particles, 3 frames x 20
//! substeps, every boundary condition kind): jelly within 1.2e-4 relative; metal, sand,
//! foam, plasticine within 5e-4, snow 1.1e-3 (6e-3 on a nearly cancelled gradient); the
//! initial F adjoint within 1.4e-4 except sand's 1.2e-2 (f32 near the Drucker-Prager apex)
//! and snow's 1.4e-3.

use crate::backend::Gpu;
use crate::engine::{GpuBuf, GpuEngine};
use crate::mpm::Counts;
use crate::recording::Recording;
use r4d_mpm::adjoint::kernels::{AdjointScratch, MpmAdjointKernels};
use r4d_mpm::kernels::{Grid, GridBc, Particles, StepConsts};
use r4d_mpm::params::PARAM_ADJOINTS;
use r4d_mpm::substep::{SubstepTables, Tape};
use r4d_mpm::State;
use r4d_shaders::mpm as k;

/// Floats per particle of the reverse sweep's private record (`SBAR_STRIDE` in
/// `wgsl/lib/transfer_vjp.wgsl`).
pub const SBAR_STRIDE: usize = 32;
/// Floats per particle of the constant record (`INFO_STRIDE` there).
pub const INFO_STRIDE: usize = 8;

/// The engine's private buffers of the reverse particle stage.
pub(crate) struct ReverseRecords<E: GpuEngine> {
    sbar: GpuBuf<E, f32>,
    info: GpuBuf<E, f32>,
}

impl<E: GpuEngine> MpmAdjointKernels for Gpu<E> {
    fn g2p_vjp(
        &self,
        before: &State<Self>,
        tape: &Tape<Self>,
        g: &Grid<Self>,
        adj: &State<Self>,
        c: &StepConsts,
        s: &mut AdjointScratch<Self>,
    ) -> Result<(), E::Error> {
        let np = before.x.len;
        let mut r = Recording::new();
        let (x_bar, fe_bar, grid_bar) = (
            r.buf(&s.x_bar.raw),
            r.buf(&s.fe_bar.raw),
            r.buf(&s.grid_bar.raw),
        );
        // The kernel turns the position and F adjoints into those of the old position and of
        // F_elastic in place, on the scratch's copies.
        let (ax, af) = (r.buf(&adj.x.raw), r.buf(&adj.f.raw));
        r.copy(ax, x_bar, adj.x.bytes());
        r.copy(af, fe_bar, adj.f.bytes());
        r.clear(grid_bar);
        let bind = [
            r.uniform(c),
            r.uniform(&Counts::new(np, g.n)),
            r.buf(&g.nodes.raw),
            r.buf(&before.x.raw),
            r.buf(&tape.f_elastic.raw),
            x_bar,
            r.buf(&adj.v.raw),
            r.buf(&adj.c.raw),
            fe_bar,
            grid_bar,
        ];
        r.dispatch(&k::G2P_VJP, np as u32, &bind);
        self.engine().execute(r)
    }

    fn grid_update_vjp(
        &self,
        tape: &Tape<Self>,
        g: &Grid<Self>,
        bcs: &GpuBuf<E, GridBc>,
        c: &StepConsts,
        s: &mut AdjointScratch<Self>,
    ) -> Result<(), E::Error> {
        let n = g.n;
        let mut r = Recording::new();
        let bind = [
            r.uniform(c),
            r.uniform(&Counts::new(0, n)),
            r.buf(&bcs.raw),
            r.buf(&tape.grid_in.raw),
            r.buf(&s.grid_bar.raw),
            r.buf(&s.grid_in_bar.raw),
        ];
        r.dispatch(&k::GRID_UPDATE_VJP, (n * n * n) as u32, &bind);
        self.engine().execute(r)
    }

    fn p2g_vjp(
        &self,
        p: &Particles<Self>,
        before: &State<Self>,
        tape: &Tape<Self>,
        t: &SubstepTables<Self>,
        n: usize,
        c: &StepConsts,
        s: &mut AdjointScratch<Self>,
        adj: &mut State<Self>,
    ) -> Result<(), E::Error> {
        let np = p.count;
        let mut records = self
            .reverse_records
            .lock()
            .unwrap_or_else(|e| e.into_inner());
        if records
            .as_ref()
            .is_none_or(|r| r.info.len != INFO_STRIDE * np)
        {
            let e = self.engine();
            *records = Some(ReverseRecords {
                sbar: GpuBuf::zeros(e, "adjoint particle records", SBAR_STRIDE * np)?,
                info: GpuBuf::zeros(e, "adjoint particle constants", INFO_STRIDE * np)?,
            });
        }
        let rec = records.as_ref().expect("allocated above");
        let mut r = Recording::new();
        let (cb, cn) = (r.uniform(c), r.uniform(&Counts::new(np, n)));
        let (info, sbar) = (r.buf(&rec.info.raw), r.buf(&rec.sbar.raw));
        let pack = [
            cn,
            r.buf(&p.x0.raw),
            r.buf(&p.vol0.raw),
            r.buf(&p.mass.raw),
            r.buf(&p.part.raw),
            info,
        ];
        r.dispatch(&k::PACK_INFO, np as u32, &pack);
        let scatter = [
            cb,
            cn,
            r.buf(&before.x.raw),
            r.buf(&tape.v1.raw),
            r.buf(&before.c.raw),
            info,
            r.buf(&p.stress.raw),
            r.buf(&s.grid_in_bar.raw),
            sbar,
        ];
        r.dispatch(&k::SCATTER_VJP, np as u32, &scatter);
        // F_elastic's adjoint becomes F_trial's, the plastic state's after the substep
        // becomes the one before it.
        let (af, ap) = (r.buf(&adj.f.raw), r.buf(&adj.plastic.raw));
        let fe_bar = r.buf(&s.fe_bar.raw);
        r.copy(fe_bar, af, s.fe_bar.bytes());
        let stress = [
            cb,
            cn,
            r.buf(&t.parts.raw),
            info,
            r.buf(&before.f.raw),
            r.buf(&before.plastic.raw),
            sbar,
            af,
            ap,
            r.buf(&before.c.raw),
            r.buf(&adj.c.raw),
        ];
        r.dispatch(&k::STRESS_VJP, np as u32, &stress);
        let (ax, x_bar) = (r.buf(&adj.x.raw), r.buf(&s.x_bar.raw));
        r.copy(x_bar, ax, s.x_bar.bytes());
        let finish = [
            cb,
            cn,
            sbar,
            info,
            r.buf(&t.particle_bcs.raw),
            ax,
            r.buf(&adj.v.raw),
            r.buf(&adj.c.raw),
            ap,
            r.buf(&s.pgrad.raw),
        ];
        r.dispatch(&k::PARTICLE_VJP, np as u32, &finish);
        self.engine().execute(r)
    }

    fn reduce_slots(
        &self,
        pgrad: &GpuBuf<E, [f32; PARAM_ADJOINTS]>,
        slot: &GpuBuf<E, u32>,
        grad: &mut GpuBuf<E, [f32; PARAM_ADJOINTS]>,
    ) -> Result<(), E::Error> {
        let mut r = Recording::new();
        let bind = [
            r.uniform(&Counts::new(pgrad.len, 0)),
            r.buf(&pgrad.raw),
            r.buf(&slot.raw),
            r.buf(&grad.raw),
        ];
        r.dispatch(&k::REDUCE_SLOTS, pgrad.len as u32, &bind);
        self.engine().execute(r)
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
        for src in [
            r4d_shaders::mpm::PARTICLE_VJP.wgsl,
            r4d_shaders::mpm::REDUCE_SLOTS.wgsl,
        ] {
            assert!(src.contains(&format!(
                "const PGRAD_STRIDE: u32 = {}u;",
                super::PARAM_ADJOINTS
            )));
        }
    }
}
