//! Reading H.264 MP4: the header ([`probe`]), frames one by one ([`Mp4Frames`]), or a whole
//! video or a selection of its frames ([`read_mp4`]).

use crate::avc::avcc_to_annexb;
use crate::color::{byte_to_unit, i420_to_rgb, i420_to_rgb8, Planes};
use crate::demux::{self, Track};
use crate::error::{Result, VideoError};
use openh264::decoder::{DecodedYUV, Decoder, DecoderConfig, Flush};
use openh264::formats::YUVSource;
use openh264::OpenH264API;
use r4d_frames::{Real, Video};
use r4d_frames::{ReferenceVideo, Video8};
use std::collections::VecDeque;
use std::io::{Read, Seek, SeekFrom};
use std::path::{Path, PathBuf};

/// The most bytes [`read_mp4`] allocates for decoded frames (8 GiB); ask for fewer frames (or
/// stream them with [`Mp4Frames`]) beyond that.
pub const MAX_DECODED_BYTES: u64 = 8 << 30;

/// What an MP4 file holds, read from its header without decoding.
#[derive(Clone, Debug, PartialEq)]
pub struct Mp4Info {
    /// The file.
    pub path: PathBuf,
    /// Frame width in pixels.
    pub width: u32,
    /// Frame height in pixels.
    pub height: u32,
    /// Number of frames (samples of the video track).
    pub frames: usize,
    /// Frames per second: frames over the track's duration.
    pub fps: f64,
    /// H.264 `profile_idc` (66 baseline, 77 main, 100 high).
    pub profile: u8,
    /// H.264 `level_idc` (e.g. 40 for level 4.0).
    pub level: u8,
}

/// Reads the header of an H.264 MP4: size, frame count and rate. Checks the whole sample table
/// against the file, so a file that passes can be decoded to the end or fails with a codec error.
pub fn probe(path: &Path) -> Result<Mp4Info> {
    Ok(info(&demux::open(path)?))
}

fn info(t: &Track) -> Mp4Info {
    Mp4Info {
        path: t.path.clone(),
        width: t.width,
        height: t.height,
        frames: t.samples.len(),
        fps: t.fps(),
        profile: t.avc.profile,
        level: t.avc.level,
    }
}

/// The frames of an H.264 MP4, decoded in display order one at a time.
///
/// Decoding is pipelined: while one frame is converted to RGB (rows in parallel), the next is
/// decoded on the calling thread, so on two cores the colour conversion costs almost nothing.
///
/// ```no_run
/// # fn main() -> Result<(), r4d_video::VideoError> {
/// let mut frames = r4d_video::Mp4Frames::open(std::path::Path::new("clip.mp4"))?;
/// let (w, h) = (frames.info().width as usize, frames.info().height as usize);
/// let mut rgb = vec![0f32; w * h * 3];
/// while frames.next_frame(&mut rgb)? {
///     // rgb holds the next frame, row-major RGB in [0, 1]
/// }
/// # Ok(()) }
/// ```
pub struct Mp4Frames {
    track: Track,
    info: Mp4Info,
    file: std::fs::File,
    decoder: Decoder,
    /// Next sample to feed the decoder.
    sample: usize,
    /// Frames handed out so far.
    emitted: usize,
    /// Frames left in the decoder after the last sample (display order).
    flushed: VecDeque<Yuv>,
    flushed_all: bool,
    /// The next frame, decoded, not yet converted.
    pending: Option<Yuv>,
    /// A frame buffer to reuse.
    spare: Option<Yuv>,
    raw: Vec<u8>,
    annexb: Vec<u8>,
}

/// A decoded frame's planes, copied out of the decoder.
#[derive(Default)]
struct Yuv {
    y: Vec<u8>,
    u: Vec<u8>,
    v: Vec<u8>,
    strides: (usize, usize, usize),
    size: (usize, usize),
}

impl Yuv {
    fn copy_from(&mut self, d: &DecodedYUV) {
        fn put(dst: &mut Vec<u8>, src: &[u8]) {
            dst.clear();
            dst.extend_from_slice(src);
        }
        put(&mut self.y, d.y());
        put(&mut self.u, d.u());
        put(&mut self.v, d.v());
        self.strides = d.strides();
        self.size = d.dimensions();
    }

    fn planes(&self) -> Planes<'_> {
        Planes {
            y: &self.y,
            u: &self.u,
            v: &self.v,
            strides: self.strides,
            size: self.size,
        }
    }
}

impl std::fmt::Debug for Mp4Frames {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Mp4Frames")
            .field("info", &self.info)
            .field("position", &self.emitted)
            .finish_non_exhaustive()
    }
}

