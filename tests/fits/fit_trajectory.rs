//! Recovery of material parameters from trajectories with the adjoint gradients
//! (`resonance4d::fit_trajectory`; no finite differences or derivative-free search).

use crate::common;

use common::fixture;
use r4d_backend_cpu::CpuBackend;
use r4d_mpm::{ParticleSet, SimConfig, Simulation, Simulator};
use r4d_optim::ParamKind;
use resonance4d::compute::{self, Compute};
use resonance4d::fit_trajectory::{fit_trajectory, FitOptions};

/// Simulates `cfg` on the CPU backend (as `r4d simulate` does) and returns frames 1 ...
fn targets(cfg: &SimConfig, scene: &ParticleSet) -> Vec<Vec<[f32; 3]>> {
    let mut sim = Simulation::new(CpuBackend::default(), cfg, scene.clone(), "target").unwrap();
    let mut st = sim.init_state(&cfg.parts).unwrap();
    (0..cfg.time.frames)
        .map(|_| {
            sim.step_frame(&mut st, &cfg.parts).unwrap();
            sim.positions(&st).unwrap()
        })
        .collect()
}

#[test]
fn recovers_a_jelly_beams_youngs_modulus_from_10x_off() {
    let truth = SimConfig::load(&fixture("fit/beam.toml")).unwrap();
    let scene = ParticleSet::from_shapes(&truth.shapes, truth.domain.dx());
    let target = targets(&truth, &scene);
    let mut start = truth.clone();
    start.parts[0].youngs_modulus_pa = 2e6;
    let fitted = fit_trajectory(
        &*compute::cpu(),
        &start,
        &scene,
        &target,
        &FitOptions::default(),
        |it| {
            eprintln!(
                "iter {:2}: loss {:.3e} E {:.0}",
                it.iter, it.loss.total, it.parts[0].e
            )
        },
    )
    .unwrap();
    let e = fitted[0].youngs_modulus_pa;
    eprintln!(
        "recovered E = {e:.0} Pa (true 2e5): {:+.2}%",
        100.0 * (e / 2e5 - 1.0)
    );
    assert!((e / 2e5 - 1.0).abs() < 0.02, "E = {e}");
}

#[test]
fn recovers_both_parts_stiffness_to_density_ratios() {
    let truth = SimConfig::load(&fixture("fit/two_part_beam.toml")).unwrap();
    let scene = ParticleSet::from_shapes(&truth.shapes, truth.domain.dx());
    let target = targets(&truth, &scene);
    let mut start = truth.clone();
    // Start about 2x off in every ratio.
    start.parts[0].youngs_modulus_pa = 6e5;
    start.parts[0].density_kg_m3 = 1500.0;
    start.parts[1].youngs_modulus_pa = 2e4;
    start.parts[1].density_kg_m3 = 400.0;
    let opts = FitOptions {
        params: vec![ParamKind::YoungsModulus, ParamKind::Density],
        iters: 70,
        ..Default::default()
    };
    let fitted = fit_trajectory(&*compute::cpu(), &start, &scene, &target, &opts, |it| {
        eprintln!(
            "iter {:2}: loss {:.3e} E/rho {:.1} {:.1}",
            it.iter,
            it.loss.total,
            it.parts[0].e / it.parts[0].density,
            it.parts[1].e / it.parts[1].density
        )
    })
    .unwrap();
    for (i, truth_ratio) in [(0, 200.0), (1, 100.0)] {
        let r = fitted[i].youngs_modulus_pa / fitted[i].density_kg_m3;
        eprintln!(
            "part {i}: E/rho = {r:.2} (true {truth_ratio}): {:+.2}%",
            100.0 * (r / truth_ratio - 1.0)
        );
        assert!(
            (r / truth_ratio - 1.0).abs() < 0.05,
            "part {i}: E/rho = {r}"
        );
    }
}

#[test]
fn a_resumed_fit_continues_exactly_where_it_stopped() {
    use resonance4d::fit_trajectory::{fit_trajectory_resumable, FitState};
    let mut truth = SimConfig::load(&fixture("fit/beam.toml")).unwrap();
    truth.time.frames = 2;
    let scene = ParticleSet::from_shapes(&truth.shapes, truth.domain.dx());
    let target = targets(&truth, &scene);
    let mut start = truth.clone();
    start.parts[0].youngs_modulus_pa = 2e6;
    let opts = FitOptions {
        iters: 4,
        ..Default::default()
    };
    let mut at2: Option<FitState> = None;
    let full = fit_trajectory_resumable(
        &*compute::cpu(),
        &start,
        &scene,
        &target,
        &opts,
        None,
        |_| {},
        |ck| {
            if ck.iters_done == 2 {
                // What a run killed after its second iteration leaves on disk.
                let json = ck.to_json();
                at2 = Some(FitState::from_json(&json).unwrap());
            }
        },
    )
    .unwrap();
    // The state refuses another run: other targets, other options.
    let mut moved = target.clone();
    moved[0][0][1] += 1e-3;
    for (t, o) in [
        (&moved, opts.clone()),
        (
            &target,
            FitOptions {
                clip_norm: Some(0.5),
                ..opts.clone()
            },
        ),
    ] {
        let e = fit_trajectory_resumable(
            &*compute::cpu(),
            &start,
            &scene,
            t,
            &o,
            at2.clone(),
            |_| {},
            |_| {},
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("fingerprint"), "{e}");
    }
    let mut iters_run = Vec::new();
    let resumed = fit_trajectory_resumable(
        &*compute::cpu(),
        &start,
        &scene,
        &target,
        &opts,
        at2,
        |it| iters_run.push(it.iter),
        |_| {},
    )
    .unwrap();
    assert_eq!(iters_run, vec![2, 3]);
    assert_eq!(full, resumed);
    assert!(full.per_particle.is_none());
}

/// The fit is generic over the simulator's kernels: its first iteration on the f64 reference
/// kernels (one core) and on the parallel CPU backend (f64, colour-slab scatter order) gives
/// the same loss and gradient up to summation order.
#[test]
fn the_fit_runs_on_the_reference_kernels_too() {
    let truth = SimConfig::load(&fixture("fit/beam.toml")).unwrap();
    let scene = ParticleSet::from_shapes(&truth.shapes, truth.domain.dx());
    let target = targets(&truth, &scene);
    let mut start = truth.clone();
    start.parts[0].youngs_modulus_pa = 2e6;
    let opts = FitOptions {
        iters: 1,
        ..Default::default()
    };
    let first = |b: &dyn Compute| {
        let mut log = Vec::new();
        fit_trajectory(b, &start, &scene, &target, &opts, |it| {
            log.push((it.loss.total, it.grad_norm))
        })
        .unwrap();
        log[0]
    };
    let (lc, gc) = first(&*compute::cpu());
    let (lr, gr) = first(&*compute::reference());
    eprintln!("cpu: loss {lc:.12e} |grad| {gc:.12e}; reference: loss {lr:.12e} |grad| {gr:.12e}");
    assert!((lc - lr).abs() <= 1e-9 * lc.abs(), "loss {lc} vs {lr}");
    assert!((gc - gr).abs() <= 1e-6 * gc.abs(), "|grad| {gc} vs {gr}");
}
