//! A trust-region quasi-Newton step on `xi = log(theta)` with box bounds: the second-order
//! alternative to AdamW for fits with a handful of free parameters.
//!
//! Each iteration evaluates one trial point (loss and gradient, like an AdamW iteration).
//! The model is `m(p) = f + g.p + p^T B p / 2` with `B` a damped-BFGS approximation of the
//! log-space Hessian (Powell's damping keeps it positive definite when the loss is not
//! locally convex). The step is the dogleg solution of the model inside a ball of radius
//! `radius` (log units), projected onto the bounds. A trial that lowers the loss is accepted;
//! the radius grows when the model predicted the decrease well and shrinks when it did not
//! or the trial was rejected. Every trial, accepted or not, updates `B` with its gradient
//! difference, so the curvature of a stiff direction (e.g. `E / density`, which sets the
//! motion's time scale) is learned in a few iterations and the step is no longer limited by
//! it — the zig-zag AdamW shows across such a valley. A trial rejected at the smallest
//! radius restarts the model (scaled identity, first radius): on a loss with noise or kinks
//! the fit keeps exploring around the best point instead of re-evaluating one trial. A second
//! such restart from the same point — or a first one from the start, whose model is the one a
//! restart makes — would repeat the earlier trials exactly (measured: the full-size
//! plasticine demo spent 28 of its 40 iterations in an 8-trial cycle, a random plasticine
//! drop 6 of its first 14), so it searches by finite differences instead (the coordinates `x +- h e_i`, then pairs of them,
//! then the minimum of the quadratic model through those probes; `h` halving after each
//! round): on a loss whose kinks make the local gradient point uphill at every step the model
//! can take, a probe still finds a lower point when there is one nearby, and a pair probe
//! finds a valley along a diagonal (two parameters that trade off).

use crate::Error;
use serde::{Deserialize, Serialize};

/// Settings of [`TrustRegionBfgs`].
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct TrustRegion {
    /// First radius (log units; 0.1 is a 10% change).
    pub initial_radius: f64,
    /// Largest radius.
    pub max_radius: f64,
    /// Smallest radius.
    pub min_radius: f64,
}

impl Default for TrustRegion {
    fn default() -> Self {
        TrustRegion {
            initial_radius: 0.1,
            max_radius: 0.5,
            min_radius: 1e-3,
        }
    }
}

/// Trust-region damped BFGS on `xi = log(theta)` (see the module docs). Serialisable, so a
/// killed run resumes with its model.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TrustRegionBfgs {
    /// Accepted point.
    x: Vec<f64>,
    /// Loss and gradient (w.r.t. xi) at `x`; `None` before the first evaluation.
    at_x: Option<(f64, Vec<f64>)>,
    /// Next point to evaluate.
    trial: Vec<f64>,
    /// Hessian approximation, row-major `n x n` (empty until the first evaluation).
    b: Vec<f64>,
    radius: f64,
    log_bounds: Vec<(f64, f64)>,
    evaluations: u64,
    accepted: u64,
    #[serde(default)]
    restarts: u64,
    /// `accepted` at the last model restart: a second restart with no acceptance in between
    /// would repeat the first one's trials exactly, so it searches by finite differences
    /// instead ([`Pattern`]).
    #[serde(default)]
    restarted_at: Option<u64>,
    /// The finite-difference search in progress, if any.
    #[serde(default)]
    pattern: Option<Pattern>,
    /// Length of the next finite-difference search's first probes, in units of the first radius:
    /// doubles each time a search from the same point finds nothing, 1 after an accepted
    /// trial.
    #[serde(default = "one")]
    probe_scale: f64,
    /// Settings.
    pub settings: TrustRegion,
}

