//! `r4d demo` and `r4d fit` end to end (small settings), resume, and typed input errors; plus
//! the PhysGaussian fitting case (ignored by default: minutes).

use std::path::{Path, PathBuf};
use std::process::Command;

use crate::common;

fn r4d(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_r4d"))
        .args(args)
        .output()
        .expect("run r4d")
}

fn r4d_strings(args: &[String]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_r4d"))
        .args(args)
        .output()
        .expect("run r4d")
}

fn tmp(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("r4d_cli_fit_{name}_{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn json(path: &Path) -> serde_json::Value {
    let t = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    serde_json::from_str(&t).unwrap()
}

fn ok(o: &std::process::Output) {
    assert!(
        o.status.success(),
        "r4d failed:\n{}\n{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    );
}

#[test]
fn quick_demo_then_fit_and_resume_on_its_inputs() {
    let d = tmp("demo");
    let out = d.join("demo");
    // The test-size plant (`--small`): the same stages and files as the full-size demo.
    let o = r4d(&["demo", "--quick", "--small", "--out", out.to_str().unwrap()]);
    ok(&o);
    let s = json(&out.join("summary.json"));
    for k in ["truth", "init", "fit"] {
        assert_eq!(
            s[k]["parts"].as_array().unwrap().len(),
            2,
            "summary.json {k}"
        );
        assert!(s[k]["parts"][1]["E"].as_f64().unwrap() > 0.0);
    }
    assert!(s["wall_time_s"].as_f64().unwrap() > 0.0);
    assert!(!s["profiles"].as_array().unwrap().is_empty());
    for f in [
        "params.json",
        "log.jsonl",
        "checkpoint.json",
        "init.json",
        "fitted.gif",
        "side_by_side.gif",
        "wt_reference.png",
        "wt_fitted.png",
        "spectrum_reference.png",
        "spectrum_fitted.png",
        "loss_curve.png",
        "fitted/frame_0000.png",
        "inputs/scene.ply",
        "inputs/reference.npy",
        "inputs/sim.toml",
        "inputs/cameras.json",
        "inputs/parts.json",
        "inputs/particles.ply",
    ] {
        assert!(out.join(f).exists(), "demo wrote no {f}");
    }
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(stdout.contains("E/density"), "{stdout}");

    // r4d fit on the demo's inputs, one iteration, then resumed for a second one.
    let inp = out.join("inputs");
    let cfg = d.join("fit.toml");
    let write_cfg = |iters: usize| {
        std::fs::write(
            &cfg,
            format!(
                "iters = {iters}\noptimizer = \"adam\"\nmulti_start = 1\nfree = [\"E\"]\nprecision = \"f32\"\nframes = 5\n[init]\ncandidates = 3\nrounds = 1\nframes = 3\n[loss.spectral]\npatch = [16, 16]\nphase_mask = 1e-3\n"
            ),
        )
        .unwrap()
    };
    write_cfg(1);
    let run = d.join("run");
    let p = |n: &str| inp.join(n).to_str().unwrap().to_string();
    let args = [
        "fit",
        "--scene",
        &p("scene.ply"),
        "--sim",
        &p("sim.toml"),
        "--particles",
        &p("particles.ply"),
        "--parts",
        &p("parts.json"),
        "--cameras",
        &p("cameras.json"),
        "--video",
        &p("reference.npy"),
        "--out",
        run.to_str().unwrap(),
        "--config",
        cfg.to_str().unwrap(),
    ];
    let o = r4d(&args);
    ok(&o);
    let err = String::from_utf8_lossy(&o.stderr);
    // The automatic strategy (the default) keeps what the file writes and decides the rest.
    assert!(
        err.contains("fit: init (3 candidates x 3 frames) -> descent (1 iterations, adam, restarted after 8 iterations without progress) (strategy = \"auto\")")
            && err.contains("iters = 1: as written (pinned)")
            && err.contains("init.rounds = 1: as written (pinned)")
            && err.contains("init.score = loss")
            && err.contains("stall = 8"),
        "the plan is printed: {err}"
    );
    let summary = json(&run.join("summary.json"));
    assert_eq!(summary["strategy"], "auto");
    assert!(summary["decisions"]
        .as_array()
        .unwrap()
        .iter()
        .any(|d| d["setting"] == "init.sampler" && d["value"] == "natural"));
    let params = json(&run.join("params.json"));
    assert_eq!(params["parts"].as_array().unwrap().len(), 2);
    assert_eq!(json(&run.join("checkpoint.json"))["iters_done"], 1);
    write_cfg(2);
    let o = r4d(&["fit", "--resume", run.to_str().unwrap()]);
    ok(&o);
    assert!(String::from_utf8_lossy(&o.stderr).contains("resuming"));
    assert_eq!(json(&run.join("checkpoint.json"))["iters_done"], 2);
    let log = std::fs::read_to_string(run.join("log.jsonl")).unwrap();
    assert_eq!(log.lines().count(), 2);
    let first: serde_json::Value = serde_json::from_str(log.lines().next().unwrap()).unwrap();
    for k in [
        "loss",
        "theta",
        "grad_log",
        "grad_norm",
        "parts",
        "time_s",
        "peak_host_bytes",
    ] {
        assert!(first.get(k).is_some(), "log record without {k}");
    }
    assert!(first["peak_host_bytes"].as_u64().unwrap() > 0);

    // Resume continues the run it resumes: settings edited beyond `iters` are refused (they
    // used to be silently used), and so is a checkpoint that cannot be read (it used to
    // restart at iteration 0 over the run).
    let text = std::fs::read_to_string(&cfg).unwrap();
    std::fs::write(&cfg, text.replace("iters = 2\n", "iters = 3\nlr = 0.5\n")).unwrap();
    let o = r4d(&["fit", "--resume", run.to_str().unwrap()]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        !o.status.success() && err.contains("lr") && err.contains("differ"),
        "{err}"
    );
    write_cfg(3);
    let ck = run.join("checkpoint.json");
    let saved = std::fs::read(&ck).unwrap();
    std::fs::write(&ck, b"\xff\xfe not a checkpoint").unwrap();
    let o = r4d(&["fit", "--resume", run.to_str().unwrap()]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        !o.status.success() && err.contains("checkpoint.json"),
        "{err}"
    );
    std::fs::write(&ck, saved).unwrap();
    assert_eq!(
        json(&ck)["iters_done"],
        2,
        "the refused resumes left the run as it was"
    );
    // A --row outside the views is refused before anything is written.
    let fresh = d.join("fresh");
    let fresh_s = fresh.to_str().unwrap().to_string();
    let mut bad = args.to_vec();
    bad[14] = &fresh_s;
    bad.extend(["--row", "100000"]);
    let o = r4d(&bad);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && err.contains("--row"), "{err}");
    assert!(!fresh.exists(), "nothing written for a refused --row");
    // Refused before any work, nothing written: a frame rate the fitted video cannot have,
    // a loss weight that overflows the loss, an output folder that holds the inputs, and an
    // earlier run without --resume or --overwrite (never two runs mixed in one folder).
    let mut bad = args.to_vec();
    bad[14] = &fresh_s;
    bad.extend(["--fps", "1e9"]);
    let o = r4d(&bad);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && err.contains("--fps"), "{err}");
    assert!(!fresh.exists(), "nothing written for a refused --fps");
    let heavy = d.join("heavy.toml");
    std::fs::write(&heavy, "iters = 1\n[loss.weights]\nspatial = 1e308\n").unwrap();
    let heavy_s = heavy.to_str().unwrap().to_string();
    let mut bad = args.to_vec();
    bad[14] = &fresh_s;
    bad[16] = &heavy_s;
    let o = r4d(&bad);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && err.contains("spatial"), "{err}");
    assert!(!fresh.exists(), "nothing written for a refused loss weight");
    let inp_s = inp.to_str().unwrap().to_string();
    let mut bad = args.to_vec();
    bad[14] = &inp_s;
    let o = r4d(&bad);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        !o.status.success() && err.contains("--out") && err.contains("contains"),
        "{err}"
    );
    let o = r4d(&args);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        !o.status.success() && err.contains("--resume") && err.contains("--overwrite"),
        "{err}"
    );
    assert_eq!(json(&run.join("checkpoint.json"))["iters_done"], 2);

    // Resume refuses other inputs: the run's checkpoint carries a fingerprint of the scene,
    // particles, parts, cameras, videos and settings (the reference changed here).
    let video_path = inp.join("reference.npy");
    let original = std::fs::read(&video_path).unwrap();
    let mut changed = original.clone();
    let last = changed.len() - 1;
    changed[last] ^= 0x01;
    std::fs::write(&video_path, &changed).unwrap();
    let o = r4d(&["fit", "--resume", run.to_str().unwrap()]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        !o.status.success() && err.contains("fingerprint") && err.contains("checkpoint.json"),
        "{err}"
    );
    std::fs::write(&video_path, &original).unwrap();

    // Killed with SIGKILL at seeded random instants and resumed, a fit ends as an uninterrupted one:
    // the same params.json byte for byte and the same log (but wall times and heap peaks).
    write_cfg(2);
    let with_out = |dir: &Path| {
        let mut a: Vec<String> = args.iter().map(|s| s.to_string()).collect();
        a[14] = dir.to_str().unwrap().to_string();
        a
    };
    let reference = d.join("uninterrupted");
    let start = std::time::Instant::now();
    ok(&r4d_strings(&with_out(&reference)));
    let wall = start.elapsed();
    let records = |dir: &Path| -> Vec<serde_json::Value> {
        std::fs::read_to_string(dir.join("log.jsonl"))
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
    };
    // Kill instants from a seeded generator (R4D_FAULT_SEED, as tests/robustness/fault_injection.rs).
    let mut seed: u64 = std::env::var("R4D_FAULT_SEED")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(0x00c0_ffee)
        | 1;
    let mut unit = move || {
        seed ^= seed << 13;
        seed ^= seed >> 7;
        seed ^= seed << 17;
        (seed >> 11) as f64 / (1u64 << 53) as f64
    };
    let shares: Vec<f64> = (0..2).map(|_| 0.1 + 0.85 * unit()).collect();
    for (k, share) in shares.into_iter().enumerate() {
        let dir = d.join(format!("killed{k}"));
        let mut child = Command::new(env!("CARGO_BIN_EXE_r4d"))
            .args(with_out(&dir))
            .stdout(std::process::Stdio::null())
            .stderr(std::process::Stdio::null())
            .spawn()
            .unwrap();
        std::thread::sleep(wall.mul_f64(share));
        let _ = child.kill();
        let _ = child.wait();
        // Killed before invocation.json was written: nothing to resume, start again.
        let o = if dir.join("invocation.json").exists() {
            r4d(&["fit", "--resume", dir.to_str().unwrap()])
        } else {
            r4d_strings(&with_out(&dir))
        };
        ok(&o);
        assert_eq!(
            std::fs::read(dir.join("params.json")).unwrap(),
            std::fs::read(reference.join("params.json")).unwrap(),
            "killed at {share} of the run: params.json differs"
        );
        assert_eq!(records(&dir), records(&reference), "killed at {share}");
    }
    // One and two threads: the same fit, byte for byte (the reference above ran on every
    // core; this machine's CI has two).
    for threads in ["1", "2"] {
        let dir = d.join(format!("threads{threads}"));
        let o = Command::new(env!("CARGO_BIN_EXE_r4d"))
            .args(with_out(&dir))
            .env("RAYON_NUM_THREADS", threads)
            .output()
            .unwrap();
        ok(&o);
        assert_eq!(
            std::fs::read(dir.join("params.json")).unwrap(),
            std::fs::read(reference.join("params.json")).unwrap(),
            "{threads} thread(s): params.json differs"
        );
        assert_eq!(records(&dir), records(&reference), "{threads} thread(s)");
    }

    // Bad inputs: a video of the wrong size, parts for another scene.
    let small = d.join("small.npy");
    let v = r4d_loss::Video::<f32>::zeros(4, 10, 12);
    r4d_loss::io::write_npy(&small, &v).unwrap();
    let mut bad = args.to_vec();
    let small_s = small.to_str().unwrap().to_string();
    bad[12] = &small_s;
    let o = r4d(&bad);
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("small.npy") && err.contains("12x10"), "{err}");
    let parts = d.join("parts.json");
    std::fs::write(&parts, r#"{"num_parts": 1, "labels": [0, 0, -1]}"#).unwrap();
    let parts_s = parts.to_str().unwrap().to_string();
    let mut bad = args.to_vec();
    bad[8] = &parts_s;
    let o = r4d(&bad);
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("parts.json") && err.contains("3 labels"),
        "{err}"
    );
    let _ = std::fs::remove_dir_all(&d);
}

