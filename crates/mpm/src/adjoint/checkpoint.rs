//! Checkpointed reverse sweep over a whole trajectory, written once and generic over any
//! stepper that can run a substep and its VJP ([`Differentiable`]).
//!
//! # Strategies, memory and recompute cost
//!
//! Let `K` be the number of substeps, `S` the bytes of one simulation state (particles:
//! `x, v, C, F, plastic` = 26 scalars per particle) and `k` the checkpoint interval.
//!
//! | strategy | `k` | states held at peak | forward substeps re-run by the backward pass |
//! |---|---|---|---|
//! | [`Checkpointing::StoreAll`] | 1 | `K + 3` | 0 |
//! | [`Checkpointing::PerFrame`] | substeps per frame | `ceil(K / k) + k + 1` | `K - ceil(K / k)` |
//! | [`Checkpointing::EveryN`]`(k)` | `k` | `ceil(K / k) + k + 1` | `K - ceil(K / k)` |
//! | [`Checkpointing::Nested`]`(n)` | frame `f`, then `n` | `ceil(K / f) + ceil(f / n) + n + 1` | about `2 K` |
//!
//! Every VJP re-runs its own substep forward to rebuild the grid and the stress (one extra
//! forward substep per backward substep in all strategies), so with checkpointing a backward
//! pass costs about two forward passes plus the reverse arithmetic. `k = sqrt(K)` minimises
//! the memory of `EveryN`: for 16 frames of 400 substeps, `k = 80` keeps 161 states instead
//! of 6401; `Nested(20)` keeps 17 + 20 + 21 = 58 (frame boundaries, the inner checkpoints
//! of one frame, one piece) for one more forward pass. [`memory_plan`] evaluates these formulas for a configuration.

/// One differentiable substep and its adjoint, fallible with the backend's error (a device
/// lost, out of memory); host backends use [`std::convert::Infallible`].
pub trait Differentiable {
    /// Simulation state.
    type State;
    /// Parameters.
    type Params;
    /// Parameter gradient (accumulated).
    type Grad;
    /// What can go wrong.
    type Error: std::error::Error + Send + Sync + 'static;
    /// Advances `s` by substep `k`.
    fn step(&self, s: &mut Self::State, p: &Self::Params, k: u64) -> Result<(), Self::Error>;
    /// Reverse sweep of substep `k`: `before` is the state at its start; `adj` holds the
    /// adjoint after it on entry and before it on return; gradients are added to `grad`.
    fn step_vjp(
        &self,
        before: &Self::State,
        p: &Self::Params,
        k: u64,
        adj: &mut Self::State,
        grad: &mut Self::Grad,
    ) -> Result<(), Self::Error>;
    /// A zero adjoint shaped like `s`.
    fn zero_adjoint(&self, s: &Self::State) -> Result<Self::State, Self::Error>;
    /// A copy of `s` (a checkpoint).
    fn clone_state(&self, s: &Self::State) -> Result<Self::State, Self::Error>;
}

/// Which states the forward pass keeps for the backward pass.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Checkpointing {
    /// Keep every substep's state (fastest, memory grows with the substep count).
    StoreAll,
    /// Keep frame boundaries; recompute a frame's substeps during the backward pass.
    PerFrame,
    /// Keep every `n`-th substep (`n = sqrt(total substeps)` minimises memory).
    EveryN(u32),
    /// Two levels: keep frame boundaries in the forward pass; in the backward pass re-run a
    /// frame keeping every `n`-th substep, then re-run each of those `n`-substep pieces
    /// keeping all its states (`n = sqrt(substeps per frame)` minimises memory). One more
    /// forward pass than [`Checkpointing::PerFrame`], far fewer states than any single level.
    Nested(u32),
}

