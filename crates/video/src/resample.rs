//! Frame-rate conversion: the nearest source frame in time, as ffmpeg's `fps` filter does
//! (no blending, so every output frame is a frame that was captured or rendered).

use r4d_frames::{Real, Video};

/// The source frame shown at each output frame when `n` frames at `from` fps are played at
/// `to` fps: output frame `k` (time `k / to`) shows source frame `round(k * from / to)`.
/// The output covers the source's duration: `floor((n - 1) * to / from) + 1` frames.
/// `None` when `n` is 0, a rate is not positive and finite, or the output would exceed
/// [`MAX_FRAMES`].
pub fn resample_indices(n: usize, from: f64, to: f64) -> Option<Vec<usize>> {
    if n == 0 || !(from.is_finite() && to.is_finite() && from > 0.0 && to > 0.0) {
        return None;
    }
    let ratio = from / to;
    // (n - 1) * to / from, with a small tolerance against rounding.
    let m = ((n - 1) as f64 / ratio + 1e-9).floor() + 1.0;
    if m.is_nan() || m > MAX_FRAMES as f64 {
        return None;
    }
    Some(
        (0..m as usize)
            .map(|k| ((k as f64 * ratio).round() as usize).min(n - 1))
            .collect(),
    )
}

/// The most frames a conversion produces.
pub const MAX_FRAMES: usize = 1_000_000;

/// `video` (at `from` fps) played at `to` fps (see [`resample_indices`]); `None` where that
/// gives `None`.
pub fn resample<T: Real>(video: &Video<T>, from: f64, to: f64) -> Option<Video<T>> {
    let idx = resample_indices(video.frames(), from, to)?;
    let (h, w) = (video.height(), video.width());
    let mut data = Vec::with_capacity(idx.len() * video.frame_len());
    for &i in &idx {
        data.extend_from_slice(video.frame(i));
    }
    Some(Video::new(idx.len(), h, w, data).expect("frames copied whole"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rates() {
        // Same rate: identity.
        assert_eq!(resample_indices(4, 30.0, 30.0).unwrap(), vec![0, 1, 2, 3]);
        // 60 -> 30: every other frame.
        assert_eq!(resample_indices(7, 60.0, 30.0).unwrap(), vec![0, 2, 4, 6]);
        // 25 -> 30 over 1 s (26 frames incl. t = 1 s): 31 frames, the nearest in time.
        let r = resample_indices(26, 25.0, 30.0).unwrap();
        assert_eq!(r.len(), 31);
        assert_eq!(&r[..7], &[0, 1, 2, 3, 3, 4, 5]);
        assert_eq!(*r.last().unwrap(), 25);
        // Nonsense rates give nothing rather than a huge allocation.
        assert!(resample_indices(5, 0.0, 30.0).is_none());
        assert!(resample_indices(5, 30.0, f64::NAN).is_none());
        assert!(resample_indices(5, 1e-300, 30.0).is_none());
    }

    #[test]
    fn resampled_video_copies_frames() {
        let v = Video::<f32>::from_frames(1, 1, (0..4).map(|t| vec![t as f32; 3])).unwrap();
        let r = resample(&v, 30.0, 15.0).unwrap();
        assert_eq!(r.frames(), 2);
        assert_eq!(r.frame(1), &[2.0; 3]);
    }
}
