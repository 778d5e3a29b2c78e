//! [`Video`]: frames of RGB values stored `(T, H, W, 3)`, row 0 at the top.

use crate::error::{FrameError, Input};
use r4d_math::Real;

/// A video: `frames` frames of `height x width` RGB pixels, stored as one `(T, H, W, 3)`
/// array (frame-major, row 0 at the top, RGB interleaved), the layout of
/// `r4d_splat::Image::rgb`. Values are nominally in `[0, 1]` (data range 1).
#[derive(Clone, Debug, PartialEq)]
pub struct Video<T = f32> {
    frames: usize,
    height: usize,
    width: usize,
    data: Vec<T>,
}

/// Checks that `len` values make `frames x height x width x 3` with no side zero; the product
/// is checked, so a shape read from a file header cannot wrap around.
pub fn check_shape(
    input: Input,
    frames: usize,
    height: usize,
    width: usize,
    len: usize,
) -> Result<(), FrameError> {
    if frames == 0 || height == 0 || width == 0 {
        return Err(FrameError::Empty {
            input,
            frames,
            height,
            width,
        });
    }
    let expected = frames
        .checked_mul(height)
        .and_then(|n| n.checked_mul(width))
        .and_then(|n| n.checked_mul(3));
    if expected != Some(len) {
        return Err(FrameError::DataLength {
            input,
            frames,
            height,
            width,
            expected: expected.unwrap_or(usize::MAX),
            got: len,
        });
    }
    Ok(())
}

impl<T: Real> Video<T> {
    /// A video from `(T, H, W, 3)` data. The length must match; frames must be non-empty.
    pub fn new(
        frames: usize,
        height: usize,
        width: usize,
        data: Vec<T>,
    ) -> Result<Self, FrameError> {
        Self::new_named(Input::Rendered, frames, height, width, data)
    }

    /// As [`Video::new`], naming the video in errors.
    pub fn new_named(
        input: Input,
        frames: usize,
        height: usize,
        width: usize,
        data: Vec<T>,
    ) -> Result<Self, FrameError> {
        check_shape(input, frames, height, width, data.len())?;
        Ok(Video {
            frames,
            height,
            width,
            data,
        })
    }

    /// A video of zeros.
    pub fn zeros(frames: usize, height: usize, width: usize) -> Self {
        Video {
            frames,
            height,
            width,
            data: vec![T::zero(); frames * height * width * 3],
        }
    }

    /// A video from frames of `height x width x 3` values each (e.g. `r4d_splat::Image::rgb`).
    pub fn from_frames<I, F>(height: usize, width: usize, frames: I) -> Result<Self, FrameError>
    where
        I: IntoIterator<Item = F>,
        F: AsRef<[T]>,
    {
        let mut data = Vec::new();
        let mut n = 0;
        for f in frames {
            data.extend_from_slice(f.as_ref());
            n += 1;
        }
        Self::new(n, height, width, data)
    }

    /// A video from `(T, 3, H, W)` (channel-planar) data, as PyTorch stores it.
    pub fn from_tchw(
        frames: usize,
        height: usize,
        width: usize,
        tchw: &[T],
    ) -> Result<Self, FrameError> {
        let plane = height * width;
        if tchw.len() != frames * 3 * plane {
            return Err(FrameError::DataLength {
                input: Input::Rendered,
                frames,
                height,
                width,
                expected: frames * 3 * plane,
                got: tchw.len(),
            });
        }
        let mut data = vec![T::zero(); tchw.len()];
        for t in 0..frames {
            for c in 0..3 {
                let src = &tchw[(t * 3 + c) * plane..(t * 3 + c + 1) * plane];
                for (p, &v) in src.iter().enumerate() {
                    data[(t * plane + p) * 3 + c] = v;
                }
            }
        }
        Self::new(frames, height, width, data)
    }

    /// The data as `(T, 3, H, W)` (channel-planar).
    pub fn to_tchw(&self) -> Vec<T> {
        let plane = self.height * self.width;
        let mut out = vec![T::zero(); self.data.len()];
        for t in 0..self.frames {
            for p in 0..plane {
                for c in 0..3 {
                    out[(t * 3 + c) * plane + p] = self.data[(t * plane + p) * 3 + c];
                }
            }
        }
        out
    }

    /// The same video in another scalar type (rounded to nearest).
    pub fn convert<U: Real>(&self) -> Video<U> {
        Video {
            frames: self.frames,
            height: self.height,
            width: self.width,
            data: self.data.iter().map(|v| U::c(v.f64())).collect(),
        }
    }

    /// Number of frames T.
    pub fn frames(&self) -> usize {
        self.frames
    }
    /// Rows per frame H.
    pub fn height(&self) -> usize {
        self.height
    }
    /// Columns per frame W.
    pub fn width(&self) -> usize {
        self.width
    }
    /// Values per frame, `H * W * 3`.
    pub fn frame_len(&self) -> usize {
        self.height * self.width * 3
    }
    /// All values, `(T, H, W, 3)`.
    pub fn data(&self) -> &[T] {
        &self.data
    }
    /// All values, mutable.
    pub fn data_mut(&mut self) -> &mut [T] {
        &mut self.data
    }
    /// The values, consuming the video.
    pub fn into_data(self) -> Vec<T> {
        self.data
    }
    /// Frame `t`, `H * W * 3` values.
    pub fn frame(&self, t: usize) -> &[T] {
        let n = self.frame_len();
        &self.data[t * n..(t + 1) * n]
    }
    /// Frame `t`, mutable.
    pub fn frame_mut(&mut self, t: usize) -> &mut [T] {
        let n = self.frame_len();
        &mut self.data[t * n..(t + 1) * n]
    }
    /// Value at frame `t`, row `y`, column `x`, channel `c`.
    pub fn at(&self, t: usize, y: usize, x: usize, c: usize) -> T {
        self.data[((t * self.height + y) * self.width + x) * 3 + c]
    }

    /// The first NaN or infinite value, as an error naming `input`.
    pub fn check_finite(&self, input: Input) -> Result<(), FrameError> {
        match self.data.iter().position(|v| !v.is_finite()) {
            None => Ok(()),
            Some(i) => {
                let channel = i % 3;
                let px = i / 3;
                let col = px % self.width;
                let row = (px / self.width) % self.height;
                let frame = px / (self.width * self.height);
                Err(FrameError::NonFinite {
                    input,
                    frame,
                    row,
                    col,
                    channel,
                    kind: if self.data[i].is_nan() {
                        "NaN"
                    } else {
                        "an infinite value"
                    },
                })
            }
        }
    }
}
