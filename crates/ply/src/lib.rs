//! # r4d-ply: a small PLY reader and writer for point data (the `vertex` element)
//!
//! Reads ASCII and binary (little/big endian) files with scalar properties of any PLY type;
//! elements after `vertex` are ignored. Every defect is a [`PlyError`] naming the file; memory
//! is never reserved for more vertices than the file can hold, so a header declaring an
//! absurd vertex count fails cleanly. Writes binary little-endian `float` properties.
//!
//! Shared by `r4d-mpm` (particles) and `r4d-splat` (INRIA 3DGS scenes).
//!
//! ```
//! let txt = b"ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nend_header\n1\n2\n";
//! let p = r4d_ply::parse_ply(txt, "mem.ply").unwrap();
//! assert_eq!(p.get("x").unwrap(), &[1.0, 2.0]);
//! assert_eq!(p.type_of("x"), Some(r4d_ply::PlyType::F32));
//! ```

use std::io::Write;
use std::path::{Path, PathBuf};

/// Errors of PLY reading and writing.
#[derive(Debug, thiserror::Error)]
pub enum PlyError {
    /// The file is not a PLY file this reader understands, or its body is inconsistent.
    #[error("{file}: malformed PLY: {message}")]
    Malformed {
        /// The file.
        file: String,
        /// What is wrong.
        message: String,
    },
    /// Reading or writing the file failed.
    #[error("{path}: {source}")]
    Io {
        /// The path.
        path: PathBuf,
        /// The OS error.
        #[source]
        source: std::io::Error,
    },
}

/// Result with [`PlyError`].
pub type Result<T, E = PlyError> = std::result::Result<T, E>;

/// The vertex element of a PLY file: one column of values per property, in file order.
#[derive(Clone, Debug, Default)]
pub struct PlyVertices {
    /// Number of vertices.
    pub count: usize,
    /// `(property name, values)`; integer properties are converted to f32 exactly up to 2^24.
    pub columns: Vec<(String, Vec<f32>)>,
    /// The declared type of each column, in the order of `columns`.
    pub types: Vec<PlyType>,
}

impl PlyVertices {
    /// The column of a property, if present.
    pub fn get(&self, name: &str) -> Option<&[f32]> {
        self.columns
            .iter()
            .find(|(n, _)| n == name)
            .map(|(_, v)| v.as_slice())
    }

    /// The declared type of a property, if present.
    pub fn type_of(&self, name: &str) -> Option<PlyType> {
        self.columns
            .iter()
            .position(|(n, _)| n == name)
            .map(|i| self.types[i])
    }
}

#[derive(Clone, Copy, PartialEq)]
enum Format {
    Ascii,
    Le,
    Be,
}

/// A scalar PLY property type.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PlyType {
    /// `char` / `int8`
    I8,
    /// `uchar` / `uint8`
    U8,
    /// `short` / `int16`
    I16,
    /// `ushort` / `uint16`
    U16,
    /// `int` / `int32`
    I32,
    /// `uint` / `uint32`
    U32,
    /// `float` / `float32`
    F32,
    /// `double` / `float64`
    F64,
}
use PlyType as Ty;

impl PlyType {
    /// Parses a PLY type name.
    pub fn parse(s: &str) -> Option<Ty> {
        Some(match s {
            "char" | "int8" => Ty::I8,
            "uchar" | "uint8" => Ty::U8,
            "short" | "int16" => Ty::I16,
            "ushort" | "uint16" => Ty::U16,
            "int" | "int32" => Ty::I32,
            "uint" | "uint32" => Ty::U32,
            "float" | "float32" => Ty::F32,
            "double" | "float64" => Ty::F64,
            _ => return None,
        })
    }
    /// Bytes per value.
    pub fn size(self) -> usize {
        match self {
            Ty::I8 | Ty::U8 => 1,
            Ty::I16 | Ty::U16 => 2,
            Ty::I32 | Ty::U32 | Ty::F32 => 4,
            Ty::F64 => 8,
        }
    }
    fn read(self, b: &[u8], le: bool) -> f32 {
        macro_rules! rd {
            ($t:ty, $n:expr) => {{
                let a: [u8; $n] = b[..$n].try_into().unwrap();
                if le {
                    <$t>::from_le_bytes(a)
                } else {
                    <$t>::from_be_bytes(a)
                }
            }};
        }
        match self {
            Ty::I8 => b[0] as i8 as f32,
            Ty::U8 => b[0] as f32,
            Ty::I16 => rd!(i16, 2) as f32,
            Ty::U16 => rd!(u16, 2) as f32,
            Ty::I32 => rd!(i32, 4) as f32,
            Ty::U32 => rd!(u32, 4) as f32,
            Ty::F32 => rd!(f32, 4),
            Ty::F64 => rd!(f64, 8) as f32,
        }
    }
}

