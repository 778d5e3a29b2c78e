//! The MP4 (ISO base-media) demuxer: finds the first video track and lists its samples.
//!
//! Read: the top-level boxes (only `moov` is loaded, at most [`MAX_MOOV_BYTES`]); in the first
//! track whose handler is `vide`: `mdhd` (time scale), `stsd` (the codec's sample entry;
//! `avc1`/`avc3` with its `avcC`), `stts` (durations), `stsc`/`stco`/`co64` (chunks) and `stsz`
//! (sizes). Every count is checked against the bytes of its box and every sample against the
//! file's length before anything is decoded. Not read: edit lists (`elst`; the samples are
//! shown from the first), composition offsets (`ctts`; the decoder reorders), other tracks
//! (audio is ignored). Fragmented MP4 (`moof`) is refused with a typed error.

use crate::bytes::{child, children, fourcc, Bytes};
use crate::error::{Result, VideoError};
use std::io::{Read, Seek, SeekFrom};
use std::path::{Path, PathBuf};

/// The largest `moov` box read (its sample tables); 64 MiB holds some 16 million samples.
pub const MAX_MOOV_BYTES: u64 = 64 << 20;

/// The most samples (frames) a track may list: 10 million, over 90 hours at 30 fps. Bounds
/// the sample table a `stsz` with one size for every sample would otherwise make from a
/// count alone.
pub const MAX_SAMPLES: u32 = 10_000_000;

/// The largest frame side accepted (H.264 level 6.2 allows 8192 x 4320).
pub const MAX_SIDE: u32 = 8192;

/// One coded frame in the file.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct Sample {
    pub offset: u64,
    pub size: u32,
}

/// The H.264 decoder configuration (`avcC`).
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub(crate) struct AvcConfig {
    /// `profile_idc` (66 baseline, 77 main, 100 high, ...).
    pub profile: u8,
    /// `level_idc`.
    pub level: u8,
    /// Bytes of each NAL unit's length prefix (1, 2 or 4).
    pub nal_length_size: u8,
    /// Sequence parameter sets.
    pub sps: Vec<Vec<u8>>,
    /// Picture parameter sets.
    pub pps: Vec<Vec<u8>>,
}

/// The video track of an MP4 file.
#[derive(Clone, Debug)]
pub(crate) struct Track {
    pub path: PathBuf,
    pub width: u32,
    pub height: u32,
    /// Ticks per second of the track's durations.
    pub timescale: u32,
    /// Sum of the sample durations, in ticks.
    pub duration: u64,
    pub avc: AvcConfig,
    pub samples: Vec<Sample>,
}

impl Track {
    /// Frames per second: samples over the track's duration.
    pub fn fps(&self) -> f64 {
        self.samples.len() as f64 * self.timescale as f64 / self.duration as f64
    }
}

/// Reads the video track's description and sample table of `path`.
pub(crate) fn open(path: &Path) -> Result<Track> {
    let mut f = std::fs::File::open(path).map_err(VideoError::io(path))?;
    let file_len = f.metadata().map_err(VideoError::io(path))?.len();
    let moov = read_moov(&mut f, file_len, path)?;
    parse_moov(&moov, file_len, path)
}

