//! The parallel (rayon) forward and reverse substep of the host simulator
//! ([`r4d_mpm::adjoint::host`]), as a [`Differentiable`] stepper for the checkpointed driver.
//!
//! It runs exactly the per-particle and per-node functions (and their VJPs) that the
//! single-threaded [`HostSim`] runs, adding only scheduling: particles in parallel, grid
//! nodes in parallel, and the two scatters (P2G, and the node adjoints of G2P) by colour-slabs
//! ([`crate::slabs`]) so no two threads write the same node. Parameter gradients are summed
//! per particle first and then over particles in index order, so results do not depend on
//! the number of threads.

use crate::slabs;
use r4d_mpm::adjoint::checkpoint::Differentiable;
use r4d_mpm::adjoint::host::{
    add_grad, HostSim, HostState, ParticleBar, PhysParams, SubstepRecord,
};
use r4d_mpm::adjoint::transfer_vjp::{g2p_vjp, grid_node_update_vjp, G2pBar};
use r4d_mpm::constitutive::MaterialParams;
use r4d_mpm::math::Real;
use r4d_mpm::transfer::{
    damped_affine, g2p_finish, gather, grid_node_update, in_domain, k, scatter, stencil,
};
use r4d_mpm::StepConsts;
use rayon::prelude::*;
use std::sync::Mutex;

/// [`HostSim`]'s substep and its reverse sweep, in parallel, in scalar type `T`.
pub struct ParallelHost<'a, T> {
    /// The simulator (config, particles, parts).
    pub sim: &'a HostSim,
    /// Grid buffers reused across substeps (allocating them anew costs page faults).
    pool: Mutex<Vec<Vec<[T; 4]>>>,
}

impl<'a, T: Real> ParallelHost<'a, T> {
    /// Wraps a host simulator.
    pub fn new(sim: &'a HostSim) -> Self {
        ParallelHost {
            sim,
            pool: Mutex::new(Vec::new()),
        }
    }

    /// A zeroed grid buffer from the pool.
    fn take_grid(&self) -> Vec<[T; 4]> {
        let n = self.sim.setup.n;
        let got = self.pool.lock().expect("grid pool").pop();
        match got {
            Some(mut g) => {
                g.par_iter_mut().for_each(|x| *x = [T::zero(); 4]);
                g
            }
            None => vec![[T::zero(); 4]; n * n * n],
        }
    }

    /// Returns a grid buffer to the pool.
    fn put_grid(&self, g: Vec<[T; 4]>) {
        self.pool.lock().expect("grid pool").push(g);
    }
}

/// A substep's forward record and its constants.
struct Forward<T> {
    c: StepConsts,
    rec: SubstepRecord<T>,
}

impl<T: Real> ParallelHost<'_, T> {
    /// Particle ids sorted by slab of their stencil base (positions `x`).
    fn slab_order(&self, x: &[[T; 3]], inv_dx: T) -> (Vec<u32>, Vec<u32>) {
        let n = self.sim.setup.n;
        // Particles outside the grid (or NaN) are left out of every transfer.
        let base: Vec<Option<u32>> = x
            .par_iter()
            .map(|p| in_domain(*p, inv_dx, n).then(|| stencil(*p, inv_dx).base[0] as u32))
            .collect();
        let mut order = vec![0u32; x.len()];
        let mut starts = vec![0u32; slabs::slab_count(n) + 1];
        slabs::sort_by_slab(&base, n, &mut order, &mut starts);
        (order, starts)
    }

    fn forward(&self, s: &mut HostState<T>, params: &[PhysParams<T>], k_sub: u64) -> Forward<T> {
        let sim = self.sim;
        let c = sim.consts_at(k_sub);
        let n = sim.setup.n;
        let mats: Vec<MaterialParams<T>> = params.iter().map(|p| p.material()).collect();
        let mass = sim.masses(params);
        let inv_dx = k::<T>(c.inv_dx);
        let x_start = s.x.clone();
        let f_trial = s.f.clone();
        let plastic_in = s.plastic.clone();
        let mut v1 = s.v.clone();
        let mut stress = vec![[T::zero(); 9]; sim.len()];
        v1.par_iter_mut()
            .zip(s.f.par_iter_mut())
            .zip(s.plastic.par_iter_mut())
            .zip(stress.par_iter_mut())
            .enumerate()
            .for_each(|(p, (((v, f), pl), st))| {
                *st = sim.particle_stage(p, &c, &mats, mass[p], v, f, pl);
            });
        let (order, starts) = self.slab_order(&s.x, inv_dx);
        let mut grid_in = self.take_grid();
        {
            let (x, cm) = (&s.x, &s.c);
            slabs::scatter_by_slab(&mut grid_in, n * n, n, &order, &starts, |lo, ids, nodes| {
                for &i in ids {
                    let i = i as usize;
                    let st = stencil(x[i], inv_dx);
                    let a = damped_affine(&cm[i], c.rpic_damping);
                    scatter(nodes, lo, n, &st, v1[i], &a, mass[i], &stress[i], &c);
                }
            });
        }
        let mut grid = self.take_grid();
        grid.par_iter_mut()
            .zip(grid_in.par_iter())
            .for_each(|(a, b)| *a = *b);
        grid.par_chunks_mut(n * n)
            .enumerate()
            .for_each(|(i, plane)| {
                for (jk, node) in plane.iter_mut().enumerate() {
                    if node[3] > T::zero() {
                        grid_node_update([i, jk / n, jk % n], node, &sim.setup.grid_bcs, &c);
                    }
                }
            });
        let f_elastic = s.f.clone();
        s.x.par_iter_mut()
            .zip(s.v.par_iter_mut())
            .zip(s.c.par_iter_mut())
            .zip(s.f.par_iter_mut())
            .for_each(|(((x, v), cm), f)| {
                if !in_domain(*x, inv_dx, n) {
                    return;
                }
                let st = stencil(*x, inv_dx);
                let g = gather(&grid, n, &st, &c);
                let _ = g2p_finish(&g, x, v, cm, f, &c);
            });
        Forward {
            c,
            rec: SubstepRecord {
                mass,
                v1,
                stress,
                x_start,
                f_trial,
                f_elastic,
                plastic_in,
                grid_in,
                grid,
                mats,
            },
        }
    }
}

