//! `r4d eval RUN_DIR`: the paper's evaluation protocol on a finished fit (see
//! `resonance4d::video_fit::eval`): videos at 30 fps against their references (MS-SSIM, PSNR,
//! LPIPS), the fit's peak memory, and, where the dataset has ground-truth point clouds,
//! Chamfer distance, HD95 and F-score. Writes `eval.json` and, under `RUN_DIR/eval/`, the
//! frames it measured (so `r4d metrics` and `r4d metrics-trajectory` can re-check them).

use super::fit::FitArgs;
use anyhow::{bail, Context, Result};
use r4d_loss::trajectory::DEFAULT_TAU;
use r4d_mpm::PartParams;
use resonance4d::fit_trajectory::PartRecord;
use resonance4d::video_fit::eval::{evaluate_trajectory, evaluate_videos, EVAL_FPS};
use resonance4d::video_fit::report::write_json;
use resonance4d::video_fit::{FitConfig, IterRecord, VideoProblem};
use serde_json::{json, Value};
use std::path::{Path, PathBuf};

/// Arguments of `r4d eval`.
#[derive(clap::Args, Debug)]
pub struct EvalArgs {
    /// The run folder of `r4d fit` (invocation.json, fit_config.json, params.json, log.jsonl).
    run_dir: PathBuf,
    /// Evaluation frame rate: references are converted to it (nearest frame) and the fit is
    /// rendered at it.
    #[arg(long, default_value_t = EVAL_FPS)]
    fps: f64,
    /// LPIPS weights (as `r4d metrics`): a safetensors file or a folder; repeatable. Default:
    /// $R4D_LPIPS_DIR if set; without weights the LPIPS values are null.
    #[arg(long = "lpips-weights", value_name = "FILE")]
    lpips_weights: Vec<PathBuf>,
    /// Where to write the JSON report (default RUN_DIR/eval.json).
    #[arg(long)]
    json: Option<PathBuf>,
}

fn read_text(path: &Path, what: &str) -> Result<String> {
    r4d_fsio::read_to_string_bounded(path, r4d_fsio::MAX_TEXT_BYTES).with_context(|| {
        format!(
            "{}: {what} (is {} a run folder of `r4d fit`?)",
            path.display(),
            path.parent().unwrap_or(Path::new(".")).display()
        )
    })
}

/// The fitted parameters of a run folder.
struct Fitted {
    /// One parameter set per part, or per particle.
    slots: Vec<PartParams>,
    /// Whether `slots` holds one set per particle (`params_particles.json`).
    per_particle: bool,
    /// The file they were read from.
    path: PathBuf,
    /// The fingerprint the file carries (`None`: written before parameter files carried one).
    fingerprint: Option<String>,
}

/// The fitted parameters of `params.json` (or per particle, `params_particles.json`) checked
/// against the parts of the problem the run folder's invocation loads: as many as it has
/// parts (particles), of their materials, physical, and every free parameter within the
/// bounds of the fit settings `cfg`.
fn fitted_slots(dir: &Path, problem: &VideoProblem, cfg: &FitConfig) -> Result<Fitted> {
    let particles = dir.join("params_particles.json");
    let (path, per_particle) = if particles.is_file() {
        (particles, true)
    } else {
        (dir.join("params.json"), false)
    };
    #[derive(serde::Deserialize)]
    struct Params {
        parts: Vec<PartRecord>,
        #[serde(default)]
        fingerprint: Option<String>,
    }
    let p: Params = serde_json::from_str(&read_text(&path, "the fitted parameters")?)
        .with_context(|| format!("{}: not a params.json of `r4d fit`", path.display()))?;
    let parts = &problem.config.parts;
    let expect = if per_particle {
        problem.particles.len()
    } else {
        parts.len()
    };
    if p.parts.len() != expect {
        bail!(
            "{}: {} parameter sets, the scene this run folder names has {expect} {}: the run folder is from another scene or config",
            path.display(),
            p.parts.len(),
            if per_particle { "particles" } else { "parts" }
        );
    }
    let mut slots = Vec::with_capacity(p.parts.len());
    for (i, r) in p.parts.iter().enumerate() {
        let base = if per_particle {
            let part = problem.particles.part.get(i).copied().unwrap_or(0) as usize;
            parts.get(part).or(parts.first())
        } else {
            parts.get(i)
        }
        .context("the config has no parts")?;
        let material = base.material.name();
        // Runs written before the material names were shared spelled PhysFlow's paste
        // "nonnewtonian".
        let same = r4d_mpm::Material::from_name(&r.material) == Some(base.material)
            || (r.material == "nonnewtonian" && base.material == r4d_mpm::Material::NonNewtonian);
        if !same {
            bail!(
                "{}: entry {i} is {}, the scene's part is {material}: the run folder is from another scene or config",
                path.display(),
                r.material
            );
        }
        let q = r.apply_to(base);
        q.validate(&format!("{} entry {i}", path.display()))?;
        slots.push(q);
    }
    // The free parameters lie within the bounds the fit searched (up to the rounding of the
    // log domain it searched in).
    let free = cfg.free_kinds(parts)?;
    let slot_parts: Vec<u32> = if per_particle {
        problem.particles.part.clone()
    } else {
        (0..parts.len() as u32).collect()
    };
    let space = r4d_optim::space::ParamSpace::new(cfg.granularity, &free, &slot_parts, |p, k| {
        cfg.bounds(parts, p, k)
    });
    let slack = 1e-9;
    for ((name, v), (lo, hi)) in space
        .names()
        .iter()
        .zip(space.values(&slots))
        .zip(space.bounds())
    {
        if !(v >= lo * (1.0 - slack) && v <= hi * (1.0 + slack)) {
            bail!(
                "{}: {name} = {v} lies outside the bounds [{lo}, {hi}] of the fit's settings: not a result of this fit",
                path.display()
            );
        }
    }
    Ok(Fitted {
        slots,
        per_particle,
        path,
        fingerprint: p.fingerprint,
    })
}

