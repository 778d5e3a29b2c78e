//! `r4d metrics-trajectory`: Chamfer distance, HD95 and F-score between simulated and reference
//! point sequences (per-frame PLYs), with every variant of `r4d_loss::trajectory`.

use anyhow::{bail, Context, Result};
use r4d_loss::trajectory::{trajectory_metrics, DEFAULT_TAU, REFERENCE_TAUS};
use std::path::{Path, PathBuf};

/// Arguments of `r4d metrics-trajectory`.
#[derive(clap::Args, Debug)]
pub struct MetricsTrajectoryArgs {
    /// Ground-truth frames: a folder of PLY files (x, y, z), in natural order (`frame_2`
    /// before `frame_10`); a gap in their numbering is an error.
    #[arg(long)]
    reference: PathBuf,
    /// Simulated frames: a folder of PLY files (`r4d simulate` output), in natural order; a
    /// gap in their numbering is an error.
    #[arg(long)]
    simulated: PathBuf,
    /// F-score thresholds (default: 0.04, plus the reference table's 0.005 .. 0.1 in --json).
    #[arg(long, value_delimiter = ',')]
    tau: Option<Vec<f64>>,
    /// Skip the first N frames of both folders (e.g. 1 to leave out the shared initial state).
    #[arg(long, default_value_t = 0)]
    skip: usize,
    /// Print one JSON object (per-frame values and means) instead of a table.
    #[arg(long)]
    json: bool,
}

fn read_frames(dir: &Path) -> Result<Vec<Vec<[f64; 3]>>> {
    let files: Vec<PathBuf> = std::fs::read_dir(dir)
        .with_context(|| format!("reading {}", dir.display()))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|e| e == "ply"))
        .collect();
    let files = r4d_fsio::seq::frame_sequence(files)?;
    if files.is_empty() {
        bail!("{}: no .ply frames", dir.display());
    }
    files
        .iter()
        .map(|f| {
            let ply = r4d_mpm::ply::read_ply(f)?;
            let col = |n: &str| {
                ply.get(n)
                    .with_context(|| format!("{}: no property '{n}'", f.display()))
            };
            let (x, y, z) = (col("x")?, col("y")?, col("z")?);
            Ok((0..ply.count)
                .map(|i| [x[i] as f64, y[i] as f64, z[i] as f64])
                .collect())
        })
        .collect()
}

/// Runs the command.
pub fn run(a: MetricsTrajectoryArgs) -> Result<()> {
    let mut reference = read_frames(&a.reference)?;
    let mut simulated = read_frames(&a.simulated)?;
    if reference.len() != simulated.len() {
        bail!(
            "{} has {} frames, {} has {}",
            a.reference.display(),
            reference.len(),
            a.simulated.display(),
            simulated.len()
        );
    }
    reference.drain(..a.skip.min(reference.len()));
    simulated.drain(..a.skip.min(simulated.len()));
    let taus: Vec<f64> = match &a.tau {
        Some(t) => t.clone(),
        None if a.json => REFERENCE_TAUS.to_vec(),
        None => vec![DEFAULT_TAU],
    };
    if taus.iter().any(|t| !(t.is_finite() && *t > 0.0)) {
        bail!("--tau values must be positive");
    }
    let m = trajectory_metrics(&simulated, &reference, &taus)?;
    if a.json {
        let mean = &m.mean_over_frames;
        let default_f = mean
            .fscore
            .iter()
            .find(|f| (f.tau - DEFAULT_TAU).abs() < 1e-12)
            .or(mean.fscore.first())
            .map(|f| f.f);
        let out = serde_json::json!({
            "cd": mean.cd_sq_sum,
            "hd95": mean.hd95_max_of_directed,
            "fscore": default_f,
            "defaults": {"cd": "cd_sq_sum", "hd95": "hd95_max_of_directed", "fscore_tau": DEFAULT_TAU},
            "frames": m.per_frame.len(),
            "mean_over_frames": mean,
            "per_frame": m.per_frame,
        });
        println!("{}", serde_json::to_string_pretty(&out)?);
        return Ok(());
    }
    let mean = &m.mean_over_frames;
    println!("frames: {} (means over frames)", m.per_frame.len());
    println!(
        "Chamfer distance (cd_sq_sum, default): {:.6e}",
        mean.cd_sq_sum
    );
    println!(
        "  cd_sq_avg {:.6e}  cd_l2_sum {:.6e}  cd_l2_avg {:.6e}",
        mean.cd_sq_avg, mean.cd_l2_sum, mean.cd_l2_avg
    );
    println!(
        "HD95 (max of directed, default): {:.6e}",
        mean.hd95_max_of_directed
    );
    println!("  hd95_pooled {:.6e}  hd {:.6e}", mean.hd95_pooled, mean.hd);
    for f in &mean.fscore {
        println!(
            "F-score @ tau {}: {:.6} (precision {:.4}, recall {:.4})",
            f.tau, f.f, f.precision, f.recall
        );
    }
    Ok(())
}