impl Checkpointing {
    /// Parses the one spelling every command and `FIT.toml` accept: `per_frame`, `store_all`,
    /// `every_n:K` (or `every:K`), `nested:K` with `K >= 1` (dashes for underscores too);
    /// the error says what is accepted.
    pub fn parse(s: &str) -> Result<Checkpointing, String> {
        let t = s.trim().replace('-', "_");
        let num = |p: &str| t.strip_prefix(p).map(|n| n.trim().parse::<u32>());
        let bad = || {
            format!(
                "checkpointing '{s}': use per_frame, store_all, every_n:K or nested:K with K >= 1"
            )
        };
        match t.as_str() {
            "per_frame" => Ok(Checkpointing::PerFrame),
            "store_all" => Ok(Checkpointing::StoreAll),
            _ => match (num("every_n:").or_else(|| num("every:")), num("nested:")) {
                (Some(Ok(n)), _) if n > 0 => Ok(Checkpointing::EveryN(n)),
                (_, Some(Ok(n))) if n > 0 => Ok(Checkpointing::Nested(n)),
                _ => Err(bad()),
            },
        }
    }

    /// The checkpoint interval in substeps.
    pub fn interval(self, substeps_per_frame: u32) -> u64 {
        match self {
            Checkpointing::StoreAll => 1,
            Checkpointing::PerFrame => substeps_per_frame.max(1) as u64,
            Checkpointing::EveryN(n) => n.max(1) as u64,
            Checkpointing::Nested(_) => substeps_per_frame.max(1) as u64,
        }
    }
}

/// Predicted peak memory of a forward + backward pass.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct MemoryPlan {
    /// Bytes of one simulation state.
    pub state_bytes: u64,
    /// Checkpoints kept by the forward pass.
    pub checkpoints: u64,
    /// States held while a segment is re-run in the backward pass.
    pub segment_states: u64,
    /// Bytes of the grid and its adjoint (two grids of `[4 scalars]` per node, plus the
    /// scattered copy the VJP keeps).
    pub grid_bytes: u64,
    /// Bytes of per-particle scratch of one substep's VJP (intermediates and adjoints).
    pub scratch_bytes: u64,
    /// Total predicted peak.
    pub peak_bytes: u64,
}

/// Predicts the peak memory of a checkpointed forward + backward pass of `substeps` substeps
/// of `particles` particles on an `n_grid^3` grid, with `scalar_bytes` per scalar (4 for f32,
/// 8 for f64).
pub fn memory_plan(
    particles: u64,
    n_grid: u64,
    substeps: u64,
    substeps_per_frame: u32,
    strategy: Checkpointing,
    scalar_bytes: u64,
) -> MemoryPlan {
    let state_bytes = particles * 26 * scalar_bytes;
    let k = strategy.interval(substeps_per_frame).min(substeps.max(1));
    let checkpoints = substeps.div_ceil(k) + 1;
    let segment_states = match strategy {
        // Inner checkpoints of one frame plus one inner piece's states.
        Checkpointing::Nested(n) => {
            let n = (n.max(1) as u64).min(k);
            k.div_ceil(n) + n + 1
        }
        _ => k + 1,
    };
    let grid_bytes = 4 * n_grid * n_grid * n_grid * 4 * scalar_bytes;
    // Per particle: the adjoint state (26), the saved intermediates (mass, v1, stress,
    // x, F_trial, F_elastic, plastic = 1 + 3 + 9 + 3 + 9 + 9 + 2) and the new state (26).
    let scratch_bytes = particles * (26 + 36 + 26) * scalar_bytes;
    let peak_bytes = (checkpoints + segment_states) * state_bytes + grid_bytes + scratch_bytes;
    MemoryPlan {
        state_bytes,
        checkpoints,
        segment_states,
        grid_bytes,
        scratch_bytes,
        peak_bytes,
    }
}

