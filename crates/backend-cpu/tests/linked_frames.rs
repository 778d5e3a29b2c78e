//! Frames handed from a simulation to a renderer of the same backend type
//! ([`Simulation::state_buffers`], `Renderer::prepare_frame_linked`, `frame_vjp_linked`,
//! `DynSimulation::add_buffers`) on the CPU: with an identity link the same image and the
//! same particle gradients as the host path bit for bit, and every mismatch a typed error
//! naming what is wrong, never a panic.

use r4d_backend_cpu::CpuBackend;
use r4d_mpm::{DynSimulation, ParticleSet, SimConfig, Simulation, Simulator};
use r4d_splat::{Camera, Gaussians, RenderSettings, SimLink, SplatRenderer};

const SCENE: &str = r#"
[domain]
n_grid = 16
[time]
substep_dt = 5e-4
frame_dt = 0.01
frames = 2
[[parts]]
material = "jelly"
youngs_modulus_pa = 2e4
[[shapes]]
kind = "box"
min = [0.4, 0.4, 0.4]
max = [0.6, 0.6, 0.6]
[[boundary]]
type = "bounding_box"
"#;

#[test]
fn linked_frames_match_the_host_path_and_refuse_mismatches() {
    let config = SimConfig::parse(SCENE, "t.toml".as_ref()).unwrap();
    let particles = ParticleSet::from_shapes(&config.shapes, config.domain.dx());
    let n = particles.x.len();
    let mut g = Gaussians::default();
    for (i, x) in particles.x.iter().enumerate() {
        let c = (i % 7) as f32 / 7.0;
        g.push_rgb(*x, [0.02; 3], [1.0, 0.1, 0.0, 0.0], 0.9, [c, 0.5, 1.0 - c]);
    }
    let cam = Camera::look_at(
        48,
        32,
        40.0,
        [0.5, -0.6, 0.8],
        [0.5, 0.5, 0.5],
        [0.0, 0.0, 1.0],
    );
    let settings = RenderSettings::default();
    let mut sim = Simulation::new(CpuBackend::<f32>::default(), &config, particles, "t").unwrap();
    let mut state = sim.init_state(&config.parts).unwrap();
    sim.step_frame(&mut state, &config.parts).unwrap();
    let (x, f) = sim.state_buffers(&state.state).unwrap();

    let mut r = SplatRenderer::new(CpuBackend::<f32>::default());
    let mut scene = r.upload_scene(&g).unwrap();
    let link = SimLink::identity(n);
    let e = r
        .prepare_frame_linked(&mut scene, &x, &f, &cam, &settings)
        .unwrap_err();
    assert!(e.to_string().contains("no simulation link"), "{e}");
    let e = r
        .link_scene(&mut scene, &SimLink::identity(n + 1))
        .unwrap_err();
    assert!(e.to_string().contains("Gaussians"), "{e}");
    r.link_scene(&mut scene, &link).unwrap();

    // The image and the particle gradients of the host path, bit for bit.
    let h = cam.height;
    let w: Vec<f32> = (0..(cam.width * h * 3) as usize)
        .map(|i| ((i * 31) % 17) as f32 / 17.0 - 0.5)
        .collect();
    let mut frame = r
        .prepare_frame_linked(&mut scene, &x, &f, &cam, &settings)
        .unwrap();
    let img = r.render_rows(&frame, 0..h).unwrap();
    assert!(img.alpha.iter().any(|&a| a > 0.5), "the block is in view");
    r.render_rows_vjp(&mut frame, 0..h, &w).unwrap();
    let (gx, gf) = r.frame_vjp_linked(frame, &mut scene, &x, &f).unwrap();
    let xs = sim.positions(&state).unwrap();
    let fs: Vec<[[f32; 3]; 3]> = sim
        .deformation_gradients(&state)
        .unwrap()
        .iter()
        .map(|m| [[m[0], m[1], m[2]], [m[3], m[4], m[5]], [m[6], m[7], m[8]]])
        .collect();
    let d = link.deformation(&g, &xs, Some(&fs), "host").unwrap();
    let mut host = SplatRenderer::new(CpuBackend::<f32>::default());
    let mut hf = host.prepare_frame(&g, Some(&d), &cam, &settings).unwrap();
    assert_eq!(host.render_rows(&hf, 0..h).unwrap().rgb, img.rgb);
    host.render_rows_vjp(&mut hf, 0..h, &w).unwrap();
    let hg = host.frame_vjp_motion(hf, &g, &d).unwrap();
    let (mut hx, mut hfg) = (vec![[0.0f32; 3]; n], vec![[0.0f32; 9]; n]);
    link.deformation_vjp(&hg, &mut hx, &mut hfg).unwrap();
    let dx = gx.get::<CpuBackend<f32>, [f32; 3]>().unwrap();
    let df = gf.get::<CpuBackend<f32>, [f32; 9]>().unwrap();
    assert_eq!(dx, &hx);
    assert_eq!(df, &hfg);

    // A frame of another particle count, or of another backend type, is refused by name.
    let (short_x, _) = {
        let cfg2 = SimConfig::parse(
            &SCENE.replace("0.6, 0.6, 0.6", "0.5, 0.6, 0.6"),
            "t".as_ref(),
        )
        .unwrap();
        let p2 = ParticleSet::from_shapes(&cfg2.shapes, cfg2.domain.dx());
        let s2 = Simulation::new(CpuBackend::<f32>::default(), &cfg2, p2, "t").unwrap();
        let st2 = s2.init_state(&cfg2.parts).unwrap();
        s2.state_buffers(&st2.state).unwrap()
    };
    let e = r
        .prepare_frame_linked(&mut scene, &short_x, &f, &cam, &settings)
        .unwrap_err();
    assert!(e.to_string().contains("the link expects"), "{e}");
    let sim64 = Simulation::new(
        CpuBackend::<f64>::with_par(r4d_backend_cpu::Par::Rayon),
        &config,
        ParticleSet::from_shapes(&config.shapes, config.domain.dx()),
        "t",
    )
    .unwrap();
    let st64 = sim64.init_state(&config.parts).unwrap();
    let (x64, f64b) = sim64.state_buffers(&st64.state).unwrap();
    let e = r
        .prepare_frame_linked(&mut scene, &x64, &f64b, &cam, &settings)
        .unwrap_err();
    assert!(e.to_string().contains("another scalar type"), "{e}");

    // The adjoint refuses gradients of the wrong length or type, naming the operation.
    let dsim: &dyn DynSimulation = &sim;
    let mut adj = dsim.zero_adjoint().unwrap();
    let err = dsim.add_buffers(&mut adj, &short_x, &gf).unwrap_err();
    assert!(err.to_string().contains("add_buffers"), "{err}");
    let err = dsim.add_buffers(&mut adj, &x64, &f64b).unwrap_err();
    assert!(err.to_string().contains("another scalar type"), "{err}");
    dsim.add_buffers(&mut adj, &gx, &gf).unwrap();
    let back = dsim.positions_f64(&adj).unwrap();
    assert_eq!(back[0], hx[0].map(f64::from));
}
