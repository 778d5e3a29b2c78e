//! The plasticine blob: a block of plasticine thrown down onto the floor (gravity plus a
//! short force impulse, so the absolute density enters the motion) flattens plastically on
//! impact and keeps its squashed shape, its yield stress dropping as it flows (softening).
//! Free: `E`, `nu`, yield stress, softening, density. Two views.

use super::{
    bounds_around, floor_collider, push_force, stage, stage_config, with, SceneSpec, Size,
};
use r4d_mpm::{Material, PartParams, ParticleSet, Shape};
use r4d_optim::video::{FitConfig, OptimizerKind, RestartsConfig};
use r4d_optim::ParamKind;
use r4d_optim::Precision;

/// The true parameters.
pub fn truth() -> PartParams {
    PartParams {
        material: Material::Plasticine,
        youngs_modulus_pa: 2e5,
        poisson_ratio: 0.3,
        yield_stress_pa: 4e3,
        density_kg_m3: 1200.0,
        softening: 5e3,
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
    // Thrown: 4.6 m/s^2 sideways and 13.8 m/s^2 down for 0.025 s, on top of gravity.
    let f = push_force([4.6, 0.0, -13.8], truth().density_kg_m3, n_grid);
    let throw = format!(
        r#"[[boundary]]
type = "particle_impulse"
force = [{fx}, 0.0, {fz}]
point = [0.4, 0.5, 0.5]
size = [0.2, 0.2, 0.2]
num_dt = {n}
"#,
        fx = f[0],
        fz = f[2],
        n = num_dt(0.025)
    );
    let boundaries = floor_collider(FLOOR, "surface = \"friction\"\nfriction = 0.8") + &throw;
    let config = stage_config(n_grid, substep_dt, frames, vec![truth()], &boundaries);
    let dx = config.domain.dx();
    let particles = ParticleSet::from_shapes(
        &[Shape::Box {
            min: [0.3125, 0.375, 0.4375],
            max: [0.5, 0.625, 0.625],
            part: 0,
            per_cell: 2,
        }],
        dx,
    );
    let t = truth();
    let start = vec![with(
        with(t, ParamKind::YieldStress, 3e4),
        ParamKind::Softening,
        1.5e4,
    )];
    let free = vec![vec![
        ParamKind::YoungsModulus,
        ParamKind::PoissonRatio,
        ParamKind::YieldStress,
        ParamKind::Softening,
        ParamKind::Density,
    ]];
    let bounds = vec![bounds_around(
        &t,
        &[
            (ParamKind::YoungsModulus, 3.0),
            (ParamKind::PoissonRatio, 0.0),
            (ParamKind::YieldStress, 3.0),
            (ParamKind::Softening, 3.0),
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
    fit.init.candidates = 64;
    fit.multi_start = 4;
    // Full size: 16 iterations per start (8 left the fit at loss 1.028 with yield stress
    // -6.7%, softening -13%; with 16 it ends at 1.004 with -4.3% and -5.7%: docs/fitting-measurements.md).
    fit.multi_start_iters = match size {
        Size::Full => 16,
        Size::Small => 8,
    };
    // Full size: the valley search after the iterations (150 loss evaluations, about 2.5
    // minutes) takes the end point from loss 1.0040 to 0.9944 (yield stress -4.3% -> -3.4%,
    // softening -5.7% -> -4.9%; E stays at +50-53%: docs/fitting-measurements.md).
    if size == Size::Full {
        fit.valley.evals = 150;
        // Then restarts along constant bulk modulus (shear modulus x 0.8^k, the other
        // parameters re-fitted by 8 iterations of gradient sampling at each): from the
        // valley search's end point (E +53%, loss 0.9944) the profile goes 0.9910, 0.9799,
        // 0.9998 at k = 1, 2, 3 and the fit ends at k = 2 (E +5.9%, yield stress -0.7%,
        // softening -1.8%); with 6 inner iterations k = 2 won by 0.0018 only
        // (docs/fitting-measurements.md). Three restarts fit the 15-minute budget (818 s in all).
        fit.shear_restarts = RestartsConfig {
            points: 3,
            factor: 0.8,
            part: 0,
            inner_iters: 8,
        };
    }
    fit.init.frames = frames;
    SceneSpec {
        scene: super::DemoScene::Plasticine,
        name: super::DemoScene::Plasticine.name().into(),
        description: format!(
            "a plasticine blob thrown onto the floor, {frames} frames at {}x{} from two views; fitting E, nu, yield stress, softening and density",
            res.0, res.1
        ),
        config,
        particles,
        part_names: vec!["blob".into()],
        palettes: vec![stage::CLAY],
        floor_z: FLOOR as f32,
        cameras: vec![
            stage::camera("front", res, [0.5, -0.3, 0.6], [0.5, 0.5, 0.3]),
            stage::camera("oblique", res, [1.1, -0.1, 0.85], [0.5, 0.5, 0.3]),
        ],
        start,
        free,
        bounds,
        // E and nu: plastic flow caps the shear stress, so the video pins the bulk modulus
        // better than the shear modulus and the fits end along a valley of roughly constant
        // bulk modulus (docs/fitting-measurements.md).
        pairs: vec![
            (0, ParamKind::YoungsModulus, ParamKind::PoissonRatio),
            (0, ParamKind::YoungsModulus, ParamKind::YieldStress),
            (0, ParamKind::YoungsModulus, ParamKind::Density),
            (0, ParamKind::PoissonRatio, ParamKind::YieldStress),
            (0, ParamKind::YieldStress, ParamKind::Softening),
        ],
        fit,
        profile_offsets: vec![-0.3, -0.15, -0.05, 0.05, 0.15, 0.3],
        profile2d_offsets: vec![-0.1, 0.1],
    }
}
