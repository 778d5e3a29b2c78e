//! Part labels of a scene's Gaussians: [`PartLabels`] lives in `r4d-segment` (the crate that
//! writes them with `r4d segment`); re-exported here so `video_fit::PartLabels` keeps working.

pub use r4d_segment::PartLabels;
