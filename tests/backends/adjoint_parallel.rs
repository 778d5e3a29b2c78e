//! The parallel CPU backend's reverse stages (`CpuBackend`, through the generic
//! `Simulation`) against the f64 reference backend's (the gradient oracle).

use r4d_backend_cpu::{CpuBackend, Par};
use r4d_mpm::adjoint::checkpoint::{value_and_grad, Checkpointing, Differentiable};
use r4d_mpm::adjoint::host::{HostSim, PhysParams};
use r4d_mpm::adjoint::kernels::MpmAdjointKernels;
use r4d_mpm::math::Real;
use r4d_mpm::reference::ReferenceBackend;
use r4d_mpm::simulation::infallible;
use r4d_mpm::Simulation;
use r4d_mpm::{
    BoundaryCondition, Domain, ForceForm, Material, PartParams, ParticleSet, Shape, SimConfig,
    SolverConfig, Surface, TimeConfig,
};
use std::convert::Infallible;

fn scene(part: PartParams) -> (SimConfig, ParticleSet) {
    let n = 16;
    let dx = 1.0 / n as f64;
    let cfg = SimConfig {
        domain: Domain {
            grid_lim: 1.0,
            n_grid: n,
        },
        time: TimeConfig {
            substep_dt: 2e-4,
            frame_dt: None,
            substeps_per_frame: Some(20),
            frames: 3,
        },
        solver: SolverConfig {
            force: ForceForm::Classic,
            rpic_damping: 0.1,
            ..Default::default()
        },
        parts: vec![PartParams {
            density_kg_m3: 800.0,
            ..part
        }],
        shapes: vec![Shape::Box {
            min: [0.3, 0.35, 3.0 * dx],
            max: [0.55, 0.6, 3.0 * dx + 0.2],
            part: 0,
            per_cell: 1,
        }],
        particles: None,
        boundary: vec![
            BoundaryCondition::BoundingBox {
                layers: 3,
                surface: Surface::Slip,
            },
            BoundaryCondition::SurfaceCollider {
                point: [0.0, 0.0, 3.5 * dx],
                normal: [0.0, 0.0, 1.0],
                surface: Surface::Friction,
                friction: 0.4,
                start_time: 0.0,
                end_time: 1.0,
            },
            BoundaryCondition::ParticleImpulse {
                force: [-0.2, 0.1, -0.5],
                point: [0.5, 0.5, 0.35],
                size: [0.1, 0.3, 0.1],
                num_dt: 30,
                start_time: 0.0,
            },
        ],
    };
    let scene = ParticleSet::from_shapes(&cfg.shapes, dx);
    (cfg, scene)
}

/// The gradient of a fixed weighted sum of positions on backend `b`.
fn grad<B: MpmAdjointKernels<Error = Infallible>>(
    b: B,
    sim: &HostSim,
    part: &PartParams,
) -> [f64; 6] {
    let d = infallible(Simulation::with_host(b, sim));
    let params = vec![PhysParams::<B::Scalar>::of(part)];
    let init = infallible(d.init(&params, &vec![[B::Scalar::c(0.0); 3]; sim.len()]));
    let (_, adj0, g) = infallible(value_and_grad(
        &d,
        &init,
        &params,
        60,
        20,
        Checkpointing::PerFrame,
        infallible(d.zero_grad()),
        |_, _| 0.0,
        |f, _, adj| {
            let mut x = infallible(d.backend().download(&adj.x));
            for (p, a) in x.iter_mut().enumerate() {
                // A fixed, particle-dependent weight per frame.
                let w = ((p * 7 + f * 3) % 11) as f64 / 11.0 - 0.5;
                a[0] += B::Scalar::c(w);
                a[2] += B::Scalar::c(0.5 - w);
            }
            infallible(d.backend().write(&mut adj.x, &x));
        },
    ));
    let mut g = infallible(d.grad_to_host(&g, &params));
    infallible(d.init_vjp(&adj0, &mut g));
    let g = g[0];
    [
        g.youngs_modulus,
        g.poisson_ratio,
        g.yield_stress,
        g.plastic_viscosity,
        g.friction_angle_deg,
        g.density,
    ]
    .map(|x| x.f64())
}

