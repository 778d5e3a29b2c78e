//! Loss profiles around the true parameters and the identifiability verdicts built on them.
//!
//! # 1-D profiles
//! For every free parameter, the loss over the whole video at `theta_k = truth_k x (1 + o)`
//! for each offset `o`, every other parameter at its true value. A least-squares parabola
//! in `u = ln(theta / truth)` over the points within +-16% gives the *conditional rise*
//! `c ln(1.1)^2`: how much a 10% error raises the loss when everything else is right.
//!
//! # 2-D profiles
//! For the pairs that may trade off (`E` vs yield stress, friction angle vs density ...), the
//! loss on a grid of both offsets; a least-squares quadratic `a + g.u + u^T H u / 2` gives the
//! log-space Hessian `H` and the correlation `rho = H_ab / sqrt(H_aa H_bb)`. When the other
//! parameter of the pair is free to compensate, a 10% error in `a` only raises the loss by
//! `(1 - rho^2)` times its conditional rise (the *marginal rise*).
//!
//! # Verdicts
//! A parameter is **identifiable** when
//! 1. the 1-D profile has its minimum at the truth and rises on both sides, and
//! 2. its marginal rise (the conditional one when no pair contains it) is at least
//!    [`MIN_RELATIVE_SENSITIVITY`] of the largest conditional rise among the free
//!    parameters.
//!
//! The threshold is relative because the absolute scale of the loss depends on the scene:
//! when the best-determined parameter is recovered to about 1%, one with 5% of its curvature
//! is recovered to about `1% / sqrt(0.05) = 4.5%`, inside every target tolerance; below that
//! the fit's number is not a measurement. A pair with `|rho|` above [`TRADE_OFF_RHO`] is
//! reported as a trade-off: the combination along the stiff direction of `H` (for `E` and
//! density: `E/density`) gets its own verdict.

use crate::video_fit::params::{get, set, ParamSpace};
use crate::video_fit::{FitConfig, FitError, Objective, VideoProblem};
use r4d_mpm::PartParams;
use r4d_optim::ParamKind;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// Share of the largest conditional rise a parameter's marginal rise needs to be called
/// identifiable.
pub const MIN_RELATIVE_SENSITIVITY: f64 = 0.05;

/// Correlation above which a 2-D profile is reported as a trade-off.
pub const TRADE_OFF_RHO: f64 = 0.95;

/// A 1-D loss profile around the truth.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Profile {
    /// Parameter name (e.g. `part1.density`).
    pub name: String,
    /// Factors applied to the true value (1 included).
    pub factors: Vec<f64>,
    /// Loss at each factor.
    pub losses: Vec<f64>,
    /// Loss rise of a 10% error, everything else at the truth (parabola in log space).
    pub rise_10pct: f64,
    /// The profile's minimum is at the truth and the loss rises on both sides.
    pub min_at_truth: bool,
    /// Marginal rise (see the module docs) relative to the largest conditional rise.
    pub relative_sensitivity: f64,
    /// The verdict (see the module docs).
    pub identifiable: bool,
}

/// A 2-D loss profile of two parameters of one part.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Profile2d {
    /// First parameter (`part0.E`).
    pub a: String,
    /// Second parameter (`part0.yield_stress`).
    pub b: String,
    /// Factors of `a` (rows).
    pub factors_a: Vec<f64>,
    /// Factors of `b` (columns).
    pub factors_b: Vec<f64>,
    /// Loss at `[i_a][i_b]`.
    pub losses: Vec<Vec<f64>>,
    /// Log-space Hessian of the fitted quadratic `[[H_aa, H_ab], [H_ab, H_bb]]`.
    pub hessian: [[f64; 2]; 2],
    /// `H_ab / sqrt(H_aa H_bb)` (0 when the quadratic is not convex).
    pub correlation: f64,
    /// The combination `a^p b^q` along the stiff direction of `H` (unit `(p, q)`, first
    /// nonzero component positive): what the video determines best.
    pub stiff_exponents: [f64; 2],
    /// `|rho|` above [`TRADE_OFF_RHO`].
    pub trade_off: bool,
}

