//! Simulation-driven initialisation (the paper's Sec. 3.3): sample candidate parameter vectors
//! over the search space, score each by simulating and comparing with the reference video,
//! and start the gradient-based fit from the best.

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::lhs::{latin_hypercube, log_space};
use crate::{Error, ParamKind};

/// Named positive bounds for a flat vector of parameters (the order the caller's `evaluate`
/// expects).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SearchSpace {
    /// Parameter names, used in error messages and reports.
    pub names: Vec<String>,
    /// `(lo, hi)` per parameter: positive, finite, `lo <= hi`.
    pub bounds: Vec<(f64, f64)>,
}

impl SearchSpace {
    /// A validated search space (see [`SearchSpace::validate`]).
    pub fn new(names: Vec<String>, bounds: Vec<(f64, f64)>) -> Result<Self, Error> {
        let space = SearchSpace { names, bounds };
        space.validate()?;
        Ok(space)
    }

    /// The given kinds with their [`ParamKind::default_bounds`], named by [`ParamKind::name`].
    pub fn from_kinds(kinds: &[ParamKind]) -> Result<Self, Error> {
        SearchSpace::new(
            kinds.iter().map(|k| k.name().to_string()).collect(),
            kinds.iter().map(|k| k.default_bounds()).collect(),
        )
    }

    /// Checks one bound per name, no duplicate names, and bounds that are positive, finite
    /// and ordered.
    pub fn validate(&self) -> Result<(), Error> {
        if self.names.len() != self.bounds.len() {
            return Err(Error::InvalidSpace(format!(
                "{} parameter names but {} bounds",
                self.names.len(),
                self.bounds.len()
            )));
        }
        for (i, name) in self.names.iter().enumerate() {
            if self.names[..i].contains(name) {
                return Err(Error::InvalidSpace(format!(
                    "parameter '{name}' appears more than once"
                )));
            }
        }
        for (name, &(lo, hi)) in self.names.iter().zip(&self.bounds) {
            if !(lo.is_finite() && hi.is_finite() && lo > 0.0 && lo <= hi) {
                return Err(Error::InvalidBounds {
                    name: name.clone(),
                    lo,
                    hi,
                });
            }
        }
        Ok(())
    }

    /// Number of parameters.
    pub fn dims(&self) -> usize {
        self.bounds.len()
    }

    /// Whether `theta` has one value per parameter, each within its closed bounds.
    pub fn contains(&self, theta: &[f64]) -> bool {
        theta.len() == self.bounds.len()
            && theta
                .iter()
                .zip(&self.bounds)
                .all(|(&t, &(lo, hi))| lo <= t && t <= hi)
    }
}

/// One evaluated candidate.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Candidate {
    /// Position in the sample order ([`InitOutcome::candidates`]); also the first argument
    /// `evaluate` received.
    pub index: usize,
    /// The parameter vector, in the search space's order.
    pub theta: Vec<f64>,
    /// Score (higher is better); `None` when the evaluation failed.
    pub score: Option<f64>,
    /// Why the evaluation failed (the evaluator's message, or "score is NaN"); `None` when it
    /// succeeded.
    pub error: Option<String>,
}

/// The result of an initialisation.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct InitOutcome {
    /// Every candidate, in sample order (`candidates[i].index == i`).
    pub candidates: Vec<Candidate>,
    /// Indices of the scored candidates, best (highest score) first; equal scores keep the
    /// lower index first. Failed candidates are absent.
    pub ranking: Vec<usize>,
    /// The first `top_k` entries of `ranking` (fewer when fewer candidates were scored).
    pub top_k: Vec<usize>,
    /// The best candidate's parameters (`candidates[ranking[0]].theta`).
    pub best: Vec<f64>,
}

impl InitOutcome {
    /// Ranks evaluated candidates (`candidates[i].index == i`, else [`Error::Setting`]): a
    /// candidate counts as scored when its score is `Some` and not NaN. Fails with
    /// [`Error::AllCandidatesFailed`] when none is scored (reporting the failure with the
    /// lowest index) and [`Error::NoCandidates`] when `candidates` is empty.
    pub fn from_candidates(candidates: Vec<Candidate>, top_k: usize) -> Result<Self, Error> {
        if let Some((i, c)) = candidates.iter().enumerate().find(|(i, c)| c.index != *i) {
            return Err(Error::Setting(format!(
                "candidate at position {i} has index {}: candidates must be in index order",
                c.index
            )));
        }
        let score = |c: &Candidate| c.score.filter(|s| !s.is_nan());
        let mut ranking: Vec<usize> = candidates
            .iter()
            .filter(|c| score(c).is_some())
            .map(|c| c.index)
            .collect();
        if ranking.is_empty() {
            let Some(first) = candidates.first() else {
                return Err(Error::NoCandidates);
            };
            return Err(Error::AllCandidatesFailed {
                count: candidates.len(),
                index: first.index,
                message: first
                    .error
                    .clone()
                    .unwrap_or_else(|| "score is NaN or missing".to_string()),
            });
        }
        // Stable sort, so equal scores keep the lower index first. No NaN is left, so
        // partial_cmp is total here (and -0.0 ties with 0.0).
        ranking.sort_by(|&a, &b| {
            let (sa, sb) = (
                score(&candidates[a]).unwrap(),
                score(&candidates[b]).unwrap(),
            );
            sb.partial_cmp(&sa).expect("NaN scores were filtered out")
        });
        let top_k = ranking[..top_k.min(ranking.len())].to_vec();
        let best = candidates[ranking[0]].theta.clone();
        Ok(InitOutcome {
            candidates,
            ranking,
            top_k,
            best,
        })
    }

