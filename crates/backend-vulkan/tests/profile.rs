//! Per-kernel GPU timing (`VulkanEngine::set_profiling`, the CLI's `--profile`): every
//! dispatch of a simulated frame is timed once, under the kernel's name, with a positive time;
//! profiling changes no result; off, nothing is measured. Runs under the validation layer in
//! CI (the query pool's reset, writes and reads are checked there).

use r4d_backend_vulkan::testing::{assert_validation_clean, vulkan_or_skip};
use r4d_backend_vulkan::VulkanBackend;
use r4d_mpm::{ParticleSet, SimConfig, Simulation, Simulator};

const SUBSTEPS: u64 = 12;

fn frame(engine: &r4d_backend_vulkan::VulkanEngine) -> Vec<[f32; 3]> {
    let cfg: SimConfig = toml::from_str(&format!(
        r#"
domain = {{ grid_lim = 1.0, n_grid = 16 }}
time = {{ substep_dt = 2e-4, substeps_per_frame = {SUBSTEPS}, frames = 1 }}
[[parts]]
material = "metal"
[[shapes]]
kind = "box"
min = [0.4, 0.4, 0.4]
max = [0.6, 0.6, 0.6]
[[boundary]]
type = "bounding_box"
"#
    ))
    .unwrap();
    let scene = ParticleSet::from_shapes(&cfg.shapes, cfg.domain.dx());
    let mut sim =
        Simulation::new(VulkanBackend::new(engine.clone()), &cfg, scene, "profile").unwrap();
    let mut s = sim.init_state(&cfg.parts).unwrap();
    sim.step_frame(&mut s, &cfg.parts).unwrap();
    sim.positions(&s).unwrap()
}

#[test]
#[cfg_attr(
    not(r4d_gpu),
    ignore = "no GPU adapter expected here (no Vulkan driver found at build time): install mesa-vulkan-drivers libvulkan1, or build with R4D_REQUIRE_GPU=1"
)]
fn every_dispatch_is_timed_under_its_kernel() {
    let Some(engine) = vulkan_or_skip("vulkan profiling") else {
        return;
    };
    assert!(engine.kernel_times().is_empty(), "off by default");
    let plain = frame(&engine);
    if !engine.set_profiling(true).unwrap() {
        eprintln!("vulkan profiling: skipped: the device has no timestamps");
        return;
    }
    let timed = frame(&engine);
    engine.finish().unwrap();
    assert_eq!(plain, timed, "profiling changed the results");
    let times = engine.kernel_times();
    assert!(!times.is_empty());
    for t in &times {
        assert!(
            t.name.starts_with("mpm_") && t.seconds.is_finite() && t.seconds >= 0.0,
            "{t:?}"
        );
    }
    // The substep's scatter, grid update and gather run once per substep.
    for k in ["mpm_p2g", "mpm_grid_update", "mpm_g2p"] {
        let t = times
            .iter()
            .find(|t| t.name == k || t.name == format!("{k}_cas"))
            .unwrap_or_else(|| panic!("{k} not timed: {times:?}"));
        assert_eq!(t.dispatches, SUBSTEPS, "{k}");
        assert!(t.seconds > 0.0, "{k}: {t:?}");
    }
    let mut prev = f64::INFINITY;
    for t in &times {
        assert!(t.seconds <= prev, "slowest first");
        prev = t.seconds;
    }
    // Off: nothing measured any more.
    assert!(!engine.set_profiling(false).unwrap());
    assert!(engine.kernel_times().is_empty());
    assert_validation_clean(&engine, "vulkan profiling");
}
