//! The built-in scenes as data: each scene's geometry, materials, loads, cameras, truth and
//! fit settings in one TOML file (`configs/demo/<scene>.toml`, compiled into the binary),
//! built into a [`SceneSpec`] by [`build`].
//!
//! A scene file is a simulation config (`[solver]`, `[[parts]]` with the true parameters,
//! `[[shapes]]`, `[[boundary]]`; see `docs/cli/config.md`) without `[domain]` and `[time]`,
//! which come from the size, plus two tables:
//!
//! * `[demo]`: `name`, `description` (`{frames}`, `{width}` and `{height}` are replaced by
//!   the size's), `part_names`, `palettes` (per part: `green`, `red_gold`, `steel`, `sand`,
//!   `foam`, `clay`, `paste`, `water`), `floor_z` (the visible floor's height, m),
//!   `frame_dt` (s, default 0.025), `[demo.full]` and `[demo.small]` (`n_grid`, `frames`,
//!   `resolution = [width, height]`, `substep_dt`), and `[[demo.cameras]]` (`name`, `eye`,
//!   `target`; 40-degree field of view, z up);
//! * `[fit]`: `free` (per part, the fitted parameter names), `start` (per part, the values
//!   the fit starts from before its initialisation; the rest are the truth's), `bounds`
//!   (`"default"`: the default bounds of each part's material, or per part a table of
//!   `name = [low, high]`), `pairs` (`[part, a, b]` with a 2-D loss profile),
//!   `profile_offsets` and `profile2d_offsets`, and the fit's settings as in `FIT.toml`:
//!   `[fit.settings]`, overridden per size by `[fit.full]` and `[fit.small]`
//!   (`init.frames` defaults to the size's frames).
//!
//! Two keys of a `particle_impulse` boundary exist only here, so that a scene loads its
//! small and full versions alike: `accel = [ax, ay, az]` (m/s^2) instead of `force` gives
//! each particle the force `accel * density * (dx / 2)^3`, the density being that of the
//! truth's part `accel_part` (default 0; two particles per cell per axis); `duration` (s)
//! instead of `num_dt` is rounded to whole substeps.

use super::{stage, DemoScene, SceneSpec, Size};
use r4d_mpm::strict::{decode, Format};
use r4d_mpm::{ParticleSet, SimConfig};
use r4d_optim::space::set;
use r4d_optim::video::FitConfig;
use r4d_optim::{FitError, ParamKind};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::Path;

/// Most video frames a scene file may ask for.
pub const MAX_FRAMES: usize = 1000;

/// Longest side of a view a scene file may ask for (pixels).
pub const MAX_SIDE: u32 = 4096;

/// The text of a built-in scene's file.
pub fn text(scene: DemoScene) -> &'static str {
    match scene {
        DemoScene::Plant => include_str!("../../../configs/demo/plant.toml"),
        DemoScene::Metal => include_str!("../../../configs/demo/metal.toml"),
        DemoScene::Sand => include_str!("../../../configs/demo/sand.toml"),
        DemoScene::Foam => include_str!("../../../configs/demo/foam.toml"),
        DemoScene::Plasticine => include_str!("../../../configs/demo/plasticine.toml"),
        DemoScene::Paste => include_str!("../../../configs/demo/paste.toml"),
        DemoScene::Fluid => include_str!("../../../configs/demo/fluid.toml"),
    }
}

/// `[demo]`: what the scene looks like and its sizes.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DemoSection {
    /// The scene's name.
    pub name: String,
    /// One line for the progress output (`{frames}`, `{width}`, `{height}` replaced).
    pub description: String,
    /// Names of the parts.
    pub part_names: Vec<String>,
    /// Colours of the parts (see the module docs).
    pub palettes: Vec<String>,
    /// Height of the visible floor (m).
    pub floor_z: f64,
    /// Time between video frames (s).
    #[serde(default = "frame_dt")]
    pub frame_dt: f64,
    /// The demo's size.
    pub full: SizeSection,
    /// The tests' size.
    pub small: SizeSection,
    /// The views.
    pub cameras: Vec<CameraSection>,
}

fn frame_dt() -> f64 {
    0.025
}

/// `[demo.full]`, `[demo.small]`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SizeSection {
    /// Grid nodes per axis over the unit box.
    pub n_grid: usize,
    /// Video frames.
    pub frames: usize,
    /// `[width, height]` of every view.
    pub resolution: [u32; 2],
    /// Simulation substep (s).
    pub substep_dt: f64,
}

