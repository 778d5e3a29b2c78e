//! Lifting 2D masks onto the Gaussians.
//!
//! For Gaussian `g` and class `c` (0 = background, `k + 1` = part `k`) the lifter sums, over
//! every view and pixel, the weight with which the renderer composites `g` into the pixel
//! (`alpha T`, [`r4d_splat::weights`]) times the mask's value of `c` at the pixel:
//!
//! ```text
//! W[g][c] = sum_views sum_pixels alpha_g(x) T_g(x) m_c(x)
//! ```
//!
//! (LUDVIG's uplifting of 2D features: occluded Gaussians get no weight, because `T` in
//! front of them is ~0, and a Gaussian's share of a pixel is what it contributes to the
//! image). A label map votes one-hot (`m_c = 1` for its class, nothing at ignored pixels); a
//! probability map votes `m_k = p_k` for the parts and `1 - sum p` for the background. Then
//! per Gaussian the class weights are normalised, `p_c = W[g][c] / sum_c W[g][c]`, and a
//! softmax at temperature `tau`, `softmax(p / tau)`, gives the class probabilities: the label
//! is the argmax (background -> -1, static) and the confidence its probability. A Gaussian no
//! pixel of any view sees (all `W = 0`) is labelled -1 with confidence 0 ("unobserved"; the
//! KNN pass in [`mod@crate::smooth`] gives it its neighbours' label).
//!
//! By default ([`ViewVote::Confusion`]) the views are not simply added: each view keeps its
//! own class distribution per Gaussian, gets a confusion matrix estimated against the other
//! views' verdict, and the label is the argmax of the posterior in which every view's
//! observation counts by the likelihood ratio its matrix gives it ([`crate::confusion`]); the
//! plain sum above is the EM's starting point and [`ViewVote::Sum`]'s result.
//!
//! Cost per view: projection (colour is not needed, so SH is skipped), the depth sort and
//! tile binning of the renderer, then the forward compositing of every pixel, each composited
//! Gaussian adding to `M + 1` (probabilities) or 1 (labels) accumulators. Tile rows are
//! dealt round-robin to `min(threads, 8)` workers, each with its own f64 accumulator of
//! `8 (M + 1) N` bytes, summed in a fixed order at the end (results do not depend on
//! scheduling for a given worker count).

use crate::boundary::boundary_trust;
use crate::error::{Error, Result};
use crate::mask::{MaskData, MaskSource, IGNORE};
use crate::Par;
use r4d_splat::project::{self as pj, CamParams, GaussianIn, Projected};
use r4d_splat::raster;
use r4d_splat::weights::{tile_weights, WeightScratch};
use r4d_splat::{Camera, Gaussians, RasterizeMode};

/// How the views' evidence is combined (module docs).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum ViewVote {
    /// Every pixel's vote summed over every view: a view that sees a Gaussian over many
    /// pixels outweighs one that sees it over few (LUDVIG's uplifting).
    Sum,
    /// Each view first makes up its own mind about each Gaussian (its class distribution),
    /// then the views vote with their confidence in that Gaussian: how well they see it
    /// (saturating) and, over [`LiftConfig::consistency_iters`] rounds, how well they agree
    /// with the other views.
    Confidence,
    /// Dawid and Skene's EM ([`crate::confusion`]): every view gets a confusion matrix,
    /// estimated from the current labels, and its votes count by what its record says they
    /// are worth (a view that erodes a thin part away, or calls one part another, loses its
    /// say on that part), starting from [`ViewVote::Sum`]'s evidence.
    #[default]
    Confusion,
}

