//! Camera files. [`load_cameras`] detects the format:
//!
//! * **r4d / reference JSON** (`tests/fixtures/splat/*/cameras.json`): an object with `cameras`
//!   (each `name, width, height, fx, fy, cx, cy, world_to_camera` (4x4 row by row), optional
//!   `near`, `far`) and optional `background` and `rasterize_mode`.
//! * **INRIA `cameras.json`** (3DGS training output): an array of `{id, img_name, width,
//!   height, position, rotation, fx, fy}` with `rotation` the camera-to-world rotation row by
//!   row and `position` the centre; the principal point is the image centre.
//! * **nerfstudio / instant-ngp `transforms.json`**: an object with `frames` (each a
//!   `transform_matrix`, camera-to-world in the OpenGL convention +y up, +z backwards) and
//!   intrinsics `fl_x, fl_y, cx, cy, w, h` at the top or per frame (`camera_angle_x` is
//!   accepted for `fl_x`). Distortion coefficients other than 0 are refused.
//! * **COLMAP text**: a directory holding `cameras.txt` and `images.txt` (or the path of
//!   `images.txt`). Models `SIMPLE_PINHOLE`, `PINHOLE`, and the radial/OpenCV models with all
//!   distortion coefficients 0. Images are ordered by name.

use crate::camera::{Camera, RasterizeMode, RenderSettings};
use crate::error::{Error, Result};
use serde_json::Value;
use std::collections::HashMap;
use std::path::Path;

/// Cameras and the render settings a camera file may carry.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct CameraSet {
    /// The cameras in file order (COLMAP: by image name).
    pub cameras: Vec<Camera>,
    /// Background colour, when the file has one.
    pub background: Option<[f32; 3]>,
    /// Rasterize mode, when the file has one.
    pub mode: Option<RasterizeMode>,
}

fn cerr(file: &str, m: impl Into<String>) -> Error {
    Error::Camera {
        file: file.to_string(),
        message: m.into(),
    }
}

fn read_text(path: &Path) -> Result<String> {
    r4d_fsio::read_to_string_bounded(path, r4d_fsio::MAX_TEXT_BYTES).map_err(|source| Error::Io {
        path: path.to_path_buf(),
        source,
    })
}

/// Loads a camera file in any of the supported formats (see the module docs).
pub fn load_cameras(path: &Path) -> Result<CameraSet> {
    let file = path.display().to_string();
    let set = if path.is_dir() || path.extension().is_some_and(|e| e == "txt") {
        let dir = if path.is_dir() {
            path.to_path_buf()
        } else {
            path.parent().unwrap_or(Path::new(".")).to_path_buf()
        };
        let cams = read_text(&dir.join("cameras.txt"))?;
        let imgs = read_text(&dir.join("images.txt"))?;
        parse_colmap(&cams, &imgs, &dir.display().to_string())?
    } else {
        parse_camera_json(&read_text(path)?, &file)?
    };
    if set.cameras.is_empty() {
        return Err(cerr(&file, "no cameras"));
    }
    for c in &set.cameras {
        c.validate(&file).map_err(|m| cerr(&file, m))?;
    }
    Ok(set)
}

/// Parses a JSON camera file (r4d/reference, INRIA or nerfstudio; see the module docs).
pub fn parse_camera_json(text: &str, file: &str) -> Result<CameraSet> {
    let v: Value = serde_json::from_str(text).map_err(|e| cerr(file, format!("not JSON: {e}")))?;
    match &v {
        Value::Array(a) => parse_inria(a, file),
        Value::Object(o) if o.contains_key("cameras") => parse_r4d(&v, file),
        Value::Object(o) if o.contains_key("frames") => parse_nerfstudio(&v, file),
        _ => Err(cerr(
            file,
            "unknown camera format: expected an object with 'cameras' (r4d), an array \
             (INRIA cameras.json) or an object with 'frames' (nerfstudio transforms.json)",
        )),
    }
}

fn num(v: &Value, key: &str, file: &str, ctx: &str) -> Result<f64> {
    v.get(key)
        .and_then(Value::as_f64)
        .ok_or_else(|| cerr(file, format!("{ctx}: missing or non-numeric '{key}'")))
}

fn matrix<const R: usize, const C: usize>(
    v: &Value,
    key: &str,
    file: &str,
    ctx: &str,
) -> Result<[[f64; C]; R]> {
    let bad = || {
        cerr(
            file,
            format!("{ctx}: '{key}' must be a {R}x{C} array of numbers"),
        )
    };
    let rows = v.get(key).and_then(Value::as_array).ok_or_else(bad)?;
    if rows.len() != R {
        return Err(bad());
    }
    let mut m = [[0.0; C]; R];
    for (i, row) in rows.iter().enumerate() {
        let row = row.as_array().filter(|r| r.len() == C).ok_or_else(bad)?;
        for (j, x) in row.iter().enumerate() {
            m[i][j] = x.as_f64().ok_or_else(bad)?;
        }
    }
    Ok(m)
}

