//! The simulator: the substep loop, frames, parameter upload and error checks, written once and
//! generic over the backend ([`MpmKernels`]).

use crate::config::SimConfig;
use crate::error::{Error, Result};
use crate::kernels::{
    blocks_per_axis, Grid, GridBc, Health, MpmKernels, ParticleBc, Particles, StepConsts,
    HEALTH_OUT_OF_DOMAIN, HEALTH_SPEED,
};
use crate::material::{PartConsts, PartParams};
use crate::math::Real;
use crate::params::{phys_params, SlotTables, MAT_CONSTS};
use crate::scene::ParticleSet;
use crate::substep::{self, SubstepTables};

/// A simulator that advances a state frame by frame under given material parameters.
///
/// The state is separate from the simulator so that it can be stored, restored and (next
/// issue) differentiated; the parameters are passed at every frame so an optimiser can change
/// them between frames or runs.
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

/// State of an MPM simulation on backend `B`.
pub struct SimState<B: MpmKernels> {
    /// Particle buffers.
    pub particles: Particles<B>,
    /// Time at the end of the last substep (s): `substep x dt`.
    pub time_s: f64,
    /// Substeps done.
    pub substep: u64,
    /// Frames done (0 = initial state).
    pub frame: usize,
    /// The parameters the particle buffers were last prepared for.
    params: Vec<PartParams>,
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

/// The MPM simulator on backend `B`.
pub struct MpmSim<B: MpmKernels> {
    backend: B,
    setup: SimSetup,
    scene: ParticleSet,
    grid: Grid<B>,
    grid_bcs: B::Buf<GridBc>,
    particle_bcs: B::Buf<ParticleBc>,
    parts: B::Buf<PartConsts>,
    mats: B::Buf<[B::Scalar; MAT_CONSTS]>,
    part_consts: Vec<PartConsts>,
    slot_part: Vec<u32>,
    uploaded: Vec<PartParams>,
}

fn be<E: std::error::Error + Send + Sync + 'static>(e: E) -> Error {
    Error::backend(e)
}

impl<B: MpmKernels> MpmSim<B> {
    /// Builds a simulator for a validated config and its particles; checks the particles and
    /// the CFL bound of every part.
    pub fn new(backend: B, config: &SimConfig, scene: ParticleSet, source: &str) -> Result<Self> {
        let setup = SimSetup::new(config);
        scene.validate(source, setup.dx, setup.n, config.parts.len())?;
        for (i, p) in config.parts.iter().enumerate() {
            p.validate(&format!("parts[{i}]"))?;
        }
        setup.check_cfl(&config.parts)?;
        let n = setup.n;
        // The grid and the particles' memory, checked before the grid is allocated.
        crate::budget::check_memory(
            source,
            crate::budget::simulation_bytes(n, scene.len() as u64),
            crate::budget::available_memory(),
        )?;
        let nb = blocks_per_axis(n);
        let grid = Grid {
            n,
            nodes: backend.zeros(n * n * n).map_err(be)?,
            active: backend.zeros(nb * nb * nb).map_err(be)?,
            scratch: backend.zeros(0).map_err(be)?,
            health: backend.zeros(1).map_err(be)?,
        };
        // Buffers hold at least one element so every backend can bind them.
        let mut gb = setup.grid_bcs.clone();
        gb.push(GridBc::default());
        let mut pb = setup.particle_bcs.clone();
        pb.push(ParticleBc::default());
        let part_consts: Vec<PartConsts> = config.parts.iter().map(|p| p.consts()).collect();
        let slot_part: Vec<u32> = (0..config.parts.len() as u32).collect();
        let tables = SlotTables::new(
            &phys_params(&config.parts),
            &part_consts,
            &slot_part,
            &scene.part,
            &scene.volume,
        );
        Ok(MpmSim {
            grid_bcs: backend.upload(&gb).map_err(be)?,
            particle_bcs: backend.upload(&pb).map_err(be)?,
            parts: backend.upload(&tables.parts).map_err(be)?,
            mats: backend.upload(&tables.mats).map_err(be)?,
            part_consts,
            slot_part,
            uploaded: config.parts.clone(),
            backend,
            setup,
            scene,
            grid,
        })
    }

    /// The backend.
    pub fn backend(&self) -> &B {
        &self.backend
    }
    /// The derived setup.
    pub fn setup(&self) -> &SimSetup {
        &self.setup
    }
    /// The grid as the last substep left it (node velocities and masses).
    pub fn grid(&self) -> &Grid<B> {
        &self.grid
    }
    /// The initial particles.
    pub fn scene(&self) -> &ParticleSet {
        &self.scene
    }
    /// The config's part parameters.
    pub fn config_params(&self) -> &[PartParams] {
        &self.setup.config.parts
    }

    /// The kernels' tables for `params` (the one parameter mapping, [`SlotTables`]).
    fn tables(&self, params: &[PartParams]) -> SlotTables<B::Scalar> {
        SlotTables::new(
            &phys_params(params),
            &self.part_consts,
            &self.slot_part,
            &self.scene.part,
            &self.scene.volume,
        )
    }

