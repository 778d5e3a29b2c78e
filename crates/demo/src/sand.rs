//! The sand column: a cylinder of sand on a rough floor collapses under gravity and spreads
//! into a pile whose run-out and slope follow the friction angle (Drucker-Prager). Gravity is
//! the only load, so the motion is unchanged when `E` and density are scaled together: the
//! video determines the friction angle (and at best `E / density`), not the absolute
//! density. Free: `E`, `nu`, friction angle, density. Two views.

use super::{bounds_around, floor_collider, stage, stage_config, with, SceneSpec, Size};
use r4d_mpm::{Material, PartParams, ParticleSet, Shape};
use r4d_optim::video::{FitConfig, OptimizerKind};
use r4d_optim::ParamKind;
use r4d_optim::Precision;

/// The true parameters.
pub fn truth() -> PartParams {
    PartParams {
        material: Material::Sand,
        youngs_modulus_pa: 2e5,
        poisson_ratio: 0.3,
        friction_angle_deg: 30.0,
        density_kg_m3: 1500.0,
        ..Default::default()
    }
}

/// Height of the floor (m): above the bounding box's three node layers at grid 16.
const FLOOR: f64 = 0.1875;

/// The scene at `size`.
pub fn spec(size: Size) -> SceneSpec {
    let (n_grid, frames, res) = match size {
        Size::Full => (24, 20, (256, 192)),
        Size::Small => (16, 12, (96, 72)),
    };
    let floor = floor_collider(FLOOR, "surface = \"friction\"\nfriction = 0.5");
    let config = stage_config(n_grid, 5e-4, frames, vec![truth()], &floor);
    let dx = config.domain.dx();
    let particles = ParticleSet::from_shapes(
        &[Shape::Cylinder {
            base: [0.5, 0.5, FLOOR],
            axis: 2,
            radius: 0.125,
            length: 0.25,
            part: 0,
            per_cell: 2,
        }],
        dx,
    );
    let t = truth();
    let start = vec![with(t, ParamKind::FrictionAngle, 45.0)];
    let free = vec![vec![
        ParamKind::YoungsModulus,
        ParamKind::PoissonRatio,
        ParamKind::FrictionAngle,
        ParamKind::Density,
    ]];
    let bounds = vec![bounds_around(
        &t,
        &[
            (ParamKind::YoungsModulus, 3.0),
            (ParamKind::PoissonRatio, 0.0),
            (ParamKind::FrictionAngle, 15.0),
            (ParamKind::Density, 3.0),
        ],
    )];
    let mut fit = FitConfig {
        iters: 40,
        lr: 0.1,
        beta1: 0.6,
        optimizer: OptimizerKind::TrustBfgs,
        precision: Precision::F32,
        ..Default::default()
    };
    fit.init.candidates = 24;
    fit.init.frames = frames;
    SceneSpec {
        scene: super::DemoScene::Sand,
        name: super::DemoScene::Sand.name().into(),
        description: format!(
            "a sand column slumping into a pile, {frames} frames at {}x{} from two views; fitting E, nu, friction angle and density",
            res.0, res.1
        ),
        config,
        particles,
        part_names: vec!["sand".into()],
        palettes: vec![stage::SAND],
        floor_z: FLOOR as f32,
        cameras: vec![
            stage::camera("front", res, [0.5, -0.35, 0.6], [0.5, 0.5, 0.27]),
            stage::camera("top", res, [0.95, 0.0, 0.95], [0.5, 0.5, 0.22]),
        ],
        start,
        free,
        bounds,
        pairs: vec![
            (0, ParamKind::FrictionAngle, ParamKind::Density),
            (0, ParamKind::YoungsModulus, ParamKind::Density),
        ],
        fit,
        profile_offsets: vec![-0.3, -0.15, -0.05, 0.05, 0.15, 0.3],
        profile2d_offsets: vec![-0.1, 0.1],
    }
}
