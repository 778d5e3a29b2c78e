//! The reverse stages of a substep on the CPU ([`MpmAdjointKernels`] for [`CpuBackend`]), run
//! in the order `r4d_mpm::substep::reverse` gives by the generic stepper
//! `r4d_mpm::Simulation`.
//!
//! They call exactly the per-particle and per-node VJP functions the single-threaded reference
//! backend calls, adding only scheduling: particles in parallel, grid nodes in parallel, and
//! the node adjoints of G2P scattered by colour-slabs ([`crate::slabs`], in the particle order
//! the forward P2G just computed for the same positions) so no two threads write the same
//! node. Parameter adjoints are kept per particle and summed per slot in particle index
//! order, so results do not depend on the number of threads.

use crate::{slabs, CpuBackend};
use r4d_mpm::adjoint::kernels::{AdjointScratch, MpmAdjointKernels};
use r4d_mpm::adjoint::particle_vjp::{particle_stage_vjp_svd, ParticleForward};
use r4d_mpm::adjoint::transfer_vjp::{g2p_vjp, grid_node_vjp, G2pBar};
use r4d_mpm::kernels::{Grid, GridBc, Particles, StepConsts, BLOCK};
use r4d_mpm::math::{svd3_many, Mat3, Real, Svd3};
use r4d_mpm::params::PARAM_ADJOINTS;
use r4d_mpm::reference::reduce_slots_in_order;
use r4d_mpm::substep::{SubstepTables, Tape};
use r4d_mpm::transfer::{in_domain, k};
use r4d_mpm::State;
use rayon::prelude::*;
use std::convert::Infallible;

