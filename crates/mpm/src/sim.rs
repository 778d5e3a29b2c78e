//! The simulator: the substep loop, frames, parameter upload and error checks, written once and
//! generic over the backend ([`MpmKernels`]).

use crate::config::SimConfig;
use crate::error::{Error, Result};
use crate::kernels::{
    blocks_per_axis, Grid, GridBc, Health, MpmKernels, ParticleBc, Particles, StepConsts,
    HEALTH_OUT_OF_DOMAIN, HEALTH_SPEED,
};
use crate::material::{PartConsts, PartParams};
use crate::scene::ParticleSet;

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
    /// Time at the end of the last substep (s), accumulated in f64.
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

    /// Refuses a substep that violates the CFL bound `dt <= max_cfl dx / c_p` of any part.
    pub fn check_cfl(&self, params: &[PartParams]) -> Result<()> {
        let dt = self.config.time.substep_dt;
        let cfl = self.config.solver.max_cfl;
        for (i, p) in params.iter().enumerate() {
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
                    material: format!("{:?}", p.material).to_lowercase(),
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
        let consts: Vec<PartConsts> = config.parts.iter().map(|p| p.consts()).collect();
        Ok(MpmSim {
            grid_bcs: backend.upload(&gb).map_err(be)?,
            particle_bcs: backend.upload(&pb).map_err(be)?,
            parts: backend.upload(&consts).map_err(be)?,
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

    fn masses(&self, params: &[PartParams]) -> Vec<f32> {
        self.scene
            .volume
            .iter()
            .zip(&self.scene.part)
            .map(|(v, &p)| (params[p as usize].density_kg_m3 * *v as f64) as f32)
            .collect()
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
            let consts: Vec<PartConsts> = params.iter().map(|p| p.consts()).collect();
            self.backend.write(&mut self.parts, &consts).map_err(be)?;
            self.uploaded = params.to_vec();
        }
        Ok(())
    }

    /// A host copy of the state (for [`crate::Snapshot::write`]).
    pub fn snapshot(&self, state: &SimState<B>) -> Result<crate::Snapshot> {
        let b = &self.backend;
        let p = &state.particles;
        Ok(crate::Snapshot {
            frame: state.frame,
            substep: state.substep,
            time_s: state.time_s,
            x: b.download(&p.x).map_err(be)?,
            v: b.download(&p.v).map_err(be)?,
            c: b.download(&p.c).map_err(be)?,
            f: b.download(&p.f).map_err(be)?,
            plastic: b.download(&p.plastic).map_err(be)?,
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
        b.write(&mut p.x, &snap.x).map_err(be)?;
        b.write(&mut p.v, &snap.v).map_err(be)?;
        b.write(&mut p.c, &snap.c).map_err(be)?;
        b.write(&mut p.f, &snap.f).map_err(be)?;
        b.write(&mut p.plastic, &snap.plastic).map_err(be)?;
        st.frame = snap.frame;
        st.substep = snap.substep;
        st.time_s = snap.time_s;
        Ok(st)
    }

    /// Runs one substep (no health check; [`Simulator::step_frame`] checks at frame end).
    pub fn substep(&mut self, state: &mut SimState<B>) -> Result<()> {
        let c = self.setup.step_consts(state.time_s, state.substep);
        let b = &self.backend;
        let p = &mut state.particles;
        if c.n_particle_bcs > 0 {
            b.particle_bcs(p, &self.particle_bcs, &c).map_err(be)?;
        }
        b.p2g(p, &self.parts, &mut self.grid, &c).map_err(be)?;
        b.grid_update(&mut self.grid, &self.grid_bcs, &c)
            .map_err(be)?;
        b.g2p(p, &mut self.grid, &c).map_err(be)?;
        state.time_s += self.setup.config.time.substep_dt;
        state.substep += 1;
        Ok(())
    }

    fn health_error(&self, h: Health, frame: usize, frame_start: u64) -> Error {
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
            HEALTH_OUT_OF_DOMAIN => Error::OutOfDomain {
                frame,
                substep,
                particle,
                coord: value,
                lo: 0.5 * self.setup.dx,
                hi: (self.setup.n as f64 - 1.5) * self.setup.dx,
            },
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
        let ident = [1.0f32, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0];
        let plastic: Vec<[f32; 2]> = self
            .scene
            .part
            .iter()
            .map(|&p| [params[p as usize].yield_stress_pa as f32, 1.0])
            .collect();
        let particles = Particles {
            count: n,
            x: b.upload(&self.scene.x).map_err(be)?,
            v: b.zeros(n).map_err(be)?,
            c: b.zeros(n).map_err(be)?,
            f: b.upload(&vec![ident; n]).map_err(be)?,
            x0: b.upload(&self.scene.x).map_err(be)?,
            vol0: b.upload(&self.scene.volume).map_err(be)?,
            mass: b.upload(&self.masses(params)).map_err(be)?,
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
            let m = self.masses(params);
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
            return Err(self.health_error(h, frame, start));
        }
        state.frame = frame;
        Ok(())
    }

    fn positions(&self, state: &SimState<B>) -> Result<Vec<[f32; 3]>> {
        self.backend.download(&state.particles.x).map_err(be)
    }

    fn deformation_gradients(&self, state: &SimState<B>) -> Result<Vec<[f32; 9]>> {
        self.backend.download(&state.particles.f).map_err(be)
    }
}
