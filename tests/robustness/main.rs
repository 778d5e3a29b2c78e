//! Robustness: kills and resumes, full disks, hostile options, typed errors.
//!
//! One test binary per axis, a module per topic; run one module with
//! `cargo test --test robustness -- MODULE::`.

#[path = "../common/mod.rs"]
mod common;

mod config_dialects;
mod errors;
mod fault_injection;
mod hostile_options;
mod hostile_readers;
