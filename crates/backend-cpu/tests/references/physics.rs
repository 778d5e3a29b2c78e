//! Physics checks of the simulator: conservation, analytic free fall, determinism of the
//! parallel backend and agreement with the single-threaded reference.

use r4d_backend_cpu::{CpuBackend, Par};
use r4d_mpm::{
    reference::ReferenceBackend, Backend, BoundaryCondition, ForceForm, Material, MpmKernels,
    PartParams, ParticleSet, SimConfig, Simulation, Simulator, Surface,
};
use r4d_testkit::scenes::{boxed, config, jelly};

fn momentum(m: &[f32], v: &[[f32; 3]]) -> [f64; 3] {
    let mut p = [0.0; 3];
    for (mi, vi) in m.iter().zip(v) {
        for a in 0..3 {
            p[a] += *mi as f64 * vi[a] as f64;
        }
    }
    p
}

fn norm(a: [f64; 3]) -> f64 {
    (a[0] * a[0] + a[1] * a[1] + a[2] * a[2]).sqrt()
}

#[test]
fn mass_and_momentum_are_conserved_in_free_space() {
    for force in [ForceForm::Mls, ForceForm::Classic] {
        let mut cfg = config(32, 1e-4, 100, jelly(1e5));
        cfg.solver.gravity = [0.0; 3];
        cfg.solver.force = force;
        let scene = boxed(&cfg, [0.4, 0.4, 0.4], [0.6, 0.6, 0.6]);
        let mut sim = Simulation::new(CpuBackend::default(), &cfg, scene.clone(), "test").unwrap();
        let mut st = sim.init_state(&cfg.parts).unwrap();
        // Translation plus a spin about z through the centre, plus a squeeze along x.
        let v: Vec<[f32; 3]> = scene
            .x
            .iter()
            .map(|p| {
                let (dx, dy) = (p[0] - 0.5, p[1] - 0.5);
                [0.3 - 2.0 * dy - 1.0 * dx, -0.2 + 2.0 * dx, 0.1]
            })
            .collect();
        sim.backend().write(&mut st.state.v, &v).unwrap();
        let m = sim.masses().unwrap();
        let p0 = momentum(&m, &v);
        let m_total: f64 = m.iter().map(|&x| x as f64).sum();
        sim.step_frame(&mut st, &cfg.parts).unwrap();
        let grid_mass: f64 = sim.with_grid(|_, g| g.nodes.iter().map(|n| n[3] as f64).sum());
        assert!(
            (grid_mass - m_total).abs() <= 1e-5 * m_total,
            "{force:?}: grid mass {grid_mass} vs particle mass {m_total}"
        );
        let p1 = momentum(&m, &st.state.v);
        let err = norm([p1[0] - p0[0], p1[1] - p0[1], p1[2] - p0[2]]) / norm(p0);
        eprintln!("{force:?}: relative momentum change over 100 substeps {err:.2e}");
        assert!(err < 1e-5, "{force:?}: momentum drift {err}");
    }
}

#[test]
fn free_fall_matches_the_analytic_parabola() {
    let mut cfg = config(32, 2e-4, 100, jelly(1e5));
    cfg.solver.force = ForceForm::Classic;
    let scene = boxed(&cfg, [0.45, 0.45, 0.8], [0.55, 0.55, 0.9]);
    let dx = cfg.domain.dx();
    let mut sim = Simulation::new(CpuBackend::default(), &cfg, scene.clone(), "test").unwrap();
    let mut st = sim.init_state(&cfg.parts).unwrap();
    let mut worst: f64 = 0.0;
    for _ in 0..12 {
        sim.step_frame(&mut st, &cfg.parts).unwrap();
        let t = st.time_s;
        let x = sim.positions(&st).unwrap();
        for (p, p0) in x.iter().zip(&scene.x) {
            let expect = p0[2] as f64 - 0.5 * 9.8 * t * t;
            worst = worst.max((p[2] as f64 - expect).abs());
            worst = worst
                .max((p[0] - p0[0]).abs() as f64)
                .max((p[1] - p0[1]).abs() as f64);
        }
    }
    eprintln!(
        "free fall: worst deviation {:.2e} m = {:.4} dx after 0.24 s",
        worst,
        worst / dx
    );
    assert!(worst < dx / 4.0, "deviation {worst} m");
}

