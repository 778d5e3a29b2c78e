//! LPIPS without pretrained weights: random weights, against a straightforward f64
//! reference written here (direct convolution loops, the official formula), and the
//! weights file's errors. The golden values with the real weights are checked by the
//! root package's `tests/references/lpips.rs`.

use super::*;
use std::collections::HashMap;

/// SplitMix64 in [-1, 1).
struct Rng(crate::tests::Rng);
impl Rng {
    fn new(seed: u64) -> Rng {
        Rng(crate::tests::Rng(seed))
    }
    fn next(&mut self) -> f64 {
        2.0 * self.0.next() - 1.0
    }
}

/// He-scaled random weights (so activations neither vanish nor explode), positive heads.
fn random_tensors(net: LpipsNet, seed: u64) -> HashMap<String, (Vec<usize>, Vec<f32>)> {
    let mut rng = Rng::new(seed);
    net.tensors()
        .into_iter()
        .map(|(key, shape)| {
            let n: usize = shape.iter().product();
            let fan_in: usize = shape[1..].iter().product();
            let v: Vec<f32> = (0..n)
                .map(|_| {
                    let r = rng.next();
                    if key.starts_with("lin") {
                        (0.5 * (r + 1.0) / shape[1] as f64 * 10.0) as f32
                    } else if key.ends_with("bias") {
                        (0.05 * r) as f32
                    } else {
                        (r * (6.0 / fan_in as f64).sqrt()) as f32
                    }
                })
                .collect();
            (key, (shape, v))
        })
        .collect()
}

fn random_metric(net: LpipsNet, seed: u64) -> Lpips {
    Lpips::new(LpipsWeights::from_tensors(net, "random", random_tensors(net, seed)).unwrap())
}

fn image(h: usize, w: usize, seed: u64) -> Vec<f32> {
    let mut rng = Rng::new(seed);
    (0..h * w * 3)
        .map(|i| {
            let (y, x) = ((i / 3) / w, (i / 3) % w);
            (0.5 + 0.3 * ((x as f64 * 0.3 + y as f64 * 0.17).sin()) + 0.15 * rng.next()) as f32
        })
        .collect()
}

/// A feature map `c x h x w` in f64.
struct Map {
    c: usize,
    h: usize,
    w: usize,
    v: Vec<f64>,
}

fn naive_conv(x: &Map, wt: &[f32], b: &[f32], cout: usize, k: usize, s: usize, p: usize) -> Map {
    let ho = (x.h + 2 * p - k) / s + 1;
    let wo = (x.w + 2 * p - k) / s + 1;
    let mut v = vec![0.0; cout * ho * wo];
    for o in 0..cout {
        for yo in 0..ho {
            for xo in 0..wo {
                let mut acc = b[o] as f64;
                for c in 0..x.c {
                    for ky in 0..k {
                        for kx in 0..k {
                            let y = (yo * s + ky) as isize - p as isize;
                            let xx = (xo * s + kx) as isize - p as isize;
                            if y < 0 || xx < 0 || y as usize >= x.h || xx as usize >= x.w {
                                continue;
                            }
                            acc += wt[((o * x.c + c) * k + ky) * k + kx] as f64
                                * x.v[(c * x.h + y as usize) * x.w + xx as usize];
                        }
                    }
                }
                v[(o * ho + yo) * wo + xo] = acc.max(0.0);
            }
        }
    }
    Map {
        c: cout,
        h: ho,
        w: wo,
        v,
    }
}

fn naive_pool(x: &Map, k: usize, s: usize) -> Map {
    let ho = (x.h - k) / s + 1;
    let wo = (x.w - k) / s + 1;
    let mut v = vec![f64::NEG_INFINITY; x.c * ho * wo];
    for c in 0..x.c {
        for yo in 0..ho {
            for xo in 0..wo {
                for dy in 0..k {
                    for dx in 0..k {
                        let e = x.v[(c * x.h + yo * s + dy) * x.w + xo * s + dx];
                        let d = &mut v[(c * ho + yo) * wo + xo];
                        *d = d.max(e);
                    }
                }
            }
        }
    }
    Map {
        c: x.c,
        h: ho,
        w: wo,
        v,
    }
}

