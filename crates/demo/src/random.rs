//! Random scenes for the recovery benchmark ([`mod@crate::recovery`], `r4d bench-recovery`): for
//! a material class and a seed, a scene drawn at random — the shape and size of the body, the
//! load, one or two cameras and the true parameters — that a fit then sees only through its
//! rendered videos.
//!
//! # Truth
//! Every parameter the class's model reads is drawn from the class's range
//! ([`Class::range`]): log-uniformly, except Poisson's ratio and the friction angle
//! (uniformly). Yield stresses are drawn as a yield strain times `E` (a yield stress of
//! `E / 10` never yields in these scenes, one of `E / 10^4` yields under gravity alone), and
//! plasticine's softening as a multiple of the yield stress. Every range lies inside the
//! fit's default bounds ([`ParamKind::default_bounds_for`]), so a fit with its default
//! settings can reach the truth.
//!
//! # Scene
//! * **Body**: a box or an upright cylinder, 0.15-0.3 m a side (a few hundred to about
//!   2,000 particles at the full size), somewhere on the stage; metal is a cantilever clamped
//!   at its root; the two-part class stacks two jelly blocks.
//! * **Load** ([`Load`]): `drop` (released above the floor), `throw` (a short force on the
//!   whole body in the air), `push` (a sideways force on the top third; metal: at the tip),
//!   `press` (a downward force on the top layer). The classes with a yield stress are loaded
//!   with 1.2-2.2 times the force that reaches it, so the scene shows plastic flow, within
//!   limits (300 m/s^2, and 2 m/s given over the load's duration) that keep every load a
//!   push, not a blast.
//!   Forces are body-force densities of the true density, so the density enters the motion
//!   of every load but the drop.
//! * **Cameras**: one or two, at a random azimuth (within 50 degrees of the front), elevation
//!   and distance, looking at the body.
//!
//! # Substep
//! Chosen from the class's stiffest corner (largest `E` and `nu`, smallest density) at CFL
//! number 0.7, never from the truth: every truth of the class runs stably, and a fit
//! candidate stiffer than the class is refused by the simulator's CFL check, as in a user's
//! fit.

use super::{floor_collider, push_force, stage, stage_config, DemoScene, SceneSpec, Size};
use r4d_mpm::{Material, PartParams, ParticleSet, Shape};
use r4d_optim::space::{default_free, set};
use r4d_optim::video::FitConfig;
use r4d_optim::{ParamKind, SplitMix64};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::fmt;

/// The material classes of the recovery benchmark.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Class {
    /// One jelly body: `E`, `nu`, density.
    Jelly,
    /// A metal cantilever without hardening: `E`, `nu`, yield stress, density.
    Metal,
    /// A metal cantilever with hardening: `E`, `nu`, yield stress, hardening, density.
    MetalHardening,
    /// A sand body: `E`, `nu`, friction angle, density.
    Sand,
    /// A foam body: `E`, `nu`, yield stress, plastic viscosity, density.
    Foam,
    /// A plasticine body: `E`, `nu`, yield stress, softening, density.
    Plasticine,
    /// Two stacked jelly blocks: `E`, `nu` and density of each.
    TwoPart,
}

impl Class {
    /// Every class, in the benchmark's order.
    pub const ALL: [Class; 7] = [
        Class::Jelly,
        Class::Metal,
        Class::MetalHardening,
        Class::Sand,
        Class::Foam,
        Class::Plasticine,
        Class::TwoPart,
    ];

