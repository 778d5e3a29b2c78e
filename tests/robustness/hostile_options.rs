//! Issue 23, the classes fixed so far: options every command checks the same way before any
//! work (one validation path), sizes a user can ask for bounded, resume state checked against
//! what it resumes. Each case must be a typed error that names the flag or file; none may
//! panic, hang or write a result.

use std::path::{Path, PathBuf};
use std::process::Command;

fn r4d(args: &[&str]) -> std::process::Output {
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
fn refused(args: &[&str], needles: &[&str]) -> String {
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
fn bench_scale_sizes_are_bounded_before_any_work() {
    for (flag, value, needle) in [
        ("--resolution", "30000x30000", "pixels"),
        ("--frames", "0", "frames"),
        ("--substeps", "1000000", "substeps"),
        ("--gaussians", "1000000000", "gaussians"),
        ("--cells", "1", "cells"),
    ] {
        refused(&["bench-scale", flag, value], &[needle]);
    }
    refused(
        &["bench-scale", "--checkpointing", "every:0"],
        &["--checkpointing"],
    );
}
