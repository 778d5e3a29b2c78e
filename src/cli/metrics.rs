//! `r4d metrics`: every image/video metric and the DMS terms of a rendered video against a
//! reference video.

use anyhow::{Context, Result};
use r4d_loss::io::read_video;
use r4d_loss::lpips;
use r4d_loss::metrics::{report, Report};
use resonance4d::video_fit::report::{lpips_json, lpips_of, LpipsValues};
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
    /// LPIPS weights: a safetensors file (AlexNet or VGG16, recognised from its contents;
    /// made by scripts/lpips_weights.sh) or a folder holding alex.safetensors and/or
    /// vgg.safetensors. Repeatable. Default: the folder named by $R4D_LPIPS_DIR, if set.
    /// Without weights the LPIPS values are null, with a note saying how to get them.
    #[arg(long = "lpips-weights", value_name = "FILE")]
    lpips_weights: Vec<PathBuf>,
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
