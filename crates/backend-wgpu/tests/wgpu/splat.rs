//! The wgpu splatting backend against gsplat's golden renders (`tests/fixtures/splat` at the
//! repository root; README there) and against the CPU backend: images by the README's
//! acceptance rule, projections within 1e-5 relative, tile lists id for id, every gradient
//! array of `render_vjp` within 5e-3 relative L2 of both (with native float atomics and with
//! the compare-exchange scatter); plus large synthetic binning/compositing and
//! `rasterize_vjp` cases (multi-level scans, many depth ties, tiles with thousands of
//! Gaussians, capped alphas), an empty render and the WGSL struct layouts.

use r4d_backend_cpu::CpuBackend;
use r4d_backend_wgpu::testing::{gpu_or_skip, gpu_or_skip_with};
use r4d_backend_wgpu::WgpuBackend;
use r4d_backend_wgpu::WgpuContext;
use r4d_splat::kernels::{Backend, SceneBufs, TileBufs};
use r4d_splat::project::Projected;
use r4d_splat::{
    Camera, CameraConsts, Deformation, GaussianGrads, Gaussians, RenderSettings, Renderer,
    SplatKernels, SplatRenderer,
};
use r4d_testkit::read_npy;
use r4d_testkit::splat_cases::{load, settings, SCENES};
use std::sync::Arc;

fn gpu(test: &str) -> Option<Arc<WgpuContext>> {
    gpu_or_skip(test).map(Arc::new)
}

// ---- rules ----------------------------------------------------------------------------------

/// The README's acceptance rule (mean abs error <= 1e-5, >= 99.9% within 1e-3, none above
/// 5e-2), over the entries where `mask` holds; returns (mean, fraction within 1e-3, max).
fn image_rule(what: &str, got: &[f32], want: &[f64], mask: Option<&[bool]>) -> (f64, f64, f64) {
    assert_eq!(got.len(), want.len(), "{what}: size");
    let (mut sum, mut n, mut within, mut max) = (0.0f64, 0usize, 0usize, 0.0f64);
    for (i, (&g, &w)) in got.iter().zip(want).enumerate() {
        if mask.is_some_and(|m| !m[i]) {
            continue;
        }
        let e = (g as f64 - w).abs();
        assert!(e.is_finite(), "{what}: entry {i} is {g} vs {w}");
        sum += e;
        n += 1;
        within += (e <= 1e-3) as usize;
        max = max.max(e);
    }
    let mean = sum / n.max(1) as f64;
    let frac = within as f64 / n.max(1) as f64;
    assert!(mean <= 1e-5, "{what}: mean abs error {mean:.3e} > 1e-5");
    assert!(
        frac >= 0.999,
        "{what}: only {:.4}% within 1e-3",
        frac * 100.0
    );
    assert!(max <= 5e-2, "{what}: max abs error {max:.3e} > 5e-2");
    (mean, frac, max)
}

fn f64s(v: &[f32]) -> Vec<f64> {
    v.iter().map(|&x| x as f64).collect()
}

/// The README's gradient rule: relative L2 error <= 5e-3 and the sign pattern of the
/// significant entries (above 1e-3 of the largest) at most 0.1% flipped; returns the error.
fn grad_rule(what: &str, got: &[f64], want: &[f64]) -> f64 {
    assert_eq!(got.len(), want.len(), "{what}: size");
    let rel = rel_l2(got, want);
    assert!(rel <= 5e-3, "{what}: relative L2 error {rel:.3e} > 5e-3");
    let big = want.iter().fold(0.0f64, |m, w| m.max(w.abs())) * 1e-3;
    let (mut flips, mut count) = (0, 0);
    for (g, w) in got.iter().zip(want) {
        if w.abs() > big {
            count += 1;
            flips += (g.signum() != w.signum()) as usize;
        }
    }
    assert!(
        flips * 1000 <= count,
        "{what}: {flips} of {count} significant entries have the wrong sign"
    );
    rel
}

/// `||got - want|| / ||want||`.
fn rel_l2(got: &[f64], want: &[f64]) -> f64 {
    assert_eq!(got.len(), want.len());
    let num: f64 = got.iter().zip(want).map(|(g, w)| (g - w) * (g - w)).sum();
    let den: f64 = want.iter().map(|w| w * w).sum();
    assert!(num.is_finite(), "non-finite gradient");
    (num / den.max(1e-300)).sqrt()
}

