//! One iteration record and one checkpoint for every fit.
//!
//! The trajectory fit (`r4d fit-trajectory`) and the video fit (`r4d fit`) write the same
//! line to `log.jsonl` ([`IterRecord`]) and the same `checkpoint.json` ([`FitState`]). A
//! checkpoint carries its format version ([`STATE_FORMAT`]), a fingerprint of everything the
//! fit it belongs to depends on (inputs and settings, [`Fingerprint`]; the iteration count
//! excepted, so that a finished run can be extended) and a checksum of its own content:
//! [`FitState::from_json`] refuses a file of another format or a damaged one, and
//! [`FitState::check`] refuses one written for other inputs, naming what differs.
//!
//! ```
//! use r4d_optim::record::{Fingerprint, FitState};
//! let mut f = Fingerprint::new();
//! f.text("inputs");
//! let state = FitState::new(vec!["E[0]".into()], f.finish());
//! let text = state.to_json();
//! let back = FitState::from_json(&text).unwrap();
//! assert_eq!(back.iters_done, 0);
//! // One changed digit is damage, not a different run.
//! let damaged = text.replacen("\"iters_done\":0", "\"iters_done\":7", 1);
//! assert!(FitState::from_json(&damaged).unwrap_err().to_string().contains("checksum"));
//! ```

use crate::space::ParamSpace;
use crate::{
    FitError, GradientSampling, InitOutcome, LogDomainOptimizer, ShearRestarts, TrustRegionBfgs,
    ValleySearch,
};
pub use r4d_fsio::Fingerprint;
use r4d_mpm::PartParams;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// The format version of [`FitState`] this build writes and reads (1: the first versioned
/// format, shared by both fits; unversioned files are refused with a message saying so).
pub const STATE_FORMAT: u32 = 1;

/// Mixes anything serializable into `f`, through its JSON form (exact for floats).
pub fn mix_json(f: &mut Fingerprint, v: &impl Serialize) {
    match serde_json::to_string(v) {
        Ok(s) => f.text(&s),
        // Not reachable for the plain data structures fingerprinted here; mixed in as a
        // marker rather than ignored.
        Err(e) => f.text(&format!("unserializable: {e}")),
    }
}

/// Everything a killed fit needs to continue exactly where it stopped (`checkpoint.json` of
/// `r4d fit` and `r4d fit-trajectory`). Write it with [`FitState::to_json`], read it with
/// [`FitState::from_json`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FitState {
    /// Format version ([`STATE_FORMAT`]); 0 in files written before versioning.
    #[serde(default)]
    pub format: u32,
    /// Fingerprint of the fit's inputs and settings (see the module docs).
    #[serde(default)]
    pub fingerprint: String,
    /// Names of the free parameters (checked on resume).
    pub names: Vec<String>,
    /// The initialisation's result, once done (video fits).
    pub init: Option<InitOutcome>,
    /// Iterations completed.
    pub iters_done: usize,
    /// The optimiser (log parameters, moments, step count); `None` before the first
    /// iteration.
    pub optimizer: Option<LogDomainOptimizer>,
    /// Lowest loss evaluated and its free parameters (in the order of `names`).
    pub best: Option<(f64, Vec<f64>)>,
    /// The trust-region optimiser (`optimizer = "trust_bfgs"`), like `optimizer`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub trust: Option<TrustRegionBfgs>,
    /// The short fits of a multi-start (`multi_start > 1`), in candidate-rank order.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub starts: Vec<StartResult>,
    /// The descent's run since its last restart on a stall (`stall > 0`), once begun.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub descent: Option<DescentRun>,
    /// The descent's iterations whose evaluation diverged (the simulation exploded, a value
    /// became non-finite), in order: each was a rejected step (see
    /// `crate::video::fit::MAX_DIVERGED`).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub diverged: Vec<usize>,
    /// The valley search after the iterations (`valley.evals > 0`), once begun.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub valley: Option<ValleySearch>,
    /// Gradient sampling after the valley search (`gradient_sampling.iters > 0`), once
    /// begun.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sampling: Option<GradientSampling>,
    /// Restarts along constant bulk modulus (`shear_restarts.points > 0`), once begun.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub restarts: Option<ShearRestarts>,
    /// Wall-clock seconds the fit has spent in all its sittings, kept while a `budget` is
    /// set (`crate::video::budget`).
    #[serde(default, skip_serializing_if = "is_zero_f64")]
    pub elapsed_s: f64,
    /// Evaluations the fit has run in all its sittings, kept while `evals` is set.
    #[serde(default, skip_serializing_if = "is_zero_usize")]
    pub evals_done: usize,
    /// Checksum of the rest of the content (set by [`FitState::to_json`]).
    #[serde(default)]
    pub checksum: String,
}

fn is_zero_f64(v: &f64) -> bool {
    *v == 0.0
}

