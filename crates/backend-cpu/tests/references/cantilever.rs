//! The cantilever's first natural frequency against beam theory.
//!
//! A jelly beam (E = 1e6 Pa, nu = 0.3, rho = 1000 kg/m^3) is clamped by zero velocity on every
//! grid node with x <= x_c, starts straight with a velocity in the first Euler-Bernoulli mode
//! shape (tip speed 0.05 m/s) and vibrates without gravity. The tip's vertical motion is fitted
//! with a sine to get the frequency. Stubby beam (L/h = 4, 6 cells thick): within 3% of
//! Timoshenko (shear coefficient 0.85, computed here by shooting on the Timoshenko equations);
//! slender beam (L/h = 10, 4 cells thick): within 5% of Euler-Bernoulli. See
//! `tests/fixtures/mpm/README.md` for what PhysGaussian's solver gets on the same stubby beam
//! (-1.1% against Timoshenko).

use r4d_backend_cpu::CpuBackend;
use r4d_mpm::{
    Backend as _, BoundaryCondition, ForceForm, Material, PartParams, ParticleSet, Shape,
    Simulation, Simulator,
};
use r4d_testkit::scenes::config;

const E: f64 = 1e6;
const NU: f64 = 0.3;
const RHO: f64 = 1000.0;
const BETA1: f64 = 1.875_104_068_711_961;

/// Euler-Bernoulli first frequency (Hz) of a cantilever with a square section of side h.
fn euler_bernoulli_hz(l: f64, h: f64) -> f64 {
    let i = h.powi(4) / 12.0;
    let a = h * h;
    BETA1 * BETA1 / (2.0 * std::f64::consts::PI * l * l) * (E * i / (RHO * a)).sqrt()
}

/// Timoshenko first frequency (Hz): shooting on
/// `w'' = psi' - rho w^2 w / (k G)`, `psi'' = -(k G A (w' - psi) + rho I w^2 psi) / (E I)`
/// from the clamp (w = psi = 0) to the free end (psi' = 0, w' - psi = 0).
fn timoshenko_hz(l: f64, h: f64, kappa: f64) -> f64 {
    let (a, i) = (h * h, h.powi(4) / 12.0);
    let g = E / (2.0 * (1.0 + NU));
    let end = |omega: f64, init: [f64; 4]| -> [f64; 4] {
        let w2 = omega * omega;
        let f = |y: [f64; 4]| -> [f64; 4] {
            let (w, dw, psi, dpsi) = (y[0], y[1], y[2], y[3]);
            [
                dw,
                dpsi - RHO * w2 * w / (kappa * g),
                dpsi,
                -(kappa * g * a * (dw - psi) + RHO * i * w2 * psi) / (E * i),
            ]
        };
        let n = 4000;
        let hstep = l / n as f64;
        let mut y = init;
        let add = |y: [f64; 4], k: [f64; 4], s: f64| std::array::from_fn(|j| y[j] + s * k[j]);
        for _ in 0..n {
            let k1 = f(y);
            let k2 = f(add(y, k1, hstep / 2.0));
            let k3 = f(add(y, k2, hstep / 2.0));
            let k4 = f(add(y, k3, hstep));
            y = std::array::from_fn(|j| {
                y[j] + hstep / 6.0 * (k1[j] + 2.0 * k2[j] + 2.0 * k3[j] + k4[j])
            });
        }
        y
    };
    let det = |omega: f64| {
        let y1 = end(omega, [0.0, 1.0, 0.0, 0.0]);
        let y2 = end(omega, [0.0, 0.0, 0.0, 1.0]);
        y1[3] * (y2[1] - y2[2]) - y2[3] * (y1[1] - y1[2])
    };
    let w_eb = 2.0 * std::f64::consts::PI * euler_bernoulli_hz(l, h);
    let (mut lo, mut step) = (0.3 * w_eb, 0.01 * w_eb);
    while det(lo).signum() == det(lo + step).signum() {
        lo += step;
        assert!(lo < 1.5 * w_eb, "no root found");
    }
    let mut hi = lo + step;
    for _ in 0..60 {
        let mid = 0.5 * (lo + hi);
        if det(lo).signum() == det(mid).signum() {
            lo = mid;
        } else {
            hi = mid;
        }
        step = hi - lo;
    }
    let _ = step;
    0.5 * (lo + hi) / (2.0 * std::f64::consts::PI)
}

