//! PhysFlow's per-scene physics config (`config/<dataset>/<scene>_config.json` of
//! github.com/zhuomanliu/PhysFlow, parsed there by `utils/decode_param.py`).
//!
//! PhysFlow's solver is a fork of PhysGaussian's, so the config is decoded by the PhysGaussian
//! importer ([`r4d_mpm::physgaussian`]: the same keys, defaults, boundary conditions and
//! truncating `int(frame_dt / substep_dt)` substeps) after four PhysFlow rules are applied:
//!
//! * **Scaled units.** PhysFlow's solver multiplies `E` by `1e7` (`SCALE_E`), `yield_stress` by
//!   `1e5` (`SCALE_YS`) and `plastic_viscosity` by `1e4` (`SCALE_PV`) (`mpm_solver_warp/
//!   mpm_utils.py`); density and friction angle are used as written. The decoded
//!   [`SimConfig`] is in SI units (Pa, Pa s, kg/m^3), as our solver uses them;
//!   [`PhysFlowUnits`] converts back.
//! * **Material names and ids.** `jelly`/`elastic` 0, `metal` 1, `sand` 2, `foam` 3,
//!   `plasticine` 4, `newtonian` 5, `non_newtonian` 6 (PhysFlow's `set_parameters_dict`; note
//!   plasticine is 4 there, 5 in PhysGaussian). `non_newtonian` (PhysFlow's toothpaste, cream,
//!   jam) and `newtonian` (droplet, letter) are our [`Material::NonNewtonian`] and
//!   [`Material::Newtonian`], PhysFlow's models as its solver computes them (see
//!   [`r4d_mpm::constitutive`]).
//! * **Every surface collider holds.** PhysFlow's `add_surface_collider` computes the slip or
//!   frictional velocity and then writes zero for every surface but its special `"cut"`: its
//!   scenes move as if every collider were `sticky`, so they are read that way (friction 0),
//!   without a warning (the PhysGaussian importer, for PhysGaussian's own scenes, applies
//!   `slip` and `friction` as intended and says so).
//! * **PhysFlow-only keys** are read with the decoder's defaults and kept in
//!   [`PhysFlowExtras`]: `opt_frame_dt` (1e-2), `mu_N` (5), `lam_N` (5), `viscosity` (0.1),
//!   `pic_damping`, `line`, `bbox_2d`, `reduction` ("sum"), `lr`, and the camera keys
//!   (`mpm_space_viewpoint_center` [1, 1, 1], `mpm_space_vertical_upward_axis` [0, 0, 1],
//!   `default_camera_index` 0, `move_camera` false, `delta_a/e/r`, ...). The preprocessing keys
//!   (`opacity_threshold` 0.02, `rotation_degree`, `rotation_axis`, `sim_area`,
//!   `particle_filling` with its defaults) become an [`r4d_splat::PrepareConfig`].
//!
//! Differences from PhysFlow's decoder, on purpose: a missing `g` is an error (PhysFlow's
//! default, the scalar 9.8, crashes its solver); a key given twice, or a key PhysFlow's decoder
//! does not know (at any depth), is an error naming it with the closest known key (PhysFlow
//! keeps the last and ignores unknown keys silently); the values go through the project's one
//! validator ([`SimConfig::validate_named`]), as the project's TOML and PhysGaussian's JSON do.

use crate::error::{DatasetError, Result};
use r4d_mpm::physgaussian;
use r4d_mpm::{Material, SimConfig};
use r4d_splat::PrepareConfig;
use serde::Serialize;
use serde_json::{Map, Value};
use std::path::{Path, PathBuf};

/// PhysFlow's unit scale of Young's modulus (`SCALE_E`): `E_Pa = E_config * 1e7`.
pub const SCALE_E: f64 = 1e7;
/// PhysFlow's unit scale of the yield stress (`SCALE_YS`): `tau_Pa = tau_config * 1e5`.
pub const SCALE_YS: f64 = 1e5;
/// PhysFlow's unit scale of the plastic viscosity (`SCALE_PV`): `eta_Pa_s = eta_config * 1e4`.
pub const SCALE_PV: f64 = 1e4;

