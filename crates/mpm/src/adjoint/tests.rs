//! Finite-difference checks (f64, central differences) of the transfer VJPs.

use super::transfer_vjp::*;
use crate::boundary::{BoundaryCondition, Surface};
use crate::kernels::{GridBc, ParticleBc, StepConsts, FORCE_CLASSIC, FORCE_MLS};
use crate::transfer::{apply_grid_bcs, g2p_finish, gather, grid_node_update, scatter, stencil};

struct Rng(u64);
impl Rng {
    fn next(&mut self) -> f64 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((self.0 >> 11) as f64 / (1u64 << 53) as f64) * 2.0 - 1.0
    }
    fn arr<const N: usize>(&mut self, s: f64) -> [f64; N] {
        std::array::from_fn(|_| s * self.next())
    }
}

const N: usize = 8;

fn consts(force: u32) -> StepConsts {
    StepConsts {
        gravity: [0.3, -0.2, -9.8],
        dt: 1e-3,
        dx: 0.125,
        inv_dx: 8.0,
        n_grid: N as u32,
        substep: 0,
        time: 0.05,
        rpic_damping: 0.0,
        grid_v_damping: 0.9,
        force_form: force,
        n_grid_bcs: 0,
        n_particle_bcs: 0,
        out_of_domain: 0,
        max_speed: 1e9,
    }
}

fn assert_close(what: &str, analytic: f64, fd: f64, scale: f64) {
    let err = (analytic - fd).abs() / scale.max(1e-12);
    assert!(
        err < 1e-6,
        "{what}: analytic {analytic:e} vs fd {fd:e} (rel err {err:e})"
    );
}

fn fd<F: Fn(f64) -> f64>(f: F, x: f64) -> f64 {
    let h = 1e-6 * x.abs().max(1.0);
    (f(x + h) - f(x - h)) / (2.0 * h)
}

/// Particle inputs of a scatter, as one flat vector: x(3) v(3) a(9) m(1) s(9).
fn scatter_loss(p: &[f64; 25], bar: &[[f64; 4]], c: &StepConsts) -> f64 {
    let x = [p[0], p[1], p[2]];
    let v = [p[3], p[4], p[5]];
    let a: [f64; 9] = std::array::from_fn(|e| p[6 + e]);
    let m = p[15];
    let s: [f64; 9] = std::array::from_fn(|e| p[16 + e]);
    let mut nodes = vec![[0.0f64; 4]; N * N * N];
    let st = stencil(x, c.inv_dx as f64);
    scatter(&mut nodes, 0, N, &st, v, &a, m, &s, c);
    nodes
        .iter()
        .zip(bar)
        .map(|(n, b)| (0..4).map(|q| n[q] * b[q]).sum::<f64>())
        .sum()
}

#[test]
fn scatter_vjp_matches_finite_differences() {
    for force in [FORCE_CLASSIC, FORCE_MLS] {
        let c = consts(force);
        let mut r = Rng(7 + force as u64);
        for _ in 0..5 {
            let mut p = [0.0f64; 25];
            for a in 0..3 {
                p[a] = 0.4 + 0.2 * r.next().abs() + 0.01 * a as f64;
            }
            for e in 3..25 {
                p[e] = r.next();
            }
            p[15] = 0.5 + r.next().abs();
            let bar: Vec<[f64; 4]> = (0..N * N * N).map(|_| r.arr(1.0)).collect();
            let mut out = ScatterBar::default();
            let st = stencil([p[0], p[1], p[2]], 8.0);
            let a: [f64; 9] = std::array::from_fn(|e| p[6 + e]);
            let s: [f64; 9] = std::array::from_fn(|e| p[16 + e]);
            scatter_vjp(
                &bar,
                N,
                &st,
                [p[3], p[4], p[5]],
                &a,
                p[15],
                &s,
                &c,
                &mut out,
            );
            let mut analytic = [0.0; 25];
            analytic[..3].copy_from_slice(&out.x);
            analytic[3..6].copy_from_slice(&out.v);
            analytic[6..15].copy_from_slice(&out.a);
            analytic[15] = out.mass;
            analytic[16..25].copy_from_slice(&out.s);
            let scale = analytic.iter().fold(0.0f64, |m, v| m.max(v.abs()));
            for e in 0..25 {
                let g = fd(
                    |t| {
                        let mut q = p;
                        q[e] = t;
                        scatter_loss(&q, &bar, &c)
                    },
                    p[e],
                );
                assert_close(&format!("force {force} input {e}"), analytic[e], g, scale);
            }
        }
    }
}

