//! # r4d-math: one scalar trait and one 3x3 module for the whole workspace
//!
//! The simulator (`r4d-mpm`), the renderer (`r4d-splat`) and the losses (`r4d-loss`) are all
//! generic over the same [`Real`] (`f32` for production, `f64` for finite-difference checks)
//! and use the same small fixed-size linear algebra:
//!
//! * [`vec3`]: 3-vectors as `[T; 3]` (dot, cross, norm, ...);
//! * [`m3`]: 3x3 matrices as row-major `[[T; 3]; 3]` arrays (products, transposes,
//!   determinant, casts); [`Mat3`] is a typed wrapper whose operators call these functions;
//! * [`eigen::sym_eigen`]: cyclic Jacobi eigen-decomposition of a symmetric matrix
//!   ([`eigen::sym_eigen_lanes`]: several side by side, bitwise the same results);
//! * [`svd::svd3`]: the SVD with PhysGaussian's sign conventions, built on `sym_eigen`
//!   ([`svd::svd3_many`]: many at once, 8 per batch, AVX2 when the processor has it);
//! * [`polar`]: the polar rotation and its VJP.
//!
//! ```
//! use r4d_math::{svd3, Mat3};
//! let f = Mat3::<f64>::from_array([1.2, 0.1, 0.0, 0.0, 0.9, 0.0, 0.0, 0.0, 1.0]);
//! let s = svd3(f);
//! assert!((s.compose(s.sigma) - f).frobenius() < 1e-12);
//! ```

pub mod eigen;
pub mod m3;
pub mod mat3;
pub mod polar;
pub mod real;
pub mod svd;
pub mod vec3;

pub use eigen::{sym_eigen, sym_eigen_lanes};
pub use m3::M3;
pub use mat3::Mat3;
pub use polar::{polar_rotation, polar_rotation_vjp};
pub use real::Real;
pub use svd::{svd3, svd3_batch, svd3_lanes, svd3_many, Svd3, SVD_BATCH};
pub use vec3::{add, cross, dot, norm, scale, sub, Vec3};
