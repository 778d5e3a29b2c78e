//! Every material shows its signature, checked with numbers.

use r4d_backend_cpu::CpuBackend;
use r4d_mpm::{
    BoundaryCondition, Material, PartParams, ParticleSet, Shape, SimConfig, SimState, Simulation,
    Simulator, Surface,
};
use r4d_testkit::scenes::{bbox, boxed, config, jelly, sim};

fn forever() -> f64 {
    f64::INFINITY
}

/// Sticky floor at z = `z`.
fn sticky_floor(z: f64) -> BoundaryCondition {
    BoundaryCondition::SurfaceCollider {
        point: [0.0, 0.0, z],
        normal: [0.0, 0.0, 1.0],
        surface: Surface::Sticky,
        friction: 0.0,
        start_time: 0.0,
        end_time: forever(),
    }
}

/// Runs `frames` frames, calling `probe` after each.
fn run(
    cfg: &SimConfig,
    scene: ParticleSet,
    frames: usize,
    mut probe: impl FnMut(usize, &Simulation<CpuBackend>, &SimState<CpuBackend>),
) {
    let mut s = sim(cfg, scene);
    let mut st = s.init_state(&cfg.parts).unwrap();
    for f in 1..=frames {
        s.step_frame(&mut st, &cfg.parts).unwrap();
        probe(f, &s, &st);
    }
}

/// Surface slope (degrees) of an axisymmetric heap centred at (cx, cy): max z per radial ring,
/// fitted where the height is between 25% and 75% of the heap's height above `floor`.
fn cone_slope_deg(x: &[[f32; 3]], dx: f64, c: [f64; 2], floor: f64) -> f64 {
    let mut rings: std::collections::BTreeMap<i64, f64> = Default::default();
    for p in x {
        let r = ((p[0] as f64 - c[0]).powi(2) + (p[1] as f64 - c[1]).powi(2)).sqrt();
        let e = rings.entry((r / dx).floor() as i64).or_insert(f64::MIN);
        *e = e.max(p[2] as f64 - floor);
    }
    let hmax = rings.values().cloned().fold(f64::MIN, f64::max);
    let pts: Vec<(f64, f64)> = rings
        .iter()
        .map(|(&k, &h)| ((k as f64 + 0.5) * dx, h))
        .filter(|&(_, h)| h > 0.25 * hmax && h < 0.75 * hmax)
        .collect();
    let n = pts.len() as f64;
    let (sx, sz) = pts.iter().fold((0.0, 0.0), |a, p| (a.0 + p.0, a.1 + p.1));
    let (mx, mz) = (sx / n, sz / n);
    let (sxx, sxz) = pts.iter().fold((0.0, 0.0), |a, p| {
        (a.0 + (p.0 - mx).powi(2), a.1 + (p.0 - mx) * (p.1 - mz))
    });
    (-sxz / sxx).atan().to_degrees()
}

/// Quasi-static collapse of a sand column (H/R = 1) on a sticky floor; grid velocity damping
/// removes the inertial run-out so the heap settles at its static slope.
fn sand_column_slope(phi: f64) -> f64 {
    let part = PartParams {
        material: Material::Sand,
        youngs_modulus_pa: 2e5,
        poisson_ratio: 0.25,
        friction_angle_deg: phi,
        density_kg_m3: 1500.0,
        ..Default::default()
    };
    let mut cfg = config(48, 1e-4, 200, part);
    cfg.solver.grid_v_damping = 0.998;
    let dx = cfg.domain.dx();
    let floor = 3.0 * dx;
    cfg.boundary = vec![
        BoundaryCondition::BoundingBox {
            layers: 3,
            surface: Surface::Slip,
        },
        sticky_floor(floor),
    ];
    let scene = ParticleSet::from_shapes(
        &[Shape::Cylinder {
            base: [0.5, 0.5, floor],
            axis: 2,
            radius: 0.125,
            length: 0.125,
            part: 0,
            per_cell: 2,
        }],
        dx,
    );
    let mut slope = 0.0;
    run(&cfg, scene, 40, |f, s, st| {
        if f == 40 {
            slope = cone_slope_deg(&s.positions(st).unwrap(), dx, [0.5, 0.5], floor);
        }
    });
    slope
}

