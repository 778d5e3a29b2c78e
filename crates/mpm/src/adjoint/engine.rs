//! The differentiable simulator, written once and generic over the kernels: [`KernelAdjoint`]
//! runs a substep forward ([`crate::substep::forward`]) and its reverse sweep
//! ([`crate::substep::reverse`]) on any backend that implements [`MpmAdjointKernels`], and is
//! the [`Differentiable`] stepper the checkpointing driver
//! ([`super::checkpoint::value_and_grad`]) runs. The f64 reference backend
//! ([`crate::reference::ReferenceBackend`]`<f64>`) is the gradient oracle; the parallel CPU
//! backend runs the fits.
//!
//! The state the driver checkpoints is [`StateBufs`] (positions, velocities, C, F, plastic
//! state: 26 scalars per particle) in backend buffers; the constants (initial positions,
//! volumes, masses, slots) and the working buffers (grid, tape, adjoint scratch) live once in
//! the stepper. A forward substep swaps the state's buffers into the working particles (no
//! copy); a reverse substep copies the checkpoint in, re-runs the substep with a
//! (lazily allocated, so forward-only runs never hold them) tape and adjoint scratch, with a
//! `Tape` ([`crate::substep::Tape`]) and runs the reverse stages.
//!
//! Parameter adjoints are accumulated per slot on the backend as `[mu, lambda, eta, alpha,
//! density]` ([`SlotGrad`]); [`KernelAdjoint::grad_to_host`] applies the chain rule to E, nu,
//! plastic viscosity and friction angle once per slot ([`PhysParams::add_material_vjp`] is
//! linear in the adjoints, so summing first is exact up to rounding) and
//! [`KernelAdjoint::init_vjp`] adds the yield stress's (through the initial plastic state).

use super::checkpoint::Differentiable;
use super::host::{HostSim, HostState};
use crate::kernels::{Grid, GridBc, MpmKernels, ParticleBc, Particles, StepConsts};
use crate::material::PartConsts;
use crate::math::Real;
use crate::params::{PhysParams, SlotTables, MAT_CONSTS, PARAM_ADJOINTS};
use crate::substep::{self, SubstepTables, Tape};
use std::sync::Mutex;

/// A simulation state (or its adjoint) in backend buffers, struct-of-arrays like
/// [`HostState`].
pub struct StateBufs<B: MpmKernels> {
    /// Positions.
    pub x: B::Buf<[B::Scalar; 3]>,
    /// Velocities.
    pub v: B::Buf<[B::Scalar; 3]>,
    /// APIC matrices.
    pub c: B::Buf<[B::Scalar; 9]>,
    /// Deformation gradients.
    pub f: B::Buf<[B::Scalar; 9]>,
    /// Plastic state `[yield stress, J_p]`.
    pub plastic: B::Buf<[B::Scalar; 2]>,
}

impl<B: MpmKernels> StateBufs<B> {
    /// An all-zero state of `n` particles.
    pub fn zeros(b: &B, n: usize) -> Result<Self, B::Error> {
        Ok(StateBufs {
            x: b.zeros(n)?,
            v: b.zeros(n)?,
            c: b.zeros(n)?,
            f: b.zeros(n)?,
            plastic: b.zeros(n)?,
        })
    }
    /// Uploads a host state.
    pub fn upload(b: &B, s: &HostState<B::Scalar>) -> Result<Self, B::Error> {
        Ok(StateBufs {
            x: b.upload(&s.x)?,
            v: b.upload(&s.v)?,
            c: b.upload(&s.c)?,
            f: b.upload(&s.f)?,
            plastic: b.upload(&s.plastic)?,
        })
    }
    /// Copies the state to the host.
    pub fn download(&self, b: &B) -> Result<HostState<B::Scalar>, B::Error> {
        Ok(HostState {
            x: b.download(&self.x)?,
            v: b.download(&self.v)?,
            c: b.download(&self.c)?,
            f: b.download(&self.f)?,
            plastic: b.download(&self.plastic)?,
        })
    }
    /// A copy on the backend.
    pub fn try_clone(&self, b: &B, n: usize) -> Result<Self, B::Error> {
        let mut out = Self::zeros(b, n)?;
        self.copy_to(b, &mut out)?;
        Ok(out)
    }
    /// Copies every field into `dst`.
    pub fn copy_to(&self, b: &B, dst: &mut Self) -> Result<(), B::Error> {
        b.copy(&self.x, &mut dst.x)?;
        b.copy(&self.v, &mut dst.v)?;
        b.copy(&self.c, &mut dst.c)?;
        b.copy(&self.f, &mut dst.f)?;
        b.copy(&self.plastic, &mut dst.plastic)
    }
    /// Adds `dx` (one vector per particle) to the positions: how a loss on the positions
    /// enters an adjoint state.
    pub fn add_to_x(&mut self, b: &B, dx: &[[B::Scalar; 3]]) -> Result<(), B::Error> {
        b.accumulate(&mut self.x, dx)
    }
    /// Adds `df` (one row-major matrix per particle) to the deformation gradients: how a
    /// rendering loss's dL/dF enters an adjoint state.
    pub fn add_to_f(&mut self, b: &B, df: &[[B::Scalar; 9]]) -> Result<(), B::Error> {
        b.accumulate(&mut self.f, df)
    }
    /// Exchanges the buffers with the state fields of `p` (no copy).
    fn swap_with(&mut self, p: &mut Particles<B>) {
        std::mem::swap(&mut self.x, &mut p.x);
        std::mem::swap(&mut self.v, &mut p.v);
        std::mem::swap(&mut self.c, &mut p.c);
        std::mem::swap(&mut self.f, &mut p.f);
        std::mem::swap(&mut self.plastic, &mut p.plastic);
    }
    /// Copies the state into the state fields of `p`.
    fn copy_into(&self, b: &B, p: &mut Particles<B>) -> Result<(), B::Error> {
        b.copy(&self.x, &mut p.x)?;
        b.copy(&self.v, &mut p.v)?;
        b.copy(&self.c, &mut p.c)?;
        b.copy(&self.f, &mut p.f)?;
        b.copy(&self.plastic, &mut p.plastic)
    }
}

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
        before: &StateBufs<Self>,
        tape: &Tape<Self>,
        g: &Grid<Self>,
        adj: &StateBufs<Self>,
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
        before: &StateBufs<Self>,
        tape: &Tape<Self>,
        t: &SubstepTables<Self>,
        n: usize,
        c: &StepConsts,
        s: &mut AdjointScratch<Self>,
        adj: &mut StateBufs<Self>,
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

