//! r4d-loss against the golden values in `tests/fixtures/loss/` (copied from the project's
//! reference data): PSNR, L1, SSIM, MS-SSIM, the DMS terms with every variant of the
//! README's ambiguity table, and the stored gradients. Tolerances are the README's: for the
//! f64 implementation 1e-8 relative on scalars and gradients within 1e-6 of each stored
//! array's abs-max; for f32 videos (f32 SSIM, f64 spectral part) 1e-5 absolute on L_spatial
//! and L_mag and 1e-3 on L_phase (skipped on the ill-conditioned case 8).
//!
//! Run with `--nocapture` to see the worst error of every quantity.

use r4d_loss::metrics::{l1, psnr};
use r4d_loss::ssim::{ms_ssim, ssim};
use r4d_loss::{
    Dms, DmsConfig, DmsWeights, FftNorm, MsSsimConfig, Real, Reduction, SpectralConfig, SsimConfig,
    Video,
};
use r4d_testkit::{fixture, read_npz, Array};
use serde_json::Value;
use std::collections::BTreeMap;

/// Worst errors per quantity, and failures.
#[derive(Default)]
struct Report {
    worst: BTreeMap<String, (f64, f64)>,
    failures: Vec<String>,
}

impl Report {
    /// `|got - want| <= atol + rtol |want|`.
    fn scalar(&mut self, case: &str, name: &str, got: f64, want: f64, rtol: f64, atol: f64) {
        let abs = (got - want).abs();
        let rel = abs / want.abs().max(1e-300);
        let e = self.worst.entry(name.to_string()).or_insert((0.0, 0.0));
        e.0 = e.0.max(rel.min(abs.max(rel)));
        e.1 = e.1.max(abs);
        let ok = abs <= atol + rtol * want.abs(); // false for NaN
        if !ok {
            self.failures.push(format!(
                "{case}: {name}: got {got:.12e}, want {want:.12e} (abs {abs:.2e}, rel {rel:.2e})"
            ));
        }
    }

    /// Every element within `tol * max|want| + atol`.
    fn array(&mut self, case: &str, name: &str, got: &[f64], want: &[f64], tol: f64, atol: f64) {
        assert_eq!(got.len(), want.len(), "{case}: {name}: length");
        let amax = want.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        let worst = got
            .iter()
            .zip(want)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0f64, f64::max);
        let rel = worst / amax.max(1e-300);
        let e = self.worst.entry(name.to_string()).or_insert((0.0, 0.0));
        e.0 = e.0.max(rel);
        e.1 = e.1.max(worst);
        let ok = worst <= tol * amax + atol; // false for NaN
        if !ok {
            self.failures.push(format!(
                "{case}: {name}: worst |diff| {worst:.3e} = {rel:.2e} x abs-max {amax:.3e}"
            ));
        }
    }

    fn finish(self, title: &str) {
        println!("{title}: worst (relative, absolute) error per quantity");
        for (k, (r, a)) in &self.worst {
            println!("  {k:40} rel {r:.2e}  abs {a:.2e}");
        }
        assert!(
            self.failures.is_empty(),
            "{} failures:\n{}",
            self.failures.len(),
            self.failures.join("\n")
        );
    }
}

fn goldens() -> Value {
    let s = std::fs::read_to_string(fixture("loss/goldens.json")).unwrap();
    serde_json::from_str(&s).unwrap()
}

struct Case {
    name: String,
    g: Value,
    arrays: std::collections::HashMap<String, Array>,
    uint8: bool,
}

fn cases() -> Vec<Case> {
    let g = goldens();
    g["cases"]
        .as_array()
        .unwrap()
        .iter()
        .map(|c| {
            let file = c["file"].as_str().unwrap();
            Case {
                name: c["name"].as_str().unwrap().to_string(),
                arrays: read_npz(&fixture(&format!("loss/{file}"))),
                uint8: c["input_storage"].as_str().unwrap().starts_with("uint8"),
                g: c.clone(),
            }
        })
        .collect()
}

/// A stored `(T, 3, H, W)` video; uint8 values k become k / 255 computed in `T`.
fn video<T: Real>(c: &Case, key: &str) -> Video<T> {
    let a = &c.arrays[key];
    let [t, ch, h, w] = a.shape[..] else {
        panic!("shape {:?}", a.shape)
    };
    assert_eq!(ch, 3);
    let vals: Vec<T> = if c.uint8 {
        a.data.iter().map(|&k| T::c(k) / T::c(255.0)).collect()
    } else {
        a.data.iter().map(|&v| T::c(v)).collect()
    };
    Video::from_tchw(t, h, w, &vals).unwrap()
}

