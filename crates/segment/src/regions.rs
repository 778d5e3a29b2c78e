//! Smooth-surface regions of the Gaussians and the part prior they give.
//!
//! **Regions.** Felzenszwalb and Huttenlocher's graph segmentation over the KNN graph (as
//! ScanNet's mesh segmentator does with normals, for the superpoints that 3D instance
//! segmentation votes over): edge `(i, j)` weighs `d = 1 - f_i f_j |n_i . n_j|^p`, with `n`
//! the shortest axis, `f` the flatness ([`crate::smooth::orientations`]) and `p`
//! [`SmoothConfig::normal_power`](crate::SmoothConfig::normal_power): 0 between flat
//! Gaussians of one smooth surface, 1 across a right-angle crease and wherever a Gaussian is
//! round (its orientation says nothing, so it bridges nothing). Edges are taken in increasing
//! weight; regions `A` and `B` merge when `d <= min(I(A) + tau / |A|, I(B) + tau / |B|)`,
//! `I` the largest weight in a region's spanning tree. Regions therefore end at creases,
//! where parts usually meet.
//!
//! **Prior.** A part that most views' masks get wrong in places (a thin stem eroded away in
//! five of eight views and covered by its neighbours' dilated masks, leaves near it that one
//! view calls stem) still has most of its evidence, summed over its whole surface, on the
//! right part. Each Gaussian's evidence for part `c` is scaled by `(R_c / R_max)^beta`, where
//! `R` is its region's summed class evidence and `R_max` its largest part entry; the
//! background entry is left alone, so the part-or-static decision stays the Gaussian's own
//! (a part and the static scene on one smooth surface — an object painted on a wall — keep
//! their boundary). The prior is a product: a Gaussian whose own evidence gives a part
//! (almost) nothing is not moved to it, so two parts on one smooth surface keep most of
//! their boundary too (measured in `tests/segment_plant.rs`).
//!
//! Cost: `12 k N` bytes of edges, one sort, a union-find pass.

use crate::error::{Error, Result};
use crate::smooth::Dsu;

/// Region id (a member Gaussian's index) of every Gaussian. `nbrs` is the `N x kk` KNN list
/// ([`crate::smooth::knn`]), `orient` the [`crate::smooth::orientations`], `power` the
/// orientation exponent `p` and `tau` the merge threshold (module docs). Lists that do not
/// fit `N` points, or a neighbour index outside them, are an error.
pub fn surface_regions(
    nbrs: &[u32],
    kk: usize,
    orient: &[[f32; 4]],
    power: f32,
    tau: f32,
) -> Result<Vec<u32>> {
    let n = orient.len();
    if n.checked_mul(kk) != Some(nbrs.len()) {
        return Err(Error::Input(format!(
            "{} neighbour indices for {n} points x {kk} neighbours",
            nbrs.len()
        )));
    }
    if let Some(&j) = nbrs.iter().find(|&&j| j as usize >= n) {
        return Err(Error::Input(format!(
            "neighbour index {j} outside the {n} points"
        )));
    }
    let mut edges: Vec<(f32, u32, u32)> = Vec::with_capacity(n * kk / 2);
    for i in 0..n {
        for &j in &nbrs[i * kk..(i + 1) * kk] {
            let j = j as usize;
            if j <= i {
                continue;
            }
            let (a, b) = (orient[i], orient[j]);
            let d = (a[0] * b[0] + a[1] * b[1] + a[2] * b[2]).abs().min(1.0);
            let w = 1.0 - a[3] * b[3] * d.powf(power);
            edges.push((w.clamp(0.0, 1.0), i as u32, j as u32));
        }
    }
    edges.sort_unstable_by(|x, y| x.0.total_cmp(&y.0).then((x.1, x.2).cmp(&(y.1, y.2))));
    let mut dsu = Dsu((0..n as u32).collect());
    let mut size = vec![1u32; n];
    let mut internal = vec![0f32; n];
    for (w, i, j) in edges {
        let (a, b) = (dsu.find(i), dsu.find(j));
        if a == b {
            continue;
        }
        let (sa, sb) = (size[a as usize], size[b as usize]);
        let ta = internal[a as usize] + tau / sa as f32;
        let tb = internal[b as usize] + tau / sb as f32;
        if w <= ta.min(tb) {
            let inner = w.max(internal[a as usize]).max(internal[b as usize]);
            dsu.union(a, b);
            let r = dsu.find(a) as usize;
            size[r] = sa + sb;
            internal[r] = inner;
        }
    }
    Ok((0..n as u32).map(|i| dsu.find(i)).collect())
}

