//! Errors of the dataset loaders: every one names the file (or folder) and the rule it breaks.

use std::path::PathBuf;

/// Result with the crate's [`DatasetError`].
pub type Result<T, E = DatasetError> = std::result::Result<T, E>;

/// Why a dataset folder could not be read.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum DatasetError {
    /// A file the layout needs is not there.
    #[error("{path}: missing: {expected}")]
    Missing {
        /// The file or folder that was looked for.
        path: PathBuf,
        /// What the layout expects there.
        expected: String,
    },
    /// A file exists but breaks a rule of its format or of the layout.
    #[error("{path}: {rule}")]
    Invalid {
        /// The file (or folder).
        path: PathBuf,
        /// The rule it breaks, with the offending value.
        rule: String,
    },
    /// The folder matches no known layout.
    #[error("{path}: not a dataset folder: {why}")]
    UnknownLayout {
        /// The folder.
        path: PathBuf,
        /// What was looked for.
        why: String,
    },
    /// A config the simulator refuses (names the file and key).
    #[error(transparent)]
    Mpm(#[from] r4d_mpm::Error),
    /// A scene or camera file the renderer refuses (names the file and field).
    #[error(transparent)]
    Splat(#[from] r4d_splat::Error),
    /// A PLY file that cannot be read.
    #[error(transparent)]
    Ply(#[from] r4d_ply::PlyError),
    /// A video or frame that cannot be read.
    #[error(transparent)]
    Video(#[from] r4d_loss::io::VideoIoError),
    /// An MP4 that cannot be read (or another codec).
    #[error(transparent)]
    Mp4(#[from] r4d_video::VideoError),
    /// Reading a file failed.
    #[error("{path}: {source}")]
    Io {
        /// The path.
        path: PathBuf,
        /// The OS error.
        #[source]
        source: std::io::Error,
    },
}

impl DatasetError {
    /// An [`DatasetError::Invalid`] for `path`.
    pub fn invalid(path: impl Into<PathBuf>, rule: impl Into<String>) -> Self {
        DatasetError::Invalid {
            path: path.into(),
            rule: rule.into(),
        }
    }
    /// A [`DatasetError::Missing`] for `path`.
    pub fn missing(path: impl Into<PathBuf>, expected: impl Into<String>) -> Self {
        DatasetError::Missing {
            path: path.into(),
            expected: expected.into(),
        }
    }
}

/// Reads a text file, naming it on failure.
pub(crate) fn read_text(path: &std::path::Path) -> Result<String> {
    r4d_fsio::read_to_string_bounded(path, r4d_fsio::MAX_TEXT_BYTES).map_err(|source| {
        DatasetError::Io {
            path: path.to_path_buf(),
            source,
        }
    })
}