    /// The candidates of [`InitOutcome::top_k`], best first.
    pub fn top_candidates(&self) -> Vec<&Candidate> {
        self.top_k.iter().map(|&i| &self.candidates[i]).collect()
    }

    /// The failed candidates, in sample order.
    pub fn failed(&self) -> impl Iterator<Item = &Candidate> + '_ {
        self.candidates
            .iter()
            .filter(|c| c.score.is_none_or(f64::is_nan))
    }
}

/// The evaluator an [`Initializer`] calls: `evaluate(index, theta)` returns the candidate's
/// score (higher is better) or why it failed. `&Evaluate<'_>` is
/// `&(dyn Fn(usize, &[f64]) -> Result<f64, String> + Sync)`; closures may borrow.
pub type Evaluate<'a> = dyn Fn(usize, &[f64]) -> Result<f64, String> + Sync + 'a;

/// Evaluates candidate `index` at `theta` as every [`Initializer`] does: a NaN score or an
/// `Err` make a failed candidate with the reason recorded.
pub fn evaluate_candidate(index: usize, theta: Vec<f64>, evaluate: &Evaluate<'_>) -> Candidate {
    let (score, error) = match evaluate(index, &theta) {
        Ok(s) if s.is_nan() => (None, Some("score is NaN".to_string())),
        Ok(s) => (Some(s), None),
        Err(e) => (None, Some(e)),
    };
    Candidate {
        index,
        theta,
        score,
        error,
    }
}

/// Chooses a starting point for the fit by evaluating candidates over a [`SearchSpace`] (the
/// video fit's start runs through this trait, so another sampler plugs in unchanged).
pub trait Initializer: Sync {
    /// The candidate points, in index order, before any evaluation (deterministic: a cluster
    /// can evaluate them in shards and rank the union with
    /// [`InitOutcome::from_candidates`]).
    fn candidates(&self, space: &SearchSpace) -> Result<Vec<Vec<f64>>, Error>;

    /// How many of the best candidates [`InitOutcome::top_k`] keeps.
    fn top_k(&self) -> usize;

    /// Whether candidates are evaluated concurrently (on rayon's current pool); the outcome
    /// does not depend on it. Default: no.
    fn parallel(&self) -> bool {
        false
    }

    /// At most this many candidates are evaluated at the same time when
    /// [`Initializer::parallel`] (e.g. what fits in a memory budget; each evaluation may
    /// still use every thread of the pool itself). Default: no limit beyond the pool's
    /// threads.
    fn max_concurrent(&self) -> usize {
        usize::MAX
    }

    /// [`Initializer::initialize`] with a progress hook: `on_done` is called once per
    /// candidate as soon as its evaluation finishes (from the evaluating thread, so in
    /// completion order when [`Initializer::parallel`]); candidates are collected in index
    /// order either way.
    fn initialize_with(
        &self,
        space: &SearchSpace,
        evaluate: &Evaluate<'_>,
        on_done: &(dyn Fn(&Candidate) + Sync),
    ) -> Result<InitOutcome, Error> {
        let points = self.candidates(space)?;
        let run = |(index, theta): (usize, Vec<f64>)| -> Candidate {
            let c = evaluate_candidate(index, theta, evaluate);
            on_done(&c);
            c
        };
        let workers = self.max_concurrent().max(1);
        let candidates: Vec<Candidate> = if !self.parallel() || workers == 1 {
            points.into_iter().enumerate().map(&run).collect()
        } else if workers >= points.len().min(rayon::current_num_threads()) {
            points.into_par_iter().enumerate().map(&run).collect()
        } else {
            run_bounded(points, workers, &run)
        };
        InitOutcome::from_candidates(candidates, self.top_k())
    }

    /// Evaluates candidates with `evaluate(index, theta)`, which returns a score (higher is
    /// better, e.g. MS-SSIM of the simulated render against the reference video) or an error
    /// message. A failed candidate (an `Err`, or a NaN score) is recorded and skipped; the
    /// initialisation fails only when every candidate fails
    /// ([`Error::AllCandidatesFailed`]) or the space or configuration is invalid.
    fn initialize(
        &self,
        space: &SearchSpace,
        evaluate: &Evaluate<'_>,
    ) -> Result<InitOutcome, Error> {
        self.initialize_with(space, evaluate, &|_| {})
    }
}

