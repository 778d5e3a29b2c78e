//! The loss crate's integration tests, in one binary: band-wise DMS against the whole-video
//! loss.

mod bands;
