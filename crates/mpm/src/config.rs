//! The project's own simulation config (TOML or JSON, chosen by file extension).
//!
//! ```toml
//! [domain]
//! grid_lim = 1.0          # the grid covers [0, grid_lim]^3 (m)
//! n_grid = 32             # nodes per axis, at i * dx with dx = grid_lim / n_grid
//!
//! [time]
//! substep_dt = 2e-4       # s
//! frame_dt = 0.02         # s; or substeps_per_frame = 100
//! frames = 25
//!
//! [solver]
//! gravity = [0.0, 0.0, -9.8]
//! force = "mls"           # or "classic" (PhysGaussian's weight-gradient force)
//!
//! [[parts]]
//! material = "jelly"
//! youngs_modulus_pa = 5e4
//! poisson_ratio = 0.25
//! density_kg_m3 = 800.0
//!
//! [[shapes]]
//! kind = "box"
//! min = [0.4375, 0.4375, 0.375]
//! max = [0.59375, 0.59375, 0.53125]
//!
//! [[boundary]]
//! type = "bounding_box"
//! ```
//!
//! `configs/` in the repository has one example per material.

use crate::boundary::BoundaryCondition;
use crate::error::{Error, Result};
use crate::kernels::{FORCE_CLASSIC, FORCE_MLS, OUT_OF_DOMAIN_CLAMP, OUT_OF_DOMAIN_ERROR};
use crate::material::PartParams;
use crate::scene::Shape;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// The simulation grid: `n_grid` nodes per axis at `i dx`, `dx = grid_lim / n_grid`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Domain {
    /// Edge of the cubic domain `[0, grid_lim]^3` (m). Default 1.
    pub grid_lim: f64,
    /// Nodes per axis. Default 64.
    pub n_grid: usize,
}
impl Default for Domain {
    fn default() -> Self {
        Domain {
            grid_lim: 1.0,
            n_grid: 64,
        }
    }
}
impl Domain {
    /// Grid spacing (m).
    pub fn dx(&self) -> f64 {
        self.grid_lim / self.n_grid as f64
    }
}

/// Time stepping.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TimeConfig {
    /// Substep length (s).
    pub substep_dt: f64,
    /// Frame length (s); the frame has `round(frame_dt / substep_dt)` substeps.
    #[serde(default)]
    pub frame_dt: Option<f64>,
    /// Substeps per frame (overrides `frame_dt`).
    #[serde(default)]
    pub substeps_per_frame: Option<u32>,
    /// Number of frames to simulate (frame 0, the initial state, is extra).
    pub frames: usize,
}
impl TimeConfig {
    /// Checks the time step and the run's length: frames at most
    /// [`budget::MAX_FRAMES`](crate::budget::MAX_FRAMES), frames x substeps per frame at most
    /// [`budget::MAX_TOTAL_SUBSTEPS`](crate::budget::MAX_TOTAL_SUBSTEPS) (computed in `f64`, so
    /// `frame_dt / substep_dt` cannot saturate or wrap); `file` names the source (a config
    /// file, or the flag that set `frames`).
    pub fn validate(&self, file: &str) -> Result<()> {
        self.validate_named(file, &|f| f.to_string())
    }

