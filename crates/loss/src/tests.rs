//! Finite-difference checks of every term's gradient (f64, random small videos), the
//! near-zero-spectrum behaviour of the phase term, and the typed errors.

use crate::ssim::{Padding, SsimConfig};
use crate::*;

/// splitmix64 in [0, 1).
pub(crate) struct Rng(pub(crate) u64);
impl Rng {
    pub(crate) fn next(&mut self) -> f64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64
    }
}

fn random_video(seed: u64, t: usize, h: usize, w: usize) -> Video<f64> {
    let mut r = Rng(seed);
    let data = (0..t * h * w * 3).map(|_| r.next()).collect();
    Video::new(t, h, w, data).unwrap()
}

/// A smooth pattern moving by `speed` px per frame, plus a little noise.
fn moving_video(seed: u64, t: usize, h: usize, w: usize, speed: f64) -> Video<f64> {
    let mut r = Rng(seed);
    let mut v = Video::zeros(t, h, w);
    for f in 0..t {
        for y in 0..h {
            for x in 0..w {
                for c in 0..3 {
                    let u = (x as f64 - speed * f as f64) * 0.4 + c as f64;
                    let val = 0.5 + 0.3 * (u.sin() * (y as f64 * 0.3).cos()) + 0.02 * r.next();
                    v.data_mut()[((f * h + y) * w + x) * 3 + c] = val;
                }
            }
        }
    }
    v
}

fn weights(l1: f64, spatial: f64, mag: f64, phase: f64) -> DmsWeights {
    DmsWeights {
        l1,
        spatial,
        mag,
        phase,
    }
}

/// Central difference of the loss along a random direction against `<grad, v>`; returns
/// the relative error.
fn fd_check(loss: &Dms<f64>, x: &Video<f64>, seed: u64) -> f64 {
    let (value, grad) = loss.value_and_grad(x).unwrap();
    assert!(value.is_finite());
    let mut r = Rng(seed);
    let v: Vec<f64> = (0..x.data().len()).map(|_| r.next() - 0.5).collect();
    let h = 1e-6;
    let shifted = |s: f64| {
        let mut y = x.clone();
        for (a, d) in y.data_mut().iter_mut().zip(&v) {
            *a += s * d;
        }
        loss.value(&y).unwrap()
    };
    let fd = (shifted(h) - shifted(-h)) / (2.0 * h);
    let an: f64 = grad.data().iter().zip(&v).map(|(g, d)| g * d).sum();
    let rel = (fd - an).abs() / an.abs().max(1e-300);
    assert!(
        rel < 1e-6,
        "finite difference {fd:.12e} vs analytic {an:.12e} (rel {rel:.2e})"
    );
    rel
}

fn dms(reference: Video<f64>, f: impl FnOnce(&mut DmsConfig)) -> Dms<f64> {
    let mut c = DmsConfig::default();
    f(&mut c);
    Dms::new(reference, c).unwrap()
}

#[test]
fn spatial_gradient_matches_finite_differences() {
    let (x, y) = (random_video(1, 3, 21, 26), random_video(2, 3, 21, 26));
    for (padding, gray) in [
        (Padding::Valid, false),
        (Padding::Same, false),
        (Padding::Valid, true),
    ] {
        let loss = dms(y.clone(), |c| {
            c.weights = weights(0.0, 1.0, 0.0, 0.0);
            c.spatial = SsimConfig {
                padding,
                gray,
                ..Default::default()
            };
        });
        let rel = fd_check(&loss, &x, 7);
        println!("spatial {padding:?} gray={gray}: rel {rel:.1e}");
    }
}

#[test]
fn spatial_gradient_of_column_tiles_matches_finite_differences() {
    // 300 px wide frames are processed in three column tiles (128 px in f64).
    let (x, y) = (random_video(21, 2, 14, 300), random_video(22, 2, 14, 300));
    for padding in [Padding::Valid, Padding::Same] {
        let loss = dms(y.clone(), |c| {
            c.weights = weights(0.0, 1.0, 0.0, 0.0);
            c.spatial.padding = padding;
        });
        fd_check(&loss, &x, 23);
        // The value against direct 2-D sums.
        let v = loss.value(&x).unwrap();
        let direct = untiled_ssim(&x, &y, padding);
        assert!(
            (v - (1.0 - direct)).abs() < 1e-13,
            "{v} vs {}",
            1.0 - direct
        );
    }
}

