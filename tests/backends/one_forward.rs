//! One forward pass: `r4d simulate` and the forward pass of a fit (the generic
//! differentiable stepper `Simulation` on the CPU backend) run the same substep code, so
//! their positions are bitwise equal, for every material's shipped config (the fluid has no
//! adjoint and is left out).

use r4d_backend_cpu::{CpuBackend, Par};
use r4d_mpm::adjoint::checkpoint::Differentiable;
use r4d_mpm::adjoint::host::{HostSim, PhysParams};
use r4d_mpm::simulation::infallible;
use r4d_mpm::Simulation;
use r4d_mpm::{Material, ParticleSet, SimConfig};
use std::path::PathBuf;
use std::process::Command;

fn repo(p: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join(p)
}

/// Positions after `frames` frames from `r4d simulate` (its PLY frame) and from the fit's
/// stepper, for one config.
fn compare(config: &str, frames: usize) {
    let path = repo(config);
    let cfg = SimConfig::load(&path).unwrap();
    let out = std::env::temp_dir().join(format!(
        "r4d_one_forward_{}_{}",
        std::process::id(),
        path.file_stem().unwrap().to_string_lossy()
    ));
    let _ = std::fs::remove_dir_all(&out);
    let o = Command::new(env!("CARGO_BIN_EXE_r4d"))
        .args([
            "simulate",
            "--config",
            path.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
            "--frames",
            &frames.to_string(),
        ])
        .output()
        .unwrap();
    assert!(
        o.status.success(),
        "{config}: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    let ply = r4d_mpm::ply::read_ply(&out.join(format!("frame_{frames:04}.ply"))).unwrap();
    let (x, y, z) = (
        ply.get("x").unwrap(),
        ply.get("y").unwrap(),
        ply.get("z").unwrap(),
    );
    let scene = ParticleSet::from_shapes(&cfg.shapes, cfg.domain.dx());
    let sim = HostSim::new(&cfg, &scene).unwrap();
    let fit = infallible(Simulation::with_host(
        CpuBackend::<f32>::with_par(Par::Rayon),
        &sim,
    ));
    let params: Vec<PhysParams<f32>> = cfg.parts.iter().map(PhysParams::of).collect();
    let mut s = infallible(fit.init(&params, &vec![[0.0; 3]; sim.len()]));
    let substeps = frames as u64 * sim.setup.substeps_per_frame as u64;
    for k in 0..substeps {
        infallible(fit.step(&mut s, &params, k));
    }
    assert_eq!(s.x.len(), x.len(), "{config}: particle count");
    let mut moved = 0.0f64;
    for (p, q) in s.x.iter().enumerate() {
        let cli = [x[p], y[p], z[p]];
        assert_eq!(
            q.map(f32::to_bits),
            cli.map(f32::to_bits),
            "{config}: particle {p}: fit forward {q:?} vs r4d simulate {cli:?}"
        );
        moved = moved.max((q[2] - scene.x[p][2]).abs() as f64);
    }
    // The comparison is only meaningful if the scene moved.
    assert!(moved > 1e-4, "{config}: nothing moved ({moved})");
    let _ = std::fs::remove_dir_all(&out);
}

/// One test per material, each on its shipped config.
macro_rules! bitwise {
    ($($name:ident: $config:literal, $material:expr;)*) => {$(
        #[test]
        fn $name() {
            let c = SimConfig::load(&repo($config)).unwrap();
            assert!(c.parts.iter().any(|p| p.material == $material), "{}", $config);
            compare($config, 1);
        }
    )*};
}

bitwise! {
    jelly_simulate_equals_fit_forward: "configs/jelly_drop.toml", Material::Jelly;
    metal_simulate_equals_fit_forward: "configs/metal_bar.toml", Material::Metal;
    sand_simulate_equals_fit_forward: "configs/sand_column.toml", Material::Sand;
    foam_simulate_equals_fit_forward: "configs/foam_press.toml", Material::Foam;
    snow_simulate_equals_fit_forward: "configs/snow_drop.toml", Material::Snow;
    plasticine_simulate_equals_fit_forward: "configs/plasticine_drop.toml", Material::Plasticine;
}
