//! # r4d-segment: part assignment by lifting 2D masks onto 3D Gaussians
//!
//! Part-level material parameters need parts. The paper segments the multi-view images with
//! a text-prompted zero-shot segmenter, lifts the 2D masks onto the Gaussians and cleans the
//! labels in 3D; this crate does the lifting and the cleaning, whatever segmenter made the
//! masks.
//!
//! 1. [`mask`]: per-view masks (label maps or per-class probabilities) behind the
//!    [`MaskSource`] trait; [`MaskDir`] reads them from files (layout in its docs), a
//!    model-backed segmenter can implement the trait.
//! 2. [`mod@lift`]: per Gaussian and class, the sum over views and pixels of the Gaussian's
//!    compositing weight `alpha T` (from the renderer's own forward pass,
//!    [`r4d_splat::weights`]) times the mask value; normalised, softmax over classes at a
//!    temperature, argmax label and its confidence; background (-1, static) for Gaussians
//!    that fall in no moving-part mask.
//! 3. [`mod@regions`]: smooth-surface regions of the Gaussians (graph segmentation that ends
//!    at creases); each region's summed evidence is a prior on which part its Gaussians are.
//!    [`mod@smooth`]: KNN in 3D (kd-tree): confidence-weighted label propagation over the
//!    graph of the `k` nearest Gaussians (neighbours across a crease count less), labels for
//!    unobserved regions, suppression of isolated clusters.
//! 4. [`labels`]: the part labels file (`{"num_parts", "class_names", "labels",
//!    "confidence", "counts"}`) that `r4d fit --parts` reads, and the transfer of labels onto
//!    simulation particles (filling particles take the label of their nearest labelled
//!    particle).
//!
//! [`segment`] runs 2 and 3. [`synthetic`] is a test scene with analytic masks.
//!
//! ## Example
//!
//! ```
//! use r4d_segment::{segment, synthetic, SegmentConfig};
//! let scene = synthetic::three_parts(3000, 1);
//! let cams = synthetic::ring_cameras(8, 96, 72);
//! let mut masks = scene.masks(&cams);
//! let out = segment(&scene.gaussians, &cams, &mut masks, &SegmentConfig::default()).unwrap();
//! let acc = synthetic::accuracy(&out.labels.labels, &scene.truth);
//! assert!(acc > 0.9, "{acc}");
//! assert_eq!(out.labels.class_names, ["box", "ball", "post"]);
//! ```

pub mod boundary;
pub mod confusion;
pub mod error;
pub mod label_map;
pub mod labels;
pub mod lift;
pub mod mask;
pub mod regions;
pub mod smooth;
pub mod synthetic;

pub use error::{Error, Result};
pub use labels::{part_colour, PartLabels};
pub use lift::{lift, LiftConfig, Lifted, ViewVote};
pub use mask::{InMemoryMasks, Mask, MaskData, MaskDir, MaskSource};
pub use smooth::{smooth, smooth_gaussians, smooth_lifted, SmoothConfig};

use r4d_splat::{Camera, Gaussians};

/// Parallelism of an algorithm (faer's `Par`): `Seq` runs on the calling thread; `Rayon` on
/// rayon's pool (with the `parallel` feature; without it, the same as `Seq`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Par {
    /// Single-threaded.
    Seq,
    /// Rayon's global pool.
    #[default]
    Rayon,
}

/// Settings of [`segment`].
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SegmentConfig {
    /// The lift.
    pub lift: LiftConfig,
    /// The KNN pass (`None`: the raw lift's labels).
    pub smooth: Option<SmoothConfig>,
}

/// The outcome of [`segment`].
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Segmentation {
    /// The raw lift (class weights, labels and confidences before smoothing).
    pub lifted: Lifted,
    /// The final labels (after smoothing when configured).
    pub labels: PartLabels,
}

/// Lifts the masks of every camera onto the Gaussians, then smooths the labels in 3D.
pub fn segment<S: MaskSource + ?Sized>(
    g: &Gaussians,
    cameras: &[Camera],
    masks: &mut S,
    cfg: &SegmentConfig,
) -> Result<Segmentation> {
    let names = masks.class_names().to_vec();
    let lifted = lift(g, cameras, masks, &cfg.lift)?;
    let (labels, confidence) = match &cfg.smooth {
        Some(s) => smooth::smooth_lifted(g, &lifted, cfg.lift.temperature, s)?,
        None => (lifted.labels.clone(), lifted.confidence.clone()),
    };
    Ok(Segmentation {
        lifted,
        labels: PartLabels::new(names, labels, confidence),
    })
}
