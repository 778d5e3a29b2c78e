//! The particle state of a simulation, one type for every driver and backend: [`State`]
//! (positions, velocities, APIC matrices, deformation gradients and the plastic state in backend
//! buffers; also the type of its adjoint) and [`SimState`], a state with its clock (frame,
//! substep, time) as frame-by-frame stepping ([`crate::Simulator`]) advances it. Its host copy is
//! [`HostState`].

use crate::adjoint::host::HostState;
use crate::kernels::{MpmKernels, Particles};
use crate::material::PartParams;

/// A simulation state (or its adjoint) in backend buffers, struct-of-arrays like
/// [`HostState`].
pub struct State<B: MpmKernels> {
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

impl<B: MpmKernels> State<B> {
    /// An all-zero state of `n` particles.
    pub fn zeros(b: &B, n: usize) -> Result<Self, B::Error> {
        Ok(State {
            x: b.zeros(n)?,
            v: b.zeros(n)?,
            c: b.zeros(n)?,
            f: b.zeros(n)?,
            plastic: b.zeros(n)?,
        })
    }
    /// Uploads a host state.
    pub fn upload(b: &B, s: &HostState<B::Scalar>) -> Result<Self, B::Error> {
        Ok(State {
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
    pub(crate) fn swap_with(&mut self, p: &mut Particles<B>) {
        std::mem::swap(&mut self.x, &mut p.x);
        std::mem::swap(&mut self.v, &mut p.v);
        std::mem::swap(&mut self.c, &mut p.c);
        std::mem::swap(&mut self.f, &mut p.f);
        std::mem::swap(&mut self.plastic, &mut p.plastic);
    }
    /// Copies the state into the state fields of `p`.
    pub(crate) fn copy_into(&self, b: &B, p: &mut Particles<B>) -> Result<(), B::Error> {
        b.copy(&self.x, &mut p.x)?;
        b.copy(&self.v, &mut p.v)?;
        b.copy(&self.c, &mut p.c)?;
        b.copy(&self.f, &mut p.f)?;
        b.copy(&self.plastic, &mut p.plastic)
    }
}
/// A [`State`] with its clock, as frame-by-frame stepping ([`crate::Simulator`]) advances it.
pub struct SimState<B: MpmKernels> {
    /// The particle state.
    pub state: State<B>,
    /// Time at the end of the last substep (s): `substep x dt`.
    pub time_s: f64,
    /// Substeps done.
    pub substep: u64,
    /// Frames done (0 = initial state).
    pub frame: usize,
    /// The parameters the state was last stepped with (checked when they change).
    pub(crate) params: Vec<PartParams>,
}
