//! The error of a malformed video: it names the offending input.

use std::fmt;

/// Which video an error is about.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Input {
    /// The rendered video (the one differentiated).
    Rendered,
    /// The reference (ground-truth) video.
    Reference,
}

impl fmt::Display for Input {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Input::Rendered => "rendered",
            Input::Reference => "reference",
        })
    }
}

/// A video whose shape or values are unusable.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum FrameError {
    /// The data length does not match the stated shape.
    #[error("{input}: {got} values for {frames} x {height} x {width} x 3 = {expected}")]
    DataLength {
        /// The video.
        input: Input,
        /// Frames stated.
        frames: usize,
        /// Rows stated.
        height: usize,
        /// Columns stated.
        width: usize,
        /// Values the shape needs.
        expected: usize,
        /// Values given.
        got: usize,
    },
    /// A video has no frames or empty frames.
    #[error("{input} is empty ({frames} frames of {height} x {width})")]
    Empty {
        /// The video.
        input: Input,
        /// Frames.
        frames: usize,
        /// Rows.
        height: usize,
        /// Columns.
        width: usize,
    },
    /// A NaN or infinite value.
    #[error("{input}: frame {frame} has {kind} at row {row}, column {col}, channel {channel}")]
    NonFinite {
        /// The video.
        input: Input,
        /// Frame index.
        frame: usize,
        /// Row.
        row: usize,
        /// Column.
        col: usize,
        /// Channel (0 = R).
        channel: usize,
        /// "NaN" or "an infinite value".
        kind: &'static str,
    },
}
