//! The valley search: a derivative-free stage after the gradient iterations for losses whose
//! minimum lies at the end of a long, curved valley between sharp, kinked walls.
//!
//! Where the return mapping's branches make the loss V-shaped in some parameters (a yield
//! stress, a density: a 3% error raises the loss by 5-10%) and shallow in others (`E` and
//! `nu` of a plastic body, which set only the elastic part of the motion), the floor of the
//! valley moves in the sharp parameters as the shallow ones change. A step in the shallow
//! parameters alone climbs the V's wall, a gradient step is not told where the wall is (the
//! kink), and a joint quadratic model does not describe a V: every local method stalls at the
//! first point where the valley bends (measured on the full-size plasticine demo,
//! `docs/fitting-measurements.md`). The valley search instead minimises the *profile*
//!
//! ```text
//! P(x_T) = min over x_S of f(x_T, x_S)
//! ```
//!
//! over the shallow directions `T`, with the sharp ones `S` re-centred at every point it
//! looks at. One round:
//!
//! 1. probes `x +- h e_i` for every parameter (`h` = [`ValleyConfig::probe`]) and, with
//!    [`ValleyConfig::pairs`], the four diagonal points `x +- h e_i +- h e_j` of every pair
//!    (`2 n^2` evaluations, 50 for five parameters, instead of `2 n`): the central
//!    differences estimate the gradient of `P` even across a V-shaped wall (the wall's two
//!    sides cancel), the second differences a Hessian (diagonal without pairs) whose
//!    off-diagonal entries come from the lower diagonal pair (the one along a valley, not
//!    across its wall); its eigenvectors above the largest ratio between neighbouring
//!    eigenvalues, when that ratio is at least [`ValleyConfig::sharp_gap`], are the sharp
//!    directions (a yield stress and a softening rate that compensate each other make one
//!    sharp direction across their valley and a shallow one along it; a shallow parameter's
//!    probes climb the walls too, so its curvature is only smaller, not small);
//! 2. walks along the steepest descent `d` within the shallow directions, the sharp ones
//!    re-centred at every point (a search along each sharp direction, sharpest first,
//!    [`ValleyConfig::sweeps`] sweeps of three evaluations and a V-shaped fit through them;
//!    with [`ValleyConfig::diagonals`] also along the diagonals of pairs of them),
//!    doubling the step while the loss falls and halving it when the first step rises; the
//!    re-centring's correction per unit step at the first accepted point predicts it at the
//!    next;
//! 3. accepts the lowest point seen (a probe included) when it lowers the loss.
//!
//! The search ends when a round lowers nothing or the evaluation budget
//! ([`ValleyConfig::evals`]) is spent. Every evaluation is a loss only (no gradient), and the
//! evaluations of one batch are independent (the caller may run them in parallel). The state
//! ([`ValleySearch`]) is serialisable: a fit checkpoints it after every round.

use crate::evaluator::Evaluator;
use serde::{Deserialize, Serialize};

/// Settings of the valley search (`[valley]` in a fit config). Every key is optional.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ValleyConfig {
    /// Loss evaluations (forward only) the search may spend; 0: off (the default).
    pub evals: usize,
    /// Length of the probes that estimate the gradient and curvature (log units).
    pub probe: f64,
    /// The sharp parameters are those above the largest ratio between neighbouring probed
    /// curvatures (sorted), when that ratio is at least this.
    pub sharp_gap: f64,
    /// First step along the valley (log units).
    pub step: f64,
    /// First step of a sharp parameter's re-centring (log units); each sweep halves it.
    pub recentre: f64,
    /// Re-centring sweeps over the sharp parameters at every point of the walk.
    pub sweeps: usize,
    /// Probe the pairs too (`2 n (n - 1)` more evaluations per round, 40 for five
    /// parameters), so that a valley along a diagonal of two parameters is found (its sharp
    /// direction is across the diagonal). Off by default: on the full-size plasticine
    /// (`docs/fitting-measurements.md`) it ended highest of the variants: loss 0.9968 after two rounds
    /// of 135 evaluations in all (then nothing lower), against 0.9944 after 150 without.
    pub pairs: bool,
    /// Re-centre along the diagonals `(u +- v) / sqrt 2` of every pair of sharp directions
    /// as well, in the last sweep (`s (s - 1)` more line searches of about three evaluations
    /// each for `s` sharp directions): two sharp parameters that compensate each other (a
    /// yield stress and a softening rate) have a valley along a diagonal that no step along
    /// one of them enters. Off by default: on the full-size plasticine it reached the lowest
    /// loss (0.9875 after 300 evaluations, against 0.9944 after 150 without) with the yield
    /// stress and softening closest, but a round costs about twice as many evaluations and
    /// `E` stayed far off (+40%; `docs/fitting-measurements.md`).
    pub diagonals: bool,
}