/// Settings of the lift.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LiftConfig {
    /// Softmax temperature `tau` over the normalised class weights (which lie in [0, 1]);
    /// smaller is more confident. Default 0.1.
    pub temperature: f32,
    /// Rasterize mode of the renderer that made the scene (opacity compensation).
    pub mode: RasterizeMode,
    /// Parallelism.
    pub par: Par,
    /// How views are combined. Default [`ViewVote::Confusion`] (on the potted-plant scene,
    /// five seeds: part Gaussians right with corrupted masks 90.8% -> 93.7%, clean masks
    /// 99.73% -> 99.90%; the confidence vote lost 1-4 points on clean masks and did not help
    /// on corrupted ones).
    pub vote: ViewVote,
    /// A pixel votes for a Gaussian with `(alpha T)^p`: `p > 1` lets the pixels a Gaussian
    /// dominates speak for it, not the tails of its footprint over a neighbour's pixels.
    /// Default 1 (2 helped thin parts on clean masks and cost 2-5 points on corrupted ones).
    pub weight_power: f32,
    /// `d0` of the boundary trust ([`crate::boundary`]): pixels nearer than this to a label
    /// boundary (pixels) vote less, except along the middle of thin parts; 0 turns it off.
    /// Default 0 (2 px changed the potted plant's accuracy by under one point either way).
    pub boundary_px: f32,
    /// [`ViewVote::Confidence`]: a view's weight saturates when it sees a Gaussian with this
    /// much compositing weight (sum of `alpha T` over its pixels). Default 0.5.
    pub saturation: f32,
    /// [`ViewVote::Confidence`]: rounds of re-weighting the views by their agreement with the
    /// consensus (0: none). Default 2.
    pub consistency_iters: u32,
    /// Scale a view's votes for a Gaussian by the share of its drawn footprint that is the
    /// Gaussian itself, `sqrt(det S / det(S + 0.3 I))` of its 2D covariance `S` (the
    /// renderer's low-pass widens a Gaussian seen edge-on into a line of pixels whose mask
    /// labels show what lies behind it). Default true.
    pub footprint_trust: bool,
    /// Confidence of a Gaussian with mixed evidence (its strongest class below [`PURE_SHARE`]
    /// of it) is scaled by `min(1, visibility / full_visibility)` (visibility: the Gaussian's
    /// compositing weight summed over the views): a Gaussian seen weakly but consistently
    /// keeps its part, one that shows only a sliver (a back face peeking out at a silhouette, a part seen through a narrow
    /// opening) keeps its vote but leaves the decision to its well-seen neighbours in the
    /// KNN pass (0: off). Default 4 (pixel-equivalents: on the potted plant's clean masks
    /// the leaves' back faces went from 80% to 99% right).
    pub full_visibility: f32,
    /// Weight of a view whose own verdict on a Gaussian is background (its strongest class
    /// there), relative to views that see a part there (1: equal). Below 1, a view in which
    /// a part's mask misses a region (an eroded boundary, a thin part the segmenter lost)
    /// outvotes less of the views that do show the part; where all views agree nothing
    /// changes. Default 0.25 (on the
    /// potted plant, mean of five seeds: clean masks 97.9% -> 98.3% of part Gaussians right,
    /// corrupted masks 84.3% -> 87.5%; the static floor stays 100% with clean masks and
    /// >= 97.6% with corrupted ones).
    pub background_weight: f32,
    /// [`ViewVote::Sum`]: rounds of the cross-view consistency check: for every view and
    /// label, the share of the view's votes for that label that land on Gaussians the *other*
    /// views (leave-one-out) call so; a view whose share falls below the median of the views
    /// for that label has its votes for it scaled by `(share / median)^2`. A view that labels a
    /// whole part as another, or dilates a part over its neighbours, loses its say on that
    /// label only (0: off). Default 0 (one round on the potted plant: +0.7 points with
    /// corrupted masks, -0.35 with clean ones, the stem losing most).
    pub view_consistency_iters: u32,
    /// [`ViewVote::Confusion`]: the EM's settings.
    pub confusion: crate::confusion::ConfusionConfig,
    /// A view "sees" a Gaussian (diagnostics: [`Lifted::views`]) when its compositing weight
    /// there reaches this. Default 0.05.
    pub seen_weight: f32,
}

impl Default for LiftConfig {
    fn default() -> Self {
        LiftConfig {
            temperature: 0.1,
            mode: RasterizeMode::Classic,
            par: Par::Rayon,
            vote: ViewVote::Confusion,
            weight_power: 1.0,
            boundary_px: 0.0,
            saturation: 0.5,
            consistency_iters: 2,
            footprint_trust: true,
            full_visibility: 4.0,
            background_weight: 0.25,
            view_consistency_iters: 0,
            confusion: Default::default(),
            seen_weight: 0.05,
        }
    }
}

impl LiftConfig {
    /// The classic lift (every pixel's `alpha T` summed over the views, no boundary trust).
    pub fn classic() -> LiftConfig {
        LiftConfig {
            vote: ViewVote::Sum,
            weight_power: 1.0,
            boundary_px: 0.0,
            consistency_iters: 0,
            footprint_trust: false,
            full_visibility: 0.0,
            background_weight: 1.0,
            ..Default::default()
        }
    }
}

