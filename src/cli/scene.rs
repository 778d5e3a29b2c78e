//! Loading a simulation config and its particles, shared by the commands.

use anyhow::Result;
use r4d_mpm::{physgaussian, ParticleSet, SimConfig};
use std::path::{Path, PathBuf};

/// The arguments that name a scene, shared by the commands.
#[derive(clap::Args, Debug)]
pub struct SceneArgs {
    /// Simulation config: the project's TOML/JSON, or a PhysGaussian scene JSON with
    /// --physgaussian.
    #[arg(long)]
    pub config: PathBuf,
    /// Read --config as a PhysGaussian scene config (config/*.json of that project).
    #[arg(long)]
    pub physgaussian: bool,
    /// Particle PLY (float x, y, z; optional volume, part). Overrides the config's particles.
    #[arg(long)]
    pub particles: Option<PathBuf>,
}

impl SceneArgs {
    /// Declares the scene's files as inputs of a command.
    pub fn inputs(&self, io: super::paths::Io) -> super::paths::Io {
        io.input("--config", &self.config)
            .input_opt("--particles", self.particles.as_deref())
    }
    /// Loads the scene.
    pub fn load(&self) -> Result<Loaded> {
        load(&self.config, self.physgaussian, self.particles.as_ref())
    }
}

/// A config with its particles, ready to simulate.
pub struct Loaded {
    /// The config.
    pub config: SimConfig,
    /// The particles.
    pub scene: ParticleSet,
    /// Where the particles came from (for error messages).
    pub source: String,
    /// Import warnings.
    pub warnings: Vec<String>,
}

/// Loads the project's config (or a PhysGaussian scene with `physgaussian`) and the particles
/// (`particles` overrides the config's file or shapes).
pub fn load(config: &Path, physgaussian: bool, particles: Option<&PathBuf>) -> Result<Loaded> {
    let (config_v, warnings, import) = if physgaussian {
        let imp = physgaussian::import_file(config)?;
        (imp.config.clone(), imp.warnings.clone(), Some(imp))
    } else {
        (SimConfig::load(config)?, Vec::new(), None)
    };
    for w in &warnings {
        eprintln!("warning: {}: {w}", config.display());
    }
    let dx = config_v.domain.dx();
    let particle_file = particles.cloned().or(config_v.particles.clone());
    let (mut scene, source, volumes_from_file) = match &particle_file {
        Some(p) => {
            let s = ParticleSet::from_ply(p, dx)?;
            let has_volume = r4d_mpm::ply::read_ply(p)?.get("volume").is_some();
            (s, p.display().to_string(), has_volume)
        }
        None if !config_v.shapes.is_empty() => (
            ParticleSet::from_shapes(&config_v.shapes, dx),
            format!("{}: shapes", config.display()),
            true,
        ),
        None => anyhow::bail!(
            "{}: no particles: pass --particles FILE.ply or add [[shapes]] to the config",
            config.display()
        ),
    };
    if let Some(imp) = &import {
        imp.apply_to_scene(&mut scene, volumes_from_file);
    }
    Ok(Loaded {
        config: config_v,
        scene,
        source,
        warnings,
    })
}
