//! The simulation driver, written once for every caller and every backend: [`Simulation`]
//! holds a problem ([`HostSim`]: config, particles, parameter slots) on backend `B` and runs
//! its substeps ([`crate::substep::forward`]) on a [`State`]:
//!
//! * frame by frame with health checks ([`crate::Simulator`], [`crate::SimState`]): `r4d simulate`,
//!   an engine's frame loop ([`frames`]);
//! * substep by substep with their VJPs ([`Differentiable`]): the fits and the evaluation,
//!   which checkpoint the forward pass ([`crate::adjoint::checkpoint`]);
//! * behind a trait object when the backend is chosen at run time ([`DynSimulation`]).
//!
//! The constants (initial positions, volumes, slots), the grid and the working buffers live
//! once in the simulation; a substep swaps the state's buffers into the working particles (no
//! copy). A reverse substep copies the checkpoint in, re-runs the substep with a (lazily
//! allocated, so forward-only runs never hold them) tape and adjoint scratch
//! ([`crate::substep::Tape`]) and runs the reverse stages.
//!
//! Parameter adjoints are accumulated per slot on the backend as `[mu, lambda, eta, alpha,
//! density]` ([`SlotGrad`]); [`Simulation::grad_to_host`] applies the chain rule to E, nu,
//! plastic viscosity and friction angle once per slot ([`PhysParams::add_material_vjp`] is
//! linear in the adjoints, so summing first is exact up to rounding) and
//! [`Simulation::init_vjp`] adds the yield stress's (through the initial plastic state).

mod dynamic;
pub mod frames;

pub use dynamic::{AnyGrad, AnyParams, AnyState, DynSimulation};

use crate::adjoint::checkpoint::Differentiable;
use crate::adjoint::host::HostSim;
use crate::adjoint::kernels::{AdjointScratch, MpmAdjointKernels, SlotGrad};
use crate::config::SimConfig;
use crate::error::{Error, Result};
use crate::kernels::{blocks_per_axis, Grid, GridBc, MpmKernels, ParticleBc, Particles};
use crate::material::PartConsts;
use crate::math::Real;
use crate::params::{PhysParams, SlotTables, MAT_CONSTS};
use crate::scene::ParticleSet;
use crate::sim::SimSetup;
use crate::state::State;
use crate::substep::{self, SubstepTables, Tape};
use std::sync::{Arc, Mutex};

pub(crate) fn be<E: std::error::Error + Send + Sync + 'static>(e: E) -> Error {
    Error::backend(e)
}

/// The working buffers of a simulation.
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
    /// Substeps ran without reading the grid's health record since it was last cleared.
    health_unread: bool,
}

/// A simulation problem ([`HostSim`]) on backend `B`: the one driver of every simulation
/// (frame by frame, [`crate::Simulator`]; substep by substep with VJPs, [`Differentiable`]).
pub struct Simulation<B: MpmKernels> {
    sim: Arc<HostSim>,
    b: B,
    grid_bcs: B::Buf<GridBc>,
    particle_bcs: B::Buf<ParticleBc>,
    slot_part: Vec<u32>,
    work: Mutex<Work<B>>,
}

impl<B: MpmKernels> Simulation<B> {
    /// The simulation of a validated config and its particles on `backend`: checks the
    /// particles (`source` names them in errors), every part's parameters, the CFL bound and
    /// the memory the grid and particles need, before allocating.
    pub fn new(backend: B, config: &SimConfig, scene: ParticleSet, source: &str) -> Result<Self> {
        let setup = SimSetup::new(config);
        scene.validate(source, setup.dx, setup.n, config.parts.len())?;
        for (i, p) in config.parts.iter().enumerate() {
            p.validate(&format!("parts[{i}]"))?;
        }
        setup.check_cfl(&config.parts)?;
        crate::budget::check_memory(
            source,
            crate::budget::simulation_bytes(setup.n, scene.len() as u64),
            crate::budget::available_memory(),
        )?;
        let host = HostSim::new(config, &scene)?;
        Self::with_host(backend, host).map_err(be)
    }