/// Walks the top-level boxes and returns `moov`'s payload.
fn read_moov(f: &mut std::fs::File, file_len: u64, path: &Path) -> Result<Vec<u8>> {
    let mut pos = 0u64;
    let mut first = true;
    let mut moov = None;
    let mut fragmented = false;
    while pos < file_len {
        let mut h = [0u8; 16];
        let avail = (file_len - pos).min(16) as usize;
        if avail < 8 {
            break; // trailing padding
        }
        f.seek(SeekFrom::Start(pos)).map_err(VideoError::io(path))?;
        f.read_exact(&mut h[..avail])
            .map_err(VideoError::io(path))?;
        let size32 = u32::from_be_bytes([h[0], h[1], h[2], h[3]]) as u64;
        let kind = [h[4], h[5], h[6], h[7]];
        if first
            && !matches!(
                &kind,
                b"ftyp" | b"moov" | b"mdat" | b"free" | b"skip" | b"wide"
            )
        {
            return Err(VideoError::container(
                path,
                format!(
                    "the file starts with '{}', not an MP4 box (ftyp, moov, mdat)",
                    fourcc(&kind)
                ),
            ));
        }
        first = false;
        let (header, size) = match size32 {
            0 => (8, file_len - pos),
            1 if avail >= 16 => {
                let mut a = [0u8; 8];
                a.copy_from_slice(&h[8..16]);
                (16, u64::from_be_bytes(a))
            }
            1 => return Err(VideoError::container(path, "the last box is truncated")),
            s => (8, s),
        };
        if size < header || size > file_len - pos {
            return Err(VideoError::container(
                path,
                format!(
                    "top-level box '{}' at byte {pos} says {size} bytes; the file has {} bytes from there \
                     (the file is truncated or corrupt)",
                    fourcc(&kind),
                    file_len - pos
                ),
            ));
        }
        match &kind {
            b"moov" => {
                let n = size - header;
                if n > MAX_MOOV_BYTES {
                    return Err(VideoError::Limit {
                        path: path.to_path_buf(),
                        what: "the 'moov' box (bytes)",
                        got: n,
                        limit: MAX_MOOV_BYTES,
                    });
                }
                let mut buf = vec![0u8; n as usize];
                f.seek(SeekFrom::Start(pos + header))
                    .map_err(VideoError::io(path))?;
                f.read_exact(&mut buf).map_err(VideoError::io(path))?;
                moov = Some(buf);
            }
            b"moof" => fragmented = true,
            _ => {}
        }
        pos += size;
    }
    match moov {
        Some(m) => {
            if fragmented {
                return Err(VideoError::container(
                    path,
                    "fragmented MP4 (moof boxes) is not supported; remux it, e.g. `ffmpeg -i IN -c copy OUT.mp4`",
                ));
            }
            Ok(m)
        }
        None => Err(VideoError::container(
            path,
            "no 'moov' box (the file is truncated, or not an MP4)",
        )),
    }
}

fn full_box<'a>(buf: &'a [u8], what: &'static str, path: &'a Path) -> Result<(u8, Bytes<'a>)> {
    let mut b = Bytes::new(buf, what, path);
    let version = b.u8()?;
    b.skip(3)?;
    Ok((version, b))
}

fn require<'a>(
    buf: &'a [u8],
    kind: &'static [u8; 4],
    parent: &'static str,
    path: &Path,
) -> Result<&'a [u8]> {
    child(buf, kind, parent, path)?.ok_or_else(|| {
        VideoError::container(
            path,
            format!("box '{}' is missing from '{parent}'", fourcc(kind)),
        )
    })
}

fn parse_moov(moov: &[u8], file_len: u64, path: &Path) -> Result<Track> {
    let mut video_traks = Vec::new();
    for (kind, trak) in children(moov, "moov", path)? {
        if &kind != b"trak" {
            continue;
        }
        let mdia = require(trak, b"mdia", "trak", path)?;
        let hdlr = require(mdia, b"hdlr", "mdia", path)?;
        let (_, mut h) = full_box(hdlr, "hdlr", path)?;
        h.skip(4)?;
        let handler = h.take(4)?;
        if handler == b"vide" {
            video_traks.push(mdia);
        }
    }
    let mdia = *video_traks
        .first()
        .ok_or_else(|| VideoError::container(path, "no video track (handler 'vide')"))?;

    let (v, mut mdhd) = full_box(require(mdia, b"mdhd", "mdia", path)?, "mdhd", path)?;
    let timescale = if v == 1 {
        mdhd.skip(16)?;
        mdhd.u32()?
    } else {
        mdhd.skip(8)?;
        mdhd.u32()?
    };
    if timescale == 0 {
        return Err(VideoError::container(
            path,
            "the video track's time scale (mdhd) is 0",
        ));
    }
    let minf = require(mdia, b"minf", "mdia", path)?;
    let stbl = require(minf, b"stbl", "minf", path)?;

    let (width, height, avc) = sample_entry(require(stbl, b"stsd", "stbl", path)?, path)?;

    // Sizes.
    let (_, mut stsz) = full_box(require(stbl, b"stsz", "stbl", path)?, "stsz", path)?;
    let fixed = stsz.u32()?;
    let count = stsz.u32()?;
    if count > MAX_SAMPLES {
        return Err(VideoError::Limit {
            path: path.to_path_buf(),
            what: "the samples of the video track ('stsz')",
            got: u64::from(count),
            limit: u64::from(MAX_SAMPLES),
        });
    }
    let sizes: Vec<u32> = if fixed == 0 {
        let mut t = stsz.table(count, 4)?;
        (0..count).map(|_| t.u32()).collect::<Result<_>>()?
    } else {
        // One size for every sample: the count is bounded by the file, not by the box.
        if u64::from(count) * u64::from(fixed) > file_len {
            return Err(VideoError::container(
                path,
                format!(
                    "'stsz' says {count} samples of {fixed} bytes; the file has {file_len} bytes"
                ),
            ));
        }
        vec![fixed; count as usize]
    };
    if sizes.is_empty() {
        return Err(VideoError::container(
            path,
            "the video track has no samples",
        ));
    }

    // Durations.
    let (_, mut stts) = full_box(require(stbl, b"stts", "stbl", path)?, "stts", path)?;
    let n = stts.u32()?;
    let mut t = stts.table(n, 8)?;
    let mut timed = 0u64;
    let mut duration = 0u64;
    for _ in 0..n {
        let c = u64::from(t.u32()?);
        let d = u64::from(t.u32()?);
        timed += c;
        duration = duration.saturating_add(c.saturating_mul(d));
    }
    if timed != sizes.len() as u64 {
        return Err(VideoError::container(
            path,
            format!("'stts' times {timed} samples, 'stsz' lists {}", sizes.len()),
        ));
    }
    if duration == 0 {
        return Err(VideoError::container(
            path,
            "the video track's duration ('stts') is 0, so it has no frame rate",
        ));
    }

    // Chunks.
    let chunk_offsets: Vec<u64> = if let Some(stco) = child(stbl, b"stco", "stbl", path)? {
        let (_, mut b) = full_box(stco, "stco", path)?;
        let n = b.u32()?;
        let mut t = b.table(n, 4)?;
        (0..n)
            .map(|_| t.u32().map(u64::from))
            .collect::<Result<_>>()?
    } else if let Some(co64) = child(stbl, b"co64", "stbl", path)? {
        let (_, mut b) = full_box(co64, "co64", path)?;
        let n = b.u32()?;
        let mut t = b.table(n, 8)?;
        (0..n).map(|_| t.u64()).collect::<Result<_>>()?
    } else {
        return Err(VideoError::container(
            path,
            "box 'stco' (or 'co64') is missing from 'stbl'",
        ));
    };
    let (_, mut stsc) = full_box(require(stbl, b"stsc", "stbl", path)?, "stsc", path)?;
    let n = stsc.u32()?;
    let mut t = stsc.table(n, 12)?;
    let mut runs = Vec::with_capacity(n as usize);
    for _ in 0..n {
        let first = t.u32()?;
        let per = t.u32()?;
        t.skip(4)?;
        runs.push((first, per));
    }
    let samples = lay_out(&sizes, &chunk_offsets, &runs, file_len, path)?;
    Ok(Track {
        path: path.to_path_buf(),
        width,
        height,
        timescale,
        duration,
        avc,
        samples,
    })
}