/// The gradient arrays of a render, named as gsplat's files (`F` only when deformed).
fn grad_arrays(g: &GaussianGrads, deformed: bool) -> Vec<(&'static str, Vec<f64>)> {
    let flat = |v: &[[f32; 3]]| -> Vec<f64> { v.iter().flatten().map(|&x| x as f64).collect() };
    let mut out = vec![
        ("means", flat(&g.means)),
        ("log_scales", flat(&g.log_scales)),
        (
            "quats",
            g.quats.iter().flatten().map(|&x| x as f64).collect(),
        ),
        ("raw_opacities", f64s(&g.opacity_logits)),
        ("sh", f64s(&g.sh)),
    ];
    if deformed {
        out.push((
            "F",
            g.f.iter().flatten().flatten().map(|&x| x as f64).collect(),
        ));
    }
    out
}

// ---- golden renders -------------------------------------------------------------------------

#[test]
#[cfg_attr(
    not(r4d_gpu),
    ignore = "no GPU adapter expected here (no Vulkan driver found at build time): install mesa-vulkan-drivers libvulkan1, or build with R4D_REQUIRE_GPU=1"
)]
fn golden_renders_match_gsplat_and_cpu() {
    let Some(ctx) = gpu("golden_renders_match_gsplat_and_cpu") else {
        return;
    };
    println!("adapter: {}", ctx.info.name);
    let mut gpu_r = SplatRenderer::new(WgpuBackend::new(ctx));
    let mut cpu_r = SplatRenderer::new(CpuBackend::default());
    for name in SCENES {
        let c = load(name);
        let s = settings(&c);
        for (k, cam) in c.cams.cameras.iter().enumerate() {
            let what = format!("{name}/cam{k}");
            let img = gpu_r.render(&c.scene, c.deform.as_ref(), cam, &s).unwrap();
            let cpu = cpu_r.render(&c.scene, c.deform.as_ref(), cam, &s).unwrap();
            assert_eq!(gpu_r.stats, cpu_r.stats, "{what}: visible / intersections");
            let p = |n: &str| read_npy(&c.dir.join(format!("cam{k}_{n}.npy")));
            // Against gsplat.
            let alpha_ref = p("alpha");
            let mask: Vec<bool> = alpha_ref.data.iter().map(|&a| a > 1e-3).collect();
            let g_rgb = image_rule(
                &format!("{what} rgb vs gsplat"),
                &img.rgb,
                &p("rgb").data,
                None,
            );
            let g_a = image_rule(
                &format!("{what} alpha vs gsplat"),
                &img.alpha,
                &alpha_ref.data,
                None,
            );
            let g_d = image_rule(
                &format!("{what} depth vs gsplat"),
                &img.depth,
                &p("depth").data,
                Some(&mask),
            );
            // Against the CPU backend.
            let cmask: Vec<bool> = cpu.alpha.iter().map(|&a| a > 1e-3).collect();
            let c_rgb = image_rule(
                &format!("{what} rgb vs cpu"),
                &img.rgb,
                &f64s(&cpu.rgb),
                None,
            );
            let c_a = image_rule(
                &format!("{what} alpha vs cpu"),
                &img.alpha,
                &f64s(&cpu.alpha),
                None,
            );
            let c_d = image_rule(
                &format!("{what} depth vs cpu"),
                &img.depth,
                &f64s(&cpu.depth),
                Some(&cmask),
            );
            println!(
                "{what}: vs gsplat rgb mean {:.2e} max {:.2e} ({:.3}% <= 1e-3), alpha mean {:.2e} \
                 max {:.2e}, depth mean {:.2e} max {:.2e} | vs cpu rgb mean {:.2e} max {:.2e}, \
                 alpha mean {:.2e} max {:.2e}, depth mean {:.2e} max {:.2e}",
                g_rgb.0,
                g_rgb.2,
                g_rgb.1 * 100.0,
                g_a.0,
                g_a.2,
                g_d.0,
                g_d.2,
                c_rgb.0,
                c_rgb.2,
                c_a.0,
                c_a.2,
                c_d.0,
                c_d.2
            );
        }
    }
}

