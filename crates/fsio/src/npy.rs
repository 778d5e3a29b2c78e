//! NumPy `.npy` arrays: the one parser and the one writer every crate uses (videos, masks,
//! rendered images). Little-endian float32 (`<f4`), float64 (`<f8`) and bool (`|b1`), C or
//! Fortran order, format versions 1.0 to 3.0. The header is read as numpy reads it (a Python
//! literal dict of exactly `descr`, `fortran_order` and `shape`), and refused where numpy
//! refuses it ([`NpyError`]). Sizes come from the file and are checked: the shape's product
//! must not overflow and the data must hold exactly that many values before anything is
//! allocated.
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
    /// Exactly `count * dtype.size()` bytes of data, in the file's order (see
    /// [`Npy::fortran_order`]; [`Npy::values_f64`] reads them in C order either way).
    pub data: &'a [u8],
    /// Whether the file stores the values in Fortran order (first index fastest), as
    /// `np.save` does for a transposed array.
    pub fortran_order: bool,
}

impl<'a> Npy<'a> {
    /// The values as f64, in C order (last index fastest) whatever the file's order.
    pub fn values_f64(&self) -> Values<'a> {
        let fortran = if self.fortran_order && self.shape.len() > 1 {
            // Fortran strides (in values) of each axis.
            let mut strides = Vec::with_capacity(self.shape.len());
            let mut s = 1usize;
            for &d in &self.shape {
                strides.push(s);
                s = s.saturating_mul(d);
            }
            Some(FortranWalk {
                shape: self.shape.clone(),
                strides,
                index: vec![0usize; self.shape.len()],
                offset: 0,
            })
        } else {
            None
        };
        Values {
            dtype: self.dtype,
            data: self.data,
            next: 0,
            count: self.count,
            fortran,
        }
    }

    /// The values as f32, in C order (float64 values rounded).
    pub fn values_f32(&self) -> impl Iterator<Item = f32> + 'a {
        self.values_f64().map(|v| v as f32)
    }
}

/// The values of an [`Npy`] as f64, in C order ([`Npy::values_f64`]).
#[derive(Clone, Debug)]
pub struct Values<'a> {
    dtype: Dtype,
    data: &'a [u8],
    next: usize,
    count: usize,
    /// Fortran order: where the next C-order value is in the file.
    fortran: Option<FortranWalk>,
}

/// The walk of a Fortran-order array in C order: the shape, each axis's Fortran stride (in
/// values), the current C-order index and its offset in the data.
#[derive(Clone, Debug)]
struct FortranWalk {
    shape: Vec<usize>,
    strides: Vec<usize>,
    index: Vec<usize>,
    offset: usize,
}

impl Iterator for Values<'_> {
    type Item = f64;

    fn next(&mut self) -> Option<f64> {
        if self.next >= self.count {
            return None;
        }
        let at = match &mut self.fortran {
            None => self.next,
            Some(w) => {
                let at = w.offset;
                // Step the C-order index (last axis fastest), keeping its Fortran offset.
                for k in (0..w.shape.len()).rev() {
                    w.index[k] += 1;
                    w.offset += w.strides[k];
                    if w.index[k] < w.shape[k] {
                        break;
                    }
                    w.offset -= w.strides[k] * w.shape[k];
                    w.index[k] = 0;
                }
                at
            }
        };
        self.next += 1;
        let size = self.dtype.size();
        let c = &self.data[at * size..(at + 1) * size];
        Some(match self.dtype {
            Dtype::F32 => f64::from(f32::from_le_bytes([c[0], c[1], c[2], c[3]])),
            Dtype::F64 => {
                let mut w = [0u8; 8];
                w.copy_from_slice(c);
                f64::from_le_bytes(w)
            }
            Dtype::Bool => f64::from(u8::from(c[0] != 0)),
        })
    }

    fn size_hint(&self) -> (usize, Option<usize>) {
        let n = self.count - self.next;
        (n, Some(n))
    }
}

impl ExactSizeIterator for Values<'_> {}

