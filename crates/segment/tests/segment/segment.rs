//! Part assignment (`r4d-segment`) on the synthetic three-part scene: masks ray-cast from the
//! analytic solids (independent of the renderer), lifted onto the Gaussians, smoothed by KNN.
//! Accuracy is the fraction of Gaussians (floor included) with their true label.

use r4d_segment::mask::{write_label_png, write_npy, MaskData};
use r4d_segment::synthetic::{self, accuracy, corrupt, SyntheticScene};
use r4d_segment::{
    lift, segment, Error, InMemoryMasks, LiftConfig, Mask, MaskDir, MaskSource, Par, SegmentConfig,
    SmoothConfig,
};
use r4d_splat::Camera;
use std::path::PathBuf;

const VIEWS: usize = 8;

fn setup() -> (SyntheticScene, Vec<Camera>) {
    (
        synthetic::three_parts(30_000, 11),
        synthetic::ring_cameras(VIEWS, 640, 480),
    )
}

fn part_accuracy(pred: &[i32], truth: &[i32]) -> f64 {
    let idx: Vec<usize> = (0..truth.len()).filter(|&i| truth[i] >= 0).collect();
    let ok = idx.iter().filter(|&&i| pred[i] == truth[i]).count();
    ok as f64 / idx.len() as f64
}