fn grid_bcs(c: &StepConsts) -> Vec<GridBc> {
    let _ = c;
    [
        BoundaryCondition::BoundingBox {
            layers: 3,
            surface: Surface::Slip,
        },
        BoundaryCondition::SurfaceCollider {
            point: [0.0, 0.0, 0.3],
            normal: [0.1, 0.2, 1.0],
            surface: Surface::Friction,
            friction: 0.3,
            start_time: 0.0,
            end_time: 1.0,
        },
        BoundaryCondition::SurfaceCollider {
            point: [0.0, 0.45, 0.0],
            normal: [0.0, -1.0, 0.3],
            surface: Surface::Slip,
            friction: 0.0,
            start_time: 0.0,
            end_time: 1.0,
        },
        BoundaryCondition::Cuboid {
            point: [0.9, 0.9, 0.9],
            size: [0.1, 0.1, 0.1],
            velocity: [0.0, 0.0, 1.0],
            start_time: 0.0,
            end_time: 1.0,
            reset: false,
        },
    ]
    .iter()
    .filter_map(|b| b.grid_bc())
    .collect()
}

#[test]
fn grid_node_update_vjp_matches_finite_differences_for_every_condition() {
    let c = consts(FORCE_CLASSIC);
    let bcs = grid_bcs(&c);
    let mut r = Rng(11);
    let mut fired = [false; 4];
    for ijk in [
        [1, 4, 4],
        [4, 4, 1],
        [4, 4, 2],
        [2, 2, 2],
        [4, 4, 4],
        [4, 6, 5],
        [6, 1, 6],
        [7, 7, 7],
    ] {
        for _ in 0..6 {
            let node: [f64; 4] = [r.next(), r.next(), 2.0 * r.next(), 0.5 + r.next().abs()];
            let vb: [f64; 3] = r.arr(1.0);
            // Which conditions change this node's velocity (to assert they fired).
            let mut u = [
                node[0] / node[3],
                node[1] / node[3],
                node[2] / node[3] - 9.8e-3,
            ];
            for (bi, bc) in bcs.iter().enumerate() {
                let before = u;
                apply_grid_bcs(ijk, &mut u, std::slice::from_ref(bc), &c);
                if before != u {
                    fired[bi] = true;
                }
            }
            let loss = |nd: [f64; 4]| {
                let mut n2 = nd;
                grid_node_update(ijk, &mut n2, &bcs, &c);
                (0..3).map(|a| n2[a] * vb[a]).sum::<f64>()
            };
            let analytic = grid_node_update_vjp(ijk, node, &bcs, &c, vb);
            for e in 0..4 {
                let g = fd(
                    |t| {
                        let mut q = node;
                        q[e] = t;
                        loss(q)
                    },
                    node[e],
                );
                assert_close(&format!("node {ijk:?} input {e}"), analytic[e], g, 1.0);
            }
        }
    }
    assert!(
        fired.iter().all(|&f| f),
        "every condition must act in the check: {fired:?}"
    );
}

#[test]
fn g2p_vjp_matches_finite_differences() {
    for force in [FORCE_CLASSIC, FORCE_MLS] {
        let c = consts(force);
        let mut r = Rng(23 + force as u64);
        let nodes: Vec<[f64; 4]> = (0..N * N * N)
            .map(|_| [r.next(), r.next(), r.next(), 1.0])
            .collect();
        let x = [0.41, 0.52, 0.47];
        let fe: [f64; 9] =
            std::array::from_fn(|e| if e % 4 == 0 { 1.0 } else { 0.0 } + 0.1 * r.next());
        let (xb, vb, cb, fb): ([f64; 3], [f64; 3], [f64; 9], [f64; 9]) =
            (r.arr(1.0), r.arr(1.0), r.arr(1.0), r.arr(1.0));
        let loss = |x: [f64; 3], fe: [f64; 9], nodes: &[[f64; 4]]| {
            let st = stencil(x, 8.0);
            let g = gather(nodes, N, &st, &c);
            let (mut x2, mut v2, mut c2, mut f2) = (x, [0.0; 3], [0.0; 9], fe);
            g2p_finish(&g, &mut x2, &mut v2, &mut c2, &mut f2, &c);
            (0..3).map(|a| x2[a] * xb[a] + v2[a] * vb[a]).sum::<f64>()
                + (0..9).map(|e| c2[e] * cb[e] + f2[e] * fb[e]).sum::<f64>()
        };
        let mut nodes_bar = vec![[0.0f64; 4]; N * N * N];
        let out = g2p_vjp(&nodes, N, x, &fe, &c, xb, vb, &cb, &fb, &mut nodes_bar, 0);
        let scale = out
            .x
            .iter()
            .chain(&out.f_elastic)
            .fold(0.0f64, |m, v| m.max(v.abs()));
        for a in 0..3 {
            let g = fd(
                |t| {
                    let mut q = x;
                    q[a] = t;
                    loss(q, fe, &nodes)
                },
                x[a],
            );
            assert_close(&format!("force {force} x[{a}]"), out.x[a], g, scale);
        }
        for e in 0..9 {
            let g = fd(
                |t| {
                    let mut q = fe;
                    q[e] = t;
                    loss(x, q, &nodes)
                },
                fe[e],
            );
            assert_close(
                &format!("force {force} Fe[{e}]"),
                out.f_elastic[e],
                g,
                scale,
            );
        }
        let st = stencil(x, 8.0);
        let base = ((st.base[0] as usize * N + st.base[1] as usize) * N) + st.base[2] as usize;
        for idx in [
            base,
            base + 1,
            base + N + 2,
            base + N * N + N,
            base + 2 * N * N + 2 * N + 2,
        ] {
            for q in 0..3 {
                let g = fd(
                    |t| {
                        let mut n2 = nodes.clone();
                        n2[idx][q] = t;
                        loss(x, fe, &n2)
                    },
                    nodes[idx][q],
                );
                assert_close(
                    &format!("force {force} node {idx}[{q}]"),
                    nodes_bar[idx][q],
                    g,
                    scale,
                );
            }
        }
    }
}