/// Why a `.npy` file was refused: what numpy refuses (a header that is not a Python literal
/// dict of exactly `descr`, `fortran_order` and `shape`, a shape that is not a tuple of
/// non-negative ints, too little data) and what this reader does not support (dtypes other
/// than `<f4`, `<f8`, `|b1`). Callers' errors name the file.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum NpyError {
    /// The magic string or the format version.
    Format(String),
    /// The header: its length, its Python literal syntax, its keys or their values.
    Header(String),
    /// A dtype this reader does not support (the `descr`).
    Dtype(String),
    /// The shape's size or the data's length.
    Size(String),
}

impl std::fmt::Display for NpyError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            NpyError::Format(m) | NpyError::Size(m) => f.write_str(m),
            NpyError::Header(m) => write!(f, "bad .npy header: {m}"),
            NpyError::Dtype(d) => write!(
                f,
                "dtype {d} is not supported (float32 '<f4', float64 '<f8' or bool '|b1')"
            ),
        }
    }
}

impl std::error::Error for NpyError {}

/// A Python literal of a `.npy` header (what `ast.literal_eval` reads, as far as headers go).
#[derive(Clone, Debug, PartialEq)]
enum Lit {
    Str(String),
    Bool(bool),
    None,
    /// An integer: its sign and magnitude (`None`: beyond 64 bits).
    Int(bool, Option<u64>),
    Float,
    Tuple(Vec<Lit>),
    List(Vec<Lit>),
    Dict(Vec<(Lit, Lit)>),
}

impl Lit {
    fn kind(&self) -> &'static str {
        match self {
            Lit::Str(_) => "a string",
            Lit::Bool(_) => "a bool",
            Lit::None => "None",
            Lit::Int(..) => "an int",
            Lit::Float => "a float",
            Lit::Tuple(_) => "a tuple",
            Lit::List(_) => "a list",
            Lit::Dict(_) => "a dict",
        }
    }
}

/// A recursive-descent reader of the Python literal subset `.npy` headers use.
struct LitParser<'s> {
    s: &'s [char],
    i: usize,
    depth: usize,
}

