//! Finite-difference checks of every gradient of the reference renderer in f64, and unit
//! checks of the polar decomposition.

use crate::camera::{Camera, RasterizeMode, RenderSettings};
use crate::project::CamParams;
use crate::real::*;
use crate::reference::{render, render_vjp, Scene};

/// Small deterministic generator (tests only).
struct Lcg(u64);
impl Lcg {
    fn next(&mut self) -> f64 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (self.0 >> 11) as f64 / (1u64 << 53) as f64
    }
    fn range(&mut self, a: f64, b: f64) -> f64 {
        a + (b - a) * self.next()
    }
}

fn scene(n: usize, degree: u32, deformed: bool, seed: u64) -> Scene<f64> {
    let mut r = Lcg(seed);
    let k = ((degree + 1) * (degree + 1)) as usize;
    let mut s = Scene::<f64> {
        sh_degree: degree,
        ..Default::default()
    };
    for _ in 0..n {
        s.means
            .push([r.range(-0.6, 0.6), r.range(-0.6, 0.6), r.range(-0.4, 0.4)]);
        s.log_scales.push([
            r.range(-2.6, -1.6),
            r.range(-2.6, -1.6),
            r.range(-2.6, -1.6),
        ]);
        s.quats.push([
            r.range(-1.0, 1.0),
            r.range(-1.0, 1.0),
            r.range(-1.0, 1.0),
            r.range(0.2, 1.0),
        ]);
        s.opacity_logits.push(r.range(-1.5, 0.5));
        for _ in 0..k * 3 {
            s.sh.push(r.range(-0.4, 0.4));
        }
    }
    if deformed {
        s.f = Some(
            (0..n)
                .map(|_| {
                    let mut m = eye3::<f64>();
                    for row in m.iter_mut() {
                        for v in row.iter_mut() {
                            *v += r.range(-0.35, 0.35);
                        }
                    }
                    m
                })
                .collect(),
        );
    }
    s
}

fn camera() -> Camera {
    let mut c = Camera::look_at(40, 30, 50.0, [0.3, -3.0, 0.8], [0.0; 3], [0.0, 0.0, 1.0]);
    c.cx = 21.3; // off-centre principal point
    c.fy = c.fx * 1.1;
    c
}

fn loss(s: &Scene<f64>, cam: &Camera, set: &RenderSettings, w: &[f64]) -> f64 {
    let (img, _) = render(s, cam, set);
    img.rgb.iter().zip(w).map(|(a, b)| a * b).sum()
}

/// Central differences of every parameter of a few Gaussians against the VJP.
fn fd_check(deformed: bool, mode: RasterizeMode, degree: u32) {
    let cam = camera();
    let set = RenderSettings {
        background: [0.2, 0.5, 0.9],
        mode,
    };
    let s = scene(24, degree, deformed, 7 + degree as u64);
    let mut r = Lcg(99);
    let w: Vec<f64> = (0..cam.width * cam.height * 3)
        .map(|_| r.range(-1.0, 1.0))
        .collect();
    let g = render_vjp(&s, &cam, &set, &w);
    let h = 1e-6;
    let k = ((degree + 1) * (degree + 1)) as usize * 3;
    let mut worst = 0.0f64;
    let mut checked = 0;
    let mut significant = 0;
    let mut check = |label: String, an: f64, perturb: &dyn Fn(&mut Scene<f64>, f64)| {
        let mut p = s.clone();
        perturb(&mut p, h);
        let lp = loss(&p, &cam, &set, &w);
        let mut m = s.clone();
        perturb(&mut m, -h);
        let lm = loss(&m, &cam, &set, &w);
        let fd = (lp - lm) / (2.0 * h);
        let err = (fd - an).abs() / (an.abs().max(fd.abs()).max(1e-3));
        assert!(err < 1e-4, "{label}: analytic {an:.8e} vs FD {fd:.8e}");
        worst = worst.max(err);
        checked += 1;
        significant += (an.abs() > 1e-3) as usize;
    };
    for i in [0usize, 5, 11, 17] {
        for a in 0..3 {
            check(format!("mean[{i}][{a}]"), g.means[i][a], &|p, d| {
                p.means[i][a] += d
            });
            check(
                format!("log_scale[{i}][{a}]"),
                g.log_scales[i][a],
                &|p, d| p.log_scales[i][a] += d,
            );
        }
        for a in 0..4 {
            check(format!("quat[{i}][{a}]"), g.quats[i][a], &|p, d| {
                p.quats[i][a] += d
            });
        }
        check(format!("opacity[{i}]"), g.opacity_logits[i], &|p, d| {
            p.opacity_logits[i] += d
        });
        for j in [0, k / 2, k - 1] {
            check(format!("sh[{i}][{j}]"), g.sh[i * k + j], &|p, d| {
                p.sh[i * k + j] += d
            });
        }
        if deformed {
            for a in 0..3 {
                for b in 0..3 {
                    check(format!("F[{i}][{a}][{b}]"), g.f[i][a][b], &|p, d| {
                        p.f.as_mut().unwrap()[i][a][b] += d
                    });
                }
            }
        }
    }
    // The check must not pass on zeros: most entries carry a real gradient.
    assert!(
        checked > 50 && significant * 4 > checked * 3,
        "{significant} of {checked}"
    );
    println!("FD check ({deformed}, {mode:?}, degree {degree}): {checked} entries, worst rel {worst:.2e}");
}