#[test]
fn sand_column_settles_near_its_friction_angle() {
    let s20 = sand_column_slope(20.0);
    let s30 = sand_column_slope(30.0);
    eprintln!("sand heap slope: phi 20 -> {s20:.1} deg, phi 30 -> {s30:.1} deg");
    assert!((s20 - 20.0).abs() < 7.0, "phi 20: slope {s20:.1}");
    assert!((s30 - 30.0).abs() < 7.0, "phi 30: slope {s30:.1}");
    assert!(
        s30 > s20 + 2.0,
        "a higher friction angle must hold a steeper heap"
    );
}

/// Max distance of any particle from its rest position, after removing the centroid.
fn shape_error(x: &[[f32; 3]], rest: &[[f32; 3]]) -> f64 {
    let (_, _, c) = bbox(x);
    let (_, _, c0) = bbox(rest);
    x.iter()
        .zip(rest)
        .map(|(p, q)| {
            (0..3)
                .map(|a| ((p[a] as f64 - c[a]) - (q[a] as f64 - c0[a])).powi(2))
                .sum::<f64>()
                .sqrt()
        })
        .fold(0.0, f64::max)
}

#[test]
fn jelly_returns_to_its_rest_shape() {
    // Zero gravity; the top half is pushed down and the bottom half up for 0.01 s (no net
    // momentum), then the squeezed cube springs back; grid damping lets it come to rest.
    let mut cfg = config(32, 1e-4, 200, jelly(2e4));
    cfg.solver.gravity = [0.0; 3];
    cfg.solver.grid_v_damping = 0.999;
    let push = |fz: f64, zc: f64| BoundaryCondition::ParticleImpulse {
        force: [0.0, 0.0, fz],
        point: [0.5, 0.5, zc],
        size: [0.2, 0.2, 0.05],
        num_dt: 200,
        start_time: 0.0,
    };
    cfg.boundary = vec![push(-0.3, 0.55), push(0.3, 0.45)];
    let scene = boxed(&cfg, [0.4, 0.4, 0.4], [0.6, 0.6, 0.6]);
    let rest = scene.x.clone();
    let extent = 0.2;
    let mut peak = 0.0f64;
    let mut last = 0.0;
    run(&cfg, scene, 30, |_, s, st| {
        let e = shape_error(&s.positions(st).unwrap(), &rest);
        peak = peak.max(e);
        last = e;
    });
    eprintln!(
        "jelly: peak shape error {:.4} m, final {:.5} m (bbox {extent} m)",
        peak, last
    );
    assert!(
        peak > 0.05 * extent,
        "the cube must deform visibly (peak {peak})"
    );
    assert!(
        last < 0.01 * extent,
        "final shape error {last} >= 1% of the bbox"
    );
}

/// A cantilever clamped at x <= 0.3 with a downward load on its tip for `load_steps`
/// substeps; returns (peak tip deflection, final tip deflection).
fn loaded_cantilever(part: PartParams) -> (f64, f64) {
    let mut cfg = config(32, 1e-4, 200, part);
    cfg.solver.gravity = [0.0; 3];
    cfg.solver.grid_v_damping = 0.999;
    cfg.boundary = vec![
        BoundaryCondition::BoundingBox {
            layers: 3,
            surface: Surface::Slip,
        },
        BoundaryCondition::Cuboid {
            point: [0.0, 0.5, 0.5],
            size: [0.3 + 0.5 / 32.0, 1.0, 1.0],
            velocity: [0.0; 3],
            start_time: 0.0,
            end_time: forever(),
            reset: false,
        },
        BoundaryCondition::ParticleImpulse {
            force: [0.0, 0.0, -0.25],
            point: [0.7, 0.5, 0.5],
            size: [0.05, 0.1, 0.1],
            num_dt: 1000,
            start_time: 0.0,
        },
    ];
    let scene = boxed(&cfg, [0.2, 0.4375, 0.46875], [0.75, 0.5625, 0.53125]);
    let tip: Vec<usize> = (0..scene.len()).filter(|&i| scene.x[i][0] > 0.72).collect();
    let z0: f64 = tip.iter().map(|&i| scene.x[i][2] as f64).sum::<f64>() / tip.len() as f64;
    let (mut peak, mut last) = (0.0f64, 0.0);
    run(&cfg, scene, 60, |_, s, st| {
        let x = s.positions(st).unwrap();
        let z: f64 = tip.iter().map(|&i| x[i][2] as f64).sum::<f64>() / tip.len() as f64;
        peak = peak.max(z0 - z);
        last = z0 - z;
    });
    (peak, last)
}