/// The class evidence (`N x (M + 1)`, background first, as [`crate::Lifted::class_weights`])
/// with every Gaussian's part entries scaled by its region's prior `(R_c / R_max)^beta`
/// (module docs), `R` the region's sum of `evidence` (same layout; the class weights
/// themselves, or another estimate of them); background entries and Gaussians without
/// evidence are unchanged. Lengths that do not fit `N` Gaussians of `M + 1` classes, or a
/// region id outside them, are an error.
pub fn region_prior(
    class_weights: &[f64],
    evidence: &[f64],
    regions: &[u32],
    num_parts: usize,
    beta: f32,
) -> Result<Vec<f64>> {
    let s = num_parts.saturating_add(1);
    let n = regions.len();
    let want = n.checked_mul(s);
    if want != Some(class_weights.len()) || want != Some(evidence.len()) {
        return Err(Error::Input(format!(
            "{} class weights and {} evidence entries for {n} Gaussians x {s} classes",
            class_weights.len(),
            evidence.len()
        )));
    }
    if let Some(&r) = regions.iter().find(|&&r| r as usize >= n) {
        return Err(Error::Input(format!(
            "region id {r} outside the {n} Gaussians"
        )));
    }
    let mut sums = vec![0f64; n * s];
    for (i, &r) in regions.iter().enumerate() {
        let r = r as usize;
        for c in 0..s {
            let w = evidence[i * s + c];
            if w.is_finite() && w > 0.0 {
                sums[r * s + c] += w;
            }
        }
    }
    let beta = beta as f64;
    let mut out = class_weights.to_vec();
    for (i, &r) in regions.iter().enumerate() {
        let rs = &sums[r as usize * s..(r as usize + 1) * s];
        let top = rs[1..].iter().copied().fold(0.0, f64::max);
        if top <= 0.0 {
            continue;
        }
        for c in 1..s {
            out[i * s + c] *= (rs[c] / top).powf(beta);
        }
    }
    Ok(out)
}

