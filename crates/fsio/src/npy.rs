//! NumPy `.npy` arrays: the one parser and the one writer every crate uses (videos, masks,
//! rendered images). Little-endian float32 (`<f4`), float64 (`<f8`) and bool (`|b1`), C order,
//! format versions 1 to 3. Sizes come from the file and are checked: the shape's product must
//! not overflow and the data must hold that many values before anything is allocated.
//!
//! ```
//! let bytes = r4d_fsio::npy::encode_f32(&[2, 3], &[0.0, 1.0, 2.0, 3.0, 4.0, 5.0]);
//! let a = r4d_fsio::npy::parse(&bytes).unwrap();
//! assert_eq!(a.shape, vec![2, 3]);
//! assert_eq!(a.values_f64().nth(4), Some(4.0));
//! ```

/// A data type of a `.npy` array.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Dtype {
    /// `<f4`.
    F32,
    /// `<f8`.
    F64,
    /// `|b1`.
    Bool,
}

impl Dtype {
    /// Bytes per value.
    pub fn size(self) -> usize {
        match self {
            Dtype::F32 => 4,
            Dtype::F64 => 8,
            Dtype::Bool => 1,
        }
    }

    /// The `descr` string.
    pub fn descr(self) -> &'static str {
        match self {
            Dtype::F32 => "<f4",
            Dtype::F64 => "<f8",
            Dtype::Bool => "|b1",
        }
    }
}

/// A parsed `.npy` array, borrowing its data.
#[derive(Clone, Debug, PartialEq)]
pub struct Npy<'a> {
    /// The data type.
    pub dtype: Dtype,
    /// The shape (C order).
    pub shape: Vec<usize>,
    /// The number of values (the shape's product).
    pub count: usize,
    /// Exactly `count * dtype.size()` bytes of data.
    pub data: &'a [u8],
}

impl Npy<'_> {
    /// The values as f64, in C order.
    pub fn values_f64(&self) -> impl Iterator<Item = f64> + '_ {
        let size = self.dtype.size();
        let dtype = self.dtype;
        self.data.chunks_exact(size).map(move |c| match dtype {
            Dtype::F32 => f64::from(f32::from_le_bytes([c[0], c[1], c[2], c[3]])),
            Dtype::F64 => {
                let mut w = [0u8; 8];
                w.copy_from_slice(c);
                f64::from_le_bytes(w)
            }
            Dtype::Bool => f64::from(u8::from(c[0] != 0)),
        })
    }

    /// The values as f32, in C order (float64 values rounded).
    pub fn values_f32(&self) -> impl Iterator<Item = f32> + '_ {
        self.values_f64().map(|v| v as f32)
    }
}

/// Parses a `.npy` file's bytes (see the module docs); the message says what is wrong.
pub fn parse(bytes: &[u8]) -> Result<Npy<'_>, String> {
    if bytes.len() < 10 || &bytes[..6] != b"\x93NUMPY" {
        return Err("not a .npy file (bad magic)".into());
    }
    let (hlen, start) = match bytes[6] {
        1 => (
            usize::from(u16::from_le_bytes([bytes[8], bytes[9]])),
            10usize,
        ),
        2 | 3 if bytes.len() >= 12 => (
            u32::from_le_bytes([bytes[8], bytes[9], bytes[10], bytes[11]]) as usize,
            12,
        ),
        v => return Err(format!("unsupported .npy version {v}")),
    };
    let end = start.checked_add(hlen).ok_or("header length overflows")?;
    let header = bytes
        .get(start..end)
        .and_then(|h| std::str::from_utf8(h).ok())
        .ok_or("truncated or non-UTF-8 header")?;
    let field = |key: &str| -> Option<&str> {
        let i = header.find(&format!("'{key}'"))? + key.len() + 2;
        Some(header.get(i..)?.trim_start_matches([' ', ':']))
    };
    let descr = field("descr")
        .and_then(|s| s.strip_prefix('\'')?.split('\'').next())
        .ok_or("no 'descr' in header")?;
    let dtype = match descr {
        "<f4" => Dtype::F32,
        "<f8" => Dtype::F64,
        "|b1" => Dtype::Bool,
        d => {
            return Err(format!(
                "dtype {d} is not supported (float32 '<f4', float64 '<f8' or bool '|b1')"
            ))
        }
    };
    if field("fortran_order").is_some_and(|s| s.starts_with("True")) {
        return Err("Fortran-order arrays are not supported".into());
    }
    let shape: Vec<usize> = field("shape")
        .and_then(|s| s.strip_prefix('(')?.split(')').next())
        .ok_or("no 'shape' in header")?
        .split(',')
        .map(str::trim)
        .filter(|s| !s.is_empty())
        .map(|s| s.parse::<usize>())
        .collect::<Result<_, _>>()
        .map_err(|e| format!("bad shape: {e}"))?;
    let count = shape
        .iter()
        .try_fold(1usize, |a, &d| a.checked_mul(d))
        .ok_or_else(|| format!("shape {shape:?} overflows"))?;
    let body = &bytes[end..];
    let need = count
        .checked_mul(dtype.size())
        .filter(|&n| n <= body.len())
        .ok_or_else(|| {
            format!(
                "{} data bytes for {count} values of {descr} (shape {shape:?})",
                body.len()
            )
        })?;
    Ok(Npy {
        dtype,
        shape,
        count,
        data: &body[..need],
    })
}

/// A float32 `.npy` file (format 1.0, C order) of `data` with `shape`. `data.len()` must be
/// the shape's product (a caller's bug otherwise: this panics).
pub fn encode_f32(shape: &[usize], data: &[f32]) -> Vec<u8> {
    assert_eq!(
        shape.iter().product::<usize>(),
        data.len(),
        "shape matches data"
    );
    let dims: Vec<String> = shape.iter().map(|d| d.to_string()).collect();
    let shape_s = if dims.len() == 1 {
        format!("({},)", dims[0])
    } else {
        format!("({})", dims.join(", "))
    };
    let mut header = format!("{{'descr': '<f4', 'fortran_order': False, 'shape': {shape_s}, }}");
    // Pad so that magic (6) + version (2) + length (2) + header + '\n' is a multiple of 64.
    let total = 10 + header.len() + 1;
    header.push_str(&" ".repeat((64 - total % 64) % 64));
    header.push('\n');
    let mut out = Vec::with_capacity(10 + header.len() + 4 * data.len());
    out.extend_from_slice(b"\x93NUMPY\x01\x00");
    out.extend_from_slice(&(header.len() as u16).to_le_bytes());
    out.extend_from_slice(header.as_bytes());
    for v in data {
        out.extend_from_slice(&v.to_le_bytes());
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trip_and_checked_sizes() {
        let b = encode_f32(&[3], &[1.0, 2.5, -3.0]);
        assert_eq!(b.len() % 64, 12);
        let a = parse(&b).unwrap();
        assert_eq!(a.values_f32().collect::<Vec<_>>(), vec![1.0, 2.5, -3.0]);
        // A shape whose product overflows, or more values than the data holds.
        let huge = String::from_utf8_lossy(&b).replace("(3,)", "(4294967296, 4294967296)");
        assert!(parse(huge.as_bytes()).is_err());
        assert!(parse(&b[..b.len() - 1]).unwrap_err().contains("data bytes"));
        assert!(parse(b"\x93NUMPY\x02\x00\xff\xff\xff\xff").is_err());
        assert!(parse(b"nope").is_err());
    }
}