#[test]
fn particle_bcs_vjp_matches_finite_differences() {
    let c = consts(FORCE_CLASSIC);
    let bcs: Vec<ParticleBc> = [
        BoundaryCondition::ParticleImpulse {
            force: [0.3, -0.2, 0.5],
            point: [0.5; 3],
            size: [0.2; 3],
            num_dt: 100,
            start_time: 0.0,
        },
        BoundaryCondition::ParticleImpulse {
            force: [0.1, 0.0, -0.7],
            point: [0.5; 3],
            size: [0.2; 3],
            num_dt: 100,
            start_time: 0.0,
        },
    ]
    .iter()
    .filter_map(|b| b.particle_bc(1e-3))
    .collect();
    let x0 = [0.5f32; 3];
    let vbar = [0.3, -1.0, 0.7];
    let m = 0.8f64;
    let loss = |m: f64| {
        let mut v = [0.1, 0.2, 0.3];
        crate::transfer::particle_bcs(x0, &mut v, m, &bcs, &c);
        (0..3).map(|a| v[a] * vbar[a]).sum::<f64>()
    };
    let mut vb = vbar;
    let mut mb = 0.0;
    particle_bcs_vjp(x0, m, &bcs, &c, &mut vb, &mut mb);
    assert_close("mass", mb, fd(loss, m), 1.0);
    assert_eq!(vb, vbar);
}

mod constitutive {
    use super::{fd, Rng};
    use crate::adjoint::constitutive_vjp::stress_update_vjp;
    use crate::constitutive::{stress_update_with, MaterialParams};
    use crate::material::{Material, PartParams};
    use crate::math::Mat3;

    struct Case {
        name: &'static str,
        part: PartParams,
        f: Mat3<f64>,
        state: [f64; 2],
        /// The return mapping must change F (plasticity fired).
        plastic: bool,
    }

    fn near(r: &mut Rng, d: [f64; 3], s: f64) -> Mat3<f64> {
        Mat3::diag(d) + Mat3::from_array(r.arr(s))
    }

    fn cases() -> Vec<Case> {
        let mut r = Rng(99);
        let base = |m: Material| PartParams {
            material: m,
            youngs_modulus_pa: 1e5,
            poisson_ratio: 0.3,
            yield_stress_pa: 500.0,
            plastic_viscosity_pa_s: 0.5,
            friction_angle_deg: 30.0,
            density_kg_m3: 1000.0,
            ..Default::default()
        };
        vec![
            Case {
                name: "jelly",
                part: base(Material::Jelly),
                f: near(&mut r, [1.0; 3], 0.1),
                state: [0.0, 1.0],
                plastic: false,
            },
            Case {
                name: "jelly at rest",
                part: base(Material::Jelly),
                f: Mat3::identity(),
                state: [0.0, 1.0],
                plastic: false,
            },
            Case {
                name: "metal",
                part: base(Material::Metal),
                f: near(&mut r, [1.05, 0.97, 1.0], 0.02),
                state: [500.0, 1.0],
                plastic: true,
            },
            Case {
                name: "metal elastic",
                part: base(Material::Metal),
                f: near(&mut r, [1.0; 3], 1e-4),
                state: [5e4, 1.0],
                plastic: false,
            },
            Case {
                name: "metal hardening",
                part: PartParams {
                    hardening: true,
                    xi: 0.5,
                    ..base(Material::Metal)
                },
                f: near(&mut r, [1.04, 0.98, 1.0], 0.02),
                state: [500.0, 1.0],
                plastic: true,
            },
            Case {
                name: "sand compression",
                part: base(Material::Sand),
                f: near(&mut r, [1.1, 0.95, 0.9], 0.01),
                state: [0.0, 1.0],
                plastic: true,
            },
            Case {
                name: "sand expansion",
                part: base(Material::Sand),
                f: near(&mut r, [1.05, 1.02, 1.03], 0.01),
                state: [0.0, 1.0],
                plastic: true,
            },
            Case {
                name: "sand elastic",
                part: base(Material::Sand),
                f: Mat3::diag([0.99, 0.99, 0.99]) + Mat3::from_array(r.arr(1e-4)),
                state: [0.0, 1.0],
                plastic: false,
            },
            Case {
                name: "foam",
                part: base(Material::Foam),
                f: near(&mut r, [1.05, 0.97, 1.0], 0.02),
                state: [500.0, 1.0],
                plastic: true,
            },
            Case {
                name: "snow",
                part: base(Material::Snow),
                f: near(&mut r, [0.95, 1.0, 1.02], 0.005),
                state: [0.0, 0.9],
                plastic: true,
            },
            Case {
                name: "plasticine",
                part: PartParams {
                    softening: 50.0,
                    ..base(Material::Plasticine)
                },
                f: near(&mut r, [1.05, 0.97, 1.0], 0.02),
                state: [500.0, 1.0],
                plastic: true,
            },
            Case {
                name: "non_newtonian beyond the yield surface",
                part: base(Material::NonNewtonian),
                f: near(&mut r, [1.05, 0.97, 1.0], 0.02),
                state: [500.0, 1.0],
                plastic: true,
            },
            Case {
                name: "non_newtonian inside the yield surface (pulled toward it)",
                part: base(Material::NonNewtonian),
                f: near(&mut r, [1.01, 0.995, 1.0], 0.005),
                state: [5e4, 1.0],
                plastic: true,
            },
            Case {
                name: "newtonian",
                part: base(Material::Newtonian),
                f: near(&mut r, [1.02, 0.99, 0.98], 0.02),
                state: [0.0, 1.0],
                plastic: false,
            },
        ]
    }

