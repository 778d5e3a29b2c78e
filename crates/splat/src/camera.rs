//! Pinhole cameras (OpenCV convention) and render settings, with gsplat's conventions:
//! `p_cam = R p_world + t`, `u = fx x / z + cx`, `v = fy y / z + cy`, pixel `(i, j)` sampled at
//! its centre `(i + 0.5, j + 0.5)`, +x right, +y down, +z forward.

use serde::{Deserialize, Serialize};

/// The most pixels a camera may have (8192 x 8192): a larger image is refused when the camera
/// is read, before anything is allocated for it.
pub const MAX_CAMERA_PIXELS: u64 = 1 << 26;

/// A pinhole camera without distortion.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Camera {
    /// Name (image name or label).
    #[serde(default)]
    pub name: String,
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
    /// Focal length along x, pixels.
    pub fx: f64,
    /// Focal length along y, pixels.
    pub fy: f64,
    /// Principal point x, pixels.
    pub cx: f64,
    /// Principal point y, pixels.
    pub cy: f64,
    /// World-to-camera 4x4 matrix, row by row (`M[row][col]`, last row `0 0 0 1`).
    pub world_to_camera: [[f64; 4]; 4],
    /// Near plane: Gaussians with camera depth `z <= near` are dropped.
    #[serde(default = "default_near")]
    pub near: f64,
    /// Far plane: Gaussians with `z >= far` are dropped.
    #[serde(default = "default_far")]
    pub far: f64,
    /// When this camera renders a horizontal band of a taller image ([`Camera::crop_rows`]):
    /// where the band lies. The projection's frustum clamp then uses the full image, so every
    /// pixel of the band equals the full image's pixel up to rounding (for bands starting on a
    /// tile row).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub crop: Option<RowCrop>,
}

/// Rows `row0 .. row0 + height` of an image of `full_height` rows (see [`Camera::crop`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct RowCrop {
    /// First row of the band in the full image.
    pub row0: u32,
    /// Rows of the full image.
    pub full_height: u32,
}

fn default_near() -> f64 {
    0.01
}
fn default_far() -> f64 {
    1e10
}

impl Camera {
    /// The rotation block of `world_to_camera`.
    pub fn rotation(&self) -> [[f64; 3]; 3] {
        let m = &self.world_to_camera;
        [0, 1, 2].map(|i| [m[i][0], m[i][1], m[i][2]])
    }

    /// The translation column of `world_to_camera`.
    pub fn translation(&self) -> [f64; 3] {
        let m = &self.world_to_camera;
        [m[0][3], m[1][3], m[2][3]]
    }

    /// The camera centre in world coordinates: `-R^T t`.
    pub fn position(&self) -> [f64; 3] {
        let r = self.rotation();
        let t = self.translation();
        [0, 1, 2].map(|j| -(r[0][j] * t[0] + r[1][j] * t[1] + r[2][j] * t[2]))
    }

    /// Builds a camera from a camera-to-world rotation (columns = camera axes in the world)
    /// and the camera centre.
    pub fn from_pose(
        name: impl Into<String>,
        width: u32,
        height: u32,
        [fx, fy, cx, cy]: [f64; 4],
        cam_to_world_rot: [[f64; 3]; 3],
        centre: [f64; 3],
    ) -> Self {
        let r = cam_to_world_rot;
        let mut m = [[0.0; 4]; 4];
        for i in 0..3 {
            for j in 0..3 {
                m[i][j] = r[j][i];
            }
            m[i][3] = -(r[0][i] * centre[0] + r[1][i] * centre[1] + r[2][i] * centre[2]);
        }
        m[3][3] = 1.0;
        Camera {
            name: name.into(),
            width,
            height,
            fx,
            fy,
            cx,
            cy,
            world_to_camera: m,
            near: default_near(),
            far: default_far(),
            crop: None,
        }
    }

    /// The camera rendering only rows `rows` of this camera's image: same pose and focal
    /// lengths, principal point moved up by `rows.start`, height `rows.len()`; the frustum
    /// clamp of the projection stays that of the full image ([`Camera::crop`]). A band starting
    /// on a multiple of the tile size (16) renders the full image's rows up to rounding.
    pub fn crop_rows(&self, rows: std::ops::Range<u32>) -> Camera {
        let base = self.crop.unwrap_or(RowCrop {
            row0: 0,
            full_height: self.height,
        });
        assert!(
            rows.start < rows.end && rows.end <= self.height,
            "rows {rows:?} of a {}-row image",
            self.height
        );
        Camera {
            height: rows.end - rows.start,
            cy: self.cy - rows.start as f64,
            crop: Some(RowCrop {
                row0: base.row0 + rows.start,
                full_height: base.full_height,
            }),
            ..self.clone()
        }
    }

