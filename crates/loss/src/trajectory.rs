//! Point-trajectory metrics: Chamfer distance, Hausdorff distance and its 95th percentile, and
//! F-score between a simulated (predicted) point cloud P and a ground-truth cloud Q, per frame
//! and over a sequence, with every variant of `tests/fixtures/metrics/README.md`.
//!
//! With `d_PQ(p) = min_q |p - q|` (exact Euclidean nearest neighbours from a kd-tree, the
//! `kiddo` crate) and `d_QP` likewise:
//!
//! | name | definition |
//! |---|---|
//! | `cd_sq_sum` (**default `cd`**) | `mean_p d_PQ^2 + mean_q d_QP^2` (pytorch3d's `chamfer_distance`, PhysFlow's loss) |
//! | `cd_sq_avg` | half of `cd_sq_sum` |
//! | `cd_l2_sum` / `cd_l2_avg` | the same with unsquared distances |
//! | `hd` | `max(max_p d_PQ, max_q d_QP)` |
//! | `hd95_max_of_directed` (**default `hd95`**) | `max(P95(d_PQ), P95(d_QP))` |
//! | `hd95_pooled` | `P95` of both directed distance sets pooled |
//! | `fscore(tau)` | `2 P R / (P + R)`, precision `P` = fraction of p with `d_PQ < tau`, recall likewise; 0 when `P + R = 0` (**default tau = 0.04**, a few hundredths of a unit-sized scene) |
//!
//! Percentiles interpolate linearly between order statistics (numpy's default). Over a
//! sequence, every metric is the plain mean over frames (the F-score: the mean of per-frame F).
//! The paper does not define its variants; the defaults above follow the magnitudes of its
//! Table 3 (squared distances for CD) and are stated in the CLI output.

use kiddo::{ImmutableKdTree, SquaredEuclidean};
use serde::Serialize;

/// Precision, recall and F-score at one threshold.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct FScore {
    /// Threshold (scene units).
    pub tau: f64,
    /// Fraction of predicted points within `tau` of the ground truth (strict).
    pub precision: f64,
    /// Fraction of ground-truth points within `tau` of the prediction (strict).
    pub recall: f64,
    /// `2 P R / (P + R)` (0 when both are 0).
    pub f: f64,
}

/// Every variant of the point-cloud metrics for one pair of clouds.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct CloudMetrics {
    /// Predicted points.
    pub n_pred: usize,
    /// Ground-truth points.
    pub n_gt: usize,
    /// `mean d_PQ^2 + mean d_QP^2` (the default Chamfer distance).
    pub cd_sq_sum: f64,
    /// Half of `cd_sq_sum`.
    pub cd_sq_avg: f64,
    /// `mean d_PQ + mean d_QP`.
    pub cd_l2_sum: f64,
    /// Half of `cd_l2_sum`.
    pub cd_l2_avg: f64,
    /// `mean d_PQ^2`.
    pub cd_sq_pred_to_gt: f64,
    /// `mean d_QP^2`.
    pub cd_sq_gt_to_pred: f64,
    /// Hausdorff distance.
    pub hd: f64,
    /// `max(P95(d_PQ), P95(d_QP))` (the default HD95).
    pub hd95_max_of_directed: f64,
    /// `P95` of the pooled directed distances.
    pub hd95_pooled: f64,
    /// `P95(d_PQ)`.
    pub p95_pred_to_gt: f64,
    /// `P95(d_QP)`.
    pub p95_gt_to_pred: f64,
    /// F-scores at the requested thresholds.
    pub fscore: Vec<FScore>,
}

/// Errors of the trajectory metrics.
#[derive(Debug, thiserror::Error)]
pub enum TrajectoryError {
    /// A cloud is empty.
    #[error("{0}: empty point cloud")]
    Empty(String),
    /// A coordinate is not finite.
    #[error("{what}: point {index} is not finite")]
    NotFinite {
        /// Which cloud.
        what: String,
        /// The point.
        index: usize,
    },
    /// Sequences of different lengths.
    #[error("{reference} frames in the reference, {simulated} in the simulation")]
    FrameCount {
        /// Reference frames.
        reference: usize,
        /// Simulated frames.
        simulated: usize,
    },
}