    /// The name on the command line and in the results.
    pub fn name(self) -> &'static str {
        match self {
            Class::Jelly => "jelly",
            Class::Metal => "metal",
            Class::MetalHardening => "metal_hardening",
            Class::Sand => "sand",
            Class::Foam => "foam",
            Class::Plasticine => "plasticine",
            Class::TwoPart => "two_part",
        }
    }

    /// Parses a name (see [`Class::name`]).
    pub fn parse(s: &str) -> Option<Class> {
        Class::ALL
            .into_iter()
            .find(|c| c.name().eq_ignore_ascii_case(s.trim()))
    }

    /// The material of the class's parts.
    pub fn material(self) -> Material {
        match self {
            Class::Jelly | Class::TwoPart => Material::Jelly,
            Class::Metal | Class::MetalHardening => Material::Metal,
            Class::Sand => Material::Sand,
            Class::Foam => Material::Foam,
            Class::Plasticine => Material::Plasticine,
        }
    }

    /// The loads a scene of the class is drawn from.
    pub fn loads(self) -> &'static [Load] {
        match self {
            Class::Jelly => &[Load::Drop, Load::Throw, Load::Push, Load::Press],
            Class::TwoPart => &[Load::Drop, Load::Throw, Load::Push],
            Class::Metal | Class::MetalHardening => &[Load::Push],
            Class::Sand => &[Load::Drop, Load::Push, Load::Press],
            Class::Foam => &[Load::Throw, Load::Push, Load::Press],
            Class::Plasticine => &[Load::Drop, Load::Throw, Load::Press],
        }
    }

    /// The class's range of `kind` (`None`: its model does not read it). The yield stress
    /// is given as a yield strain (a fraction of `E`), the softening as a multiple of the
    /// yield stress.
    pub fn range(self, kind: ParamKind) -> Option<(f64, f64)> {
        use ParamKind as K;
        let r = match (self, kind) {
            (Class::Jelly | Class::TwoPart, K::YoungsModulus) => (2e4, 1e6),
            (Class::Jelly | Class::TwoPart, K::Density) => (300.0, 2000.0),
            (Class::Metal | Class::MetalHardening, K::YoungsModulus) => (3e5, 3e6),
            (Class::Metal | Class::MetalHardening, K::YieldStress) => (4e-3, 2e-2),
            (Class::Metal | Class::MetalHardening, K::Density) => (500.0, 3000.0),
            (Class::MetalHardening, K::Hardening) => (0.05, 0.5),
            (Class::Sand, K::YoungsModulus) => (5e4, 1e6),
            (Class::Sand, K::FrictionAngle) => (20.0, 45.0),
            (Class::Sand, K::Density) => (1000.0, 2500.0),
            (Class::Foam, K::YoungsModulus) => (2e4, 3e5),
            (Class::Foam, K::PoissonRatio) => (0.05, 0.3),
            (Class::Foam, K::YieldStress) => (1e-2, 5e-2),
            (Class::Foam, K::PlasticViscosity) => (10.0, 800.0),
            (Class::Foam, K::Density) => (120.0, 600.0),
            (Class::Plasticine, K::YoungsModulus) => (5e4, 1e6),
            (Class::Plasticine, K::YieldStress) => (5e-3, 3e-2),
            (Class::Plasticine, K::Softening) => (0.2, 2.0),
            (Class::Plasticine, K::Density) => (600.0, 2000.0),
            (_, K::PoissonRatio) => (0.15, 0.4),
            _ => return None,
        };
        Some(r)
    }

    /// What the fit's config holds before the initialisation replaces it: the material's
    /// defaults (metal with hardening on).
    pub fn start(self) -> PartParams {
        let mut p = PartParams {
            material: self.material(),
            ..Default::default()
        };
        if self == Class::MetalHardening {
            p.hardening = true;
            p.xi = 0.1;
        }
        p
    }
}

impl fmt::Display for Class {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// How a random scene is set moving.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Load {
    /// Released above the floor.
    Drop,
    /// A short force on the whole body in the air, then it lands.
    Throw,
    /// A sideways force on the top third of a body on the floor (metal: on the tip of the
    /// cantilever, down or sideways).
    Push,
    /// A downward force on the top layer of a body on the floor.
    Press,
}

impl Load {
    /// The name in the results.
    pub fn name(self) -> &'static str {
        match self {
            Load::Drop => "drop",
            Load::Throw => "throw",
            Load::Push => "push",
            Load::Press => "press",
        }
    }
}

