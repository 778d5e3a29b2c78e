//! Fault injection: runs killed with SIGKILL at random instants and resumed end
//! byte-identical to uninterrupted runs; a full disk is a typed error that leaves no torn
//! file; one and two threads give byte-identical outputs.
//!
//! The kill instants come from a seeded generator (`R4D_FAULT_SEED`, `R4D_FAULT_KILLS` kills
//! per command, default 3), spread over each command's measured uninterrupted wall time.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::time::{Duration, Instant};

fn repo(rel: &str) -> String {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join(rel)
        .display()
        .to_string()
}

fn tmp(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("r4d_fault_{}_{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn r4d_env(args: &[String], env: &[(&str, &str)]) -> Output {
    let mut c = Command::new(env!("CARGO_BIN_EXE_r4d"));
    c.args(args);
    for (k, v) in env {
        c.env(k, v);
    }
    c.output().expect("run r4d")
}

fn r4d(args: &[String]) -> Output {
    r4d_env(args, &[])
}

fn ok(o: &Output) {
    assert!(
        o.status.success(),
        "r4d failed:\n{}\n{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    );
}

fn strings(a: &[&str]) -> Vec<String> {
    a.iter().map(|s| s.to_string()).collect()
}

/// A small seeded generator (xorshift).
struct Rng(u64);
impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        self.0
    }
    /// Uniform in [0, 1).
    fn unit(&mut self) -> f64 {
        (self.next() >> 11) as f64 / (1u64 << 53) as f64
    }
}

fn rng() -> Rng {
    let seed = std::env::var("R4D_FAULT_SEED")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(0x00c0_ffee_u64);
    Rng(seed | 1)
}

fn kills() -> usize {
    std::env::var("R4D_FAULT_KILLS")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(3)
}

/// Starts `args`, kills it with SIGKILL after `after` (if it is still running); returns
/// whether it was killed.
fn kill_after(args: &[String], after: Duration) -> bool {
    let mut child = Command::new(env!("CARGO_BIN_EXE_r4d"))
        .args(args)
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .spawn()
        .expect("start r4d");
    let start = Instant::now();
    while start.elapsed() < after {
        if child.try_wait().unwrap().is_some() {
            return false;
        }
        std::thread::sleep(Duration::from_millis(5));
    }
    // `Child::kill` sends SIGKILL on Unix: no handler runs, nothing is flushed.
    let _ = child.kill();
    let _ = child.wait();
    true
}

/// Every file under `dir` (relative path -> bytes), skipping names `skip` accepts.
fn files(dir: &Path, skip: &dyn Fn(&str) -> bool) -> Vec<(String, Vec<u8>)> {
    fn walk(root: &Path, d: &Path, out: &mut Vec<(String, Vec<u8>)>, skip: &dyn Fn(&str) -> bool) {
        let mut entries: Vec<_> = std::fs::read_dir(d).unwrap().flatten().collect();
        entries.sort_by_key(|e| e.file_name());
        for e in entries {
            let p = e.path();
            let rel = p.strip_prefix(root).unwrap().display().to_string();
            if skip(&rel) {
                continue;
            }
            if p.is_dir() {
                walk(root, &p, out, skip);
            } else {
                out.push((rel, std::fs::read(&p).unwrap()));
            }
        }
    }
    let mut out = Vec::new();
    walk(dir, dir, &mut out, skip);
    out
}

/// Asserts two runs' files are byte-identical (names and contents).
fn same_files(a: &[(String, Vec<u8>)], b: &[(String, Vec<u8>)], what: &str) {
    let names = |v: &[(String, Vec<u8>)]| v.iter().map(|f| f.0.clone()).collect::<Vec<_>>();
    assert_eq!(names(a), names(b), "{what}: different files");
    for ((n, x), (_, y)) in a.iter().zip(b) {
        assert!(x == y, "{what}: {n} differs");
    }
}

