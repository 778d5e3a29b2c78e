//! Diagnostic outputs of a video fit (paper Sec. 4): the fitted frames as PNGs and GIFs,
//! reference and fit side by side, the w-t spatiotemporal slice of one image row, its
//! temporal spectrum, and loss curves.
//!
//! Conventions: videos are [`Video<f32>`] RGB in `[0, 1]` with row 0 at the top; 8-bit
//! outputs store `round(clip(v, 0, 1) * 255)`. [`write_fit_diagnostics`] writes the whole
//! set for one fit into a folder.
//!
//! Loss curves are drawn with `plotters`; their text uses DejaVu Sans, embedded in the
//! library (`assets/fonts/`, license in `assets/fonts/LICENSE-DejaVu.txt`), so charts
//! render the same on a machine with no fonts installed.

use image::codecs::gif::{GifEncoder, Repeat};
use image::{Delay, Frame, Rgb, RgbImage, RgbaImage};
use plotters::coord::ranged1d::{AsRangedCoord, ValueFormatter};
use plotters::prelude::*;
use r4d_loss::Video;
use rustfft::num_complex::Complex;
use rustfft::FftPlanner;
use std::ops::Range;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;
use std::time::Duration;

/// Errors of the diagnostic writers.
#[derive(Debug, thiserror::Error)]
pub enum DiagError {
    /// A file or folder could not be created or written.
    #[error("{}: {source}", path.display())]
    Io {
        /// The file or folder.
        path: PathBuf,
        /// The underlying error.
        source: std::io::Error,
    },
    /// An MP4 could not be encoded or written.
    #[error(transparent)]
    Video(#[from] r4d_video::VideoError),
    /// An image or GIF could not be encoded or written.
    #[error("{}: {source}", path.display())]
    Image {
        /// The file.
        path: PathBuf,
        /// The underlying error.
        source: image::ImageError,
    },
    /// Two videos that must have the same number of frames do not.
    #[error("frame counts differ: {left} vs {right}")]
    FrameCount {
        /// Frames of the first (left, reference) video.
        left: usize,
        /// Frames of the second (right, fitted) video.
        right: usize,
    },
    /// Two videos that must have the same frame height do not.
    #[error("frame heights differ: {left} vs {right} rows")]
    Height {
        /// Rows of the first (left, reference) video.
        left: usize,
        /// Rows of the second (right, fitted) video.
        right: usize,
    },
    /// The chosen image row is not in the video.
    #[error("row {row} is out of range: the video has {height} rows")]
    Row {
        /// The requested row.
        row: usize,
        /// Rows per frame.
        height: usize,
    },
    /// The frame rate is not a finite positive number.
    #[error("fps must be finite and positive, got {0}")]
    Fps(f64),
    /// A chart could not be drawn (no data, invalid font, plotting failure).
    #[error("{}: {reason}", path.display())]
    Plot {
        /// The chart's file.
        path: PathBuf,
        /// What went wrong.
        reason: String,
    },
}

/// Result of this module.
pub type Result<T> = std::result::Result<T, DiagError>;

/// Minimum height in pixels of a [`wt_slice`] picture (time is upscaled to reach it).
pub const WT_MIN_HEIGHT: usize = 128;

/// Width of the white separator between the videos of [`side_by_side`], in pixels.
pub const SEPARATOR_WIDTH: usize = 4;

/// Size in pixels (width, height) of a [`loss_curve_png`] chart.
pub const LOSS_CURVE_SIZE: (u32, u32) = (900, 540);

/// The paths written by [`write_fit_diagnostics`] and the image row its slices use.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct DiagnosticFiles {
    /// The image row of the w-t slices and spectra.
    pub row: usize,
    /// `fitted/frame_XXXX.png`, one per frame.
    pub fitted_frames: Vec<PathBuf>,
    /// `fitted.gif`.
    pub fitted_gif: PathBuf,
    /// `side_by_side/frame_XXXX.png` (reference left, fit right), one per frame.
    pub side_by_side_frames: Vec<PathBuf>,
    /// `side_by_side.gif`.
    pub side_by_side_gif: PathBuf,
    /// `fitted.mp4` (H.264; see [`write_mp4`]).
    pub fitted_mp4: PathBuf,
    /// `side_by_side.mp4`.
    pub side_by_side_mp4: PathBuf,
    /// `wt_reference.png`: the reference's w-t slice.
    pub wt_reference: PathBuf,
    /// `wt_fitted.png`: the fit's w-t slice.
    pub wt_fitted: PathBuf,
    /// `spectrum_reference.png`: the reference's temporal spectrum.
    pub spectrum_reference: PathBuf,
    /// `spectrum_fitted.png`: the fit's temporal spectrum (same colour scale).
    pub spectrum_fitted: PathBuf,
}

// ---------------------------------------------------------------------------------------
// Frames and GIFs
// ---------------------------------------------------------------------------------------

/// One value as 8 bits: `round(clip(v, 0, 1) * 255)` (NaN gives 0).
fn to_u8(v: f32) -> u8 {
    (v.clamp(0.0, 1.0) * 255.0).round() as u8
}

/// Frame `t` as an 8-bit RGB image.
fn frame_rgb(video: &Video<f32>, t: usize) -> RgbImage {
    let bytes = video.frame(t).iter().map(|&v| to_u8(v)).collect();
    RgbImage::from_raw(video.width() as u32, video.height() as u32, bytes)
        .expect("a frame holds width * height * 3 values")
}

/// Creates `dir` and its parents.
fn create_dir(dir: &Path) -> Result<()> {
    std::fs::create_dir_all(dir).map_err(|source| DiagError::Io {
        path: dir.to_path_buf(),
        source,
    })
}

