//! Options every command checks the same way before any
//! work (one validation path), sizes a user can ask for bounded, resume state checked against
//! what it resumes. Each case must be a typed error that names the flag or file; none may
//! panic, hang or write a result.

use std::path::{Path, PathBuf};
use std::process::Command;

/// Runs `r4d args`.
pub(crate) fn r4d(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_r4d"))
        .args(args)
        .output()
        .unwrap()
}

fn repo(rel: &str) -> String {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join(rel)
        .display()
        .to_string()
}

fn out_dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("r4d_hostile_{}_{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    d
}

/// Runs `r4d args`, expects a failure whose message contains every `needle`.
pub(crate) fn refused(args: &[&str], needles: &[&str]) -> String {
    let o = r4d(args);
    let err = String::from_utf8_lossy(&o.stderr).to_string();
    assert!(!o.status.success(), "{args:?} was accepted: {err}");
    assert!(!err.contains("panicked"), "{args:?} panicked: {err}");
    for n in needles {
        assert!(err.contains(n), "{args:?}: '{n}' not in: {err}");
    }
    err
}

#[test]
fn fit_trajectory_refuses_what_fit_refuses_before_writing() {
    let out = out_dir("fit_traj");
    let base = |extra: &[&str]| -> Vec<String> {
        let mut v: Vec<String> = [
            "fit-trajectory",
            "--config",
            &repo("tests/fixtures/fit/beam_start.toml"),
            "--target",
            "/nonexistent-targets",
            "--params",
            "E",
            "--out",
            out.to_str().unwrap(),
        ]
        .iter()
        .map(|s| s.to_string())
        .collect();
        v.extend(extra.iter().map(|s| s.to_string()));
        v
    };
    for (extra, needles) in [
        (&["--beta1", "1.5"][..], &["--beta1", "[0, 1)"][..]),
        (&["--beta2=-0.1"][..], &["--beta2"][..]),
        (&["--lr", "0"][..], &["--lr"][..]),
        (
            &["--checkpointing", "every:0"][..],
            &["--checkpointing", "K >= 1"][..],
        ),
        (
            &["--checkpointing", "nested:x"][..],
            &["--checkpointing"][..],
        ),
    ] {
        let args = base(extra);
        let args: Vec<&str> = args.iter().map(|s| s.as_str()).collect();
        refused(&args, needles);
        assert!(!out.join("log.jsonl").exists(), "{extra:?}: wrote a log");
    }
}

#[test]
fn dataset_options_without_a_dataset_are_refused() {
    let out = out_dir("fit_dataset_opts");
    for (flag, value) in [("--key-frames", "3"), ("--format", "physflow")] {
        refused(
            &[
                "fit",
                "--video",
                "/nonexistent.npy",
                "--out",
                out.to_str().unwrap(),
                flag,
                value,
            ],
            &[flag, "only to --dataset"],
        );
    }
}

#[test]
fn bench_scale_sizes_are_bounded_before_any_work() {
    for (flag, value, needle) in [
        ("--resolution", "30000x30000", "pixels"),
        ("--frames", "0", "frames"),
        ("--substeps", "1000000", "substeps"),
        ("--gaussians", "1000000000", "gaussians"),
        ("--gaussians", "0", "at least the block's"),
        ("--cells", "1", "cells"),
    ] {
        refused(&["bench-scale", flag, value], &[needle]);
    }
    refused(
        &["bench-scale", "--checkpointing", "every:0"],
        &["--checkpointing"],
    );
}

