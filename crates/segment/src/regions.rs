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
//! their boundary too (measured in `crates/segment/tests/segment/segment_plant.rs`).
//!
//! **Static.** The background entry is scaled too, but only one way and only where the
//! region's strongest part outweighs the static scene in it: by `(R_0 / R_max)^q`. A part's
//! surface whose rim most views' eroded masks give to the static scene (a petal's edge) keeps
//! it, while a region the static scene dominates (a wall with a part painted on it, a floor
//! split into a part and static) is left alone, so that boundary is the Gaussians' own.
//!
//! **Appearance.** Where the masks' evidence over a whole region is nearly even, or wrong
//! (the pot's inner wall, which most views' dilated soil masks cover; a thin leaf that most
//! views erode into the soil behind it), the colours still tell: the region's summed
//! evidence is first scaled per part by how well its Gaussians' base colours fit that part's
//! robust colour model ([`appearance_weighted`]). It is a compatibility test, not a contest:
//! parts of one colour (a stem and its leaves) both fit and keep their evidence, a colour no
//! part has changes nothing, and the scale never goes below `1 - s`.
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

/// Every region id names one of the `regions.len()` Gaussians, else the first that does not.
fn check_region_ids(regions: &[u32]) -> Result<()> {
    let n = regions.len();
    match regions.iter().find(|&&r| r as usize >= n) {
        Some(&r) => Err(Error::Input(format!(
            "region id {r} outside the {n} Gaussians"
        ))),
        None => Ok(()),
    }
}

/// The class evidence (`N x (M + 1)`, background first, as [`crate::Lifted::class_weights`])
/// with every Gaussian's part entries scaled by its region's prior `(R_c / R_max)^beta`
/// (module docs), `R` the region's sum of `evidence` (same layout; the class weights
/// themselves, or another estimate of them), and its background entry by
/// `(R_0 / R_max)^static_power` where the region's strongest part outweighs the background
/// (`R_0 < R_max`; elsewhere, and with `static_power` 0, it is unchanged); Gaussians without
/// evidence are unchanged. Lengths that do not fit `N` Gaussians of `M + 1` classes, or a
/// region id outside them, are an error.
pub fn region_prior(
    class_weights: &[f64],
    evidence: &[f64],
    regions: &[u32],
    num_parts: usize,
    beta: f32,
    static_power: f32,
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
    check_region_ids(regions)?;
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
    let static_power = static_power as f64;
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
        if static_power > 0.0 && rs[0] < top {
            out[i * s] *= (rs[0].max(0.0) / top).powf(static_power);
        }
    }
    Ok(out)
}