#[test]
fn metal_keeps_a_residual_deflection_but_jelly_does_not() {
    let metal = PartParams {
        material: Material::Metal,
        youngs_modulus_pa: 5e6,
        poisson_ratio: 0.3,
        yield_stress_pa: 5e3,
        density_kg_m3: 1500.0,
        ..Default::default()
    };
    let (mp, ml) = loaded_cantilever(metal);
    let (jp, jl) = loaded_cantilever(PartParams {
        density_kg_m3: 1500.0,
        ..jelly(5e6)
    });
    eprintln!(
        "metal tip: peak {mp:.4} m final {ml:.4} m; jelly tip: peak {jp:.4} m final {jl:.5} m"
    );
    assert!(mp > 0.01, "the load must bend the metal bar (peak {mp})");
    assert!(ml > 0.2 * mp, "metal residual {ml} <= 20% of peak {mp}");
    assert!(
        jl.abs() < 0.1 * jp,
        "jelly must spring back (final {jl}, peak {jp})"
    );
}

/// A block on a sticky floor whose top layer is dragged sideways at 0.2 m/s for 0.1 s and then
/// released; returns (peak, final) shear offset of the top relative to the bottom.
fn sheared_block(part: PartParams) -> (f64, f64) {
    let mut cfg = config(32, 1e-4, 200, part);
    cfg.solver.grid_v_damping = 0.999;
    let dx = cfg.domain.dx();
    cfg.boundary = vec![
        BoundaryCondition::BoundingBox {
            layers: 3,
            surface: Surface::Slip,
        },
        sticky_floor(4.0 * dx),
        BoundaryCondition::ParticleVelocity {
            velocity: [0.2, 0.0, 0.0],
            point: [0.5, 0.5, 4.0 * dx + 0.16],
            size: [0.2, 0.2, 0.02],
            start_time: 0.0,
            end_time: 0.1,
        },
    ];
    let scene = boxed(&cfg, [0.4, 0.4, 3.0 * dx], [0.6, 0.6, 4.0 * dx + 0.18]);
    let top: Vec<usize> = (0..scene.len())
        .filter(|&i| scene.x[i][2] as f64 > 4.0 * dx + 0.15)
        .collect();
    let x0: f64 = top.iter().map(|&i| scene.x[i][0] as f64).sum::<f64>() / top.len() as f64;
    let (mut peak, mut last) = (0.0f64, 0.0);
    run(&cfg, scene, 25, |_, s, st| {
        let x = s.positions(st).unwrap();
        let xt: f64 = top.iter().map(|&i| x[i][0] as f64).sum::<f64>() / top.len() as f64;
        peak = peak.max(xt - x0);
        last = xt - x0;
    });
    (peak, last)
}

#[test]
fn foam_flows_past_yield_and_stays_elastic_below() {
    let foam = |yield_stress| PartParams {
        material: Material::Foam,
        youngs_modulus_pa: 2e5,
        poisson_ratio: 0.2,
        yield_stress_pa: yield_stress,
        plastic_viscosity_pa_s: 1.0,
        density_kg_m3: 300.0,
        ..Default::default()
    };
    let (yp, yl) = sheared_block(foam(1e3));
    let (ep, el) = sheared_block(foam(1e8));
    eprintln!(
        "foam above yield: peak {yp:.4} final {yl:.4}; below yield: peak {ep:.4} final {el:.5}"
    );
    assert!(yp > 0.015, "the top must move (peak {yp})");
    assert!(
        yl > 0.5 * yp,
        "foam past yield keeps its shear: final {yl}, peak {yp}"
    );
    assert!(
        el.abs() < 0.1 * ep,
        "below yield the foam springs back: final {el}, peak {ep}"
    );
}

