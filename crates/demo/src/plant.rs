//! The plant: a stiff, light stem (part 0) clamped at its base and a softer, heavier head
//! (part 1) on a tiled floor in front of a striped wall. A sideways force acts on the head's
//! particles for the first substeps (a force impulse, so the head's mass and with it the
//! absolute density enter the motion, not only `E / density`), then the plant sways under
//! gravity. Free: `E` and density of both parts, one view.

use super::{stage, stage_config, SceneSpec, Size};
use r4d_mpm::{PartParams, ParticleSet, Shape};
use r4d_optim::video::FitConfig;
use r4d_optim::ParamKind;
use r4d_optim::Precision;

/// The true parameters of the stem and the head.
pub fn truth() -> Vec<PartParams> {
    let stem = PartParams {
        youngs_modulus_pa: 3e5,
        poisson_ratio: 0.3,
        density_kg_m3: 500.0,
        ..Default::default()
    };
    let head = PartParams {
        youngs_modulus_pa: 6e4,
        density_kg_m3: 1200.0,
        ..stem
    };
    vec![stem, head]
}

/// The scene at `size`.
pub fn spec(size: Size) -> SceneSpec {
    let (n_grid, frames, res) = match size {
        Size::Full => (24, 16, (256, 192)),
        Size::Small => (16, 10, (96, 72)),
    };
    let boundaries = r#"[[boundary]]
type = "cuboid"
point = [0.5, 0.5, 0.125]
size = [0.5, 0.5, 0.045]
velocity = [0.0, 0.0, 0.0]
[[boundary]]
type = "particle_impulse"
force = [0.5, 0.18, 0.0]
point = [0.5, 0.5, 0.53125]
size = [0.13, 0.13, 0.1]
num_dt = 30
"#;
    // 75 substeps per 0.025-s frame.
    let config = stage_config(n_grid, 0.025 / 75.0, frames, truth(), boundaries);
    let dx = config.domain.dx();
    let shapes = [
        // Stem: 0.125 x 0.125 x 0.3125 m, clamped at the bottom.
        Shape::Box {
            min: [0.4375, 0.4375, 0.125],
            max: [0.5625, 0.5625, 0.4375],
            part: 0,
            per_cell: 2,
        },
        // Head: a 0.25 x 0.25 x 0.1875-m bulb on top, soft enough to wobble on its own.
        Shape::Box {
            min: [0.375, 0.375, 0.4375],
            max: [0.625, 0.625, 0.625],
            part: 1,
            per_cell: 2,
        },
    ];
    let particles = ParticleSet::from_shapes(&shapes, dx);
    let mut start = truth();
    for s in &mut start {
        s.youngs_modulus_pa = 1e5;
        s.density_kg_m3 = 1000.0;
    }
    let free = vec![vec![ParamKind::YoungsModulus, ParamKind::Density]; 2];
    let bounds = vec![
        [
            ("E".to_string(), [1e4, 1e6]),
            ("density".to_string(), [200.0, 3000.0])
        ]
        .into_iter()
        .collect();
        2
    ];
    let mut fit = FitConfig {
        iters: 30,
        lr: 0.15,
        beta1: 0.6,
        precision: Precision::F32,
        ..Default::default()
    };
    fit.init.candidates = 16;
    fit.init.frames = frames;
    SceneSpec {
        scene: super::DemoScene::Plant,
        name: super::DemoScene::Plant.name().into(),
        description: format!(
            "a two-part plant (stiff stem, soft heavy head), {frames} frames at {}x{}; fitting E and density of both parts",
            res.0, res.1
        ),
        config,
        particles,
        part_names: vec!["stem".into(), "head".into()],
        palettes: vec![stage::GREEN, stage::RED_GOLD],
        floor_z: 0.12,
        cameras: vec![stage::camera(
            "demo",
            res,
            [0.6, -0.33, 0.52],
            [0.5, 0.5, 0.32],
        )],
        start,
        free,
        bounds,
        pairs: Vec::new(),
        fit,
        profile_offsets: vec![-0.3, -0.15, -0.05, 0.05, 0.15, 0.3],
        profile2d_offsets: vec![-0.15, -0.05, 0.05, 0.15],
    }
}
