//! Reverse-mode differentiation of the simulator (issue 3, in progress).
//!
//! The adjoints live here once, generic over [`Real`](crate::math::Real) so every one is
//! checked against f64 central finite differences, and the backends will mirror them.
//!
//! Done:
//! * [`transfer_vjp`]: VJPs of the transfer stages of a substep (particle boundary
//!   conditions, RPIC damping, P2G scatter with the classic and MLS stress forces, the grid
//!   node update with every grid boundary condition, G2P with advection and the F update).
//! * [`constitutive_vjp`]: the VJP of every isotropic constitutive model (fixed corotated,
//!   StVK-Hencky, von Mises with hardening, Drucker-Prager, viscoplastic foam, plasticine
//!   softening, snow), through the SVD, with the regularisation of repeated singular values
//!   documented there.
//! * [`host`]: a single-threaded host simulator generic over f32/f64 with the exact reverse
//!   sweep of a substep; gradients flow to every part's E, nu, yield stress, plastic
//!   viscosity, friction angle and density, and to the initial positions and velocities.
//!   Whole trajectories (3 frames x 20 substeps, boundary conditions and plasticity active)
//!   match f64 finite differences to better than 1e-4 for every material (tests below).
//!
//! * [`checkpoint`]: the checkpointed reverse sweep over a trajectory (`StoreAll`,
//!   `PerFrame`, `EveryN`) and `memory_plan`.
//! * [`trajectory_loss`]: position and Chamfer losses with gradients.
//!
//! The parallel CPU version of the host sweep is `r4d_backend_cpu::adjoint::ParallelHost`;
//! the GPU version `r4d_backend_wgpu::adjoint::WgpuAdjoint` (WGSL kernels, state and
//! parameter gradients on the device). Both implement [`checkpoint::Differentiable`], so the
//! checkpointing driver is written once. Not done yet: the fluid's adjoint.

pub mod checkpoint;
pub mod constitutive_vjp;
pub mod host;
pub mod trajectory_loss;
pub mod transfer_vjp;

#[cfg(test)]
mod tests;