/// Three parts (jelly, metal, sand) with every kind of boundary condition.
fn mixed_scene() -> (SimConfig, ParticleSet) {
    let mut cfg = config(32, 1e-4, 100, jelly(1e5));
    cfg.parts.push(PartParams {
        material: Material::Metal,
        youngs_modulus_pa: 1e6,
        poisson_ratio: 0.3,
        yield_stress_pa: 1e3,
        density_kg_m3: 2000.0,
        ..Default::default()
    });
    cfg.parts.push(PartParams {
        material: Material::Sand,
        youngs_modulus_pa: 2e5,
        poisson_ratio: 0.25,
        friction_angle_deg: 35.0,
        density_kg_m3: 1500.0,
        ..Default::default()
    });
    cfg.boundary = vec![
        BoundaryCondition::BoundingBox {
            layers: 3,
            surface: Surface::Slip,
        },
        BoundaryCondition::SurfaceCollider {
            point: [0.0, 0.0, 0.15],
            normal: [0.0, 0.2, 1.0],
            surface: Surface::Friction,
            friction: 0.4,
            start_time: 0.0,
            end_time: 1.0,
        },
        BoundaryCondition::Cuboid {
            point: [0.3, 0.5, 0.5],
            size: [0.03, 0.1, 0.1],
            velocity: [0.0, 0.0, 0.05],
            start_time: 0.0,
            end_time: 1.0,
            reset: false,
        },
        BoundaryCondition::ParticleImpulse {
            force: [0.0, 0.05, -0.1],
            point: [0.6, 0.5, 0.5],
            size: [0.05, 0.2, 0.2],
            num_dt: 50,
            start_time: 0.0,
        },
    ];
    let dx = cfg.domain.dx();
    let shapes = [
        r4d_mpm::Shape::Box {
            min: [0.25, 0.4, 0.45],
            max: [0.7, 0.6, 0.55],
            part: 1,
            per_cell: 2,
        },
        r4d_mpm::Shape::Box {
            min: [0.3, 0.3, 0.2],
            max: [0.45, 0.45, 0.35],
            part: 0,
            per_cell: 2,
        },
        r4d_mpm::Shape::Cylinder {
            base: [0.6, 0.3, 0.2],
            axis: 2,
            radius: 0.06,
            length: 0.15,
            part: 2,
            per_cell: 2,
        },
    ];
    (cfg, ParticleSet::from_shapes(&shapes, dx))
}

fn trajectory<B: MpmKernels>(backend: B, frames: usize) -> Vec<Vec<[f32; 3]>> {
    let (cfg, scene) = mixed_scene();
    let mut sim = Simulation::new(backend, &cfg, scene, "mixed").unwrap();
    let mut st = sim.init_state(&cfg.parts).unwrap();
    let mut out = Vec::new();
    for _ in 0..frames {
        sim.step_frame(&mut st, &cfg.parts).unwrap();
        out.push(sim.positions(&st).unwrap());
    }
    out
}

#[test]
fn parallel_cpu_backend_is_bitwise_equal_to_a_single_threaded_run() {
    let seq = trajectory(CpuBackend::new(Par::Seq), 5);
    let par = trajectory(CpuBackend::new(Par::Threads(2)), 5);
    let par3 = trajectory(CpuBackend::new(Par::Threads(3)), 5);
    assert!(seq == par, "1 vs 2 threads differ");
    assert!(seq == par3, "1 vs 3 threads differ");
}

