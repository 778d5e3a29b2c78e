//! References nobody here wrote that need the whole program: the official LPIPS values (the
//! `r4d metrics` command among them) and PhysFlow-made fluid scenes read as datasets. The
//! single-crate references live with their crates: physics, PhysGaussian trajectories and
//! gsplat renders in `crates/backend-cpu/tests/references`, the loss and metric goldens in
//! `crates/loss/tests/loss`, segmentation in `crates/segment/tests/segment`.
//!
//! One test binary per axis, a module per topic; run one module with
//! `cargo test --test references -- MODULE::`.

#[path = "../common/mod.rs"]
mod common;

mod lpips;
mod physflow_fluids;