/// A finite-difference search around `x` at scale `h`, used where the gradient has failed at
/// every radius twice (a loss whose kinks make the local gradient point uphill at every
/// finite step). A round tries, in order, and stops at the first trial that lowers the loss:
///
/// 1. the coordinate probes `x +- h e_i` (largest `|g_i|` first, downhill side first);
/// 2. with at most [`MAX_PAIR_PARAMS`] parameters, the pair probes
///    `x + s_i t_i e_i + s_j t_j e_j`, `s` each coordinate's better side, the lengths `t`
///    scaled so both coordinates' probes rose alike (`h` for the softer one): a valley along
///    a diagonal (two parameters that trade off) is lower there although every coordinate
///    probe is higher;
/// 3. the minimum of the quadratic model through the probes (gradient and Hessian by finite
///    differences at scale `h`: diagonal from the coordinate probes, off-diagonal from the
///    pair probes, zero without them), damped to positive definite, at most `2 h` long;
///
/// then `h / 2` and a new round.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
struct Pattern {
    /// `(coordinate, sign)` of the coordinate probes in the order they are tried.
    order: Vec<(usize, f64)>,
    /// The next trial of the round: `< order.len()` a coordinate probe, then the pair probes,
    /// then the model's minimum.
    next: usize,
    /// The probe length (log units).
    h: f64,
    /// The losses of this round's probes, in order (non-finite: `+inf`).
    #[serde(default)]
    losses: Vec<f64>,
}

/// Largest number of free parameters for which the finite-difference search probes pairs
/// (`n (n - 1) / 2` trials per round: 28 at 8).
pub const MAX_PAIR_PARAMS: usize = 8;

impl Pattern {
    /// Coordinates by decreasing `|g_i|`, each first downhill by its gradient, then uphill.
    fn new(g: &[f64], h: f64) -> Pattern {
        let mut idx: Vec<usize> = (0..g.len()).collect();
        idx.sort_by(|&a, &b| g[b].abs().total_cmp(&g[a].abs()).then(a.cmp(&b)));
        let order = idx
            .iter()
            .flat_map(|&i| {
                let down = if g[i] > 0.0 { -1.0 } else { 1.0 };
                [(i, down), (i, -down)]
            })
            .collect();
        Pattern {
            order,
            next: 0,
            h,
            losses: Vec::new(),
        }
    }

    /// Number of coordinates.
    fn n(&self) -> usize {
        self.order.len() / 2
    }

    /// The pairs probed after the coordinates, `(i, j)` with `i < j`.
    fn pairs(&self) -> Vec<(usize, usize)> {
        let n = self.n();
        if n > MAX_PAIR_PARAMS {
            return Vec::new();
        }
        (0..n)
            .flat_map(|i| (i + 1..n).map(move |j| (i, j)))
            .collect()
    }

    /// Trials in a round (the model's minimum last).
    fn round_len(&self) -> usize {
        self.order.len() + self.pairs().len() + 1
    }

    /// `f(x + h e_i)` and `f(x - h e_i)` per coordinate (`+inf` where not probed).
    fn coordinate_losses(&self) -> (Vec<f64>, Vec<f64>) {
        let n = self.n();
        let mut plus = vec![f64::INFINITY; n];
        let mut minus = vec![f64::INFINITY; n];
        for (&(i, sign), &l) in self.order.iter().zip(&self.losses) {
            if sign > 0.0 {
                plus[i] = l;
            } else {
                minus[i] = l;
            }
        }
        (plus, minus)
    }

    /// Each coordinate's better side (+1 or -1).
    fn sides(&self) -> Vec<f64> {
        let (plus, minus) = self.coordinate_losses();
        plus.iter()
            .zip(&minus)
            .map(|(p, m)| if p <= m { 1.0 } else { -1.0 })
            .collect()
    }

    /// The step lengths of pair `(i, j)`'s probe: `h` for the coordinate whose better-side
    /// probe rose less, shorter for the other, `h sqrt(r_min / r)` with `r` the rises, so
    /// both contribute alike to a quadratic loss (the probe runs along the diagonal of the
    /// coordinates scaled by their curvature: a narrow valley between a stiff parameter and
    /// a soft one is found there).
    fn pair_lengths(&self, i: usize, j: usize, f0: f64) -> (f64, f64) {
        let (plus, minus) = self.coordinate_losses();
        let rise = |k: usize| (plus[k].min(minus[k]) - f0).max(0.0);
        let (ri, rj) = (rise(i), rise(j));
        let r = ri.min(rj);
        let len = |rk: f64| {
            if rk > 0.0 && r.is_finite() && rk.is_finite() {
                self.h * (r / rk).sqrt()
            } else {
                self.h
            }
        };
        (len(ri), len(rj))
    }

