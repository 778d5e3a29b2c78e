//! The paste: a column of toothpaste-like paste (PhysFlow's `non_newtonian`, the model of the
//! paper's PAC-NeRF paste scenes) stands on a rough floor and slumps under its own weight:
//! where the stress exceeds the yield stress it flows at a rate set by the plastic viscosity,
//! and it comes to rest as a mound once the stress has fallen to the yield stress. How far it
//! slumps follows the yield stress, how fast the viscosity. Gravity is the only load, so the
//! motion is unchanged when `E`, the yield stress, the viscosity and the density are scaled
//! together: the density is fixed (a user knows it or the video cannot tell it), `nu` too.
//! Free: `E`, yield stress, plastic viscosity. Two views.

use super::{bounds_around, floor_collider, stage, stage_config, with, SceneSpec, Size};
use r4d_mpm::{Material, PartParams, ParticleSet, Shape};
use r4d_optim::video::{FitConfig, OptimizerKind};
use r4d_optim::ParamKind;
use r4d_optim::Precision;

/// The true parameters.
pub fn truth() -> PartParams {
    PartParams {
        material: Material::NonNewtonian,
        youngs_modulus_pa: 2e5,
        poisson_ratio: 0.4,
        yield_stress_pa: 1.2e3,
        plastic_viscosity_pa_s: 150.0,
        density_kg_m3: 1400.0,
        ..Default::default()
    }
}

/// Height of the floor (m).
const FLOOR: f64 = 0.1875;

/// The scene at `size`.
pub fn spec(size: Size) -> SceneSpec {
    let (n_grid, frames, res) = match size {
        Size::Full => (24, 20, (256, 192)),
        Size::Small => (16, 12, (96, 72)),
    };
    let floor = floor_collider(FLOOR, "surface = \"sticky\"");
    let config = stage_config(n_grid, 5e-4, frames, vec![truth()], &floor);
    let dx = config.domain.dx();
    let particles = ParticleSet::from_shapes(
        &[Shape::Box {
            min: [0.375, 0.4375, FLOOR],
            max: [0.625, 0.5625, FLOOR + 0.3125],
            part: 0,
            per_cell: 2,
        }],
        dx,
    );
    let t = truth();
    let start = vec![with(
        with(t, ParamKind::YieldStress, 4e3),
        ParamKind::PlasticViscosity,
        40.0,
    )];
    let free = vec![vec![
        ParamKind::YoungsModulus,
        ParamKind::YieldStress,
        ParamKind::PlasticViscosity,
    ]];
    let bounds = vec![bounds_around(
        &t,
        &[
            (ParamKind::YoungsModulus, 3.0),
            (ParamKind::YieldStress, 3.0),
            (ParamKind::PlasticViscosity, 3.0),
        ],
    )];
    let mut fit = FitConfig {
        iters: 30,
        lr: 0.1,
        beta1: 0.6,
        optimizer: OptimizerKind::TrustBfgs,
        precision: Precision::F64,
        ..Default::default()
    };
    fit.init.candidates = 16;
    fit.init.frames = frames;
    SceneSpec {
        scene: super::DemoScene::Paste,
        name: super::DemoScene::Paste.name().into(),
        description: format!(
            "a column of paste slumping under its own weight, {frames} frames at {}x{} from two views; fitting E, yield stress and plastic viscosity",
            res.0, res.1
        ),
        config,
        particles,
        part_names: vec!["paste".into()],
        palettes: vec![stage::PASTE],
        floor_z: FLOOR as f32,
        cameras: vec![
            stage::camera("front", res, [0.5, -0.3, 0.6], [0.5, 0.5, 0.3]),
            stage::camera("oblique", res, [1.1, -0.1, 0.85], [0.5, 0.5, 0.3]),
        ],
        start,
        free,
        bounds,
        pairs: vec![
            (0, ParamKind::YieldStress, ParamKind::PlasticViscosity),
            (0, ParamKind::YoungsModulus, ParamKind::YieldStress),
        ],
        fit,
        profile_offsets: vec![-0.3, -0.15, -0.05, 0.05, 0.15, 0.3],
        profile2d_offsets: vec![-0.1, 0.1],
    }
}