#[test]
fn every_gradient_matches_finite_differences_in_f64() {
    fd_check(false, RasterizeMode::Classic, 3);
    fd_check(false, RasterizeMode::Antialiased, 2);
}

#[test]
fn deformation_gradient_matches_finite_differences_in_f64() {
    fd_check(true, RasterizeMode::Classic, 3);
    fd_check(true, RasterizeMode::Antialiased, 1);
}

/// A camera cropped to bands of rows (on tile rows or not) renders exactly the full image's
/// rows (its projection and tiles are the full image's), and the band VJPs add up to the full
/// image's VJP.
#[test]
fn row_bands_render_the_full_images_rows_and_their_vjps_add_up() {
    let mut cam = Camera::look_at(40, 64, 50.0, [0.3, -3.0, 0.8], [0.0; 3], [0.0, 0.0, 1.0]);
    cam.cy = 29.7;
    for mode in [RasterizeMode::Classic, RasterizeMode::Antialiased] {
        let set = RenderSettings {
            background: [0.2, 0.5, 0.9],
            mode,
        };
        // Large Gaussians too, so that some cross band borders and some lie beyond the
        // frustum clamp of a band (but not of the full image).
        let mut s = scene(40, 2, true, 5);
        for (i, ls) in s.log_scales.iter_mut().enumerate().take(6) {
            *ls = [-0.9 - 0.1 * i as f64; 3];
        }
        let (full, _) = render(&s, &cam, &set);
        let mut r = Lcg(3);
        let w: Vec<f64> = (0..cam.width * cam.height * 3)
            .map(|_| r.range(-1.0, 1.0))
            .collect();
        let g_full = render_vjp(&s, &cam, &set, &w);
        let row = (cam.width * 3) as usize;
        let mut g_sum: Option<crate::reference::SceneGrad<f64>> = None;
        for band in [0u32..16, 16..37, 37..64] {
            let c = cam.crop_rows(band.clone());
            assert_eq!(
                CamParams::<f64>::new(&c, mode).lims,
                CamParams::<f64>::new(&cam, mode).lims
            );
            let (img, _) = render(&s, &c, &set);
            let rows = band.start as usize * row..band.end as usize * row;
            let worst = img
                .rgb
                .iter()
                .zip(&full.rgb[rows.clone()])
                .map(|(a, b)| (a - b).abs())
                .fold(0.0f64, f64::max);
            // The same arithmetic as the full image's pixels.
            assert!(
                worst == 0.0,
                "{mode:?} rows {band:?}: max difference {worst:e}"
            );
            let g = render_vjp(&s, &c, &set, &w[rows]);
            match &mut g_sum {
                None => g_sum = Some(g),
                Some(acc) => {
                    for (a, b) in acc.means.iter_mut().zip(&g.means) {
                        (0..3).for_each(|k| a[k] += b[k]);
                    }
                    for (a, b) in acc.log_scales.iter_mut().zip(&g.log_scales) {
                        (0..3).for_each(|k| a[k] += b[k]);
                    }
                    for (a, b) in acc.opacity_logits.iter_mut().zip(&g.opacity_logits) {
                        *a += b;
                    }
                }
            }
        }
        let g_sum = g_sum.unwrap();
        let close = |a: &[f64], b: &[f64]| {
            let num: f64 = a.iter().zip(b).map(|(x, y)| (x - y).powi(2)).sum();
            let den: f64 = b.iter().map(|y| y * y).sum();
            assert!(
                den > 0.0 && (num / den).sqrt() < 1e-12,
                "{mode:?}: {}",
                (num / den).sqrt()
            );
        };
        close(&g_sum.means.concat(), &g_full.means.concat());
        close(&g_sum.log_scales.concat(), &g_full.log_scales.concat());
        close(&g_sum.opacity_logits, &g_full.opacity_logits);
    }
}

