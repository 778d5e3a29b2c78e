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
//! loss on a grid of both offsets (the demo: factors 0.9, 1, 1.1). For each parameter of the
//! pair, the *marginal share* is the loss rise of a 10% error when the partner takes its best
//! grid value, over the rise with the partner at the truth: 1 when the partner cannot
//! compensate, near 0 when it can (a valley). It is read off the grid, not from a fitted
//! quadratic: near the truth the DMS loss is kinked (its magnitude term is an absolute
//! difference), and a quadratic fitted to a kink reports spurious correlations. A
//! least-squares quadratic's log-space Hessian and correlation are still reported, for
//! information, when the quadratic is convex.
//!
//! # Verdicts
//! A parameter is **identifiable** when
//! 1. the 1-D profile has its minimum at the truth and rises on both sides, and
//! 2. its marginal rise — its conditional rise times the smallest marginal share of the
//!    pairs that contain it — is at least [`MIN_RELATIVE_SENSITIVITY`] of the largest
//!    conditional rise among the free parameters.
//!
//! The threshold is relative because the absolute scale of the loss depends on the scene:
//! when the best-determined parameter is recovered to about 1%, one with 5% of its curvature
//! is recovered to about `1% / sqrt(0.05) = 4.5%`, inside every target tolerance; below that
//! the fit's number is not a measurement. A pair with a marginal share below
//! [`TRADE_OFF_SHARE`] is reported as a trade-off; `E/density` gets its own verdict.

use r4d_mpm::PartParams;
use r4d_optim::space::{get, set, ParamSpace};
use r4d_optim::video::{FitConfig, Objective, VideoProblem};
use r4d_optim::FitError;
use r4d_optim::ParamKind;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// Share of the largest conditional rise a parameter's marginal rise needs to be called
/// identifiable.
pub const MIN_RELATIVE_SENSITIVITY: f64 = 0.05;

