//! Seeded Latin hypercube sampling and the log-space map used by the initialiser.
//!
//! The random numbers come from SplitMix64 (Steele, Lea and Flood, "Fast splittable
//! pseudorandom number generators", OOPSLA 2014; the constants are those of Vigna's reference
//! `splitmix64.c`). It is written out here rather than taken from a crate so that a seed gives
//! the same samples on every platform and with every version of the dependencies: a fitted
//! run's `init.json` can be regenerated exactly.

/// SplitMix64: a 64-bit state advanced by the golden-ratio increment, output through a
/// variant of the MurmurHash3 finaliser. Period 2^64; every seed (0 included) is valid.
#[derive(Clone, Debug)]
pub struct SplitMix64 {
    state: u64,
}

impl SplitMix64 {
    /// A generator seeded with `seed`.
    pub fn new(seed: u64) -> Self {
        SplitMix64 { state: seed }
    }

    /// The next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        self.state = self.state.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.state;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform in `[0, 1)`: the top 53 bits scaled by 2^-53.
    pub fn next_f64(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
    }

    /// Uniform integer in `[0, n)` without modulo bias (rejection of the incomplete top
    /// block). `n` must be positive.
    pub fn below(&mut self, n: u64) -> u64 {
        debug_assert!(n > 0);
        // u64::MAX - zone = 2^64 mod n, so [0, zone] holds a whole number of blocks of n.
        let zone = u64::MAX - (u64::MAX - n + 1) % n;
        loop {
            let x = self.next_u64();
            if x <= zone {
                return x % n;
            }
        }
    }
}

/// The largest `f64` below a positive finite `x` (`f64::next_down` needs Rust 1.86).
fn prev_float(x: f64) -> f64 {
    debug_assert!(x > 0.0 && x.is_finite());
    f64::from_bits(x.to_bits() - 1)
}

/// `n` points of a Latin hypercube in `[0, 1)^dims`, reproducible from `seed`.
///
/// In every dimension each stratum `[k/n, (k+1)/n)` (bounds computed as `k as f64 / n as f64`)
/// holds exactly one point, at a uniformly random position inside it; the assignment of
/// strata to points is an independent random permutation per dimension. Returns `n` vectors
/// of length `dims` (an empty vector for `n = 0`).
///
/// The sequence is fixed by this algorithm and SplitMix64 seeded with `seed`: for each
/// dimension in turn, a Fisher–Yates shuffle of `0..n` (swapping position `i` with a uniform
/// `j <= i`, `i` from `n - 1` down to 1) followed by `n` uniforms, one per point.
///
/// ```
/// let pts = r4d_optim::latin_hypercube(4, 2, 7);
/// for d in 0..2 {
///     let mut strata: Vec<usize> = pts.iter().map(|p| (p[d] * 4.0) as usize).collect();
///     strata.sort();
///     assert_eq!(strata, vec![0, 1, 2, 3]);
/// }
/// assert_eq!(pts, r4d_optim::latin_hypercube(4, 2, 7));
/// ```
pub fn latin_hypercube(n: usize, dims: usize, seed: u64) -> Vec<Vec<f64>> {
    let mut rng = SplitMix64::new(seed);
    let mut points = vec![Vec::with_capacity(dims); n];
    let nf = n as f64;
    let mut perm: Vec<usize> = Vec::with_capacity(n);
    for _ in 0..dims {
        perm.clear();
        perm.extend(0..n);
        for i in (1..n).rev() {
            let j = rng.below(i as u64 + 1) as usize;
            perm.swap(i, j);
        }
        for (point, &k) in points.iter_mut().zip(&perm) {
            let (lo, hi) = (k as f64 / nf, (k + 1) as f64 / nf);
            let u = rng.next_f64();
            let mut x = lo + u * (hi - lo);
            // Rounding can land on the upper edge (u is at most 1 - 2^-53): stay inside.
            if x >= hi {
                x = prev_float(hi).max(lo);
            }
            point.push(x);
        }
    }
    points
}