#[test]
fn a_crop_beyond_the_image_is_refused() {
    let cam = camera();
    let mut c = cam.crop_rows(16..30);
    assert!(c.validate("t").is_ok());
    c.height = 20;
    assert!(c.validate("t").unwrap_err().contains("crop rows"));
}

/// A render's tape gives the VJP without projecting, binning or compositing again, and the
/// one-call VJP's gradients up to the transmittance's rounding (recovered by division there,
/// tracked forward here); a wrong-sized dL/drgb is refused.
#[test]
fn the_taped_vjp_equals_the_one_call_vjp() {
    use crate::gaussians::{Deformation, Gaussians};
    use crate::reference::ReferenceSplat;
    use crate::{Renderer, SplatRenderer};
    let cam = Camera::look_at(40, 24, 50.0, [0.3, -3.0, 0.8], [0.0; 3], [0.0, 0.0, 1.0]);
    let set = RenderSettings {
        background: [0.2, 0.5, 0.9],
        ..Default::default()
    };
    let s = scene(60, 1, true, 9);
    let f32v = |v: &[f64]| v.iter().map(|&x| x as f32).collect::<Vec<f32>>();
    let g = Gaussians {
        means: s.means.iter().map(|m| m.map(|x| x as f32)).collect(),
        log_scales: s.log_scales.iter().map(|m| m.map(|x| x as f32)).collect(),
        quats: s.quats.iter().map(|m| m.map(|x| x as f32)).collect(),
        opacity_logits: f32v(&s.opacity_logits),
        sh: f32v(&s.sh),
        sh_degree: s.sh_degree,
    };
    let d = Deformation {
        means: g.means.clone(),
        f: s.f
            .as_ref()
            .unwrap()
            .iter()
            .map(|m| m.map(|r| r.map(|x| x as f32)))
            .collect(),
    };
    let mut r = Lcg(4);
    let w: Vec<f32> = (0..cam.width * cam.height * 3)
        .map(|_| r.range(-1.0, 1.0) as f32)
        .collect();
    let mut ren = SplatRenderer::new(ReferenceSplat);
    let one = ren.render_vjp(&g, Some(&d), &cam, &set, &w).unwrap();
    let (img, tape) = ren.render_taped(&g, Some(&d), &cam, &set).unwrap();
    assert_eq!(img, ren.render(&g, Some(&d), &cam, &set).unwrap());
    assert_eq!(tape.size(), (40, 24));
    let taped = ren.render_vjp_taped(tape, &w).unwrap();
    let flat = |g: &crate::GaussianGrads| -> Vec<f32> {
        let mut v: Vec<f32> = g.means.iter().flatten().copied().collect();
        v.extend(g.log_scales.iter().flatten());
        v.extend(g.quats.iter().flatten());
        v.extend(&g.opacity_logits);
        v.extend(&g.sh);
        v.extend(g.f.iter().flatten().flatten());
        v
    };
    let (a, b) = (flat(&one), flat(&taped));
    assert_eq!(a.len(), b.len());
    let scale = a.iter().fold(0f32, |m, x| m.max(x.abs()));
    let worst = a
        .iter()
        .zip(&b)
        .fold(0f32, |m, (x, y)| m.max((x - y).abs()));
    assert!(
        scale > 0.0 && worst <= 1e-4 * scale,
        "worst {worst} of {scale}"
    );
    let (_, tape) = ren.render_taped(&g, Some(&d), &cam, &set).unwrap();
    let e = ren.render_vjp_taped(tape, &w[1..]).unwrap_err();
    assert!(e.to_string().contains("40x24"), "{e}");
}