/// `log.jsonl` without the fields that measure the run (wall time, heap peak).
fn log_records(path: &Path) -> Vec<serde_json::Value> {
    std::fs::read_to_string(path)
        .unwrap()
        .lines()
        .map(|l| {
            let mut v: serde_json::Value = serde_json::from_str(l).unwrap();
            let o = v.as_object_mut().unwrap();
            o.remove("time_s");
            o.remove("peak_host_bytes");
            v
        })
        .collect()
}

/// The sagging beam's truth (2 frames of `tests/fixtures/fit/beam.toml`) simulated into
/// `root/truth`: the target of the trajectory fits below.
fn beam_truth(root: &Path) -> String {
    let truth = root.join("truth");
    ok(&r4d(&strings(&[
        "simulate",
        "--config",
        &repo("tests/fixtures/fit/beam.toml"),
        "--out",
        truth.to_str().unwrap(),
        "--frames",
        "2",
    ])));
    truth.to_str().unwrap().to_string()
}

/// `r4d fit-trajectory` of the beam from `beam_start.toml` towards `truth`, writing `out`.
fn fit_trajectory_args(truth: &str, params: &str, iters: usize, out: &Path) -> Vec<String> {
    strings(&[
        "fit-trajectory",
        "--config",
        &repo("tests/fixtures/fit/beam_start.toml"),
        "--target",
        truth,
        "--params",
        params,
        "--iters",
        &iters.to_string(),
        "--frames",
        "2",
        "--out",
        out.to_str().unwrap(),
    ])
}

/// Runs the command `make(dir)` uninterrupted, then, for several kill instants, killed and
/// resumed (the same arguments plus `--resume`) until it succeeds; returns (reference dir,
/// resumed dirs).
fn killed_and_resumed(name: &str, make: &dyn Fn(&Path) -> Vec<String>) -> (PathBuf, Vec<PathBuf>) {
    let resume = |dir: &Path| {
        let mut a = make(dir);
        a.push("--resume".into());
        a
    };
    let root = tmp(name);
    let reference = root.join("reference");
    let start = Instant::now();
    ok(&r4d(&make(&reference)));
    let wall = start.elapsed();
    let mut r = rng();
    let mut dirs = Vec::new();
    for k in 0..kills() {
        let dir = root.join(format!("killed{k}"));
        // Somewhere in the run: after the start-up, before the end.
        let at = wall.mul_f64(0.1 + 0.85 * r.unit());
        let killed = kill_after(&make(&dir), at);
        eprintln!("{name}: killed at {at:?} of {wall:?}: {killed}");
        // Resume until done (a resume may itself be killed: twice more, shorter).
        for j in 0..2 {
            let at = wall.mul_f64(0.05 + 0.4 * r.unit());
            if !kill_after(&resume(&dir), at) {
                break;
            }
            eprintln!("{name}: resume {j} killed at {at:?}");
        }
        ok(&r4d(&resume(&dir)));
        dirs.push(dir);
    }
    (reference, dirs)
}

#[test]
fn simulate_killed_at_random_instants_resumes_byte_identical() {
    let make = |dir: &Path| {
        strings(&[
            "simulate",
            "--config",
            &repo("configs/metal_bar.toml"),
            "--frames",
            "12",
            "--out",
            dir.to_str().unwrap(),
        ])
    };
    let (reference, dirs) = killed_and_resumed("simulate", &make);
    // The frames and the final state; summary.json holds wall times.
    let skip = |n: &str| n == "summary.json";
    let want = files(&reference, &skip);
    assert!(want.iter().any(|f| f.0 == "frame_0012.ply"));
    for d in dirs {
        same_files(&want, &files(&d, &skip), &d.display().to_string());
    }
}