#[test]
fn cpu_backend_matches_the_reference_kernels() {
    let reference = trajectory(ReferenceBackend::new(), 5);
    let cpu = trajectory(CpuBackend::default(), 5);
    let dx = 1.0 / 32.0;
    for (k, (a, b)) in reference.iter().zip(&cpu).enumerate() {
        let worst = a
            .iter()
            .zip(b)
            .flat_map(|(p, q)| (0..3).map(move |i| (p[i] - q[i]).abs()))
            .fold(0.0f32, f32::max);
        eprintln!("frame {}: max |cpu - reference| = {worst:.2e} m", k + 1);
        // Only the summation order of P2G differs (f32 round-off, amplified by plasticity).
        assert!((worst as f64) < 1e-3 * dx, "frame {}: {worst}", k + 1);
    }
}

/// Mean x-velocity after 0.2 s of a stiff block launched at 1 m/s along a floor collider, and
/// the x displacement of its bottom particle layer.
fn sliding_speed(surface: Surface, friction: f64) -> (f64, f64) {
    let mut cfg = config(
        32,
        1e-4,
        200,
        PartParams {
            youngs_modulus_pa: 2e6,
            ..jelly(1e5)
        },
    );
    let dx = cfg.domain.dx();
    let floor = 4.0 * dx;
    cfg.boundary = vec![
        BoundaryCondition::BoundingBox {
            layers: 3,
            surface: Surface::Slip,
        },
        BoundaryCondition::SurfaceCollider {
            point: [0.0, 0.0, floor],
            normal: [0.0, 0.0, 1.0],
            surface,
            friction,
            start_time: 0.0,
            end_time: f64::INFINITY,
        },
    ];
    let scene = boxed(&cfg, [0.2, 0.4, floor], [0.35, 0.6, floor + 0.1]);
    let mut sim = Simulation::new(CpuBackend::default(), &cfg, scene.clone(), "slide").unwrap();
    let mut st = sim.init_state(&cfg.parts).unwrap();
    sim.backend()
        .write(&mut st.state.v, &vec![[1.0, 0.0, 0.0]; scene.len()])
        .unwrap();
    for _ in 0..10 {
        sim.step_frame(&mut st, &cfg.parts).unwrap();
    }
    let v = &st.state.v;
    let speed = v.iter().map(|p| p[0] as f64).sum::<f64>() / v.len() as f64;
    let x = &st.state.x;
    let bottom: Vec<usize> = (0..scene.len())
        .filter(|&i| (scene.x[i][2] as f64) < floor + 0.5 * dx)
        .collect();
    let shift = bottom
        .iter()
        .map(|&i| (x[i][0] - scene.x[i][0]) as f64)
        .sum::<f64>()
        / bottom.len() as f64;
    (speed, shift)
}

#[test]
fn surface_colliders_slip_stick_and_rub_with_coulomb_friction() {
    let (slip, slip_shift) = sliding_speed(Surface::Slip, 0.0);
    let (rough, _) = sliding_speed(Surface::Friction, 0.3);
    let (_, sticky_shift) = sliding_speed(Surface::Sticky, 0.0);
    // Coulomb friction decelerates at mu g: 1 - 0.3 * 9.8 * 0.2 = 0.412 m/s after 0.2 s.
    eprintln!(
        "after 0.2 s: slip {slip:.3} m/s (bottom moved {slip_shift:.3} m), friction 0.3 {rough:.3} m/s, sticky bottom moved {sticky_shift:.4} m"
    );
    assert!(slip > 0.95 && slip_shift > 0.18, "slip {slip} {slip_shift}");
    assert!((rough - 0.412).abs() < 0.05, "friction {rough}");
    // Particles straddle the first free node layer above the plane, so they creep a little.
    assert!(
        sticky_shift.abs() < 0.1 * slip_shift,
        "sticky bottom moved {sticky_shift}"
    );
}