    /// [`TimeConfig::validate`] for a config whose keys are spelled otherwise: `name` maps a
    /// field's path here (`time.frames`) to the key of the source file (PhysGaussian's
    /// `frame_num`).
    pub fn validate_named(&self, file: &str, name: &dyn Fn(&str) -> String) -> Result<()> {
        use crate::budget::{MAX_FRAMES, MAX_TOTAL_SUBSTEPS};
        let bad = |field: &str, value: f64, reason: String| Error::InvalidParameter {
            what: file.to_string(),
            field: name(field),
            value,
            reason,
        };
        if !(self.substep_dt.is_finite() && self.substep_dt > 0.0) {
            return Err(bad(
                "time.substep_dt",
                self.substep_dt,
                "must be > 0".into(),
            ));
        }
        if let Some(f) = self.frame_dt {
            if !(f.is_finite() && f >= self.substep_dt) {
                return Err(bad("time.frame_dt", f, "must be >= substep_dt".into()));
            }
        }
        if self.substeps_per_frame == Some(0) {
            return Err(bad("time.substeps_per_frame", 0.0, "must be >= 1".into()));
        }
        if self.frames > MAX_FRAMES {
            return Err(bad(
                "time.frames",
                self.frames as f64,
                format!("at most {MAX_FRAMES} frames (MAX_FRAMES)"),
            ));
        }
        let per_frame = match (self.substeps_per_frame, self.frame_dt) {
            (Some(n), _) => n as f64,
            (None, Some(f)) => (f / self.substep_dt).round().max(1.0),
            (None, None) => 1.0,
        };
        let total = per_frame * self.frames as f64;
        if per_frame > MAX_TOTAL_SUBSTEPS as f64 || total > MAX_TOTAL_SUBSTEPS as f64 {
            let (field, value) = match (self.substeps_per_frame, self.frame_dt) {
                (Some(n), _) => ("time.substeps_per_frame", n as f64),
                (None, Some(f)) => ("time.frame_dt", f),
                (None, None) => ("time.frames", self.frames as f64),
            };
            return Err(bad(
                field,
                value,
                format!(
                    "{per_frame:e} substeps per frame x {} frames = {total:e} substeps, more than \
                     the {MAX_TOTAL_SUBSTEPS} a simulation may run (MAX_TOTAL_SUBSTEPS): raise \
                     substep_dt or lower frame_dt or frames",
                    self.frames
                ),
            ));
        }
        Ok(())
    }

    /// Substeps per frame.
    pub fn substeps(&self) -> u32 {
        match (self.substeps_per_frame, self.frame_dt) {
            (Some(n), _) => n,
            (None, Some(f)) => (f / self.substep_dt).round().max(1.0) as u32,
            (None, None) => 1,
        }
    }
}

/// Which stress force the transfer uses.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum ForceForm {
    /// MLS-MPM (Hu et al. 2018): the stress enters the affine momentum, `-dt V0 (4/dx^2) tau w dpos`.
    #[default]
    Mls,
    /// Gradient of the B-spline weights, `-dt V0 tau grad w` (PhysGaussian's solver).
    Classic,
}

/// What happens when a particle leaves the grid interior.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "snake_case")]
pub enum OutOfDomain {
    /// Stop with [`Error::OutOfDomain`].
    #[default]
    Error,
    /// Clamp the position back inside.
    Clamp,
}

/// Solver options.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SolverConfig {
    /// Gravity (m/s^2). Default (0, 0, -9.8).
    pub gravity: [f64; 3],
    /// Stress force form. Default MLS.
    pub force: ForceForm,
    /// RPIC damping (0 = APIC).
    pub rpic_damping: f64,
    /// Grid velocity damping factor per substep; only values < 1 damp. Default 1.
    pub grid_v_damping: f64,
    /// Out-of-domain policy. Default error.
    pub out_of_domain: OutOfDomain,
    /// CFL number: substep_dt must be <= max_cfl dx / c_p up front, and a particle faster than
    /// max_cfl dx / substep_dt stops the run. Default 1.
    pub max_cfl: f64,
}
impl Default for SolverConfig {
    fn default() -> Self {
        SolverConfig {
            gravity: [0.0, 0.0, -9.8],
            force: ForceForm::Mls,
            rpic_damping: 0.0,
            grid_v_damping: 1.0,
            out_of_domain: OutOfDomain::Error,
            max_cfl: 1.0,
        }
    }
}
impl SolverConfig {
    /// Device code of the force form.
    pub fn force_code(&self) -> u32 {
        match self.force {
            ForceForm::Mls => FORCE_MLS,
            ForceForm::Classic => FORCE_CLASSIC,
        }
    }
    /// Device code of the out-of-domain policy.
    pub fn out_of_domain_code(&self) -> u32 {
        match self.out_of_domain {
            OutOfDomain::Error => OUT_OF_DOMAIN_ERROR,
            OutOfDomain::Clamp => OUT_OF_DOMAIN_CLAMP,
        }
    }
}