    fn check_params(&self, params: &[PartParams]) -> Result<()> {
        if params.len() != self.setup.config.parts.len() {
            return Err(Error::config(
                "parameters",
                format!(
                    "{} part parameter sets given, the scene has {} parts",
                    params.len(),
                    self.setup.config.parts.len()
                ),
            ));
        }
        for (i, p) in params.iter().enumerate() {
            p.validate(&format!("parts[{i}]"))?;
        }
        self.setup.check_cfl(params)
    }

    fn upload_params(&mut self, params: &[PartParams]) -> Result<()> {
        if params != self.uploaded.as_slice() {
            let t = self.tables(params);
            self.backend.write(&mut self.parts, &t.parts).map_err(be)?;
            self.backend.write(&mut self.mats, &t.mats).map_err(be)?;
            self.uploaded = params.to_vec();
        }
        Ok(())
    }

    /// A host copy of the state (for [`crate::Snapshot::write`]; the caller sets its
    /// fingerprint).
    pub fn snapshot(&self, state: &SimState<B>) -> Result<crate::Snapshot> {
        let b = &self.backend;
        let p = &state.particles;
        Ok(crate::Snapshot {
            frame: state.frame,
            substep: state.substep,
            time_s: state.time_s,
            x: to_f32(b.download(&p.x).map_err(be)?),
            v: to_f32(b.download(&p.v).map_err(be)?),
            c: to_f32(b.download(&p.c).map_err(be)?),
            f: to_f32(b.download(&p.f).map_err(be)?),
            plastic: to_f32(b.download(&p.plastic).map_err(be)?),
            fingerprint: String::new(),
        })
    }

    /// A state restored from a snapshot, with the given part parameters.
    pub fn restore(&self, snap: &crate::Snapshot, params: &[PartParams]) -> Result<SimState<B>> {
        let mut st = self.init_state(params)?;
        if snap.x.len() != self.scene.len() {
            return Err(Error::Scene {
                what: "snapshot".into(),
                message: format!(
                    "{} particles, the scene has {}",
                    snap.x.len(),
                    self.scene.len()
                ),
            });
        }
        let b = &self.backend;
        let p = &mut st.particles;
        b.write(&mut p.x, &from_f32(&snap.x)).map_err(be)?;
        b.write(&mut p.v, &from_f32(&snap.v)).map_err(be)?;
        b.write(&mut p.c, &from_f32(&snap.c)).map_err(be)?;
        b.write(&mut p.f, &from_f32(&snap.f)).map_err(be)?;
        b.write(&mut p.plastic, &from_f32(&snap.plastic))
            .map_err(be)?;
        st.frame = snap.frame;
        st.substep = snap.substep;
        st.time_s = snap.time_s;
        Ok(st)
    }

    /// Runs one substep (no health check; [`Simulator::step_frame`] checks at frame end): the
    /// stage order of [`substep::forward`], as every simulation runs it.
    pub fn substep(&mut self, state: &mut SimState<B>) -> Result<()> {
        let c = self.setup.consts_at(state.substep);
        let tables = SubstepTables {
            parts: &self.parts,
            mats: &self.mats,
            grid_bcs: &self.grid_bcs,
            particle_bcs: &self.particle_bcs,
        };
        substep::forward(
            &self.backend,
            &mut state.particles,
            &mut self.grid,
            &tables,
            &c,
            None,
        )
        .map_err(be)?;
        state.substep += 1;
        state.time_s = state.substep as f64 * self.setup.config.time.substep_dt;
        Ok(())
    }

    /// The error of health record `h`; `x`: the particles' positions now (they tell which
    /// axis a particle left along, as the record keeps one coordinate).
    fn health_error(
        &self,
        h: Health,
        frame: usize,
        frame_start: u64,
        x: &[[B::Scalar; 3]],
    ) -> Error {
        let global = h.substep as u64;
        let substep = global.saturating_sub(frame_start) as usize;
        let particle = h.particle as usize;
        let value = f32::from_bits(h.value_bits) as f64;
        match h.code {
            HEALTH_SPEED => Error::SpeedLimit {
                frame,
                substep,
                particle,
                speed: value,
                limit: self.setup.config.solver.max_cfl * self.setup.dx
                    / self.setup.config.time.substep_dt,
            },
            HEALTH_OUT_OF_DOMAIN => {
                let (lo, hi) = (
                    0.5 * self.setup.dx,
                    (self.setup.n as f64 - 1.5) * self.setup.dx,
                );
                // The axis: one outside the interior now, else the coordinate nearest the
                // recorded value.
                let p = x.get(particle).map(|p| p.map(|c| c.f64()));
                let axis = p.map_or(0, |p| {
                    (0..3)
                        .find(|&a| !(lo..hi).contains(&p[a]))
                        .unwrap_or_else(|| {
                            (0..3)
                                .min_by(|&a, &b| {
                                    (p[a] - value).abs().total_cmp(&(p[b] - value).abs())
                                })
                                .unwrap_or(0)
                        })
                });
                Error::OutOfDomain {
                    frame,
                    substep,
                    particle,
                    axis,
                    coord: value,
                    lo,
                    hi,
                }
            }
            _ => Error::NonFinite {
                frame,
                substep,
                global_substep: global,
                particle,
            },
        }
    }
}

