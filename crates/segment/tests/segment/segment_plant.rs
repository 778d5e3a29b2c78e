//! Part lifting on the harder potted-plant scene (`r4d_segment::synthetic::plant`: a pot with a
//! rim, soil seen only through the opening, a thin curved stem, thin drooping leaves, petals;
//! anisotropic Gaussians with non-unit quaternions in shuffled order; masks ray-cast from the
//! analytic primitives). Accuracy is per part, over the Gaussians some view sees
//! (compositing weight >= 0.05 pixel-equivalents), after the KNN pass.
//!
//! The targets (>= 99.5% with clean masks; >= 97% and no part below 93% with
//! corrupted ones) are reached on every seed tested here; every stage (label propagation,
//! the visibility-aware lift, the region prior, its appearance term) keeps or improves every
//! seed, and the region prior costs little where parts share a smooth surface.

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
/// Gaussians, with the default KNN pass (`regions`: with the smooth-surface region prior).
fn score(
    scene: &PlantScene,
    cams: &[Camera],
    masks: &InMemoryMasks,
    lift: LiftConfig,
    regions: bool,
) -> (Vec<f64>, f64) {
    let cfg = SegmentConfig {
        lift,
        smooth: Some(if regions {
            SmoothConfig::default()
        } else {
            no_regions()
        }),
    };
    score_with(scene, cams, masks, cfg)
}

/// The default KNN pass without the region prior.
fn no_regions() -> SmoothConfig {
    SmoothConfig {
        region_tau: 0.0,
        ..Default::default()
    }
}