/// A complete simulation description.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SimConfig {
    /// Grid.
    #[serde(default)]
    pub domain: Domain,
    /// Time stepping.
    pub time: TimeConfig,
    /// Solver options.
    #[serde(default)]
    pub solver: SolverConfig,
    /// Parts; particle part ids index this list.
    pub parts: Vec<PartParams>,
    /// Built-in shapes that generate particles (used when no particle file is given).
    #[serde(default)]
    pub shapes: Vec<Shape>,
    /// A PLY particle file (relative paths are relative to the config file).
    #[serde(default)]
    pub particles: Option<PathBuf>,
    /// Boundary conditions, applied in order.
    #[serde(default)]
    pub boundary: Vec<BoundaryCondition>,
}

/// Reads a text file of at most [`r4d_fsio::MAX_TEXT_BYTES`] (a config, a scene JSON).
pub(crate) fn read_text(path: &Path) -> Result<String> {
    r4d_fsio::read_to_string_bounded(path, r4d_fsio::MAX_TEXT_BYTES).map_err(|source| Error::Io {
        path: path.to_path_buf(),
        source,
    })
}

impl SimConfig {
    /// Reads a config (`.toml` or `.json`) and validates it. A relative `particles` path is
    /// resolved against the config's folder.
    pub fn load(path: &Path) -> Result<SimConfig> {
        let file = path.display().to_string();
        let text = read_text(path)?;
        let mut cfg = Self::parse(&text, path)?;
        if let Some(p) = &cfg.particles {
            if p.is_relative() {
                cfg.particles = Some(path.parent().unwrap_or(Path::new(".")).join(p));
            }
        }
        cfg.validate(&file)?;
        Ok(cfg)
    }

    /// Parses config text; the extension of `path` picks the format (JSON for `.json`, TOML
    /// otherwise). Decoded by [`crate::strict`]: a key twice, an unknown key at any depth (named
    /// by its path, with the closest known key) or a document that is not a table is an error.
    pub fn parse(text: &str, path: &Path) -> Result<SimConfig> {
        let file = path.display().to_string();
        crate::strict::decode(text, crate::strict::Format::of_path(path))
            .map_err(|e| Error::config(&file, e))
    }

    /// Checks every value; `file` names the source in errors. The particles' source (shapes,
    /// a `particles` file or `--particles`) is the loader's to check: a config without shapes
    /// is valid when the particles come from elsewhere.
    pub fn validate(&self, file: &str) -> Result<()> {
        self.validate_named(file, &|f| f.to_string())
    }