/// Places every sample: chunk `c` (1-based) holds the samples-per-chunk of the last `stsc` run
/// whose first chunk is `<= c`; samples follow each other inside a chunk.
fn lay_out(
    sizes: &[u32],
    chunks: &[u64],
    runs: &[(u32, u32)],
    file_len: u64,
    path: &Path,
) -> Result<Vec<Sample>> {
    if runs.first().map(|r| r.0) != Some(1) {
        return Err(VideoError::container(
            path,
            "'stsc' does not start at chunk 1",
        ));
    }
    if runs.windows(2).any(|w| w[1].0 <= w[0].0) {
        return Err(VideoError::container(
            path,
            "'stsc' first-chunk numbers are not increasing",
        ));
    }
    let mut out = Vec::with_capacity(sizes.len());
    let mut run = 0usize;
    for (ci, &chunk) in chunks.iter().enumerate() {
        if out.len() == sizes.len() {
            break;
        }
        let c = ci as u64 + 1;
        while run + 1 < runs.len() && u64::from(runs[run + 1].0) <= c {
            run += 1;
        }
        let mut offset = chunk;
        for _ in 0..runs[run].1 {
            let Some(&size) = sizes.get(out.len()) else {
                break;
            };
            let end = offset.checked_add(u64::from(size));
            if end.is_none_or(|e| e > file_len) {
                return Err(VideoError::container(
                    path,
                    format!(
                        "sample {} ({size} bytes at byte {offset}) lies beyond the end of the file ({file_len} bytes)",
                        out.len()
                    ),
                ));
            }
            out.push(Sample { offset, size });
            offset += u64::from(size);
        }
    }
    if out.len() != sizes.len() {
        return Err(VideoError::container(
            path,
            format!(
                "the chunk tables ('stsc', 'stco') place {} of the {} samples",
                out.len(),
                sizes.len()
            ),
        ));
    }
    Ok(out)
}