/// The result of lifting: accumulated class weights and the per-Gaussian decision.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Lifted {
    /// Number of parts `M`.
    pub num_parts: usize,
    /// The combined class evidence `W[g][c]`, `N x (M + 1)` row-major; column 0 is the
    /// background ([`ViewVote::Sum`]: sums of pixel votes; [`ViewVote::Confidence`]: sums of
    /// the views' class distributions times their weights; [`ViewVote::Confusion`]: the
    /// posterior class probabilities times the summed votes).
    pub class_weights: Vec<f64>,
    /// Label per Gaussian (-1: background/static or unobserved).
    pub labels: Vec<i32>,
    /// Softmax probability of the label (0 when unobserved).
    pub confidence: Vec<f32>,
    /// Total compositing weight per Gaussian over all views (sum of `alpha T`; 0: unseen).
    pub visibility: Vec<f32>,
    /// Number of views that see each Gaussian ([`LiftConfig::seen_weight`]).
    pub views: Vec<u16>,
    /// Per view ([`ViewVote::Sum`] and [`ViewVote::Confusion`], against the summed votes; 0
    /// otherwise), over the Gaussians it sees fully and is sure about (90% of its own votes
    /// on one class), the share of its votes on which it disagrees with the other views
    /// combined (leave-one-out): a view that labels a part as another, or misses it, stands
    /// out.
    pub view_disagreement: Vec<f32>,
    /// [`ViewVote::Confusion`]: the summed votes the EM started from (what
    /// [`ViewVote::Sum`] gives as `class_weights`), `N x (M + 1)`; empty for the other votes.
    pub summed_weights: Vec<f64>,
    /// The factor each Gaussian's confidence was scaled by for weak visibility
    /// ([`LiftConfig::full_visibility`]; 1 where it was not), for classifying again.
    pub confidence_scale: Vec<f32>,
}

impl Lifted {
    /// Sum of Gaussian `g`'s class weights (0: no view sees it).
    pub fn total_weight(&self, g: usize) -> f64 {
        let s = self.num_parts + 1;
        self.class_weights[g * s..(g + 1) * s].iter().sum()
    }

    /// Number of Gaussians no view sees.
    pub fn unobserved(&self) -> usize {
        (0..self.labels.len())
            .filter(|&g| self.total_weight(g) <= 0.0)
            .count()
    }
}

/// Labels and confidences from class weights (`N x (M + 1)`, background first): normalise,
/// softmax at `temperature`, argmax (ties: the lower class, background first).
pub fn classify(class_weights: &[f64], num_parts: usize, temperature: f32) -> (Vec<i32>, Vec<f32>) {
    let s = num_parts + 1;
    assert_eq!(class_weights.len() % s, 0, "N x (M + 1) weights");
    let inv_t = 1.0 / temperature as f64;
    class_weights
        .chunks_exact(s)
        .map(|row| {
            let total: f64 = row.iter().sum();
            if total.is_nan() || total <= 0.0 {
                return (-1, 0.0);
            }
            let (mut best, mut arg) = (row[0], 0);
            for (c, &w) in row.iter().enumerate().skip(1) {
                if w > best {
                    (best, arg) = (w, c);
                }
            }
            // softmax(p / tau)[arg] = 1 / sum_c exp((p_c - p_arg) / tau)
            let z: f64 = row
                .iter()
                .map(|&w| ((w - best) / total * inv_t).exp())
                .sum();
            (arg as i32 - 1, (1.0 / z) as f32)
        })
        .unzip()
}

fn check_config(cfg: &LiftConfig) -> Result<()> {
    let positive = |name: &str, v: f32| {
        if v.is_finite() && v > 0.0 {
            Ok(())
        } else {
            Err(Error::Input(format!(
                "{name} {v} (must be positive and finite)"
            )))
        }
    };
    positive("temperature", cfg.temperature)?;
    positive("weight power", cfg.weight_power)?;
    positive("saturation", cfg.saturation)?;
    if !(cfg.background_weight.is_finite() && (0.0..=1.0).contains(&cfg.background_weight)) {
        return Err(Error::Input(format!(
            "background weight {} (must lie in [0, 1])",
            cfg.background_weight
        )));
    }
    if !(cfg.full_visibility.is_finite() && cfg.full_visibility >= 0.0) {
        return Err(Error::Input(format!(
            "full visibility {} (must be >= 0 and finite)",
            cfg.full_visibility
        )));
    }
    if !(cfg.boundary_px.is_finite() && (0.0..=64.0).contains(&cfg.boundary_px)) {
        return Err(Error::Input(format!(
            "boundary distance {} px (must lie in [0, 64])",
            cfg.boundary_px
        )));
    }
    if !(cfg.seen_weight.is_finite() && cfg.seen_weight >= 0.0) {
        return Err(Error::Input(format!(
            "seen weight {} (must be >= 0 and finite)",
            cfg.seen_weight
        )));
    }
    let c = &cfg.confusion;
    if !(1..=100).contains(&c.iters) {
        return Err(Error::Input(format!(
            "{} confusion EM rounds (must lie in 1..=100)",
            c.iters
        )));
    }
    if !(c.diagonal_prior.is_finite() && c.diagonal_prior >= 0.0) {
        return Err(Error::Input(format!(
            "confusion diagonal prior {} (must be >= 0 and finite)",
            c.diagonal_prior
        )));
    }
    if !(c.floor.is_finite() && c.floor > 0.0) {
        return Err(Error::Input(format!(
            "confusion floor {} (must be positive and finite)",
            c.floor
        )));
    }
    if cfg.consistency_iters > 100 {
        return Err(Error::Input(format!(
            "{} consistency rounds (at most 100)",
            cfg.consistency_iters
        )));
    }
    Ok(())
}

