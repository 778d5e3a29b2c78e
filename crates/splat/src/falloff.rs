//! A Gaussian's falloff `exp(-s)` at a pixel, the one exponential of compositing
//! ([`crate::raster`], [`crate::span`]). In f32 it is computed by arithmetic alone (Cody-Waite
//! range reduction, Cephes' degree-5 polynomial, the power of two assembled from its bits), so
//! that a loop over lanes vectorises and every path that composites in f32 gets the same bits
//! on every processor; within 2 ulp of the correctly rounded `exp` for `s` in `[0, 87]`. In
//! f64 (the finite-difference checks) it is `f64::exp`.

use crate::real::Real;

/// `exp(-s)` (see the module docs); NaN for NaN.
#[inline(always)]
pub fn falloff<T: Real>(s: T) -> T {
    if T::NAME == "f32" {
        // Exact conversions: the f32 value itself.
        T::c(falloff_f32(s.f64() as f32) as f64)
    } else {
        (-s).exp()
    }
}

/// `exp(-s)` in f32 by arithmetic alone; `s` below 0 is taken as 0 and above 87 as 87
/// (compositing only asks for `s` in `[0, ln 255 + 1e-3]`).
#[inline(always)]
pub fn falloff_f32(s: f32) -> f32 {
    const LOG2E: f32 = std::f32::consts::LOG2_E;
    // ln 2 split so that `n * LN2_HI` is exact for |n| < 2^9.
    const LN2_HI: f32 = 0.693_359_4;
    const LN2_LO: f32 = -2.121_944_4e-4;
    // Adding and subtracting 1.5 * 2^23 rounds to the nearest integer.
    const ROUND: f32 = 12_582_912.0;
    // NaN stays NaN (through the clamp and the polynomial).
    let x = -s.clamp(0.0, 87.0);
    let n = (x * LOG2E + ROUND) - ROUND;
    let r = (x - n * LN2_HI) - n * LN2_LO;
    let p = ((((1.987_569_1e-4 * r + 1.398_199_9e-3) * r + 8.333_452e-3) * r + 4.166_579_6e-2) * r
        + 1.666_666_5e-1)
        * r
        + 0.5;
    let e = p * (r * r) + r + 1.0;
    // 2^n for n in [-126, 0] (n = 0 for NaN).
    let scale = f32::from_bits((((n as i32).max(-126) + 127) as u32) << 23);
    e * scale
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Within 2 ulp of the f64 exponential rounded to f32 over compositing's range (and
    /// beyond), exactly 1 at 0, NaN for NaN.
    #[test]
    fn falloff_f32_is_within_two_ulp() {
        let mut worst = 0u32;
        let mut s = 0.0f32;
        while s <= 87.0 {
            let want = (-(s as f64)).exp() as f32;
            let got = falloff_f32(s);
            let ulp = (got.to_bits() as i64 - want.to_bits() as i64).unsigned_abs() as u32;
            worst = worst.max(ulp);
            s = if s < 6.0 { s + 1.3e-5 } else { s + 7.7e-3 };
        }
        assert!(worst <= 2, "worst {worst} ulp");
        assert_eq!(falloff_f32(0.0), 1.0);
        assert!(falloff_f32(f32::NAN).is_nan());
        assert_eq!(falloff::<f64>(0.5), (-0.5f64).exp());
        assert_eq!(falloff::<f32>(0.5), falloff_f32(0.5));
    }
}