fn materials() -> Vec<(&'static str, PartParams)> {
    let base = |m: Material| PartParams {
        material: m,
        youngs_modulus_pa: 3e4,
        ..Default::default()
    };
    vec![
        ("jelly", base(Material::Jelly)),
        (
            "metal",
            PartParams {
                yield_stress_pa: 20.0,
                hardening: true,
                xi: 0.3,
                ..base(Material::Metal)
            },
        ),
        (
            "sand",
            PartParams {
                friction_angle_deg: 35.0,
                ..base(Material::Sand)
            },
        ),
        (
            "foam",
            PartParams {
                yield_stress_pa: 20.0,
                plastic_viscosity_pa_s: 2.0,
                ..base(Material::Foam)
            },
        ),
        (
            "snow",
            PartParams {
                snow_critical_compression: 2e-3,
                snow_critical_stretch: 1e-3,
                ..base(Material::Snow)
            },
        ),
        (
            "plasticine",
            PartParams {
                yield_stress_pa: 20.0,
                softening: 5.0,
                ..base(Material::Plasticine)
            },
        ),
        (
            "non_newtonian",
            PartParams {
                yield_stress_pa: 20.0,
                plastic_viscosity_pa_s: 2.0,
                ..base(Material::NonNewtonian)
            },
        ),
        (
            "newtonian",
            PartParams {
                poisson_ratio: 0.45,
                ..base(Material::Newtonian)
            },
        ),
    ]
}

const NAMES: [&str; 6] = [
    "E",
    "nu",
    "yield_stress",
    "plastic_viscosity",
    "friction_angle",
    "density",
];

fn rel(a: f64, b: f64) -> f64 {
    let s = a.abs().max(b.abs());
    if s == 0.0 {
        0.0
    } else {
        (a - b).abs() / s
    }
}

#[test]
fn parallel_adjoint_in_f64_matches_the_reference_sweep() {
    for (name, part) in materials() {
        let (cfg, sc) = scene(part);
        let sim = HostSim::new(&cfg, &sc).unwrap();
        let reference = grad(ReferenceBackend::<f64>::in_scalar(), &sim, &cfg.parts[0]);
        let parallel = grad(cpu::<f64>(Par::Rayon), &sim, &cfg.parts[0]);
        for i in 0..6 {
            let r = rel(reference[i], parallel[i]);
            assert!(
                r < 1e-9,
                "{name}: d/d{}: parallel {} vs reference {} (rel {r:e})",
                NAMES[i],
                parallel[i],
                reference[i]
            );
        }
    }
}

#[test]
fn parallel_adjoint_in_f32_matches_the_f64_reference_gradient() {
    for (name, part) in materials() {
        let (cfg, sc) = scene(part);
        let sim = HostSim::new(&cfg, &sc).unwrap();
        let reference = grad(ReferenceBackend::<f64>::in_scalar(), &sim, &cfg.parts[0]);
        let f32_grad = grad(cpu::<f32>(Par::Rayon), &sim, &cfg.parts[0]);
        for i in 0..6 {
            let r = rel(reference[i], f32_grad[i]);
            eprintln!(
                "{name}: d/d{}: f64 {:+.5e} parallel f32 {:+.5e} rel {r:.1e}",
                NAMES[i], reference[i], f32_grad[i]
            );
            assert!(r < 1e-2, "{name}: d/d{}: rel {r:e}", NAMES[i]);
        }
    }
}

#[test]
fn parallel_adjoint_does_not_depend_on_the_thread_count() {
    let (cfg, sc) = scene(PartParams {
        material: Material::Metal,
        youngs_modulus_pa: 3e4,
        yield_stress_pa: 20.0,
        ..Default::default()
    });
    let sim = HostSim::new(&cfg, &sc).unwrap();
    let run = |threads: usize| grad(cpu::<f32>(Par::Threads(threads)), &sim, &cfg.parts[0]);
    assert_eq!(run(1), run(2));
    assert_eq!(run(1), run(3));
}

