//! The loss crate's integration tests, in one binary: band-wise DMS against the whole-video
//! loss, the losses and metrics against the pytorch-msssim / numpy goldens, the trajectory
//! metrics against numpy + scipy.

mod bands;
mod loss_goldens;
mod trajectory_metrics;
