//! The renderer's scalar type and small linear algebra: re-exported from `r4d-math`, the one
//! implementation shared with the simulator and the losses (`f32` for rendering, `f64` for
//! finite-difference checks). Matrices are row-major `[[T; 3]; 3]` arrays.

pub use r4d_math::m3::{
    add, cast3, det, eye3, mat_t_vec, mat_vec, mul, mul_at, mul_bt, transpose, zero3, M3,
};
pub use r4d_math::vec3::{cast as castv, cross, dot, Vec3 as V3};
pub use r4d_math::Real;