/// Projects every Gaussian for the weights only (colour skipped: SH degree 0, zero
/// coefficients). Culled Gaussians get radii (0, 0).
pub fn project_for_weights(g: &Gaussians, cam: &CamParams<f32>, par: Par) -> Vec<Projected<f32>> {
    let one = |i: usize| {
        let gi = GaussianIn {
            mean: g.means[i],
            log_scale: g.log_scales[i],
            quat: g.quats[i],
            opacity_logit: g.opacity_logits[i],
            f: None,
        };
        pj::project(&gi, &[0.0; 3], 0, cam).unwrap_or_default()
    };
    match par {
        #[cfg(feature = "parallel")]
        Par::Rayon => {
            use rayon::prelude::*;
            (0..g.len())
                .into_par_iter()
                .with_min_len(1024)
                .map(one)
                .collect()
        }
        _ => (0..g.len()).map(one).collect(),
    }
}

fn depth_order(proj: &[Projected<f32>], par: Par) -> Vec<u32> {
    match par {
        #[cfg(feature = "parallel")]
        Par::Rayon => {
            use rayon::prelude::*;
            let mut order: Vec<u32> = (0..proj.len() as u32)
                .into_par_iter()
                .filter(|&i| proj[i as usize].radii != [0, 0])
                .collect();
            // The same order as `raster::depth_order` (f32 depth, then index).
            order.par_sort_unstable_by(|&a, &b| {
                proj[a as usize]
                    .depth
                    .total_cmp(&proj[b as usize].depth)
                    .then(a.cmp(&b))
            });
            order
        }
        _ => raster::depth_order(proj),
    }
}

/// Number of accumulators (workers) the lift uses.
pub fn workers(par: Par) -> usize {
    match par {
        #[cfg(feature = "parallel")]
        Par::Rayon => rayon::current_num_threads().clamp(1, 8),
        _ => 1,
    }
}

/// Lifts the masks of every camera onto the Gaussians (see the module docs). `masks` gives
/// one mask per camera, of the camera's size.
pub fn lift<S: MaskSource + ?Sized>(
    g: &Gaussians,
    cameras: &[Camera],
    masks: &mut S,
    cfg: &LiftConfig,
) -> Result<Lifted> {
    lift_with_progress(g, cameras, masks, cfg, |_| {})
}

/// A Gaussian whose strongest class has at least this share of its evidence keeps its
/// confidence however weakly it is seen ([`LiftConfig::full_visibility`]).
pub const PURE_SHARE: f64 = 0.9;

/// Largest memory of [`lift`]'s vote tables (`views x N x (M + 2)` bytes) and accumulators
/// (`workers x N x (M + 2)` f64 and `N x (M + 1)` f64): 4 GiB.
pub const MAX_VOTE_BYTES: usize = 4 << 30;

/// The most classes x pixels one view may have in [`lift`] (`M x width x height`, checked
/// from the cameras before any mask is read): a view's probability maps and its votes grow
/// with both.
pub const MAX_CLASS_PIXELS: u64 = 1 << 30;

/// The label map a mask votes with most (for the boundary trust): 0 background, `k + 1`
/// part `k`, [`IGNORE`] where it votes for nothing.
fn argmax_labels(mask: &crate::mask::Mask, m: usize) -> Vec<u16> {
    match &mask.data {
        MaskData::Labels(l) => l.clone(),
        MaskData::Probabilities(_) => (0..mask.height)
            .flat_map(|j| (0..mask.width).map(move |i| (i, j)))
            .map(|(i, j)| mask.argmax(i, j, m).map_or(IGNORE, |c| (c + 1) as u16))
            .collect(),
    }
}