/// The default F-score threshold.
pub const DEFAULT_TAU: f64 = 0.04;

/// The thresholds of the reference table.
pub const REFERENCE_TAUS: [f64; 6] = [0.005, 0.01, 0.02, 0.04, 0.05, 0.1];

fn check(c: &[[f64; 3]], what: &str) -> Result<(), TrajectoryError> {
    if c.is_empty() {
        return Err(TrajectoryError::Empty(what.to_string()));
    }
    if let Some(index) = c.iter().position(|p| p.iter().any(|v| !v.is_finite())) {
        return Err(TrajectoryError::NotFinite {
            what: what.to_string(),
            index,
        });
    }
    Ok(())
}

/// Distances from every point of `from` to its nearest neighbour in `to`.
pub fn nearest_distances(from: &[[f64; 3]], to: &[[f64; 3]]) -> Vec<f64> {
    let tree: ImmutableKdTree<f64, 3> = ImmutableKdTree::new_from_slice(to);
    from.iter()
        .map(|p| {
            tree.nearest_one::<SquaredEuclidean>(p)
                .distance
                .max(0.0)
                .sqrt()
        })
        .collect()
}

/// numpy's default percentile (linear interpolation at position `(n - 1) q / 100`).
pub fn percentile(values: &[f64], q: f64) -> f64 {
    let mut v = values.to_vec();
    v.sort_by(f64::total_cmp);
    let pos = (v.len() - 1) as f64 * q / 100.0;
    let lo = pos.floor() as usize;
    let hi = pos.ceil() as usize;
    v[lo] + (v[hi] - v[lo]) * (pos - lo as f64)
}

fn mean(v: &[f64]) -> f64 {
    v.iter().sum::<f64>() / v.len() as f64
}

/// Every metric for one pair of clouds (`pred` = simulated, `gt` = ground truth).
pub fn cloud_metrics(
    pred: &[[f64; 3]],
    gt: &[[f64; 3]],
    taus: &[f64],
) -> Result<CloudMetrics, TrajectoryError> {
    check(pred, "simulated cloud")?;
    check(gt, "reference cloud")?;
    let d_pq = nearest_distances(pred, gt);
    let d_qp = nearest_distances(gt, pred);
    let sq = |d: &[f64]| mean(&d.iter().map(|x| x * x).collect::<Vec<_>>());
    let (sq_pq, sq_qp) = (sq(&d_pq), sq(&d_qp));
    let (l_pq, l_qp) = (mean(&d_pq), mean(&d_qp));
    let max = |d: &[f64]| d.iter().copied().fold(0.0, f64::max);
    let (p95_pq, p95_qp) = (percentile(&d_pq, 95.0), percentile(&d_qp, 95.0));
    let pooled: Vec<f64> = d_pq.iter().chain(&d_qp).copied().collect();
    let fscore = taus
        .iter()
        .map(|&tau| {
            let precision = d_pq.iter().filter(|&&d| d < tau).count() as f64 / d_pq.len() as f64;
            let recall = d_qp.iter().filter(|&&d| d < tau).count() as f64 / d_qp.len() as f64;
            let f = if precision + recall > 0.0 {
                2.0 * precision * recall / (precision + recall)
            } else {
                0.0
            };
            FScore {
                tau,
                precision,
                recall,
                f,
            }
        })
        .collect();
    Ok(CloudMetrics {
        n_pred: pred.len(),
        n_gt: gt.len(),
        cd_sq_sum: sq_pq + sq_qp,
        cd_sq_avg: 0.5 * (sq_pq + sq_qp),
        cd_l2_sum: l_pq + l_qp,
        cd_l2_avg: 0.5 * (l_pq + l_qp),
        cd_sq_pred_to_gt: sq_pq,
        cd_sq_gt_to_pred: sq_qp,
        hd: max(&d_pq).max(max(&d_qp)),
        hd95_max_of_directed: p95_pq.max(p95_qp),
        hd95_pooled: percentile(&pooled, 95.0),
        p95_pred_to_gt: p95_pq,
        p95_gt_to_pred: p95_qp,
        fscore,
    })
}

