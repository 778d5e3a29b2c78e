//! Band-wise DMS ([`BandedDms`]) against the whole-video loss ([`Dms`]): the band terms add
//! up to the whole video's terms and the band gradients (added at their rows) to its
//! gradient.

use r4d_loss::bands::{BandedDms, ReferenceVideo, Video8};
use r4d_loss::{Dms, DmsConfig, DmsTerms, DmsWeights, LossError, Padding, Real, Reduction, Video};

/// A moving bright disc over a textured background plus noise: every term is active.
fn video<T: Real>(frames: usize, h: usize, w: usize, seed: u64, speed: f64) -> Video<T> {
    let mut s = seed;
    let mut rnd = move || {
        s = s
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((s >> 11) as f64) / (1u64 << 53) as f64
    };
    let mut data = Vec::with_capacity(frames * h * w * 3);
    for t in 0..frames {
        let (cx, cy) = (
            10.0 + speed * t as f64,
            h as f64 * 0.4 + 0.5 * speed * t as f64,
        );
        for y in 0..h {
            for x in 0..w {
                let d = ((x as f64 - cx).powi(2) + (y as f64 - cy).powi(2)).sqrt();
                let disc = if d < 9.0 { 0.6 } else { 0.0 };
                for c in 0..3 {
                    let bg = 0.2 + 0.1 * ((x * (c + 1) + 3 * y) as f64 * 0.37).sin();
                    data.push(T::c((bg + disc + 0.05 * rnd()).clamp(0.0, 1.0)));
                }
            }
        }
    }
    Video::new(frames, h, w, data).unwrap()
}

fn rel(a: f64, b: f64) -> f64 {
    (a - b).abs() / b.abs().max(1e-30)
}

/// Sums the band terms and the band gradients of `rendered`.
fn banded<T: Real>(loss: &BandedDms, rendered: &Video<T>) -> (DmsTerms, Vec<T>) {
    let (h, w) = (rendered.height(), rendered.width());
    let mut terms = DmsTerms::default();
    let mut grad = vec![T::zero(); rendered.data().len()];
    let bands: Vec<_> = loss.bands().cloned().collect();
    for (b, band) in bands.iter().enumerate() {
        let rows = band.rows.clone();
        let mut data = Vec::new();
        for t in 0..rendered.frames() {
            data.extend_from_slice(&rendered.frame(t)[rows.start * w * 3..rows.end * w * 3]);
        }
        let x = Video::new(rendered.frames(), rows.len(), w, data).unwrap();
        let mut g = vec![T::zero(); x.data().len()];
        let t_b = loss.band_terms_and_grad_into(b, &x, &mut g).unwrap();
        let t_v = loss.band_terms(b, &x).unwrap();
        assert!(
            rel(t_v.total, t_b.total) < 1e-12,
            "band {b}: {t_v:?} vs {t_b:?}"
        );
        terms.add(&t_b);
        let fl = rows.len() * w * 3;
        for t in 0..rendered.frames() {
            let dst =
                &mut grad[t * h * w * 3 + rows.start * w * 3..t * h * w * 3 + rows.end * w * 3];
            for (d, s) in dst.iter_mut().zip(&g[t * fl..(t + 1) * fl]) {
                *d += *s;
            }
        }
    }
    (terms, grad)
}

fn check<T: Real>(cfg: DmsConfig, frames: usize, h: usize, w: usize, band_rows: usize, tol: f64) {
    let reference = video::<f32>(frames, h, w, 1, 2.0);
    let rendered = video::<T>(frames, h, w, 7, 1.5);
    let whole = Dms::new(reference.convert::<T>(), cfg.clone()).unwrap();
    let mut g_whole = vec![T::zero(); rendered.data().len()];
    let t_whole = whole.terms_and_grad_into(&rendered, &mut g_whole).unwrap();
    let loss = BandedDms::new(ReferenceVideo::F32(reference), frames, cfg, band_rows).unwrap();
    assert!(loss.len() > 1 || band_rows >= h, "expected several bands");
    let (t_band, g_band) = banded(&loss, &rendered);
    let pairs = [
        (t_whole.l1, t_band.l1),
        (t_whole.spatial, t_band.spatial),
        (t_whole.mag, t_band.mag),
        (t_whole.phase, t_band.phase),
    ];
    for (a, b) in pairs {
        assert_eq!(a.is_some(), b.is_some());
        if let (Some(a), Some(b)) = (a, b) {
            assert!(rel(b, a) < tol, "term {b} vs whole {a}");
        }
    }
    assert!(
        rel(t_band.total, t_whole.total) < tol,
        "{t_band:?} vs {t_whole:?}"
    );
    assert_eq!(t_band.masked, t_whole.masked);
    let num: f64 = g_band
        .iter()
        .zip(&g_whole)
        .map(|(a, b)| (a.f64() - b.f64()).powi(2))
        .sum();
    let den: f64 = g_whole.iter().map(|b| b.f64().powi(2)).sum();
    assert!(den > 0.0);
    assert!(
        (num / den).sqrt() < tol,
        "gradient rel L2 {}",
        (num / den).sqrt()
    );
}

#[test]
fn bands_add_up_to_the_whole_video_in_f64() {
    for band_rows in [16, 20, 32] {
        check::<f64>(DmsConfig::default(), 5, 75, 40, band_rows, 1e-11);
    }
    let mut cfg = DmsConfig {
        weights: DmsWeights {
            l1: 0.7,
            spatial: 0.5,
            mag: 2.0,
            phase: 0.3,
        },
        ..Default::default()
    };
    cfg.spectral.phase_mask = Some(1e-3);
    cfg.spectral.mag_reduction = Reduction::Sum;
    cfg.spatial.gray = true;
    check::<f64>(cfg, 4, 67, 33, 16, 1e-11);
}

