//! Video files for resonance4d.
//!
//! * **H.264 MP4, read** ([`probe`], [`read_mp4`], [`Mp4Frames`]): the demuxer is ours (about
//!   400 lines, every count and offset checked against its box and the file before anything is
//!   allocated or decoded; see `demux.rs` for what it reads and ignores), the decoder is Cisco's
//!   OpenH264 compiled from source by the `openh264` crate, so no system ffmpeg or codec library
//!   is needed. Baseline, main and high profile progressive streams decode; a track coded with
//!   anything else (HEVC `hvc1`/`hev1`, AV1 `av01`, VP9 `vp09`, MPEG-4 `mp4v`, ...) is a
//!   [`VideoError::Codec`] that names the codec. Frames come out as 8-bit RGB in `[0, 1]`
//!   (BT.601 limited range; see [`color`]).
//! * **H.264 MP4, write** ([`write_mp4`], [`Mp4Writer`]): baseline profile, yuv420p, `moov`
//!   first, plays in browsers.
//! * **Frame-rate conversion** ([`resample`], [`resample_indices`]): nearest frame in time.
//! * **One reader for every format the CLI accepts** ([`read_video`], [`video_fps`]): an `.mp4`
//!   (also `.m4v`, `.mov`), a folder of PNG frames or a `.npy` (the latter two read by
//!   [`r4d_frames::io`]).
//!
//! ```no_run
//! # fn main() -> Result<(), r4d_video::VideoError> {
//! use std::path::Path;
//! let info = r4d_video::probe(Path::new("capture.mp4"))?;
//! println!("{}x{}, {} frames at {:.2} fps", info.width, info.height, info.frames, info.fps);
//! // Every other frame of the first second, as f32 RGB.
//! let pick: Vec<usize> = (0..info.frames.min(info.fps as usize)).step_by(2).collect();
//! let video = r4d_video::read_mp4::<f32>(Path::new("capture.mp4"), Some(&pick))?;
//! r4d_video::write_mp4(Path::new("copy.mp4"), &video, info.fps / 2.0)?;
//! # Ok(()) }
//! ```

mod avc;
mod bytes;
pub mod color;
mod decode;
mod demux;
mod encode;
pub mod error;
mod mux;
mod resample;

pub use decode::{probe, read_mp4, read_mp4_reference, Mp4Frames, Mp4Info, MAX_DECODED_BYTES};
pub use demux::{MAX_MOOV_BYTES, MAX_SAMPLES, MAX_SIDE};
pub use encode::{
    write_mp4, Mp4Writer, MAX_ENCODE_LONG, MAX_ENCODE_SHORT, MAX_FPS, MIN_ENCODE_SIDE,
};
pub use error::{Result, VideoError};
pub use resample::{resample, resample_indices, MAX_FRAMES};

use r4d_frames::{Real, Video};
use std::path::Path;

/// Whether `path` names an MP4 container by its extension (`.mp4`, `.m4v`, `.mov`).
pub fn is_mp4(path: &Path) -> bool {
    path.extension().is_some_and(|e| {
        let e = e.to_ascii_lowercase();
        e == "mp4" || e == "m4v" || e == "mov"
    })
}

/// Reads a video in any format the CLI accepts: an H.264 MP4 (see [`read_mp4`]), a folder of
/// PNG frames or a `.npy` (see [`r4d_frames::io::read_video`]).
pub fn read_video<T: Real>(path: &Path) -> Result<Video<T>> {
    if is_mp4(path) && !path.is_dir() {
        read_mp4(path, None)
    } else {
        Ok(r4d_frames::io::read_video(path)?)
    }
}

/// The frame rate a video file records: an MP4's (frames over duration); `None` for frame
/// folders and `.npy`, which carry none.
pub fn video_fps(path: &Path) -> Result<Option<f64>> {
    if is_mp4(path) && !path.is_dir() {
        Ok(Some(probe(path)?.fps))
    } else {
        Ok(None)
    }
}