/// The five taps of the backbone, written out per net as the papers' tables list them.
fn naive_features(
    net: LpipsNet,
    t: &HashMap<String, (Vec<usize>, Vec<f32>)>,
    img: &[f32],
    h: usize,
    w: usize,
) -> Vec<Map> {
    let shift = [-0.030, -0.088, -0.188];
    let scale = [0.458, 0.448, 0.450];
    let mut v = vec![0.0; 3 * h * w];
    for c in 0..3 {
        for i in 0..h * w {
            v[c * h * w + i] = ((2.0 * img[i * 3 + c] as f64 - 1.0) - shift[c]) / scale[c];
        }
    }
    let mut x = Map { c: 3, h, w, v };
    let conv = |x: &Map, idx: usize, k: usize, s: usize, p: usize| {
        let (shape, wt) = &t[&format!("features.{idx}.weight")];
        let b = &t[&format!("features.{idx}.bias")].1;
        naive_conv(x, wt, b, shape[0], k, s, p)
    };
    let mut taps = Vec::new();
    match net {
        LpipsNet::Alex => {
            x = conv(&x, 0, 11, 4, 2);
            taps.push(Map {
                v: x.v.clone(),
                ..x
            });
            let x1 = naive_pool(&taps[0], 3, 2);
            let x2 = conv(&x1, 3, 5, 1, 2);
            let x3 = naive_pool(&x2, 3, 2);
            taps.push(x2);
            let x4 = conv(&x3, 6, 3, 1, 1);
            let x5 = conv(&x4, 8, 3, 1, 1);
            let x6 = conv(&x5, 10, 3, 1, 1);
            taps.extend([x4, x5, x6]);
        }
        LpipsNet::Vgg => {
            let mut idx = 0;
            for (stage, convs) in [2, 2, 3, 3, 3].into_iter().enumerate() {
                if stage > 0 {
                    x = naive_pool(&x, 2, 2);
                    idx += 1;
                }
                for _ in 0..convs {
                    x = conv(&x, idx, 3, 1, 1);
                    idx += 2;
                }
                taps.push(Map {
                    v: x.v.clone(),
                    ..x
                });
            }
        }
    }
    taps
}

fn naive_lpips(
    net: LpipsNet,
    t: &HashMap<String, (Vec<usize>, Vec<f32>)>,
    a: &[f32],
    b: &[f32],
    h: usize,
    w: usize,
) -> f64 {
    let fa = naive_features(net, t, a, h, w);
    let fb = naive_features(net, t, b, h, w);
    let mut total = 0.0;
    for (k, (ma, mb)) in fa.iter().zip(&fb).enumerate() {
        let head = &t[&format!("lin{k}.model.1.weight")].1;
        let n = ma.h * ma.w;
        let mut sum = 0.0;
        for i in 0..n {
            let na: f64 = (0..ma.c)
                .map(|c| ma.v[c * n + i].powi(2))
                .sum::<f64>()
                .sqrt()
                + 1e-10;
            let nb: f64 = (0..mb.c)
                .map(|c| mb.v[c * n + i].powi(2))
                .sum::<f64>()
                .sqrt()
                + 1e-10;
            sum += (0..ma.c)
                .map(|c| head[c] as f64 * (ma.v[c * n + i] / na - mb.v[c * n + i] / nb).powi(2))
                .sum::<f64>();
        }
        total += sum / n as f64;
    }
    total
}

#[test]
fn random_weights_match_a_straightforward_reference() {
    for (net, h, w) in [
        (LpipsNet::Alex, 67, 83),
        (LpipsNet::Alex, 31, 40),
        (LpipsNet::Vgg, 37, 29),
        (LpipsNet::Vgg, 16, 16),
    ] {
        let t = random_tensors(net, 7);
        let m = random_metric(net, 7);
        let (a, b) = (image(h, w, 1), image(h, w, 2));
        let want = naive_lpips(net, &t, &a, &b, h, w);
        let got = m.pair(&a, &b, h, w).unwrap();
        assert!(want > 1e-3, "{net}: the reference is degenerate ({want})");
        assert!(
            (got - want).abs() <= 1e-4 * want,
            "{net} {h}x{w}: got {got}, reference {want}"
        );
        // Identical frames: exactly zero.
        assert_eq!(m.pair(&a, &a, h, w).unwrap(), 0.0);
    }
}

#[test]
fn bands_give_the_whole_frames_value() {
    for net in LpipsNet::ALL {
        let (h, w) = (97, 71);
        let m = random_metric(net, 3);
        let (a, b) = (image(h, w, 4), image(h, w, 5));
        let whole = m.pair(&a, &b, h, w).unwrap();
        assert_eq!(m.bands_for(h, w).unwrap(), 1);
        let (rows, cols) = m.levels(h, w).unwrap();
        let full = m.band_bytes(&m.arch.plan(&rows, 1)[0], &cols);
        for budget in [full * 3 / 4, full / 3, full / 8] {
            let banded = m.clone().with_band_budget(budget);
            let n = banded.bands_for(h, w).unwrap();
            assert!(n > 1, "{net}: budget {budget} gives {n} band");
            let v = banded.pair(&a, &b, h, w).unwrap();
            assert!(
                (v - whole).abs() <= 1e-5 * whole,
                "{net}, {n} bands: {v} vs {whole}"
            );
        }
    }
}