    /// Height and principal point `cy` of the full image (this camera's own unless cropped).
    pub fn full_frame_y(&self) -> (u32, f64) {
        match self.crop {
            Some(c) => (c.full_height, self.cy + c.row0 as f64),
            None => (self.height, self.cy),
        }
    }

    /// A camera at `eye` looking at `target`, image `up` direction approximately `up`.
    pub fn look_at(
        width: u32,
        height: u32,
        fov_x_deg: f64,
        eye: [f64; 3],
        target: [f64; 3],
        up: [f64; 3],
    ) -> Self {
        let sub = |a: [f64; 3], b: [f64; 3]| [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
        let cross = |a: [f64; 3], b: [f64; 3]| {
            [
                a[1] * b[2] - a[2] * b[1],
                a[2] * b[0] - a[0] * b[2],
                a[0] * b[1] - a[1] * b[0],
            ]
        };
        let norm = |a: [f64; 3]| {
            let l = (a[0] * a[0] + a[1] * a[1] + a[2] * a[2]).sqrt().max(1e-300);
            [a[0] / l, a[1] / l, a[2] / l]
        };
        let z = norm(sub(target, eye));
        let x = norm(cross(z, up));
        let y = cross(z, x);
        let rot = [0, 1, 2].map(|i| [x[i], y[i], z[i]]);
        let fx = 0.5 * width as f64 / (0.5 * fov_x_deg.to_radians()).tan();
        Camera::from_pose(
            "look_at",
            width,
            height,
            [fx, fx, width as f64 / 2.0, height as f64 / 2.0],
            rot,
            eye,
        )
    }

    /// Checks sizes, intrinsics and the pose; `what` names the source.
    pub fn validate(&self, what: &str) -> Result<(), String> {
        let name = &self.name;
        if self.width == 0 || self.height == 0 || self.width > 1 << 15 || self.height > 1 << 15 {
            return Err(format!(
                "{what}: camera '{name}': image size {}x{} (1..=32768)",
                self.width, self.height
            ));
        }
        let pixels = self.width as u64 * self.height as u64;
        if pixels > MAX_CAMERA_PIXELS {
            return Err(format!(
                "{what}: camera '{name}': image size {}x{} is {pixels} pixels; the limit is {MAX_CAMERA_PIXELS} (8192 x 8192: one f32 RGB frame of it is 805 MB, and a render holds several such buffers)",
                self.width, self.height
            ));
        }
        for (field, v) in [
            ("fx", self.fx),
            ("fy", self.fy),
            ("cx", self.cx),
            ("cy", self.cy),
        ] {
            if !v.is_finite() || ((field == "fx" || field == "fy") && v <= 0.0) {
                return Err(format!("{what}: camera '{name}': {field} = {v}"));
            }
        }
        if self
            .world_to_camera
            .iter()
            .flatten()
            .any(|v| !v.is_finite())
        {
            return Err(format!(
                "{what}: camera '{name}': world_to_camera is not finite"
            ));
        }
        let r = self.rotation();
        for i in 0..3 {
            for j in 0..3 {
                let d: f64 = (0..3).map(|k| r[i][k] * r[j][k]).sum();
                let want = if i == j { 1.0 } else { 0.0 };
                if (d - want).abs() > 1e-4 {
                    return Err(format!(
                        "{what}: camera '{name}': world_to_camera rotation is not orthonormal"
                    ));
                }
            }
        }
        let det = r[0][0] * (r[1][1] * r[2][2] - r[1][2] * r[2][1])
            - r[0][1] * (r[1][0] * r[2][2] - r[1][2] * r[2][0])
            + r[0][2] * (r[1][0] * r[2][1] - r[1][1] * r[2][0]);
        if det < 0.0 {
            return Err(format!(
                "{what}: camera '{name}': world_to_camera rotation has determinant {det:.3}: a mirror, not a rotation (a camera pose must be proper, det +1)"
            ));
        }
        if !(self.near > 0.0 && self.far > self.near) {
            return Err(format!(
                "{what}: camera '{name}': near {} / far {}",
                self.near, self.far
            ));
        }
        if let Some(c) = self.crop {
            if c.row0 as u64 + self.height as u64 > c.full_height as u64 {
                return Err(format!(
                    "{what}: camera '{name}': crop rows {}..{} of a {}-row image",
                    c.row0,
                    c.row0 + self.height,
                    c.full_height
                ));
            }
        }
        Ok(())
    }
}

/// gsplat's rasterize modes.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum RasterizeMode {
    /// Opacity as given.
    #[default]
    Classic,
    /// Opacity scaled by `sqrt(det(Sigma_2d) / det(Sigma_2d + 0.3 I))` (Mip-Splatting's
    /// compensation of the low-pass).
    Antialiased,
}

