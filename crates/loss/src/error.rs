//! The error type of every loss and metric: it names the offending input.

pub use r4d_frames::Input;

/// Bad input or configuration of a loss or metric.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum LossError {
    /// A malformed video: its shape, or a NaN or infinite value (names the input).
    #[error(transparent)]
    Frame(#[from] r4d_frames::FrameError),
    /// The two videos have different frame counts.
    #[error("reference has {reference} frames, rendered has {rendered}")]
    FrameCount {
        /// Frames of the reference.
        reference: usize,
        /// Frames of the rendered video.
        rendered: usize,
    },
    /// The two videos have different frame sizes.
    #[error(
        "reference frames are {}x{} (HxW), rendered frames are {}x{}",
        reference.0, reference.1, rendered.0, rendered.1
    )]
    FrameSize {
        /// (height, width) of the reference.
        reference: (usize, usize),
        /// (height, width) of the rendered video.
        rendered: (usize, usize),
    },
    /// Too few frames for a term that needs frame differences.
    #[error("{input} has {frames} frame(s); {what} needs at least {needed}")]
    TooFewFrames {
        /// The video.
        input: Input,
        /// Frames it has.
        frames: usize,
        /// Frames needed.
        needed: usize,
        /// The term that needs them.
        what: &'static str,
    },
    /// Frames smaller than one spectral patch.
    #[error(
        "{input}: frames of {height}x{width} (HxW) are smaller than one {patch_h}x{patch_w} \
         patch of the spectral loss"
    )]
    SmallerThanPatch {
        /// The video.
        input: Input,
        /// Rows.
        height: usize,
        /// Columns.
        width: usize,
        /// Patch rows.
        patch_h: usize,
        /// Patch columns.
        patch_w: usize,
    },
    /// Frames smaller than the SSIM window (valid filtering needs at least one output pixel).
    #[error(
        "{input}: frames of {height}x{width} (HxW) are smaller than the {window}x{window} SSIM \
         window"
    )]
    SmallerThanWindow {
        /// The video.
        input: Input,
        /// Rows.
        height: usize,
        /// Columns.
        width: usize,
        /// Window size.
        window: usize,
    },
    /// MS-SSIM with this window needs larger frames (pytorch-msssim's assertion).
    #[error(
        "{input}: MS-SSIM with a {window}-tap window needs both sides > {min_side_exclusive} px \
         (frames are {height}x{width}); use `MsSsimConfig::largest_window` for the \
         smaller-window fallback"
    )]
    TooSmallForMsSsim {
        /// The video.
        input: Input,
        /// Rows.
        height: usize,
        /// Columns.
        width: usize,
        /// Window size.
        window: usize,
        /// `(window - 1) * 16`.
        min_side_exclusive: usize,
    },
    /// A gradient buffer of the wrong length.
    #[error("gradient buffer has {got} values, the rendered video has {expected}")]
    GradientLength {
        /// Values of the rendered video.
        expected: usize,
        /// Values of the buffer.
        got: usize,
    },
    /// An invalid configuration value.
    #[error("invalid loss configuration: {0}")]
    Config(String),
}