fn is_zero_usize(v: &usize) -> bool {
    *v == 0
}

impl FitState {
    /// The state of a fit that has done nothing yet.
    pub fn new(names: Vec<String>, fingerprint: String) -> FitState {
        FitState {
            format: STATE_FORMAT,
            fingerprint,
            names,
            init: None,
            iters_done: 0,
            optimizer: None,
            best: None,
            trust: None,
            starts: Vec::new(),
            descent: None,
            diverged: Vec::new(),
            valley: None,
            sampling: None,
            restarts: None,
            elapsed_s: 0.0,
            evals_done: 0,
            checksum: String::new(),
        }
    }

    /// The checksum of everything but the checksum field.
    fn content_checksum(&self) -> String {
        let mut body = self.clone();
        body.checksum.clear();
        let mut f = Fingerprint::new();
        mix_json(&mut f, &body);
        f.finish()
    }

    /// The state as one line of JSON, with its checksum (what `checkpoint.json` holds).
    pub fn to_json(&self) -> String {
        let mut s = self.clone();
        s.format = STATE_FORMAT;
        s.checksum = s.content_checksum();
        serde_json::to_string(&s).unwrap_or_else(|e| format!("unserializable state: {e}"))
    }

    /// Reads a state written by [`FitState::to_json`]: refuses text that is not a state,
    /// another format version and content that does not match its checksum (a damaged or
    /// hand-edited file), with [`FitError::Resume`] saying which.
    pub fn from_json(text: &str) -> Result<FitState, FitError> {
        let s: FitState = serde_json::from_str(text)
            .map_err(|e| FitError::Resume(format!("not a fit checkpoint: {e}")))?;
        if s.format != STATE_FORMAT {
            return Err(FitError::Resume(format!(
                "checkpoint format {} (0: written before checkpoints were versioned), this version of r4d reads format {STATE_FORMAT}; start the fit again",
                s.format
            )));
        }
        if s.checksum != s.content_checksum() {
            return Err(FitError::Resume(
                "the checksum does not match the content: the file was damaged or edited".into(),
            ));
        }
        Ok(s)
    }

    /// Checks the state against the fit that resumes from it before anything resumes: the
    /// same inputs and settings (fingerprint), the same free parameters, optimiser vectors of
    /// the right length and finite, the best point, the initialisation and the multi-start
    /// results consistent (a foreign or damaged state is [`FitError::Resume`], never a panic
    /// or a silent restart).
    pub fn check(&self, space: &ParamSpace, fingerprint: &str) -> Result<(), FitError> {
        let names = space.names();
        if self.fingerprint != fingerprint {
            return Err(FitError::Resume(format!(
                "the checkpoint was written for other inputs or settings (fingerprint {}, this run {fingerprint}): a scene, video, camera, part, target or fit setting changed since",
                if self.fingerprint.is_empty() { "none" } else { &self.fingerprint }
            )));
        }
        if self.names != names {
            return Err(FitError::Resume(format!(
                "the checkpoint fits {} parameters ({}...), this run {} ({}...)",
                self.names.len(),
                self.names.first().cloned().unwrap_or_default(),
                names.len(),
                names.first().cloned().unwrap_or_default()
            )));
        }
        let n = space.len();
        let resume = |what: &str, e: String| FitError::Resume(format!("{what}: {e}"));
        if let Some(o) = &self.optimizer {
            o.validate(n)
                .map_err(|e| resume("the checkpoint's optimiser", e.to_string()))?;
        }
        if let Some(o) = &self.trust {
            o.validate(n)
                .map_err(|e| resume("the checkpoint's trust-region optimiser", e.to_string()))?;
        }
        if let Some(v) = &self.valley {
            v.validate(n)
                .map_err(|e| resume("the checkpoint's valley search", e))?;
        }
        let finite_positive = |t: &[f64]| t.iter().all(|v| v.is_finite() && *v > 0.0);
        if let Some((l, t)) = &self.best {
            if t.len() != n || !finite_positive(t) || l.is_nan() {
                return Err(resume(
                    "the checkpoint's best point",
                    format!(
                        "{} values (loss {l}), this fit has {n} positive parameters",
                        t.len()
                    ),
                ));
            }
        }
        for r in &self.starts {
            if r.theta.len() != n || !finite_positive(&r.theta) {
                return Err(resume(
                    "the checkpoint's multi-start results",
                    format!("{} values, this fit has {n}", r.theta.len()),
                ));
            }
        }
        if let Some(init) = &self.init {
            let m = init.best.len();
            let bad = init.candidates.iter().any(|c| c.theta.len() != m)
                || init
                    .candidates
                    .iter()
                    .enumerate()
                    .any(|(i, c)| c.index != i)
                || init.ranking.iter().any(|&i| i >= init.candidates.len())
                || init.top_k.iter().any(|&i| i >= init.candidates.len())
                || !finite_positive(&init.best);
            if bad {
                return Err(resume(
                    "the checkpoint's initialisation",
                    "inconsistent candidates, ranking or best point".into(),
                ));
            }
        }
        Ok(())
    }
}

