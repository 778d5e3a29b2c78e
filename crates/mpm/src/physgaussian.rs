//! Importer for PhysGaussian scene configs (`config/*.json` of github.com/XPandora/PhysGaussian).
//!
//! The importer reproduces PhysGaussian's solver (`mpm_solver_warp`): the classic
//! weight-gradient stress force, initial volumes, `n_grid` nodes per axis at `i dx`, the
//! substep order, its material formulas, its defaults for missing keys and its truncating
//! `int(frame_dt / substep_dt)` substeps per frame. Differences we keep on purpose:
//!
//! * **Surface colliders work.** PhysGaussian computes the slip/friction velocity and then
//!   writes zero (every collider is sticky); we apply `slip` and frictional surfaces as
//!   intended. `sticky` is unchanged. The hard-coded `"cut"` surface is refused.
//! * **Snow is a real model** (Stomakhin et al. 2013); PhysGaussian's snow branch computes no
//!   stress.
//! * **Scene preprocessing is a separate step.** `rotation_degree`, `sim_area`, `scale`,
//!   `opacity_threshold` and `particle_filling` act on Gaussians in PhysGaussian's
//!   `gs_simulation.py`; here that is `r4d prepare` (`r4d_splat::prepare`), which writes the
//!   particles in MPM space. The simulator takes particles as given (as the solver's
//!   `load_from_sampling` does) and notes such keys in a warning.
//! * **Safety checks.** A substep that violates the CFL bound is refused up front, and a run
//!   that produces NaN, exceeds the CFL speed or leaves the grid stops with a typed error.
//! * **Strict keys and values.** A key given twice, a key PhysGaussian does not read (at the top
//!   level, in a boundary condition or a material region) or an unknown material or collider
//!   surface is an error naming it with the closest known name (PhysGaussian keeps the last
//!   duplicate, ignores unknown keys and treats any unknown surface as friction); the values go
//!   through the project's validator ([`SimConfig::validate_named`]).
//! * `enforce_particle_velocity_rotation` is not supported (a typed error says so).
//! * A missing `g` is an error (PhysGaussian's decoder default, a scalar, crashes its solver).
//! * Sand's stress uses `log(max(|s|, 1e-14))` so an inverted particle gives a finite stress.

use crate::boundary::{BoundaryCondition, Surface};
use crate::config::{Domain, ForceForm, OutOfDomain, SimConfig, SolverConfig, TimeConfig};
use crate::error::{Error, Result};
use crate::material::{Material, PartParams};
use crate::scene::ParticleSet;
use crate::strict;
use serde_json::{Map, Value};
use std::path::Path;

/// A material region of `additional_material_params`: particles strictly inside get their own
/// part with these E, nu and density.
#[derive(Clone, Debug, PartialEq)]
pub struct MaterialRegion {
    /// Centre (m).
    pub point: [f64; 3],
    /// Half extents (m).
    pub size: [f64; 3],
}

/// The result of importing a PhysGaussian config.
#[derive(Clone, Debug)]
pub struct Import {
    /// The equivalent config (no particles yet: they come from a PLY file).
    pub config: SimConfig,
    /// Regions of `additional_material_params`; region `r` is part `r + 1`.
    pub regions: Vec<MaterialRegion>,
    /// Keys that were ignored, with the reason.
    pub warnings: Vec<String>,
}

impl Import {
    /// Assigns parts from the material regions (later regions win, as in PhysGaussian) and,
    /// for sand with estimated volumes, replaces every volume by the mean (PhysGaussian does
    /// this for sand). `volumes_from_file` tells whether the PLY carried volumes.
    pub fn apply_to_scene(&self, scene: &mut ParticleSet, volumes_from_file: bool) {
        for (i, x) in scene.x.iter().enumerate() {
            let mut part = 0u32;
            for (r, reg) in self.regions.iter().enumerate() {
                if (0..3).all(|a| {
                    let p = x[a] as f64;
                    p > reg.point[a] - reg.size[a] && p < reg.point[a] + reg.size[a]
                }) {
                    part = r as u32 + 1;
                }
            }
            scene.part[i] = part;
        }
        if !volumes_from_file
            && self.config.parts[0].material == Material::Sand
            && !scene.is_empty()
        {
            let mean = scene.volume.iter().map(|&v| v as f64).sum::<f64>() / scene.len() as f64;
            scene.volume.iter_mut().for_each(|v| *v = mean as f32);
        }
    }
}

