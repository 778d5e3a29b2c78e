//! Errors of the `r4d-splat` crate: every defect of a file names the file and the field.

use std::path::PathBuf;

/// Result with the crate's [`Error`].
pub type Result<T, E = Error> = std::result::Result<T, E>;

/// Errors of the renderer and its inputs.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// A PLY file is malformed (syntax, truncation, types, missing properties, NaN).
    #[error("{file}: {message}")]
    Ply {
        /// The file.
        file: String,
        /// What is wrong, naming the property and vertex where known.
        message: String,
    },
    /// A camera file is malformed.
    #[error("{file}: {message}")]
    Camera {
        /// The file.
        file: String,
        /// What is wrong, naming the field where known.
        message: String,
    },
    /// Inputs do not fit together (array lengths, image sizes, indices).
    #[error("{0}")]
    Mismatch(String),
    /// Reading or writing a file failed.
    #[error("{path}: {source}")]
    Io {
        /// The path.
        path: PathBuf,
        /// The OS error.
        #[source]
        source: std::io::Error,
    },
    /// A backend failed.
    #[error("backend: {0}")]
    Backend(#[source] Box<dyn std::error::Error + Send + Sync>),
}

impl From<r4d_ply::PlyError> for Error {
    fn from(e: r4d_ply::PlyError) -> Self {
        match e {
            r4d_ply::PlyError::Malformed { file, message } => Error::Ply {
                file,
                message: format!("malformed PLY: {message}"),
            },
            r4d_ply::PlyError::Io { path, source } => Error::Io { path, source },
        }
    }
}