/// The verdict on one free parameter or determined combination.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Verdict {
    /// Name (`part0.yield_stress`, `part0.E/density`).
    pub name: String,
    /// The video determines it (see the module docs).
    pub identifiable: bool,
    /// Marginal rise relative to the largest conditional rise.
    pub relative_sensitivity: f64,
    /// Why, in words.
    pub reason: String,
}

fn space(cfg: &FitConfig, truth: &[PartParams]) -> Result<ParamSpace, FitError> {
    let free = cfg.free_kinds(truth)?;
    let ids: Vec<u32> = (0..truth.len() as u32).collect();
    Ok(ParamSpace::new(cfg.granularity, &free, &ids, |p, k| {
        cfg.bounds(p, k)
    }))
}

fn scaled(truth: &[PartParams], changes: &[(usize, ParamKind, f64)]) -> Vec<PartParams> {
    let mut p = truth.to_vec();
    for &(s, k, f) in changes {
        set(&mut p[s], k, get(&truth[s], k) * f);
    }
    p
}

/// Loss over the whole video at each parameter set (in parallel).
fn losses(obj: &Objective, sets: Vec<Vec<PartParams>>) -> Result<Vec<f64>, FitError> {
    sets.into_par_iter()
        .map(|p| Ok(obj.value(&p)?.total))
        .collect()
}

fn factors(offsets: &[f64]) -> Vec<f64> {
    let mut f: Vec<f64> = offsets.iter().map(|o| 1.0 + o).collect();
    f.push(1.0);
    f.sort_by(f64::total_cmp);
    f.dedup();
    f
}

/// Solves the normal equations of a small least-squares problem (rows `x`, targets `y`);
/// `None` when singular.
fn least_squares(x: &[Vec<f64>], y: &[f64]) -> Option<Vec<f64>> {
    let n = x.first()?.len();
    let mut a = vec![vec![0.0; n + 1]; n];
    for (row, &t) in x.iter().zip(y) {
        for i in 0..n {
            for j in 0..n {
                a[i][j] += row[i] * row[j];
            }
            a[i][n] += row[i] * t;
        }
    }
    // Gaussian elimination with partial pivoting.
    for c in 0..n {
        let p = (c..n).max_by(|&i, &j| a[i][c].abs().total_cmp(&a[j][c].abs()))?;
        if a[p][c].abs() < 1e-300 {
            return None;
        }
        a.swap(c, p);
        for r in 0..n {
            if r != c {
                let f = a[r][c] / a[c][c];
                for k in c..=n {
                    a[r][k] -= f * a[c][k];
                }
            }
        }
    }
    Some((0..n).map(|i| a[i][n] / a[i][i]).collect())
}

/// Rise of a 10% error from a 1-D profile: `c ln(1.1)^2` of the parabola `a + b u + c u^2`
/// over the points with `|u| <= ln(1.16)`.
fn rise_10pct(factors: &[f64], losses: &[f64]) -> f64 {
    let (x, y): (Vec<Vec<f64>>, Vec<f64>) = factors
        .iter()
        .zip(losses)
        .map(|(f, l)| (f.ln(), *l))
        .filter(|(u, _)| u.abs() <= 1.16f64.ln())
        .map(|(u, l)| (vec![1.0, u, u * u], l))
        .unzip();
    if x.len() < 3 {
        return 0.0;
    }
    least_squares(&x, &y).map_or(0.0, |c| c[2].max(0.0) * 1.1f64.ln().powi(2))
}