/// Evaluates `points` with `workers` tasks on rayon's current pool, each taking the next
/// point in index order when it is free (no more than `workers` evaluations at once; nested
/// parallelism inside an evaluation uses the whole pool). Results in index order.
fn run_bounded(
    points: Vec<Vec<f64>>,
    workers: usize,
    run: &(dyn Fn((usize, Vec<f64>)) -> Candidate + Sync),
) -> Vec<Candidate> {
    let n = points.len();
    let queue = std::sync::Mutex::new(points.into_iter().enumerate());
    let done: std::sync::Mutex<Vec<Option<Candidate>>> =
        std::sync::Mutex::new((0..n).map(|_| None).collect());
    rayon::scope(|s| {
        for _ in 0..workers.min(n) {
            s.spawn(|_| loop {
                let next = queue.lock().unwrap_or_else(|e| e.into_inner()).next();
                let Some((i, theta)) = next else { break };
                let c = run((i, theta));
                done.lock().unwrap_or_else(|e| e.into_inner())[i] = Some(c);
            });
        }
    });
    done.into_inner()
        .unwrap_or_else(|e| e.into_inner())
        .into_iter()
        .map(|c| c.expect("every candidate evaluated"))
        .collect()
}

/// Latin hypercube initialisation: `candidates` points of a seeded Latin hypercube
/// ([`latin_hypercube`]), mapped into the bounds in log10 space ([`log_space`], so every
/// decade of a wide range is sampled alike), plus the `include` points; all are evaluated and
/// ranked.
///
/// Candidate `i < candidates` is Latin hypercube point `i`; the `include` points follow, in
/// their order. The outcome depends only on the space, `candidates`, `seed`, `include`,
/// `top_k` and the evaluator's results, not on `parallel` or thread scheduling.
///
/// With `parallel`, candidates are evaluated on rayon's current thread pool (run inside
/// `ThreadPool::install` to limit the threads); set it to `false` when the evaluator is not
/// worth running concurrently (e.g. it holds one GPU queue). A panic in `evaluate` is not
/// caught: it propagates to the caller.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct LatinHypercubeInit {
    /// Number of Latin hypercube samples (the paper's N = 32).
    pub candidates: usize,
    /// Seed of the sampler.
    pub seed: u64,
    /// How many of the best candidates [`InitOutcome::top_k`] lists (default 4).
    pub top_k: usize,
    /// Evaluate candidates concurrently with rayon (default `true`).
    pub parallel: bool,
    /// With `parallel`, at most this many evaluations at once (`None`, the default: as many
    /// as the pool has threads). Bounds the memory when each evaluation holds a large
    /// simulation; the outcome does not depend on it.
    pub max_concurrent: Option<usize>,
    /// Extra candidates evaluated too, e.g. the user's starting point: each must have one
    /// positive finite value per parameter, within the bounds. Default: none.
    pub include: Vec<Vec<f64>>,
}

impl Default for LatinHypercubeInit {
    fn default() -> Self {
        LatinHypercubeInit {
            candidates: 32,
            seed: 0,
            top_k: 4,
            parallel: true,
            max_concurrent: None,
            include: Vec::new(),
        }
    }
}

impl LatinHypercubeInit {
    /// The candidate parameter vectors, in sample order, without evaluating them. Fails on an
    /// invalid space, an `include` point that does not fit it, or no candidates at all.
    pub fn sample(&self, space: &SearchSpace) -> Result<Vec<Vec<f64>>, Error> {
        space.validate()?;
        check_include(space, &self.include)?;
        let mut points: Vec<Vec<f64>> = latin_hypercube(self.candidates, space.dims(), self.seed)
            .into_iter()
            .map(|u| {
                u.iter()
                    .zip(&space.bounds)
                    .map(|(&u, &(lo, hi))| log_space(u, lo, hi))
                    .collect()
            })
            .collect();
        points.extend(self.include.iter().cloned());
        if points.is_empty() {
            return Err(Error::NoCandidates);
        }
        Ok(points)
    }
}

/// Checks that every extra candidate has one value per parameter, within the bounds.
fn check_include(space: &SearchSpace, include: &[Vec<f64>]) -> Result<(), Error> {
    for (j, p) in include.iter().enumerate() {
        if p.len() != space.dims() {
            return Err(Error::InvalidInclude {
                position: j,
                message: format!(
                    "{} values for {} parameters ({})",
                    p.len(),
                    space.dims(),
                    space.names.join(", ")
                ),
            });
        }
        for ((&t, &(lo, hi)), name) in p.iter().zip(&space.bounds).zip(&space.names) {
            if !(t.is_finite() && lo <= t && t <= hi) {
                return Err(Error::InvalidInclude {
                    position: j,
                    message: format!("parameter '{name}' = {t} is outside [{lo}, {hi}]"),
                });
            }
        }
    }
    Ok(())
}