impl LitParser<'_> {
    fn err(&self, what: &str) -> NpyError {
        let near: String = self.s[self.i.min(self.s.len())..].iter().take(16).collect();
        NpyError::Header(format!(
            "not a Python literal: {what} at character {} (near {near:?})",
            self.i
        ))
    }

    fn ws(&mut self) {
        while self.i < self.s.len() && matches!(self.s[self.i], ' ' | '\t' | '\n' | '\r' | '\x0c') {
            self.i += 1;
        }
    }

    fn peek(&self) -> Option<char> {
        self.s.get(self.i).copied()
    }

    fn eat(&mut self, c: char) -> bool {
        self.ws();
        if self.peek() == Some(c) {
            self.i += 1;
            true
        } else {
            false
        }
    }

    fn value(&mut self) -> Result<Lit, NpyError> {
        self.ws();
        self.depth += 1;
        if self.depth > 32 {
            return Err(self.err("nesting deeper than 32"));
        }
        let v = match self.peek() {
            Some('{') => {
                self.i += 1;
                let mut items = Vec::new();
                loop {
                    if self.eat('}') {
                        break;
                    }
                    let k = self.value()?;
                    if !self.eat(':') {
                        return Err(self.err("expected ':'"));
                    }
                    let v = self.value()?;
                    items.push((k, v));
                    if self.eat(',') {
                        continue;
                    }
                    if self.eat('}') {
                        break;
                    }
                    return Err(self.err("expected ',' or '}'"));
                }
                Lit::Dict(items)
            }
            Some(open @ ('(' | '[')) => {
                self.i += 1;
                let close = if open == '(' { ')' } else { ']' };
                let mut items = Vec::new();
                let mut comma = false;
                loop {
                    if self.eat(close) {
                        break;
                    }
                    items.push(self.value()?);
                    if self.eat(',') {
                        comma = true;
                        continue;
                    }
                    if self.eat(close) {
                        break;
                    }
                    return Err(self.err(&format!("expected ',' or '{close}'")));
                }
                if open == '[' {
                    Lit::List(items)
                } else if items.len() == 1 && !comma {
                    // `(3)` is the int 3, not a tuple.
                    items.pop().expect("one item")
                } else {
                    Lit::Tuple(items)
                }
            }
            Some(q @ ('\'' | '"')) => {
                self.i += 1;
                let mut out = String::new();
                loop {
                    match self.peek() {
                        None | Some('\n') => return Err(self.err("unterminated string")),
                        Some('\\') => return Err(self.err("escape in a string")),
                        Some(c) if c == q => {
                            self.i += 1;
                            break;
                        }
                        Some(c) => {
                            out.push(c);
                            self.i += 1;
                        }
                    }
                }
                Lit::Str(out)
            }
            Some(c) if c == '-' || c == '+' || c.is_ascii_digit() || c == '.' => self.number()?,
            Some(c) if c.is_ascii_alphabetic() || c == '_' => {
                let start = self.i;
                while self
                    .peek()
                    .is_some_and(|c| c.is_ascii_alphanumeric() || c == '_')
                {
                    self.i += 1;
                }
                let word: String = self.s[start..self.i].iter().collect();
                match word.as_str() {
                    "True" => Lit::Bool(true),
                    "False" => Lit::Bool(false),
                    "None" => Lit::None,
                    _ => {
                        self.i = start;
                        return Err(self.err(&format!("the name '{word}'")));
                    }
                }
            }
            _ => return Err(self.err("expected a value")),
        };
        self.depth -= 1;
        Ok(v)
    }

    /// An int (decimal with `_` between digits, or `0x`, `0o`, `0b`) or a float, with signs.
    fn number(&mut self) -> Result<Lit, NpyError> {
        let mut neg = false;
        while let Some(c @ ('-' | '+')) = self.peek() {
            neg ^= c == '-';
            self.i += 1;
            self.ws();
        }
        let start = self.i;
        while self
            .peek()
            .is_some_and(|c| c.is_ascii_alphanumeric() || c == '_' || c == '.')
        {
            self.i += 1;
        }
        let tok: String = self.s[start..self.i].iter().collect();
        let lower = tok.to_ascii_lowercase();
        let (radix, digits) = match lower.get(..2) {
            Some("0x") => (16, &lower[2..]),
            Some("0o") => (8, &lower[2..]),
            Some("0b") => (2, &lower[2..]),
            _ => (10, lower.as_str()),
        };
        let ok_underscores = !digits.is_empty()
            && !digits.starts_with('_')
            && !digits.ends_with('_')
            && !digits.contains("__");
        let plain = digits.replace('_', "");
        if ok_underscores && !plain.is_empty() && plain.chars().all(|c| c.is_digit(radix)) {
            // Python 3 refuses decimal ints with a leading zero (`007`), except zero itself.
            if radix == 10
                && plain.len() > 1
                && plain.starts_with('0')
                && !plain.trim_start_matches('0').is_empty()
            {
                self.i = start;
                return Err(self.err("an int with a leading zero"));
            }
            let v = u64::from_str_radix(&plain, radix).ok();
            let v = v.or_else(|| plain.chars().all(|c| c == '0').then_some(0));
            return Ok(Lit::Int(neg, v));
        }
        if radix == 10 && plain.parse::<f64>().is_ok() {
            return Ok(Lit::Float);
        }
        self.i = start;
        Err(self.err(&format!("the number '{tok}'")))
    }
}