/// A drawn scene: the spec the benchmark fits, and what was drawn.
#[derive(Clone, Debug)]
pub struct RandomScene {
    /// The class.
    pub class: Class,
    /// The seed it was drawn from.
    pub seed: u64,
    /// The load.
    pub load: Load,
    /// The scene (truth in `spec.config.parts`, the class's start in `spec.start`).
    pub spec: SceneSpec,
}

/// Uniform in `[lo, hi)`.
fn uniform(r: &mut SplitMix64, (lo, hi): (f64, f64)) -> f64 {
    lo + (hi - lo) * r.next_f64()
}

/// Log-uniform in `[lo, hi)`.
fn log_uniform(r: &mut SplitMix64, (lo, hi): (f64, f64)) -> f64 {
    (lo.ln() + (hi.ln() - lo.ln()) * r.next_f64()).exp()
}

/// The class's true parameters drawn from its ranges.
fn draw_truth(class: Class, r: &mut SplitMix64) -> PartParams {
    let mut p = class.start();
    let e = log_uniform(r, class.range(ParamKind::YoungsModulus).expect("E"));
    p.youngs_modulus_pa = e;
    for k in ParamKind::ALL {
        let Some(range) = class.range(k) else {
            continue;
        };
        let v = match k {
            ParamKind::YoungsModulus => continue,
            ParamKind::PoissonRatio | ParamKind::FrictionAngle => uniform(r, range),
            ParamKind::YieldStress => e * log_uniform(r, range),
            ParamKind::Softening => p.yield_stress_pa * log_uniform(r, range),
            _ => log_uniform(r, range),
        };
        set(&mut p, k, v);
    }
    p
}

/// The stiffest part of the class (largest `E` and `nu`, smallest density): what the
/// substep is chosen for.
fn stiffest(class: Class) -> PartParams {
    let hi = |k| class.range(k).expect("range").1;
    PartParams {
        material: class.material(),
        youngs_modulus_pa: hi(ParamKind::YoungsModulus),
        poisson_ratio: hi(ParamKind::PoissonRatio),
        density_kg_m3: class.range(ParamKind::Density).expect("density").0,
        ..Default::default()
    }
}

/// Frame interval of the scenes (s); the stage's.
const FRAME_DT: f64 = 0.025;

/// CFL number of the class's stiffest corner.
const CFL: f64 = 0.7;

/// A `particle_impulse` boundary of force `f` (N per particle) on the box `point +- size`
/// for `seconds` from `start` (s) in substeps of `dt`.
fn impulse(
    f: [f64; 3],
    point: [f64; 3],
    size: [f64; 3],
    start: f64,
    seconds: f64,
    dt: f64,
) -> String {
    format!(
        "[[boundary]]\ntype = \"particle_impulse\"\nforce = [{:e}, {:e}, {:e}]\n\
         point = [{}, {}, {}]\nsize = [{}, {}, {}]\nnum_dt = {}\nstart_time = {start}\n",
        f[0],
        f[1],
        f[2],
        point[0],
        point[1],
        point[2],
        size[0],
        size[1],
        size[2],
        ((seconds / dt).round() as u32).max(1)
    )
}

/// The largest body-force acceleration a load applies (m/s^2): the forces that reach a
/// yield stress on a thin layer are capped here so that no scene is a blast.
const MAX_ACCEL: f64 = 300.0;

/// The largest velocity a load gives the particles it acts on, acceleration times duration
/// (m/s): a press or push stronger than this crushes or flings the body in a frame or two.
const MAX_DV: f64 = 2.0;