/// A stored `(T, 3, H, W)` gradient in `(T, H, W, 3)` order.
fn grad_thwc(c: &Case, key: &str) -> Vec<f64> {
    let a = &c.arrays[key];
    let [t, _, h, w] = a.shape[..] else { panic!() };
    Video::from_tchw(t, h, w, &a.data).unwrap().into_data()
}

fn num(v: &Value) -> Option<f64> {
    v.as_f64()
}

fn dms_with(reference: &Video<f64>, f: impl FnOnce(&mut DmsConfig)) -> Dms<f64> {
    let mut cfg = DmsConfig::default();
    f(&mut cfg);
    Dms::new(reference.clone(), cfg).unwrap()
}

const RTOL: f64 = 1e-8;
const GTOL: f64 = 1e-6;

#[test]
fn metrics_match_the_goldens_in_f64() {
    let mut r = Report::default();
    for c in cases() {
        let (x, y) = (video::<f64>(&c, "rendered"), video::<f64>(&c, "reference"));
        let n = &c.name;
        let g = &c.g;
        r.scalar(
            n,
            "l1",
            l1(&x, &y).unwrap(),
            num(&g["l1"]).unwrap(),
            RTOL,
            1e-15,
        );
        let p = psnr(&x, &y).unwrap();
        r.scalar(n, "mse", p.mse, num(&g["mse"]).unwrap(), RTOL, 1e-18);
        assert_eq!(
            p.mean_of_frames.is_none(),
            g["psnr_mean_of_frames"].is_null(),
            "{n}"
        );
        assert_eq!(
            p.whole_video.is_none(),
            g["psnr_whole_video"].is_null(),
            "{n}"
        );
        if let Some(v) = p.mean_of_frames {
            r.scalar(
                n,
                "psnr_mean_of_frames",
                v,
                num(&g["psnr_mean_of_frames"]).unwrap(),
                RTOL,
                0.0,
            );
        }
        if let Some(v) = p.whole_video {
            r.scalar(
                n,
                "psnr_whole_video",
                v,
                num(&g["psnr_whole_video"]).unwrap(),
                RTOL,
                0.0,
            );
        }
        for (t, want) in g["psnr_per_frame"].as_array().unwrap().iter().enumerate() {
            assert_eq!(p.per_frame[t].is_none(), want.is_null(), "{n} frame {t}");
            if let Some(v) = p.per_frame[t] {
                r.scalar(n, "psnr_per_frame", v, want.as_f64().unwrap(), RTOL, 0.0);
            }
        }
        let s = ssim(&x, &y, &SsimConfig::default()).unwrap();
        r.scalar(
            n,
            "ssim_pm",
            s.mean,
            num(&g["ssim_pm"]).unwrap(),
            RTOL,
            1e-14,
        );
        r.scalar(
            n,
            "ssim_pm_nonneg",
            s.nonnegative,
            num(&g["ssim_pm_nonneg"]).unwrap(),
            RTOL,
            1e-14,
        );
        for (t, want) in g["ssim_pm_per_frame"]
            .as_array()
            .unwrap()
            .iter()
            .enumerate()
        {
            r.scalar(
                n,
                "ssim_pm_per_frame",
                s.per_frame[t],
                want.as_f64().unwrap(),
                RTOL,
                1e-14,
            );
        }
        let sp = ssim(&x, &y, &SsimConfig::same_pad()).unwrap();
        r.scalar(
            n,
            "ssim_same_pad",
            sp.mean,
            num(&g["ssim_same_pad"]).unwrap(),
            RTOL,
            1e-14,
        );
        match num(&g["ms_ssim"]) {
            Some(want) => {
                let m = ms_ssim(&x, &y, &MsSsimConfig::default()).unwrap();
                r.scalar(n, "ms_ssim", m.mean, want, RTOL, 0.0);
                for (t, w) in g["ms_ssim_per_frame"]
                    .as_array()
                    .unwrap()
                    .iter()
                    .enumerate()
                {
                    r.scalar(
                        n,
                        "ms_ssim_per_frame",
                        m.per_frame[t],
                        w.as_f64().unwrap(),
                        RTOL,
                        0.0,
                    );
                }
            }
            None => {
                let e = ms_ssim(&x, &y, &MsSsimConfig::default()).unwrap_err();
                assert!(e.to_string().contains("> 160 px"), "{e}");
            }
        }
        if let Some(sw) = g.get("ms_ssim_small_win").filter(|v| !v.is_null()) {
            let min_side = x.height().min(x.width());
            let cfg = MsSsimConfig::largest_window(min_side).unwrap();
            assert_eq!(cfg.window as u64, sw["win_size"].as_u64().unwrap(), "{n}");
            let m = ms_ssim(&x, &y, &cfg).unwrap();
            // Small windows are recomputed in f32 here and by PyTorch (exp may differ by an
            // ulp), hence 1e-7.
            r.scalar(
                n,
                "ms_ssim_small_win",
                m.mean,
                num(&sw["value"]).unwrap(),
                1e-7,
                0.0,
            );
        }
    }
    r.finish("metrics (f64)");
}