/// The header dict's three keys, each checked as numpy checks them.
fn read_header(header: &[char]) -> Result<(String, bool, Vec<usize>), NpyError> {
    let mut p = LitParser {
        s: header,
        i: 0,
        depth: 0,
    };
    let v = p.value()?;
    p.ws();
    if p.i != header.len() {
        return Err(p.err("text after the header dict"));
    }
    let Lit::Dict(items) = v else {
        return Err(NpyError::Header(format!(
            "the header is {}, not a dict",
            v.kind()
        )));
    };
    let mut descr = None;
    let mut fortran = None;
    let mut shape = None;
    for (k, v) in items {
        let key = match &k {
            Lit::Str(s) => s.as_str(),
            other => {
                return Err(NpyError::Header(format!(
                    "a key is {}, not a string",
                    other.kind()
                )))
            }
        };
        let slot = match key {
            "descr" => &mut descr,
            "fortran_order" => &mut fortran,
            "shape" => &mut shape,
            _ => {
                return Err(NpyError::Header(format!(
                    "unexpected key '{key}' (the header holds exactly 'descr', 'fortran_order' and 'shape')"
                )))
            }
        };
        if slot.replace(v).is_some() {
            return Err(NpyError::Header(format!("key '{key}' appears twice")));
        }
    }
    let missing = |k: &str| {
        NpyError::Header(format!(
            "no '{k}' (the header holds exactly 'descr', 'fortran_order' and 'shape')"
        ))
    };
    let descr = match descr.ok_or_else(|| missing("descr"))? {
        Lit::Str(s) => s,
        other => return Err(NpyError::Dtype(format!("{other:?}"))),
    };
    let fortran = match fortran.ok_or_else(|| missing("fortran_order"))? {
        Lit::Bool(b) => b,
        other => {
            return Err(NpyError::Header(format!(
                "'fortran_order' is {}, not True or False",
                other.kind()
            )))
        }
    };
    let shape = match shape.ok_or_else(|| missing("shape"))? {
        Lit::Tuple(dims) => dims
            .iter()
            .map(|d| match d {
                Lit::Int(false, Some(n)) => usize::try_from(*n)
                    .map_err(|_| NpyError::Size(format!("shape dimension {n} overflows"))),
                Lit::Int(false, None) => {
                    Err(NpyError::Size("a shape dimension is beyond 64 bits".into()))
                }
                Lit::Int(true, _) => Err(NpyError::Header("a shape dimension is negative".into())),
                other => Err(NpyError::Header(format!(
                    "a shape dimension is {}, not an int",
                    other.kind()
                ))),
            })
            .collect::<Result<Vec<usize>, NpyError>>()?,
        other => {
            return Err(NpyError::Header(format!(
                "'shape' is {}, not a tuple of ints",
                other.kind()
            )))
        }
    };
    Ok((descr, fortran, shape))
}

