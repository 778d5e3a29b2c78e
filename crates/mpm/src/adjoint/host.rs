//! A host (CPU, single-threaded) simulator generic over the scalar type, with the exact reverse
//! sweep of its substep: the f64 reference every gradient is checked against.
//!
//! It runs the same per-particle and per-node functions as the backends ([`crate::transfer`],
//! [`crate::constitutive`]) on plain `Vec`s and a full grid, and differentiates them with the
//! VJPs of [`super::transfer_vjp`] and [`super::constitutive_vjp`]. Gradients flow to every
//! part's physical parameters ([`PhysParams`]: E, nu, yield stress, plastic viscosity,
//! friction angle, density) and to the initial state (positions, velocities).
//!
//! Differences from [`crate::MpmSim`]: the time of substep `k` is `k dt` (MpmSim accumulates
//! `t += dt` like PhysGaussian; the two differ by round-off, which matters only when a
//! boundary-condition window ends exactly on a substep), the out-of-domain clamp is not
//! differentiated (a particle outside the grid is skipped by the transfers, never indexed out
//! of bounds), and the fluid model has no adjoint yet.

use super::constitutive_vjp::stress_update_vjp;
use super::transfer_vjp::{
    damped_affine_vjp, g2p_vjp, grid_node_update_vjp, particle_bcs_vjp, scatter_vjp, ScatterBar,
};
use crate::config::SimConfig;
use crate::constitutive::{stress_update_with, MaterialParams};
use crate::error::{Error, Result};
use crate::material::{PartConsts, PartParams};
use crate::math::{Mat3, Real};
use crate::scene::ParticleSet;
use crate::sim::SimSetup;
use crate::transfer::{
    damped_affine, g2p_finish, gather, grid_node_update, in_domain, k, particle_bcs, scatter,
    stencil, stress_scale,
};

/// The physical parameters of a part that receive gradients, in SI units.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PhysParams<T> {
    /// Young's modulus E (Pa).
    pub youngs_modulus: T,
    /// Poisson's ratio nu.
    pub poisson_ratio: T,
    /// Initial yield stress (Pa).
    pub yield_stress: T,
    /// Plastic viscosity (Pa s).
    pub plastic_viscosity: T,
    /// Friction angle (degrees).
    pub friction_angle_deg: T,
    /// Density (kg/m^3).
    pub density: T,
}

/// PhysGaussian's degrees-to-radians factor (its truncated pi), kept for identical yields.
#[expect(clippy::approx_constant, reason = "PhysGaussian's truncated pi")]
const DEG: f64 = 3.14159265 / 180.0;

impl<T: Real> PhysParams<T> {
    /// The values of a part.
    pub fn of(p: &PartParams) -> Self {
        PhysParams {
            youngs_modulus: T::c(p.youngs_modulus_pa),
            poisson_ratio: T::c(p.poisson_ratio),
            yield_stress: T::c(p.yield_stress_pa),
            plastic_viscosity: T::c(p.plastic_viscosity_pa_s),
            friction_angle_deg: T::c(p.friction_angle_deg),
            density: T::c(p.density_kg_m3),
        }
    }

    /// The constants the constitutive model reads: mu, lambda, plastic viscosity, alpha.
    pub fn material(&self) -> MaterialParams<T> {
        let (e, nu) = (self.youngs_modulus, self.poisson_ratio);
        let one = T::one();
        let two = T::c(2.0);
        let phi = self.friction_angle_deg * T::c(DEG);
        let sp = phi.sin();
        MaterialParams {
            mu: e / (two * (one + nu)),
            lambda: e * nu / ((one + nu) * (one - two * nu)),
            eta: self.plastic_viscosity,
            alpha: T::c((2.0f64 / 3.0).sqrt()) * two * sp / (T::c(3.0) - sp),
        }
    }