    #[test]
    fn constitutive_vjp_matches_finite_differences_for_every_material() {
        let dt = 1e-4;
        for case in cases() {
            let pc = case.part.consts();
            let p0 = MaterialParams::<f64>::of(&pc);
            let mut r = Rng(5);
            let (fe_bar, tau_bar) = (Mat3::from_array(r.arr(1.0)), Mat3::from_array(r.arr(1e-4)));
            let state_bar: [f64; 2] = r.arr(1e-3);
            let loss = |f: Mat3<f64>, st: [f64; 2], p: MaterialParams<f64>| {
                let mut st2 = st;
                let (fe, tau) = stress_update_with(f, &pc, &mut st2, p, dt);
                let a = fe.to_array();
                let t = tau.to_array();
                (0..9)
                    .map(|e| a[e] * fe_bar.to_array()[e] + t[e] * tau_bar.to_array()[e])
                    .sum::<f64>()
                    + st2[0] * state_bar[0]
                    + st2[1] * state_bar[1]
            };
            // The branch of interest fired.
            let mut st2 = case.state;
            let (fe, _) = stress_update_with(case.f, &pc, &mut st2, p0, dt);
            let changed = (fe - case.f).frobenius() > 1e-9;
            assert_eq!(
                changed, case.plastic,
                "{}: plasticity fired = {changed}",
                case.name
            );
            let bar =
                stress_update_vjp(case.f, &pc, case.state, p0, dt, fe_bar, tau_bar, state_bar);
            let mut worst: f64 = 0.0;
            let mut check = |what: String, a: f64, g: f64, scale: f64| {
                let err = (a - g).abs() / scale.max(1e-300);
                worst = worst.max(err);
                assert!(
                    err < 1e-5,
                    "{}: {what}: analytic {a:e} fd {g:e} rel {err:e}",
                    case.name
                );
            };
            let fa = bar.f_trial.to_array();
            let fscale = fa.iter().fold(0.0f64, |m, v| m.max(v.abs()));
            for e in 0..9 {
                let g = fd(
                    |t| {
                        let mut a = case.f.to_array();
                        a[e] = t;
                        loss(Mat3::from_array(a), case.state, p0)
                    },
                    case.f.to_array()[e],
                );
                check(format!("dF[{e}]"), fa[e], g, fscale);
            }
            for e in 0..2 {
                let g = fd(
                    |t| {
                        let mut s = case.state;
                        s[e] = t;
                        loss(case.f, s, p0)
                    },
                    case.state[e],
                );
                check(
                    format!("dstate[{e}]"),
                    bar.state[e],
                    g,
                    bar.state[e].abs().max(g.abs()).max(1e-12),
                );
            }
            let pv = [p0.mu, p0.lambda, p0.eta, p0.alpha, p0.h];
            let pb = [
                bar.params.mu,
                bar.params.lambda,
                bar.params.eta,
                bar.params.alpha,
                bar.params.h,
            ];
            for e in 0..5 {
                let g = fd(
                    |t| {
                        let mut q = pv;
                        q[e] = t;
                        loss(
                            case.f,
                            case.state,
                            MaterialParams {
                                mu: q[0],
                                lambda: q[1],
                                eta: q[2],
                                alpha: q[3],
                                h: q[4],
                            },
                        )
                    },
                    pv[e],
                );
                check(
                    format!("dparam[{e}]"),
                    pb[e],
                    g,
                    pb[e].abs().max(g.abs()).max(1e-300),
                );
            }
            eprintln!("{}: worst relative error {worst:.2e}", case.name);
        }
    }
}

