//! Frame-by-frame simulation as an interface ([`Simulator`]) and the fixed settings every
//! simulation derives from its config ([`SimSetup`]); the driver is [`crate::Simulation`].

use crate::config::SimConfig;
use crate::error::{Error, Result};
use crate::kernels::{GridBc, ParticleBc, StepConsts};
use crate::material::PartParams;
use crate::math::Real;

/// A simulator that advances a state frame by frame under given material parameters.
///
/// The state is separate from the simulator so that it can be stored and restored; the
/// parameters are passed at every frame so an optimiser can change them between frames or
/// runs. Implemented by [`crate::Simulation`] on every backend.
pub trait Simulator {
    /// Simulation state (backend-owned buffers).
    type State;
    /// Error type.
    type Error: std::error::Error + Send + Sync + 'static;
    /// A fresh state at rest (frame 0) for the given per-part parameters.
    fn init_state(&self, params: &[PartParams]) -> Result<Self::State, Self::Error>;
    /// Advances one frame.
    fn step_frame(
        &mut self,
        state: &mut Self::State,
        params: &[PartParams],
    ) -> Result<(), Self::Error>;
    /// Particle positions (m), in input order.
    fn positions(&self, state: &Self::State) -> Result<Vec<[f32; 3]>, Self::Error>;
    /// Deformation gradients `F[i][j] = dx_i / dX_j` (row-major), in input order.
    fn deformation_gradients(&self, state: &Self::State) -> Result<Vec<[f32; 9]>, Self::Error>;
}

/// Fixed settings of a simulation, derived from a [`SimConfig`].
#[derive(Clone, Debug)]
pub struct SimSetup {
    /// The validated config.
    pub config: SimConfig,
    /// Grid spacing (m).
    pub dx: f64,
    /// Nodes per axis.
    pub n: usize,
    /// Substeps per frame.
    pub substeps_per_frame: u32,
    /// Grid boundary conditions in order.
    pub grid_bcs: Vec<GridBc>,
    /// Particle boundary conditions in order.
    pub particle_bcs: Vec<ParticleBc>,
}

impl SimSetup {
    /// Derives the setup; the config must be valid.
    pub fn new(config: &SimConfig) -> SimSetup {
        let dt = config.time.substep_dt;
        SimSetup {
            dx: config.domain.dx(),
            n: config.domain.n_grid,
            substeps_per_frame: config.time.substeps(),
            grid_bcs: config.boundary.iter().filter_map(|b| b.grid_bc()).collect(),
            particle_bcs: config
                .boundary
                .iter()
                .filter_map(|b| b.particle_bc(dt))
                .collect(),
            config: config.clone(),
        }
    }

    /// Constants of substep `k` (global index), which starts at time `k dt`: every
    /// simulation (`r4d simulate`, the fits' forward and reverse passes) times substeps so.
    pub fn consts_at(&self, k: u64) -> StepConsts {
        self.step_consts(k as f64 * self.config.time.substep_dt, k)
    }

    /// Constants of the substep with global index `substep` starting at `time_s`.
    pub fn step_consts(&self, time_s: f64, substep: u64) -> StepConsts {
        let s = &self.config.solver;
        let dt = self.config.time.substep_dt;
        StepConsts {
            gravity: s.gravity.map(|g| g as f32),
            dt: dt as f32,
            dx: self.dx as f32,
            inv_dx: (1.0 / self.dx) as f32,
            n_grid: self.n as u32,
            substep: substep.min(u32::MAX as u64) as u32,
            time: time_s as f32,
            rpic_damping: s.rpic_damping as f32,
            grid_v_damping: s.grid_v_damping as f32,
            force_form: s.force_code(),
            n_grid_bcs: self.grid_bcs.len() as u32,
            n_particle_bcs: self.particle_bcs.len() as u32,
            out_of_domain: s.out_of_domain_code(),
            max_speed: (s.max_cfl * self.dx / dt) as f32,
        }
    }

    /// Refuses a substep that violates the CFL bound `dt <= max_cfl dx / c_p` of any part,
    /// or, for a `fluid`, the explicit viscous stress's bound
    /// `dt <= max_cfl VISCOUS_STABILITY rho dx^2 / viscosity`.
    pub fn check_cfl(&self, params: &[PartParams]) -> Result<()> {
        let dt = self.config.time.substep_dt;
        let cfl = self.config.solver.max_cfl;
        for (i, p) in params.iter().enumerate() {
            if let Some(bound) = p.viscous_dt_bound(self.dx, cfl) {
                if dt > bound {
                    return Err(Error::ViscousStability {
                        dt_s: dt,
                        bound_s: bound,
                        cfl,
                        factor: crate::VISCOUS_STABILITY,
                        dx_m: self.dx,
                        viscosity: p.plastic_viscosity_pa_s,
                        density: p.density_kg_m3,
                        part: i,
                        material: p.material.name().to_string(),
                    });
                }
            }
            let c = p.p_wave_speed();
            let bound = cfl * self.dx / c;
            if dt > bound {
                return Err(Error::CflViolation {
                    dt_s: dt,
                    bound_s: bound,
                    cfl,
                    dx_m: self.dx,
                    wave_speed: c,
                    part: i,
                    material: p.material.name().to_string(),
                });
            }
        }
        Ok(())
    }
}

/// `x` in the scalar type `S` (exact).
fn cast<S: Real>(x: f32) -> S {
    S::c(x as f64)
}

/// Host f32 arrays in the scalar type `S` (exact).
pub fn from_f32<S: Real, const N: usize>(v: &[[f32; N]]) -> Vec<[S; N]> {
    v.iter().map(|a| a.map(cast)).collect()
}

/// Arrays in scalar type `S` rounded to f32 (for files and the renderer).
pub fn to_f32<S: Real, const N: usize>(v: Vec<[S; N]>) -> Vec<[f32; N]> {
    v.into_iter().map(|a| a.map(|x| x.f64() as f32)).collect()
}
