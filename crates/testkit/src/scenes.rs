//! Scene builders shared by the physics tests.

use r4d_backend_cpu::CpuBackend;
use r4d_mpm::{
    BoundaryCondition, Domain, ForceForm, PartParams, ParticleSet, Shape, SimConfig, Simulation,
    SolverConfig, TimeConfig,
};

/// An elastic jelly part: E as given, nu 0.3, density 1000 kg/m^3.
pub fn jelly(e: f64) -> PartParams {
    PartParams {
        material: r4d_mpm::Material::Jelly,
        youngs_modulus_pa: e,
        poisson_ratio: 0.3,
        density_kg_m3: 1000.0,
        ..Default::default()
    }
}

/// A config with one part, no shapes and no boundary conditions.
pub fn config(n_grid: usize, dt: f64, substeps: u32, part: PartParams) -> SimConfig {
    SimConfig {
        domain: Domain {
            grid_lim: 1.0,
            n_grid,
        },
        time: TimeConfig {
            substep_dt: dt,
            frame_dt: None,
            substeps_per_frame: Some(substeps),
            frames: 1,
        },
        solver: SolverConfig {
            force: ForceForm::Mls,
            ..Default::default()
        },
        parts: vec![part],
        shapes: Vec::new(),
        particles: None,
        boundary: Vec::<BoundaryCondition>::new(),
    }
}

/// Samples a box of particles (2 per cell per axis).
pub fn boxed(cfg: &SimConfig, min: [f64; 3], max: [f64; 3]) -> ParticleSet {
    ParticleSet::from_shapes(
        &[Shape::Box {
            min,
            max,
            part: 0,
            per_cell: 2,
        }],
        cfg.domain.dx(),
    )
}

/// A simulator on the CPU backend.
pub fn sim(cfg: &SimConfig, scene: ParticleSet) -> Simulation<CpuBackend> {
    Simulation::new(CpuBackend::default(), cfg, scene, "test").unwrap()
}

/// Bounding box (lo, hi) and centroid of points.
pub fn bbox(x: &[[f32; 3]]) -> ([f64; 3], [f64; 3], [f64; 3]) {
    let mut lo = [f64::MAX; 3];
    let mut hi = [f64::MIN; 3];
    let mut c = [0.0; 3];
    for p in x {
        for a in 0..3 {
            let v = p[a] as f64;
            lo[a] = lo[a].min(v);
            hi[a] = hi[a].max(v);
            c[a] += v / x.len() as f64;
        }
    }
    (lo, hi, c)
}