fn parse_r4d(v: &Value, file: &str) -> Result<CameraSet> {
    let background = match v.get("background") {
        None | Some(Value::Null) => None,
        Some(b) => {
            let a = b
                .as_array()
                .filter(|a| a.len() == 3)
                .and_then(|a| a.iter().map(Value::as_f64).collect::<Option<Vec<_>>>())
                .ok_or_else(|| cerr(file, "'background' must be [r, g, b]"))?;
            let b = [a[0] as f32, a[1] as f32, a[2] as f32];
            RenderSettings {
                background: b,
                ..Default::default()
            }
            .validate("'background'")
            .map_err(|m| cerr(file, m))?;
            Some(b)
        }
    };
    let mode = match v.get("rasterize_mode").and_then(Value::as_str) {
        None => None,
        Some("classic") => Some(RasterizeMode::Classic),
        Some("antialiased") => Some(RasterizeMode::Antialiased),
        Some(m) => {
            return Err(cerr(
                file,
                format!("rasterize_mode '{m}': expected 'classic' or 'antialiased'"),
            ))
        }
    };
    let list = v["cameras"]
        .as_array()
        .ok_or_else(|| cerr(file, "'cameras' must be an array"))?;
    let mut cameras = Vec::with_capacity(list.len());
    for (i, c) in list.iter().enumerate() {
        let ctx = format!("cameras[{i}]");
        let size = |k: &str| -> Result<u32> {
            let x = num(c, k, file, &ctx)?;
            if (1.0..=32768.0).contains(&x) && x.fract() == 0.0 {
                Ok(x as u32)
            } else {
                Err(cerr(
                    file,
                    format!("{ctx}: '{k}' = {x} (a whole number 1..=32768)"),
                ))
            }
        };
        cameras.push(Camera {
            name: c
                .get("name")
                .and_then(Value::as_str)
                .map_or_else(|| format!("cam{i}"), str::to_string),
            width: size("width")?,
            height: size("height")?,
            fx: num(c, "fx", file, &ctx)?,
            fy: num(c, "fy", file, &ctx)?,
            cx: num(c, "cx", file, &ctx)?,
            cy: num(c, "cy", file, &ctx)?,
            world_to_camera: matrix::<4, 4>(c, "world_to_camera", file, &ctx)?,
            crop: None,
            near: c.get("near").and_then(Value::as_f64).unwrap_or(0.01),
            far: c.get("far").and_then(Value::as_f64).unwrap_or(1e10),
        });
    }
    Ok(CameraSet {
        cameras,
        background,
        mode,
    })
}

fn parse_inria(a: &[Value], file: &str) -> Result<CameraSet> {
    let mut cameras = Vec::with_capacity(a.len());
    for (i, c) in a.iter().enumerate() {
        let ctx = format!("camera {i}");
        let w = num(c, "width", file, &ctx)?;
        let h = num(c, "height", file, &ctx)?;
        if !(w >= 1.0 && h >= 1.0 && w <= 32768.0 && h <= 32768.0) {
            return Err(cerr(file, format!("{ctx}: image size {w}x{h}")));
        }
        let pos = c
            .get("position")
            .and_then(Value::as_array)
            .filter(|p| p.len() == 3)
            .and_then(|p| p.iter().map(Value::as_f64).collect::<Option<Vec<_>>>())
            .ok_or_else(|| cerr(file, format!("{ctx}: 'position' must be [x, y, z]")))?;
        let rot = matrix::<3, 3>(c, "rotation", file, &ctx)?;
        let name = c
            .get("img_name")
            .and_then(Value::as_str)
            .map_or_else(|| format!("cam{i}"), str::to_string);
        cameras.push(Camera::from_pose(
            name,
            w as u32,
            h as u32,
            [
                num(c, "fx", file, &ctx)?,
                num(c, "fy", file, &ctx)?,
                w / 2.0,
                h / 2.0,
            ],
            rot,
            [pos[0], pos[1], pos[2]],
        ));
    }
    Ok(CameraSet {
        cameras,
        ..Default::default()
    })
}

