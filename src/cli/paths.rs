//! Where a command reads and where it writes, checked before any work.
//!
//! Every command declares its inputs and outputs ([`Io`]); [`Io::check`] resolves them
//! (canonical paths, symbolic links followed; an output that does not exist yet is resolved
//! through its nearest existing folder) and refuses, naming both flags:
//! * an output that is an input;
//! * an output folder that contains an input (writing into it could replace the input, or add
//!   files the command would later read as input);
//! * an output inside an input folder the command reads;
//! * two outputs that are the same path.
//!
//! A command that writes a folder of results claims it with [`claim_dir`]: an empty or new
//! folder is used as is; a non-empty one must be a run of the same command and the user must
//! say what to do with it: `--resume` continues it, `--overwrite` removes the earlier run's
//! files first. Two runs are never mixed in one folder, and a folder that is not a run of
//! r4d (no [`RUN_MARKER`], none of the command's own files) is never written into or
//! emptied.

use anyhow::{bail, Context, Result};
use std::path::{Component, Path, PathBuf};

/// The file that marks a folder as the run folder of an r4d command (JSON:
/// `{"command": NAME}`).
pub const RUN_MARKER: &str = ".r4d-run";

/// The largest marker file read (it holds one short JSON object).
const MAX_MARKER_BYTES: u64 = 4096;

/// A command's inputs and outputs, by flag.
#[derive(Default)]
pub struct Io {
    inputs: Vec<(String, PathBuf)>,
    outputs: Vec<(String, PathBuf)>,
}

impl Io {
    /// No paths yet.
    pub fn new() -> Io {
        Io::default()
    }
    /// An input (a file or a folder the command reads).
    pub fn input(mut self, flag: &str, path: &Path) -> Io {
        self.inputs.push((flag.to_string(), path.to_path_buf()));
        self
    }
    /// An optional input.
    pub fn input_opt(self, flag: &str, path: Option<&Path>) -> Io {
        match path {
            Some(p) => self.input(flag, p),
            None => self,
        }
    }
    /// Several inputs given by one (repeatable) flag.
    pub fn inputs<'a>(mut self, flag: &str, paths: impl IntoIterator<Item = &'a PathBuf>) -> Io {
        for p in paths {
            self = self.input(flag, p);
        }
        self
    }
    /// An output (a file or a folder the command writes).
    pub fn output(mut self, flag: &str, path: &Path) -> Io {
        self.outputs.push((flag.to_string(), path.to_path_buf()));
        self
    }
    /// An optional output.
    pub fn output_opt(self, flag: &str, path: Option<&Path>) -> Io {
        match path {
            Some(p) => self.output(flag, p),
            None => self,
        }
    }

    /// Refuses outputs that would touch an input, or each other (see the module docs).
    pub fn check(&self) -> Result<()> {
        let inputs: Vec<(&str, &Path, PathBuf, bool)> = self
            .inputs
            .iter()
            .map(|(f, p)| (f.as_str(), p.as_path(), resolve(p), p.is_dir()))
            .collect();
        let outputs: Vec<(&str, &Path, PathBuf)> = self
            .outputs
            .iter()
            .map(|(f, p)| (f.as_str(), p.as_path(), resolve(p)))
            .collect();
        for (of, op, ro) in &outputs {
            for (inf, ip, ri, in_dir) in &inputs {
                let (o, i) = (op.display(), ip.display());
                if ro == ri {
                    bail!("{of} {o} is {inf} {i}: the command would overwrite its input; write the output elsewhere");
                }
                if ri.starts_with(ro) {
                    bail!("{of} {o} contains {inf} {i}: writing there could replace the input or mix outputs into it; write the output elsewhere");
                }
                if *in_dir && ro.starts_with(ri) {
                    bail!("{of} {o} is inside {inf} {i}, a folder the command reads: write the output elsewhere");
                }
            }
        }
        for (a, (af, ap, ra)) in outputs.iter().enumerate() {
            for (bf, bp, rb) in &outputs[a + 1..] {
                if ra == rb || rb.starts_with(ra) || ra.starts_with(rb) {
                    bail!(
                        "{af} {} and {bf} {} overlap: each output needs its own path",
                        ap.display(),
                        bp.display()
                    );
                }
            }
        }
        Ok(())
    }
}