mod trajectory {
    //! Whole-trajectory gradients of the host simulator against f64 finite differences:
    //! every material x every parameter, 3 frames of 20 substeps, boundary conditions active.
    use super::Rng;
    use crate::adjoint::checkpoint::Differentiable;
    use crate::adjoint::host::{HostSim, PhysParams};
    use crate::boundary::{BoundaryCondition, Surface};
    use crate::config::{Domain, ForceForm, SimConfig, SolverConfig, TimeConfig};
    use crate::constitutive::stress_update_with;
    use crate::material::{Material, PartParams};
    use crate::math::Mat3;
    use crate::reference::ReferenceBackend;
    use crate::scene::{ParticleSet, Shape};
    use crate::simulation::Simulation;
    use crate::state::State as StateOf;

    const FRAMES: usize = 3;
    const SPF: u64 = 20;

    fn scene_for(part: PartParams, force: ForceForm) -> (SimConfig, ParticleSet) {
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
                substeps_per_frame: Some(SPF as u32),
                frames: FRAMES,
            },
            solver: SolverConfig {
                force,
                rpic_damping: 0.1,
                ..Default::default()
            },
            parts: vec![part],
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
                BoundaryCondition::Cuboid {
                    point: [0.3, 0.5, 0.5],
                    size: [0.04, 0.5, 0.5],
                    velocity: [0.0; 3],
                    start_time: 0.0,
                    end_time: 1.0,
                    reset: false,
                },
                BoundaryCondition::ParticleImpulse {
                    force: [-0.02, 0.01, -0.05],
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

    struct Weights {
        x: Vec<Vec<[f64; 3]>>,
        f: Vec<Vec<[f64; 9]>>,
    }

    type Oracle = Simulation<ReferenceBackend<f64>>;
    type State = StateOf<ReferenceBackend<f64>>;

    fn frame_loss(s: &State, w: &Weights, frame: usize) -> f64 {
        let mut l = 0.0;
        for p in 0..s.x.len() {
            for a in 0..3 {
                l += w.x[frame][p][a] * s.x[p][a];
            }
            for e in 0..9 {
                l += w.f[frame][p][e] * s.f[p][e];
            }
        }
        l
    }

    /// Loss of a run; also counts the plastic projections that happened.
    fn run(
        eng: &Oracle,
        params: &[PhysParams<f64>],
        v0: &[[f64; 3]],
        w: &Weights,
    ) -> (f64, Vec<State>, usize) {
        let sim = eng.host();
        let mut s = eng.init(params, v0).unwrap();
        let mut states = vec![eng.clone_state(&s).unwrap()];
        let mut loss = 0.0;
        let mut plastic_events = 0;
        for kk in 0..FRAMES as u64 * SPF {
            for p in 0..s.x.len() {
                let part = sim.part[p] as usize;
                let mut st = s.plastic[p];
                let f = Mat3::from_array(s.f[p]);
                let (fe, _) = stress_update_with(
                    f,
                    &sim.consts[part],
                    &mut st,
                    params[part].material(sim.consts[part].material),
                    2e-4,
                );
                if (fe - f).frobenius() > 1e-12 {
                    plastic_events += 1;
                }
            }
            eng.step(&mut s, &params.to_vec(), kk).unwrap();
            states.push(eng.clone_state(&s).unwrap());
            if (kk + 1) % SPF == 0 {
                loss += frame_loss(&s, w, ((kk + 1) / SPF) as usize - 1);
            }
        }
        (loss, states, plastic_events)
    }

    fn check_material(name: &str, part: PartParams, force: ForceForm, plastic: bool) {
        let (cfg, scene) = scene_for(part, force);
        let sim = HostSim::new(&cfg, &scene).unwrap();
        let np = sim.len();
        let mut r = Rng(31);
        let w = Weights {
            x: (0..FRAMES)
                .map(|_| (0..np).map(|_| r.arr(1.0)).collect())
                .collect(),
            f: (0..FRAMES)
                .map(|_| (0..np).map(|_| r.arr(0.1)).collect())
                .collect(),
        };
        let v0: Vec<[f64; 3]> = (0..np).map(|_| [0.05, -0.02, 0.03]).collect();
        let params = vec![PhysParams::<f64>::of(&part)];
        let eng = Oracle::with_host(ReferenceBackend::in_scalar(), sim.clone()).unwrap();
        let (_, states, events) = run(&eng, &params, &v0, &w);
        assert_eq!(events > 0, plastic, "{name}: {events} plastic projections");
        // Reverse sweep.
        let mut adj = eng.zero_adjoint(&states[0]).unwrap();
        let mut grad = eng.zero_grad().unwrap();
        for kk in (0..FRAMES as u64 * SPF).rev() {
            if (kk + 1) % SPF == 0 {
                let fr = ((kk + 1) / SPF) as usize - 1;
                for p in 0..np {
                    for a in 0..3 {
                        adj.x[p][a] += w.x[fr][p][a];
                    }
                    for e in 0..9 {
                        adj.f[p][e] += w.f[fr][p][e];
                    }
                }
            }
            eng.step_vjp(&states[kk as usize], &params, kk, &mut adj, &mut grad)
                .unwrap();
        }
        let mut grad = eng.grad_to_host(&grad, &params).unwrap();
        eng.init_vjp(&adj, &mut grad).unwrap();
        let g = grad[0];
        let analytic = [
            ("E", g.youngs_modulus),
            ("nu", g.poisson_ratio),
            ("yield_stress", g.yield_stress),
            ("plastic_viscosity", g.plastic_viscosity),
            ("friction_angle", g.friction_angle_deg),
            ("density", g.density),
            ("hardening", g.hardening),
            ("softening", g.softening),
        ];
        let p0 = params[0];
        let values = [
            p0.youngs_modulus,
            p0.poisson_ratio,
            p0.yield_stress,
            p0.plastic_viscosity,
            p0.friction_angle_deg,
            p0.density,
            p0.hardening,
            p0.softening,
        ];
        for (e, (pname, a)) in analytic.iter().enumerate() {
            let h = 1e-4 * values[e].abs().max(1e-3);
            let eval = |t: f64| {
                let mut q = values;
                q[e] = t;
                let pp = PhysParams {
                    youngs_modulus: q[0],
                    poisson_ratio: q[1],
                    yield_stress: q[2],
                    plastic_viscosity: q[3],
                    friction_angle_deg: q[4],
                    density: q[5],
                    hardening: q[6],
                    softening: q[7],
                };
                run(&eng, &[pp], &v0, &w).0
            };
            let fd = (eval(values[e] + h) - eval(values[e] - h)) / (2.0 * h);
            let rel = (a - fd).abs() / a.abs().max(fd.abs()).max(1e-300);
            eprintln!("{name}: d/d{pname}: adjoint {a:+.6e} fd {fd:+.6e} rel {rel:.1e}");
            // Parameters a model does not read have zero gradient on both sides.
            let negligible = a.abs().max(fd.abs()) * values[e].abs().max(1e-3) < 1e-9;
            assert!(
                negligible || rel < 1e-4,
                "{name}: d/d{pname}: adjoint {a:e} vs fd {fd:e} (rel {rel:e})"
            );
        }
        // Initial velocity of the whole object (PhysDreamer's use) and one initial position.
        let vbar: f64 = adj.v.iter().map(|v| v[0]).sum();
        let fd_v = {
            let h = 1e-6;
            let shifted = |d: f64| {
                run(
                    &eng,
                    &params,
                    &v0.iter()
                        .map(|v| [v[0] + d, v[1], v[2]])
                        .collect::<Vec<_>>(),
                    &w,
                )
                .0
            };
            (shifted(h) - shifted(-h)) / (2.0 * h)
        };
        let rel = (vbar - fd_v).abs() / vbar.abs().max(fd_v.abs());
        eprintln!("{name}: d/dv0_x: adjoint {vbar:+.6e} fd {fd_v:+.6e} rel {rel:.1e}");
        assert!(rel < 1e-4, "{name}: initial velocity gradient rel {rel:e}");
    }

    fn base(m: Material) -> PartParams {
        PartParams {
            material: m,
            youngs_modulus_pa: 3e4,
            poisson_ratio: 0.3,
            yield_stress_pa: 300.0,
            plastic_viscosity_pa_s: 0.2,
            friction_angle_deg: 35.0,
            density_kg_m3: 800.0,
            ..Default::default()
        }
    }

    #[test]
    fn trajectory_gradients_match_finite_differences_jelly() {
        check_material("jelly (mls)", base(Material::Jelly), ForceForm::Mls, false);
        check_material(
            "jelly (classic)",
            base(Material::Jelly),
            ForceForm::Classic,
            false,
        );
    }
    #[test]
    fn trajectory_gradients_match_finite_differences_metal() {
        let p = PartParams {
            hardening: true,
            xi: 0.3,
            yield_stress_pa: 20.0,
            ..base(Material::Metal)
        };
        check_material("metal", p, ForceForm::Mls, true);
    }
    #[test]
    fn trajectory_gradients_match_finite_differences_sand() {
        check_material("sand", base(Material::Sand), ForceForm::Classic, true);
    }
    #[test]
    fn trajectory_gradients_match_finite_differences_foam() {
        check_material(
            "foam",
            PartParams {
                yield_stress_pa: 20.0,
                plastic_viscosity_pa_s: 2.0,
                ..base(Material::Foam)
            },
            ForceForm::Mls,
            true,
        );
    }
    #[test]
    fn trajectory_gradients_match_finite_differences_snow() {
        check_material(
            "snow",
            PartParams {
                snow_critical_compression: 2e-3,
                snow_critical_stretch: 1e-3,
                ..base(Material::Snow)
            },
            ForceForm::Mls,
            true,
        );
    }
    #[test]
    fn trajectory_gradients_match_finite_differences_plasticine() {
        check_material(
            "plasticine",
            PartParams {
                // Strong enough that the softening's own gradient is well above the
                // finite difference's round-off.
                softening: 200.0,
                yield_stress_pa: 20.0,
                ..base(Material::Plasticine)
            },
            ForceForm::Classic,
            true,
        );
    }
    #[test]
    fn trajectory_gradients_match_finite_differences_non_newtonian() {
        // PhysFlow's paste: the mapping runs at every substep (from F = I at the first, with
        // Warp's rounding), inside and beyond the yield surface.
        check_material(
            "non_newtonian",
            PartParams {
                // A viscosity near eta = 2 mu dt, where the mapping is most sensitive to it,
                // so that its gradient stands well above the finite difference's round-off.
                yield_stress_pa: 20.0,
                plastic_viscosity_pa_s: 20.0,
                ..base(Material::NonNewtonian)
            },
            ForceForm::Mls,
            true,
        );
    }
    #[test]
    fn trajectory_gradients_match_finite_differences_fluid() {
        // The weakly compressible fluid: pressure from the bulk modulus (E, nu), viscous
        // stress from the APIC matrix (plastic viscosity); F keeps only its volume.
        check_material(
            "fluid",
            PartParams {
                plastic_viscosity_pa_s: 2.0,
                ..base(Material::Fluid)
            },
            ForceForm::Mls,
            false,
        );
    }
    #[test]
    fn trajectory_gradients_match_finite_differences_newtonian() {
        // PhysFlow's drop: an elastic solid of low shear and high bulk modulus.
        check_material(
            "newtonian",
            PartParams {
                poisson_ratio: 0.45,
                ..base(Material::Newtonian)
            },
            ForceForm::Mls,
            false,
        );
    }
}

mod precision {
    //! The adjoint in f32 (the simulation's precision) against the f64 reference gradient,
    //! through the checkpointed driver.
    use super::Rng;
    use crate::adjoint::checkpoint::{value_and_grad, Checkpointing};
    use crate::adjoint::host::{HostSim, PhysParams};
    use crate::boundary::{BoundaryCondition, Surface};
    use crate::config::{Domain, ForceForm, SimConfig, SolverConfig, TimeConfig};
    use crate::material::{Material, PartParams};
    use crate::math::Real;
    use crate::reference::ReferenceBackend;
    use crate::scene::{ParticleSet, Shape};
    use crate::simulation::Simulation;

