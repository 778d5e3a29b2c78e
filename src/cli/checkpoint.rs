//! `checkpoint.json` of `r4d fit` and `r4d fit-trajectory`: one format for both
//! ([`FitState`], versioned, checksummed, fingerprinted), written atomically.

use anyhow::{Context, Result};
use resonance4d::video_fit::FitState;
use std::path::Path;

/// The largest checkpoint read (bytes): a per-particle fit of a million particles writes a few
/// hundred MB; a larger file is refused from its size.
const MAX_CHECKPOINT_BYTES: u64 = 2 << 30;

/// Reads a run's checkpoint: `None` when there is none yet (a run killed before its first
/// checkpoint starts over); an unreadable, damaged or foreign-format file is an error naming
/// it, never a silent restart that overwrites the run.
pub fn read(path: &Path) -> Result<Option<FitState>> {
    let bytes = match r4d_fsio::read_bounded(path, MAX_CHECKPOINT_BYTES) {
        Ok(b) => b,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
        Err(e) => return Err(e).with_context(|| format!("--resume: reading {}", path.display())),
    };
    let text = std::str::from_utf8(&bytes)
        .map_err(|_| anyhow::anyhow!("{}: not a fit checkpoint (not UTF-8)", path.display()))?;
    let state =
        FitState::from_json(text).with_context(|| format!("--resume: {}", path.display()))?;
    Ok(Some(state))
}

/// Writes a checkpoint atomically.
pub fn write(path: &Path, state: &FitState) -> Result<()> {
    r4d_fsio::write_atomic(path, (state.to_json() + "\n").as_bytes())
        .with_context(|| format!("writing {}", path.display()))
}