impl<T: Real> Differentiable for ParallelHost<'_, T> {
    type State = HostState<T>;
    type Params = Vec<PhysParams<T>>;
    type Grad = Vec<PhysParams<T>>;

    fn step(&self, s: &mut HostState<T>, p: &Vec<PhysParams<T>>, k_sub: u64) {
        let fw = self.forward(s, p, k_sub);
        self.put_grid(fw.rec.grid_in);
        self.put_grid(fw.rec.grid);
    }

    fn step_vjp(
        &self,
        before: &HostState<T>,
        params: &Vec<PhysParams<T>>,
        k_sub: u64,
        adj: &mut HostState<T>,
        grad: &mut Vec<PhysParams<T>>,
    ) {
        let sim = self.sim;
        let mut s = before.clone();
        let fw = self.forward(&mut s, params, k_sub);
        let c = fw.c;
        let n = sim.setup.n;
        let np = sim.len();
        let inv_dx = k::<T>(c.inv_dx);
        // G2P: node adjoints by slabs, per-particle adjoints returned per slab.
        let (order, starts) = self.slab_order(&fw.rec.x_start, inv_dx);
        let mut grid_bar = self.take_grid();
        let per_slab: Vec<Vec<(u32, G2pBar<T>)>> = slabs::scatter_by_slab(
            &mut grid_bar,
            n * n,
            n,
            &order,
            &starts,
            |lo, ids, nodes| {
                ids.iter()
                    .map(|&i| {
                        let p = i as usize;
                        let g = g2p_vjp(
                            &fw.rec.grid,
                            n,
                            fw.rec.x_start[p],
                            &fw.rec.f_elastic[p],
                            &c,
                            adj.x[p],
                            adj.v[p],
                            &adj.c[p],
                            &adj.f[p],
                            nodes,
                            lo,
                        );
                        (i, g)
                    })
                    .collect()
            },
        );
        let mut x_bar = vec![[T::zero(); 3]; np];
        let mut fe_bar = vec![[T::zero(); 9]; np];
        for (i, g) in per_slab.into_iter().flatten() {
            x_bar[i as usize] = g.x;
            fe_bar[i as usize] = g.f_elastic;
        }
        // Grid update.
        let mut grid_in_bar = self.take_grid();
        grid_in_bar
            .par_chunks_mut(n * n)
            .enumerate()
            .for_each(|(i, plane)| {
                for (jk, out) in plane.iter_mut().enumerate() {
                    let idx = i * n * n + jk;
                    let vb = [grid_bar[idx][0], grid_bar[idx][1], grid_bar[idx][2]];
                    if vb.iter().any(|x| *x != T::zero()) {
                        *out = grid_node_update_vjp(
                            [i, jk / n, jk % n],
                            fw.rec.grid_in[idx],
                            &sim.setup.grid_bcs,
                            &c,
                            vb,
                        );
                    }
                }
            });
        // P2G, stress and particle conditions, per particle.
        let per_particle: Vec<(ParticleBar<T>, PhysParams<T>)> = (0..np)
            .into_par_iter()
            .map(|p| {
                sim.particle_stage_vjp(
                    p,
                    &c,
                    &fw.rec,
                    &before.c[p],
                    &grid_in_bar,
                    &fe_bar[p],
                    &x_bar[p],
                    &adj.plastic[p],
                    params,
                )
            })
            .collect();
        self.put_grid(grid_bar);
        self.put_grid(grid_in_bar);
        for (p, (bar, g)) in per_particle.into_iter().enumerate() {
            add_grad(&mut grad[sim.slot[p] as usize], &g);
            adj.x[p] = bar.x;
            adj.v[p] = bar.v;
            adj.c[p] = bar.c;
            adj.f[p] = bar.f;
            adj.plastic[p] = bar.plastic;
        }
        self.put_grid(fw.rec.grid_in);
        self.put_grid(fw.rec.grid);
    }

    fn zero_adjoint(&self, s: &HostState<T>) -> HostState<T> {
        HostState::zeros(s.x.len())
    }
}
