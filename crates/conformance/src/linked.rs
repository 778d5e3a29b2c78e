//! The device link check, for a backend whose frames stay on its device
//! ([`Compute::frames_on_device`]): a simulated frame's own buffers
//! ([`r4d_mpm::DynSimulation::frame_buffers`]) moved onto a scene by the backend's link kernel
//! and rendered ([`r4d_splat::Renderer::prepare_frame_linked`]), and the render VJP's particle
//! gradients ([`r4d_splat::Renderer::frame_vjp_linked`]) added to an adjoint there, against
//! the CPU renderer fed the same frame through the host link ([`SimLink::deformation`],
//! [`SimLink::deformation_vjp`]).

use crate::scenes::two_jellies;
use crate::{rel_l2, Checks, Failure, Tolerances};
use r4d_backend_cpu::CpuBackend;
use r4d_mpm::adjoint::host::HostSim;
use r4d_mpm::ForceForm;
use r4d_optim::compute::{Compute, Precision};
use r4d_optim::FitError;
use r4d_splat::{Camera, Gaussians, RenderSettings, SimLink, SplatRenderer};
use std::sync::Arc;

/// Static Gaussians before the simulated ones in the scene.
const STATIC: usize = 40;

/// The scene: `STATIC` static Gaussians, then one per particle (in reverse particle order),
/// and a link that turns and halves the simulation space.
fn linked_scene(particles: usize) -> (Gaussians, SimLink, Camera) {
    let n = STATIC + particles;
    let mut g = Gaussians {
        sh_degree: 1,
        ..Default::default()
    };
    for i in 0..n {
        let t = i as f32 / n as f32;
        g.means.push([0.3 * t - 0.15, 0.1 * (t * 7.0).sin(), 0.05]);
        g.log_scales
            .push([0.012f32.ln(), 0.02f32.ln(), 0.015f32.ln()]);
        g.quats.push([1.0, 0.1 * t, -0.2 * t, 0.05]);
        g.opacity_logits.push(1.5 - 2.0 * t);
        for k in 0..4 * 3 {
            g.sh.push(((i * 5 + k) % 7) as f32 / 7.0 - 0.3);
        }
    }
    let (c, s) = (0.5f64.cos(), 0.5f64.sin());
    let link = SimLink {
        scene_gaussians: n,
        simulated: (0..particles).map(|p| (n - 1 - p) as u32).collect(),
        filled: 0,
        rotation: [[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]],
        centre: [0.0; 3],
        scale: 2.0,
        shift: [0.45, 0.45, 0.3],
    };
    let cam = Camera::look_at(64, 48, 50.0, [0.1, -0.9, 0.35], [0.0; 3], [0.0, 0.0, 1.0]);
    (g, link, cam)
}

