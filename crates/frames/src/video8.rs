//! Compact videos: [`Video8`] (8-bit values `k / 255`, a quarter of f32 and exact for frames
//! read from 8-bit files) and [`ReferenceVideo`] (a reference kept as bytes when it is 8-bit,
//! else f32; converted band by band when a loss reads it).

use crate::error::{FrameError, Input};
use crate::video::Video;
use r4d_math::Real;
use std::borrow::Cow;
use std::ops::Range;

/// A video of 8-bit values `k / 255`, `(T, H, W, 3)` like [`Video`].
#[derive(Clone, Debug, PartialEq)]
pub struct Video8 {
    frames: usize,
    height: usize,
    width: usize,
    data: Vec<u8>,
}

impl Video8 {
    /// A video from `(T, H, W, 3)` bytes (value `k` means `k / 255`); the length must be
    /// `frames * height * width * 3` and no side zero.
    pub fn new(
        frames: usize,
        height: usize,
        width: usize,
        data: Vec<u8>,
    ) -> Result<Video8, FrameError> {
        crate::video::check_shape(Input::Reference, frames, height, width, data.len())?;
        Ok(Video8 {
            frames,
            height,
            width,
            data,
        })
    }

    /// The video of `video` when every value is exactly `k / 255` in f32 for an integer
    /// `k` (as the PNG reader stores 8-bit frames); `None` otherwise.
    pub fn from_exact(video: &Video<f32>) -> Option<Video8> {
        let mut data = Vec::with_capacity(video.data().len());
        for &v in video.data() {
            let k = (v * 255.0).round();
            if !(0.0..=255.0).contains(&k) || (k as u8) as f32 / 255.0 != v {
                return None;
            }
            data.push(k as u8);
        }
        Some(Video8 {
            frames: video.frames(),
            height: video.height(),
            width: video.width(),
            data,
        })
    }

    /// `video` rounded to the nearest `k / 255` (values clamped to `[0, 1]`).
    pub fn quantize(video: &Video<f32>) -> Video8 {
        Video8 {
            frames: video.frames(),
            height: video.height(),
            width: video.width(),
            data: video
                .data()
                .iter()
                .map(|v| (v.clamp(0.0, 1.0) * 255.0).round() as u8)
                .collect(),
        }
    }

    /// Number of frames.
    pub fn frames(&self) -> usize {
        self.frames
    }
    /// Rows per frame.
    pub fn height(&self) -> usize {
        self.height
    }
    /// Columns per frame.
    pub fn width(&self) -> usize {
        self.width
    }
    /// The bytes, `(T, H, W, 3)`.
    pub fn data(&self) -> &[u8] {
        &self.data
    }
}

/// A reference video as the band-wise losses store it (`r4d_loss::bands::BandedDms`): bytes when the source is 8-bit, else f32.
/// `From<Video<f32>>` picks the compact form ([`ReferenceVideo::compact`]).
#[derive(Clone, Debug, PartialEq)]
pub enum ReferenceVideo {
    /// Float values.
    F32(Video<f32>),
    /// 8-bit values `k / 255`.
    U8(Video8),
}

impl From<Video<f32>> for ReferenceVideo {
    fn from(v: Video<f32>) -> Self {
        ReferenceVideo::compact(v)
    }
}

impl<'r> From<ReferenceVideo> for Cow<'r, ReferenceVideo> {
    fn from(v: ReferenceVideo) -> Self {
        Cow::Owned(v)
    }
}

impl<'r> From<&'r ReferenceVideo> for Cow<'r, ReferenceVideo> {
    fn from(v: &'r ReferenceVideo) -> Self {
        Cow::Borrowed(v)
    }
}

impl ReferenceVideo {
    /// The most compact exact storage of `video`: bytes when every value is `k / 255`,
    /// else the f32 video itself.
    pub fn compact(video: Video<f32>) -> ReferenceVideo {
        match Video8::from_exact(&video) {
            Some(v8) => ReferenceVideo::U8(v8),
            None => ReferenceVideo::F32(video),
        }
    }

    /// Number of frames.
    pub fn frames(&self) -> usize {
        match self {
            ReferenceVideo::F32(v) => v.frames(),
            ReferenceVideo::U8(v) => v.frames,
        }
    }
    /// Rows per frame.
    pub fn height(&self) -> usize {
        match self {
            ReferenceVideo::F32(v) => v.height(),
            ReferenceVideo::U8(v) => v.height,
        }
    }
    /// Columns per frame.
    pub fn width(&self) -> usize {
        match self {
            ReferenceVideo::F32(v) => v.width(),
            ReferenceVideo::U8(v) => v.width,
        }
    }
    /// Bytes held.
    pub fn bytes(&self) -> usize {
        match self {
            ReferenceVideo::F32(v) => v.data().len() * 4,
            ReferenceVideo::U8(v) => v.data.len(),
        }
    }

    /// Rows `rows` of the first `frames` frames, in type `T`.
    pub fn rows<T: Real>(&self, frames: usize, rows: Range<usize>) -> Video<T> {
        let (h, w) = (self.height(), self.width());
        assert!(frames <= self.frames() && rows.end <= h && rows.start < rows.end);
        let (a, b) = (rows.start * w * 3, rows.end * w * 3);
        let flen = h * w * 3;
        let mut data = Vec::with_capacity(frames * (b - a));
        for t in 0..frames {
            match self {
                ReferenceVideo::F32(v) => data.extend(
                    v.data()[t * flen + a..t * flen + b]
                        .iter()
                        .map(|&x| T::c(x as f64)),
                ),
                ReferenceVideo::U8(v) => data.extend(
                    v.data[t * flen + a..t * flen + b]
                        .iter()
                        .map(|&k| T::c(k as f64 / 255.0)),
                ),
            }
        }
        Video::new(frames, rows.len(), w, data).expect("band shape")
    }

    /// The whole video in f32.
    pub fn to_f32(&self) -> Video<f32> {
        self.rows(self.frames(), 0..self.height())
    }

    /// Frame `t` in f32, `H * W * 3` values.
    pub fn frame_f32(&self, t: usize) -> Vec<f32> {
        let flen = self.height() * self.width() * 3;
        match self {
            ReferenceVideo::F32(v) => v.frame(t).to_vec(),
            ReferenceVideo::U8(v) => v.data[t * flen..(t + 1) * flen]
                .iter()
                .map(|&k| k as f32 / 255.0)
                .collect(),
        }
    }

    /// The first NaN or infinite value, as an error naming the reference.
    pub fn check_finite(&self) -> Result<(), FrameError> {
        match self {
            ReferenceVideo::F32(v) => v.check_finite(Input::Reference),
            ReferenceVideo::U8(_) => Ok(()),
        }
    }
}
