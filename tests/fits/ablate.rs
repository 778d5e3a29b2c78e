//! `r4d ablate` and `r4d merge` on the PAC-NeRF fixture (tiny fits): every study gives one row
//! per variant, a two-shard run merges to the unsharded `ablation.json` byte for byte, a
//! finished variant is not fitted again, and gaps and overlaps in a shard set are refused.

use crate::common;

use std::path::{Path, PathBuf};
use std::process::Command;

fn tmp(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("r4d_ablate_{name}_{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn r4d(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_r4d"))
        .args(args)
        .output()
        .expect("run r4d")
}

fn ok(args: &[&str]) -> String {
    let out = r4d(args);
    assert!(
        out.status.success(),
        "r4d {args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).to_string()
}

fn json(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

#[test]
fn ablations_shard_merge_and_refuse_broken_shard_sets() {
    let base = tmp("run");
    let ds = common::fixture("datasets").join("pacnerf/toyball");
    let ds = ds.to_str().unwrap();
    let cfg = base.join("fit.toml");
    std::fs::write(
        &cfg,
        "iters = 1\nlr = 0.1\n[init]\ncandidates = 2\nframes = 2\n",
    )
    .unwrap();
    let cfg = cfg.to_str().unwrap();
    let abl = |study: &str, out: &Path, shard: Option<&str>| {
        let mut args = vec!["ablate", "--dataset", ds, "--study", study, "--config", cfg];
        let out = out.to_str().unwrap().to_string();
        args.extend(["--out", &out]);
        if let Some(s) = shard {
            args.extend(["--shard", s]);
        }
        ok(&args)
    };

    // Every study: one row per variant, in the paper's order.
    for (study, labels) in [
        ("loss", vec!["L1", "SSIM", "L1+FFT", "SSIM+FFT"]),
        ("init", vec!["config start", "LHS init"]),
        ("granularity", vec!["particle", "object", "part"]),
        ("density", vec!["density fixed", "density free"]),
    ] {
        let out = base.join(study);
        let table = abl(study, &out, None);
        let t = json(&out.join("ablation.json"));
        assert_eq!(t["study"], study);
        let got: Vec<&str> = t["rows"]
            .as_array()
            .unwrap()
            .iter()
            .map(|r| r["variant"].as_str().unwrap())
            .collect();
        assert_eq!(got, labels, "{table}");
        for r in t["rows"].as_array().unwrap() {
            assert!(
                r["params"].is_array() && r.get("psnr").is_some() && r.get("ms_ssim").is_some()
            );
            assert!(table.contains(r["variant"].as_str().unwrap()));
        }
    }
    // The density variants differ in exactly the free density.
    let t = json(&base.join("density/ablation.json"));
    let fixed = &t["rows"][0]["params"][0]["density"];
    let start = json(&base.join("density/runs/toyball/density_fixed/params.json"));
    assert_eq!(*fixed, start["parts"][0]["density"]);

    // A finished variant is not fitted again.
    let p = base.join("loss/runs/toyball/l1/params.json");
    let before = std::fs::metadata(&p).unwrap().modified().unwrap();
    abl("loss", &base.join("loss"), None);
    assert_eq!(std::fs::metadata(&p).unwrap().modified().unwrap(), before);

    // Two shards merge to the unsharded table, byte for byte.
    let sh = base.join("sharded");
    abl("loss", &sh, Some("1/2"));
    // A gap: shard 0 has not run.
    let out = r4d(&["merge", sh.to_str().unwrap()]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("shard-0-of-2"), "{err}");
    abl("loss", &sh, Some("0/2"));
    let table = ok(&["merge", sh.to_str().unwrap()]);
    assert!(table.contains("SSIM+FFT"));
    assert_eq!(
        std::fs::read(sh.join("ablation.json")).unwrap(),
        std::fs::read(base.join("loss/ablation.json")).unwrap()
    );
    let s0 = json(&sh.join("shard-0-of-2/shard.json"));
    assert_eq!(
        s0["items"],
        serde_json::json!(["toyball/l1", "toyball/l1_fft"])
    );

    // An overlap: a shard of another split in the same folder.
    std::fs::create_dir_all(sh.join("shard-0-of-3")).unwrap();
    let out = r4d(&["merge", sh.to_str().unwrap()]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("overlap"));

    // The main table over a list of scenes, sharded across them.
    let scenes = base.join("scenes");
    for name in ["ball_a", "ball_b"] {
        common::copy_dir(
            &common::fixture("datasets").join("pacnerf/toyball"),
            &scenes.join(name),
        );
        let cfg_json = scenes.join(name).join("toyball_config.json");
        std::fs::rename(
            &cfg_json,
            scenes.join(name).join(format!("{name}_config.json")),
        )
        .unwrap();
    }
    let (a_, b_) = (scenes.join("ball_a"), scenes.join("ball_b"));
    let main_args = |out: &Path, shard: Option<&str>| {
        let mut v: Vec<String> = ["ablate", "--study", "main", "--config", cfg]
            .iter()
            .map(|s| s.to_string())
            .collect();
        for d in [&a_, &b_] {
            v.extend(["--dataset".into(), d.display().to_string()]);
        }
        v.extend(["--out".into(), out.display().to_string()]);
        if let Some(s) = shard {
            v.extend(["--shard".into(), s.into()]);
        }
        v
    };
    let run = |args: Vec<String>| ok(&args.iter().map(String::as_str).collect::<Vec<_>>());
    let whole = base.join("main_whole");
    let table = run(main_args(&whole, None));
    assert!(
        table.contains("ball_a") && table.contains("ball_b"),
        "{table}"
    );
    let split = base.join("main_split");
    run(main_args(&split, Some("0/2")));
    run(main_args(&split, Some("1/2")));
    ok(&["merge", split.to_str().unwrap()]);
    assert_eq!(
        std::fs::read(split.join("ablation.json")).unwrap(),
        std::fs::read(whole.join("ablation.json")).unwrap()
    );

    // Bad --shard values are refused before any work.
    let out = r4d(&[
        "ablate",
        "--dataset",
        ds,
        "--study",
        "loss",
        "--out",
        base.join("x").to_str().unwrap(),
        "--shard",
        "2/2",
    ]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("--shard 2/2"));
}

#[test]
fn sharded_initialisation_merges_and_resumes_to_the_unsharded_fit() {
    let base = tmp("lhs");
    let ds = common::fixture("datasets").join("pacnerf/toyball");
    let ds = ds.to_str().unwrap();
    let cfg = base.join("fit.toml");
    std::fs::write(
        &cfg,
        "iters = 2\nlr = 0.1\n[init]\ncandidates = 5\nframes = 2\n",
    )
    .unwrap();
    let cfg = cfg.to_str().unwrap();
    let full = base.join("full");
    ok(&[
        "fit",
        "--dataset",
        ds,
        "--config",
        cfg,
        "--out",
        full.to_str().unwrap(),
    ]);
    let sh = base.join("sharded");
    let s = sh.to_str().unwrap();
    for i in ["2/3", "0/3"] {
        ok(&[
            "fit",
            "--dataset",
            ds,
            "--config",
            cfg,
            "--out",
            s,
            "--shard",
            i,
        ]);
    }
    let out = r4d(&["merge", s]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("shard-1-of-3"));
    ok(&[
        "fit",
        "--dataset",
        ds,
        "--config",
        cfg,
        "--out",
        s,
        "--shard",
        "1/3",
    ]);
    let merged = ok(&["merge", s]);
    assert!(merged.contains("5 candidates from 3 shard(s)"), "{merged}");
    assert_eq!(json(&sh.join("init.json")), json(&full.join("init.json")));
    ok(&["fit", "--resume", s]);
    assert_eq!(
        std::fs::read(sh.join("params.json")).unwrap(),
        std::fs::read(full.join("params.json")).unwrap()
    );
    // A shard of another fit's settings is refused.
    let other = base.join("other.toml");
    std::fs::write(&other, "iters = 2\n[init]\ncandidates = 5\nframes = 3\n").unwrap();
    let mixed = base.join("mixed");
    let m = mixed.to_str().unwrap();
    ok(&[
        "fit",
        "--dataset",
        ds,
        "--config",
        cfg,
        "--out",
        m,
        "--shard",
        "0/2",
    ]);
    ok(&[
        "fit",
        "--dataset",
        ds,
        "--config",
        other.to_str().unwrap(),
        "--out",
        m,
        "--shard",
        "1/2",
    ]);
    let out = r4d(&["merge", m]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("different fits"));
}