/// Fits `a sin(w t) + b cos(w t) + c` and returns the best frequency (Hz).
fn fit_frequency_hz(t: &[f64], z: &[f64], guess_hz: f64) -> f64 {
    let residual = |f: f64| {
        let w = 2.0 * std::f64::consts::PI * f;
        // Normal equations for the 3 linear coefficients.
        let mut m = [[0.0f64; 3]; 3];
        let mut r = [0.0f64; 3];
        for (&ti, &zi) in t.iter().zip(z) {
            let b = [(w * ti).sin(), (w * ti).cos(), 1.0];
            for p in 0..3 {
                r[p] += b[p] * zi;
                for q in 0..3 {
                    m[p][q] += b[p] * b[q];
                }
            }
        }
        let det3 = |m: [[f64; 3]; 3]| {
            m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
                - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
                + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0])
        };
        let d = det3(m);
        let coef: [f64; 3] = std::array::from_fn(|k| {
            let mut mk = m;
            for p in 0..3 {
                mk[p][k] = r[p];
            }
            det3(mk) / d
        });
        t.iter()
            .zip(z)
            .map(|(&ti, &zi)| {
                let fit = coef[0] * (w * ti).sin() + coef[1] * (w * ti).cos() + coef[2];
                (zi - fit).powi(2)
            })
            .sum::<f64>()
    };
    // Coarse scan, then golden-section refinement.
    let mut best = guess_hz;
    let mut best_r = f64::MAX;
    for k in 0..=200 {
        let f = guess_hz * (0.6 + 0.8 * k as f64 / 200.0);
        let r = residual(f);
        if r < best_r {
            best_r = r;
            best = f;
        }
    }
    let (mut a, mut b) = (best - 0.004 * guess_hz, best + 0.004 * guess_hz);
    let g = 0.5 * (5f64.sqrt() - 1.0);
    for _ in 0..60 {
        let (c, d) = (b - g * (b - a), a + g * (b - a));
        if residual(c) < residual(d) {
            b = d;
        } else {
            a = c;
        }
    }
    0.5 * (a + b)
}

