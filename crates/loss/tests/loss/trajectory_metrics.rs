//! Point-trajectory metrics against `tests/fixtures/metrics` (numpy + scipy cKDTree goldens,
//! copied to `tests/fixtures/metrics`): every variant, every pair, the trajectory means.

use r4d_loss::trajectory::{cloud_metrics, trajectory_metrics, CloudMetrics, REFERENCE_TAUS};
use r4d_testkit::{fixture, read_npz, Array};
use serde_json::Value;

fn cloud(a: &Array) -> Vec<[f64; 3]> {
    a.data.chunks(3).map(|c| [c[0], c[1], c[2]]).collect()
}

fn check(label: &str, got: &CloudMetrics, want: &Value, with_pr: bool) -> f64 {
    let mut worst = 0.0f64;
    let mut cmp = |name: &str, g: f64| {
        let w = want[name]
            .as_f64()
            .unwrap_or_else(|| panic!("{label}: golden {name}"));
        let err = (g - w).abs() / w.abs().max(1e-12);
        assert!(
            (g - w).abs() <= 1e-12 + 1e-9 * w.abs(),
            "{label}: {name} = {g:e}, golden {w:e}"
        );
        worst = worst.max(if w == 0.0 { (g - w).abs() } else { err });
    };
    cmp("cd_sq_sum", got.cd_sq_sum);
    cmp("cd_sq_avg", got.cd_sq_avg);
    cmp("cd_l2_sum", got.cd_l2_sum);
    cmp("cd_l2_avg", got.cd_l2_avg);
    cmp("hd", got.hd);
    cmp("hd95_max_of_directed", got.hd95_max_of_directed);
    cmp("hd95_pooled", got.hd95_pooled);
    if with_pr {
        cmp("cd_sq_pred_to_gt", got.cd_sq_pred_to_gt);
        cmp("cd_sq_gt_to_pred", got.cd_sq_gt_to_pred);
        cmp("p95_pred_to_gt", got.p95_pred_to_gt);
        cmp("p95_gt_to_pred", got.p95_gt_to_pred);
    }
    for f in &got.fscore {
        let key = format!("{}", f.tau);
        let w = &want["fscore"][&key];
        let wf = if with_pr { w["f"].as_f64() } else { w.as_f64() }.unwrap();
        assert!(
            (f.f - wf).abs() <= 1e-12,
            "{label}: F@{key} = {} vs {wf}",
            f.f
        );
        if with_pr {
            assert!((f.precision - w["precision"].as_f64().unwrap()).abs() <= 1e-12);
            assert!((f.recall - w["recall"].as_f64().unwrap()).abs() <= 1e-12);
        }
    }
    worst
}

#[test]
fn every_variant_matches_the_scipy_goldens() {
    let npz = read_npz(&fixture("metrics/pointclouds.npz"));
    let golden: Value = serde_json::from_str(
        &std::fs::read_to_string(fixture("metrics/metrics_goldens.json")).unwrap(),
    )
    .unwrap();
    for pair in golden["pairs"].as_array().unwrap() {
        let name = pair["name"].as_str().unwrap();
        let m = cloud_metrics(
            &cloud(&npz[&format!("{name}_pred")]),
            &cloud(&npz[&format!("{name}_gt")]),
            &REFERENCE_TAUS,
        )
        .unwrap();
        assert_eq!(m.n_pred, pair["n_pred"].as_u64().unwrap() as usize);
        let worst = check(name, &m, pair, true);
        println!("{name}: worst relative error {worst:.2e}");
    }
    let traj = &golden["trajectory"];
    let n = traj["n_frames"].as_u64().unwrap() as usize;
    let pred: Vec<_> = (0..n)
        .map(|t| cloud(&npz[&format!("traj_pred_t{t}")]))
        .collect();
    let gt: Vec<_> = (0..n)
        .map(|t| cloud(&npz[&format!("traj_gt_t{t}")]))
        .collect();
    let m = trajectory_metrics(&pred, &gt, &REFERENCE_TAUS).unwrap();
    for (t, f) in m.per_frame.iter().enumerate() {
        check(
            &format!("trajectory frame {t}"),
            f,
            &traj["per_frame"][t],
            true,
        );
    }
    let worst = check(
        "trajectory mean",
        &m.mean_over_frames,
        &traj["mean_over_frames"],
        false,
    );
    println!("trajectory mean: worst relative error {worst:.2e}");
}