    /// Chain rule of [`PhysParams::material`]: adds the gradient of the physical parameters
    /// given that of the material constants.
    pub fn add_material_vjp(&self, bar: &MaterialParams<T>, out: &mut PhysParams<T>) {
        let (e, nu) = (self.youngs_modulus, self.poisson_ratio);
        let one = T::one();
        let two = T::c(2.0);
        let d = (one + nu) * (one - two * nu);
        out.youngs_modulus += bar.mu / (two * (one + nu)) + bar.lambda * nu / d;
        out.poisson_ratio += -bar.mu * e / (two * (one + nu) * (one + nu))
            + bar.lambda * e * (one + two * nu * nu) / (d * d);
        out.plastic_viscosity += bar.eta;
        let phi = self.friction_angle_deg * T::c(DEG);
        let (sp, cp) = (phi.sin(), phi.cos());
        let da = T::c((2.0f64 / 3.0).sqrt()) * two * T::c(3.0) * cp
            / ((T::c(3.0) - sp) * (T::c(3.0) - sp));
        out.friction_angle_deg += bar.alpha * da * T::c(DEG);
    }
}

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
    /// Builds the host simulator; the config must be valid. Fluid parts are refused.
    pub fn new(config: &SimConfig, scene: &ParticleSet) -> Result<Self> {
        let setup = SimSetup::new(config);
        scene.validate("host simulation", setup.dx, setup.n, config.parts.len())?;
        if let Some(i) = config
            .parts
            .iter()
            .position(|p| p.material == crate::Material::Fluid)
        {
            return Err(Error::config(
                format!("parts[{i}]"),
                "the fluid model has no adjoint yet",
            ));
        }
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
        self.slot.iter().map(|&s| s as usize + 1).max().unwrap_or(0)
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

    /// Particle masses `density x V0` for the given parameters.
    pub fn masses<T: Real>(&self, params: &[PhysParams<T>]) -> Vec<T> {
        self.vol0
            .iter()
            .zip(&self.slot)
            .map(|(&v, &p)| params[p as usize].density * T::c(v))
            .collect()
    }

    /// Constants of substep `k` (time `k dt`).
    pub fn consts_at(&self, k_sub: u64) -> crate::StepConsts {
        self.setup
            .step_consts(k_sub as f64 * self.setup.config.time.substep_dt, k_sub)
    }

    /// The forward pass of substep `k_sub`, returning the intermediates the reverse sweep
    /// needs: masses, velocities after the particle conditions, stress terms, the scattered
    /// grid and the updated grid.
    fn forward<T: Real>(
        &self,
        s: &mut HostState<T>,
        params: &[PhysParams<T>],
        k_sub: u64,
    ) -> SubstepRecord<T> {
        let c = self.consts_at(k_sub);
        let n = self.setup.n;
        let mats: Vec<MaterialParams<T>> = params.iter().map(|p| p.material()).collect();
        let mass = self.masses(params);
        let np = self.len();
        let mut v1 = s.v.clone();
        let mut stress = vec![[T::zero(); 9]; np];
        let x_start = s.x.clone();
        let f_trial = s.f.clone();
        let plastic_in = s.plastic.clone();
        for p in 0..np {
            stress[p] = self.particle_stage(
                p,
                &c,
                &mats,
                mass[p],
                &mut v1[p],
                &mut s.f[p],
                &mut s.plastic[p],
            );
        }
        let mut grid_in = vec![[T::zero(); 4]; n * n * n];
        let inv_dx = k::<T>(c.inv_dx);
        for p in 0..np {
            // A particle that left the grid (or went NaN) is skipped, never indexed out of
            // bounds; the run's loss then shows it.
            if !in_domain(s.x[p], inv_dx, n) {
                continue;
            }
            let st = stencil(s.x[p], inv_dx);
            let a = damped_affine(&s.c[p], c.rpic_damping);
            scatter(&mut grid_in, 0, n, &st, v1[p], &a, mass[p], &stress[p], &c);
        }
        let mut grid = grid_in.clone();
        for i in 0..n {
            for j in 0..n {
                for kk in 0..n {
                    let node = &mut grid[(i * n + j) * n + kk];
                    // Nodes without mass stay at rest and are never gathered with weight.
                    if node[3] > T::zero() {
                        grid_node_update([i, j, kk], node, &self.setup.grid_bcs, &c);
                    }
                }
            }
        }
        let f_elastic = s.f.clone();
        for p in 0..np {
            if !in_domain(s.x[p], inv_dx, n) {
                continue;
            }
            let st = stencil(s.x[p], inv_dx);
            let g = gather(&grid, n, &st, &c);
            let _ = g2p_finish(&g, &mut s.x[p], &mut s.v[p], &mut s.c[p], &mut s.f[p], &c);
        }
        SubstepRecord {
            mass,
            v1,
            stress,
            x_start,
            f_trial,
            f_elastic,
            plastic_in,
            grid_in,
            grid,
            mats,
        }
    }

    /// The particle stage of a substep for particle `p`: boundary conditions on its velocity
    /// `v` (becoming the scatter's velocity), return mapping of `f` and `plastic` in place;
    /// returns the scatter's stress term.
    #[allow(clippy::too_many_arguments)]
    pub fn particle_stage<T: Real>(
        &self,
        p: usize,
        c: &crate::StepConsts,
        mats: &[MaterialParams<T>],
        mass: T,
        v: &mut [T; 3],
        f: &mut [T; 9],
        plastic: &mut [T; 2],
    ) -> [T; 9] {
        particle_bcs(self.x0[p], v, mass, &self.setup.particle_bcs, c);
        let (part, slot) = (self.part[p] as usize, self.slot[p] as usize);
        let (fe, tau) = stress_update_with(
            Mat3::from_array(*f),
            &self.consts[part],
            plastic,
            mats[slot],
            k(c.dt),
        );
        *f = fe.to_array();
        tau.sym()
            .scaled(stress_scale(T::c(self.vol0[p]), c))
            .to_array()
    }

    /// Reverse of the P2G, stress and particle-condition stages for particle `p`: from the
    /// scattered grid's adjoint, the adjoints of F_elastic and of the plastic state (after the
    /// substep), and the position adjoint gathered by G2P, returns the particle's adjoint state
    /// before the substep and its parameter gradient (for its slot).
    #[allow(clippy::too_many_arguments)]
    pub fn particle_stage_vjp<T: Real>(
        &self,
        p: usize,
        c: &crate::StepConsts,
        rec: &SubstepRecord<T>,
        c_before: &[T; 9],
        grid_in_bar: &[[T; 4]],
        fe_bar: &[T; 9],
        x_bar_g2p: &[T; 3],
        plastic_bar: &[T; 2],
        params: &[PhysParams<T>],
    ) -> (ParticleBar<T>, PhysParams<T>) {
        let z = T::zero();
        let inv_dx = k::<T>(c.inv_dx);
        let mut g = PhysParams::default();
        if !in_domain(rec.x_start[p], inv_dx, self.setup.n) {
            let bar = ParticleBar {
                x: [z; 3],
                v: [z; 3],
                c: [z; 9],
                f: [z; 9],
                plastic: [z; 2],
            };
            return (bar, g);
        }
        let (part, slot) = (self.part[p] as usize, self.slot[p] as usize);
        let st = stencil(rec.x_start[p], inv_dx);
        let a = damped_affine(c_before, c.rpic_damping);
        let mut sb = ScatterBar::default();
        scatter_vjp(
            grid_in_bar,
            self.setup.n,
            &st,
            rec.v1[p],
            &a,
            rec.mass[p],
            &rec.stress[p],
            c,
            &mut sb,
        );
        let tau_bar = Mat3::from_array(sb.s).scaled(stress_scale(T::c(self.vol0[p]), c));
        let cb = stress_update_vjp(
            Mat3::from_array(rec.f_trial[p]),
            &self.consts[part],
            rec.plastic_in[p],
            rec.mats[slot],
            k(c.dt),
            Mat3::from_array(*fe_bar),
            tau_bar,
            *plastic_bar,
        );
        params[slot].add_material_vjp(&cb.params, &mut g);
        let mut v_bar = sb.v;
        let mut m_bar = sb.mass;
        particle_bcs_vjp(
            self.x0[p],
            rec.mass[p],
            &self.setup.particle_bcs,
            c,
            &mut v_bar,
            &mut m_bar,
        );
        g.density += m_bar * T::c(self.vol0[p]);
        let bar = ParticleBar {
            x: std::array::from_fn(|q| x_bar_g2p[q] + sb.x[q]),
            v: v_bar,
            c: damped_affine_vjp(&sb.a, c.rpic_damping),
            f: cb.f_trial.to_array(),
            plastic: cb.state,
        };
        (bar, g)
    }

    /// Advances one substep (`k_sub` is its global index).
    pub fn substep<T: Real>(&self, s: &mut HostState<T>, params: &[PhysParams<T>], k_sub: u64) {
        let _ = self.forward(s, params, k_sub);
    }

    /// Reverse sweep of substep `k_sub`: `before` is the state at its start, `adj` holds the
    /// adjoint of the state after it on entry and before it on return; parameter gradients are
    /// added to `grad`.
    pub fn substep_vjp<T: Real>(
        &self,
        before: &HostState<T>,
        params: &[PhysParams<T>],
        k_sub: u64,
        adj: &mut HostState<T>,
        grad: &mut [PhysParams<T>],
    ) {
        let mut s = before.clone();
        let it = self.forward(&mut s, params, k_sub);
        let c = self.consts_at(k_sub);
        let n = self.setup.n;
        let np = self.len();
        let inv_dx = k::<T>(c.inv_dx);
        // G2P.
        let mut grid_bar = vec![[T::zero(); 4]; n * n * n];
        let mut x_bar = vec![[T::zero(); 3]; np];
        let mut fe_bar = vec![[T::zero(); 9]; np];
        for p in 0..np {
            if !in_domain(it.x_start[p], inv_dx, n) {
                continue;
            }
            let g = g2p_vjp(
                &it.grid,
                n,
                it.x_start[p],
                &it.f_elastic[p],
                &c,
                adj.x[p],
                adj.v[p],
                &adj.c[p],
                &adj.f[p],
                &mut grid_bar,
                0,
            );
            x_bar[p] = g.x;
            fe_bar[p] = g.f_elastic;
        }
        // Grid update.
        let mut grid_in_bar = vec![[T::zero(); 4]; n * n * n];
        for i in 0..n {
            for j in 0..n {
                for kk in 0..n {
                    let idx = (i * n + j) * n + kk;
                    let vb = [grid_bar[idx][0], grid_bar[idx][1], grid_bar[idx][2]];
                    if vb.iter().any(|x| *x != T::zero()) {
                        grid_in_bar[idx] = grid_node_update_vjp(
                            [i, j, kk],
                            it.grid_in[idx],
                            &self.setup.grid_bcs,
                            &c,
                            vb,
                        );
                    }
                }
            }
        }
        // P2G, stress, particle conditions.
        let mut out = HostState::zeros(np);
        for p in 0..np {
            let (bar, g) = self.particle_stage_vjp(
                p,
                &c,
                &it,
                &before.c[p],
                &grid_in_bar,
                &fe_bar[p],
                &x_bar[p],
                &adj.plastic[p],
                params,
            );
            add_grad(&mut grad[self.slot[p] as usize], &g);
            out.x[p] = bar.x;
            out.v[p] = bar.v;
            out.c[p] = bar.c;
            out.f[p] = bar.f;
            out.plastic[p] = bar.plastic;
        }
        *adj = out;
    }

    /// Adds the gradient of the initial state's dependence on the parameters (the initial
    /// plastic yield stress) to `grad`, given the adjoint of the initial state.
    pub fn init_vjp<T: Real>(&self, adj0: &HostState<T>, grad: &mut [PhysParams<T>]) {
        for (p, &slot) in self.slot.iter().enumerate() {
            grad[slot as usize].yield_stress += adj0.plastic[p][0];
        }
    }
}

