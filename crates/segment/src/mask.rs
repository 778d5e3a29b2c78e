//! 2D segmentation masks: the [`MaskSource`] trait the lifter reads views from, and
//! [`MaskDir`], the shipped source that reads mask files.
//!
//! ## The mask directory
//!
//! One mask per camera of the camera file. The mask of camera `i` is looked for under the
//! stem of the camera's name (`frame_0003.jpg` -> `frame_0003`), then under `i` written with
//! four digits (`0003`), then plainly (`3`). For a key `K` it is, in this order:
//!
//! * `K.png`: a **label map**, 8- or 16-bit grayscale: 0 = background/static, `k` = part
//!   `k - 1` (`1 ..= M`); the `ignore` value of `classes.json` (if any) marks pixels that
//!   vote for nothing. Any other value is an error naming the file and the pixel.
//! * `K.npy`: **stacked probability maps**, float32/float64 (or bool), shape `(M, H, W)` (or
//!   `(H, W)` when `M = 1`): `p_k(x)` = probability that pixel `x` shows part `k`.
//! * `K/` (a folder): **one probability map per class**, `K/<class>.png` (8- or 16-bit
//!   grayscale, `v / 255` or `v / 65535`) or `K/<class>.npy` (2-D, float or bool). Every class
//!   needs its map; a map of an undeclared class is an error.
//!
//! Probabilities must lie in [0, 1]; the background's is `max(0, 1 - sum_k p_k)`.
//!
//! An optional `classes.json`, `{"class_names": ["stem", "head"], "ignore": 255}`, names the
//! `M` parts (label `k + 1` is `class_names[k]`) and fixes `M`, so that label values above
//! `M` are caught. Without it the names are `part0, part1, ...` and `M` is inferred: from the
//! file names of the first per-class folder (sorted), else the first stacked `.npy`'s shape,
//! else the largest value of the label maps.

use crate::error::{Error, Result};
use r4d_splat::Camera;
use serde::Deserialize;
use std::path::{Path, PathBuf};

/// The value of a label map pixel that votes for nothing (set from `classes.json`'s `ignore`).
pub const IGNORE: u16 = u16::MAX;

/// The pixels of one view's mask.
#[derive(Clone, Debug, PartialEq)]
pub enum MaskData {
    /// One label per pixel (`[H][W]`): 0 = background, `k` = part `k - 1`, [`IGNORE`] = no
    /// vote.
    Labels(Vec<u16>),
    /// `M` part probabilities per pixel (`[H][W][M]`), each in [0, 1]; the background gets
    /// `max(0, 1 - sum)`.
    Probabilities(Vec<f32>),
}

/// One view's mask.
#[derive(Clone, Debug, PartialEq)]
pub struct Mask {
    /// Where it came from (a file, or a model's description of the view): named in errors.
    pub origin: String,
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// The pixels.
    pub data: MaskData,
}

impl Mask {
    /// The class a pixel votes for most: -1 background, `k` part `k`, `None` ignored (for
    /// display).
    pub fn argmax(&self, i: u32, j: u32, num_parts: usize) -> Option<i32> {
        let p = (j * self.width + i) as usize;
        match &self.data {
            MaskData::Labels(l) => (l[p] != IGNORE).then(|| l[p] as i32 - 1),
            MaskData::Probabilities(v) => {
                let px = &v[p * num_parts..(p + 1) * num_parts];
                let bg = 1.0 - px.iter().sum::<f32>();
                let (mut best, mut arg) = (bg, -1);
                for (k, &q) in px.iter().enumerate() {
                    if q > best {
                        (best, arg) = (q, k as i32);
                    }
                }
                Some(arg)
            }
        }
    }
}

/// A source of per-view masks. The shipped implementation reads files ([`MaskDir`]); a
/// model-backed segmenter (a text-prompted detector + SAM, run on the views' images) can
/// implement it to feed the lifter directly.
pub trait MaskSource {
    /// The names of the `M` moving parts; part `k` is label `k + 1` in label maps and the
    /// `k`-th probability.
    fn class_names(&self) -> &[String];