/// Per-frame metrics of two sequences and their means over frames.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct TrajectoryMetrics {
    /// One entry per frame.
    pub per_frame: Vec<CloudMetrics>,
    /// Mean over frames of every scalar metric (F-score: mean of the per-frame F, stored in
    /// `f` of each threshold; precision and recall are averaged too).
    pub mean_over_frames: CloudMetrics,
}

/// Metrics of every frame pair and their means.
pub fn trajectory_metrics(
    pred: &[Vec<[f64; 3]>],
    gt: &[Vec<[f64; 3]>],
    taus: &[f64],
) -> Result<TrajectoryMetrics, TrajectoryError> {
    if pred.len() != gt.len() || pred.is_empty() {
        return Err(TrajectoryError::FrameCount {
            reference: gt.len(),
            simulated: pred.len(),
        });
    }
    let per_frame = pred
        .iter()
        .zip(gt)
        .map(|(p, q)| cloud_metrics(p, q, taus))
        .collect::<Result<Vec<_>, _>>()?;
    let n = per_frame.len() as f64;
    let avg = |f: &dyn Fn(&CloudMetrics) -> f64| per_frame.iter().map(f).sum::<f64>() / n;
    let mean_over_frames = CloudMetrics {
        n_pred: per_frame.iter().map(|m| m.n_pred).sum::<usize>() / per_frame.len(),
        n_gt: per_frame.iter().map(|m| m.n_gt).sum::<usize>() / per_frame.len(),
        cd_sq_sum: avg(&|m| m.cd_sq_sum),
        cd_sq_avg: avg(&|m| m.cd_sq_avg),
        cd_l2_sum: avg(&|m| m.cd_l2_sum),
        cd_l2_avg: avg(&|m| m.cd_l2_avg),
        cd_sq_pred_to_gt: avg(&|m| m.cd_sq_pred_to_gt),
        cd_sq_gt_to_pred: avg(&|m| m.cd_sq_gt_to_pred),
        hd: avg(&|m| m.hd),
        hd95_max_of_directed: avg(&|m| m.hd95_max_of_directed),
        hd95_pooled: avg(&|m| m.hd95_pooled),
        p95_pred_to_gt: avg(&|m| m.p95_pred_to_gt),
        p95_gt_to_pred: avg(&|m| m.p95_gt_to_pred),
        fscore: (0..taus.len())
            .map(|k| FScore {
                tau: taus[k],
                precision: avg(&|m| m.fscore[k].precision),
                recall: avg(&|m| m.fscore[k].recall),
                f: avg(&|m| m.fscore[k].f),
            })
            .collect(),
    };
    Ok(TrajectoryMetrics {
        per_frame,
        mean_over_frames,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn percentile_matches_numpy() {
        // np.percentile([1, 2, 3, 4, 10], 95) = 8.8
        assert!((percentile(&[4.0, 1.0, 10.0, 3.0, 2.0], 95.0) - 8.8).abs() < 1e-12);
        assert_eq!(percentile(&[7.0], 95.0), 7.0);
    }

    #[test]
    fn translated_cloud_has_the_shift_as_distance() {
        let p: Vec<[f64; 3]> = (0..50).map(|i| [i as f64, 0.0, 0.0]).collect();
        let q: Vec<[f64; 3]> = p.iter().map(|x| [x[0], 0.01, 0.0]).collect();
        let m = cloud_metrics(&p, &q, &[0.005, 0.02]).unwrap();
        assert!((m.cd_l2_avg - 0.01).abs() < 1e-12 && (m.hd - 0.01).abs() < 1e-12);
        assert_eq!(m.fscore[0].f, 0.0);
        assert_eq!(m.fscore[1].f, 1.0);
        assert!(cloud_metrics(&[], &q, &[]).is_err());
    }
}
