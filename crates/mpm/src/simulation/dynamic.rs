//! A [`Simulation`] behind a trait object ([`DynSimulation`]), for code that picks its backend
//! at run time (the fits, the evaluation): states, parameters and gradients are opaque boxes of
//! the backend's own types, host data crosses in f64, and a box another simulation made, or a
//! backend that returns data of the wrong length, is a typed error naming the operation.

use super::Simulation;
use crate::adjoint::checkpoint::Differentiable;
use crate::adjoint::host::HostSim;
use crate::adjoint::kernels::{MpmAdjointKernels, SlotGrad};
use crate::error::{Error, Result};
use crate::material::PartParams;
use crate::math::Real;
use crate::params::PhysParams;
use crate::state::State;
use r4d_backend::AnyBuf;
use std::any::Any;

/// A particle state (or its adjoint) of a [`DynSimulation`]: its backend's [`State`], boxed.
pub struct AnyState(Box<dyn Any + Send + Sync>);
/// Parameters prepared for a [`DynSimulation`] (one per slot, in its backend's scalar type).
pub struct AnyParams(Box<dyn Any + Send + Sync>);
/// Parameter adjoints accumulated by a [`DynSimulation`] on its backend.
pub struct AnyGrad(Box<dyn Any + Send + Sync>);

impl std::fmt::Debug for AnyState {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("AnyState")
    }
}

/// A differentiable simulation whose backend is chosen at run time: what
/// [`Simulation`]`<B>` does for every `B`, object-safe. The checkpointing driver runs it
/// ([`Differentiable`] is implemented for `dyn DynSimulation`).
pub trait DynSimulation: Send + Sync {
    /// The backend's name (`"cpu"`, `"wgpu"`, ...).
    fn backend_name(&self) -> &str;
    /// The scalar type it simulates in (`"f32"`, `"f64"`).
    fn precision(&self) -> &'static str;
    /// The problem.
    fn host(&self) -> &HostSim;
    /// `slots` (one per parameter slot) in the backend's scalar type.
    fn params(&self, slots: &[PartParams]) -> AnyParams;
    /// The initial state with initial velocities `v0`.
    fn init(&self, params: &AnyParams, v0: &[[f64; 3]]) -> Result<AnyState>;
    /// Advances `s` by substep `k`.
    fn step(&self, s: &mut AnyState, params: &AnyParams, k: u64) -> Result<()>;
    /// Reverse sweep of substep `k` ([`Differentiable::step_vjp`]).
    fn step_vjp(
        &self,
        before: &AnyState,
        params: &AnyParams,
        k: u64,
        adj: &mut AnyState,
        grad: &mut AnyGrad,
    ) -> Result<()>;
    /// A zero adjoint.
    fn zero_adjoint(&self) -> Result<AnyState>;
    /// A copy of `s` (a checkpoint).
    fn clone_state(&self, s: &AnyState) -> Result<AnyState>;
    /// A zero parameter gradient.
    fn zero_grad(&self) -> Result<AnyGrad>;
    /// The parameter gradient per slot in f64: `grad`'s slot sums through the chain rule plus
    /// the initial state's share (adjoint `adj0`).
    fn gradient(
        &self,
        grad: &AnyGrad,
        adj0: &AnyState,
        params: &AnyParams,
    ) -> Result<Vec<PhysParams<f64>>>;
    /// Positions of `s`, in f64.
    fn positions_f64(&self, s: &AnyState) -> Result<Vec<[f64; 3]>>;
    /// Deformation gradients of `s` (row-major), in f64.
    fn deformation_gradients_f64(&self, s: &AnyState) -> Result<Vec<[f64; 9]>>;
    /// Adds `dx` to the positions of the adjoint `adj` (how a loss on positions enters it).
    fn add_to_x(&self, adj: &mut AnyState, dx: &[[f64; 3]]) -> Result<()>;
    /// Adds `df` to the deformation gradients of the adjoint `adj`.
    fn add_to_f(&self, adj: &mut AnyState, df: &[[f64; 9]]) -> Result<()>;
    /// Copies of the positions (`[S; 3]`) and row-major deformation gradients (`[S; 9]`) of
    /// `s` made on the backend, `S` its scalar type: nothing crosses to the host, and a
    /// renderer of the same backend reads them where they are.
    fn frame_buffers(&self, s: &AnyState) -> Result<(AnyBuf, AnyBuf)>;
    /// Adds `dx` and `df`, buffers of this backend (`[S; 3]` and `[S; 9]` per particle), to
    /// the positions and deformation gradients of the adjoint `adj`, on the backend.
    fn add_buffers(&self, adj: &mut AnyState, dx: &AnyBuf, df: &AnyBuf) -> Result<()>;
    /// Reads and clears the health record the substeps keep on the backend: the code of the
    /// first problem since the last read (0 none; `HEALTH_*` in [`crate::kernels`]). One
    /// small record crosses to the host.
    fn take_health_code(&self) -> Result<u32>;
}

