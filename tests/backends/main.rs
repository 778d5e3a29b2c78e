//! Backends against each other: the GPU engines and the parallel CPU backend against the reference, forward and adjoint.
//!
//! One test binary per axis, a module per topic; run one module with
//! `cargo test --test backends -- MODULE::`.

mod adjoint_conformance;
mod adjoint_parallel;
mod backend_conformance;
mod one_forward;
