//! Reading and writing videos: a directory of PNG frames or a float32 `.npy` of shape
//! `(T, H, W, 3)`, the video format of every `r4d` command.
//!
//! * PNG directory: every `*.png` in the directory, in natural order (`frame_2.png` before
//!   `frame_10.png`; [`r4d_fsio::seq`]), so `frame_0000.png, frame_0001.png, ...` as
//!   `r4d render --frames` writes them. A gap in the numbering (`frame_3.png` missing between
//!   `frame_2.png` and `frame_4.png`) is an error naming the missing number. An 8-bit
//!   value `k` means `k / 255` and a 16-bit value `k / 65535`, with no gamma conversion.
//!   Gray frames are replicated to RGB; an alpha channel is ignored.
//! * `.npy`: little-endian float32 (or float64, rounded) in C or Fortran order, shape
//!   `(T, H, W, 3)`; a single `(H, W, 3)` frame is read as a one-frame video. Every value must
//!   lie in [0, 1] (a value outside, NaN included, is an error naming the file, the value and
//!   where it is: videos are RGB in [0, 1], not 0..255).
//! * Every frame of a video has the first frame's size.

use crate::error::Input;
use crate::video::Video;
use r4d_math::Real;
use std::path::{Path, PathBuf};

/// Why a video could not be read or written; names the file.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum VideoIoError {
    /// A file or directory could not be read or written.
    #[error("{path}: {source}")]
    Io {
        /// The path.
        path: PathBuf,
        /// The error.
        source: std::io::Error,
    },
    /// Not a directory and not a `.npy` file.
    #[error("{0}: not a directory of PNG frames or a .npy file")]
    UnknownFormat(PathBuf),
    /// A directory without PNG files.
    #[error("{0}: no .png frames in the directory")]
    NoFrames(PathBuf),
    /// A PNG that could not be decoded.
    #[error("{path}: {message}")]
    Png {
        /// The file.
        path: PathBuf,
        /// The decoder's message.
        message: String,
    },
    /// Frames of different sizes.
    #[error("{path}: frame is {got:?} (WxH), the first frame is {expected:?}")]
    FrameSize {
        /// The file.
        path: PathBuf,
        /// Size of the first frame.
        expected: (u32, u32),
        /// Size of this frame.
        got: (u32, u32),
    },
    /// A gap or a repeated number in a folder's numbered frames.
    #[error("{0}")]
    Sequence(#[from] r4d_fsio::seq::SequenceError),
    /// A value of a float video outside [0, 1] (or not a number).
    #[error("{path}: value {value} at frame {frame}, row {row}, column {col}, channel {channel} is outside [0, 1] (video values are RGB in [0, 1]; divide 8-bit values by 255)")]
    Range {
        /// The file.
        path: PathBuf,
        /// The value.
        value: f64,
        /// Its frame.
        frame: usize,
        /// Its row.
        row: usize,
        /// Its column.
        col: usize,
        /// Its channel (0 red, 1 green, 2 blue).
        channel: usize,
    },
    /// A malformed or unsupported `.npy`.
    #[error("{path}: {message}")]
    Npy {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
}

/// Reads a video: a directory of PNG frames or a `.npy` (see the module docs).
pub fn read_video<T: Real>(path: &Path) -> Result<Video<T>, VideoIoError> {
    if path.is_dir() {
        read_png_dir(path)
    } else if path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("npy"))
    {
        read_npy(path)
    } else if !path.exists() {
        Err(VideoIoError::Io {
            path: path.to_path_buf(),
            source: std::io::Error::new(std::io::ErrorKind::NotFound, "no such file or directory"),
        })
    } else {
        Err(VideoIoError::UnknownFormat(path.to_path_buf()))
    }
}

fn io_err(path: &Path) -> impl FnOnce(std::io::Error) -> VideoIoError + '_ {
    move |source| VideoIoError::Io {
        path: path.to_path_buf(),
        source,
    }
}

/// The largest frame side read from an image file (pixels; cameras are bounded the same way).
pub const MAX_IMAGE_SIDE: u32 = 8192;
/// The most memory one decoded frame may take (bytes).
pub const MAX_IMAGE_BYTES: u64 = 256 << 20;

/// The most memory a video read from `.npy` or image frames may take (bytes; the MP4 reader's
/// `MAX_DECODED_BYTES` is the same 8 GiB).
pub const MAX_VIDEO_BYTES: u64 = 8 << 30;

/// Every `*.png` of `dir`, in natural order with the numbering checked
/// ([`r4d_fsio::seq::frame_sequence`]: a gap or a number written twice is an error).
pub fn png_frames(dir: &Path) -> Result<Vec<PathBuf>, VideoIoError> {
    let files: Vec<PathBuf> = std::fs::read_dir(dir)
        .map_err(io_err(dir))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.is_file() && p.extension().is_some_and(|e| e.eq_ignore_ascii_case("png")))
        .collect();
    Ok(r4d_fsio::seq::frame_sequence(files)?)
}