    /// The mask of view `view`, seen by `camera`. Its size must be the camera's (the lifter
    /// checks and names [`Mask::origin`] when it is not); probability masks have
    /// `class_names().len()` values per pixel.
    fn mask(&mut self, view: usize, camera: &Camera) -> Result<Mask>;
}

/// Masks given in memory, one per view (tests, or masks computed by the caller).
#[derive(Clone, Debug, Default)]
pub struct InMemoryMasks {
    /// Part names.
    pub class_names: Vec<String>,
    /// One mask per view.
    pub masks: Vec<Mask>,
}

impl MaskSource for InMemoryMasks {
    fn class_names(&self) -> &[String] {
        &self.class_names
    }

    fn mask(&mut self, view: usize, camera: &Camera) -> Result<Mask> {
        self.masks.get(view).cloned().ok_or_else(|| Error::NoMask {
            dir: "in-memory masks".into(),
            view,
            camera: camera.name.clone(),
            tried: format!("{} masks given", self.masks.len()),
        })
    }
}

/// How one view's mask is stored.
#[derive(Clone, Debug, PartialEq)]
pub enum MaskFile {
    /// A label map PNG.
    Labels(PathBuf),
    /// Stacked probabilities `(M, H, W)` in one `.npy`.
    Stacked(PathBuf),
    /// A folder of per-class maps: `(class name, file)`, sorted by name.
    PerClass(PathBuf, Vec<(String, PathBuf)>),
}