    fn grad<T: Real>(sim: &HostSim, part: &PartParams, w: &[Vec<[f64; 3]>]) -> [f64; 8] {
        let params = vec![PhysParams::<T>::of(part)];
        let v0 = vec![[T::zero(); 3]; sim.len()];
        let stepper =
            Simulation::with_host(ReferenceBackend::<T>::in_scalar(), sim.clone()).unwrap();
        let init = stepper.init(&params, &v0).unwrap();
        let (_, adj0, g) = value_and_grad(
            &stepper,
            &init,
            &params,
            60,
            20,
            Checkpointing::EveryN(7),
            stepper.zero_grad().unwrap(),
            |_, _| 0.0,
            |f, _, adj| {
                for (a, wp) in adj.x.iter_mut().zip(&w[f - 1]) {
                    for q in 0..3 {
                        a[q] += T::c(wp[q]);
                    }
                }
            },
        )
        .unwrap();
        let mut g = stepper.grad_to_host(&g, &params).unwrap();
        stepper.init_vjp(&adj0, &mut g).unwrap();
        let g = g[0];
        [
            g.youngs_modulus,
            g.poisson_ratio,
            g.yield_stress,
            g.plastic_viscosity,
            g.friction_angle_deg,
            g.density,
            g.hardening,
            g.softening,
        ]
        .map(|x| x.f64())
    }

