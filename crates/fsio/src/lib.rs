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
pub mod seq;

use std::ffi::OsString;
use std::fs::File;
use std::io::{self, BufWriter, Read, Write};
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

/// The most bytes a text input (a configuration: TOML or JSON, a camera file, a parts file, a
/// run folder's JSON records) is read to: 256 MiB. Such files are a few kilobytes; a larger
/// one (or a device, a pipe) is refused by [`read_to_string_bounded`] before it fills memory.
pub const MAX_TEXT_BYTES: u64 = 256 << 20;

/// The most bytes a binary input read whole (a PLY file, a `state.r4d` snapshot, a COLMAP
/// binary file) is read to: 4 GiB. Readers with a tighter bound of their own
/// (videos, images, LPIPS weights, checkpoints) use theirs.
pub const MAX_BINARY_BYTES: u64 = 4 << 30;

/// Reads a whole file of at most `max` bytes, counting the bytes it actually reads: a regular
/// file whose size is over `max` is refused from its metadata before anything is read, and
/// any source (a device such as `/dev/zero`, a pipe, a file that grows while it is read) is
/// refused as soon as more than `max` bytes arrive, so no file can make a reader allocate
/// without bound. The error is `InvalidData`, giving the limit. The errors do not repeat the
/// path: callers' error types name the file.
pub fn read_bounded(path: &Path, max: u64) -> io::Result<Vec<u8>> {
    let f = File::open(path)?;
    let meta = f.metadata()?;
    if meta.is_file() && meta.len() > max {
        return Err(too_large(Some(meta.len()), max));
    }
    // Regular files: reserve what the metadata says (already checked against `max`); other
    // sources report no useful length.
    let hint = if meta.is_file() { meta.len() } else { 0 };
    let mut out = Vec::with_capacity(usize::try_from(hint.min(max)).unwrap_or(0));
    f.take(max.saturating_add(1)).read_to_end(&mut out)?;
    if out.len() as u64 > max {
        return Err(too_large(None, max));
    }
    Ok(out)
}

/// [`read_bounded`] for UTF-8 text: more than `max` bytes or text that is not UTF-8 is an
/// `InvalidData` error.
pub fn read_to_string_bounded(path: &Path, max: u64) -> io::Result<String> {
    String::from_utf8(read_bounded(path, max)?).map_err(|e| {
        io::Error::new(
            io::ErrorKind::InvalidData,
            format!("not UTF-8 text: {}", e.utf8_error()),
        )
    })
}

/// The error of a source larger than a reader's limit (its size when known).
fn too_large(len: Option<u64>, max: u64) -> io::Error {
    let msg = match len {
        Some(len) => format!("{len} bytes, more than the {max} read from such a file"),
        None => format!("more than the {max} bytes read from such a file"),
    };
    io::Error::new(io::ErrorKind::InvalidData, msg)
}

/// Writes `bytes` to `path` atomically (see the crate docs).
pub fn write_atomic(path: &Path, bytes: &[u8]) -> io::Result<()> {
    let mut f = AtomicFile::create(path)?;
    f.write_all(bytes)
        .map_err(|e| write_error(path, Some(&f.tmp), e))?;
    f.commit()
}

/// An error about writing `target`, naming it (and, where it was the temporary file that
/// failed, that file too).
fn write_error(target: &Path, tmp: Option<&Path>, e: io::Error) -> io::Error {
    let msg = match tmp {
        Some(t) => format!("{}: temporary file {}: {e}", target.display(), t.display()),
        None => format!("{}: {e}", target.display()),
    };
    io::Error::new(e.kind(), msg)
}

/// A file written atomically: write through it (buffered), then [`AtomicFile::commit`].
/// Its `Write` errors are the plain I/O errors (callers name the file).
///
/// Every failure removes the temporary file and leaves the target as it was: a failed
/// write or flush (a full disk, a file size limit), a failed sync, a failed rename (the
/// target became a folder, a permission), and a writer dropped without a commit (an error
/// on the way). The errors name the target.
#[derive(Debug)]
pub struct AtomicFile {
    target: PathBuf,
    tmp: PathBuf,
    out: Option<BufWriter<File>>,
    /// Set once the rename has succeeded: the temporary file is the target now.
    committed: bool,
}