/// Grid initialisation: the centres of a regular grid of `k` cells per parameter in log10
/// space ([`log_space`]), `k` the largest with `k^dims <= candidates` (at least 1: the box's
/// centre), plus the `include` points; all are evaluated and ranked. Deterministic (no seed):
/// every decade of every parameter is covered alike, which suits one or two free parameters;
/// with more, the Latin hypercube ([`LatinHypercubeInit`]) covers each parameter's range with
/// far fewer candidates.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct LogGridInit {
    /// The most grid points evaluated (the grid has `k^dims` of them).
    pub candidates: usize,
    /// How many of the best candidates [`InitOutcome::top_k`] lists (default 4).
    pub top_k: usize,
    /// Evaluate candidates concurrently with rayon (default `true`).
    pub parallel: bool,
    /// With `parallel`, at most this many evaluations at once (`None`: the pool's threads).
    pub max_concurrent: Option<usize>,
    /// Extra candidates evaluated too (one positive finite value per parameter, within the
    /// bounds).
    pub include: Vec<Vec<f64>>,
}

impl Default for LogGridInit {
    fn default() -> Self {
        LogGridInit {
            candidates: 32,
            top_k: 4,
            parallel: true,
            max_concurrent: None,
            include: Vec::new(),
        }
    }
}

impl LogGridInit {
    /// Cells per parameter for `dims` parameters: the largest `k >= 1` with
    /// `k^dims <= candidates`.
    pub fn points_per_axis(&self, dims: usize) -> usize {
        let mut k = 1usize;
        while (k + 1)
            .checked_pow(dims as u32)
            .is_some_and(|n| n <= self.candidates)
        {
            k += 1;
        }
        k
    }

    /// The grid points (the first parameter varying slowest), then `include`.
    pub fn sample(&self, space: &SearchSpace) -> Result<Vec<Vec<f64>>, Error> {
        space.validate()?;
        check_include(space, &self.include)?;
        if self.candidates == 0 && self.include.is_empty() {
            return Err(Error::NoCandidates);
        }
        let d = space.dims();
        let mut points = Vec::new();
        if self.candidates > 0 {
            let k = self.points_per_axis(d);
            let total = k.pow(d as u32);
            for i in 0..total {
                let mut rest = i;
                let mut p = vec![0.0; d];
                for a in (0..d).rev() {
                    let cell = rest % k;
                    rest /= k;
                    let (lo, hi) = space.bounds[a];
                    p[a] = log_space((cell as f64 + 0.5) / k as f64, lo, hi);
                }
                points.push(p);
            }
        }
        points.extend(self.include.iter().cloned());
        Ok(points)
    }
}

/// A Latin hypercube over each parameter's natural scale: log-uniform over the parameters
/// that span decades (moduli, stresses, viscosities, densities), uniform over those given
/// `linear` (Poisson's ratio and the friction angle, whose physics is not scale-free: with
/// bounds `[0.01, 0.49]` a log-uniform Poisson's ratio puts half the candidates below 0.07,
/// where it barely matters). The same strata and seed as [`LatinHypercubeInit`].
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct NaturalScaleInit {
    /// The Latin hypercube's settings (`include` and all).
    pub lhs: LatinHypercubeInit,
    /// Per parameter of the space: sampled uniformly (`true`) or log-uniformly.
    pub linear: Vec<bool>,
}

impl NaturalScaleInit {
    /// Whether `kind` is sampled uniformly (Poisson's ratio, the friction angle).
    pub fn is_linear(kind: crate::ParamKind) -> bool {
        matches!(
            kind,
            crate::ParamKind::PoissonRatio | crate::ParamKind::FrictionAngle
        )
    }

    /// The candidate parameter vectors, in sample order (see [`LatinHypercubeInit::sample`]).
    pub fn sample(&self, space: &SearchSpace) -> Result<Vec<Vec<f64>>, Error> {
        space.validate()?;
        check_include(space, &self.lhs.include)?;
        if self.linear.len() != space.dims() {
            return Err(Error::Setting(format!(
                "{} linear flags for {} parameters",
                self.linear.len(),
                space.dims()
            )));
        }
        let mut points: Vec<Vec<f64>> =
            latin_hypercube(self.lhs.candidates, space.dims(), self.lhs.seed)
                .into_iter()
                .map(|u| {
                    u.iter()
                        .zip(&space.bounds)
                        .zip(&self.linear)
                        .map(|((&u, &(lo, hi)), &lin)| {
                            if lin {
                                (lo + u.clamp(0.0, 1.0) * (hi - lo)).clamp(lo, hi)
                            } else {
                                log_space(u, lo, hi)
                            }
                        })
                        .collect()
                })
                .collect();
        points.extend(self.lhs.include.iter().cloned());
        if points.is_empty() {
            return Err(Error::NoCandidates);
        }
        Ok(points)
    }
}