/// Runs `substeps` substeps forward from `init`, calling `frame_loss(frame, state)` at every
/// frame boundary (frames 1 ..), keeping checkpoints per `strategy`; then the reverse sweep,
/// where `frame_adjoint(frame, state, adj)` adds the loss gradient at each frame boundary.
/// Returns the total loss, the adjoint of the initial state and the parameter gradient.
#[allow(clippy::too_many_arguments)]
pub fn value_and_grad<D: Differentiable + ?Sized>(
    d: &D,
    init: &D::State,
    params: &D::Params,
    substeps: u64,
    substeps_per_frame: u32,
    strategy: Checkpointing,
    mut grad: D::Grad,
    mut frame_loss: impl FnMut(usize, &D::State) -> f64,
    mut frame_adjoint: impl FnMut(usize, &D::State, &mut D::State),
) -> Result<(f64, D::State, D::Grad), D::Error> {
    let spf = substeps_per_frame.max(1) as u64;
    let k = strategy.interval(substeps_per_frame);
    // Forward with checkpoints.
    let mut checkpoints = vec![d.clone_state(init)?];
    let mut s = d.clone_state(init)?;
    let mut loss = 0.0;
    for j in 0..substeps {
        d.step(&mut s, params, j)?;
        if (j + 1) % spf == 0 {
            loss += frame_loss(((j + 1) / spf) as usize, &s);
        }
        if (j + 1) % k == 0 && j + 1 < substeps {
            checkpoints.push(d.clone_state(&s)?);
        }
    }
    // Backward, segment by segment.
    let mut adj = d.zero_adjoint(init)?;
    let segments = substeps.div_ceil(k);
    let inner = match strategy {
        Checkpointing::Nested(n) => (n.max(1) as u64).min(k),
        _ => k,
    };
    for seg in (0..segments).rev() {
        let start = seg * k;
        let end = ((seg + 1) * k).min(substeps);
        let last = match checkpoints.get(seg as usize + 1) {
            Some(c) => c,
            None => &s,
        };
        if inner >= end - start {
            reverse_piece(
                d,
                &checkpoints[seg as usize],
                last,
                params,
                start,
                end,
                spf,
                &mut adj,
                &mut grad,
                &mut frame_adjoint,
            )?;
            continue;
        }
        // Nested: checkpoints every `inner` substeps inside the segment, then each piece.
        let mut inner_cks = vec![d.clone_state(&checkpoints[seg as usize])?];
        let mut t = d.clone_state(&checkpoints[seg as usize])?;
        for j in start..end - 1 {
            d.step(&mut t, params, j)?;
            if (j + 1 - start) % inner == 0 {
                inner_cks.push(d.clone_state(&t)?);
            }
        }
        drop(t);
        let pieces = (end - start).div_ceil(inner);
        for piece in (0..pieces).rev() {
            let a = start + piece * inner;
            let b = (a + inner).min(end);
            let piece_last = match inner_cks.get(piece as usize + 1) {
                Some(c) => c,
                None => last,
            };
            reverse_piece(
                d,
                &inner_cks[piece as usize],
                piece_last,
                params,
                a,
                b,
                spf,
                &mut adj,
                &mut grad,
                &mut frame_adjoint,
            )?;
        }
    }
    Ok((loss, adj, grad))
}

