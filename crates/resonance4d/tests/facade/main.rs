//! The facade's tests, in one binary: the examples run as tests, and the host backends pass
//! the exported conformance suite.

mod conformance;
mod examples;