impl Default for ValleyConfig {
    fn default() -> Self {
        ValleyConfig {
            evals: 0,
            probe: 0.03,
            sharp_gap: 3.0,
            step: 0.05,
            recentre: 0.02,
            sweeps: 2,
            pairs: false,
            diagonals: false,
        }
    }
}

impl ValleyConfig {
    /// Whether the search is off (`evals == 0`).
    pub fn is_off(&self) -> bool {
        self.evals == 0
    }

    /// Refuses settings that cannot run, naming the key.
    pub fn validate(&self) -> Result<(), String> {
        let pos = |v: f64, key: &str, max: f64| {
            if v.is_finite() && v > 0.0 && v <= max {
                Ok(())
            } else {
                Err(format!("valley.{key} = {v}: must be in (0, {max}]"))
            }
        };
        pos(self.probe, "probe", 1.0)?;
        if !(self.sharp_gap.is_finite() && self.sharp_gap >= 1.0) {
            return Err(format!(
                "valley.sharp_gap = {}: must be finite and at least 1",
                self.sharp_gap
            ));
        }
        pos(self.step, "step", 2.0)?;
        pos(self.recentre, "recentre", 1.0)?;
        if self.sweeps == 0 || self.sweeps > 8 {
            return Err(format!(
                "valley.sweeps = {}: must be in [1, 8]",
                self.sweeps
            ));
        }
        if self.evals > 100_000 {
            return Err(format!(
                "valley.evals = {}: at most 100000 evaluations",
                self.evals
            ));
        }
        Ok(())
    }
}

/// What one round of the valley search did.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ValleyRound {
    /// The sharp directions (unit vectors in log space; re-centred at every point).
    pub sharp: Vec<Vec<f64>>,
    /// The probed curvatures (eigenvalues of the finite-difference Hessian), decreasing.
    pub curvatures: Vec<f64>,
    /// The walk's direction (unit length, log units; orthogonal to the sharp directions).
    pub direction: Vec<f64>,
    /// Length of the accepted step along it (log units; 0: none accepted).
    pub step: f64,
    /// Loss before the round.
    pub loss_before: f64,
    /// Loss after it.
    pub loss_after: f64,
    /// Evaluations the round spent.
    pub evals: usize,
}

/// The state of a valley search (see the module docs): the point, its loss, the evaluations
/// spent and the rounds done. Works on `log(theta)`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ValleySearch {
    /// The accepted point, `log(theta)`.
    x: Vec<f64>,
    /// Its loss (`None` before it is evaluated).
    loss: Option<f64>,
    log_bounds: Vec<(f64, f64)>,
    /// First step of the next walk (log units).
    step: f64,
    /// Evaluations spent.
    pub evals: usize,
    /// Whether a round lowered nothing (the search is over).
    pub done: bool,
    /// The rounds so far.
    pub rounds: Vec<ValleyRound>,
}

impl ValleySearch {
    /// A search from `theta` (positive, inside `bounds`) whose loss is `loss` when known.
    pub fn new(
        theta: &[f64],
        loss: Option<f64>,
        bounds: &[(f64, f64)],
        cfg: &ValleyConfig,
    ) -> Result<ValleySearch, String> {
        if theta.len() != bounds.len() || theta.is_empty() {
            return Err(format!(
                "{} parameters and {} bounds",
                theta.len(),
                bounds.len()
            ));
        }
        for (i, (&t, &(lo, hi))) in theta.iter().zip(bounds).enumerate() {
            let ok = t.is_finite() && lo.is_finite() && hi.is_finite();
            if !(ok && lo > 0.0 && lo <= t && t <= hi) {
                return Err(format!(
                    "parameter {i}: {t} outside its bounds [{lo}, {hi}] or not positive"
                ));
            }
        }
        Ok(ValleySearch {
            x: theta.iter().map(|t| t.ln()).collect(),
            loss: loss.filter(|l| l.is_finite()),
            log_bounds: bounds.iter().map(|(l, u)| (l.ln(), u.ln())).collect(),
            step: cfg.step,
            evals: 0,
            done: false,
            rounds: Vec::new(),
        })
    }

    /// The accepted point (`theta`, not its log).
    pub fn theta(&self) -> Vec<f64> {
        self.x.iter().map(|v| v.exp()).collect()
    }

    /// The accepted point's loss, once evaluated.
    pub fn loss(&self) -> Option<f64> {
        self.loss
    }

