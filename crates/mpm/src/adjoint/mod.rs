//! Reverse-mode differentiation of the simulator.
//!
//! The adjoints live here once, generic over [`Real`](crate::math::Real) so every one is
//! checked against f64 central finite differences:
//!
//! * [`transfer_vjp`]: VJPs of the transfer stages of a substep (particle boundary
//!   conditions, RPIC damping, P2G scatter with the classic and MLS stress forces, the grid
//!   node update with every grid boundary condition, G2P with advection and the F update).
//! * [`constitutive_vjp`]: the VJP of every isotropic constitutive model (fixed corotated,
//!   StVK-Hencky, von Mises with hardening, Drucker-Prager, viscoplastic foam, plasticine
//!   softening, snow), through the SVD, with the regularisation of repeated singular values
//!   documented there.
//! * [`particle_vjp`]: the reverse of one particle's P2G stage, the per-particle function the
//!   host backends' `p2g_vjp` kernels call.
//! * [`kernels`]: the reverse stages every differentiating backend implements
//!   ([`kernels::MpmAdjointKernels`]), run by the one driver [`crate::Simulation`] (the
//!   stage order is [`crate::substep`]'s). On the f64
//!   reference backend it is the gradient oracle: whole trajectories (3 frames x 20
//!   substeps, boundary conditions and plasticity active) match f64 finite differences to
//!   better than 1e-4 for every material's E, nu, yield stress, plastic viscosity, friction
//!   angle and density, and for the initial velocities (tests below).
//! * [`host`]: the problem description (config, particles, parameter slots, initial state).
//! * [`checkpoint`]: the checkpointed reverse sweep over a trajectory (`StoreAll`,
//!   `PerFrame`, `EveryN`, `Nested`), fallible, and `memory_plan`.
//! * [`trajectory_loss`]: position and Chamfer losses with gradients.
//!
//! The CPU backend implements the reverse stages in parallel (`r4d_backend_cpu`), the wgpu
//! backend in WGSL (`r4d_backend_wgpu::mpm_vjp`, state and parameter gradients on the
//! device); both run through the one driver [`crate::Simulation`] and the one
//! checkpointing driver.

pub mod checkpoint;
pub mod constitutive_vjp;
pub mod host;
pub mod kernels;
pub mod particle_vjp;
pub mod trajectory_loss;
pub mod transfer_vjp;

#[cfg(test)]
mod per_node_vjp;
#[cfg(test)]
mod tests;
