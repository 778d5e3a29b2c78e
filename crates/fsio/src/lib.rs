//! # r4d-fsio: atomic file writes
//!
//! Every result resonance4d writes (frames, checkpoints, parameters, videos, reports) goes
//! through [`write_atomic`] or [`AtomicFile`]: the bytes go to a temporary file next to the
//! target (`NAME.r4d-tmp`), are flushed and synced, and the temporary file is renamed over
//! the target. A kill at any instant, or a full disk, leaves either the old file or the new
//! one, never a truncated one; a failed write removes its temporary file and returns the
//! error (naming the target).
//!
//! ```
//! let dir = std::env::temp_dir().join(format!("r4d-fsio-doc-{}", std::process::id()));
//! std::fs::create_dir_all(&dir).unwrap();
//! let path = dir.join("params.json");
//! r4d_fsio::write_atomic(&path, b"{}\n").unwrap();
//! assert_eq!(std::fs::read(&path).unwrap(), b"{}\n");
//! # std::fs::remove_dir_all(&dir).unwrap();
//! ```
//!
//! [`Fingerprint`] is the 128-bit hash that checkpoints and snapshots carry: of the inputs
//! they resume (refusing a resume on other inputs) and of their own content (a checksum).

pub mod npy;

use std::ffi::OsString;
use std::fs::File;
use std::io::{self, BufWriter, Write};
use std::path::{Path, PathBuf};

/// The temporary file [`write_atomic`] and [`AtomicFile`] write before the rename.
pub fn temp_path(path: &Path) -> PathBuf {
    let mut name = path
        .file_name()
        .map(OsString::from)
        .unwrap_or_else(|| OsString::from("out"));
    name.push(".r4d-tmp");
    path.with_file_name(name)
}

/// An I/O error that names `path`.
fn named(path: &Path, e: io::Error) -> io::Error {
    io::Error::new(e.kind(), format!("{}: {e}", path.display()))
}

/// Reads a whole file of at most `max` bytes: a larger one is refused from its size before
/// anything is read (an `InvalidData` error giving its size and the limit), so a file cannot
/// make a reader allocate without bound. The errors do not repeat the path: callers' error
/// types name the file.
pub fn read_bounded(path: &Path, max: u64) -> io::Result<Vec<u8>> {
    let len = std::fs::metadata(path)?.len();
    if len > max {
        return Err(io::Error::new(
            io::ErrorKind::InvalidData,
            format!("{len} bytes, more than the {max} read from such a file"),
        ));
    }
    std::fs::read(path)
}

/// Writes `bytes` to `path` atomically (see the crate docs).
pub fn write_atomic(path: &Path, bytes: &[u8]) -> io::Result<()> {
    let mut f = AtomicFile::create(path)?;
    f.write_all(bytes).map_err(|e| named(path, e))?;
    f.commit()
}

/// A file written atomically: write through it (buffered), then [`AtomicFile::commit`]. Dropped
/// without a commit (an error on the way), it removes its temporary file and leaves the
/// target as it was.
#[derive(Debug)]
pub struct AtomicFile {
    target: PathBuf,
    tmp: PathBuf,
    out: Option<BufWriter<File>>,
}

impl AtomicFile {
    /// Starts writing `path` (creates the temporary file, replacing a stale one).
    pub fn create(path: &Path) -> io::Result<AtomicFile> {
        let tmp = temp_path(path);
        // A stale temporary file (a killed earlier write) or a link put there is replaced,
        // never written through.
        match std::fs::remove_file(&tmp) {
            Ok(()) => {}
            Err(e) if e.kind() == io::ErrorKind::NotFound => {}
            Err(e) => return Err(named(&tmp, e)),
        }
        let f = File::options()
            .write(true)
            .create_new(true)
            .open(&tmp)
            .map_err(|e| named(&tmp, e))?;
        Ok(AtomicFile {
            target: path.to_path_buf(),
            tmp,
            out: Some(BufWriter::with_capacity(1 << 16, f)),
        })
    }

