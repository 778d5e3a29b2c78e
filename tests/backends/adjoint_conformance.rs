//! The device adjoint against the parallel CPU adjoint, one suite for every GPU engine (wgpu
//! and Vulkan: `wgpu::*`, `vulkan::*`): the one stepper (`Simulation`) on `WgpuBackend` /
//! `VulkanBackend` and on `CpuBackend<f32>`, driven by the same checkpointing
//! driver: parameter gradients (the bound for elastic scenes: 1e-3 relative) and the
//! adjoint of the initial state.

use crate::common::gpu::{self, Lease};
use r4d_backend_cpu::{CpuBackend, Par};
use r4d_backend_vulkan::{VulkanBackend, VulkanEngine};
use r4d_backend_wgpu::{WgpuBackend, WgpuContext};
use r4d_conformance::scenes::{initial_velocity, two_jellies as scene, weights};
use r4d_mpm::adjoint::checkpoint::{value_and_grad, Checkpointing, Differentiable};
use r4d_mpm::adjoint::host::{HostSim, HostState, PhysParams};
use r4d_mpm::adjoint::kernels::MpmAdjointKernels;
use r4d_mpm::simulation::infallible;
use r4d_mpm::Simulation;
use r4d_mpm::{ForceForm, Material, PartParams, ParticleSet};

/// Gradients and initial adjoint of the weighted position loss on backend `b`.
fn run<B: MpmAdjointKernels<Scalar = f32>>(
    b: B,
    sim: &HostSim,
    params: &[PhysParams<f32>],
) -> (Vec<PhysParams<f32>>, HostState<f32>) {
    let d = Simulation::with_host(b, sim).unwrap();
    let init = d.init(params, &initial_velocity(sim.len())).unwrap();
    let (_, adj0, g) = value_and_grad(
        &d,
        &init,
        &params.to_vec(),
        60,
        20,
        Checkpointing::PerFrame,
        d.zero_grad().unwrap(),
        |_, _| 0.0,
        |f, _, adj| adj.add_to_x(d.backend(), &weights(f, sim.len())).unwrap(),
    )
    .unwrap();
    (
        d.grad_to_host(&g, params).unwrap(),
        adj0.download(d.backend()).unwrap(),
    )
}

fn cpu(sim: &HostSim, params: &[PhysParams<f32>]) -> (Vec<PhysParams<f32>>, HostState<f32>) {
    run(CpuBackend::<f32>::with_par(Par::Rayon), sim, params)
}

/// A GPU engine the suite runs on (every test below runs on each, `wgpu::*` and `vulkan::*`):
/// the binary's shared engine (`tests/common/gpu.rs`).
enum Gpu {
    Wgpu(Lease<std::sync::Arc<WgpuContext>>),
    Vulkan(Lease<VulkanEngine>),
}

impl Gpu {
    fn wgpu(test: &str) -> Option<Gpu> {
        gpu::wgpu(test).map(Gpu::Wgpu)
    }

    fn vulkan(test: &str) -> Option<Gpu> {
        gpu::vulkan(test).map(Gpu::Vulkan)
    }

    /// No validation message on the Vulkan engine (`R4D_VULKAN_VALIDATION=1`).
    fn check(&self, test: &str) {
        if let Gpu::Vulkan(e) = self {
            r4d_backend_vulkan::testing::assert_validation_clean(e, test);
        }
    }
}

fn gpu(
    b: &Gpu,
    sim: &HostSim,
    params: &[PhysParams<f32>],
) -> (Vec<PhysParams<f32>>, HostState<f32>) {
    match b {
        Gpu::Wgpu(ctx) => run(WgpuBackend::new((**ctx).clone()), sim, params),
        Gpu::Vulkan(e) => run(VulkanBackend::new((**e).clone()), sim, params),
    }
}

fn rel(a: f64, b: f64) -> f64 {
    let s = a.abs().max(b.abs());
    if s == 0.0 {
        0.0
    } else {
        (a - b).abs() / s
    }
}

/// Relative L2 difference of two flattened arrays.
fn rel_l2(a: &[f32], b: &[f32]) -> f64 {
    let (mut d, mut s) = (0.0f64, 0.0f64);
    for (x, y) in a.iter().zip(b) {
        d += (*x as f64 - *y as f64).powi(2);
        s += (*y as f64).powi(2);
    }
    (d / s.max(1e-300)).sqrt()
}