/// The lift and the KNN pass as they were before visibility-aware lifting, label
/// propagation and the region prior (one vote round).
fn before() -> SegmentConfig {
    SegmentConfig {
        lift: LiftConfig::classic(),
        smooth: Some(SmoothConfig {
            rounds: 1,
            ..no_regions()
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
        let classic = score(&scene, &cams, &masks, LiftConfig::classic(), false);
        let lift = score(&scene, &cams, &masks, LiftConfig::default(), false);
        let new = score(&scene, &cams, &masks, LiftConfig::default(), true);
        println!("seed {seed} clean: {}", row("before", &old));
        println!("seed {seed} clean: {}", row("classic", &classic));
        println!("seed {seed} clean: {}", row("lift", &lift));
        println!("seed {seed} clean: {}", row("default", &new));
        // Propagation helps the classic lift; the visibility-aware lift helps further; the
        // region prior keeps it.
        assert!(
            classic.1 > old.1 + 0.05,
            "seed {seed}: {} vs {}",
            classic.1,
            old.1
        );
        assert!(
            lift.1 >= classic.1,
            "seed {seed}: {} vs {}",
            lift.1,
            classic.1
        );
        assert!(
            new.1 >= lift.1 - 0.001,
            "seed {seed}: {} vs {}",
            new.1,
            lift.1
        );
        assert!(new.1 >= 0.995, "seed {seed}: {}", new.1);
        sum += new.1;
        // pot, soil, stem, leaves, petals
        for (k, floor) in [0.999, 0.999, 0.98, 0.995, 0.95].into_iter().enumerate() {
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
    assert!(sum / 3.0 >= 0.998, "mean {}", sum / 3.0);
}

#[test]
fn corrupted_masks_per_part_table() {
    let seeds = 5;
    let mut sums = [0.0; 4];
    let worst = |p: &[f64]| p[1..].iter().copied().fold(1.0, f64::min);
    for seed in 0..seeds {
        let (scene, cams, masks) = setup(seed);
        let bad = corrupted(&masks, seed);
        let old = score_with(&scene, &cams, &bad, before());
        let summed = score(
            &scene,
            &cams,
            &bad,
            LiftConfig {
                vote: ViewVote::Sum,
                ..Default::default()
            },
            false,
        );
        let lift = score(&scene, &cams, &bad, LiftConfig::default(), false);
        let new = score(&scene, &cams, &bad, LiftConfig::default(), true);
        println!("seed {seed} corrupted: {}", row("before", &old));
        println!("seed {seed} corrupted: {}", row("sum", &summed));
        println!("seed {seed} corrupted: {}", row("confusion", &lift));
        println!("seed {seed} corrupted: {}", row("default", &new));
        for (s, x) in sums.iter_mut().zip([&old, &summed, &lift, &new]) {
            *s += x.1;
        }
        assert!(new.1 > old.1 + 0.02, "seed {seed}: {} vs {}", new.1, old.1);
        // The region prior keeps or improves every seed's total and its worst part.
        assert!(new.1 >= lift.1, "seed {seed}: {} vs {}", new.1, lift.1);
        assert!(
            worst(&new.0) >= worst(&lift.0),
            "seed {seed}: worst part {} vs {}",
            worst(&new.0),
            worst(&lift.0)
        );
        // The target: 97%, and no part under 93%.
        assert!(new.1 >= 0.97, "seed {seed}: {}", new.1);
        assert!(worst(&new.0) >= 0.93, "seed {seed}: {:?}", new.0);
        // The static floor survives the corruption.
        assert!(new.0[0] >= 0.97, "seed {seed}, floor: {}", new.0[0]);
    }
    let n = seeds as f64;
    println!(
        "mean over {seeds} seeds: before {:.4}, sum {:.4}, confusion {:.4}, default (confusion + regions) {:.4}",
        sums[0] / n,
        sums[1] / n,
        sums[2] / n,
        sums[3] / n
    );
    assert!(sums[3] / n >= 0.995, "mean {}", sums[3] / n);
    assert!(sums[2] >= sums[1] + 0.005 * n, "{sums:?}");
}

/// The appearance term of the region prior on the seeds where the region prior alone misses
/// the target (corrupted masks): the pot's inner wall, which most views' dilated soil
/// masks cover (seeds 1, 9), a leaf that most views erode into the soil behind it (seed 12),
/// a leaf given to the soil on another (seed 14). Without it each misses (a part under 93% or
/// the total under 97%); with it each reaches the target, and no part loses more than half a
/// point.
#[test]
fn appearance_reaches_the_target_where_regions_alone_miss() {
    let worst = |p: &[f64]| p[1..].iter().copied().fold(1.0, f64::min);
    for seed in [1u64, 9, 12, 14] {
        let (scene, cams, masks) = setup(seed);
        let bad = corrupted(&masks, seed);
        let run = |appearance: f32| {
            let cfg = SegmentConfig {
                lift: LiftConfig::default(),
                smooth: Some(SmoothConfig {
                    appearance,
                    ..Default::default()
                }),
            };
            score_with(&scene, &cams, &bad, cfg)
        };
        let (off, on) = (run(0.0), run(SmoothConfig::default().appearance));
        println!("seed {seed} corrupted: {}", row("no app.", &off));
        println!("seed {seed} corrupted: {}", row("default", &on));
        assert!(
            off.1 < 0.97 || worst(&off.0) < 0.93,
            "seed {seed} met the target without appearance: {off:?}"
        );
        assert!(on.1 >= 0.97, "seed {seed}: {}", on.1);
        assert!(worst(&on.0) >= 0.93, "seed {seed}: {:?}", on.0);
        for (k, (a, b)) in off.0.iter().zip(&on.0).enumerate() {
            assert!(*b >= a - 0.005, "seed {seed} class {k}: {b} vs {a}");
        }
    }
}

/// The region prior's one-sided static term on the seed where, with the appearance term,
/// the target was still missed: a petal's rim that most views' eroded masks give to the
/// static scene (seed 28: petals 86% without it). With it the petals reach the target and
/// the static scene stays right.
#[test]
fn static_prior_keeps_a_petal_rim_that_eroded_masks_give_away() {
    let seed = 28;
    let (scene, cams, masks) = setup(seed);
    let bad = corrupted(&masks, seed);
    let run = |region_static_power: f32| {
        let cfg = SegmentConfig {
            lift: LiftConfig::default(),
            smooth: Some(SmoothConfig {
                region_static_power,
                ..Default::default()
            }),
        };
        score_with(&scene, &cams, &bad, cfg)
    };
    let (off, on) = (run(0.0), run(SmoothConfig::default().region_static_power));
    println!("seed {seed} corrupted: {}", row("no static", &off));
    println!("seed {seed} corrupted: {}", row("default", &on));
    assert!(
        off.0[5] < 0.93,
        "petals without the static term: {:?}",
        off.0
    );
    assert!(on.0[5] >= 0.97, "petals: {:?}", on.0);
    assert!(on.1 >= 0.97 && on.0[0] >= 0.999, "{on:?}");
}

/// Parts that share a smooth surface, where the region prior has no crease to stop at: the
/// three-part scene with its floor split at `x = -0.3` into a part and static (one plane,
/// two labels), and into two parts. With clean and corrupted masks the region prior costs
/// these splits at most a little (measured with corrupted masks against no prior: the
/// part-or-static split's static side up to 1.3 points, from the one-sided static term,
/// which alone costs it 1.7; the two-part split up to 1.0 point of the smaller part).
#[test]
fn parts_on_one_smooth_surface_keep_their_boundary() {
    use r4d_segment::synthetic::{self, corrupt, Solid};
    for (two, seed) in [(false, 0u64), (false, 1), (true, 0), (true, 1)] {
        let mut scene = synthetic::three_parts(20_000, seed + 1);
        scene.solids.push((
            Solid::Box {
                min: [-1.0, -1.0, -0.01],
                max: [-0.3, 1.0, 0.0005],
            },
            3,
        ));
        scene.class_names.push("left".into());
        if two {
            scene.solids.push((
                Solid::Box {
                    min: [-0.3, -1.0, -0.01],
                    max: [1.0, 1.0, 0.0005],
                },
                4,
            ));
            scene.class_names.push("right".into());
        }
        for (t, p) in scene.truth.iter_mut().zip(&scene.gaussians.means) {
            if *t == -1 && p[0] < -0.3 {
                *t = 3;
            } else if *t == -1 && two {
                *t = 4;
            }
        }
        let np = scene.class_names.len();
        let cams = synthetic::ring_cameras(8, 160, 120);
        let clean = scene.masks(&cams);
        let mut bad = clean.clone();
        for (v, m) in bad.masks.iter_mut().enumerate() {
            let (w, h) = (m.width, m.height);
            if let MaskData::Labels(l) = &mut m.data {
                corrupt(l, w, h, np as u16 + 1, 3, 0.05, 100 * seed + v as u64);
            }
        }
        for (name, masks) in [("clean", &clean), ("corrupted", &bad)] {
            let run = |smooth: SmoothConfig| {
                let cfg = SegmentConfig {
                    lift: LiftConfig::default(),
                    smooth: Some(smooth),
                };
                let out = segment(&scene.gaussians, &cams, &mut masks.clone(), &cfg).unwrap();
                let seen = |i: usize| out.lifted.visibility[i] >= 0.05;
                per_part(&out.labels.labels, &scene.truth, np, seen)
                    .iter()
                    .map(|(r, t)| (*t > 0).then(|| *r as f64 / *t as f64))
                    .collect::<Vec<_>>()
            };
            let (off, on) = (run(no_regions()), run(SmoothConfig::default()));
            println!("split (two parts: {two}) seed {seed} {name}: static, box, ball, post, left[, right]: without regions {off:.3?}, with {on:.3?}");
            for (k, (a, b)) in off.iter().zip(&on).enumerate() {
                if let (Some(a), Some(b)) = (a, b) {
                    assert!(
                        *b >= a - 0.025,
                        "two {two} seed {seed} {name} class {k}: {b} vs {a}"
                    );
                }
            }
        }
    }
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
        let plain = score(&scene, &cams, &bad, LiftConfig::default(), true);
        let checked = score(
            &scene,
            &cams,
            &bad,
            LiftConfig {
                view_consistency_iters: 1,
                ..Default::default()
            },
            true,
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
