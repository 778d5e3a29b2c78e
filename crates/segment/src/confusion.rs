//! Combining the views through per-view confusion matrices (Dawid and Skene's EM for
//! several annotators, 1979): [`crate::ViewVote::Confusion`].
//!
//! Every view is an annotator with its own way of being wrong: it erodes one part (a thin
//! stem vanishes from it), dilates another over its neighbours, labels a whole part as
//! another. Per view `v`, a confusion matrix `C_v[c][o]` (the probability that a Gaussian of
//! true class `c` gets observed label `o` from the view) is estimated from the current
//! posterior, and the posterior from the matrices:
//!
//! ```text
//! M-step:  C_v[c][o] ~ alpha [c == o] + beta + sum_g a_v(g) P_-v(g, c) q_v(g, o)
//! E-step:  log P(g, c) = sum_v a_v(g) sum_o q_v(g, o) log C_v[c][o] + const
//! ```
//!
//! with `q_v(g, .)` the view's own class distribution for Gaussian `g` (its pixels' votes,
//! normalised) and `a_v(g)` how well the view sees it (saturating, [`crate::LiftConfig::saturation`]).
//! The likelihood ratio of an observation is what the view's record says it is worth: where a
//! view erodes the stem away, "background" over the stem is nearly as likely for stem
//! Gaussians as for background ones, so it hardly counts against the stem; the views that do
//! show the stem (where a stem label almost never falls on anything else) decide. A view that
//! calls the petals leaves has `C[petals][leaves] ~ C[leaves][leaves]`: its leaves label says
//! nothing about petals against leaves.
//!
//! `P_-v` is the verdict of the views other than `v` (leave-one-out): the first round takes it
//! from the summed votes ([`crate::ViewVote::Sum`]'s evidence) less view `v`'s own, later
//! rounds from the posterior less view `v`'s log likelihood, so a view's own mistakes do not
//! make it look honest. The prior over classes is uniform (a small part is not penalised for
//! being small). Each view's observation counts as `a_v(g)` pixels' worth of independent
//! labels drawn from `q_v(g, .)` (the log of a mixture would let a thin part's boundary
//! pixels, half background, outvote its label: measured, the stem fell to 27% with clean
//! masks).

/// Settings of the EM (module docs).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ConfusionConfig {
    /// EM rounds (at least 1). Default 1: on the potted plant (five seeds, corrupted masks)
    /// one round took the part Gaussians from 90.8% to 93.7% right, two rounds 91.8%, four
    /// 89.8% — later rounds sharpen the matrices around their own mistakes (a thin part's
    /// mixed observations drift to its neighbours, on clean masks too).
    pub iters: u32,
    /// Pseudo-count on each confusion matrix's diagonal, as a share of the class's total
    /// weight in the view (keeps a view that sees a class barely at all near "honest").
    /// Default 0.05 (0.01-0.2 changed the potted plant's accuracy by under 0.3 points).
    pub diagonal_prior: f64,
    /// Pseudo-count on every entry, likewise (no observation is impossible). Default 1e-3
    /// (1e-4-1e-2: under 0.1 points).
    pub floor: f64,
}

impl Default for ConfusionConfig {
    fn default() -> Self {
        ConfusionConfig {
            iters: 1,
            diagonal_prior: 0.05,
            floor: 1e-3,
        }
    }
}

/// One view's observation of one Gaussian: its strength `a_v(g)` and class shares.
#[inline]
fn observation(votes: &[u8], n: usize, s: usize, v: usize, g: usize) -> Option<(f64, &[u8])> {
    let sw = s + 1;
    let r = &votes[(v * n + g) * sw..(v * n + g + 1) * sw];
    (r[s] > 0).then(|| (r[s] as f64 / 255.0, &r[..s]))
}

/// The per-view votes [`crate::lift()`] keeps.
#[derive(Clone, Copy, Debug)]
pub(crate) struct VoteTable<'a> {
    /// `views x N x (M + 2)` bytes: `M + 1` class shares out of 255, then the view's
    /// strength out of 255 (0: the view does not see the Gaussian).
    pub votes: &'a [u8],
    /// `views x N`: each view's total vote per Gaussian, as added to the summed evidence.
    pub totals: &'a [f32],
    /// Gaussians `N`.
    pub n: usize,
    /// Classes `M + 1` (background first).
    pub s: usize,
    /// Views.
    pub nv: usize,
}

