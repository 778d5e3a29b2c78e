//! Reverse-mode differentiation of the simulator (issue 3, in progress).
//!
//! The adjoints live here once, generic over [`Real`](crate::math::Real) so every one is
//! checked against f64 central finite differences, and the backends mirror them.
//!
//! Done:
//! * [`transfer_vjp`]: VJPs of the transfer stages of a substep (particle boundary
//!   conditions, RPIC damping, P2G scatter with the classic and MLS stress forces, the grid
//!   node update with every grid boundary condition, G2P with advection and the F update),
//!   each checked against f64 finite differences in this module's tests.
//!
//! Not done yet (tracked in issue 3): the VJPs of the constitutive models (SVD and return
//! mappings), the substep/frame reverse sweep and its checkpointing strategies with
//! `memory_plan`, parameter granularity, the `_vjp` kernel methods of the backends, and
//! `r4d fit-trajectory`.

pub mod constitutive_vjp;
pub mod transfer_vjp;

#[cfg(test)]
mod tests;
