//! Snapshots of a simulation state on disk, so a killed run resumes where it stopped.
//!
//! Format 2 (little-endian): the magic `R4DSNAP2`, then `u64` particle count, `u64` frame,
//! `u64` substep, `f64` time (s), the 32-byte fingerprint of the run's inputs (ASCII hex,
//! [`Snapshot::fingerprint`]), the particle arrays as raw f32: `x` (3 per particle), `v` (3),
//! `C` (9), `F` (9), plastic state (2); last, the 32-byte checksum (ASCII hex,
//! [`r4d_fsio::Fingerprint`]) of every byte before it. [`Snapshot::read`] refuses another
//! format (format 1, `R4DSNAP1`, had neither fingerprint nor checksum), a wrong particle
//! count, a wrong size, a checksum mismatch (damage) and a fingerprint mismatch (a state of
//! other inputs), each with a typed error naming the file.

use crate::error::{Error, Result};
use std::path::Path;

const MAGIC: &[u8; 8] = b"R4DSNAP2";
/// Header bytes: magic, four 8-byte fields, the fingerprint.
const HEADER: usize = 8 + 32 + 32;
/// Trailer bytes: the checksum.
const TRAILER: usize = 32;
/// f32 values per particle.
const PER_PARTICLE: usize = 26;

/// The checksum of `bytes` (32 ASCII hex digits).
fn checksum(bytes: &[u8]) -> [u8; 32] {
    let mut f = r4d_fsio::Fingerprint::new();
    f.bytes(bytes);
    let mut out = [0u8; 32];
    out.copy_from_slice(f.finish().as_bytes());
    out
}

/// A fingerprint as its 32 stored bytes (zero-padded; longer ones are hashed).
fn fingerprint_bytes(fp: &str) -> [u8; 32] {
    let mut out = [0u8; 32];
    if fp.len() <= 32 {
        out[..fp.len()].copy_from_slice(fp.as_bytes());
    } else {
        let mut f = r4d_fsio::Fingerprint::new();
        f.text(fp);
        out.copy_from_slice(f.finish().as_bytes());
    }
    out
}

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
    /// Fingerprint of the run's inputs (config, particles, options: whatever the caller
    /// resumes; at most 32 bytes are stored, longer ones are hashed), checked by
    /// [`Snapshot::read`].
    pub fingerprint: String,
}

impl Snapshot {
    /// Writes the snapshot atomically (a temporary file renamed over `path`).
    pub fn write(&self, path: &Path) -> Result<()> {
        let io = |source| Error::Io {
            path: path.to_path_buf(),
            source,
        };
        let mut b = Vec::with_capacity(HEADER + self.x.len() * PER_PARTICLE * 4 + TRAILER);
        b.extend_from_slice(MAGIC);
        b.extend_from_slice(&(self.x.len() as u64).to_le_bytes());
        b.extend_from_slice(&(self.frame as u64).to_le_bytes());
        b.extend_from_slice(&self.substep.to_le_bytes());
        b.extend_from_slice(&self.time_s.to_le_bytes());
        b.extend_from_slice(&fingerprint_bytes(&self.fingerprint));
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
        let sum = checksum(&b);
        b.extend_from_slice(&sum);
        r4d_fsio::write_atomic(path, &b).map_err(io)
    }

    /// Reads a snapshot of `particles` particles written for the inputs `fingerprint` (see
    /// the module docs for what is refused).
    pub fn read(path: &Path, particles: usize, fingerprint: &str) -> Result<Snapshot> {
        let len = std::fs::metadata(path)
            .map_err(|source| Error::Io {
                path: path.to_path_buf(),
                source,
            })?
            .len();
        // The size is known from the particle count: a larger file is not read.
        let expected = (particles as u64)
            .saturating_mul((PER_PARTICLE * 4) as u64)
            .saturating_add((HEADER + TRAILER) as u64);
        if len > expected {
            return Err(Error::Scene {
                what: path.display().to_string(),
                message: format!(
                    "{len} bytes, expected {expected} for {particles} particles (not this scene's state)"
                ),
            });
        }
        let b = r4d_fsio::read_bounded(path, r4d_fsio::MAX_BINARY_BYTES).map_err(|source| {
            Error::Io {
                path: path.to_path_buf(),
                source,
            }
        })?;
        Snapshot::decode(&b, path, particles, fingerprint)
    }