/// The backward passes on the GPU (`rasterize_vjp.wgsl`, `project_vjp.wgsl`) against the CPU
/// backend (every gradient array within 5e-3 relative L2) and against gsplat's autograd
/// gradients (the README's rule), on every golden scene and camera, with native float atomics
/// (where the adapter has them) and with the compare-exchange scatter.
#[test]
#[cfg_attr(
    not(r4d_gpu),
    ignore = "no GPU adapter expected here (no Vulkan driver found at build time): install mesa-vulkan-drivers libvulkan1, or build with R4D_REQUIRE_GPU=1"
)]
fn gradients_match_cpu_and_gsplat() {
    for float_atomics in [true, false] {
        let Some(ctx) = gpu_or_skip_with("gradients_match_cpu_and_gsplat", float_atomics) else {
            return;
        };
        let scatter = if ctx.float_atomics {
            "native float atomics"
        } else {
            "compare-exchange"
        };
        println!("adapter {}: {scatter}", ctx.info.name);
        let mut r = SplatRenderer::new(WgpuBackend::new(Arc::new(ctx)));
        let mut cpu = SplatRenderer::new(CpuBackend::default());
        let mut worst: Vec<(&str, f64, f64)> = Vec::new();
        for name in SCENES {
            let c = load(name);
            let s = settings(&c);
            for (k, cam) in c.cams.cameras.iter().enumerate() {
                let what = format!("{name}/cam{k} ({scatter})");
                let w: Vec<f32> = read_npy(&c.dir.join(format!("cam{k}_loss_weights.npy")))
                    .data
                    .iter()
                    .map(|&x| x as f32)
                    .collect();
                let g = r
                    .render_vjp(&c.scene, c.deform.as_ref(), cam, &s, &w)
                    .unwrap();
                let gc = cpu
                    .render_vjp(&c.scene, c.deform.as_ref(), cam, &s, &w)
                    .unwrap();
                let cpu_arrays = grad_arrays(&gc, c.deform.is_some());
                let mut line = String::new();
                for ((a, got), (_, want_cpu)) in
                    grad_arrays(&g, c.deform.is_some()).iter().zip(&cpu_arrays)
                {
                    let e_cpu = rel_l2(got, want_cpu);
                    assert!(
                        e_cpu <= 5e-3,
                        "{what} {a}: relative L2 {e_cpu:.3e} vs the CPU backend > 5e-3"
                    );
                    let gold = read_npy(&c.dir.join(format!("cam{k}_grad_{a}.npy")));
                    let e_gold = grad_rule(&format!("{what} {a} vs gsplat"), got, &gold.data);
                    line += &format!(" {a} {e_cpu:.1e}/{e_gold:.1e}");
                    match worst.iter_mut().find(|x| x.0 == *a) {
                        Some(x) => {
                            x.1 = x.1.max(e_cpu);
                            x.2 = x.2.max(e_gold);
                        }
                        None => worst.push((a, e_cpu, e_gold)),
                    }
                }
                println!("{what}: rel L2 vs cpu/gsplat:{line}");
            }
        }
        for (a, e_cpu, e_gold) in worst {
            println!("worst {a} ({scatter}): vs cpu {e_cpu:.2e}, vs gsplat {e_gold:.2e}");
        }
    }
}

// ---- projection and tile lists against the CPU backend --------------------------------------

fn scene_bufs<B: SplatKernels>(b: &B, g: &Gaussians, d: Option<&Deformation>) -> SceneBufs<B> {
    SceneBufs {
        n: g.len(),
        sh_degree: g.sh_degree,
        means: b.upload(d.map_or(&g.means, |d| &d.means)).unwrap(),
        log_scales: b.upload(&g.log_scales).unwrap(),
        quats: b.upload(&g.quats).unwrap(),
        opacity_logits: b.upload(&g.opacity_logits).unwrap(),
        sh: b.upload(&g.sh).unwrap(),
        f: d.map(|d| b.upload(&d.f).unwrap()),
    }
}

/// Worst relative differences of the projected values: mean2d relative to max(|uv|, image
/// size), conic to max(|a|, |c|), depth, opacity and colour to max(|x|, 1), and the conic's
/// relative difference divided by `1 + cond / 10` (`cond`: condition number of the 2D
/// covariance); panics on a culling difference. Returns (worst, radii that differ, visible).
fn compare_projections(
    what: &str,
    gpu: &[Projected<f32>],
    cpu: &[Projected<f32>],
    size: f32,
) -> ([f64; 6], usize, usize) {
    assert_eq!(gpu.len(), cpu.len());
    let mut worst = [0.0f64; 6];
    let (mut rad, mut visible) = (0, 0);
    for (i, (g, c)) in gpu.iter().zip(cpu).enumerate() {
        assert_eq!(
            g.radii == [0, 0],
            c.radii == [0, 0],
            "{what}: Gaussian {i} culled differently: {g:?} vs {c:?}"
        );
        if c.radii == [0, 0] {
            assert_eq!(
                *g,
                Projected::default(),
                "{what}: culled Gaussian {i} not zeroed"
            );
            continue;
        }
        visible += 1;
        rad += (g.radii != c.radii) as usize;
        let d = |a: f32, b: f32, s: f32| ((a - b).abs() / s) as f64;
        for a in 0..2 {
            worst[0] = worst[0].max(d(g.mean2d[a], c.mean2d[a], c.mean2d[a].abs().max(size)));
        }
        // The conic inverts a 2x2 covariance whose condition number reaches ~1e4 for the
        // needles of `aniso_near_bg`: f32 rounding differences (exp, fused multiply-adds) are
        // amplified by it, on either backend, so it scales the allowance.
        let cs = c.conic[0].abs().max(c.conic[2].abs());
        let [ca, cb, cc] = c.conic.map(|x| x as f64);
        let (half_tr, det) = ((ca + cc) / 2.0, ca * cc - cb * cb);
        let disc = (half_tr * half_tr - det).max(0.0).sqrt();
        let cond = (half_tr + disc) / (half_tr - disc).max(1e-30);
        for a in 0..3 {
            let e = d(g.conic[a], c.conic[a], cs);
            worst[1] = worst[1].max(e);
            worst[5] = worst[5].max(e / (1.0 + 0.1 * cond));
        }
        worst[2] = worst[2].max(d(g.depth, c.depth, c.depth.abs()));
        worst[3] = worst[3].max(d(g.opacity, c.opacity, c.opacity.abs().max(1.0)));
        for a in 0..3 {
            worst[4] = worst[4].max(d(g.color[a], c.color[a], c.color[a].abs().max(1.0)));
        }
    }
    (worst, rad, visible)
}