#[test]
fn fit_trajectory_killed_at_random_instants_resumes_byte_identical() {
    let truth = beam_truth(&tmp("fit_trajectory_truth"));
    let make = move |dir: &Path| fit_trajectory_args(&truth, "E,density", 4, dir);
    let (reference, dirs) = killed_and_resumed("fit_trajectory", &make);
    let want_params = std::fs::read(reference.join("params.json")).unwrap();
    let want_log = log_records(&reference.join("log.jsonl"));
    assert_eq!(want_log.len(), 4);
    for d in dirs {
        assert_eq!(
            std::fs::read(d.join("params.json")).unwrap(),
            want_params,
            "{}: params.json differs",
            d.display()
        );
        assert_eq!(
            log_records(&d.join("log.jsonl")),
            want_log,
            "{}",
            d.display()
        );
    }
}

/// Inputs of `r4d segment` (the synthetic three-part scene) in `dir`.
fn segment_inputs(dir: &Path) {
    use r4d_segment::synthetic;
    let scene = synthetic::three_parts(3000, 2);
    let cams = synthetic::ring_cameras(4, 96, 72);
    r4d_splat::ply::write_gaussians(&dir.join("scene.ply"), &scene.gaussians).unwrap();
    std::fs::write(
        dir.join("cameras.json"),
        serde_json::to_string(&serde_json::json!({ "cameras": cams })).unwrap(),
    )
    .unwrap();
    let masks = dir.join("masks");
    std::fs::create_dir_all(&masks).unwrap();
    for c in &cams {
        r4d_segment::mask::write_label_png(
            &masks.join(&c.name),
            c.width,
            c.height,
            &scene.label_mask(c),
        )
        .unwrap();
    }
}

fn segment_args(inputs: &Path, out: &Path) -> Vec<String> {
    strings(&[
        "segment",
        "--scene",
        inputs.join("scene.ply").to_str().unwrap(),
        "--cameras",
        inputs.join("cameras.json").to_str().unwrap(),
        "--masks",
        inputs.join("masks").to_str().unwrap(),
        "--out",
        out.join("parts.json").to_str().unwrap(),
    ])
}

#[test]
fn segment_killed_at_random_instants_leaves_no_torn_file_and_reruns_identical() {
    let root = tmp("segment");
    let inputs = root.join("inputs");
    std::fs::create_dir_all(&inputs).unwrap();
    segment_inputs(&inputs);
    let reference = root.join("reference");
    let start = Instant::now();
    ok(&r4d(&segment_args(&inputs, &reference)));
    let wall = start.elapsed();
    let want = files(&reference, &|_| false);
    let mut r = rng();
    for k in 0..kills() {
        let dir = root.join(format!("killed{k}"));
        kill_after(
            &segment_args(&inputs, &dir),
            wall.mul_f64(0.1 + 0.85 * r.unit()),
        );
        // Whatever a kill left is whole: every file present equals the reference's (no
        // truncated JSON, PLY or PNG). A SIGKILL during a write can leave that write's
        // temporary file (NAME.r4d-tmp, never the target itself); the next run replaces it.
        if dir.exists() {
            let temporary = |n: &str| n.ends_with(".r4d-tmp");
            for (n, bytes) in files(&dir, &temporary) {
                let w = want.iter().find(|f| f.0 == n);
                assert!(
                    w.is_some_and(|w| w.1 == bytes),
                    "{n}: a killed run left a file that is not the finished one"
                );
            }
        }
        // `segment` is one pass: it is resumed by running it again (no temporary file is
        // left then: the comparison is over every file).
        ok(&r4d(&segment_args(&inputs, &dir)));
        same_files(&want, &files(&dir, &|_| false), &dir.display().to_string());
    }
}