#[test]
fn dms_terms_and_variants_match_the_goldens_in_f64() {
    let mut r = Report::default();
    for c in cases() {
        let (x, y) = (video::<f64>(&c, "rendered"), video::<f64>(&c, "reference"));
        let n = &c.name;
        let g = &c.g;
        let t = dms_with(&y, |_| {}).terms(&x).unwrap();
        r.scalar(
            n,
            "L_spatial",
            t.spatial.unwrap(),
            num(&g["L_spatial"]).unwrap(),
            RTOL,
            1e-14,
        );
        r.scalar(
            n,
            "L_mag",
            t.mag.unwrap(),
            num(&g["L_mag"]).unwrap(),
            RTOL,
            1e-15,
        );
        r.scalar(
            n,
            "L_phase",
            t.phase.unwrap(),
            num(&g["L_phase"]).unwrap(),
            RTOL,
            1e-15,
        );
        r.scalar(n, "L_DMS", t.total, num(&g["L_DMS"]).unwrap(), RTOL, 1e-15);
        let v = &g["variants"];
        for (key, patch) in [("patch8x8", 8), ("patch32x32", 32)] {
            let t = dms_with(&y, |c| c.spectral.patch = [patch, patch])
                .terms(&x)
                .unwrap();
            r.scalar(
                n,
                &format!("{key}.L_mag"),
                t.mag.unwrap(),
                num(&v[key]["L_mag"]).unwrap(),
                RTOL,
                1e-15,
            );
            r.scalar(
                n,
                &format!("{key}.L_phase"),
                t.phase.unwrap(),
                num(&v[key]["L_phase"]).unwrap(),
                RTOL,
                1e-15,
            );
        }
        let t = dms_with(&y, |c| c.spectral.norm = FftNorm::Ortho)
            .terms(&x)
            .unwrap();
        let vo = &v["fft_norm_ortho"];
        r.scalar(
            n,
            "fft_norm_ortho.L_mag",
            t.mag.unwrap(),
            num(&vo["L_mag"]).unwrap(),
            RTOL,
            1e-15,
        );
        r.scalar(
            n,
            "fft_norm_ortho.L_phase",
            t.phase.unwrap(),
            num(&vo["L_phase"]).unwrap(),
            RTOL,
            1e-15,
        );
        let t = dms_with(&y, |c| c.spectral.mag_reduction = Reduction::Sum)
            .terms(&x)
            .unwrap();
        r.scalar(
            n,
            "L_mag_sum_reduction",
            t.mag.unwrap(),
            num(&v["L_mag_sum_reduction"]).unwrap(),
            RTOL,
            1e-12,
        );
        let t = dms_with(&y, |c| c.spectral.eps = 1e-6).terms(&x).unwrap();
        r.scalar(
            n,
            "eps_1e-6.L_phase",
            t.phase.unwrap(),
            num(&v["eps_1e-6"]["L_phase"]).unwrap(),
            RTOL,
            1e-15,
        );
        let t = dms_with(&y, |c| c.spatial = SsimConfig::same_pad())
            .terms(&x)
            .unwrap();
        r.scalar(
            n,
            "L_spatial_same_pad",
            t.spatial.unwrap(),
            num(&v["L_spatial_same_pad"]).unwrap(),
            RTOL,
            1e-14,
        );
        let t = dms_with(&y, |c| c.spatial.gray = true).terms(&x).unwrap();
        r.scalar(
            n,
            "L_spatial_pm_gray",
            t.spatial.unwrap(),
            num(&v["L_spatial_pm_gray"]).unwrap(),
            RTOL,
            1e-14,
        );
    }
    r.finish("DMS terms and variants (f64)");
}