impl AtomicFile {
    /// Starts writing `path` (creates the temporary file, replacing a stale one). A target
    /// that is a folder is refused here, before anything is written.
    pub fn create(path: &Path) -> io::Result<AtomicFile> {
        if path.is_dir() {
            return Err(write_error(
                path,
                None,
                io::Error::new(
                    io::ErrorKind::IsADirectory,
                    "is a folder, not a file: give a file name",
                ),
            ));
        }
        let tmp = temp_path(path);
        // A stale temporary file (a killed earlier write) or a link put there is replaced,
        // never written through.
        match std::fs::remove_file(&tmp) {
            Ok(()) => {}
            Err(e) if e.kind() == io::ErrorKind::NotFound => {}
            Err(e) => return Err(write_error(path, Some(&tmp), e)),
        }
        // `create_new`: nothing exists at `tmp` unless this call made it, so a failure here
        // leaves nothing behind.
        let f = File::options()
            .write(true)
            .create_new(true)
            .open(&tmp)
            .map_err(|e| write_error(path, Some(&tmp), e))?;
        Ok(AtomicFile {
            target: path.to_path_buf(),
            tmp,
            out: Some(BufWriter::with_capacity(1 << 16, f)),
            committed: false,
        })
    }

    /// The file this writes.
    pub fn path(&self) -> &Path {
        &self.target
    }

    /// Flushes, syncs and renames the temporary file over the target. On an error the
    /// temporary file is removed (the target keeps its old content) and the error names the
    /// target.
    pub fn commit(mut self) -> io::Result<()> {
        // `self` is dropped on every return below: [`Drop`] removes the temporary file
        // unless the rename succeeded.
        self.finish()
            .map_err(|e| write_error(&self.target, None, e))?;
        // The rename is durable once the directory is synced (best effort: not every
        // platform can open a directory).
        if let Some(dir) = self.target.parent().filter(|d| !d.as_os_str().is_empty()) {
            if let Ok(d) = File::open(dir) {
                let _ = d.sync_all();
            }
        }
        Ok(())
    }