    /// The offset (log units) of trial `k` of the round from `x`; `f0 = f(x)`.
    fn offset(&self, k: usize, f0: f64) -> Vec<f64> {
        let n = self.n();
        let mut d = vec![0.0; n];
        if k < self.order.len() {
            let (i, sign) = self.order[k];
            d[i] = sign * self.h;
        } else if let Some(&(i, j)) = self.pairs().get(k - self.order.len()) {
            let s = self.sides();
            let (ti, tj) = self.pair_lengths(i, j, f0);
            d[i] = s[i] * ti;
            d[j] = s[j] * tj;
        } else {
            d = self.model_step(f0);
        }
        d
    }

    /// The minimum of the finite-difference quadratic model (see the type's docs).
    fn model_step(&self, f0: f64) -> Vec<f64> {
        let n = self.n();
        let h = self.h;
        let (plus, minus) = self.coordinate_losses();
        let ok = |v: f64| v.is_finite();
        let mut g = vec![0.0; n];
        let mut hm = vec![0.0; n * n];
        for i in 0..n {
            if ok(plus[i]) && ok(minus[i]) {
                g[i] = (plus[i] - minus[i]) / (2.0 * h);
                hm[i * n + i] = (plus[i] + minus[i] - 2.0 * f0) / (h * h);
            }
        }
        let s = self.sides();
        for (k, &(i, j)) in self.pairs().iter().enumerate() {
            let Some(&fij) = self.losses.get(self.order.len() + k) else {
                break;
            };
            // The 1-D parabolas at the pair's step lengths.
            let (ti, tj) = self.pair_lengths(i, j, f0);
            let along = |k: usize, t: f64| f0 + g[k] * s[k] * t + 0.5 * hm[k * n + k] * t * t;
            let (fi, fj) = (along(i, ti), along(j, tj));
            if ok(fij) && ok(fi) && ok(fj) && ok(plus[i] + minus[i] + plus[j] + minus[j]) {
                let hij = (fij - fi - fj + f0) / (ti * tj * s[i] * s[j]);
                hm[i * n + j] = hij;
                hm[j * n + i] = hij;
            }
        }
        // Damped to positive definite: H + lambda I, lambda from 0 up.
        let scale = (0..n)
            .map(|i| hm[i * n + i].abs())
            .fold(0.0, f64::max)
            .max(1e-12);
        let neg: Vec<f64> = g.iter().map(|v| -v).collect();
        let mut lambda = 0.0;
        let mut step = vec![0.0; n];
        for _ in 0..40 {
            let mut b = hm.clone();
            for i in 0..n {
                b[i * n + i] += lambda;
            }
            if let Some(p) = solve_spd(&b, &neg) {
                step = p;
                break;
            }
            lambda = if lambda == 0.0 {
                1e-6 * scale
            } else {
                4.0 * lambda
            };
        }
        let len = norm(&step);
        if len > 2.0 * h {
            step.iter_mut().for_each(|v| *v *= 2.0 * h / len);
        }
        step
    }
}

fn one() -> f64 {
    1.0
}

/// `c I`, row-major `n x n`.
fn scaled_identity(n: usize, c: f64) -> Vec<f64> {
    (0..n * n)
        .map(|k| if k % (n + 1) == 0 { c } else { 0.0 })
        .collect()
}

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

fn norm(a: &[f64]) -> f64 {
    dot(a, a).sqrt()
}

/// `B v` for a row-major `n x n` `B`.
fn mat_vec(b: &[f64], v: &[f64]) -> Vec<f64> {
    let n = v.len();
    (0..n).map(|i| dot(&b[i * n..(i + 1) * n], v)).collect()
}

/// Solves `B x = r` by Cholesky; `None` when `B` is not positive definite.
fn solve_spd(b: &[f64], r: &[f64]) -> Option<Vec<f64>> {
    let n = r.len();
    let mut l = vec![0.0; n * n];
    for i in 0..n {
        for j in 0..=i {
            let s = b[i * n + j] - (0..j).map(|k| l[i * n + k] * l[j * n + k]).sum::<f64>();
            if i == j {
                if s <= 0.0 || !s.is_finite() {
                    return None;
                }
                l[i * n + i] = s.sqrt();
            } else {
                l[i * n + j] = s / l[j * n + j];
            }
        }
    }
    let mut y = vec![0.0; n];
    for i in 0..n {
        y[i] = (r[i] - (0..i).map(|k| l[i * n + k] * y[k]).sum::<f64>()) / l[i * n + i];
    }
    let mut x = vec![0.0; n];
    for i in (0..n).rev() {
        x[i] = (y[i] - (i + 1..n).map(|k| l[k * n + i] * x[k]).sum::<f64>()) / l[i * n + i];
    }
    Some(x)
}