/// A part's parameters in PhysFlow's config units (paste them back into a PhysFlow config).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, serde::Deserialize)]
pub struct PhysFlowUnits {
    /// Young's modulus / 1e7.
    #[serde(rename = "E")]
    pub e: f64,
    /// Poisson's ratio.
    pub nu: f64,
    /// Density (kg/m^3, unscaled).
    pub density: f64,
    /// Yield stress / 1e5.
    pub yield_stress: f64,
    /// Plastic viscosity / 1e4.
    pub plastic_viscosity: f64,
}

impl PhysFlowUnits {
    /// Converts SI parameters (as the solver uses them) to PhysFlow's config units.
    pub fn from_si(p: &r4d_mpm::PartParams) -> Self {
        PhysFlowUnits {
            e: p.youngs_modulus_pa / SCALE_E,
            nu: p.poisson_ratio,
            density: p.density_kg_m3,
            yield_stress: p.yield_stress_pa / SCALE_YS,
            plastic_viscosity: p.plastic_viscosity_pa_s / SCALE_PV,
        }
    }
}

/// The keys PhysFlow reads that do not reach the solver (defaults of `decode_param.py`).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct PhysFlowExtras {
    /// The material name as written.
    pub material_name: String,
    /// PhysFlow's material id (see the module docs).
    pub material_id: u32,
    /// `opt_frame_dt` (s): the simulated time between PhysFlow's optimisation frames.
    pub opt_frame_dt: f64,
    /// `frame_dt` (s) as written.
    pub frame_dt: f64,
    /// `frame_num`.
    pub frame_num: usize,
    /// `mu_N`, `lam_N`, `viscosity` (read by PhysFlow's decoder for its fluids).
    pub mu_n: f64,
    /// See `mu_n`.
    pub lam_n: f64,
    /// See `mu_n`.
    pub viscosity: f64,
    /// `default_camera_index` (0).
    pub default_camera_index: i64,
    /// `move_camera` (false): PhysFlow orbits its render camera per frame; not reproduced.
    pub move_camera: bool,
    /// `mpm_space_viewpoint_center` ([1, 1, 1]).
    pub mpm_space_viewpoint_center: [f64; 3],
    /// `mpm_space_vertical_upward_axis` ([0, 0, 1]).
    pub mpm_space_vertical_upward_axis: [f64; 3],
    /// `line` (the w-t slice: `axis`, `pos`, `start`, `end`), when present.
    pub line: Option<Value>,
    /// `bbox_2d`, when present.
    pub bbox_2d: Option<Value>,
    /// `reduction` ("sum").
    pub reduction: String,
    /// `lr`, when present.
    pub lr: Option<Value>,
}

/// A decoded PhysFlow config.
#[derive(Clone, Debug)]
pub struct PhysFlowConfig {
    /// The file.
    pub path: PathBuf,
    /// The solver's config in SI units (no particles yet).
    pub config: SimConfig,
    /// `additional_material_params` regions (region `r` is part `r + 1`), simulation space.
    pub regions: Vec<physgaussian::MaterialRegion>,
    /// The preprocessing keys.
    pub prepare: PrepareConfig,
    /// PhysFlow-only keys.
    pub extras: PhysFlowExtras,
    /// Keys ignored or interpreted differently, with the reason.
    pub warnings: Vec<String>,
}

/// Keys read by PhysFlow's decoder that the PhysGaussian importer does not know.
pub const PHYSFLOW_ONLY: &[&str] = &[
    "opt_frame_dt",
    "mu_N",
    "lam_N",
    "viscosity",
    "line",
    "bbox_2d",
    "reduction",
    "lr",
];

fn num(map: &Map<String, Value>, key: &str, default: f64, path: &Path) -> Result<f64> {
    match map.get(key) {
        None | Some(Value::Null) => Ok(default),
        Some(v) => v
            .as_f64()
            .filter(|x| x.is_finite())
            .ok_or_else(|| DatasetError::invalid(path, format!("{key}: expected a number"))),
    }
}

fn vec3(map: &Map<String, Value>, key: &str, default: [f64; 3], path: &Path) -> Result<[f64; 3]> {
    match map.get(key) {
        None | Some(Value::Null) => Ok(default),
        Some(Value::Array(a)) if a.len() == 3 && a.iter().all(|v| v.as_f64().is_some()) => {
            Ok([0, 1, 2].map(|i| a[i].as_f64().unwrap_or(0.0)))
        }
        Some(_) => Err(DatasetError::invalid(
            path,
            format!("{key}: expected an array of 3 numbers"),
        )),
    }
}