#[test]
fn videos_u8_and_streams_agree() {
    let m = random_metric(LpipsNet::Alex, 11);
    let (t, h, w) = (3, 40, 52);
    let frames: Vec<(Vec<f32>, Vec<f32>)> = (0..t)
        .map(|i| (image(h, w, 10 + i as u64), image(h, w, 20 + i as u64)))
        .collect();
    let q = |v: &[f32]| -> Vec<u8> {
        v.iter()
            .map(|x| (x.clamp(0.0, 1.0) * 255.0).round() as u8)
            .collect()
    };
    let va = Video::from_frames(h, w, frames.iter().map(|f| f.0.clone())).unwrap();
    let vb = Video::from_frames(h, w, frames.iter().map(|f| f.1.clone())).unwrap();
    let v = m.video(&va, &vb).unwrap();
    assert_eq!(v.per_frame.len(), t);
    let mean = v.per_frame.iter().sum::<f64>() / t as f64;
    assert!((v.mean - mean).abs() < 1e-15);
    for (i, f) in frames.iter().enumerate() {
        assert_eq!(m.pair(&f.0, &f.1, h, w).unwrap(), v.per_frame[i]);
    }
    // u8 frames equal f32 frames holding k / 255.
    let s8 = m
        .stream(t, h, w, |i| Ok((q(&frames[i].0), q(&frames[i].1))))
        .unwrap();
    let s32 = m
        .stream(t, h, w, |i| {
            let u = |v: Vec<u8>| {
                v.into_iter()
                    .map(|k| k as f32 / 255.0)
                    .collect::<Vec<f32>>()
            };
            Ok((u(q(&frames[i].0)), u(q(&frames[i].1))))
        })
        .unwrap();
    assert_eq!(s8, s32);
    // f64 videos are evaluated in f32.
    let v64 = m.video(&va.convert::<f64>(), &vb.convert::<f64>()).unwrap();
    assert_eq!(v64.per_frame, v.per_frame);
}

#[test]
fn bad_frames_are_typed_errors() {
    let m = random_metric(LpipsNet::Alex, 1);
    let e = m
        .pair(&image(30, 64, 1), &image(30, 64, 2), 30, 64)
        .unwrap_err();
    assert!(
        matches!(
            e,
            LpipsError::FrameTooSmall {
                min: 31,
                height: 30,
                ..
            }
        ),
        "{e}"
    );
    assert!(e.to_string().contains("at least 31x31"), "{e}");
    let e = m
        .pair(&image(40, 40, 1)[..100], &image(40, 40, 2), 40, 40)
        .unwrap_err();
    assert!(
        matches!(
            e,
            LpipsError::DataLength {
                what: "rendered",
                ..
            }
        ),
        "{e}"
    );
    let mut bad = image(40, 40, 1);
    bad[17] = f32::NAN;
    let e = m.pair(&image(40, 40, 2), &bad, 40, 40).unwrap_err();
    assert!(
        matches!(
            e,
            LpipsError::NotFinitePixel {
                what: "reference",
                ..
            }
        ),
        "{e}"
    );
    let a = Video::<f32>::zeros(2, 40, 40);
    let b = Video::<f32>::zeros(3, 40, 40);
    assert!(matches!(m.video(&a, &b), Err(LpipsError::Mismatch { .. })));
}

/// A minimal safetensors writer (the format: u64 header length, JSON header, data).
fn safetensors_bytes(
    tensors: &[(String, Vec<usize>, &str, Vec<u8>)],
    meta: Option<&str>,
) -> Vec<u8> {
    let mut header = String::from("{");
    if let Some(n) = meta {
        header += &format!("\"__metadata__\":{{\"net\":\"{n}\"}},");
    }
    let mut off = 0;
    let mut body = Vec::new();
    for (i, (k, shape, dtype, data)) in tensors.iter().enumerate() {
        if i > 0 {
            header += ",";
        }
        header += &format!(
            "\"{k}\":{{\"dtype\":\"{dtype}\",\"shape\":{shape:?},\"data_offsets\":[{off},{}]}}",
            off + data.len()
        );
        off += data.len();
        body.extend_from_slice(data);
    }
    header += "}";
    let mut out = (header.len() as u64).to_le_bytes().to_vec();
    out.extend_from_slice(header.as_bytes());
    out.extend_from_slice(&body);
    out
}

