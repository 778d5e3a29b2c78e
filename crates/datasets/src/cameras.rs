//! Camera conventions of the datasets, converted to the renderer's (OpenCV axes, pixel centres
//! at `+0.5`, `p_cam = R p_world + t`).
//!
//! * **OpenGL camera-to-world** (NeRF/Blender `transform_matrix`, PAC-NeRF `c2w`): columns are
//!   the camera's x right, y up, z backwards. Negating columns 1 and 2 gives OpenCV axes (as
//!   PhysDreamer's loader does). PAC-NeRF's rays (DVGO `get_rays`, `inverse_y = False`) go
//!   through `((i + 0.5 - cx) / fx, -(j + 0.5 - cy) / fy, -1)`: with the flip that is the
//!   renderer's `u = fx x / z + cx` sampled at `i + 0.5`, so `cx`, `cy` are used unchanged.
//! * **COLMAP binary** (`sparse/0/cameras.bin`, `images.bin`): read here and handed to the text
//!   parser of `r4d-splat` ([`r4d_splat::camera_io::parse_colmap`]), so both forms share one
//!   interpretation (PINHOLE / SIMPLE_PINHOLE, distortion-free radial and OpenCV models).
//! * **Video size**: a camera whose image size differs from its video's is rescaled to the video
//!   when the aspect ratios agree within 1% (focal lengths and principal point scaled per axis);
//!   otherwise it is a typed error.

use crate::error::{DatasetError, Result};
use r4d_splat::Camera;
use std::path::Path;

/// A camera from an OpenGL camera-to-world matrix (3x4 or 4x4 rows) and pinhole intrinsics
/// `[fx, fy, cx, cy]` in pixels.
pub fn from_gl_c2w(
    name: impl Into<String>,
    width: u32,
    height: u32,
    k: [f64; 4],
    c2w: &[[f64; 4]],
) -> Camera {
    // Columns of the rotation are the camera axes in the world; OpenCV: (x, -y, -z).
    let mut rot = [[0.0; 3]; 3];
    for i in 0..3 {
        rot[i] = [c2w[i][0], -c2w[i][1], -c2w[i][2]];
    }
    let centre = [c2w[0][3], c2w[1][3], c2w[2][3]];
    Camera::from_pose(name, width, height, k, rot, centre)
}

/// Checks that the rotation block of a camera-to-world matrix is a proper rotation
/// (orthonormal within 1e-3, determinant +1).
pub fn check_rotation(c2w: &[[f64; 4]], path: &Path, ctx: &str) -> Result<()> {
    for i in 0..3 {
        for j in 0..3 {
            let d: f64 = (0..3).map(|k| c2w[k][i] * c2w[k][j]).sum();
            let want = if i == j { 1.0 } else { 0.0 };
            if (d - want).abs() >= 1e-3 || d.is_nan() {
                return Err(DatasetError::invalid(
                    path,
                    format!("{ctx}: the rotation block is not orthonormal (column {i} . column {j} = {d})"),
                ));
            }
        }
    }
    let r = |i: usize, j: usize| c2w[i][j];
    let det = r(0, 0) * (r(1, 1) * r(2, 2) - r(1, 2) * r(2, 1))
        - r(0, 1) * (r(1, 0) * r(2, 2) - r(1, 2) * r(2, 0))
        + r(0, 2) * (r(1, 0) * r(2, 1) - r(1, 1) * r(2, 0));
    if det < 0.0 {
        return Err(DatasetError::invalid(
            path,
            format!("{ctx}: the rotation block is a reflection (determinant {det:.3})"),
        ));
    }
    Ok(())
}

/// PhysFlow's image-size cap (`get_camera_view`: width and height at most 1920, the field of
/// view kept from `fx`, `fy`): the image is cropped about its centre.
pub fn cap_size(cam: &Camera, max: u32) -> Camera {
    let mut c = cam.clone();
    if c.width > max || c.height > max {
        let (w, h) = (c.width.min(max), c.height.min(max));
        c.cx -= 0.5 * (c.width - w) as f64;
        c.cy -= 0.5 * (c.height - h) as f64;
        c.width = w;
        c.height = h;
    }
    c
}

