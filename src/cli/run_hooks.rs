//! Progress bars, `log.jsonl`, `init.json` and `checkpoint.json` for `r4d fit` and
//! `r4d demo`.

use anyhow::{bail, Context, Result};
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use r4d_mpm::PartParams;
use r4d_optim::ParamKind;
use r4d_optim::{Candidate, InitOutcome};
use resonance4d::video_fit::report::write_json;
use resonance4d::video_fit::{FitConfig, FitEvent, FitHooks, FitState, IterRecord};
use std::io::{BufRead, IsTerminal, Write};
use std::path::{Path, PathBuf};

/// The hooks of a run folder.
pub struct RunHooks {
    dir: PathBuf,
    log_file: std::fs::File,
    /// The iteration records (those of an earlier, resumed run included).
    pub log: Vec<IterRecord>,
    bar: ProgressBar,
    init_bar: ProgressBar,
    error: Option<anyhow::Error>,
}

fn bar(len: u64, template: &str) -> ProgressBar {
    let b = if std::io::stderr().is_terminal() {
        ProgressBar::new(len)
    } else {
        ProgressBar::with_draw_target(Some(len), ProgressDrawTarget::hidden())
    };
    b.set_style(ProgressStyle::with_template(template).expect("valid template"));
    b
}

impl RunHooks {
    /// Opens `dir/log.jsonl`; when resuming keeps its first `iters_done` records.
    pub fn new(dir: &Path, cfg: &FitConfig, resume: Option<&FitState>) -> Result<Self> {
        let path = dir.join("log.jsonl");
        let keep = resume.map_or(0, |s| s.iters_done);
        let (log_file, log) = open_log_records(&path, keep)?;
        let b = bar(
            cfg.iters as u64,
            "{bar:40} iter {pos}/{len} [{elapsed} < {eta}] {msg}",
        );
        b.set_position(keep as u64);
        Ok(RunHooks {
            dir: dir.to_path_buf(),
            log_file,
            log,
            bar: b,
            init_bar: bar(
                (cfg.init.candidates + usize::from(cfg.init.include_start)) as u64,
                "{bar:40} init candidate {pos}/{len} [{elapsed} < {eta}] {msg}",
            ),
            error: None,
        })
    }

    fn keep(&mut self, r: Result<()>) {
        if let Err(e) = r {
            self.error.get_or_insert(e);
        }
    }

    /// Clears the bars; returns the first I/O error a hook met.
    pub fn finish(&mut self) -> Result<()> {
        self.bar.finish_and_clear();
        match self.error.take() {
            Some(e) => Err(e),
            None => Ok(()),
        }
    }
}

impl FitHooks for RunHooks {
    fn heap(&self) -> Option<std::sync::Arc<dyn r4d_optim::HeapProbe>> {
        Some(std::sync::Arc::new(resonance4d::alloc::CountingProbe))
    }

    fn on_event(&mut self, e: &FitEvent<'_>) {
        match *e {
            FitEvent::Candidate(c) => self.candidate(c),
            FitEvent::Init { outcome, names } => self.init(outcome, names),
            FitEvent::Start(r) => self.start(r),
            FitEvent::Iter(r) => self.iter(r),
            FitEvent::Valley {
                round,
                names,
                theta,
            } => self.valley(round, names, theta),
            FitEvent::Sampling {
                round,
                names,
                theta,
            } => self.sampling(round, names, theta),
            FitEvent::Restart { restart, names } => self.restart(restart, names),
            FitEvent::Stalled {
                iter,
                lowest,
                seed,
                theta,
                names,
            } => eprintln!(
                "descent: stalled at iteration {iter} (its lowest loss {lowest:.5e} fell by less \
                 than 0.01% over the last `stall` iterations): restarting from seed {seed}: {}",
                named_values(names, theta).join(" ")
            ),
            FitEvent::Diverged {
                iter,
                error,
                retreat,
                ends,
                names,
            } => {
                let then = match retreat {
                    Some(t) => format!(
                        "back to the best point {} with half the learning rate",
                        named_values(names, t).join(" ")
                    ),
                    None => "the trust region shrinks".to_string(),
                };
                eprintln!("descent: iteration {iter} diverged ({error}): step rejected, {then}");
                if ends {
                    eprintln!(
                        "descent: {} iterations in a row diverged: the descent ends at the best \
                         point",
                        resonance4d::video_fit::fit::MAX_DIVERGED
                    );
                }
            }
            _ => {}
        }
    }

    fn on_checkpoint(&mut self, s: &FitState) {
        let r = super::checkpoint::write(&self.dir.join("checkpoint.json"), s);
        self.keep(r);
    }
}

/// An initialisation score as printed: its MS-SSIM, or the loss of a negated-loss score
/// (`[init] score = "loss"`).
pub(super) fn score_text(s: f64) -> String {
    if s < 0.0 {
        format!("loss {:.4}", -s)
    } else {
        format!("MS-SSIM {s:.4}")
    }
}

