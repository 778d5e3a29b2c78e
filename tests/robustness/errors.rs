//! Bad input and exploding simulations give typed errors that name the file, field, frame
//! and substep; never a panic, never silent garbage.

use crate::common;

use common::scenes::{boxed, config, jelly};
use r4d_backend_cpu::CpuBackend;
use r4d_mpm::{
    BoundaryCondition, Error, OutOfDomain, PartParams, ParticleSet, SimConfig, Simulation,
    Simulator,
};

fn tmp(name: &str) -> std::path::PathBuf {
    let d = std::env::temp_dir().join(format!("r4d_errors_{}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d.join(name)
}

#[test]
fn a_substep_beyond_the_cfl_bound_is_refused_up_front() {
    let cfg = config(32, 1e-2, 1, jelly(1e6));
    let scene = boxed(&cfg, [0.4; 3], [0.6; 3]);
    let e = Simulation::new(CpuBackend::default(), &cfg, scene, "t")
        .err()
        .unwrap();
    assert!(matches!(e, Error::CflViolation { .. }), "{e}");
    let msg = e.to_string();
    assert!(
        msg.contains("dt must be <=") && msg.contains("part 0"),
        "{msg}"
    );
}

#[test]
fn a_viscosity_beyond_the_explicit_stability_bound_is_refused_up_front() {
    // Measured: this block explodes from viscosity dt / (rho dx^2) = 0.66 (7000 Pa s here);
    // the bound is 0.5 (4883 Pa s).
    let fluid = |eta: f64| PartParams {
        material: r4d_mpm::Material::Fluid,
        youngs_modulus_pa: 1.2e5,
        plastic_viscosity_pa_s: eta,
        density_kg_m3: 1000.0,
        ..Default::default()
    };
    let cfg = config(32, 1e-4, 1, fluid(7000.0));
    let scene = boxed(&cfg, [0.4; 3], [0.6; 3]);
    let e = Simulation::new(CpuBackend::default(), &cfg, scene.clone(), "t")
        .err()
        .unwrap();
    assert!(matches!(e, Error::ViscousStability { part: 0, .. }), "{e}");
    let e = cfg.validate("fluid.toml").unwrap_err().to_string();
    assert!(
        e.contains("fluid.toml") && e.contains("parts[0].plastic_viscosity_pa_s"),
        "{e}"
    );
    let ok = config(32, 1e-4, 1, fluid(4800.0));
    assert!(Simulation::new(CpuBackend::default(), &ok, scene, "t").is_ok());
}

#[test]
fn an_exploding_simulation_stops_with_frame_and_substep() {
    // max_cfl 20 lets an unstable dt through the up-front check; the run must then stop.
    let mut cfg = config(32, 2e-3, 50, jelly(1e6));
    cfg.solver.max_cfl = 20.0;
    cfg.solver.gravity = [0.0, 0.0, -9.8];
    cfg.boundary = vec![BoundaryCondition::BoundingBox {
        layers: 3,
        surface: Default::default(),
    }];
    let scene = boxed(&cfg, [0.4; 3], [0.6; 3]);
    let mut sim = Simulation::new(CpuBackend::default(), &cfg, scene, "t").unwrap();
    let mut st = sim.init_state(&cfg.parts).unwrap();
    let mut err = None;
    for _ in 0..20 {
        if let Err(e) = sim.step_frame(&mut st, &cfg.parts) {
            err = Some(e);
            break;
        }
    }
    let e = err.expect("an unstable run must report an error");
    let msg = e.to_string();
    assert!(
        matches!(
            e,
            Error::SpeedLimit { .. } | Error::NonFinite { .. } | Error::OutOfDomain { .. }
        ),
        "{msg}"
    );
    assert!(msg.contains("frame") && msg.contains("substep"), "{msg}");
}

#[test]
fn leaving_the_domain_is_an_error_or_clamped_by_policy() {
    let mut cfg: SimConfig = config(32, 1e-4, 100, jelly(1e5));
    cfg.solver.gravity = [0.0, 0.0, -200.0];
    let scene = boxed(&cfg, [0.45, 0.45, 0.1], [0.55, 0.55, 0.2]);
    let mut sim = Simulation::new(CpuBackend::default(), &cfg, scene.clone(), "t").unwrap();
    let mut st = sim.init_state(&cfg.parts).unwrap();
    let e = (0..50)
        .find_map(|_| sim.step_frame(&mut st, &cfg.parts).err())
        .expect("must fail");
    assert!(matches!(e, Error::OutOfDomain { axis: 2, .. }), "{e}");
    // The message names the axis that left (gravity pulls along -z here).
    assert!(e.to_string().contains("(z = "), "{e}");

    cfg.solver.out_of_domain = OutOfDomain::Clamp;
    let mut sim = Simulation::new(CpuBackend::default(), &cfg, scene, "t").unwrap();
    let mut st = sim.init_state(&cfg.parts).unwrap();
    for _ in 0..10 {
        sim.step_frame(&mut st, &cfg.parts).unwrap();
    }
    let dx = cfg.domain.dx() as f32;
    for p in sim.positions(&st).unwrap() {
        assert!(p.iter().all(|&c| c >= 0.5 * dx && c < 30.5 * dx), "{p:?}");
    }
}

#[test]
fn invalid_parameters_name_the_part_and_field() {
    let cfg = config(32, 1e-4, 1, jelly(1e5));
    let scene = boxed(&cfg, [0.4; 3], [0.6; 3]);
    let sim = Simulation::new(CpuBackend::default(), &cfg, scene, "t").unwrap();
    for (p, field) in [
        (
            PartParams {
                poisson_ratio: 0.5,
                ..jelly(1e5)
            },
            "poisson_ratio",
        ),
        (
            PartParams {
                youngs_modulus_pa: -3.0,
                ..jelly(1e5)
            },
            "youngs_modulus_pa",
        ),
        (
            PartParams {
                density_kg_m3: f64::NAN,
                ..jelly(1e5)
            },
            "density_kg_m3",
        ),
    ] {
        let e = sim.init_state(&[p]).err().unwrap().to_string();
        assert!(e.contains("parts[0]") && e.contains(field), "{e}");
    }
    let e = sim
        .init_state(&[jelly(1e5), jelly(1e5)])
        .err()
        .unwrap()
        .to_string();
    assert!(e.contains("2 part parameter sets"), "{e}");
}

#[test]
fn bad_particles_name_the_file_and_particle() {
    let cfg = config(32, 1e-4, 1, jelly(1e5));
    let mut scene = boxed(&cfg, [0.4; 3], [0.6; 3]);
    scene.x[7] = [0.5, f32::NAN, 0.5];
    let e = Simulation::new(CpuBackend::default(), &cfg, scene.clone(), "in.ply")
        .err()
        .unwrap()
        .to_string();
    assert!(e.contains("in.ply") && e.contains("particle 7"), "{e}");
    scene.x[7] = [0.5, 1.5, 0.5];
    let e = Simulation::new(CpuBackend::default(), &cfg, scene.clone(), "in.ply")
        .err()
        .unwrap()
        .to_string();
    assert!(e.contains("outside the grid"), "{e}");
    scene.x[7] = [0.5; 3];
    scene.part[3] = 4;
    let e = Simulation::new(CpuBackend::default(), &cfg, scene, "in.ply")
        .err()
        .unwrap()
        .to_string();
    assert!(e.contains("particle 3") && e.contains("part 4"), "{e}");
}

#[test]
fn malformed_ply_files_are_typed_errors() {
    let f = tmp("truncated.ply");
    std::fs::write(&f, b"ply\nformat binary_little_endian 1.0\nelement vertex 10\nproperty float x\nproperty float y\nproperty float z\nend_header\n\x00\x00\x00\x00").unwrap();
    let e = ParticleSet::from_ply(&f, 1.0 / 32.0).err().unwrap();
    assert!(matches!(e, Error::Ply { .. }), "{e}");
    assert!(e.to_string().contains("truncated.ply"));
    let f = tmp("noz.ply");
    std::fs::write(&f, b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nend_header\n0.5 0.5\n").unwrap();
    let e = ParticleSet::from_ply(&f, 1.0 / 32.0)
        .err()
        .unwrap()
        .to_string();
    assert!(e.contains("noz.ply") && e.contains("'z'"), "{e}");
    let e = ParticleSet::from_ply(&tmp("missing.ply"), 1.0 / 32.0)
        .err()
        .unwrap()
        .to_string();
    assert!(e.contains("missing.ply"), "{e}");
}

#[test]
fn malformed_configs_name_the_file_and_field() {
    let f = tmp("bad.toml");
    std::fs::write(&f, "[time]\nsubstep_dt = 1e-4\nframes = 2\n[[parts]]\nmaterial = \"jelly\"\npoisson_ratio = 0.7\n[[shapes]]\nkind = \"box\"\nmin = [0.4,0.4,0.4]\nmax = [0.6,0.6,0.6]\n").unwrap();
    let e = SimConfig::load(&f).err().unwrap().to_string();
    assert!(e.contains("bad.toml") && e.contains("poisson_ratio"), "{e}");
    std::fs::write(
        &f,
        "[time]\nsubstep_dt = 1e-4\nframes = 2\n[[parts]]\nmaterial = \"rubber\"\n",
    )
    .unwrap();
    let e = SimConfig::load(&f).err().unwrap().to_string();
    assert!(e.contains("bad.toml") && e.contains("rubber"), "{e}");
    std::fs::write(
        &f,
        "[time]\nsubstep_dt = 1e-4\nframes = 2\nfoo = 1\n[[parts]]\nmaterial = \"jelly\"\n",
    )
    .unwrap();
    let e = SimConfig::load(&f).err().unwrap().to_string();
    assert!(e.contains("foo"), "{e}");
}

/// A user-given index or count that the code indexes or divides by (a cylinder's axis, the
/// I and N of a `shard-I-of-N` folder) is checked first: a typed error naming the file, the
/// field and the rule, never a panic.
#[test]
fn user_given_axes_and_shard_counts_are_checked_before_use() {
    let f = tmp("axis5.toml");
    for axis in [3, 5, 1usize << 40] {
        std::fs::write(
            &f,
            format!("[time]\nsubstep_dt = 1e-4\nframes = 2\n[[parts]]\nmaterial = \"jelly\"\n[[shapes]]\nkind = \"cylinder\"\nbase = [0.5, 0.5, 0.3]\naxis = {axis}\nradius = 0.1\nlength = 0.2\n"),
        )
        .unwrap();
        let e = SimConfig::load(&f).err().unwrap().to_string();
        assert!(
            e.contains("axis5.toml")
                && e.contains("shapes[0]")
                && e.contains(&format!("axis = {axis}")),
            "{e}"
        );
        // Through the command too (its own validation path).
        let o = std::process::Command::new(env!("CARGO_BIN_EXE_r4d"))
            .args(["simulate", "--config", f.to_str().unwrap(), "--out"])
            .arg(tmp("axis5_out"))
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success() && !err.contains("panicked"), "{err}");
        assert!(err.contains("shapes[0]") && err.contains("axis"), "{err}");
    }
    // Sampled without validation, the shape gives no particle (no panic).
    let s: r4d_mpm::Shape = toml::from_str(
        "kind = \"cylinder\"\nbase = [0.5, 0.5, 0.3]\naxis = 5\nradius = 0.1\nlength = 0.2\n",
    )
    .unwrap();
    assert!(ParticleSet::from_shapes(&[s], 1.0 / 32.0).is_empty());

    // Shard folders whose numbers break the rule of --shard I/N.
    for name in ["shard-0-of-0", "shard-3-of-2", "shard-0-of-100001"] {
        let out = tmp(&format!("merge_{name}"));
        let _ = std::fs::remove_dir_all(&out);
        std::fs::create_dir_all(out.join(name)).unwrap();
        std::fs::write(
            out.join(name).join("shard.json"),
            r#"{"kind": "init", "shard": 0, "of": 0, "total": 0, "candidates": []}"#,
        )
        .unwrap();
        let o = std::process::Command::new(env!("CARGO_BIN_EXE_r4d"))
            .args(["merge", out.to_str().unwrap()])
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(
            !o.status.success() && !err.contains("panicked"),
            "{name}: {err}"
        );
        assert!(
            err.contains(name) && err.contains("0 <= I < N"),
            "{name}: {err}"
        );
    }
}
