//! Why a video file could not be read or written; every variant names the file.

use std::path::PathBuf;

/// Why a video file could not be read or written.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum VideoError {
    /// The file could not be opened, read or written.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The error.
        source: std::io::Error,
    },
    /// Not an ISO base-media (MP4) file, or a structure in it breaks the format's rules.
    #[error("{path}: not a valid MP4 file: {message}")]
    Container {
        /// The file.
        path: PathBuf,
        /// The rule that is broken, and where.
        message: String,
    },
    /// The video track is coded with something other than H.264.
    #[error(
        "{path}: the video is coded as '{codec}'; only H.264 ('avc1'/'avc3') MP4 can be read \
         (convert it, e.g. `ffmpeg -i IN -c:v libx264 -pix_fmt yuv420p OUT.mp4`, or give a folder of PNG frames)"
    )]
    Codec {
        /// The file.
        path: PathBuf,
        /// The sample-entry code of the track (`hvc1`, `av01`, `vp09`, `mp4v`, ...).
        codec: String,
    },
    /// The H.264 stream could not be decoded.
    #[error("{path}: H.264 frame {frame}: {message}")]
    Decode {
        /// The file.
        path: PathBuf,
        /// The sample (0-based) being decoded.
        frame: usize,
        /// The decoder's message.
        message: String,
    },
    /// A size or count beyond what this reader or writer accepts.
    #[error("{path}: {what} is {got}, the limit is {limit}")]
    Limit {
        /// The file.
        path: PathBuf,
        /// What is too large.
        what: &'static str,
        /// Its value.
        got: u64,
        /// The limit.
        limit: u64,
    },
    /// The frames asked for do not exist in the video.
    #[error("{path}: {message}")]
    Frames {
        /// The file.
        path: PathBuf,
        /// What was asked and what the video has.
        message: String,
    },
    /// The encoder failed or was given frames it cannot take.
    #[error("{path}: H.264 encoding: {message}")]
    Encode {
        /// The file being written.
        path: PathBuf,
        /// What went wrong.
        message: String,
    },
    /// A PNG directory or `.npy` video (read by `r4d_frames::io`).
    #[error(transparent)]
    Other(#[from] r4d_frames::io::VideoIoError),
}

impl VideoError {
    pub(crate) fn container(path: &std::path::Path, message: impl Into<String>) -> Self {
        VideoError::Container {
            path: path.to_path_buf(),
            message: message.into(),
        }
    }

    pub(crate) fn io(path: &std::path::Path) -> impl FnOnce(std::io::Error) -> Self + '_ {
        move |source| VideoError::Io {
            path: path.to_path_buf(),
            source,
        }
    }
}

/// Result with [`VideoError`].
pub type Result<T, E = VideoError> = std::result::Result<T, E>;