fn wrong(backend: &str, op: &'static str, message: String) -> Error {
    Error::BackendOutput {
        backend: backend.to_string(),
        op,
        message,
    }
}

impl<B: MpmAdjointKernels> Simulation<B> {
    fn state<'s>(&self, s: &'s AnyState, op: &'static str) -> Result<&'s State<B>> {
        s.0.downcast_ref()
            .ok_or_else(|| wrong(self.b.name(), op, "a state another simulation made".into()))
    }
    fn state_mut<'s>(&self, s: &'s mut AnyState, op: &'static str) -> Result<&'s mut State<B>> {
        s.0.downcast_mut()
            .ok_or_else(|| wrong(self.b.name(), op, "a state another simulation made".into()))
    }
    fn phys<'p>(
        &self,
        p: &'p AnyParams,
        op: &'static str,
    ) -> Result<&'p Vec<PhysParams<B::Scalar>>> {
        let p: &Vec<PhysParams<B::Scalar>> = p.0.downcast_ref().ok_or_else(|| {
            wrong(
                self.b.name(),
                op,
                "parameters prepared by another simulation".into(),
            )
        })?;
        let want = self.sim.slots().max(1);
        if p.len() != want {
            return Err(wrong(
                self.b.name(),
                op,
                format!("{} parameter sets for {want} slots", p.len()),
            ));
        }
        Ok(p)
    }
    /// `v` converted to f64, checked to hold one element per particle.
    fn host_f64<const N: usize>(
        &self,
        v: Vec<[B::Scalar; N]>,
        op: &'static str,
    ) -> Result<Vec<[f64; N]>> {
        if v.len() != self.sim.len() {
            return Err(wrong(
                self.b.name(),
                op,
                format!("{} elements for {} particles", v.len(), self.sim.len()),
            ));
        }
        Ok(v.iter().map(|a| a.map(|c| c.f64())).collect())
    }
    fn per_particle<const N: usize>(
        &self,
        v: &[[f64; N]],
        op: &'static str,
    ) -> Result<Vec<[B::Scalar; N]>> {
        if v.len() != self.sim.len() {
            return Err(wrong(
                self.b.name(),
                op,
                format!("{} values for {} particles", v.len(), self.sim.len()),
            ));
        }
        Ok(v.iter().map(|a| a.map(B::Scalar::c)).collect())
    }
}

fn be<E: std::error::Error + Send + Sync + 'static>(e: E) -> Error {
    Error::backend(e)
}

impl<B: crate::MpmKernels> Simulation<B> {
    /// Copies of the positions (`[S; 3]`) and row-major deformation gradients (`[S; 9]`) of
    /// `s` made on the backend ([`DynSimulation::frame_buffers`] for a typed state): a
    /// renderer of the same backend draws them where they are
    /// (`r4d_splat::Renderer::prepare_frame_linked`), nothing crosses to the host.
    pub fn state_buffers(&self, s: &State<B>) -> Result<(AnyBuf, AnyBuf)> {
        let n = self.sim.len();
        let mut x = self.b.zeros::<[B::Scalar; 3]>(n).map_err(be)?;
        self.b.copy(&s.x, &mut x).map_err(be)?;
        let mut f = self.b.zeros::<[B::Scalar; 9]>(n).map_err(be)?;
        self.b.copy(&s.f, &mut f).map_err(be)?;
        Ok((AnyBuf::new(&self.b, x, n), AnyBuf::new(&self.b, f, n)))
    }
}

