//! Frame-by-frame stepping of a [`Simulation`] ([`Simulator`]): parameters given per part and
//! checked when they change, the grid's health record read at every frame end (an exploded,
//! too fast or escaped particle becomes a typed error naming the frame, substep and particle),
//! snapshots for resuming.

use super::{be, Simulation};
use crate::error::{Error, Result};
use crate::kernels::{Health, MpmKernels, HEALTH_OUT_OF_DOMAIN, HEALTH_SPEED};
use crate::material::PartParams;
use crate::math::Real;
use crate::params::PhysParams;
use crate::sim::{from_f32, to_f32, Simulator};
use crate::state::SimState;

impl<B: MpmKernels> Simulation<B> {
    /// The config's part parameters.
    pub fn config_params(&self) -> &[PartParams] {
        &self.sim.setup.config.parts
    }

    /// Parameters per slot from parameters per part.
    fn slot_params(&self, params: &[PartParams]) -> Vec<PhysParams<B::Scalar>> {
        self.slot_part
            .iter()
            .map(|&p| PhysParams::of(&params[p as usize]))
            .collect()
    }

    fn check_params(&self, params: &[PartParams]) -> Result<()> {
        let parts = self.sim.setup.config.parts.len();
        if params.len() != parts {
            return Err(Error::config(
                "parameters",
                format!(
                    "{} part parameter sets given, the scene has {parts} parts",
                    params.len()
                ),
            ));
        }
        for (i, p) in params.iter().enumerate() {
            p.validate(&format!("parts[{i}]"))?;
        }
        self.sim.setup.check_cfl(params)
    }

    /// Runs one substep of `state` (no health check; [`Simulator::step_frame`] checks at
    /// frame end): the stage order of [`crate::substep::forward`], as every simulation runs
    /// it.
    pub fn step_substep(&self, state: &mut SimState<B>) -> Result<()> {
        let phys = self.slot_params(&state.params);
        self.substep(&mut state.state, &phys, state.substep)
            .map_err(be)?;
        state.substep += 1;
        state.time_s = state.substep as f64 * self.sim.setup.config.time.substep_dt;
        Ok(())
    }

    /// A host copy of the state (for [`crate::Snapshot::write`]; the caller sets its
    /// fingerprint).
    pub fn snapshot(&self, state: &SimState<B>) -> Result<crate::Snapshot> {
        let b = &self.b;
        let p = &state.state;
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
        if snap.x.len() != self.sim.len() {
            return Err(Error::Scene {
                what: "snapshot".into(),
                message: format!(
                    "{} particles, the scene has {}",
                    snap.x.len(),
                    self.sim.len()
                ),
            });
        }
        let b = &self.b;
        let p = &mut st.state;
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

    /// Reads and clears the grid's health record.
    pub(crate) fn take_health(&self) -> Result<Health> {
        let mut w = self.lock();
        let h = self.b.download(&w.g.health).map_err(be)?[0];
        if h.code != 0 {
            self.b
                .write(&mut w.g.health, &[Health::default()])
                .map_err(be)?;
        }
        w.health_unread = false;
        Ok(h)
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
        let setup = &self.sim.setup;
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
                limit: setup.config.solver.max_cfl * setup.dx / setup.config.time.substep_dt,
            },
            HEALTH_OUT_OF_DOMAIN => {
                let (lo, hi) = (0.5 * setup.dx, (setup.n as f64 - 1.5) * setup.dx);
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

impl<B: MpmKernels> Simulator for Simulation<B> {
    type State = SimState<B>;
    type Error = Error;

    fn init_state(&self, params: &[PartParams]) -> Result<SimState<B>> {
        self.check_params(params)?;
        let zero = B::Scalar::c(0.0);
        let phys = self.slot_params(params);
        let state = self
            .init(&phys, &vec![[zero; 3]; self.sim.len()])
            .map_err(be)?;
        self.prepare_params(&phys).map_err(be)?;
        Ok(SimState {
            state,
            time_s: 0.0,
            substep: 0,
            frame: 0,
            params: params.to_vec(),
        })
    }

    fn step_frame(&mut self, state: &mut SimState<B>, params: &[PartParams]) -> Result<()> {
        if params != state.params.as_slice() {
            self.check_params(params)?;
            state.params = params.to_vec();
        }
        // A record left by substeps nobody checked (a differentiable run) is not this frame's.
        if self.lock().health_unread {
            self.take_health()?;
        }
        let phys = self.slot_params(params);
        let frame = state.frame + 1;
        let start = state.substep;
        let dt = self.sim.setup.config.time.substep_dt;
        for _ in 0..self.sim.setup.substeps_per_frame {
            self.substep(&mut state.state, &phys, state.substep)
                .map_err(be)?;
            state.substep += 1;
            state.time_s = state.substep as f64 * dt;
        }
        let h = self.take_health()?;
        if h.code != 0 {
            let x = self.b.download(&state.state.x).unwrap_or_default();
            return Err(self.health_error(h, frame, start, &x));
        }
        state.frame = frame;
        Ok(())
    }

    fn positions(&self, state: &SimState<B>) -> Result<Vec<[f32; 3]>> {
        Ok(to_f32(self.b.download(&state.state.x).map_err(be)?))
    }

    fn deformation_gradients(&self, state: &SimState<B>) -> Result<Vec<[f32; 9]>> {
        Ok(to_f32(self.b.download(&state.state.f).map_err(be)?))
    }
}
