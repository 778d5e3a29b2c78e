//! The renderer checks: images and every gradient array of the render VJP, with and without a
//! deformation.

use crate::scenes::splats;
use crate::{rel_l2, Checks, Failure, Tolerances};
use r4d_backend_cpu::CpuBackend;
use r4d_optim::compute::Compute;
use r4d_optim::FitError;
use r4d_splat::{GaussianGrads, Image, RenderSettings, Renderer, SplatRenderer};

fn arrays(g: &GaussianGrads) -> Vec<(&'static str, Vec<f64>)> {
    let f = |v: &[f32]| v.iter().map(|&x| x as f64).collect::<Vec<_>>();
    vec![
        ("means", f(g.means.as_flattened())),
        ("log_scales", f(g.log_scales.as_flattened())),
        ("quats", f(g.quats.as_flattened())),
        ("opacity_logits", f(&g.opacity_logits)),
        ("sh", f(&g.sh)),
        ("F", f(g.f.as_flattened().as_flattened())),
    ]
}

pub(crate) fn run(
    compute: &dyn Compute,
    tol: &Tolerances,
    checks: &mut Checks,
) -> Result<(), Failure> {
    let (scene, deform, cam) = splats();
    let s = RenderSettings {
        background: [0.1, 0.2, 0.3],
        ..Default::default()
    };
    let mut cpu = SplatRenderer::new(CpuBackend::default());
    // Weights that vary over the image and the channels.
    let n = (cam.width * cam.height * 3) as usize;
    let w: Vec<f32> = (0..n)
        .map(|i| ((i * 7919) % 13) as f32 / 13.0 - 0.4)
        .collect();
    for (label, d) in [("", None), ("deformed.", Some(&deform))] {
        let mut out: Option<(Image, GaussianGrads)> = None;
        compute
            .with_renderer(&mut |r| {
                let img = r.render(&scene, d, &cam, &s)?;
                let g = r.render_vjp(&scene, d, &cam, &s, &w)?;
                out = Some((img, g));
                Ok(())
            })
            .map_err(|e| checks.backend_error(e))?;
        let Some((got, gg)) = out else {
            return Err(checks.backend_error(FitError::backend_msg(
                compute.name(),
                "with_renderer did not call the renderer",
            )));
        };
        let splat_err = |e| checks.backend_error(FitError::Splat(e));
        let want = cpu.render(&scene, d, &cam, &s).map_err(splat_err)?;
        let gw = cpu.render_vjp(&scene, d, &cam, &s, &w).map_err(splat_err)?;
        let (a, b): (Vec<f32>, Vec<f32>) = (
            got.rgb.iter().chain(&got.alpha).copied().collect(),
            want.rgb.iter().chain(&want.alpha).copied().collect(),
        );
        if a.len() != b.len() {
            return Err(checks.backend_error(FitError::backend_msg(
                compute.name(),
                format!("an image of {} values, {} expected", a.len(), b.len()),
            )));
        }
        if want.alpha.iter().all(|&v| v == 0.0) {
            return Err(checks.scene("the reference image is empty".into()));
        }
        let errs: Vec<f64> = a
            .iter()
            .zip(&b)
            .map(|(x, y)| (x - y).abs() as f64)
            .collect();
        let mean = errs.iter().sum::<f64>() / errs.len() as f64;
        let max = errs.iter().copied().fold(0.0, f64::max);
        checks.push(format!("render.{label}mean"), mean, tol.image_mean)?;
        checks.push(format!("render.{label}max"), max, tol.image_max)?;
        for ((what, x), (_, y)) in arrays(&gg).into_iter().zip(arrays(&gw)) {
            if y.iter().all(|v| *v == 0.0) {
                continue;
            }
            checks.push(
                format!("render_vjp.{label}{what}"),
                rel_l2(&x, &y),
                tol.render_vjp,
            )?;
        }
    }
    Ok(())
}