/// The camera rescaled to a video of `width` x `height` (see the module docs); `what` names the
/// video in errors.
pub fn fit_to_video(cam: &Camera, width: u32, height: u32, what: &Path) -> Result<Camera> {
    if cam.width == width && cam.height == height {
        return Ok(cam.clone());
    }
    let a_cam = cam.width as f64 / cam.height as f64;
    let a_vid = width as f64 / height as f64;
    if ((a_cam - a_vid) / a_cam).abs() > 0.01 {
        return Err(DatasetError::invalid(
            what,
            format!(
                "frames are {width}x{height} but camera '{}' is {}x{} (aspect ratios differ by more than 1%)",
                cam.name, cam.width, cam.height
            ),
        ));
    }
    let sx = width as f64 / cam.width as f64;
    let sy = height as f64 / cam.height as f64;
    let mut c = cam.clone();
    c.fx *= sx;
    c.cx *= sx;
    c.fy *= sy;
    c.cy *= sy;
    c.width = width;
    c.height = height;
    Ok(c)
}

struct Bin<'a> {
    b: &'a [u8],
    at: usize,
    path: &'a Path,
}

impl Bin<'_> {
    fn take(&mut self, n: usize) -> Result<&[u8]> {
        if self.b.len() - self.at < n {
            return Err(DatasetError::invalid(
                self.path,
                format!("truncated at byte {} (COLMAP binary)", self.at),
            ));
        }
        let s = &self.b[self.at..self.at + n];
        self.at += n;
        Ok(s)
    }
    fn u64(&mut self) -> Result<u64> {
        Ok(u64::from_le_bytes(
            self.take(8)?.try_into().expect("8 bytes"),
        ))
    }
    fn i32(&mut self) -> Result<i32> {
        Ok(i32::from_le_bytes(
            self.take(4)?.try_into().expect("4 bytes"),
        ))
    }
    fn f64(&mut self) -> Result<f64> {
        Ok(f64::from_le_bytes(
            self.take(8)?.try_into().expect("8 bytes"),
        ))
    }
    /// A count that the rest of the file can hold with `min_bytes` per item.
    fn count(&mut self, min_bytes: usize, what: &str) -> Result<usize> {
        let n = self.u64()?;
        let left = (self.b.len() - self.at) as u64;
        if n > left / min_bytes.max(1) as u64 {
            return Err(DatasetError::invalid(
                self.path,
                format!("{what} = {n} does not fit in the file's {left} remaining bytes"),
            ));
        }
        Ok(n as usize)
    }
}

const COLMAP_MODELS: &[(&str, usize)] = &[
    ("SIMPLE_PINHOLE", 3),
    ("PINHOLE", 4),
    ("SIMPLE_RADIAL", 4),
    ("RADIAL", 5),
    ("OPENCV", 8),
    ("OPENCV_FISHEYE", 8),
    ("FULL_OPENCV", 12),
    ("FOV", 5),
    ("SIMPLE_RADIAL_FISHEYE", 4),
    ("RADIAL_FISHEYE", 5),
    ("THIN_PRISM_FISHEYE", 12),
];

/// Converts COLMAP's `cameras.bin` and `images.bin` to the text forms (`cameras.txt`,
/// `images.txt` without 2D points).
pub fn colmap_bin_to_text(cameras: &Path, images: &Path) -> Result<(String, String)> {
    let read = |p: &Path| {
        r4d_fsio::read_bounded(p, r4d_fsio::MAX_BINARY_BYTES).map_err(|source| DatasetError::Io {
            path: p.to_path_buf(),
            source,
        })
    };
    colmap_bin_bytes_to_text(&read(cameras)?, cameras, &read(images)?, images)
}

