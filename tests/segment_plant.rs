//! Part lifting on the harder potted-plant scene (`r4d_segment::synthetic::plant`: a pot with a
//! rim, soil seen only through the opening, a thin curved stem, thin drooping leaves, petals;
//! anisotropic Gaussians with non-unit quaternions in shuffled order; masks ray-cast from the
//! analytic primitives). Accuracy is per part, over the Gaussians some view sees
//! (compositing weight >= 0.05 pixel-equivalents), after the KNN pass.
//!
//! The targets (>= 99.5% with clean masks; >= 97% and no part below 93% with
//! corrupted ones) are reached with clean masks, not with corrupted ones; these tests hold
//! the measured state: with clean masks >= 99% on every seed (>= 99.5% on average) and every
//! stage (label propagation, then the visibility-aware lift) helps on every seed; with
//! corrupted masks the defaults beat the pipeline as it was on every seed and the classic
//! lift on average.

use r4d_segment::mask::MaskData;
use r4d_segment::synthetic::plant::{self, corrupt_parts, mislabel_part, per_part, PlantScene};
use r4d_segment::{segment, InMemoryMasks, LiftConfig, SegmentConfig, SmoothConfig, ViewVote};
use r4d_splat::Camera;

const PARTS: [&str; 5] = ["pot", "soil", "stem", "leaves", "petals"];

fn setup(seed: u64) -> (PlantScene, Vec<Camera>, InMemoryMasks) {
    let scene = plant::potted_plant(30_000, 100 + seed);
    let cams = plant::plant_cameras(8, 256, 256);
    let masks = scene.masks(&cams);
    (scene, cams, masks)
}

/// Every part's mask moved by 2-4 px (eroded or dilated at random), 5% of the pixels
/// flipped, and in one view one part labelled as another.
fn corrupted(masks: &InMemoryMasks, seed: u64) -> InMemoryMasks {
    let mut bad = masks.clone();
    for (v, m) in bad.masks.iter_mut().enumerate() {
        let (w, h) = (m.width, m.height);
        if let MaskData::Labels(l) = &mut m.data {
            corrupt_parts(l, w, h, 5, [2, 4], 0.05, seed * 31 + v as u64);
            if v == seed as usize % 8 {
                mislabel_part(l, 4 + (seed % 2) as u16, 3 - (seed % 2) as u16);
            }
        }
    }
    bad
}

/// Per part (floor first) accuracy over seen Gaussians, and the accuracy over all seen part
/// Gaussians.
fn score(
    scene: &PlantScene,
    cams: &[Camera],
    masks: &InMemoryMasks,
    lift: LiftConfig,
) -> (Vec<f64>, f64) {
    let cfg = SegmentConfig {
        lift,
        smooth: Some(SmoothConfig::default()),
    };
    score_with(scene, cams, masks, cfg)
}

/// The lift and the KNN pass as they were before visibility-aware lifting and label
/// propagation (one vote round).
fn before() -> SegmentConfig {
    SegmentConfig {
        lift: LiftConfig::classic(),
        smooth: Some(SmoothConfig {
            rounds: 1,
            ..Default::default()
        }),
    }
}

fn score_with(
    scene: &PlantScene,
    cams: &[Camera],
    masks: &InMemoryMasks,
    cfg: SegmentConfig,
) -> (Vec<f64>, f64) {
    let out = segment(&scene.gaussians, cams, &mut masks.clone(), &cfg).unwrap();
    let seen = |i: usize| out.lifted.visibility[i] >= 0.05;
    let pp = per_part(&out.labels.labels, &scene.truth, 5, seen);
    let (r, t) = pp[1..].iter().fold((0, 0), |a, b| (a.0 + b.0, a.1 + b.1));
    (
        pp.iter()
            .map(|(r, t)| *r as f64 / (*t).max(1) as f64)
            .collect(),
        r as f64 / t as f64,
    )
}

fn row(name: &str, (per, all): &(Vec<f64>, f64)) -> String {
    let cells: Vec<String> = per[1..]
        .iter()
        .zip(PARTS)
        .map(|(a, p)| format!("{p} {:.1}", 100.0 * a))
        .collect();
    format!("{name:8} all {:.1} | {}", 100.0 * all, cells.join(", "))
}

#[test]
fn clean_masks_per_part_and_every_stage_helps() {
    let mut sum = 0.0;
    for seed in 0..3 {
        let (scene, cams, masks) = setup(seed);
        let old = score_with(&scene, &cams, &masks, before());
        let classic = score(&scene, &cams, &masks, LiftConfig::classic());
        let new = score(&scene, &cams, &masks, LiftConfig::default());
        println!("seed {seed} clean: {}", row("before", &old));
        println!("seed {seed} clean: {}", row("classic", &classic));
        println!("seed {seed} clean: {}", row("default", &new));
        // Propagation helps the classic lift; the visibility-aware lift helps further.
        assert!(
            classic.1 > old.1 + 0.05,
            "seed {seed}: {} vs {}",
            classic.1,
            old.1
        );
        assert!(
            new.1 >= classic.1,
            "seed {seed}: {} vs {}",
            new.1,
            classic.1
        );
        assert!(new.1 >= 0.995, "seed {seed}: {}", new.1);
        sum += new.1;
        // pot, soil, stem, leaves, petals
        for (k, floor) in [0.999, 0.999, 0.97, 0.995, 0.95].into_iter().enumerate() {
            assert!(
                new.0[k + 1] >= floor,
                "seed {seed}, {}: {}",
                PARTS[k],
                new.0[k + 1]
            );
        }
        // The floor (static) stays right.
        assert!(new.0[0] >= 0.999, "seed {seed}, floor: {}", new.0[0]);
    }
    assert!(sum / 3.0 >= 0.995, "mean {}", sum / 3.0);
}