/// An element of the header: name, count and scalar properties.
type Element = (String, usize, Vec<(String, Ty)>);

/// Reads the vertex element of a PLY file.
pub fn read_ply(path: &Path) -> Result<PlyVertices> {
    let bytes = r4d_fsio::read_bounded(path, r4d_fsio::MAX_BINARY_BYTES).map_err(|source| {
        PlyError::Io {
            path: path.to_path_buf(),
            source,
        }
    })?;
    parse_ply(&bytes, &path.display().to_string())
}

/// Parses PLY bytes; `file` names the source in errors.
pub fn parse_ply(bytes: &[u8], file: &str) -> Result<PlyVertices> {
    let err = |m: String| PlyError::Malformed {
        file: file.to_string(),
        message: m,
    };
    // Header: lines up to "end_header".
    let mut pos = 0usize;
    let mut lines = Vec::new();
    loop {
        let rest = &bytes[pos..];
        let nl = rest
            .iter()
            .position(|&b| b == b'\n')
            .ok_or_else(|| err("header has no end_header line".into()))?;
        let line = std::str::from_utf8(&rest[..nl])
            .map_err(|_| err("header is not text".into()))?
            .trim_end_matches('\r')
            .trim()
            .to_string();
        pos += nl + 1;
        if line == "end_header" {
            break;
        }
        lines.push(line);
        if lines.len() > 100_000 {
            return Err(err("header too long".into()));
        }
    }
    if lines.first().map(String::as_str) != Some("ply") {
        return Err(err("does not start with 'ply'".into()));
    }
    let mut format = None;
    // (element name, count, properties (name, type))
    let mut elements: Vec<Element> = Vec::new();
    let mut has_list_in: Vec<bool> = Vec::new();
    for (ln, line) in lines.iter().enumerate().skip(1) {
        let t: Vec<&str> = line.split_whitespace().collect();
        match t.first().copied() {
            Some("format") => {
                format = Some(match t.get(1).copied() {
                    Some("ascii") => Format::Ascii,
                    Some("binary_little_endian") => Format::Le,
                    Some("binary_big_endian") => Format::Be,
                    other => return Err(err(format!("unknown format {other:?}"))),
                })
            }
            Some("element") => {
                let (Some(name), Some(n)) = (t.get(1), t.get(2)) else {
                    return Err(err(format!(
                        "header line {}: bad element line '{line}'",
                        ln + 1
                    )));
                };
                let n: usize = n
                    .parse()
                    .map_err(|_| err(format!("element {name}: bad count '{n}'")))?;
                elements.push((name.to_string(), n, Vec::new()));
                has_list_in.push(false);
            }
            Some("property") => {
                let Some(el) = elements.last_mut() else {
                    return Err(err("property before any element".into()));
                };
                if t.get(1) == Some(&"list") {
                    *has_list_in.last_mut().unwrap() = true;
                    continue;
                }
                let (Some(ty), Some(name)) = (t.get(1), t.get(2)) else {
                    return Err(err(format!("bad property line '{line}'")));
                };
                let ty = Ty::parse(ty)
                    .ok_or_else(|| err(format!("property {name}: unknown type '{ty}'")))?;
                el.2.push((name.to_string(), ty));
            }
            Some("comment") | Some("obj_info") | None => {}
            Some(other) => return Err(err(format!("unknown header keyword '{other}'"))),
        }
    }
    let format = format.ok_or_else(|| err("no format line".into()))?;
    let vi = elements
        .iter()
        .position(|e| e.0 == "vertex")
        .ok_or_else(|| err("no 'vertex' element".into()))?;
    if elements[..=vi].iter().zip(&has_list_in).any(|(_, &l)| l) {
        return Err(err(
            "list properties in or before the vertex element are not supported".into(),
        ));
    }
    // Sizes declared by the header: checked, so a huge element before `vertex` is an error
    // instead of a wrapped offset that reads the wrong bytes.
    let mut skip_bytes = 0usize;
    for e in &elements[..vi] {
        let stride: usize = e.2.iter().map(|p| p.1.size()).sum();
        skip_bytes = e
            .1
            .checked_mul(stride)
            .and_then(|b| b.checked_add(skip_bytes))
            .ok_or_else(|| {
                err(format!(
                    "element '{}' before 'vertex' declares {} entries of {stride} bytes: more than any file holds",
                    e.0, e.1
                ))
            })?;
    }
    let (_, count, props) = &elements[vi];
    let count = *count;
    // A vertex without properties takes no bytes: a huge declared count would loop for
    // ever over nothing (found by tests/fuzz_parsers.rs).
    if props.is_empty() && count > 0 {
        return Err(err(format!(
            "the vertex element declares {count} vertices but no property"
        )));
    }
    // Reserve no more than the body can hold: every vertex takes at least one byte (binary)
    // or two (ASCII: a digit and a separator), so an absurd declared count cannot allocate.
    let body = bytes.len().saturating_sub(pos);
    let cap = count.min(body);
    let mut columns: Vec<(String, Vec<f32>)> = props
        .iter()
        .map(|(n, _)| (n.clone(), Vec::with_capacity(cap)))
        .collect();
    let types: Vec<Ty> = props.iter().map(|p| p.1).collect();
    match format {
        Format::Ascii => {
            let text = std::str::from_utf8(&bytes[pos..])
                .map_err(|_| err("ASCII body is not text".into()))?;
            let skip_rows = elements[..vi]
                .iter()
                .try_fold(0usize, |a, e| a.checked_add(e.1))
                .ok_or_else(|| err("elements before 'vertex' declare too many rows".into()))?;
            // Rows keep their line ends: a row without one is the file's last line, cut
            // (a writer ends every row with a newline), possibly inside a number.
            let mut rows = text
                .split_inclusive('\n')
                .filter(|l| !l.trim().is_empty())
                .skip(skip_rows);
            for r in 0..count {
                let line = rows.next().ok_or_else(|| {
                    err(format!(
                        "vertex {r}: file ends early ({count} declared, {r} present)"
                    ))
                })?;
                if !line.ends_with('\n') {
                    return Err(err(format!(
                        "vertex {r}: the file ends inside the row ('{}' has no line end): truncated",
                        line.trim()
                    )));
                }
                let mut vals = line.split_whitespace();
                for (ci, (name, _)) in props.iter().enumerate() {
                    let tok = vals
                        .next()
                        .ok_or_else(|| err(format!("vertex {r}: missing value for '{name}'")))?;
                    let v: f32 = tok.parse().map_err(|_| {
                        err(format!("vertex {r}: '{name}' = '{tok}' is not a number"))
                    })?;
                    columns[ci].1.push(v);
                }
                let extra = vals.count();
                if extra > 0 {
                    return Err(err(format!(
                        "vertex {r}: {} values, the header declares {} properties",
                        props.len() + extra,
                        props.len()
                    )));
                }
            }
        }
        Format::Le | Format::Be => {
            let le = format == Format::Le;
            let stride: usize = props.iter().map(|p| p.1.size()).sum();
            let start = pos
                .checked_add(skip_bytes)
                .filter(|&st| st <= bytes.len())
                .ok_or_else(|| {
                    err(format!(
                        "the elements before 'vertex' need {skip_bytes} bytes, the body has {}",
                        bytes.len() - pos
                    ))
                })?;
            let need = count
                .checked_mul(stride)
                .and_then(|b| b.checked_add(start))
                .ok_or_else(|| err("vertex count too large".into()))?;
            if bytes.len() < need {
                return Err(err(format!(
                    "file ends early: {count} vertices of {stride} bytes need {} bytes, found {}",
                    need - pos,
                    bytes.len() - pos
                )));
            }
            for r in 0..count {
                let mut off = start + r * stride;
                for (ci, (_, ty)) in props.iter().enumerate() {
                    columns[ci].1.push(ty.read(&bytes[off..], le));
                    off += ty.size();
                }
            }
        }
    }
    Ok(PlyVertices {
        count,
        columns,
        types,
    })
}