/// `r4d fit` on PhysGaussian's fitting case (a video PhysGaussian's solver simulated and
/// gsplat rendered, 8-bit PNG frames of camera 0): E/density within 10%. Minutes: run with
/// `cargo test --release --test cli -- cli_fit:: --ignored`.
#[test]
#[ignore = "minutes of fitting: run with `cargo test --release --test cli -- cli_fit:: --ignored`"]
fn physgaussian_fit_jelly_arch_recovers_e_over_density() {
    let f = common::fixture("physgaussian/fit_jelly_arch");
    let d = tmp("arch");
    let cfg = d.join("fit.toml");
    std::fs::write(
        &cfg,
        "strategy = \"fixed\"\niters = 25\nlr = 0.15\nbeta1 = 0.6\nprecision = \"f32\"\nfree = [\"E\", \"density\"]\n[init]\ncandidates = 16\n[loss.spectral]\nphase_mask = 1e-3\n[[parts]]\nid = 0\nbounds = { E = [1e4, 1e7], density = [100.0, 3000.0] }\n",
    )
    .unwrap();
    let s = |n: &str| f.join(n).to_str().unwrap().to_string();
    let run = d.join("run");
    let o = r4d(&[
        "fit",
        "--scene",
        &s("scene.ply"),
        "--sim",
        &s("physgaussian_config.json"),
        "--particles",
        &s("particles.ply"),
        "--parts",
        &s("scene.ply"),
        "--cameras",
        &s("cameras.json"),
        "--video",
        &s("cam0"),
        "--out",
        run.to_str().unwrap(),
        "--config",
        cfg.to_str().unwrap(),
    ]);
    ok(&o);
    eprintln!("{}", String::from_utf8_lossy(&o.stdout));
    let p = json(&run.join("params.json"));
    let (e, rho) = (
        p["parts"][0]["E"].as_f64().unwrap(),
        p["parts"][0]["density"].as_f64().unwrap(),
    );
    let err = (e / rho) / (3e5 / 600.0) - 1.0;
    eprintln!(
        "E {e:.4e} density {rho:.1}: E/density error {:.2}%",
        100.0 * err
    );
    assert!(err.abs() < 0.1, "E/density off by {:.1}%", 100.0 * err);
}