pub(crate) fn run(
    compute: &dyn Compute,
    tol: &Tolerances,
    checks: &mut Checks,
) -> Result<(), Failure> {
    let fit = |e: FitError| checks.backend_error(e);
    let (cfg, particles) = two_jellies(ForceForm::Mls);
    let sim = Arc::new(HostSim::new(&cfg, &particles).map_err(|e| fit(FitError::Mpm(e)))?);
    let d = compute
        .simulation(Precision::F32, sim.clone())
        .map_err(fit)?;
    let err = |e| fit(FitError::sim(d.backend_name(), e));
    let n = sim.len();
    let p = d.params(&cfg.parts);
    let mut s = d.init(&p, &vec![[0.0, 0.0, -0.3]; n]).map_err(err)?;
    for k in 0..sim.setup.substeps_per_frame as u64 {
        d.step(&mut s, &p, k).map_err(err)?;
    }
    let (xb, fb) = d.frame_buffers(&s).map_err(err)?;
    let x: Vec<[f32; 3]> = d
        .positions_f64(&s)
        .map_err(err)?
        .iter()
        .map(|v| v.map(|c| c as f32))
        .collect();
    let f: Vec<[[f32; 3]; 3]> = d
        .deformation_gradients_f64(&s)
        .map_err(err)?
        .iter()
        .map(|m| [0, 1, 2].map(|i| [0, 1, 2].map(|j| m[3 * i + j] as f32)))
        .collect();
    let (scene, link, cam) = linked_scene(n);
    let settings = RenderSettings {
        background: [0.2, 0.1, 0.3],
        ..Default::default()
    };
    let h = cam.height;
    let w: Vec<f32> = (0..(cam.width * h * 3) as usize)
        .map(|i| ((i * 7919) % 13) as f32 / 13.0 - 0.4)
        .collect();
    let mut out = None;
    compute
        .with_renderer(&mut |r| {
            let mut handle = r.upload_scene(&scene)?;
            r.link_scene(&mut handle, &link)?;
            let mut frame = r.prepare_frame_linked(&mut handle, &xb, &fb, &cam, &settings)?;
            let img = r.render_rows(&frame, 0..h)?;
            r.render_rows_vjp(&mut frame, 0..h, &w)?;
            out = Some((img, r.frame_vjp_linked(frame, &mut handle, &xb, &fb)?));
            Ok(())
        })
        .map_err(fit)?;
    let Some((got, (gx, gf))) = out else {
        return Err(fit(FitError::backend_msg(
            compute.name(),
            "with_renderer did not call the renderer",
        )));
    };
    // The device gradients come back through an adjoint state.
    let mut adj = d.zero_adjoint().map_err(err)?;
    d.add_buffers(&mut adj, &gx, &gf).map_err(err)?;
    let got_dx = d.positions_f64(&adj).map_err(err)?;
    let got_df = d.deformation_gradients_f64(&adj).map_err(err)?;

    let splat = |e| fit(FitError::Splat(e));
    let deform = link
        .deformation(&scene, &x, Some(&f), "linked")
        .map_err(splat)?;
    let mut cpu = SplatRenderer::new(CpuBackend::default());
    let mut frame = cpu
        .prepare_frame(&scene, Some(&deform), &cam, &settings)
        .map_err(splat)?;
    let want = cpu.render_rows(&frame, 0..h).map_err(splat)?;
    cpu.render_rows_vjp(&mut frame, 0..h, &w).map_err(splat)?;
    let g = cpu
        .frame_vjp_motion(frame, &scene, &deform)
        .map_err(splat)?;
    let (mut want_dx, mut want_df) = (vec![[0.0f32; 3]; n], vec![[0.0f32; 9]; n]);
    link.deformation_vjp(&g, &mut want_dx, &mut want_df)
        .map_err(splat)?;

    if want.alpha.iter().filter(|&&a| a > 0.1).count() < 20 {
        return Err(checks.scene("the linked scene covers too little of the image".into()));
    }
    if got.rgb.len() != want.rgb.len() {
        return Err(fit(FitError::backend_msg(
            compute.name(),
            format!(
                "an image of {} values, {} expected",
                got.rgb.len(),
                want.rgb.len()
            ),
        )));
    }
    let errs: Vec<f64> = got
        .rgb
        .iter()
        .zip(&want.rgb)
        .map(|(a, b)| (a - b).abs() as f64)
        .collect();
    let mean = errs.iter().sum::<f64>() / errs.len() as f64;
    let max = errs.iter().copied().fold(0.0, f64::max);
    checks.push("linked.render.mean".into(), mean, tol.image_mean)?;
    checks.push("linked.render.max".into(), max, tol.image_max)?;
    let f64s = |v: &[f32]| v.iter().map(|&c| c as f64).collect::<Vec<_>>();
    let (wx, wf) = (f64s(want_dx.as_flattened()), f64s(want_df.as_flattened()));
    if wx.iter().all(|&v| v == 0.0) || wf.iter().all(|&v| v == 0.0) {
        return Err(checks.scene("the linked render VJP's reference gradient is zero".into()));
    }
    let ex = rel_l2(got_dx.as_flattened(), &wx);
    checks.push("linked.vjp.x".into(), ex, tol.render_vjp)?;
    let ef = rel_l2(got_df.as_flattened(), &wf);
    checks.push("linked.vjp.F".into(), ef, tol.render_vjp)
}
