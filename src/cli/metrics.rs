//! `r4d metrics`: every image/video metric and the DMS terms of a rendered video against a
//! reference video.

use anyhow::{bail, Context, Result};
use r4d_loss::lpips;
use r4d_loss::metrics::{report, Report};
use r4d_video::read_video;
use resonance4d::video_fit::report::{lpips_json, lpips_of, LpipsValues};
use serde_json::{json, Value};
use std::path::PathBuf;

/// Arguments of `r4d metrics`.
#[derive(clap::Args, Debug)]
pub struct MetricsArgs {
    /// The reference (ground-truth) video: an H.264 .mp4, a directory of PNG frames (sorted
    /// by file name) or a float32 .npy of shape (T, H, W, 3).
    #[arg(long)]
    reference: PathBuf,
    /// The rendered video, in the same formats.
    #[arg(long)]
    rendered: PathBuf,
    /// Compare at this frame rate: each video is converted to it from its own rate (nearest
    /// frame in time; the paper evaluates at 30). An MP4 knows its rate; give
    /// --reference-fps / --rendered-fps for frame folders and .npy.
    #[arg(long)]
    fps: Option<f64>,
    /// Frame rate of --reference (overrides an MP4's own).
    #[arg(long)]
    reference_fps: Option<f64>,
    /// Frame rate of --rendered (overrides an MP4's own).
    #[arg(long)]
    rendered_fps: Option<f64>,
    /// Print one JSON object instead of a table.
    #[arg(long)]
    json: bool,
    /// LPIPS weights: a safetensors file (AlexNet or VGG16, recognised from its contents;
    /// made by scripts/lpips_weights.sh) or a folder holding alex.safetensors and/or
    /// vgg.safetensors. Repeatable. Default: the folder named by $R4D_LPIPS_DIR, if set.
    /// Without weights the LPIPS values are null, with a note saying how to get them.
    #[arg(long = "lpips-weights", value_name = "FILE")]
    lpips_weights: Vec<PathBuf>,
}

/// Runs `r4d metrics`.
pub fn run(a: MetricsArgs) -> Result<()> {
    for (flag, v) in [
        ("--fps", a.fps),
        ("--reference-fps", a.reference_fps),
        ("--rendered-fps", a.rendered_fps),
    ] {
        if let Some(f) = v {
            if !(f.is_finite() && f > 0.0 && f <= r4d_video::MAX_FPS) {
                bail!("{flag} {f}: must be in (0, {}]", r4d_video::MAX_FPS);
            }
        }
    }
    let rate = |flag: &str, given: Option<f64>, path: &std::path::Path| -> Result<Option<f64>> {
        Ok(match given {
            Some(f) => Some(f),
            None => r4d_video::video_fps(path)
                .with_context(|| format!("{flag}: reading the frame rate"))?,
        })
    };
    let ref_fps = rate("--reference", a.reference_fps, &a.reference)?;
    let ren_fps = rate("--rendered", a.rendered_fps, &a.rendered)?;
    let reference = read_video::<f32>(&a.reference).context("reading the reference video")?;
    let rendered = read_video::<f32>(&a.rendered).context("reading the rendered video")?;
    let (reference, rendered) = match a.fps {
        Some(to) => {
            let convert = |v: r4d_loss::Video<f32>, from: Option<f64>, which: &str| {
                let from = from.with_context(|| {
                    format!("--fps: the {which} video carries no frame rate; give --{which}-fps")
                })?;
                r4d_video::resample(&v, from, to).with_context(|| {
                    format!("--fps {to}: converting the {which} video from {from} fps gives too many frames")
                })
            };
            (
                convert(reference, ref_fps, "reference")?,
                convert(rendered, ren_fps, "rendered")?,
            )
        }
        None => {
            if let (Some(f), Some(g)) = (ref_fps, ren_fps) {
                if (f - g).abs() > 1e-6 * f {
                    bail!("the reference is {f} fps, the rendered video {g} fps: give --fps to compare them at one rate");
                }
            }
            (reference, rendered)
        }
    };
    let r = report(&rendered, &reference).with_context(|| {
        format!(
            "comparing rendered {} with reference {}",
            a.rendered.display(),
            a.reference.display()
        )
    })?;
    // Weights given explicitly: frames too small for a backbone are an error; from the
    // default folder ($R4D_LPIPS_DIR) a note.
    let metrics = lpips::load_all(&a.lpips_weights).context("loading LPIPS weights")?;
    let lp =
        lpips_of(&metrics, &rendered, &reference, !a.lpips_weights.is_empty()).context("LPIPS")?;
    let mut r = r;
    r.notes.extend(lp.notes.iter().cloned());
    for n in &r.notes {
        eprintln!("note: {n}");
    }
    if a.json {
        println!("{}", to_json(&r, &lp));
    } else {
        print_table(&a, &r, &lp);
    }
    Ok(())
}

