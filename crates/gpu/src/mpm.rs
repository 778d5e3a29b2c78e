//! [`r4d_mpm::MpmKernels`] for [`Gpu`] on every engine: particles and grid live in device buffers;
//! the host sees them only through `download`. Each stage is one recording of
//! `r4d-shaders`' MPM kernels (`wgsl/mpm/`), mirroring the per-particle and per-node
//! functions of `r4d_mpm::transfer` and `r4d_mpm::constitutive`:
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

use crate::backend::Gpu;
use crate::engine::{GpuBuf, GpuEngine};
use crate::recording::Recording;
use bytemuck::{Pod, Zeroable};
use r4d_mpm::kernels::{Grid, GridBc, MpmKernels, ParticleBc, Particles, StepConsts};
use r4d_mpm::params::MAT_CONSTS;
use r4d_mpm::PartConsts;
use r4d_shaders::mpm as k;

/// Per-dispatch sizes (`Counts` in `wgsl/lib/structs.wgsl`).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct Counts {
    /// Particles (or values, for element-wise kernels).
    pub particles: u32,
    /// Grid nodes per axis.
    pub n_grid: u32,
    /// Padding.
    pub _pad: [u32; 2],
}

impl Counts {
    /// Sizes of a dispatch.
    pub fn new(particles: usize, n_grid: usize) -> Self {
        Counts {
            particles: particles as u32,
            n_grid: n_grid as u32,
            _pad: [0; 2],
        }
    }
}

impl<E: GpuEngine> MpmKernels for Gpu<E> {
    type Scalar = f32;

    fn accumulate<const N: usize>(
        &self,
        dst: &mut GpuBuf<E, [f32; N]>,
        add: &[[f32; N]],
    ) -> Result<(), E::Error> {
        assert_eq!(dst.len, add.len(), "accumulate: same length");
        let n = N * add.len();
        let mut r = Recording::new();
        let bind = [r.uniform(&Counts::new(n, 0)), r.data(add), r.buf(&dst.raw)];
        r.dispatch(&k::ADD_VJP, n as u32, &bind);
        self.engine.execute(r)
    }

    fn accumulate_buf<const N: usize>(
        &self,
        dst: &mut GpuBuf<E, [f32; N]>,
        add: &GpuBuf<E, [f32; N]>,
    ) -> Result<(), E::Error> {
        assert_eq!(dst.len, add.len, "accumulate_buf: same length");
        let n = N * add.len;
        if n == 0 {
            return Ok(());
        }
        let mut r = Recording::new();
        let bind = [
            r.uniform(&Counts::new(n, 0)),
            r.buf(&add.raw),
            r.buf(&dst.raw),
        ];
        r.dispatch(&k::ADD_VJP, n as u32, &bind);
        self.engine.execute(r)
    }

    fn particle_bcs(
        &self,
        p: &mut Particles<Self>,
        bcs: &GpuBuf<E, ParticleBc>,
        c: &StepConsts,
    ) -> Result<(), E::Error> {
        if c.n_particle_bcs == 0 {
            return Ok(());
        }
        let mut r = Recording::new();
        let bind = [
            r.uniform(c),
            r.uniform(&Counts::new(p.count, c.n_grid as usize)),
            r.buf(&bcs.raw),
            r.buf(&p.x0.raw),
            r.buf(&p.mass.raw),
            r.buf(&p.v.raw),
        ];
        r.dispatch(&k::PARTICLE_BCS, p.count as u32, &bind);
        self.engine.execute(r)
    }

    fn p2g(
        &self,
        p: &mut Particles<Self>,
        parts: &GpuBuf<E, PartConsts>,
        // The f32 kernels read the material constants from `parts` (the same values).
        _mats: &GpuBuf<E, [f32; MAT_CONSTS]>,
        g: &mut Grid<Self>,
        c: &StepConsts,
    ) -> Result<(), E::Error> {
        let mut r = Recording::new();
        let (cb, n) = (r.uniform(c), r.uniform(&Counts::new(p.count, g.n)));
        let nodes = r.buf(&g.nodes.raw);
        let (x, v, cm, f) = (
            r.buf(&p.x.raw),
            r.buf(&p.v.raw),
            r.buf(&p.c.raw),
            r.buf(&p.f.raw),
        );
        let (mass, stress) = (r.buf(&p.mass.raw), r.buf(&p.stress.raw));
        r.clear(nodes);
        let stress_bind = [
            cb,
            n,
            r.buf(&parts.raw),
            r.buf(&p.part.raw),
            r.buf(&p.vol0.raw),
            cm,
            f,
            r.buf(&p.plastic.raw),
            stress,
        ];
        r.dispatch(&k::P2G_STRESS, p.count as u32, &stress_bind);
        r.dispatch(
            &k::P2G,
            p.count as u32,
            &[cb, n, x, v, cm, mass, stress, nodes],
        );
        self.engine.execute(r)
    }

    fn grid_update(
        &self,
        g: &mut Grid<Self>,
        bcs: &GpuBuf<E, GridBc>,
        c: &StepConsts,
    ) -> Result<(), E::Error> {
        let mut r = Recording::new();
        let bind = [
            r.uniform(c),
            r.uniform(&Counts::new(0, g.n)),
            r.buf(&bcs.raw),
            r.buf(&g.nodes.raw),
        ];
        r.dispatch(&k::GRID_UPDATE, (g.n * g.n * g.n) as u32, &bind);
        self.engine.execute(r)
    }

    fn g2p(
        &self,
        p: &mut Particles<Self>,
        g: &mut Grid<Self>,
        c: &StepConsts,
    ) -> Result<(), E::Error> {
        let mut scratch = self
            .health_scratch
            .lock()
            .unwrap_or_else(|e| e.into_inner());
        if scratch.as_ref().is_none_or(|s| s.len < 1 + 2 * p.count) {
            let mut init = vec![0u32; 1 + 2 * p.count];
            init[0] = u32::MAX;
            *scratch = Some(GpuBuf::upload(&self.engine, "health scratch", &init)?);
        }
        let scratch = scratch.as_ref().expect("allocated above");
        let mut r = Recording::new();
        let cb = r.uniform(c);
        let sc = r.buf(&scratch.raw);
        let bind = [
            cb,
            r.uniform(&Counts::new(p.count, g.n)),
            r.buf(&g.nodes.raw),
            r.buf(&p.x.raw),
            r.buf(&p.v.raw),
            r.buf(&p.c.raw),
            r.buf(&p.f.raw),
            sc,
        ];
        r.dispatch(&k::G2P, p.count as u32, &bind);
        let health = r.buf(&g.health.raw);
        r.dispatch_groups(&k::HEALTH, [1, 1, 1], &[cb, sc, health]);
        self.engine.execute(r)
    }
}