    #[test]
    fn f32_adjoint_matches_the_f64_reference_within_1e_2() {
        let n = 16;
        let dx = 1.0 / n as f64;
        for (name, part) in [
            (
                "jelly",
                PartParams {
                    material: Material::Jelly,
                    youngs_modulus_pa: 3e4,
                    ..Default::default()
                },
            ),
            (
                "metal",
                PartParams {
                    material: Material::Metal,
                    youngs_modulus_pa: 3e4,
                    yield_stress_pa: 20.0,
                    hardening: true,
                    xi: 0.3,
                    ..Default::default()
                },
            ),
            (
                "sand",
                PartParams {
                    material: Material::Sand,
                    youngs_modulus_pa: 3e4,
                    friction_angle_deg: 35.0,
                    ..Default::default()
                },
            ),
            (
                "foam",
                PartParams {
                    material: Material::Foam,
                    youngs_modulus_pa: 3e4,
                    yield_stress_pa: 20.0,
                    plastic_viscosity_pa_s: 2.0,
                    ..Default::default()
                },
            ),
            (
                "snow",
                PartParams {
                    material: Material::Snow,
                    youngs_modulus_pa: 3e4,
                    snow_critical_compression: 2e-3,
                    snow_critical_stretch: 1e-3,
                    ..Default::default()
                },
            ),
            (
                "plasticine",
                PartParams {
                    material: Material::Plasticine,
                    youngs_modulus_pa: 3e4,
                    yield_stress_pa: 20.0,
                    softening: 5.0,
                    ..Default::default()
                },
            ),
        ] {
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
                    force: ForceForm::Mls,
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
            let sim = HostSim::new(&cfg, &scene).unwrap();
            let mut r = Rng(3);
            let w: Vec<Vec<[f64; 3]>> = (0..3)
                .map(|_| (0..sim.len()).map(|_| r.arr(1.0)).collect())
                .collect();
            let g64 = grad::<f64>(&sim, &cfg.parts[0], &w);
            let g32 = grad::<f32>(&sim, &cfg.parts[0], &w);
            for (i, pname) in [
                "E",
                "nu",
                "yield_stress",
                "plastic_viscosity",
                "friction_angle",
                "density",
                "hardening",
                "softening",
            ]
            .iter()
            .enumerate()
            {
                let scale = g64[i].abs().max(g32[i].abs());
                let rel = if scale == 0.0 {
                    0.0
                } else {
                    (g64[i] - g32[i]).abs() / scale
                };
                eprintln!(
                    "{name}: d/d{pname}: f64 {:+.5e} f32 {:+.5e} rel {rel:.1e}",
                    g64[i], g32[i]
                );
                // Sand cannot reach 1e-2: at rest it sits on the apex of the Drucker-Prager
                // cone, where the branch (elastic or projection to the apex) is decided by the
                // sign of a volumetric strain of the size of f32 round-off, so f32 and f64 runs
                // take different branches for many particles (3-5% gradient differences here).
                let tol = if name == "sand" { 1e-1 } else { 1e-2 };
                assert!(
                    rel < tol,
                    "{name}: d/d{pname}: f32 {} vs f64 {} (rel {rel})",
                    g32[i],
                    g64[i]
                );
            }
        }
    }
}

/// Largest absolute difference between two slices, relative to the largest entry of `a`.
fn rel_diff(a: &[f64], b: &[f64]) -> f64 {
    let scale = a.iter().fold(1e-300f64, |m, v| m.max(v.abs()));
    a.iter()
        .zip(b)
        .fold(0.0f64, |m, (x, y)| m.max((x - y).abs()))
        / scale
}

#[test]
fn separable_transfer_vjps_match_the_node_by_node_oracle() {
    use super::per_node_vjp::{g2p_vjp_per_node, scatter_vjp_per_node};
    for force in [FORCE_CLASSIC, FORCE_MLS] {
        let c = consts(force);
        let mut r = Rng(101 + force as u64);
        for _ in 0..20 {
            let x: [f64; 3] = std::array::from_fn(|a| 0.3 + 0.4 * r.next().abs() + 0.01 * a as f64);
            let bar: Vec<[f64; 4]> = (0..N * N * N).map(|_| r.arr(1.0)).collect();
            let st = stencil(x, 8.0);
            let (v, a, s): ([f64; 3], [f64; 9], [f64; 9]) = (r.arr(1.0), r.arr(3.0), r.arr(2.0));
            let m = 0.5 + r.next().abs();
            let (mut fast, mut slow) = (ScatterBar::default(), ScatterBar::default());
            scatter_vjp(&bar, N, &st, v, &a, m, &s, &c, &mut fast);
            scatter_vjp_per_node(&bar, N, &st, v, &a, m, &s, &c, &mut slow);
            let flat = |b: &ScatterBar<f64>| {
                let mut o = Vec::new();
                o.extend_from_slice(&b.x);
                o.extend_from_slice(&b.v);
                o.extend_from_slice(&b.a);
                o.push(b.mass);
                o.extend_from_slice(&b.s);
                o
            };
            let e = rel_diff(&flat(&slow), &flat(&fast));
            assert!(e < 1e-13, "scatter_vjp, force {force}: rel diff {e:e}");

            let nodes: Vec<[f64; 4]> = (0..N * N * N)
                .map(|_| [r.next(), r.next(), r.next(), 1.0 + r.next().abs()])
                .collect();
            let fe: [f64; 9] =
                std::array::from_fn(|e| if e % 4 == 0 { 1.0 } else { 0.0 } + 0.2 * r.next());
            let (xb, vb, cb, fb): ([f64; 3], [f64; 3], [f64; 9], [f64; 9]) =
                (r.arr(1.0), r.arr(1.0), r.arr(1.0), r.arr(1.0));
            let init: Vec<[f64; 4]> = (0..N * N * N).map(|_| r.arr(1.0)).collect();
            let (mut nb_fast, mut nb_slow) = (init.clone(), init);
            let f = g2p_vjp(&nodes, N, x, &fe, &c, xb, vb, &cb, &fb, &mut nb_fast, 0);
            let g = g2p_vjp_per_node(&nodes, N, x, &fe, &c, xb, vb, &cb, &fb, &mut nb_slow, 0);
            let e = rel_diff(
                &[g.x.as_slice(), &g.f_elastic].concat(),
                &[f.x.as_slice(), &f.f_elastic].concat(),
            );
            assert!(
                e < 1e-13,
                "g2p_vjp particle adjoints, force {force}: rel diff {e:e}"
            );
            let e = rel_diff(nb_slow.as_flattened(), nb_fast.as_flattened());
            assert!(
                e < 1e-13,
                "g2p_vjp node adjoints, force {force}: rel diff {e:e}"
            );
        }
    }
}