fn to_json(r: &Report, lp: &LpipsValues) -> Value {
    let mut v = json!({
        "frames": r.frames,
        "height": r.height,
        "width": r.width,
        "psnr": r.psnr.mean_of_frames,
        "psnr_video": r.psnr.whole_video,
        "psnr_per_frame": r.psnr.per_frame,
        "mse": r.psnr.mse,
        "l1": r.l1,
        "ssim": r.ssim.as_ref().map(|s| s.mean),
        "ssim_per_frame": r.ssim.as_ref().map(|s| s.per_frame.clone()),
        "ms_ssim": r.ms_ssim.as_ref().map(|m| m.mean),
        "ms_ssim_per_frame": r.ms_ssim.as_ref().map(|m| m.per_frame.clone()),
        "ms_ssim_small_window": r.ms_ssim_small_window.as_ref().map(|(w, m)| json!({
            "window": w,
            "value": m.mean,
        })),
        "dms_spatial": r.dms_spatial,
        "dms_mag": r.dms_mag,
        "dms_phase": r.dms_phase,
        "dms": r.dms(),
        "notes": r.notes,
    });
    lpips_json(
        lp.alex.as_ref(),
        lp.vgg.as_ref(),
        v.as_object_mut().expect("an object"),
    );
    v
}

fn print_table(a: &MetricsArgs, r: &Report, lp: &LpipsValues) {
    let opt = |v: Option<f64>, digits: usize| match v {
        Some(v) => format!("{v:.digits$}"),
        None => "undefined".to_string(),
    };
    let db = |v: Option<f64>| match v {
        Some(v) => format!("{v:.4} dB"),
        None => "inf (identical)".to_string(),
    };
    println!("reference  {}", a.reference.display());
    println!("rendered   {}", a.rendered.display());
    println!(
        "video      {} frames of {}x{} (HxW)",
        r.frames, r.height, r.width
    );
    println!(
        "PSNR       {} (mean over frames)",
        db(r.psnr.mean_of_frames)
    );
    println!(
        "PSNR video {} (MSE over the whole video)",
        db(r.psnr.whole_video)
    );
    let per: Vec<String> = r
        .psnr
        .per_frame
        .iter()
        .map(|p| p.map_or("inf".into(), |v| format!("{v:.2}")))
        .collect();
    println!("PSNR/frame {}", per.join(" "));
    println!("SSIM       {}", opt(r.ssim.as_ref().map(|s| s.mean), 6));
    match (&r.ms_ssim, &r.ms_ssim_small_window) {
        (Some(m), _) => println!("MS-SSIM    {:.6}", m.mean),
        (None, Some((w, m))) => println!(
            "MS-SSIM    undefined (frames <= 160 px); with a {w}-tap window: {:.6}",
            m.mean
        ),
        (None, None) => println!("MS-SSIM    undefined"),
    }
    println!("L1         {:.6}", r.l1);
    println!("MSE        {:.6e}", r.psnr.mse);
    println!(
        "DMS        {} = spatial {} + mag {} + phase {}",
        opt(r.dms(), 6),
        opt(r.dms_spatial, 6),
        opt(r.dms_mag, 6),
        opt(r.dms_phase, 6)
    );
    for (net, v) in [("alex", &lp.alex), ("vgg", &lp.vgg)] {
        match v {
            Some(v) => println!("LPIPS-{net:<5}{:.6} (mean over frames)", v.mean),
            None => println!("LPIPS-{net:<5}not computed (see the note)"),
        }
    }
}