    /// Checks a deserialised state against a fit of `n` parameters.
    pub fn validate(&self, n: usize) -> Result<(), String> {
        if self.x.len() != n || self.log_bounds.len() != n {
            return Err(format!(
                "the valley search holds {} parameters, the fit has {n}",
                self.x.len()
            ));
        }
        let inside = self
            .x
            .iter()
            .zip(&self.log_bounds)
            .all(|(v, (lo, hi))| v.is_finite() && lo <= v && v <= hi);
        let step_ok = self.step.is_finite() && self.step > 0.0;
        if !inside || !step_ok || self.loss.is_some_and(|l| l.is_nan()) {
            return Err("the valley search's point, loss or step is not valid".into());
        }
        Ok(())
    }

    fn clamp(&self, mut p: Vec<f64>) -> Vec<f64> {
        for (v, (lo, hi)) in p.iter_mut().zip(&self.log_bounds) {
            *v = v.clamp(*lo, *hi);
        }
        p
    }

    /// Evaluations of a round's probes.
    fn probe_count(&self, pairs: bool) -> usize {
        let n = self.x.len();
        let pair_probes = if Self::with_pairs(n, pairs) {
            2 * n * (n - 1)
        } else {
            0
        };
        2 * n + pair_probes
    }

    /// Whether a round of `n` parameters probes the pairs.
    fn with_pairs(n: usize, pairs: bool) -> bool {
        pairs && n <= MAX_PAIR_PARAMS
    }

    /// The probe points around `x` at scale `h`: `x +- h e_i` per parameter, then with
    /// `pairs` and at most [`MAX_PAIR_PARAMS`] parameters the four diagonal points `x +- h
    /// e_i +- h e_j` of every pair.
    fn probes(&self, h: f64, pairs: bool) -> Vec<Vec<f64>> {
        let n = self.x.len();
        let mut pts = Vec::new();
        let at = |moves: &[(usize, f64)]| {
            let mut p = self.x.clone();
            for &(i, s) in moves {
                p[i] += s * h;
            }
            self.clamp(p)
        };
        for i in 0..n {
            pts.push(at(&[(i, 1.0)]));
            pts.push(at(&[(i, -1.0)]));
        }
        if Self::with_pairs(n, pairs) {
            for i in 0..n {
                for j in i + 1..n {
                    for (a, b) in [(1.0, 1.0), (-1.0, -1.0), (1.0, -1.0), (-1.0, 1.0)] {
                        pts.push(at(&[(i, a), (j, b)]));
                    }
                }
            }
        }
        pts
    }

    /// Central-difference gradient and Hessian from the [`ValleySearch::probes`] losses
    /// `fs` around `x` (loss `f0`). A coordinate whose probe failed is a wall: its Hessian
    /// row is zero but for a diagonal above every other. An off-diagonal entry uses the pair
    /// of diagonal points that is lower (`x +- (e_i + e_j)` or `x +- (e_i - e_j)`): exact on a
    /// quadratic either way, and on a V-shaped valley along a diagonal it is the one that
    /// sees the valley (the other pair straddles the wall). Clamped probes (at a bound) give
    /// one-sided or zero entries.
    fn finite_differences(
        &self,
        h: f64,
        f0: f64,
        pts: &[Vec<f64>],
        fs: &[f64],
    ) -> (Vec<f64>, Vec<f64>) {
        let n = self.x.len();
        let mut g = vec![0.0; n];
        let mut hess = vec![0.0; n * n];
        let mut wall = vec![false; n];
        // A probe's step is `h` up to round-off (`(x + h) - x` is not `h` exactly), less where
        // the bound clamped it.
        let full = |k: usize, i: usize| {
            ((pts[k][i] - self.x[i]).abs() - h).abs() <= 1e-9 * (1.0 + self.x[i].abs())
        };
        for i in 0..n {
            let (fp, fm) = (fs[2 * i], fs[2 * i + 1]);
            if !(fp.is_finite() && fm.is_finite()) {
                wall[i] = true;
                continue;
            }
            let hp = pts[2 * i][i] - self.x[i];
            let hm = self.x[i] - pts[2 * i + 1][i];
            if hp > 0.0 && hm > 0.0 {
                g[i] = (fp - fm) / (hp + hm);
                hess[i * n + i] =
                    2.0 * (fp * hm + fm * hp - f0 * (hp + hm)) / (hp * hm * (hp + hm));
            } else if hp > 0.0 {
                g[i] = (fp - f0) / hp;
            } else if hm > 0.0 {
                g[i] = (f0 - fm) / hm;
            }
        }
        if pts.len() > 2 * n {
            let mut k = 2 * n;
            for i in 0..n {
                for j in i + 1..n {
                    let q = &fs[k..k + 4];
                    let unclamped = (k..k + 4).all(|m| full(m, i) && full(m, j))
                        && full(2 * i, i)
                        && full(2 * i + 1, i)
                        && full(2 * j, j)
                        && full(2 * j + 1, j);
                    k += 4;
                    if wall[i] || wall[j] || !unclamped || q.iter().any(|v| !v.is_finite()) {
                        continue;
                    }
                    let ci = fs[2 * i] + fs[2 * i + 1];
                    let cj = fs[2 * j] + fs[2 * j + 1];
                    let (same, cross) = (q[0] + q[1], q[2] + q[3]);
                    let hij = if same <= cross {
                        (same - ci - cj + 2.0 * f0) / (2.0 * h * h)
                    } else {
                        -(cross - ci - cj + 2.0 * f0) / (2.0 * h * h)
                    };
                    hess[i * n + j] = hij;
                    hess[j * n + i] = hij;
                }
            }
        }
        let top = hess
            .iter()
            .step_by(n + 1)
            .fold(0.0f64, |m, v| m.max(v.abs()))
            .max(1.0 / (h * h));
        for i in (0..n).filter(|&i| wall[i]) {
            for j in 0..n {
                hess[i * n + j] = 0.0;
                hess[j * n + i] = 0.0;
            }
            hess[i * n + i] = 1e3 * top;
        }
        (g, hess)
    }