/// A frame prepared once ([`crate::Renderer::prepare_frame`]: projected, sorted and binned for
/// the whole image) renders any rows exactly as the whole image and as a camera cropped to
/// them, and the bands' VJPs, summed into the frame's projection gradient and pulled through
/// the projection once ([`crate::Renderer::frame_vjp`]), give the whole image's VJP: the same
/// numbers for bands on tile rows (the same order of sums), within f32 rounding otherwise.
#[test]
fn a_prepared_frame_renders_and_differentiates_bands_as_the_whole_image() {
    use crate::gaussians::{Deformation, GaussianGrads, Gaussians};
    use crate::reference::ReferenceSplat;
    use crate::{Renderer, SplatRenderer};
    let mut cam = Camera::look_at(40, 64, 50.0, [0.3, -3.0, 0.8], [0.0; 3], [0.0, 0.0, 1.0]);
    cam.cy = 29.7;
    let set = RenderSettings {
        background: [0.2, 0.5, 0.9],
        mode: RasterizeMode::Antialiased,
    };
    let mut s = scene(60, 2, true, 11);
    for (i, ls) in s.log_scales.iter_mut().enumerate().take(6) {
        *ls = [-0.9 - 0.1 * i as f64; 3];
    }
    let f32v = |v: &[f64]| v.iter().map(|&x| x as f32).collect::<Vec<f32>>();
    let g = Gaussians {
        means: s.means.iter().map(|m| m.map(|x| x as f32)).collect(),
        log_scales: s.log_scales.iter().map(|m| m.map(|x| x as f32)).collect(),
        quats: s.quats.iter().map(|m| m.map(|x| x as f32)).collect(),
        opacity_logits: f32v(&s.opacity_logits),
        sh: f32v(&s.sh),
        sh_degree: s.sh_degree,
    };
    let d = Deformation {
        means: g.means.iter().map(|m| [m[0] + 0.02, m[1], m[2]]).collect(),
        f: s.f
            .as_ref()
            .unwrap()
            .iter()
            .map(|m| m.map(|r| r.map(|x| x as f32)))
            .collect(),
    };
    let mut r = Lcg(5);
    let w: Vec<f32> = (0..cam.width * cam.height * 3)
        .map(|_| r.range(-1.0, 1.0) as f32)
        .collect();
    let mut ren = SplatRenderer::new(ReferenceSplat);
    let whole = ren.render(&g, Some(&d), &cam, &set).unwrap();
    let g_whole = ren.render_vjp(&g, Some(&d), &cam, &set, &w).unwrap();
    let flat = |g: &GaussianGrads| -> Vec<f32> {
        let mut v: Vec<f32> = g.means.iter().flatten().copied().collect();
        v.extend(g.log_scales.iter().flatten());
        v.extend(g.quats.iter().flatten());
        v.extend(&g.opacity_logits);
        v.extend(&g.sh);
        v.extend(g.f.iter().flatten().flatten());
        v
    };
    let row = (cam.width * 3) as usize;
    let px = cam.width as usize;
    for bands in [
        vec![0u32..16, 16..48, 48..64],
        vec![0u32..21, 21..37, 37..40, 40..64],
    ] {
        // The frame of a cropped camera is the full image's.
        let mut frame = ren
            .prepare_frame(&g, Some(&d), &cam.crop_rows(16..32), &set)
            .unwrap();
        assert_eq!(frame.size(), (40, 64));
        for b in &bands {
            let img = ren.render_rows(&frame, b.clone()).unwrap();
            let (r0, r1) = (b.start as usize, b.end as usize);
            assert_eq!((img.width, img.height), (40, b.len() as u32));
            assert_eq!(img.rgb, whole.rgb[r0 * row..r1 * row], "rows {b:?}");
            assert_eq!(img.alpha, whole.alpha[r0 * px..r1 * px], "rows {b:?}");
            assert_eq!(img.depth, whole.depth[r0 * px..r1 * px], "rows {b:?}");
            let cropped = ren
                .render(&g, Some(&d), &cam.crop_rows(b.clone()), &set)
                .unwrap();
            assert_eq!(cropped, img, "rows {b:?}");
            ren.render_rows_vjp(&mut frame, b.clone(), &w[r0 * row..r1 * row])
                .unwrap();
        }
        let g_bands = ren.frame_vjp(frame, &g, Some(&d)).unwrap();
        let (a, b) = (flat(&g_bands), flat(&g_whole));
        assert_eq!(a.len(), b.len());
        if bands[1].start % 16 == 0 {
            assert_eq!(a, b, "bands {bands:?}");
        } else {
            let scale = b.iter().fold(0f32, |m, x| m.max(x.abs()));
            let worst = a
                .iter()
                .zip(&b)
                .fold(0f32, |m, (x, y)| m.max((x - y).abs()));
            assert!(
                scale > 0.0 && worst <= 1e-5 * scale,
                "bands {bands:?}: worst {worst} of {scale}"
            );
        }
    }
    // A frame without any band VJP gives zero gradients; wrong rows, a wrong-sized dL/drgb
    // and another scene are refused.
    let mut frame = ren.prepare_frame(&g, Some(&d), &cam, &set).unwrap();
    assert!(ren.render_rows(&frame, 60..65).is_err());
    assert!(ren.render_rows(&frame, 8..8).is_err());
    let e = ren
        .render_rows_vjp(&mut frame, 0..16, &w[..row * 15])
        .unwrap_err();
    assert!(e.to_string().contains("rows 0..16"), "{e}");
    assert!(ren.frame_vjp(frame, &g, None).is_err());
    let frame = ren.prepare_frame(&g, Some(&d), &cam, &set).unwrap();
    let zero = ren.frame_vjp(frame, &g, Some(&d)).unwrap();
    assert!(flat(&zero).iter().all(|&x| x == 0.0));
}

