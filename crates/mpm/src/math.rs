//! The simulator's scalar type and 3x3 linear algebra: re-exported from `r4d-math`, the one
//! implementation shared with the renderer and the losses. Matrices are row-major: `m[i][j]`
//! is row `i`, column `j`; for a deformation gradient `F[i][j] = dx_i / dX_j`.

pub use r4d_math::{
    add, cross, dot, norm, scale, sub, svd3, svd3_many, Mat3, Real, Svd3, Vec3, SVD_BATCH,
};
