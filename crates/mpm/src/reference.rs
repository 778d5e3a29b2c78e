//! The reference backend: single-threaded, plain index loops over the whole grid, clear before
//! fast. Every other backend is tested against it. It calls the per-particle and per-node
//! functions of [`crate::transfer`], which hold the math once.

use crate::adjoint::kernels::{AdjointScratch, MpmAdjointKernels};
use crate::adjoint::particle_vjp::{particle_stage_vjp, ParticleForward};
use crate::adjoint::transfer_vjp::{g2p_vjp, grid_node_vjp};
use crate::kernels::{
    Backend, Grid, GridBc, MemoryUsage, MpmKernels, ParticleBc, Particles, StepConsts,
    HEALTH_OUT_OF_DOMAIN,
};
use crate::material::PartConsts;
use crate::math::Real;
use crate::params::{MAT_CONSTS, PARAM_ADJOINTS};
use crate::state::State;
use crate::substep::{SubstepTables, Tape};
use crate::transfer::{
    damped_affine, g2p_finish, gather, grid_node_update, in_domain, k, out_of_domain_coordinate,
    particle_bcs, particle_stress, record, scatter, stencil,
};
use std::convert::Infallible;
use std::marker::PhantomData;

/// Single-threaded reference implementation of [`MpmKernels`] on host `Vec`s, in scalar type
/// `T` (`f64`: the gradient oracle).
#[derive(Clone, Copy, Debug, Default)]
pub struct ReferenceBackend<T = f32>(PhantomData<T>);

impl ReferenceBackend<f32> {
    /// The f32 reference backend.
    pub fn new() -> Self {
        ReferenceBackend(PhantomData)
    }
}

impl<T: Real> ReferenceBackend<T> {
    /// The reference backend in scalar type `T`.
    pub fn in_scalar() -> Self {
        ReferenceBackend(PhantomData)
    }
}

impl<T: Real> Backend for ReferenceBackend<T> {
    r4d_backend::host_vec_backend!();

    fn name(&self) -> &'static str {
        "reference"
    }
    fn memory_usage(&self) -> MemoryUsage {
        MemoryUsage::default()
    }
}

impl<T: Real> MpmKernels for ReferenceBackend<T> {
    type Scalar = T;
    crate::host_vec_accumulate!();

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
        mats: &Vec<[T; MAT_CONSTS]>,
        g: &mut Grid<Self>,
        c: &StepConsts,
    ) -> Result<(), Infallible> {
        g.nodes.fill([T::zero(); 4]);
        let inv_dx = k::<T>(c.inv_dx);
        for i in 0..p.count {
            let s = p.part[i] as usize;
            p.stress[i] = particle_stress(
                &mut p.f[i],
                &mut p.plastic[i],
                &p.c[i],
                p.vol0[i],
                &parts[s],
                &mats[s],
                c,
            );
        }
        for i in 0..p.count {
            if !in_domain(p.x[i], inv_dx, g.n) {
                continue; // reported by g2p's health check
            }
            let st = stencil(p.x[i], inv_dx);
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
        let inv_dx = k::<T>(c.inv_dx);
        for i in 0..p.count {
            if !in_domain(p.x[i], inv_dx, g.n) {
                let worst = out_of_domain_coordinate(p.x[i], inv_dx, g.n);
                record(&mut h, HEALTH_OUT_OF_DOMAIN, c.substep, i as u32, worst);
                continue;
            }
            let st = stencil(p.x[i], inv_dx);
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
}

impl<T: Real> MpmAdjointKernels for ReferenceBackend<T> {
    fn g2p_vjp(
        &self,
        before: &State<Self>,
        tape: &Tape<Self>,
        g: &Grid<Self>,
        adj: &State<Self>,
        c: &StepConsts,
        s: &mut AdjointScratch<Self>,
    ) -> Result<(), Infallible> {
        let inv_dx = k::<T>(c.inv_dx);
        s.grid_bar.fill([T::zero(); 4]);
        for i in 0..before.x.len() {
            if !in_domain(before.x[i], inv_dx, g.n) {
                s.x_bar[i] = [T::zero(); 3];
                s.fe_bar[i] = [T::zero(); 9];
                continue;
            }
            let b = g2p_vjp(
                &g.nodes,
                g.n,
                before.x[i],
                &tape.f_elastic[i],
                c,
                adj.x[i],
                adj.v[i],
                &adj.c[i],
                &adj.f[i],
                &mut s.grid_bar,
                0,
            );
            s.x_bar[i] = b.x;
            s.fe_bar[i] = b.f_elastic;
        }
        Ok(())
    }

    fn grid_update_vjp(
        &self,
        tape: &Tape<Self>,
        g: &Grid<Self>,
        bcs: &Vec<GridBc>,
        c: &StepConsts,
        s: &mut AdjointScratch<Self>,
    ) -> Result<(), Infallible> {
        let bcs = &bcs[..c.n_grid_bcs as usize];
        let n = g.n;
        for i in 0..n {
            for j in 0..n {
                for kk in 0..n {
                    let idx = (i * n + j) * n + kk;
                    s.grid_in_bar[idx] =
                        grid_node_vjp([i, j, kk], tape.grid_in[idx], s.grid_bar[idx], bcs, c);
                }
            }
        }
        Ok(())
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
    ) -> Result<(), Infallible> {
        let pbcs = &t.particle_bcs[..c.n_particle_bcs as usize];
        for i in 0..p.count {
            let slot = p.part[i] as usize;
            let fw = ParticleForward {
                x0: p.x0[i],
                x: before.x[i],
                c: &before.c[i],
                f_trial: &before.f[i],
                plastic: before.plastic[i],
                v1: tape.v1[i],
                mass: p.mass[i],
                vol0: p.vol0[i],
                stress: &p.stress[i],
                pc: &t.parts[slot],
                mat: &t.mats[slot],
            };
            let (bar, g) = particle_stage_vjp(
                &fw,
                &s.grid_in_bar,
                n,
                pbcs,
                c,
                &s.fe_bar[i],
                &s.x_bar[i],
                &adj.plastic[i],
            );
            adj.x[i] = bar.x;
            adj.v[i] = bar.v;
            adj.c[i] = bar.c;
            adj.f[i] = bar.f;
            adj.plastic[i] = bar.plastic;
            s.pgrad[i] = g;
        }
        Ok(())
    }

    fn reduce_slots(
        &self,
        pgrad: &Vec<[T; PARAM_ADJOINTS]>,
        slot: &Vec<u32>,
        grad: &mut Vec<[T; PARAM_ADJOINTS]>,
    ) -> Result<(), Infallible> {
        reduce_slots_in_order(pgrad, slot, grad);
        Ok(())
    }
}

/// Adds per-particle parameter adjoints to their slots' sums, in particle index order (the
/// host backends' deterministic reduction).
pub fn reduce_slots_in_order<T: Real>(
    pgrad: &[[T; PARAM_ADJOINTS]],
    slot: &[u32],
    grad: &mut [[T; PARAM_ADJOINTS]],
) {
    for (g, &s) in pgrad.iter().zip(slot) {
        let acc = &mut grad[s as usize];
        for (a, v) in acc.iter_mut().zip(g) {
            *a += *v;
        }
    }
}