/// Loss profiles of every free parameter around `truth` (one forward run per point).
pub fn profiles(
    problem: &VideoProblem,
    cfg: &FitConfig,
    truth: &[PartParams],
    offsets: &[f64],
) -> Result<Vec<Profile>, FitError> {
    let obj = Objective::new(problem, cfg.frames, &cfg.loss, false)?;
    let space = space(cfg, truth)?;
    let factors = factors(offsets);
    let mut sets = vec![truth.to_vec()];
    for e in &space.entries {
        let s = e.slot.expect("part-level profile");
        for &f in factors.iter().filter(|&&f| f != 1.0) {
            sets.push(scaled(truth, &[(s, e.kind, f)]));
        }
    }
    let all = losses(&obj, sets)?;
    let base = all[0];
    let per = factors.len() - 1;
    let one = factors.iter().position(|&f| f == 1.0).expect("truth point");
    let mut out = Vec::new();
    for (i, name) in space.names().into_iter().enumerate() {
        let mut l = all[1 + i * per..1 + (i + 1) * per].to_vec();
        l.insert(one, base);
        let lo = if one > 0 { l[one - 1] - l[one] } else { 0.0 };
        let hi = l.get(one + 1).map_or(0.0, |v| v - l[one]);
        out.push(Profile {
            name,
            rise_10pct: rise_10pct(&factors, &l),
            min_at_truth: l.iter().all(|&v| v >= l[one]) && lo > 0.0 && hi > 0.0,
            factors: factors.clone(),
            losses: l,
            relative_sensitivity: 0.0,
            identifiable: false,
        });
    }
    Ok(out)
}

/// 2-D profiles of `pairs` (`(part, a, b)`) around `truth` on the grid `offsets x offsets`.
pub fn profiles_2d(
    problem: &VideoProblem,
    cfg: &FitConfig,
    truth: &[PartParams],
    pairs: &[(usize, ParamKind, ParamKind)],
    offsets: &[f64],
) -> Result<Vec<Profile2d>, FitError> {
    let obj = Objective::new(problem, cfg.frames, &cfg.loss, false)?;
    let f = factors(offsets);
    let mut out = Vec::new();
    for &(part, ka, kb) in pairs {
        let sets: Vec<Vec<PartParams>> = f
            .iter()
            .flat_map(|&fa| {
                f.iter()
                    .map(move |&fb| scaled(truth, &[(part, ka, fa), (part, kb, fb)]))
            })
            .collect();
        let flat = losses(&obj, sets)?;
        let grid: Vec<Vec<f64>> = flat.chunks(f.len()).map(|c| c.to_vec()).collect();
        let mut x = Vec::new();
        let mut y = Vec::new();
        for (i, &fa) in f.iter().enumerate() {
            for (j, &fb) in f.iter().enumerate() {
                let (u, v) = (fa.ln(), fb.ln());
                x.push(vec![1.0, u, v, 0.5 * u * u, u * v, 0.5 * v * v]);
                y.push(grid[i][j]);
            }
        }
        let c = least_squares(&x, &y).unwrap_or_else(|| vec![0.0; 6]);
        let h = [[c[3], c[4]], [c[4], c[5]]];
        let rho = if h[0][0] > 0.0 && h[1][1] > 0.0 {
            (h[0][1] / (h[0][0] * h[1][1]).sqrt()).clamp(-1.0, 1.0)
        } else {
            0.0
        };
        // Stiff eigenvector of the symmetric 2x2 H.
        let (p, q) = (h[0][0], h[1][1]);
        let r = h[0][1];
        let lmax = 0.5 * (p + q) + (0.25 * (p - q).powi(2) + r * r).sqrt();
        let mut ev = if r.abs() > 1e-300 {
            [r, lmax - p]
        } else if p >= q {
            [1.0, 0.0]
        } else {
            [0.0, 1.0]
        };
        let n = (ev[0] * ev[0] + ev[1] * ev[1]).sqrt();
        ev = ev.map(|e| e / n);
        if ev[0] < 0.0 || (ev[0] == 0.0 && ev[1] < 0.0) {
            ev = ev.map(|e| -e);
        }
        out.push(Profile2d {
            a: format!("part{part}.{}", ka.name()),
            b: format!("part{part}.{}", kb.name()),
            factors_a: f.clone(),
            factors_b: f.clone(),
            losses: grid,
            hessian: h,
            correlation: rho,
            stiff_exponents: ev,
            trade_off: rho.abs() > TRADE_OFF_RHO,
        });
    }
    Ok(out)
}