impl MaskFile {
    fn path(&self) -> &Path {
        match self {
            MaskFile::Labels(p) | MaskFile::Stacked(p) | MaskFile::PerClass(p, _) => p,
        }
    }
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct ClassesFile {
    class_names: Vec<String>,
    #[serde(default)]
    ignore: Option<u16>,
}

/// Masks read from a directory (layout in the module docs).
#[derive(Clone, Debug)]
pub struct MaskDir {
    /// The directory.
    pub dir: PathBuf,
    /// The mask file of each camera, in camera order.
    pub files: Vec<MaskFile>,
    /// Part names.
    pub class_names: Vec<String>,
    /// The label value that votes for nothing, if any.
    pub ignore: Option<u16>,
}

fn keys(view: usize, cam: &Camera) -> Vec<String> {
    let mut k = Vec::new();
    if let Some(stem) = Path::new(&cam.name).file_stem().and_then(|s| s.to_str()) {
        if !stem.is_empty() {
            k.push(stem.to_string());
        }
    }
    for s in [format!("{view:04}"), view.to_string()] {
        if !k.contains(&s) {
            k.push(s);
        }
    }
    k
}

fn per_class_files(dir: &Path) -> Result<Vec<(String, PathBuf)>> {
    let mut out = Vec::new();
    for e in std::fs::read_dir(dir).map_err(Error::io(dir))? {
        let p = e.map_err(Error::io(dir))?.path();
        let ext = p
            .extension()
            .and_then(|e| e.to_str())
            .map(str::to_ascii_lowercase);
        if !matches!(ext.as_deref(), Some("png" | "npy")) {
            continue;
        }
        let stem = p.file_stem().and_then(|s| s.to_str()).unwrap_or_default();
        if let Some((other, _)) = out.iter().find(|(n, _): &&(String, PathBuf)| n == stem) {
            return Err(Error::mask(
                p.display(),
                format!("a second map for class '{other}'"),
            ));
        }
        out.push((stem.to_string(), p));
    }
    out.sort();
    if out.is_empty() {
        return Err(Error::mask(
            dir.display(),
            "no per-class maps (<class>.png or <class>.npy) in this folder",
        ));
    }
    Ok(out)
}

/// A `classes.json`'s text, checked: `(class names, ignore value)` (`path` names the file in
/// errors).
pub fn parse_classes(text: &str, path: &Path) -> Result<(Vec<String>, Option<u16>)> {
    let file = path.display().to_string();
    let c: ClassesFile = serde_json::from_str(text).map_err(|e| Error::Classes {
        file: file.clone(),
        message: format!("{e} (expected {{\"class_names\": [\"...\"], \"ignore\": 255}})"),
    })?;
    if c.class_names.is_empty() || c.class_names.len() >= IGNORE as usize {
        return Err(Error::Classes {
            file,
            message: format!("{} class names (1 ..= 65534)", c.class_names.len()),
        });
    }
    if let Some(i) = c.ignore {
        if (i as usize) <= c.class_names.len() {
            return Err(Error::Classes {
                file,
                message: format!(
                    "ignore = {i} is a class label (0 ..= {})",
                    c.class_names.len()
                ),
            });
        }
    }
    Ok((c.class_names, c.ignore))
}

impl MaskDir {
    /// Finds the mask of every camera in `dir` (a camera without one is an error naming it
    /// and the names tried) and settles the classes (see the module docs).
    pub fn open(dir: &Path, cameras: &[Camera]) -> Result<MaskDir> {
        if !dir.is_dir() {
            return Err(Error::Io {
                path: dir.to_path_buf(),
                source: std::io::Error::new(
                    std::io::ErrorKind::NotFound,
                    "not a directory of masks",
                ),
            });
        }
        let classes_path = dir.join("classes.json");
        let classes = if classes_path.is_file() {
            let text = r4d_fsio::read_to_string_bounded(&classes_path, r4d_fsio::MAX_TEXT_BYTES)
                .map_err(Error::io(&classes_path))?;
            let (class_names, ignore) = parse_classes(&text, &classes_path)?;
            Some(ClassesFile {
                class_names,
                ignore,
            })
        } else {
            None
        };
        let mut files = Vec::with_capacity(cameras.len());
        for (v, cam) in cameras.iter().enumerate() {
            let ks = keys(v, cam);
            let mut found = None;
            for k in &ks {
                let (png, npy, sub) = (
                    dir.join(format!("{k}.png")),
                    dir.join(format!("{k}.npy")),
                    dir.join(k),
                );
                found = if png.is_file() {
                    Some(MaskFile::Labels(png))
                } else if npy.is_file() {
                    Some(MaskFile::Stacked(npy))
                } else if sub.is_dir() {
                    Some(MaskFile::PerClass(sub.clone(), per_class_files(&sub)?))
                } else {
                    None
                };
                if found.is_some() {
                    break;
                }
            }
            let tried: Vec<String> = ks
                .iter()
                .map(|k| format!("{k}.png, {k}.npy, {k}/"))
                .collect();
            files.push(found.ok_or_else(|| Error::NoMask {
                dir: dir.display().to_string(),
                view: v,
                camera: cam.name.clone(),
                tried: tried.join(", "),
            })?);
        }
        let (class_names, ignore) = match classes {
            Some(c) => (c.class_names, c.ignore),
            None => (infer_classes(&files)?, None),
        };
        Ok(MaskDir {
            dir: dir.to_path_buf(),
            files,
            class_names,
            ignore,
        })
    }
}

fn infer_classes(files: &[MaskFile]) -> Result<Vec<String>> {
    let numbered = |m: usize| (0..m).map(|k| format!("part{k}")).collect();
    if let Some(MaskFile::PerClass(_, maps)) =
        files.iter().find(|f| matches!(f, MaskFile::PerClass(..)))
    {
        return Ok(maps.iter().map(|(n, _)| n.clone()).collect());
    }
    if let Some(MaskFile::Stacked(p)) = files.iter().find(|f| matches!(f, MaskFile::Stacked(_))) {
        let a = read_npy(p)?;
        return Ok(numbered(match a.shape[..] {
            [m, _, _] => m,
            _ => 1,
        }));
    }
    let mut max = 0u32;
    for f in files {
        if let MaskFile::Labels(p) = f {
            let (_, _, l) = read_label_png(p)?;
            max = max.max(l.iter().copied().max().unwrap_or(0) as u32);
        }
    }
    if max as usize >= IGNORE as usize {
        return Err(Error::mask(
            files[0].path().display(),
            format!("label {max}: at most 65534 classes"),
        ));
    }
    Ok(numbered(max as usize))
}

impl MaskSource for MaskDir {
    fn class_names(&self) -> &[String] {
        &self.class_names
    }