/// Draws the scene of `class` from `seed` at `size` (the same seed gives the same scene).
pub fn scene(class: Class, seed: u64, size: Size) -> RandomScene {
    let mut r = SplitMix64::new(seed ^ (class as u64 + 1).wrapping_mul(0x9E37_79B9_7F4A_7C15));
    let (n_grid, frames, res, side) = match size {
        Size::Full => (20usize, 20usize, (160u32, 120u32), (0.15, 0.3)),
        Size::Small => (12, 10, (64, 48), (0.17, 0.25)),
    };
    let dx = 1.0 / n_grid as f64;
    let floor = 3.0 * dx;
    let c = stiffest(class).p_wave_speed();
    let per_frame = (FRAME_DT / (CFL * dx / c)).ceil().max(1.0);
    let dt = FRAME_DT / per_frame;
    let load = class.loads()[r.below(class.loads().len() as u64) as usize];
    let parts_n = if class == Class::TwoPart { 2 } else { 1 };
    let truth: Vec<PartParams> = (0..parts_n).map(|_| draw_truth(class, &mut r)).collect();
    let rho = truth[0].density_kg_m3;
    let in_air = matches!(load, Load::Drop | Load::Throw);
    // The body: its lower corner, extents, and the shapes.
    let (shapes, lo, ext) = if matches!(class, Class::Metal | Class::MetalHardening) {
        let len = uniform(&mut r, (0.45, 0.6));
        let w = uniform(&mut r, (0.1, 0.15)).max(2.0 * dx);
        let t = uniform(&mut r, (0.1, 0.15)).max(2.0 * dx);
        let lo = [0.2, 0.5 - w / 2.0, 0.5 - t / 2.0];
        let shapes = vec![Shape::Box {
            min: lo,
            max: [lo[0] + len, lo[1] + w, lo[2] + t],
            part: 0,
            per_cell: 2,
        }];
        (shapes, lo, [len, w, t])
    } else {
        let w = uniform(&mut r, side);
        let d = uniform(&mut r, side);
        let h = match class {
            Class::Sand => uniform(&mut r, (1.2, 2.0)) * w.min(d),
            _ => uniform(&mut r, side),
        };
        let lift = if in_air {
            uniform(&mut r, (0.08, 0.2))
        } else {
            0.0
        };
        let lo = [
            uniform(&mut r, (0.4, 0.6)) - w / 2.0,
            uniform(&mut r, (0.45, 0.55)) - d / 2.0,
            floor + lift,
        ];
        let cylinder = class != Class::TwoPart && r.next_f64() < 0.5;
        let shapes = if class == Class::TwoPart {
            let split = uniform(&mut r, (0.4, 0.6));
            let mid = lo[2] + h * split;
            vec![
                Shape::Box {
                    min: lo,
                    max: [lo[0] + w, lo[1] + d, mid],
                    part: 0,
                    per_cell: 2,
                },
                Shape::Box {
                    min: [lo[0], lo[1], mid],
                    max: [lo[0] + w, lo[1] + d, lo[2] + h],
                    part: 1,
                    per_cell: 2,
                },
            ]
        } else if cylinder {
            let radius = w.min(d) / 2.0;
            vec![Shape::Cylinder {
                base: [lo[0] + w / 2.0, lo[1] + d / 2.0, lo[2]],
                axis: 2,
                radius,
                length: h,
                part: 0,
                per_cell: 2,
            }]
        } else {
            vec![Shape::Box {
                min: lo,
                max: [lo[0] + w, lo[1] + d, lo[2] + h],
                part: 0,
                per_cell: 2,
            }]
        };
        (shapes, lo, [w, d, h])
    };
    let centre = [0, 1, 2].map(|a| lo[a] + ext[a] / 2.0);
    let top = lo[2] + ext[2];
    let yield_stress = truth[0].yield_stress_pa;
    let yields = matches!(
        class,
        Class::Metal | Class::MetalHardening | Class::Foam | Class::Plasticine
    );
    // The boundaries: the floor (and the clamp of a cantilever), then the load.
    let surface = match class {
        Class::Sand => "surface = \"friction\"\nfriction = 0.6",
        Class::Plasticine => "surface = \"friction\"\nfriction = 0.8",
        _ => "surface = \"sticky\"",
    };
    let mut boundaries = floor_collider(floor, surface);
    let margin = dx;
    match (class, load) {
        (Class::Metal | Class::MetalHardening, _) => {
            let [len, w, t] = ext;
            boundaries += &format!(
                "[[boundary]]\ntype = \"cuboid\"\npoint = [{}, {}, {}]\nsize = [0.1, {}, {}]\n\
                 velocity = [0.0, 0.0, 0.0]\n",
                lo[0], centre[1], centre[2], w, t
            );
            // Bending stress at the root of a tip force on the last `tip` metres over a
            // free length `len - 0.1`: 6 rho a tip (free - tip / 2) / t.
            let tip = 0.1;
            let free = len - 0.1;
            let f = uniform(&mut r, (1.3, 2.2));
            let a = (f * yield_stress * t / (6.0 * rho * tip * (free - tip / 2.0))).min(MAX_ACCEL);
            let dir = if r.next_f64() < 0.5 {
                [0.0, 0.0, -a]
            } else {
                [0.0, a, 0.0]
            };
            let secs = uniform(&mut r, (0.08, 0.15));
            let dir = dir.map(|v| v.clamp(-MAX_DV / secs, MAX_DV / secs));
            boundaries += &impulse(
                push_force(dir, rho, n_grid),
                [lo[0] + len - tip / 2.0, centre[1], centre[2]],
                [tip / 2.0, w / 2.0 + margin, t / 2.0 + margin],
                0.0,
                secs,
                dt,
            );
        }
        (_, Load::Drop) => {}
        (_, Load::Throw) => {
            let phi = uniform(&mut r, (0.0, std::f64::consts::TAU));
            let ah = uniform(&mut r, (4.0, 12.0));
            let av = uniform(&mut r, (-20.0, 0.0));
            boundaries += &impulse(
                push_force([ah * phi.cos(), ah * phi.sin(), av], rho, n_grid),
                centre,
                ext.map(|e| e / 2.0 + margin),
                0.0,
                0.05,
                dt,
            );
        }
        (_, Load::Push) => {
            // The top third (two-part: the top part) pushed sideways.
            let band = if class == Class::TwoPart {
                top - match &shapes[1] {
                    Shape::Box { min, .. } => min[2],
                    _ => unreachable!("two-part scenes are boxes"),
                }
            } else {
                ext[2] / 3.0
            };
            let a = if yields {
                uniform(&mut r, (1.2, 2.0)) * yield_stress / (rho * band)
            } else {
                uniform(&mut r, (15.0, 50.0))
            }
            .min(MAX_ACCEL);
            let phi = uniform(&mut r, (0.0, std::f64::consts::TAU));
            let secs = uniform(&mut r, (0.05, 0.15));
            let a = a.min(MAX_DV / secs);
            boundaries += &impulse(
                push_force([a * phi.cos(), a * phi.sin(), 0.0], rho, n_grid),
                [centre[0], centre[1], top - band / 2.0],
                [ext[0] / 2.0 + margin, ext[1] / 2.0 + margin, band / 2.0],
                0.0,
                secs,
                dt,
            );
        }
        (_, Load::Press) => {
            let layer = (ext[2] / 4.0).max(dx);
            let a = if yields {
                uniform(&mut r, (1.2, 2.0)) * yield_stress / (rho * layer)
            } else {
                uniform(&mut r, (20.0, 60.0))
            }
            .min(MAX_ACCEL);
            let secs = uniform(&mut r, (0.1, 0.2));
            let a = a.min(MAX_DV / secs);
            boundaries += &impulse(
                push_force([0.0, 0.0, -a], rho, n_grid),
                [centre[0], centre[1], top - layer / 2.0],
                [ext[0] / 2.0 + margin, ext[1] / 2.0 + margin, layer / 2.0],
                0.0,
                secs,
                dt,
            );
        }
    }
    let config = stage_config(n_grid, dt, frames, truth.clone(), &boundaries);
    let particles = ParticleSet::from_shapes(&shapes, dx);
    // Cameras: azimuth within 50 degrees of the front (-y), looking at the body's centre.
    let target = [centre[0], centre[1], (centre[2] - 0.05).max(floor)];
    let cam = |r: &mut SplitMix64, name: &str, az: f64| {
        let el = uniform(r, (0.2, 0.6));
        let dist = uniform(r, (0.8, 1.05));
        let eye = [
            target[0] + dist * el.cos() * az.sin(),
            target[1] - dist * el.cos() * az.cos(),
            target[2] + dist * el.sin(),
        ];
        stage::camera(name, res, eye, target)
    };
    let az = uniform(&mut r, (-0.87, 0.87));
    let mut cameras = vec![cam(&mut r, "view0", az)];
    if r.next_f64() < 0.5 {
        let turn = uniform(&mut r, (0.6, 1.2));
        let az2 = if az > 0.0 { az - turn } else { az + turn };
        cameras.push(cam(&mut r, "view1", az2));
    }
    let start = vec![class.start(); parts_n];
    let free: Vec<Vec<ParamKind>> = start.iter().map(default_free).collect();
    let pairs = free
        .iter()
        .enumerate()
        .flat_map(|(part, kinds)| {
            kinds
                .iter()
                .enumerate()
                .flat_map(move |(i, &a)| kinds[i + 1..].iter().map(move |&b| (part, a, b)))
        })
        .collect();
    let mut fit = FitConfig::default();
    fit.init.frames = fit.init.frames.min(frames);
    let (scene, palettes, part_names) = match class {
        Class::Jelly => (DemoScene::Plant, vec![stage::RED_GOLD], vec!["body"]),
        Class::TwoPart => (
            DemoScene::Plant,
            vec![stage::GREEN, stage::RED_GOLD],
            vec!["bottom", "top"],
        ),
        Class::Metal | Class::MetalHardening => {
            (DemoScene::Metal, vec![stage::STEEL], vec!["beam"])
        }
        Class::Sand => (DemoScene::Sand, vec![stage::SAND], vec!["body"]),
        Class::Foam => (DemoScene::Foam, vec![stage::FOAM], vec!["body"]),
        Class::Plasticine => (DemoScene::Plasticine, vec![stage::CLAY], vec!["body"]),
    };
    let name = format!("{}-{seed}", class.name());
    let spec = SceneSpec {
        scene,
        description: format!(
            "{name}: {} ({} particles, {} view(s) at {}x{}, {frames} frames, {} substeps per frame)",
            load.name(),
            particles.x.len(),
            cameras.len(),
            res.0,
            res.1,
            per_frame as u32
        ),
        name,
        config,
        particles,
        part_names: part_names.into_iter().map(String::from).collect(),
        palettes,
        floor_z: floor as f32,
        cameras,
        start,
        bounds: vec![BTreeMap::new(); free.len()],
        free,
        pairs,
        fit,
        profile_offsets: vec![-0.15, -0.05, 0.05, 0.15],
        profile2d_offsets: vec![-0.1, 0.1],
    };
    RandomScene {
        class,
        seed,
        load,
        spec,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A seed gives the same scene; the truth lies in the class's range and inside the fit's
    /// default bounds; the substep keeps the class's stiffest corner under the CFL bound.
    #[test]
    fn scenes_are_reproducible_and_inside_the_bounds() {
        for class in Class::ALL {
            for seed in 0..6 {
                let a = scene(class, seed, Size::Full);
                let b = scene(class, seed, Size::Full);
                assert_eq!(a.spec.description, b.spec.description);
                assert_eq!(a.spec.config.parts, b.spec.config.parts);
                assert!(!a.spec.particles.x.is_empty());
                assert!(a.spec.particles.x.len() <= 2500, "{}", a.spec.description);
                for p in &a.spec.config.parts {
                    for &k in &default_free(&class.start()) {
                        let v = r4d_optim::space::get(p, k);
                        let (lo, hi) = k.default_bounds_for(p.material);
                        assert!(v > lo && v < hi, "{class} {}: {v}", k.name());
                    }
                    let dt = a.spec.config.time.substep_dt;
                    assert!(dt <= CFL * a.spec.config.domain.dx() / p.p_wave_speed() * 1.0001);
                }
            }
        }
        assert_eq!(Class::parse("Metal_Hardening"), Some(Class::MetalHardening));
        assert_eq!(Class::parse("water"), None);
    }
}