    /// The one validator of every config dialect (the project's TOML and JSON, PhysGaussian's
    /// and PhysFlow's scene JSON decode into a [`SimConfig`] and come here): the same limits
    /// and messages, with each field named as the source file spells it. `name` maps a
    /// field's path in this struct (`domain.n_grid`, `solver.grid_v_damping`,
    /// `parts[1].poisson_ratio`, `boundary[2].start_time`) to that key.
    pub fn validate_named(&self, file: &str, name: &dyn Fn(&str) -> String) -> Result<()> {
        let bad = |field: &str, value: f64, reason: &str| Error::InvalidParameter {
            what: file.to_string(),
            field: name(field),
            value,
            reason: reason.to_string(),
        };
        // A part's or a condition's own check names its bare field; prefix its path here.
        let rename = |prefix: String, e: Error| match e {
            Error::InvalidParameter {
                field,
                value,
                reason,
                ..
            } => Error::InvalidParameter {
                what: file.to_string(),
                field: name(&format!("{prefix}.{field}")),
                value,
                reason,
            },
            other => other,
        };
        let d = &self.domain;
        if !(d.grid_lim.is_finite() && d.grid_lim > 0.0) {
            return Err(bad("domain.grid_lim", d.grid_lim, "must be > 0"));
        }
        if d.n_grid < 8 || d.n_grid > 1024 {
            return Err(bad(
                "domain.n_grid",
                d.n_grid as f64,
                "must lie in [8, 1024]",
            ));
        }
        self.time.validate_named(file, name)?;
        let s = &self.solver;
        for (a, g) in s.gravity.iter().enumerate() {
            if !g.is_finite() {
                return Err(bad(&format!("solver.gravity[{a}]"), *g, "must be finite"));
            }
        }
        if !(s.max_cfl.is_finite() && s.max_cfl > 0.0) {
            return Err(bad("solver.max_cfl", s.max_cfl, "must be > 0"));
        }
        if !(s.grid_v_damping.is_finite() && s.grid_v_damping > 0.0) {
            return Err(bad(
                "solver.grid_v_damping",
                s.grid_v_damping,
                "must be > 0",
            ));
        }
        if !s.rpic_damping.is_finite() || s.rpic_damping > 1.0 {
            return Err(bad("solver.rpic_damping", s.rpic_damping, "must be <= 1"));
        }
        if self.parts.is_empty() {
            return Err(Error::config(
                file,
                format!("{}: at least one part is required", name("parts")),
            ));
        }
        for (i, p) in self.parts.iter().enumerate() {
            p.validate(file)
                .map_err(|e| rename(format!("parts[{i}]"), e))?;
        }
        let mut sampled = 0u64;
        for (i, sh) in self.shapes.iter().enumerate() {
            let what = format!("{file}: shapes[{i}]");
            sh.validate(&what, self.parts.len())?;
            sampled = sampled.saturating_add(sh.check_in_grid(&what, d.dx(), d.n_grid)?);
        }
        let max = crate::budget::MAX_SHAPE_PARTICLES;
        if sampled > max {
            return Err(Error::config(
                file,
                format!(
                    "shapes: about {sampled} particles, more than the {max} shapes may sample \
                     (MAX_SHAPE_PARTICLES): lower per_cell or n_grid, or shrink the shapes"
                ),
            ));
        }
        for (i, b) in self.boundary.iter().enumerate() {
            b.validate(file, d.n_grid)
                .map_err(|e| rename(format!("boundary[{i}]"), e))?;
        }
        // The CFL bound of every part, before any particle is sampled (after the size budgets) (the simulator checks
        // it again for the parameters it is given).
        let dt = self.time.substep_dt;
        for (i, p) in self.parts.iter().enumerate() {
            let c = p.p_wave_speed();
            let bound = s.max_cfl * d.dx() / c;
            if dt > bound {
                return Err(bad(
                    &format!("parts[{i}].youngs_modulus_pa"),
                    p.youngs_modulus_pa,
                    &format!(
                        "with density {:e} kg/m^3 its P-wave speed {c:e} m/s needs substep_dt <= \
                         max_cfl dx / c_p = {bound:e} s (CFL), the config has {dt:e} s: lower \
                         time.substep_dt or the modulus",
                        p.density_kg_m3
                    ),
                ));
            }
            if let Some(bound) = p.viscous_dt_bound(d.dx(), s.max_cfl) {
                if dt > bound {
                    return Err(bad(
                        &format!("parts[{i}].plastic_viscosity_pa_s"),
                        p.plastic_viscosity_pa_s,
                        &format!(
                            "the fluid's explicit viscous stress needs substep_dt <= max_cfl {} \
                             rho dx^2 / viscosity = {bound:e} s (density {:e} kg/m^3, dx {:e} \
                             m), the config has {dt:e} s: lower time.substep_dt or the viscosity",
                            crate::VISCOUS_STABILITY,
                            p.density_kg_m3,
                            d.dx()
                        ),
                    ));
                }
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const BASE: &str = "[time]\nsubstep_dt = 1e-4\nframes = 2\n[[parts]]\nmaterial = \"jelly\"\n";

    fn err(text: &str, file: &str) -> String {
        match SimConfig::parse(text, Path::new(file)) {
            Ok(c) => c.validate(file).unwrap_err().to_string(),
            Err(e) => e.to_string(),
        }
    }

    #[test]
    fn a_config_without_shapes_is_valid_when_particles_come_from_elsewhere() {
        let c = SimConfig::parse(BASE, Path::new("c.toml")).unwrap();
        c.validate("c.toml").unwrap();
    }

    #[test]
    fn part_values_beyond_their_limits_or_the_cfl_bound_name_the_file_and_key() {
        let part = |extra: &str| {
            format!(
                "[time]\nsubstep_dt = 1e-4\nframes = 2\n[[parts]]\nmaterial = \"jelly\"\n{extra}"
            )
        };
        for (extra, key, limit) in [
            (
                "youngs_modulus_pa = 1e300\n",
                "parts[0].youngs_modulus_pa",
                "1e13",
            ),
            ("density_kg_m3 = 1e308\n", "parts[0].density_kg_m3", "1e6"),
            ("density_kg_m3 = 1e-300\n", "parts[0].density_kg_m3", "1e-6"),
            (
                "yield_stress_pa = 1e30\n",
                "parts[0].yield_stress_pa",
                "1e13",
            ),
        ] {
            let e = err(&part(extra), "c.toml");
            assert!(
                e.contains("c.toml") && e.contains(key) && e.contains(limit),
                "{extra}: {e}"
            );
        }
        // Within the limits but too stiff for the substep: the CFL bound, before sampling.
        let e = err(&part("youngs_modulus_pa = 1e12\n"), "c.toml");
        assert!(
            e.contains("c.toml") && e.contains("parts[0].youngs_modulus_pa") && e.contains("CFL"),
            "{e}"
        );
        err_free(&part("youngs_modulus_pa = 1e6\n"));
    }

    fn err_free(text: &str) {
        let c = SimConfig::parse(text, Path::new("c.toml")).unwrap();
        c.validate("c.toml").unwrap();
    }

    #[test]
    fn boundary_values_are_named_by_their_path() {
        let e = err(
            &format!("{BASE}[[boundary]]\ntype = \"bounding_box\"\n[[boundary]]\ntype = \"cuboid\"\npoint = [0.5, 0.5, 0.5]\nsize = [0.1, 0.1, 0.1]\nstart_time = nan\n"),
            "c.toml",
        );
        assert!(
            e.contains("c.toml: invalid boundary[1].start_time = NaN"),
            "{e}"
        );
        let e = err(
            &format!("{BASE}[[boundary]]\ntype = \"bounding_box\"\nlayers = 4000000000\n"),
            "c.toml",
        );
        assert!(
            e.contains("boundary[0].layers") && e.contains("[1, 31]"),
            "{e}"
        );
    }

    #[test]
    fn typos_at_any_depth_duplicates_and_non_tables_are_errors() {
        let e = err(
            &format!("{BASE}[solver]\ngravty = [0.0, 0.0, -9.8]\n"),
            "c.toml",
        );
        assert!(
            e.starts_with("c.toml: ") && e.contains("`solver.gravty`") && e.contains("`gravity`?"),
            "{e}"
        );
        let e = err(
            &format!("{BASE}[[boundary]]\ntype = \"cuboid\"\npoint = [0.5, 0.5, 0.5]\nsize = [0.1, 0.1, 0.1]\nstrat_time = 0.0\n"),
            "c.toml",
        );
        assert!(
            e.contains("`boundary[0].strat_time`") && e.contains("`start_time`?"),
            "{e}"
        );
        let e = err(&BASE.replace("\"jelly\"", "\"jely\""), "c.toml");
        assert!(
            e.contains("`jely` of `parts[0].material`") && e.contains("`jelly`?"),
            "{e}"
        );
        let e = err(
            &format!("{BASE}[domain]\nn_grid = 32\nn_grid = 64\n"),
            "c.toml",
        );
        assert!(e.contains("c.toml") && e.contains("duplicate key"), "{e}");
        let json = r#"{"time": {"substep_dt": 1e-4, "frames": 2, "frames": 3}, "parts": [{}]}"#;
        let e = err(json, "c.json");
        assert!(e.contains("c.json") && e.contains("duplicate"), "{e}");
        for text in ["[]", "[{\"substep_dt\": 1e-4}, [], []]", "1"] {
            let e = err(text, "c.json");
            assert!(
                e.contains("c.json: expected a table of keys"),
                "{text}: {e}"
            );
        }
    }
}
