//! The foam block: a block of foam on the floor is squeezed by a downward push on its top
//! layer in two stages — a traction of 1.5 times the yield stress for 0.1 s, then 3 times it
//! for another 0.1 s — and released. Above the yield stress the foam flows at a rate that
//! grows with the excess stress over the plastic viscosity; two stress levels give two rates,
//! which separate the yield stress from the viscosity (one level determines only their
//! combination). The push is a force (body-force density), so the absolute density enters
//! the motion. After the release the block springs back to a permanent dent. Free: `E`,
//! `nu`, yield stress, plastic viscosity, density. Two views.

use super::{
    bounds_around, floor_collider, push_force, stage, stage_config, with, SceneSpec, Size,
};
use r4d_mpm::{Material, PartParams, ParticleSet, Shape};
use r4d_optim::video::{FitConfig, OptimizerKind};
use r4d_optim::ParamKind;
use r4d_optim::Precision;

/// The true parameters.
pub fn truth() -> PartParams {
    PartParams {
        material: Material::Foam,
        youngs_modulus_pa: 1e5,
        poisson_ratio: 0.2,
        yield_stress_pa: 3e3,
        plastic_viscosity_pa_s: 2e3,
        density_kg_m3: 300.0,
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
    // The full scene's substep is twice the small one's (CFL number 0.24 at the truth, 0.72
    // at the bounds' fastest corner); the small one keeps the finer step it was measured
    // with.
    let substep_dt = match size {
        Size::Full => 5e-4,
        Size::Small => 2.5e-4,
    };
    let num_dt = |seconds: f64| (seconds / substep_dt).round() as u32;
    let top = FLOOR + 0.25;
    // Traction sigma on the top 0.1 m: a body-force acceleration sigma / (density 0.1 m).
    let t = truth();
    let a = 1.5 * t.yield_stress_pa / (t.density_kg_m3 * 0.1);
    let f = push_force([0.0, 0.0, -a], t.density_kg_m3, n_grid);
    let pushes = format!(
        r#"[[boundary]]
type = "particle_impulse"
force = [0.0, 0.0, {fz}]
point = [0.5, 0.5, {mid}]
size = [0.25, 0.2, 0.05]
num_dt = {n2}
[[boundary]]
type = "particle_impulse"
force = [0.0, 0.0, {fz}]
point = [0.5, 0.5, {mid}]
size = [0.25, 0.2, 0.05]
num_dt = {n1}
start_time = 0.1
"#,
        fz = f[2],
        mid = top - 0.05,
        n2 = num_dt(0.2),
        n1 = num_dt(0.1)
    );
    let boundaries = floor_collider(FLOOR, "surface = \"sticky\"") + &pushes;
    let config = stage_config(n_grid, substep_dt, frames, vec![truth()], &boundaries);
    let dx = config.domain.dx();
    let particles = ParticleSet::from_shapes(
        &[Shape::Box {
            min: [0.3125, 0.375, FLOOR],
            max: [0.6875, 0.625, top],
            part: 0,
            per_cell: 2,
        }],
        dx,
    );
    let start = vec![with(
        with(t, ParamKind::YieldStress, 2e4),
        ParamKind::PlasticViscosity,
        100.0,
    )];
    let free = vec![vec![
        ParamKind::YoungsModulus,
        ParamKind::PoissonRatio,
        ParamKind::YieldStress,
        ParamKind::PlasticViscosity,
        ParamKind::Density,
    ]];
    let bounds = vec![bounds_around(
        &t,
        &[
            (ParamKind::YoungsModulus, 3.0),
            (ParamKind::PoissonRatio, 0.0),
            (ParamKind::YieldStress, 3.0),
            (ParamKind::PlasticViscosity, 3.0),
            (ParamKind::Density, 3.0),
        ],
    )];
    let mut fit = FitConfig {
        iters: 40,
        lr: 0.1,
        beta1: 0.6,
        optimizer: OptimizerKind::TrustBfgs,
        precision: Precision::F64,
        ..Default::default()
    };
    fit.init.candidates = 24;
    fit.init.frames = frames;
    SceneSpec {
        scene: super::DemoScene::Foam,
        name: super::DemoScene::Foam.name().into(),
        description: format!(
            "a foam block pressed and released, {frames} frames at {}x{} from two views; fitting E, nu, yield stress, plastic viscosity and density",
            res.0, res.1
        ),
        config,
        particles,
        part_names: vec!["foam".into()],
        palettes: vec![stage::FOAM],
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
