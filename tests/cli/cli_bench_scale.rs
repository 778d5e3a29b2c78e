//! `r4d bench-scale` at a reduced scale: the table, the JSON keys other tools read, the
//! measured peaks, and typed errors for bad arguments.

use std::process::Command;

fn r4d() -> Command {
    Command::new(env!("CARGO_BIN_EXE_r4d"))
}

#[test]
fn bench_scale_prints_stages_and_writes_json() {
    let dir = std::env::temp_dir().join(format!("r4d_bench_scale_{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let json = dir.join("bench.json");
    let out = r4d()
        .args([
            "bench-scale",
            "--cells",
            "6",
            "--gaussians",
            "6000",
            "--frames",
            "3",
            "--substeps",
            "15",
            "--resolution",
            "160x96",
            "--band-rows",
            "32",
            "--json",
        ])
        .arg(&json)
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{stdout}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    for s in [
        "forward simulation",
        "render VJP",
        "reverse sweep",
        "memory_plan",
        "21.77",
    ] {
        assert!(stdout.contains(s), "missing '{s}' in\n{stdout}");
    }
    let v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    assert_eq!(v["particles"], 6 * 6 * 6 * 8);
    assert_eq!(v["gaussians"], 6000);
    assert_eq!(v["frames"], 3);
    assert_eq!(v["substeps_per_frame"], 15);
    assert_eq!(v["checkpointing"], "nested:20");
    // 96 rows in 32-row bands.
    assert_eq!(v["bands"], 3);
    assert!(v["loss"].as_f64().unwrap() > 0.0);
    // The binary installs the counting allocator: the peaks are measured, and the whole
    // iteration's peak bounds every stage's.
    assert_eq!(v["heap_measured"], true);
    let peak = v["peak_bytes"].as_u64().unwrap();
    let prof = &v["profile"];
    for k in [
        "forward_peak_bytes",
        "loss_peak_bytes",
        "backward_peak_bytes",
    ] {
        let p = prof[k].as_u64().unwrap();
        assert!(p > 0 && p <= peak, "{k} = {p}, peak {peak}");
    }
    for k in [
        "forward_s",
        "render_s",
        "loss_s",
        "render_vjp_s",
        "backward_s",
    ] {
        assert!(prof[k].as_f64().unwrap() > 0.0, "{k}");
    }
    assert!(v["memory_plan_bytes"].as_u64().unwrap() > 0);
    std::fs::remove_dir_all(&dir).ok();
}

/// `--init N`: the initialisation's time and memory at the benchmark's scene, every candidate
/// scored (in range, none failed within the stable bounds), the JSON keys other tools read.
#[test]
fn bench_scale_init_times_the_candidates() {
    let dir = std::env::temp_dir().join(format!("r4d_bench_init_{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let json = dir.join("init.json");
    let out = r4d()
        .args([
            "bench-scale",
            "--init",
            "3",
            "--cells",
            "6",
            "--gaussians",
            "6000",
            "--frames",
            "2",
            "--substeps",
            "10",
            "--resolution",
            "96x64",
            "--reference",
            "rest",
            "--json",
        ])
        .arg(&json)
        .output()
        .unwrap();
    let (stdout, stderr) = (
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr),
    );
    assert!(out.status.success(), "{stdout}\n{stderr}");
    assert!(stdout.contains("whole initialisation"), "{stdout}");
    assert_eq!(
        stderr.matches("bench-scale: candidate").count(),
        3,
        "{stderr}"
    );
    let v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    assert_eq!(v["candidates"], 3);
    assert_eq!(v["failed"], 0);
    assert_eq!(v["frames"], 2);
    let best = v["best_score"].as_f64().unwrap();
    assert!(best > 0.0 && best <= 1.0, "{best}");
    assert!(v["total_s"].as_f64().unwrap() > 0.0);
    assert!(v["concurrent"].as_u64().unwrap() >= 1);
    assert!(v["candidate_bytes_estimate"].as_u64().unwrap() > 0);
    assert_eq!(v["heap_measured"], true);
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn bench_scale_refuses_bad_arguments() {
    for (args, want) in [
        (vec!["--resolution", "big"], "--resolution"),
        (vec!["--cells", "60"], "--cells"),
        (vec!["--reference", "video"], "--reference"),
        (vec!["--checkpointing", "sometimes"], "checkpointing"),
        (vec!["--backend", "cuda"], "--backend"),
        (vec!["--init", "0"], "--init 0"),
        (vec!["--init", "10001"], "MAX_INIT_CANDIDATES"),
    ] {
        let out = r4d().arg("bench-scale").args(&args).output().unwrap();
        assert!(!out.status.success(), "{args:?}");
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(err.contains(want), "{args:?}: {err}");
    }
}