/// Parses a `.npy` file's bytes (see the module docs), as strictly as numpy reads them: the
/// magic and a version numpy writes (1.0, 2.0, 3.0), a header that fits the file and is a
/// Python literal dict of exactly `descr`, `fortran_order` (a bool) and `shape` (a tuple of
/// non-negative ints) followed only by whitespace, and exactly the data the shape needs (too
/// little, or bytes left over, is an error). Fortran-order arrays are read
/// ([`Npy::values_f64`] gives C order).
pub fn parse(bytes: &[u8]) -> Result<Npy<'_>, NpyError> {
    if bytes.len() < 10 || &bytes[..6] != b"\x93NUMPY" {
        return Err(NpyError::Format("not a .npy file (bad magic)".into()));
    }
    let (major, minor) = (bytes[6], bytes[7]);
    let (hlen, start) = match (major, minor) {
        (1, 0) => (
            usize::from(u16::from_le_bytes([bytes[8], bytes[9]])),
            10usize,
        ),
        (2 | 3, 0) if bytes.len() >= 12 => (
            u32::from_le_bytes([bytes[8], bytes[9], bytes[10], bytes[11]]) as usize,
            12,
        ),
        (2 | 3, 0) => return Err(NpyError::Format("truncated .npy preamble".into())),
        (v, m) => {
            return Err(NpyError::Format(format!(
                "unsupported .npy version {v}.{m} (1.0, 2.0 or 3.0)"
            )))
        }
    };
    let end = start
        .checked_add(hlen)
        .ok_or_else(|| NpyError::Header("header length overflows".into()))?;
    let raw = bytes.get(start..end).ok_or_else(|| {
        NpyError::Header(format!(
            "the header length is {hlen} bytes, the file has {} after the preamble",
            bytes.len() - start
        ))
    })?;
    // Versions 1 and 2 store the header in latin-1, version 3 in UTF-8.
    let header: Vec<char> = if major == 3 {
        std::str::from_utf8(raw)
            .map_err(|_| NpyError::Header("a version 3.0 header is not UTF-8".into()))?
            .chars()
            .collect()
    } else {
        raw.iter().map(|&b| char::from(b)).collect()
    };
    let (descr, fortran_order, shape) = read_header(&header)?;
    let dtype = match descr.as_str() {
        "<f4" => Dtype::F32,
        "<f8" => Dtype::F64,
        "|b1" => Dtype::Bool,
        _ => return Err(NpyError::Dtype(descr)),
    };
    let count = shape
        .iter()
        .try_fold(1usize, |a, &d| a.checked_mul(d))
        .ok_or_else(|| NpyError::Size(format!("shape {shape:?} overflows")))?;
    let body = &bytes[end..];
    let need = count
        .checked_mul(dtype.size())
        .filter(|&n| n == body.len())
        .ok_or_else(|| {
            NpyError::Size(format!(
                "{} data bytes for {count} values of {descr} (shape {shape:?}; {} bytes expected)",
                body.len(),
                count.saturating_mul(dtype.size())
            ))
        })?;
    Ok(Npy {
        dtype,
        shape,
        count,
        data: &body[..need],
        fortran_order,
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
        assert!(parse(&b[..b.len() - 1])
            .unwrap_err()
            .to_string()
            .contains("data bytes"));
        assert!(parse(b"\x93NUMPY\x02\x00\xff\xff\xff\xff").is_err());
        assert!(parse(b"nope").is_err());
    }

    /// A version-1 `.npy` with `header` padded as numpy pads it and `body`.
    fn npy(header: &str, body: &[u8]) -> Vec<u8> {
        let mut h = header.to_string();
        let total = 10 + h.len() + 1;
        h.push_str(&" ".repeat((64 - total % 64) % 64));
        h.push('\n');
        let mut out = b"\x93NUMPY\x01\x00".to_vec();
        out.extend_from_slice(&(h.len() as u16).to_le_bytes());
        out.extend_from_slice(h.as_bytes());
        out.extend_from_slice(body);
        out
    }

    #[test]
    fn headers_numpy_refuses_are_refused() {
        let body = [0u8; 24];
        // What numpy writes, and what it reads besides (no trailing comma, double quotes,
        // other key order, spaces).
        for ok in [
            "{'descr': '<f4', 'fortran_order': False, 'shape': (2, 3), }",
            "{'descr': '<f4', 'fortran_order': False, 'shape': (2, 3)}",
            "{\"shape\": (6,), \"fortran_order\": False, \"descr\": \"<f4\"}",
            "{ 'descr' : '<f4' , 'fortran_order' : False , 'shape' : ( 2 , 3 , ) }",
            "{'descr': '<f8', 'fortran_order': True, 'shape': (3,)}",
            "{'descr': '<f4', 'fortran_order': False, 'shape': (0x2, 1_0 ,)}",
        ] {
            let body = if ok.contains("1_0") {
                &[0u8; 80][..]
            } else {
                &body[..]
            };
            let f = npy(ok, body);
            parse(&f).unwrap_or_else(|e| panic!("{ok}: {e}"));
        }
        for (bad, why) in [
            ("{'descr': '<f4', 'shape': (6,)}", "no 'fortran_order'"),
            (
                "{'descr': '<f4', 'fortran_order': False, 'shape': (6,), 'extra': 1}",
                "unexpected key 'extra'",
            ),
            (
                "{'descr': '<f4', 'descr': '<f4', 'fortran_order': False, 'shape': (6,)}",
                "twice",
            ),
            (
                "{'descr': '<f4', 'fortran_order': False, 'shape': [6]}",
                "a list",
            ),
            (
                "{'descr': '<f4', 'fortran_order': False, 'shape': (6)}",
                "an int",
            ),
            (
                "{'descr': '<f4', 'fortran_order': False, 'shape': (-6,)}",
                "negative",
            ),
            (
                "{'descr': '<f4', 'fortran_order': False, 'shape': (6.0,)}",
                "a float",
            ),
            (
                "{'descr': '<f4', 'fortran_order': False, 'shape': (True,)}",
                "a bool",
            ),
            (
                "{'descr': '<f4', 'fortran_order': 0, 'shape': (6,)}",
                "not True or False",
            ),
            (
                "{'descr': '<f4', 'fortran_order': false, 'shape': (6,)}",
                "the name 'false'",
            ),
            (
                "{'descr': '<f4', 'fortran_order': False, 'shape': (6,)} x",
                "after the header",
            ),
            (
                "{'descr': '<f4', 'fortran_order': False, 'shape': (6,)",
                "expected",
            ),
            (
                "{'descr': '<f4' 'fortran_order': False, 'shape': (6,)}",
                "expected",
            ),
            (
                "{'descr': <f4, 'fortran_order': False, 'shape': (6,)}",
                "expected a value",
            ),
            (
                "{'descr': '<f4', 'fortran_order': False, 'shape': (06,)}",
                "leading zero",
            ),
            ("('descr', '<f4')", "not a dict"),
            (
                "{'descr': '<i4', 'fortran_order': False, 'shape': (6,)}",
                "<i4",
            ),
            (
                "{'descr': '<f4', 'fortran_order': False, 'shape': (99999999999999999999999,)}",
                "64 bits",
            ),
        ] {
            let e = parse(&npy(bad, &body)).expect_err(bad).to_string();
            assert!(e.contains(why), "{bad}: {e}");
        }
        let good = npy(
            "{'descr': '<f4', 'fortran_order': False, 'shape': (6,)}",
            &body,
        );
        // Bytes left over after the data, a minor version, a header longer than the file.
        let mut long = good.clone();
        long.push(0);
        assert!(parse(&long)
            .unwrap_err()
            .to_string()
            .contains("25 data bytes"));
        let mut minor = good.clone();
        minor[7] = 1;
        assert!(parse(&minor).unwrap_err().to_string().contains("1.1"));
        let mut hlen = good.clone();
        hlen[8] = 0xff;
        hlen[9] = 0xff;
        assert!(parse(&hlen)
            .unwrap_err()
            .to_string()
            .contains("header length"));
    }

    #[test]
    fn fortran_order_arrays_read_in_c_order() {
        // The 2 x 3 array [[0, 1, 2], [3, 4, 5]] stored column by column.
        let data: Vec<u8> = [0.0f32, 3.0, 1.0, 4.0, 2.0, 5.0]
            .iter()
            .flat_map(|v| v.to_le_bytes())
            .collect();
        let f = npy(
            "{'descr': '<f4', 'fortran_order': True, 'shape': (2, 3), }",
            &data,
        );
        let a = parse(&f).unwrap();
        assert!(a.fortran_order);
        assert_eq!(
            a.values_f32().collect::<Vec<_>>(),
            [0.0, 1.0, 2.0, 3.0, 4.0, 5.0]
        );
        // Three axes: element (i, j, k) of a 2 x 2 x 2 array is at i + 2 j + 4 k.
        let vals: Vec<u8> = (0..8)
            .map(|f| {
                let (i, j, k) = (f % 2, (f / 2) % 2, f / 4);
                (i * 4 + j * 2 + k) as f64
            })
            .flat_map(|v| v.to_le_bytes())
            .collect();
        let f = npy(
            "{'descr': '<f8', 'fortran_order': True, 'shape': (2, 2, 2), }",
            &vals,
        );
        let got: Vec<f64> = parse(&f).unwrap().values_f64().collect();
        assert_eq!(got, (0..8).map(f64::from).collect::<Vec<_>>());
    }
}