#[test]
fn particles_leaving_the_grid_do_not_crash_the_adjoint() {
    let (mut cfg, _) = scene(PartParams {
        material: Material::Jelly,
        youngs_modulus_pa: 3e4,
        ..Default::default()
    });
    cfg.boundary.clear();
    cfg.solver.gravity = [0.0, 0.0, -4000.0];
    cfg.solver.max_cfl = 50.0;
    let sc = ParticleSet::from_shapes(&cfg.shapes, cfg.domain.dx());
    let sim = HostSim::new(&cfg, &sc).unwrap();
    // The block falls through the floor of the grid within the run.
    let params = vec![PhysParams::<f64>::of(&cfg.parts[0])];
    let oracle = infallible(Simulation::with_host(
        ReferenceBackend::<f64>::in_scalar(),
        &sim,
    ));
    let mut st = infallible(oracle.init(&params, &vec![[0.0; 3]; sim.len()]));
    for k in 0..60 {
        infallible(oracle.step(&mut st, &params, k));
    }
    assert!(
        st.x.iter().any(|p| p[2] < 0.5 / 16.0),
        "the test must push particles out of the grid"
    );
    let _ = grad(ReferenceBackend::<f64>::in_scalar(), &sim, &cfg.parts[0]);
    let _ = grad(cpu::<f32>(Par::Rayon), &sim, &cfg.parts[0]);
}

/// Per-particle gradients (the paper's ablation): they sum to the per-part gradient, and one
/// particle's E gradient matches finite differences.
#[test]
fn per_particle_gradients_sum_to_the_part_gradient_and_match_finite_differences() {
    let (cfg, sc) = scene(PartParams {
        material: Material::Metal,
        youngs_modulus_pa: 3e4,
        yield_stress_pa: 20.0,
        ..Default::default()
    });
    let part_sim = HostSim::new(&cfg, &sc).unwrap();
    let sim = HostSim::new(&cfg, &sc).unwrap().per_particle();
    assert_eq!(sim.slots(), sim.len());
    let loss_weights = |f: usize, p: usize| ((p * 7 + f * 3) % 11) as f64 / 11.0 - 0.5;
    let run = |sim: &HostSim, params: &Vec<PhysParams<f64>>| {
        let d = infallible(Simulation::with_host(cpu::<f64>(Par::Rayon), sim));
        let init = infallible(d.init(params, &vec![[0.0; 3]; sim.len()]));
        let (l, adj0, g) = infallible(value_and_grad(
            &d,
            &init,
            params,
            60,
            20,
            Checkpointing::PerFrame,
            infallible(d.zero_grad()),
            |f, s| {
                s.x.iter()
                    .enumerate()
                    .map(|(p, x)| loss_weights(f, p) * x[0])
                    .sum()
            },
            |f, _, adj| {
                adj.x
                    .iter_mut()
                    .enumerate()
                    .for_each(|(p, a)| a[0] += loss_weights(f, p))
            },
        ));
        let mut g = infallible(d.grad_to_host(&g, params));
        infallible(d.init_vjp(&adj0, &mut g));
        (l, g)
    };
    let one = PhysParams::<f64>::of(&cfg.parts[0]);
    let (_, g_part) = run(&part_sim, &vec![one]);
    let per = vec![one; sim.len()];
    let (_, g_per) = run(&sim, &per);
    let summed: f64 = g_per.iter().map(|g| g.youngs_modulus).sum();
    assert!(
        rel(summed, g_part[0].youngs_modulus) < 1e-9,
        "{summed} vs {}",
        g_part[0].youngs_modulus
    );
    let summed_y: f64 = g_per.iter().map(|g| g.yield_stress).sum();
    assert!(rel(summed_y, g_part[0].yield_stress) < 1e-9);
    // Finite differences on the particle with the largest E gradient.
    let (p, _) = g_per
        .iter()
        .enumerate()
        .max_by(|a, b| {
            a.1.youngs_modulus
                .abs()
                .total_cmp(&b.1.youngs_modulus.abs())
        })
        .unwrap();
    let h = 1e-4 * one.youngs_modulus;
    let eval = |d: f64| {
        let mut q = per.clone();
        q[p].youngs_modulus += d;
        run(&sim, &q).0
    };
    let fd = (eval(h) - eval(-h)) / (2.0 * h);
    let r = rel(fd, g_per[p].youngs_modulus);
    eprintln!(
        "particle {p}: dL/dE adjoint {:e} fd {fd:e} rel {r:.1e}",
        g_per[p].youngs_modulus
    );
    assert!(r < 1e-4, "rel {r}");
}

/// The CPU backend in scalar type `T`.
fn cpu<T: Real>(par: Par) -> CpuBackend<T> {
    CpuBackend::with_par(par)
}