/// Creates the parent folder of `path`, if it has one.
fn create_parent(path: &Path) -> Result<()> {
    match path.parent().filter(|d| !d.as_os_str().is_empty()) {
        Some(dir) => create_dir(dir),
        None => Ok(()),
    }
}

/// Saves an RGB image as PNG, creating the parent folder.
fn save_png(path: &Path, img: &RgbImage) -> Result<()> {
    create_parent(path)?;
    let mut bytes = Vec::new();
    img.write_to(
        &mut std::io::Cursor::new(&mut bytes),
        image::ImageFormat::Png,
    )
    .map_err(|source| DiagError::Image {
        path: path.to_path_buf(),
        source,
    })?;
    r4d_fsio::write_atomic(path, &bytes).map_err(|source| DiagError::Io {
        path: path.to_path_buf(),
        source,
    })
}

/// Writes every frame of `video` as an 8-bit PNG `dir/{prefix}_{t:04}.png` (values
/// `round(clip(v, 0, 1) * 255)`), creating `dir`, and returns the paths in frame order.
pub fn write_png_frames(dir: &Path, video: &Video<f32>, prefix: &str) -> Result<Vec<PathBuf>> {
    create_dir(dir)?;
    (0..video.frames())
        .map(|t| {
            let path = dir.join(format!("{prefix}_{t:04}.png"));
            save_png(&path, &frame_rgb(video, t))?;
            Ok(path)
        })
        .collect()
}

/// Writes `video` as an animated GIF that loops forever, one frame every `1 / fps`
/// seconds (GIF stores delays in 10 ms steps; many viewers slow delays under 20 ms down).
/// Colours are quantised to GIF's 256-entry palettes per frame.
pub fn write_gif(path: &Path, video: &Video<f32>, fps: f64) -> Result<()> {
    let delay = frame_delay(fps)?;
    let img_err = |source| DiagError::Image {
        path: path.to_path_buf(),
        source,
    };
    let mut bytes = Vec::new();
    {
        let mut gif = GifEncoder::new_with_speed(&mut bytes, 10);
        gif.set_repeat(Repeat::Infinite).map_err(img_err)?;
        for t in 0..video.frames() {
            let rgba = rgba_of(&frame_rgb(video, t));
            gif.encode_frame(Frame::from_parts(rgba, 0, 0, delay))
                .map_err(img_err)?;
        }
    } // Dropping the encoder writes the GIF trailer.
    create_parent(path)?;
    r4d_fsio::write_atomic(path, &bytes).map_err(|source| DiagError::Io {
        path: path.to_path_buf(),
        source,
    })
}

/// Writes `video` as an H.264 MP4 (yuv420p, plays in browsers; `r4d_video::write_mp4`) at
/// `fps`. A video larger than the encoder's 3840 x 2160 (a side-by-side of two 1080p videos)
/// is halved (2 x 2 box filter) until it fits.
pub fn write_mp4(path: &Path, video: &Video<f32>, fps: f64) -> Result<()> {
    create_parent(path)?;
    let mut v = std::borrow::Cow::Borrowed(video);
    while v.width().max(v.height()) > r4d_video::MAX_ENCODE_LONG
        || v.width().min(v.height()) > r4d_video::MAX_ENCODE_SHORT
    {
        v = std::borrow::Cow::Owned(halve(&v));
    }
    Ok(r4d_video::write_mp4(path, &v, fps)?)
}

/// `video` at half the width and height (2 x 2 averages; an odd last row/column is dropped).
fn halve(video: &Video<f32>) -> Video<f32> {
    let (h, w) = (video.height() / 2, video.width() / 2);
    let (h, w) = (h.max(1), w.max(1));
    let src_w = video.width();
    Video::from_frames(
        h,
        w,
        (0..video.frames()).map(|t| {
            let f = video.frame(t);
            let at = |y: usize, x: usize, c: usize| {
                let (y, x) = (y.min(video.height() - 1), x.min(src_w - 1));
                f[(y * src_w + x) * 3 + c]
            };
            let mut out = vec![0f32; h * w * 3];
            for y in 0..h {
                for x in 0..w {
                    for c in 0..3 {
                        out[(y * w + x) * 3 + c] = 0.25
                            * (at(2 * y, 2 * x, c)
                                + at(2 * y, 2 * x + 1, c)
                                + at(2 * y + 1, 2 * x, c)
                                + at(2 * y + 1, 2 * x + 1, c));
                    }
                }
            }
            out
        }),
    )
    .expect("a halved frame is non-empty")
}

/// The GIF frame delay for `fps` frames per second.
fn frame_delay(fps: f64) -> Result<Delay> {
    if !(fps.is_finite() && fps > 0.0) {
        return Err(DiagError::Fps(fps));
    }
    Ok(Delay::from_saturating_duration(Duration::from_secs_f64(
        1.0 / fps,
    )))
}

/// An opaque RGBA copy of an RGB image.
fn rgba_of(img: &RgbImage) -> RgbaImage {
    RgbaImage::from_fn(img.width(), img.height(), |x, y| {
        let Rgb([r, g, b]) = *img.get_pixel(x, y);
        image::Rgba([r, g, b, 255])
    })
}

// ---------------------------------------------------------------------------------------
// Side by side
// ---------------------------------------------------------------------------------------

/// Checks that two videos have the same frame count and height (for [`side_by_side`]).
fn check_stackable(left: &Video<f32>, right: &Video<f32>) -> Result<()> {
    if left.frames() != right.frames() {
        return Err(DiagError::FrameCount {
            left: left.frames(),
            right: right.frames(),
        });
    }
    if left.height() != right.height() {
        return Err(DiagError::Height {
            left: left.height(),
            right: right.height(),
        });
    }
    Ok(())
}

