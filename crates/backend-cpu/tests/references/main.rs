//! The CPU backend against physics and references nobody here wrote: conservation, free
//! fall and beam theory, every material's behaviour, PhysGaussian's trajectories, gsplat's
//! renders and gradients. One binary; run one module with
//! `cargo test -p r4d-backend-cpu --test references -- MODULE::`.

mod cantilever;
mod fluids_physics;
mod materials;
mod physgaussian_import;
mod physics;
mod splat_golden;
