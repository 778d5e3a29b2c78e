//! The files a finished fit leaves in its run directory: `params.json`, the fitted video,
//! side-by-side comparison, w-t slices and their temporal spectra, and the loss curve.

use crate::diagnostics::{loss_curve_png, write_fit_diagnostics, DiagnosticFiles};
use r4d_loss::lpips::{Lpips, LpipsError, LpipsNet, LpipsValue};
use r4d_loss::Video;
use r4d_mpm::PartParams;
use r4d_optim::record::Terms;
use r4d_optim::trajectory::PartRecord;
use r4d_optim::video::fit::{terms_of, FitOutcome, IterRecord};
use r4d_optim::video::{FitConfig, Objective, VideoProblem};
use r4d_optim::FitError;
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
    /// The evaluation metrics of every view (`metrics.json`, see [`video_metrics`]).
    pub metrics: serde_json::Value,
}

/// Inserts the LPIPS keys into a metrics object: `lpips` (AlexNet's mean over frames, the
/// lpips package's default net; VGG16's when only it was computed), `lpips_alex`,
/// `lpips_vgg` (means) and `lpips_alex_per_frame`, `lpips_vgg_per_frame`; `null` where not
/// computed.
pub fn lpips_json(
    alex: Option<&LpipsValue>,
    vgg: Option<&LpipsValue>,
    obj: &mut serde_json::Map<String, serde_json::Value>,
) {
    let mean = |v: Option<&LpipsValue>| v.map(|v| v.mean);
    let per = |v: Option<&LpipsValue>| v.map(|v| v.per_frame.clone());
    obj.insert("lpips".into(), json!(mean(alex).or(mean(vgg))));
    obj.insert("lpips_alex".into(), json!(mean(alex)));
    obj.insert("lpips_alex_per_frame".into(), json!(per(alex)));
    obj.insert("lpips_vgg".into(), json!(mean(vgg)));
    obj.insert("lpips_vgg_per_frame".into(), json!(per(vgg)));
}

/// LPIPS of a video pair per net, where computed, and why not.
#[derive(Clone, Debug, Default)]
pub struct LpipsValues {
    /// AlexNet's.
    pub alex: Option<LpipsValue>,
    /// VGG16's.
    pub vgg: Option<LpipsValue>,
    /// Why a net was not computed.
    pub notes: Vec<String>,
}

/// LPIPS of a video pair with each given metric. Frames too small for a backbone give a
/// note (`strict`: an error) and no value.
pub fn lpips_of(
    metrics: &[Lpips],
    rendered: &Video<f32>,
    reference: &Video<f32>,
    strict: bool,
) -> Result<LpipsValues, LpipsError> {
    let mut notes = Vec::new();
    if metrics.is_empty() {
        notes.push(format!(
            "LPIPS not computed: {}",
            r4d_loss::lpips::HOW_TO_GET_WEIGHTS
        ));
    }
    let (mut alex, mut vgg) = (None, None);
    for m in metrics {
        match m.video(rendered, reference) {
            Ok(v) => match m.net() {
                LpipsNet::Alex => alex = Some(v),
                LpipsNet::Vgg => vgg = Some(v),
            },
            Err(e @ LpipsError::FrameTooSmall { .. }) if !strict => {
                notes.push(format!("LPIPS-{} not computed: {e}", m.net()));
            }
            Err(e) => return Err(e),
        }
    }
    Ok(LpipsValues { alex, vgg, notes })
}

/// The paper's video metrics of a fitted video against its reference: PSNR (mean of the
/// per-frame values, null when a frame is identical; per frame; `psnr_video` over the whole
/// video), SSIM, MS-SSIM (or, for frames of at most 160 px, the
/// smaller-window value under `ms_ssim_small_window`), LPIPS (see [`lpips_json`]; null with a
/// note without weights), and `notes`.
pub fn video_metrics(
    reference: &Video<f32>,
    fitted: &Video<f32>,
    lpips: &[Lpips],
) -> Result<serde_json::Value, FitError> {
    let r = r4d_loss::metrics::report(fitted, reference)?;
    let lp = lpips_of(lpips, fitted, reference, false)
        .map_err(|e| FitError::Input(format!("LPIPS: {e}")))?;
    let mut notes = r.notes.clone();
    notes.extend(lp.notes);
    let mut v = json!({
        "frames": r.frames,
        "height": r.height,
        "width": r.width,
        "psnr": r.psnr.mean_of_frames,
        "psnr_per_frame": r.psnr.per_frame,
        "psnr_video": r.psnr.whole_video,
        "ssim": r.ssim.as_ref().map(|s| s.mean),
        "ms_ssim": r.ms_ssim.as_ref().map(|m| m.mean),
        "ms_ssim_small_window": r.ms_ssim_small_window.as_ref().map(|(w, m)| json!({
            "window": w,
            "value": m.mean,
        })),
        "notes": notes,
    });
    lpips_json(
        lp.alex.as_ref(),
        lp.vgg.as_ref(),
        v.as_object_mut().expect("an object"),
    );
    Ok(v)
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
    r4d_fsio::write_atomic(path, (text + "\n").as_bytes()).map_err(io)
}

/// Writes the results of `outcome` into `dir`: `params.json` (and `params_particles.json`
/// for per-particle fits; both with the fit's `fingerprint`, [`r4d_optim::video::fingerprint`]), the fitted video of every view over all reference frames with its
/// diagnostics (`row`: the w-t slice row, default the reference's busiest row),
/// `metrics.json` (the evaluation metrics of every view against its reference, LPIPS with
/// the given metrics; [`video_metrics`]), and `loss_curve.png` from `log`.
pub fn write_results(
    dir: &Path,
    problem: &VideoProblem,
    cfg: &FitConfig,
    outcome: &FitOutcome,
    log: &[IterRecord],
    row: Option<usize>,
    lpips: &[Lpips],
) -> Result<ResultFiles, FitError> {
    std::fs::create_dir_all(dir).map_err(|e| FitError::Input(format!("{}: {e}", dir.display())))?;
    // Both parameter files carry the fit's fingerprint (that of its checkpoint), so that
    // `r4d eval` can tell them from another run's.
    let print = r4d_optim::video::fingerprint(problem, cfg);
    let with_print = |mut v: serde_json::Value| {
        v["fingerprint"] = json!(print);
        v
    };
    let params = dir.join("params.json");
    write_json(&params, &with_print(params_json(&outcome.parts)))?;
    if outcome.slots.len() != outcome.parts.len() {
        write_json(
            &dir.join("params_particles.json"),
            &with_print(params_json(&outcome.slots)),
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
    let mut view_metrics = Vec::new();
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
        let mut m = video_metrics(&reference, fitted, lpips)?;
        m["view"] = json!(k);
        view_metrics.push(m);
    }
    let metrics = json!({ "views": view_metrics });
    write_json(&dir.join("metrics.json"), &metrics)?;
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
        final_terms: terms_of(&ev),
        metrics,
    })
}
