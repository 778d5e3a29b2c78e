//! A backend of your own in one file: a `Compute` (what every fit runs on: a simulation and a
//! renderer) that delegates to the CPU backend and counts the calls, passes the conformance
//! suite and runs a video fit that gives the CPU's result bit for bit:
//! `cargo run --release -p resonance4d --example counting_backend`

use resonance4d::prelude::*;
use std::sync::atomic::{AtomicUsize, Ordering::Relaxed};
use std::sync::Arc;

#[derive(Debug, Default)]
struct Counting {
    simulations: AtomicUsize,
    renderer_uses: AtomicUsize,
}

impl Compute for Counting {
    fn name(&self) -> &str {
        "counting"
    }
    fn simulation(
        &self,
        p: Precision,
        sim: Arc<HostSim>,
    ) -> Result<Box<dyn DynSimulation>, FitError> {
        self.simulations.fetch_add(1, Relaxed);
        resonance4d::compute::cpu().simulation(p, sim)
    }
    fn with_renderer(
        &self,
        f: &mut dyn FnMut(&mut dyn Renderer) -> Result<(), FitError>,
    ) -> Result<(), FitError> {
        self.renderer_uses.fetch_add(1, Relaxed);
        f(&mut SplatRenderer::new(CpuBackend::default()))
    }
}

/// Runs the example.
pub fn main() -> Result<(), Box<dyn std::error::Error>> {
    let counting = Arc::new(Counting::default());
    print!(
        "{}",
        resonance4d::conformance::run(&*counting, &Default::default())?
    );
    let text = include_str!("jelly_on_floor.toml");
    let mut config = SimConfig::parse(text, "jelly_on_floor.toml".as_ref())?;
    let truth = config.parts.clone();
    config.parts[0].youngs_modulus_pa *= 2.0;
    let (eye, target) = ([0.5, -0.3, 0.6], [0.5, 0.5, 0.35]);
    let camera = Camera::look_at(48, 36, 40.0, eye, target, [0.0, 0.0, 1.0]);
    let mut problem = ProblemBuilder::new(config)
        .camera(camera)
        .rendered_from(&truth)?;
    let mut fit = FitConfig {
        // As written here: the automatic strategy would decide the stages and their budgets.
        strategy: Strategy::Fixed,
        iters: 4,
        free: Some(vec!["E".into()]),
        ..Default::default()
    };
    fit.init.enabled = false;

    problem.compute = counting.clone();
    let mine = run_fit(&problem, &fit, None, &mut NoHooks)?;
    problem.compute = resonance4d::compute::cpu();
    let cpu = run_fit(&problem, &fit, None, &mut NoHooks)?;
    println!(
        "{} simulations, {} renderer uses; E {:.1} Pa on it, {:.1} Pa on the CPU",
        counting.simulations.load(Relaxed),
        counting.renderer_uses.load(Relaxed),
        mine.parts[0].youngs_modulus_pa,
        cpu.parts[0].youngs_modulus_pa
    );
    assert!(counting.simulations.load(Relaxed) > 0 && counting.renderer_uses.load(Relaxed) > 0);
    assert_eq!(
        mine.parts, cpu.parts,
        "the delegating backend computes the CPU's numbers"
    );
    Ok(())
}