fn bins_of<B: SplatKernels>(b: &B, t: &TileBufs<B>) -> (Vec<u32>, Vec<u32>) {
    (b.download(&t.offsets).unwrap(), b.download(&t.ids).unwrap())
}

#[test]
#[cfg_attr(
    not(r4d_gpu),
    ignore = "no GPU adapter expected here (no Vulkan driver found at build time): install mesa-vulkan-drivers libvulkan1, or build with R4D_REQUIRE_GPU=1"
)]
fn projection_and_tile_lists_match_cpu() {
    let Some(ctx) = gpu("projection_and_tile_lists_match_cpu") else {
        return;
    };
    let gb = WgpuBackend::new(ctx);
    let cb = CpuBackend::default();
    for name in SCENES {
        let c = load(name);
        let s = settings(&c);
        let gs = scene_bufs(&gb, &c.scene, c.deform.as_ref());
        let cs = scene_bufs(&cb, &c.scene, c.deform.as_ref());
        for (k, cam) in c.cams.cameras.iter().enumerate() {
            let what = format!("{name}/cam{k}");
            let cc = CameraConsts::new(cam, &s, c.scene.sh_degree);
            let gp_buf = gb.project(&gs, &cc).unwrap();
            let gp = gb.download(&gp_buf).unwrap();
            let cp = cb.project(&cs, &cc).unwrap();
            let size = cam.width.max(cam.height) as f32;
            let (worst, rad, visible) = compare_projections(&what, &gp, &cp, size);
            println!(
                "{what}: {visible} visible, {rad} radii differ; worst relative: mean2d {:.2e}, \
                 conic {:.2e} ({:.2e} per condition), depth {:.2e}, opacity {:.2e}, colour {:.2e}",
                worst[0], worst[1], worst[5], worst[2], worst[3], worst[4]
            );
            assert_eq!(rad, 0, "{what}: radii differ");
            for (i, f) in [
                (0, "mean2d"),
                (5, "conic"),
                (2, "depth"),
                (3, "opacity"),
                (4, "colour"),
            ] {
                assert!(
                    worst[i] <= 1e-5,
                    "{what}: {f} differs by {:.3e} relative",
                    worst[i]
                );
            }
            // The same projection binned on both: identical lists.
            let cpu_bins = cb.bin_tiles(&cp, &cc).unwrap();
            let up = gb.upload(&cp).unwrap();
            let gpu_bins = gb.bin_tiles(&up, &cc).unwrap();
            assert_eq!(gpu_bins.intersections, cpu_bins.intersections, "{what}");
            let (go, gi) = bins_of(&gb, &gpu_bins);
            assert_eq!(go, cpu_bins.offsets, "{what}: offsets");
            assert_eq!(gi, cpu_bins.ids, "{what}: ids");
            // Each backend's own projection binned: identical for these scenes too.
            let gpu_own = gb.bin_tiles(&gp_buf, &cc).unwrap();
            let (go, gi) = bins_of(&gb, &gpu_own);
            assert_eq!(
                go, cpu_bins.offsets,
                "{what}: offsets of the GPU projection"
            );
            assert_eq!(gi, cpu_bins.ids, "{what}: ids of the GPU projection");
            println!(
                "{what}: {} intersections, tile lists identical",
                cpu_bins.intersections
            );
        }
    }
}