fn parse_nerfstudio(v: &Value, file: &str) -> Result<CameraSet> {
    let frames = v["frames"]
        .as_array()
        .ok_or_else(|| cerr(file, "'frames' must be an array"))?;
    let mut cameras = Vec::with_capacity(frames.len());
    for (i, f) in frames.iter().enumerate() {
        let ctx = format!("frames[{i}]");
        // Per-frame intrinsics override the top-level ones.
        let get = |k: &str| f.get(k).or_else(|| v.get(k)).and_then(Value::as_f64);
        for k in ["k1", "k2", "k3", "k4", "p1", "p2"] {
            if get(k).is_some_and(|x| x != 0.0) {
                return Err(cerr(
                    file,
                    format!("{ctx}: distortion '{k}' is not 0; undistort the images first"),
                ));
            }
        }
        let w = get("w").ok_or_else(|| cerr(file, format!("{ctx}: missing 'w'")))?;
        let h = get("h").ok_or_else(|| cerr(file, format!("{ctx}: missing 'h'")))?;
        if !(w >= 1.0 && h >= 1.0 && w <= 32768.0 && h <= 32768.0) {
            return Err(cerr(file, format!("{ctx}: image size {w}x{h}")));
        }
        let fx = match get("fl_x") {
            Some(f) => f,
            None => {
                let ax = get("camera_angle_x").ok_or_else(|| {
                    cerr(file, format!("{ctx}: missing 'fl_x' (or 'camera_angle_x')"))
                })?;
                0.5 * w / (0.5 * ax).tan()
            }
        };
        let fy = get("fl_y").unwrap_or(fx);
        let cx = get("cx").unwrap_or(w / 2.0);
        let cy = get("cy").unwrap_or(h / 2.0);
        let m = matrix::<4, 4>(f, "transform_matrix", file, &ctx)?;
        // OpenGL camera axes (+y up, +z back) -> OpenCV (+y down, +z forward).
        let rot = [0, 1, 2].map(|r| [m[r][0], -m[r][1], -m[r][2]]);
        let name = f
            .get("file_path")
            .and_then(Value::as_str)
            .map_or_else(|| format!("frame{i}"), str::to_string);
        cameras.push(Camera::from_pose(
            name,
            w as u32,
            h as u32,
            [fx, fy, cx, cy],
            rot,
            [m[0][3], m[1][3], m[2][3]],
        ));
    }
    Ok(CameraSet {
        cameras,
        ..Default::default()
    })
}

/// A POINTS2D line of COLMAP's `images.txt`: empty, or numbers in triples (an image line ends
/// with its name and has 10 or more fields, not a multiple of 3 numbers).
fn is_points_line(line: &str) -> bool {
    let t: Vec<&str> = line.split_whitespace().collect();
    t.len() % 3 == 0 && t.iter().all(|s| s.parse::<f64>().is_ok())
}

