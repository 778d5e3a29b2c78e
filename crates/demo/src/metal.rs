//! The metal beam: a cantilever clamped at its left end, bent past yield by a downward push
//! on its tip (a force impulse, so the absolute density enters the motion), then released:
//! it springs back, rings at its bending frequency (`E / density`) around a permanently bent
//! shape (the yield stress). A second, stronger push (1.6x) then bends it further against the
//! yield stress that linear hardening raised as the beam flowed, so the two bends separate
//! the initial yield stress from the hardening coefficient (one push alone trades them off:
//! a stiffer start or a faster hardening bend it alike). Free: `E`, `nu`,
//! yield stress, hardening coefficient, density. Two views.

use super::{bounds_around, push_force, stage, stage_config, with, SceneSpec, Size};
use r4d_mpm::{Material, PartParams, ParticleSet, Shape};
use r4d_optim::video::{FitConfig, OptimizerKind};
use r4d_optim::ParamKind;
use r4d_optim::Precision;

/// The true parameters.
pub fn truth() -> PartParams {
    PartParams {
        material: Material::Metal,
        youngs_modulus_pa: 2e6,
        poisson_ratio: 0.3,
        yield_stress_pa: 6.5e4,
        density_kg_m3: 800.0,
        hardening: true,
        xi: 0.5,
        ..Default::default()
    }
}

/// The scene at `size`.
pub fn spec(size: Size) -> SceneSpec {
    let (n_grid, frames, res) = match size {
        Size::Full => (24, 24, (256, 192)),
        Size::Small => (16, 16, (96, 72)),
    };
    // 41 m/s^2 downwards on the tip for 0.08 s, then 1.6x that from 0.2 s.
    let f = push_force([0.0, 0.0, -41.0], truth().density_kg_m3, n_grid);
    let boundaries = format!(
        r#"[[boundary]]
type = "cuboid"
point = [0.2, 0.5, 0.5]
size = [0.15, 0.2, 0.2]
velocity = [0.0, 0.0, 0.0]
[[boundary]]
type = "particle_impulse"
force = [0.0, 0.0, {fz}]
point = [0.75, 0.5, 0.5]
size = [0.05, 0.1, 0.1]
num_dt = 400
[[boundary]]
type = "particle_impulse"
force = [0.0, 0.0, {fz2}]
point = [0.75, 0.5, 0.5]
size = [0.05, 0.1, 0.1]
num_dt = 400
start_time = 0.2
"#,
        fz = f[2],
        fz2 = 1.6 * f[2]
    );
    let config = stage_config(n_grid, 2e-4, frames, vec![truth()], &boundaries);
    let dx = config.domain.dx();
    let particles = ParticleSet::from_shapes(
        &[Shape::Box {
            min: [0.2, 0.4375, 0.4375],
            max: [0.8, 0.5625, 0.5625],
            part: 0,
            per_cell: 2,
        }],
        dx,
    );
    let t = truth();
    let start = vec![with(
        with(
            with(t, ParamKind::YieldStress, 3e5),
            ParamKind::YoungsModulus,
            1e6,
        ),
        ParamKind::Hardening,
        0.2,
    )];
    let free = vec![vec![
        ParamKind::YoungsModulus,
        ParamKind::PoissonRatio,
        ParamKind::YieldStress,
        ParamKind::Hardening,
        ParamKind::Density,
    ]];
    let mut bounds = vec![bounds_around(
        &t,
        &[
            (ParamKind::YoungsModulus, 3.0),
            (ParamKind::PoissonRatio, 0.0),
            (ParamKind::YieldStress, 3.0),
            (ParamKind::Hardening, 3.0),
            (ParamKind::Density, 3.0),
        ],
    )];
    // Hardening above 1 is unstable (ParamKind::default_bounds): capped at 0.9.
    bounds[0].insert(ParamKind::Hardening.name().into(), [t.xi / 3.0, 0.9]);
    let mut fit = FitConfig {
        iters: 40,
        lr: 0.1,
        beta1: 0.6,
        optimizer: OptimizerKind::TrustBfgs,
        precision: Precision::F64,
        ..Default::default()
    };
    fit.init.candidates = 64;
    fit.init.frames = frames;
    SceneSpec {
        scene: super::DemoScene::Metal,
        name: super::DemoScene::Metal.name().into(),
        description: format!(
            "a metal cantilever bent past yield by two pushes and released, {frames} frames at {}x{} from two views; fitting E, nu, yield stress, hardening and density",
            res.0, res.1
        ),
        config,
        particles,
        part_names: vec!["beam".into()],
        palettes: vec![stage::STEEL],
        floor_z: 0.12,
        cameras: vec![
            stage::camera("front", res, [0.5, -0.45, 0.55], [0.5, 0.5, 0.45]),
            stage::camera("oblique", res, [1.25, -0.15, 0.8], [0.5, 0.5, 0.42]),
        ],
        start,
        free,
        bounds,
        pairs: vec![
            (0, ParamKind::YoungsModulus, ParamKind::YieldStress),
            (0, ParamKind::YoungsModulus, ParamKind::Density),
            (0, ParamKind::PoissonRatio, ParamKind::YieldStress),
            (0, ParamKind::YieldStress, ParamKind::Hardening),
        ],
        fit,
        profile_offsets: vec![-0.3, -0.15, -0.05, 0.05, 0.15, 0.3],
        profile2d_offsets: vec![-0.1, 0.1],
    }
}