/// Checks a decoded frame's size against the header.
fn check_size(info: &Mp4Info, yuv: &DecodedYUV) -> Result<()> {
    let (w, h) = yuv.dimensions();
    if (w as u32, h as u32) != (info.width, info.height) {
        return Err(VideoError::container(
            &info.path,
            format!(
                "the sample entry says {}x{}, the H.264 stream decodes to {w}x{h}",
                info.width, info.height
            ),
        ));
    }
    Ok(())
}

impl Mp4Frames {
    /// Opens the file and checks its header (see [`probe`]).
    pub fn open(path: &Path) -> Result<Self> {
        let track = demux::open(path)?;
        let file = std::fs::File::open(path).map_err(VideoError::io(path))?;
        let decoder = Decoder::with_api_config(
            OpenH264API::from_source(),
            DecoderConfig::new().flush_after_decode(Flush::NoFlush),
        )
        .map_err(|e| VideoError::Decode {
            path: path.to_path_buf(),
            frame: 0,
            message: format!("the decoder could not start: {e}"),
        })?;
        Ok(Mp4Frames {
            info: info(&track),
            track,
            file,
            decoder,
            sample: 0,
            emitted: 0,
            flushed: VecDeque::new(),
            flushed_all: false,
            pending: None,
            spare: None,
            raw: Vec::new(),
            annexb: Vec::new(),
        })
    }

    /// What the file holds.
    pub fn info(&self) -> &Mp4Info {
        &self.info
    }

    /// Frames decoded and returned so far.
    pub fn position(&self) -> usize {
        self.emitted
    }

    fn decode_err(&self, frame: usize, message: impl Into<String>) -> VideoError {
        VideoError::Decode {
            path: self.track.path.clone(),
            frame,
            message: message.into(),
        }
    }

    /// Decodes the next frame in display order into `into`; `Ok(false)` after the last.
    fn decode_one(&mut self, into: &mut Yuv) -> Result<bool> {
        loop {
            if let Some(f) = self.flushed.pop_front() {
                *into = f;
                return Ok(true);
            }
            if self.sample < self.track.samples.len() {
                let s = self.track.samples[self.sample];
                let path = self.track.path.clone();
                self.raw.resize(s.size as usize, 0);
                self.file
                    .seek(SeekFrom::Start(s.offset))
                    .map_err(VideoError::io(&path))?;
                self.file
                    .read_exact(&mut self.raw)
                    .map_err(VideoError::io(&path))?;
                self.annexb.clear();
                if self.sample == 0 {
                    // avcC's parameter sets go in front of the first frame.
                    for set in self.track.avc.sps.iter().chain(&self.track.avc.pps) {
                        self.annexb.extend_from_slice(&[0, 0, 0, 1]);
                        self.annexb.extend_from_slice(set);
                    }
                }
                avcc_to_annexb(&self.raw, self.track.avc.nal_length_size, &mut self.annexb)
                    .map_err(|m| self.decode_err(self.sample, m))?;
                let frame = self.sample;
                self.sample += 1;
                match self.decoder.decode(&self.annexb) {
                    Ok(Some(yuv)) => {
                        check_size(&self.info, &yuv)?;
                        into.copy_from(&yuv);
                        return Ok(true);
                    }
                    Ok(None) => continue,
                    Err(e) => {
                        return Err(VideoError::Decode {
                            path,
                            frame,
                            message: e.to_string(),
                        })
                    }
                }
            }
            if self.flushed_all {
                return Ok(false);
            }
            self.flushed_all = true;
            let path = self.track.path.clone();
            let frames = self
                .decoder
                .flush_remaining()
                .map_err(|e| VideoError::Decode {
                    path,
                    frame: self.sample,
                    message: e.to_string(),
                })?;
            let mut out = VecDeque::with_capacity(frames.len());
            for yuv in &frames {
                check_size(&self.info, yuv)?;
                let mut f = Yuv::default();
                f.copy_from(yuv);
                out.push_back(f);
            }
            drop(frames);
            self.flushed = out;
        }
    }

    /// Converts the pending frame with `convert` into `out` while decoding the one after it.
    fn next_with<O: Send + ?Sized>(
        &mut self,
        out: &mut O,
        convert: impl Fn(&Planes, &mut O) + Sync,
    ) -> Result<bool> {
        if self.pending.is_none() {
            let mut f = self.spare.take().unwrap_or_default();
            if self.decode_one(&mut f)? {
                self.pending = Some(f);
            } else {
                if self.emitted != self.track.samples.len() {
                    return Err(self.decode_err(
                        self.emitted,
                        format!(
                            "the stream decoded to {} frames, the track lists {}",
                            self.emitted,
                            self.track.samples.len()
                        ),
                    ));
                }
                return Ok(false);
            }
        }
        let current = self.pending.take().expect("decoded above");
        let mut next = self.spare.take().unwrap_or_default();
        let got = std::thread::scope(|s| {
            let conv = s.spawn(|| convert(&current.planes(), out));
            let got = self.decode_one(&mut next);
            conv.join().expect("colour conversion does not panic");
            got
        })?;
        self.emitted += 1;
        if got {
            self.pending = Some(next);
        }
        self.spare = Some(current);
        Ok(true)
    }