#[test]
fn bands_add_up_to_the_whole_video_in_f32() {
    check::<f32>(DmsConfig::default(), 6, 90, 48, 32, 2e-5);
}

#[test]
fn a_short_last_band_joins_the_one_before() {
    let r = video::<f32>(3, 70, 24, 1, 1.0);
    // 70 rows in 32-row bands: 0..32, 32..64, then 6 rows (< a patch) join the second.
    let loss = BandedDms::new(ReferenceVideo::F32(r), 3, DmsConfig::default(), 32).unwrap();
    let owns: Vec<_> = loss.bands().map(|b| b.own.clone()).collect();
    assert_eq!(owns, vec![0..32, 32..70]);
    let rows: Vec<_> = loss.bands().map(|b| b.rows.clone()).collect();
    assert_eq!(rows, vec![0..42, 32..70]);
}

#[test]
fn an_8_bit_reference_is_stored_as_bytes_and_gives_the_same_loss() {
    let v = video::<f32>(3, 40, 20, 3, 1.0);
    let q = Video8::quantize(&v);
    let as_f32: Video<f32> = ReferenceVideo::U8(q.clone()).rows(3, 0..40);
    let exact = Video8::from_exact(&as_f32).expect("k/255 values are exact");
    assert_eq!(exact, q);
    assert!(
        Video8::from_exact(&v).is_none(),
        "noisy floats are not 8-bit"
    );
    let compact = ReferenceVideo::compact(as_f32.clone());
    assert!(matches!(compact, ReferenceVideo::U8(_)));
    assert_eq!(compact.bytes(), 3 * 40 * 20 * 3);
    let rendered = video::<f32>(3, 40, 20, 9, 2.0);
    let a = BandedDms::new(compact, 3, DmsConfig::default(), 16).unwrap();
    let b = BandedDms::new(ReferenceVideo::F32(as_f32), 3, DmsConfig::default(), 16).unwrap();
    let (ta, _) = banded(&a, &rendered);
    let (tb, _) = banded(&b, &rendered);
    assert_eq!(ta, tb);
}

#[test]
fn bad_settings_are_typed_errors() {
    let r = video::<f32>(3, 40, 20, 1, 1.0);
    let mut cfg = DmsConfig::default();
    cfg.spatial.padding = Padding::Same;
    let e = BandedDms::new(ReferenceVideo::F32(r.clone()), 3, cfg, 16).unwrap_err();
    assert!(
        matches!(e, LossError::Config(ref m) if m.contains("valid")),
        "{e}"
    );
    let e = BandedDms::new(ReferenceVideo::F32(r.clone()), 4, DmsConfig::default(), 16);
    assert!(e.is_err());
    let loss = BandedDms::new(ReferenceVideo::F32(r), 3, DmsConfig::default(), 16).unwrap();
    let wrong = Video::<f32>::zeros(3, 5, 20);
    assert!(loss.band_terms(0, &wrong).is_err());
    let mut nan = Video::<f32>::zeros(3, loss.bands().next().unwrap().rows.len(), 20);
    nan.data_mut()[7] = f32::NAN;
    assert!(matches!(
        loss.band_terms(0, &nan),
        Err(LossError::Frame(r4d_loss::FrameError::NonFinite { .. }))
    ));
}

/// The traits the video objective uses: [`r4d_loss::VideoLoss`] makes the banded DMS of a
/// view, and that [`r4d_loss::BandedLoss`] as a whole-video [`r4d_loss::Loss`] (its bands
/// stitched by `whole_video_terms`) gives the whole video's DMS value and gradient.
#[test]
fn the_banded_loss_traits_give_the_whole_video_dms() {
    use r4d_loss::{Loss, VideoLoss};
    let (frames, h, w) = (4, 70, 36);
    let reference = video::<f32>(frames, h, w, 3, 2.0);
    let rendered = video::<f32>(frames, h, w, 9, 1.2);
    let cfg = DmsConfig::default();
    let whole = Dms::new(reference.clone(), cfg.clone()).unwrap();
    let mut g_whole = vec![0.0f32; rendered.data().len()];
    let v_whole = whole.value_and_grad_into(&rendered, &mut g_whole).unwrap();
    let reference = ReferenceVideo::F32(reference);
    let made = cfg.banded(&reference, frames, 16).unwrap();
    assert!(made.band_rows().len() > 2, "several bands");
    let direct = BandedDms::new(&reference, frames, cfg, 16).unwrap();
    let v = direct.value(&rendered).unwrap();
    let mut g = vec![0.0f32; rendered.data().len()];
    let v2 = direct.value_and_grad_into(&rendered, &mut g).unwrap();
    let v3 = r4d_loss::banded_loss::whole_video_terms(&*made, &rendered, None)
        .unwrap()
        .total;
    assert!(rel(v, v_whole) < 1e-5, "banded {v} vs whole {v_whole}");
    assert_eq!(v, v2);
    assert_eq!(v, v3, "the VideoLoss-made loss is the same banded DMS");
    let num: f64 = g
        .iter()
        .zip(&g_whole)
        .map(|(a, b)| (*a as f64 - *b as f64).powi(2))
        .sum();
    let den: f64 = g_whole.iter().map(|b| (*b as f64).powi(2)).sum();
    assert!(
        den > 0.0 && (num / den).sqrt() < 1e-4,
        "gradient rel L2 {}",
        (num / den).sqrt()
    );
    // A video of the wrong length is refused, not read out of bounds.
    let short = video::<f32>(frames - 1, h, w, 9, 1.2);
    assert!(direct.value(&short).is_err());
}
