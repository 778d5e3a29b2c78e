//! A fit's overall budget (`budget = "15m"` and `evals = N` in FIT.toml): once either is spent
//! the fit starts no new unit of work (a descent iteration, a multi-start iteration, a round
//! of a refining stage, a restart) and ends with the lowest point so far. The initialisation
//! always completes (its candidates count). What was spent is kept in the checkpoint
//! (`FitState::elapsed_s`, `FitState::evals_done`, only while the budget is set), so a
//! resumed fit spends what is left, and a larger budget extends a finished one.

use crate::record::FitState;
use crate::FitError;
use std::time::Instant;

/// Seconds of a duration written `90s`, `15m`, `1h`, `1h30m` or `2.5m` (a bare number is
/// seconds).
pub fn parse_duration(text: &str) -> Result<f64, String> {
    let t = text.trim();
    let form = || format!("'{text}': expected a duration such as 90s, 15m, 1h or 1h30m");
    if let Ok(v) = t.parse::<f64>() {
        return (v.is_finite() && v > 0.0).then_some(v).ok_or_else(form);
    }
    let (mut total, mut num) = (0.0f64, String::new());
    for c in t.chars() {
        match c {
            '0'..='9' | '.' => num.push(c),
            'h' | 'm' | 's' => {
                let v: f64 = num.parse().map_err(|_| form())?;
                total += v * match c {
                    'h' => 3600.0,
                    'm' => 60.0,
                    _ => 1.0,
                };
                num.clear();
            }
            _ => return Err(form()),
        }
    }
    if !(num.is_empty() && total.is_finite() && total > 0.0) {
        return Err(form());
    }
    Ok(total)
}

/// The budget of one run of a fit, with what earlier sittings spent.
pub(crate) struct Budget {
    limit_s: Option<f64>,
    limit_evals: Option<usize>,
    start: Instant,
    before_s: f64,
    before_evals: usize,
    /// Evaluations of objectives other than the fit's (the initialisation's candidates).
    extra_evals: usize,
}

impl Budget {
    /// The budget of `budget` / `evals` (checked by [`crate::video::FitConfig::validate`]),
    /// continuing from what `state` records as spent.
    pub(crate) fn new(
        budget: &Option<String>,
        evals: Option<usize>,
        state: &FitState,
    ) -> Result<Budget, FitError> {
        let limit_s = match budget {
            Some(b) => {
                Some(parse_duration(b).map_err(|e| FitError::Input(format!("budget = {e}")))?)
            }
            None => None,
        };
        Ok(Budget {
            limit_s,
            limit_evals: evals,
            start: Instant::now(),
            before_s: state.elapsed_s,
            before_evals: state.evals_done,
            extra_evals: 0,
        })
    }

    /// Counts `n` evaluations of another objective (the initialisation's candidates).
    pub(crate) fn add_evals(&mut self, n: usize) {
        self.extra_evals += n;
    }

    /// Evaluations spent over every sitting: the fit's `fit_evals` of this sitting, the
    /// other objectives' and the earlier sittings'.
    pub(crate) fn evals(&self, fit_evals: usize) -> usize {
        self.before_evals + self.extra_evals + fit_evals
    }

    fn seconds(&self) -> f64 {
        self.before_s + self.start.elapsed().as_secs_f64()
    }

    /// Whether the budget is spent, the fit's objective having run `fit_evals` evaluations
    /// in this sitting.
    pub(crate) fn spent(&self, fit_evals: usize) -> bool {
        self.limit_evals.is_some_and(|l| self.evals(fit_evals) >= l)
            || self.limit_s.is_some_and(|l| self.seconds() >= l)
    }

    /// Writes what was spent into the checkpoint (only the parts that are limited: a fit
    /// without a budget writes the same state as before budgets existed).
    /// Evaluations left under `evals` (`None` without an evaluation budget): a stage whose
    /// rounds take many evaluations caps a round with it.
    pub(crate) fn evals_left(&self, fit_evals: usize) -> Option<usize> {
        self.limit_evals
            .map(|l| l.saturating_sub(self.evals(fit_evals)))
    }

    /// Whether `share` (in (0, 1]) of the budget is spent: the descent's end when the
    /// refining stages after it get the rest (`descent_share`).
    pub(crate) fn spent_share(&self, fit_evals: usize, share: f64) -> bool {
        self.limit_evals
            .is_some_and(|l| self.evals(fit_evals) as f64 >= share * l as f64)
            || self.limit_s.is_some_and(|l| self.seconds() >= share * l)
    }

    pub(crate) fn stamp(&self, state: &mut FitState, fit_evals: usize) {
        if self.limit_evals.is_some() {
            state.evals_done = self.evals(fit_evals);
        }
        if self.limit_s.is_some() {
            state.elapsed_s = self.seconds();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn durations_parse_and_bad_ones_are_refused() {
        assert_eq!(parse_duration("90s").unwrap(), 90.0);
        assert_eq!(parse_duration("15m").unwrap(), 900.0);
        assert_eq!(parse_duration("1h30m").unwrap(), 5400.0);
        assert_eq!(parse_duration("2.5m").unwrap(), 150.0);
        assert_eq!(parse_duration("42").unwrap(), 42.0);
        for bad in ["", "0", "0s", "15 min", "m", "1h30", "-5m", "inf"] {
            assert!(parse_duration(bad).is_err(), "{bad}");
        }
    }
}