    fn check_len(&self, len: usize) -> Result<()> {
        let n = self.info.width as usize * self.info.height as usize * 3;
        if len != n {
            return Err(self.decode_err(
                self.emitted,
                format!("the output buffer holds {len} values, a frame has {n}"),
            ));
        }
        Ok(())
    }

    /// Decodes the next frame into `out` (`width * height * 3` values, row-major RGB in
    /// `[0, 1]`, each `k / 255`); `Ok(false)` after the last frame.
    pub fn next_frame(&mut self, out: &mut [f32]) -> Result<bool> {
        self.check_len(out.len())?;
        self.next_with(out, i420_to_rgb)
    }

    /// As [`Mp4Frames::next_frame`], as 8-bit RGB (`width * height * 3` bytes).
    pub fn next_frame_rgb8(&mut self, out: &mut [u8]) -> Result<bool> {
        self.check_len(out.len())?;
        self.next_with(out, i420_to_rgb8)
    }
}

/// Decodes the frames at the sorted indices `select` (all when `None`) and hands each to
/// `sink`; checks the selection against the file and the memory the caller will keep
/// (`bytes_per_value` per value) against [`MAX_DECODED_BYTES`] before decoding.
fn decode_selected(
    path: &Path,
    select: Option<&[usize]>,
    bytes_per_value: u64,
    mut sink: impl FnMut(&[u8]),
) -> Result<Mp4Info> {
    let mut frames = Mp4Frames::open(path)?;
    let info = frames.info().clone();
    let frames_err = |message: String| VideoError::Frames {
        path: path.to_path_buf(),
        message,
    };
    let all: Vec<usize>;
    let select = match select {
        Some(s) => {
            if s.windows(2).any(|w| w[1] <= w[0]) {
                return Err(frames_err(
                    "the frames to read must be given in increasing order".into(),
                ));
            }
            if let Some(&last) = s.last().filter(|&&l| l >= info.frames) {
                return Err(frames_err(format!(
                    "frame {last} was asked for; the video has {} frames (0..{})",
                    info.frames, info.frames
                )));
            }
            s
        }
        None => {
            all = (0..info.frames).collect();
            &all
        }
    };
    if select.is_empty() {
        return Err(frames_err("no frames were asked for".into()));
    }
    let (w, h) = (info.width as usize, info.height as usize);
    let bytes = (select.len() as u64)
        .saturating_mul((w * h * 3) as u64)
        .saturating_mul(bytes_per_value);
    if bytes > MAX_DECODED_BYTES {
        return Err(VideoError::Limit {
            path: path.to_path_buf(),
            what: "the decoded frames (bytes; ask for fewer frames)",
            got: bytes,
            limit: MAX_DECODED_BYTES,
        });
    }
    let mut buf = vec![0u8; w * h * 3];
    for &want in select {
        loop {
            let index = frames.position();
            if !frames.next_frame_rgb8(&mut buf)? {
                return Err(frames_err(format!(
                    "the video ended after {index} frames; frame {want} was asked for"
                )));
            }
            if index == want {
                sink(&buf);
                break;
            }
        }
    }
    Ok(info)
}

/// Decodes an H.264 MP4 to a video of RGB in `[0, 1]`: every frame, or the frames at the sorted
/// indices of `select` (decoding stops after the last one). The memory the frames need is
/// checked against [`MAX_DECODED_BYTES`] before anything is decoded.
pub fn read_mp4<T: Real>(path: &Path, select: Option<&[usize]>) -> Result<Video<T>> {
    let mut data: Vec<T> = Vec::new();
    let size = std::mem::size_of::<T>() as u64;
    let lut = byte_to_unit();
    let info = decode_selected(path, select, size, |f| {
        data.extend(f.iter().map(|&k| T::c(f64::from(lut[k as usize]))))
    })?;
    let n = data.len() / (info.width as usize * info.height as usize * 3);
    Ok(
        Video::new(n, info.height as usize, info.width as usize, data)
            .expect("frame count and size were checked"),
    )
}

/// As [`read_mp4`], kept as 8-bit values (a quarter of the memory of `f32`; decoded frames are
/// 8-bit, so nothing is lost): the form the fit stores reference videos in.
pub fn read_mp4_reference(path: &Path, select: Option<&[usize]>) -> Result<ReferenceVideo> {
    let mut data: Vec<u8> = Vec::new();
    let info = decode_selected(path, select, 1, |f| data.extend_from_slice(f))?;
    let (w, h) = (info.width as usize, info.height as usize);
    let n = data.len() / (w * h * 3);
    Ok(ReferenceVideo::U8(
        Video8::new(n, h, w, data).expect("frame count and size were checked"),
    ))
}
