//! Fits: the video fit, the trajectory fit, the demo scenes' recovery, ablations and dataset folders.
//!
//! One test binary per axis, a module per topic; run one module with
//! `cargo test --test fits -- MODULE::`.

#[path = "../common/mod.rs"]
mod common;

mod ablate;
mod datasets;
mod demo_recovery;
mod fit_trajectory;
mod fluid_eval;
mod video_fit;
