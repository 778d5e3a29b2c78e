//! The renderer on the Vulkan engine against the CPU backend on gsplat's golden scenes
//! (`tests/fixtures/splat` at the repository root): images within 1e-6 of the CPU's on average
//! and 1e-3 at most (f32 on both; the CPU is within 2.4e-3 of gsplat), every gradient array of `render_vjp` within 5e-3 relative L2 (the wgpu
//! backend's bounds, `crates/backend-wgpu/tests/wgpu/splat.rs`). Skipped without a Vulkan device
//! unless `R4D_REQUIRE_GPU=1`.

use r4d_backend_cpu::CpuBackend;
use r4d_backend_vulkan::testing::vulkan_or_skip;
use r4d_backend_vulkan::VulkanBackend;
use r4d_splat::{
    load_cameras, Deformation, GaussianGrads, RenderSettings, Renderer, SplatRenderer,
};
use std::path::Path;

fn rel_l2(got: &[f64], want: &[f64]) -> f64 {
    let d: f64 = got.iter().zip(want).map(|(a, b)| (a - b) * (a - b)).sum();
    let n: f64 = want.iter().map(|b| b * b).sum();
    (d / n.max(1e-300)).sqrt()
}

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

#[test]
#[cfg_attr(
    not(r4d_gpu),
    ignore = "no GPU adapter expected here (no Vulkan driver found at build time): install mesa-vulkan-drivers libvulkan1, or build with R4D_REQUIRE_GPU=1"
)]
fn renders_and_gradients_match_the_cpu_on_the_golden_scenes() {
    let Some(engine) = vulkan_or_skip("vulkan renderer") else {
        return;
    };
    let mut vk = SplatRenderer::new(VulkanBackend::new(engine.clone()));
    let mut cpu = SplatRenderer::new(CpuBackend::default());
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../tests/fixtures/splat");
    for name in [
        "sh0_basic",
        "sh3_shell_bg",
        "aniso_near_bg",
        "antialiased_sh2_white",
    ] {
        let dir = root.join(name);
        let scene = r4d_splat::ply::read_gaussians(&dir.join("scene.ply")).unwrap();
        let cams = load_cameras(&dir.join("cameras.json")).unwrap();
        let s = RenderSettings {
            background: cams.background.unwrap_or([0.0; 3]),
            mode: cams.mode.unwrap_or_default(),
        };
        // A deformation that moves and shears every Gaussian a little (dL/dF is exercised).
        let deform = Deformation {
            means: scene
                .means
                .iter()
                .map(|m| [m[0] + 0.01, m[1], m[2]])
                .collect(),
            f: vec![[[1.02, 0.03, 0.0], [0.0, 0.98, 0.01], [0.0, 0.0, 1.0]]; scene.len()],
        };
        for (k, cam) in cams.cameras.iter().enumerate() {
            for d in [None, Some(&deform)] {
                let want = cpu.render(&scene, d, cam, &s).unwrap();
                let got = vk.render(&scene, d, cam, &s).unwrap();
                let errs: Vec<f32> = got
                    .rgb
                    .iter()
                    .chain(&got.alpha)
                    .zip(want.rgb.iter().chain(&want.alpha))
                    .map(|(a, b)| (a - b).abs())
                    .collect();
                let max = errs.iter().copied().fold(0.0f32, f32::max);
                let mean = errs.iter().map(|&e| e as f64).sum::<f64>() / errs.len() as f64;
                assert!(
                    mean <= 1e-6 && max <= 1e-3,
                    "{name} camera {k}: image differs by {mean:.2e} on average, {max:.2e} at most"
                );
                // Weights that vary over the image and the channels.
                let w: Vec<f32> = (0..want.rgb.len())
                    .map(|i| ((i * 7919) % 13) as f32 / 13.0 - 0.4)
                    .collect();
                let gw = cpu.render_vjp(&scene, d, cam, &s, &w).unwrap();
                let gg = vk.render_vjp(&scene, d, cam, &s, &w).unwrap();
                for ((what, a), (_, b)) in arrays(&gg).into_iter().zip(arrays(&gw)) {
                    if b.iter().all(|v| *v == 0.0) {
                        continue;
                    }
                    let e = rel_l2(&a, &b);
                    assert!(e < 5e-3, "{name} camera {k} {what}: relative L2 {e:.2e}");
                }
            }
        }
    }
    r4d_backend_vulkan::testing::assert_validation_clean(&engine, "vulkan renderer");
}
