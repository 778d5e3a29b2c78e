//! `r4d prepare`: turn a captured 3DGS scene into simulation input with PhysGaussian's
//! preprocessing keys (opacity threshold, rotations, `sim_area` crop, normalisation, interior
//! filling). Writes `OUT/scene.ply` (the Gaussians kept, world frame), `OUT/particles.ply`
//! (simulation-space particles: simulated Gaussians, then filling particles) and
//! `OUT/link.json` (which Gaussian each particle moves and the world-to-simulation map), the
//! inputs of `r4d simulate --particles` and `r4d render --frame/--frames --link`.

use anyhow::{Context, Result};
use r4d_splat::{prepare, PrepareConfig};
use std::path::PathBuf;

/// Arguments of `r4d prepare`.
#[derive(clap::Args, Debug)]
pub struct PrepareArgs {
    /// The captured scene: an INRIA 3DGS PLY file.
    #[arg(long)]
    scene: PathBuf,
    /// A PhysGaussian scene config (JSON); its preprocessing keys are used: opacity_threshold,
    /// rotation_degree, rotation_axis, sim_area, scale, grid_lim, particle_filling.
    #[arg(long)]
    config: PathBuf,
    /// Output folder.
    #[arg(long)]
    out: PathBuf,
    /// OUT holds an earlier `r4d prepare` output: remove its files first (without this a
    /// non-empty OUT is refused).
    #[arg(long)]
    overwrite: bool,
}

/// Decodes the preprocessing keys of a PhysGaussian (or PhysFlow) scene config under the rules
/// of every config dialect (`r4d_mpm::strict`): a key twice, or an unknown key at the top level
/// or inside `particle_filling`, is an error naming it with the closest known key.
fn read_config(text: &str) -> std::result::Result<PrepareConfig, String> {
    let map = r4d_mpm::strict::parse_json_object(text)?;
    let mut known = r4d_mpm::physgaussian::known_keys();
    known.extend(r4d_datasets::physflow_config::PHYSFLOW_ONLY);
    r4d_mpm::strict::check_keys(map.keys(), &known, "")?;
    r4d_mpm::strict::decode_value(serde_json::Value::Object(map))
}

/// Runs the command.
pub fn run(a: PrepareArgs) -> Result<()> {
    super::paths::Io::new()
        .input("--scene", &a.scene)
        .input("--config", &a.config)
        .output("--out", &a.out)
        .check()?;
    // The config first: its mistakes are reported before the scene is read.
    let text = r4d_fsio::read_to_string_bounded(&a.config, r4d_fsio::MAX_TEXT_BYTES)
        .with_context(|| format!("reading {}", a.config.display()))?;
    let cfg = read_config(&text).map_err(|e| anyhow::anyhow!("{}: {e}", a.config.display()))?;
    let input = r4d_splat::ply::read_gaussians(&a.scene)?;
    let p = prepare(&input, &cfg, &a.config.display().to_string())?;
    for w in &p.warnings {
        eprintln!("warning: {}: {w}", a.config.display());
    }
    super::paths::claim_dir(
        "--out",
        &a.out,
        "prepare",
        &["link.json"],
        super::paths::Existing::from_flags(false, a.overwrite),
    )?;
    r4d_splat::ply::write_gaussians(&a.out.join("scene.ply"), &p.scene)?;
    let cols: Vec<Vec<f32>> = (0..3)
        .map(|ax| p.particles.iter().map(|x| x[ax]).collect())
        .collect();
    r4d_mpm::ply::write_ply(
        &a.out.join("particles.ply"),
        &["x", "y", "z"],
        &[&cols[0], &cols[1], &cols[2]],
    )?;
    p.link.save(&a.out.join("link.json"))?;
    eprintln!(
        "{} of {} Gaussians kept, {} simulated, {} static, {} filling particles -> {}",
        p.scene.len(),
        input.len(),
        p.link.simulated.len(),
        p.scene.len() - p.link.simulated.len(),
        p.link.filled,
        a.out.display()
    );
    Ok(())
}