impl TrustRegionBfgs {
    /// Starts at positive `theta` within positive `bounds`.
    pub fn new(
        theta: Vec<f64>,
        bounds: Vec<(f64, f64)>,
        settings: TrustRegion,
    ) -> Result<Self, Error> {
        if theta.len() != bounds.len() {
            return Err(Error::Invalid {
                index: theta.len().min(bounds.len()),
                message: format!(
                    "{} values for {} bounds: one bound per parameter",
                    theta.len(),
                    bounds.len()
                ),
            });
        }
        for (i, (&t, &(l, u))) in theta.iter().zip(&bounds).enumerate() {
            if !(l.is_finite() && u.is_finite() && l > 0.0 && u >= l) {
                return Err(Error::Invalid {
                    index: i,
                    message: format!("bounds [{l}, {u}] must be positive, finite and ordered"),
                });
            }
            if !(t.is_finite() && t > 0.0) {
                return Err(Error::Invalid {
                    index: i,
                    message: format!("value {t} must be positive and finite"),
                });
            }
        }
        let s = settings;
        let ordered = s.min_radius > 0.0
            && s.min_radius <= s.initial_radius
            && s.initial_radius <= s.max_radius
            && s.max_radius.is_finite();
        if !ordered {
            return Err(Error::Invalid {
                index: 0,
                message: format!(
                    "trust radii must satisfy 0 < min ({}) <= initial ({}) <= max ({}) < inf",
                    s.min_radius, s.initial_radius, s.max_radius
                ),
            });
        }
        let log_bounds: Vec<(f64, f64)> = bounds.iter().map(|(l, u)| (l.ln(), u.ln())).collect();
        let x: Vec<f64> = theta
            .iter()
            .zip(&log_bounds)
            .map(|(t, (l, u))| t.ln().clamp(*l, *u))
            .collect();
        Ok(TrustRegionBfgs {
            trial: x.clone(),
            x,
            at_x: None,
            b: Vec::new(),
            radius: settings.initial_radius,
            log_bounds,
            evaluations: 0,
            accepted: 0,
            restarts: 0,
            restarted_at: None,
            pattern: None,
            probe_scale: 1.0,
            settings,
        })
    }

    /// Checks a state read back (a checkpoint) before it is stepped: `n` parameters, every
    /// vector that long (the model `n x n` or empty), values finite and inside ordered
    /// bounds, a positive radius within valid settings.
    pub fn validate(&self, n: usize) -> Result<(), Error> {
        let bad = |index: usize, message: String| Err(Error::Invalid { index, message });
        let model_ok = self.b.is_empty() || self.b.len() == n.saturating_mul(n);
        let at_ok = self
            .at_x
            .as_ref()
            .is_none_or(|(l, g)| g.len() == n && l.is_finite() && g.iter().all(|v| v.is_finite()));
        if self.x.len() != n || self.trial.len() != n || self.log_bounds.len() != n || !model_ok {
            return bad(
                0,
                format!(
                    "the trust-region state holds {} / {} / {} values and a {}-entry model, this fit has {n} parameters",
                    self.x.len(),
                    self.trial.len(),
                    self.log_bounds.len(),
                    self.b.len()
                ),
            );
        }
        if !at_ok || self.b.iter().any(|v| !v.is_finite()) {
            return bad(
                0,
                "damaged trust-region state (non-finite model or gradient)".into(),
            );
        }
        for i in 0..n {
            let (lo, hi) = self.log_bounds[i];
            let inside = |v: f64| v.is_finite() && (lo..=hi).contains(&v);
            if !(lo.is_finite()
                && hi.is_finite()
                && lo <= hi
                && inside(self.x[i])
                && inside(self.trial[i]))
            {
                return bad(
                    i,
                    format!(
                        "damaged trust-region state: log values {} and {}, log bounds [{lo}, {hi}]",
                        self.x[i], self.trial[i]
                    ),
                );
            }
        }
        if !(self.probe_scale.is_finite() && self.probe_scale >= 1.0) {
            return bad(
                0,
                format!(
                    "damaged trust-region state: probe scale {}",
                    self.probe_scale
                ),
            );
        }
        if let Some(p) = &self.pattern {
            let ok = p.order.len() == 2 * n
                && p.next < p.round_len()
                && p.losses.len() < p.round_len()
                && p.order
                    .iter()
                    .all(|&(i, sg)| i < n && (sg == 1.0 || sg == -1.0))
                && p.h.is_finite()
                && p.h > 0.0;
            if !ok {
                return bad(
                    0,
                    format!(
                        "damaged trust-region state: coordinate search at {} of {} probes, length {}",
                        p.next,
                        p.order.len(),
                        p.h
                    ),
                );
            }
        }
        let s = self.settings;
        let ordered = s.min_radius > 0.0
            && s.min_radius <= s.initial_radius
            && s.initial_radius <= s.max_radius
            && s.max_radius.is_finite();
        if !(ordered && self.radius.is_finite() && self.radius > 0.0) {
            return bad(
                0,
                format!(
                    "damaged trust-region state: radius {} with settings {:?}",
                    self.radius, s
                ),
            );
        }
        Ok(())
    }