// ---- synthetic: large binning and compositing ------------------------------------------------

struct Lcg(u64);

impl Lcg {
    fn next(&mut self) -> f32 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((self.0 >> 40) as f32) / (1u64 << 24) as f32
    }
}

/// `n` projected Gaussians on a `w x h` image: sizes up to ~40 px, depths on 500 levels (many
/// exact ties), 10% culled, some centres off screen.
fn synthetic(n: usize, w: f32, h: f32, seed: u64) -> Vec<Projected<f32>> {
    let mut r = Lcg(seed);
    (0..n)
        .map(|_| {
            if r.next() < 0.1 {
                return Projected::default();
            }
            let sx = 0.3 + 12.0 * r.next() * r.next();
            let sy = 0.3 + 12.0 * r.next() * r.next();
            let rho = 1.6 * r.next() - 0.8;
            let (a, b, c) = (sx * sx + 0.3, rho * sx * sy, sy * sy + 0.3);
            let det = a * c - b * b;
            let u = (w + 60.0) * r.next() - 30.0;
            let v = (h + 60.0) * r.next() - 30.0;
            let color = [r.next(), r.next(), r.next()];
            Projected {
                mean2d: [u, v],
                conic: [c / det, -b / det, a / det],
                depth: 0.5 + (500.0 * r.next()).floor() * 0.01,
                opacity: 0.02 + 0.97 * r.next(),
                color,
                radii: [
                    (3.33 * a.sqrt()).ceil() as u32,
                    (3.33 * c.sqrt()).ceil() as u32,
                ],
            }
        })
        .collect()
}

#[test]
#[cfg_attr(
    not(r4d_gpu),
    ignore = "no GPU adapter expected here (no Vulkan driver found at build time): install mesa-vulkan-drivers libvulkan1, or build with R4D_REQUIRE_GPU=1"
)]
fn large_synthetic_binning_and_compositing_match_cpu() {
    let Some(ctx) = gpu("large_synthetic_binning_and_compositing_match_cpu") else {
        return;
    };
    let gb = WgpuBackend::new(ctx);
    let cb = CpuBackend::default();
    for (w, h, n, seed) in [
        (1920u32, 1080u32, 150_000usize, 1u64),
        (33, 17, 3000, 2),
        (16, 16, 1, 3),
    ] {
        let cam = Camera::look_at(w, h, 60.0, [0.0, -3.0, 0.0], [0.0; 3], [0.0, 0.0, 1.0]);
        let s = RenderSettings {
            background: [0.2, 0.4, 0.6],
            ..Default::default()
        };
        let cc = CameraConsts::new(&cam, &s, 0);
        let proj = synthetic(n, w as f32, h as f32, seed);
        let what = format!("synthetic {w}x{h} n={n}");
        let up = gb.upload(&proj).unwrap();
        // Twice: the second run is timed without the pipeline builds.
        drop(gb.bin_tiles(&up, &cc).unwrap());
        let t0 = std::time::Instant::now();
        let gpu_bins = gb.bin_tiles(&up, &cc).unwrap();
        let (go, gi) = bins_of(&gb, &gpu_bins);
        let t_bin = t0.elapsed();
        let cpu_bins = cb.bin_tiles(&proj, &cc).unwrap();
        assert_eq!(gpu_bins.intersections, cpu_bins.intersections, "{what}");
        assert_eq!(go, cpu_bins.offsets, "{what}: offsets");
        assert_eq!(gi, cpu_bins.ids, "{what}: ids");
        let longest = go.windows(2).map(|p| p[1] - p[0]).max().unwrap_or(0);
        let img = gb.rasterize(&up, &gpu_bins, &cc).unwrap();
        let cimg = cb.rasterize(&proj, &cpu_bins, &cc).unwrap();
        let rgb = gb.download(&img.rgb).unwrap();
        let alpha = gb.download(&img.alpha).unwrap();
        let depth = gb.download(&img.depth).unwrap();
        let e_rgb = image_rule(&format!("{what} rgb"), &rgb, &f64s(&cimg.rgb), None);
        let e_a = image_rule(&format!("{what} alpha"), &alpha, &f64s(&cimg.alpha), None);
        // Depth is in scene units here (0.5..5.5): compare relative to it.
        let rel: Vec<f64> = cimg
            .depth
            .iter()
            .map(|&d| d as f64 / d.max(1.0) as f64)
            .collect();
        let grel: Vec<f32> = depth
            .iter()
            .zip(&cimg.depth)
            .map(|(&g, &c)| g / c.max(1.0))
            .collect();
        let mask: Vec<bool> = cimg.alpha.iter().map(|&a| a > 1e-3).collect();
        let e_d = image_rule(&format!("{what} depth"), &grel, &rel, Some(&mask));
        println!(
            "{what}: {} intersections (longest tile list {longest}), identical tile lists \
             (GPU binning + readback {:.0} ms); rgb mean {:.2e} max {:.2e}, alpha max {:.2e}, \
             depth max {:.2e} vs cpu",
            cpu_bins.intersections,
            t_bin.as_secs_f64() * 1e3,
            e_rgb.0,
            e_rgb.2,
            e_a.2,
            e_d.2
        );
    }
}