/// Reads and converts a PhysGaussian scene config.
pub fn import_file(path: &Path) -> Result<Import> {
    let text = crate::config::read_text(path)?;
    import_str(&text, &path.display().to_string())
}

struct Reader<'a> {
    file: &'a str,
    map: &'a Map<String, Value>,
    ctx: String,
}

impl<'a> Reader<'a> {
    fn err(&self, key: &str, msg: &str) -> Error {
        Error::config(self.file, format!("{}{key}: {msg}", self.ctx))
    }
    fn f64_or(&self, key: &str, default: f64) -> Result<f64> {
        match self.map.get(key) {
            None | Some(Value::Null) => Ok(default),
            Some(v) => v.as_f64().ok_or_else(|| self.err(key, "expected a number")),
        }
    }
    fn f64_req(&self, key: &str) -> Result<f64> {
        match self.map.get(key) {
            None => Err(self.err(key, "missing")),
            Some(v) => v.as_f64().ok_or_else(|| self.err(key, "expected a number")),
        }
    }
    fn vec3_opt(&self, key: &str) -> Result<Option<[f64; 3]>> {
        match self.map.get(key) {
            None | Some(Value::Null) => Ok(None),
            Some(Value::Array(a)) if a.len() == 3 => {
                let mut out = [0.0; 3];
                for (o, v) in out.iter_mut().zip(a) {
                    *o = v
                        .as_f64()
                        .ok_or_else(|| self.err(key, "expected 3 numbers"))?;
                }
                Ok(Some(out))
            }
            Some(_) => Err(self.err(key, "expected an array of 3 numbers")),
        }
    }
    fn vec3_req(&self, key: &str) -> Result<[f64; 3]> {
        self.vec3_opt(key)?.ok_or_else(|| self.err(key, "missing"))
    }
    fn vec3_or(&self, key: &str, d: [f64; 3]) -> Result<[f64; 3]> {
        Ok(self.vec3_opt(key)?.unwrap_or(d))
    }
}

const IGNORED_RENDER_KEYS: &[&str] = &[
    "mpm_space_vertical_upward_axis",
    "mpm_space_viewpoint_center",
    "default_camera_index",
    "show_hint",
    "init_azimuthm",
    "init_elevation",
    "init_radius",
    "move_camera",
    "delta_a",
    "delta_e",
    "delta_r",
    "pic_damping",
    "_notes",
];
const PREPROCESSING_KEYS: &[&str] = &[
    "opacity_threshold",
    "rotation_degree",
    "rotation_axis",
    "sim_area",
    "scale",
    "particle_filling",
];

/// The keys of a PhysGaussian scene config that reach the solver.
const KNOWN_KEYS: &[&str] = &[
    "material",
    "E",
    "nu",
    "density",
    "g",
    "grid_lim",
    "n_grid",
    "substep_dt",
    "frame_dt",
    "frame_num",
    "yield_stress",
    "plastic_viscosity",
    "friction_angle",
    "hardening",
    "xi",
    "softening",
    "rpic_damping",
    "grid_v_damping_scale",
    "boundary_conditions",
    "additional_material_params",
];

/// PhysGaussian's material names, and PhysFlow's two fluids (its configs are PhysGaussian's
/// dialect).
const MATERIALS: &[&str] = &[
    "jelly",
    "metal",
    "sand",
    "foam",
    "snow",
    "plasticine",
    "non_newtonian",
    "newtonian",
];

/// PhysGaussian's boundary condition types.
const BOUNDARY_TYPES: &[&str] = &[
    "bounding_box",
    "cuboid",
    "particle_impulse",
    "enforce_particle_translation",
    "release_particles_sequentially",
    "surface_collider",
    "enforce_particle_velocity_rotation",
];

/// Every top-level key a PhysGaussian scene config may hold (the solver's, the renderer's
/// and the preprocessing keys), for dialects built on this one.
pub fn known_keys() -> Vec<&'static str> {
    let mut k = KNOWN_KEYS.to_vec();
    k.extend(IGNORED_RENDER_KEYS);
    k.extend(PREPROCESSING_KEYS);
    k
}

