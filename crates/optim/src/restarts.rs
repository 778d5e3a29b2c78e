//! Restarts along constant bulk modulus: a profile of the loss over a part's shear modulus
//! for an elastoplastic body whose video pins its bulk modulus but hardly its shear modulus.
//!
//! Plastic flow caps the deviatoric stress at the yield surface, so the elastic shear
//! response shows only in the small elastic strains around it, while the volume change stays
//! elastic throughout: fits of such a body end along a valley of nearly constant bulk
//! modulus `K = E / (3 (1 - 2 nu))`, where a lower shear modulus `G = E / (2 (1 + nu))` and a
//! re-fitted yield stress and softening explain the video almost as well, and the trench the
//! other parameters must find at the right `G` is too narrow for a walk along the valley to
//! enter (`docs/fitting-measurements.md`, the full-size plasticine). This stage profiles the valley
//! instead: from the lowest point so far it restarts at `G * factor^k` with `K` kept, `E` and
//! `nu` fixed there, and runs gradient sampling ([`crate::sampling`]) over every other free
//! parameter for `inner_iters` iterations; the profile is the loss each restart ends at.
//! It steps `k = 1, 2, ...` while the profile falls, tries `k = -1, -2, ...` instead when the
//! first restart is not below the starting point, and ends after `points` restarts; the
//! lowest restart becomes the fit's point when it is below everything seen before.

use crate::sampling::GradientSampling;
use serde::{Deserialize, Serialize};

/// Settings of the restarts (`[shear_restarts]` in a fit config). Every key is optional.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RestartsConfig {
    /// Restarts at most; 0: off (the default).
    pub points: usize,
    /// Shear-modulus ratio between neighbouring restarts (`< 1`: lower shear modulus first).
    pub factor: f64,
    /// The part whose `E` and `nu` (both free) are moved (object fits: ignored).
    pub part: u32,
    /// Gradient-sampling iterations over the other free parameters at each restart.
    pub inner_iters: usize,
}

impl Default for RestartsConfig {
    fn default() -> Self {
        RestartsConfig {
            points: 0,
            factor: 0.8,
            part: 0,
            inner_iters: 6,
        }
    }
}

impl RestartsConfig {
    /// Whether the stage is off (`points == 0`).
    pub fn is_off(&self) -> bool {
        self.points == 0
    }

    /// Refuses settings that cannot run, naming the key.
    pub fn validate(&self) -> Result<(), String> {
        if !(self.factor.is_finite() && self.factor > 0.1 && self.factor < 10.0)
            || (self.factor - 1.0).abs() < 1e-3
        {
            return Err(format!(
                "shear_restarts.factor = {}: must be in (0.1, 10) and not 1",
                self.factor
            ));
        }
        if self.points > 64 {
            return Err(format!(
                "shear_restarts.points = {}: at most 64",
                self.points
            ));
        }
        if !self.is_off() && (self.inner_iters == 0 || self.inner_iters > 1000) {
            return Err(format!(
                "shear_restarts.inner_iters = {}: must be in [1, 1000]",
                self.inner_iters
            ));
        }
        Ok(())
    }
}

/// `E` and `nu` from the bulk and shear moduli.
pub fn e_nu_from_k_g(k: f64, g: f64) -> (f64, f64) {
    (
        9.0 * k * g / (3.0 * k + g),
        (3.0 * k - 2.0 * g) / (2.0 * (3.0 * k + g)),
    )
}

/// The bulk and shear moduli of `E` and `nu`.
pub fn k_g_from_e_nu(e: f64, nu: f64) -> (f64, f64) {
    (e / (3.0 * (1.0 - 2.0 * nu)), e / (2.0 * (1.0 + nu)))
}

/// One finished restart.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Restart {
    /// The power of `factor` its shear modulus was started at.
    pub k: i32,
    /// Its `E` and `nu`.
    pub e: f64,
    /// Its Poisson's ratio.
    pub nu: f64,
    /// The loss the inner search ended at (the profile's value).
    pub loss: f64,
    /// Every free parameter at that point (the fit's order).
    pub theta: Vec<f64>,
    /// The inner search (`None` where the restart's simulation failed: loss infinite).
    pub inner: Option<GradientSampling>,
}

/// The state of the restarts.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ShearRestarts {
    /// The point they start from (every free parameter) and its loss.
    pub origin: Vec<f64>,
    /// The loss there.
    pub origin_loss: f64,
    /// Finished restarts, in the order they ran.
    pub done: Vec<Restart>,
    /// The restart in progress: its `k` and inner search.
    pub current: Option<(i32, GradientSampling)>,
}