/// [`lift`], calling `progress(view)` after each view.
pub fn lift_with_progress<S: MaskSource + ?Sized>(
    g: &Gaussians,
    cameras: &[Camera],
    masks: &mut S,
    cfg: &LiftConfig,
    mut progress: impl FnMut(usize),
) -> Result<Lifted> {
    check_config(cfg)?;
    g.validate("scene")?;
    let m = masks.class_names().len();
    let s = m + 1;
    // Per worker and view: the class votes and the raw weight (column `s`).
    let sw = s + 1;
    let n = g.len();
    let nv = cameras.len();
    let nw = workers(cfg.par);
    // Classes x pixels of every view, before any mask is read: a view's work and its
    // probability maps grow with both.
    for cam in cameras {
        let class_pixels = (m as u64)
            .saturating_mul(cam.width as u64)
            .saturating_mul(cam.height as u64);
        if class_pixels > MAX_CLASS_PIXELS {
            return Err(Error::Input(format!(
                "camera '{}': {m} classes x {} x {} pixels = {class_pixels} class-pixels, more \
                 than the {MAX_CLASS_PIXELS} a view may have (MAX_CLASS_PIXELS): use fewer \
                 classes or smaller images",
                cam.name, cam.width, cam.height
            )));
        }
    }
    // One byte per class and one for the view's weight, per view and Gaussian; and the
    // per-worker accumulators (f64) and class weights beside them, all counted before any is
    // allocated.
    let vote_bytes = nv
        .checked_mul(n)
        .and_then(|x| x.checked_mul(sw))
        .filter(|&b| b <= MAX_VOTE_BYTES);
    let work_bytes = n
        .checked_mul(sw)
        .and_then(|x| x.checked_mul(8 * nw))
        .and_then(|x| x.checked_add(n.checked_mul(s)?.checked_mul(8)?));
    let vote_bytes = vote_bytes
        .zip(work_bytes)
        .filter(|&(v, w)| v.checked_add(w).is_some_and(|t| t <= MAX_VOTE_BYTES))
        .map(|(v, _)| v)
        .ok_or_else(|| {
            Error::Input(format!(
                "{nv} views x {n} Gaussians x {sw} classes of votes (and {nw} workers' \
                 accumulators) exceed the lift's limit of {} GiB (MAX_VOTE_BYTES)",
                MAX_VOTE_BYTES >> 30
            ))
        })?;
    let mut votes = vec![0u8; vote_bytes];
    // Each view's total vote per Gaussian (for the consistency check).
    let mut view_totals = vec![0f32; nv * n];
    let mut accs = vec![vec![0f64; n * sw]; nw];
    let mut scratch: Vec<WeightScratch<f32>> = vec![WeightScratch::default(); nw];
    let mut class_weights = vec![0f64; n * s];
    let mut visibility = vec![0f32; n];
    let mut views = vec![0u16; n];
    let p = cfg.weight_power as f64;
    let power = move |w: f64| {
        if p == 1.0 {
            w
        } else if p == 2.0 {
            w * w
        } else {
            w.powf(p)
        }
    };
    for (v, cam) in cameras.iter().enumerate() {
        cam.validate(&format!("camera {v}")).map_err(Error::Input)?;
        let mask = masks.mask(v, cam)?;
        if (mask.width, mask.height) != (cam.width, cam.height) {
            return Err(Error::MaskSize {
                file: mask.origin,
                view: v,
                camera: cam.name.clone(),
                got_w: mask.width,
                got_h: mask.height,
                want_w: cam.width,
                want_h: cam.height,
            });
        }
        let px = (cam.width as usize) * (cam.height as usize);
        let ok = match &mask.data {
            MaskData::Labels(l) => l.len() == px,
            MaskData::Probabilities(p) => p.len() == px * m,
        };
        if !ok {
            return Err(Error::mask(
                &mask.origin,
                format!(
                    "pixel data does not fit {}x{} pixels and {m} classes",
                    cam.width, cam.height
                ),
            ));
        }
        let trust = (cfg.boundary_px > 0.0).then(|| {
            boundary_trust(
                &argmax_labels(&mask, m),
                cam.width as usize,
                cam.height as usize,
                cfg.boundary_px,
            )
        });
        let cp = CamParams::<f32>::new(cam, cfg.mode);
        let proj = project_for_weights(g, &cp, cfg.par);
        let order = depth_order(&proj, cfg.par);
        let bins = raster::bin_tiles(&proj, &order, cam.width, cam.height);
        let (w, h) = (cam.width, cam.height);
        let data = &mask.data;
        let rho: Option<Vec<f32>> = cfg
            .footprint_trust
            .then(|| proj.iter().map(footprint_share).collect());
        let (proj, bins, trust, rho) = (&proj, &bins, trust.as_deref(), rho.as_deref());
        let work = |wk: usize, acc: &mut [f64], sc: &mut WeightScratch<f32>| {
            for ty in (wk as u32..bins.tiles_y).step_by(nw) {
                for tx in 0..bins.tiles_x {
                    let ids = bins.tile((ty * bins.tiles_x + tx) as usize);
                    tile_weights(proj, ids, tx, ty, w, h, sc, |i, j, id, wt| {
                        let pix = (j * w + i) as usize;
                        let a = &mut acc[id as usize * sw..(id as usize + 1) * sw];
                        let wt = wt as f64;
                        a[s] += wt;
                        // (the footprint share, per Gaussian, is applied once per view below)
                        let vote = match trust {
                            Some(t) => power(wt) * t[pix] as f64,
                            None => power(wt),
                        };
                        match data {
                            MaskData::Labels(l) => {
                                let c = l[pix];
                                if c != IGNORE {
                                    a[c as usize] += vote;
                                }
                            }
                            MaskData::Probabilities(pr) => {
                                let q = &pr[pix * m..(pix + 1) * m];
                                let parts: f32 = q.iter().sum();
                                a[0] += vote * (1.0 - parts).max(0.0) as f64;
                                for (ac, &qc) in a[1..s].iter_mut().zip(q) {
                                    *ac += vote * qc as f64;
                                }
                            }
                        }
                    })
                }
            }
        };
        match cfg.par {
            #[cfg(feature = "parallel")]
            Par::Rayon if nw > 1 => {
                use rayon::prelude::*;
                accs.par_iter_mut()
                    .zip(scratch.par_iter_mut())
                    .enumerate()
                    .for_each(|(wk, (acc, sc))| work(wk, acc, sc));
            }
            _ => {
                for (wk, (acc, sc)) in accs.iter_mut().zip(scratch.iter_mut()).enumerate() {
                    work(wk, acc, sc);
                }
            }
        }
        // This view's evidence per Gaussian (workers summed in a fixed order): into the sum,
        // the visibility and the view's vote table; the accumulators start the next view at 0.
        let vview = &mut votes[v * n * sw..(v + 1) * n * sw];
        let mut row = vec![0f64; sw];
        for gi in 0..n {
            row.iter_mut().for_each(|x| *x = 0.0);
            for acc in accs.iter_mut() {
                let a = &mut acc[gi * sw..(gi + 1) * sw];
                for (r, x) in row.iter_mut().zip(a.iter_mut()) {
                    *r += *x;
                    *x = 0.0;
                }
            }
            let wv = row[s];
            if wv <= 0.0 {
                continue;
            }
            if let Some(r) = rho {
                let r = r[gi] as f64;
                row[..s].iter_mut().for_each(|x| *x *= r);
            }
            // A view whose own verdict on the Gaussian is background counts less.
            if cfg.background_weight != 1.0 && row[1..s].iter().all(|&x| x < row[0]) {
                let b = cfg.background_weight as f64;
                row[..s].iter_mut().for_each(|x| *x *= b);
            }
            visibility[gi] += wv as f32;
            if wv >= cfg.seen_weight as f64 {
                views[gi] = views[gi].saturating_add(1);
            }
            if cfg.vote != ViewVote::Confidence {
                for (cw, r) in class_weights[gi * s..(gi + 1) * s].iter_mut().zip(&row) {
                    *cw += r;
                }
            }
            let tot: f64 = row[..s].iter().sum();
            if let Some(t) = view_totals.get_mut(v * n + gi) {
                *t = tot as f32;
            }
            if tot > 0.0 {
                let out = &mut vview[gi * sw..(gi + 1) * sw];
                for (o, r) in out.iter_mut().zip(&row[..s]) {
                    *o = (r / tot * 255.0).round() as u8;
                }
                // At least 1: a view that sees the Gaussian at all keeps a say.
                out[s] = ((wv / cfg.saturation as f64).min(1.0) * 255.0)
                    .round()
                    .max(1.0) as u8;
            }
        }
        progress(v);
    }
    if cfg.vote == ViewVote::Confidence {
        combine_views(&votes, n, s, nv, cfg.consistency_iters, &mut class_weights);
    }
    let check = cfg.vote == ViewVote::Sum && cfg.view_consistency_iters > 0;
    let sums = check.then(|| class_weights.clone());
    if check {
        let sums = sums.as_deref().unwrap_or_default();
        let mut w = vec![1f64; nv * s];
        for _ in 0..cfg.view_consistency_iters {
            w = view_label_weights(&votes, &view_totals, &class_weights, n, s, nv);
            reweigh(&votes, &view_totals, &w, n, s, nv, &mut class_weights);
        }
        // Gaussians whose views all carry no weight any more keep their plain sums.
        for (g, row) in class_weights.chunks_exact_mut(s).enumerate() {
            if row.iter().all(|&x| x <= 0.0) {
                row.copy_from_slice(&sums[g * s..(g + 1) * s]);
            }
        }
        let _ = w;
    }
    let summed = (cfg.vote == ViewVote::Confusion).then(|| class_weights.clone());
    if let Some(init) = &summed {
        let table = crate::confusion::VoteTable {
            votes: &votes,
            totals: &view_totals,
            n,
            s,
            nv,
        };
        crate::confusion::combine(&table, init, &cfg.confusion, &mut class_weights);
        // Posterior times the summed evidence: `total_weight` keeps its meaning.
        for (row, i) in class_weights.chunks_exact_mut(s).zip(init.chunks_exact(s)) {
            let t: f64 = i.iter().sum();
            row.iter_mut().for_each(|x| *x *= t);
        }
    }
    let sums = sums
        .as_deref()
        .or(summed.as_deref())
        .unwrap_or(&class_weights);
    let (labels, mut confidence) = classify(&class_weights, m, cfg.temperature);
    let mut confidence_scale = vec![1f32; n];
    if cfg.full_visibility > 0.0 {
        for (g, (k, &v)) in confidence_scale.iter_mut().zip(&visibility).enumerate() {
            let row = &sums[g * s..(g + 1) * s];
            let tot: f64 = row.iter().sum();
            let top = row.iter().copied().fold(0.0, f64::max);
            // Seen weakly but consistently: keeps its confidence.
            if tot > 0.0 && top / tot < PURE_SHARE {
                *k = (v / cfg.full_visibility).min(1.0);
            }
        }
        for (c, &k) in confidence.iter_mut().zip(&confidence_scale) {
            *c *= k;
        }
    }
    let view_disagreement = if cfg.vote != ViewVote::Confidence {
        leave_one_out_disagreement(&votes, &view_totals, sums, n, s, nv)
    } else {
        vec![0.0; nv]
    };
    Ok(Lifted {
        num_parts: m,
        class_weights,
        labels,
        confidence,
        visibility,
        views,
        view_disagreement,
        confidence_scale,
        summed_weights: summed.unwrap_or_default(),
    })
}