/// Checks that the run folder's files belong to one fit: the inputs `invocation.json` names
/// and the settings of `fit_config.json` have the fingerprint of the checksummed
/// `checkpoint.json` and of the parameter file. A file of another run is an error naming it;
/// a parameter file without a fingerprint (written before they carried one) is accepted with
/// a note.
fn verify_run(dir: &Path, problem: &VideoProblem, cfg: &FitConfig, fitted: &Fitted) -> Result<()> {
    let now = resonance4d::video_fit::fingerprint(problem, cfg);
    let ck_path = dir.join("checkpoint.json");
    let ck = super::checkpoint::read(&ck_path)
        .with_context(|| format!("{}: the fit's checkpoint", ck_path.display()))?
        .map(|s| s.fingerprint);
    let (inv, cfg_path) = (dir.join("invocation.json"), dir.join("fit_config.json"));
    let inputs_differ = || {
        anyhow::anyhow!(
            "{} and {}: the inputs and settings they name (fingerprint {now}) are not those the run was fitted on (fingerprint {}, recorded in {}): one of them names other files or was replaced",
            inv.display(),
            cfg_path.display(),
            ck.as_deref().or(fitted.fingerprint.as_deref()).unwrap_or("none"),
            if ck.is_some() { ck_path.display() } else { fitted.path.display() }
        )
    };
    match (&fitted.fingerprint, &ck) {
        (Some(p), _) if *p == now => {
            if ck.as_ref().is_some_and(|c| *c != now) {
                bail!(
                    "{}: written for other inputs or settings than this run's (fingerprint {}, the run {now}): a checkpoint of another run",
                    ck_path.display(),
                    ck.as_deref().unwrap_or_default()
                );
            }
        }
        (Some(p), Some(c)) if *c == now => bail!(
            "{}: written by another fit (fingerprint {p}, this run folder's inputs and settings {now})",
            fitted.path.display()
        ),
        (Some(_), _) => return Err(inputs_differ()),
        (None, Some(c)) if *c != now => return Err(inputs_differ()),
        (None, _) => eprintln!(
            "note: {} carries no fingerprint (written before parameter files carried one): checked against the scene's parts and the fit's bounds only",
            fitted.path.display()
        ),
    }
    Ok(())
}

/// The largest `peak_host_bytes` of `log.jsonl` (`None` without a log or a counting
/// allocator).
fn peak_memory(dir: &Path) -> Result<Option<usize>> {
    let path = dir.join("log.jsonl");
    let Ok(text) = r4d_fsio::read_to_string_bounded(&path, r4d_fsio::MAX_TEXT_BYTES) else {
        return Ok(None);
    };
    let mut peak = 0usize;
    for (i, line) in text
        .lines()
        .enumerate()
        .filter(|(_, l)| !l.trim().is_empty())
    {
        let r: IterRecord = serde_json::from_str(line)
            .with_context(|| format!("{} line {}: not a fit log record", path.display(), i + 1))?;
        peak = peak.max(r.peak_host_bytes);
    }
    Ok((peak > 0).then_some(peak))
}

/// Mean over views of a metric (`None` if any view lacks it).
fn mean_of(views: &[Value], key: &str) -> Option<f64> {
    mean(views.iter().map(|v| v.pointer(key).and_then(Value::as_f64)))
}

fn mean(vals: impl Iterator<Item = Option<f64>>) -> Option<f64> {
    let vals: Option<Vec<f64>> = vals.collect();
    vals.filter(|v| !v.is_empty())
        .map(|v| v.iter().sum::<f64>() / v.len() as f64)
}