#[test]
fn demo_scenes_report_every_free_parameter_with_a_verdict() {
    let d = tmp("demo-scenes");
    let out = d.join("foam");
    let o = r4d(&[
        "demo",
        "--scene",
        "foam",
        "--small",
        "--quick",
        "--out",
        out.to_str().unwrap(),
    ]);
    ok(&o);
    let s = json(&out.join("summary.json"));
    assert_eq!(s["scene"], "foam");
    let quantities: Vec<&str> = s["recovery"]
        .as_array()
        .unwrap()
        .iter()
        .map(|r| r["quantity"].as_str().unwrap())
        .collect();
    for q in [
        "E",
        "nu",
        "yield_stress",
        "plastic_viscosity",
        "density",
        "E/density",
    ] {
        assert!(quantities.contains(&q), "{q} missing from {quantities:?}");
    }
    let verdicts = s["identifiability"].as_array().unwrap();
    assert!(verdicts
        .iter()
        .any(|v| v["name"] == "part0.plastic_viscosity"));
    assert!(verdicts
        .iter()
        .all(|v| v["identifiable"].is_boolean() && v["reason"].is_string()));
    assert_eq!(s["profiles_2d"].as_array().unwrap().len(), 2);
    for f in [
        "view_0/side_by_side.gif",
        "view_1/fitted.mp4",
        "inputs/reference_1.npy",
    ] {
        assert!(out.join(f).exists(), "demo wrote no {f}");
    }
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(stdout.contains("plastic_viscosity"), "{stdout}");
    // An unknown scene is a typed error naming the flag and the choices.
    let o = r4d(&[
        "demo",
        "--scene",
        "lava",
        "--out",
        d.join("x").to_str().unwrap(),
    ]);
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("--scene") && err.contains("plasticine"),
        "{err}"
    );
}
