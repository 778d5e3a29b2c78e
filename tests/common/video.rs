//! The small video-fit problem shared by the video-fit tests (`tests/fits/video_fit.rs`) and
//! their GPU parity (`tests/backends/video_fit_gpu.rs`).
#![allow(dead_code)]

use r4d_mpm::{PartParams, ParticleSet, SimConfig};
use resonance4d::video_fit::{FitConfig, Objective, Strategy, VideoProblem, View};
use std::path::Path;

/// A small elastic block (one part, or two stacked parts) clamped at its base and pushed
/// sideways at the top, seen by a 64 x 64 camera; the reference is rendered from `truth`.
pub fn small_problem(truth: &[PartParams], frames: usize) -> VideoProblem {
    let text = format!(
        r#"
[domain]
n_grid = 16
[time]
substep_dt = 1e-3
substeps_per_frame = 12
frames = {frames}
[solver]
gravity = [0.0, 0.0, -9.8]
[[boundary]]
type = "bounding_box"
[[boundary]]
type = "cuboid"
point = [0.5, 0.5, 0.1875]
size = [0.5, 0.5, 0.07]
[[boundary]]
type = "particle_impulse"
force = [0.25, 0.1, 0.0]
point = [0.5, 0.5, 0.6]
size = [0.2, 0.2, 0.1]
num_dt = 8
{parts}"#,
        parts = truth
            .iter()
            .map(|_| "[[parts]]\nmaterial = \"jelly\"\n")
            .collect::<String>()
    );
    let mut config = SimConfig::parse(&text, Path::new("small.toml")).unwrap();
    config.parts = truth.to_vec();
    let dx = config.domain.dx();
    let d = |i: f64| i * dx;
    let top = if truth.len() > 1 { 1 } else { 0 };
    let shapes = [
        r4d_mpm::Shape::Box {
            min: [d(6.0), d(7.0), d(3.0)],
            max: [d(10.0), d(9.0), d(8.0)],
            part: 0,
            per_cell: 2,
        },
        r4d_mpm::Shape::Box {
            min: [d(6.0), d(7.0), d(8.0)],
            max: [d(10.0), d(9.0), d(11.0)],
            part: top,
            per_cell: 2,
        },
    ];
    let particles = ParticleSet::from_shapes(&shapes, dx);
    let mut scene = r4d_splat::Gaussians {
        sh_degree: 0,
        ..Default::default()
    };
    let s = (0.25 * dx) as f32;
    for x in &particles.x {
        let c = x.map(|v| (v / 0.125).floor() as i64);
        let odd = (c[0] + c[1] + c[2]).rem_euclid(2) as f32;
        scene.means.push(*x);
        scene.log_scales.push([s.ln(); 3]);
        scene.quats.push([1.0, 0.0, 0.0, 0.0]);
        scene.opacity_logits.push(3.0);
        scene
            .sh
            .extend([0.9 - 0.7 * odd, 0.3 + 0.5 * odd, 0.2].map(|v| (v - 0.5) / 0.2820948));
    }
    let mut link = r4d_splat::SimLink::identity(scene.len());
    link.simulated = (0..particles.x.len() as u32).collect();
    let camera = r4d_splat::Camera::look_at(
        64,
        64,
        45.0,
        [0.55, -0.45, 0.55],
        [0.5, 0.5, 0.42],
        [0.0, 0.0, 1.0],
    );
    let mut p = VideoProblem {
        config,
        particles,
        scene,
        link,
        settings: r4d_splat::RenderSettings {
            background: [0.9, 0.9, 0.85],
            ..Default::default()
        },
        views: vec![View {
            name: "small".into(),
            video: r4d_loss::Video::zeros(frames + 1, 64, 64).into(),
            camera,
        }],
        fps: 1.0 / 12e-3,
        compute: resonance4d::compute::cpu(),
    };
    let obj = Objective::new(&p, None, &fit_config(0).loss, false).unwrap();
    p.views[0].video = obj.render(truth).unwrap().remove(0).into();
    p
}

pub fn jelly(e: f64, rho: f64) -> PartParams {
    PartParams {
        youngs_modulus_pa: e,
        poisson_ratio: 0.3,
        density_kg_m3: rho,
        ..Default::default()
    }
}

pub fn fit_config(iters: usize) -> FitConfig {
    let mut c = FitConfig {
        // As written here: the automatic strategy would decide the stages and their budgets.
        strategy: Strategy::Fixed,
        iters,
        lr: 0.1,
        beta1: 0.6,
        free: Some(vec!["E".into(), "density".into()]),
        ..Default::default()
    };
    c.init.enabled = false;
    c.loss.spectral.patch = [8, 8];
    c.loss.spectral.phase_mask = Some(1e-3);
    c
}
