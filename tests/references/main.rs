//! Physics and references nobody here wrote: conservation and beam theory, PhysGaussian trajectories, gsplat renders, pytorch-msssim / LPIPS values, segmentation.
//!
//! One test binary per axis, a module per topic; run one module with
//! `cargo test --test references -- MODULE::`.

#[path = "../common/mod.rs"]
mod common;

mod cantilever;
mod fluids_physics;
mod loss_goldens;
mod lpips;
mod materials;
mod physflow_fluids;
mod physgaussian_import;
mod physics;
mod segment;
mod segment_plant;
mod splat_golden;
mod trajectory_metrics;