    fn mask(&mut self, view: usize, camera: &Camera) -> Result<Mask> {
        let m = self.class_names.len();
        let file = self.files.get(view).ok_or_else(|| Error::NoMask {
            dir: self.dir.display().to_string(),
            view,
            camera: camera.name.clone(),
            tried: format!("{} views found", self.files.len()),
        })?;
        match file {
            MaskFile::Labels(p) => {
                let (w, h, mut l) = read_label_png(p)?;
                for (k, v) in l.iter_mut().enumerate() {
                    if Some(*v) == self.ignore {
                        *v = IGNORE;
                    } else if *v as usize > m {
                        return Err(Error::UnknownLabel {
                            file: p.display().to_string(),
                            x: (k % w as usize) as u32,
                            y: (k / w as usize) as u32,
                            value: *v as u32,
                            num_parts: m,
                            ignore: self
                                .ignore
                                .map(|i| format!(", {i} = ignored"))
                                .unwrap_or_default(),
                        });
                    }
                }
                Ok(Mask {
                    origin: p.display().to_string(),
                    width: w,
                    height: h,
                    data: MaskData::Labels(l),
                })
            }
            MaskFile::Stacked(p) => {
                let a = read_npy(p)?;
                let (mm, h, w) = match a.shape[..] {
                    [mm, h, w] => (mm, h, w),
                    [h, w] => (1, h, w),
                    _ => {
                        return Err(Error::mask(
                            p.display(),
                            format!("shape {:?}: expected (M, H, W) or (H, W)", a.shape),
                        ))
                    }
                };
                if mm != m {
                    return Err(Error::mask(
                        p.display(),
                        format!(
                            "{mm} probability maps for {m} classes ({})",
                            self.class_names.join(", ")
                        ),
                    ));
                }
                check_probabilities(&a.data, p)?;
                let mut data = vec![0f32; m * h * w];
                for k in 0..m {
                    for (px, &v) in a.data[k * h * w..(k + 1) * h * w].iter().enumerate() {
                        data[px * m + k] = v;
                    }
                }
                Ok(Mask {
                    origin: p.display().to_string(),
                    width: w as u32,
                    height: h as u32,
                    data: MaskData::Probabilities(data),
                })
            }
            MaskFile::PerClass(folder, maps) => {
                for (name, path) in maps {
                    if !self.class_names.contains(name) {
                        return Err(Error::UnknownClass {
                            file: path.display().to_string(),
                            class: name.clone(),
                            known: self.class_names.join(", "),
                        });
                    }
                }
                let mut data = Vec::new();
                let mut size = None;
                for (k, class) in self.class_names.iter().enumerate() {
                    let (_, path) = maps.iter().find(|(n, _)| n == class).ok_or_else(|| {
                        Error::mask(
                            folder.display(),
                            format!("no map for class '{class}' ({class}.png or {class}.npy)"),
                        )
                    })?;
                    let (w, h, v) = read_probability_map(path)?;
                    match size {
                        None => {
                            size = Some((w, h));
                            data = vec![0f32; m * (w * h) as usize];
                        }
                        Some(s) if s != (w, h) => {
                            return Err(Error::mask(
                                path.display(),
                                format!(
                                    "{w}x{h}, but the other maps of this view are {}x{}",
                                    s.0, s.1
                                ),
                            ))
                        }
                        _ => {}
                    }
                    for (px, q) in v.into_iter().enumerate() {
                        data[px * m + k] = q;
                    }
                }
                let (w, h) = size.expect("at least one class");
                Ok(Mask {
                    origin: folder.display().to_string(),
                    width: w,
                    height: h,
                    data: MaskData::Probabilities(data),
                })
            }
        }
    }
}

/// The largest mask image side read (pixels; cameras are bounded the same way).
pub const MAX_IMAGE_SIDE: u32 = 8192;
/// The most memory one decoded mask image may take (bytes).
pub const MAX_IMAGE_BYTES: u64 = 256 << 20;
/// The largest `.npy` mask file read (bytes): a stack of class maps `(M, H, W)` in float64
/// at the image limit fits many classes; a larger file, a device or a pipe is refused as its
/// bytes arrive.
pub const MAX_NPY_MASK_BYTES: u64 = 4 << 30;

fn decode_png(bytes: &[u8], path: &Path) -> Result<image::DynamicImage> {
    let mut limits = image::Limits::default();
    limits.max_image_width = Some(MAX_IMAGE_SIDE);
    limits.max_image_height = Some(MAX_IMAGE_SIDE);
    limits.max_alloc = Some(MAX_IMAGE_BYTES);
    let mut reader = image::ImageReader::new(std::io::Cursor::new(bytes))
        .with_guessed_format()
        .map_err(Error::io(path))?;
    reader.limits(limits);
    reader
        .decode()
        .map_err(|e| Error::mask(path.display(), format!("cannot decode: {e}")))
}

/// A mask file's bytes, refusing one larger than [`MAX_IMAGE_BYTES`] before reading it.
fn read_bounded(path: &Path) -> Result<Vec<u8>> {
    r4d_fsio::read_bounded(path, MAX_IMAGE_BYTES).map_err(Error::io(path))
}

const GRAY_ONLY: &str = "an indexed (palette) PNG: save the label indices as grayscale, \
     e.g. PIL's Image.fromarray(np.array(Image.open(f)).astype(np.uint8))";

/// Reads an 8- or 16-bit grayscale label PNG: `(width, height, labels)`.
pub fn read_label_png(path: &Path) -> Result<(u32, u32, Vec<u16>)> {
    decode_label_png(&read_bounded(path)?, path)
}

/// [`read_label_png`] on the file's bytes (`path` names it in errors).
pub fn decode_label_png(bytes: &[u8], path: &Path) -> Result<(u32, u32, Vec<u16>)> {
    use image::DynamicImage as D;
    let img = decode_png(bytes, path)?;
    let (w, h) = (img.width(), img.height());
    let l = match img {
        D::ImageLuma8(b) => b.into_raw().into_iter().map(u16::from).collect(),
        D::ImageLuma16(b) => b.into_raw(),
        other => {
            return Err(Error::mask(
                path.display(),
                format!(
                    "a label map must be 8- or 16-bit grayscale, this is {:?} (for {GRAY_ONLY})",
                    other.color()
                ),
            ))
        }
    };
    Ok((w, h, l))
}

/// Reads one class's probability map: an 8/16-bit grayscale PNG (`v / max`) or a 2-D `.npy`.
pub fn read_probability_map(path: &Path) -> Result<(u32, u32, Vec<f32>)> {
    let is_npy = path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("npy"));
    let bytes = if is_npy {
        r4d_fsio::read_bounded(path, MAX_NPY_MASK_BYTES).map_err(Error::io(path))?
    } else {
        read_bounded(path)?
    };
    decode_probability_map(&bytes, path, is_npy)
}