/// Scales a unit-scaled key of an object in place (`E`, `yield_stress`, `plastic_viscosity`).
fn scale_key(
    map: &mut Map<String, Value>,
    key: &str,
    s: f64,
    ctx: &str,
    path: &Path,
) -> Result<()> {
    if let Some(v) = map.get(key) {
        if v.is_null() {
            return Ok(());
        }
        let x = v
            .as_f64()
            .ok_or_else(|| DatasetError::invalid(path, format!("{ctx}{key}: expected a number")))?;
        map.insert(key.into(), Value::from(x * s));
    }
    Ok(())
}

/// Reads and decodes a PhysFlow config file.
pub fn load(path: &Path) -> Result<PhysFlowConfig> {
    decode(&crate::error::read_text(path)?, path)
}

/// Decodes PhysFlow config text; `path` names the file in errors.
pub fn decode(text: &str, path: &Path) -> Result<PhysFlowConfig> {
    // A key twice is an error (never last-wins), as in every config dialect.
    let mut map =
        r4d_mpm::strict::parse_json_object(text).map_err(|e| DatasetError::invalid(path, e))?;
    let mut known = physgaussian::known_keys();
    known.extend(PHYSFLOW_ONLY);
    r4d_mpm::strict::check_keys(map.keys(), &known, "")
        .map_err(|e| DatasetError::invalid(path, e))?;
    let mut warnings = Vec::new();
    let material_name = match map.get("material") {
        None => "jelly".to_string(),
        Some(Value::String(s)) => s.clone(),
        Some(_) => return Err(DatasetError::invalid(path, "material: expected a string")),
    };
    let (material_id, ours) = match material_name.as_str() {
        "jelly" | "elastic" => (0, "jelly"),
        "metal" => (1, "metal"),
        "sand" => (2, "sand"),
        "foam" => (3, "foam"),
        "plasticine" => (4, "plasticine"),
        "newtonian" => (5, "newtonian"),
        "non_newtonian" => (6, "non_newtonian"),
        other => {
            return Err(DatasetError::invalid(
                path,
                r4d_mpm::strict::unknown_value(
                    "material",
                    other,
                    &[
                        "jelly",
                        "elastic",
                        "metal",
                        "sand",
                        "foam",
                        "plasticine",
                        "newtonian",
                        "non_newtonian",
                    ],
                ),
            ))
        }
    };
    map.insert("material".into(), Value::from(ours));
    if let Some(Value::Array(list)) = map.get_mut("boundary_conditions") {
        for bc in list.iter_mut().filter_map(Value::as_object_mut) {
            let collider = bc.get("type").and_then(Value::as_str) == Some("surface_collider");
            let cut = bc.get("surface").and_then(Value::as_str) == Some("cut");
            if collider && !cut && bc.get("surface").is_some_and(Value::is_string) {
                bc.insert("surface".into(), Value::from("sticky"));
                bc.insert("friction".into(), Value::from(0.0));
            }
        }
    }
    scale_key(&mut map, "E", SCALE_E, "", path)?;
    // PhysFlow's decoder default E = 1e5 is also in scaled units.
    if map.get("E").is_none_or(Value::is_null) {
        map.insert("E".into(), Value::from(1e5 * SCALE_E));
    }
    scale_key(&mut map, "yield_stress", SCALE_YS, "", path)?;
    scale_key(&mut map, "plastic_viscosity", SCALE_PV, "", path)?;
    if let Some(list) = map.get_mut("additional_material_params") {
        if let Some(list) = list.as_array_mut() {
            for (i, item) in list.iter_mut().enumerate() {
                if let Some(m) = item.as_object_mut() {
                    let ctx = format!("additional_material_params[{i}].");
                    scale_key(m, "E", SCALE_E, &ctx, path)?;
                }
            }
        }
    }
    let extras = PhysFlowExtras {
        material_name: material_name.clone(),
        material_id,
        opt_frame_dt: num(&map, "opt_frame_dt", 1e-2, path)?,
        frame_dt: num(&map, "frame_dt", 1e-2, path)?,
        frame_num: num(&map, "frame_num", 100.0, path)?.max(0.0) as usize,
        mu_n: num(&map, "mu_N", 5.0, path)?,
        lam_n: num(&map, "lam_N", 5.0, path)?,
        viscosity: num(&map, "viscosity", 1e-1, path)?,
        default_camera_index: num(&map, "default_camera_index", 0.0, path)? as i64,
        move_camera: match map.get("move_camera") {
            None | Some(Value::Null) => false,
            Some(Value::Bool(b)) => *b,
            Some(_) => {
                return Err(DatasetError::invalid(
                    path,
                    "move_camera: expected true or false",
                ))
            }
        },
        mpm_space_viewpoint_center: vec3(&map, "mpm_space_viewpoint_center", [1.0; 3], path)?,
        mpm_space_vertical_upward_axis: vec3(
            &map,
            "mpm_space_vertical_upward_axis",
            [0.0, 0.0, 1.0],
            path,
        )?,
        line: map.get("line").filter(|v| !v.is_null()).cloned(),
        bbox_2d: map.get("bbox_2d").filter(|v| !v.is_null()).cloned(),
        reduction: match map.get("reduction") {
            None | Some(Value::Null) => "sum".into(),
            Some(Value::String(s)) => s.clone(),
            Some(_) => return Err(DatasetError::invalid(path, "reduction: expected a string")),
        },
        lr: map.get("lr").filter(|v| !v.is_null()).cloned(),
    };
    if extras.opt_frame_dt.is_nan() || extras.opt_frame_dt <= 0.0 {
        return Err(DatasetError::invalid(
            path,
            format!("opt_frame_dt = {} must be > 0", extras.opt_frame_dt),
        ));
    }
    if extras.move_camera {
        warnings.push(
            "move_camera: PhysFlow orbits its render camera by delta_a/delta_e/delta_r per frame; \
             the views here are the dataset's cameras as stored (the reference video's camera \
             does not move)"
                .to_string(),
        );
    }
    // The preprocessing keys, with PhysFlow's defaults (PrepareConfig's serde names match).
    let mut pre = Map::new();
    for key in [
        "opacity_threshold",
        "rotation_degree",
        "rotation_axis",
        "sim_area",
        "particle_filling",
        "grid_lim",
    ] {
        if let Some(v) = map.get(key).filter(|v| !v.is_null()) {
            pre.insert(key.into(), v.clone());
        }
    }
    let prepare: PrepareConfig = r4d_mpm::strict::decode_value(Value::Object(pre))
        .map_err(|e| DatasetError::invalid(path, format!("preprocessing keys: {e}")))?;
    for key in PHYSFLOW_ONLY {
        map.remove(*key);
    }
    let file = path.display().to_string();
    let imp = physgaussian::import_str(&Value::Object(map).to_string(), &file)?;
    for w in imp.warnings {
        // The importer's note on preprocessing keys is about `r4d prepare`; here the loader
        // applies them.
        if !w.contains("r4d prepare") {
            warnings.push(w);
        }
    }
    debug_assert!(imp
        .config
        .parts
        .iter()
        .all(|p| p.material != Material::Snow));
    Ok(PhysFlowConfig {
        path: path.to_path_buf(),
        config: imp.config,
        regions: imp.regions,
        prepare,
        extras,
        warnings,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    const TELEPHONE: &str = r#"{
        "opacity_threshold": 0.02, "rotation_degree": [0.0], "rotation_axis": [0],
        "substep_dt": 1e-4, "frame_dt": 4e-2, "opt_frame_dt": 4e-2, "frame_num": 50,
        "nu": 0.45, "E": 0.1, "material": "elastic", "density": 1350, "g": [0,0,0],
        "grid_v_damping_scale": 0.9999, "rpic_damping": 0.0,
        "boundary_conditions": [
            {"type": "bounding_box"},
            {"type": "cuboid", "point": [0.95, 0.98, 1.44], "size": [0.1, 0.1, 0.1],
             "velocity": [0, 0, 0], "start_time": 0, "end_time": 1e3, "reset": 1},
            {"type": "particle_impulse", "force": [-1.0, 0, 0], "point": [1.048, 0.8972, 1.0461],
             "num_dt": 2, "start_time": 0}],
        "mpm_space_vertical_upward_axis": [0,0,1], "mpm_space_viewpoint_center": [0.95,1.07,1],
        "default_camera_index": 0, "show_hint": false, "move_camera": true,
        "delta_a": -0.6, "delta_e": -0.1, "delta_r": 0.0005,
        "line": {"axis": 0, "pos": 850, "start": 500, "end": 1250},
        "bbox_2d": [200, 1050, 500, 1250], "reduction": "sum",
        "lr": {"E": [0.1, 0.001], "nu": [0.1, 0.001]}}"#;

    #[test]
    fn telephone_decodes_in_si_with_physflow_defaults() {
        let c = decode(TELEPHONE, Path::new("telephone_config.json")).unwrap();
        let p = &c.config.parts[0];
        assert_eq!(p.material, Material::Jelly);
        assert!((p.youngs_modulus_pa - 1e6).abs() < 1e-6, "E 0.1 x 1e7");
        assert_eq!(p.density_kg_m3, 1350.0);
        assert_eq!(c.config.domain.n_grid, 50, "PhysFlow's default n_grid");
        assert_eq!(c.config.domain.grid_lim, 2.0);
        assert_eq!(
            c.config.time.substeps(),
            400,
            "int(0.04 / 1e-4) = 400 in Python"
        );
        assert_eq!(c.config.time.frames, 50);
        assert_eq!(c.extras.opt_frame_dt, 0.04);
        assert!(c.extras.move_camera);
        assert_eq!(c.prepare.opacity_threshold, 0.02);
        match &c.config.boundary[2] {
            r4d_mpm::BoundaryCondition::ParticleImpulse { size, num_dt, .. } => {
                assert_eq!(*size, [1.0; 3], "PhysFlow's default impulse size");
                assert_eq!(*num_dt, 2);
            }
            b => panic!("{b:?}"),
        }
        assert!(c.warnings.iter().any(|w| w.contains("move_camera")));
    }

    #[test]
    fn plastic_units_scale_and_round_trip() {
        let c = decode(
            r#"{"material": "foam", "E": 0.01, "nu": 0.3, "yield_stress": 0.05,
                "plastic_viscosity": 0.01, "density": 75, "g": [0, 0, 0]}"#,
            Path::new("alocasia_config.json"),
        )
        .unwrap();
        let p = c.config.parts[0];
        assert!((p.youngs_modulus_pa - 1e5).abs() < 1e-6);
        assert!((p.yield_stress_pa - 5e3).abs() < 1e-9);
        assert!((p.plastic_viscosity_pa_s - 100.0).abs() < 1e-9);
        let back = PhysFlowUnits::from_si(&p);
        assert!((back.e - 0.01).abs() < 1e-15 && (back.yield_stress - 0.05).abs() < 1e-15);
        assert!((back.plastic_viscosity - 0.01).abs() < 1e-15 && back.density == 75.0);
        // Defaults of the decoder: E = 1e5 in scaled units, opt_frame_dt 1e-2, reduction sum
        // (so stiff that only a substep under the CFL bound of 3.9e-7 s simulates it).
        let stable = r#""substep_dt": 1e-7, "frame_dt": 1e-5"#;
        let e = decode(r#"{"g": [0, 0, -9.8]}"#, Path::new("d.json"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("d.json") && e.contains("CFL"), "{e}");
        let d = decode(
            &format!(r#"{{"g": [0, 0, -9.8], {stable}}}"#),
            Path::new("d.json"),
        )
        .unwrap();
        assert!((d.config.parts[0].youngs_modulus_pa - 1e12).abs() < 1.0);
        assert_eq!(d.extras.opt_frame_dt, 1e-2);
        assert_eq!(d.extras.reduction, "sum");
        assert_eq!(d.config.time.frames, 100);
        let n = decode(
            &format!(r#"{{"g": [0, 0, 0], "E": null, {stable}}}"#),
            Path::new("n.json"),
        )
        .unwrap();
        assert!(
            (n.config.parts[0].youngs_modulus_pa - 1e12).abs() < 1.0,
            "null E = default"
        );
    }

    /// PhysFlow's solver holds every surface collider (it writes zero velocity after computing
    /// the slip one): its scenes are read that way, without a warning.
    #[test]
    fn every_surface_collider_holds_as_in_physflows_solver() {
        let c = decode(
            r#"{"material": "jelly", "E": 1e-3, "g": [0, 0, -9.8], "boundary_conditions": [
                {"type": "surface_collider", "point": [1, 1, 0.5], "normal": [0, 0, 1],
                 "surface": "slip", "friction": 0.3, "start_time": 0, "end_time": 1e3}]}"#,
            Path::new("slip.json"),
        )
        .unwrap();
        assert!(c.warnings.is_empty(), "{:?}", c.warnings);
        match &c.config.boundary[..] {
            [r4d_mpm::BoundaryCondition::SurfaceCollider {
                surface, friction, ..
            }] => {
                assert_eq!(*surface, r4d_mpm::Surface::Sticky);
                assert_eq!(*friction, 0.0);
            }
            b => panic!("{b:?}"),
        }
    }

    #[test]
    fn physflow_materials_and_refusals() {
        let nn = decode(
            r#"{"material": "non_newtonian", "E": 3e-5, "nu": 0.3, "g": [0,-9.8,0]}"#,
            Path::new("t.json"),
        )
        .unwrap();
        assert_eq!(nn.config.parts[0].material, Material::NonNewtonian);
        assert_eq!(nn.extras.material_id, 6);
        assert!(nn.warnings.is_empty(), "{:?}", nn.warnings);
        let pl = decode(
            r#"{"material": "plasticine", "E": 1e-3, "g": [0,-9.8,0]}"#,
            Path::new("c.json"),
        )
        .unwrap();
        assert_eq!(pl.extras.material_id, 4);
        let nw = decode(
            r#"{"material": "newtonian", "E": 5e-4, "nu": 0.499, "density": 800, "g": [0,0,0]}"#,
            Path::new("drop.json"),
        )
        .unwrap();
        assert_eq!(nw.config.parts[0].material, Material::Newtonian);
        assert_eq!(nw.extras.material_id, 5);
        assert!(nw.warnings.is_empty(), "{:?}", nw.warnings);
        let e = decode(
            r#"{"material": "honey", "g": [0,0,0]}"#,
            Path::new("h.json"),
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("h.json") && e.contains("honey"), "{e}");
        let e = decode(r#"{"E": 0.1}"#, Path::new("g.json"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("g.json") && e.contains("g: missing"), "{e}");
        let e = decode(
            r#"{"g": [0,0,0], "boundary_conditions": [{"type": "cuboid", "point": [1,1,1]}]}"#,
            Path::new("b.json"),
        )
        .unwrap_err()
        .to_string();
        assert!(
            e.contains("b.json") && e.contains("boundary_conditions[0]"),
            "{e}"
        );
        let e = decode(
            r#"{"g": [0,0,0], "opt_frame_dt": "x"}"#,
            Path::new("o.json"),
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("o.json") && e.contains("opt_frame_dt"), "{e}");
    }

    /// The same strict rules as every config dialect: a key twice, an unknown key at any depth
    /// (top level, a boundary condition, `particle_filling`) and the project's value limits.
    #[test]
    fn keys_and_values_are_checked_as_in_every_dialect() {
        let err = |t: &str| decode(t, Path::new("p.json")).unwrap_err().to_string();
        let e = err(r#"{"g": [0,0,0], "E": 0.1, "E": 0.2}"#);
        assert!(
            e.contains("p.json") && e.contains("duplicate key `E`"),
            "{e}"
        );
        let e = err(r#"{"g": [0,0,0], "opt_frame_dtt": 0.1}"#);
        assert!(
            e.contains("`opt_frame_dtt`") && e.contains("`opt_frame_dt`?"),
            "{e}"
        );
        let e = err(r#"{"g": [0,0,0], "particle_filling": {"n_gird": 64}}"#);
        assert!(
            e.contains("`particle_filling.n_gird`") && e.contains("`n_grid`?"),
            "{e}"
        );
        let e = err(r#"{"g": [0,0,0], "grid_v_damping_scale": 0}"#);
        assert!(
            e.contains("invalid grid_v_damping_scale = 0: must be > 0"),
            "{e}"
        );
        let e = err(r#"{"g": [0,0,0], "material": "jely"}"#);
        assert!(e.contains("`jelly`?"), "{e}");
        assert!(err("[]").contains("expected a table of keys"));
    }
}