    /// One round (see the module docs), spending at most `budget` evaluations (a round needs
    /// its probes, `2 n + 2 n (n - 1)` evaluations with at most [`MAX_PAIR_PARAMS`]
    /// parameters, and two more; with fewer it ends the search). Returns the round's record, `None`
    /// when the search is over.
    pub fn round(
        &mut self,
        cfg: &ValleyConfig,
        budget: usize,
        eval: &dyn Evaluator,
    ) -> Option<ValleyRound> {
        let n = self.x.len();
        if self.done || budget < self.probe_count(cfg.pairs) + 2 {
            self.done = true;
            return None;
        }
        let mut ev = Counter {
            eval,
            spent: 0,
            budget,
        };
        let f0 = match self.loss {
            Some(l) => l,
            None => {
                let l = ev.batch(std::slice::from_ref(&self.x))[0];
                if !l.is_finite() {
                    self.done = true;
                    self.evals += ev.spent;
                    return None;
                }
                self.loss = Some(l);
                l
            }
        };
        // 1. Probes: gradient and curvature.
        let h = cfg.probe;
        let probes = self.probes(h, cfg.pairs);
        let fs = ev.batch(&probes);
        let mut best = (f0, self.x.clone());
        for (p, &f) in probes.iter().zip(&fs) {
            if f < best.0 {
                best = (f, p.clone());
            }
        }
        let (g, hess) = self.finite_differences(h, f0, &probes, &fs);
        let (values, vectors) = jacobi_eigen(&hess, n);
        let sharp: Vec<Vec<f64>> = sharp_set(&values, cfg.sharp_gap)
            .into_iter()
            .map(|k| vectors[k].clone())
            .collect();
        // The steepest descent within the shallow subspace.
        let mut d: Vec<f64> = g.iter().map(|v| -v).collect();
        for u in &sharp {
            let a = dot(&d, u);
            d.iter_mut().zip(u).for_each(|(v, w)| *v -= a * w);
        }
        let norm = dot(&d, &d).sqrt();
        let mut accepted_step = 0.0;
        if norm > 1e-12 * dot(&g, &g).sqrt() && norm.is_finite() {
            d.iter_mut().for_each(|v| *v /= norm);
            // 2. The walk along d, the sharp directions re-centred at every point.
            let mut s = self.step;
            let min_step = cfg.step / 8.0;
            let mut improved = false;
            // The re-centring's correction per unit step, from the first accepted point.
            let mut drift: Option<Vec<f64>> = None;
            while ev.left() > 0 {
                let p: Vec<f64> = (0..n)
                    .map(|i| self.x[i] + s * (d[i] + drift.as_ref().map_or(0.0, |dr| dr[i])))
                    .collect();
                let p = self.clamp(p);
                if p == self.x {
                    break;
                }
                let (f, q) = recentre(p, &sharp, cfg, &mut ev, self);
                if f < best.0 {
                    if drift.is_none() {
                        drift = Some((0..n).map(|i| (q[i] - self.x[i]) / s - d[i]).collect());
                    }
                    best = (f, q);
                    accepted_step = s;
                    improved = true;
                    s *= 2.0;
                } else if improved {
                    break;
                } else {
                    s /= 2.0;
                    if s < min_step {
                        break;
                    }
                }
            }
        }
        // 3. The lowest point seen.
        let record = ValleyRound {
            sharp,
            curvatures: values,
            direction: d,
            step: accepted_step,
            loss_before: f0,
            loss_after: best.0.min(f0),
            evals: ev.spent,
        };
        self.evals += ev.spent;
        if best.0 < f0 {
            self.x = best.1;
            self.loss = Some(best.0);
            if accepted_step > 0.0 {
                self.step = accepted_step.max(cfg.step / 8.0);
            }
        } else {
            self.done = true;
        }
        self.rounds.push(record.clone());
        Some(record)
    }
}

