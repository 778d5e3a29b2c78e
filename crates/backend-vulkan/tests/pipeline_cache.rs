//! The pipeline cache on disk: written when an engine goes, read by the next; a damaged or
//! foreign file is ignored (the engine compiles from scratch), never trusted.

use r4d_backend_vulkan::testing::vulkan_or_skip;
use r4d_backend_vulkan::VulkanBackend;
use r4d_mpm::{ParticleSet, SimConfig, Simulation, Simulator};

fn simulate() -> Option<Vec<[f32; 3]>> {
    let engine = vulkan_or_skip("pipeline cache")?;
    let cfg: SimConfig = toml::from_str(
        r#"
domain = { grid_lim = 1.0, n_grid = 16 }
time = { substep_dt = 2e-4, substeps_per_frame = 10, frames = 1 }
[[parts]]
material = "jelly"
[[shapes]]
kind = "box"
min = [0.4, 0.4, 0.4]
max = [0.6, 0.6, 0.6]
[[boundary]]
type = "bounding_box"
"#,
    )
    .unwrap();
    let scene = ParticleSet::from_shapes(&cfg.shapes, cfg.domain.dx());
    let mut sim =
        Simulation::new(VulkanBackend::new(engine.clone()), &cfg, scene, "cache").unwrap();
    let mut s = sim.init_state(&cfg.parts).unwrap();
    sim.step_frame(&mut s, &cfg.parts).unwrap();
    let x = sim.positions(&s).unwrap();
    r4d_backend_vulkan::testing::assert_validation_clean(&engine, "pipeline cache");
    Some(x)
}

#[test]
#[cfg_attr(
    not(r4d_gpu),
    ignore = "no GPU adapter expected here (no Vulkan driver found at build time): install mesa-vulkan-drivers libvulkan1, or build with R4D_REQUIRE_GPU=1"
)]
fn the_cache_is_saved_reused_and_a_bad_one_ignored() {
    let dir = std::env::temp_dir().join(format!("r4d-vk-cache-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let file = dir.join("pipelines.bin");
    // SAFETY: this test binary has one test; nothing else reads the environment meanwhile.
    unsafe { std::env::set_var("R4D_VULKAN_PIPELINE_CACHE", &file) };
    let Some(first) = simulate() else {
        return;
    };
    let saved = std::fs::read(&file).expect("the cache was written when the engine went");
    assert_eq!(&saved[..8], b"R4DVKPC1");
    assert!(saved.len() >= 40 + 32, "a Vulkan pipeline cache header");
    assert_eq!(u32::from_le_bytes(saved[44..48].try_into().unwrap()), 1);
    // Read back by the next engine: the same results.
    assert_eq!(simulate().unwrap(), first);
    // Damaged (a plausible header with garbage after it, then plain garbage): ignored.
    let mut bad = saved.clone();
    for b in bad.iter_mut().skip(40 + 32) {
        *b ^= 0x5a;
    }
    for data in [bad, vec![0xffu8; 100], Vec::new()] {
        std::fs::write(&file, &data).unwrap();
        assert_eq!(simulate().unwrap(), first);
    }
    let _ = std::fs::remove_dir_all(&dir);
}