/// What each event prints and writes.
impl RunHooks {
    fn candidate(&mut self, c: &Candidate) {
        self.init_bar.inc(1);
        match (c.score, &c.error) {
            (Some(s), _) => self
                .init_bar
                .set_message(format!("#{} {}", c.index, score_text(s))),
            (None, Some(e)) => self
                .init_bar
                .set_message(format!("#{} failed: {e}", c.index)),
            _ => {}
        }
    }

    fn init(&mut self, o: &InitOutcome, names: &[String]) {
        self.init_bar.finish_and_clear();
        let mut lines = vec![format!(
            "initialisation: {} candidates, {} failed; top {}:",
            o.candidates.len(),
            o.failed().count(),
            o.top_k.len()
        )];
        for c in o.top_candidates() {
            let vals = named_values(names, &c.theta);
            lines.push(format!(
                "  #{:<3} {}  {}",
                c.index,
                score_text(c.score.unwrap_or(f64::NAN)),
                vals.join(" ")
            ));
        }
        eprintln!("{}", lines.join("\n"));
        let r = write_json(
            &self.dir.join("init.json"),
            &serde_json::json!({ "names": names, "outcome": o }),
        )
        .map_err(anyhow::Error::from);
        self.keep(r);
    }

    fn iter(&mut self, r: &IterRecord) {
        self.bar.inc(1);
        self.bar
            .set_message(format!("loss {:.4e} |g| {:.2e}", r.loss.total, r.grad_norm));
        if self.bar.is_hidden() {
            eprintln!(
                "iter {:>4}: loss {:.5e}  |grad| {:.3e}  {:.1} s",
                r.iter, r.loss.total, r.grad_norm, r.time_s
            );
        }
        let res = append_record(&mut self.log_file, r);
        self.keep(res);
        self.log.push(r.clone());
    }

    fn start(&mut self, r: &resonance4d::video_fit::StartResult) {
        if r.loss == f64::MAX {
            eprintln!(
                "multi-start: candidate #{} ({}) failed: {}",
                r.candidate,
                score_text(r.score.unwrap_or(f64::NAN)),
                r.failed.as_deref().unwrap_or("")
            );
            return;
        }
        eprintln!(
            "multi-start: candidate #{} ({}) reached loss {:.5e}{}",
            r.candidate,
            score_text(r.score.unwrap_or(f64::NAN)),
            r.loss,
            r.failed
                .as_deref()
                .map(|f| format!(" (then stopped: {f})"))
                .unwrap_or_default()
        );
    }

    fn valley(&mut self, r: &resonance4d::video_fit::ValleyRound, names: &[String], theta: &[f64]) {
        // Each sharp direction by its components above 0.3 (`+0.83 yield_stress -0.55 softening`).
        let sharp: Vec<String> = r
            .sharp
            .iter()
            .map(|u| {
                let terms: Vec<String> = u
                    .iter()
                    .zip(names)
                    .filter(|(w, _)| w.abs() >= 0.3)
                    .map(|(w, n)| format!("{w:+.2} {n}"))
                    .collect();
                terms.join(" ")
            })
            .collect();
        let vals = named_values(names, theta);
        eprintln!(
            "valley search: loss {:.5e} -> {:.5e} ({} evaluations, step {:.3}, re-centred: {}); {}",
            r.loss_before,
            r.loss_after,
            r.evals,
            r.step,
            if sharp.is_empty() {
                "none".to_string()
            } else {
                sharp.join("; ")
            },
            vals.join(" ")
        );
    }

    fn sampling(
        &mut self,
        r: &resonance4d::video_fit::SamplingRound,
        names: &[String],
        theta: &[f64],
    ) {
        let vals = named_values(names, theta);
        eprintln!(
            "gradient sampling: loss {:.5e} -> {:.5e} (step {:.4}, radius {:.4}, min-norm gradient {:.3e}; {} gradients, {} evaluations); {}",
            r.loss_before,
            r.loss_after,
            r.step,
            r.radius,
            r.min_norm,
            r.gradients,
            r.evals,
            vals.join(" ")
        );
    }

    fn restart(&mut self, r: &resonance4d::video_fit::Restart, names: &[String]) {
        let vals = named_values(names, &r.theta);
        eprintln!(
            "shear restart {:+}: E {:.4e}, nu {:.4} -> loss {:.5e}; {}",
            r.k,
            r.e,
            r.nu,
            r.loss,
            vals.join(" ")
        );
    }
}