/// Largest number of parameters for which a round probes the pairs (`2 n (n - 1)` extra
/// evaluations: 40 at 5, 112 at 8); above it the Hessian is diagonal.
pub const MAX_PAIR_PARAMS: usize = 8;

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

/// Eigenvalues (decreasing) and unit eigenvectors of the symmetric `n x n` matrix `a`
/// (row-major), by cyclic Jacobi rotations (`n` is a handful of parameters).
fn jacobi_eigen(a: &[f64], n: usize) -> (Vec<f64>, Vec<Vec<f64>>) {
    let mut m = a.to_vec();
    let mut v = vec![0.0; n * n];
    for i in 0..n {
        v[i * n + i] = 1.0;
    }
    for _sweep in 0..64 {
        let off: f64 = (0..n)
            .flat_map(|i| (0..n).filter(move |&j| j != i).map(move |j| (i, j)))
            .map(|(i, j)| m[i * n + j] * m[i * n + j])
            .sum();
        let scale: f64 = m.iter().map(|x| x * x).sum();
        if off <= 1e-30 * scale || !off.is_finite() {
            break;
        }
        for p in 0..n {
            for q in p + 1..n {
                let apq = m[p * n + q];
                if apq == 0.0 {
                    continue;
                }
                let theta = (m[q * n + q] - m[p * n + p]) / (2.0 * apq);
                let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
                let t = if theta == 0.0 { 1.0 } else { t };
                let c = 1.0 / (t * t + 1.0).sqrt();
                let s = t * c;
                for k in 0..n {
                    let (mkp, mkq) = (m[k * n + p], m[k * n + q]);
                    m[k * n + p] = c * mkp - s * mkq;
                    m[k * n + q] = s * mkp + c * mkq;
                }
                for k in 0..n {
                    let (mpk, mqk) = (m[p * n + k], m[q * n + k]);
                    m[p * n + k] = c * mpk - s * mqk;
                    m[q * n + k] = s * mpk + c * mqk;
                }
                for k in 0..n {
                    let (vkp, vkq) = (v[k * n + p], v[k * n + q]);
                    v[k * n + p] = c * vkp - s * vkq;
                    v[k * n + q] = s * vkp + c * vkq;
                }
            }
        }
    }
    let mut order: Vec<usize> = (0..n).collect();
    order.sort_by(|&a, &b| m[b * n + b].total_cmp(&m[a * n + a]));
    let values = order.iter().map(|&k| m[k * n + k]).collect();
    let vectors = order
        .iter()
        .map(|&k| (0..n).map(|i| v[i * n + k]).collect())
        .collect();
    (values, vectors)
}

/// The sharp ones among directions with probed curvatures `c` (the Hessian's eigenvalues):
/// those marked `+inf`, and of the positive finite ones, sorted, those above the largest
/// ratio between neighbours when it is at least `gap` (a lone positive curvature among flat
/// or concave ones is sharp). Never every direction. Returns indices into `c`.
fn sharp_set(c: &[f64], gap: f64) -> Vec<usize> {
    let mut pos: Vec<usize> = (0..c.len())
        .filter(|&i| c[i].is_finite() && c[i] > 0.0)
        .collect();
    pos.sort_by(|&a, &b| c[b].total_cmp(&c[a]).then(a.cmp(&b)));
    let mut sharp: Vec<usize> = (0..c.len()).filter(|&i| c[i] == f64::INFINITY).collect();
    let mut split = 0;
    if pos.len() == 1 && sharp.len() + 1 < c.len() {
        split = 1;
    }
    let mut best = gap;
    for j in 1..pos.len() {
        let r = c[pos[j - 1]] / c[pos[j]];
        if r >= best {
            best = r;
            split = j;
        }
    }
    sharp.extend_from_slice(&pos[..split]);
    if sharp.len() >= c.len() {
        sharp.clear();
    }
    sharp.sort_unstable();
    sharp
}

/// Evaluations within a budget.
struct Counter<'e> {
    eval: &'e dyn Evaluator,
    spent: usize,
    budget: usize,
}

impl Counter<'_> {
    fn left(&self) -> usize {
        self.budget.saturating_sub(self.spent)
    }

    /// Evaluates `pts` (all of them: the caller checks [`Counter::left`]).
    fn batch(&mut self, pts: &[Vec<f64>]) -> Vec<f64> {
        self.spent += pts.len();
        let mut out = self.eval.values(pts);
        out.resize(pts.len(), f64::INFINITY);
        out.iter_mut()
            .for_each(|v| *v = if v.is_finite() { *v } else { f64::INFINITY });
        out
    }
}