#[test]
fn snow_compacts_under_compression() {
    let snow = PartParams {
        material: Material::Snow,
        youngs_modulus_pa: 1.4e5,
        poisson_ratio: 0.2,
        density_kg_m3: 400.0,
        ..PartParams::new(Material::Snow)
    };
    let mut cfg = config(32, 5e-5, 400, snow);
    let dx = cfg.domain.dx();
    // A plate descends on the block at 0.3 m/s for 0.2 s (6 cm into a 15 cm block).
    cfg.boundary = vec![
        BoundaryCondition::BoundingBox {
            layers: 3,
            surface: Surface::Slip,
        },
        BoundaryCondition::Cuboid {
            point: [0.5, 0.5, 3.0 * dx + 0.15 + 1.5 * dx],
            size: [0.3, 0.3, dx],
            velocity: [0.0, 0.0, -0.3],
            start_time: 0.0,
            end_time: 0.2,
            reset: false,
        },
    ];
    let scene = boxed(&cfg, [0.4, 0.4, 3.0 * dx], [0.6, 0.6, 3.0 * dx + 0.15]);
    let mut mean_jp = 1.0;
    run(&cfg, scene, 10, |_, _, st| {
        let p = &st.state.plastic;
        mean_jp = p.iter().map(|s| s[1] as f64).sum::<f64>() / p.len() as f64;
    });
    eprintln!("snow: mean J_p after compression {mean_jp:.3}");
    assert!(mean_jp < 0.9, "mean J_p = {mean_jp}");
}

/// A slab pressed 4 cm by a descending plate that then stops acting; returns the slab's
/// thickness before and after.
fn pressed_slab(part: PartParams) -> (f64, f64) {
    let mut cfg = config(32, 1e-4, 200, part);
    cfg.solver.grid_v_damping = 0.999;
    let dx = cfg.domain.dx();
    let (z0, z1) = (3.0 * dx, 3.0 * dx + 0.1);
    cfg.boundary = vec![
        BoundaryCondition::BoundingBox {
            layers: 3,
            surface: Surface::Slip,
        },
        BoundaryCondition::Cuboid {
            point: [0.5, 0.5, z1 + 0.75 * dx],
            size: [0.3, 0.3, dx],
            velocity: [0.0, 0.0, -0.4],
            start_time: 0.0,
            end_time: 0.1,
            reset: false,
        },
    ];
    let scene = boxed(&cfg, [0.4, 0.4, z0], [0.6, 0.6, z1]);
    let (lo0, hi0, _) = bbox(&scene.x);
    let mut h = 0.0;
    run(&cfg, scene, 30, |_, s, st| {
        let (lo, hi, _) = bbox(&s.positions(st).unwrap());
        h = hi[2] - lo[2];
    });
    (hi0[2] - lo0[2], h)
}

#[test]
fn plasticine_stays_flattened_but_jelly_recovers() {
    let plast = PartParams {
        material: Material::Plasticine,
        youngs_modulus_pa: 3e5,
        poisson_ratio: 0.3,
        yield_stress_pa: 2e3,
        softening: 0.1,
        density_kg_m3: 1200.0,
        ..Default::default()
    };
    let (h0, h) = pressed_slab(plast);
    let (j0, j) = pressed_slab(PartParams {
        density_kg_m3: 1200.0,
        ..jelly(3e5)
    });
    eprintln!("plasticine: thickness {h0:.4} -> {h:.4} m; jelly {j0:.4} -> {j:.4} m");
    assert!(h < 0.85 * h0, "plasticine must stay flattened: {h0} -> {h}");
    assert!(j > 0.95 * j0, "jelly must recover: {j0} -> {j}");
}
