//! The `r4d` commands end to end (the binary run as a user runs it): arguments, outputs, resume.
//!
//! One test binary per axis, a module per topic; run one module with
//! `cargo test --test cli -- MODULE::`.

#[path = "../common/mod.rs"]
mod common;

mod cli;
mod cli_bench_recovery;
mod cli_bench_scale;
mod cli_fit;
mod cli_metrics;
mod cli_render;
mod segment_cli;
mod video_cli;