/// Every count read from a file or a flag, and every product of them, is
/// refused against its documented limit before any work (each of these used to hang, abort
/// or allocate without bound), and fast.
#[test]
fn counts_and_their_products_are_bounded_before_work() {
    let dir = out_dir("budgets");
    std::fs::create_dir_all(&dir).unwrap();
    let base = std::fs::read_to_string(repo("tests/fixtures/fit/beam_start.toml")).unwrap();
    let config = |name: &str, from: &str, to: &str| -> String {
        assert!(base.contains(from), "{from}");
        let p = dir.join(name);
        std::fs::write(&p, base.replace(from, to)).unwrap();
        p.display().to_string()
    };
    let out = dir.join("out");
    let o = out.to_str().unwrap();
    let frame_dt = config("frame_dt.toml", "substeps_per_frame = 50", "frame_dt = 1e9");
    let tiny_dt = config(
        "tiny_dt.toml",
        "substep_dt = 2e-4\nsubsteps_per_frame = 50",
        "substep_dt = 1e-300\nframe_dt = 0.02",
    );
    let frames = config("frames.toml", "frames = 6", "frames = 1000000000");
    let outside = config(
        "outside.toml",
        "origin = [0.2083333, 0.4375, 0.4375]",
        "origin = [0.2083333, 0.4375, 5.0]",
    );
    let many = config(
        "many.toml",
        "thickness = 0.125\n",
        "thickness = 0.125\nper_cell = 8\n",
    );
    let many = {
        // n_grid 1024 and per_cell 8 over the beam: ~2e9 particles before sampling.
        let t = std::fs::read_to_string(&many)
            .unwrap()
            .replace("n_grid = 24", "n_grid = 1024");
        std::fs::write(&many, t).unwrap();
        many
    };
    let start = std::time::Instant::now();
    for (args, needles) in [
        (
            vec!["simulate", "--config", &frame_dt, "--out", o],
            vec!["frame_dt.toml", "time.frame_dt", "MAX_TOTAL_SUBSTEPS"],
        ),
        (
            vec!["simulate", "--config", &tiny_dt, "--out", o],
            vec!["tiny_dt.toml", "time.frame_dt", "MAX_TOTAL_SUBSTEPS"],
        ),
        (
            vec!["simulate", "--config", &frames, "--out", o],
            vec!["frames.toml", "time.frames", "MAX_FRAMES"],
        ),
        (
            vec![
                "simulate",
                "--config",
                &repo("tests/fixtures/fit/beam_start.toml"),
                "--frames",
                "400000",
                "--out",
                o,
            ],
            vec!["--frames 400000", "time.frames", "MAX_FRAMES"],
        ),
        (
            vec!["simulate", "--config", &outside, "--out", o],
            vec![
                "outside.toml",
                "shapes[0]",
                "z =",
                "outside the grid interior",
            ],
        ),
        (
            vec!["simulate", "--config", &many, "--out", o],
            vec!["many.toml", "MAX_SHAPE_PARTICLES"],
        ),
        (
            vec!["demo", "--quick", "--candidates", "4294967297", "--out", o],
            vec!["--candidates = 4294967297", "MAX_INIT_CANDIDATES"],
        ),
        (
            vec!["demo", "--quick", "--iters", "100000000000", "--out", o],
            vec!["--iters", "MAX_ITERS"],
        ),
        (
            // bench-scale at its own documented maxima, all together.
            vec![
                "bench-scale",
                "--cells",
                "48",
                "--gaussians",
                "20000000",
                "--frames",
                "1000",
                "--substeps",
                "10000",
                "--resolution",
                "8192x8192",
                "--checkpointing",
                "store_all",
            ],
            vec!["GiB", "8192x8192", "store_all"],
        ),
    ] {
        refused(&args, &needles);
        assert!(
            !out.join("frame_0000.ply").exists(),
            "{args:?}: wrote a frame"
        );
    }
    // Refusals come from the inputs' sizes, not from work: all of them in well under a minute
    // (a hang or a sampling of 2e9 particles would take far longer).
    assert!(start.elapsed().as_secs() < 60, "{:?}", start.elapsed());

    // A parts file's count is checked in usize before any conversion: 4294967297 used to wrap
    // to 1 in an i32 check and then size a 412 GB allocation.
    let e = r4d_segment::labels::PartLabels::parse(
        r#"{"num_parts": 4294967297, "labels": [0, -1, 0]}"#,
        Path::new("parts.json"),
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("parts.json") && e.contains("MAX_PARTS"), "{e}");
    let ok = r4d_segment::labels::PartLabels::parse(
        r#"{"num_parts": 2, "labels": [0, -1, 1]}"#,
        Path::new("parts.json"),
    );
    assert!(ok.is_ok(), "{ok:?}");

    // A FIT.toml's candidates, and candidates x frames.
    for (toml, needle) in [
        ("[init]\ncandidates = 4294967297\n", "MAX_INIT_CANDIDATES"),
        (
            "[init]\ncandidates = 10000\nframes = 1000\n",
            "MAX_INIT_FRAME_EVALS",
        ),
        ("iters = 4294967297\n", "MAX_ITERS"),
    ] {
        let p = dir.join("FIT.toml");
        std::fs::write(&p, toml).unwrap();
        let e = r4d_optim::video::config::FitConfig::load(&p)
            .unwrap_err()
            .to_string();
        assert!(e.contains("FIT.toml") && e.contains(needle), "{toml}: {e}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// Readers count the bytes they read; a device or a pipe given as a file is
/// refused at the reader's limit instead of filling memory.
#[cfg(unix)]
#[test]
fn readers_count_the_bytes_they_read() {
    let out = out_dir("dev_zero");
    let o = out.to_str().unwrap();
    refused(
        &["simulate", "--config", "/dev/zero", "--out", o],
        &["/dev/zero", "more than the 268435456 bytes"],
    );
    let dir = out_dir("dev_zero_cfg");
    std::fs::create_dir_all(&dir).unwrap();
    let fit = dir.join("FIT.toml");
    std::os::unix::fs::symlink("/dev/zero", &fit).unwrap();
    let e = r4d_optim::video::config::FitConfig::load(&fit)
        .unwrap_err()
        .to_string();
    assert!(e.contains("FIT.toml") && e.contains("268435456"), "{e}");
    let _ = std::fs::remove_dir_all(&dir);
}

/// docs/LIMITS.md cannot drift from the code: every constant its constants table names holds
/// the documented value in the documented file, and every constant the limits table names is
/// in the constants table.
#[test]
fn limits_doc_matches_the_code() {
    let doc = std::fs::read_to_string(repo("docs/LIMITS.md")).unwrap();
    let (limits, rest) = doc
        .split_once("## The constants")
        .expect("LIMITS.md has a constants table");
    let ticked = |cell: &str| cell.trim().trim_matches('`').to_string();
    let mut listed = Vec::new();
    let section = rest.split("\n## ").next().unwrap();
    for row in section.lines().filter(|l| l.starts_with("| `")) {
        let cells: Vec<&str> = row.trim_matches('|').split('|').collect();
        assert_eq!(cells.len(), 3, "{row}");
        let (name, value, file) = (ticked(cells[0]), ticked(cells[1]), ticked(cells[2]));
        let code = std::fs::read_to_string(repo(&file))
            .unwrap_or_else(|e| panic!("LIMITS.md names {file}: {e}"));
        let found = code.lines().any(|l| {
            let l = l.trim_start().trim_start_matches("pub ");
            l.starts_with(&format!("const {name}:")) && l.ends_with(&format!("= {value};"))
        });
        assert!(found, "LIMITS.md: {name} = {value} is not in {file}");
        listed.push(name);
    }
    assert!(listed.len() >= 40, "{listed:?}");
    // Constants the limits table names (`MAX_...`, `..._BYTES`) are in the constants table.
    let table = limits.split("## Options").next().unwrap();
    for word in table.split(|c: char| !(c.is_ascii_alphanumeric() || c == '_')) {
        let is_const = word.len() > 3
            && word.chars().all(|c| c.is_ascii_uppercase() || c == '_')
            && (word.starts_with("MAX_") || word.ends_with("_BYTES"));
        if is_const {
            assert!(
                listed.iter().any(|n| n == word),
                "LIMITS.md names {word} but its constants table does not"
            );
        }
    }
}
