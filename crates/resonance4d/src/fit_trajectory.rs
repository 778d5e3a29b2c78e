//! The trajectory fit (`r4d fit-trajectory`): the algorithm is [`r4d_optim::trajectory`]; it
//! runs on any [`Compute`] ([`crate::compute`]).

pub use r4d_optim::trajectory::{
    fit_trajectory, fit_trajectory_resumable, FitOptions, FitState, Fitted, Granularity,
    IterRecord, PartRecord,
};
pub use r4d_optim::{Compute, FitError};