/// What a substep's reverse sweep needs from its forward pass (per particle unless noted).
pub struct SubstepRecord<T> {
    /// Masses.
    pub mass: Vec<T>,
    /// Velocities after the particle boundary conditions.
    pub v1: Vec<[T; 3]>,
    /// Stress terms of the scatter.
    pub stress: Vec<[T; 9]>,
    /// Positions at the start of the substep.
    pub x_start: Vec<[T; 3]>,
    /// Trial deformation gradients (before the return mapping).
    pub f_trial: Vec<[T; 9]>,
    /// Elastic deformation gradients (after it).
    pub f_elastic: Vec<[T; 9]>,
    /// Plastic state before the substep.
    pub plastic_in: Vec<[T; 2]>,
    /// Scattered grid (momentum, mass).
    pub grid_in: Vec<[T; 4]>,
    /// Updated grid (velocity, mass).
    pub grid: Vec<[T; 4]>,
    /// Material constants per parameter slot.
    pub mats: Vec<MaterialParams<T>>,
}

/// One particle's adjoint state.
#[derive(Clone, Copy, Debug)]
pub struct ParticleBar<T> {
    /// Position adjoint.
    pub x: [T; 3],
    /// Velocity adjoint.
    pub v: [T; 3],
    /// APIC matrix adjoint.
    pub c: [T; 9],
    /// Deformation gradient adjoint.
    pub f: [T; 9],
    /// Plastic state adjoint.
    pub plastic: [T; 2],
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

/// [`HostSim`] as a [`Differentiable`](super::checkpoint::Differentiable) stepper in scalar
/// type `T`.
pub struct HostStepper<'a, T> {
    /// The simulator.
    pub sim: &'a HostSim,
    _t: std::marker::PhantomData<T>,
}

impl<'a, T> HostStepper<'a, T> {
    /// Wraps a host simulator.
    pub fn new(sim: &'a HostSim) -> Self {
        HostStepper {
            sim,
            _t: std::marker::PhantomData,
        }
    }
}

impl<T: Real> super::checkpoint::Differentiable for HostStepper<'_, T> {
    type State = HostState<T>;
    type Params = Vec<PhysParams<T>>;
    type Grad = Vec<PhysParams<T>>;
    fn step(&self, s: &mut HostState<T>, p: &Vec<PhysParams<T>>, k: u64) {
        self.sim.substep(s, p, k);
    }
    fn step_vjp(
        &self,
        before: &HostState<T>,
        p: &Vec<PhysParams<T>>,
        k: u64,
        adj: &mut HostState<T>,
        grad: &mut Vec<PhysParams<T>>,
    ) {
        self.sim.substep_vjp(before, p, k, adj, grad);
    }
    fn zero_adjoint(&self, s: &HostState<T>) -> HostState<T> {
        HostState::zeros(s.x.len())
    }
}