/// `[[demo.cameras]]`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CameraSection {
    /// The view's name.
    pub name: String,
    /// Camera position (m).
    pub eye: [f64; 3],
    /// The point it looks at (m).
    pub target: [f64; 3],
}

/// `bounds` of `[fit]`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum BoundsSection {
    /// `"default"`: the default bounds of each part's material.
    Named(String),
    /// Per part, `name = [low, high]`.
    Explicit(Vec<BTreeMap<String, [f64; 2]>>),
}

/// `[fit]`: what is fitted and how.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FitSection {
    /// Per part, the free parameters' names.
    pub free: Vec<Vec<String>>,
    /// Per part, the starting values that differ from the truth.
    #[serde(default)]
    pub start: Vec<BTreeMap<String, f64>>,
    /// The bounds.
    pub bounds: BoundsSection,
    /// `[part, a, b]`: pairs with a 2-D loss profile.
    #[serde(default)]
    pub pairs: Vec<(usize, String, String)>,
    /// Relative offsets of the 1-D profiles.
    pub profile_offsets: Vec<f64>,
    /// Relative offsets of each axis of the 2-D profiles.
    pub profile2d_offsets: Vec<f64>,
    /// `FIT.toml` keys for both sizes.
    #[serde(default)]
    pub settings: toml::Table,
    /// `FIT.toml` keys of the full size (over `settings`).
    #[serde(default)]
    pub full: toml::Table,
    /// `FIT.toml` keys of the small size (over `settings`).
    #[serde(default)]
    pub small: toml::Table,
}

/// A palette by name.
fn palette(name: &str) -> Option<stage::Palette> {
    Some(match name {
        "green" => stage::GREEN,
        "red_gold" => stage::RED_GOLD,
        "steel" => stage::STEEL,
        "sand" => stage::SAND,
        "foam" => stage::FOAM,
        "clay" => stage::CLAY,
        "paste" => stage::PASTE,
        "water" => stage::WATER,
        _ => return None,
    })
}

/// `b` merged over `a` (tables merged key by key, everything else replaced).
fn merge(a: &mut toml::Table, b: &toml::Table) {
    for (k, v) in b {
        match (a.get_mut(k), v) {
            (Some(toml::Value::Table(x)), toml::Value::Table(y)) => merge(x, y),
            _ => {
                a.insert(k.clone(), v.clone());
            }
        }
    }
}

/// A parameter name of `[fit]`.
fn kind(file: &str, key: &str, name: &str) -> Result<ParamKind, FitError> {
    ParamKind::parse(name).map_err(|e| FitError::Input(format!("{file}: {key}: {e}")))
}