/// [`read_probability_map`] on the file's bytes: a `.npy` array when `npy`, else a PNG.
pub fn decode_probability_map(
    bytes: &[u8],
    path: &Path,
    npy: bool,
) -> Result<(u32, u32, Vec<f32>)> {
    use image::DynamicImage as D;
    if npy {
        let a = parse_npy(bytes).map_err(|m| Error::mask(path.display(), m))?;
        let [h, w] = a.shape[..] else {
            return Err(Error::mask(
                path.display(),
                format!("shape {:?}: a per-class map is 2-D (H, W)", a.shape),
            ));
        };
        check_probabilities(&a.data, path)?;
        return Ok((w as u32, h as u32, a.data));
    }
    let img = decode_png(bytes, path)?;
    let (w, h) = (img.width(), img.height());
    let v = match img {
        D::ImageLuma8(b) => b.into_raw().into_iter().map(|v| v as f32 / 255.0).collect(),
        D::ImageLuma16(b) => b
            .into_raw()
            .into_iter()
            .map(|v| v as f32 / 65535.0)
            .collect(),
        other => {
            return Err(Error::mask(
                path.display(),
                format!(
                    "a probability map PNG must be 8- or 16-bit grayscale, this is {:?}",
                    other.color()
                ),
            ))
        }
    };
    Ok((w, h, v))
}

