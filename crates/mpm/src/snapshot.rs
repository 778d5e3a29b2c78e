//! Snapshots of a simulation state on disk, so a killed run resumes where it stopped.
//!
//! Format (little-endian): the magic `R4DSNAP1`, then `u64` particle count, `u64` frame,
//! `u64` substep, `f64` time (s), then the particle arrays as raw f32: `x` (3 per particle),
//! `v` (3), `C` (9), `F` (9), plastic state (2).

use crate::error::{Error, Result};
use std::path::Path;

const MAGIC: &[u8; 8] = b"R4DSNAP1";

/// A host copy of a simulation state.
#[derive(Clone, Debug, PartialEq)]
pub struct Snapshot {
    /// Frames done.
    pub frame: usize,
    /// Substeps done.
    pub substep: u64,
    /// Simulated time (s).
    pub time_s: f64,
    /// Positions.
    pub x: Vec<[f32; 3]>,
    /// Velocities.
    pub v: Vec<[f32; 3]>,
    /// APIC matrices.
    pub c: Vec<[f32; 9]>,
    /// Deformation gradients.
    pub f: Vec<[f32; 9]>,
    /// Plastic states.
    pub plastic: Vec<[f32; 2]>,
}

impl Snapshot {
    /// Writes the snapshot atomically (a temporary file renamed over `path`).
    pub fn write(&self, path: &Path) -> Result<()> {
        let io = |source| Error::Io {
            path: path.to_path_buf(),
            source,
        };
        let mut b = Vec::with_capacity(40 + self.x.len() * 26 * 4);
        b.extend_from_slice(MAGIC);
        b.extend_from_slice(&(self.x.len() as u64).to_le_bytes());
        b.extend_from_slice(&(self.frame as u64).to_le_bytes());
        b.extend_from_slice(&self.substep.to_le_bytes());
        b.extend_from_slice(&self.time_s.to_le_bytes());
        for part in [
            bytemuck::cast_slice::<_, f32>(&self.x),
            bytemuck::cast_slice(&self.v),
            bytemuck::cast_slice(&self.c),
            bytemuck::cast_slice(&self.f),
            bytemuck::cast_slice(&self.plastic),
        ] {
            for x in part {
                b.extend_from_slice(&x.to_le_bytes());
            }
        }
        let tmp = path.with_extension("tmp");
        std::fs::write(&tmp, &b).map_err(io)?;
        std::fs::rename(&tmp, path).map_err(io)
    }

    /// Reads a snapshot of `particles` particles.
    pub fn read(path: &Path, particles: usize) -> Result<Snapshot> {
        let b = std::fs::read(path).map_err(|source| Error::Io {
            path: path.to_path_buf(),
            source,
        })?;
        let bad = |m: String| Error::Scene {
            what: path.display().to_string(),
            message: m,
        };
        if b.len() < 40 || &b[..8] != MAGIC {
            return Err(bad("not a resonance4d state snapshot".into()));
        }
        let u = |o: usize| u64::from_le_bytes(b[o..o + 8].try_into().expect("8 bytes"));
        let n = u(8) as usize;
        if n != particles {
            return Err(bad(format!(
                "the snapshot has {n} particles, the scene {particles}"
            )));
        }
        if b.len() != 40 + n * 26 * 4 {
            return Err(bad(format!(
                "truncated: {} bytes, expected {}",
                b.len(),
                40 + n * 26 * 4
            )));
        }
        let mut off = 40;
        let mut take = |count: usize| -> Vec<f32> {
            let out = b[off..off + 4 * count]
                .chunks_exact(4)
                .map(|c| f32::from_le_bytes(c.try_into().expect("4 bytes")))
                .collect();
            off += 4 * count;
            out
        };
        fn group<const K: usize>(v: Vec<f32>) -> Vec<[f32; K]> {
            v.chunks_exact(K)
                .map(|c| c.try_into().expect("K values"))
                .collect()
        }
        let x = group::<3>(take(3 * n));
        let v = group::<3>(take(3 * n));
        let c = group::<9>(take(9 * n));
        let f = group::<9>(take(9 * n));
        let plastic = group::<2>(take(2 * n));
        Ok(Snapshot {
            frame: u(16) as usize,
            substep: u(24),
            time_s: f64::from_le_bytes(b[32..40].try_into().expect("8 bytes")),
            x,
            v,
            c,
            f,
            plastic,
        })
    }
}
