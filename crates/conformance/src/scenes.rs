//! The suite's scenes, also used by the GPU engines' detailed adjoint tests: a two-part jelly
//! object with every kind of boundary condition ([`two_jellies`]), a fixed linear position
//! loss ([`weights`]), initial velocities ([`initial_velocity`]) and a small splatting scene
//! ([`splats`]).

use r4d_mpm::{
    BoundaryCondition, Domain, ForceForm, Material, PartParams, ParticleSet, Shape, SimConfig,
    SolverConfig, Surface, TimeConfig,
};
use r4d_splat::{Camera, Deformation, Gaussians};

/// Two jelly parts in a bounding box (sticky with the classic force form; slip, plus a friction
/// ground collider, with MLS), the upper one partly held by a cuboid clamp, the lower one
/// resting in the box's layers and pushed by an impulse.
pub fn two_jellies(force: ForceForm) -> (SimConfig, ParticleSet) {
    let n = 24;
    let dx = 1.0 / n as f64;
    let cfg = SimConfig {
        domain: Domain {
            grid_lim: 1.0,
            n_grid: n,
        },
        time: TimeConfig {
            substep_dt: 2e-4,
            frame_dt: None,
            substeps_per_frame: Some(20),
            frames: 3,
        },
        solver: SolverConfig {
            force,
            rpic_damping: 0.1,
            ..Default::default()
        },
        parts: vec![
            PartParams {
                material: Material::Jelly,
                youngs_modulus_pa: 3e4,
                poisson_ratio: 0.3,
                density_kg_m3: 800.0,
                ..Default::default()
            },
            PartParams {
                material: Material::Jelly,
                youngs_modulus_pa: 1e4,
                poisson_ratio: 0.4,
                density_kg_m3: 1200.0,
                ..Default::default()
            },
        ],
        shapes: vec![
            Shape::Box {
                min: [0.3, 0.3, 3.2 * dx],
                max: [0.6, 0.6, 4.0 * dx + 0.15],
                part: 0,
                per_cell: 2,
            },
            Shape::Box {
                min: [0.35, 0.35, 4.0 * dx + 0.15],
                max: [0.55, 0.55, 4.0 * dx + 0.3],
                part: 1,
                per_cell: 2,
            },
        ],
        particles: None,
        boundary: vec![
            BoundaryCondition::BoundingBox {
                layers: 3,
                surface: match force {
                    ForceForm::Classic => Surface::Sticky,
                    _ => Surface::Slip,
                },
            },
            BoundaryCondition::SurfaceCollider {
                point: [0.0, 0.0, 3.6 * dx],
                normal: [0.02, 0.0, 1.0],
                surface: Surface::Friction,
                friction: 0.4,
                start_time: 0.0,
                end_time: match force {
                    ForceForm::Classic => 0.0,
                    _ => 1.0,
                },
            },
            BoundaryCondition::Cuboid {
                point: [0.45, 0.45, 4.0 * dx + 0.3],
                size: [0.05, 0.05, 0.04],
                velocity: [0.0, 0.0, 0.0],
                start_time: 0.0,
                end_time: 1.0,
                reset: false,
            },
            BoundaryCondition::ParticleImpulse {
                force: [-0.2, 0.1, 0.5],
                point: [0.4, 0.45, 4.0 * dx + 0.05],
                size: [0.1, 0.2, 0.1],
                num_dt: 30,
                start_time: 0.0,
            },
        ],
    };
    let scene = ParticleSet::from_shapes(&cfg.shapes, dx);
    (cfg, scene)
}

/// Loss weights of frame `f`: a fixed, particle-dependent linear position loss.
pub fn weights(f: usize, n: usize) -> Vec<[f32; 3]> {
    (0..n)
        .map(|p| {
            let w = ((p * 7 + f * 3) % 11) as f32 / 11.0 - 0.5;
            [w, 0.25 * w, 0.5 - w]
        })
        .collect()
}

/// Initial velocities of `n` particles: varied, downwards.
pub fn initial_velocity(n: usize) -> Vec<[f32; 3]> {
    (0..n)
        .map(|p| {
            let s = (p % 5) as f32 / 5.0 - 0.4;
            [0.3 * s, -0.2 * s, -0.2]
        })
        .collect()
}

/// 240 Gaussians of SH degree 1 (scales, rotations, opacities and colours varied by a fixed
/// sequence) seen by a 64 x 48 camera, and a deformation that moves and shears each.
pub fn splats() -> (Gaussians, Deformation, Camera) {
    let n = 240;
    let mut seq = 0x2545_f491_u64;
    let mut next = move || {
        seq = seq
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1_442_695_040_888_963_407);
        ((seq >> 40) as f32) / (1u64 << 24) as f32
    };
    let mut g = Gaussians {
        sh_degree: 1,
        ..Default::default()
    };
    for _ in 0..n {
        g.means
            .push([next() - 0.5, next() - 0.5, 0.6 * (next() - 0.5)]);
        g.log_scales
            .push([0.0; 3].map(|_| (0.02 + 0.06 * next()).ln()));
        g.quats
            .push([1.0, next() - 0.5, next() - 0.5, next() - 0.5]);
        g.opacity_logits.push(4.0 * next() - 1.0);
        for _ in 0..4 * 3 {
            g.sh.push(next() - 0.3);
        }
    }
    let deform = Deformation {
        means: g.means.iter().map(|m| [m[0] + 0.01, m[1], m[2]]).collect(),
        f: (0..n)
            .map(|i| {
                let s = 0.02 * (i % 5) as f32;
                [[1.0 + s, 0.03, 0.0], [0.0, 0.98, 0.01], [0.0, s, 1.0]]
            })
            .collect(),
    };
    let cam = Camera::look_at(64, 48, 50.0, [0.2, -1.8, 0.4], [0.0; 3], [0.0, 0.0, 1.0]);
    (g, deform, cam)
}
