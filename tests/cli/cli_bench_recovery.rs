//! `r4d bench-recovery` in its small version (the CI's): random scenes fitted under an
//! evaluation budget, one result file per scene, the table, resume and sharding, and typed
//! errors for bad arguments and mismatched settings.

use std::path::Path;
use std::process::{Command, Output};

fn r4d(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_r4d"))
        .args(args)
        .output()
        .expect("run r4d")
}

fn text(o: &Output) -> String {
    format!(
        "{}{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    )
}

fn bench(out: &Path, extra: &[&str]) -> Output {
    let mut args = vec![
        "bench-recovery",
        "--out",
        out.to_str().unwrap(),
        "--small",
        "--scenes",
        "1",
        "--materials",
        "jelly,sand",
        "--budget",
        "none",
        "--evals",
        "36",
    ];
    args.extend_from_slice(extra);
    r4d(&args)
}

/// Two shards fill one folder with a result per scene; the table holds both classes with
/// their determined and recovered counts; a resumed run fits nothing; other settings are
/// refused naming bench.json.
#[test]
fn bench_recovery_fits_scenes_resumes_and_refuses_other_settings() {
    let out = std::env::temp_dir().join(format!("r4d_bench_recovery_{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&out);
    for shard in ["0/2", "1/2"] {
        let o = bench(&out, &["--shard", shard]);
        assert!(o.status.success(), "{}", text(&o));
        assert!(text(&o).contains("1 scene(s) in this run"), "{}", text(&o));
    }
    for f in [
        "scenes/jelly-0.json",
        "scenes/sand-0.json",
        "table.md",
        "bench.json",
    ] {
        assert!(out.join(f).is_file(), "{f} missing");
    }
    let scene: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("scenes/sand-0.json")).unwrap()).unwrap();
    assert_eq!(scene["class"], "sand");
    assert!(scene["failed"].is_null(), "{scene}");
    assert!(scene["evals"].as_u64().unwrap() <= 36 + 1, "{scene}");
    let names: Vec<&str> = scene["params"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| p["name"].as_str().unwrap())
        .collect();
    assert_eq!(
        names,
        [
            "part0.E",
            "part0.nu",
            "part0.friction_angle",
            "part0.density"
        ]
    );
    let table = std::fs::read_to_string(out.join("table.md")).unwrap();
    assert!(
        table.contains("| jelly | 1 |") && table.contains("| sand | 1 |"),
        "{table}"
    );

    // Resumed: nothing left to fit, the same table.
    let o = bench(&out, &["--resume"]);
    assert!(o.status.success(), "{}", text(&o));
    assert!(
        text(&o).contains("2 done earlier, 0 to fit"),
        "{}",
        text(&o)
    );
    assert_eq!(
        std::fs::read_to_string(out.join("table.md")).unwrap(),
        table
    );
    // Without --resume the folder is refused; with other settings too.
    let o = bench(&out, &[]);
    assert!(!o.status.success());
    assert!(text(&o).contains("--resume"), "{}", text(&o));
    let o = r4d(&[
        "bench-recovery",
        "--out",
        out.to_str().unwrap(),
        "--small",
        "--evals",
        "99",
        "--resume",
    ]);
    assert!(!o.status.success());
    assert!(text(&o).contains("bench.json"), "{}", text(&o));
    // A folder from before the automatic strategy was the default (its bench.json records
    // no strategy: the fixed defaults) is not continued with the automatic one.
    let bench_json = out.join("bench.json");
    let saved = std::fs::read_to_string(&bench_json).unwrap();
    let mut old: serde_json::Value = serde_json::from_str(&saved).unwrap();
    assert_eq!(old["settings"]["strategy"], "auto");
    old["settings"].as_object_mut().unwrap().remove("strategy");
    std::fs::write(&bench_json, old.to_string()).unwrap();
    let o = bench(&out, &["--resume"]);
    assert!(!o.status.success());
    assert!(
        text(&o).contains("bench.json") && text(&o).contains("\"fixed\""),
        "{}",
        text(&o)
    );
    std::fs::write(&bench_json, saved).unwrap();
    // A result file that is not one is named.
    std::fs::write(out.join("scenes/foam-0.json"), b"{not json").unwrap();
    let o = r4d(&["bench-recovery", "--out", out.to_str().unwrap(), "--report"]);
    assert!(!o.status.success());
    assert!(text(&o).contains("foam-0.json"), "{}", text(&o));
    let _ = std::fs::remove_dir_all(&out);
}

/// Bad arguments are refused before any scene is drawn, naming the flag.
#[test]
fn bench_recovery_refuses_bad_arguments() {
    let out = std::env::temp_dir().join(format!("r4d_bench_recovery_bad_{}", std::process::id()));
    for (args, flag) in [
        (vec!["--materials", "water"], "--materials"),
        (vec!["--scenes", "0"], "--scenes"),
        (vec!["--evals", "0"], "--evals"),
        (vec!["--budget", "0s"], "--budget"),
        (vec!["--budget", "soon"], "--budget"),
        (vec!["--budget", "none"], "--evals"),
        (vec!["--shard", "2/2"], "--shard"),
    ] {
        let mut a = vec!["bench-recovery", "--out", out.to_str().unwrap()];
        a.extend(args.iter());
        let o = r4d(&a);
        assert!(!o.status.success(), "{args:?} accepted");
        assert!(text(&o).contains(flag), "{args:?}: {}", text(&o));
        assert!(!out.exists(), "{args:?} wrote {}", out.display());
    }
}