/// Simulates the cantilever and returns its measured first frequency (Hz).
/// The section is `cells` cells thick, clamped on node layers x <= x_c = clamp_node dx.
fn measured_frequency_hz(
    n_grid: usize,
    cells: usize,
    l_over_h: usize,
    clamp_node: usize,
    dt: f64,
    periods: f64,
) -> f64 {
    let part = PartParams {
        material: Material::Jelly,
        youngs_modulus_pa: E,
        poisson_ratio: NU,
        density_kg_m3: RHO,
        ..Default::default()
    };
    let mut cfg = config(n_grid, dt, 10, part);
    cfg.solver.gravity = [0.0; 3];
    cfg.solver.force = ForceForm::Mls;
    let dx = cfg.domain.dx();
    let h = cells as f64 * dx;
    let l = l_over_h as f64 * h;
    let xc = clamp_node as f64 * dx;
    let lo = 0.5 - h / 2.0;
    cfg.boundary = vec![BoundaryCondition::Cuboid {
        point: [0.0, 0.5, 0.5],
        size: [xc + 0.5 * dx, 1.0, 1.0],
        velocity: [0.0; 3],
        start_time: 0.0,
        end_time: f64::INFINITY,
        reset: false,
    }];
    let scene = ParticleSet::from_shapes(
        &[Shape::Beam {
            origin: [xc - 4.0 * dx, lo, lo],
            length: l + 4.0 * dx,
            width: h,
            thickness: h,
            part: 0,
            per_cell: 2,
        }],
        dx,
    );
    // First Euler-Bernoulli mode shape, tip speed 0.05 m/s.
    let sigma = (BETA1.cosh() + BETA1.cos()) / (BETA1.sinh() + BETA1.sin());
    let mode = |xi: f64| {
        (BETA1 * xi).cosh()
            - (BETA1 * xi).cos()
            - sigma * ((BETA1 * xi).sinh() - (BETA1 * xi).sin())
    };
    let v: Vec<[f32; 3]> = scene
        .x
        .iter()
        .map(|p| {
            let xi = ((p[0] as f64 - xc) / l).clamp(0.0, 1.0);
            [0.0, 0.0, (0.05 * mode(xi) / mode(1.0)) as f32]
        })
        .collect();
    let tip: Vec<usize> = (0..scene.len())
        .filter(|&i| scene.x[i][0] as f64 > xc + l - dx)
        .collect();
    let z0: f64 = tip.iter().map(|&i| scene.x[i][2] as f64).sum::<f64>() / tip.len() as f64;
    let mut sim = Simulation::new(CpuBackend::default(), &cfg, scene, "cantilever").unwrap();
    let mut st = sim.init_state(&cfg.parts).unwrap();
    sim.backend().write(&mut st.state.v, &v).unwrap();
    let f_eb = euler_bernoulli_hz(l, h);
    let samples = (periods / f_eb / (10.0 * dt)).ceil() as usize;
    let (mut t, mut z) = (vec![0.0], vec![0.0]);
    for _ in 0..samples {
        sim.step_frame(&mut st, &cfg.parts).unwrap();
        let x = sim.positions(&st).unwrap();
        t.push(st.time_s);
        z.push(tip.iter().map(|&i| x[i][2] as f64).sum::<f64>() / tip.len() as f64 - z0);
    }
    let amp = z.iter().cloned().fold(0.0f64, |m, v| m.max(v.abs()));
    eprintln!("tip amplitude {amp:.2e} m over {samples} samples");
    fit_frequency_hz(&t, &z, f_eb)
}

#[test]
fn timoshenko_solver_reproduces_the_reference_figure() {
    // tests/fixtures/mpm/README.md: L = 0.5 m, h = 0.125 m, kappa 0.85 -> 2.439 Hz; EB 2.554 Hz.
    let f = timoshenko_hz(0.5, 0.125, 0.85);
    assert!((f - 2.439).abs() < 0.002, "{f}");
    assert!((euler_bernoulli_hz(0.5, 0.125) - 2.554).abs() < 0.001);
}

#[test]
fn stubby_cantilever_matches_timoshenko_within_3_percent() {
    // n_grid 48: h = 6 dx = 0.125 m, L = 4 h = 0.5 m, clamp x <= 0.3125 m (node 15).
    let f = measured_frequency_hz(48, 6, 4, 15, 1.5e-4, 1.3);
    let ft = timoshenko_hz(0.5, 0.125, 0.85);
    let err = f / ft - 1.0;
    eprintln!(
        "stubby cantilever: {f:.4} Hz vs Timoshenko {ft:.4} Hz: {:+.2}%",
        100.0 * err
    );
    assert!(err.abs() < 0.03, "{:+.2}%", 100.0 * err);
}

#[test]
fn slender_cantilever_matches_euler_bernoulli_within_5_percent() {
    // n_grid 64: h = 4 dx = 0.0625 m, L = 10 h = 0.625 m, clamp x <= 0.125 m (node 8).
    let f = measured_frequency_hz(64, 4, 10, 8, 1.5e-4, 1.1);
    let (l, h) = (0.625, 0.0625);
    let fe = euler_bernoulli_hz(l, h);
    let err = f / fe - 1.0;
    eprintln!(
        "slender cantilever: {f:.4} Hz vs Euler-Bernoulli {fe:.4} Hz: {:+.2}% (Timoshenko {:.4} Hz)",
        100.0 * err,
        timoshenko_hz(l, h, 0.85)
    );
    assert!(err.abs() < 0.05, "{:+.2}%", 100.0 * err);
}