    /// The parameters to evaluate next.
    pub fn theta(&self) -> Vec<f64> {
        self.trial.iter().map(|x| x.exp()).collect()
    }

    /// The accepted parameters (the lowest loss seen so far).
    pub fn accepted_theta(&self) -> Vec<f64> {
        self.x.iter().map(|x| x.exp()).collect()
    }

    /// Current trust radius (log units).
    pub fn radius(&self) -> f64 {
        self.radius
    }

    /// Evaluations taken and how many of them were accepted.
    pub fn counts(&self) -> (u64, u64) {
        (self.evaluations, self.accepted)
    }

    /// Restarts of the model after a rejection at the smallest radius.
    pub fn restarts(&self) -> u64 {
        self.restarts
    }

    /// Moves parameter `i` of the accepted point to `value` (clamped to its bounds) and
    /// evaluates from there next: the jump of a flat-direction probe, whose loss the caller
    /// has seen to be lower. The model's row and column of `i` are reset.
    pub fn set_theta(&mut self, i: usize, value: f64) {
        if i >= self.x.len() || value.is_nan() || value <= 0.0 {
            return;
        }
        let (lo, hi) = self.log_bounds[i];
        self.x[i] = value.ln().clamp(lo, hi);
        self.trial = self.x.clone();
        // The next evaluation re-anchors the model at the moved point.
        self.at_x = None;
        let n = self.x.len();
        if self.b.len() == n * n {
            let d = self.b[i * n + i];
            for k in 0..n {
                self.b[i * n + k] = 0.0;
                self.b[k * n + i] = 0.0;
            }
            self.b[i * n + i] = d;
        }
    }

