//! Writing `.npy` arrays (little-endian float32, C order, format version 1.0).

use anyhow::{Context, Result};
use std::path::Path;

/// Writes `data` with `shape` as a float32 `.npy` file.
pub fn write_npy_f32(path: &Path, shape: &[usize], data: &[f32]) -> Result<()> {
    let out = r4d_fsio::npy::encode_f32(shape, data);
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    }
    r4d_fsio::write_atomic(path, &out).with_context(|| format!("writing {}", path.display()))
}