/// The two videos next to each other: each frame is `left`'s frame, a
/// [`SEPARATOR_WIDTH`]-pixel white (1.0) column band, then `right`'s frame, so the result
/// is `left.width() + 4 + right.width()` wide. Errors if the frame counts or heights differ
/// (widths may differ).
pub fn side_by_side(left: &Video<f32>, right: &Video<f32>) -> Result<Video<f32>> {
    check_stackable(left, right)?;
    let (wl, wr) = (left.width() * 3, right.width() * 3);
    let sep = [1.0f32; SEPARATOR_WIDTH * 3];
    let rows = left.frames() * left.height();
    let mut data = Vec::with_capacity(rows * (wl + sep.len() + wr));
    for (l, r) in left.data().chunks(wl).zip(right.data().chunks(wr)) {
        data.extend_from_slice(l);
        data.extend_from_slice(&sep);
        data.extend_from_slice(r);
    }
    let width = left.width() + SEPARATOR_WIDTH + right.width();
    Ok(Video::new(left.frames(), left.height(), width, data)
        .expect("side-by-side data has the stated shape"))
}

// ---------------------------------------------------------------------------------------
// w-t slice
// ---------------------------------------------------------------------------------------

/// Checks that `row` is an image row of `video`.
fn check_row(video: &Video<f32>, row: usize) -> Result<()> {
    if row >= video.height() {
        return Err(DiagError::Row {
            row,
            height: video.height(),
        });
    }
    Ok(())
}

/// How many pixel rows each frame gets in a [`wt_slice`] of a `frames`-frame video:
/// `ceil(WT_MIN_HEIGHT / frames)`, at least 1.
pub fn wt_time_scale(frames: usize) -> usize {
    WT_MIN_HEIGHT.div_ceil(frames.max(1)).max(1)
}

/// The w-t spatiotemporal slice of image row `row`: a picture `W` pixels wide in which
/// pixel row `t` shows that image row in frame `t` (time runs downwards), coloured as the
/// video (8-bit). So that short videos stay visible, time is upscaled by nearest neighbour:
/// each frame fills [`wt_time_scale`]`(T)` consecutive pixel rows, making the picture
/// `T * wt_time_scale(T)` (at least [`WT_MIN_HEIGHT`]) pixels tall; frame `t` occupies
/// pixel rows `t * s .. (t + 1) * s`.
pub fn wt_slice(video: &Video<f32>, row: usize) -> Result<RgbImage> {
    check_row(video, row)?;
    let s = wt_time_scale(video.frames());
    let height = (video.frames() * s) as u32;
    Ok(RgbImage::from_fn(video.width() as u32, height, |x, py| {
        let (t, x) = (py as usize / s, x as usize);
        Rgb([0, 1, 2].map(|c| to_u8(video.at(t, row, x, c))))
    }))
}

// ---------------------------------------------------------------------------------------
// Temporal spectrum
// ---------------------------------------------------------------------------------------

/// Luminance (Rec. 601: 0.299 R + 0.587 G + 0.114 B) of one pixel.
fn luminance(video: &Video<f32>, t: usize, y: usize, x: usize) -> f64 {
    0.299 * video.at(t, y, x, 0) as f64
        + 0.587 * video.at(t, y, x, 1) as f64
        + 0.114 * video.at(t, y, x, 2) as f64
}

/// `log(1 + |X_k|)` of one image row: `bins = floor(T / 2) + 1` frequencies by `width`
/// columns, stored frequency-major (`values[k * width + x]`).
struct Spectrum {
    width: usize,
    bins: usize,
    values: Vec<f64>,
}

impl Spectrum {
    /// For each column of `row`: the luminance over time, mean removed, its (unnormalised)
    /// DFT over time `X_k = sum_t l_t exp(-2 pi i k t / T)`, kept for `k = 0 ..= T / 2`.
    fn of_row(video: &Video<f32>, row: usize) -> Result<Self> {
        check_row(video, row)?;
        let (frames, width) = (video.frames(), video.width());
        let bins = frames / 2 + 1;
        let fft = FftPlanner::<f64>::new().plan_fft_forward(frames);
        let mut values = vec![0.0; bins * width];
        let mut buf = vec![Complex::new(0.0, 0.0); frames];
        for x in 0..width {
            for (t, b) in buf.iter_mut().enumerate() {
                *b = Complex::new(luminance(video, t, row, x), 0.0);
            }
            let mean = buf.iter().map(|b| b.re).sum::<f64>() / frames as f64;
            buf.iter_mut().for_each(|b| b.re -= mean);
            fft.process(&mut buf);
            for k in 0..bins {
                values[k * width + x] = buf[k].norm().ln_1p();
            }
        }
        Ok(Spectrum {
            width,
            bins,
            values,
        })
    }

    /// The largest value (0 for an empty or all-NaN spectrum).
    fn max(&self) -> f64 {
        self.values.iter().copied().fold(0.0, f64::max)
    }

    /// The picture: pixel `(x, k)` is `viridis(value / vmax)`; frequency 0 at the top.
    fn to_image(&self, vmax: f64) -> RgbImage {
        let scale = if vmax > 0.0 { 1.0 / vmax } else { 0.0 };
        RgbImage::from_fn(self.width as u32, self.bins as u32, |x, k| {
            viridis(self.values[k as usize * self.width + x as usize] * scale)
        })
    }
}

/// Viridis (matplotlib's perceptually uniform map) at 11 evenly spaced stops.
const VIRIDIS: [[u8; 3]; 11] = [
    [68, 1, 84],
    [72, 36, 117],
    [65, 68, 135],
    [53, 95, 141],
    [42, 120, 142],
    [33, 145, 140],
    [34, 168, 132],
    [68, 191, 112],
    [122, 209, 81],
    [189, 223, 38],
    [253, 231, 37],
];

