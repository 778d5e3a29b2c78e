//! The fluid drop: a cylinder of viscous, weakly compressible Newtonian fluid (`fluid`) is
//! released just above the floor, lands and spreads into a puddle. The spreading speed
//! follows the viscosity; the landing squeezes the fluid and it rings at the speed of sound
//! that the bulk modulus sets (`K = E / (3 (1 - 2 nu))`: `E` and `nu` enter only through `K`,
//! so `nu` is fixed and `E` stands for `K`). Gravity is the only load: scaling the viscosity,
//! the bulk modulus and the density together changes nothing, so the density is fixed.
//! Free: `E` (the bulk modulus), viscosity (`plastic_viscosity`). Two views.

use super::{bounds_around, floor_collider, stage, stage_config, SceneSpec, Size};
use r4d_mpm::{Material, PartParams, ParticleSet, Shape};
use r4d_optim::video::{FitConfig, OptimizerKind};
use r4d_optim::ParamKind;
use r4d_optim::Precision;

/// The true parameters: bulk modulus 5e4 Pa (speed of sound 7 m/s), viscosity 60 Pa s.
pub fn truth() -> PartParams {
    PartParams {
        material: Material::Fluid,
        youngs_modulus_pa: 6e4,
        poisson_ratio: 0.3,
        plastic_viscosity_pa_s: 60.0,
        density_kg_m3: 1000.0,
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
        &[Shape::Cylinder {
            base: [0.5, 0.5, FLOOR + 0.0625],
            axis: 2,
            radius: 0.125,
            length: 0.1875,
            part: 0,
            per_cell: 2,
        }],
        dx,
    );
    let t = truth();
    let mut start = t;
    start.youngs_modulus_pa = 1.5e5;
    start.plastic_viscosity_pa_s = 20.0;
    let free = vec![vec![ParamKind::YoungsModulus, ParamKind::PlasticViscosity]];
    let bounds = vec![bounds_around(
        &t,
        &[
            (ParamKind::YoungsModulus, 3.0),
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
        scene: super::DemoScene::Fluid,
        name: super::DemoScene::Fluid.name().into(),
        description: format!(
            "a viscous drop landing and spreading, {frames} frames at {}x{} from two views; fitting the bulk modulus (E) and the viscosity",
            res.0, res.1
        ),
        config,
        particles,
        part_names: vec!["fluid".into()],
        palettes: vec![stage::WATER],
        floor_z: FLOOR as f32,
        cameras: vec![
            stage::camera("front", res, [0.5, -0.3, 0.6], [0.5, 0.5, 0.3]),
            stage::camera("top", res, [0.95, 0.0, 0.95], [0.5, 0.5, 0.22]),
        ],
        start: vec![start],
        free,
        bounds,
        pairs: vec![(0, ParamKind::YoungsModulus, ParamKind::PlasticViscosity)],
        fit,
        profile_offsets: vec![-0.3, -0.15, -0.05, 0.05, 0.15, 0.3],
        profile2d_offsets: vec![-0.1, 0.1],
    }
}