impl Initializer for NaturalScaleInit {
    fn candidates(&self, space: &SearchSpace) -> Result<Vec<Vec<f64>>, Error> {
        self.sample(space)
    }

    fn top_k(&self) -> usize {
        self.lhs.top_k
    }

    fn parallel(&self) -> bool {
        self.lhs.parallel
    }

    fn max_concurrent(&self) -> usize {
        self.lhs.max_concurrent.unwrap_or(usize::MAX)
    }
}

/// [`Initializer`] for a sampler with `sample`, `top_k`, `parallel` and `max_concurrent`.
macro_rules! sampler_initializer {
    ($t:ty) => {
        impl Initializer for $t {
            fn candidates(&self, space: &SearchSpace) -> Result<Vec<Vec<f64>>, Error> {
                self.sample(space)
            }

            fn top_k(&self) -> usize {
                self.top_k
            }

            fn parallel(&self) -> bool {
                self.parallel
            }

            fn max_concurrent(&self) -> usize {
                self.max_concurrent.unwrap_or(usize::MAX)
            }
        }
    };
}

sampler_initializer!(LatinHypercubeInit);
sampler_initializer!(LogGridInit);

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::atomic::{AtomicUsize, Ordering};
    use std::sync::Mutex;

    /// The grid covers each parameter's decades alike (cell centres in log10 space), uses
    /// at most `candidates` points, and ranks the point nearest the optimum first.
    #[test]
    fn log_grid_covers_the_box_in_log_space() {
        let space = SearchSpace::new(
            vec!["E".into(), "density".into()],
            vec![(1e3, 1e7), (100.0, 10_000.0)],
        )
        .unwrap();
        let g = LogGridInit {
            candidates: 20,
            parallel: false,
            ..Default::default()
        };
        assert_eq!(g.points_per_axis(2), 4);
        let pts = g.sample(&space).unwrap();
        assert_eq!(pts.len(), 16);
        // E's cells are decades 1e3..1e4, ..: centres at 10^3.5, 10^4.5, ...
        let es: Vec<f64> = pts.iter().step_by(4).map(|p| p[0].log10()).collect();
        for (e, want) in es.iter().zip([3.5, 4.5, 5.5, 6.5]) {
            assert!((e - want).abs() < 1e-12, "{es:?}");
        }
        let out = g
            .initialize(&space, &|_, t| {
                Ok(-((t[0].log10() - 5.4).abs() + (t[1].log10() - 2.3).abs()))
            })
            .unwrap();
        let best = &out.best;
        assert!((best[0].log10() - 5.5).abs() < 1e-9 && (best[1].log10() - 2.25).abs() < 1e-9);
        // One parameter, fewer candidates than cells of two: the box's centre.
        let one = LogGridInit {
            candidates: 1,
            ..Default::default()
        };
        let c = one.sample(&space).unwrap();
        assert_eq!(c.len(), 1);
        assert!((c[0][0].log10() - 5.0).abs() < 1e-12);
        let none = LogGridInit {
            candidates: 0,
            ..Default::default()
        };
        assert!(matches!(none.sample(&space), Err(Error::NoCandidates)));
    }

    /// Any sampler is an initializer: the trait's evaluation, failure handling and ranking
    /// come with `candidates` and `top_k`.
    #[test]
    fn a_custom_sampler_plugs_into_the_trait() {
        struct Grid;
        impl Initializer for Grid {
            fn candidates(&self, _space: &SearchSpace) -> Result<Vec<Vec<f64>>, Error> {
                Ok(vec![vec![1.0], vec![10.0], vec![100.0], vec![f64::NAN]])
            }
            fn top_k(&self) -> usize {
                2
            }
        }
        let space = SearchSpace::new(vec!["E".into()], vec![(1.0, 1e3)]).unwrap();
        let seen = Mutex::new(Vec::new());
        let init: &dyn Initializer = &Grid;
        let out = init
            .initialize_with(
                &space,
                &|_, t| {
                    if t[0].is_nan() {
                        Err("no value".into())
                    } else {
                        Ok(-(t[0].log10() - 1.2).abs())
                    }
                },
                &|c| seen.lock().unwrap().push(c.index),
            )
            .unwrap();
        assert_eq!(out.best, vec![10.0]);
        assert_eq!(out.top_k, vec![1, 2]);
        assert_eq!(out.failed().count(), 1);
        assert_eq!(*seen.lock().unwrap(), vec![0, 1, 2, 3]);
        assert_eq!(
            init.initialize(&space, &|_, _| Ok(0.0))
                .unwrap()
                .ranking
                .len(),
            4
        );
    }

    fn space3() -> SearchSpace {
        SearchSpace::new(
            vec!["E".into(), "yield_stress".into(), "density".into()],
            vec![(1e3, 1e7), (1e2, 1e6), (1e2, 1e4)],
        )
        .unwrap()
    }

    /// Peak at E = 1e5, yield stress = 1e4, density = 1e3 (in log10 units).
    fn peak(_: usize, t: &[f64]) -> Result<f64, String> {
        let target = [5.0, 4.0, 3.0];
        Ok(-t
            .iter()
            .zip(target)
            .map(|(x, c)| (x.log10() - c).powi(2))
            .sum::<f64>())
    }

    #[test]
    fn search_space_validation_names_the_parameter() {
        let e = SearchSpace::new(vec!["E".into(), "nu".into()], vec![(1e3, 1e7), (0.0, 0.49)])
            .unwrap_err();
        assert!(matches!(&e, Error::InvalidBounds { name, .. } if name == "nu"));
        assert!(e.to_string().contains("'nu'"), "{e}");
        for bad in [
            (-1.0, 2.0),
            (2.0, 1.0),
            (1.0, f64::INFINITY),
            (f64::NAN, 1.0),
        ] {
            let e = SearchSpace::new(vec!["density".into()], vec![bad]).unwrap_err();
            assert!(e.to_string().contains("'density'"), "{e}");
        }
        let e = SearchSpace::new(vec!["E".into()], vec![]).unwrap_err();
        assert!(matches!(e, Error::InvalidSpace(_)), "{e}");
        let e = SearchSpace::new(vec!["E".into(), "E".into()], vec![(1.0, 2.0); 2]).unwrap_err();
        assert!(e.to_string().contains("'E'"), "{e}");
        // An invalid space built by hand is caught by the initialiser too.
        let raw = SearchSpace {
            names: vec!["E".into()],
            bounds: vec![(0.0, 1.0)],
        };
        assert!(LatinHypercubeInit::default()
            .initialize(&raw, &peak)
            .is_err());
        let k = SearchSpace::from_kinds(&ParamKind::ALL).unwrap();
        assert_eq!(k.dims(), ParamKind::ALL.len());
        assert_eq!(k.names[1], "nu");
        assert_eq!(k.bounds[1], (0.01, 0.49));
    }

    /// The natural-scale sampler uses the Latin hypercube's strata: uniform over a linear
    /// parameter (half the candidates above the midpoint), log-uniform over the others, all
    /// inside the bounds; a flag count that does not match the space is refused.
    #[test]
    fn natural_scale_samples_poisson_ratio_uniformly() {
        let space = SearchSpace::new(
            vec!["E".into(), "nu".into()],
            vec![(1e3, 1e7), (0.01, 0.49)],
        )
        .unwrap();
        let init = NaturalScaleInit {
            lhs: LatinHypercubeInit {
                candidates: 40,
                seed: 3,
                ..Default::default()
            },
            linear: vec![false, true],
        };
        let pts = init.sample(&space).unwrap();
        assert_eq!(pts.len(), 40);
        assert!(pts
            .iter()
            .all(|p| p[0] >= 1e3 && p[0] <= 1e7 && p[1] >= 0.01 && p[1] <= 0.49));
        assert_eq!(pts.iter().filter(|p| p[1] > 0.25).count(), 20);
        assert_eq!(pts.iter().filter(|p| p[0] > 1e5).count(), 20);
        let log = init.lhs.sample(&space).unwrap();
        assert_eq!(log.iter().filter(|p| p[1] > 0.07).count(), 20);
        let bad = NaturalScaleInit {
            linear: vec![true],
            ..init
        };
        assert!(bad.sample(&space).is_err());
    }

    #[test]
    fn every_candidate_respects_the_bounds() {
        let space = SearchSpace::from_kinds(&ParamKind::ALL).unwrap();
        for (n, seed) in [(1usize, 0u64), (7, 1), (32, 2), (200, 3)] {
            let init = LatinHypercubeInit {
                candidates: n,
                seed,
                ..Default::default()
            };
            let pts = init.sample(&space).unwrap();
            assert_eq!(pts.len(), n);
            for p in &pts {
                assert!(space.contains(p), "{p:?}");
            }
            // One candidate per log10 stratum in every dimension.
            for (d, &(lo, hi)) in space.bounds.iter().enumerate() {
                let mut strata: Vec<usize> = pts
                    .iter()
                    .map(|p| {
                        let u = (p[d].log10() - lo.log10()) / (hi.log10() - lo.log10());
                        ((u * n as f64).floor() as usize).min(n - 1)
                    })
                    .collect();
                strata.sort();
                // Rounding in log10/pow can move a point across a stratum edge by ~1 ulp, so
                // allow a neighbour; the exact property is tested on the unit hypercube.
                for (k, s) in strata.iter().enumerate() {
                    assert!(s.abs_diff(k) <= 1, "dim {d}: stratum {s} at rank {k}");
                }
            }
        }
        // Degenerate bounds give the bound itself.
        let fixed = SearchSpace::new(vec!["nu".into()], vec![(0.3, 0.3)]).unwrap();
        let pts = LatinHypercubeInit::default().sample(&fixed).unwrap();
        assert!(pts.iter().all(|p| p == &vec![0.3]));
    }

    #[test]
    fn picks_the_best_of_a_known_score_function() {
        let space = space3();
        let init = LatinHypercubeInit {
            candidates: 64,
            seed: 11,
            ..Default::default()
        };
        let out = init.initialize(&space, &peak).unwrap();
        assert_eq!(out.candidates.len(), 64);
        assert_eq!(out.ranking.len(), 64);
        assert_eq!(out.top_k.len(), 4);
        assert_eq!(out.top_k[..], out.ranking[..4]);
        // Brute force: the best is the arg max of the scores, the ranking is sorted.
        let scores: Vec<f64> = out.candidates.iter().map(|c| c.score.unwrap()).collect();
        let argmax = (0..64).fold(0, |b, i| if scores[i] > scores[b] { i } else { b });
        assert_eq!(out.ranking[0], argmax);
        assert_eq!(out.best, out.candidates[argmax].theta);
        assert!(out.ranking.windows(2).all(|w| scores[w[0]] >= scores[w[1]]));
        for (i, c) in out.candidates.iter().enumerate() {
            assert_eq!(c.index, i);
            assert_eq!(c.score, peak(i, &c.theta).ok());
            assert!(c.error.is_none());
        }
        // Each stratum is 1/64 of the range (4, 4 and 2 decades): the best point is close to
        // the peak in every coordinate only if the sampler covers the space.
        let d = peak(0, &out.best).unwrap();
        assert!(d > -1.0, "best score {d}, best {:?}", out.best);
        assert_eq!(out.top_candidates().len(), 4);
        assert_eq!(out.top_candidates()[0].theta, out.best);
        assert_eq!(out.failed().count(), 0);
        // The outcome round-trips through serde.
        let json = serde_json::to_string(&out).unwrap();
        let back: InitOutcome = serde_json::from_str(&json).unwrap();
        assert_eq!(back, out);
    }

    #[test]
    fn parallel_equals_sequential_and_include_is_evaluated() {
        let space = space3();
        let start = vec![1e5, 1e4, 1e3];
        let base = LatinHypercubeInit {
            candidates: 40,
            seed: 5,
            top_k: 6,
            parallel: false,
            max_concurrent: None,
            include: vec![start.clone()],
        };
        // Some failures, a slow candidate so completion order differs from index order.
        let eval = |i: usize, t: &[f64]| -> Result<f64, String> {
            if i % 7 == 3 {
                return Err(format!("candidate {i} exploded"));
            }
            if i % 11 == 4 {
                return Ok(f64::NAN);
            }
            if i == 0 {
                std::thread::sleep(std::time::Duration::from_millis(20));
            }
            peak(i, t)
        };
        let seq = base.initialize(&space, &eval).unwrap();
        let par_init = LatinHypercubeInit {
            parallel: true,
            ..base.clone()
        };
        let order = Mutex::new(Vec::new());
        let par = par_init
            .initialize_with(&space, &eval, &|c| order.lock().unwrap().push(c.index))
            .unwrap();
        assert_eq!(seq, par);
        // At most two at once on a pool of four threads: the same outcome.
        let (now, most) = (AtomicUsize::new(0), AtomicUsize::new(0));
        let counted = |i: usize, t: &[f64]| -> Result<f64, String> {
            let k = now.fetch_add(1, Ordering::SeqCst) + 1;
            most.fetch_max(k, Ordering::SeqCst);
            std::thread::sleep(std::time::Duration::from_millis(2));
            let r = eval(i, t);
            now.fetch_sub(1, Ordering::SeqCst);
            r
        };
        let bounded = LatinHypercubeInit {
            parallel: true,
            max_concurrent: Some(2),
            ..base.clone()
        };
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(4)
            .build()
            .unwrap();
        let two = pool.install(|| bounded.initialize(&space, &counted).unwrap());
        assert_eq!(seq, two);
        assert!(most.load(Ordering::SeqCst) <= 2, "{most:?} at once");
        let mut order = order.into_inner().unwrap();
        order.sort();
        assert_eq!(order, (0..41).collect::<Vec<_>>());
        // The included start is candidate 40, is the exact peak, so it wins.
        assert_eq!(seq.candidates[40].theta, start);
        assert_eq!(seq.ranking[0], 40);
        assert_eq!(seq.best, start);
        // The LHS part is the same as without `include`, and a different seed changes it.
        let no_inc = LatinHypercubeInit {
            include: vec![],
            ..base.clone()
        };
        let lhs_part: Vec<Vec<f64>> = seq.candidates[..40]
            .iter()
            .map(|c| c.theta.clone())
            .collect();
        assert_eq!(no_inc.sample(&space).unwrap(), lhs_part);
        let other = LatinHypercubeInit { seed: 6, ..no_inc };
        assert_ne!(other.sample(&space).unwrap(), lhs_part);
    }

    #[test]
    fn failures_are_recorded_and_skipped() {
        let space = space3();
        let init = LatinHypercubeInit {
            candidates: 20,
            seed: 1,
            top_k: 30,
            ..Default::default()
        };
        let calls = AtomicUsize::new(0);
        let eval = |i: usize, t: &[f64]| -> Result<f64, String> {
            calls.fetch_add(1, Ordering::Relaxed);
            match i % 4 {
                0 => Err(format!("simulation exploded at step {i}")),
                1 => Ok(f64::NAN),
                _ => peak(i, t),
            }
        };
        let out = init.initialize(&space, &eval).unwrap();
        assert_eq!(calls.load(Ordering::Relaxed), 20);
        assert_eq!(out.candidates.len(), 20);
        assert_eq!(out.ranking.len(), 10);
        // top_k larger than the scored count: all of them.
        assert_eq!(out.top_k, out.ranking);
        assert!(out.ranking.iter().all(|&i| i % 4 >= 2));
        let failed: Vec<usize> = out.failed().map(|c| c.index).collect();
        assert_eq!(failed, (0..20).filter(|i| i % 4 < 2).collect::<Vec<_>>());
        assert_eq!(
            out.candidates[4].error.as_deref(),
            Some("simulation exploded at step 4")
        );
        assert_eq!(out.candidates[5].error.as_deref(), Some("score is NaN"));
        assert_eq!(out.candidates[5].score, None);
    }

    #[test]
    fn all_failed_is_a_typed_error_with_the_first_failure() {
        let space = space3();
        for parallel in [false, true] {
            let init = LatinHypercubeInit {
                candidates: 8,
                parallel,
                ..Default::default()
            };
            let eval = |i: usize, _: &[f64]| -> Result<f64, String> {
                if i == 2 {
                    Ok(f64::NAN)
                } else {
                    Err(format!("exploded (candidate {i})"))
                }
            };
            let e = init.initialize(&space, &eval).unwrap_err();
            match &e {
                Error::AllCandidatesFailed {
                    count,
                    index,
                    message,
                } => {
                    assert_eq!((*count, *index), (8, 0));
                    assert_eq!(message, "exploded (candidate 0)");
                }
                other => panic!("unexpected error {other:?}"),
            }
            assert!(e.to_string().contains("all 8"), "{e}");
        }
        let none = LatinHypercubeInit {
            candidates: 0,
            ..Default::default()
        };
        assert!(matches!(
            none.initialize(&space, &peak),
            Err(Error::NoCandidates)
        ));
    }

    #[test]
    fn ties_keep_the_lower_index_first() {
        let space = space3();
        let init = LatinHypercubeInit {
            candidates: 12,
            ..Default::default()
        };
        // Scores 0, 1, 2, 0, 1, 2, ... with -0.0 tying with 0.0.
        let eval = |i: usize, _: &[f64]| -> Result<f64, String> {
            Ok(match i % 3 {
                0 if i % 2 == 1 => -0.0,
                r => r as f64,
            })
        };
        let out = init.initialize(&space, &eval).unwrap();
        assert_eq!(out.ranking, vec![2, 5, 8, 11, 1, 4, 7, 10, 0, 3, 6, 9]);
        assert_eq!(out.top_k, vec![2, 5, 8, 11]);
        assert_eq!(out.best, out.candidates[2].theta);
    }

    #[test]
    fn bad_include_points_are_rejected_by_name() {
        let space = space3();
        let wrong_len = LatinHypercubeInit {
            include: vec![vec![1e5, 1e4]],
            ..Default::default()
        };
        let e = wrong_len.sample(&space).unwrap_err();
        assert!(
            matches!(e, Error::InvalidInclude { position: 0, .. }),
            "{e}"
        );
        let outside = LatinHypercubeInit {
            include: vec![vec![1e5, 1e4, 1e3], vec![1e5, 1e4, 5e4]],
            ..Default::default()
        };
        let e = outside.sample(&space).unwrap_err();
        assert!(
            matches!(e, Error::InvalidInclude { position: 1, .. }),
            "{e}"
        );
        assert!(e.to_string().contains("'density'"), "{e}");
        // Only included points, no samples.
        let only = LatinHypercubeInit {
            candidates: 0,
            include: vec![vec![1e5, 1e4, 1e3]],
            ..Default::default()
        };
        let out = only.initialize(&space, &peak).unwrap();
        assert_eq!(out.best, vec![1e5, 1e4, 1e3]);
    }

    #[test]
    fn config_deserialises_with_defaults() {
        let c: LatinHypercubeInit = serde_json::from_str(r#"{"seed": 3}"#).unwrap();
        assert_eq!(
            c,
            LatinHypercubeInit {
                seed: 3,
                ..Default::default()
            }
        );
        assert_eq!(c.candidates, 32);
        assert_eq!(c.top_k, 4);
        assert!(c.parallel);
    }
}
