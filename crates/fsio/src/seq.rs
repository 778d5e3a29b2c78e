//! Numbered file sequences (video frames, simulated frames): the one natural order and the one
//! numbering check every reader of a folder of frames uses.
//!
//! * [`natural_cmp`] orders names with their digit runs compared as numbers, so `frame_2.png`
//!   comes before `frame_10.png` (text order would put `frame_10` first).
//! * [`check_numbering`] finds gaps: names of the form `PREFIX<number>SUFFIX` that share
//!   their prefix and suffix form a sequence, whose numbers must follow each other at one
//!   step (1 for every frame, or a constant stride for a subsampled video). A missing
//!   number, or one number written twice (`frame_1.png` and `frame_01.png`), is a
//!   [`SequenceError`] naming the number.
//!
//! ```
//! use std::path::PathBuf;
//! let mut files: Vec<PathBuf> = ["f_10.png", "f_2.png", "f_1.png"].map(PathBuf::from).to_vec();
//! r4d_fsio::seq::sort_natural(&mut files);
//! assert_eq!(files[2], PathBuf::from("f_10.png"));
//! let gap: Vec<PathBuf> = ["f_1.png", "f_2.png", "f_4.png"].map(PathBuf::from).to_vec();
//! let e = r4d_fsio::seq::check_numbering(&gap).unwrap_err();
//! assert_eq!(e.missing(), Some(3));
//! ```

use std::cmp::Ordering;
use std::fmt;
use std::path::{Path, PathBuf};

/// Compares two names in natural order: runs of ASCII digits compare as numbers (leading
/// zeros aside; a tie in value is broken by the shorter run first), everything else
/// compares as text.
pub fn natural_cmp(a: &str, b: &str) -> Ordering {
    let (a, b) = (a.as_bytes(), b.as_bytes());
    let (mut i, mut j) = (0, 0);
    while i < a.len() && j < b.len() {
        if a[i].is_ascii_digit() && b[j].is_ascii_digit() {
            let ie = run_end(a, i);
            let je = run_end(b, j);
            let (da, db) = (&a[i..ie], &b[j..je]);
            // Compare by value: strip leading zeros, then the longer run is larger.
            let ta = strip_zeros(da);
            let tb = strip_zeros(db);
            let o = ta.len().cmp(&tb.len()).then_with(|| ta.cmp(tb));
            if o != Ordering::Equal {
                return o;
            }
            let o = da.len().cmp(&db.len());
            if o != Ordering::Equal {
                return o;
            }
            i = ie;
            j = je;
        } else {
            let o = a[i].cmp(&b[j]);
            if o != Ordering::Equal {
                return o;
            }
            i += 1;
            j += 1;
        }
    }
    (a.len() - i).cmp(&(b.len() - j))
}

fn run_end(s: &[u8], mut i: usize) -> usize {
    while i < s.len() && s[i].is_ascii_digit() {
        i += 1;
    }
    i
}

fn strip_zeros(d: &[u8]) -> &[u8] {
    let k = d.iter().position(|&c| c != b'0').unwrap_or(d.len());
    &d[k..]
}

/// The file name of a path as text (lossy), for ordering and numbering.
fn name_of(p: &Path) -> String {
    p.file_name()
        .unwrap_or(p.as_os_str())
        .to_string_lossy()
        .into_owned()
}

/// Sorts paths by their file names in natural order ([`natural_cmp`]; full paths break ties).
pub fn sort_natural(paths: &mut [PathBuf]) {
    paths.sort_by(|a, b| natural_cmp(&name_of(a), &name_of(b)).then_with(|| a.cmp(b)));
}

/// A file name split around its last run of digits: `frame_0012.png` is
/// `("frame_", 12, ".png")` with 4 digits.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Numbered {
    /// The text before the number.
    pub prefix: String,
    /// The number.
    pub number: u64,
    /// How many digits the name writes it with (zero padding included).
    pub digits: usize,
    /// The text after the number (the extension included).
    pub suffix: String,
}