/// Runs the EM on the per-view vote table (`views x N x (M + 2)` bytes: `M + 1` class shares
/// out of 255 and the view's strength out of 255, as [`crate::lift()`] keeps it) from the summed
/// evidence `init` (`N x (M + 1)`, any non-negative weights; rows of zeros are unobserved) of
/// which view `v` contributed `totals[v N + g]` to Gaussian `g` (spread as its shares), and
/// writes the posterior class probabilities into `out` (rows of zeros stay zeros). Each
/// view's matrix is estimated against the *other* views' verdict (leave-one-out), so a view's
/// own mistakes do not make it look honest.
pub(crate) fn combine(table: &VoteTable, init: &[f64], cfg: &ConfusionConfig, out: &mut [f64]) {
    let VoteTable {
        votes,
        totals,
        n,
        s,
        nv,
    } = *table;
    debug_assert_eq!(init.len(), n * s);
    debug_assert_eq!(out.len(), n * s);
    debug_assert_eq!(totals.len(), nv * n);
    debug_assert_eq!(votes.len(), nv * n * (s + 1));
    let mut lp = vec![0f64; n * s];
    let mut conf = Vec::new();
    for it in 0..cfg.iters.max(1) {
        // Round 0: against the other views' summed votes; then against their posterior.
        let state = if it == 0 {
            Consensus::Summed { init, totals }
        } else {
            Consensus::Posterior {
                lp: &lp,
                conf: &conf,
            }
        };
        let c = m_step(votes, n, s, nv, &state, cfg);
        let mut next = vec![0f64; n * s];
        e_step(votes, n, s, nv, &c, &mut next);
        (lp, conf) = (next, c);
    }
    for (o, row) in out.chunks_exact_mut(s).zip(lp.chunks_exact(s)) {
        softmax_into(row, o);
    }
}

/// What a view's matrix is estimated against.
enum Consensus<'a> {
    /// The summed votes less the view's own.
    Summed { init: &'a [f64], totals: &'a [f32] },
    /// The log posterior less the view's own log likelihood.
    Posterior { lp: &'a [f64], conf: &'a [f64] },
}

fn softmax_into(lp: &[f64], out: &mut [f64]) {
    if lp.iter().all(|&x| x == f64::NEG_INFINITY) {
        out.iter_mut().for_each(|o| *o = 0.0);
        return;
    }
    let top = lp.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let z: f64 = lp.iter().map(|l| (l - top).exp()).sum();
    for (o, l) in out.iter_mut().zip(lp) {
        *o = (l - top).exp() / z;
    }
}

/// View `v`'s log likelihood of each class for one Gaussian, `a sum_o q_o log C[c][o]`, from
/// the view's `log C` (`cv`).
#[inline]
fn view_log_lik(a: f64, q: &[u8], cv: &[f64], s: usize, out: &mut [f64]) {
    for (c, l) in out.iter_mut().enumerate() {
        let ll: f64 = q
            .iter()
            .zip(&cv[c * s..(c + 1) * s])
            .map(|(&qo, &lc)| qo as f64 * lc)
            .sum::<f64>()
            / 255.0;
        *l = a * ll;
    }
}

/// The logs of the confusion matrices (`nv x s x s`, rows normalised before the log).
fn m_step(
    votes: &[u8],
    n: usize,
    s: usize,
    nv: usize,
    state: &Consensus,
    cfg: &ConfusionConfig,
) -> Vec<f64> {
    let per_view = |v: usize| {
        let mut c = vec![0f64; s * s];
        let mut p = vec![0f64; s];
        let mut ll = vec![0f64; s];
        for g in 0..n {
            let Some((a, q)) = observation(votes, n, s, v, g) else {
                continue;
            };
            // The other views' verdict on g.
            match state {
                Consensus::Summed { init, totals } => {
                    let t = totals[v * n + g] as f64 / 255.0;
                    for (pc, (&w, &qc)) in p.iter_mut().zip(init[g * s..(g + 1) * s].iter().zip(q))
                    {
                        *pc = (w - t * qc as f64).max(0.0);
                    }
                    let tot: f64 = p.iter().sum();
                    if tot <= 1e-12 {
                        continue;
                    }
                    p.iter_mut().for_each(|x| *x /= tot);
                }
                Consensus::Posterior { lp, conf } => {
                    view_log_lik(a, q, &conf[v * s * s..(v + 1) * s * s], s, &mut ll);
                    for (l, &x) in ll.iter_mut().zip(&lp[g * s..(g + 1) * s]) {
                        *l = x - *l;
                    }
                    softmax_into(&ll, &mut p);
                }
            }
            for (ci, &pc) in p.iter().enumerate() {
                if pc <= 0.0 {
                    continue;
                }
                let w = a * pc / 255.0;
                for (o, &qo) in q.iter().enumerate() {
                    c[ci * s + o] += w * qo as f64;
                }
            }
        }
        for ci in 0..s {
            let row = &mut c[ci * s..(ci + 1) * s];
            let tot: f64 = row.iter().sum::<f64>();
            for (o, x) in row.iter_mut().enumerate() {
                *x = if tot <= 1e-12 {
                    // A class the view never sees: an honest annotator.
                    if o == ci {
                        1.0
                    } else {
                        cfg.floor
                    }
                } else {
                    *x + tot * (cfg.floor + if o == ci { cfg.diagonal_prior } else { 0.0 })
                };
            }
            let t: f64 = row.iter().sum();
            row.iter_mut().for_each(|x| *x = (*x / t).ln());
        }
        c
    };
    #[cfg(feature = "parallel")]
    let conf: Vec<f64> = {
        use rayon::prelude::*;
        (0..nv).into_par_iter().flat_map_iter(per_view).collect()
    };
    #[cfg(not(feature = "parallel"))]
    let conf: Vec<f64> = (0..nv).flat_map(per_view).collect();
    conf
}