/// Marginal share below which a 2-D profile is reported as a trade-off.
pub const TRADE_OFF_SHARE: f64 = 0.1;

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
    /// `H_ab / sqrt(H_aa H_bb)` of the fitted quadratic; `None` when it is not convex.
    pub correlation: Option<f64>,
    /// Marginal share of `a` and of `b` (see the module docs).
    pub marginal_share: [f64; 2],
    /// A marginal share below [`TRADE_OFF_SHARE`].
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
        cfg.bounds(truth, p, k)
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
        let convex = h[0][0] > 0.0 && h[1][1] > 0.0 && h[0][0] * h[1][1] > h[0][1] * h[0][1];
        let rho = convex.then(|| h[0][1] / (h[0][0] * h[1][1]).sqrt());
        // Marginal shares on the grid: rows are a's factors, columns b's.
        let one = f.iter().position(|&v| v == 1.0).expect("truth point");
        let l0 = grid[one][one];
        let share = |get: &dyn Fn(usize, usize) -> f64| {
            let (mut cond, mut marg, mut n) = (0.0, 0.0, 0.0);
            for i in (0..f.len()).filter(|&i| i != one) {
                cond += get(i, one) - l0;
                marg += (0..f.len())
                    .map(|j| get(i, j))
                    .fold(f64::INFINITY, f64::min)
                    - l0;
                n += 1.0;
            }
            if cond > 0.0 && n > 0.0 {
                (marg / cond).clamp(0.0, 1.0)
            } else {
                0.0
            }
        };
        let sa = share(&|i, j| grid[i][j]);
        let sb = share(&|i, j| grid[j][i]);
        out.push(Profile2d {
            a: format!("part{part}.{}", ka.name()),
            b: format!("part{part}.{}", kb.name()),
            factors_a: f.clone(),
            factors_b: f.clone(),
            losses: grid,
            hessian: h,
            correlation: rho,
            marginal_share: [sa, sb],
            trade_off: sa.min(sb) < TRADE_OFF_SHARE,
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
        let mine = |q: &Profile2d| {
            if q.a == p.name {
                q.marginal_share[0]
            } else {
                q.marginal_share[1]
            }
        };
        let partner = pairs
            .iter()
            .filter(|q| q.a == p.name || q.b == p.name)
            .min_by(|x, y| mine(x).total_cmp(&mine(y)));
        let shrink = partner.map_or(1.0, mine);
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
                "trades off with {other} (it compensates all but {:.0}% of a 10% error's loss rise): only their combination is determined",
                100.0 * mine(q)
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
    // E/density per part: determined when E and density both are; else from their 2-D
    // profile when there is one, else from the more sensitive of the two 1-D profiles.
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
            // Moving E or density alone by 10% changes the ratio by about 10%; the smaller of
            // the two rises (conditional on the other) over the largest conditional rise.
            Some(q) => {
                let one = q.factors_a.iter().position(|&v| v == 1.0).expect("truth");
                let l0 = q.losses[one][one];
                let n = q.factors_a.len();
                let side = |get: &dyn Fn(usize) -> f64| {
                    let v: Vec<f64> = (0..n).filter(|&i| i != one).map(get).collect();
                    v.iter().sum::<f64>() / v.len().max(1) as f64 - l0
                };
                let rise = side(&|i| q.losses[i][one]).min(side(&|j| q.losses[one][j]));
                if max_rise > 0.0 {
                    (rise / max_rise).max(0.0)
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

/// Kinds measured in pascals (or pascal-seconds): scaling every one of them and the density
/// by the same factor scales every stress and every inertial force alike.
fn stress_like(k: ParamKind) -> bool {
    matches!(
        k,
        ParamKind::YoungsModulus
            | ParamKind::YieldStress
            | ParamKind::PlasticViscosity
            | ParamKind::Softening
    )
}

/// The loss profile along the *stress-density scale*: every free stress-like parameter (`E`,
/// yield stress, plastic viscosity, softening) and the density of every part whose density
/// is free, scaled together by each factor of `offsets`. Under gravity alone (and
/// prescribed velocities) the motion is exactly unchanged along it, so no pair profile sees
/// the invariance when three or more of these parameters are free; a force given in
/// newtons breaks it. Named `scale`; `None` when no part has its density and a stress-like
/// parameter free.
pub fn scale_profile(
    problem: &VideoProblem,
    cfg: &FitConfig,
    truth: &[PartParams],
    offsets: &[f64],
) -> Result<Option<Profile>, FitError> {
    let free = cfg.free_kinds(truth)?;
    let members: Vec<(usize, ParamKind)> = free
        .iter()
        .enumerate()
        .filter(|(_, kinds)| {
            kinds.contains(&ParamKind::Density) && kinds.iter().any(|&k| stress_like(k))
        })
        .flat_map(|(part, kinds)| {
            kinds
                .iter()
                .filter(|&&k| stress_like(k) || k == ParamKind::Density)
                .map(move |&k| (part, k))
        })
        .collect();
    if members.is_empty() {
        return Ok(None);
    }
    let obj = Objective::new(problem, cfg.frames, &cfg.loss, false)?;
    let factors = factors(offsets);
    let sets = factors
        .iter()
        .map(|&f| {
            let changes: Vec<(usize, ParamKind, f64)> =
                members.iter().map(|&(p, k)| (p, k, f)).collect();
            scaled(truth, &changes)
        })
        .collect();
    let l = losses(&obj, sets)?;
    let one = factors.iter().position(|&f| f == 1.0).expect("truth point");
    let lo = if one > 0 { l[one - 1] - l[one] } else { 0.0 };
    let hi = l.get(one + 1).map_or(0.0, |v| v - l[one]);
    Ok(Some(Profile {
        name: "scale".into(),
        rise_10pct: rise_10pct(&factors, &l),
        min_at_truth: l.iter().all(|&v| v >= l[one]) && lo > 0.0 && hi > 0.0,
        factors,
        losses: l,
        relative_sensitivity: 0.0,
        identifiable: false,
    }))
}

/// Applies the stress-density scale profile to the verdicts of `profiles` (see
/// [`verdicts`]): when a 10% move along the scale raises the loss by less than
/// [`MIN_RELATIVE_SENSITIVITY`] of the largest conditional rise, the free stress-like
/// parameters and densities are not determined one by one (only their ratios are), and
/// their verdicts say so. Returns whether it downgraded any.
pub fn apply_scale(verdicts: &mut [Verdict], profiles: &mut [Profile], scale: &Profile) -> bool {
    let max_rise = profiles.iter().map(|p| p.rise_10pct).fold(0.0f64, f64::max);
    let rel = if max_rise > 0.0 {
        scale.rise_10pct / max_rise
    } else {
        0.0
    };
    if rel >= MIN_RELATIVE_SENSITIVITY {
        return false;
    }
    let member = |name: &str| {
        name.split_once('.').is_some_and(|(_, k)| {
            ParamKind::parse(k).is_ok_and(|k| stress_like(k) || k == ParamKind::Density)
        })
    };
    let mut any = false;
    for v in verdicts
        .iter_mut()
        .filter(|v| member(&v.name) && v.identifiable)
    {
        v.identifiable = false;
        v.reason = format!(
            "scaling every stress-like parameter and the density together by 10% raises the loss by only {:.2}% of the most sensitive parameter's rise: only their ratios are determined",
            100.0 * rel
        );
        any = true;
    }
    for p in profiles.iter_mut().filter(|p| member(&p.name)) {
        p.identifiable = false;
    }
    any
}

#[cfg(test)]
mod tests {
    use super::*;

    fn profile(name: &str, rise: f64) -> Profile {
        Profile {
            name: name.into(),
            factors: vec![0.9, 1.0, 1.1],
            losses: vec![1.0 + rise, 1.0, 1.0 + rise],
            rise_10pct: rise,
            min_at_truth: true,
            relative_sensitivity: 0.0,
            identifiable: false,
        }
    }

    /// A flat stress-density scale takes the stress-like parameters and the density out of
    /// the determined ones and leaves the dimensionless ones; a steep one changes nothing.
    #[test]
    fn a_flat_stress_density_scale_leaves_only_ratios_determined() {
        let mut ps = vec![
            profile("part0.E", 1.0),
            profile("part0.nu", 0.5),
            profile("part0.yield_stress", 0.8),
            profile("part0.density", 0.9),
        ];
        let mut v = verdicts(&mut ps, &[]);
        assert!(v.iter().all(|v| v.identifiable), "{v:?}");
        assert!(!apply_scale(&mut v, &mut ps, &profile("scale", 0.2)));
        assert!(apply_scale(&mut v, &mut ps, &profile("scale", 0.01)));
        let ok: Vec<(&str, bool)> = v
            .iter()
            .map(|v| (v.name.as_str(), v.identifiable))
            .collect();
        assert_eq!(
            &ok[..4],
            &[
                ("part0.E", false),
                ("part0.nu", true),
                ("part0.yield_stress", false),
                ("part0.density", false)
            ]
        );
        assert!(v[0].reason.contains("ratios"), "{}", v[0].reason);
        assert!(!ps[0].identifiable && ps[1].identifiable);
    }
}