impl Numbered {
    /// Splits a file name around its last run of ASCII digits; `None` when it has none (or
    /// the run is longer than 18 digits, so not a frame number).
    pub fn parse(name: &str) -> Option<Numbered> {
        let b = name.as_bytes();
        let end = b.iter().rposition(|c| c.is_ascii_digit())? + 1;
        let start = b[..end]
            .iter()
            .rposition(|c| !c.is_ascii_digit())
            .map_or(0, |k| k + 1);
        if end - start > 18 {
            return None;
        }
        Some(Numbered {
            prefix: name[..start].to_string(),
            number: name[start..end].parse().ok()?,
            digits: end - start,
            suffix: name[end..].to_string(),
        })
    }

    /// The name of number `n` in this name's pattern (same prefix, suffix and padding).
    pub fn name_of(&self, n: u64) -> String {
        format!(
            "{}{n:0width$}{}",
            self.prefix,
            self.suffix,
            width = self.digits
        )
    }
}

/// A numbered sequence of files that is not whole; names the files and the number.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum SequenceError {
    /// A number is missing between two files of one sequence.
    Gap {
        /// The file before the gap.
        before: PathBuf,
        /// The file after it.
        after: PathBuf,
        /// The first missing number.
        missing: u64,
        /// The name the missing file would have.
        missing_name: String,
        /// The sequence's step (1 unless every file is a constant stride apart).
        step: u64,
    },
    /// Two files carry the same number (`frame_1.png` and `frame_01.png`).
    Duplicate {
        /// One file.
        first: PathBuf,
        /// The other.
        second: PathBuf,
        /// The number both carry.
        number: u64,
    },
}

impl SequenceError {
    /// The missing number of a gap.
    pub fn missing(&self) -> Option<u64> {
        match self {
            SequenceError::Gap { missing, .. } => Some(*missing),
            SequenceError::Duplicate { .. } => None,
        }
    }
}

impl fmt::Display for SequenceError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            SequenceError::Gap {
                before,
                after,
                missing,
                missing_name,
                step,
            } => {
                let stride = if *step == 1 {
                    String::new()
                } else {
                    format!(" (the files are numbered every {step})")
                };
                write!(
                    f,
                    "{}: frame {missing} ({missing_name}) is missing from the numbered sequence between {} and {}{stride}",
                    before.parent().unwrap_or(Path::new("")).display(),
                    name_of(before),
                    name_of(after)
                )
            }
            SequenceError::Duplicate {
                first,
                second,
                number,
            } => write!(
                f,
                "{} and {}: both are frame {number} of one numbered sequence",
                first.display(),
                second.display()
            ),
        }
    }
}

impl std::error::Error for SequenceError {}

/// Checks the numbering of a folder's files (see the module docs): every group of two or
/// more names sharing a prefix and suffix around their last number must step evenly, with
/// no number missing and none twice. Names without a number are not part of any sequence.
pub fn check_numbering(paths: &[PathBuf]) -> Result<(), SequenceError> {
    let mut groups: Vec<(Numbered, Vec<(u64, &PathBuf)>)> = Vec::new();
    for p in paths {
        let Some(n) = Numbered::parse(&name_of(p)) else {
            continue;
        };
        match groups
            .iter_mut()
            .find(|(k, _)| k.prefix == n.prefix && k.suffix == n.suffix)
        {
            Some((_, members)) => members.push((n.number, p)),
            None => {
                let number = n.number;
                groups.push((n, vec![(number, p)]));
            }
        }
    }
    for (pattern, mut members) in groups {
        if members.len() < 2 {
            continue;
        }
        members.sort_by_key(|m| m.0);
        if let Some(w) = members.windows(2).find(|w| w[0].0 == w[1].0) {
            return Err(SequenceError::Duplicate {
                first: w[0].1.clone(),
                second: w[1].1.clone(),
                number: w[0].0,
            });
        }
        let step = members
            .windows(2)
            .map(|w| w[1].0 - w[0].0)
            .min()
            .unwrap_or(1);
        if let Some(w) = members.windows(2).find(|w| w[1].0 - w[0].0 != step) {
            let missing = w[0].0 + step;
            let digits = Numbered::parse(&name_of(w[0].1)).map_or(pattern.digits, |n| n.digits);
            let missing_name = Numbered { digits, ..pattern }.name_of(missing);
            return Err(SequenceError::Gap {
                before: w[0].1.clone(),
                after: w[1].1.clone(),
                missing,
                missing_name,
                step,
            });
        }
    }
    Ok(())
}

