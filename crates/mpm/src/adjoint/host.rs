//! The differentiable simulation problem on the host: a validated config, its particles and
//! their parameter slots ([`HostSim`]), the initial state ([`HostState`]) and the parameters that
//! receive gradients ([`PhysParams`]: every part's E, nu, yield stress, plastic viscosity,
//! friction angle and density, plus the initial positions and velocities).
//!
//! The substep and its reverse sweep are not here: they run on any backend through
//! [`crate::Simulation`] (the f64 reference backend is the gradient oracle). The
//! out-of-domain clamp is not differentiated (a particle outside the grid is skipped by the
//! transfers, never indexed out of bounds).

use crate::config::SimConfig;
use crate::error::Result;
use crate::material::PartConsts;
use crate::math::Real;
pub use crate::params::PhysParams;
use crate::scene::ParticleSet;
use crate::sim::SimSetup;

/// Simulation state on the host.
#[derive(Clone, Debug, PartialEq)]
pub struct HostState<T> {
    /// Positions.
    pub x: Vec<[T; 3]>,
    /// Velocities.
    pub v: Vec<[T; 3]>,
    /// APIC matrices.
    pub c: Vec<[T; 9]>,
    /// Deformation gradients (F_trial after G2P).
    pub f: Vec<[T; 9]>,
    /// Plastic state `[yield stress, J_p]`.
    pub plastic: Vec<[T; 2]>,
}

impl<T: Real> HostState<T> {
    /// All-zero state of `n` particles (used for adjoints).
    pub fn zeros(n: usize) -> Self {
        let z = T::zero();
        HostState {
            x: vec![[z; 3]; n],
            v: vec![[z; 3]; n],
            c: vec![[z; 9]; n],
            f: vec![[z; 9]; n],
            plastic: vec![[z; 2]; n],
        }
    }
}

/// The host simulator: a validated config and its particles.
#[derive(Clone, Debug)]
pub struct HostSim {
    /// Derived settings (grid, boundary conditions, time stepping).
    pub setup: SimSetup,
    /// Device constants of each part (material id and the non-differentiated constants).
    pub consts: Vec<PartConsts>,
    /// Initial positions (f32, as the particle boundary conditions select by them).
    pub x0: Vec<[f32; 3]>,
    /// Initial volumes.
    pub vol0: Vec<f64>,
    /// Part of each particle.
    pub part: Vec<u32>,
    /// Parameter slot of each particle: its part (the default) or its own index (per-particle
    /// parameters, see [`HostSim::per_particle`]). Parameter vectors and gradients are indexed
    /// by slot.
    pub slot: Vec<u32>,
}

impl HostSim {
    /// Builds the host simulator; the config must be valid. (A backend whose reverse stages do
    /// not cover a part's model refuses it in [`crate::Simulation::with_host`].)
    pub fn new(config: &SimConfig, scene: &ParticleSet) -> Result<Self> {
        let setup = SimSetup::new(config);
        scene.validate("host simulation", setup.dx, setup.n, config.parts.len())?;
        Ok(HostSim {
            consts: config.parts.iter().map(|p| p.consts()).collect(),
            x0: scene.x.clone(),
            vol0: scene.volume.iter().map(|&v| v as f64).collect(),
            part: scene.part.clone(),
            slot: scene.part.clone(),
            setup,
        })
    }

    /// Gives every particle its own parameter slot (the paper's per-particle ablation):
    /// parameter vectors then have one entry per particle.
    pub fn per_particle(mut self) -> Self {
        self.slot = (0..self.x0.len() as u32).collect();
        self
    }

    /// Number of parameter slots (parts, or particles after [`HostSim::per_particle`]).
    pub fn slots(&self) -> usize {
        let used = self.slot.iter().map(|&s| s as usize + 1).max().unwrap_or(0);
        // Per part: every part of the config is a slot, also one no particle belongs to (a
        // parts file whose last part is empty), so slot indices are part indices.
        if self.slot == self.part {
            used.max(self.consts.len())
        } else {
            used
        }
    }

    /// Number of particles.
    pub fn len(&self) -> usize {
        self.x0.len()
    }
    /// True when there are no particles.
    pub fn is_empty(&self) -> bool {
        self.x0.is_empty()
    }

    /// The state at rest with initial velocities `v0`.
    pub fn init<T: Real>(&self, params: &[PhysParams<T>], v0: &[[T; 3]]) -> HostState<T> {
        let n = self.len();
        let z = T::zero();
        let o = T::one();
        HostState {
            x: self.x0.iter().map(|p| p.map(|c| T::c(c as f64))).collect(),
            v: v0.to_vec(),
            c: vec![[z; 9]; n],
            f: vec![[o, z, z, z, o, z, z, z, o]; n],
            plastic: self
                .slot
                .iter()
                .map(|&p| [params[p as usize].yield_stress, o])
                .collect(),
        }
    }

    /// Constants of substep `k` (time `k dt`, as every simulation times substeps).
    pub fn consts_at(&self, k_sub: u64) -> crate::StepConsts {
        self.setup.consts_at(k_sub)
    }

    /// Adds the gradient of the initial state's dependence on the parameters (the initial
    /// plastic yield stress) to `grad`, given the adjoint of the initial state.
    pub fn init_vjp<T: Real>(&self, adj0: &HostState<T>, grad: &mut [PhysParams<T>]) {
        self.init_vjp_plastic(&adj0.plastic, grad);
    }

    /// [`HostSim::init_vjp`] from the adjoint of the initial plastic state alone.
    pub fn init_vjp_plastic<T: Real>(&self, plastic_adj: &[[T; 2]], grad: &mut [PhysParams<T>]) {
        for (pl, &slot) in plastic_adj.iter().zip(&self.slot) {
            grad[slot as usize].yield_stress += pl[0];
        }
    }

    /// The part of each parameter slot (the slot tables' `slot_part`).
    pub fn slot_parts(&self) -> Vec<u32> {
        let mut slot_part = vec![0u32; self.slots().max(1)];
        for (&s, &p) in self.slot.iter().zip(&self.part) {
            slot_part[s as usize] = p;
        }
        slot_part
    }
}

/// Adds one particle's parameter gradient to a slot's.
pub fn add_grad<T: Real>(acc: &mut PhysParams<T>, g: &PhysParams<T>) {
    acc.youngs_modulus += g.youngs_modulus;
    acc.poisson_ratio += g.poisson_ratio;
    acc.yield_stress += g.yield_stress;
    acc.plastic_viscosity += g.plastic_viscosity;
    acc.friction_angle_deg += g.friction_angle_deg;
    acc.density += g.density;
}

/// A shared copy of `sim` (what [`crate::Simulation::with_host`] takes: a simulation keeps
/// its problem).
impl From<&HostSim> for std::sync::Arc<HostSim> {
    fn from(sim: &HostSim) -> Self {
        std::sync::Arc::new(sim.clone())
    }
}