fn check_probabilities(v: &[f32], path: &Path) -> Result<()> {
    if let Some(i) = v
        .iter()
        .position(|p| !(p.is_finite() && (-1e-6..=1.0 + 1e-6).contains(p)))
    {
        return Err(Error::mask(
            path.display(),
            format!(
                "value {} at flat index {i} is not a probability in [0, 1]",
                v[i]
            ),
        ));
    }
    Ok(())
}

/// A `.npy` array read as f32: shape and values in C order.
#[derive(Clone, Debug, PartialEq)]
pub struct NpyArray {
    /// The shape.
    pub shape: Vec<usize>,
    /// The values, C order.
    pub data: Vec<f32>,
}

/// Reads a little-endian float32/float64 or bool `.npy` in C order.
pub fn read_npy(path: &Path) -> Result<NpyArray> {
    let bytes = r4d_fsio::read_bounded(path, MAX_NPY_MASK_BYTES).map_err(Error::io(path))?;
    parse_npy(&bytes).map_err(|m| Error::mask(path.display(), m))
}

/// A mask array from the bytes of a `.npy` file ([`r4d_fsio::npy::parse`]: sizes checked).
pub fn parse_npy(bytes: &[u8]) -> Result<NpyArray, String> {
    let a = r4d_fsio::npy::parse(bytes).map_err(|e| match e {
        r4d_fsio::npy::NpyError::Dtype(_) => {
            format!("{e}; save probabilities as float, not uint8")
        }
        e => e.to_string(),
    })?;
    Ok(NpyArray {
        data: a.values_f32().collect(),
        shape: a.shape,
    })
}

/// Writes a float32 `.npy` (C order; for tests and tools that produce masks).
pub fn write_npy(path: &Path, shape: &[usize], data: &[f32]) -> Result<()> {
    let out = r4d_fsio::npy::encode_f32(shape, data);
    r4d_fsio::write_atomic(path, &out).map_err(Error::io(path))
}

/// Writes a label map as a grayscale PNG (8-bit when every value fits, else 16-bit).
pub fn write_label_png(path: &Path, width: u32, height: u32, labels: &[u16]) -> Result<()> {
    assert_eq!(
        labels.len(),
        (width * height) as usize,
        "one label per pixel"
    );
    let mut bytes = Vec::new();
    let mut cursor = std::io::Cursor::new(&mut bytes);
    let png = image::ImageFormat::Png;
    let r = if labels.iter().all(|&l| l <= 255) {
        let b: Vec<u8> = labels.iter().map(|&l| l as u8).collect();
        image::GrayImage::from_raw(width, height, b)
            .expect("sized")
            .write_to(&mut cursor, png)
    } else {
        image::ImageBuffer::<image::Luma<u16>, _>::from_raw(width, height, labels.to_vec())
            .expect("sized")
            .write_to(&mut cursor, png)
    };
    r.map_err(|e| Error::mask(path.display(), format!("cannot write: {e}")))?;
    r4d_fsio::write_atomic(path, &bytes).map_err(Error::io(path))
}
