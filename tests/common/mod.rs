//! Helpers shared by the integration tests: the shared engines of the GPU tests, the video
//! fit's small problem, and `r4d-testkit`'s fixtures, `.npz` reading and scenes.
#![allow(dead_code)]

pub mod gpu;
pub mod video;

pub use r4d_testkit::*;