struct Work<B: MpmKernels> {
    p: Particles<B>,
    g: Grid<B>,
    /// The reverse sweep's buffers, allocated by its first substep (a forward-only run, and
    /// whatever the caller does between the forward and the reverse pass, such as rendering,
    /// never holds them).
    reverse: Option<(Tape<B>, AdjointScratch<B>)>,
    parts: B::Buf<PartConsts>,
    mats: B::Buf<[B::Scalar; MAT_CONSTS]>,
    params: Option<Vec<PhysParams<B::Scalar>>>,
}

/// [`HostSim`]'s problem (config, particles, slots) on backend `B`, as a [`Differentiable`]
/// stepper in the backend's scalar type.
pub struct KernelAdjoint<'a, B: MpmAdjointKernels> {
    /// The problem description.
    pub sim: &'a HostSim,
    b: B,
    grid_bcs: B::Buf<GridBc>,
    particle_bcs: B::Buf<ParticleBc>,
    slot_part: Vec<u32>,
    work: Mutex<Work<B>>,
}

impl<'a, B: MpmAdjointKernels> KernelAdjoint<'a, B> {
    /// The stepper of `sim` on backend `b` (allocates the working buffers).
    pub fn new(b: B, sim: &'a HostSim) -> Result<Self, B::Error> {
        let np = sim.len();
        let n = sim.setup.n;
        let slots = sim.slots().max(1);
        let slot_part = sim.slot_parts();
        let vol0: Vec<B::Scalar> = sim.vol0.iter().map(|&v| B::Scalar::c(v)).collect();
        let mut gb = sim.setup.grid_bcs.clone();
        gb.push(GridBc::default());
        let mut pb = sim.setup.particle_bcs.clone();
        pb.push(ParticleBc::default());
        let nb = crate::kernels::blocks_per_axis(n);
        let p = Particles {
            count: np,
            x: b.zeros(np)?,
            v: b.zeros(np)?,
            c: b.zeros(np)?,
            f: b.zeros(np)?,
            x0: b.upload(&sim.x0)?,
            vol0: b.upload(&vol0)?,
            mass: b.zeros(np)?,
            part: b.upload(&sim.slot)?,
            plastic: b.zeros(np)?,
            stress: b.zeros(np)?,
        };
        let g = Grid {
            n,
            nodes: b.zeros(n * n * n)?,
            active: b.zeros(nb * nb * nb)?,
            scratch: b.zeros(0)?,
            health: b.zeros(1)?,
        };
        let work = Work {
            reverse: None,
            parts: b.zeros(slots)?,
            mats: b.zeros(slots)?,
            params: None,
            p,
            g,
        };
        Ok(KernelAdjoint {
            grid_bcs: b.upload(&gb)?,
            particle_bcs: b.upload(&pb)?,
            sim,
            b,
            slot_part,
            work: Mutex::new(work),
        })
    }

    /// The backend.
    pub fn backend(&self) -> &B {
        &self.b
    }

    /// The initial state ([`HostSim::init`]) on the backend.
    pub fn init(
        &self,
        params: &[PhysParams<B::Scalar>],
        v0: &[[B::Scalar; 3]],
    ) -> Result<StateBufs<B>, B::Error> {
        StateBufs::upload(&self.b, &self.sim.init(params, v0))
    }