/// The verdicts (see the module docs); fills in `relative_sensitivity` and `identifiable`
/// of `profiles`. Without profiles nothing is judged and every verdict is absent.
pub fn verdicts(profiles: &mut [Profile], pairs: &[Profile2d]) -> Vec<Verdict> {
    let max_rise = profiles.iter().map(|p| p.rise_10pct).fold(0.0f64, f64::max);
    let mut out = Vec::new();
    for p in profiles.iter_mut() {
        let partner = pairs
            .iter()
            .filter(|q| q.a == p.name || q.b == p.name)
            .max_by(|x, y| x.correlation.abs().total_cmp(&y.correlation.abs()));
        let shrink = partner.map_or(1.0, |q| 1.0 - q.correlation * q.correlation);
        p.relative_sensitivity = if max_rise > 0.0 {
            p.rise_10pct * shrink / max_rise
        } else {
            0.0
        };
        p.identifiable = p.min_at_truth && p.relative_sensitivity >= MIN_RELATIVE_SENSITIVITY;
        let reason = if !p.min_at_truth {
            "the loss profile is flat or not lowest at the truth".to_string()
        } else if p.identifiable {
            format!(
                "a 10% error raises the loss by {:.1}% of the most sensitive parameter's rise",
                100.0 * p.relative_sensitivity
            )
        } else if let Some(q) = partner.filter(|q| q.trade_off) {
            let other = if q.a == p.name { &q.b } else { &q.a };
            format!(
                "trades off with {other} (correlation {:.3}): only their combination is determined",
                q.correlation
            )
        } else {
            format!(
                "a 10% error raises the loss by only {:.2}% of the most sensitive parameter's rise",
                100.0 * p.relative_sensitivity
            )
        };
        out.push(Verdict {
            name: p.name.clone(),
            identifiable: p.identifiable,
            relative_sensitivity: p.relative_sensitivity,
            reason,
        });
    }
    // E/density per part: from its 2-D profile when there is one (the curvature along the
    // direction (1, -1) of (ln E, ln density)), else determined when E or density is.
    let parts: std::collections::BTreeSet<String> = profiles
        .iter()
        .filter_map(|p| p.name.split_once('.').map(|(a, _)| a.to_string()))
        .collect();
    for part in parts {
        let (e, d) = (format!("{part}.E"), format!("{part}.density"));
        let (Some(pe), Some(pd)) = (
            profiles.iter().find(|p| p.name == e),
            profiles.iter().find(|p| p.name == d),
        ) else {
            continue;
        };
        let rel = match pairs.iter().find(|q| q.a == e && q.b == d) {
            Some(q) => {
                // In r = ln E - ln density, m = ln E + ln density: the marginal curvature of
                // r (m free to compensate), then the rise of a 10% error in the ratio.
                let h = q.hessian;
                let hrr = 0.25 * (h[0][0] - 2.0 * h[0][1] + h[1][1]);
                let hmm = 0.25 * (h[0][0] + 2.0 * h[0][1] + h[1][1]);
                let hrm = 0.25 * (h[0][0] - h[1][1]);
                let marginal = if hmm > 0.0 {
                    hrr - hrm * hrm / hmm
                } else {
                    hrr
                };
                let rise = 0.5 * marginal.max(0.0) * 1.1f64.ln().powi(2);
                if max_rise > 0.0 {
                    rise / max_rise
                } else {
                    0.0
                }
            }
            None => pe.relative_sensitivity.max(pd.relative_sensitivity),
        };
        let both = pe.identifiable && pd.identifiable;
        let ok = both || ((pe.min_at_truth || pd.min_at_truth) && rel >= MIN_RELATIVE_SENSITIVITY);
        out.push(Verdict {
            name: format!("{part}.E/density"),
            identifiable: ok,
            relative_sensitivity: rel,
            reason: if both {
                "E and density are both determined".into()
            } else if ok {
                "the elastic wave speed (E/density) sets the motion's time scale".into()
            } else {
                "the motion barely depends on the elastic wave speed".into()
            },
        });
    }
    out
}