/// What a region sums for its prior: with the per-view confusion matrices, the mean of a
/// Gaussian's posterior and its share of the summed votes (times its total weight); `None`:
/// the class weights themselves. The two estimates fail in different places: the confusion
/// posterior restores a thin part that most views erase (the potted plant's stem: its
/// region's summed votes favour the soil, seed 2), the summed votes keep a surface that a
/// view with a clean record covers with a neighbour's dilated mask (the pot's inner wall,
/// seed 1); their mean is right on both (`tests/segment_plant.rs`).
pub(crate) fn region_evidence(lifted: &crate::Lifted) -> Option<Vec<f64>> {
    let s = lifted.num_parts + 1;
    if lifted.summed_weights.len() != lifted.class_weights.len() {
        return None;
    }
    let mut out = vec![0f64; lifted.class_weights.len()];
    for ((o, a), b) in out
        .chunks_exact_mut(s)
        .zip(lifted.class_weights.chunks_exact(s))
        .zip(lifted.summed_weights.chunks_exact(s))
    {
        let (ta, tb): (f64, f64) = (a.iter().sum(), b.iter().sum());
        if ta > 0.0 && tb > 0.0 && ta.is_finite() && tb.is_finite() {
            for c in 0..s {
                o[c] = 0.5 * ta * (a[c] / ta + b[c] / tb);
            }
        }
    }
    Some(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::smooth::knn;

    /// Lists that do not fit are typed errors, not panics.
    #[test]
    fn mismatched_inputs_are_errors() {
        let o = [[0.0, 0.0, 1.0, 1.0]; 3];
        assert!(surface_regions(&[0, 1], 1, &o, 16.0, 1.0).is_err());
        assert!(surface_regions(&[0, 1, 7], 1, &o, 16.0, 1.0).is_err());
        assert!(surface_regions(&[0, 1, 2], 1, &o, 16.0, 1.0).is_ok());
        let w = [1.0; 6];
        assert!(region_prior(&w, &w[..4], &[0, 0, 0], 1, 4.0).is_err());
        assert!(region_prior(&w, &w, &[0, 0, 9], 1, 4.0).is_err());
        assert!(region_prior(&w, &w, &[0, 0], 1, 4.0).is_err());
        assert!(region_prior(&w, &w, &[0, 0, 0], usize::MAX, 4.0).is_err());
    }

    /// The evidence a region sums: the mean of the posterior's and the summed votes' shares,
    /// times the posterior's total; the class weights alone without summed votes.
    #[test]
    fn evidence_mixes_the_two_estimates() {
        let mut l = crate::Lifted {
            num_parts: 1,
            class_weights: vec![0.0, 4.0, 3.0, 1.0],
            summed_weights: vec![1.0, 1.0, 0.0, 0.0],
            ..Default::default()
        };
        let e = region_evidence(&l).unwrap();
        // Gaussian 0: shares (0, 1) and (0.5, 0.5) -> (0.25, 0.75) x 4; Gaussian 1: no
        // summed votes -> nothing.
        assert_eq!(e, vec![1.0, 3.0, 0.0, 0.0]);
        l.summed_weights.clear();
        assert!(region_evidence(&l).is_none());
    }

    /// Two flat sheets meeting at a right angle (an L): two regions, split at the crease;
    /// round Gaussians on one sheet do not join it.
    #[test]
    fn regions_end_at_creases() {
        let mut pts = Vec::new();
        let mut orient = Vec::new();
        for i in 0..20 {
            for j in 0..20 {
                // Floor z = 0 (normal z), x in (0, 1].
                pts.push([0.05 * (i + 1) as f32, 0.05 * j as f32, 0.0]);
                orient.push([0.0, 0.0, 1.0, 1.0]);
                // Wall x = 0 (normal x), z in (0, 1].
                pts.push([0.0, 0.05 * j as f32, 0.05 * (i + 1) as f32]);
                orient.push([1.0, 0.0, 0.0, 1.0]);
            }
        }
        let (kk, nb) = knn(&pts, 8, crate::Par::Seq);
        let reg = surface_regions(&nb, kk, &orient, 16.0, 30.0).unwrap();
        let floor = reg[0];
        let wall = reg[1];
        assert_ne!(floor, wall);
        for (k, &r) in reg.iter().enumerate() {
            assert_eq!(r, if k % 2 == 0 { floor } else { wall }, "Gaussian {k}");
        }
        // Round Gaussians: each its own region.
        let round: Vec<[f32; 4]> = orient.iter().map(|o| [o[0], o[1], o[2], 0.0]).collect();
        let reg = surface_regions(&nb, kk, &round, 16.0, 0.5).unwrap();
        let mut ids = reg.clone();
        ids.sort_unstable();
        ids.dedup();
        assert_eq!(ids.len(), pts.len());
    }

    /// The prior moves a Gaussian with mixed evidence to its region's part, leaves one with
    /// no evidence for that part alone, and never touches the background entry.
    #[test]
    fn prior_scales_parts_by_the_region() {
        // Three Gaussians in one region, parts a, b: the region's evidence favours a.
        let w = vec![
            0.0, 9.0, 1.0, // clearly a
            0.1, 0.4, 0.5, // mixed, leaning b
            0.2, 0.0, 0.8, // b only
        ];
        let out = region_prior(&w, &w, &[0, 0, 0], 2, 4.0).unwrap();
        // R = [0.3, 9.4, 2.3]: a unchanged, b scaled by (2.3 / 9.4)^4.
        let f = (2.3f64 / 9.4).powi(4);
        let want = [0.0, 9.0, f, 0.1, 0.4, 0.5 * f, 0.2, 0.0, 0.8 * f];
        for (a, b) in out.iter().zip(want) {
            assert!((a - b).abs() < 1e-12, "{out:?}");
        }
        // Mixed moves to a; b-only stays b (nothing for a to scale); background as it was.
        assert!(out[4] > out[5]);
        assert!(out[8] > out[7]);
        // Separate regions: nothing changes where each region has one part.
        let out = region_prior(&w, &w, &[0, 1, 2], 2, 4.0).unwrap();
        let (_, l0) = (0, crate::lift::classify(&out, 2, 0.1).0);
        assert_eq!(l0, crate::lift::classify(&w, 2, 0.1).0);
    }
}
