//! The order of one MPM substep, written once for every backend and every caller
//! (every [`crate::Simulation`]: `r4d simulate`, the fits' forward and reverse passes).
//!
//! Forward ([`forward`]):
//! 1. `particle_bcs`: impulses and velocity overrides (skipped when there are none);
//! 2. `p2g`: return mapping and stress per particle, scatter to the grid;
//! 3. `grid_update`: momentum to velocity, gravity, damping, grid boundary conditions;
//! 4. `g2p`: gather, advect, update F, health check.
//!
//! Reverse ([`reverse`], after a forward pass with a tape): `g2p_vjp`, `grid_update_vjp`,
//! `p2g_vjp` (particle conditions, return mapping, scatter); the parameter adjoints are then
//! summed per slot (`reduce_slots`).
//!
//! With a [`Tape`] the forward pass also keeps what the reverse sweep needs and the state
//! does not hold: the velocities after the particle conditions, F_elastic and the scattered
//! grid (the updated grid stays in [`Grid::nodes`]).

use crate::adjoint::kernels::{AdjointScratch, MpmAdjointKernels};
use crate::kernels::{Grid, GridBc, MpmKernels, ParticleBc, Particles, StepConsts};
use crate::material::PartConsts;
use crate::params::MAT_CONSTS;
use crate::state::State;

/// The tables a substep reads besides the particles and the grid.
pub struct SubstepTables<'a, B: MpmKernels> {
    /// Fixed constants per parameter slot.
    pub parts: &'a B::Buf<PartConsts>,
    /// Material constants per parameter slot (`[mu, lambda, eta, alpha]`).
    pub mats: &'a B::Buf<[B::Scalar; MAT_CONSTS]>,
    /// Grid boundary conditions (at least one element; `StepConsts::n_grid_bcs` are used).
    pub grid_bcs: &'a B::Buf<GridBc>,
    /// Particle boundary conditions (at least one element).
    pub particle_bcs: &'a B::Buf<ParticleBc>,
}

/// Intermediates of one forward substep kept for its reverse sweep.
pub struct Tape<B: MpmKernels> {
    /// Velocities after the particle boundary conditions (the scatter's velocities).
    pub v1: B::Buf<[B::Scalar; 3]>,
    /// Deformation gradients after the return mapping.
    pub f_elastic: B::Buf<[B::Scalar; 9]>,
    /// The scattered grid (momentum, mass) before the grid update.
    pub grid_in: B::Buf<[B::Scalar; 4]>,
}

impl<B: MpmKernels> Tape<B> {
    /// A tape for `particles` particles on an `n^3` grid.
    pub fn new(b: &B, particles: usize, n: usize) -> Result<Self, B::Error> {
        Ok(Tape {
            v1: b.zeros(particles)?,
            f_elastic: b.zeros(particles)?,
            grid_in: b.zeros(n * n * n)?,
        })
    }
}

/// Runs one substep forward with constants `c`; with `tape`, records its intermediates.
pub fn forward<B: MpmKernels>(
    b: &B,
    p: &mut Particles<B>,
    g: &mut Grid<B>,
    t: &SubstepTables<B>,
    c: &StepConsts,
    tape: Option<&mut Tape<B>>,
) -> Result<(), B::Error> {
    forward_to_grid(b, p, g, t, c, tape)?;
    b.g2p(p, g, c)
}

/// The forward substep up to the updated grid (stages 1-3, without G2P): what [`reverse`]
/// needs besides the state before the substep and the tape (the particle stage's stress in
/// `p`, the updated grid and its active blocks in `g`).
pub fn forward_to_grid<B: MpmKernels>(
    b: &B,
    p: &mut Particles<B>,
    g: &mut Grid<B>,
    t: &SubstepTables<B>,
    c: &StepConsts,
    mut tape: Option<&mut Tape<B>>,
) -> Result<(), B::Error> {
    if c.n_particle_bcs > 0 {
        b.particle_bcs(p, t.particle_bcs, c)?;
    }
    if let Some(tp) = tape.as_deref_mut() {
        b.copy(&p.v, &mut tp.v1)?;
    }
    b.p2g(p, t.parts, t.mats, g, c)?;
    if let Some(tp) = tape {
        b.copy(&p.f, &mut tp.f_elastic)?;
        b.copy(&g.nodes, &mut tp.grid_in)?;
    }
    b.grid_update(g, t.grid_bcs, c)
}

/// Runs the reverse sweep of one substep whose forward pass (from `before`, with `tape`) just
/// ran on `p` and `g` ([`forward_to_grid`] is enough): replaces `adj` (the adjoint after the substep) with the adjoint before
/// it and leaves each particle's parameter adjoints in `s.pgrad`.
#[allow(clippy::too_many_arguments)]
pub fn reverse<B: MpmAdjointKernels>(
    b: &B,
    p: &Particles<B>,
    g: &Grid<B>,
    t: &SubstepTables<B>,
    c: &StepConsts,
    before: &State<B>,
    tape: &Tape<B>,
    s: &mut AdjointScratch<B>,
    adj: &mut State<B>,
) -> Result<(), B::Error> {
    b.g2p_vjp(before, tape, g, adj, c, s)?;
    b.grid_update_vjp(tape, g, t.grid_bcs, c, s)?;
    b.p2g_vjp(p, before, tape, t, g.n, c, s, adj)
}