fn read_png_dir<T: Real>(dir: &Path) -> Result<Video<T>, VideoIoError> {
    let files = png_frames(dir)?;
    if files.is_empty() {
        return Err(VideoIoError::NoFrames(dir.to_path_buf()));
    }
    read_frames(&files, dir)
}

/// Reads the given image files (PNG, or JPEG) as the frames of one video, in the order given;
/// `what` names the video in errors. Every frame must have the first frame's size.
pub fn read_frames<T: Real>(files: &[PathBuf], what: &Path) -> Result<Video<T>, VideoIoError> {
    let dir = what;
    if files.is_empty() {
        return Err(VideoIoError::NoFrames(dir.to_path_buf()));
    }
    let mut data = Vec::new();
    let mut size = None;
    for f in files {
        let img = decode_image(
            &r4d_fsio::read_bounded(f, MAX_IMAGE_BYTES).map_err(io_err(f))?,
            f,
        )?;
        let wh = (img.width(), img.height());
        match size {
            None => {
                // The whole video's size is known from the first frame: checked before the
                // other frames are decoded.
                let bytes = u64::from(wh.0)
                    .saturating_mul(u64::from(wh.1))
                    .saturating_mul(3 * std::mem::size_of::<T>() as u64)
                    .saturating_mul(files.len() as u64);
                if bytes > MAX_VIDEO_BYTES {
                    return Err(VideoIoError::Png {
                        path: dir.to_path_buf(),
                        message: format!(
                            "{} frames of {}x{} need {bytes} bytes: videos are read up to {MAX_VIDEO_BYTES} bytes (r4d_loss::io::MAX_VIDEO_BYTES; select fewer frames or a smaller size)",
                            files.len(),
                            wh.0,
                            wh.1
                        ),
                    });
                }
                size = Some(wh)
            }
            Some(s) if s != wh => {
                return Err(VideoIoError::FrameSize {
                    path: f.clone(),
                    expected: s,
                    got: wh,
                })
            }
            _ => {}
        }
        push_rgb(&img, f, &mut data)?;
    }
    let (w, h) = size.expect("at least one frame");
    Video::new_named(Input::Rendered, files.len(), h as usize, w as usize, data).map_err(|e| {
        VideoIoError::Png {
            path: dir.to_path_buf(),
            message: e.to_string(),
        }
    })
}

/// Decodes an image file's bytes (PNG, JPEG; the format from the content), within
/// [`MAX_IMAGE_SIDE`] and [`MAX_IMAGE_BYTES`]; `path` names it in errors.
pub fn decode_image(bytes: &[u8], path: &Path) -> Result<image::DynamicImage, VideoIoError> {
    let mut limits = image::Limits::default();
    limits.max_image_width = Some(MAX_IMAGE_SIDE);
    limits.max_image_height = Some(MAX_IMAGE_SIDE);
    limits.max_alloc = Some(MAX_IMAGE_BYTES);
    let mut reader = image::ImageReader::new(std::io::Cursor::new(bytes))
        .with_guessed_format()
        .map_err(io_err(path))?;
    reader.limits(limits);
    reader.decode().map_err(|e| VideoIoError::Png {
        path: path.to_path_buf(),
        message: e.to_string(),
    })
}

/// One frame from an image file's bytes: `(width, height, RGB values k / max)`.
pub fn decode_frame<T: Real>(
    bytes: &[u8],
    path: &Path,
) -> Result<(u32, u32, Vec<T>), VideoIoError> {
    let img = decode_image(bytes, path)?;
    let mut data = Vec::new();
    push_rgb(&img, path, &mut data)?;
    Ok((img.width(), img.height(), data))
}