/// One start of a multi-start: a short fit from an initialisation candidate.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct StartResult {
    /// The candidate's index in the initialisation.
    pub candidate: usize,
    /// Its MS-SSIM score.
    pub score: Option<f64>,
    /// Lowest loss of the short fit (`f64::MAX` when it failed before any evaluation).
    pub loss: f64,
    /// The parameters of that loss (the fit's free parameters).
    pub theta: Vec<f64>,
    /// Why the short fit stopped early (its simulation diverged), if it did: the start keeps
    /// the lowest loss it reached before, and the other starts go on.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub failed: Option<String>,
}

/// The descent's current run when it restarts where it stalls (`stall` in a fit config):
/// which seed it started from and the progress since.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct DescentRun {
    /// The seed it started from (0: the best point of the multi-start or the
    /// initialisation; then the further seeds in order).
    pub seed: usize,
    /// The lowest loss of this run so far (`None` before its first iteration).
    pub lowest: Option<f64>,
    /// The iteration at which the lowest loss last fell by the required share, or the run
    /// began.
    pub since: usize,
    /// The iterations at which earlier runs stalled, in order.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub stalls: Vec<usize>,
}

/// Loss terms (absent terms were not evaluated; the trajectory fit has the total only).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Terms {
    /// Weighted total.
    pub total: f64,
    /// Mean absolute error.
    #[serde(default)]
    pub l1: Option<f64>,
    /// `1 - SSIM`.
    #[serde(default)]
    pub spatial: Option<f64>,
    /// Spectral log-magnitude term.
    #[serde(default)]
    pub mag: Option<f64>,
    /// Spectral phase term.
    #[serde(default)]
    pub phase: Option<f64>,
}

/// One iteration of a fit (a line of `log.jsonl`).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct IterRecord {
    /// Iteration (0-based); the parameters are those evaluated at it.
    pub iter: usize,
    /// Loss terms (video fits: summed over views).
    pub loss: Terms,
    /// Free parameters evaluated, by name.
    pub theta: BTreeMap<String, f64>,
    /// `dL/dxi` (log-domain gradient) by name, before clipping.
    pub grad_log: BTreeMap<String, f64>,
    /// Norm of `dL/dxi` before clipping.
    pub grad_norm: f64,
    /// Learning rate of the step taken after this evaluation (the trust-region optimiser:
    /// its base radius).
    pub lr: f64,
    /// The parameters per part (per-particle fits: geometric means).
    pub parts: Vec<PartRecord>,
    /// Wall time of the iteration (s).
    pub time_s: f64,
    /// Peak heap bytes of the process since the fit started, as measured by the caller's
    /// [`crate::HeapProbe`] (0 without one; the `r4d` binary's counting allocator).
    pub peak_host_bytes: usize,
    /// Flat-direction probes run after this evaluation (video fits, `flat_probe`).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub probes: Vec<FlatProbe>,
}

impl IterRecord {
    /// The record of iteration `iter`: `loss` at `theta` (the free parameters named `names`)
    /// with `dL/dtheta = gtheta`, its part summary `parts`, and the step's figures.
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        iter: usize,
        loss: Terms,
        names: &[String],
        theta: &[f64],
        gtheta: &[f64],
        (grad_norm, lr): (f64, f64),
        parts: &[PartParams],
        (time_s, peak_host_bytes): (f64, usize),
    ) -> IterRecord {
        IterRecord {
            iter,
            loss,
            theta: names.iter().cloned().zip(theta.iter().copied()).collect(),
            grad_log: names
                .iter()
                .cloned()
                .zip(gtheta.iter().zip(theta).map(|(g, t)| g * t))
                .collect(),
            grad_norm,
            lr,
            parts: parts
                .iter()
                .enumerate()
                .map(|(i, p)| PartRecord::of(i, p))
                .collect(),
            time_s,
            peak_host_bytes,
            probes: Vec::new(),
        }
    }
}

/// One flat-direction probe: a parameter whose gradient was exactly zero, evaluated across
/// its bounds with the others fixed.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FlatProbe {
    /// The parameter.
    pub name: String,
    /// Its value when the gradient was zero.
    pub from: f64,
    /// The value it continues from (= `from` when no probed value was better).
    pub to: f64,
    /// Loss at `from` (the iteration's loss).
    pub loss_from: f64,
    /// Lowest probed loss.
    pub loss_best: f64,
}