/// `rasterize_vjp` alone against the CPU backend on the synthetic projections (tiles with
/// hundreds to thousands of Gaussians, so several batches of the back-to-front walk; every
/// 11th Gaussian nearly opaque, so alpha hits the 0.999 cap), per field of `ProjectedGrad`,
/// with both scatter variants.
#[test]
#[cfg_attr(
    not(r4d_gpu),
    ignore = "no GPU adapter expected here (no Vulkan driver found at build time): install mesa-vulkan-drivers libvulkan1, or build with R4D_REQUIRE_GPU=1"
)]
fn synthetic_rasterize_vjp_matches_cpu() {
    for float_atomics in [true, false] {
        let Some(ctx) = gpu_or_skip_with("synthetic_rasterize_vjp_matches_cpu", float_atomics)
        else {
            return;
        };
        let native = ctx.float_atomics;
        let gb = WgpuBackend::new(Arc::new(ctx));
        let cb = CpuBackend::default();
        for (w, h, n, seed) in [(320u32, 180u32, 20_000usize, 4u64), (33, 17, 3000, 5)] {
            let cam = Camera::look_at(w, h, 60.0, [0.0, -3.0, 0.0], [0.0; 3], [0.0, 0.0, 1.0]);
            let s = RenderSettings {
                background: [0.2, 0.4, 0.6],
                ..Default::default()
            };
            let cc = CameraConsts::new(&cam, &s, 0);
            let mut proj = synthetic(n, w as f32, h as f32, seed);
            for p in proj.iter_mut().step_by(11) {
                p.opacity = 0.9995;
            }
            let mut r = Lcg(seed + 100);
            let d_rgb: Vec<f32> = (0..w * h * 3).map(|_| 2.0 * r.next() - 1.0).collect();
            let what = format!("synthetic {w}x{h} n={n} (native atomics: {native})");
            let cpu_bins = cb.bin_tiles(&proj, &cc).unwrap();
            let cpu_img = cb.rasterize(&proj, &cpu_bins, &cc).unwrap();
            let mut want = cb.zeros(proj.len()).unwrap();
            cb.rasterize_vjp(&proj, &cpu_bins, &cc, Some(&cpu_img), &d_rgb, &mut want)
                .unwrap();
            let up = gb.upload(&proj).unwrap();
            let bins = gb.bin_tiles(&up, &cc).unwrap();
            let img = gb.rasterize(&up, &bins, &cc).unwrap();
            // The tapes agree: the same Gaussians end every pixel's compositing.
            let (cl, gl) = (&cpu_img.last, gb.download(&img.last).unwrap());
            let same = cl.iter().zip(&gl).filter(|(a, b)| a == b).count();
            assert!(
                same as f64 >= 0.999 * cl.len() as f64,
                "{what}: last position differs at {} of {} pixels",
                cl.len() - same,
                cl.len()
            );
            let d = gb.upload(&d_rgb).unwrap();
            let t0 = std::time::Instant::now();
            let mut acc = gb.zeros(proj.len()).unwrap();
            gb.rasterize_vjp(&up, &bins, &cc, Some(&img), &d, &mut acc)
                .unwrap();
            let got = gb.download(&acc).unwrap();
            let dt = t0.elapsed();
            let field = |v: &[r4d_splat::project::ProjectedGrad<f32>], f: usize| -> Vec<f64> {
                v.iter()
                    .flat_map(|g| match f {
                        0 => g.mean2d.to_vec(),
                        1 => g.conic.to_vec(),
                        2 => vec![g.opacity],
                        _ => g.color.to_vec(),
                    })
                    .map(|x| x as f64)
                    .collect()
            };
            let mut line = String::new();
            for (f, name) in ["mean2d", "conic", "opacity", "colour"].iter().enumerate() {
                let e = rel_l2(&field(&got, f), &field(&want, f));
                assert!(e <= 5e-3, "{what}: {name} relative L2 {e:.3e} > 5e-3");
                line += &format!(" {name} {e:.2e}");
            }
            println!(
                "{what}: {} intersections, rasterize_vjp {:.0} ms; rel L2 vs cpu:{line}",
                cpu_bins.intersections,
                dt.as_secs_f64() * 1e3
            );
        }
    }
}

