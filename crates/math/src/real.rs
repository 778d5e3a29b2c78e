//! The floating-point scalar every numeric crate of the workspace is generic over.

use num_traits::Float;
use std::fmt::{Debug, Display};
use std::ops::{AddAssign, MulAssign, SubAssign};

mod sealed {
    pub trait Sealed {}
    impl Sealed for f32 {}
    impl Sealed for f64 {}
}

/// A floating-point scalar: `f32` (simulation state, frames, device data) or `f64`
/// (finite-difference checks, reference computations). Sealed: implemented for exactly
/// these two types; `Pod`, so buffers of it can be uploaded to a device.
pub trait Real:
    Float
    + bytemuck::Pod
    + Default
    + Debug
    + Display
    + Send
    + Sync
    + AddAssign
    + SubAssign
    + MulAssign
    + 'static
    + sealed::Sealed
{
    /// `"f32"` or `"f64"` (for messages and precision switches).
    const NAME: &'static str;
    /// The value nearest to the `f64` `x` (exact for `f64`, rounded to nearest for `f32`).
    fn c(x: f64) -> Self;
    /// The value as `f64` (exact).
    fn f64(self) -> f64;
}

impl Real for f32 {
    const NAME: &'static str = "f32";
    #[inline(always)]
    fn c(x: f64) -> Self {
        x as f32
    }
    #[inline(always)]
    fn f64(self) -> f64 {
        self as f64
    }
}

impl Real for f64 {
    const NAME: &'static str = "f64";
    #[inline(always)]
    fn c(x: f64) -> Self {
        x
    }
    #[inline(always)]
    fn f64(self) -> f64 {
        self
    }
}

#[cfg(test)]
mod tests {
    use super::Real;

    #[test]
    fn conversions_round_to_nearest_and_back_exactly() {
        assert_eq!(f32::c(0.1), 0.1f32);
        assert_eq!(f64::c(0.1), 0.1);
        assert_eq!(0.1f32.f64(), 0.1f32 as f64);
        assert_eq!((f32::NAME, f64::NAME), ("f32", "f64"));
    }
}