/// Runs `r4d eval`.
pub fn run(a: EvalArgs) -> Result<()> {
    let dir = &a.run_dir;
    let run_file = |name: &str| dir.join(name);
    super::paths::Io::new()
        .input(
            "RUN_DIR (the fit's arguments)",
            &run_file("invocation.json"),
        )
        .input("RUN_DIR (the fit's settings)", &run_file("fit_config.json"))
        .input("RUN_DIR (the fitted parameters)", &run_file("params.json"))
        .input("RUN_DIR (the fit's log)", &run_file("log.jsonl"))
        .inputs("--lpips-weights", &a.lpips_weights)
        .output_opt("--json", a.json.as_deref())
        .check()?;
    if !(a.fps.is_finite() && a.fps > 0.0 && a.fps <= r4d_video::MAX_FPS) {
        bail!("--fps {}: must be in (0, {}]", a.fps, r4d_video::MAX_FPS);
    }
    let lpips = r4d_loss::lpips::load_all(&a.lpips_weights).context("--lpips-weights")?;
    let inv = dir.join("invocation.json");
    let mut fit: FitArgs = serde_json::from_str(&read_text(&inv, "the fit's invocation")?)
        .with_context(|| format!("{}: not an r4d fit invocation", inv.display()))?;
    fit.resolve_saved_paths(&inv)?;
    let cfg_path = dir.join("fit_config.json");
    let cfg: FitConfig = serde_json::from_str(&read_text(&cfg_path, "the fit's settings")?)
        .with_context(|| format!("{}: not a fit_config.json", cfg_path.display()))?;
    let (problem, _) = super::fit::load_problem(&fit)
        .with_context(|| format!("loading the inputs {} names", inv.display()))?;
    let fitted = fitted_slots(dir, &problem, &cfg)?;
    verify_run(dir, &problem, &cfg, &fitted)?;
    let (slots, per_particle) = (fitted.slots, fitted.per_particle);
    let peak = peak_memory(dir)?;
    let gt = match fit.dataset_dir() {
        Some(d) => r4d_datasets::GroundTruth::from_pcd(d)?.point_clouds,
        None => Vec::new(),
    };

    eprintln!(
        "evaluating {} view(s) at {} fps{}",
        problem.views.len(),
        a.fps,
        if gt.is_empty() {
            String::new()
        } else {
            format!(" and {} ground-truth point clouds", gt.len())
        }
    );
    let ev = evaluate_videos(&problem, &cfg, &slots, per_particle, a.fps, &lpips)?;
    let out = dir.join("eval");
    for (k, (rendered, reference)) in ev.rendered.iter().zip(&ev.references).enumerate() {
        let vdir = out.join(format!("view_{k}"));
        let _ = std::fs::remove_dir_all(&vdir);
        r4d_loss::io::write_png_dir(&vdir.join("rendered"), rendered)?;
        r4d_loss::io::write_png_dir(&vdir.join("reference"), reference)?;
        resonance4d::fit_diagnostics::write_mp4(&vdir.join("rendered.mp4"), rendered, a.fps)?;
    }
    let traj = if gt.is_empty() {
        None
    } else {
        let t = evaluate_trajectory(&problem, &slots, per_particle, &gt)?;
        let tdir = out.join("trajectory");
        let _ = std::fs::remove_dir_all(&tdir);
        std::fs::create_dir_all(&tdir).with_context(|| format!("creating {}", tdir.display()))?;
        for (j, x) in t.simulated.iter().enumerate() {
            let cols: Vec<Vec<f32>> = (0..3)
                .map(|c| x.iter().map(|p| p[c] as f32).collect())
                .collect();
            let refs: Vec<&[f32]> = cols.iter().map(Vec::as_slice).collect();
            r4d_mpm::ply::write_ply(
                &tdir.join(format!("frame_{j:04}.ply")),
                &["x", "y", "z"],
                &refs,
            )?;
        }
        Some(t)
    };

    let mean = traj.as_ref().map(|t| &t.metrics.mean_over_frames);
    let f_score = mean.and_then(|m| {
        m.fscore
            .iter()
            .find(|f| (f.tau - DEFAULT_TAU).abs() < 1e-12)
            .map(|f| f.f)
    });
    let mut notes: Vec<String> = Vec::new();
    for v in &ev.views {
        for n in v["notes"].as_array().into_iter().flatten() {
            if let Some(s) = n.as_str() {
                if !notes.iter().any(|m| m == s) {
                    notes.push(s.to_string());
                }
            }
        }
    }
    if gt.is_empty() {
        notes.push(
            "no ground-truth point clouds (pcd/<k>.ply): chamfer, hd95, f_score are null".into(),
        );
    }
    let report = json!({
        "run": dir,
        "fps": a.fps,
        "frames": ev.frames,
        "ms_ssim": mean_of(&ev.views, "/ms_ssim"),
        "ms_ssim_small_window": mean_of(&ev.views, "/ms_ssim_small_window/value"),
        "psnr": mean_of(&ev.views, "/psnr"),
        "psnr_video": mean_of(&ev.views, "/psnr_video"),
        "ssim": mean_of(&ev.views, "/ssim"),
        "lpips_alex": mean_of(&ev.views, "/lpips_alex"),
        "lpips_vgg": mean_of(&ev.views, "/lpips_vgg"),
        "peak_memory_bytes": peak,
        "chamfer": mean.map(|m| m.cd_sq_sum),
        "hd95": mean.map(|m| m.hd95_max_of_directed),
        "f_score": f_score,
        "f_score_tau": DEFAULT_TAU,
        "trajectory_frames": traj.as_ref().map(|t| t.simulated.len()),
        "views": ev.views,
        "notes": notes,
    });
    let json_path = a.json.clone().unwrap_or_else(|| dir.join("eval.json"));
    write_json(&json_path, &report)?;
    for n in &notes {
        eprintln!("note: {n}");
    }
    println!("{}", table(&scene_name(&fit, dir), &report));
    eprintln!("wrote {} and {}", json_path.display(), out.display());
    Ok(())
}

