//! Heap measurement through a hook the caller supplies: the fit reports the peak memory of
//! its stages without reaching for a global allocator itself (the `r4d` binary's counting
//! allocator implements [`HeapProbe`]; an embedding engine may plug in its own, or none).

use std::fmt::Debug;

/// Measures the highest live heap bytes over stretches of work. Implementations must let
/// several measurements run at once without disturbing each other (parallel initialisation
/// candidates each measure their own evaluation).
pub trait HeapProbe: Send + Sync + Debug {
    /// Starts a measurement.
    fn start(&self) -> Box<dyn HeapSpan>;
}

/// A running measurement ([`HeapProbe::start`]).
pub trait HeapSpan: Send {
    /// The live heap bytes when the measurement started (0 when nothing can be measured).
    fn base(&self) -> usize;
    /// The highest live heap bytes (absolute) since the measurement started; 0 when nothing
    /// could be measured.
    fn peak(&self) -> usize;
}