    /// The file this writes.
    pub fn path(&self) -> &Path {
        &self.target
    }

    /// Flushes, syncs and renames the temporary file over the target.
    pub fn commit(mut self) -> io::Result<()> {
        let target = self.target.clone();
        let out = self.out.take().expect("an AtomicFile is committed once");
        let f = out
            .into_inner()
            .map_err(|e| named(&target, e.into_error()))?;
        f.sync_all().map_err(|e| named(&target, e))?;
        drop(f);
        std::fs::rename(&self.tmp, &target).map_err(|e| named(&target, e))?;
        // The rename is durable once the directory is synced (best effort: not every
        // platform can open a directory).
        if let Some(dir) = target.parent().filter(|d| !d.as_os_str().is_empty()) {
            if let Ok(d) = File::open(dir) {
                let _ = d.sync_all();
            }
        }
        Ok(())
    }
}

impl Write for AtomicFile {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        match &mut self.out {
            Some(o) => o.write(buf),
            None => Err(io::Error::other("write after commit")),
        }
    }

    fn write_all(&mut self, buf: &[u8]) -> io::Result<()> {
        match &mut self.out {
            Some(o) => o.write_all(buf),
            None => Err(io::Error::other("write after commit")),
        }
    }

    fn flush(&mut self) -> io::Result<()> {
        match &mut self.out {
            Some(o) => o.flush(),
            None => Ok(()),
        }
    }
}

impl Drop for AtomicFile {
    fn drop(&mut self) {
        if self.out.take().is_some() {
            let _ = std::fs::remove_file(&self.tmp);
        }
    }
}

/// A 128-bit fingerprint (of a run's inputs, or a checksum of a file's content): two multiply-rotate lanes over 64-bit words, each
/// field prefixed by its length (so that `("ab", "c")` and `("a", "bc")` differ). Not a
/// cryptographic hash: it tells an edited or exchanged input from the original, not a
/// forgery. Stable across platforms and versions of this format.
#[derive(Clone, Debug)]
pub struct Fingerprint {
    a: u64,
    b: u64,
}

impl Default for Fingerprint {
    fn default() -> Self {
        Fingerprint::new()
    }
}

impl Fingerprint {
    /// An empty fingerprint.
    pub fn new() -> Fingerprint {
        Fingerprint {
            a: 0x243f_6a88_85a3_08d3,
            b: 0x1319_8a2e_0370_7344,
        }
    }

    /// Mixes one word.
    pub fn word(&mut self, w: u64) {
        self.a = (self.a ^ w)
            .wrapping_mul(0x9e37_79b9_7f4a_7c15)
            .rotate_left(29);
        self.b = (self.b ^ w.rotate_left(17))
            .wrapping_mul(0xc2b2_ae3d_27d4_eb4f)
            .rotate_left(31);
    }

    /// Mixes bytes (with their length).
    pub fn bytes(&mut self, data: &[u8]) {
        self.word(data.len() as u64);
        let mut chunks = data.chunks_exact(8);
        for c in &mut chunks {
            let mut w = [0u8; 8];
            w.copy_from_slice(c);
            self.word(u64::from_le_bytes(w));
        }
        let rest = chunks.remainder();
        if !rest.is_empty() {
            let mut w = [0u8; 8];
            w[..rest.len()].copy_from_slice(rest);
            self.word(u64::from_le_bytes(w));
        }
    }

    /// Mixes a string.
    pub fn text(&mut self, s: &str) {
        self.bytes(s.as_bytes());
    }

    /// Mixes `f32` values (their bits, with the count).
    pub fn f32s(&mut self, v: &[f32]) {
        self.word(v.len() as u64);
        for x in v {
            self.word(u64::from(x.to_bits()));
        }
    }

    /// Mixes `u32` values (with the count).
    pub fn u32s(&mut self, v: &[u32]) {
        self.word(v.len() as u64);
        for x in v {
            self.word(u64::from(*x));
        }
    }