/// Reverse sweep of substeps `start..end` given the states at both ends: re-runs the piece
/// keeping every state (the end state is `last`, not re-run), then the VJPs in reverse, with
/// `frame_adjoint` at each frame boundary.
#[allow(clippy::too_many_arguments)]
fn reverse_piece<D: Differentiable + ?Sized>(
    d: &D,
    first: &D::State,
    last: &D::State,
    params: &D::Params,
    start: u64,
    end: u64,
    spf: u64,
    adj: &mut D::State,
    grad: &mut D::Grad,
    frame_adjoint: &mut impl FnMut(usize, &D::State, &mut D::State),
) -> Result<(), D::Error> {
    let mut states = Vec::with_capacity((end - start + 1) as usize);
    states.push(d.clone_state(first)?);
    for j in start..end - 1 {
        let mut next = d.clone_state(states.last().expect("piece start"))?;
        d.step(&mut next, params, j)?;
        states.push(next);
    }
    states.push(d.clone_state(last)?);
    for j in (start..end).rev() {
        if (j + 1) % spf == 0 {
            let local = (j + 1 - start) as usize;
            frame_adjoint(((j + 1) / spf) as usize, &states[local], adj);
        }
        d.step_vjp(&states[(j - start) as usize], params, j, adj, grad)?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::cell::Cell;

    /// A scalar linear recurrence x <- a x + p with a counter of forward steps.
    struct Toy {
        a: f64,
        steps: Cell<u64>,
    }
    impl Differentiable for Toy {
        type State = f64;
        type Params = f64;
        type Grad = f64;
        type Error = std::convert::Infallible;
        fn step(&self, s: &mut f64, p: &f64, _k: u64) -> Result<(), Self::Error> {
            self.steps.set(self.steps.get() + 1);
            *s = self.a * *s + p;
            Ok(())
        }
        fn step_vjp(
            &self,
            _b: &f64,
            _p: &f64,
            _k: u64,
            adj: &mut f64,
            grad: &mut f64,
        ) -> Result<(), Self::Error> {
            *grad += *adj;
            *adj *= self.a;
            Ok(())
        }
        fn zero_adjoint(&self, _s: &f64) -> Result<f64, Self::Error> {
            Ok(0.0)
        }
        fn clone_state(&self, s: &f64) -> Result<f64, Self::Error> {
            Ok(*s)
        }
    }

    #[test]
    fn every_strategy_gives_the_same_gradient_and_the_documented_recompute() {
        let mut results = Vec::new();
        for strategy in [
            Checkpointing::StoreAll,
            Checkpointing::PerFrame,
            Checkpointing::EveryN(7),
            Checkpointing::Nested(6),
        ] {
            let toy = Toy {
                a: 0.9,
                steps: Cell::new(0),
            };
            // Loss: sum over frames of the state.
            let (l, adj0, g) = value_and_grad(
                &toy,
                &1.0,
                &0.5,
                60,
                20,
                strategy,
                0.0,
                |_, s| *s,
                |_, _, adj| *adj += 1.0,
            )
            .unwrap();
            // Forward 60, then the documented recompute K - ceil(K / k).
            let expect = match strategy {
                Checkpointing::StoreAll => 60,
                Checkpointing::PerFrame => 60 + 60 - 3,
                Checkpointing::EveryN(_) => 60 + 60 - 9,
                // Frames of 20: the inner checkpoint pass re-runs 19 per frame, then pieces
                // of 6, 6, 6, 2 re-run 5 + 5 + 5 + 1.
                Checkpointing::Nested(_) => 60 + 3 * 19 + 3 * 16,
            };
            assert_eq!(toy.steps.get(), expect, "{strategy:?}");
            results.push((l, adj0, g));
        }
        // Analytic: x_n = a^n x0 + p (1 - a^n) / (1 - a); L = x_20 + x_40 + x_60.
        let (a, p) = (0.9f64, 0.5);
        let x = |n: i32| a.powi(n) + p * (1.0 - a.powi(n)) / (1.0 - a);
        let dl_dx0 = a.powi(20) + a.powi(40) + a.powi(60);
        let dl_dp = [20, 40, 60]
            .iter()
            .map(|&n| (1.0 - a.powi(n)) / (1.0 - a))
            .sum::<f64>();
        for (l, adj0, g) in results {
            assert!((l - (x(20) + x(40) + x(60))).abs() < 1e-12);
            assert!((adj0 - dl_dx0).abs() < 1e-12);
            assert!((g - dl_dp).abs() < 1e-10);
        }
    }

    #[test]
    fn memory_plan_follows_the_formula() {
        let all = memory_plan(1000, 32, 6400, 400, Checkpointing::StoreAll, 4);
        let per = memory_plan(1000, 32, 6400, 400, Checkpointing::PerFrame, 4);
        let sq = memory_plan(1000, 32, 6400, 400, Checkpointing::EveryN(80), 4);
        assert_eq!(all.checkpoints, 6401);
        assert_eq!(per.checkpoints + per.segment_states, 17 + 401);
        assert_eq!(sq.checkpoints + sq.segment_states, 81 + 81);
        let nested = memory_plan(1000, 32, 6400, 400, Checkpointing::Nested(20), 4);
        assert_eq!(nested.checkpoints + nested.segment_states, 17 + 20 + 21);
        assert!(nested.peak_bytes < sq.peak_bytes);
        assert!(sq.peak_bytes < per.peak_bytes && per.peak_bytes < all.peak_bytes);
    }
}