/// Maps `u` in `[0, 1]` to `10^(log10 lo + u (log10 hi - log10 lo))`: uniform in `u` is
/// log-uniform between `lo` and `hi`.
///
/// `lo` and `hi` must be positive (debug builds assert it). `u` outside `[0, 1]` is clamped,
/// `u = 0` gives `lo` and `u = 1` gives `hi` exactly, and the result never leaves the closed
/// interval between `lo` and `hi` (floating-point rounding is clamped away). A NaN `u` gives
/// NaN.
///
/// ```
/// use r4d_optim::log_space;
/// assert_eq!(log_space(0.0, 1e3, 1e7), 1e3);
/// assert!((log_space(0.5, 1e3, 1e7) - 1e5).abs() < 1e-6);
/// assert_eq!(log_space(1.0, 1e3, 1e7), 1e7);
/// ```
pub fn log_space(u: f64, lo: f64, hi: f64) -> f64 {
    debug_assert!(lo > 0.0 && hi > 0.0, "log_space needs positive bounds");
    if u.is_nan() {
        return f64::NAN;
    }
    if u <= 0.0 {
        return lo;
    }
    if u >= 1.0 {
        return hi;
    }
    let (a, b) = (lo.log10(), hi.log10());
    let x = 10f64.powf(a + u * (b - a));
    x.clamp(lo.min(hi), lo.max(hi))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn splitmix64_reference_values() {
        // Vigna's splitmix64.c seeded with 1234567.
        let mut r = SplitMix64::new(1_234_567);
        let got: Vec<u64> = (0..5).map(|_| r.next_u64()).collect();
        assert_eq!(
            got,
            vec![
                6_457_827_717_110_365_317,
                3_203_168_211_198_807_973,
                9_817_491_932_198_370_423,
                4_593_380_528_125_082_431,
                16_408_922_859_458_223_821,
            ]
        );
    }

    #[test]
    fn splitmix64_below_is_in_range_and_covers() {
        let mut r = SplitMix64::new(3);
        for n in [1u64, 2, 3, 7, 10] {
            let mut seen = vec![false; n as usize];
            for _ in 0..200 {
                let x = r.below(n);
                assert!(x < n);
                seen[x as usize] = true;
            }
            assert!(seen.iter().all(|&s| s), "n = {n}");
        }
        assert!(r.below(u64::MAX) < u64::MAX);
        for _ in 0..1000 {
            let u = r.next_f64();
            assert!((0.0..1.0).contains(&u));
        }
    }

    /// Sorted, the points of one dimension must sit one per stratum, the j-th in the j-th.
    fn assert_one_per_stratum(pts: &[Vec<f64>], n: usize, dims: usize) {
        assert_eq!(pts.len(), n);
        let nf = n as f64;
        for d in 0..dims {
            let mut col: Vec<f64> = pts.iter().map(|p| p[d]).collect();
            col.sort_by(|a, b| a.partial_cmp(b).unwrap());
            for (k, &x) in col.iter().enumerate() {
                assert!((0.0..1.0).contains(&x), "n {n} dim {d}: {x} outside [0, 1)");
                let (lo, hi) = (k as f64 / nf, (k + 1) as f64 / nf);
                assert!(
                    lo <= x && x < hi,
                    "n {n} dim {d}: stratum {k} [{lo}, {hi}) has {x}"
                );
            }
        }
    }

    #[test]
    fn lhs_one_sample_per_stratum_per_dimension() {
        for n in [1usize, 2, 3, 5, 8, 32, 100, 1000] {
            for dims in [1usize, 2, 3, 6, 11] {
                for seed in [0u64, 1, 42, u64::MAX] {
                    let pts = latin_hypercube(n, dims, seed);
                    assert!(pts.iter().all(|p| p.len() == dims));
                    assert_one_per_stratum(&pts, n, dims);
                }
            }
        }
        assert!(latin_hypercube(0, 3, 1).is_empty());
        assert_eq!(latin_hypercube(4, 0, 1), vec![Vec::<f64>::new(); 4]);
    }

    #[test]
    fn lhs_is_reproducible_and_seed_dependent() {
        for (n, dims) in [(2usize, 1usize), (8, 3), (32, 6)] {
            let a = latin_hypercube(n, dims, 12_345);
            assert_eq!(a, latin_hypercube(n, dims, 12_345));
            let b = latin_hypercube(n, dims, 12_346);
            assert_ne!(a, b, "n {n} dims {dims}");
            assert_ne!(a, latin_hypercube(n, dims, 0));
        }
        // Permutations differ between dimensions (not the same shuffle reused).
        let p = latin_hypercube(32, 2, 9);
        let strata =
            |d: usize| -> Vec<usize> { p.iter().map(|x| (x[d] * 32.0) as usize).collect() };
        assert_ne!(strata(0), strata(1));
    }

    #[test]
    fn lhs_marginals_look_uniform() {
        // Positions inside the strata: their mean offset should be about 1/2.
        let n = 2000;
        let pts = latin_hypercube(n, 2, 5);
        for d in 0..2 {
            let mean_offset = pts.iter().map(|p| (p[d] * n as f64).fract()).sum::<f64>() / n as f64;
            assert!((mean_offset - 0.5).abs() < 0.03, "dim {d}: {mean_offset}");
        }
    }

    #[test]
    fn lhs_stays_inside_upper_stratum_edge() {
        assert_eq!(prev_float(1.0), 1.0 - f64::EPSILON / 2.0);
        // The largest possible uniform must still land below the stratum's upper edge.
        let u = 1.0 - f64::EPSILON / 2.0;
        for n in [2usize, 3, 7, 1000] {
            let nf = n as f64;
            let (lo, hi) = ((n - 1) as f64 / nf, 1.0);
            let mut x = lo + u * (hi - lo);
            if n == 2 {
                // 0.5 + (0.5 - 2^-54) rounds (to even) up to 1.0: the fix-up is needed.
                assert_eq!(x, 1.0);
            }
            if x >= hi {
                x = prev_float(hi).max(lo);
            }
            assert!(x < 1.0 && x >= lo);
        }
    }

    #[test]
    fn log_space_endpoints_and_monotonicity() {
        for (lo, hi) in [
            (1e3, 1e7),
            (0.01, 0.49),
            (5.0, 60.0),
            (1e-2, 1e3),
            (2.0, 2.0),
        ] {
            assert_eq!(log_space(0.0, lo, hi), lo);
            assert_eq!(log_space(1.0, lo, hi), hi);
            assert_eq!(log_space(-0.5, lo, hi), lo);
            assert_eq!(log_space(1.5, lo, hi), hi);
            let mut prev = lo;
            for i in 1..=1000 {
                let x = log_space(i as f64 / 1000.0, lo, hi);
                assert!(x >= prev, "[{lo}, {hi}] at {i}: {x} < {prev}");
                assert!(lo <= x && x <= hi);
                prev = x;
            }
            // The midpoint is the geometric mean.
            let mid = log_space(0.5, lo, hi);
            assert!((mid / (lo * hi).sqrt() - 1.0).abs() < 1e-12);
        }
        assert!((log_space(0.25, 1.0, 1e4) - 10.0).abs() < 1e-12);
        assert!(log_space(f64::NAN, 1.0, 2.0).is_nan());
    }
}