/// Gradient of one term alone.
fn term_grad(y: &Video<f64>, x: &Video<f64>, weights: DmsWeights, spatial: SsimConfig) -> Vec<f64> {
    let cfg = DmsConfig {
        weights,
        spatial,
        spectral: SpectralConfig::default(),
    };
    let d = Dms::new(y.clone(), cfg).unwrap();
    let mut g = vec![0.0; x.data().len()];
    d.terms_and_grad_into(x, &mut g).unwrap();
    g
}

const ONLY_SPATIAL: DmsWeights = DmsWeights {
    l1: 0.0,
    spatial: 1.0,
    mag: 0.0,
    phase: 0.0,
};
const ONLY_MAG: DmsWeights = DmsWeights {
    l1: 0.0,
    spatial: 0.0,
    mag: 1.0,
    phase: 0.0,
};
const ONLY_PHASE: DmsWeights = DmsWeights {
    l1: 0.0,
    spatial: 0.0,
    mag: 0.0,
    phase: 1.0,
};

fn stats(g: &[f64]) -> (f64, f64, f64) {
    let absmax = g.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let l2 = g.iter().map(|v| v * v).sum::<f64>().sqrt();
    let sum = g.iter().sum::<f64>();
    (absmax, l2, sum)
}

/// Largest gray difference between the last and the first frame.
fn end_to_end_change(x: &Video<f64>) -> f64 {
    let (a, b) = (x.frame(0), x.frame(x.frames() - 1));
    a.chunks(3)
        .zip(b.chunks(3))
        .map(|(p, q)| {
            let g = |p: &[f64]| 0.299 * p[0] + 0.587 * p[1] + 0.114 * p[2];
            (g(q) - g(p)).abs()
        })
        .fold(0.0, f64::max)
}

/// Absolute floor for gradients that are zero up to round-off (case 3's spatial gradient,
/// 6e-18 in the goldens).
const GATOL: f64 = 1e-15;

#[test]
fn dms_gradients_match_the_goldens_in_f64() {
    let mut r = Report::default();
    for c in cases() {
        let (x, y) = (video::<f64>(&c, "rendered"), video::<f64>(&c, "reference"));
        let n = &c.name;
        let g = &c.g;
        let gs = term_grad(&y, &x, ONLY_SPATIAL, SsimConfig::default());
        let gm = term_grad(&y, &x, ONLY_MAG, SsimConfig::default());
        let gp = term_grad(&y, &x, ONLY_PHASE, SsimConfig::default());
        let gd: Vec<f64> = gs
            .iter()
            .zip(&gm)
            .zip(&gp)
            .map(|((a, b), c)| a + b + c)
            .collect();
        let full = {
            let d = Dms::new(y.clone(), DmsConfig::default()).unwrap();
            let mut out = vec![0.0; x.data().len()];
            d.terms_and_grad_into(&x, &mut out).unwrap();
            out
        };
        r.array(n, "grad_L_DMS (terms vs total)", &full, &gd, 1e-12, 0.0);
        // A rendered clip whose last frame equals its first (case 2: 2 Hz over 15 frame
        // intervals at 30 fps, one full period) has a temporal-DC spectrum
        // sum_t D_t = Y_{T-1} - Y_0 that is zero up to round-off; the direction of
        // d|F|/dF = F/|F| there is the direction of that round-off, different for every FFT
        // implementation. That part of the magnitude gradient reaches only the first and
        // the last frame (dL/dY_t = g_{t-1} - g_t with g constant in t), so those two frames
        // are compared separately with a loose bound and the interior ones at the README's
        // tolerance.
        let periodic = end_to_end_change(&x) < 1e-9;
        let flen = x.frame_len();
        let interior = flen..x.data().len() - flen;
        for (key, got) in [
            ("grad_L_spatial", &gs),
            ("grad_L_mag", &gm),
            ("grad_L_phase", &gp),
        ] {
            if !c.arrays.contains_key(key) {
                continue;
            }
            let want = grad_thwc(&c, key);
            if periodic && key == "grad_L_mag" {
                let amax = want.iter().fold(0.0f64, |m, v| m.max(v.abs()));
                r.array(
                    n,
                    "grad_L_mag (interior frames, periodic clip)",
                    &got[interior.clone()],
                    &want[interior.clone()],
                    0.0,
                    GTOL * amax,
                );
                r.array(
                    n,
                    "grad_L_mag (end frames, periodic clip)",
                    got,
                    &want,
                    0.2,
                    0.0,
                );
            } else {
                r.array(n, key, got, &want, GTOL, GATOL);
            }
        }
        if c.arrays.contains_key("grad_L_spatial_same_pad") {
            let gsp = term_grad(&y, &x, ONLY_SPATIAL, SsimConfig::same_pad());
            r.array(
                n,
                "grad_L_spatial_same_pad",
                &gsp,
                &grad_thwc(&c, "grad_L_spatial_same_pad"),
                GTOL,
                GATOL,
            );
            r.scalar(
                n,
                "grad_L_spatial_same_pad_absmax",
                stats(&gsp).0,
                num(&g["grad_L_spatial_same_pad_absmax"]).unwrap(),
                1e-6,
                0.0,
            );
        }
        // Summary statistics (the only gradient data of cases 6 and 8). The sums are
        // cancellations (1e-17 for the spectral terms), so they get an absolute tolerance of
        // 1e-9 of the l2 norm. The magnitude gradient of a (nearly) periodic clip is skipped
        // (see above); its share of grad_L_DMS is below the tolerance.
        for (key, got) in [
            ("grad_L_spatial", &gs),
            ("grad_L_mag", &gm),
            ("grad_L_phase", &gp),
            ("grad_L_DMS", &gd),
        ] {
            if key == "grad_L_mag" && end_to_end_change(&x) < 1e-6 {
                continue;
            }
            let (amax, l2, sum) = stats(got);
            let want_l2 = num(&g[format!("{key}_l2norm")]).unwrap();
            r.scalar(
                n,
                &format!("{key}_absmax"),
                amax,
                num(&g[format!("{key}_absmax")]).unwrap(),
                1e-6,
                GATOL,
            );
            r.scalar(n, &format!("{key}_l2norm"), l2, want_l2, 1e-6, GATOL);
            r.scalar(
                n,
                &format!("{key}_sum"),
                sum,
                num(&g[format!("{key}_sum")]).unwrap(),
                1e-6,
                1e-9 * want_l2 + GATOL,
            );
        }
    }
    r.finish("DMS gradients (f64)");
}