/// The viridis colour of `v` in `[0, 1]` (clipped; NaN gives the dark end), interpolated
/// linearly between the stops of [`VIRIDIS`].
fn viridis(v: f64) -> Rgb<u8> {
    let v = if v.is_nan() { 0.0 } else { v.clamp(0.0, 1.0) };
    let pos = v * (VIRIDIS.len() - 1) as f64;
    let i = (pos.floor() as usize).min(VIRIDIS.len() - 2);
    let f = pos - i as f64;
    let (a, b) = (VIRIDIS[i], VIRIDIS[i + 1]);
    Rgb([0, 1, 2].map(|c| (a[c] as f64 + f * (b[c] as f64 - a[c] as f64)).round() as u8))
}

/// The temporal spectrum of image row `row`: for each column `x`, the luminance
/// `0.299 R + 0.587 G + 0.114 B` over time with its mean removed, and its unnormalised DFT
/// over time `X_k`. The picture is `W` pixels wide and `floor(T / 2) + 1` tall; pixel row
/// `k` is frequency bin `k` (`k` cycles per video, `k * fps / T` Hz), **frequency 0 at the
/// top**. Each pixel is `log(1 + |X_k|)` divided by the picture's largest value and mapped
/// through viridis (dark purple 0, yellow the maximum). Use [`temporal_spectrum_pair`] to
/// compare two videos on one scale.
pub fn temporal_spectrum(video: &Video<f32>, row: usize) -> Result<RgbImage> {
    let s = Spectrum::of_row(video, row)?;
    Ok(s.to_image(s.max()))
}

/// [`temporal_spectrum`] of `reference` and `fitted` at the same row on one shared colour
/// scale (the larger of the two maxima maps to yellow), so their colours compare directly.
/// Returns `(reference, fitted)` pictures; the videos may differ in size.
pub fn temporal_spectrum_pair(
    reference: &Video<f32>,
    fitted: &Video<f32>,
    row: usize,
) -> Result<(RgbImage, RgbImage)> {
    let a = Spectrum::of_row(reference, row)?;
    let b = Spectrum::of_row(fitted, row)?;
    let vmax = a.max().max(b.max());
    Ok((a.to_image(vmax), b.to_image(vmax)))
}

/// The image row with the largest temporal variance of luminance, summed over the row's
/// columns: the row that crosses the most motion. Ties go to the smaller row; a video with
/// no temporal change at all gives the middle row `H / 2`.
pub fn busiest_row(video: &Video<f32>) -> usize {
    let n = video.frames() as f64;
    let variance = |y: usize| -> f64 {
        (0..video.width())
            .map(|x| {
                let l: Vec<f64> = (0..video.frames())
                    .map(|t| luminance(video, t, y, x))
                    .collect();
                let mean = l.iter().sum::<f64>() / n;
                l.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / n
            })
            .sum()
    };
    let (mut best, mut best_var) = (video.height() / 2, 0.0);
    for y in 0..video.height() {
        let v = variance(y);
        if v > best_var {
            (best, best_var) = (y, v);
        }
    }
    best
}

// ---------------------------------------------------------------------------------------
// Loss curves
// ---------------------------------------------------------------------------------------

/// DejaVu Sans, embedded so that chart text renders without system fonts.
static DEJAVU_SANS: &[u8] = include_bytes!("../assets/fonts/DejaVuSans.ttf");

/// Registers the embedded font as plotters' `sans-serif` family, once per process.
fn register_font_once() -> std::result::Result<(), String> {
    static REGISTERED: OnceLock<bool> = OnceLock::new();
    let ok = *REGISTERED.get_or_init(|| {
        plotters::style::register_font("sans-serif", FontStyle::Normal, DEJAVU_SANS).is_ok()
    });
    ok.then_some(())
        .ok_or_else(|| "the embedded DejaVu Sans font could not be loaded".to_string())
}

/// Series colours (matplotlib's tab10), cycled.
const SERIES_COLORS: [RGBColor; 10] = [
    RGBColor(31, 119, 180),
    RGBColor(255, 127, 14),
    RGBColor(44, 160, 44),
    RGBColor(214, 39, 40),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
    RGBColor(227, 119, 194),
    RGBColor(127, 127, 127),
    RGBColor(188, 189, 34),
    RGBColor(23, 190, 207),
];

/// `v` with `decimals` decimals, trailing zeros (and a bare point) removed.
fn trimmed_fixed(v: f64, decimals: usize) -> String {
    let s = format!("{v:.decimals$}");
    if s.contains('.') {
        s.trim_end_matches('0').trim_end_matches('.').into()
    } else {
        s
    }
}

/// `v` in scientific notation with `digits` mantissa decimals, trailing zeros removed
/// (`1.5e-4`, `1e3`).
fn trimmed_sci(v: f64, digits: usize) -> String {
    let s = format!("{v:.digits$e}");
    match s.split_once('e') {
        Some((m, e)) if m.contains('.') => {
            format!("{}e{e}", m.trim_end_matches('0').trim_end_matches('.'))
        }
        _ => s,
    }
}

/// A tick label on a logarithmic axis: plain decimals for moderate magnitudes, else
/// `1.5e-4` style.
fn log_tick_label(v: f64) -> String {
    let a = v.abs();
    if (1e-3..1e5).contains(&a) {
        trimmed_fixed(v, (3 - a.log10().floor() as i32).clamp(0, 6) as usize)
    } else {
        trimmed_sci(v, 2)
    }
}