/// `sqrt(det S / det(S + 0.3 I))` from the conic (the inverse of `S + 0.3 I`): 1 for a
/// Gaussian much larger than a pixel, towards 0 for one seen edge-on or smaller than a pixel.
pub fn footprint_share(p: &Projected<f32>) -> f32 {
    let [a, b, c] = p.conic.map(|x| x as f64);
    let det_c = a * c - b * b;
    if p.radii == [0, 0] || det_c.is_nan() || det_c <= 0.0 {
        return 0.0;
    }
    // S + 0.3 I = conic^-1.
    let (s00, s01, s11) = (c / det_c, -b / det_c, a / det_c);
    let det_b = s00 * s11 - s01 * s01;
    let det_s = (s00 - 0.3) * (s11 - 0.3) - s01 * s01;
    (det_s.max(0.0) / det_b).sqrt() as f32
}

fn argmax_u8(r: &[u8]) -> usize {
    let mut best = 0;
    for (c, &x) in r.iter().enumerate() {
        if x > r[best] {
            best = c;
        }
    }
    best
}

/// View `v`'s vote for class `l` on Gaussian `g`: its total times its class share.
fn view_vote<'a>(
    votes: &'a [u8],
    totals: &[f32],
    n: usize,
    s: usize,
    v: usize,
    g: usize,
) -> Option<(f64, &'a [u8])> {
    let t = totals[v * n + g] as f64;
    (t > 0.0).then(|| {
        (
            t / 255.0,
            &votes[(v * n + g) * (s + 1)..(v * n + g) * (s + 1) + s],
        )
    })
}