/// `path` made absolute with symbolic links followed: canonical when it exists, else the
/// canonical form of its nearest existing ancestor joined with the rest (`.` and `..`
/// resolved lexically there).
pub fn resolve(path: &Path) -> PathBuf {
    if let Ok(p) = path.canonicalize() {
        return p;
    }
    let abs = if path.is_absolute() {
        path.to_path_buf()
    } else {
        std::env::current_dir()
            .unwrap_or_else(|_| PathBuf::from("/"))
            .join(path)
    };
    let mut existing = abs.as_path();
    let mut rest: Vec<Component> = Vec::new();
    while !existing.exists() {
        match (existing.parent(), existing.components().next_back()) {
            (Some(parent), Some(last)) => {
                rest.push(last);
                existing = parent;
            }
            _ => break,
        }
    }
    let mut out = existing
        .canonicalize()
        .unwrap_or_else(|_| existing.to_path_buf());
    for c in rest.into_iter().rev() {
        match c {
            Component::CurDir => {}
            Component::ParentDir => {
                out.pop();
            }
            other => out.push(other.as_os_str()),
        }
    }
    out
}

/// What to do with a non-empty output folder.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Existing {
    /// Refuse it (neither `--resume` nor `--overwrite` given).
    Refuse,
    /// Continue the run in it (`--resume`).
    Resume,
    /// Remove the earlier run's files first (`--overwrite`).
    Overwrite,
}

impl Existing {
    /// From a command's `--resume` and `--overwrite` flags (clap keeps them exclusive).
    pub fn from_flags(resume: bool, overwrite: bool) -> Existing {
        if overwrite {
            Existing::Overwrite
        } else if resume {
            Existing::Resume
        } else {
            Existing::Refuse
        }
    }
}

/// Claims `dir` (given by `flag`) as the run folder of `command`: creates it when missing and
/// marks it. A non-empty folder must be a run of `command` (its [`RUN_MARKER`], or for a run
/// written before markers existed one of `signature`, files every run of the command
/// writes); then `existing` decides: continue it, or empty it first. Returns whether an
/// earlier run is continued (`--resume` of an empty or missing folder starts a new one).
pub fn claim_dir(
    flag: &str,
    dir: &Path,
    command: &str,
    signature: &[&str],
    existing: Existing,
) -> Result<bool> {
    let shown = dir.display();
    if dir.exists() && !dir.is_dir() {
        bail!("{flag} {shown} is a file; it must be a folder (new or empty, or an earlier run of r4d {command})");
    }
    let entries: Vec<PathBuf> = if dir.is_dir() {
        std::fs::read_dir(dir)
            .with_context(|| format!("{flag}: reading {shown}"))?
            .map(|e| e.map(|e| e.path()))
            .collect::<std::io::Result<_>>()
            .with_context(|| format!("{flag}: reading {shown}"))?
    } else {
        Vec::new()
    };
    let resumed = if entries.is_empty() {
        // Nothing to continue: `--resume` of a run killed before it wrote anything starts it.
        false
    } else {
        let owner = run_owner(dir, command, signature)?;
        match (owner.as_deref(), existing) {
            (Some(c), Existing::Resume) if c == command => true,
            (Some(c), Existing::Overwrite) if c == command => {
                for e in &entries {
                    let r = if e.is_dir() && !e.is_symlink() {
                        std::fs::remove_dir_all(e)
                    } else {
                        std::fs::remove_file(e)
                    };
                    r.with_context(|| {
                        format!("--overwrite: removing {} of the earlier run", e.display())
                    })?;
                }
                false
            }
            (Some(c), Existing::Refuse) if c == command => bail!(
                "{flag} {shown} holds an earlier run of r4d {command}: continue it with --resume, or replace it with --overwrite (removes its files first)"
            ),
            (Some(c), _) => bail!(
                "{flag} {shown} holds a run of r4d {c}, not of r4d {command}: choose a new or empty folder"
            ),
            (None, _) => bail!(
                "{flag} {shown} is not empty and is not a run folder of r4d {command}: choose a new or empty folder (r4d never writes into or empties a folder of other files)"
            ),
        }
    };
    std::fs::create_dir_all(dir).with_context(|| format!("{flag}: creating {shown}"))?;
    let marker = serde_json::json!({ "command": command }).to_string();
    r4d_fsio::write_atomic(&dir.join(RUN_MARKER), marker.as_bytes())
        .with_context(|| format!("{flag}: marking {shown} as a run of r4d {command}"))?;
    Ok(resumed)
}

