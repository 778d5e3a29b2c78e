//! The backend conformance suite: one set of scenes, run on every backend and compared with
//! the CPU backend (tolerances: elastic scenes within 1e-4 relative after 20
//! frames; path-dependent materials within 0.05 dx per particle and 0.01 dx for the centroid
//! after 10 frames, since float atomics reorder sums and plastic flow amplifies rounding).
//!
//! GPU instances use the binary's shared engines (`tests/common/gpu.rs`, made by
//! `r4d_backend_wgpu::testing::gpu_or_skip` and its Vulkan twin). Where the build finds no GPU
//! driver (`cfg(r4d_gpu)`, `build/gpu_probe.rs`) they are reported as ignored, with the reason;
//! where it finds one, or with `R4D_REQUIRE_GPU=1` (CI), a missing adapter fails them.

use crate::common::gpu;
use r4d_backend_cpu::CpuBackend;
use r4d_backend_wgpu::testing::gpu_or_skip_with;
use r4d_backend_wgpu::WgpuBackend;
use r4d_mpm::{MpmKernels, ParticleSet, SimConfig, Simulation, Simulator};
use std::sync::Arc;

/// Runs `frames` frames; returns positions and deformation gradients.
fn run<B: MpmKernels>(
    backend: B,
    cfg: &SimConfig,
    frames: usize,
) -> (Vec<[f32; 3]>, Vec<[f32; 9]>) {
    let scene = ParticleSet::from_shapes(&cfg.shapes, cfg.domain.dx());
    let mut sim = Simulation::new(backend, cfg, scene, "conformance").unwrap();
    let mut s = sim.init_state(&cfg.parts).unwrap();
    for _ in 0..frames {
        sim.step_frame(&mut s, &cfg.parts).unwrap();
    }
    (
        sim.positions(&s).unwrap(),
        sim.deformation_gradients(&s).unwrap(),
    )
}

fn cfg(text: &str) -> SimConfig {
    let c: SimConfig = toml::from_str(text).unwrap();
    c.validate("conformance").unwrap();
    c
}

/// An elastic beam clamped at one end by a sticky cuboid, loaded by an impulse, next to a
/// slanted frictional collider and a moving cuboid, inside slip walls: every grid and particle
/// boundary condition in one scene.
const JELLY_BEAM: &str = r#"
domain = { grid_lim = 1.0, n_grid = 32 }
time = { substep_dt = 2e-4, substeps_per_frame = 25, frames = 20 }
[[parts]]
material = "jelly"
youngs_modulus_pa = 2e5
poisson_ratio = 0.3
density_kg_m3 = 1000.0
[[shapes]]
kind = "box"
min = [0.2, 0.4, 0.5]
max = [0.7, 0.55, 0.6]
[[boundary]]
type = "bounding_box"
[[boundary]]
type = "cuboid"
point = [0.22, 0.475, 0.55]
size = [0.04, 0.1, 0.1]
[[boundary]]
type = "cuboid"
point = [0.85, 0.5, 0.2]
size = [0.05, 0.05, 0.05]
velocity = [0.0, 0.0, 0.1]
end_time = 0.05
reset = true
[[boundary]]
type = "surface_collider"
point = [0.5, 0.5, 0.25]
normal = [0.1, 0.0, 0.995]
surface = "friction"
friction = 0.3
[[boundary]]
type = "particle_impulse"
force = [0.0, 0.0, -0.002]
point = [0.65, 0.475, 0.55]
size = [0.06, 0.1, 0.1]
num_dt = 50
[[boundary]]
type = "particle_velocity"
velocity = [0.0, 0.1, 0.0]
point = [0.45, 0.475, 0.55]
size = [0.03, 0.1, 0.1]
end_time = 0.01
"#;

/// Two jelly parts of different stiffness and density, stacked, falling onto a slip floor.
const TWO_PART: &str = r#"
domain = { grid_lim = 1.0, n_grid = 32 }
time = { substep_dt = 2e-4, substeps_per_frame = 25, frames = 20 }
solver = { force = "classic", rpic_damping = 0.1 }
[[parts]]
material = "jelly"
youngs_modulus_pa = 1e5
poisson_ratio = 0.3
density_kg_m3 = 800.0
[[parts]]
material = "jelly"
youngs_modulus_pa = 4e5
poisson_ratio = 0.25
density_kg_m3 = 1500.0
[[shapes]]
kind = "box"
min = [0.35, 0.35, 0.2]
max = [0.6, 0.6, 0.35]
part = 0
[[shapes]]
kind = "box"
min = [0.4, 0.4, 0.35]
max = [0.55, 0.55, 0.45]
part = 1
[[boundary]]
type = "bounding_box"
"#;

