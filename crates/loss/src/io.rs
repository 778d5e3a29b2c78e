//! Reading and writing videos: a directory of PNG frames or a float32 `.npy` of shape
//! `(T, H, W, 3)`, the video format of every `r4d` command.
//!
//! * PNG directory: every `*.png` in the directory, sorted by file name (so
//!   `frame_0000.png, frame_0001.png, ...` as `r4d render --frames` writes them). An 8-bit
//!   value `k` means `k / 255` and a 16-bit value `k / 65535`, with no gamma conversion.
//!   Gray frames are replicated to RGB; an alpha channel is ignored.
//! * `.npy`: little-endian float32 (or float64, rounded) in C order, shape `(T, H, W, 3)`;
//!   a single `(H, W, 3)` frame is read as a one-frame video.

use crate::error::Input;
use crate::real::Real;
use crate::video::Video;
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

/// Every `*.png` of `dir`, sorted by file name.
pub fn png_frames(dir: &Path) -> Result<Vec<PathBuf>, VideoIoError> {
    let mut files: Vec<PathBuf> = std::fs::read_dir(dir)
        .map_err(io_err(dir))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.is_file() && p.extension().is_some_and(|e| e.eq_ignore_ascii_case("png")))
        .collect();
    files.sort_by(|a, b| a.file_name().cmp(&b.file_name()));
    Ok(files)
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
        let mut limits = image::Limits::default();
        limits.max_image_width = Some(MAX_IMAGE_SIDE);
        limits.max_image_height = Some(MAX_IMAGE_SIDE);
        limits.max_alloc = Some(MAX_IMAGE_BYTES);
        let mut reader = image::ImageReader::open(f)
            .map_err(io_err(f))?
            .with_guessed_format()
            .map_err(io_err(f))?;
        reader.limits(limits);
        let img = reader.decode().map_err(|e| VideoIoError::Png {
            path: f.clone(),
            message: e.to_string(),
        })?;
        let wh = (img.width(), img.height());
        match size {
            None => size = Some(wh),
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
    let bytes = std::fs::read(path).map_err(io_err(path))?;
    let bad = |message: String| VideoIoError::Npy {
        path: path.to_path_buf(),
        message,
    };
    if bytes.len() < 10 || &bytes[..6] != b"\x93NUMPY" {
        return Err(bad("not a .npy file (bad magic)".into()));
    }
    let (hlen, start) = match bytes[6] {
        1 => (u16::from_le_bytes([bytes[8], bytes[9]]) as usize, 10),
        2 | 3 if bytes.len() >= 12 => (
            u32::from_le_bytes([bytes[8], bytes[9], bytes[10], bytes[11]]) as usize,
            12,
        ),
        v => return Err(bad(format!("unsupported .npy version {v}"))),
    };
    let header = bytes
        .get(start..start + hlen)
        .and_then(|h| std::str::from_utf8(h).ok())
        .ok_or_else(|| bad("truncated or non-UTF-8 header".into()))?;
    let field = |key: &str| -> Option<&str> {
        let i = header.find(&format!("'{key}'"))? + key.len() + 2;
        Some(header[i..].trim_start_matches([' ', ':']))
    };
    let descr = field("descr")
        .and_then(|s| s.strip_prefix('\'')?.split('\'').next())
        .ok_or_else(|| bad("no 'descr' in header".into()))?;
    if field("fortran_order").is_some_and(|s| s.starts_with("True")) {
        return Err(bad("Fortran-order arrays are not supported".into()));
    }
    let shape: Vec<usize> = field("shape")
        .and_then(|s| s.strip_prefix('(')?.split(')').next())
        .ok_or_else(|| bad("no 'shape' in header".into()))?
        .split(',')
        .map(str::trim)
        .filter(|s| !s.is_empty())
        .map(|s| s.parse::<usize>())
        .collect::<Result<_, _>>()
        .map_err(|e| bad(format!("bad shape: {e}")))?;
    let (t, h, w) = match shape[..] {
        [t, h, w, 3] => (t, h, w),
        [h, w, 3] => (1, h, w),
        _ => {
            return Err(bad(format!(
                "shape {shape:?}, expected (T, H, W, 3) or (H, W, 3)"
            )))
        }
    };
    // Sizes come from the file: checked, and bounded by the data actually present before
    // anything is allocated.
    let n = [t, h, w, 3]
        .iter()
        .try_fold(1usize, |a, &d| a.checked_mul(d))
        .ok_or_else(|| bad(format!("shape {shape:?} overflows")))?;
    let body = &bytes[start + hlen..];
    let data: Vec<T> = match descr {
        "<f4" => {
            if body.len() / 4 < n {
                return Err(bad(format!(
                    "{} data bytes for {n} float32 values",
                    body.len()
                )));
            }
            body.chunks_exact(4)
                .take(n)
                .map(|c| T::c(f32::from_le_bytes([c[0], c[1], c[2], c[3]]) as f64))
                .collect()
        }
        "<f8" => {
            if body.len() / 8 < n {
                return Err(bad(format!(
                    "{} data bytes for {n} float64 values",
                    body.len()
                )));
            }
            body.chunks_exact(8)
                .take(n)
                .map(|c| T::c(f64::from_le_bytes(c.try_into().expect("8 bytes"))))
                .collect()
        }
        d => {
            return Err(bad(format!(
                "dtype {d} is not supported (float32 '<f4' or float64 '<f8')"
            )))
        }
    };
    Video::new(t, h, w, data).map_err(|e| bad(e.to_string()))
}

/// Writes a video as a float32 `.npy` of shape `(T, H, W, 3)`.
pub fn write_npy<T: Real>(path: &Path, video: &Video<T>) -> Result<(), VideoIoError> {
    let shape = format!(
        "({}, {}, {}, 3)",
        video.frames(),
        video.height(),
        video.width()
    );
    let mut header = format!("{{'descr': '<f4', 'fortran_order': False, 'shape': {shape}, }}");
    let total = 10 + header.len() + 1;
    header.push_str(&" ".repeat((64 - total % 64) % 64));
    header.push('\n');
    let mut out = Vec::with_capacity(10 + header.len() + 4 * video.data().len());
    out.extend_from_slice(b"\x93NUMPY\x01\x00");
    out.extend_from_slice(&(header.len() as u16).to_le_bytes());
    out.extend_from_slice(header.as_bytes());
    for v in video.data() {
        out.extend_from_slice(&(v.f64() as f32).to_le_bytes());
    }
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