/// The log posterior (uniform prior, up to a constant per Gaussian; `-inf` where no view
/// sees the Gaussian).
fn e_step(votes: &[u8], n: usize, s: usize, nv: usize, conf: &[f64], lp: &mut [f64]) {
    let one = |g: usize, row: &mut [f64]| {
        let mut ll = vec![0f64; s];
        let mut seen = false;
        row.iter_mut().for_each(|x| *x = 0.0);
        for v in 0..nv {
            let Some((a, q)) = observation(votes, n, s, v, g) else {
                continue;
            };
            seen = true;
            view_log_lik(a, q, &conf[v * s * s..(v + 1) * s * s], s, &mut ll);
            row.iter_mut().zip(&ll).for_each(|(r, l)| *r += l);
        }
        if !seen {
            row.iter_mut().for_each(|x| *x = f64::NEG_INFINITY);
        }
    };
    #[cfg(feature = "parallel")]
    {
        use rayon::prelude::*;
        lp.par_chunks_mut(s)
            .enumerate()
            .with_min_len(1024)
            .for_each(|(g, row)| one(g, row));
    }
    #[cfg(not(feature = "parallel"))]
    for (g, row) in lp.chunks_mut(s).enumerate() {
        one(g, row);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Builds a vote table from per-view hard labels (`None`: not seen).
    fn table(obs: &[Vec<Option<usize>>], s: usize) -> Vec<u8> {
        let nv = obs.len();
        let n = obs[0].len();
        let mut t = vec![0u8; nv * n * (s + 1)];
        for (v, ov) in obs.iter().enumerate() {
            for (g, o) in ov.iter().enumerate() {
                if let Some(o) = o {
                    let r = &mut t[(v * n + g) * (s + 1)..(v * n + g + 1) * (s + 1)];
                    r[*o] = 255;
                    r[s] = 255;
                }
            }
        }
        t
    }

    /// Each view's total vote per Gaussian (1 where it sees it).
    fn totals(obs: &[Vec<Option<usize>>]) -> Vec<f32> {
        obs.iter()
            .flat_map(|ov| ov.iter().map(|o| if o.is_some() { 1.0 } else { 0.0 }))
            .collect()
    }

    /// Five views; a small part (class 2) that three of them erode away (they call it
    /// background) and two show: the summed votes lose it 3:2, the EM keeps it, because in
    /// the two honest views a class-2 label almost never falls on background.
    #[test]
    fn views_that_miss_a_part_lose_their_say_on_it() {
        let s = 3;
        let truth: Vec<usize> = (0..300)
            .map(|g| {
                if g < 200 {
                    0
                } else if g < 270 {
                    1
                } else {
                    2
                }
            })
            .collect();
        let n = truth.len();
        let obs: Vec<Vec<Option<usize>>> = (0..5)
            .map(|v| {
                truth
                    .iter()
                    .map(|&c| Some(if v < 3 && c == 2 { 0 } else { c }))
                    .collect()
            })
            .collect();
        let votes = table(&obs, s);
        let mut init = vec![0f64; n * s];
        for ov in &obs {
            for (g, o) in ov.iter().enumerate() {
                init[g * s + o.unwrap()] += 1.0;
            }
        }
        let right = |w: &[f64]| {
            (0..n)
                .filter(|&g| {
                    let r = &w[g * s..(g + 1) * s];
                    let arg = (0..s).fold(0, |b, c| if r[c] > r[b] { c } else { b });
                    arg == truth[g]
                })
                .count()
        };
        assert_eq!(right(&init), 270, "the sum loses class 2");
        let mut out = vec![0f64; n * s];
        let t = totals(&obs);
        let tab = VoteTable {
            votes: &votes,
            totals: &t,
            n,
            s,
            nv: 5,
        };
        combine(&tab, &init, &ConfusionConfig::default(), &mut out);
        assert_eq!(right(&out), n, "EM recovers every Gaussian");
        for row in out.chunks_exact(s) {
            assert!((row.iter().sum::<f64>() - 1.0).abs() < 1e-9);
        }
    }

    #[test]
    fn unseen_gaussians_stay_unobserved() {
        let s = 2;
        let obs = vec![vec![Some(1), None]];
        let votes = table(&obs, s);
        let init = vec![0.0, 1.0, 0.0, 0.0];
        let mut out = vec![0f64; 4];
        let t = totals(&obs);
        let tab = VoteTable {
            votes: &votes,
            totals: &t,
            n: 2,
            s,
            nv: 1,
        };
        combine(&tab, &init, &ConfusionConfig::default(), &mut out);
        assert_eq!(&out[2..], &[0.0, 0.0]);
        assert!(out[1] > out[0]);
    }
}