/// The consistency weights `w[v][l]` ([`LiftConfig::view_consistency_iters`]) from the current
/// combined evidence `cw` (which contains every view's votes; each view is compared with the
/// rest).
fn view_label_weights(
    votes: &[u8],
    totals: &[f32],
    cw: &[f64],
    n: usize,
    s: usize,
    nv: usize,
) -> Vec<f64> {
    let mut hit = vec![0f64; nv * s];
    let mut all = vec![0f64; nv * s];
    let mut rest = vec![0f64; s];
    for g in 0..n {
        let row = &cw[g * s..(g + 1) * s];
        for v in 0..nv {
            let Some((t, q)) = view_vote(votes, totals, n, s, v, g) else {
                continue;
            };
            // Leave-one-out consensus.
            for (r, (&c, &ql)) in rest.iter_mut().zip(row.iter().zip(q)) {
                *r = c - t * ql as f64;
            }
            let mut best = 0;
            for (c, &x) in rest.iter().enumerate() {
                if x > rest[best] {
                    best = c;
                }
            }
            if rest[best] <= 0.0 {
                continue;
            }
            for (l, &ql) in q.iter().enumerate() {
                let e = t * ql as f64;
                all[v * s + l] += e;
                if l == best {
                    hit[v * s + l] += e;
                }
            }
        }
    }
    let share: Vec<Option<f64>> = hit
        .iter()
        .zip(&all)
        .map(|(h, a)| (*a > 0.0).then(|| h / a))
        .collect();
    let mut w = vec![1f64; nv * s];
    for l in 0..s {
        let mut col: Vec<f64> = (0..nv).filter_map(|v| share[v * s + l]).collect();
        if col.is_empty() {
            continue;
        }
        col.sort_by(f64::total_cmp);
        let median = col[col.len() / 2];
        if median <= 0.0 {
            continue;
        }
        for v in 0..nv {
            if let Some(p) = share[v * s + l] {
                w[v * s + l] = (p / median).min(1.0).powi(2);
            }
        }
    }
    w
}