    /// The simulation of `sim` (validated by its constructor; per-part or per-particle
    /// parameter slots) on backend `b`; allocates the working buffers.
    pub fn with_host(b: B, sim: impl Into<Arc<HostSim>>) -> std::result::Result<Self, B::Error> {
        let sim: Arc<HostSim> = sim.into();
        let np = sim.len();
        let n = sim.setup.n;
        let slots = sim.slots().max(1);
        let slot_part = sim.slot_parts();
        let vol0: Vec<B::Scalar> = sim.vol0.iter().map(|&v| B::Scalar::c(v)).collect();
        let mut gb = sim.setup.grid_bcs.clone();
        gb.push(GridBc::default());
        let mut pb = sim.setup.particle_bcs.clone();
        pb.push(ParticleBc::default());
        let nb = blocks_per_axis(n);
        // The state fields are placeholders a state's buffers are swapped with for a forward
        // substep (no copy); the reverse sweep, which copies a checkpoint in, sizes them.
        let p = Particles {
            count: np,
            x: b.zeros(0)?,
            v: b.zeros(0)?,
            c: b.zeros(0)?,
            f: b.zeros(0)?,
            x0: b.upload(&sim.x0)?,
            vol0: b.upload(&vol0)?,
            mass: b.zeros(np)?,
            part: b.upload(&sim.slot)?,
            plastic: b.zeros(0)?,
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
            health_unread: false,
            p,
            g,
        };
        Ok(Simulation {
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

    /// The problem: config-derived setup, initial particles, parameter slots.
    pub fn host(&self) -> &HostSim {
        &self.sim
    }

    /// The derived setup (grid, boundary conditions, time stepping).
    pub fn setup(&self) -> &SimSetup {
        &self.sim.setup
    }

    /// Calls `f` with the grid as the last substep left it (node velocities and masses).
    pub fn with_grid<R>(&self, f: impl FnOnce(&B, &Grid<B>) -> R) -> R {
        let w = self.lock();
        f(&self.b, &w.g)
    }

    /// The particle masses of the parameters last stepped with (or given to
    /// [`crate::Simulator::init_state`]).
    pub fn masses(&self) -> std::result::Result<Vec<B::Scalar>, B::Error> {
        self.b.download(&self.lock().p.mass)
    }

    /// The initial state ([`HostSim::init`]) with initial velocities `v0`, on the backend.
    pub fn init(
        &self,
        params: &[PhysParams<B::Scalar>],
        v0: &[[B::Scalar; 3]],
    ) -> std::result::Result<State<B>, B::Error> {
        // Field by field, so at most one field's host copy is alive ([`HostSim::init`]'s
        // values).
        let (b, sim) = (&self.b, &*self.sim);
        let n = sim.len();
        let (z, o) = (B::Scalar::c(0.0), B::Scalar::c(1.0));
        let x: Vec<[B::Scalar; 3]> = sim
            .x0
            .iter()
            .map(|p| p.map(|c| B::Scalar::c(c as f64)))
            .collect();
        let x = b.upload(&x)?;
        let f = b.upload(&vec![[o, z, z, z, o, z, z, z, o]; n])?;
        let plastic: Vec<[B::Scalar; 2]> = sim
            .slot
            .iter()
            .map(|&p| [params[p as usize].yield_stress, o])
            .collect();
        Ok(State {
            x,
            v: b.upload(v0)?,
            c: b.zeros(n)?,
            f,
            plastic: b.upload(&plastic)?,
        })
    }

    /// A zero parameter gradient (one entry per slot).
    pub fn zero_grad(&self) -> std::result::Result<SlotGrad<B>, B::Error> {
        Ok(SlotGrad {
            acc: self.b.zeros(self.sim.slots().max(1))?,
        })
    }

    /// The accumulated gradient as [`PhysParams`] per slot: the chain rule of the material
    /// constants and of the masses. The yield stress's gradient through the initial state is
    /// added by [`Simulation::init_vjp`].
    pub fn grad_to_host(
        &self,
        g: &SlotGrad<B>,
        params: &[PhysParams<B::Scalar>],
    ) -> std::result::Result<Vec<PhysParams<B::Scalar>>, B::Error> {
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
        adj0: &State<B>,
        grad: &mut [PhysParams<B::Scalar>],
    ) -> std::result::Result<(), B::Error> {
        let plastic = self.b.download(&adj0.plastic)?;
        self.sim.init_vjp_plastic(&plastic, grad);
        Ok(())
    }

    /// Advances `s` by substep `k` (global index: it starts at time `k dt`) with the
    /// parameters `params` (one per slot); no health check (frame-by-frame stepping,
    /// [`crate::Simulator::step_frame`], checks at frame end).
    pub fn substep(
        &self,
        s: &mut State<B>,
        params: &[PhysParams<B::Scalar>],
        k: u64,
    ) -> std::result::Result<(), B::Error> {
        let mut guard = self.lock();
        let w = &mut *guard;
        self.prepare(w, params)?;
        let c = self.sim.consts_at(k);
        let t = self.tables(&w.parts, &w.mats);
        w.health_unread = true;
        s.swap_with(&mut w.p);
        let r = substep::forward(&self.b, &mut w.p, &mut w.g, &t, &c, None);
        s.swap_with(&mut w.p);
        r
    }

    /// Writes the tables of `params` when they changed.
    pub(crate) fn prepare_params(
        &self,
        params: &[PhysParams<B::Scalar>],
    ) -> std::result::Result<(), B::Error> {
        self.prepare(&mut self.lock(), params)
    }

    fn prepare(
        &self,
        w: &mut Work<B>,
        params: &[PhysParams<B::Scalar>],
    ) -> std::result::Result<(), B::Error> {
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

    /// The tables a substep reads besides the particles and the grid.
    fn tables<'t>(
        &'t self,
        parts: &'t B::Buf<PartConsts>,
        mats: &'t B::Buf<[B::Scalar; MAT_CONSTS]>,
    ) -> SubstepTables<'t, B> {
        SubstepTables {
            parts,
            mats,
            grid_bcs: &self.grid_bcs,
            particle_bcs: &self.particle_bcs,
        }
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, Work<B>> {
        // A panic while holding the lock leaves buffers that `prepare` rewrites as needed.
        self.work.lock().unwrap_or_else(|e| e.into_inner())
    }
}

impl<B: MpmAdjointKernels> Differentiable for Simulation<B> {
    type State = State<B>;
    type Params = Vec<PhysParams<B::Scalar>>;
    type Grad = SlotGrad<B>;
    type Error = B::Error;

    fn step(
        &self,
        s: &mut State<B>,
        params: &Self::Params,
        k: u64,
    ) -> std::result::Result<(), B::Error> {
        self.substep(s, params, k)
    }

    fn step_vjp(
        &self,
        before: &State<B>,
        params: &Self::Params,
        k: u64,
        adj: &mut State<B>,
        grad: &mut SlotGrad<B>,
    ) -> std::result::Result<(), B::Error> {
        let mut guard = self.lock();
        let w = &mut *guard;
        self.prepare(w, params)?;
        if w.reverse.is_none() {
            let (np, n) = (self.sim.len(), self.sim.setup.n);
            w.reverse = Some((
                Tape::new(&self.b, np, n)?,
                AdjointScratch::new(&self.b, np, n)?,
            ));
            State::zeros(&self.b, np)?.swap_with(&mut w.p);
        }
        let c = self.sim.consts_at(k);
        let t = self.tables(&w.parts, &w.mats);
        w.health_unread = true;
        let (tape, scratch) = w.reverse.as_mut().expect("allocated above");
        before.copy_into(&self.b, &mut w.p)?;
        substep::forward_to_grid(&self.b, &mut w.p, &mut w.g, &t, &c, Some(tape))?;
        substep::reverse(&self.b, &w.p, &w.g, &t, &c, before, tape, scratch, adj)?;
        self.b
            .reduce_slots(&scratch.pgrad, &w.p.part, &mut grad.acc)
    }

    fn zero_adjoint(&self, _s: &State<B>) -> std::result::Result<State<B>, B::Error> {
        State::zeros(&self.b, self.sim.len())
    }

    fn clone_state(&self, s: &State<B>) -> std::result::Result<State<B>, B::Error> {
        s.try_clone(&self.b, self.sim.len())
    }
}

/// The value of a result that cannot fail (the host backends' [`std::convert::Infallible`]).
pub fn infallible<T>(r: std::result::Result<T, std::convert::Infallible>) -> T {
    match r {
        Ok(v) => v,
        Err(e) => match e {},
    }
}