/// The region evidence with every region's part entries scaled by how well its colours fit
/// each part's: the appearance term of the prior (module docs). `colours` are the Gaussians'
/// base colours (RGB, [`crate::smooth::base_colours`]), `evidence` the `N x (M + 1)` class
/// evidence (background first) and `strength` `s` in `[0, 1]`.
///
/// Each part's colour model is a robust Gaussian in RGB ([`colour_model`]) over the colours of
/// the Gaussians weighted by the square of their evidence share for that part (mixed,
/// uncertain Gaussians hardly count). The model is a test of compatibility, not a contest:
/// a colour within the model's 99% ellipsoid (`D^2 <= 11.34`, chi-square with 3 degrees of
/// freedom) fits the part fully, one further out by `exp(-(D^2 - 11.34) / 2)`, so two parts
/// of one colour (the plant's stem and leaves share a green) both fit and nothing changes
/// between them. A region's `A_c` is its members' mean fit, and its part entries are scaled
/// by `1 - s + s A_c / A_max`: colour alone can overturn at most a `1 / (1 - s)` lead of the
/// masks' evidence, and a region whose colours fit no part is left alone. A part with less
/// than an effective sample of 3 gets no model and the factor 1. Lengths that do not fit, a
/// region id outside the Gaussians or `s` outside `[0, 1]` are errors.
pub fn appearance_weighted(
    evidence: &[f64],
    colours: &[[f32; 3]],
    regions: &[u32],
    num_parts: usize,
    strength: f32,
) -> Result<Vec<f64>> {
    let s = num_parts.saturating_add(1);
    let n = regions.len();
    if n.checked_mul(s) != Some(evidence.len()) || colours.len() != n {
        return Err(Error::Input(format!(
            "{} evidence entries and {} colours for {n} Gaussians x {s} classes",
            evidence.len(),
            colours.len()
        )));
    }
    check_region_ids(regions)?;
    if !(strength.is_finite() && (0.0..=1.0).contains(&strength)) {
        return Err(Error::Input(format!(
            "appearance strength {strength} (must lie in [0, 1])"
        )));
    }
    let mut out = evidence.to_vec();
    if strength == 0.0 || num_parts == 0 || n == 0 {
        return Ok(out);
    }
    let m = num_parts;
    let finite: Vec<bool> = colours
        .iter()
        .map(|c| c.iter().all(|v| v.is_finite()))
        .collect();
    let models: Vec<Option<ColourModel>> = (0..m)
        .map(|c| {
            let samples: Vec<([f64; 3], f64)> = (0..n)
                .filter(|&i| finite[i])
                .filter_map(|i| {
                    let e = &evidence[i * s..(i + 1) * s];
                    let t: f64 = e.iter().filter(|v| v.is_finite() && **v > 0.0).sum();
                    let v = e[c + 1];
                    (t > 0.0 && v.is_finite() && v > 0.0)
                        .then(|| (colours[i].map(|x| x as f64), (v / t).powi(2)))
                })
                .collect();
            colour_model(&samples)
        })
        .collect();
    if models.iter().all(Option::is_none) {
        return Ok(out);
    }
    // Per region: the members' mean fit to every part.
    let mut acc = vec![0f64; n * m];
    let mut count = vec![0u32; n];
    for i in (0..n).filter(|&i| finite[i]) {
        let x = colours[i].map(|v| v as f64);
        let r = regions[i] as usize;
        for c in 0..m {
            acc[r * m + c] += models[c].as_ref().map_or(1.0, |md| md.fit(&x));
        }
        count[r] += 1;
    }
    let strength = strength as f64;
    let mut factor = vec![1f64; n * m];
    for r in (0..n).filter(|&r| count[r] > 0) {
        let a = &acc[r * m..(r + 1) * m];
        for c in 0..m {
            let ac = (a[c] / count[r] as f64).clamp(0.0, 1.0);
            factor[r * m + c] = 1.0 - strength + strength * ac;
        }
    }
    for (i, &r) in regions.iter().enumerate() {
        for c in 0..m {
            out[i * s + c + 1] *= factor[r as usize * m + c];
        }
    }
    Ok(out)
}

/// The 99% quantile of the chi-square distribution with 3 degrees of freedom.
const CHI2_3_99: f64 = 11.345;

/// A part's colour model: mean and inverse covariance in RGB.
#[derive(Clone, Debug)]
pub struct ColourModel {
    /// Mean colour.
    pub mean: [f64; 3],
    /// Inverse of the covariance (with `0.02^2` added on the diagonal).
    pub inv_cov: [[f64; 3]; 3],
}

impl ColourModel {
    /// Squared Mahalanobis distance of `x` from the mean.
    pub fn d2(&self, x: &[f64; 3]) -> f64 {
        let d = [0, 1, 2].map(|a| x[a] - self.mean[a]);
        let mut q = 0.0;
        for a in 0..3 {
            for b in 0..3 {
                q += d[a] * self.inv_cov[a][b] * d[b];
            }
        }
        q
    }

    /// How well `x` fits: 1 within the 99% ellipsoid, `exp(-(D^2 - 11.345) / 2)` outside.
    pub fn fit(&self, x: &[f64; 3]) -> f64 {
        (-0.5 * (self.d2(x) - CHI2_3_99).max(0.0)).exp()
    }
}