/// SSIM by direct 2-D sums (no tiles, no rings), for checking the streaming code.
fn untiled_ssim(x: &Video<f64>, y: &Video<f64>, padding: Padding) -> f64 {
    let g: Vec<f64> = ssim::GAUSS_11.iter().map(|&v| v as f64).collect();
    let pad = if padding == Padding::Same { 5i64 } else { 0 };
    let (h, w) = (x.height() as i64, x.width() as i64);
    let (ho, wo) = (h + 2 * pad - 10, w + 2 * pad - 10);
    let mut total = 0.0;
    for t in 0..x.frames() {
        for c in 0..3 {
            for i in 0..ho {
                for j in 0..wo {
                    let mut s = [0.0; 5];
                    for a in 0..11 {
                        for b in 0..11 {
                            let (r, q) = (i + a - pad, j + b - pad);
                            if r < 0 || q < 0 || r >= h || q >= w {
                                continue;
                            }
                            let wgt = if padding == Padding::Same {
                                (ssim::GAUSS_11[a as usize] * ssim::GAUSS_11[b as usize]) as f64
                            } else {
                                g[a as usize] * g[b as usize]
                            };
                            let xv = x.at(t, r as usize, q as usize, c);
                            let yv = y.at(t, r as usize, q as usize, c);
                            s[0] += wgt * xv;
                            s[1] += wgt * yv;
                            s[2] += wgt * xv * xv;
                            s[3] += wgt * yv * yv;
                            s[4] += wgt * xv * yv;
                        }
                    }
                    let (mx, my) = (s[0], s[1]);
                    let l = (2.0 * mx * my + 1e-4) / (mx * mx + my * my + 1e-4);
                    let cs = (2.0 * (s[4] - mx * my) + 9e-4)
                        / ((s[2] - mx * mx) + (s[3] - my * my) + 9e-4);
                    total += l * cs;
                }
            }
        }
    }
    total / (x.frames() * 3) as f64 / (ho * wo) as f64
}

#[test]
fn l1_gradient_matches_finite_differences() {
    let (x, y) = (random_video(3, 2, 8, 8), random_video(4, 2, 8, 8));
    let loss = dms(y, |c| c.weights = weights(1.0, 0.0, 0.0, 0.0));
    fd_check(&loss, &x, 9);
}