/// Builds the scene of the file `text` (named `file` in errors) at `size`, as `scene`.
pub fn build(scene: DemoScene, text: &str, file: &str, size: Size) -> Result<SceneSpec, FitError> {
    let bad = |m: String| FitError::Input(format!("{file}: {m}"));
    let mut table: toml::Table = toml::from_str(text).map_err(|e| bad(e.to_string()))?;
    let take = |t: &mut toml::Table, key: &str| -> Result<toml::Value, FitError> {
        t.remove(key)
            .ok_or_else(|| bad(format!("the table [{key}] is missing")))
    };
    let to_text = |v: &toml::Table| toml::to_string(v).map_err(|e| bad(e.to_string()));
    let demo_table = match take(&mut table, "demo")? {
        toml::Value::Table(t) => t,
        _ => return Err(bad("demo must be a table".into())),
    };
    let fit_table = match take(&mut table, "fit")? {
        toml::Value::Table(t) => t,
        _ => return Err(bad("fit must be a table".into())),
    };
    let demo: DemoSection =
        decode(&to_text(&demo_table)?, Format::Toml).map_err(|e| bad(format!("[demo]: {e}")))?;
    let fit: FitSection =
        decode(&to_text(&fit_table)?, Format::Toml).map_err(|e| bad(format!("[fit]: {e}")))?;
    let sz = match size {
        Size::Full => demo.full,
        Size::Small => demo.small,
    };
    let which = match size {
        Size::Full => "[demo.full]",
        Size::Small => "[demo.small]",
    };
    if !(sz.substep_dt.is_finite() && sz.substep_dt > 0.0) {
        return Err(bad(format!(
            "{which} substep_dt = {}: must be > 0",
            sz.substep_dt
        )));
    }
    if sz.frames == 0 || sz.frames > MAX_FRAMES {
        return Err(bad(format!(
            "{which} frames = {}: must be 1..={MAX_FRAMES}",
            sz.frames
        )));
    }
    if sz.resolution.iter().any(|&r| r == 0 || r > MAX_SIDE) {
        return Err(bad(format!(
            "{which} resolution = {:?}: each side must be 1..={MAX_SIDE}",
            sz.resolution
        )));
    }
    for (key, _) in [("domain", ()), ("time", ())] {
        if table.contains_key(key) {
            return Err(bad(format!(
                "[{key}] comes from [demo.full] / [demo.small]; remove it"
            )));
        }
    }
    // The simulation: the file's tables with the size's grid and time.
    let mut domain = toml::Table::new();
    domain.insert("grid_lim".into(), 1.0.into());
    domain.insert("n_grid".into(), (sz.n_grid as i64).into());
    let mut time = toml::Table::new();
    time.insert("substep_dt".into(), sz.substep_dt.into());
    time.insert("frame_dt".into(), demo.frame_dt.into());
    time.insert("frames".into(), (sz.frames as i64).into());
    table.insert("domain".into(), domain.into());
    table.insert("time".into(), time.into());
    let densities: Vec<f64> = match table.get("parts") {
        Some(toml::Value::Array(parts)) => parts
            .iter()
            .map(|p| {
                p.get("density_kg_m3")
                    .and_then(|d| d.as_float())
                    .unwrap_or(r4d_mpm::PartParams::default().density_kg_m3)
            })
            .collect(),
        _ => Vec::new(),
    };
    if let Some(toml::Value::Array(list)) = table.get_mut("boundary") {
        for (i, b) in list.iter_mut().enumerate() {
            let Some(b) = b.as_table_mut() else { continue };
            if let Some(a) = b.remove("accel") {
                let part = match b.remove("accel_part") {
                    Some(v) => v.as_integer().ok_or_else(|| {
                        bad(format!("boundary {i}: accel_part must be an integer"))
                    })?,
                    None => 0,
                };
                let rho = *usize::try_from(part)
                    .ok()
                    .and_then(|p| densities.get(p))
                    .ok_or_else(|| {
                        bad(format!(
                            "boundary {i}: accel_part = {part}: no such part ({} parts)",
                            densities.len()
                        ))
                    })?;
                let a: [f64; 3] = a
                    .try_into()
                    .map_err(|e| bad(format!("boundary {i}: accel: {e}")))?;
                let f = super::push_force(a, rho, sz.n_grid);
                b.insert(
                    "force".into(),
                    toml::Value::Array(f.iter().map(|&x| x.into()).collect()),
                );
            }
            if let Some(d) = b.remove("duration") {
                let d = d
                    .as_float()
                    .filter(|d| d.is_finite() && *d > 0.0)
                    .ok_or_else(|| {
                        bad(format!(
                            "boundary {i}: duration must be a positive number (s)"
                        ))
                    })?;
                b.insert("num_dt".into(), ((d / sz.substep_dt).round() as i64).into());
            }
        }
    }
    let mut config = SimConfig::parse(&to_text(&table)?, Path::new(file))
        .map_err(|e| FitError::Input(e.to_string()))?;
    let particles = ParticleSet::from_shapes(&config.shapes, config.domain.dx());
    config.shapes.clear();
    let n = config.parts.len();
    let per_part = |what: &str, len: usize| {
        if len == n {
            Ok(())
        } else {
            Err(bad(format!("{what} has {len} entries for {n} parts")))
        }
    };
    per_part("[demo] part_names", demo.part_names.len())?;
    per_part("[demo] palettes", demo.palettes.len())?;
    per_part("[fit] free", fit.free.len())?;
    let palettes = demo
        .palettes
        .iter()
        .map(|p| palette(p).ok_or_else(|| bad(format!("[demo] palettes: no palette '{p}'"))))
        .collect::<Result<Vec<_>, _>>()?;
    let free = fit
        .free
        .iter()
        .map(|names| names.iter().map(|s| kind(file, "[fit] free", s)).collect())
        .collect::<Result<Vec<Vec<ParamKind>>, _>>()?;
    let mut start = config.parts.clone();
    if !fit.start.is_empty() {
        per_part("[fit] start", fit.start.len())?;
    }
    for (p, values) in start.iter_mut().zip(&fit.start) {
        for (k, &v) in values {
            set(p, kind(file, "[fit] start", k)?, v);
        }
    }
    let bounds = match &fit.bounds {
        BoundsSection::Named(s) if s == "default" => vec![BTreeMap::new(); n],
        BoundsSection::Named(s) => {
            return Err(bad(format!(
                "[fit] bounds = \"{s}\": use \"default\" or one table per part"
            )))
        }
        BoundsSection::Explicit(b) => {
            per_part("[fit] bounds", b.len())?;
            for t in b {
                for k in t.keys() {
                    kind(file, "[fit] bounds", k)?;
                }
            }
            b.clone()
        }
    };
    let pairs = fit
        .pairs
        .iter()
        .map(|(part, a, b)| {
            if *part >= n {
                return Err(bad(format!("[fit] pairs: part {part} of {n}")));
            }
            Ok((
                *part,
                kind(file, "[fit] pairs", a)?,
                kind(file, "[fit] pairs", b)?,
            ))
        })
        .collect::<Result<Vec<_>, _>>()?;
    let mut settings = fit.settings.clone();
    merge(
        &mut settings,
        match size {
            Size::Full => &fit.full,
            Size::Small => &fit.small,
        },
    );
    let mut fit_config: FitConfig = decode(&to_text(&settings)?, Format::Toml)
        .map_err(|e| bad(format!("[fit] settings: {e}")))?;
    let init_frames_given = settings
        .get("init")
        .and_then(|i| i.as_table())
        .is_some_and(|i| i.contains_key("frames"));
    if !init_frames_given {
        fit_config.init.frames = sz.frames;
    }
    fit_config
        .validate()
        .map_err(|e| bad(format!("[fit] settings: {e}")))?;
    let res = (sz.resolution[0], sz.resolution[1]);
    let cameras = demo
        .cameras
        .iter()
        .map(|c| stage::camera(&c.name, res, c.eye, c.target))
        .collect();
    let description = demo
        .description
        .replace("{frames}", &sz.frames.to_string())
        .replace("{width}", &res.0.to_string())
        .replace("{height}", &res.1.to_string());
    Ok(SceneSpec {
        scene,
        name: demo.name,
        description,
        config,
        particles,
        part_names: demo.part_names,
        palettes,
        floor_z: demo.floor_z as f32,
        cameras,
        start,
        free,
        bounds,
        pairs,
        fit: fit_config,
        profile_offsets: fit.profile_offsets,
        profile2d_offsets: fit.profile2d_offsets,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use r4d_mpm::BoundaryCondition as Boundary;

    /// Every built-in scene builds at both sizes, with its truth, free parameters, cameras
    /// and particles; the size sets the grid, the frames and the views' resolution.
    #[test]
    fn every_built_in_scene_builds_at_both_sizes() {
        for scene in DemoScene::ALL {
            let full = scene.spec(Size::Full);
            let small = scene.spec(Size::Small);
            for s in [&full, &small] {
                assert_eq!(s.name, scene.name());
                assert!(!s.particles.x.is_empty(), "{}", s.name);
                assert!(s.config.shapes.is_empty());
                let n = s.config.parts.len();
                assert!(n >= 1);
                assert_eq!((s.free.len(), s.bounds.len(), s.start.len()), (n, n, n));
                assert_eq!((s.part_names.len(), s.palettes.len()), (n, n));
                assert!(!s.cameras.is_empty());
                assert!(!s.description.contains('{'), "{}", s.description);
                assert_eq!(s.fit.init.frames, s.config.time.frames);
                s.fit.validate().unwrap();
            }
            assert!(full.config.domain.n_grid > small.config.domain.n_grid);
            assert!(full.cameras[0].width > small.cameras[0].width);
            assert_eq!(full.config.parts, small.config.parts);
        }
        // The plant's truth and start as the file gives them.
        let plant = DemoScene::Plant.spec(Size::Full);
        assert_eq!(plant.config.parts[1].youngs_modulus_pa, 6e4);
        assert_eq!(plant.start[1].youngs_modulus_pa, 1e5);
        assert_eq!(plant.start[1].poisson_ratio, 0.3);
        // Size-specific fit settings: the full plasticine runs its valley search.
        assert_eq!(DemoScene::Plasticine.spec(Size::Full).fit.valley.evals, 150);
        assert_eq!(DemoScene::Plasticine.spec(Size::Small).fit.valley.evals, 0);
    }

    const MINIMAL: &str = r#"
[demo]
name = "block"
description = "{frames} frames at {width}x{height}"
part_names = ["block"]
palettes = ["steel"]
floor_z = 0.1
[demo.full]
n_grid = 16
frames = 4
resolution = [64, 48]
substep_dt = 1e-3
[demo.small]
n_grid = 8
frames = 2
resolution = [32, 24]
substep_dt = 2e-3
[[demo.cameras]]
name = "front"
eye = [0.5, -0.5, 0.5]
target = [0.5, 0.5, 0.3]
[fit]
free = [["E", "density"]]
bounds = "default"
profile_offsets = [-0.1, 0.1]
profile2d_offsets = [-0.1, 0.1]
[[parts]]
material = "jelly"
density_kg_m3 = 500.0
[[shapes]]
kind = "box"
min = [0.4, 0.4, 0.4]
max = [0.6, 0.6, 0.6]
[[boundary]]
type = "particle_impulse"
accel = [0.0, 0.0, -10.0]
point = [0.5, 0.5, 0.5]
size = [0.2, 0.2, 0.2]
duration = 0.0105
"#;

    /// `accel` becomes the force per particle of the part's density at the size's grid,
    /// `duration` whole substeps; the description gets the size's numbers; "default"
    /// bounds are the material's.
    #[test]
    fn accelerations_and_durations_follow_the_size() {
        let s = build(DemoScene::Plant, MINIMAL, "block.toml", Size::Small).unwrap();
        assert_eq!(s.description, "2 frames at 32x24");
        assert!(s.bounds[0].is_empty());
        let Boundary::ParticleImpulse { force, num_dt, .. } = s.config.boundary[0] else {
            panic!("{:?}", s.config.boundary);
        };
        // (dx / 2)^3 = (1 / 16)^3 at grid 8.
        assert_eq!(force, [0.0, 0.0, -10.0 * 500.0 / 4096.0]);
        assert_eq!(num_dt, 5);
        let f = build(DemoScene::Plant, MINIMAL, "block.toml", Size::Full).unwrap();
        let Boundary::ParticleImpulse { force, num_dt, .. } = f.config.boundary[0] else {
            panic!();
        };
        assert_eq!((force[2] * 32768.0, num_dt), (-5000.0, 11));
    }

    /// A mistake in a scene file is an error naming the file and the key.
    #[test]
    fn bad_scene_files_are_refused_by_key() {
        let cases = [
            ("name = \"block\"", "name = \"block\"\ncolour = 1", "colour"),
            (
                "palettes = [\"steel\"]",
                "palettes = [\"chrome\"]",
                "chrome",
            ),
            (
                "free = [[\"E\", \"density\"]]",
                "free = [[\"E\", \"mass\"]]",
                "mass",
            ),
            (
                "free = [[\"E\", \"density\"]]",
                "free = []",
                "free has 0 entries",
            ),
            ("bounds = \"default\"", "bounds = \"tight\"", "bounds"),
            ("duration = 0.0105", "duration = -1.0", "duration"),
            (
                "type = \"particle_impulse\"",
                "type = \"particle_impulse\"\naccel_part = 3",
                "accel_part = 3",
            ),
            ("[[parts]]", "[domain]\nn_grid = 4\n[[parts]]", "[domain]"),
            ("[demo]", "[scene]", "[demo]"),
            (
                "resolution = [32, 24]",
                "resolution = [0, 24]",
                "resolution",
            ),
            ("frames = 2", "frames = 0", "frames"),
            ("substep_dt = 2e-3", "substep_dt = -1.0", "substep_dt"),
        ];
        for (from, to, needle) in cases {
            let text = MINIMAL.replacen(from, to, 1);
            let e = build(DemoScene::Plant, &text, "block.toml", Size::Small)
                .err()
                .unwrap_or_else(|| panic!("accepted: {to}"))
                .to_string();
            assert!(e.contains("block.toml") && e.contains(needle), "{to}: {e}");
        }
    }
}
