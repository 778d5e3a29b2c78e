//! The reverse stages of a substep that each differentiating backend implements
//! ([`MpmAdjointKernels`]), their scratch buffers and the per-slot parameter adjoints. The order
//! they run in is written once in [`crate::substep::reverse`]; the driver is
//! [`crate::Simulation`].

use crate::kernels::{Grid, GridBc, MpmKernels, Particles, StepConsts};
use crate::params::PARAM_ADJOINTS;
use crate::state::State;
use crate::substep::{SubstepTables, Tape};

/// Scratch of one substep's reverse sweep.
pub struct AdjointScratch<B: MpmKernels> {
    /// Adjoint of the updated grid (node velocities; written by `g2p_vjp`).
    pub grid_bar: B::Buf<[B::Scalar; 4]>,
    /// Adjoint of the scattered grid (momentum, mass; written by `grid_update_vjp`).
    pub grid_in_bar: B::Buf<[B::Scalar; 4]>,
    /// Position adjoint gathered by `g2p_vjp`, per particle.
    pub x_bar: B::Buf<[B::Scalar; 3]>,
    /// F_elastic adjoint from `g2p_vjp`, per particle.
    pub fe_bar: B::Buf<[B::Scalar; 9]>,
    /// Parameter adjoints `[mu, lambda, eta, alpha, density]` per particle (`p2g_vjp`).
    pub pgrad: B::Buf<[B::Scalar; PARAM_ADJOINTS]>,
}

impl<B: MpmKernels> AdjointScratch<B> {
    /// Scratch for `particles` particles on an `n^3` grid.
    pub fn new(b: &B, particles: usize, n: usize) -> Result<Self, B::Error> {
        Ok(AdjointScratch {
            grid_bar: b.zeros(n * n * n)?,
            grid_in_bar: b.zeros(n * n * n)?,
            x_bar: b.zeros(particles)?,
            fe_bar: b.zeros(particles)?,
            pgrad: b.zeros(particles)?,
        })
    }
}

/// The reverse stages of a substep, implemented by each backend that differentiates. The
/// order they run in is [`crate::substep::reverse`]; each mirrors the per-particle or per-node
/// VJP functions of [`super::transfer_vjp`], [`super::constitutive_vjp`] and
/// [`super::particle_vjp`].
pub trait MpmAdjointKernels: MpmKernels {
    /// Reverse of G2P: from the adjoint `adj` of the state after the substep, writes the node
    /// velocity adjoints into `s.grid_bar` (cleared first, at least on the active blocks) and each particle's position and
    /// F_elastic adjoints into `s.x_bar`, `s.fe_bar`. `before` is the state at the start of
    /// the substep, `g` the updated grid, `tape` the forward intermediates.
    #[allow(clippy::too_many_arguments)]
    fn g2p_vjp(
        &self,
        before: &State<Self>,
        tape: &Tape<Self>,
        g: &Grid<Self>,
        adj: &State<Self>,
        c: &StepConsts,
        s: &mut AdjointScratch<Self>,
    ) -> Result<(), Self::Error>;
    /// Reverse of the grid update: `s.grid_in_bar` from `s.grid_bar` (zero where the velocity
    /// adjoint is zero), on every node of the blocks `g.active` marks (the forward pass of the
    /// same substep marked them); a backend may leave the other nodes as they are, since no
    /// particle's stencil reaches them.
    fn grid_update_vjp(
        &self,
        tape: &Tape<Self>,
        g: &Grid<Self>,
        bcs: &Self::Buf<GridBc>,
        c: &StepConsts,
        s: &mut AdjointScratch<Self>,
    ) -> Result<(), Self::Error>;
    /// Reverse of the particle stage and the scatter: replaces `adj` (after the substep; its
    /// plastic adjoint is read) with the adjoint before the substep, and writes each
    /// particle's parameter adjoints into `s.pgrad`.
    #[allow(clippy::too_many_arguments)]
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
    ) -> Result<(), Self::Error>;
    /// Adds the per-particle parameter adjoints `pgrad` to their slots' sums in `grad`
    /// (`slot` of each particle); deterministic (particle index order on the host).
    fn reduce_slots(
        &self,
        pgrad: &Self::Buf<[Self::Scalar; PARAM_ADJOINTS]>,
        slot: &Self::Buf<u32>,
        grad: &mut Self::Buf<[Self::Scalar; PARAM_ADJOINTS]>,
    ) -> Result<(), Self::Error>;
}

/// Parameter adjoints accumulated per slot on the backend: `[mu, lambda, eta, alpha,
/// density]`.
pub struct SlotGrad<B: MpmKernels> {
    /// One entry per parameter slot.
    pub acc: B::Buf<[B::Scalar; PARAM_ADJOINTS]>,
}
