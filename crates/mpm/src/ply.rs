//! PLY reading and writing for particles: [`r4d_ply`] with errors mapped into the crate's
//! [`Error`] (`Error::Ply` naming the file).

use crate::error::{Error, Result};
pub use r4d_ply::{PlyType, PlyVertices};
use std::path::Path;

impl From<r4d_ply::PlyError> for Error {
    fn from(e: r4d_ply::PlyError) -> Self {
        match e {
            r4d_ply::PlyError::Malformed { file, message } => Error::Ply { file, message },
            r4d_ply::PlyError::Io { path, source } => Error::Io { path, source },
        }
    }
}

/// Reads the vertex element of a PLY file.
pub fn read_ply(path: &Path) -> Result<PlyVertices> {
    Ok(r4d_ply::read_ply(path)?)
}

/// Parses PLY bytes; `file` names the source in errors.
pub fn parse_ply(bytes: &[u8], file: &str) -> Result<PlyVertices> {
    Ok(r4d_ply::parse_ply(bytes, file)?)
}

/// Writes float columns as a binary little-endian PLY vertex element.
pub fn write_ply(path: &Path, names: &[&str], columns: &[&[f32]]) -> Result<()> {
    Ok(r4d_ply::write_ply(path, names, columns)?)
}
