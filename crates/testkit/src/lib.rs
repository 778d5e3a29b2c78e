//! # r4d-testkit: helpers shared by the workspace's tests (not published)
//!
//! The repository's reference fixtures (`tests/fixtures`, copied from data other projects
//! made: gsplat renders, pytorch-msssim and numpy goldens, PhysGaussian trajectories), a
//! reader for their `.npz` / `.npy` arrays, and the small MPM scenes the physics tests build
//! ([`scenes`]), gsplat's golden render cases ([`splat_cases`]). A test that reads a fixture panics with the path when it is missing.

pub mod scenes;
pub mod splat_cases;

use std::collections::HashMap;
use std::io::Read;
use std::path::{Path, PathBuf};

/// Copies the folder `from` to `to`, recursively (test fixtures into a temp dir).
pub fn copy_dir(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for e in std::fs::read_dir(from).unwrap() {
        let e = e.unwrap();
        let t = to.join(e.file_name());
        if e.path().is_dir() {
            copy_dir(&e.path(), &t);
        } else {
            std::fs::copy(e.path(), &t).unwrap();
        }
    }
}

/// An array from a `.npy` member: shape and values converted to f64.
#[derive(Clone, Debug)]
pub struct Array {
    /// The shape.
    pub shape: Vec<usize>,
    /// The values, C order.
    pub data: Vec<f64>,
}

impl Array {
    /// Element at a multi-index.
    pub fn at(&self, idx: &[usize]) -> f64 {
        let mut o = 0;
        for (i, &k) in idx.iter().enumerate() {
            o = o * self.shape[i] + k;
        }
        self.data[o]
    }
}

/// Path of a fixture file under the repository's `tests/fixtures`.
pub fn fixture(rel: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../tests/fixtures")
        .join(rel)
}

/// Reads every array of an `.npz` file (little-endian f4/f8/i4/i8/u1, C order).
pub fn read_npz(path: &Path) -> HashMap<String, Array> {
    let f = std::fs::File::open(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let mut z = zip::ZipArchive::new(f).unwrap();
    let mut out = HashMap::new();
    for i in 0..z.len() {
        let mut m = z.by_index(i).unwrap();
        let name = m.name().trim_end_matches(".npy").to_string();
        let mut bytes = Vec::new();
        m.read_to_end(&mut bytes).unwrap();
        out.insert(name, parse_npy(&bytes));
    }
    out
}

/// Parses an `.npy` file's bytes (little-endian f4/f8/i4/i8/u1, C order) to f64.
pub fn parse_npy(b: &[u8]) -> Array {
    assert_eq!(&b[..6], b"\x93NUMPY");
    let (hlen, start) = if b[6] == 1 {
        (u16::from_le_bytes([b[8], b[9]]) as usize, 10)
    } else {
        (u32::from_le_bytes([b[8], b[9], b[10], b[11]]) as usize, 12)
    };
    let header = std::str::from_utf8(&b[start..start + hlen]).unwrap();
    assert!(header.contains("'fortran_order': False"), "{header}");
    let descr = header
        .split("'descr': '")
        .nth(1)
        .unwrap()
        .split('\'')
        .next()
        .unwrap();
    let shape_s = header
        .split("'shape': (")
        .nth(1)
        .unwrap()
        .split(')')
        .next()
        .unwrap();
    let shape: Vec<usize> = shape_s
        .split(',')
        .map(str::trim)
        .filter(|s| !s.is_empty())
        .map(|s| s.parse().unwrap())
        .collect();
    let body = &b[start + hlen..];
    let n: usize = shape.iter().product();
    let data: Vec<f64> = match descr {
        "<f4" => body
            .chunks_exact(4)
            .take(n)
            .map(|c| f32::from_le_bytes(c.try_into().unwrap()) as f64)
            .collect(),
        "<f8" => body
            .chunks_exact(8)
            .take(n)
            .map(|c| f64::from_le_bytes(c.try_into().unwrap()))
            .collect(),
        "<i4" => body
            .chunks_exact(4)
            .take(n)
            .map(|c| i32::from_le_bytes(c.try_into().unwrap()) as f64)
            .collect(),
        "<i8" => body
            .chunks_exact(8)
            .take(n)
            .map(|c| i64::from_le_bytes(c.try_into().unwrap()) as f64)
            .collect(),
        "|u1" => body.iter().take(n).map(|&c| c as f64).collect(),
        d => panic!("unsupported dtype {d}"),
    };
    assert_eq!(data.len(), n);
    Array { shape, data }
}

/// Reads one `.npy` file.
pub fn read_npy(path: &Path) -> Array {
    let b = std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    parse_npy(&b)
}

/// A `(T, 3, H, W)` video of a loss fixture (`tests/fixtures/loss/FILE`, array `key`) as f32;
/// all-integer data in 0..=255 (the 8-bit cases) as k / 255 (a gradient array never is).
pub fn loss_case_video(file: &str, key: &str) -> r4d_frames::Video<f32> {
    let a = &read_npz(&fixture(&format!("loss/{file}")))[key];
    let [t, _, h, w] = a.shape[..] else {
        panic!("{file}:{key}: not (T, 3, H, W)")
    };
    let uint8 = key != "grad" && a.data.iter().all(|v| v.fract() == 0.0 && *v <= 255.0);
    let vals: Vec<f32> = a
        .data
        .iter()
        .map(|&v| if uint8 { v as f32 / 255.0 } else { v as f32 })
        .collect();
    r4d_frames::Video::from_tchw(t, h, w, &vals).unwrap()
}