    /// Flush, sync, close, rename; `committed` once the rename succeeded.
    fn finish(&mut self) -> io::Result<()> {
        let out = self
            .out
            .as_mut()
            .ok_or_else(|| io::Error::other("committed twice"))?;
        out.flush()?;
        out.get_ref().sync_all()?;
        // Closed before the rename (some platforms cannot rename an open file).
        self.out = None;
        std::fs::rename(&self.tmp, &self.target)?;
        self.committed = true;
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
        if let Some(out) = self.out.take() {
            // Abandoned: the buffered bytes are discarded, not flushed into a file that is
            // about to be removed.
            let (file, _unflushed) = out.into_parts();
            drop(file);
        }
        if !self.committed {
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

    /// The files in `d` (names), sorted.
    fn listing(d: &Path) -> Vec<String> {
        let mut v: Vec<String> = std::fs::read_dir(d)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        v.sort();
        v
    }

    #[test]
    fn a_folder_target_is_refused_before_writing_and_leaves_nothing() {
        let d = dir("folder");
        let p = d.join("out.json");
        std::fs::create_dir(&p).unwrap();
        std::fs::write(p.join("inside.txt"), b"user data").unwrap();
        let e = write_atomic(&p, b"x").unwrap_err();
        assert!(e.to_string().contains("out.json"), "{e}");
        assert_eq!(e.kind(), io::ErrorKind::IsADirectory, "{e}");
        assert!(AtomicFile::create(&p).is_err());
        assert_eq!(listing(&d), ["out.json"]);
        assert_eq!(std::fs::read(p.join("inside.txt")).unwrap(), b"user data");
        std::fs::remove_dir_all(&d).unwrap();
    }

    #[test]
    fn a_failed_rename_removes_the_temporary_file() {
        let d = dir("rename");
        let p = d.join("params.json");
        let mut f = AtomicFile::create(&p).unwrap();
        f.write_all(b"new").unwrap();
        // The target turns into a non-empty folder between create and commit: the rename
        // fails.
        std::fs::create_dir(&p).unwrap();
        std::fs::write(p.join("keep"), b"user data").unwrap();
        let e = f.commit().unwrap_err();
        assert!(e.to_string().contains("params.json"), "{e}");
        assert_eq!(listing(&d), ["params.json"]);
        assert_eq!(std::fs::read(p.join("keep")).unwrap(), b"user data");
        std::fs::remove_dir_all(&d).unwrap();
    }

    #[test]
    fn a_parent_that_is_a_file_is_an_error_that_leaves_it_unchanged() {
        let d = dir("parent_file");
        let parent = d.join("frames");
        std::fs::write(&parent, b"a file").unwrap();
        let e = write_atomic(&parent.join("f.ply"), b"x").unwrap_err();
        assert!(e.to_string().contains("f.ply"), "{e}");
        assert_eq!(std::fs::read(&parent).unwrap(), b"a file");
        assert_eq!(listing(&d), ["frames"]);
        std::fs::remove_dir_all(&d).unwrap();
    }

    /// Runs the test `name` of this binary again in a child process through `sh -c PRELUDE`
    /// (with `R4D_FSIO_CHILD` set to `arg`), prefixed by `wrapper`; `None` where the child
    /// cannot be started.
    #[cfg(unix)]
    fn child(
        name: &str,
        arg: &Path,
        prelude: &str,
        wrapper: &[&str],
    ) -> Option<std::process::Output> {
        let exe = std::env::current_exe().ok()?;
        let mut cmd = std::process::Command::new(wrapper.first().copied().unwrap_or("sh"));
        if !wrapper.is_empty() {
            cmd.args(&wrapper[1..]).arg("sh");
        }
        cmd.arg("-c")
            .arg(format!("{prelude} exec \"$0\" \"$@\""))
            .arg(exe)
            .args(["--exact", name, "--nocapture", "--test-threads=1"])
            .env("R4D_FSIO_CHILD", arg);
        cmd.output().ok()
    }

    /// In the child of `a_full_disk_mid_write_leaves_the_old_file_and_no_temporary_file`
    /// (a file size limit of 4 KiB, SIGXFSZ ignored: writes past it fail with EFBIG, as on a
    /// full disk): a write that fails inside `write_all`, and one that fails only in the
    /// flush of `commit`.
    fn write_past_the_limit(d: &Path) {
        let big = d.join("big.bin");
        let e = write_atomic(&big, &vec![1u8; 1 << 20]).unwrap_err();
        assert!(e.to_string().contains("big.bin"), "{e}");
        let small = d.join("small.bin");
        let mut f = AtomicFile::create(&small).unwrap();
        // Below the buffer's capacity: it all fails at the flush.
        f.write_all(&[2u8; 10_000]).unwrap();
        let e = f.commit().unwrap_err();
        assert!(e.to_string().contains("small.bin"), "{e}");
    }

    #[cfg(unix)]
    #[test]
    fn a_full_disk_mid_write_leaves_the_old_file_and_no_temporary_file() {
        const NAME: &str = "tests::a_full_disk_mid_write_leaves_the_old_file_and_no_temporary_file";
        if let Some(d) = std::env::var_os("R4D_FSIO_CHILD") {
            write_past_the_limit(Path::new(&d));
            return;
        }
        let d = dir("efbig");
        write_atomic(&d.join("big.bin"), b"old big").unwrap();
        write_atomic(&d.join("small.bin"), b"old small").unwrap();
        // dash and bash in POSIX mode count `ulimit -f` in 512-byte blocks, bash otherwise in
        // KiB: 8 is 4 or 8 KiB, below both writes.
        let o = child(NAME, &d, "trap '' XFSZ; ulimit -f 8 &&", &[]).expect("sh runs the child");
        assert!(
            o.status.success(),
            "the child failed: {}{}",
            String::from_utf8_lossy(&o.stdout),
            String::from_utf8_lossy(&o.stderr)
        );
        assert!(String::from_utf8_lossy(&o.stdout).contains("1 passed"));
        assert_eq!(std::fs::read(d.join("big.bin")).unwrap(), b"old big");
        assert_eq!(std::fs::read(d.join("small.bin")).unwrap(), b"old small");
        assert_eq!(listing(&d), ["big.bin", "small.bin"]);
        std::fs::remove_dir_all(&d).unwrap();
    }

    /// In the child of `a_read_only_folder_is_an_error_naming_the_target`: the write into the
    /// folder is refused.
    fn write_into_read_only(d: &Path) {
        let e = write_atomic(&d.join("a.json"), b"new").unwrap_err();
        assert_eq!(e.kind(), io::ErrorKind::PermissionDenied, "{e}");
        assert!(e.to_string().contains("a.json"), "{e}");
    }

    #[cfg(unix)]
    #[test]
    fn a_read_only_folder_is_an_error_naming_the_target() {
        use std::os::unix::fs::PermissionsExt;
        const NAME: &str = "tests::a_read_only_folder_is_an_error_naming_the_target";
        if let Some(d) = std::env::var_os("R4D_FSIO_CHILD") {
            write_into_read_only(Path::new(&d));
            return;
        }
        let d = dir("read_only");
        write_atomic(&d.join("a.json"), b"old").unwrap();
        std::fs::set_permissions(&d, std::fs::Permissions::from_mode(0o555)).unwrap();
        // A privileged user (root) writes into read-only folders: the write then runs as
        // `nobody`, for whom the folder (not theirs, 0555) is read-only too.
        let privileged = File::create(d.join("probe")).is_ok();
        let _ = std::fs::remove_file(d.join("probe"));
        if privileged {
            let o = child(
                NAME,
                &d,
                "",
                &[
                    "setpriv",
                    "--reuid=65534",
                    "--regid=65534",
                    "--clear-groups",
                ],
            )
            .expect("setpriv runs the child as nobody (util-linux)");
            assert!(
                o.status.success() && String::from_utf8_lossy(&o.stdout).contains("1 passed"),
                "the child failed: {}{}",
                String::from_utf8_lossy(&o.stdout),
                String::from_utf8_lossy(&o.stderr)
            );
        } else {
            write_into_read_only(&d);
        }
        std::fs::set_permissions(&d, std::fs::Permissions::from_mode(0o755)).unwrap();
        assert_eq!(std::fs::read(d.join("a.json")).unwrap(), b"old");
        assert_eq!(listing(&d), ["a.json"]);
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

    #[cfg(unix)]
    #[test]
    fn bounded_reads_count_the_bytes_of_sources_without_a_length() {
        // A device reports length 0 and never ends: the bytes read are counted.
        let e = read_bounded(Path::new("/dev/zero"), 1 << 16).unwrap_err();
        assert_eq!(e.kind(), io::ErrorKind::InvalidData);
        assert!(e.to_string().contains("65536"), "{e}");
        let e = read_to_string_bounded(Path::new("/dev/zero"), 10).unwrap_err();
        assert!(e.to_string().contains("more than the 10"), "{e}");
        let d = dir("bounded-text");
        let p = d.join("t.toml");
        write_atomic(&p, b"a = 1\n").unwrap();
        assert_eq!(read_to_string_bounded(&p, 6).unwrap(), "a = 1\n");
        write_atomic(&p, &[0xff, 0xfe]).unwrap();
        let e = read_to_string_bounded(&p, 6).unwrap_err();
        assert!(e.to_string().contains("UTF-8"), "{e}");
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