/// A part's parameters in the `params.json` schema.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct PartRecord {
    /// Part index.
    pub id: usize,
    /// Material name.
    pub material: String,
    /// Young's modulus (Pa).
    #[serde(rename = "E")]
    pub e: f64,
    /// Poisson's ratio.
    pub nu: f64,
    /// Density (kg/m^3).
    pub density: f64,
    /// Yield stress (Pa).
    pub yield_stress: f64,
    /// Plastic viscosity (Pa s).
    pub plastic_viscosity: f64,
    /// Friction angle (degrees).
    pub friction_angle: f64,
    /// Hardening coefficient `xi` (a metal with `hardening`; absent otherwise).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub hardening: Option<f64>,
    /// Softening rate (Pa per unit plastic strain; plasticine; absent otherwise).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub softening: Option<f64>,
}

impl PartRecord {
    /// The record of a part.
    pub fn of(id: usize, p: &PartParams) -> Self {
        use crate::space::{get, reads};
        let read = |k| reads(p, k).then(|| get(p, k));
        PartRecord {
            id,
            material: p.material.name().to_string(),
            e: p.youngs_modulus_pa,
            nu: p.poisson_ratio,
            density: p.density_kg_m3,
            yield_stress: p.yield_stress_pa,
            plastic_viscosity: p.plastic_viscosity_pa_s,
            friction_angle: p.friction_angle_deg,
            hardening: read(crate::ParamKind::Hardening),
            softening: read(crate::ParamKind::Softening),
        }
    }

    /// `base` with this record's parameters (material and everything the record does not
    /// hold kept from `base`; hardening and softening only where the record has them).
    pub fn apply_to(&self, base: &PartParams) -> PartParams {
        use crate::ParamKind as K;
        let mut q = *base;
        let held = [
            (K::YoungsModulus, Some(self.e)),
            (K::PoissonRatio, Some(self.nu)),
            (K::Density, Some(self.density)),
            (K::YieldStress, Some(self.yield_stress)),
            (K::PlasticViscosity, Some(self.plastic_viscosity)),
            (K::FrictionAngle, Some(self.friction_angle)),
            (K::Hardening, self.hardening),
            (K::Softening, self.softening),
        ];
        for (k, v) in held {
            if let Some(v) = v {
                crate::space::set(&mut q, k, v);
            }
        }
        q
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Softening and hardening are recorded for the materials that read them only, and a
    /// record without them (an older run folder) still reads.
    #[test]
    fn part_records_carry_softening_and_hardening_where_read() {
        use r4d_mpm::Material;
        let plasticine = PartParams {
            material: Material::Plasticine,
            softening: 5e3,
            ..Default::default()
        };
        let r = PartRecord::of(0, &plasticine);
        assert_eq!((r.softening, r.hardening), (Some(5e3), None));
        let metal = PartParams {
            material: Material::Metal,
            hardening: true,
            xi: 0.3,
            ..Default::default()
        };
        assert_eq!(PartRecord::of(1, &metal).hardening, Some(0.3));
        let jelly = PartRecord::of(2, &PartParams::default());
        let text = serde_json::to_string(&jelly).unwrap();
        assert!(
            !text.contains("softening") && !text.contains("hardening"),
            "{text}"
        );
        let back: PartRecord = serde_json::from_str(&text).unwrap();
        assert_eq!(back, jelly);
        let text = serde_json::to_string(&r).unwrap();
        assert!(text.contains("\"softening\":5000.0"), "{text}");
        // Applied back onto a part (`r4d eval`): the fitted softening replaces the config's.
        let start = PartParams {
            softening: 1.5e4,
            ..plasticine
        };
        assert_eq!(r.apply_to(&start), plasticine);
        assert_eq!(back.apply_to(&PartParams::default()), PartParams::default());
    }

    #[test]
    fn state_round_trips_and_refuses_damage_and_old_formats() {
        let mut s = FitState::new(vec!["E[0]".into(), "density[0]".into()], "f".repeat(32));
        s.iters_done = 3;
        s.best = Some((0.125, vec![1e5, 1e3 / 3.0]));
        let text = s.to_json();
        let back = FitState::from_json(&text).unwrap();
        assert_eq!(back.best, s.best);
        assert_eq!(back.iters_done, 3);
        // Every digit of the best point is covered by the checksum.
        let edited = text.replacen("0.125", "0.126", 1);
        assert_ne!(edited, text);
        assert!(FitState::from_json(&edited).is_err());
        // An unversioned file (what this tool wrote before) is refused as such.
        let mut old: serde_json::Value = serde_json::from_str(&text).unwrap();
        let o = old.as_object_mut().unwrap();
        o.remove("format");
        o.remove("checksum");
        let e = FitState::from_json(&old.to_string())
            .unwrap_err()
            .to_string();
        assert!(e.contains("format 0"), "{e}");
        assert!(FitState::from_json("{").is_err());
        assert!(FitState::from_json("").is_err());
    }
}