impl<B: MpmKernels> Simulator for MpmSim<B> {
    type State = SimState<B>;
    type Error = Error;

    fn init_state(&self, params: &[PartParams]) -> Result<SimState<B>> {
        self.check_params(params)?;
        let b = &self.backend;
        let n = self.scene.len();
        let (z, o) = (B::Scalar::c(0.0), B::Scalar::c(1.0));
        let ident = [o, z, z, z, o, z, z, z, o];
        let yields = phys_params::<B::Scalar>(params);
        let plastic: Vec<[B::Scalar; 2]> = self
            .scene
            .part
            .iter()
            .map(|&p| [yields[p as usize].yield_stress, o])
            .collect();
        let particles = Particles {
            count: n,
            x: upload_as(b, &self.scene.x).map_err(be)?,
            v: b.zeros(n).map_err(be)?,
            c: b.zeros(n).map_err(be)?,
            f: b.upload(&vec![ident; n]).map_err(be)?,
            x0: b.upload(&self.scene.x).map_err(be)?,
            vol0: upload_as(b, &self.scene.volume).map_err(be)?,
            mass: b.upload(&self.tables(params).mass).map_err(be)?,
            part: b.upload(&self.scene.part).map_err(be)?,
            plastic: b.upload(&plastic).map_err(be)?,
            stress: b.zeros(n).map_err(be)?,
        };
        Ok(SimState {
            particles,
            time_s: 0.0,
            substep: 0,
            frame: 0,
            params: params.to_vec(),
        })
    }

    fn step_frame(&mut self, state: &mut SimState<B>, params: &[PartParams]) -> Result<()> {
        if params != state.params.as_slice() {
            self.check_params(params)?;
            let m = self.tables(params).mass;
            self.backend
                .write(&mut state.particles.mass, &m)
                .map_err(be)?;
            state.params = params.to_vec();
        }
        self.upload_params(params)?;
        let frame = state.frame + 1;
        let start = state.substep;
        for _ in 0..self.setup.substeps_per_frame {
            self.substep(state)?;
        }
        let h = self.backend.download(&self.grid.health).map_err(be)?[0];
        if h.code != 0 {
            self.backend
                .write(&mut self.grid.health, &[Health::default()])
                .map_err(be)?;
            let x = self
                .backend
                .download(&state.particles.x)
                .unwrap_or_default();
            return Err(self.health_error(h, frame, start, &x));
        }
        state.frame = frame;
        Ok(())
    }

    fn positions(&self, state: &SimState<B>) -> Result<Vec<[f32; 3]>> {
        Ok(to_f32(
            self.backend.download(&state.particles.x).map_err(be)?,
        ))
    }

    fn deformation_gradients(&self, state: &SimState<B>) -> Result<Vec<[f32; 9]>> {
        Ok(to_f32(
            self.backend.download(&state.particles.f).map_err(be)?,
        ))
    }
}

/// `x` in the scalar type `S` (exact).
fn cast<S: Real>(x: f32) -> S {
    S::c(x as f64)
}

/// Uploads f32 host data as the backend's scalar type, without a host copy when it is f32.
fn upload_as<B, V, W>(b: &B, v: &[V]) -> std::result::Result<B::Buf<W>, B::Error>
where
    B: MpmKernels,
    V: bytemuck::Pod + Send + Sync + AsScalar<W>,
    W: bytemuck::Pod + Send + Sync,
{
    match bytemuck::try_cast_slice::<V, W>(v) {
        Ok(same) if B::Scalar::NAME == "f32" => b.upload(same),
        _ => b.upload(&v.iter().map(|x| x.as_scalar()).collect::<Vec<W>>()),
    }
}

/// Conversion of f32 host data to the scalar type (exact).
trait AsScalar<W> {
    fn as_scalar(&self) -> W;
}
impl<S: Real> AsScalar<S> for f32 {
    fn as_scalar(&self) -> S {
        cast(*self)
    }
}
impl<S: Real, const N: usize> AsScalar<[S; N]> for [f32; N] {
    fn as_scalar(&self) -> [S; N] {
        self.map(cast)
    }
}

/// Host f32 arrays in the scalar type `S` (exact).
pub fn from_f32<S: Real, const N: usize>(v: &[[f32; N]]) -> Vec<[S; N]> {
    v.iter().map(|a| a.map(cast)).collect()
}

/// Arrays in scalar type `S` rounded to f32 (for files and the renderer).
pub fn to_f32<S: Real, const N: usize>(v: Vec<[S; N]>) -> Vec<[f32; N]> {
    v.into_iter().map(|a| a.map(|x| x.f64() as f32)).collect()
}