/// The PhysGaussian key of a field of the decoded [`SimConfig`] (its path as
/// [`SimConfig::validate_named`] names it); `sources[k]` is the `boundary_conditions` entry
/// condition `k` comes from.
fn key_of(field: &str, sources: &[usize]) -> String {
    let simple = match field {
        "domain.grid_lim" => Some("grid_lim"),
        "domain.n_grid" => Some("n_grid"),
        "time.substep_dt" => Some("substep_dt"),
        "time.frame_dt" | "time.substeps_per_frame" => Some("frame_dt"),
        "time.frames" => Some("frame_num"),
        "solver.grid_v_damping" => Some("grid_v_damping_scale"),
        "solver.rpic_damping" => Some("rpic_damping"),
        "parts" => Some("material"),
        _ => None,
    };
    if let Some(k) = simple {
        return k.to_string();
    }
    if let Some(rest) = field.strip_prefix("solver.gravity") {
        return format!("g{rest}");
    }
    let split = |rest: &str| -> Option<(usize, String)> {
        let (i, f) = rest.split_once("].")?;
        Some((i.parse().ok()?, f.to_string()))
    };
    if let Some((i, f)) = field.strip_prefix("parts[").and_then(split) {
        let key = match f.as_str() {
            "youngs_modulus_pa" => "E",
            "poisson_ratio" => "nu",
            "density_kg_m3" => "density",
            "yield_stress_pa" => "yield_stress",
            "plastic_viscosity_pa_s" => "plastic_viscosity",
            "friction_angle_deg" => "friction_angle",
            other => other,
        };
        return match i {
            0 => key.to_string(),
            _ => format!("additional_material_params[{}].{key}", i - 1),
        };
    }
    if let Some((k, f)) = field.strip_prefix("boundary[").and_then(split) {
        let entry = sources.get(k).copied().unwrap_or(k);
        return format!("boundary_conditions[{entry}].{f}");
    }
    field.to_string()
}

