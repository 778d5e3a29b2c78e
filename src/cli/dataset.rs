//! `r4d dataset inspect DIR [--json]`: what a dataset folder holds and how it is interpreted.

use anyhow::{Context, Result};
use r4d_datasets::{Layout, LoadOptions};
use std::path::PathBuf;

/// Arguments of `r4d dataset`.
#[derive(clap::Args, Debug)]
pub struct DatasetArgs {
    #[command(subcommand)]
    command: DatasetCommand,
}

#[derive(clap::Subcommand, Debug)]
enum DatasetCommand {
    /// Read a dataset folder (PhysFlow's release, PhysDreamer, PAC-NeRF) and report what was
    /// found and how it is interpreted: layout, Gaussians, particles, parts in SI units,
    /// normalisation, cameras, videos, ground truth.
    Inspect(InspectArgs),
}

/// The options every command that reads a dataset shares.
#[derive(clap::Args, Debug, Clone, Default, serde::Serialize, serde::Deserialize)]
pub struct DatasetOptions {
    /// Layout of the folder (default: detected): physflow, physdreamer or pacnerf.
    #[arg(long)]
    #[serde(default)]
    pub format: Option<String>,
    /// PhysFlow's key-frame rule on images_generated/: keep every (n / K)-th frame, spaced
    /// 11 x opt_frame_dt (PhysFlow's n_key_frame is 8).
    #[arg(long = "key-frames")]
    #[serde(default)]
    pub key_frames: Option<usize>,
}

impl DatasetOptions {
    /// The loader's options, with the physics config `sim` and the frame rate `fps` when given.
    pub fn load_options(&self, sim: Option<&PathBuf>, fps: Option<f64>) -> Result<LoadOptions> {
        let format = match &self.format {
            None => None,
            Some(f) => Some(Layout::parse(f).with_context(|| {
                format!("--format {f}: expected physflow, physdreamer or pacnerf")
            })?),
        };
        Ok(LoadOptions {
            format,
            sim: sim.cloned(),
            fps,
            key_frames: self.key_frames,
            video_optional: false,
        })
    }
}

/// Arguments of `r4d dataset inspect`.
#[derive(clap::Args, Debug)]
pub struct InspectArgs {
    /// The dataset folder (e.g. PhysFlow's model/phys_dreamer/telephone).
    dir: PathBuf,
    /// Print the report as JSON (keys documented in docs/cli/data.md).
    #[arg(long)]
    json: bool,
    /// The physics config (default: where the layout keeps it).
    #[arg(long)]
    sim: Option<PathBuf>,
    /// Frame rate of the reference videos (default: the layout's; PhysFlow: 1 / frame_dt,
    /// PAC-NeRF: 1 / frame_dt of its config, PhysDreamer: 30).
    #[arg(long)]
    fps: Option<f64>,
    #[command(flatten)]
    opts: DatasetOptions,
}

/// Runs the command.
pub fn run(a: DatasetArgs) -> Result<()> {
    match a.command {
        DatasetCommand::Inspect(a) => inspect(a),
    }
}

fn inspect(a: InspectArgs) -> Result<()> {
    // A scene without a reference video can still be inspected (its views list is empty).
    let opts = LoadOptions {
        video_optional: true,
        ..a.opts.load_options(a.sim.as_ref(), a.fps)?
    };
    let ds = r4d_datasets::load(&a.dir, &opts)?;
    let s = ds.summary();
    if a.json {
        println!("{}", serde_json::to_string_pretty(&s)?);
        return Ok(());
    }
    println!("{} ({} layout)", ds.dir.display(), ds.layout.name());
    if let Some(c) = &ds.config_file {
        println!("physics config: {}", c.display());
    }
    println!(
        "Gaussians: {} in {}, {} after the opacity filter; {} simulated particles ({} filling), {} static Gaussians rendered at rest",
        ds.gaussians_in_file,
        ds.gaussian_file.display(),
        ds.gaussians_after_opacity_filter,
        ds.particles.len(),
        ds.link.filled,
        ds.static_gaussians()
    );
    let n = &s["normalisation"];
    println!(
        "normalisation: {}\n  rotation {}, mean {}, scale {:.6}, shift {}",
        n["formula"].as_str().unwrap_or(""),
        n["rotation"],
        n["mean"],
        n["scale"].as_f64().unwrap_or(f64::NAN),
        n["shift"]
    );
    println!(
        "grid: {} nodes per axis over [0, {}]^3, gravity {:?}; substep {:e} s, frame {:.6} s ({} substeps), {} frames",
        ds.config.domain.n_grid,
        ds.config.domain.grid_lim,
        ds.config.solver.gravity,
        ds.config.time.substep_dt,
        s["frame_dt"].as_f64().unwrap_or(f64::NAN),
        ds.config.time.substeps(),
        ds.config.time.frames
    );
    for p in s["parts"].as_array().into_iter().flatten() {
        println!(
            "part {}: {} ({} particles): E {:.4e} Pa, nu {}, density {} kg/m^3, yield stress {:.4e} Pa, plastic viscosity {:.4e} Pa s, friction angle {} deg",
            p["id"], p["material"], p["particles"], p["E_Pa"].as_f64().unwrap_or(f64::NAN), p["nu"], p["density_kg_m3"],
            p["yield_stress_Pa"].as_f64().unwrap_or(f64::NAN), p["plastic_viscosity_Pa_s"].as_f64().unwrap_or(f64::NAN), p["friction_angle_deg"]
        );
    }
    for (i, b) in ds.config.boundary.iter().enumerate().take(12) {
        println!("boundary condition {i}: {}", serde_json::to_string(b)?);
    }
    if ds.config.boundary.len() > 12 {
        println!(
            "... {} boundary conditions in all",
            ds.config.boundary.len()
        );
    }
    for c in s["cameras"].as_array().into_iter().flatten().take(16) {
        println!(
            "camera {}: {}x{}, fx {:.2}, fy {:.2}, fov {:.1} x {:.1} deg",
            c["name"],
            c["width"],
            c["height"],
            c["fx"].as_f64().unwrap_or(0.0),
            c["fy"].as_f64().unwrap_or(0.0),
            c["fov_x_deg"].as_f64().unwrap_or(0.0),
            c["fov_y_deg"].as_f64().unwrap_or(0.0)
        );
    }
    for v in s["videos"].as_array().into_iter().flatten() {
        println!(
            "video {}: {} frames at {} fps, {}x{}, camera {}",
            v["path"].as_str().unwrap_or(""),
            v["frames"],
            v["fps"],
            v["width"],
            v["height"],
            v["camera"]
        );
    }
    println!(
        "ground truth: {}",
        if ds.ground_truth.point_clouds.is_empty() {
            "none".to_string()
        } else {
            format!("{} point clouds (pcd/)", ds.ground_truth.point_clouds.len())
        }
    );
    for w in &ds.warnings {
        println!("note: {w}");
    }
    Ok(())
}
