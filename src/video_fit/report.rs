//! The files a finished fit leaves in its run directory: `params.json`, the fitted video,
//! side-by-side comparison, w-t slices and their temporal spectra, and the loss curve.

use super::fit::{FitOutcome, IterRecord, Terms};
use super::problem::{Objective, VideoProblem};
use super::{FitConfig, FitError};
use crate::fit_diagnostics::{loss_curve_png, write_fit_diagnostics, DiagnosticFiles};
use crate::fit_trajectory::PartRecord;
use r4d_mpm::PartParams;
use serde_json::json;
use std::path::{Path, PathBuf};

/// What [`write_results`] wrote.
#[derive(Clone, Debug)]
pub struct ResultFiles {
    /// `params.json`.
    pub params: PathBuf,
    /// Diagnostics per view (`view_K/` when there are several views, else the run folder).
    pub views: Vec<DiagnosticFiles>,
    /// `loss_curve.png` (absent without iterations).
    pub loss_curve: Option<PathBuf>,
    /// Loss terms of the fitted parameters over every video frame.
    pub final_terms: Terms,
}

/// `{"parts": [...]}` in the schema of `params.json`.
pub fn params_json(parts: &[PartParams]) -> serde_json::Value {
    let records: Vec<PartRecord> = parts
        .iter()
        .enumerate()
        .map(|(i, p)| PartRecord::of(i, p))
        .collect();
    json!({ "parts": records })
}

/// Writes `value` as pretty JSON to `path`, atomically (temp file, then rename).
pub fn write_json(path: &Path, value: &impl serde::Serialize) -> Result<(), FitError> {
    let io = |e: std::io::Error| FitError::Input(format!("{}: {e}", path.display()));
    let text = serde_json::to_string_pretty(value)
        .map_err(|e| FitError::Input(format!("{}: {e}", path.display())))?;
    let tmp = path.with_extension("json.tmp");
    std::fs::write(&tmp, text + "\n").map_err(io)?;
    std::fs::rename(&tmp, path).map_err(io)
}

/// Writes the results of `outcome` into `dir`: `params.json` (and `params_particles.json`
/// for per-particle fits), the fitted video of every view over all reference frames with its
/// diagnostics (`row`: the w-t slice row, default the reference's busiest row), and
/// `loss_curve.png` from `log`.
pub fn write_results(
    dir: &Path,
    problem: &VideoProblem,
    cfg: &FitConfig,
    outcome: &FitOutcome,
    log: &[IterRecord],
    row: Option<usize>,
) -> Result<ResultFiles, FitError> {
    std::fs::create_dir_all(dir).map_err(|e| FitError::Input(format!("{}: {e}", dir.display())))?;
    let params = dir.join("params.json");
    write_json(&params, &params_json(&outcome.parts))?;
    if outcome.slots.len() != outcome.parts.len() {
        write_json(
            &dir.join("params_particles.json"),
            &params_json(&outcome.slots),
        )?;
    }
    // The fitted parameters over the whole video (part slots: per-particle values are
    // rendered through their own slots).
    let mut obj = Objective::new(
        problem,
        None,
        &cfg.loss,
        outcome.slots.len() != outcome.parts.len(),
    )?;
    obj.precision = cfg.precision;
    let (ev, videos) = obj.render_and_value(&outcome.slots)?;
    let mut views = Vec::new();
    for (k, (v, fitted)) in problem.views.iter().zip(&videos).enumerate() {
        let vdir = if problem.views.len() > 1 {
            dir.join(format!("view_{k}"))
        } else {
            dir.to_path_buf()
        };
        let reference = r4d_loss::Video::from_frames(
            v.video.height(),
            v.video.width(),
            (0..fitted.frames()).map(|t| v.video.frame_f32(t)),
        )?;
        views.push(
            write_fit_diagnostics(&vdir, &reference, fitted, row, problem.fps)
                .map_err(|e| FitError::Input(e.to_string()))?,
        );
    }
    let loss_curve = if log.is_empty() {
        None
    } else {
        let path = dir.join("loss_curve.png");
        let it = |f: &dyn Fn(&Terms) -> Option<f64>| -> Vec<(f64, f64)> {
            log.iter()
                .filter_map(|r| f(&r.loss).map(|v| (r.iter as f64, v)))
                .collect()
        };
        let mut series: Vec<(&str, Vec<(f64, f64)>)> = vec![("total", it(&|t| Some(t.total)))];
        for (name, s) in [
            ("L1", it(&|t| t.l1)),
            ("1 - SSIM", it(&|t| t.spatial)),
            ("spectral magnitude", it(&|t| t.mag)),
            ("spectral phase", it(&|t| t.phase)),
        ] {
            if !s.is_empty() {
                series.push((name, s));
            }
        }
        loss_curve_png(&path, "DMS loss per iteration", &series)
            .map_err(|e| FitError::Input(e.to_string()))?;
        Some(path)
    };
    Ok(ResultFiles {
        params,
        views,
        loss_curve,
        final_terms: Terms::of(&ev),
    })
}