/// Parses COLMAP's `cameras.txt` and `images.txt`; `what` names the source in errors.
pub fn parse_colmap(cameras_txt: &str, images_txt: &str, what: &str) -> Result<CameraSet> {
    let file_c = format!("{what}/cameras.txt");
    let file_i = format!("{what}/images.txt");
    let mut intr: HashMap<u64, (u32, u32, [f64; 4])> = HashMap::new();
    for (ln, line) in cameras_txt.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let t: Vec<&str> = line.split_whitespace().collect();
        let bad = |m: &str| cerr(&file_c, format!("line {}: {m}", ln + 1));
        if t.len() < 5 {
            return Err(bad("expected CAMERA_ID MODEL WIDTH HEIGHT PARAMS[]"));
        }
        let id: u64 = t[0].parse().map_err(|_| bad("bad CAMERA_ID"))?;
        let w: u32 = t[2].parse().map_err(|_| bad("bad WIDTH"))?;
        let h: u32 = t[3].parse().map_err(|_| bad("bad HEIGHT"))?;
        let p: Vec<f64> = t[4..]
            .iter()
            .map(|s| s.parse::<f64>())
            .collect::<std::result::Result<_, _>>()
            .map_err(|_| bad("bad PARAMS"))?;
        let need = |n: usize| {
            if p.len() == n {
                Ok(())
            } else {
                Err(bad(&format!("model {} takes {n} parameters", t[1])))
            }
        };
        let zero_dist = |from: usize| {
            if p[from..].iter().all(|&d| d == 0.0) {
                Ok(())
            } else {
                Err(bad(&format!(
                    "model {} has non-zero distortion; undistort the images first",
                    t[1]
                )))
            }
        };
        let k = match t[1] {
            "SIMPLE_PINHOLE" => {
                need(3)?;
                [p[0], p[0], p[1], p[2]]
            }
            "PINHOLE" => {
                need(4)?;
                [p[0], p[1], p[2], p[3]]
            }
            "SIMPLE_RADIAL" | "RADIAL" => {
                need(if t[1] == "RADIAL" { 5 } else { 4 })?;
                zero_dist(3)?;
                [p[0], p[0], p[1], p[2]]
            }
            "OPENCV" | "FULL_OPENCV" => {
                need(if t[1] == "OPENCV" { 8 } else { 12 })?;
                zero_dist(4)?;
                [p[0], p[1], p[2], p[3]]
            }
            m => return Err(bad(&format!("unsupported camera model {m}"))),
        };
        intr.insert(id, (w, h, k));
    }
    let mut cams = Vec::new();
    let mut lines = images_txt
        .lines()
        .enumerate()
        .filter(|(_, l)| !l.trim().starts_with('#'))
        .peekable();
    while let Some((ln, line)) = lines.next() {
        let t: Vec<&str> = line.split_whitespace().collect();
        if t.is_empty() {
            continue;
        }
        let bad = |m: &str| cerr(&file_i, format!("line {}: {m}", ln + 1));
        if t.len() < 10 {
            return Err(bad("expected IMAGE_ID QW QX QY QZ TX TY TZ CAMERA_ID NAME"));
        }
        let f: Vec<f64> = t[1..8]
            .iter()
            .map(|s| s.parse::<f64>())
            .collect::<std::result::Result<_, _>>()
            .map_err(|_| bad("bad pose"))?;
        let cam_id: u64 = t[8].parse().map_err(|_| bad("bad CAMERA_ID"))?;
        let &(w, h, k) = intr
            .get(&cam_id)
            .ok_or_else(|| bad(&format!("camera {cam_id} is not in cameras.txt")))?;
        let n = (f[0] * f[0] + f[1] * f[1] + f[2] * f[2] + f[3] * f[3]).sqrt();
        if n.is_nan() || n <= 0.0 {
            return Err(bad("zero quaternion"));
        }
        let (qw, qx, qy, qz) = (f[0] / n, f[1] / n, f[2] / n, f[3] / n);
        let r = [
            [
                1.0 - 2.0 * (qy * qy + qz * qz),
                2.0 * (qx * qy - qw * qz),
                2.0 * (qx * qz + qw * qy),
            ],
            [
                2.0 * (qx * qy + qw * qz),
                1.0 - 2.0 * (qx * qx + qz * qz),
                2.0 * (qy * qz - qw * qx),
            ],
            [
                2.0 * (qx * qz - qw * qy),
                2.0 * (qy * qz + qw * qx),
                1.0 - 2.0 * (qx * qx + qy * qy),
            ],
        ];
        let mut m = [[0.0; 4]; 4];
        for i in 0..3 {
            m[i][..3].copy_from_slice(&r[i]);
            m[i][3] = f[4 + i];
        }
        m[3][3] = 1.0;
        cams.push(Camera {
            name: t[9..].join(" "),
            width: w,
            height: h,
            fx: k[0],
            fy: k[1],
            cx: k[2],
            cy: k[3],
            world_to_camera: m,
            crop: None,
            near: 0.01,
            far: 1e10,
        });
        // The next line lists the image's 2D points (X Y POINT3D_ID triples, possibly none:
        // an empty line). A file written without them has the next image line there: it is
        // kept, not skipped (skipping it used to lose every other image silently).
        if lines.peek().is_some_and(|(_, l)| is_points_line(l)) {
            lines.next();
        }
    }
    cams.sort_by(|a, b| a.name.cmp(&b.name));
    Ok(CameraSet {
        cameras: cams,
        ..Default::default()
    })
}

#[cfg(test)]
mod colmap_tests {
    use super::*;

    /// An `images.txt` written without its POINTS2D lines keeps every image (it used to lose
    /// every other one silently); with them (empty or not) it reads the same.
    #[test]
    fn images_without_points_lines_keep_every_image() {
        let cams = "1 PINHOLE 64 48 50 50 32 24\n";
        let img = |i: u32| format!("{i} 1 0 0 0 0 0 {i} 1 view_{i}.png\n");
        let without: String = (1..=4).map(img).collect();
        let with: String = (1..=4)
            .map(|i| {
                let pts = if i % 2 == 0 {
                    "\n".to_string()
                } else {
                    "1.0 2.0 -1 3.5 4.5 7\n".into()
                };
                img(i) + &pts
            })
            .collect();
        let a = parse_colmap(cams, &without, "colmap").unwrap();
        let b = parse_colmap(cams, &with, "colmap").unwrap();
        assert_eq!(a.cameras.len(), 4);
        assert_eq!(a.cameras, b.cameras);
    }
}