fn tmp(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("r4d_segment_{}_{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

#[test]
fn clean_masks_label_at_least_99_percent() {
    let (scene, cams) = setup();
    let n = scene.truth.len();
    assert!(n > 25_000, "{n}");
    for part in -1..3 {
        assert!(scene.truth.iter().filter(|&&t| t == part).count() > 1000);
    }
    let mut masks = scene.masks(&cams);
    let cfg = SegmentConfig {
        smooth: Some(SmoothConfig::default()),
        ..Default::default()
    };
    let out = segment(&scene.gaussians, &cams, &mut masks, &cfg).unwrap();
    let raw = accuracy(&out.lifted.labels, &scene.truth);
    let knn = accuracy(&out.labels.labels, &scene.truth);
    println!(
        "clean masks, {n} Gaussians, {VIEWS} views: raw lift {:.4} (parts only {:.4}, {} unobserved), after KNN {:.4} (parts only {:.4})",
        raw,
        part_accuracy(&out.lifted.labels, &scene.truth),
        out.lifted.unobserved(),
        knn,
        part_accuracy(&out.labels.labels, &scene.truth),
    );
    assert!(raw >= 0.99, "raw lift {raw}");
    assert!(knn >= 0.99, "after KNN {knn}");
    assert!(part_accuracy(&out.labels.labels, &scene.truth) >= 0.99);
    assert_eq!(out.labels.num_parts, 3);
    assert_eq!(
        out.labels.counts.iter().sum::<usize>(),
        out.labels.labels.iter().filter(|&&l| l >= 0).count()
    );
    // Correct Gaussians are confident, on average.
    let mean_conf: f32 = out.labels.confidence.iter().sum::<f32>() / n as f32;
    assert!(mean_conf > 0.8, "{mean_conf}");
}

#[test]
fn corrupted_masks_at_least_95_percent_after_knn_and_knn_helps() {
    let (scene, cams) = setup();
    let mut masks = scene.masks(&cams);
    let mut changed = 0usize;
    let mut total = 0usize;
    for (v, m) in masks.masks.iter_mut().enumerate() {
        let MaskData::Labels(l) = &mut m.data else {
            unreachable!()
        };
        let before = l.clone();
        corrupt(l, m.width, m.height, 4, 3, 0.05, 100 + v as u64);
        changed += l.iter().zip(&before).filter(|(a, b)| a != b).count();
        total += l.len();
    }
    // The corruption is real: boundaries moved and 5% flipped.
    let frac = changed as f64 / total as f64;
    assert!(frac > 0.06, "{frac}");
    let cfg = SegmentConfig {
        smooth: Some(SmoothConfig::default()),
        ..Default::default()
    };
    let out = segment(&scene.gaussians, &cams, &mut masks, &cfg).unwrap();
    let raw = accuracy(&out.lifted.labels, &scene.truth);
    let knn = accuracy(&out.labels.labels, &scene.truth);
    println!(
        "corrupted masks ({:.1}% of pixels changed): raw lift {raw:.4} (parts only {:.4}), after KNN {knn:.4} (parts only {:.4})",
        100.0 * frac,
        part_accuracy(&out.lifted.labels, &scene.truth),
        part_accuracy(&out.labels.labels, &scene.truth),
    );
    assert!(knn >= 0.95, "after KNN {knn}");
    assert!(knn > raw, "KNN {knn} vs raw {raw}");
}

/// Label masks as one-hot probabilities.
fn one_hot(masks: &InMemoryMasks) -> InMemoryMasks {
    let m = masks.class_names.len();
    InMemoryMasks {
        class_names: masks.class_names.clone(),
        masks: masks
            .masks
            .iter()
            .map(|mk| {
                let MaskData::Labels(l) = &mk.data else {
                    unreachable!()
                };
                let mut p = vec![0f32; l.len() * m];
                for (px, &c) in l.iter().enumerate() {
                    if c > 0 {
                        p[px * m + c as usize - 1] = 1.0;
                    }
                }
                Mask {
                    data: MaskData::Probabilities(p),
                    ..mk.clone()
                }
            })
            .collect(),
    }
}

fn small() -> (SyntheticScene, Vec<Camera>, InMemoryMasks) {
    let scene = synthetic::three_parts(4000, 5);
    let cams = synthetic::ring_cameras(4, 160, 120);
    let masks = scene.masks(&cams);
    (scene, cams, masks)
}

fn close(a: &[f64], b: &[f64], tol: f64) -> bool {
    a.len() == b.len()
        && a.iter()
            .zip(b)
            .all(|(x, y)| (x - y).abs() <= tol * (1.0 + x.abs()))
}

#[test]
fn probability_masks_vote_like_label_masks() {
    let (scene, cams, mut labels) = small();
    let cfg = LiftConfig::default();
    let a = lift(&scene.gaussians, &cams, &mut labels, &cfg).unwrap();
    let mut probs = one_hot(&labels);
    let b = lift(&scene.gaussians, &cams, &mut probs, &cfg).unwrap();
    assert!(close(&a.class_weights, &b.class_weights, 1e-12));
    assert_eq!(a.labels, b.labels);
    assert!(a.labels.contains(&2) && a.labels.contains(&-1));
    // Half-sure masks: the same argmax, lower confidence.
    for mk in probs.masks.iter_mut() {
        if let MaskData::Probabilities(p) = &mut mk.data {
            p.iter_mut().for_each(|v| *v = 0.2 + 0.5 * *v);
        }
    }
    let c = lift(&scene.gaussians, &cams, &mut probs, &cfg).unwrap();
    let seen: Vec<usize> = (0..a.labels.len())
        .filter(|&i| a.total_weight(i) > 0.05)
        .collect();
    let same = seen.iter().filter(|&&i| a.labels[i] == c.labels[i]).count();
    assert!(
        same as f64 > 0.97 * seen.len() as f64,
        "{same} / {}",
        seen.len()
    );
    let mean = |l: &r4d_segment::Lifted| seen.iter().map(|&i| l.confidence[i] as f64).sum::<f64>();
    assert!(mean(&c) < 0.9 * mean(&a), "{} vs {}", mean(&c), mean(&a));
}

#[test]
fn temperature_changes_confidence_not_labels() {
    let (scene, cams, mut masks) = small();
    let mut last: Option<r4d_segment::Lifted> = None;
    for t in [1.0f32, 0.3, 0.1, 0.03] {
        let cfg = LiftConfig {
            temperature: t,
            ..Default::default()
        };
        let l = lift(&scene.gaussians, &cams, &mut masks, &cfg).unwrap();
        if let Some(p) = &last {
            assert_eq!(p.labels, l.labels);
            let (sp, sl): (f32, f32) = (p.confidence.iter().sum(), l.confidence.iter().sum());
            assert!(sl > sp, "temperature {t}: {sl} <= {sp}");
        }
        last = Some(l);
    }
    let e = lift(
        &scene.gaussians,
        &cams,
        &mut masks,
        &LiftConfig {
            temperature: 0.0,
            ..Default::default()
        },
    )
    .unwrap_err();
    assert!(matches!(e, Error::Input(_)), "{e}");
}

#[test]
fn parallel_lift_matches_serial() {
    let (scene, cams, mut masks) = small();
    let seq = LiftConfig {
        par: Par::Seq,
        ..Default::default()
    };
    let a = lift(&scene.gaussians, &cams, &mut masks, &seq).unwrap();
    let b = lift(&scene.gaussians, &cams, &mut masks, &LiftConfig::default()).unwrap();
    assert!(close(&a.class_weights, &b.class_weights, 1e-9));
    assert_eq!(a.labels, b.labels);
}

/// Gaussians inside the box are occluded by its faces: the lift gives them little weight
/// (alpha T behind the surface is small; the synthetic surface is a single layer of discs
/// that lets a few percent through, where a weight without T would be of the faces' order),
/// and the KNN pass gives them the box's label.
/// Gaussians outside every view get no weight at all: label -1, confidence 0.
#[test]
fn occluded_and_unseen_gaussians() {
    let mut scene = synthetic::three_parts(6000, 8);
    let cams = synthetic::ring_cameras(6, 200, 150);
    let g = &mut scene.gaussians;
    let mut r = synthetic::Rng(3);
    let first = g.len();
    let add = |g: &mut r4d_splat::Gaussians, p: [f64; 3]| {
        g.means.push(p.map(|v| v as f32));
        g.log_scales.push([-4.5; 3]);
        g.quats.push([1.0, 0.0, 0.0, 0.0]);
        g.opacity_logits.push(3.0);
        g.sh.extend([0.0; 3]);
    };
    for _ in 0..400 {
        let p = [r.range(-0.5, 0.2), r.range(-0.35, 0.35), r.range(0.05, 0.4)];
        add(g, p);
        scene.truth.push(0);
    }
    // High above the scene: in no camera's field of view.
    for k in 0..50 {
        add(g, [0.01 * k as f64, 0.0, 8.0]);
    }
    let mut masks = scene.masks(&cams);
    let cfg = SegmentConfig {
        smooth: Some(SmoothConfig::default()),
        ..Default::default()
    };
    let out = segment(&scene.gaussians, &cams, &mut masks, &cfg).unwrap();
    let lf = &out.lifted;
    let inside = first..first + 400;
    let mut w_in: Vec<f64> = inside.clone().map(|i| lf.total_weight(i)).collect();
    let mut w_surf: Vec<f64> = (0..first)
        .filter(|&i| scene.truth[i] == 0)
        .map(|i| lf.total_weight(i))
        .collect();
    w_in.sort_by(f64::total_cmp);
    w_surf.sort_by(f64::total_cmp);
    let (med_in, med_surf) = (w_in[w_in.len() / 2], w_surf[w_surf.len() / 2]);
    println!("median total weight: inside the box {med_in:.2e}, on its faces {med_surf:.2e}");
    assert!(med_in < 0.1 * med_surf, "{med_in} vs {med_surf}");
    let ok = inside
        .clone()
        .filter(|&i| out.labels.labels[i] == 0)
        .count();
    assert!(ok >= 390, "{ok} of 400 interior Gaussians labelled box");
    let above = first + 400..first + 450;
    assert_eq!(lf.unobserved(), 50);
    assert!(above
        .clone()
        .all(|i| lf.labels[i] == -1 && lf.confidence[i] == 0.0));
    // The smoothing gives them the label of the nearest seen Gaussian, with confidence 0.
    assert!(above.clone().all(|i| out.labels.confidence[i] == 0.0));
}

fn cam_names(cams: &[Camera]) -> Vec<String> {
    cams.iter()
        .map(|c| c.name.trim_end_matches(".png").to_string())
        .collect()
}

/// Every file format of a mask folder gives the lift of the in-memory masks.
#[test]
fn mask_dir_reads_every_format() {
    let (scene, cams, mut mem) = small();
    let names = cam_names(&cams);
    let dir = tmp("formats");
    std::fs::write(
        dir.join("classes.json"),
        r#"{"class_names": ["box", "ball", "post"], "ignore": 255}"#,
    )
    .unwrap();
    let m = 3;
    for (v, mk) in mem.masks.iter().enumerate() {
        let MaskData::Labels(l) = &mk.data else {
            unreachable!()
        };
        let (w, h) = (mk.width as usize, mk.height as usize);
        let plane = |k: usize| -> Vec<f32> {
            l.iter()
                .map(|&c| (c as usize == k + 1) as u8 as f32)
                .collect()
        };
        match v {
            // A label PNG named after the camera.
            0 => write_label_png(
                &dir.join(format!("{}.png", names[v])),
                mk.width,
                mk.height,
                l,
            )
            .unwrap(),
            // Stacked probabilities named by the camera's index.
            1 => {
                let data: Vec<f32> = (0..m).flat_map(plane).collect();
                write_npy(&dir.join("0001.npy"), &[m, h, w], &data).unwrap();
            }
            // Per-class PNGs.
            2 => {
                let sub = dir.join(&names[v]);
                std::fs::create_dir_all(&sub).unwrap();
                for (k, name) in ["box", "ball", "post"].iter().enumerate() {
                    let b: Vec<u8> = plane(k).iter().map(|&p| (p * 255.0) as u8).collect();
                    image::GrayImage::from_raw(mk.width, mk.height, b)
                        .unwrap()
                        .save(sub.join(format!("{name}.png")))
                        .unwrap();
                }
            }
            // Per-class .npy.
            _ => {
                let sub = dir.join(v.to_string());
                std::fs::create_dir_all(&sub).unwrap();
                for (k, name) in ["box", "ball", "post"].iter().enumerate() {
                    write_npy(&sub.join(format!("{name}.npy")), &[h, w], &plane(k)).unwrap();
                }
            }
        }
    }
    let mut files = MaskDir::open(&dir, &cams).unwrap();
    assert_eq!(files.class_names(), ["box", "ball", "post"]);
    let cfg = LiftConfig::default();
    let a = lift(&scene.gaussians, &cams, &mut mem, &cfg).unwrap();
    let b = lift(&scene.gaussians, &cams, &mut files, &cfg).unwrap();
    assert!(close(&a.class_weights, &b.class_weights, 1e-9));
    // Without classes.json the names come from the per-class maps.
    std::fs::remove_file(dir.join("classes.json")).unwrap();
    let files = MaskDir::open(&dir, &cams).unwrap();
    assert_eq!(files.class_names(), ["ball", "box", "post"]);
    // Ignored pixels vote for nothing.
    let dir = tmp("ignore");
    std::fs::write(
        dir.join("classes.json"),
        r#"{"class_names": ["a", "b", "c"], "ignore": 255}"#,
    )
    .unwrap();
    for (v, c) in cams.iter().enumerate() {
        let l = vec![255u16; (c.width * c.height) as usize];
        write_label_png(&dir.join(format!("{v}.png")), c.width, c.height, &l).unwrap();
    }
    let mut files = MaskDir::open(&dir, &cams).unwrap();
    let l = lift(&scene.gaussians, &cams, &mut files, &cfg).unwrap();
    assert_eq!(l.unobserved(), scene.truth.len());
}

fn label_dir(name: &str, cams: &[Camera], masks: &InMemoryMasks) -> PathBuf {
    let dir = tmp(name);
    for (v, mk) in masks.masks.iter().enumerate() {
        let MaskData::Labels(l) = &mk.data else {
            unreachable!()
        };
        write_label_png(&dir.join(format!("{v}.png")), mk.width, mk.height, l).unwrap();
    }
    let _ = cams;
    dir
}

#[test]
fn bad_masks_are_typed_errors_naming_the_file() {
    let (scene, cams, mem) = small();
    let g = &scene.gaussians;
    let cfg = LiftConfig::default();
    let run = |dir: &std::path::Path| -> Result<(), Error> {
        let mut files = MaskDir::open(dir, &cams)?;
        lift(g, &cams, &mut files, &cfg).map(|_| ())
    };
    // A view without a mask.
    let dir = label_dir("missing", &cams, &mem);
    std::fs::remove_file(dir.join("2.png")).unwrap();
    let e = run(&dir).unwrap_err();
    assert!(matches!(e, Error::NoMask { view: 2, .. }), "{e}");
    let msg = e.to_string();
    assert!(
        msg.contains("missing") && msg.contains("view_02") && msg.contains("0002.png"),
        "{msg}"
    );
    // A mask of the wrong size.
    let dir = label_dir("size", &cams, &mem);
    write_label_png(&dir.join("1.png"), 100, 120, &vec![0; 12000]).unwrap();
    let e = run(&dir).unwrap_err();
    assert!(
        matches!(
            e,
            Error::MaskSize {
                view: 1,
                got_w: 100,
                want_w: 160,
                ..
            }
        ),
        "{e}"
    );
    assert!(e.to_string().contains("1.png"), "{e}");
    // A label naming no class.
    let dir = label_dir("unknown", &cams, &mem);
    std::fs::write(
        dir.join("classes.json"),
        r#"{"class_names": ["box", "ball", "post"]}"#,
    )
    .unwrap();
    let mut l = vec![0u16; 160 * 120];
    l[5 * 160 + 7] = 9;
    write_label_png(&dir.join("3.png"), 160, 120, &l).unwrap();
    let e = run(&dir).unwrap_err();
    assert!(
        matches!(
            e,
            Error::UnknownLabel {
                x: 7,
                y: 5,
                value: 9,
                ..
            }
        ),
        "{e}"
    );
    assert!(e.to_string().contains("3.png"), "{e}");
    // Without classes.json the largest label sets the number of parts instead.
    std::fs::remove_file(dir.join("classes.json")).unwrap();
    assert_eq!(MaskDir::open(&dir, &cams).unwrap().class_names().len(), 9);
    // A colour PNG as a label map.
    let dir = label_dir("rgb", &cams, &mem);
    image::RgbImage::new(160, 120)
        .save(dir.join("0.png"))
        .unwrap();
    let e = run(&dir).unwrap_err();
    assert!(
        e.to_string().contains("0.png") && e.to_string().contains("grayscale"),
        "{e}"
    );
    // Malformed classes.json.
    let dir = label_dir("classes", &cams, &mem);
    std::fs::write(dir.join("classes.json"), r#"{"names": ["a"]}"#).unwrap();
    let e = run(&dir).unwrap_err();
    assert!(
        matches!(e, Error::Classes { .. }) && e.to_string().contains("classes.json"),
        "{e}"
    );
    // Per-class maps: an undeclared class, a missing class, values outside [0, 1], a dtype.
    let dir = tmp("perclass");
    std::fs::write(dir.join("classes.json"), r#"{"class_names": ["a", "b"]}"#).unwrap();
    for v in 0..cams.len() {
        let sub = dir.join(v.to_string());
        std::fs::create_dir_all(&sub).unwrap();
        for c in ["a", "b"] {
            write_npy(
                &sub.join(format!("{c}.npy")),
                &[120, 160],
                &vec![0.25; 19200],
            )
            .unwrap();
        }
    }
    assert!(run(&dir).is_ok());
    write_npy(
        &dir.join("1").join("wheel.npy"),
        &[120, 160],
        &vec![0.0; 19200],
    )
    .unwrap();
    let e = run(&dir).unwrap_err();
    assert!(
        matches!(e, Error::UnknownClass { .. }) && e.to_string().contains("wheel.npy"),
        "{e}"
    );
    std::fs::remove_file(dir.join("1").join("wheel.npy")).unwrap();
    std::fs::remove_file(dir.join("1").join("b.npy")).unwrap();
    let e = run(&dir).unwrap_err();
    assert!(e.to_string().contains("no map for class 'b'"), "{e}");
    write_npy(&dir.join("1").join("b.npy"), &[120, 160], &vec![1.5; 19200]).unwrap();
    let e = run(&dir).unwrap_err();
    assert!(
        e.to_string().contains("b.npy") && e.to_string().contains("[0, 1]"),
        "{e}"
    );
    let mut bytes = std::fs::read(dir.join("0").join("a.npy")).unwrap();
    let at = bytes.windows(3).position(|w| w == b"<f4").unwrap();
    bytes[at..at + 3].copy_from_slice(b"|u1");
    std::fs::write(dir.join("1").join("b.npy"), &bytes).unwrap();
    let e = run(&dir).unwrap_err();
    assert!(
        e.to_string().contains("b.npy") && e.to_string().contains("|u1"),
        "{e}"
    );
}