    /// Mixes points (with the count).
    pub fn points(&mut self, v: &[[f32; 3]]) {
        self.word(v.len() as u64);
        for p in v {
            for x in p {
                self.word(u64::from(x.to_bits()));
            }
        }
    }

    /// The fingerprint as 32 hex digits.
    pub fn finish(&self) -> String {
        let mut f = self.clone();
        f.word(0x5be0_cd19_137e_2179);
        format!("{:016x}{:016x}", f.a, f.b)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fingerprint_separates_fields_and_values() {
        let fp = |f: &dyn Fn(&mut Fingerprint)| {
            let mut h = Fingerprint::new();
            f(&mut h);
            h.finish()
        };
        let ab_c = fp(&|h| {
            h.text("ab");
            h.text("c")
        });
        let a_bc = fp(&|h| {
            h.text("a");
            h.text("bc")
        });
        assert_ne!(ab_c, a_bc);
        assert_ne!(fp(&|h| h.f32s(&[1.0])), fp(&|h| h.f32s(&[1.0000001])));
        assert_ne!(fp(&|h| h.f32s(&[0.0])), fp(&|h| h.f32s(&[-0.0])));
        assert_eq!(fp(&|h| h.f32s(&[2.5, 3.0])), fp(&|h| h.f32s(&[2.5, 3.0])));
        // Pinned: the value may not change between builds (files carry it).
        assert_eq!(fp(&|h| h.text("r4d")), fp(&|h| h.bytes(b"r4d")));
        assert_eq!(ab_c.len(), 32);
    }

    fn dir(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("r4d-fsio-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    #[test]
    fn replaces_whole_files_and_abandons_cleanly() {
        let d = dir("replace");
        let p = d.join("a.json");
        write_atomic(&p, b"old").unwrap();
        write_atomic(&p, b"new contents").unwrap();
        assert_eq!(std::fs::read(&p).unwrap(), b"new contents");
        // An abandoned write leaves the old file and no temporary file.
        {
            let mut f = AtomicFile::create(&p).unwrap();
            f.write_all(b"half").unwrap();
        }
        assert_eq!(std::fs::read(&p).unwrap(), b"new contents");
        assert!(!temp_path(&p).exists());
        std::fs::remove_dir_all(&d).unwrap();
    }

    #[cfg(unix)]
    #[test]
    fn a_link_at_the_temporary_path_is_replaced_not_written_through() {
        let d = dir("full");
        let p = d.join("frame.ply");
        write_atomic(&p, b"old").unwrap();
        // A link at the temporary path is replaced, not written through.
        std::os::unix::fs::symlink("/dev/full", temp_path(&p)).unwrap();
        write_atomic(&p, b"new").unwrap();
        assert_eq!(std::fs::read(&p).unwrap(), b"new");
        assert!(!temp_path(&p).exists());
        std::fs::remove_dir_all(&d).unwrap();
    }

    #[test]
    fn bounded_reads_refuse_larger_files_by_their_size() {
        let d = dir("bounded");
        let p = d.join("big.bin");
        write_atomic(&p, &[7u8; 100]).unwrap();
        assert_eq!(read_bounded(&p, 100).unwrap().len(), 100);
        let e = read_bounded(&p, 99).unwrap_err();
        assert_eq!(e.kind(), io::ErrorKind::InvalidData);
        assert!(
            e.to_string().contains("100 bytes") && e.to_string().contains("99"),
            "{e}"
        );
        assert!(read_bounded(&d.join("none"), 1).is_err());
        std::fs::remove_dir_all(&d).unwrap();
    }

    #[test]
    fn a_missing_folder_is_an_error_naming_the_file() {
        let d = dir("missing");
        let p = d.join("no/such/dir/x.json");
        let e = write_atomic(&p, b"x").unwrap_err();
        assert!(e.to_string().contains("x.json"), "{e}");
        std::fs::remove_dir_all(&d).unwrap();
    }
}