impl ShearRestarts {
    /// Restarts from `origin` (its loss `loss`).
    pub fn new(origin: Vec<f64>, loss: f64) -> ShearRestarts {
        ShearRestarts {
            origin,
            origin_loss: loss,
            done: Vec::new(),
            current: None,
        }
    }

    /// The next restart's `k`, `None` when the stage is over: `1, 2, ...` while each lowers
    /// the profile; `-1, -2, ...` when the first is not below the origin; at most `points`.
    pub fn next_k(&self, cfg: &RestartsConfig) -> Option<i32> {
        if self.done.len() >= cfg.points {
            return None;
        }
        let side = |sign: i32| -> Vec<f64> {
            let mut v: Vec<&Restart> = self.done.iter().filter(|r| r.k * sign > 0).collect();
            v.sort_by_key(|r| r.k * sign);
            v.iter().map(|r| r.loss).collect()
        };
        let falling = |l: &[f64]| match l {
            [] => true,
            [a] => *a < self.origin_loss,
            [.., a, b] => b < a,
        };
        let (down, up) = (side(1), side(-1));
        if up.is_empty() {
            if falling(&down) {
                return Some(down.len() as i32 + 1);
            }
            return (down.len() == 1).then_some(-1);
        }
        falling(&up).then(|| -(up.len() as i32) - 1)
    }

    /// The lowest restart, if any.
    pub fn best(&self) -> Option<&Restart> {
        self.done.iter().min_by(|a, b| a.loss.total_cmp(&b.loss))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::SamplingConfig;

    #[test]
    fn moduli_round_trip() {
        let (k, g) = k_g_from_e_nu(2e5, 0.3);
        let (e, nu) = e_nu_from_k_g(k, g);
        assert!((e / 2e5 - 1.0).abs() < 1e-12 && (nu - 0.3).abs() < 1e-12);
    }

    fn restart(k: i32, loss: f64) -> Restart {
        Restart {
            k,
            e: 1.0,
            nu: 0.3,
            loss,
            theta: vec![1.0],
            inner: Some(
                GradientSampling::new(&[1.0], loss, &[(0.1, 10.0)], &SamplingConfig::default())
                    .unwrap(),
            ),
        }
    }

    /// Onwards while the profile falls, the other way when the first restart is not lower,
    /// never more than `points`.
    #[test]
    fn the_sequence_follows_the_profile_downhill() {
        let cfg = RestartsConfig {
            points: 4,
            ..Default::default()
        };
        let mut s = ShearRestarts::new(vec![1.0], 1.0);
        assert_eq!(s.next_k(&cfg), Some(1));
        s.done.push(restart(1, 0.99));
        assert_eq!(s.next_k(&cfg), Some(2));
        s.done.push(restart(2, 0.97));
        assert_eq!(s.next_k(&cfg), Some(3));
        s.done.push(restart(3, 0.98));
        assert_eq!(s.next_k(&cfg), None, "rose after falling");
        assert_eq!(s.best().unwrap().k, 2);
        let mut s = ShearRestarts::new(vec![1.0], 1.0);
        s.done.push(restart(1, 1.01));
        assert_eq!(s.next_k(&cfg), Some(-1));
        s.done.push(restart(-1, 0.95));
        assert_eq!(s.next_k(&cfg), Some(-2));
        s.done.push(restart(-2, 0.94));
        assert_eq!(s.next_k(&cfg), Some(-3));
        s.done.push(restart(-3, 0.93));
        assert_eq!(s.next_k(&cfg), None, "points spent");
        let mut s = ShearRestarts::new(vec![1.0], 1.0);
        s.done.push(restart(1, 1.01));
        s.done.push(restart(-1, 1.02));
        assert_eq!(s.next_k(&cfg), None, "neither side lower");
    }

    #[test]
    fn bad_settings_are_refused_naming_the_key() {
        let bad = RestartsConfig {
            factor: 1.0,
            ..Default::default()
        };
        assert!(bad
            .validate()
            .unwrap_err()
            .contains("shear_restarts.factor"));
        let bad = RestartsConfig {
            points: 2,
            inner_iters: 0,
            ..Default::default()
        };
        assert!(bad
            .validate()
            .unwrap_err()
            .contains("shear_restarts.inner_iters"));
    }
}
