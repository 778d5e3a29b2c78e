//! Reference videos of a dataset: where the frames are, how many, their size and frame rate.
//! Frames are read only when the fit asks ([`VideoSource::read`]).

use crate::error::{DatasetError, Result};
use r4d_loss::bands::ReferenceVideo;
use r4d_loss::Video;
use std::path::{Path, PathBuf};

/// One reference video.
#[derive(Clone, Debug, PartialEq)]
pub struct VideoSource {
    /// The video file or frame folder.
    pub path: PathBuf,
    /// Its frames (image files, in order); empty for a container file.
    pub files: Vec<PathBuf>,
    /// Number of frames.
    pub frames: usize,
    /// Frames per second.
    pub fps: f64,
    /// Frame width (pixels).
    pub width: u32,
    /// Frame height (pixels).
    pub height: u32,
}

/// Whether a file name has one of the image extensions frames may have.
pub fn is_frame_file(p: &Path) -> bool {
    p.extension().is_some_and(|e| {
        let e = e.to_ascii_lowercase();
        e == "png" || e == "jpg" || e == "jpeg"
    })
}

/// The image files of a folder (PNG or JPEG), in natural order (`frame_2` before
/// `frame_10`) with their numbering checked: a gap or a number written twice is an error
/// naming the number ([`r4d_fsio::seq::frame_sequence`]).
pub fn frame_files(dir: &Path) -> Result<Vec<PathBuf>> {
    let rd = std::fs::read_dir(dir).map_err(|source| DatasetError::Io {
        path: dir.to_path_buf(),
        source,
    })?;
    let files: Vec<PathBuf> = rd
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.is_file() && is_frame_file(p))
        .collect();
    r4d_fsio::seq::frame_sequence(files)
        .map_err(|e| DatasetError::Video(r4d_loss::io::VideoIoError::Sequence(e)))
}

/// PhysFlow's key-frame rule (`CogVideoGuidance`): of `n` sorted files keep those whose index
/// `i` has `i % (n / key_frames) == 0` (so possibly one more than `key_frames`).
pub fn key_frame_indices(n: usize, key_frames: usize) -> Vec<usize> {
    let per = (n / key_frames.max(1)).max(1);
    (0..n).filter(|i| i % per == 0).collect()
}

/// An image file's width and height, from its header.
pub fn image_size(path: &Path) -> Result<(u32, u32)> {
    image::image_dimensions(path)
        .map_err(|e| DatasetError::invalid(path, format!("not a readable image: {e}")))
}

fn check_fps(path: &Path, fps: f64) -> Result<()> {
    if !(fps.is_finite() && fps > 0.0) {
        return Err(DatasetError::invalid(
            path,
            format!("frame rate {fps} must be > 0"),
        ));
    }
    Ok(())
}

impl VideoSource {
    /// A video made of image files at `fps`; reads the first frame's header for the size.
    pub fn from_frames(path: &Path, files: Vec<PathBuf>, fps: f64) -> Result<Self> {
        let first = files
            .first()
            .ok_or_else(|| DatasetError::missing(path, "image frames (.png or .jpg)"))?;
        let (width, height) = image_size(first)?;
        check_fps(path, fps)?;
        Ok(VideoSource {
            path: path.to_path_buf(),
            frames: files.len(),
            files,
            fps,
            width,
            height,
        })
    }

    /// An H.264 MP4 (`.mp4`, `.m4v`, `.mov`), at its own frame rate unless `fps` says
    /// otherwise; reads the header only.
    pub fn from_mp4(path: &Path, fps: Option<f64>) -> Result<Self> {
        let info = r4d_video::probe(path)?;
        let fps = fps.unwrap_or(info.fps);
        check_fps(path, fps)?;
        Ok(VideoSource {
            path: path.to_path_buf(),
            files: Vec::new(),
            frames: info.frames,
            fps,
            width: info.width,
            height: info.height,
        })
    }

    /// Whether the video is a container file (MP4) rather than image files.
    pub fn is_container(&self) -> bool {
        self.files.is_empty()
    }

    /// Decodes every frame (values `k / 255`, RGB).
    pub fn read(&self) -> Result<Video<f32>> {
        if self.is_container() {
            return Ok(r4d_video::read_mp4(&self.path, None)?);
        }
        Ok(r4d_loss::io::read_frames(&self.files, &self.path)?)
    }

    /// Decodes every frame into the fit's storage of a reference video (8-bit frames as
    /// bytes: a 1080p MP4 frame takes 6 MB, not 25).
    pub fn read_reference(&self) -> Result<ReferenceVideo> {
        if self.is_container() {
            return Ok(r4d_video::read_mp4_reference(&self.path, None)?);
        }
        Ok(ReferenceVideo::compact(self.read()?))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn physflow_key_frames() {
        assert_eq!(
            key_frame_indices(49, 8),
            vec![0, 6, 12, 18, 24, 30, 36, 42, 48]
        );
        assert_eq!(key_frame_indices(16, 8), vec![0, 2, 4, 6, 8, 10, 12, 14]);
        assert_eq!(key_frame_indices(5, 8), vec![0, 1, 2, 3, 4]);
    }
}