/// A robust Gaussian colour model of weighted samples `(colour, weight)`: the minimum
/// covariance determinant estimate (Rousseeuw's C-steps from the weighted per-channel median:
/// mean and covariance of the samples nearest the current model that make up half of the
/// weight, until that half stops changing), scaled so that the weighted median of `D^2` is
/// chi-square's, then the weighted mean and covariance of the samples within its 97.5%
/// ellipsoid. So a minority of another part's colour (up to half the weight: a neighbour's
/// eroded or dilated mask, a whole leaf that most views give to the soil) does not move it.
/// `None` with an effective sample (`(sum w)^2 / sum w^2`) under 3.
pub fn colour_model(samples: &[([f64; 3], f64)]) -> Option<ColourModel> {
    const REG: f64 = 0.02 * 0.02;
    const CHI2_3_50: f64 = 2.366;
    const CHI2_3_975: f64 = 9.348;
    let samples: Vec<([f64; 3], f64)> = samples
        .iter()
        .copied()
        .filter(|(x, w)| w.is_finite() && *w > 0.0 && x.iter().all(|v| v.is_finite()))
        .collect();
    let (w1, w2) = samples
        .iter()
        .fold((0.0, 0.0), |a, (_, w)| (a.0 + w, a.1 + w * w));
    if !(w2 > 0.0 && w1 * w1 / w2 >= 3.0) {
        return None;
    }
    // The weighted median of `(value, weight)` pairs.
    let median = |vals: &mut Vec<(f64, f64)>| {
        vals.sort_by(|a, b| a.0.total_cmp(&b.0));
        let half = 0.5 * vals.iter().map(|v| v.1).sum::<f64>();
        let mut acc = 0.0;
        for (x, w) in vals.iter() {
            acc += w;
            if acc >= half {
                return *x;
            }
        }
        vals.last().map_or(0.0, |v| v.0)
    };
    // Mean and covariance (plus `REG`) of the samples selected by `keep`.
    let moments = |keep: &dyn Fn(usize) -> bool| -> Option<([f64; 3], [[f64; 3]; 3])> {
        let (mut ws, mut mu) = (0.0, [0f64; 3]);
        for (i, (x, w)) in samples.iter().enumerate() {
            if keep(i) {
                ws += w;
                for a in 0..3 {
                    mu[a] += w * x[a];
                }
            }
        }
        if ws <= 0.0 {
            return None;
        }
        mu = mu.map(|v| v / ws);
        let mut k = [[0f64; 3]; 3];
        for (i, (x, w)) in samples.iter().enumerate() {
            if keep(i) {
                let d = [0, 1, 2].map(|a| x[a] - mu[a]);
                for a in 0..3 {
                    for b in 0..3 {
                        k[a][b] += w * d[a] * d[b] / ws;
                    }
                }
            }
        }
        for (a, row) in k.iter_mut().enumerate() {
            row[a] += REG;
        }
        Some((mu, k))
    };
    let model_of = |mean: [f64; 3], k: &[[f64; 3]; 3]| {
        invert3(k).map(|(inv_cov, _)| ColourModel { mean, inv_cov })
    };
    let mut mean = [0f64; 3];
    let mut cov = [[0f64; 3]; 3];
    for a in 0..3 {
        let mut v: Vec<(f64, f64)> = samples.iter().map(|(x, w)| (x[a], *w)).collect();
        mean[a] = median(&mut v);
        let mut dev: Vec<(f64, f64)> = samples
            .iter()
            .map(|(x, w)| ((x[a] - mean[a]).abs(), *w))
            .collect();
        let mad = 1.4826 * median(&mut dev);
        cov[a][a] = mad * mad + REG;
    }
    let mut model = model_of(mean, &cov)?;
    // C-steps: the half of the weight nearest the model.
    let mut kept: Vec<bool> = Vec::new();
    for _ in 0..20 {
        let mut order: Vec<(f64, usize)> = samples
            .iter()
            .enumerate()
            .map(|(i, (x, _))| (model.d2(x), i))
            .collect();
        order.sort_by(|a, b| a.0.total_cmp(&b.0));
        let mut keep = vec![false; samples.len()];
        let mut acc = 0.0;
        for &(_, i) in &order {
            keep[i] = true;
            acc += samples[i].1;
            if acc >= 0.5 * w1 {
                break;
            }
        }
        if keep == kept {
            break;
        }
        let Some((mu, k)) = moments(&|i| keep[i]) else {
            break;
        };
        let Some(next) = model_of(mu, &k) else { break };
        model = next;
        cov = k;
        kept = keep;
    }
    // Consistency: scale the half-sample covariance so the median `D^2` is chi-square's.
    let mut d2: Vec<(f64, f64)> = samples.iter().map(|(x, w)| (model.d2(x), *w)).collect();
    let med = median(&mut d2);
    if med.is_finite() && med > 0.0 {
        let f = med / CHI2_3_50;
        let k = cov.map(|r| r.map(|v| v * f));
        if let Some(m) = model_of(model.mean, &k) {
            model = m;
        }
    }
    // Reweighting: the samples within the 97.5% ellipsoid.
    let inside: Vec<bool> = samples
        .iter()
        .map(|(x, _)| model.d2(x) <= CHI2_3_975)
        .collect();
    if let Some((mu, k)) = moments(&|i| inside[i]) {
        if let Some(m) = model_of(mu, &k) {
            model = m;
        }
    }
    Some(model)
}