#[test]
fn one_and_two_threads_give_byte_identical_outputs() {
    let root = tmp("threads");
    let inputs = root.join("inputs");
    std::fs::create_dir_all(&inputs).unwrap();
    segment_inputs(&inputs);
    let truth_s = beam_truth(&root);
    type Make = Box<dyn Fn(&Path) -> Vec<String>>;
    let inputs2 = inputs.clone();
    let commands: Vec<(&str, Make, &[&str])> = vec![
        (
            "simulate",
            Box::new(|d: &Path| {
                strings(&[
                    "simulate",
                    "--config",
                    &repo("configs/jelly_drop.toml"),
                    "--frames",
                    "3",
                    "--out",
                    d.to_str().unwrap(),
                ])
            }),
            &["summary.json"],
        ),
        (
            "fit-trajectory",
            Box::new(move |d: &Path| fit_trajectory_args(&truth_s, "E", 2, d)),
            // The log holds wall times; its other fields are compared below.
            &["log.jsonl"],
        ),
        (
            "segment",
            Box::new(move |d: &Path| segment_args(&inputs2, d)),
            &[],
        ),
        (
            "render",
            Box::new(|d: &Path| {
                std::fs::create_dir_all(d).unwrap();
                strings(&[
                    "render",
                    "--scene",
                    &repo("tests/fixtures/splat/sh3_shell_bg/scene.ply"),
                    "--camera",
                    &repo("tests/fixtures/splat/sh3_shell_bg/cameras.json"),
                    "--camera-index",
                    "1",
                    "--out",
                    d.join("img.png").to_str().unwrap(),
                    "--out-raw",
                    d.join("img.npy").to_str().unwrap(),
                ])
            }),
            &[],
        ),
    ];
    for (name, make, skip) in &commands {
        let mut outs = Vec::new();
        for threads in ["1", "2"] {
            let d = root.join(format!("{name}-{threads}"));
            let o = r4d_env(&make(&d), &[("RAYON_NUM_THREADS", threads)]);
            ok(&o);
            outs.push(d);
        }
        let skip_fn = |n: &str| skip.contains(&n);
        same_files(
            &files(&outs[0], &skip_fn),
            &files(&outs[1], &skip_fn),
            &format!("{name}: 1 vs 2 threads"),
        );
        if outs[0].join("log.jsonl").exists() {
            assert_eq!(
                log_records(&outs[0].join("log.jsonl")),
                log_records(&outs[1].join("log.jsonl")),
                "{name}: log.jsonl, 1 vs 2 threads"
            );
        }
    }
}

/// A small tmpfs (root only): a full disk. Returns `None` (and says why) where it cannot
/// be mounted.
fn small_tmpfs(dir: &Path, size: &str) -> Option<()> {
    std::fs::create_dir_all(dir).ok()?;
    let o = Command::new("mount")
        .args(["-t", "tmpfs", "-o", &format!("size={size}"), "tmpfs"])
        .arg(dir)
        .output()
        .ok()?;
    if !o.status.success() {
        eprintln!(
            "skipped: cannot mount a small tmpfs for the full-disk test ({}); run the tests as root to include it",
            String::from_utf8_lossy(&o.stderr).trim()
        );
        return None;
    }
    Some(())
}

#[test]
fn a_full_disk_is_a_typed_error_and_leaves_no_torn_file() {
    let root = tmp("full_disk");
    let mnt = root.join("mnt");
    if small_tmpfs(&mnt, "300k").is_none() {
        eprintln!("skipped: a_full_disk_is_a_typed_error_and_leaves_no_torn_file");
        return;
    }
    struct Unmount(PathBuf);
    impl Drop for Unmount {
        fn drop(&mut self) {
            let _ = Command::new("umount").arg(&self.0).status();
        }
    }
    let _guard = Unmount(mnt.clone());
    // 2 592 particles x 12 bytes per frame: the disk fills after a few frames.
    let out = mnt.join("sim");
    let o = r4d(&strings(&[
        "simulate",
        "--config",
        &repo("configs/jelly_drop.toml"),
        "--frames",
        "40",
        "--out",
        out.to_str().unwrap(),
    ]));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success(), "a full disk went unnoticed");
    assert!(
        err.contains("No space left on device")
            && (err.contains(".ply") || err.contains("state.r4d")),
        "the error names neither the cause nor the file: {err}"
    );
    // Every file left is whole: frames parse, the state reads, no temporary file.
    for (n, _) in files(&out, &|_| false) {
        assert!(!n.ends_with(".r4d-tmp"), "{n}: a temporary file was left");
        if n.ends_with(".ply") {
            r4d_mpm::ply::read_ply(&out.join(&n))
                .unwrap_or_else(|e| panic!("{n}: torn by the full disk: {e}"));
        }
    }
    // And a resume on a disk with room continues from the last whole state.
    let _ = Command::new("mount")
        .args(["-o", "remount,size=64m"])
        .arg(&mnt)
        .status();
    let o = r4d(&strings(&[
        "simulate",
        "--config",
        &repo("configs/jelly_drop.toml"),
        "--frames",
        "40",
        "--out",
        out.to_str().unwrap(),
        "--resume",
    ]));
    ok(&o);
}