impl<B: MpmAdjointKernels> DynSimulation for Simulation<B> {
    fn backend_name(&self) -> &str {
        self.b.name()
    }
    fn precision(&self) -> &'static str {
        B::Scalar::NAME
    }
    fn host(&self) -> &HostSim {
        &self.sim
    }
    fn params(&self, slots: &[PartParams]) -> AnyParams {
        let p: Vec<PhysParams<B::Scalar>> = slots.iter().map(PhysParams::of).collect();
        AnyParams(Box::new(p))
    }
    fn init(&self, params: &AnyParams, v0: &[[f64; 3]]) -> Result<AnyState> {
        let v0 = self.per_particle(v0, "init")?;
        let s = Simulation::init(self, self.phys(params, "init")?, &v0).map_err(be)?;
        Ok(AnyState(Box::new(s)))
    }
    fn step(&self, s: &mut AnyState, params: &AnyParams, k: u64) -> Result<()> {
        let p = self.phys(params, "step")?;
        self.substep(self.state_mut(s, "step")?, p, k).map_err(be)
    }
    fn step_vjp(
        &self,
        before: &AnyState,
        params: &AnyParams,
        k: u64,
        adj: &mut AnyState,
        grad: &mut AnyGrad,
    ) -> Result<()> {
        let g: &mut SlotGrad<B> = grad.0.downcast_mut().ok_or_else(|| {
            wrong(
                self.b.name(),
                "step_vjp",
                "a gradient another simulation made".into(),
            )
        })?;
        let p = self.phys(params, "step_vjp")?;
        let before = self.state(before, "step_vjp")?;
        let adj = self.state_mut(adj, "step_vjp")?;
        Differentiable::step_vjp(self, before, p, k, adj, g).map_err(be)
    }
    fn zero_adjoint(&self) -> Result<AnyState> {
        let s = State::zeros(&self.b, self.sim.len()).map_err(be)?;
        Ok(AnyState(Box::new(s)))
    }
    fn clone_state(&self, s: &AnyState) -> Result<AnyState> {
        let s = self.state(s, "clone_state")?;
        Ok(AnyState(Box::new(
            s.try_clone(&self.b, self.sim.len()).map_err(be)?,
        )))
    }
    fn zero_grad(&self) -> Result<AnyGrad> {
        Ok(AnyGrad(Box::new(Simulation::zero_grad(self).map_err(be)?)))
    }
    fn gradient(
        &self,
        grad: &AnyGrad,
        adj0: &AnyState,
        params: &AnyParams,
    ) -> Result<Vec<PhysParams<f64>>> {
        let g: &SlotGrad<B> = grad.0.downcast_ref().ok_or_else(|| {
            wrong(
                self.b.name(),
                "gradient",
                "a gradient another simulation made".into(),
            )
        })?;
        let p = self.phys(params, "gradient")?;
        let mut out = self.grad_to_host(g, p).map_err(be)?;
        if out.len() != p.len() {
            return Err(wrong(
                self.b.name(),
                "gradient",
                format!("{} slot gradients for {} slots", out.len(), p.len()),
            ));
        }
        self.init_vjp(self.state(adj0, "gradient")?, &mut out)
            .map_err(be)?;
        Ok(out.iter().map(PhysParams::to_f64).collect())
    }
    fn positions_f64(&self, s: &AnyState) -> Result<Vec<[f64; 3]>> {
        let s = self.state(s, "positions")?;
        self.host_f64(self.b.download(&s.x).map_err(be)?, "positions")
    }
    fn deformation_gradients_f64(&self, s: &AnyState) -> Result<Vec<[f64; 9]>> {
        let s = self.state(s, "deformation_gradients")?;
        self.host_f64(self.b.download(&s.f).map_err(be)?, "deformation_gradients")
    }
    fn add_to_x(&self, adj: &mut AnyState, dx: &[[f64; 3]]) -> Result<()> {
        let d = self.per_particle(dx, "add_to_x")?;
        let a = self.state_mut(adj, "add_to_x")?;
        a.add_to_x(&self.b, &d).map_err(be)
    }
    fn add_to_f(&self, adj: &mut AnyState, df: &[[f64; 9]]) -> Result<()> {
        let d = self.per_particle(df, "add_to_f")?;
        let a = self.state_mut(adj, "add_to_f")?;
        a.add_to_f(&self.b, &d).map_err(be)
    }
    fn frame_buffers(&self, s: &AnyState) -> Result<(AnyBuf, AnyBuf)> {
        self.state_buffers(self.state(s, "frame_buffers")?)
    }
    fn add_buffers(&self, adj: &mut AnyState, dx: &AnyBuf, df: &AnyBuf) -> Result<()> {
        let n = self.sim.len();
        let name = self.b.name();
        let check = |a: &AnyBuf, what: &str| {
            if a.len() != n {
                return Err(wrong(
                    name,
                    "add_buffers",
                    format!("{} {what} for {n} particles", a.len()),
                ));
            }
            Ok(())
        };
        check(dx, "position gradients")?;
        check(df, "deformation gradient gradients")?;
        let other = |a: &AnyBuf| {
            wrong(
                name,
                "add_buffers",
                format!(
                    "a buffer of backend {} or of another scalar type",
                    a.backend()
                ),
            )
        };
        let x = dx.get::<B, [B::Scalar; 3]>().ok_or_else(|| other(dx))?;
        let f = df.get::<B, [B::Scalar; 9]>().ok_or_else(|| other(df))?;
        let a = self.state_mut(adj, "add_buffers")?;
        self.b.accumulate_buf(&mut a.x, x).map_err(be)?;
        self.b.accumulate_buf(&mut a.f, f).map_err(be)
    }
    fn take_health_code(&self) -> Result<u32> {
        Ok(self.take_health()?.code)
    }
}

impl Differentiable for dyn DynSimulation + '_ {
    type State = AnyState;
    type Params = AnyParams;
    type Grad = AnyGrad;
    type Error = Error;

    fn step(&self, s: &mut AnyState, p: &AnyParams, k: u64) -> Result<()> {
        DynSimulation::step(self, s, p, k)
    }
    fn step_vjp(
        &self,
        before: &AnyState,
        p: &AnyParams,
        k: u64,
        adj: &mut AnyState,
        grad: &mut AnyGrad,
    ) -> Result<()> {
        DynSimulation::step_vjp(self, before, p, k, adj, grad)
    }
    fn zero_adjoint(&self, _s: &AnyState) -> Result<AnyState> {
        DynSimulation::zero_adjoint(self)
    }
    fn clone_state(&self, s: &AnyState) -> Result<AnyState> {
        DynSimulation::clone_state(self, s)
    }
}
