//! An engine's frame loop, headless: each frame steps the simulation and draws its Gaussians
//! (positions and covariances deformed by the particles' F), then writes the frame as a PNG:
//! `cargo run --release -p resonance4d --example frame_loop [OUT_DIR (default: a temp dir)]`.
//! Simulation and renderer share one backend type, so the renderer reads the particles where
//! the simulation left them (on a GPU backend nothing of a frame leaves the device).

use resonance4d::loss::{io::write_png_dir, Video};
use resonance4d::prelude::*;

const SCENE: &str = r#"
[domain]
n_grid = 24
[time]
substep_dt = 5e-4
frame_dt = 0.025
frames = 12
[[parts]]
material = "jelly"
youngs_modulus_pa = 3e4
density_kg_m3 = 1000.0
[[shapes]]
kind = "box"
min = [0.375, 0.375, 0.4]
max = [0.625, 0.625, 0.6]
[[boundary]]
type = "bounding_box"
[[boundary]]
type = "surface_collider"
point = [0.0, 0.0, 0.2]
normal = [0.0, 0.0, 1.0]
surface = "sticky"
"#;

/// Runs the example.
pub fn main() -> Result<(), Box<dyn std::error::Error>> {
    let tmp = std::env::temp_dir().join("r4d_frame_loop");
    let out = std::env::args().nth(1).unwrap_or(tmp.display().to_string());
    let config = SimConfig::parse(SCENE, "jelly.toml".as_ref())?;
    let dx = config.domain.dx() as f32;
    let particles = ParticleSet::from_shapes(&config.shapes, config.domain.dx());

    // One Gaussian per particle, in a red-gold checker so the jelly's wobble shows.
    let mut gaussians = Gaussians::default();
    for x in &particles.x {
        let odd = x.iter().map(|v| (v / 0.0625).floor() as i32).sum::<i32>() & 1;
        let rgb = [[0.86, 0.20, 0.36], [0.98, 0.78, 0.22]][odd as usize];
        gaussians.push_rgb(*x, [0.3 * dx; 3], [1.0, 0.0, 0.0, 0.0], 0.95, rgb);
    }
    let link = SimLink::identity(gaussians.len());
    let (eye, target) = ([0.5, -0.4, 0.7], [0.5, 0.5, 0.35]);
    let camera = Camera::look_at(160, 120, 40.0, eye, target, [0.0, 0.0, 1.0]);
    let settings = RenderSettings {
        background: [0.93, 0.92, 0.86],
        ..Default::default()
    };

    let mut sim = Simulation::new(CpuBackend::<f32>::default(), &config, particles, "jelly")?;
    let mut state = sim.init_state(&config.parts)?;
    let mut renderer = SplatRenderer::new(CpuBackend::default());
    let mut scene = renderer.upload_scene(&gaussians)?;
    renderer.link_scene(&mut scene, &link)?;
    let mut frames = Vec::new();
    for _ in 0..config.time.frames {
        sim.step_frame(&mut state, &config.parts)?;
        let (x, f) = sim.state_buffers(&state.state)?;
        let frame = renderer.prepare_frame_linked(&mut scene, &x, &f, &camera, &settings)?;
        frames.push(renderer.render_rows(&frame, 0..camera.height)?.rgb);
    }
    let video = Video::from_frames(120, 160, frames.iter().map(|f| f.as_slice()))?;
    write_png_dir(out.as_ref(), &video)?;
    println!("wrote {} frames to {out}", video.frames());
    Ok(())
}
