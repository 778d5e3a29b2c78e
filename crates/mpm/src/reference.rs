//! The reference backend: single-threaded, plain index loops over the whole grid, clear before
//! fast. Every other backend is tested against it. It calls the per-particle and per-node
//! functions of [`crate::transfer`], which hold the math once.

use crate::kernels::{
    Grid, GridBc, MemoryUsage, MpmKernels, ParticleBc, Particles, StepConsts, HEALTH_OUT_OF_DOMAIN,
};
use crate::material::PartConsts;
use crate::transfer::{
    damped_affine, g2p_finish, gather, grid_node_update, in_domain, particle_bcs, particle_stress,
    record, scatter, stencil,
};
use std::convert::Infallible;

/// Single-threaded reference implementation of [`MpmKernels`] on host `Vec`s.
#[derive(Clone, Copy, Debug, Default)]
pub struct ReferenceBackend;

impl MpmKernels for ReferenceBackend {
    crate::host_vec_buffers!();

    fn name(&self) -> &'static str {
        "reference"
    }
    fn particle_bcs(
        &self,
        p: &mut Particles<Self>,
        bcs: &Vec<ParticleBc>,
        c: &StepConsts,
    ) -> Result<(), Infallible> {
        let bcs = &bcs[..c.n_particle_bcs as usize];
        for i in 0..p.count {
            particle_bcs(p.x0[i], &mut p.v[i], p.mass[i], bcs, c);
        }
        Ok(())
    }

    fn p2g(
        &self,
        p: &mut Particles<Self>,
        parts: &Vec<PartConsts>,
        g: &mut Grid<Self>,
        c: &StepConsts,
    ) -> Result<(), Infallible> {
        g.nodes.fill([0.0; 4]);
        for i in 0..p.count {
            let pc = &parts[p.part[i] as usize];
            p.stress[i] =
                particle_stress(&mut p.f[i], &mut p.plastic[i], &p.c[i], p.vol0[i], pc, c);
        }
        for i in 0..p.count {
            if !in_domain(p.x[i], c.inv_dx, g.n) {
                continue; // reported by g2p's health check
            }
            let st = stencil(p.x[i], c.inv_dx);
            let cm = damped_affine(&p.c[i], c.rpic_damping);
            scatter(
                &mut g.nodes,
                0,
                g.n,
                &st,
                p.v[i],
                &cm,
                p.mass[i],
                &p.stress[i],
                c,
            );
        }
        Ok(())
    }

    fn grid_update(
        &self,
        g: &mut Grid<Self>,
        bcs: &Vec<GridBc>,
        c: &StepConsts,
    ) -> Result<(), Infallible> {
        let n = g.n;
        let bcs = &bcs[..c.n_grid_bcs as usize];
        for i in 0..n {
            for j in 0..n {
                for k in 0..n {
                    grid_node_update([i, j, k], &mut g.nodes[(i * n + j) * n + k], bcs, c);
                }
            }
        }
        Ok(())
    }

    fn g2p(
        &self,
        p: &mut Particles<Self>,
        g: &mut Grid<Self>,
        c: &StepConsts,
    ) -> Result<(), Infallible> {
        let mut h = g.health[0];
        for i in 0..p.count {
            if !in_domain(p.x[i], c.inv_dx, g.n) {
                record(&mut h, HEALTH_OUT_OF_DOMAIN, c.substep, i as u32, p.x[i][0]);
                continue;
            }
            let st = stencil(p.x[i], c.inv_dx);
            let gathered = gather(&g.nodes, g.n, &st, c);
            let (code, val) = g2p_finish(
                &gathered,
                &mut p.x[i],
                &mut p.v[i],
                &mut p.c[i],
                &mut p.f[i],
                c,
            );
            record(&mut h, code, c.substep, i as u32, val);
        }
        g.health[0] = h;
        Ok(())
    }

    fn memory_usage(&self) -> MemoryUsage {
        MemoryUsage::default()
    }
}