/// Re-centres the sharp directions of `p` (see [`ValleyConfig::sweeps`]): per sweep and
/// sharp direction, the two neighbours at `+-delta` and the minimum of the V through the
/// three points; where a neighbour is lower, steps on that way (at most four steps). With
/// [`ValleyConfig::diagonals`] the last sweep also searches the diagonals `(u +- v) / sqrt 2`
/// of every pair of sharp directions. Returns the lowest point's loss and the point.
fn recentre(
    p: Vec<f64>,
    sharp: &[Vec<f64>],
    cfg: &ValleyConfig,
    ev: &mut Counter<'_>,
    search: &ValleySearch,
) -> (f64, Vec<f64>) {
    if ev.left() == 0 {
        return (f64::INFINITY, p);
    }
    let f = ev.batch(std::slice::from_ref(&p))[0];
    let mut best = (f, p);
    if !f.is_finite() {
        return best;
    }
    let mut diagonals = Vec::new();
    if cfg.diagonals {
        for a in 0..sharp.len() {
            for b in a + 1..sharp.len() {
                for sign in [1.0, -1.0] {
                    let d: Vec<f64> = sharp[a]
                        .iter()
                        .zip(&sharp[b])
                        .map(|(x, y)| (x + sign * y) * std::f64::consts::FRAC_1_SQRT_2)
                        .collect();
                    diagonals.push(d);
                }
            }
        }
    }
    for sweep in 0..cfg.sweeps {
        let delta = cfg.recentre / f64::from(1u32 << sweep.min(30));
        let last = sweep + 1 == cfg.sweeps;
        let extra = if last { &diagonals[..] } else { &[] };
        for u in sharp.iter().chain(extra) {
            if ev.left() < 2 {
                return best;
            }
            line_search(u, delta, &mut best, ev, search);
        }
    }
    best
}