/// Every file name under `dir` that is an atomic write's temporary file.
fn temporaries(dir: &Path) -> Vec<String> {
    files(dir, &|_| false)
        .into_iter()
        .map(|f| f.0)
        .filter(|n| n.ends_with(".r4d-tmp"))
        .collect()
}

/// Writes that fail (a file size limit reached mid-write, as on a full disk; an output whose
/// name is taken by a folder) are typed errors naming the file, and leave no temporary file
/// and no torn or changed file. Unlike the tmpfs test this needs no privilege: the limit is
/// the shell's `ulimit -f`, with SIGXFSZ ignored so that the write fails with EFBIG.
#[cfg(unix)]
#[test]
fn failed_writes_leave_no_temporary_file_and_no_changed_file() {
    let root = tmp("failed_writes");
    // dash counts `ulimit -f` in 512-byte blocks (bash in KiB): 8 KiB at most, less than a
    // frame of 2 592 particles.
    let out = root.join("sim");
    let o = Command::new("sh")
        .arg("-c")
        .arg("trap '' XFSZ; ulimit -f 16 && exec \"$0\" \"$@\"")
        .arg(env!("CARGO_BIN_EXE_r4d"))
        .args([
            "simulate",
            "--config",
            &repo("configs/jelly_drop.toml"),
            "--frames",
            "3",
            "--out",
            out.to_str().unwrap(),
        ])
        .output()
        .expect("sh runs r4d");
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        !o.status.success(),
        "a write past the file size limit went unnoticed"
    );
    assert!(!err.contains("panicked"), "{err}");
    assert!(
        err.contains("File too large") && (err.contains(".ply") || err.contains("state.r4d")),
        "the error names neither the cause nor the file: {err}"
    );
    assert_eq!(temporaries(&out), Vec::<String>::new());
    for (n, _) in files(&out, &|_| false) {
        if n.ends_with(".ply") {
            r4d_mpm::ply::read_ply(&out.join(&n))
                .unwrap_or_else(|e| panic!("{n}: torn by the failed write: {e}"));
        }
    }

    // An output file whose name is taken by a folder of the user's: refused, the folder
    // untouched.
    let inputs = root.join("inputs");
    std::fs::create_dir_all(&inputs).unwrap();
    segment_inputs(&inputs);
    let seg = root.join("seg");
    std::fs::create_dir_all(seg.join("parts.json")).unwrap();
    std::fs::write(seg.join("parts.json/notes.txt"), b"user data").unwrap();
    let o = r4d(&segment_args(&inputs, &seg));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && !err.contains("panicked"), "{err}");
    assert!(err.contains("parts.json"), "{err}");
    assert_eq!(
        std::fs::read(seg.join("parts.json/notes.txt")).unwrap(),
        b"user data"
    );
    assert_eq!(temporaries(&seg), Vec::<String>::new());
    assert_eq!(temporaries(&inputs), Vec::<String>::new());
}