fn device_adjoint_matches_the_parallel_cpu_adjoint_on_jelly(ctx: &Gpu) {
    // MLS is the conformance suite's scene (`conformance_suite`).
    for force in [ForceForm::Classic] {
        let (cfg, sc) = scene(force);
        let sim = HostSim::new(&cfg, &sc).unwrap();
        let params: Vec<PhysParams<f32>> = cfg.parts.iter().map(PhysParams::of).collect();
        let (gc, ac) = cpu(&sim, &params);
        let (gg, ag) = gpu(ctx, &sim, &params);
        eprintln!("{force:?}: {} particles", sim.len());
        for s in 0..params.len() {
            let pairs = [
                ("E", gc[s].youngs_modulus, gg[s].youngs_modulus),
                ("nu", gc[s].poisson_ratio, gg[s].poisson_ratio),
                ("density", gc[s].density, gg[s].density),
            ];
            for (name, c, g) in pairs {
                let r = rel(c as f64, g as f64);
                eprintln!("{force:?} part {s}: d/d{name}: cpu {c:+.6e} gpu {g:+.6e} rel {r:.1e}");
                assert!(r < 1e-3, "{force:?} part {s}: d/d{name}: rel {r:e}");
            }
        }
        let flat3 = |v: &[[f32; 3]]| v.iter().flatten().copied().collect::<Vec<f32>>();
        let flat9 = |v: &[[f32; 9]]| v.iter().flatten().copied().collect::<Vec<f32>>();
        let checks = [
            ("x", rel_l2(&flat3(&ag.x), &flat3(&ac.x))),
            ("v", rel_l2(&flat3(&ag.v), &flat3(&ac.v))),
            ("C", rel_l2(&flat9(&ag.c), &flat9(&ac.c))),
            ("F", rel_l2(&flat9(&ag.f), &flat9(&ac.f))),
        ];
        for (name, r) in checks {
            eprintln!("{force:?}: initial adjoint of {name}: rel L2 {r:.1e}");
            assert!(
                r < 1e-3,
                "{force:?}: initial adjoint of {name}: rel L2 {r:e}"
            );
        }
    }
}

fn per_particle_gradients_are_reduced_per_slot(ctx: &Gpu) {
    let (cfg, sc) = scene(ForceForm::Mls);
    let sim = HostSim::new(&cfg, &sc).unwrap().per_particle();
    let params: Vec<PhysParams<f32>> = sim
        .part
        .iter()
        .map(|&p| PhysParams::of(&cfg.parts[p as usize]))
        .collect();
    let (gc, _) = cpu(&sim, &params);
    let (gg, _) = gpu(ctx, &sim, &params);
    type Field = fn(&PhysParams<f32>) -> f32;
    let fields: [(&str, Field); 3] = [
        ("E", |g| g.youngs_modulus),
        ("nu", |g| g.poisson_ratio),
        ("density", |g| g.density),
    ];
    for (name, f) in fields {
        let a: Vec<f32> = gg.iter().map(f).collect();
        let b: Vec<f32> = gc.iter().map(f).collect();
        let r = rel_l2(&a, &b);
        eprintln!("per particle d/d{name}: rel L2 {r:.1e}");
        assert!(r < 1e-3, "per particle d/d{name}: rel L2 {r:e}");
    }
}

/// The largest |gradient| of a field over the slots.
fn scale(g: &[PhysParams<f32>], field: &str) -> f64 {
    g.iter()
        .map(|p| match field {
            "E" => p.youngs_modulus,
            "nu" => p.poisson_ratio,
            "yield" => p.yield_stress,
            "viscosity" => p.plastic_viscosity,
            "friction" => p.friction_angle_deg,
            "hardening" => p.hardening,
            "softening" => p.softening,
            _ => p.density,
        })
        .fold(0.0f64, |m, x| m.max(x.abs() as f64))
}