/// Sorts a folder's frame files naturally ([`sort_natural`]) and checks their numbering
/// ([`check_numbering`]): the order every frame reader uses.
pub fn frame_sequence(mut paths: Vec<PathBuf>) -> Result<Vec<PathBuf>, SequenceError> {
    sort_natural(&mut paths);
    check_numbering(&paths)?;
    Ok(paths)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn paths(names: &[&str]) -> Vec<PathBuf> {
        names.iter().map(|n| PathBuf::from("d").join(n)).collect()
    }

    #[test]
    fn natural_order_compares_numbers_by_value() {
        let mut v = paths(&[
            "frame_10.png",
            "frame_2.png",
            "frame_0.png",
            "frame_1.png",
            "a.png",
            "frame_02.png",
        ]);
        sort_natural(&mut v);
        let names: Vec<String> = v.iter().map(|p| name_of(p)).collect();
        assert_eq!(
            names,
            [
                "a.png",
                "frame_0.png",
                "frame_1.png",
                "frame_2.png",
                "frame_02.png",
                "frame_10.png"
            ]
        );
        assert_eq!(natural_cmp("x9", "x10"), Ordering::Less);
        assert_eq!(natural_cmp("x", "x1"), Ordering::Less);
        assert_eq!(natural_cmp("b1", "a2"), Ordering::Greater);
        assert_eq!(
            natural_cmp("f99999999999999999999999", "f100000000000000000000000"),
            Ordering::Less
        );
    }

    #[test]
    fn gaps_and_duplicates_are_reported_with_the_number() {
        assert!(check_numbering(&paths(&["f_0.png", "f_1.png", "f_2.png"])).is_ok());
        // A constant stride (a subsampled video) is a whole sequence.
        assert!(check_numbering(&paths(&["f_0000.png", "f_0010.png", "f_0020.png"])).is_ok());
        // Names outside the pattern are not part of it; one file is no sequence.
        assert!(check_numbering(&paths(&["f_1.png", "f_2.png", "cover.png", "g_9.png"])).is_ok());
        let e = check_numbering(&paths(&[
            "frame_0001.png",
            "frame_0002.png",
            "frame_0004.png",
        ]))
        .unwrap_err();
        assert_eq!(e.missing(), Some(3));
        let s = e.to_string();
        assert!(s.contains("frame 3") && s.contains("frame_0003.png"), "{s}");
        let e =
            check_numbering(&paths(&["f_0.png", "f_10.png", "f_20.png", "f_40.png"])).unwrap_err();
        assert_eq!(e.missing(), Some(30));
        assert!(e.to_string().contains("every 10"), "{e}");
        let e = check_numbering(&paths(&["f_1.png", "f_01.png"])).unwrap_err();
        assert!(
            matches!(e, SequenceError::Duplicate { number: 1, .. }),
            "{e}"
        );
        // frame_sequence sorts first: text order would put 10 before 2.
        let v = frame_sequence(paths(&["f_10.png", "f_9.png", "f_8.png"])).unwrap();
        assert_eq!(name_of(&v[0]), "f_8.png");
    }

    #[test]
    fn numbered_names_split_at_the_last_digits() {
        let n = Numbered::parse("cam2_frame_0012.png").unwrap();
        assert_eq!(
            (n.prefix.as_str(), n.number, n.digits),
            ("cam2_frame_", 12, 4)
        );
        assert_eq!(n.name_of(7), "cam2_frame_0007.png");
        assert!(Numbered::parse("cover.png").is_none());
        assert!(Numbered::parse("f_1234567890123456789012.png").is_none());
    }
}