/// Settings of a render besides the camera.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RenderSettings {
    /// Background colour (added as `T_final * background`).
    pub background: [f32; 3],
    /// Rasterize mode.
    pub mode: RasterizeMode,
}

impl RenderSettings {
    /// Checks the settings: the background colour is three values in `[0, 1]` (an image's
    /// range; anything else would flow into the raw output and the loss). `what` names the
    /// source (a file, a flag) in the message.
    pub fn validate(&self, what: &str) -> Result<(), String> {
        if let Some(v) = self
            .background
            .iter()
            .find(|v| !(v.is_finite() && (0.0..=1.0).contains(*v)))
        {
            return Err(format!(
                "{what}: background {:?} has {v}: each of r, g, b must be in [0, 1]",
                self.background
            ));
        }
        Ok(())
    }
}

impl Default for RenderSettings {
    fn default() -> Self {
        RenderSettings {
            background: [0.0; 3],
            mode: RasterizeMode::Classic,
        }
    }
}

/// The fixed constants of the pipeline (gsplat's values).
pub mod consts {
    /// Low-pass added to the diagonal of the 2D covariance (pixels^2).
    pub const EPS2D: f64 = 0.3;
    /// Alpha cap.
    pub const ALPHA_MAX: f64 = 0.999;
    /// Alpha below which a Gaussian is skipped at a pixel.
    pub const ALPHA_MIN: f64 = 1.0 / 255.0;
    /// Transmittance at or below which compositing stops (exclusively).
    pub const T_MIN: f64 = 1e-4;
    /// Screen-space radius in standard deviations.
    pub const RADIUS_SIGMAS: f64 = 3.33;
    /// Tile edge in pixels.
    pub const TILE: u32 = 16;
}

#[cfg(test)]
mod limit_tests {
    use super::*;

    /// A camera too large to render in memory and a mirrored pose are refused when
    /// the camera is checked, with the camera's name and the limit in the message.
    #[test]
    fn huge_images_and_mirror_poses_are_refused() {
        let mut c = Camera::look_at(
            64,
            48,
            60.0,
            [0.0, -3.0, 0.5],
            [0.0, 0.0, 0.5],
            [0.0, 0.0, 1.0],
        );
        c.name = "front".into();
        c.validate("t").unwrap();
        let mut big = c.clone();
        big.width = 32768;
        big.height = 32768;
        let e = big.validate("t").unwrap_err();
        assert!(
            e.contains("front") && e.contains(&MAX_CAMERA_PIXELS.to_string()),
            "{e}"
        );
        // A reflection: negate one row of R (and of t).
        for j in 0..4 {
            c.world_to_camera[0][j] = -c.world_to_camera[0][j];
        }
        let e = c.validate("t").unwrap_err();
        assert!(e.contains("mirror"), "{e}");
    }

    /// A background outside [0, 1] is refused where it is read (it used to flow into the raw
    /// output).
    #[test]
    fn backgrounds_outside_the_unit_range_are_refused() {
        let s = RenderSettings {
            background: [0.2, 1.5, 0.0],
            ..Default::default()
        };
        assert!(s.validate("--background").unwrap_err().contains("1.5"));
        RenderSettings::default().validate("t").unwrap();
        let e = crate::camera_io::parse_camera_json(
            r#"{"cameras": [], "background": [2, 0, 0]}"#,
            "c.json",
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("c.json") && e.contains("background"), "{e}");
    }
}
