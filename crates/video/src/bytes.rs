//! Bounded big-endian reading of ISO base-media boxes: every read is checked against the box it
//! belongs to, so a size or count in a hostile file can neither read past its box nor make the
//! reader allocate more than the box holds.

use crate::error::{Result, VideoError};
use std::path::Path;

/// A cursor over one box's payload.
pub(crate) struct Bytes<'a> {
    buf: &'a [u8],
    pos: usize,
    /// The box being read (`"stsz"`), for errors.
    what: &'static str,
    path: &'a Path,
}

impl<'a> Bytes<'a> {
    pub(crate) fn new(buf: &'a [u8], what: &'static str, path: &'a Path) -> Self {
        Bytes {
            buf,
            pos: 0,
            what,
            path,
        }
    }

    /// Bytes not read yet.
    pub(crate) fn remaining(&self) -> usize {
        self.buf.len() - self.pos
    }

    pub(crate) fn take(&mut self, n: usize) -> Result<&'a [u8]> {
        if n > self.remaining() {
            return Err(VideoError::container(
                self.path,
                format!(
                    "box '{}' is truncated: {} bytes needed at offset {}, {} left",
                    self.what,
                    n,
                    self.pos,
                    self.remaining()
                ),
            ));
        }
        let s = &self.buf[self.pos..self.pos + n];
        self.pos += n;
        Ok(s)
    }

    pub(crate) fn skip(&mut self, n: usize) -> Result<()> {
        self.take(n).map(|_| ())
    }

    pub(crate) fn u8(&mut self) -> Result<u8> {
        Ok(self.take(1)?[0])
    }

    pub(crate) fn u16(&mut self) -> Result<u16> {
        let b = self.take(2)?;
        Ok(u16::from_be_bytes([b[0], b[1]]))
    }

    pub(crate) fn u32(&mut self) -> Result<u32> {
        let b = self.take(4)?;
        Ok(u32::from_be_bytes([b[0], b[1], b[2], b[3]]))
    }

    pub(crate) fn u64(&mut self) -> Result<u64> {
        let b = self.take(8)?;
        let mut a = [0u8; 8];
        a.copy_from_slice(b);
        Ok(u64::from_be_bytes(a))
    }

    /// A table of `count` entries of `entry` bytes each, refused unless the box holds them all
    /// (so the count cannot ask for more memory than the file has).
    pub(crate) fn table(&mut self, count: u32, entry: usize) -> Result<Bytes<'a>> {
        let need = (count as usize)
            .checked_mul(entry)
            .filter(|&n| n <= self.remaining());
        match need {
            Some(n) => Ok(Bytes::new(self.take(n)?, self.what, self.path)),
            None => Err(VideoError::container(
                self.path,
                format!(
                    "box '{}' says {} entries of {} bytes, it holds {} bytes",
                    self.what,
                    count,
                    entry,
                    self.remaining()
                ),
            )),
        }
    }
}

/// The child boxes of a payload, as `(type, payload)`; a child that does not fit is an error.
pub(crate) fn children<'a>(
    buf: &'a [u8],
    parent: &'static str,
    path: &Path,
) -> Result<Vec<([u8; 4], &'a [u8])>> {
    let mut out = Vec::new();
    let mut pos = 0usize;
    while pos < buf.len() {
        let rest = &buf[pos..];
        if rest.len() < 8 {
            // Some writers pad a container with up to 7 zero bytes; anything else is an error.
            if rest.iter().all(|&b| b == 0) {
                break;
            }
            return Err(VideoError::container(
                path,
                format!("a box inside '{parent}' at offset {pos} is truncated"),
            ));
        }
        let size32 = u32::from_be_bytes([rest[0], rest[1], rest[2], rest[3]]) as u64;
        let kind = [rest[4], rest[5], rest[6], rest[7]];
        let (header, size) = match size32 {
            0 => (8u64, rest.len() as u64),
            1 => {
                if rest.len() < 16 {
                    return Err(VideoError::container(
                        path,
                        format!("a box inside '{parent}' at offset {pos} is truncated"),
                    ));
                }
                let mut a = [0u8; 8];
                a.copy_from_slice(&rest[8..16]);
                (16, u64::from_be_bytes(a))
            }
            s => (8, s),
        };
        if size < header || size > rest.len() as u64 {
            return Err(VideoError::container(
                path,
                format!(
                    "box '{}' inside '{parent}' says {size} bytes; {} are left in '{parent}'",
                    fourcc(&kind),
                    rest.len()
                ),
            ));
        }
        out.push((kind, &rest[header as usize..size as usize]));
        pos += size as usize;
    }
    Ok(out)
}

/// The first child of type `kind`, or `None`.
pub(crate) fn child<'a>(
    buf: &'a [u8],
    kind: &[u8; 4],
    parent: &'static str,
    path: &Path,
) -> Result<Option<&'a [u8]>> {
    Ok(children(buf, parent, path)?
        .into_iter()
        .find(|(k, _)| k == kind)
        .map(|(_, p)| p))
}

/// A four-character code as text (non-printable bytes escaped).
pub(crate) fn fourcc(kind: &[u8; 4]) -> String {
    kind.iter()
        .flat_map(|&b| std::ascii::escape_default(b))
        .map(char::from)
        .collect()
}
