//! The video fit, as one path for the CLI and for embedding: the algorithm is
//! [`r4d_optim::video`] (problem, objective, `FIT.toml`, the fit loop); with the `eval` feature
//! the evaluation, the result files and dataset folders as problems (`r4d_eval`). The backend
//! is a [`crate::compute`] (`problem.compute`).

#[cfg(feature = "eval")]
pub use r4d_eval::{dataset, eval, report};
pub use r4d_optim::space as params;
pub use r4d_optim::video::*;
pub use r4d_optim::{Compute, FitError, Precision};
#[cfg(feature = "segment")]
pub use r4d_segment::PartLabels;

#[cfg(feature = "eval")]
pub use dataset::{problem_from_dataset, problem_with_views};
