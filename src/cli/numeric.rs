//! Numeric command-line options: every float option is read as f64 and checked against its
//! documented range when the command line is parsed, before any work. A value that would
//! round to 0 or to infinity where the command uses it as f32 (`1e-300`, `1e300`), NaN, and
//! anything outside the range is refused; clap's message names the flag, and ours the value
//! and the range.

/// Why a numeric option's value was refused (clap's message around it names the flag).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum NumberError {
    /// Not a number at all.
    #[error("'{0}' is not a number")]
    NotANumber(String),
    /// NaN or an infinity.
    #[error("{0} is not a finite number")]
    NotFinite(f64),
    /// Outside the option's range.
    #[error("{value} is outside the allowed range [{lo}, {hi}]")]
    OutOfRange {
        /// The value given.
        value: f64,
        /// The smallest value allowed.
        lo: f64,
        /// The largest value allowed.
        hi: f64,
    },
}

/// Parses one value as a finite f64 within `[lo, hi]`.
pub fn parse_in(s: &str, lo: f64, hi: f64) -> Result<f64, NumberError> {
    let v: f64 = s
        .trim()
        .parse()
        .map_err(|_| NumberError::NotANumber(s.to_string()))?;
    if !v.is_finite() {
        return Err(NumberError::NotFinite(v));
    }
    if !(lo..=hi).contains(&v) {
        return Err(NumberError::OutOfRange { value: v, lo, hi });
    }
    Ok(v)
}

/// A clap value parser for a finite f64 option within `[lo, hi]` (see the module docs).
pub fn f64_in(
    lo: f64,
    hi: f64,
) -> impl Fn(&str) -> Result<f64, NumberError> + Clone + Send + Sync + 'static {
    move |s| parse_in(s, lo, hi)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tiny_huge_and_nan_values_are_refused_with_the_range() {
        assert_eq!(parse_in("0.25", 0.0, 1.0), Ok(0.25));
        assert_eq!(parse_in("1e-3", 1e-6, 1e6), Ok(1e-3));
        // 1e-300 is 0 in f32: refused by a range whose floor keeps it meaningful.
        let e = parse_in("1e-300", 1e-6, 1e6).unwrap_err();
        assert!(e.to_string().contains("[0.000001, 1000000]"), "{e}");
        assert!(matches!(
            parse_in("1e300", 0.0, 64.0),
            Err(NumberError::OutOfRange { .. })
        ));
        assert!(matches!(
            parse_in("nan", 0.0, 1.0),
            Err(NumberError::NotFinite(_))
        ));
        assert!(matches!(
            parse_in("inf", 0.0, 1.0),
            Err(NumberError::NotFinite(_))
        ));
        assert!(matches!(
            parse_in("0.5x", 0.0, 1.0),
            Err(NumberError::NotANumber(_))
        ));
    }
}