fn compare_elastic(label: &str, text: &str, backend: impl MpmKernels, frames: usize) {
    let c = cfg(text);
    let (x_ref, f_ref) = run(CpuBackend::default(), &c, frames);
    let (x, f) = run(backend, &c, frames);
    let lim = c.domain.grid_lim;
    let dx_max = x
        .iter()
        .zip(&x_ref)
        .flat_map(|(a, b)| (0..3).map(move |k| (a[k] - b[k]).abs() as f64))
        .fold(0.0, f64::max)
        / lim;
    let f_scale = f_ref
        .iter()
        .flatten()
        .fold(0.0f64, |m, v| m.max(v.abs() as f64));
    let df_max = f
        .iter()
        .zip(&f_ref)
        .flat_map(|(a, b)| (0..9).map(move |k| (a[k] - b[k]).abs() as f64))
        .fold(0.0, f64::max)
        / f_scale;
    // The scene really moved.
    let moved = x_ref
        .iter()
        .zip(run(CpuBackend::default(), &c, 0).0)
        .map(|(a, b)| (0..3).map(|k| (a[k] - b[k]).abs()).fold(0.0f32, f32::max))
        .fold(0.0f32, f32::max);
    println!("{label}: {} particles, moved up to {moved:.3e} m; max |dx| / grid_lim = {dx_max:.2e}, max |dF| / max|F| = {df_max:.2e}", x.len());
    assert!(moved > 0.01 * lim as f32, "{label}: the scene did not move");
    assert!(
        dx_max <= 1e-4,
        "{label}: positions differ by {dx_max:.3e} (relative)"
    );
    assert!(
        df_max <= 1e-4,
        "{label}: F differs by {df_max:.3e} (relative)"
    );
}

fn compare_plastic(label: &str, text: &str, backend: impl MpmKernels, frames: usize) {
    let c = cfg(text);
    let dx = c.domain.dx();
    let (x_ref, _) = run(CpuBackend::default(), &c, frames);
    let (x, _) = run(backend, &c, frames);
    let x0 = run(CpuBackend::default(), &c, 0).0;
    let moved = x_ref
        .iter()
        .zip(&x0)
        .map(|(a, b)| {
            (0..3)
                .map(|k| (a[k] - b[k]).abs() as f64)
                .fold(0.0, f64::max)
        })
        .fold(0.0, f64::max)
        / dx;
    assert!(moved > 0.5, "{label}: the scene moved only {moved:.3} dx");
    let worst = x
        .iter()
        .zip(&x_ref)
        .map(|(a, b)| {
            (0..3)
                .map(|k| ((a[k] - b[k]) as f64).powi(2))
                .sum::<f64>()
                .sqrt()
        })
        .fold(0.0, f64::max)
        / dx;
    let n = x.len() as f64;
    let centroid =
        |p: &[[f32; 3]]| [0, 1, 2].map(|k| p.iter().map(|q| q[k] as f64).sum::<f64>() / n);
    let (ca, cb) = (centroid(&x), centroid(&x_ref));
    let dc = (0..3).map(|k| (ca[k] - cb[k]).powi(2)).sum::<f64>().sqrt() / dx;
    println!(
        "{label}: {} particles; worst particle {worst:.2e} dx, centroid {dc:.2e} dx",
        x.len()
    );
    assert!(
        worst <= 0.05,
        "{label}: a particle differs by {worst:.3e} dx"
    );
    assert!(dc <= 0.01, "{label}: the centroid differs by {dc:.3e} dx");
}