#[test]
fn corrupted_masks_per_part_table() {
    let (mut sum_classic, mut sum_summed, mut sum_new) = (0.0, 0.0, 0.0);
    let seeds = 5;
    for seed in 0..seeds {
        let (scene, cams, masks) = setup(seed);
        let bad = corrupted(&masks, seed);
        let old = score_with(&scene, &cams, &bad, before());
        let classic = score(&scene, &cams, &bad, LiftConfig::classic());
        let summed = score(
            &scene,
            &cams,
            &bad,
            LiftConfig {
                vote: ViewVote::Sum,
                ..Default::default()
            },
        );
        let new = score(&scene, &cams, &bad, LiftConfig::default());
        println!("seed {seed} corrupted: {}", row("before", &old));
        println!("seed {seed} corrupted: {}", row("classic", &classic));
        println!("seed {seed} corrupted: {}", row("sum", &summed));
        println!("seed {seed} corrupted: {}", row("default", &new));
        sum_classic += classic.1;
        sum_summed += summed.1;
        sum_new += new.1;
        assert!(new.1 >= 0.9, "seed {seed}: {}", new.1);
        assert!(new.1 > old.1 + 0.02, "seed {seed}: {} vs {}", new.1, old.1);
        // The per-view confusion matrices keep or improve the worst part on every seed and
        // the total on average; a seed's total may drop a little
        // (seed 4: 94.5% against 97.0%, its stem 69.5% against 50.5%)
        assert!(
            new.1 > summed.1 - 0.03,
            "seed {seed}: {} vs {}",
            new.1,
            summed.1
        );
        let worst = |p: &[f64]| p[1..].iter().copied().fold(1.0, f64::min);
        assert!(
            worst(&new.0) >= worst(&summed.0),
            "seed {seed}: worst part {} vs {}",
            worst(&new.0),
            worst(&summed.0)
        );
        // The static floor survives the corruption.
        assert!(new.0[0] >= 0.97, "seed {seed}, floor: {}", new.0[0]);
    }
    let n = seeds as f64;
    println!(
        "mean over {seeds} seeds: classic {:.4}, sum {:.4}, default (confusion) {:.4}",
        sum_classic / n,
        sum_summed / n,
        sum_new / n
    );
    assert!(
        sum_new >= sum_summed + 0.005 * n,
        "mean {} vs {}",
        sum_new / n,
        sum_summed / n
    );
    assert!(
        sum_new >= sum_classic + 0.06 * n,
        "mean {} vs {}",
        sum_new / n,
        sum_classic / n
    );
}

/// The per-view disagreement diagnostic (leave-one-out) points at a view that labelled a
/// whole part as another; the cross-view consistency option runs and stays within a point of
/// the default with corrupted masks.
#[test]
fn disagreement_points_at_the_mislabelled_view() {
    let (scene, cams, masks) = setup(0);
    for bad_view in [3usize, 5] {
        let mut m = masks.clone();
        if let MaskData::Labels(l) = &mut m.masks[bad_view].data {
            mislabel_part(l, 4, 3); // leaves -> stem
        }
        let cfg = SegmentConfig {
            lift: LiftConfig::default(),
            smooth: Some(SmoothConfig::default()),
        };
        let out = segment(&scene.gaussians, &cams, &mut m, &cfg).unwrap();
        let d = &out.lifted.view_disagreement;
        println!("view {bad_view} mislabelled: disagreement per view {d:?}");
        let mut sorted = d.clone();
        sorted.sort_by(f32::total_cmp);
        let median = sorted[d.len() / 2];
        let worst = (0..d.len()).max_by(|&a, &b| d[a].total_cmp(&d[b])).unwrap();
        assert_eq!(worst, bad_view, "{d:?}");
        assert!(d[bad_view] > 3.0 * median, "{d:?}");
    }
    for seed in 0..2 {
        let (scene, cams, masks) = setup(seed);
        let bad = corrupted(&masks, seed);
        let plain = score(&scene, &cams, &bad, LiftConfig::default());
        let checked = score(
            &scene,
            &cams,
            &bad,
            LiftConfig {
                view_consistency_iters: 1,
                ..Default::default()
            },
        );
        println!("seed {seed} corrupted: {}", row("checked", &checked));
        assert!(
            checked.1 > plain.1 - 0.01,
            "seed {seed}: {} vs {}",
            checked.1,
            plain.1
        );
    }
}
