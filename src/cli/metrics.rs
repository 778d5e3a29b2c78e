//! `r4d metrics`: every image/video metric and the DMS terms of a rendered video against a
//! reference video.

use anyhow::{Context, Result};
use r4d_loss::io::read_video;
use r4d_loss::metrics::{report, Report};
use serde_json::{json, Value};
use std::path::PathBuf;

/// Arguments of `r4d metrics`.
#[derive(clap::Args, Debug)]
pub struct MetricsArgs {
    /// The reference (ground-truth) video: a directory of PNG frames (sorted by file name)
    /// or a float32 .npy of shape (T, H, W, 3).
    #[arg(long)]
    reference: PathBuf,
    /// The rendered video, in the same formats.
    #[arg(long)]
    rendered: PathBuf,
    /// Print one JSON object instead of a table.
    #[arg(long)]
    json: bool,
}

/// Runs `r4d metrics`.
pub fn run(a: MetricsArgs) -> Result<()> {
    let reference = read_video::<f32>(&a.reference).context("reading the reference video")?;
    let rendered = read_video::<f32>(&a.rendered).context("reading the rendered video")?;
    let r = report(&rendered, &reference).with_context(|| {
        format!(
            "comparing rendered {} with reference {}",
            a.rendered.display(),
            a.reference.display()
        )
    })?;
    for n in &r.notes {
        eprintln!("note: {n}");
    }
    if a.json {
        println!("{}", to_json(&r));
    } else {
        print_table(&a, &r);
    }
    Ok(())
}

fn to_json(r: &Report) -> Value {
    json!({
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
        "lpips": Value::Null,
        "notes": r.notes,
    })
}

fn print_table(a: &MetricsArgs, r: &Report) {
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
    println!("LPIPS      not computed (needs pretrained AlexNet/VGG weights, not available)");
}