/// Inverse and determinant of a symmetric 3 x 3 matrix; `None` when it is not positive
/// definite (or not finite).
fn invert3(k: &[[f64; 3]; 3]) -> Option<([[f64; 3]; 3], f64)> {
    let c = |a: usize, b: usize, x: usize, y: usize| k[a][x] * k[b][y] - k[a][y] * k[b][x];
    let cof = [
        [c(1, 2, 1, 2), -c(1, 2, 0, 2), c(1, 2, 0, 1)],
        [-c(0, 2, 1, 2), c(0, 2, 0, 2), -c(0, 2, 0, 1)],
        [c(0, 1, 1, 2), -c(0, 1, 0, 2), c(0, 1, 0, 1)],
    ];
    let det = k[0][0] * cof[0][0] + k[0][1] * cof[0][1] + k[0][2] * cof[0][2];
    if !(det.is_finite() && det > 0.0) {
        return None;
    }
    // The inverse is the transposed cofactor matrix over the determinant (symmetric here).
    let mut inv = [[0f64; 3]; 3];
    for (a, row) in inv.iter_mut().enumerate() {
        for (b, v) in row.iter_mut().enumerate() {
            *v = cof[b][a] / det;
        }
    }
    Some((inv, det))
}

/// What a region sums for its prior: with the per-view confusion matrices, the mean of a
/// Gaussian's posterior and its share of the summed votes (times its total weight); `None`:
/// the class weights themselves. The two estimates fail in different places: the confusion
/// posterior restores a thin part that most views erase (the potted plant's stem: its
/// region's summed votes favour the soil, seed 2), the summed votes keep a surface that a
/// view with a clean record covers with a neighbour's dilated mask (the pot's inner wall,
/// seed 1); their mean is right on both (`crates/segment/tests/segment/segment_plant.rs`).
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
        assert!(region_prior(&w, &w[..4], &[0, 0, 0], 1, 4.0, 0.0).is_err());
        assert!(region_prior(&w, &w, &[0, 0, 9], 1, 4.0, 0.0).is_err());
        assert!(region_prior(&w, &w, &[0, 0], 1, 4.0, 0.0).is_err());
        assert!(region_prior(&w, &w, &[0, 0, 0], usize::MAX, 4.0, 0.0).is_err());
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

    /// The static prior: where a part outweighs the static scene in a region, its
    /// Gaussians' background evidence is scaled down; where the static scene dominates,
    /// nothing changes (a part painted on a static wall keeps its boundary).
    #[test]
    fn static_prior_is_one_sided() {
        // Region 0 (a petal): mostly petal evidence, a rim Gaussian leaning static.
        // Region 1 (a wall): mostly static, a painted part Gaussian.
        let w = vec![
            0.1, 0.9, // petal
            0.1, 0.9, // petal
            0.6, 0.4, // the rim: static by its own evidence
            0.9, 0.1, // wall
            0.9, 0.1, // wall
            0.2, 0.8, // painted part
        ];
        let regions = [0, 0, 0, 3, 3, 3];
        let out = region_prior(&w, &w, &regions, 1, 4.0, 2.0).unwrap();
        // Region 0: R = (0.8, 2.2): background scaled by (0.8 / 2.2)^2.
        let f = (0.8f64 / 2.2).powi(2);
        assert!((out[4] - 0.6 * f).abs() < 1e-12 && out[5] == 0.4);
        assert!(out[5] > out[4], "the rim joins the petal: {out:?}");
        // Region 1: the static scene dominates: untouched, the painted part stays a part.
        assert_eq!(&out[6..], &w[6..]);
        // Power 0: the background entry is never touched.
        let off = region_prior(&w, &w, &regions, 1, 4.0, 0.0).unwrap();
        assert_eq!(off[4], 0.6);
    }

    /// Deterministic colours scattered around `c` by up to +-0.03 per channel.
    fn jitter(c: [f64; 3], k: usize) -> [f64; 3] {
        let h = |a: usize| ((k * 7919 + a * 104_729) % 1000) as f64 / 1000.0 - 0.5;
        [c[0] + 0.06 * h(0), c[1] + 0.06 * h(1), c[2] + 0.06 * h(2)]
    }

    const BROWN: [f64; 3] = [0.30, 0.21, 0.13];
    const GREEN: [f64; 3] = [0.24, 0.50, 0.19];
    const TERRACOTTA: [f64; 3] = [0.70, 0.39, 0.23];

    /// The robust colour model stays on the majority colour with 40% of the weight on
    /// another (a whole leaf that most views give to the soil); the plain weighted mean
    /// would sit between the two and fit both.
    #[test]
    fn colour_model_resists_a_minority_of_another_colour() {
        let mut samples: Vec<([f64; 3], f64)> = (0..600).map(|k| (jitter(BROWN, k), 1.0)).collect();
        samples.extend((0..400).map(|k| (jitter(GREEN, k + 600), 1.0)));
        samples.push(([f64::NAN, 0.0, 0.0], 1.0));
        samples.push((GREEN, f64::INFINITY));
        let m = colour_model(&samples).unwrap();
        for a in 0..3 {
            assert!((m.mean[a] - BROWN[a]).abs() < 0.01, "{:?}", m.mean);
        }
        assert_eq!(m.fit(&BROWN), 1.0);
        assert!(m.fit(&GREEN) < 1e-6, "{}", m.fit(&GREEN));
        // The 99% ellipsoid holds nearly all of the brown samples.
        let inside = (0..600)
            .filter(|&k| m.fit(&jitter(BROWN, k)) == 1.0)
            .count();
        assert!(inside >= 580, "{inside}");
        // Too little evidence: no model.
        assert!(colour_model(&[(BROWN, 1.0), (BROWN, 1.0)]).is_none());
        assert!(colour_model(&[(BROWN, 1.0), (BROWN, 0.01), (BROWN, 0.01)]).is_none());
        assert!(colour_model(&[]).is_none());
    }

    /// An ambiguous region whose colour fits one part and not the other moves to the part it
    /// fits; a region between two parts of one colour, and one whose colour fits no part,
    /// keep the ratio of their evidence; strength 0 changes nothing.
    #[test]
    fn appearance_moves_ambiguous_regions_by_colour_only_where_it_tells() {
        // Parts: 0 pot (terracotta), 1 soil (brown), 2 stem and 3 leaves (both green).
        let m = 4;
        let s = m + 1;
        let mut evidence = Vec::new();
        let mut colours = Vec::new();
        let mut regions = Vec::new();
        // Confident regions of every part: 300 Gaussians each, region id = first member.
        for (p, c) in [TERRACOTTA, BROWN, GREEN, GREEN].into_iter().enumerate() {
            let first = regions.len() as u32;
            for k in 0..300 {
                let mut e = vec![0.0; s];
                e[p + 1] = 1.0;
                evidence.extend(e);
                colours.push(jitter(c, k + 300 * p).map(|v| v as f32));
                regions.push(first);
            }
        }
        // Ambiguous regions (evidence 0.4 / 0.6): terracotta between pot and soil (leaning
        // soil); green between stem and leaves; grey between pot and soil.
        let cases = [(TERRACOTTA, 0, 1), (GREEN, 2, 3), ([0.5, 0.5, 0.5], 0, 1)];
        let mut firsts = Vec::new();
        for (t, (c, a, b)) in cases.into_iter().enumerate() {
            let first = regions.len() as u32;
            firsts.push(first as usize);
            for k in 0..40 {
                let mut e = vec![0.0; s];
                e[a + 1] = 0.4;
                e[b + 1] = 0.6;
                evidence.extend(e);
                colours.push(jitter(c, 5000 + 40 * t + k).map(|v| v as f32));
                regions.push(first);
            }
        }
        let out = appearance_weighted(&evidence, &colours, &regions, m, 0.8).unwrap();
        let at = |i: usize, c: usize| out[i * s + c + 1];
        // Terracotta: soil's 0.6 scaled to about 0.2 x 0.6, pot's 0.4 kept.
        let i = firsts[0];
        assert!((at(i, 0) - 0.4).abs() < 1e-9, "{}", at(i, 0));
        assert!((0.119..0.13).contains(&at(i, 1)), "{}", at(i, 1));
        // Green between stem and leaves: both fit, nothing changes.
        let i = firsts[1];
        assert!((at(i, 2) - 0.4).abs() < 1e-9 && (at(i, 3) - 0.6).abs() < 1e-9);
        // Grey fits no part: every part scaled alike, the ratio kept.
        let i = firsts[2];
        assert!(
            (at(i, 1) / at(i, 0) - 1.5).abs() < 1e-9,
            "{} {}",
            at(i, 0),
            at(i, 1)
        );
        // Confident regions keep their part; the background entry is never touched.
        assert!((at(0, 0) - 1.0).abs() < 1e-9);
        for i in 0..regions.len() {
            assert_eq!(out[i * s], evidence[i * s]);
        }
        // Strength 0: unchanged.
        let same = appearance_weighted(&evidence, &colours, &regions, m, 0.0).unwrap();
        assert_eq!(same, evidence);
    }

    /// Inputs that do not fit, and strengths outside [0, 1], are typed errors.
    #[test]
    fn appearance_refuses_bad_inputs() {
        let e = [0.0, 1.0, 0.0, 1.0];
        let c = [[0.5f32; 3]; 2];
        assert!(appearance_weighted(&e, &c, &[0, 0], 1, 0.5).is_ok());
        assert!(appearance_weighted(&e[..3], &c, &[0, 0], 1, 0.5).is_err());
        assert!(appearance_weighted(&e, &c[..1], &[0, 0], 1, 0.5).is_err());
        assert!(appearance_weighted(&e, &c, &[0, 5], 1, 0.5).is_err());
        for bad in [-0.1, 1.5, f32::NAN, f32::INFINITY] {
            let err = appearance_weighted(&e, &c, &[0, 0], 1, bad).unwrap_err();
            assert!(err.to_string().contains("appearance"), "{err}");
        }
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
        let out = region_prior(&w, &w, &[0, 0, 0], 2, 4.0, 0.0).unwrap();
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
        let out = region_prior(&w, &w, &[0, 1, 2], 2, 4.0, 0.0).unwrap();
        let (_, l0) = (0, crate::lift::classify(&out, 2, 0.1).0);
        assert_eq!(l0, crate::lift::classify(&w, 2, 0.1).0);
    }
}