impl<T: Real> MpmAdjointKernels for CpuBackend<T> {
    fn g2p_vjp(
        &self,
        before: &State<Self>,
        tape: &Tape<Self>,
        g: &Grid<Self>,
        adj: &State<Self>,
        c: &StepConsts,
        s: &mut AdjointScratch<Self>,
    ) -> Result<(), Infallible> {
        let n = g.n;
        let np = before.x.len();
        let inv_dx = k::<T>(c.inv_dx);
        // The forward P2G of this substep ran on the same positions and left the slab order
        // in the grid's scratch: [keys (np) | order (np) | slab starts].
        let order = &g.scratch[np..2 * np];
        let starts = &g.scratch[2 * np..];
        let AdjointScratch {
            grid_bar,
            x_bar,
            fe_bar,
            ..
        } = s;
        let seq = self.sequential(np);
        let sorted = starts[slabs::slab_count(n)] as usize;
        // Another thread using a clone of this backend holds the buffer: use a fresh one.
        let mut guard = self.g2p_bar.try_lock().ok();
        let mut fresh = Vec::new();
        let buf = guard.as_deref_mut().unwrap_or(&mut fresh);
        buf.resize(sorted, G2pBar::default());
        self.run_as(seq, || {
            // Every node G2P's stencils reach lies in a block the forward P2G marked active.
            crate::for_active_blocks(seq, grid_bar, &g.active, n, |_, x| *x = [T::zero(); 4]);
            slabs::scatter_by_slab(
                seq,
                grid_bar,
                n * n,
                n,
                order,
                starts,
                &mut buf[..],
                |lo, ids, nodes, out| {
                    for (&i, o) in ids.iter().zip(out.iter_mut()) {
                        let p = i as usize;
                        *o = g2p_vjp(
                            &g.nodes,
                            n,
                            before.x[p],
                            &tape.f_elastic[p],
                            c,
                            adj.x[p],
                            adj.v[p],
                            &adj.c[p],
                            &adj.f[p],
                            nodes,
                            lo,
                        );
                    }
                },
            );
            if seq {
                x_bar.fill([T::zero(); 3]);
                fe_bar.fill([T::zero(); 9]);
            } else {
                x_bar
                    .par_iter_mut()
                    .zip(fe_bar.par_iter_mut())
                    .for_each(|(x, f)| {
                        *x = [T::zero(); 3];
                        *f = [T::zero(); 9];
                    });
            }
            for (&i, b) in order[..sorted].iter().zip(buf.iter()) {
                debug_assert!(in_domain(before.x[i as usize], inv_dx, n));
                x_bar[i as usize] = b.x;
                fe_bar[i as usize] = b.f_elastic;
            }
        });
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
        // Only the active blocks: every stencil node of this substep lies in one, and the
        // other nodes of `grid_in_bar` are never read.
        let bcs = &bcs[..c.n_grid_bcs as usize];
        let n = g.n;
        let grid_bar = &s.grid_bar;
        let grid_in = &tape.grid_in;
        let active_nodes = g.active.iter().filter(|&&a| a != 0).count() * BLOCK.pow(3);
        let seq = self.sequential_nodes(active_nodes);
        self.run_as(seq, || {
            crate::for_active_blocks(seq, &mut s.grid_in_bar, &g.active, n, |ijk, out| {
                let idx = (ijk[0] * n + ijk[1]) * n + ijk[2];
                *out = grid_node_vjp(ijk, grid_in[idx], grid_bar[idx], bcs, c);
            })
        });
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
        let (grid_in_bar, fe_bar, x_bar) = (&s.grid_in_bar, &s.fe_bar, &s.x_bar);
        let State {
            x,
            v,
            c: cm,
            f,
            plastic,
        } = adj;
        // In chunks whose f64 SVDs of F_trial are computed side by side (bitwise `svd3`).
        const CHUNK: usize = crate::STRESS_CHUNK;
        type Chunk<'a, T> = (
            usize,
            (
                (
                    (
                        ((&'a mut [[T; 3]], &'a mut [[T; 3]]), &'a mut [[T; 9]]),
                        &'a mut [[T; 9]],
                    ),
                    &'a mut [[T; 2]],
                ),
                &'a mut [[T; PARAM_ADJOINTS]],
            ),
        );
        let stage = |(ci, (((((ax, av), ac), af), ap), pg)): Chunk<'_, T>| {
            let i0 = ci * CHUNK;
            let len = ax.len();
            let mut fm = [Mat3::<f64>::default(); CHUNK];
            for (j, m) in fm[..len].iter_mut().enumerate() {
                *m = Mat3::from_array(before.f[i0 + j]).cast();
            }
            let mut svd = [Svd3::<f64>::default(); CHUNK];
            svd3_many(&fm[..len], &mut svd[..len]);
            for j in 0..len {
                let i = i0 + j;
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
                let (bar, g) = particle_stage_vjp_svd(
                    &fw,
                    &svd[j],
                    grid_in_bar,
                    n,
                    pbcs,
                    c,
                    &fe_bar[i],
                    &x_bar[i],
                    &ap[j],
                );
                ax[j] = bar.x;
                av[j] = bar.v;
                ac[j] = bar.c;
                af[j] = bar.f;
                ap[j] = bar.plastic;
                pg[j] = g;
            }
        };
        if self.sequential(x.len()) {
            x.chunks_mut(CHUNK)
                .zip(v.chunks_mut(CHUNK))
                .zip(cm.chunks_mut(CHUNK))
                .zip(f.chunks_mut(CHUNK))
                .zip(plastic.chunks_mut(CHUNK))
                .zip(s.pgrad.chunks_mut(CHUNK))
                .enumerate()
                .for_each(stage);
        } else {
            self.run(|| {
                x.par_chunks_mut(CHUNK)
                    .zip(v.par_chunks_mut(CHUNK))
                    .zip(cm.par_chunks_mut(CHUNK))
                    .zip(f.par_chunks_mut(CHUNK))
                    .zip(plastic.par_chunks_mut(CHUNK))
                    .zip(s.pgrad.par_chunks_mut(CHUNK))
                    .enumerate()
                    .for_each(stage)
            });
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