/// A tick label on a linear axis spanning `span`: as many digits as the tick spacing
/// (about `span / 10`) needs; values within `span * 1e-9` of zero print as `0`.
fn linear_tick_label(v: f64, span: f64) -> String {
    let a = v.abs();
    if a <= span * 1e-9 {
        return "0".into();
    }
    let step_exp = (span / 10.0).log10().floor() as i32;
    if (1e-3..1e5).contains(&a) {
        trimmed_fixed(v, (1 - step_exp).clamp(0, 12) as usize)
    } else {
        trimmed_sci(
            v,
            (a.log10().floor() as i32 - step_exp + 1).clamp(1, 6) as usize,
        )
    }
}

/// The finite points of each series (points with a NaN or infinite coordinate dropped).
type Points<'a> = Vec<(&'a str, Vec<(f64, f64)>)>;

/// The series with their non-finite points dropped.
fn finite_series<'a>(series: &'a [(&'a str, Vec<(f64, f64)>)]) -> Points<'a> {
    series
        .iter()
        .map(|(name, pts)| {
            let pts = pts
                .iter()
                .copied()
                .filter(|(x, y)| x.is_finite() && y.is_finite())
                .collect();
            (*name, pts)
        })
        .collect()
}

/// `(min, max)` of some values, `None` when there are none.
fn extent(values: impl Iterator<Item = f64>) -> Option<(f64, f64)> {
    values.fold(None, |acc, v| match acc {
        None => Some((v, v)),
        Some((lo, hi)) => Some((lo.min(v), hi.max(v))),
    })
}

/// A linear axis range over `[lo, hi]`, padded by 5 % of the span when `margin`; a flat
/// range is padded by 10 % of its value (by 1 around zero).
fn linear_range(lo: f64, hi: f64, margin: bool) -> Range<f64> {
    let pad = match (hi > lo, margin) {
        (true, true) => 0.05 * (hi - lo),
        (true, false) => 0.0,
        (false, _) if lo == 0.0 => 1.0,
        (false, _) => 0.1 * lo.abs(),
    };
    lo - pad..hi + pad
}

/// A logarithmic axis range over positive `[lo, hi]`, padded by 5 % of the decades
/// (a factor 2 either way when flat).
fn log_range(lo: f64, hi: f64) -> Range<f64> {
    let f = if hi > lo { (hi / lo).powf(0.05) } else { 2.0 };
    lo / f..hi * f
}

/// Draws the chart on `area`: title, axes with labels, one line per series, legend.
fn draw_chart<DB, Y>(
    area: &DrawingArea<DB, plotters::coord::Shift>,
    title: &str,
    series: &Points,
    x: Range<f64>,
    y: Y,
    y_desc: &str,
    y_label: &dyn Fn(&f64) -> String,
) -> std::result::Result<(), String>
where
    DB: DrawingBackend,
    Y: AsRangedCoord<Value = f64>,
    Y::CoordDescType: ValueFormatter<f64>,
{
    let e = |e: DrawingAreaErrorKind<DB::ErrorType>| e.to_string();
    let x_span = x.end - x.start;
    let x_label = move |v: &f64| linear_tick_label(*v, x_span);
    area.fill(&WHITE).map_err(e)?;
    let mut chart = ChartBuilder::on(area)
        .caption(title, ("sans-serif", 24))
        .margin(16)
        .x_label_area_size(48)
        .y_label_area_size(80)
        .build_cartesian_2d(x, y)
        .map_err(e)?;
    chart
        .configure_mesh()
        .x_desc("iteration")
        .y_desc(y_desc)
        .x_label_formatter(&x_label)
        .y_label_formatter(y_label)
        .label_style(("sans-serif", 15))
        .axis_desc_style(("sans-serif", 17))
        .draw()
        .map_err(e)?;
    for (i, (name, pts)) in series.iter().enumerate() {
        let style = SERIES_COLORS[i % SERIES_COLORS.len()].stroke_width(2);
        chart
            .draw_series(LineSeries::new(pts.iter().copied(), style))
            .map_err(e)?
            .label(*name)
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 24, y)], style));
    }
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::UpperRight)
        .label_font(("sans-serif", 15))
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .draw()
        .map_err(e)
}

/// Renders the chart into an RGB buffer of [`LOSS_CURVE_SIZE`].
fn render_loss_chart(title: &str, series: &Points) -> std::result::Result<RgbImage, String> {
    register_font_once()?;
    let all = || series.iter().flat_map(|(_, p)| p.iter().copied());
    let (x0, x1) = extent(all().map(|p| p.0)).ok_or("no finite points to plot")?;
    let (y0, y1) = extent(all().map(|p| p.1)).ok_or("no finite points to plot")?;
    let (w, h) = LOSS_CURVE_SIZE;
    let mut buf = vec![0u8; (w * h * 3) as usize];
    {
        let area = BitMapBackend::with_buffer(&mut buf, (w, h)).into_drawing_area();
        let x = linear_range(x0, x1, false);
        if y0 > 0.0 {
            let y = log_range(y0, y1).log_scale();
            let label = |v: &f64| log_tick_label(*v);
            draw_chart(&area, title, series, x, y, "loss (log scale)", &label)?;
        } else {
            let y = linear_range(y0, y1, true);
            let span = y.end - y.start;
            let label = move |v: &f64| linear_tick_label(*v, span);
            draw_chart(&area, title, series, x, y, "loss", &label)?;
        }
        area.present().map_err(|e| e.to_string())?;
    }
    Ok(RgbImage::from_raw(w, h, buf).expect("buffer of w * h * 3 bytes"))
}