#[test]
fn f32_videos_meet_the_float32_tolerances() {
    let mut r = Report::default();
    for c in cases() {
        let (x, y) = (video::<f32>(&c, "rendered"), video::<f32>(&c, "reference"));
        let n = &c.name;
        let g = &c.g;
        let d = Dms::new(y.clone(), DmsConfig::default()).unwrap();
        let mut grad = vec![0.0f32; x.data().len()];
        let t = d.terms_and_grad_into(&x, &mut grad).unwrap();
        r.scalar(
            n,
            "f32 L_spatial",
            t.spatial.unwrap(),
            num(&g["L_spatial"]).unwrap(),
            0.0,
            1e-5,
        );
        r.scalar(
            n,
            "f32 L_mag",
            t.mag.unwrap(),
            num(&g["L_mag"]).unwrap(),
            0.0,
            1e-5,
        );
        if n != "illcond_float_blobs_freq_2.0Hz_vs_3.0Hz" {
            r.scalar(
                n,
                "f32 L_phase",
                t.phase.unwrap(),
                num(&g["L_phase"]).unwrap(),
                0.0,
                1e-3,
            );
        }
        let s = ssim(&x, &y, &SsimConfig::default()).unwrap();
        r.scalar(
            n,
            "f32 ssim_pm",
            s.mean,
            num(&g["ssim_pm"]).unwrap(),
            0.0,
            1e-5,
        );
        let sp = ssim(&x, &y, &SsimConfig::same_pad()).unwrap();
        r.scalar(
            n,
            "f32 ssim_same_pad",
            sp.mean,
            num(&g["ssim_same_pad"]).unwrap(),
            0.0,
            1e-5,
        );
        // The f32 spatial gradient against the stored one (f32 SSIM arithmetic).
        if c.arrays.contains_key("grad_L_spatial") {
            let yy = y.clone();
            let cfg = DmsConfig {
                weights: ONLY_SPATIAL,
                ..Default::default()
            };
            let mut gs = vec![0.0f32; x.data().len()];
            Dms::new(yy, cfg)
                .unwrap()
                .terms_and_grad_into(&x, &mut gs)
                .unwrap();
            let gs: Vec<f64> = gs.iter().map(|&v| v as f64).collect();
            // Absolute floor: f32 round-off of the zero gradient of identical videos.
            r.array(
                n,
                "f32 grad_L_spatial",
                &gs,
                &grad_thwc(&c, "grad_L_spatial"),
                5e-4,
                1e-8,
            );
        }
    }
    r.finish("f32 videos");
}