#[test]
fn spectral_gradients_match_finite_differences() {
    let (x, y) = (
        moving_video(5, 5, 20, 27, 1.0),
        moving_video(6, 5, 20, 27, 1.7),
    );
    type Variant = (&'static str, fn(&mut SpectralConfig));
    let variants: [Variant; 6] = [
        ("16x16 (crop to 16x16)", |_| {}),
        // Odd patch width: the real-input DFT along w by a full-length complex FFT, and a
        // single self-conjugate plane.
        ("5x7 (crop to 20x21)", |s| s.patch = [5, 7]),
        ("8x8 (crop to 16x24)", |s| s.patch = [8, 8]),
        ("4x8 ortho", |s| {
            s.patch = [4, 8];
            s.norm = FftNorm::Ortho;
        }),
        ("8x8 sum", |s| {
            s.patch = [8, 8];
            s.mag_reduction = Reduction::Sum;
        }),
        ("8x8 eps 1e-3", |s| {
            s.patch = [8, 8];
            s.eps = 1e-3;
        }),
    ];
    for (name, f) in variants {
        for (term, w) in [
            ("mag", weights(0.0, 0.0, 1.0, 0.0)),
            ("phase", weights(0.0, 0.0, 0.0, 1.0)),
        ] {
            let loss = dms(y.clone(), |c| {
                c.weights = w;
                f(&mut c.spectral);
            });
            let rel = fd_check(&loss, &x, 11);
            println!("{term} {name}: rel {rel:.1e}");
        }
    }
}

#[test]
fn dms_gradient_matches_finite_differences_with_weights() {
    let (x, y) = (
        moving_video(7, 4, 24, 24, 0.5),
        moving_video(8, 4, 24, 24, 1.5),
    );
    let loss = dms(y, |c| {
        c.weights = weights(0.3, 0.7, 1.3, 0.9);
        c.spectral.patch = [8, 8];
    });
    fd_check(&loss, &x, 13);
}

#[test]
fn gradient_of_a_pair_of_patches_equals_single_patch_gradients() {
    // 3 patches per band: one pair and one single patch share the backward FFT.
    let (x, y) = (random_video(9, 4, 8, 24), random_video(10, 4, 8, 24));
    let loss = dms(y.clone(), |c| {
        c.weights = weights(0.0, 0.0, 1.0, 1.0);
        c.spectral.patch = [8, 8];
    });
    let (_, g) = loss.value_and_grad(&x).unwrap();
    // The same patches one at a time (8-px wide videos).
    for j in 0..3 {
        let crop = |v: &Video<f64>| {
            let mut out = Video::zeros(4, 8, 8);
            for t in 0..4 {
                for r in 0..8 {
                    for c in 0..8 {
                        for k in 0..3 {
                            out.data_mut()[((t * 8 + r) * 8 + c) * 3 + k] =
                                v.at(t, r, j * 8 + c, k);
                        }
                    }
                }
            }
            out
        };
        let single = dms(crop(&y), |c| {
            c.weights = weights(0.0, 0.0, 1.0, 1.0);
            c.spectral.patch = [8, 8];
        });
        let (_, gs) = single.value_and_grad(&crop(&x)).unwrap();
        for t in 0..4 {
            for r in 0..8 {
                for c in 0..8 {
                    for k in 0..3 {
                        // Means over 3 patches vs 1: the single-patch gradient is 3x.
                        let a = g.at(t, r, j * 8 + c, k) * 3.0;
                        let b = gs.at(t, r, c, k);
                        assert!((a - b).abs() < 1e-12 * (1.0 + b.abs()), "{a} vs {b}");
                    }
                }
            }
        }
    }
}

#[test]
fn f32_videos_follow_the_f64_gradient() {
    let (x, y) = (
        moving_video(11, 4, 32, 32, 0.5),
        moving_video(12, 4, 32, 32, 1.5),
    );
    let l64 = dms(y.clone(), |_| {});
    let (v64, g64) = l64.value_and_grad(&x).unwrap();
    let l32 = Dms::new(y.convert::<f32>(), DmsConfig::default()).unwrap();
    let (v32, g32) = l32.value_and_grad(&x.convert::<f32>()).unwrap();
    assert!((v64 - v32).abs() < 1e-5, "{v64} vs {v32}");
    let amax = g64.data().iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let worst = g64
        .data()
        .iter()
        .zip(g32.data())
        .map(|(a, b)| (a - *b as f64).abs())
        .fold(0.0f64, f64::max);
    assert!(worst < 1e-3 * amax, "worst {worst:e} of abs-max {amax:e}");
}

/// The phase term where the rendered spectrum is zero: a static rendered video against a
/// moving reference. Every rendered entry is exactly 0, so `S = 0` (L_phase = 1) and the
/// gradient is `-P_g / (N eps)` per entry: ~1/eps. A larger eps scales it down by the same
/// factor; the magnitude mask removes it.
#[test]
fn static_rendered_video_against_a_moving_reference() {
    let y = moving_video(13, 6, 32, 32, 1.0);
    let mut x = y.clone();
    let f0 = y.frame(0).to_vec();
    for t in 1..6 {
        x.frame_mut(t).copy_from_slice(&f0);
    }
    let phase_only = |f: fn(&mut SpectralConfig)| {
        dms(y.clone(), |c| {
            c.weights = weights(0.0, 0.0, 0.0, 1.0);
            f(&mut c.spectral);
        })
    };
    let absmax = |g: &Video<f64>| g.data().iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let (v, g) = phase_only(|_| {}).value_and_grad(&x).unwrap();
    assert_eq!(v, 1.0);
    let g8 = absmax(&g);
    let (v6, g) = phase_only(|s| s.eps = 1e-6).value_and_grad(&x).unwrap();
    assert_eq!(v6, 1.0);
    let g6 = absmax(&g);
    let (vm, g) = phase_only(|s| s.phase_mask = Some(1e-3))
        .value_and_grad(&x)
        .unwrap();
    let gm = absmax(&g);
    let n = 4 * 5 * 256; // entries
    println!(
        "static vs moving: max |dL_phase/dx| = {g8:.3e} (eps 1e-8), {g6:.3e} (eps 1e-6), \
         {gm:.1e} (mask 1e-3); 1/(N eps) = {:.3e}",
        1.0 / (n as f64 * 1e-8)
    );
    assert!(g8 > 1e3, "{g8}");
    assert!((g8 / g6 - 100.0).abs() < 1e-3, "{}", g8 / g6);
    assert_eq!(vm, 1.0);
    assert_eq!(gm, 0.0);
    // The magnitude term stays well-conditioned there (d|F| = 0 at F = 0).
    let mag = dms(y.clone(), |c| c.weights = weights(0.0, 0.0, 1.0, 0.0));
    let (_, g) = mag.value_and_grad(&x).unwrap();
    assert_eq!(absmax(&g), 0.0);
}

#[test]
fn identical_videos_give_zero_loss_and_gradient_except_phase_round_off() {
    let y = moving_video(14, 5, 32, 32, 1.0);
    let loss = dms(y.clone(), |_| {});
    let t = loss.terms(&y).unwrap();
    assert!(t.spatial.unwrap().abs() < 1e-14);
    assert_eq!(t.mag.unwrap(), 0.0);
    assert!(t.phase.unwrap() < 1e-5 && t.phase.unwrap() > 0.0);
}

#[test]
fn bad_input_gives_typed_errors_naming_the_input() {
    let y = random_video(15, 4, 32, 32);
    let loss = dms(y.clone(), |_| {});
    let msg = |e: LossError| e.to_string();
    let e = loss.value(&random_video(1, 5, 32, 32)).unwrap_err();
    assert!(matches!(
        e,
        LossError::FrameCount {
            reference: 4,
            rendered: 5
        }
    ));
    assert_eq!(msg(e), "reference has 4 frames, rendered has 5");
    let e = loss.value(&random_video(1, 4, 32, 48)).unwrap_err();
    assert!(matches!(e, LossError::FrameSize { .. }), "{e}");
    assert!(msg(e).contains("rendered frames are 32x48"));
    let mut nan = random_video(1, 4, 32, 32);
    nan.data_mut()[((3 * 32 + 2) * 32 + 5) * 3 + 1] = f64::NAN;
    let e = loss.value(&nan).unwrap_err();
    assert_eq!(
        msg(e),
        "rendered: frame 3 has NaN at row 2, column 5, channel 1"
    );
    let mut inf = y.clone();
    inf.data_mut()[0] = f64::INFINITY;
    let e = Dms::new(inf, DmsConfig::default()).unwrap_err();
    assert!(msg(e).starts_with("reference: frame 0 has an infinite value"));
    let e = Dms::new(random_video(1, 1, 32, 32), DmsConfig::default()).unwrap_err();
    assert!(
        matches!(e, LossError::TooFewFrames { frames: 1, .. }),
        "{e}"
    );
    let e = Dms::new(random_video(1, 3, 12, 40), DmsConfig::default()).unwrap_err();
    assert!(matches!(e, LossError::SmallerThanPatch { .. }), "{e}");
    let e = Dms::new(
        random_video(1, 3, 16, 10),
        DmsConfig::ablation(Ablation::Ssim),
    )
    .unwrap_err();
    assert!(
        matches!(e, LossError::SmallerThanWindow { window: 11, .. }),
        "{e}"
    );
    let e = ssim::ssim(
        &random_video(1, 1, 10, 30),
        &random_video(2, 1, 10, 30),
        &SsimConfig::default(),
    )
    .unwrap_err();
    assert!(msg(e).starts_with("rendered: frames of 10x30"));
    let e = ssim::ms_ssim(&y, &y, &MsSsimConfig::default()).unwrap_err();
    assert!(matches!(e, LossError::TooSmallForMsSsim { .. }), "{e}");
    let mut g = vec![0.0; 5];
    let e = loss.value_and_grad_into(&y, &mut g).unwrap_err();
    assert!(matches!(e, LossError::GradientLength { .. }), "{e}");
    assert!(matches!(
        Video::<f32>::new(2, 4, 4, vec![0.0; 10]),
        Err(r4d_frames::FrameError::DataLength { .. })
    ));
    let mut c = DmsConfig::default();
    c.spectral.eps = -1.0;
    assert!(matches!(Dms::new(y.clone(), c), Err(LossError::Config(_))));
    // One frame is fine without the spectral terms.
    let one = random_video(1, 1, 16, 16);
    Dms::new(one.clone(), DmsConfig::ablation(Ablation::L1))
        .unwrap()
        .value(&one)
        .unwrap();
}

#[test]
fn ablation_weights() {
    let y = moving_video(16, 3, 32, 32, 1.0);
    let x = moving_video(17, 3, 32, 32, 2.0);
    let full = dms(y.clone(), |_| {}).terms(&x).unwrap();
    let l1 = metrics::l1(&x, &y).unwrap();
    for (a, want) in [
        (Ablation::L1, l1),
        (Ablation::Ssim, full.spatial.unwrap()),
        (
            Ablation::L1Fft,
            l1 + full.mag.unwrap() + full.phase.unwrap(),
        ),
        (Ablation::SsimFft, full.total),
    ] {
        let t = Dms::new(y.clone(), DmsConfig::ablation(a))
            .unwrap()
            .terms(&x)
            .unwrap();
        assert!(
            (t.total - want).abs() < 1e-12,
            "{a:?}: {} vs {want}",
            t.total
        );
    }
}
