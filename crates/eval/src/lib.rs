//! # r4d-eval: evaluation and reports of resonance4d's fits
//!
//! What is measured on a fit, and what a finished fit leaves behind, generic over the backend
//! (a fit's problem carries its [`r4d_optim::Compute`]; no backend crate here):
//!
//! * [`eval`]: the paper's evaluation protocol on fitted parameters (`r4d eval`): PSNR, SSIM,
//!   MS-SSIM and LPIPS on videos at 30 fps, Chamfer, HD95 and F-score on trajectories.
//! * [`report`]: the files a fit leaves in its run directory (`params.json`,
//!   `metrics.json`, the fitted video and its diagnostics, the loss curve).
//! * [`diagnostics`]: the diagnostic images (side-by-side GIF, w-t slices and their temporal
//!   spectra, loss curve).
//! * [`dataset`]: a dataset folder ([`r4d_datasets`]) as a fitting problem.
//! * [`bench_scale`]: one fit iteration at the paper's scale, measured stage by stage
//!   (`r4d bench-scale`).

pub mod bench_scale;
pub mod dataset;
pub mod diagnostics;
pub mod eval;
pub mod report;