/// [`colmap_bin_to_text`] on the files' bytes (`cameras` and `images` name them in errors).
pub fn colmap_bin_bytes_to_text(
    cb: &[u8],
    cameras: &Path,
    ib: &[u8],
    images: &Path,
) -> Result<(String, String)> {
    let mut r = Bin {
        b: cb,
        at: 0,
        path: cameras,
    };
    let n = r.count(24, "number of cameras")?;
    let mut ctext = String::new();
    for _ in 0..n {
        let id = r.i32()?;
        let model = r.i32()?;
        let w = r.u64()?;
        let h = r.u64()?;
        let &(name, np) = usize::try_from(model)
            .ok()
            .and_then(|m| COLMAP_MODELS.get(m))
            .ok_or_else(|| {
                DatasetError::invalid(cameras, format!("camera {id}: unknown model id {model}"))
            })?;
        let mut line = format!("{id} {name} {w} {h}");
        for _ in 0..np {
            line.push_str(&format!(" {:?}", r.f64()?));
        }
        ctext.push_str(&line);
        ctext.push('\n');
    }
    let mut r = Bin {
        b: ib,
        at: 0,
        path: images,
    };
    let n = r.count(4 + 56 + 4 + 1 + 8, "number of images")?;
    let mut itext = String::new();
    for _ in 0..n {
        let id = r.i32()?;
        let q = [r.f64()?, r.f64()?, r.f64()?, r.f64()?];
        let t = [r.f64()?, r.f64()?, r.f64()?];
        let cam = r.i32()?;
        let start = r.at;
        let len = r.b[start..].iter().position(|&c| c == 0).ok_or_else(|| {
            DatasetError::invalid(images, format!("image {id}: unterminated name"))
        })?;
        let name = String::from_utf8(r.take(len)?.to_vec())
            .map_err(|_| DatasetError::invalid(images, format!("image {id}: name is not UTF-8")))?;
        r.take(1)?;
        if name.trim().is_empty() || name.contains('\n') {
            return Err(DatasetError::invalid(
                images,
                format!("image {id}: bad name {name:?}"),
            ));
        }
        let np = r.count(24, "number of 2D points")?;
        r.take(np * 24)?;
        itext.push_str(&format!(
            "{id} {:?} {:?} {:?} {:?} {:?} {:?} {:?} {cam} {name}\n\n",
            q[0], q[1], q[2], q[3], t[0], t[1], t[2]
        ));
    }
    Ok((ctext, itext))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gl_camera_sees_the_point_it_looks_at() {
        // Camera at z = 4 looking down -z (OpenGL: identity rotation).
        let c2w = [
            [1.0, 0.0, 0.0, 0.0],
            [0.0, 1.0, 0.0, 0.0],
            [0.0, 0.0, 1.0, 4.0],
        ];
        let cam = from_gl_c2w("c", 100, 80, [50.0, 50.0, 50.0, 40.0], &c2w);
        let project = |p: [f64; 3]| {
            let r = cam.rotation();
            let t = cam.translation();
            let q: [f64; 3] =
                [0, 1, 2].map(|i| r[i][0] * p[0] + r[i][1] * p[1] + r[i][2] * p[2] + t[i]);
            (
                cam.fx * q[0] / q[2] + cam.cx,
                cam.fy * q[1] / q[2] + cam.cy,
                q[2],
            )
        };
        let (u, v, z) = project([0.0, 0.0, 0.0]);
        assert!((u - 50.0).abs() < 1e-12 && (v - 40.0).abs() < 1e-12 && (z - 4.0).abs() < 1e-12);
        // World +y (up) appears higher in the image (smaller v), +x to the right.
        let (u, v, _) = project([1.0, 1.0, 0.0]);
        assert!(u > 50.0 && v < 40.0, "{u} {v}");
    }

    #[test]
    fn rescale_and_cap() {
        let cam = from_gl_c2w(
            "c",
            2000,
            1000,
            [1000.0, 1000.0, 1000.0, 500.0],
            &[
                [1.0, 0.0, 0.0, 0.0],
                [0.0, 1.0, 0.0, 0.0],
                [0.0, 0.0, 1.0, 4.0],
            ],
        );
        let c = cap_size(&cam, 1920);
        assert_eq!((c.width, c.height, c.fx), (1920, 1000, 1000.0));
        assert_eq!(c.cx, 960.0);
        let v = fit_to_video(&cam, 1000, 500, Path::new("v")).unwrap();
        assert_eq!((v.fx, v.cx, v.fy, v.cy), (500.0, 500.0, 500.0, 250.0));
        let e = fit_to_video(&cam, 1000, 1000, Path::new("v.mp4"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("v.mp4") && e.contains("aspect"), "{e}");
    }
}