/// A row of a tile composited at once ([`crate::span::composite_span`], and its AVX2 f32
/// instance) gives bitwise [`crate::raster::composite_pixel`] of each pixel, traces included,
/// with pixels left out, capped alphas, early stops and Gaussians no pixel of the row touches.
#[test]
fn a_span_composites_bitwise_as_pixel_by_pixel() {
    use crate::project::Projected;
    use crate::raster::{composite_pixel, Contribution, PixelOut, TileSplats};
    use crate::span::{composite_span, composite_span_f32, SPAN};
    type Run<T> = fn(
        u32,
        u32,
        &[bool],
        &TileSplats<T>,
        &[T; 3],
        &mut [(PixelOut<T>, T); SPAN],
        Option<&mut [Vec<Contribution<T>>; SPAN]>,
    );
    fn check<T: Real>(seed: u64, run: Run<T>) {
        let mut r = Lcg(seed);
        let proj: Vec<Projected<T>> = (0..400)
            .map(|i| {
                let a = r.range(0.01, 0.6);
                let cc = r.range(0.01, 0.6);
                let b = r.range(-0.9, 0.9) * (a * cc).sqrt();
                Projected {
                    mean2d: [T::c(r.range(-6.0, 40.0)), T::c(r.range(-6.0, 22.0))],
                    conic: [T::c(a), T::c(b), T::c(cc)],
                    depth: T::c(r.range(1.0, 5.0)),
                    opacity: T::c(if i % 9 == 0 {
                        0.9995
                    } else {
                        r.range(0.05, 0.99)
                    }),
                    color: [T::c(r.next()), T::c(r.next()), T::c(r.next())],
                    radii: [3, 3],
                }
            })
            .collect();
        let ids: Vec<u32> = (0..proj.len() as u32).collect();
        let mut tile = TileSplats::default();
        tile.gather(&ids, &proj);
        let bg = [T::c(0.2), T::c(0.5), T::c(0.9)];
        for (i0, j) in [(16u32, 3u32), (0, 9), (16, 15)] {
            let live: Vec<bool> = (0..13).map(|l| l != 4).collect();
            let mut out = [(PixelOut::<T>::default(), T::zero()); SPAN];
            let mut traces: [Vec<Contribution<T>>; SPAN] = std::array::from_fn(|_| Vec::new());
            run(i0, j, &live, &tile, &bg, &mut out, Some(&mut traces));
            let mut stopped = 0;
            for (l, &on) in live.iter().enumerate() {
                if !on {
                    assert_eq!(out[l], (PixelOut::default(), T::zero()));
                    continue;
                }
                let mut trace = Vec::new();
                let want = composite_pixel(i0 + l as u32, j, &tile, &bg, Some(&mut trace));
                assert_eq!(out[l], want, "pixel ({}, {j})", i0 + l as u32);
                assert_eq!(traces[l].len(), trace.len());
                for (a, b) in traces[l].iter().zip(&trace) {
                    assert_eq!(
                        (a.k, a.alpha, a.t, a.g, a.d, a.capped),
                        (b.k, b.alpha, b.t, b.g, b.d, b.capped)
                    );
                }
                stopped += ((want.0.last as usize) < tile.len()) as usize;
            }
            assert!(stopped > 0, "some pixel stops early");
        }
    }
    for seed in 0..4 {
        check::<f32>(seed, composite_span::<f32>);
        check::<f32>(seed, composite_span_f32);
        check::<f64>(seed, composite_span::<f64>);
    }
}