    /// A zero gradient (one entry per slot).
    pub fn zero_grad(&self) -> Result<SlotGrad<B>, B::Error> {
        Ok(SlotGrad {
            acc: self.b.zeros(self.sim.slots().max(1))?,
        })
    }

    /// The accumulated gradient as [`PhysParams`] per slot: the chain rule of the material
    /// constants and of the masses. The yield stress's gradient through the initial state is
    /// added by [`KernelAdjoint::init_vjp`].
    pub fn grad_to_host(
        &self,
        g: &SlotGrad<B>,
        params: &[PhysParams<B::Scalar>],
    ) -> Result<Vec<PhysParams<B::Scalar>>, B::Error> {
        let acc = self.b.download(&g.acc)?;
        Ok(params
            .iter()
            .zip(acc.iter().zip(&self.slot_part))
            .map(|(p, (a, &part))| p.from_slot_adjoint(a, self.sim.consts[part as usize].material))
            .collect())
    }

    /// Adds the gradient of the initial state's dependence on the parameters (the initial
    /// yield stress) given the initial state's adjoint.
    pub fn init_vjp(
        &self,
        adj0: &StateBufs<B>,
        grad: &mut [PhysParams<B::Scalar>],
    ) -> Result<(), B::Error> {
        let plastic = self.b.download(&adj0.plastic)?;
        self.sim.init_vjp_plastic(&plastic, grad);
        Ok(())
    }

    /// Writes the tables of `params` when they changed.
    fn prepare(&self, w: &mut Work<B>, params: &[PhysParams<B::Scalar>]) -> Result<(), B::Error> {
        if w.params.as_deref() == Some(params) {
            return Ok(());
        }
        let t = SlotTables::new(
            params,
            &self.sim.consts,
            &self.slot_part,
            &self.sim.slot,
            &self.sim.vol0,
        );
        self.b.write(&mut w.parts, &t.parts)?;
        self.b.write(&mut w.mats, &t.mats)?;
        self.b.write(&mut w.p.mass, &t.mass)?;
        w.params = Some(params.to_vec());
        Ok(())
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, Work<B>> {
        // A panic while holding the lock leaves buffers that `prepare` rewrites as needed.
        self.work.lock().unwrap_or_else(|e| e.into_inner())
    }
}

impl<B: MpmAdjointKernels> Differentiable for KernelAdjoint<'_, B> {
    type State = StateBufs<B>;
    type Params = Vec<PhysParams<B::Scalar>>;
    type Grad = SlotGrad<B>;
    type Error = B::Error;

    fn step(&self, s: &mut StateBufs<B>, params: &Self::Params, k: u64) -> Result<(), B::Error> {
        let mut guard = self.lock();
        let w = &mut *guard;
        self.prepare(w, params)?;
        let c = self.sim.consts_at(k);
        let t = SubstepTables {
            parts: &w.parts,
            mats: &w.mats,
            grid_bcs: &self.grid_bcs,
            particle_bcs: &self.particle_bcs,
        };
        s.swap_with(&mut w.p);
        let r = substep::forward(&self.b, &mut w.p, &mut w.g, &t, &c, None);
        s.swap_with(&mut w.p);
        r
    }

    fn step_vjp(
        &self,
        before: &StateBufs<B>,
        params: &Self::Params,
        k: u64,
        adj: &mut StateBufs<B>,
        grad: &mut SlotGrad<B>,
    ) -> Result<(), B::Error> {
        let mut guard = self.lock();
        let w = &mut *guard;
        self.prepare(w, params)?;
        if w.reverse.is_none() {
            let (np, n) = (self.sim.len(), self.sim.setup.n);
            w.reverse = Some((
                Tape::new(&self.b, np, n)?,
                AdjointScratch::new(&self.b, np, n)?,
            ));
        }
        let c = self.sim.consts_at(k);
        let t = SubstepTables {
            parts: &w.parts,
            mats: &w.mats,
            grid_bcs: &self.grid_bcs,
            particle_bcs: &self.particle_bcs,
        };
        let (tape, scratch) = w.reverse.as_mut().expect("allocated above");
        before.copy_into(&self.b, &mut w.p)?;
        substep::forward_to_grid(&self.b, &mut w.p, &mut w.g, &t, &c, Some(tape))?;
        substep::reverse(&self.b, &w.p, &w.g, &t, &c, before, tape, scratch, adj)?;
        self.b
            .reduce_slots(&scratch.pgrad, &w.p.part, &mut grad.acc)
    }

    fn zero_adjoint(&self, _s: &StateBufs<B>) -> Result<StateBufs<B>, B::Error> {
        StateBufs::zeros(&self.b, self.sim.len())
    }

    fn clone_state(&self, s: &StateBufs<B>) -> Result<StateBufs<B>, B::Error> {
        s.try_clone(&self.b, self.sim.len())
    }
}

/// The value of a result that cannot fail (the host backends' [`std::convert::Infallible`]).
pub fn infallible<T>(r: Result<T, std::convert::Infallible>) -> T {
    match r {
        Ok(v) => v,
        Err(e) => match e {},
    }
}