/// Converts PhysGaussian config text; `file` names the source in errors.
///
/// The text is read by [`strict`] rules (a key twice or an unknown key at any depth is an
/// error naming it, with the closest known key) and the decoded config goes through
/// [`SimConfig::validate_named`], the validator of the project's own configs, with each field
/// named by its PhysGaussian key.
pub fn import_str(text: &str, file: &str) -> Result<Import> {
    let root = strict::parse_json_object(text).map_err(|e| Error::config(file, e))?;
    let map = &root;
    let r = Reader {
        file,
        map,
        ctx: String::new(),
    };
    let mut known: Vec<&str> = KNOWN_KEYS.to_vec();
    known.extend(IGNORED_RENDER_KEYS);
    known.extend(PREPROCESSING_KEYS);
    strict::check_keys(map.keys(), &known, "").map_err(|e| Error::config(file, e))?;
    let mut warnings = Vec::new();

    let mat_name = match map.get("material") {
        None => "jelly".to_string(),
        Some(Value::String(s)) => s.clone(),
        Some(_) => return Err(r.err("material", "expected a string")),
    };
    let material = Material::from_name(&mat_name)
        .filter(|m| m.physgaussian_id().is_some() || m.physflow_id().is_some())
        .ok_or_else(|| {
            Error::config(
                file,
                strict::unknown_value("material", &mat_name, MATERIALS),
            )
        })?;
    let defaults = PartParams::default();
    let base = PartParams {
        material,
        youngs_modulus_pa: r.f64_or("E", 1e5)?,
        poisson_ratio: r.f64_or("nu", 0.4)?,
        density_kg_m3: r.f64_or("density", 200.0)?,
        yield_stress_pa: r.f64_or("yield_stress", 0.0)?,
        plastic_viscosity_pa_s: r.f64_or("plastic_viscosity", 0.0)?,
        friction_angle_deg: r.f64_or("friction_angle", 25.0)?,
        hardening: r.f64_or("hardening", 0.0)? == 1.0,
        xi: r.f64_or("xi", 0.0)?,
        softening: r.f64_or("softening", 0.1)?,
        ..defaults
    };
    let gravity = match map.get("g") {
        None => return Err(r.err("g", "missing (a 3-vector in m/s^2, e.g. [0, 0, -9.8])")),
        Some(_) => r.vec3_req("g")?,
    };
    // Only the types are checked here; the values go through `SimConfig::validate_named`.
    let grid_lim = r.f64_or("grid_lim", 2.0)?;
    let n_grid = r.f64_or("n_grid", 50.0)?;
    if !(n_grid >= 0.0 && n_grid.fract() == 0.0) {
        return Err(r.err("n_grid", "expected a non-negative integer"));
    }
    let substep_dt = r.f64_or("substep_dt", 1e-4)?;
    let frame_dt = r.f64_or("frame_dt", 1e-2)?;
    let frame_num = r.f64_or("frame_num", 100.0)?;
    if !(frame_num >= 0.0 && frame_num.fract() == 0.0) {
        return Err(r.err("frame_num", "expected a non-negative integer"));
    }
    // PhysGaussian: steps_per_frame = int(frame_dt / substep_dt) (truncation, as Python does);
    // a non-positive substep_dt is refused by the validator before this count is used.
    let substeps = (frame_dt / substep_dt) as u32;

    let mut parts = vec![base];
    let mut regions = Vec::new();
    if let Some(v) = map.get("additional_material_params") {
        let list = v
            .as_array()
            .ok_or_else(|| r.err("additional_material_params", "expected a list"))?;
        for (i, item) in list.iter().enumerate() {
            let m = item.as_object().ok_or_else(|| {
                r.err(
                    &format!("additional_material_params[{i}]"),
                    "expected an object",
                )
            })?;
            let rr = Reader {
                file,
                map: m,
                ctx: format!("additional_material_params[{i}]."),
            };
            strict::check_keys(
                m.keys(),
                &["point", "size", "E", "nu", "density"],
                &format!("additional_material_params[{i}]"),
            )
            .map_err(|e| Error::config(file, e))?;
            regions.push(MaterialRegion {
                point: rr.vec3_req("point")?,
                size: rr.vec3_req("size")?,
            });
            parts.push(PartParams {
                youngs_modulus_pa: rr.f64_req("E")?,
                poisson_ratio: rr.f64_req("nu")?,
                density_kg_m3: rr.f64_or("density", base.density_kg_m3)?,
                ..base
            });
        }
    }

    let mut boundary = Vec::new();
    // The entry of `boundary_conditions` each condition comes from (one entry may expand).
    let mut sources = Vec::new();
    if let Some(v) = map.get("boundary_conditions") {
        let list = v
            .as_array()
            .ok_or_else(|| r.err("boundary_conditions", "expected a list"))?;
        for (i, item) in list.iter().enumerate() {
            let m = item
                .as_object()
                .ok_or_else(|| r.err(&format!("boundary_conditions[{i}]"), "expected an object"))?;
            let b = Reader {
                file,
                map: m,
                ctx: format!("boundary_conditions[{i}]."),
            };
            let ty = match m.get("type") {
                Some(Value::String(t)) => t.as_str(),
                Some(_) => return Err(b.err("type", "expected a string")),
                None => return Err(b.err("type", "missing")),
            };
            let keys: &[&str] = match ty {
                "bounding_box" => &["type"],
                "cuboid" => &[
                    "type",
                    "point",
                    "size",
                    "velocity",
                    "start_time",
                    "end_time",
                    "reset",
                ],
                "particle_impulse" => &["type", "force", "point", "size", "num_dt", "start_time"],
                "enforce_particle_translation" => &[
                    "type",
                    "velocity",
                    "point",
                    "size",
                    "start_time",
                    "end_time",
                ],
                "release_particles_sequentially" => &[
                    "type",
                    "normal",
                    "start_position",
                    "end_position",
                    "start_time",
                    "end_time",
                    "num_layers",
                ],
                "surface_collider" => &[
                    "type",
                    "point",
                    "normal",
                    "surface",
                    "friction",
                    "start_time",
                    "end_time",
                ],
                "enforce_particle_velocity_rotation" => {
                    return Err(b.err(
                        "type",
                        "enforce_particle_velocity_rotation is not supported yet",
                    ))
                }
                other => {
                    return Err(Error::config(
                        file,
                        strict::unknown_value(
                            &format!("boundary_conditions[{i}].type"),
                            other,
                            BOUNDARY_TYPES,
                        ),
                    ))
                }
            };
            strict::check_keys(m.keys(), keys, &format!("boundary_conditions[{i}]"))
                .map_err(|e| Error::config(file, e))?;
            let before = boundary.len();
            match ty {
                "bounding_box" => boundary.push(BoundaryCondition::BoundingBox {
                    layers: 3,
                    surface: Surface::Slip,
                }),
                "cuboid" => boundary.push(BoundaryCondition::Cuboid {
                    point: b.vec3_req("point")?,
                    size: b.vec3_req("size")?,
                    velocity: b.vec3_req("velocity")?,
                    start_time: b.f64_or("start_time", 0.0)?,
                    end_time: b.f64_or("end_time", 1e3)?,
                    reset: b.f64_or("reset", 0.0)? == 1.0,
                }),
                "particle_impulse" => {
                    let num_dt = b.f64_or("num_dt", 1.0)?;
                    if !(num_dt >= 0.0 && num_dt.fract() == 0.0) {
                        return Err(b.err("num_dt", "expected a non-negative integer"));
                    }
                    boundary.push(BoundaryCondition::ParticleImpulse {
                        force: b.vec3_req("force")?,
                        point: b.vec3_or("point", [1.0; 3])?,
                        size: b.vec3_or("size", [1.0; 3])?,
                        num_dt: num_dt as u32,
                        start_time: b.f64_or("start_time", 0.0)?,
                    })
                }
                "enforce_particle_translation" => {
                    boundary.push(BoundaryCondition::ParticleVelocity {
                        velocity: b.vec3_req("velocity")?,
                        point: b.vec3_req("point")?,
                        size: b.vec3_req("size")?,
                        start_time: b.f64_req("start_time")?,
                        end_time: b.f64_req("end_time")?,
                    })
                }
                "release_particles_sequentially" => {
                    // PhysGaussian expands this into 50 held layers (num_layers is ignored).
                    let normal = b.vec3_req("normal")?;
                    let s0 = b.f64_req("start_position")?;
                    let s1 = b.f64_req("end_position")?;
                    let t0 = b.f64_req("start_time")?;
                    let t1 = b.f64_req("end_time")?;
                    let axis = (0..3)
                        .rev()
                        .find(|&a| normal[a] != 0.0)
                        .ok_or_else(|| b.err("normal", "must have a non-zero component"))?;
                    let layers = 50;
                    let l = (s0 - s1).abs() / layers as f64;
                    for i in 0..layers {
                        let mut point = [1.0; 3];
                        let mut size = [1.0; 3];
                        point[axis] = s1;
                        size[axis] = l * (layers - i) as f64;
                        boundary.push(BoundaryCondition::ParticleVelocity {
                            velocity: [0.0; 3],
                            point,
                            size,
                            start_time: t0,
                            end_time: t1 * (i + 1) as f64 / layers as f64,
                        });
                    }
                }
                "surface_collider" => {
                    let surface = match m.get("surface") {
                        Some(Value::String(t)) => match t.as_str() {
                            "sticky" => Surface::Sticky,
                            "slip" => Surface::Slip,
                            "friction" => Surface::Friction,
                            "cut" => return Err(b.err(
                                "surface",
                                "'cut' is a hard-coded special case of PhysGaussian and is not supported",
                            )),
                            other => {
                                return Err(Error::config(
                                    file,
                                    strict::unknown_value(
                                        &format!("boundary_conditions[{i}].surface"),
                                        other,
                                        &["sticky", "slip", "friction", "cut"],
                                    ),
                                ))
                            }
                        },
                        Some(_) => return Err(b.err("surface", "expected a string")),
                        None => return Err(b.err("surface", "missing")),
                    };
                    boundary.push(BoundaryCondition::SurfaceCollider {
                        point: b.vec3_req("point")?,
                        normal: b.vec3_req("normal")?,
                        surface,
                        friction: b.f64_or("friction", 0.0)?,
                        start_time: b.f64_or("start_time", 0.0)?,
                        end_time: b.f64_or("end_time", 1e3)?,
                    });
                    if surface != Surface::Sticky {
                        warnings.push(format!(
                            "boundary_conditions[{i}]: '{}' collider applied as intended; PhysGaussian's solver makes every collider sticky (a bug)",
                            m.get("surface").and_then(Value::as_str).unwrap_or("")
                        ));
                    }
                }
                _ => {}
            }
            sources.resize(boundary.len(), i);
            debug_assert!(boundary.len() > before);
        }
    }

    for key in map.keys() {
        if PREPROCESSING_KEYS.contains(&key.as_str()) {
            warnings.push(format!(
                "{key}: Gaussian-scene preprocessing is done by `r4d prepare`; the particles are taken as given, in MPM space"
            ));
        }
    }

    let config = SimConfig {
        domain: Domain {
            grid_lim,
            n_grid: n_grid as usize,
        },
        time: TimeConfig {
            substep_dt,
            frame_dt: Some(frame_dt),
            substeps_per_frame: Some(substeps.max(1)),
            frames: frame_num as usize,
        },
        solver: SolverConfig {
            gravity,
            force: ForceForm::Classic,
            rpic_damping: r.f64_or("rpic_damping", 0.0)?,
            grid_v_damping: r.f64_or("grid_v_damping_scale", 1.1)?,
            out_of_domain: OutOfDomain::Error,
            max_cfl: 1.0,
        },
        parts,
        shapes: Vec::new(),
        particles: None,
        boundary,
    };
    config.validate_named(file, &|f| key_of(f, &sources))?;
    Ok(Import {
        config,
        regions,
        warnings,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn imports_keys_defaults_and_regions() {
        let imp = import_str(
            r#"{"material": "metal", "E": 2e6, "nu": 0.3, "g": [0,0,-9.8], "yield_stress": 1e4,
                "hardening": 1, "xi": 0.5, "substep_dt": 2e-5, "frame_dt": 0.02, "frame_num": 3,
                "rotation_degree": [10.0],
                "boundary_conditions": [{"type": "bounding_box"},
                  {"type": "surface_collider", "point": [0,0,0.5], "normal": [0,0,1], "surface": "slip", "friction": 0.0, "start_time": 0, "end_time": 1}],
                "additional_material_params": [{"point": [1,1,1], "size": [0.1,0.1,0.1], "E": 1e5, "nu": 0.2}]}"#,
            "x.json",
        )
        .unwrap();
        let c = &imp.config;
        assert_eq!(
            c.time.substeps(),
            999,
            "int(0.02 / 2e-5) truncates to 999 in PhysGaussian"
        );
        assert_eq!(c.domain.n_grid, 50);
        assert_eq!(c.parts.len(), 2);
        assert!(c.parts[0].hardening);
        assert_eq!(c.parts[1].density_kg_m3, 200.0);
        assert_eq!(c.boundary.len(), 2);
        assert_eq!(imp.warnings.len(), 2, "{:?}", imp.warnings);
        let mut s = ParticleSet {
            x: vec![[1.0, 1.0, 1.0], [0.5, 0.5, 0.5]],
            volume: vec![1.0; 2],
            part: vec![0; 2],
        };
        imp.apply_to_scene(&mut s, true);
        assert_eq!(s.part, vec![1, 0]);
    }

    #[test]
    fn bad_values_are_typed_errors_naming_the_key() {
        let e = import_str(r#"{"g": [0,0,-9.8], "nu": 0.5}"#, "s.json")
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("s.json") && e.contains("invalid nu = 0.5"),
            "{e}"
        );
        let e = import_str(r#"{"E": 1e5}"#, "s.json")
            .unwrap_err()
            .to_string();
        assert!(e.contains("g: missing"), "{e}");
        let e = import_str(
            r#"{"g": [0,0,-9.8], "boundary_conditions": [{"type": "warp"}]}"#,
            "s.json",
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("`boundary_conditions[0].type`"), "{e}");
        let e = import_str(r#"{"g": [0,0,0], "n_grid": 1e9}"#, "s.json")
            .unwrap_err()
            .to_string();
        assert!(e.contains("n_grid") && e.contains("1024"), "{e}");
    }

    /// The importer's values go through the project's validator: what the TOML refuses, the
    /// JSON refuses with the same limit and message, naming the PhysGaussian key.
    #[test]
    fn the_project_validator_checks_imported_values() {
        let toml_err = |solver: &str| {
            let text = format!(
                "[time]\nsubstep_dt = 1e-4\nframes = 2\n[solver]\n{solver}\n[[parts]]\nmaterial = \"jelly\"\n"
            );
            SimConfig::parse(&text, Path::new("c.toml"))
                .unwrap()
                .validate("c.toml")
                .unwrap_err()
                .to_string()
        };
        for v in ["-1", "0"] {
            let e = import_str(
                &format!(r#"{{"g": [0,0,-9.8], "grid_v_damping_scale": {v}}}"#),
                "s.json",
            )
            .unwrap_err()
            .to_string();
            assert!(e.contains("s.json: invalid grid_v_damping_scale"), "{e}");
            let t = toml_err(&format!("grid_v_damping = {v}"));
            let reason = |m: &str| m.rsplit(": ").next().unwrap_or("").to_string();
            assert_eq!(reason(&e), reason(&t), "{e} / {t}");
        }
        let e = import_str(r#"{"g": [0,0,-9.8], "frame_num": 1e9}"#, "s.json")
            .unwrap_err()
            .to_string();
        assert!(e.contains("frame_num") && e.contains("MAX_FRAMES"), "{e}");
        let e = import_str(r#"{"g": [0,0,-9.8], "substep_dt": -1}"#, "s.json")
            .unwrap_err()
            .to_string();
        assert!(e.contains("invalid substep_dt = -1"), "{e}");
        let e = import_str(
            r#"{"g": [0,0,-9.8], "boundary_conditions": [{"type": "bounding_box"},
                {"type": "release_particles_sequentially", "normal": [0,0,1], "start_position": 1,
                 "end_position": 1, "start_time": 0, "end_time": 1}]}"#,
            "s.json",
        )
        .unwrap_err()
        .to_string();
        assert!(
            e.contains("boundary_conditions[1].size[2]") && e.contains("half extent"),
            "the expanded layers are named by their entry: {e}"
        );
    }

    /// Keys: a key twice, an unknown key at any depth, an unknown material or surface is an
    /// error naming it with the closest known name (never last-wins, never jelly).
    #[test]
    fn keys_and_names_are_strict() {
        let err = |t: &str| import_str(t, "s.json").unwrap_err().to_string();
        let e = err(r#"{"g": [0,0,-9.8], "E": 1e5, "E": 2e5}"#);
        assert!(
            e.contains("s.json") && e.contains("duplicate key `E`"),
            "{e}"
        );
        let e = err(r#"{"g": [0,0,-9.8], "materail": "metal"}"#);
        assert!(
            e.contains("`materail`") && e.contains("did you mean `material`?"),
            "{e}"
        );
        let e = err(r#"{"g": [0,0,-9.8], "material": "jely"}"#);
        assert!(
            e.contains("unknown value `jely` of `material`: did you mean `jelly`?"),
            "{e}"
        );
        let e = err(r#"{"g": [0,0,-9.8], "material": "rubber"}"#);
        assert!(e.contains("unknown value `rubber`"), "{e}");
        let e = err(
            r#"{"g": [0,0,-9.8], "boundary_conditions": [{"type": "cuboid", "point": [1,1,1],
                "size": [0.1,0.1,0.1], "velocity": [0,0,0], "strat_time": 0}]}"#,
        );
        assert!(
            e.contains("`boundary_conditions[0].strat_time`") && e.contains("`start_time`?"),
            "{e}"
        );
        let e = err(
            r#"{"g": [0,0,-9.8], "boundary_conditions": [{"type": "surface_collider",
                "point": [1,1,1], "normal": [0,0,1], "surface": "stiky"}]}"#,
        );
        assert!(e.contains("`stiky`") && e.contains("`sticky`?"), "{e}");
        let e = err(
            r#"{"g": [0,0,-9.8], "additional_material_params": [{"point": [1,1,1],
                "size": [1,1,1], "E": 1e5, "nu": 0.2, "densty": 3}]}"#,
        );
        assert!(e.contains("additional_material_params[0].densty"), "{e}");
        assert!(err("[]").contains("expected a table of keys"));
    }
}
