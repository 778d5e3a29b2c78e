//! The scalar types videos and computations use: `f32` and `f64`.

use num_traits::Float;

mod sealed {
    pub trait Sealed {}
    impl Sealed for f32 {}
    impl Sealed for f64 {}
}

/// A floating-point scalar: `f32` (the renderer's frames) or `f64` (finite-difference
/// checks, reference comparisons). Sealed.
pub trait Real:
    Float
    + Default
    + Send
    + Sync
    + std::fmt::Debug
    + std::fmt::Display
    + std::ops::AddAssign
    + std::ops::SubAssign
    + std::ops::MulAssign
    + 'static
    + sealed::Sealed
{
    /// The value as `f64` (exact).
    fn f64(self) -> f64;
    /// The nearest value to `x` (round to nearest).
    fn cast(x: f64) -> Self;
    /// `f32` for `f32`, `f64` for `f64` (a name for messages).
    const NAME: &'static str;
}

impl Real for f32 {
    #[inline(always)]
    fn f64(self) -> f64 {
        self as f64
    }
    #[inline(always)]
    fn cast(x: f64) -> Self {
        x as f32
    }
    const NAME: &'static str = "f32";
}

impl Real for f64 {
    #[inline(always)]
    fn f64(self) -> f64 {
        self
    }
    #[inline(always)]
    fn cast(x: f64) -> Self {
        x
    }
    const NAME: &'static str = "f64";
}
