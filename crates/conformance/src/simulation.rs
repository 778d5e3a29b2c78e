//! The simulation checks: the forward pass frame by frame and the gradient of a fixed position
//! loss through the checkpointed reverse sweep.

use crate::scenes::{initial_velocity, two_jellies, weights};
use crate::{rel, rel_l2, Checks, Failure, Tolerances};
use r4d_backend_cpu::{CpuBackend, Par};
use r4d_mpm::adjoint::checkpoint::{value_and_grad, Checkpointing};
use r4d_mpm::adjoint::host::{HostSim, PhysParams};
use r4d_mpm::{DynSimulation, ForceForm};
use r4d_optim::compute::{simulation_on, Compute, Precision};
use r4d_optim::FitError;
use std::cell::RefCell;
use std::sync::Arc;

/// What one simulation produced.
struct Run {
    x: Vec<Vec<[f64; 3]>>,
    f: Vec<Vec<[f64; 9]>>,
    grad: Vec<PhysParams<f64>>,
    adj_x0: Vec<[f64; 3]>,
    adj_f0: Vec<[f64; 9]>,
}

fn simulate(d: &dyn DynSimulation, params: &[r4d_mpm::PartParams]) -> Result<Run, FitError> {
    let err = |e| FitError::sim(d.backend_name(), e);
    let sim = d.host();
    let n = sim.len();
    let spf = sim.setup.substeps_per_frame;
    let frames = sim.setup.config.time.frames;
    let p = d.params(params);
    let v0: Vec<[f64; 3]> = initial_velocity(n)
        .iter()
        .map(|v| v.map(f64::from))
        .collect();
    let init = d.init(&p, &v0).map_err(err)?;
    let (x, f, failed) = (
        RefCell::new(Vec::new()),
        RefCell::new(Vec::new()),
        RefCell::new(None),
    );
    let keep = |e: r4d_mpm::Error| {
        failed.borrow_mut().get_or_insert(e);
    };
    let (_, adj0, grad) = value_and_grad(
        d,
        &init,
        &p,
        frames as u64 * spf as u64,
        spf,
        Checkpointing::PerFrame,
        d.zero_grad().map_err(err)?,
        |_, s| {
            match (d.positions_f64(s), d.deformation_gradients_f64(s)) {
                (Ok(a), Ok(b)) => {
                    x.borrow_mut().push(a);
                    f.borrow_mut().push(b);
                }
                (Err(e), _) | (_, Err(e)) => keep(e),
            }
            0.0
        },
        |frame, _, adj| {
            let w: Vec<[f64; 3]> = weights(frame, n).iter().map(|v| v.map(f64::from)).collect();
            if let Err(e) = d.add_to_x(adj, &w) {
                keep(e);
            }
        },
    )
    .map_err(err)?;
    if let Some(e) = failed.into_inner() {
        return Err(err(e));
    }
    Ok(Run {
        x: x.into_inner(),
        f: f.into_inner(),
        grad: d.gradient(&grad, &adj0, &p).map_err(err)?,
        adj_x0: d.positions_f64(&adj0).map_err(err)?,
        adj_f0: d.deformation_gradients_f64(&adj0).map_err(err)?,
    })
}

/// The forward and adjoint checks; returns the precision the backend simulated in.
pub(crate) fn run(
    compute: &dyn Compute,
    tol: &Tolerances,
    checks: &mut Checks,
) -> Result<String, Failure> {
    let (cfg, scene) = two_jellies(ForceForm::Mls);
    let sim =
        Arc::new(HostSim::new(&cfg, &scene).map_err(|e| checks.backend_error(FitError::Mpm(e)))?);
    let d = compute
        .simulation(Precision::F64, sim.clone())
        .map_err(|e| checks.backend_error(e))?;
    let precision = d.precision().to_string();
    let reference = match precision.as_str() {
        "f32" => simulation_on(CpuBackend::<f32>::with_par(Par::Rayon), sim),
        _ => simulation_on(CpuBackend::<f64>::with_par(Par::Rayon), sim),
    }
    .map_err(|e| checks.backend_error(e))?;
    let got = simulate(&*d, &cfg.parts).map_err(|e| checks.backend_error(e))?;
    let want = simulate(&*reference, &cfg.parts).map_err(|e| checks.backend_error(e))?;
    if got.x.len() != want.x.len() {
        return Err(checks.scene(format!(
            "{} frames simulated, the reference has {}",
            got.x.len(),
            want.x.len()
        )));
    }
    let moved = want.x[0]
        .iter()
        .zip(want.x.last().expect("frames"))
        .flat_map(|(a, b)| (0..3).map(move |k| (a[k] - b[k]).abs()))
        .fold(0.0, f64::max);
    let lim = cfg.domain.grid_lim;
    if moved < 0.02 * cfg.domain.dx() {
        return Err(checks.scene(format!("the scene moved only {moved:.2e} m")));
    }
    let max_diff = |a: &[Vec<f64>], b: &[Vec<f64>]| {
        a.iter()
            .zip(b)
            .flat_map(|(p, q)| p.iter().zip(q).map(|(u, v)| (u - v).abs()))
            .fold(0.0, f64::max)
    };
    let flat3 = |v: &[Vec<[f64; 3]>]| -> Vec<Vec<f64>> {
        v.iter().map(|f| f.as_flattened().to_vec()).collect()
    };
    let flat9 = |v: &[Vec<[f64; 9]>]| -> Vec<Vec<f64>> {
        v.iter().map(|f| f.as_flattened().to_vec()).collect()
    };
    let dx = max_diff(&flat3(&got.x), &flat3(&want.x)) / lim;
    checks.push("forward.x".into(), dx, tol.positions)?;
    let f_scale = flat9(&want.f)
        .iter()
        .flatten()
        .fold(0.0f64, |m, v| m.max(v.abs()));
    let df = max_diff(&flat9(&got.f), &flat9(&want.f)) / f_scale;
    checks.push("forward.F".into(), df, tol.deformation)?;
    for (s, (g, w)) in got.grad.iter().zip(&want.grad).enumerate() {
        for (name, a, b) in [
            ("E", g.youngs_modulus, w.youngs_modulus),
            ("nu", g.poisson_ratio, w.poisson_ratio),
            ("density", g.density, w.density),
        ] {
            if b == 0.0 {
                return Err(checks.scene(format!("the reference's d/d{name} of part {s} is 0")));
            }
            checks.push(format!("adjoint.{name}[{s}]"), rel(a, b), tol.gradient)?;
        }
    }
    let x0 = rel_l2(got.adj_x0.as_flattened(), want.adj_x0.as_flattened());
    checks.push("adjoint.x0".into(), x0, tol.initial_adjoint)?;
    let f0 = rel_l2(got.adj_f0.as_flattened(), want.adj_f0.as_flattened());
    checks.push("adjoint.F0".into(), f0, tol.initial_adjoint)?;
    Ok(precision)
}