fn file_of(
    net: LpipsNet,
    meta: Option<&str>,
    edit: impl Fn(&mut Vec<(String, Vec<usize>, &str, Vec<u8>)>),
) -> Vec<u8> {
    let t = random_tensors(net, 5);
    let mut list: Vec<(String, Vec<usize>, &str, Vec<u8>)> = net
        .tensors()
        .into_iter()
        .map(|(k, shape)| {
            let bytes = t[&k].1.iter().flat_map(|v| v.to_le_bytes()).collect();
            (k, shape, "F32", bytes)
        })
        .collect();
    edit(&mut list);
    safetensors_bytes(&list, meta)
}

#[test]
fn weights_files_load_and_bad_ones_name_file_and_tensor() {
    for net in LpipsNet::ALL {
        for meta in [None, Some(net.name())] {
            let w =
                LpipsWeights::from_safetensors(&file_of(net, meta, |_| {}), "w.st", None).unwrap();
            assert_eq!(w.net(), net);
            let direct = LpipsWeights::from_tensors(net, "t", random_tensors(net, 5)).unwrap();
            assert_eq!(w.convs, direct.convs);
            assert_eq!(w.heads, direct.heads);
        }
    }
    let err = |bytes: Vec<u8>, expect| {
        LpipsWeights::from_safetensors(&bytes, "w.st", expect).unwrap_err()
    };
    // A VGG file given as Alex.
    let e = err(file_of(LpipsNet::Vgg, None, |_| {}), Some(LpipsNet::Alex));
    assert!(
        matches!(
            e,
            LpipsError::WrongNet {
                expected: LpipsNet::Alex,
                found: LpipsNet::Vgg,
                ..
            }
        ),
        "{e}"
    );
    assert!(e.to_string().starts_with("w.st:"), "{e}");
    // Metadata contradicting the shapes.
    let e = err(file_of(LpipsNet::Vgg, Some("alex"), |_| {}), None);
    assert!(e.to_string().contains("metadata says alex"), "{e}");
    // Truncated.
    let full = file_of(LpipsNet::Alex, None, |_| {});
    for cut in [4, 20, full.len() / 2, full.len() - 1] {
        let e = err(full[..cut].to_vec(), None);
        assert!(matches!(e, LpipsError::Format { .. }), "cut {cut}: {e}");
    }
    // A missing tensor.
    let e = err(
        file_of(LpipsNet::Alex, None, |l| {
            l.retain(|t| t.0 != "lin3.model.1.weight")
        }),
        None,
    );
    assert!(
        matches!(&e, LpipsError::MissingTensor { tensor, .. } if tensor == "lin3.model.1.weight"),
        "{e}"
    );
    // A wrong shape.
    let e = err(
        file_of(LpipsNet::Alex, None, |l| {
            let t = l.iter_mut().find(|t| t.0 == "features.6.bias").unwrap();
            t.1 = vec![383];
            t.3.truncate(383 * 4);
        }),
        None,
    );
    assert!(
        matches!(&e, LpipsError::Shape { tensor, found, .. } if tensor == "features.6.bias" && found == &[383]),
        "{e}"
    );
    // Another dtype.
    let e = err(
        file_of(LpipsNet::Alex, None, |l| {
            let t = l.iter_mut().find(|t| t.0 == "features.3.weight").unwrap();
            t.2 = "F16";
            let n = t.3.len() / 2;
            t.3.truncate(n);
        }),
        None,
    );
    assert!(
        matches!(&e, LpipsError::DType { tensor, .. } if tensor == "features.3.weight"),
        "{e}"
    );
    // A non-finite weight.
    let e = err(
        file_of(LpipsNet::Alex, None, |l| {
            let t = l.iter_mut().find(|t| t.0 == "features.8.weight").unwrap();
            t.3[40..44].copy_from_slice(&f32::NAN.to_le_bytes());
        }),
        None,
    );
    assert!(
        matches!(&e, LpipsError::NotFiniteWeight { tensor, .. } if tensor == "features.8.weight"),
        "{e}"
    );
    // Not a safetensors file at all; a header length far beyond the file.
    assert!(matches!(
        err(b"PK\x03\x04 not safetensors".to_vec(), None),
        LpipsError::Format { .. }
    ));
    let mut huge = u64::MAX.to_le_bytes().to_vec();
    huge.extend_from_slice(b"{}");
    assert!(matches!(err(huge, None), LpipsError::Format { .. }));
    // A missing file names it.
    let e = LpipsWeights::from_file(Path::new("/nonexistent/alex.safetensors"), None).unwrap_err();
    assert!(
        e.to_string().contains("/nonexistent/alex.safetensors"),
        "{e}"
    );
}
