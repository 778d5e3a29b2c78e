//! Backends against each other: the GPU engines and the parallel CPU backend against the reference, forward and adjoint,
//! and the trajectory and video fits on the GPU engines against the CPU's. Every GPU test of the
//! root package that runs in-process lives here, on the binary's shared engines
//! (`tests/common/gpu.rs`), so each engine compiles its pipelines once.
//!
//! One test binary per axis, a module per topic; run one module with
//! `cargo test --test backends -- MODULE::`.

#[path = "../common/mod.rs"]
mod common;

mod adjoint_conformance;
mod adjoint_parallel;
mod backend_conformance;
mod conformance_suite;
mod fit_trajectory_gpu;
mod one_forward;
mod video_fit_gpu;