/// The plastic models, two per scene (part 0 and part 1, each with its own values), so that
/// every model runs on the device once and mixed-material scenes are covered too.
fn plastic_materials() -> Vec<(&'static str, PartParams, PartParams)> {
    let base = |m: Material| PartParams {
        material: m,
        youngs_modulus_pa: 3e4,
        ..Default::default()
    };
    let metal = PartParams {
        yield_stress_pa: 20.0,
        hardening: true,
        xi: 0.3,
        ..base(Material::Metal)
    };
    let sand = PartParams {
        friction_angle_deg: 35.0,
        ..base(Material::Sand)
    };
    let foam = PartParams {
        yield_stress_pa: 20.0,
        plastic_viscosity_pa_s: 2.0,
        ..base(Material::Foam)
    };
    let snow = PartParams {
        snow_critical_compression: 2e-3,
        snow_critical_stretch: 1e-3,
        ..base(Material::Snow)
    };
    let plasticine = PartParams {
        yield_stress_pa: 20.0,
        softening: 200.0,
        ..base(Material::Plasticine)
    };
    // PhysFlow's two fluids.
    let paste = PartParams {
        yield_stress_pa: 20.0,
        plastic_viscosity_pa_s: 2.0,
        ..base(Material::NonNewtonian)
    };
    let drop = PartParams {
        poisson_ratio: 0.45,
        ..base(Material::Newtonian)
    };
    let fluid = PartParams {
        plastic_viscosity_pa_s: 2.0,
        ..base(Material::Fluid)
    };
    vec![
        ("metal | sand", metal, sand),
        ("foam | snow", foam, snow),
        ("plasticine | non_newtonian", plasticine, paste),
        ("newtonian | fluid", drop, fluid),
    ]
}

/// Bounds: 1e-2 relative per gradient (floored at 1e-2 of the field's largest slot gradient), as
/// the f32 CPU adjoint's own bound against f64 for these models (tests/backends/adjoint_parallel.rs);
/// measured on lavapipe, either scatter: <= 5e-4 for metal, sand, foam and plasticine, snow
/// 1.1e-3 (d/dnu of part 1) and 6e-3 on its nearly cancelled d/dE. Initial adjoint: x, v
/// 1e-3 (measured 1.4e-5); F 5e-2 (measured up to 1.2e-2, sand; 1.4e-4 metal).
fn device_adjoint_matches_the_parallel_cpu_adjoint_on_plastic_materials(ctx: &Gpu) {
    for (name, part, second) in plastic_materials() {
        let (mut cfg, _) = scene(ForceForm::Mls);
        cfg.parts[0] = PartParams {
            density_kg_m3: 800.0,
            ..part
        };
        cfg.parts[1] = PartParams {
            density_kg_m3: 1200.0,
            youngs_modulus_pa: 1e4,
            poisson_ratio: 0.35,
            ..second
        };
        let sc = ParticleSet::from_shapes(&cfg.shapes, cfg.domain.dx());
        let sim = HostSim::new(&cfg, &sc).unwrap();
        let params: Vec<PhysParams<f32>> = cfg.parts.iter().map(PhysParams::of).collect();
        let (mut gc, ac) = cpu(&sim, &params);
        let (mut gg, ag) = gpu(ctx, &sim, &params);
        sim.init_vjp(&ac, &mut gc);
        sim.init_vjp(&ag, &mut gg);
        for s in 0..params.len() {
            let pairs = [
                ("E", gc[s].youngs_modulus, gg[s].youngs_modulus),
                ("nu", gc[s].poisson_ratio, gg[s].poisson_ratio),
                ("yield", gc[s].yield_stress, gg[s].yield_stress),
                (
                    "viscosity",
                    gc[s].plastic_viscosity,
                    gg[s].plastic_viscosity,
                ),
                (
                    "friction",
                    gc[s].friction_angle_deg,
                    gg[s].friction_angle_deg,
                ),
                ("density", gc[s].density, gg[s].density),
                ("hardening", gc[s].hardening, gg[s].hardening),
                ("softening", gc[s].softening, gg[s].softening),
            ];
            for (field, c, g) in pairs {
                // Relative to the field's largest gradient over the slots (one slot's may
                // nearly cancel).
                let floor = 1e-2 * scale(&gc, field);
                let r = (c as f64 - g as f64).abs() / (c.abs().max(g.abs()) as f64).max(floor);
                eprintln!("{name} part {s}: d/d{field}: cpu {c:+.6e} gpu {g:+.6e} rel {r:.1e}");
                assert!(c == g || r < 1e-2, "{name} part {s}: d/d{field}: rel {r:e}");
            }
        }
        let flat3 = |v: &[[f32; 3]]| v.iter().flatten().copied().collect::<Vec<f32>>();
        let flat9 = |v: &[[f32; 9]]| v.iter().flatten().copied().collect::<Vec<f32>>();
        let (x, v, f) = (
            rel_l2(&flat3(&ag.x), &flat3(&ac.x)),
            rel_l2(&flat3(&ag.v), &flat3(&ac.v)),
            rel_l2(&flat9(&ag.f), &flat9(&ac.f)),
        );
        eprintln!("{name}: initial adjoint rel L2: x {x:.1e} v {v:.1e} F {f:.1e}");
        assert!(x < 1e-3 && v < 1e-3 && f < 5e-2, "{name}: initial adjoint");
    }
}

