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
        "strategy = \"fixed\"\niters = 1\nlr = 0.1\n[init]\ncandidates = 2\nframes = 2\n",
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
        "strategy = \"fixed\"\niters = 2\nlr = 0.1\n[init]\ncandidates = 5\nframes = 2\n",
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
    std::fs::write(
        &other,
        "strategy = \"fixed\"\niters = 2\n[init]\ncandidates = 5\nframes = 3\n",
    )
    .unwrap();
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

/// `r4d` in the working directory `cwd`.
fn r4d_in(cwd: &Path, args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_r4d"))
        .current_dir(cwd)
        .args(args)
        .output()
        .expect("run r4d")
}

/// Expects `out` to be a refusal (no panic) whose message contains every needle.
fn refused(out: &std::process::Output, needles: &[&str]) {
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "accepted: {err}");
    assert!(!err.contains("panicked"), "{err}");
    for n in needles {
        assert!(err.contains(n), "'{n}' not in: {err}");
    }
}

/// Files another run (or a hand) wrote are checked before use: `eval` verifies a run
/// folder's parameters, invocation and settings against the fit's fingerprint and bounds;
/// `merge` refuses non-numeric and out-of-range metrics, non-physical parameters and forged
/// initialisation candidates; run folders store absolute paths, so that `fit --resume` and
/// `eval` work from any working directory (and older folders with relative paths still
/// resolve).
#[test]
fn runs_trust_nothing_another_run_wrote() {
    let base = tmp("foreign");
    let ds_a = base.join("data/toyball");
    common::copy_dir(&common::fixture("datasets").join("pacnerf/toyball"), &ds_a);
    // Another scene: the same ball, stiffer at the start.
    let ds_b = base.join("data/other");
    common::copy_dir(&ds_a, &ds_b);
    let text = std::fs::read_to_string(ds_b.join("toyball_config.json")).unwrap();
    std::fs::remove_file(ds_b.join("toyball_config.json")).unwrap();
    std::fs::write(
        ds_b.join("other_config.json"),
        text.replace("\"E\": 0.005", "\"E\": 0.007"),
    )
    .unwrap();
    std::fs::write(
        base.join("fit.toml"),
        "strategy = \"fixed\"\niters = 1\nlr = 0.1\n[init]\ncandidates = 2\nframes = 2\n",
    )
    .unwrap();
    // Fits run from `base` with paths relative to it.
    let fit = |ds: &str, out: &str| {
        let o = r4d_in(
            &base,
            &["fit", "--dataset", ds, "--config", "fit.toml", "--out", out],
        );
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    };
    fit("data/toyball", "runs/a");
    fit("data/other", "runs/b");
    let (run_a, run_b) = (base.join("runs/a"), base.join("runs/b"));
    let inv = json(&run_a.join("invocation.json"));
    for k in ["dataset", "config", "out"] {
        assert!(
            Path::new(inv[k].as_str().unwrap()).is_absolute(),
            "invocation.json {k}: {}",
            inv[k]
        );
    }
    assert!(json(&run_a.join("params.json"))["fingerprint"].is_string());
    // From another working directory.
    let elsewhere = base.join("elsewhere");
    std::fs::create_dir_all(&elsewhere).unwrap();
    let ok_in = |cwd: &Path, args: &[&str]| {
        let o = r4d_in(cwd, args);
        assert!(
            o.status.success(),
            "{args:?}: {}",
            String::from_utf8_lossy(&o.stderr)
        );
    };
    ok_in(&elsewhere, &["eval", run_a.to_str().unwrap()]);

    // A copy of run a with one file replaced by `edit`, evaluated.
    let copy_with = |name: &str, edit: &dyn Fn(&Path)| {
        let d = base.join("forged").join(name);
        common::copy_dir(&run_a, &d);
        edit(&d);
        r4d_in(&elsewhere, &["eval", d.to_str().unwrap()])
    };
    // params.json of another scene's fit (same parts, same material).
    let o = copy_with("params_b", &|d| {
        std::fs::copy(run_b.join("params.json"), d.join("params.json")).unwrap();
    });
    refused(&o, &["params.json", "another fit"]);
    // invocation.json naming another scene; fit_config.json of other settings.
    let o = copy_with("inv_b", &|d| {
        let mut v = json(&d.join("invocation.json"));
        v["dataset"] = serde_json::json!(ds_b);
        std::fs::write(d.join("invocation.json"), v.to_string()).unwrap();
    });
    refused(&o, &["invocation.json", "not those the run was fitted on"]);
    let o = copy_with("cfg_b", &|d| {
        let mut v = json(&d.join("fit_config.json"));
        v["lr"] = serde_json::json!(0.3);
        std::fs::write(d.join("fit_config.json"), v.to_string()).unwrap();
    });
    refused(&o, &["fit_config.json", "not those the run was fitted on"]);
    // Parameter values: non-physical, outside the fit's bounds, not numbers.
    for (name, e, needle) in [
        ("e_neg", serde_json::json!(-1.0), "youngs_modulus_pa"),
        ("e_huge", serde_json::json!(1e12), "bounds"),
        ("e_text", serde_json::json!("banana"), "params.json"),
    ] {
        let o = copy_with(name, &|d| {
            let mut v = json(&d.join("params.json"));
            v["parts"][0]["E"] = e.clone();
            std::fs::write(d.join("params.json"), v.to_string()).unwrap();
        });
        refused(&o, &["params.json", needle]);
    }

    // Resume from another working directory: a run folder of today (absolute paths), and
    // one of an older r4d (paths relative to the directory its fit ran in), which resolves
    // from that directory and, where its paths lead there from the run folder, from any.
    ok_in(&elsewhere, &["fit", "--resume", run_a.to_str().unwrap()]);
    let old = base.join("runs/old");
    common::copy_dir(&run_a, &old);
    let relative_inv = |dataset: &str, config: &str| {
        let mut v = json(&old.join("invocation.json"));
        v["dataset"] = serde_json::json!(dataset);
        v["config"] = serde_json::json!(config);
        v["out"] = serde_json::json!("runs/old");
        std::fs::write(old.join("invocation.json"), v.to_string()).unwrap();
    };
    relative_inv("data/toyball", "fit.toml");
    let o = r4d_in(&elsewhere, &["fit", "--resume", old.to_str().unwrap()]);
    refused(&o, &["invocation.json", "--dataset data/toyball"]);
    ok_in(&base, &["fit", "--resume", "runs/old"]);
    // Rewritten with absolute paths by the resume.
    let v = json(&old.join("invocation.json"));
    assert_eq!(
        v["dataset"],
        serde_json::json!(std::path::absolute(&ds_a).unwrap())
    );
    relative_inv("../../data/toyball", "../../fit.toml");
    ok_in(&elsewhere, &["fit", "--resume", old.to_str().unwrap()]);
    ok_in(&elsewhere, &["eval", old.to_str().unwrap()]);

    // merge: forged rows of an ablation shard.
    let row = serde_json::json!({
        "scene": "toyball", "variant": "Resonance4D", "slug": "main",
        "params": json(&run_a.join("params.json"))["parts"],
        "ms_ssim": 0.9, "ms_ssim_small_window": null, "psnr": 30.0, "psnr_video": null,
        "lpips_alex": null, "lpips_vgg": null, "chamfer": null, "hd95": null, "f_score": null,
    });
    let merge_rows = |name: &str, edit: &dyn Fn(&mut serde_json::Value)| {
        let out = base.join("merge").join(name);
        let mut r = row.clone();
        edit(&mut r);
        let shard = serde_json::json!({
            "study": "main", "shard": 0, "of": 1, "scenes": ["toyball"],
            "items": ["toyball/main"], "rows": [r],
        });
        std::fs::create_dir_all(out.join("shard-0-of-1")).unwrap();
        std::fs::write(out.join("shard-0-of-1/shard.json"), shard.to_string()).unwrap();
        (r4d(&["merge", out.to_str().unwrap()]), out)
    };
    let (o, out) = merge_rows("valid", &|_| {});
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(out.join("ablation.json").is_file());
    for (name, key, value, needle) in [
        (
            "banana",
            "psnr",
            serde_json::json!("banana"),
            "not a number",
        ),
        (
            "ms_ssim_5",
            "ms_ssim",
            serde_json::json!(5.0),
            "outside [0, 1]",
        ),
        ("chamfer_neg", "chamfer", serde_json::json!(-1.0), "chamfer"),
    ] {
        let (o, out) = merge_rows(name, &|r| r[key] = value.clone());
        refused(&o, &["shard-0-of-1", "rows[0]", key, needle]);
        assert!(!out.join("ablation.json").exists());
    }
    let (o, _) = merge_rows("e_neg", &|r| r["params"][0]["E"] = serde_json::json!(-1.0));
    refused(&o, &["rows[0]", "youngs_modulus_pa"]);

    // merge: forged candidates of an initialisation shard.
    let sh = base.join("init_shards");
    let s = sh.to_str().unwrap();
    let shard_args = [
        "fit",
        "--dataset",
        "data/toyball",
        "--config",
        "fit.toml",
        "--out",
        s,
    ];
    ok_in(&base, &[&shard_args[..], &["--shard", "0/1"]].concat());
    let shard_json = sh.join("shard-0-of-1/shard.json");
    let good = json(&shard_json);
    let names: Vec<String> = serde_json::from_value(good["names"].clone()).unwrap();
    let e = names
        .iter()
        .position(|n| n.ends_with(".E"))
        .expect("E is free");
    type Edit = Box<dyn Fn(&mut serde_json::Value, usize)>;
    let forgeries: Vec<(&str, Edit, &str)> = vec![
        (
            "score 5",
            Box::new(|c, _| c["score"] = serde_json::json!(5.0)),
            "outside [0, 1]",
        ),
        (
            "E = -1",
            Box::new(|c, e| c["theta"][e] = serde_json::json!(-1.0)),
            "outside its bounds",
        ),
        (
            "a value short",
            Box::new(|c, _| {
                c["theta"].as_array_mut().unwrap().pop();
            }),
            "values for the",
        ),
    ];
    for (what, edit, needle) in forgeries {
        let mut v = good.clone();
        edit(&mut v["candidates"][1], e);
        std::fs::write(&shard_json, v.to_string()).unwrap();
        let o = r4d(&["merge", s]);
        refused(&o, &["shard-0-of-1", "candidate #1", needle]);
        assert!(
            !sh.join("checkpoint.json").exists(),
            "{what}: a checkpoint was written"
        );
    }
    std::fs::write(&shard_json, good.to_string()).unwrap();
    ok_in(&base, &["merge", s]);
    ok_in(&elsewhere, &["fit", "--resume", s]);
}