fn scene_name(fit: &FitArgs, dir: &Path) -> String {
    fit.dataset_dir()
        .unwrap_or(dir)
        .file_name()
        .and_then(|n| n.to_str())
        .unwrap_or("run")
        .to_string()
}

/// A number with `d` decimals, or `n/a`.
pub(crate) fn num(v: &Value, d: usize) -> String {
    v.as_f64().map_or("n/a".to_string(), |x| format!("{x:.d$}"))
}

/// MS-SSIM of a report or row; the small-window value, marked `*`, when the standard one is
/// undefined (frames <= 160 px).
pub(crate) fn ms_ssim_cell(r: &Value) -> String {
    if r["ms_ssim"].is_null() && !r["ms_ssim_small_window"].is_null() {
        format!("{}*", num(&r["ms_ssim_small_window"], 4))
    } else {
        num(&r["ms_ssim"], 4)
    }
}

/// PSNR (mean of frames) of a report or row; the whole-video value, marked `+`, when a frame
/// is identical to its reference.
pub(crate) fn psnr_cell(r: &Value) -> String {
    if r["psnr"].is_null() && !r["psnr_video"].is_null() {
        format!("{}+", num(&r["psnr_video"], 2))
    } else {
        num(&r["psnr"], 2)
    }
}

/// The paper's columns: Table 2 (MS-SSIM, PSNR, LPIPS, memory) and, with ground truth, Table
/// 3 (Chamfer, HD95, F-score).
pub(crate) fn table(scene: &str, r: &Value) -> String {
    let f = num;
    let ms = ms_ssim_cell(r);
    let mem = r["peak_memory_bytes"]
        .as_f64()
        .map_or("n/a".to_string(), |b| format!("{:.3}", b / 1e9));
    let psnr = psnr_cell(r);
    let mut s = format!(
        "{:<16} {:>9} {:>8} {:>12} {:>12} {:>11}\n{:<16} {:>9} {:>8} {:>12} {:>12} {:>11}",
        "scene",
        "MS-SSIM^",
        "PSNR^",
        "LPIPS-alex_",
        "LPIPS-vgg_",
        "memory GB",
        scene,
        ms,
        psnr,
        f(&r["lpips_alex"], 4),
        f(&r["lpips_vgg"], 4),
        mem
    );
    if !r["chamfer"].is_null() {
        s.push_str(&format!(
            "\n\n{:<16} {:>12} {:>12} {:>10}\n{:<16} {:>12} {:>12} {:>10}",
            "scene",
            "Chamfer_",
            "HD95_",
            "F-score^",
            scene,
            format!("{:.4e}", r["chamfer"].as_f64().unwrap_or(f64::NAN)),
            format!("{:.4e}", r["hd95"].as_f64().unwrap_or(f64::NAN)),
            f(&r["f_score"], 4)
        ));
    }
    s.push_str(&format!(
        "\n({} frames at {} fps; ^ higher is better, _ lower is better{})",
        r["frames"],
        r["fps"],
        if ms.ends_with('*') {
            "; * MS-SSIM with the smaller window of frames <= 160 px"
        } else {
            ""
        }
    ));
    if psnr.ends_with('+') {
        s.push_str("\n(+ PSNR over the whole video: a frame is identical to its reference)");
    }
    s
}