/// Draws loss terms against iteration as a PNG line chart of [`LOSS_CURVE_SIZE`] pixels:
/// one line per `(name, [(iteration, value)])` series, with title, axis labels, and a
/// legend of the names. The y axis is logarithmic when every value is positive, linear
/// otherwise. Points with a NaN or infinite coordinate are skipped; it is an error when no
/// point is left. Text uses the embedded DejaVu Sans, so no system font is needed.
pub fn loss_curve_png(path: &Path, title: &str, series: &[(&str, Vec<(f64, f64)>)]) -> Result<()> {
    let series = finite_series(series);
    let img = render_loss_chart(title, &series).map_err(|reason| DiagError::Plot {
        path: path.to_path_buf(),
        reason,
    })?;
    save_png(path, &img)
}

// ---------------------------------------------------------------------------------------
// Everything for one fit
// ---------------------------------------------------------------------------------------

/// Writes the diagnostics of a video fit into `dir` (created if needed):
///
/// - `fitted/frame_XXXX.png`, `fitted.gif` and `fitted.mp4`: the fitted video;
/// - `side_by_side/frame_XXXX.png`, `side_by_side.gif` and `side_by_side.mp4`: reference
///   left, fit right
///   ([`side_by_side`]);
/// - `wt_reference.png`, `wt_fitted.png`: w-t slices of image row `row` ([`wt_slice`]);
/// - `spectrum_reference.png`, `spectrum_fitted.png`: their temporal spectra on one colour
///   scale ([`temporal_spectrum_pair`]), each frequency bin stretched to
///   [`wt_time_scale`]`(bins)` rows (frequency 0 at the top).
///
/// `row` defaults to [`busiest_row`] of the reference (the row with the largest temporal
/// variance of luminance, so the slice crosses the motion). GIFs play at `fps`. The videos
/// must have the same frame count and height; everything is checked before any file is
/// written.
pub fn write_fit_diagnostics(
    dir: &Path,
    reference: &Video<f32>,
    fitted: &Video<f32>,
    row: Option<usize>,
    fps: f64,
) -> Result<DiagnosticFiles> {
    check_stackable(reference, fitted)?;
    frame_delay(fps)?;
    let row = row.unwrap_or_else(|| busiest_row(reference));
    check_row(reference, row)?;
    create_dir(dir)?;

    let fitted_frames = write_png_frames(&dir.join("fitted"), fitted, "frame")?;
    let fitted_gif = dir.join("fitted.gif");
    write_gif(&fitted_gif, fitted, fps)?;

    let both = side_by_side(reference, fitted)?;
    let side_by_side_frames = write_png_frames(&dir.join("side_by_side"), &both, "frame")?;
    let side_by_side_gif = dir.join("side_by_side.gif");
    write_gif(&side_by_side_gif, &both, fps)?;
    let fitted_mp4 = dir.join("fitted.mp4");
    write_mp4(&fitted_mp4, fitted, fps)?;
    let side_by_side_mp4 = dir.join("side_by_side.mp4");
    write_mp4(&side_by_side_mp4, &both, fps)?;

    let wt_reference = dir.join("wt_reference.png");
    save_png(&wt_reference, &wt_slice(reference, row)?)?;
    let wt_fitted = dir.join("wt_fitted.png");
    save_png(&wt_fitted, &wt_slice(fitted, row)?)?;

    let (spec_ref, spec_fit) = temporal_spectrum_pair(reference, fitted, row)?;
    // A spectrum has only T/2 + 1 rows: stretch each frequency bin to a band of rows so the
    // file is at least WT_MIN_HEIGHT pixels tall.
    let stretch = |img: RgbImage| -> RgbImage {
        let s = wt_time_scale(img.height() as usize) as u32;
        RgbImage::from_fn(img.width(), img.height() * s, |x, y| {
            *img.get_pixel(x, y / s)
        })
    };
    let (spec_ref, spec_fit) = (stretch(spec_ref), stretch(spec_fit));
    let spectrum_reference = dir.join("spectrum_reference.png");
    save_png(&spectrum_reference, &spec_ref)?;
    let spectrum_fitted = dir.join("spectrum_fitted.png");
    save_png(&spectrum_fitted, &spec_fit)?;

    Ok(DiagnosticFiles {
        row,
        fitted_frames,
        fitted_gif,
        side_by_side_frames,
        side_by_side_gif,
        fitted_mp4,
        side_by_side_mp4,
        wt_reference,
        wt_fitted,
        spectrum_reference,
        spectrum_fitted,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use image::AnimationDecoder;
    use std::sync::atomic::{AtomicUsize, Ordering};

    /// A unique temporary folder, removed on drop.
    struct TempDir(PathBuf);

    impl TempDir {
        fn new(tag: &str) -> Self {
            static COUNTER: AtomicUsize = AtomicUsize::new(0);
            let nanos = std::time::SystemTime::now()
                .duration_since(std::time::UNIX_EPOCH)
                .map(|d| d.as_nanos())
                .unwrap_or(0);
            let n = COUNTER.fetch_add(1, Ordering::Relaxed);
            let name = format!("r4d-diag-{tag}-{}-{nanos}-{n}", std::process::id());
            let dir = std::env::temp_dir().join(name);
            std::fs::create_dir_all(&dir).unwrap();
            TempDir(dir)
        }
    }

    impl Drop for TempDir {
        fn drop(&mut self) {
            let _ = std::fs::remove_dir_all(&self.0);
        }
    }

    /// A video whose value at `(t, y, x, c)` is `f(t, y, x, c)`.
    fn video(
        frames: usize,
        height: usize,
        width: usize,
        f: impl Fn(usize, usize, usize, usize) -> f32,
    ) -> Video<f32> {
        let mut data = Vec::with_capacity(frames * height * width * 3);
        for t in 0..frames {
            for y in 0..height {
                for x in 0..width {
                    for c in 0..3 {
                        data.push(f(t, y, x, c));
                    }
                }
            }
        }
        Video::new(frames, height, width, data).unwrap()
    }

    /// A red one-pixel-wide vertical bar at column `t` in frame `t`, on black.
    fn moving_bar(frames: usize, height: usize, width: usize) -> Video<f32> {
        video(frames, height, width, |t, _, x, c| {
            if x == t && c == 0 {
                1.0
            } else {
                0.0
            }
        })
    }

    /// Grey pixel at column 1 of every row oscillating at `k` cycles per video.
    fn oscillating(frames: usize, k: usize, amplitude: f32) -> Video<f32> {
        video(frames, 2, 3, |t, _, x, _| {
            let phase = 2.0 * std::f32::consts::PI * (k * t) as f32 / frames as f32;
            if x == 1 {
                0.5 + amplitude * phase.cos()
            } else {
                0.25
            }
        })
    }

    #[test]
    fn side_by_side_size_and_separator() {
        let left = video(3, 4, 5, |_, _, _, _| 0.2);
        let right = video(3, 4, 2, |_, _, _, _| 0.7);
        let both = side_by_side(&left, &right).unwrap();
        assert_eq!((both.frames(), both.height(), both.width()), (3, 4, 11));
        for t in 0..3 {
            for y in 0..4 {
                for c in 0..3 {
                    assert_eq!(both.at(t, y, 4, c), 0.2);
                    assert!((5..9).all(|x| both.at(t, y, x, c) == 1.0));
                    assert_eq!(both.at(t, y, 9, c), 0.7);
                }
            }
        }
    }

    #[test]
    fn side_by_side_rejects_mismatches() {
        let a = video(3, 4, 5, |_, _, _, _| 0.0);
        let frames = video(2, 4, 5, |_, _, _, _| 0.0);
        let height = video(3, 5, 5, |_, _, _, _| 0.0);
        assert!(matches!(
            side_by_side(&a, &frames),
            Err(DiagError::FrameCount { left: 3, right: 2 })
        ));
        assert!(matches!(
            side_by_side(&a, &height),
            Err(DiagError::Height { left: 4, right: 5 })
        ));
    }

    #[test]
    fn wt_slice_traces_moving_bar() {
        let (frames, width) = (10, 12);
        let v = moving_bar(frames, 6, width);
        let img = wt_slice(&v, 2).unwrap();
        let s = wt_time_scale(frames);
        assert_eq!(s, 13);
        assert_eq!(
            (img.width(), img.height()),
            (width as u32, (frames * s) as u32)
        );
        assert!(img.height() as usize >= WT_MIN_HEIGHT);
        for py in 0..img.height() {
            let t = py as usize / s;
            for x in 0..width as u32 {
                let want = if x as usize == t {
                    [255, 0, 0]
                } else {
                    [0, 0, 0]
                };
                assert_eq!(img.get_pixel(x, py).0, want, "pixel ({x}, {py})");
            }
        }
        assert!(matches!(
            wt_slice(&v, 6),
            Err(DiagError::Row { row: 6, height: 6 })
        ));
        // Long videos are not upscaled.
        assert_eq!(wt_time_scale(200), 1);
    }

    #[test]
    fn temporal_spectrum_peaks_at_frequency() {
        let (frames, k) = (32, 5);
        let v = oscillating(frames, k, 0.4);
        let img = temporal_spectrum(&v, 1).unwrap();
        assert_eq!((img.width(), img.height()), (3, (frames / 2 + 1) as u32));
        // Column 1: the maximum (yellow) at row k only; constant columns are dark.
        let top = viridis(1.0);
        for row in 0..img.height() {
            let is_peak = *img.get_pixel(1, row) == top;
            assert_eq!(is_peak, row as usize == k, "row {row}");
            assert_eq!(*img.get_pixel(0, row), viridis(0.0));
        }
        let s = Spectrum::of_row(&v, 1).unwrap();
        let col: Vec<f64> = (0..s.bins).map(|b| s.values[b * s.width + 1]).collect();
        // |X_k| = amplitude * T / 2 for a cosine.
        assert!((col[k] - (0.4f64 * 16.0).ln_1p()).abs() < 1e-5);
        assert!(col.iter().enumerate().all(|(b, &m)| b == k || m < 1e-4));
        assert!(temporal_spectrum(&v, 2).is_err());
    }

    #[test]
    fn temporal_spectrum_pair_shares_scale() {
        let strong = oscillating(32, 3, 0.4);
        let weak = oscillating(32, 3, 0.05);
        let (a, b) = temporal_spectrum_pair(&strong, &weak, 0).unwrap();
        assert_eq!(*a.get_pixel(1, 3), viridis(1.0));
        let (alone, _) = temporal_spectrum_pair(&weak, &weak, 0).unwrap();
        assert_eq!(*alone.get_pixel(1, 3), viridis(1.0));
        assert_ne!(*b.get_pixel(1, 3), viridis(1.0));
    }

    #[test]
    fn busiest_row_finds_motion() {
        let v = video(
            8,
            6,
            5,
            |t, y, x, _| if y == 3 && x == t % 5 { 1.0 } else { 0.0 },
        );
        assert_eq!(busiest_row(&v), 3);
        assert_eq!(busiest_row(&video(4, 6, 5, |_, _, _, _| 0.5)), 3);
    }

    #[test]
    fn png_frames_round_trip() {
        let tmp = TempDir::new("png");
        let v = video(2, 3, 4, |t, y, x, c| (t + y + x + c) as f32 / 10.0 - 0.1);
        let paths = write_png_frames(&tmp.0, &v, "f").unwrap();
        assert_eq!(
            paths,
            vec![tmp.0.join("f_0000.png"), tmp.0.join("f_0001.png")]
        );
        let img = image::open(&paths[1]).unwrap().to_rgb8();
        assert_eq!((img.width(), img.height()), (4, 3));
        for (x, y, px) in img.enumerate_pixels() {
            for c in 0..3 {
                assert_eq!(px[c], to_u8(v.at(1, y as usize, x as usize, c)));
            }
        }
    }

    #[test]
    fn gif_loops_all_frames() {
        let tmp = TempDir::new("gif");
        let path = tmp.0.join("sub/a.gif");
        let v = moving_bar(5, 4, 6);
        write_gif(&path, &v, 10.0).unwrap();
        let file = std::io::BufReader::new(std::fs::File::open(&path).unwrap());
        let frames = image::codecs::gif::GifDecoder::new(file)
            .unwrap()
            .into_frames()
            .collect_frames()
            .unwrap();
        assert_eq!(frames.len(), 5);
        assert_eq!(frames[0].delay().numer_denom_ms(), (100, 1));
        assert!(matches!(write_gif(&path, &v, 0.0), Err(DiagError::Fps(_))));
    }

    #[test]
    fn loss_curve_png_is_valid_png_with_text() {
        let tmp = TempDir::new("loss");
        let decay: Vec<(f64, f64)> = (0..200)
            .map(|i| (i as f64, (-0.03 * i as f64).exp()))
            .collect();
        let slow: Vec<(f64, f64)> = (0..200)
            .map(|i| (i as f64, 0.5 / (1.0 + i as f64)))
            .collect();
        let path = tmp.0.join("loss.png");
        loss_curve_png(&path, "Fit loss", &[("total", decay.clone()), ("l1", slow)]).unwrap();
        let img = image::open(&path).unwrap().to_rgb8();
        assert_eq!((img.width(), img.height()), LOSS_CURVE_SIZE);
        // The title band above the plot holds dark text pixels.
        let dark = (0..img.width())
            .flat_map(|x| (0..40).map(move |y| (x, y)))
            .filter(|&(x, y)| img.get_pixel(x, y).0.iter().all(|&c| c < 100))
            .count();
        assert!(dark > 50, "no title text drawn ({dark} dark pixels)");

        // Non-positive values: linear axis; non-finite points skipped.
        let signed = vec![(0.0, -1.0), (1.0, f64::NAN), (2.0, 0.5)];
        let lin = tmp.0.join("lin.png");
        loss_curve_png(&lin, "signed", &[("x", signed)]).unwrap();
        assert!(image::open(&lin).is_ok());
        let err = loss_curve_png(&lin, "empty", &[("x", vec![(0.0, f64::NAN)])]);
        assert!(matches!(err, Err(DiagError::Plot { .. })));
    }

    #[test]
    fn tick_labels_are_short() {
        assert_eq!(linear_tick_label(-2.2e-16, 2.2), "0");
        assert_eq!(linear_tick_label(0.4, 2.2), "0.4");
        assert_eq!(linear_tick_label(250.0, 300.0), "250");
        assert_eq!(linear_tick_label(1.00002, 1e-4), "1.00002");
        assert_eq!(linear_tick_label(1.5e-5, 2e-5), "1.5e-5");
        assert_eq!(log_tick_label(0.01), "0.01");
        assert_eq!(log_tick_label(1e-5), "1e-5");
        assert_eq!(log_tick_label(2e6), "2e6");
    }

    #[test]
    fn fit_diagnostics_writes_every_file() {
        let tmp = TempDir::new("fit");
        let reference = moving_bar(6, 5, 8);
        let fitted = video(
            6,
            5,
            8,
            |t, _, x, c| {
                if x == t + 1 && c == 0 {
                    0.8
                } else {
                    0.0
                }
            },
        );
        let files = write_fit_diagnostics(&tmp.0, &reference, &fitted, None, 12.0).unwrap();
        assert_eq!(files.row, 0);
        assert_eq!(files.fitted_frames.len(), 6);
        assert_eq!(files.side_by_side_frames.len(), 6);
        assert_eq!(files.fitted_frames[5], tmp.0.join("fitted/frame_0005.png"));
        let sbs = image::open(&files.side_by_side_frames[0]).unwrap();
        assert_eq!((sbs.width(), sbs.height()), (8 + 4 + 8, 5));
        let singles = [
            &files.fitted_gif,
            &files.side_by_side_gif,
            &files.wt_reference,
            &files.wt_fitted,
            &files.spectrum_reference,
            &files.spectrum_fitted,
        ];
        let all = files.fitted_frames.iter().chain(&files.side_by_side_frames);
        for p in all.chain(singles) {
            assert!(p.starts_with(&tmp.0), "{}", p.display());
            assert!(image::open(p).is_ok(), "{} unreadable", p.display());
        }
        for (p, frames) in [(&files.fitted_mp4, 6), (&files.side_by_side_mp4, 6)] {
            assert!(p.starts_with(&tmp.0), "{}", p.display());
            assert_eq!(r4d_video::probe(p).unwrap().frames, frames);
        }
        let spec = image::open(&files.spectrum_fitted).unwrap();
        // 4 frequency bins, each stretched to ceil(128 / 4) rows.
        assert_eq!(
            (spec.width(), spec.height()),
            (8, 4 * wt_time_scale(4) as u32)
        );

        let bad = write_fit_diagnostics(&tmp.0, &reference, &fitted, Some(5), 12.0);
        assert!(matches!(bad, Err(DiagError::Row { row: 5, height: 5 })));
    }
}