/// Writes float columns as a binary little-endian PLY vertex element, atomically (a kill
/// leaves the old file or the new one, [`r4d_fsio`]).
pub fn write_ply(path: &Path, names: &[&str], columns: &[&[f32]]) -> Result<()> {
    assert_eq!(names.len(), columns.len(), "one name per column");
    let count = columns.first().map_or(0, |c| c.len());
    assert!(
        columns.iter().all(|c| c.len() == count),
        "columns of equal length"
    );
    let io = |source| PlyError::Io {
        path: path.to_path_buf(),
        source,
    };
    let mut w = r4d_fsio::AtomicFile::create(path).map_err(io)?;
    let mut header = format!("ply\nformat binary_little_endian 1.0\nelement vertex {count}\n");
    for n in names {
        header.push_str(&format!("property float {n}\n"));
    }
    header.push_str("end_header\n");
    w.write_all(header.as_bytes()).map_err(io)?;
    let mut row = Vec::with_capacity(4 * names.len());
    for r in 0..count {
        row.clear();
        for c in columns {
            row.extend_from_slice(&c[r].to_le_bytes());
        }
        w.write_all(&row).map_err(io)?;
    }
    w.commit().map_err(io)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ascii_and_binary_roundtrip() {
        let txt = b"ply\nformat ascii 1.0\ncomment hi\nelement vertex 2\nproperty float x\nproperty double y\nproperty int part\nend_header\n1 2 3\n4.5 5 -1\n";
        let p = parse_ply(txt, "t.ply").unwrap();
        assert_eq!(p.count, 2);
        assert_eq!(p.get("part").unwrap(), &[3.0, -1.0]);
        let dir = std::env::temp_dir().join(format!("r4d_ply_{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let f = dir.join("a.ply");
        write_ply(&f, &["x", "y"], &[&[1.0, 2.0], &[3.0, 4.0]]).unwrap();
        let q = read_ply(&f).unwrap();
        assert_eq!(q.get("y").unwrap(), &[3.0, 4.0]);
    }

    /// An element before `vertex` whose declared size overflows (or exceeds the
    /// file) is an error; it used to wrap the offset and read the wrong bytes, exit 0.
    #[test]
    fn huge_elements_before_vertex_are_errors() {
        let mut f = b"ply\nformat binary_little_endian 1.0\nelement junk 4611686018427387904\nproperty double a\nproperty double b\nelement vertex 1\nproperty float x\nend_header\n".to_vec();
        f.extend_from_slice(&1.5f32.to_le_bytes());
        let e = parse_ply(&f, "junk.ply").unwrap_err().to_string();
        assert!(e.contains("junk.ply") && e.contains("junk"), "{e}");
        let mut g = b"ply\nformat binary_little_endian 1.0\nelement junk 1000\nproperty float a\nelement vertex 1\nproperty float x\nend_header\n".to_vec();
        g.extend_from_slice(&1.5f32.to_le_bytes());
        let e = parse_ply(&g, "short.ply").unwrap_err().to_string();
        assert!(e.contains("short.ply"), "{e}");
        let a = b"ply\nformat ascii 1.0\nelement junk 18446744073709551615\nproperty float a\nelement junk2 18446744073709551615\nproperty float a\nelement vertex 1\nproperty float x\nend_header\n1\n";
        let e = parse_ply(a, "rows.ply").unwrap_err().to_string();
        assert!(e.contains("rows.ply"), "{e}");
        // A small element before vertex is skipped correctly.
        let mut ok = b"ply\nformat binary_little_endian 1.0\nelement junk 2\nproperty uchar a\nelement vertex 1\nproperty float x\nend_header\n\x07\x08".to_vec();
        ok.extend_from_slice(&2.5f32.to_le_bytes());
        assert_eq!(parse_ply(&ok, "ok.ply").unwrap().get("x").unwrap(), &[2.5]);
    }

    #[test]
    fn malformed_files_name_the_problem() {
        let e = parse_ply(b"ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\nend_header\n\0\0", "bad.ply")
            .unwrap_err()
            .to_string();
        assert!(e.contains("bad.ply") && e.contains("ends early"), "{e}");
        let e = parse_ply(b"plx\n", "b.ply").unwrap_err().to_string();
        assert!(e.contains("b.ply"), "{e}");
        let e = parse_ply(
            b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nend_header\nabc\n",
            "c.ply",
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("not a number"), "{e}");
    }

    #[test]
    fn absurd_vertex_counts_fail_without_allocating() {
        for fmt in ["ascii", "binary_little_endian"] {
            let h = format!(
                "ply\nformat {fmt} 1.0\nelement vertex 999999999999999\nproperty float x\nend_header\n1\n"
            );
            let e = parse_ply(h.as_bytes(), "huge.ply").unwrap_err().to_string();
            assert!(e.contains("huge.ply"), "{e}");
        }
    }

    #[test]
    fn truncated_ascii_bodies_are_typed_errors() {
        let head = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nend_header\n";
        let whole = format!("{head}1.25 2.5\n3.75 4.5\n5.125 6.875\n");
        assert_eq!(
            parse_ply(whole.as_bytes(), "ok.ply")
                .unwrap()
                .get("y")
                .unwrap(),
            &[2.5, 4.5, 6.875]
        );
        // Every cut inside the body: inside a number, between values, between rows.
        for cut in head.len()..whole.len() - 1 {
            let e = parse_ply(&whole.as_bytes()[..cut], "cut.ply")
                .expect_err(&whole[..cut])
                .to_string();
            assert!(e.contains("cut.ply"), "{e}");
            assert!(
                e.contains("truncated") || e.contains("ends early") || e.contains("missing value"),
                "{e}"
            );
        }
        // Fewer rows than declared, with a line end.
        let e = parse_ply(format!("{head}1 2\n3 4\n").as_bytes(), "few.ply")
            .unwrap_err()
            .to_string();
        assert!(e.contains("3 declared, 2 present"), "{e}");
        // A row with more values than properties (the rows do not match the header).
        let e = parse_ply(format!("{head}1 2 3\n4 5\n6 7\n").as_bytes(), "wide.ply")
            .unwrap_err()
            .to_string();
        assert!(e.contains("vertex 0: 3 values"), "{e}");
    }
}
