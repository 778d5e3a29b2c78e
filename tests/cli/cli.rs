//! The `r4d` binary: output layout and formats, PhysGaussian import, error exit codes.

use crate::common;

use common::fixture;
use r4d_mpm::ply::read_ply;
use std::path::{Path, PathBuf};
use std::process::Command;

fn r4d(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_r4d"))
        .args(args)
        .output()
        .unwrap()
}

fn out_dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("r4d_cli_{}_{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    d
}

fn repo(rel: &str) -> String {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join(rel)
        .display()
        .to_string()
}

#[test]
fn simulate_writes_frames_with_f_and_a_summary() {
    let out = out_dir("demo");
    let o = r4d(&[
        "simulate",
        "--config",
        &repo("configs/jelly_drop.toml"),
        "--out",
        out.to_str().unwrap(),
        "--frames",
        "2",
        "--write-f",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let f0 = read_ply(&out.join("frame_0000.ply")).unwrap();
    let f2 = read_ply(&out.join("frame_0002.ply")).unwrap();
    assert!(!out.join("frame_0003.ply").exists());
    let names: Vec<&str> = f2.columns.iter().map(|c| c.0.as_str()).collect();
    assert_eq!(
        names,
        ["x", "y", "z", "f00", "f01", "f02", "f10", "f11", "f12", "f20", "f21", "f22"]
    );
    assert_eq!(f0.get("f00").unwrap()[0], 1.0);
    assert!(
        f2.get("z").unwrap()[0] < f0.get("z").unwrap()[0],
        "the cube falls"
    );
    let s: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    assert_eq!(s["frames"], 3);
    assert_eq!(s["particles"], f0.count);
    assert_eq!(s["substeps"], 400);
    assert!(s["wall_time_s"].as_f64().unwrap() > 0.0);
    assert_eq!(s["config"]["parts"][0]["material"], "jelly");
}

#[test]
fn physgaussian_scene_imports_and_keeps_input_order() {
    let out = out_dir("pg");
    let dir = fixture("physgaussian/fit_jelly_arch");
    let o = r4d(&[
        "simulate",
        "--physgaussian",
        "--config",
        dir.join("physgaussian_config.json").to_str().unwrap(),
        "--particles",
        dir.join("particles.ply").to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--frames",
        "1",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let input = read_ply(&dir.join("particles.ply")).unwrap();
    let f0 = read_ply(&out.join("frame_0000.ply")).unwrap();
    assert_eq!(f0.count, 2592);
    assert_eq!(f0.get("x").unwrap(), input.get("x").unwrap());
    let f1 = read_ply(&out.join("frame_0001.ply")).unwrap();
    assert!(
        f1.get("x").unwrap()[2000] > input.get("x").unwrap()[2000],
        "impulse pushes +x"
    );
}

#[test]
fn bad_input_exits_nonzero_naming_the_file() {
    let out = out_dir("bad");
    std::fs::create_dir_all(&out).unwrap();
    let ply = out.join("broken.ply");
    std::fs::write(
        &ply,
        b"ply\nformat binary_little_endian 1.0\nelement vertex 5\nproperty float x\nend_header\n",
    )
    .unwrap();
    let o = r4d(&[
        "simulate",
        "--config",
        &repo("configs/jelly_drop.toml"),
        "--particles",
        ply.to_str().unwrap(),
        "--out",
        out.join("o").to_str().unwrap(),
    ]);
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("broken.ply"), "{err}");
    let o = r4d(&[
        "simulate",
        "--config",
        "/nonexistent.toml",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("/nonexistent.toml"));
}

#[test]
fn every_shipped_config_loads_and_runs_a_substep() {
    use r4d_backend_cpu::CpuBackend;
    use r4d_mpm::{ParticleSet, SimConfig, Simulation, Simulator};
    let mut n = 0;
    for e in std::fs::read_dir(repo("configs")).unwrap() {
        let p = e.unwrap().path();
        // `configs/demo/` holds the demo scenes' files (built by `r4d_demo::scene_file`,
        // tested there), not simulation configs.
        if p.is_dir() {
            continue;
        }
        let cfg = SimConfig::load(&p).unwrap_or_else(|e| panic!("{e}"));
        let scene = ParticleSet::from_shapes(&cfg.shapes, cfg.domain.dx());
        let sim = Simulation::new(CpuBackend::default(), &cfg, scene, &p.display().to_string())
            .unwrap_or_else(|e| panic!("{e}"));
        let mut st = sim.init_state(&cfg.parts).unwrap();
        sim.step_substep(&mut st).unwrap();
        n += 1;
    }
    assert!(n >= 7);
}

#[test]
fn fit_trajectory_writes_params_json_and_a_log() {
    let truth = out_dir("fit_truth");
    let o = r4d(&[
        "simulate",
        "--config",
        &repo("tests/fixtures/fit/beam.toml"),
        "--out",
        truth.to_str().unwrap(),
        "--frames",
        "2",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let out = out_dir("fit_out");
    let o = r4d(&[
        "fit-trajectory",
        "--config",
        &repo("tests/fixtures/fit/beam_start.toml"),
        "--target",
        truth.to_str().unwrap(),
        "--params",
        "E,density",
        "--out",
        out.to_str().unwrap(),
        "--iters",
        "2",
        "--frames",
        "2",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let p: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("params.json")).unwrap()).unwrap();
    let part = &p["parts"][0];
    assert_eq!(part["id"], 0);
    assert_eq!(part["material"], "jelly");
    for key in [
        "E",
        "nu",
        "density",
        "yield_stress",
        "plastic_viscosity",
        "friction_angle",
    ] {
        assert!(part[key].is_number(), "{key} missing: {p}");
    }
    let log = std::fs::read_to_string(out.join("log.jsonl")).unwrap();
    assert_eq!(log.lines().count(), 2);
    let first: serde_json::Value = serde_json::from_str(log.lines().next().unwrap()).unwrap();
    assert!(first["loss"]["total"].as_f64().unwrap() > 0.0 && first["grad_norm"].is_number());
    // A run continued with --resume picks up after the last completed iteration.
    let o = r4d(&[
        "fit-trajectory",
        "--config",
        &repo("tests/fixtures/fit/beam_start.toml"),
        "--target",
        truth.to_str().unwrap(),
        "--params",
        "E,density",
        "--out",
        out.to_str().unwrap(),
        "--iters",
        "3",
        "--frames",
        "2",
        "--resume",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(String::from_utf8_lossy(&o.stderr).contains("resuming after iteration 2"));
    let log = std::fs::read_to_string(out.join("log.jsonl")).unwrap();
    assert_eq!(log.lines().count(), 3);
    assert!(out.join("checkpoint.json").exists());
    // Bad parameter names are refused with the list of known ones.
    let o = r4d(&[
        "fit-trajectory",
        "--config",
        &repo("tests/fixtures/fit/beam_start.toml"),
        "--target",
        truth.to_str().unwrap(),
        "--params",
        "stiffness",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("unknown parameter 'stiffness'"));
}

#[test]
fn per_particle_fit_writes_a_parameter_ply() {
    let truth = out_dir("pp_truth");
    let o = r4d(&[
        "simulate",
        "--config",
        &repo("tests/fixtures/fit/beam.toml"),
        "--out",
        truth.to_str().unwrap(),
        "--frames",
        "1",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let out = out_dir("pp_out");
    let o = r4d(&[
        "fit-trajectory",
        "--config",
        &repo("tests/fixtures/fit/beam_start.toml"),
        "--target",
        truth.to_str().unwrap(),
        "--params",
        "E",
        "--out",
        out.to_str().unwrap(),
        "--iters",
        "2",
        "--frames",
        "1",
        "--granularity",
        "particle",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let ply = read_ply(&out.join("params_particles.ply")).unwrap();
    let frame = read_ply(&truth.join("frame_0000.ply")).unwrap();
    assert_eq!(ply.count, frame.count);
    let e = ply.get("E").unwrap();
    // The steps moved the per-particle moduli away from the 2e6 start, each on its own.
    let (lo, hi) = e
        .iter()
        .fold((f32::MAX, f32::MIN), |(a, b), &v| (a.min(v), b.max(v)));
    assert!(lo < 2e6 && hi > lo, "E in [{lo}, {hi}]");
    let p: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("params.json")).unwrap()).unwrap();
    let mean = p["parts"][0]["E"].as_f64().unwrap();
    assert!(
        mean >= lo as f64 * 0.999 && mean <= hi as f64 * 1.001,
        "{mean}"
    );
}

#[test]
fn a_resumed_simulation_writes_the_same_frames_as_an_uninterrupted_one() {
    let full = out_dir("resume_full");
    let o = r4d(&[
        "simulate",
        "--config",
        &repo("configs/metal_bar.toml"),
        "--out",
        full.to_str().unwrap(),
        "--frames",
        "4",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    // A run "killed" after frame 2, then resumed to frame 4.
    let part = out_dir("resume_part");
    let o = r4d(&[
        "simulate",
        "--config",
        &repo("configs/metal_bar.toml"),
        "--out",
        part.to_str().unwrap(),
        "--frames",
        "2",
    ]);
    assert!(o.status.success());
    let o = r4d(&[
        "simulate",
        "--config",
        &repo("configs/metal_bar.toml"),
        "--out",
        part.to_str().unwrap(),
        "--frames",
        "4",
        "--resume",
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(String::from_utf8_lossy(&o.stderr).contains("resuming after frame 2"));
    for k in 0..=4 {
        let name = format!("frame_{k:04}.ply");
        let a = std::fs::read(full.join(&name)).unwrap();
        let b = std::fs::read(part.join(&name)).unwrap();
        assert!(a == b, "{name} differs");
    }
    // A snapshot of another scene is refused with a typed error naming the file.
    let o = r4d(&[
        "simulate",
        "--config",
        &repo("configs/jelly_drop.toml"),
        "--out",
        part.to_str().unwrap(),
        "--frames",
        "5",
        "--resume",
    ]);
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("state.r4d"));
}