/// A von Mises metal beam with hardening, clamped at both ends by sticky cuboids and pushed
/// down at mid-span by a moving plate until it yields.
const METAL_BEAM: &str = r#"
domain = { grid_lim = 1.0, n_grid = 32 }
time = { substep_dt = 1e-4, substeps_per_frame = 40, frames = 10 }
[[parts]]
material = "metal"
youngs_modulus_pa = 2e6
poisson_ratio = 0.3
yield_stress_pa = 2e4
density_kg_m3 = 1500.0
hardening = true
xi = 0.5
[[shapes]]
kind = "box"
min = [0.25, 0.4375, 0.46875]
max = [0.75, 0.53125, 0.5625]
[[boundary]]
type = "bounding_box"
[[boundary]]
type = "cuboid"
point = [0.28125, 0.5, 0.5]
size = [0.045, 0.1, 0.1]
[[boundary]]
type = "cuboid"
point = [0.71875, 0.5, 0.5]
size = [0.045, 0.1, 0.1]
[[boundary]]
type = "cuboid"
point = [0.5, 0.5, 0.58]
size = [0.05, 0.1, 0.02]
velocity = [0.0, 0.0, -1.0]
"#;

fn plastic_scene(material: &str, extra: &str, press: bool) -> String {
    format!(
        r#"
domain = {{ grid_lim = 1.0, n_grid = 32 }}
time = {{ substep_dt = 2e-4, substeps_per_frame = 40, frames = 10 }}
[[parts]]
material = "{material}"
{extra}
[[shapes]]
kind = "box"
min = [0.35, 0.35, 0.1]
max = [0.65, 0.6, 0.35]
[[boundary]]
type = "bounding_box"
{}
"#,
        if press {
            "[[boundary]]\ntype = \"cuboid\"\npoint = [0.5, 0.47, 0.37]\nsize = [0.08, 0.2, 0.02]\nvelocity = [0.0, 0.0, -1.0]\n"
        } else {
            ""
        }
    )
}

#[test]
#[cfg_attr(
    not(r4d_gpu),
    ignore = "no GPU adapter expected here (no Vulkan driver found at build time): install mesa-vulkan-drivers libvulkan1, or build with R4D_REQUIRE_GPU=1"
)]
fn elastic_jelly_beam_with_every_boundary_condition_matches_cpu_on_wgpu() {
    let Some(ctx) = gpu::wgpu("wgpu_jelly_beam") else {
        return;
    };
    compare_elastic(
        "wgpu jelly beam",
        JELLY_BEAM,
        WgpuBackend::new((*ctx).clone()),
        20,
    );
}

#[test]
#[cfg_attr(
    not(r4d_gpu),
    ignore = "no GPU adapter expected here (no Vulkan driver found at build time): install mesa-vulkan-drivers libvulkan1, or build with R4D_REQUIRE_GPU=1"
)]
fn compare_exchange_scatter_matches_cpu_on_wgpu() {
    let Some(c) = gpu_or_skip_with("wgpu_cas", false) else {
        return;
    };
    assert!(!c.float_atomics);
    compare_elastic(
        "wgpu (compare-exchange scatter) two-part object",
        TWO_PART,
        WgpuBackend::new(Arc::new(c)),
        20,
    );
}

#[test]
#[cfg_attr(
    not(r4d_gpu),
    ignore = "no GPU adapter expected here (no Vulkan driver found at build time): install mesa-vulkan-drivers libvulkan1, or build with R4D_REQUIRE_GPU=1"
)]
fn elastic_two_part_object_matches_cpu_on_wgpu() {
    let Some(ctx) = gpu::wgpu("wgpu_two_part") else {
        return;
    };
    compare_elastic(
        "wgpu two-part object",
        TWO_PART,
        WgpuBackend::new((*ctx).clone()),
        20,
    );
}