/// Per view, over the Gaussians it sees fully (weight >= the saturation) and is sure about
/// (90% of its own votes on one class), the share (weighted by its votes) on which its verdict
/// differs from the other views' combined one ([`Lifted::view_disagreement`]).
fn leave_one_out_disagreement(
    votes: &[u8],
    totals: &[f32],
    cw: &[f64],
    n: usize,
    s: usize,
    nv: usize,
) -> Vec<f32> {
    let sw = s + 1;
    let mut rest = vec![0f64; s];
    (0..nv)
        .map(|v| {
            let (mut seen, mut differ) = (0f64, 0f64);
            for g in 0..n {
                let r = &votes[(v * n + g) * sw..(v * n + g + 1) * sw];
                let Some((t, q)) = view_vote(votes, totals, n, s, v, g) else {
                    continue;
                };
                let top = argmax_u8(q);
                if r[s] < 255 || (q[top] as f64) < 0.9 * 255.0 {
                    continue;
                }
                let row = &cw[g * s..(g + 1) * s];
                for (x, (&c, &ql)) in rest.iter_mut().zip(row.iter().zip(q)) {
                    *x = c - t * ql as f64;
                }
                if rest.iter().all(|&x| x <= 1e-12) {
                    continue;
                }
                let other = argmax_f64(&rest);
                seen += t;
                if other != top {
                    differ += t;
                }
            }
            (differ / seen.max(1e-300)) as f32
        })
        .collect()
}

fn argmax_f64(r: &[f64]) -> usize {
    let mut best = 0;
    for (c, &x) in r.iter().enumerate() {
        if x > r[best] {
            best = c;
        }
    }
    best
}

/// `out[g][l] = sum_v vote_v(g, l) w[v][l]`.
fn reweigh(
    votes: &[u8],
    totals: &[f32],
    w: &[f64],
    n: usize,
    s: usize,
    nv: usize,
    out: &mut [f64],
) {
    for (g, row) in out.chunks_exact_mut(s).enumerate() {
        row.iter_mut().for_each(|x| *x = 0.0);
        for v in 0..nv {
            if let Some((t, q)) = view_vote(votes, totals, n, s, v, g) {
                for (l, (o, &ql)) in row.iter_mut().zip(q).enumerate() {
                    *o += t * ql as f64 * w[v * s + l];
                }
            }
        }
    }
}

/// [`ViewVote::Confidence`]: per Gaussian, the views' class distributions `q_v` weighted by
/// their confidence `k_v`; `iters` rounds multiply each `k_v` by the square of its agreement
/// `q_v . P` with the consensus `P` of the previous round.
fn combine_views(votes: &[u8], n: usize, s: usize, nv: usize, iters: u32, out: &mut [f64]) {
    let sw = s + 1;
    let one = |gi: usize, row: &mut [f64]| {
        let mut k: Vec<(usize, f64)> = (0..nv)
            .filter_map(|v| {
                let kv = votes[(v * n + gi) * sw + s];
                (kv > 0).then_some((v, kv as f64 / 255.0))
            })
            .collect();
        let q = |v: usize, c: usize| votes[(v * n + gi) * sw + c] as f64 / 255.0;
        let consensus = |k: &[(usize, f64)], row: &mut [f64]| {
            row.iter_mut().for_each(|x| *x = 0.0);
            for &(v, kv) in k {
                for (c, r) in row.iter_mut().enumerate() {
                    *r += kv * q(v, c);
                }
            }
        };
        consensus(&k, row);
        for _ in 0..iters {
            let tot: f64 = row.iter().sum();
            if tot <= 0.0 {
                break;
            }
            for (v, kv) in k.iter_mut() {
                let agree: f64 = (0..s).map(|c| q(*v, c) * row[c] / tot).sum();
                *kv *= agree * agree;
            }
            consensus(&k, row);
        }
    };
    #[cfg(feature = "parallel")]
    {
        use rayon::prelude::*;
        out.par_chunks_mut(s)
            .enumerate()
            .with_min_len(1024)
            .for_each(|(gi, row)| one(gi, row));
    }
    #[cfg(not(feature = "parallel"))]
    for (gi, row) in out.chunks_mut(s).enumerate() {
        one(gi, row);
    }
}
