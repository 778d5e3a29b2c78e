//! Errors of the `r4d-segment` crate: every defect of an input names the file (or the mask
//! source's description of the view) and what is wrong with it.

use std::path::PathBuf;

/// Result with the crate's [`Error`].
pub type Result<T, E = Error> = std::result::Result<T, E>;

/// Errors of mask reading, lifting and part label files.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// Reading or writing a file failed.
    #[error("{path}: {source}")]
    Io {
        /// The path.
        path: PathBuf,
        /// The OS error.
        #[source]
        source: std::io::Error,
    },
    /// A mask file cannot be decoded or has the wrong pixel format, dtype, shape or values.
    #[error("{file}: {message}")]
    Mask {
        /// The mask file.
        file: String,
        /// What is wrong.
        message: String,
    },
    /// A mask's size is not its camera's.
    #[error("{file}: mask is {got_w}x{got_h} but camera {view} ('{camera}') is {want_w}x{want_h}")]
    MaskSize {
        /// The mask file (or the source's description of the view).
        file: String,
        /// The view's index in the camera file.
        view: usize,
        /// The camera's name.
        camera: String,
        /// Mask width.
        got_w: u32,
        /// Mask height.
        got_h: u32,
        /// Camera width.
        want_w: u32,
        /// Camera height.
        want_h: u32,
    },
    /// A view has no mask.
    #[error("{dir}: no mask for camera {view} ('{camera}'): tried {tried}")]
    NoMask {
        /// The mask directory.
        dir: String,
        /// The view's index in the camera file.
        view: usize,
        /// The camera's name.
        camera: String,
        /// The file names looked for.
        tried: String,
    },
    /// A label map holds a value that names no class.
    #[error(
        "{file}: pixel ({x}, {y}) has label {value}, which names no class (0 = background, 1..={num_parts} = parts{ignore})"
    )]
    UnknownLabel {
        /// The mask file.
        file: String,
        /// Pixel column.
        x: u32,
        /// Pixel row.
        y: u32,
        /// The value found.
        value: u32,
        /// Number of parts.
        num_parts: usize,
        /// `", N = ignored"` when an ignore value is set, else empty.
        ignore: String,
    },
    /// A per-class probability map names a class that is not declared.
    #[error("{file}: unknown class '{class}' (classes: {known})")]
    UnknownClass {
        /// The offending map.
        file: String,
        /// Its class name.
        class: String,
        /// The declared classes.
        known: String,
    },
    /// The classes file (`classes.json`) is malformed.
    #[error("{file}: {message}")]
    Classes {
        /// The file.
        file: String,
        /// What is wrong.
        message: String,
    },
    /// A part labels file (JSON or PLY with a `part` property) is malformed.
    #[error("{file}: {message}")]
    Parts {
        /// The file.
        file: String,
        /// What is wrong.
        message: String,
    },
    /// Inputs that do not fit together (label counts, particles, parameters).
    #[error("{0}")]
    Input(String),
    /// The scene or a camera was refused by the renderer's checks.
    #[error(transparent)]
    Splat(#[from] r4d_splat::Error),
    /// A PLY file could not be read or written.
    #[error(transparent)]
    Ply(#[from] r4d_ply::PlyError),
}

impl Error {
    /// An I/O error on `path`.
    pub fn io(path: impl Into<PathBuf>) -> impl FnOnce(std::io::Error) -> Error {
        let path = path.into();
        move |source| Error::Io { path, source }
    }

    /// A mask defect in `file`.
    pub fn mask(file: impl std::fmt::Display, message: impl Into<String>) -> Error {
        Error::Mask {
            file: file.to_string(),
            message: message.into(),
        }
    }
}