/// A frame prepared once on the GPU (projected, sorted and binned for the whole image)
/// renders bands of rows (on tile rows or not) exactly as the whole image, and the bands'
/// VJPs summed into its projection gradient and pulled through the projection once give the
/// whole image's VJP (within 1e-3 relative L2: the float atomics add in another order, which
/// the needles of `aniso_near_bg` amplify to ~1e-4, as on the CPU), on every golden scene.
#[test]
#[cfg_attr(
    not(r4d_gpu),
    ignore = "no GPU adapter expected here (no Vulkan driver found at build time): install mesa-vulkan-drivers libvulkan1, or build with R4D_REQUIRE_GPU=1"
)]
fn prepared_frames_render_and_differentiate_bands_as_the_whole_image() {
    let Some(ctx) = gpu("prepared_frames_render_and_differentiate_bands_as_the_whole_image") else {
        return;
    };
    let mut r = SplatRenderer::new(WgpuBackend::new(ctx));
    for name in SCENES {
        let c = load(name);
        let s = settings(&c);
        for (k, cam) in c.cams.cameras.iter().enumerate() {
            let what = format!("{name}/cam{k}");
            let (w, h) = (cam.width as usize, cam.height);
            let whole = r.render(&c.scene, c.deform.as_ref(), cam, &s).unwrap();
            let d_rgb: Vec<f32> = read_npy(&c.dir.join(format!("cam{k}_loss_weights.npy")))
                .data
                .iter()
                .map(|&x| x as f32)
                .collect();
            let g = r
                .render_vjp(&c.scene, c.deform.as_ref(), cam, &s, &d_rgb)
                .unwrap();
            let cuts = [0, 16.min(h), (h / 2) | 1, h];
            let mut frame = r
                .prepare_frame(&c.scene, c.deform.as_ref(), cam, &s)
                .unwrap();
            for b in cuts.windows(2).filter(|b| b[0] < b[1]) {
                let (r0, r1) = (b[0] as usize, b[1] as usize);
                let img = r.render_rows(&frame, b[0]..b[1]).unwrap();
                assert_eq!(img.rgb, whole.rgb[r0 * w * 3..r1 * w * 3], "{what} {b:?}");
                assert_eq!(img.alpha, whole.alpha[r0 * w..r1 * w], "{what} {b:?}");
                r.render_rows_vjp(&mut frame, b[0]..b[1], &d_rgb[r0 * w * 3..r1 * w * 3])
                    .unwrap();
            }
            let gb = r.frame_vjp(frame, &c.scene, c.deform.as_ref()).unwrap();
            let mut worst = 0.0f64;
            for ((a, got), (_, want)) in grad_arrays(&gb, c.deform.is_some())
                .iter()
                .zip(&grad_arrays(&g, c.deform.is_some()))
            {
                let e = rel_l2(got, want);
                assert!(e <= 1e-3, "{what} {a}: relative L2 {e:.3e} > 1e-3");
                worst = worst.max(e);
            }
            println!("{what}: bands vs whole image, worst gradient rel L2 {worst:.2e}");
        }
    }
}

#[test]
#[cfg_attr(
    not(r4d_gpu),
    ignore = "no GPU adapter expected here (no Vulkan driver found at build time): install mesa-vulkan-drivers libvulkan1, or build with R4D_REQUIRE_GPU=1"
)]
fn empty_renders_are_background_with_zero_gradients() {
    let Some(ctx) = gpu("empty_renders_are_background_with_zero_gradients") else {
        return;
    };
    let mut r = SplatRenderer::new(WgpuBackend::new(ctx));
    let cam = Camera::look_at(40, 24, 60.0, [0.0, -3.0, 0.0], [0.0; 3], [0.0, 0.0, 1.0]);
    let s = RenderSettings {
        background: [0.1, 0.2, 0.3],
        ..Default::default()
    };
    // One Gaussian behind the camera, and no Gaussians at all.
    let behind = Gaussians {
        sh_degree: 0,
        means: vec![[0.0, -10.0, 0.0]],
        log_scales: vec![[-1.0; 3]],
        quats: vec![[1.0, 0.0, 0.0, 0.0]],
        opacity_logits: vec![3.0],
        sh: vec![1.0, 0.0, 0.0],
    };
    let none = Gaussians {
        sh_degree: 0,
        ..Default::default()
    };
    for g in [behind, none] {
        let img = r.render(&g, None, &cam, &s).unwrap();
        assert_eq!(r.stats.intersections, 0);
        for px in img.rgb.chunks(3) {
            assert_eq!(px, &[0.1, 0.2, 0.3]);
        }
        assert!(img.alpha.iter().all(|&a| a == 0.0));
        assert!(img.depth.iter().all(|&d| d == 0.0));
        // Nothing visible: every gradient is 0.
        let d_rgb = vec![1.0f32; img.rgb.len()];
        let gr = r.render_vjp(&g, None, &cam, &s, &d_rgb).unwrap();
        assert_eq!(gr.means.len(), g.len());
        assert_eq!(gr.sh.len(), g.sh.len());
        for (name, a) in grad_arrays(&gr, false) {
            assert!(a.iter().all(|&x| x == 0.0), "{name} of an invisible scene");
        }
    }
}

