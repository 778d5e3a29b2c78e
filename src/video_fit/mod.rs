//! The video fit, as one path for the CLI and for embedding: the algorithm is
//! [`r4d_optim::video`] (problem, objective, `FIT.toml`, the fit loop), the evaluation and the
//! result files are [`r4d_eval`]; the backend is a [`crate::compute`] (`problem.compute`).

pub use r4d_eval::{dataset, eval, report};
pub use r4d_optim::space as params;
pub use r4d_optim::video::*;
pub use r4d_optim::{Compute, FitError, Precision};
pub use r4d_segment::PartLabels;

pub use dataset::{problem_from_dataset, problem_with_views};