/// The path-dependent scenes of the suite: every plastic model and the fluid.
fn path_dependent_scenes() -> Vec<(&'static str, String)> {
    vec![
        ("metal beam (clamped, pressed at mid-span)", METAL_BEAM.to_string()),
        (
            "sand column",
            plastic_scene(
                "sand",
                "youngs_modulus_pa = 2e5\npoisson_ratio = 0.3\nfriction_angle_deg = 30.0\ndensity_kg_m3 = 1600.0",
                false,
            ),
        ),
        (
            "foam block (pressed)",
            plastic_scene(
                "foam",
                "youngs_modulus_pa = 1e5\npoisson_ratio = 0.2\nyield_stress_pa = 2e3\nplastic_viscosity_pa_s = 0.5\ndensity_kg_m3 = 300.0",
                true,
            ),
        ),
        (
            "plasticine (pressed)",
            plastic_scene(
                "plasticine",
                "youngs_modulus_pa = 3e5\npoisson_ratio = 0.3\nyield_stress_pa = 2e3\nsoftening = 0.1\ndensity_kg_m3 = 1200.0",
                true,
            ),
        ),
        (
            "snow (pressed)",
            plastic_scene(
                "snow",
                "youngs_modulus_pa = 1.4e5\npoisson_ratio = 0.2\ndensity_kg_m3 = 400.0",
                true,
            ),
        ),
        (
            "fluid",
            plastic_scene(
                "fluid",
                "youngs_modulus_pa = 2e5\npoisson_ratio = 0.3\nplastic_viscosity_pa_s = 0.01\ndensity_kg_m3 = 1000.0",
                false,
            ),
        ),
    ]
}

/// Every path-dependent scene on a backend made by `make` against the CPU.
fn path_dependent_materials_match_cpu<B: MpmKernels>(engine: &str, make: impl Fn() -> B) {
    for (label, text) in path_dependent_scenes() {
        compare_plastic(&format!("{engine} {label}"), &text, make(), 10);
    }
}

#[test]
#[cfg_attr(
    not(r4d_gpu),
    ignore = "no GPU adapter expected here (no Vulkan driver found at build time): install mesa-vulkan-drivers libvulkan1, or build with R4D_REQUIRE_GPU=1"
)]
fn path_dependent_materials_match_cpu_on_wgpu() {
    let Some(ctx) = gpu::wgpu("wgpu_plastic") else {
        return;
    };
    path_dependent_materials_match_cpu("wgpu", || WgpuBackend::new((*ctx).clone()));
}

#[test]
#[cfg_attr(
    not(r4d_gpu),
    ignore = "no GPU adapter expected here (no Vulkan driver found at build time): install mesa-vulkan-drivers libvulkan1, or build with R4D_REQUIRE_GPU=1"
)]
fn elastic_scenes_match_cpu_on_vulkan() {
    let Some(e) = gpu::vulkan("vulkan_elastic") else {
        return;
    };
    compare_elastic(
        "vulkan jelly beam",
        JELLY_BEAM,
        r4d_backend_vulkan::VulkanBackend::new(e.clone()),
        20,
    );
    compare_elastic(
        "vulkan two-part object",
        TWO_PART,
        r4d_backend_vulkan::VulkanBackend::new(e.clone()),
        20,
    );
    r4d_backend_vulkan::testing::assert_validation_clean(&e, "vulkan_elastic");
    eprintln!("vulkan float atomics: {}", e.float_atomics());
}

#[test]
#[cfg_attr(
    not(r4d_gpu),
    ignore = "no GPU adapter expected here (no Vulkan driver found at build time): install mesa-vulkan-drivers libvulkan1, or build with R4D_REQUIRE_GPU=1"
)]
fn compare_exchange_scatter_matches_cpu_on_vulkan() {
    let Some(e) = r4d_backend_vulkan::testing::vulkan_or_skip_with("vulkan_cas", false) else {
        return;
    };
    assert!(!e.float_atomics());
    compare_elastic(
        "vulkan (compare-exchange scatter) two-part object",
        TWO_PART,
        r4d_backend_vulkan::VulkanBackend::new(e.clone()),
        20,
    );
    r4d_backend_vulkan::testing::assert_validation_clean(&e, "vulkan_cas");
}

#[test]
#[cfg_attr(
    not(r4d_gpu),
    ignore = "no GPU adapter expected here (no Vulkan driver found at build time): install mesa-vulkan-drivers libvulkan1, or build with R4D_REQUIRE_GPU=1"
)]
fn path_dependent_materials_match_cpu_on_vulkan() {
    let Some(e) = gpu::vulkan("vulkan_plastic") else {
        return;
    };
    path_dependent_materials_match_cpu("vulkan", || {
        r4d_backend_vulkan::VulkanBackend::new(e.clone())
    });
    r4d_backend_vulkan::testing::assert_validation_clean(&e, "vulkan_plastic");
}