/// A fifth of the particles fall out of the grid (skipped by the transfers, zero adjoint
/// from then on). Without boundary conditions the block is in free fall, so the parameter
/// gradients nearly vanish: E and nu are checked to 1e-2 (measured up to 6e-3), the density's
/// (5e-8 against 5e-3 with the boundaries: summation noise, 5-8% run to run) is only printed;
/// the initial adjoint is well conditioned: 1e-3 relative L2 (measured 7e-7).
fn particles_leaving_the_grid_match_the_cpu_adjoint(ctx: &Gpu) {
    let (mut cfg, _) = scene(ForceForm::Mls);
    cfg.boundary.clear();
    cfg.solver.gravity = [0.0, 0.0, -2000.0];
    cfg.solver.max_cfl = 50.0;
    let sc = ParticleSet::from_shapes(&cfg.shapes, cfg.domain.dx());
    let sim = HostSim::new(&cfg, &sc).unwrap();
    let params: Vec<PhysParams<f32>> = cfg.parts.iter().map(PhysParams::of).collect();
    let (gc, ac) = cpu(&sim, &params);
    let (gg, ag) = gpu(ctx, &sim, &params);
    let host = infallible(Simulation::with_host(
        CpuBackend::<f32>::with_par(Par::Rayon),
        &sim,
    ));
    let mut st = infallible(host.init(&params, &initial_velocity(sim.len())));
    for k in 0..60 {
        infallible(host.step(&mut st, &params, k));
    }
    let left = st.x.iter().filter(|p| p[2] < 0.5 / 24.0).count();
    eprintln!("{left} particles left the grid");
    assert!(left > 0, "the test must push particles out of the grid");
    for s in 0..params.len() {
        for (name, c, g) in [
            ("E", gc[s].youngs_modulus, gg[s].youngs_modulus),
            ("nu", gc[s].poisson_ratio, gg[s].poisson_ratio),
            ("density", gc[s].density, gg[s].density),
        ] {
            let r = rel(c as f64, g as f64);
            eprintln!("out of grid, part {s}: d/d{name}: cpu {c:+.6e} gpu {g:+.6e} rel {r:.1e}");
            assert!(
                name == "density" || r < 1e-2,
                "part {s}: d/d{name}: rel {r:e}"
            );
        }
    }
    let flat3 = |v: &[[f32; 3]]| v.iter().flatten().copied().collect::<Vec<f32>>();
    let flat9 = |v: &[[f32; 9]]| v.iter().flatten().copied().collect::<Vec<f32>>();
    for (name, r) in [
        ("x", rel_l2(&flat3(&ag.x), &flat3(&ac.x))),
        ("v", rel_l2(&flat3(&ag.v), &flat3(&ac.v))),
        ("F", rel_l2(&flat9(&ag.f), &flat9(&ac.f))),
    ] {
        eprintln!("out of grid: initial adjoint of {name}: rel L2 {r:.1e}");
        assert!(r < 1e-3, "initial adjoint of {name}: rel L2 {r:e}");
    }
}

/// Each check on each GPU engine (ignored where the build finds no GPU driver), as
/// `CHECK::wgpu` and `CHECK::vulkan`: the test harness takes tests in name order, so the two
/// engines' runs of a check sit side by side and run at the same time (each engine serves
/// one test at a time; their first pipeline compilations on lavapipe, tens of seconds each,
/// then overlap).
macro_rules! on_engines {
    ($check:ident) => {
        mod $check {
            on_engines!(@engine $check wgpu);
            on_engines!(@engine $check vulkan);
        }
    };
    (@engine $check:ident $engine:ident) => {
        #[test]
        #[cfg_attr(
            not(r4d_gpu),
            ignore = "no GPU adapter expected here (no Vulkan driver found at build time): install mesa-vulkan-drivers libvulkan1, or build with R4D_REQUIRE_GPU=1"
        )]
        fn $engine() {
            if let Some(b) = super::Gpu::$engine(stringify!($check)) {
                super::$check(&b);
                b.check(stringify!($check));
            }
        }
    };
}

on_engines!(device_adjoint_matches_the_parallel_cpu_adjoint_on_jelly);
on_engines!(per_particle_gradients_are_reduced_per_slot);
on_engines!(device_adjoint_matches_the_parallel_cpu_adjoint_on_plastic_materials);
on_engines!(particles_leaving_the_grid_match_the_cpu_adjoint);