/// The first sample entry of `stsd`: its size and, for H.264, its `avcC`.
fn sample_entry(stsd: &[u8], path: &Path) -> Result<(u32, u32, AvcConfig)> {
    let (_, mut b) = full_box(stsd, "stsd", path)?;
    let n = b.u32()?;
    if n == 0 {
        return Err(VideoError::container(path, "'stsd' has no sample entry"));
    }
    let rest = &stsd[8..];
    let entries = children(rest, "stsd", path)?;
    let (kind, entry) = entries
        .first()
        .ok_or_else(|| VideoError::container(path, "'stsd' has no sample entry"))?;
    if !matches!(kind, b"avc1" | b"avc3") {
        return Err(VideoError::Codec {
            path: path.to_path_buf(),
            codec: fourcc(kind),
        });
    }
    // VisualSampleEntry: 6 reserved, data_reference_index, 16 bytes pre-defined/reserved,
    // width, height, then 50 bytes (resolutions, frame count, compressor name, depth, -1).
    let mut v = Bytes::new(entry, "avc1", path);
    v.skip(24)?;
    let width = u32::from(v.u16()?);
    let height = u32::from(v.u16()?);
    v.skip(50)?;
    for (name, side) in [("width", width), ("height", height)] {
        if side == 0 || side > MAX_SIDE {
            return Err(VideoError::Limit {
                path: path.to_path_buf(),
                what: if name == "width" {
                    "the frame width ('avc1')"
                } else {
                    "the frame height ('avc1')"
                },
                got: u64::from(side),
                limit: u64::from(MAX_SIDE),
            });
        }
    }
    let boxes = &entry[78..];
    let avcc = child(boxes, b"avcC", "avc1", path)?
        .ok_or_else(|| VideoError::container(path, "the H.264 sample entry has no 'avcC' box"))?;
    Ok((width, height, parse_avcc(avcc, path)?))
}

fn parse_avcc(buf: &[u8], path: &Path) -> Result<AvcConfig> {
    let mut b = Bytes::new(buf, "avcC", path);
    let version = b.u8()?;
    if version != 1 {
        return Err(VideoError::container(
            path,
            format!("'avcC' version is {version}, expected 1"),
        ));
    }
    let profile = b.u8()?;
    b.skip(1)?;
    let level = b.u8()?;
    let nal_length_size = (b.u8()? & 3) + 1;
    if nal_length_size == 3 {
        return Err(VideoError::container(
            path,
            "'avcC' NAL length size is 3 bytes (only 1, 2 or 4 are valid)",
        ));
    }
    let sets = |count: usize, b: &mut Bytes| -> Result<Vec<Vec<u8>>> {
        (0..count)
            .map(|_| {
                let n = b.u16()? as usize;
                Ok(b.take(n)?.to_vec())
            })
            .collect()
    };
    let n_sps = (b.u8()? & 0x1f) as usize;
    let sps = sets(n_sps, &mut b)?;
    let n_pps = b.u8()? as usize;
    let pps = sets(n_pps, &mut b)?;
    Ok(AvcConfig {
        profile,
        level,
        nal_length_size,
        sps,
        pps,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn p() -> &'static Path {
        Path::new("x.mp4")
    }

    #[test]
    fn chunks_follow_stsc_runs() {
        let sizes = [10, 20, 30, 40, 50];
        // Chunks 1-2 hold two samples each, chunk 3 holds one.
        let s = lay_out(&sizes, &[100, 200, 300], &[(1, 2), (3, 1)], 1000, p()).unwrap();
        let offs: Vec<u64> = s.iter().map(|s| s.offset).collect();
        assert_eq!(offs, vec![100, 110, 200, 230, 300]);
    }

    #[test]
    fn sample_past_the_end_is_refused() {
        let e = lay_out(&[10, 2000], &[100], &[(1, 2)], 1000, p()).unwrap_err();
        assert!(e.to_string().contains("sample 1"), "{e}");
        let e = lay_out(&[10, 20], &[100], &[(1, 1)], 1000, p()).unwrap_err();
        assert!(e.to_string().contains("place 1 of the 2"), "{e}");
        let e = lay_out(&[10], &[u64::MAX - 3], &[(1, 1)], 1000, p()).unwrap_err();
        assert!(e.to_string().contains("beyond"), "{e}");
    }

    #[test]
    fn huge_table_counts_are_refused_before_allocating() {
        // stsz: version/flags, size 0, count 0xffffffff, no entries.
        let mut stsz = vec![0u8; 4];
        stsz.extend(0u32.to_be_bytes());
        stsz.extend(u32::MAX.to_be_bytes());
        let (_, mut b) = full_box(&stsz, "stsz", p()).unwrap();
        b.u32().unwrap();
        let n = b.u32().unwrap();
        let e = b.table(n, 4).err().unwrap();
        assert!(e.to_string().contains("4294967295 entries"), "{e}");
    }
}
