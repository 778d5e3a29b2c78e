//! The scalar types videos and computations use (`f32` for frames, `f64` for
//! finite-difference checks and reference comparisons): `r4d-math`'s [`Real`], shared with
//! the simulator and the renderer.

pub use r4d_math::Real;