// ---- layouts --------------------------------------------------------------------------------

#[test]
fn wgsl_splat_structs_match_the_rust_layouts() {
    use std::mem::{offset_of, size_of};
    let find = |name: &str| {
        r4d_backend_wgpu::shaders::LAYOUTS
            .iter()
            .find(|l| l.0 == name)
            .unwrap_or_else(|| panic!("WGSL struct {name} not reflected"))
    };
    let check = |name: &str, size: usize, fields: &[(&str, usize)]| {
        let l = find(name);
        assert_eq!(l.1 as usize, size, "{name}: size");
        for (f, off) in fields {
            let m =
                l.2.iter()
                    .find(|m| m.0 == *f)
                    .unwrap_or_else(|| panic!("{name}.{f}"));
            assert_eq!(m.1 as usize, *off, "{name}.{f}: offset");
        }
    };
    check(
        "CameraConsts",
        size_of::<CameraConsts>(),
        &[
            ("rot0", offset_of!(CameraConsts, rot)),
            ("rot1", offset_of!(CameraConsts, rot) + 16),
            ("rot2", offset_of!(CameraConsts, rot) + 32),
            ("trans", offset_of!(CameraConsts, trans)),
            ("campos", offset_of!(CameraConsts, campos)),
            ("background", offset_of!(CameraConsts, background)),
            ("intrinsics", offset_of!(CameraConsts, intrinsics)),
            ("near_far", offset_of!(CameraConsts, near_far)),
            ("size", offset_of!(CameraConsts, size)),
            ("tiles", offset_of!(CameraConsts, tiles)),
            ("antialiased", offset_of!(CameraConsts, antialiased)),
            ("sh_degree", offset_of!(CameraConsts, sh_degree)),
            ("lims", offset_of!(CameraConsts, lims)),
            ("rows", offset_of!(CameraConsts, rows)),
        ],
    );
    type P = Projected<f32>;
    check(
        "Projected",
        size_of::<P>(),
        &[
            ("mean_x", offset_of!(P, mean2d)),
            ("mean_y", offset_of!(P, mean2d) + 4),
            ("conic_a", offset_of!(P, conic)),
            ("conic_b", offset_of!(P, conic) + 4),
            ("conic_c", offset_of!(P, conic) + 8),
            ("depth", offset_of!(P, depth)),
            ("opacity", offset_of!(P, opacity)),
            ("color_r", offset_of!(P, color)),
            ("color_g", offset_of!(P, color) + 4),
            ("color_b", offset_of!(P, color) + 8),
            ("radius_x", offset_of!(P, radii)),
            ("radius_y", offset_of!(P, radii) + 4),
        ],
    );
    type G = r4d_splat::project::ProjectedGrad<f32>;
    check(
        "ProjectedGrad",
        size_of::<G>(),
        &[
            ("mean_x", offset_of!(G, mean2d)),
            ("mean_y", offset_of!(G, mean2d) + 4),
            ("conic_a", offset_of!(G, conic)),
            ("conic_b", offset_of!(G, conic) + 4),
            ("conic_c", offset_of!(G, conic) + 8),
            ("opacity", offset_of!(G, opacity)),
            ("color_r", offset_of!(G, color)),
            ("color_g", offset_of!(G, color) + 4),
            ("color_b", offset_of!(G, color) + 8),
        ],
    );
    type S = r4d_gpu::SplatProjectParams;
    check(
        "SplatProjectParams",
        size_of::<S>(),
        &[
            ("n", offset_of!(S, n)),
            ("has_f", offset_of!(S, has_f)),
            ("sh_degree", offset_of!(S, sh_degree)),
            ("sh_len", offset_of!(S, sh_len)),
        ],
    );
    check("SplatTileKey", 12, &[("tile", 0), ("depth", 4), ("id", 8)]);
}