    /// [`Snapshot::read`] on the file's bytes (`path` names it in errors).
    pub fn decode(b: &[u8], path: &Path, particles: usize, fingerprint: &str) -> Result<Snapshot> {
        let bad = |m: String| Error::Scene {
            what: path.display().to_string(),
            message: m,
        };
        if b.len() >= 8 && &b[..8] == b"R4DSNAP1" {
            return Err(bad(
                "a format-1 state snapshot (written by an older r4d, without fingerprint or checksum); this version reads format 2: simulate again without --resume".into(),
            ));
        }
        if b.len() < HEADER + TRAILER || &b[..8] != MAGIC {
            return Err(bad("not a resonance4d state snapshot".into()));
        }
        let u = |o: usize| {
            let mut w = [0u8; 8];
            w.copy_from_slice(&b[o..o + 8]);
            u64::from_le_bytes(w)
        };
        let n = u(8);
        if n != particles as u64 {
            return Err(bad(format!(
                "the snapshot has {n} particles, the scene {particles}"
            )));
        }
        let expected = particles
            .checked_mul(PER_PARTICLE * 4)
            .and_then(|v| v.checked_add(HEADER + TRAILER));
        if expected != Some(b.len()) {
            return Err(bad(format!(
                "{} bytes, expected {} for {particles} particles (truncated or damaged)",
                b.len(),
                expected.map_or("more than memory".into(), |e| e.to_string())
            )));
        }
        let body = b.len() - TRAILER;
        if checksum(&b[..body]) != b[body..] {
            return Err(bad(
                "the checksum does not match the content: the file was damaged".into(),
            ));
        }
        if b[40..72] != fingerprint_bytes(fingerprint) {
            return Err(bad(
                "the snapshot was written for other inputs (a config setting other than frames, the particles, the backend or --write-f changed): simulate again without --resume".into(),
            ));
        }
        let values: Vec<f32> = b[HEADER..body]
            .chunks_exact(4)
            .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
            .collect();
        let n = particles;
        let mut off = 0;
        let mut take = |count: usize| -> &[f32] {
            let out = &values[off..off + count];
            off += count;
            out
        };
        fn group<const K: usize>(v: &[f32]) -> Vec<[f32; K]> {
            v.chunks_exact(K)
                .map(|c| {
                    let mut a = [0f32; K];
                    a.copy_from_slice(c);
                    a
                })
                .collect()
        }
        let x = group::<3>(take(3 * n));
        let v = group::<3>(take(3 * n));
        let c = group::<9>(take(9 * n));
        let f = group::<9>(take(9 * n));
        let plastic = group::<2>(take(2 * n));
        Ok(Snapshot {
            frame: usize::try_from(u(16)).map_err(|_| bad("frame count out of range".into()))?,
            substep: u(24),
            time_s: f64::from_bits(u(32)),
            x,
            v,
            c,
            f,
            plastic,
            fingerprint: fingerprint.to_string(),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn snap(n: usize) -> Snapshot {
        Snapshot {
            frame: 3,
            substep: 300,
            time_s: 0.03,
            x: (0..n).map(|i| [i as f32, 1.0, 2.0]).collect(),
            v: vec![[0.5; 3]; n],
            c: vec![[0.25; 9]; n],
            f: vec![[1.0; 9]; n],
            plastic: vec![[0.0, 1.0]; n],
            fingerprint: "0123456789abcdef0123456789abcdef".into(),
        }
    }

    #[test]
    fn round_trip_and_every_refusal() {
        let dir = std::env::temp_dir().join(format!("r4d-snap-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join("state.r4d");
        let s = snap(5);
        s.write(&p).unwrap();
        assert_eq!(Snapshot::read(&p, 5, &s.fingerprint).unwrap(), s);
        let msg = |r: Result<Snapshot>| r.unwrap_err().to_string();
        assert!(msg(Snapshot::read(&p, 6, &s.fingerprint)).contains("particles"));
        assert!(msg(Snapshot::read(&p, 5, "other")).contains("other inputs"));
        let good = std::fs::read(&p).unwrap();
        // Any flipped bit of the content is damage.
        for at in [
            9,
            20,
            40,
            HEADER + 7,
            good.len() - TRAILER - 1,
            good.len() - 1,
        ] {
            let mut bad = good.clone();
            bad[at] ^= 0x10;
            std::fs::write(&p, &bad).unwrap();
            let e = msg(Snapshot::read(&p, 5, &s.fingerprint));
            assert!(
                e.contains("checksum") || e.contains("particles") || e.contains("snapshot"),
                "byte {at}: {e}"
            );
        }
        std::fs::write(&p, &good[..good.len() - 3]).unwrap();
        assert!(msg(Snapshot::read(&p, 5, &s.fingerprint)).contains("truncated"));
        let mut old = good.clone();
        old[..8].copy_from_slice(b"R4DSNAP1");
        std::fs::write(&p, &old).unwrap();
        assert!(msg(Snapshot::read(&p, 5, &s.fingerprint)).contains("format-1"));
        // A huge particle count in the header is refused before any allocation.
        let mut huge = good.clone();
        huge[8..16].copy_from_slice(&u64::MAX.to_le_bytes());
        std::fs::write(&p, &huge).unwrap();
        assert!(msg(Snapshot::read(&p, usize::MAX, "x")).contains("bytes"));
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