    /// Takes the loss and `dL/dtheta` at [`TrustRegionBfgs::theta`], chooses the next trial;
    /// returns the norm of `dL/dxi`. A non-finite loss or gradient counts as a rejected
    /// trial (the radius shrinks).
    pub fn step(&mut self, loss: f64, grad_theta: &[f64]) -> f64 {
        let n = self.x.len();
        let g: Vec<f64> = grad_theta
            .iter()
            .zip(&self.trial)
            .map(|(g, x)| g * x.exp())
            .collect();
        let gnorm = norm(&g);
        self.evaluations = self.evaluations.saturating_add(1);
        let finite = loss.is_finite() && g.iter().all(|v| v.is_finite());
        match self.at_x.take() {
            None => {
                if finite {
                    self.x = self.trial.clone();
                    let fresh = self.b.len() != n * n;
                    if fresh {
                        self.b = scaled_identity(n, gnorm.max(1e-12) / self.radius);
                    }
                    self.at_x = Some((loss, g));
                    self.accepted = self.accepted.saturating_add(1);
                    if fresh && self.radius == self.settings.initial_radius {
                        // The first model is the one a restart here would make: restarting
                        // it would repeat its trials exactly, so the probes follow it.
                        self.restarted_at = Some(self.accepted);
                    }
                } else {
                    self.radius = (0.25 * self.radius).max(self.settings.min_radius);
                }
            }
            Some((f, gx)) => {
                let s: Vec<f64> = self.trial.iter().zip(&self.x).map(|(a, b)| a - b).collect();
                let bs = mat_vec(&self.b, &s);
                let pred = -(dot(&gx, &s) + 0.5 * dot(&s, &bs));
                if finite {
                    // Damped BFGS update with y = g_trial - g_x.
                    let y: Vec<f64> = g.iter().zip(&gx).map(|(a, b)| a - b).collect();
                    let sbs = dot(&s, &bs);
                    let sy = dot(&s, &y);
                    if sbs > 1e-300 {
                        let th = if sy >= 0.2 * sbs {
                            1.0
                        } else {
                            0.8 * sbs / (sbs - sy)
                        };
                        let r: Vec<f64> = y
                            .iter()
                            .zip(&bs)
                            .map(|(yi, bi)| th * yi + (1.0 - th) * bi)
                            .collect();
                        let sr = dot(&s, &r);
                        if sr > 1e-300 {
                            for i in 0..n {
                                for j in 0..n {
                                    self.b[i * n + j] += r[i] * r[j] / sr - bs[i] * bs[j] / sbs;
                                }
                            }
                        }
                    }
                }
                let step = norm(&s);
                if finite && loss < f && self.pattern.take().is_some() {
                    // A probe found a lower point: the model restarts there (once: if the
                    // gradient fails again the probes resume).
                    self.x = self.trial.clone();
                    self.restart(&g);
                    self.at_x = Some((loss, g));
                    self.accepted = self.accepted.saturating_add(1);
                    self.restarted_at = Some(self.accepted);
                    self.probe_scale = 1.0;
                } else if finite && loss < f {
                    let rho = if pred > 0.0 { (f - loss) / pred } else { 0.0 };
                    if rho > 0.75 && step > 0.8 * self.radius {
                        self.radius = (2.0 * self.radius).min(self.settings.max_radius);
                    } else if rho < 0.25 {
                        self.radius = (0.5 * self.radius).max(self.settings.min_radius);
                    }
                    self.x = self.trial.clone();
                    self.at_x = Some((loss, g));
                    self.accepted = self.accepted.saturating_add(1);
                    self.probe_scale = 1.0;
                } else if let Some(pat) = self.pattern.as_mut() {
                    // The trial failed: the next one of the round, then half the length.
                    if pat.next < pat.round_len() - 1 {
                        pat.losses.push(if finite { loss } else { f64::INFINITY });
                    }
                    pat.next += 1;
                    let model_next = pat.next == pat.round_len() - 1
                        && pat.model_step(f).iter().any(|&p| p != 0.0);
                    if pat.next >= pat.round_len() - 1 && !model_next {
                        pat.next = 0;
                        pat.h *= 0.5;
                        pat.losses.clear();
                    }
                    if pat.h < self.settings.min_radius {
                        // Nothing lower down to the smallest probe: the next search from
                        // this point probes twice as far (up to the largest radius).
                        self.probe_scale = (2.0 * self.probe_scale)
                            .min(self.settings.max_radius / self.settings.initial_radius);
                        self.pattern = None;
                        self.restart(&gx);
                    }
                    self.at_x = Some((f, gx));
                } else if self.radius <= self.settings.min_radius {
                    // Rejected at the smallest radius: the model no longer describes the
                    // loss near x (noise, a kink). Restart it: a scaled identity and the
                    // first radius, so the next trials explore again instead of repeating;
                    // if the last restart was from this same point, its trials would repeat
                    // exactly: probe the coordinates instead.
                    if self.restarted_at == Some(self.accepted) {
                        let h = self.settings.initial_radius * self.probe_scale;
                        self.pattern = Some(Pattern::new(&gx, h));
                        self.restarted_at = None;
                    } else {
                        self.restart(&gx);
                    }
                    self.at_x = Some((f, gx));
                } else {
                    self.radius = (0.5 * step.min(self.radius)).max(self.settings.min_radius);
                    self.at_x = Some((f, gx));
                }
            }
        }
        self.trial = self.next_trial();
        gnorm
    }

    /// Restarts the model at `x` (gradient `g` there): a scaled identity and the first radius.
    fn restart(&mut self, g: &[f64]) {
        let c = norm(g).max(1e-12) / self.settings.initial_radius;
        self.b = scaled_identity(self.x.len(), c);
        self.radius = self.settings.initial_radius;
        self.restarts = self.restarts.saturating_add(1);
        self.restarted_at = Some(self.accepted);
    }

