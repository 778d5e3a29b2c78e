//! The fit's parameter spaces live in `r4d-optim` ([`r4d_optim::space`]); re-exported here.

pub use r4d_optim::space::*;