/// The command whose run `dir` holds: its marker's, else `command` when one of `signature`
/// is there (a run from before markers), else none.
fn run_owner(dir: &Path, command: &str, signature: &[&str]) -> Result<Option<String>> {
    let marker = dir.join(RUN_MARKER);
    if marker.is_file() {
        let bytes = r4d_fsio::read_bounded(&marker, MAX_MARKER_BYTES)
            .with_context(|| format!("reading {}", marker.display()))?;
        let v: serde_json::Value = serde_json::from_slice(&bytes)
            .with_context(|| format!("{}: not an r4d run marker", marker.display()))?;
        return match v.get("command").and_then(|c| c.as_str()) {
            Some(c) => Ok(Some(c.to_string())),
            None => bail!(
                "{}: not an r4d run marker (no \"command\")",
                marker.display()
            ),
        };
    }
    Ok(signature
        .iter()
        .any(|s| dir.join(s).exists())
        .then(|| command.to_string()))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tmp(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("r4d-paths-{}-{name}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    #[test]
    fn outputs_that_touch_inputs_are_refused_through_links_and_dots() {
        let d = tmp("touch");
        std::fs::write(d.join("scene.ply"), b"x").unwrap();
        std::fs::create_dir_all(d.join("video")).unwrap();
        let same = Io::new()
            .input("--scene", &d.join("scene.ply"))
            .output("--out", &d.join("sub/../scene.ply"));
        let e = same.check().unwrap_err().to_string();
        assert!(e.contains("--out") && e.contains("--scene"), "{e}");
        #[cfg(unix)]
        {
            std::os::unix::fs::symlink(d.join("scene.ply"), d.join("link.ply")).unwrap();
            let linked = Io::new()
                .input("--scene", &d.join("scene.ply"))
                .output("--out", &d.join("link.ply"));
            assert!(linked.check().is_err());
        }
        let contains = Io::new()
            .input("--video", &d.join("video"))
            .output("--out", &d);
        assert!(contains.check().is_err());
        let inside = Io::new()
            .input("--video", &d.join("video"))
            .output("--out", &d.join("video/run"));
        assert!(inside.check().is_err());
        let twice = Io::new()
            .output("--out", &d.join("a.png"))
            .output("--out-raw", &d.join("./a.png"));
        assert!(twice.check().is_err());
        // Beside a file input is fine.
        let beside = Io::new()
            .input("--scene", &d.join("scene.ply"))
            .output("--out", &d.join("labels.json"));
        beside.check().unwrap();
    }

    #[test]
    fn run_folders_are_resumed_or_overwritten_never_mixed() {
        let d = tmp("claim");
        let run = d.join("run");
        assert!(!claim_dir("--out", &run, "simulate", &[], Existing::Refuse).unwrap());
        std::fs::write(run.join("frame_0001.ply"), b"x").unwrap();
        let e = claim_dir("--out", &run, "simulate", &[], Existing::Refuse).unwrap_err();
        assert!(e.to_string().contains("--overwrite"), "{e}");
        assert!(claim_dir("--out", &run, "simulate", &[], Existing::Resume).unwrap());
        assert!(run.join("frame_0001.ply").exists());
        assert!(claim_dir("--out", &run, "fit", &[], Existing::Overwrite).is_err());
        assert!(!claim_dir("--out", &run, "simulate", &[], Existing::Overwrite).unwrap());
        assert!(!run.join("frame_0001.ply").exists());
        // A folder of other files is never used, even with --overwrite.
        let user = d.join("user");
        std::fs::create_dir_all(&user).unwrap();
        std::fs::write(user.join("notes.txt"), b"mine").unwrap();
        for how in [Existing::Refuse, Existing::Resume, Existing::Overwrite] {
            assert!(claim_dir("--out", &user, "simulate", &[], how).is_err());
        }
        assert!(user.join("notes.txt").exists());
        // A run from before markers is recognised by its own files.
        std::fs::write(user.join("state.r4d"), b"s").unwrap();
        assert!(claim_dir("--out", &user, "simulate", &["state.r4d"], Existing::Resume).unwrap());
        // --resume of nothing starts a run.
        assert!(!claim_dir("--out", &d.join("new"), "simulate", &[], Existing::Resume).unwrap());
    }
}