/// One direction `u` of [`recentre`] from `best` (its loss and point), updated in place.
fn line_search(
    u: &[f64],
    delta: f64,
    best: &mut (f64, Vec<f64>),
    ev: &mut Counter<'_>,
    search: &ValleySearch,
) {
    let along = |from: &[f64], t: f64| {
        let q: Vec<f64> = from.iter().zip(u).map(|(v, w)| v + t * w).collect();
        search.clamp(q)
    };
    let (qp, qm) = (along(&best.1, delta), along(&best.1, -delta));
    let fs = ev.batch(&[qp.clone(), qm.clone()]);
    let (fp, fm) = (fs[0], fs[1]);
    let f0 = best.0;
    if fp < f0 || fm < f0 {
        // Downhill: walk that way while it keeps falling.
        let s = if fp < fm { 1.0 } else { -1.0 };
        let (mut f, mut q) = if fp < fm { (fp, qp) } else { (fm, qm) };
        for _ in 0..4 {
            if ev.left() == 0 {
                break;
            }
            let next = along(&q, s * delta);
            if next == q {
                break;
            }
            let fnext = ev.batch(std::slice::from_ref(&next))[0];
            if fnext < f {
                (f, q) = (fnext, next);
            } else {
                break;
            }
        }
        *best = (f, q);
    } else if fp.is_finite() && fm.is_finite() && ev.left() > 0 {
        // The minimum of the V through the three points.
        let b = (fp.max(fm) - f0) / delta;
        if b > 0.0 {
            let m = if fm >= fp {
                (delta - (fp - f0) / b) / 2.0
            } else {
                -(delta - (fm - f0) / b) / 2.0
            };
            if m.abs() > delta / 8.0 {
                let q = along(&best.1, m);
                let fq = ev.batch(std::slice::from_ref(&q))[0];
                if fq < f0 {
                    *best = (fq, q);
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sharp_parameters_are_above_the_largest_curvature_gap() {
        // The plasticine's pattern: two V-shaped walls, three shallow directions.
        assert_eq!(
            sharp_set(&[11.0, -2.0, 165.0, 30.0, 163.0], 3.0),
            vec![2, 4]
        );
        // No gap of 3: nothing is re-centred.
        assert!(sharp_set(&[1.0, 2.0, 4.0], 3.0).is_empty());
        // A lone positive curvature; a failed probe; never all of them.
        assert_eq!(sharp_set(&[-1.0, 5.0, 0.0], 3.0), vec![1]);
        assert_eq!(sharp_set(&[f64::INFINITY, 1.0], 3.0), vec![0]);
        assert!(sharp_set(&[f64::INFINITY, f64::INFINITY], 3.0).is_empty());
        assert!(sharp_set(&[5.0], 3.0).is_empty());
    }

    /// A curved valley with a V-shaped wall: `a` is shallow, `y` sharp, and the floor of the
    /// V in `y` moves with `a` (`y* = 0.3 a`), like a yield stress that follows `E`.
    fn v_valley(x: &[f64]) -> f64 {
        let (a, y) = (x[0], x[1]);
        0.05 * (a - 0.5).powi(2) + 3.0 * (y - 0.3 * a).abs()
    }

    fn search_on(
        f: &(dyn Fn(&[f64]) -> f64 + Sync),
        x0: &[f64],
        cfg: &ValleyConfig,
    ) -> ValleySearch {
        let bounds: Vec<(f64, f64)> = x0.iter().map(|_| ((-3f64).exp(), 3f64.exp())).collect();
        let theta: Vec<f64> = x0.iter().map(|v| v.exp()).collect();
        let mut s = ValleySearch::new(&theta, None, &bounds, cfg).unwrap();
        let eval = crate::FnEvaluator::new(f);
        while s.evals < cfg.evals {
            if s.round(cfg, cfg.evals - s.evals, &eval).is_none() {
                break;
            }
        }
        s
    }

    #[test]
    fn walks_a_curved_valley_with_a_kinked_wall() {
        let cfg = ValleyConfig {
            evals: 400,
            ..Default::default()
        };
        // Start on the valley's floor, far from the minimum along it.
        let x0 = [-0.5, -0.15];
        let s = search_on(&v_valley, &x0, &cfg);
        let x: Vec<f64> = s.theta().iter().map(|t| t.ln()).collect();
        assert!(s.evals <= cfg.evals);
        // One sharp direction: across the wall, mostly the second coordinate.
        assert_eq!(s.rounds[0].sharp.len(), 1);
        assert!(
            s.rounds[0].sharp[0][1].abs() > 0.9,
            "{:?}",
            s.rounds[0].sharp
        );
        assert!((x[0] - 0.5).abs() < 0.1, "a = {} (truth 0.5)", x[0]);
        assert!((x[1] - 0.15).abs() < 0.03, "y = {} (truth 0.15)", x[1]);
        // Steps along the shallow coordinate alone climb the wall: a coordinate step of
        // the same length from the start rises.
        let f0 = v_valley(&x0);
        assert!(v_valley(&[x0[0] + cfg.step, x0[1]]) > f0);
        assert!(s.loss().unwrap() < 0.1 * f0);
    }

    /// Two parameters that compensate each other (a yield stress and a softening rate): a
    /// V-shaped valley along the diagonal, whose floor falls towards `(0.5, 0.5)`; a third
    /// parameter is a plain bowl. Every coordinate step from the start rises; the search
    /// finds the diagonal from the pair probes and walks it.
    #[test]
    fn walks_a_diagonal_valley_that_no_coordinate_step_enters() {
        let f = |x: &[f64]| {
            3.0 * (x[0] - x[1]).abs() + 0.05 * (x[0] + x[1] - 1.0).powi(2) + (x[2] - 0.2).powi(2)
        };
        let cfg = ValleyConfig {
            evals: 600,
            pairs: true,
            ..Default::default()
        };
        let x0 = [0.0, 0.0, 0.0];
        for i in 0..2 {
            for s in [-1.0, 1.0] {
                let mut p = x0;
                p[i] += s * cfg.step;
                assert!(f(&p) > f(&x0));
            }
        }
        let s = search_on(&f, &x0, &cfg);
        let x: Vec<f64> = s.theta().iter().map(|t| t.ln()).collect();
        let u = &s.rounds[0].sharp[0];
        assert!(
            (u[0] + u[1]).abs() < 0.2 && u[0].abs() > 0.6,
            "sharp direction {u:?}"
        );
        assert!(
            (x[0] - 0.5).abs() < 0.05 && (x[1] - 0.5).abs() < 0.05 && (x[2] - 0.2).abs() < 0.05,
            "{x:?} after {} evaluations",
            s.evals
        );
    }

    /// Two sharp parameters that compensate each other (`y = s` costs nothing on the first
    /// wall) and whose common value follows a shallow one (`y + s = 0.4 a` on the second):
    /// re-centring each alone climbs the first wall, so only the diagonal re-centring lets
    /// the walk in `a` go on.
    #[test]
    fn diagonal_recentring_follows_two_compensating_sharp_parameters() {
        let f = |x: &[f64]| {
            let (a, y, s) = (x[0], x[1], x[2]);
            0.05 * (a - 0.5).powi(2) + 3.0 * (y - s).abs() + 2.0 * (y + s - 0.4 * a).abs()
        };
        let x0 = [-0.5, -0.1, -0.1];
        let base = ValleyConfig {
            evals: 800,
            ..Default::default()
        };
        let off = search_on(&f, &x0, &base);
        let on = search_on(
            &f,
            &x0,
            &ValleyConfig {
                diagonals: true,
                ..base
            },
        );
        let a = |s: &ValleySearch| s.theta()[0].ln();
        assert_eq!(on.rounds[0].sharp.len(), 2, "{:?}", on.rounds[0]);
        assert!((a(&on) - 0.5).abs() < 0.1, "with diagonals: a = {}", a(&on));
        assert!(a(&off) < 0.0, "without: a = {}", a(&off));
    }

    /// The pair probes' off-diagonal entries survive round-off away from 0 (a probe's step
    /// `(x + h) - x` is not `h` exactly at `x = ln 3e5`): the Hessian of a quadratic with a
    /// coupling is recovered there.
    #[test]
    fn pair_probes_give_the_coupling_away_from_the_origin() {
        let c = [12.61, -1.54, 8.25];
        let f = |x: &[f64]| {
            let d: Vec<f64> = x.iter().zip(&c).map(|(a, b)| a - b).collect();
            d[0] * d[0] + 2.0 * d[1] * d[1] + d[2] * d[2] + 1.5 * d[0] * d[1]
        };
        let cfg = ValleyConfig {
            evals: 100,
            pairs: true,
            ..Default::default()
        };
        let x0 = [12.7, -1.5, 8.2];
        let bounds: Vec<(f64, f64)> = x0
            .iter()
            .map(|v| ((v - 3.0f64).exp(), (v + 3.0f64).exp()))
            .collect();
        let theta: Vec<f64> = x0.iter().map(|v| v.exp()).collect();
        let s = ValleySearch::new(&theta, None, &bounds, &cfg).unwrap();
        let pts = s.probes(cfg.probe, true);
        let fs: Vec<f64> = pts.iter().map(|p| f(p)).collect();
        let (_, hess) = s.finite_differences(cfg.probe, f(&s.x), &pts, &fs);
        let want = [2.0, 1.5, 0.0, 1.5, 4.0, 0.0, 0.0, 0.0, 2.0];
        for (k, (a, b)) in hess.iter().zip(want).enumerate() {
            assert!((a - b).abs() < 1e-4, "entry {k}: {a} vs {b} ({hess:?})");
        }
    }

    #[test]
    fn jacobi_eigen_decomposes_a_symmetric_matrix() {
        let a = [4.0, 1.0, 0.5, 1.0, 3.0, -0.2, 0.5, -0.2, 1.0];
        let (vals, vecs) = jacobi_eigen(&a, 3);
        assert!(vals[0] >= vals[1] && vals[1] >= vals[2]);
        for (l, v) in vals.iter().zip(&vecs) {
            assert!((dot(v, v) - 1.0).abs() < 1e-12);
            for i in 0..3 {
                let av: f64 = (0..3).map(|j| a[i * 3 + j] * v[j]).sum();
                assert!((av - l * v[i]).abs() < 1e-10);
            }
        }
        assert!((vals.iter().sum::<f64>() - 8.0).abs() < 1e-12);
    }

    #[test]
    fn stops_at_a_minimum_and_respects_the_budget() {
        let cfg = ValleyConfig {
            evals: 60,
            ..Default::default()
        };
        let q = |x: &[f64]| x.iter().map(|v| v * v).sum::<f64>();
        let s = search_on(&q, &[0.0, 0.0, 0.0], &cfg);
        assert!(s.done);
        assert_eq!(s.theta(), vec![1.0; 3]);
        let s = search_on(
            &v_valley,
            &[-0.5, -0.15],
            &ValleyConfig { evals: 15, ..cfg },
        );
        assert!(s.evals <= 15, "{} evaluations", s.evals);
    }

    #[test]
    fn failed_points_are_walls_not_minima() {
        let cfg = ValleyConfig {
            evals: 200,
            ..Default::default()
        };
        // Everything above y = 0.2 fails (a diverging simulation).
        let f = |x: &[f64]| {
            if x[1] > 0.2 {
                f64::NAN
            } else {
                v_valley(x)
            }
        };
        let s = search_on(&f, &[-0.5, -0.15], &cfg);
        assert!(s.loss().unwrap().is_finite());
        assert!(s.loss().unwrap() < v_valley(&[-0.5, -0.15]));
    }

    #[test]
    fn refuses_points_outside_their_bounds_and_bad_settings() {
        let cfg = ValleyConfig::default();
        assert!(ValleySearch::new(&[5.0], None, &[(1.0, 2.0)], &cfg).is_err());
        assert!(ValleySearch::new(&[1.5], None, &[(1.0, 2.0), (1.0, 2.0)], &cfg).is_err());
        assert!(ValleyConfig { sweeps: 0, ..cfg }.validate().is_err());
        assert!(ValleyConfig {
            probe: f64::NAN,
            ..cfg
        }
        .validate()
        .is_err());
        assert!(ValleyConfig {
            sharp_gap: 0.5,
            ..cfg
        }
        .validate()
        .is_err());
        assert!(cfg.validate().is_ok());
    }
}