/// Appends an image's pixels as RGB values `k / max`.
fn push_rgb<T: Real>(
    img: &image::DynamicImage,
    path: &Path,
    out: &mut Vec<T>,
) -> Result<(), VideoIoError> {
    use image::DynamicImage as D;
    let q8 = |k: u8| T::c(k as f64 / 255.0);
    let q16 = |k: u16| T::c(k as f64 / 65535.0);
    match img {
        D::ImageRgb8(b) => out.extend(b.as_raw().iter().map(|&k| q8(k))),
        D::ImageRgba8(b) => {
            for p in b.as_raw().chunks_exact(4) {
                out.extend(p[..3].iter().map(|&k| q8(k)));
            }
        }
        D::ImageLuma8(b) => {
            for &k in b.as_raw() {
                out.extend([q8(k); 3]);
            }
        }
        D::ImageLumaA8(b) => {
            for p in b.as_raw().chunks_exact(2) {
                out.extend([q8(p[0]); 3]);
            }
        }
        D::ImageRgb16(b) => out.extend(b.as_raw().iter().map(|&k| q16(k))),
        D::ImageRgba16(b) => {
            for p in b.as_raw().chunks_exact(4) {
                out.extend(p[..3].iter().map(|&k| q16(k)));
            }
        }
        D::ImageLuma16(b) => {
            for &k in b.as_raw() {
                out.extend([q16(k); 3]);
            }
        }
        D::ImageLumaA16(b) => {
            for p in b.as_raw().chunks_exact(2) {
                out.extend([q16(p[0]); 3]);
            }
        }
        _ => {
            return Err(VideoIoError::Png {
                path: path.to_path_buf(),
                message: format!("unsupported pixel format {:?}", img.color()),
            })
        }
    }
    Ok(())
}

fn read_npy<T: Real>(path: &Path) -> Result<Video<T>, VideoIoError> {
    // r4d_loss::io::MAX_VIDEO_BYTES: a larger file is refused from its size.
    let bytes = r4d_fsio::read_bounded(path, MAX_VIDEO_BYTES).map_err(io_err(path))?;
    decode_npy_video(&bytes, path)
}

/// A video from the bytes of a `.npy` file (`path` names it in errors): float32 or float64,
/// shape `(T, H, W, 3)` or `(H, W, 3)`, sizes checked ([`r4d_fsio::npy::parse`]).
pub fn decode_npy_video<T: Real>(bytes: &[u8], path: &Path) -> Result<Video<T>, VideoIoError> {
    let bad = |message: String| VideoIoError::Npy {
        path: path.to_path_buf(),
        message,
    };
    let a = r4d_fsio::npy::parse(bytes).map_err(|e| bad(e.to_string()))?;
    if a.dtype == r4d_fsio::npy::Dtype::Bool {
        return Err(bad(
            "dtype |b1 is not supported for a video (float32 '<f4' or float64 '<f8')".into(),
        ));
    }
    let (t, h, w) = match a.shape[..] {
        [t, h, w, 3] => (t, h, w),
        [h, w, 3] => (1, h, w),
        _ => {
            return Err(bad(format!(
                "shape {:?}, expected (T, H, W, 3) or (H, W, 3)",
                a.shape
            )))
        }
    };
    // Checked before the copy: a value outside [0, 1] (or NaN) names where it is.
    if let Some((i, value)) = a
        .values_f64()
        .enumerate()
        .find(|(_, v)| !(0.0..=1.0).contains(v))
    {
        let (px, channel) = (i / 3, i % 3);
        return Err(VideoIoError::Range {
            path: path.to_path_buf(),
            value,
            frame: px / (h * w),
            row: px / w % h,
            col: px % w,
            channel,
        });
    }
    let data: Vec<T> = a.values_f64().map(T::c).collect();
    Video::new(t, h, w, data).map_err(|e| bad(e.to_string()))
}

/// Writes a video as a float32 `.npy` of shape `(T, H, W, 3)`.
pub fn write_npy<T: Real>(path: &Path, video: &Video<T>) -> Result<(), VideoIoError> {
    let data: Vec<f32> = video.data().iter().map(|v| v.f64() as f32).collect();
    let out = r4d_fsio::npy::encode_f32(&[video.frames(), video.height(), video.width(), 3], &data);
    r4d_fsio::write_atomic(path, &out).map_err(io_err(path))
}

/// Writes a video as 8-bit PNG frames `dir/frame_NNNN.png` (values clamped to [0, 1],
/// `round(255 v)`).
pub fn write_png_dir<T: Real>(dir: &Path, video: &Video<T>) -> Result<(), VideoIoError> {
    std::fs::create_dir_all(dir).map_err(io_err(dir))?;
    for t in 0..video.frames() {
        let px: Vec<u8> = video
            .frame(t)
            .iter()
            .map(|v| (v.f64().clamp(0.0, 1.0) * 255.0).round() as u8)
            .collect();
        let path = dir.join(format!("frame_{t:04}.png"));
        let png_error = |message: String| VideoIoError::Png {
            path: path.clone(),
            message,
        };
        let img = image::RgbImage::from_raw(video.width() as u32, video.height() as u32, px)
            .ok_or_else(|| png_error("frame buffer of the wrong size".into()))?;
        let mut bytes = Vec::new();
        img.write_to(
            &mut std::io::Cursor::new(&mut bytes),
            image::ImageFormat::Png,
        )
        .map_err(|e| png_error(e.to_string()))?;
        r4d_fsio::write_atomic(&path, &bytes).map_err(io_err(&path))?;
    }
    Ok(())
}