    /// The dogleg step from `x` inside the radius, projected onto the bounds (or the next
    /// finite-difference search's trial).
    fn next_trial(&self) -> Vec<f64> {
        let Some((_, g)) = &self.at_x else {
            return self.x.clone();
        };
        if let Some(p) = &self.pattern {
            let f0 = self.at_x.as_ref().map_or(0.0, |(f, _)| *f);
            return self
                .x
                .iter()
                .zip(&p.offset(p.next, f0))
                .zip(&self.log_bounds)
                .map(|((x, d), (lo, hi))| (x + d).clamp(*lo, *hi))
                .collect();
        }
        // Directions that point out of the box at an active bound are dropped.
        let g: Vec<f64> = g
            .iter()
            .zip(&self.x)
            .zip(&self.log_bounds)
            .map(|((&gi, &xi), &(lo, hi))| {
                if (xi <= lo && gi > 0.0) || (xi >= hi && gi < 0.0) {
                    0.0
                } else {
                    gi
                }
            })
            .collect();
        let gg = dot(&g, &g);
        if gg == 0.0 {
            return self.x.clone();
        }
        let r = self.radius;
        let neg: Vec<f64> = g.iter().map(|v| -v).collect();
        let p = match solve_spd(&self.b, &neg) {
            Some(pn) if norm(&pn) <= r => pn,
            newton => {
                let gbg = dot(&g, &mat_vec(&self.b, &g));
                let cauchy_len = if gbg > 0.0 { gg / gbg } else { f64::INFINITY };
                let pu: Vec<f64> = g.iter().map(|v| -cauchy_len * v).collect();
                match newton {
                    Some(pn) if norm(&pu) < r => {
                        // Walk from the Cauchy point towards the Newton point to the boundary.
                        let d: Vec<f64> = pn.iter().zip(&pu).map(|(a, b)| a - b).collect();
                        let (a, b, c) = (dot(&d, &d), 2.0 * dot(&pu, &d), dot(&pu, &pu) - r * r);
                        let t = (-b + (b * b - 4.0 * a * c).max(0.0).sqrt()) / (2.0 * a);
                        pu.iter()
                            .zip(&d)
                            .map(|(p, d)| p + t.clamp(0.0, 1.0) * d)
                            .collect()
                    }
                    _ => {
                        let s = r / gg.sqrt();
                        g.iter().map(|v| -s * v).collect()
                    }
                }
            }
        };
        self.x
            .iter()
            .zip(&p)
            .zip(&self.log_bounds)
            .map(|((x, p), (lo, hi))| (x + p).clamp(*lo, *hi))
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An ill-conditioned quadratic valley in log space (condition number 1e3): the trust
    /// region reaches the minimum in a few dozen evaluations.
    #[test]
    fn minimises_an_ill_conditioned_valley() {
        let target = [2e5f64.ln(), 800f64.ln()];
        let f = |x: &[f64]| {
            let (u, v) = (x[0] - target[0], x[1] - target[1]);
            let (a, b) = (u - v, u + v);
            (
                500.0 * a * a + 0.5 * b * b,
                [1000.0 * a + b, -1000.0 * a + b],
            )
        };
        let mut o = TrustRegionBfgs::new(
            vec![1e6, 300.0],
            vec![(1e4, 1e7), (100.0, 3000.0)],
            TrustRegion::default(),
        )
        .unwrap();
        for _ in 0..40 {
            let th = o.theta();
            let x: Vec<f64> = th.iter().map(|t| t.ln()).collect();
            let (l, g) = f(&x);
            o.step(l, &[g[0] / th[0], g[1] / th[1]]);
        }
        let t = o.accepted_theta();
        assert!((t[0] / 2e5 - 1.0).abs() < 1e-3, "{t:?}");
        assert!((t[1] / 800.0 - 1.0).abs() < 1e-3, "{t:?}");
    }

    #[test]
    fn respects_bounds_and_rejects_bad_settings() {
        let mut o =
            TrustRegionBfgs::new(vec![5.0], vec![(1.0, 10.0)], TrustRegion::default()).unwrap();
        for _ in 0..30 {
            let t = o.theta()[0];
            // Minimum at 100, outside the bounds: the fit stops at the bound.
            let g = 2.0 * (t.ln() - 100f64.ln()) / t;
            o.step((t.ln() - 100f64.ln()).powi(2), &[g]);
        }
        assert!((o.accepted_theta()[0] - 10.0).abs() < 1e-9);
        let bad = TrustRegion {
            min_radius: 0.0,
            ..Default::default()
        };
        assert!(TrustRegionBfgs::new(vec![1.0], vec![(0.5, 2.0)], bad).is_err());
        assert!(TrustRegionBfgs::new(vec![1.0], vec![], TrustRegion::default()).is_err());
    }

    /// A gradient that points uphill everywhere (the reported gradient is the true one
    /// negated): every model step fails; the restarts, then the coordinate probes, still
    /// reach the minimum (before them, the fit stayed at its start: every trial was rejected).
    #[test]
    fn coordinate_probes_take_over_where_the_gradient_misleads() {
        let target = [3f64.ln(), 0.5f64.ln()];
        let mut o = TrustRegionBfgs::new(
            vec![1.0, 1.0],
            vec![(0.01, 100.0); 2],
            TrustRegion::default(),
        )
        .unwrap();
        for _ in 0..400 {
            let th = o.theta();
            let x: Vec<f64> = th.iter().map(|t| t.ln()).collect();
            let d = [x[0] - target[0], x[1] - target[1]];
            let l = d[0] * d[0] + d[1] * d[1];
            // dL/dtheta of the true loss, negated.
            o.step(l, &[-2.0 * d[0] / th[0], -2.0 * d[1] / th[1]]);
        }
        let t = o.accepted_theta();
        assert!((t[0] / 3.0 - 1.0).abs() < 2e-3, "{t:?}");
        assert!((t[1] / 0.5 - 1.0).abs() < 2e-3, "{t:?}");
        assert!(o.restarts() >= 1);
        // The state survives a checkpoint round trip and validates.
        let back: TrustRegionBfgs =
            serde_json::from_str(&serde_json::to_string(&o).unwrap()).unwrap();
        assert_eq!(back, o);
        back.validate(2).unwrap();
    }

    /// Where every model step from the start fails, no trial is evaluated twice before the
    /// fit leaves the start: the first model is a restart's, so the probes follow it (a
    /// restart there repeated its trials exactly, measured on a random plasticine drop).
    #[test]
    fn a_failing_first_model_is_not_repeated() {
        let mut o = TrustRegionBfgs::new(
            vec![1.0, 1.0],
            vec![(0.01, 100.0); 2],
            TrustRegion::default(),
        )
        .unwrap();
        let start = o.accepted_theta();
        let mut trials: Vec<Vec<f64>> = Vec::new();
        while o.accepted_theta() == start && trials.len() < 200 {
            let th = o.theta();
            let x: Vec<f64> = th.iter().map(|t| t.ln()).collect();
            let d = [x[0] - 3f64.ln(), x[1] - 0.5f64.ln()];
            trials.push(th.clone());
            o.step(
                d[0] * d[0] + d[1] * d[1],
                &[-2.0 * d[0] / th[0], -2.0 * d[1] / th[1]],
            );
        }
        assert_ne!(o.accepted_theta(), start, "the fit left its start");
        for (i, a) in trials.iter().enumerate().skip(1) {
            assert!(
                !trials[1..i].contains(a),
                "trial {i} {a:?} repeats an earlier one: {trials:?}"
            );
        }
    }

    /// On a quadratic, the finite-difference model through the coordinate and pair probes is
    /// exact: its step lands on the minimum, including a diagonal valley's.
    #[test]
    fn the_probes_model_finds_a_diagonal_valleys_minimum() {
        let target = [0.03, -0.05];
        let f = |x: &[f64]| {
            let (u, v) = (x[0] - target[0], x[1] - target[1]);
            // Narrow along (2, 1), the coordinates unequally curved.
            40.0 * (u - 2.0 * v).powi(2) + 0.5 * (u + v).powi(2)
        };
        let mut p = Pattern::new(&[1.0, -1.0], 0.1);
        for k in 0..p.round_len() - 1 {
            let d = p.offset(k, f(&[0.0, 0.0]));
            p.losses.push(f(&d));
        }
        let step = p.model_step(f(&[0.0, 0.0]));
        assert!((step[0] - target[0]).abs() < 1e-9, "{step:?}");
        assert!((step[1] - target[1]).abs() < 1e-9, "{step:?}");
    }

    #[test]
    fn a_failed_evaluation_shrinks_the_radius() {
        let mut o =
            TrustRegionBfgs::new(vec![5.0, 5.0], vec![(1.0, 10.0); 2], TrustRegion::default())
                .unwrap();
        o.step(1.0, &[0.1, 0.1]);
        let r = o.radius();
        o.step(f64::NAN, &[0.0, 0.0]);
        assert!(o.radius() < r);
        assert_eq!(o.counts(), (2, 1));
    }
}