/// Opens a run's `log.jsonl` for writing: when resuming after `keep` iterations, keeps its
/// first `keep` records (a run killed after logging but before checkpointing left extra lines
/// that the resumed run writes again) and returns them; a log with fewer records than the
/// checkpoint's iterations, or a damaged one, is an error naming it.
pub fn open_log_records(path: &Path, keep: usize) -> Result<(std::fs::File, Vec<IterRecord>)> {
    let mut log = Vec::new();
    if keep > 0 {
        let f = std::fs::File::open(path)
            .with_context(|| format!("resuming: reading {}", path.display()))?;
        // The bytes read are bounded (a device or a pipe at the log's name cannot fill memory).
        let f = std::io::Read::take(f, r4d_fsio::MAX_TEXT_BYTES);
        for (i, line) in std::io::BufReader::new(f).lines().take(keep).enumerate() {
            let line = line.with_context(|| format!("resuming: reading {}", path.display()))?;
            log.push(serde_json::from_str(&line).with_context(|| {
                format!(
                    "{}: line {} is not an iteration record",
                    path.display(),
                    i + 1
                )
            })?);
        }
        if log.len() < keep {
            bail!(
                "{}: {} records, the checkpoint has {keep} iterations (the log was truncated or replaced)",
                path.display(),
                log.len()
            );
        }
    }
    // The kept records are rewritten atomically, then appended to.
    let mut text = String::new();
    for r in &log {
        text += &serde_json::to_string(r)?;
        text.push('\n');
    }
    r4d_fsio::write_atomic(path, text.as_bytes())
        .with_context(|| format!("writing {}", path.display()))?;
    let file = std::fs::OpenOptions::new()
        .append(true)
        .open(path)
        .with_context(|| format!("writing {}", path.display()))?;
    Ok((file, log))
}

/// [`open_log_records`] without the records.
pub fn open_log(path: &Path, keep: usize) -> Result<std::fs::File> {
    open_log_records(path, keep).map(|(f, _)| f)
}

/// Appends one record to a log (a whole line per write, flushed).
pub fn append_record(log: &mut std::fs::File, r: &IterRecord) -> Result<()> {
    let mut line = serde_json::to_string(r)?;
    line.push('\n');
    log.write_all(line.as_bytes())?;
    log.flush()?;
    Ok(())
}

/// A table of the fit's free parameters: start and fit per part and kind (per-particle fits:
/// geometric means per part), `E/density` where both are free, and a note on every
/// parameter whose gradient was exactly zero at every iteration of `log` — the video carried
/// no information about it along the fit (e.g. a yield stress no particle reached), so its
/// value is not a measurement.
pub fn param_table(
    init: &[PartParams],
    fit: &[PartParams],
    space: &resonance4d::video_fit::ParamSpace,
    log: &[IterRecord],
) -> String {
    use resonance4d::video_fit::params::get;
    use std::fmt::Write as _;
    let names = space.names();
    let per_particle = space.granularity == resonance4d::video_fit::Granularity::Particle;
    let flat = |name: &str| {
        !per_particle
            && !log.is_empty()
            && log
                .iter()
                .all(|r| r.grad_log.get(name).is_some_and(|g| *g == 0.0))
    };
    let mut rows: Vec<(usize, String, f64, f64, String)> = Vec::new();
    let mut seen = std::collections::HashSet::new();
    for (e, name) in space.entries.iter().zip(&names) {
        let parts: Vec<usize> = match e.part {
            Some(p) => vec![p],
            None => (0..fit.len()).collect(),
        };
        for p in parts {
            if !seen.insert((p, e.kind)) {
                continue;
            }
            let note = if flat(name) {
                "not determined: zero gradient at every iteration".to_string()
            } else {
                String::new()
            };
            rows.push((
                p,
                e.kind.name().to_string(),
                get(&init[p], e.kind),
                get(&fit[p], e.kind),
                note,
            ));
        }
    }
    for p in 0..fit.len() {
        let has = |k| seen.contains(&(p, k));
        if has(ParamKind::YoungsModulus) && has(ParamKind::Density) {
            let r = |q: &PartParams| q.youngs_modulus_pa / q.density_kg_m3;
            rows.push((
                p,
                "E/density".into(),
                r(&init[p]),
                r(&fit[p]),
                String::new(),
            ));
        }
    }
    rows.sort_by_key(|r| r.0);
    let mut s = String::new();
    let _ = writeln!(
        s,
        "{:<6} {:<18} {:>12} {:>12}",
        "part", "quantity", "init", "fit"
    );
    for (p, q, i, f, note) in rows {
        let _ = writeln!(s, "{p:<6} {q:<18} {i:>12.4e} {f:>12.4e}  {note}");
    }
    s
}

/// `name=value` of every free parameter (`part0.E=2.0000e5`), for the progress lines.
fn named_values(names: &[String], theta: &[f64]) -> Vec<String> {
    names
        .iter()
        .zip(theta)
        .map(|(n, v)| format!("{n}={v:.4e}"))
        .collect()
}
