//! A video-fitting problem (scene, particles, parts, cameras, reference videos) and its
//! objective: simulate, render every view, evaluate the DMS loss, and differentiate all of it
//! back to the parameters of every part.
//!
//! # Time
//! Video frame `k` is at `t = k / fps`; simulation frame `j` (after `j x substeps_per_frame`
//! substeps, frame 0 the rest state) at `t = j x frame_dt`. When the two grids differ the
//! rendered video is resampled linearly in time between the two nearest simulated frames
//! ([`TimeMap`]), and the gradient is split back with the same weights.

use super::FitError;
use r4d_backend_cpu::adjoint::ParallelHost;
use r4d_backend_cpu::splat::CpuSplat;
use r4d_loss::{Dms, DmsConfig, DmsTerms, Video};
use r4d_mpm::adjoint::checkpoint::{value_and_grad, Checkpointing, Differentiable};
use r4d_mpm::adjoint::host::{HostSim, HostState, PhysParams};
use r4d_mpm::math::Real;
use r4d_mpm::{PartParams, ParticleSet, SimConfig};
use r4d_splat::{Camera, Deformation, Gaussians, RenderSettings, Renderer, SimLink, SplatRenderer};
use serde::{Deserialize, Serialize};
use std::cell::RefCell;

/// One camera and the reference video seen from it.
#[derive(Clone, Debug)]
pub struct View {
    /// Label for messages (file name).
    pub name: String,
    /// The camera.
    pub camera: Camera,
    /// The reference video `(T, H, W, 3)`, same size as the camera.
    pub video: Video<f32>,
}

/// Everything a video fit needs.
#[derive(Clone, Debug)]
pub struct VideoProblem {
    /// Simulation settings; `parts` hold the starting parameters of every part.
    pub config: SimConfig,
    /// The simulated particles with their part ids.
    pub particles: ParticleSet,
    /// The static 3DGS scene.
    pub scene: Gaussians,
    /// Which Gaussians follow which particles.
    pub link: SimLink,
    /// Background and rasterize mode.
    pub settings: RenderSettings,
    /// The supervised views.
    pub views: Vec<View>,
    /// Frame rate of the reference videos.
    pub fps: f64,
}

/// Floating-point type of the simulation and its reverse sweep.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Precision {
    /// Single precision (faster; gradients agree with f64 to a few 1e-3 relative).
    F32,
    /// Double precision (default).
    #[default]
    F64,
}

/// Where each video frame lies on the simulation's frame grid.
#[derive(Clone, Debug, PartialEq)]
pub struct TimeMap {
    /// Per video frame: the two simulated frames around it and the weight of the second.
    pub taps: Vec<(usize, usize, f32)>,
    /// The last simulated frame needed.
    pub sim_frames: usize,
}

impl TimeMap {
    /// The map of `video_frames` frames at `fps` onto frames of `frame_dt` seconds.
    pub fn new(video_frames: usize, fps: f64, frame_dt: f64) -> TimeMap {
        let taps: Vec<(usize, usize, f32)> = (0..video_frames)
            .map(|k| {
                let s = k as f64 / (fps * frame_dt);
                let r = s.round();
                if (s - r).abs() < 1e-6 {
                    (r as usize, r as usize, 0.0)
                } else {
                    let j = s.floor();
                    (j as usize, j as usize + 1, (s - j) as f32)
                }
            })
            .collect();
        let sim_frames = taps.iter().map(|t| t.1).max().unwrap_or(0);
        TimeMap { taps, sim_frames }
    }

    /// True when every video frame is a simulated frame.
    pub fn is_identity(&self) -> bool {
        self.taps.iter().all(|t| t.2 == 0.0)
    }
}

impl VideoProblem {
    /// Checks the pieces against each other: videos match their cameras, at least 2 frames,
    /// the link matches the scene and the particles, part ids exist.
    pub fn validate(&self) -> Result<(), FitError> {
        let bad = |m: String| Err(FitError::Input(m));
        if self.views.is_empty() {
            return bad("no view to fit: give a camera and its video".into());
        }
        if !(self.fps.is_finite() && self.fps > 0.0) {
            return bad(format!("fps is {}, must be positive", self.fps));
        }
        for v in &self.views {
            let (w, h) = (v.camera.width as usize, v.camera.height as usize);
            if v.video.width() != w || v.video.height() != h {
                return bad(format!(
                    "{}: the video is {}x{} but camera '{}' renders {w}x{h}",
                    v.name,
                    v.video.width(),
                    v.video.height(),
                    v.camera.name
                ));
            }
            if v.video.frames() < 2 {
                return bad(format!("{}: the video needs at least 2 frames", v.name));
            }
        }
        self.link
            .validate("link")
            .map_err(|e| FitError::Input(e.to_string()))?;
        if self.link.scene_gaussians != self.scene.len() {
            return bad(format!(
                "the link is for {} Gaussians, the scene has {}",
                self.link.scene_gaussians,
                self.scene.len()
            ));
        }
        let want = self.link.simulated.len() + self.link.filled;
        if self.particles.x.len() != want {
            return bad(format!(
                "{} particles, but the link maps {} simulated Gaussians + {} filling particles",
                self.particles.x.len(),
                self.link.simulated.len(),
                self.link.filled
            ));
        }
        if let Some(&p) = self
            .particles
            .part
            .iter()
            .find(|&&p| p as usize >= self.config.parts.len())
        {
            return bad(format!(
                "particle part id {p} but the simulation config has {} parts",
                self.config.parts.len()
            ));
        }
        Ok(())
    }

    /// Frames of the shortest reference video.
    pub fn video_frames(&self) -> usize {
        self.views
            .iter()
            .map(|v| v.video.frames())
            .min()
            .unwrap_or(0)
    }
}

/// One evaluation of the objective.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Evaluation {
    /// Mean over views of the DMS total.
    pub total: f64,
    /// Terms per view.
    pub views: Vec<DmsTerms>,
}

/// The differentiable objective over the first `frames` video frames.
pub struct Objective<'a> {
    problem: &'a VideoProblem,
    sim: HostSim,
    time: TimeMap,
    dms: Vec<Dms<f32>>,
    /// Checkpointing of the reverse sweep.
    pub checkpointing: Checkpointing,
    /// Simulation precision.
    pub precision: Precision,
}

fn first_err(slot: &RefCell<Option<FitError>>, e: FitError) {
    let mut s = slot.borrow_mut();
    if s.is_none() {
        *s = Some(e);
    }
}

impl<'a> Objective<'a> {
    /// The objective of `problem` on its first `frames` video frames (all when `None`), with
    /// per-particle parameter slots when `per_particle`.
    pub fn new(
        problem: &'a VideoProblem,
        frames: Option<usize>,
        dms: &DmsConfig,
        per_particle: bool,
    ) -> Result<Self, FitError> {
        problem.validate()?;
        let frames = frames
            .unwrap_or(usize::MAX)
            .min(problem.video_frames())
            .max(2);
        let mut sim = HostSim::new(&problem.config, &problem.particles)?;
        if per_particle {
            sim = sim.per_particle();
        }
        let t = &problem.config.time;
        let frame_dt = t.substeps() as f64 * t.substep_dt;
        let time = TimeMap::new(frames, problem.fps, frame_dt);
        let dms = problem
            .views
            .iter()
            .map(|v| {
                let r = Video::from_frames(
                    v.video.height(),
                    v.video.width(),
                    (0..frames).map(|t| v.video.frame(t).to_vec()),
                )?;
                Dms::new(r, dms.clone())
            })
            .collect::<Result<Vec<_>, _>>()
            .map_err(|e| FitError::Input(format!("reference video: {e}")))?;
        Ok(Objective {
            problem,
            sim,
            time,
            dms,
            checkpointing: Checkpointing::PerFrame,
            precision: Precision::F64,
        })
    }

    /// The host simulator (its `slot` gives each particle's parameter slot).
    pub fn sim(&self) -> &HostSim {
        &self.sim
    }

    /// The part of every parameter slot.
    pub fn slot_parts(&self) -> Vec<u32> {
        if self.sim.slots() == self.problem.config.parts.len() && self.sim.slot == self.sim.part {
            (0..self.problem.config.parts.len() as u32).collect()
        } else {
            self.sim.part.clone()
        }
    }

    /// The starting parameters of every slot (the config's parts, per particle if needed).
    pub fn initial_slots(&self) -> Vec<PartParams> {
        self.slot_parts()
            .iter()
            .map(|&p| self.problem.config.parts[p as usize])
            .collect()
    }

    /// Video frames evaluated.
    pub fn frames(&self) -> usize {
        self.time.taps.len()
    }

    /// The time map.
    pub fn time_map(&self) -> &TimeMap {
        &self.time
    }

    /// Simulates and renders every view (no gradient): the fitted videos.
    pub fn render(&self, slots: &[PartParams]) -> Result<Vec<Video<f32>>, FitError> {
        match self.precision {
            Precision::F32 => self.run::<f32>(slots, false).map(|r| r.2),
            Precision::F64 => self.run::<f64>(slots, false).map(|r| r.2),
        }
    }

    /// Simulates and renders every view and evaluates the loss (no gradient).
    pub fn render_and_value(
        &self,
        slots: &[PartParams],
    ) -> Result<(Evaluation, Vec<Video<f32>>), FitError> {
        match self.precision {
            Precision::F32 => self.run::<f32>(slots, false).map(|r| (r.0, r.2)),
            Precision::F64 => self.run::<f64>(slots, false).map(|r| (r.0, r.2)),
        }
    }

    /// The loss (no gradient).
    pub fn value(&self, slots: &[PartParams]) -> Result<Evaluation, FitError> {
        match self.precision {
            Precision::F32 => self.run::<f32>(slots, false).map(|r| r.0),
            Precision::F64 => self.run::<f64>(slots, false).map(|r| r.0),
        }
    }

    /// The loss and its gradient with respect to every slot's parameters.
    pub fn value_and_grad(
        &self,
        slots: &[PartParams],
    ) -> Result<(Evaluation, Vec<PhysParams<f64>>), FitError> {
        let r = match self.precision {
            Precision::F32 => self.run::<f32>(slots, true)?,
            Precision::F64 => self.run::<f64>(slots, true)?,
        };
        Ok((r.0, r.1.expect("gradient requested")))
    }

    /// Renders one simulated state from every view.
    fn render_state<T: Real>(
        &self,
        s: &HostState<T>,
        what: &str,
    ) -> Result<Vec<Vec<f32>>, FitError> {
        self.check_domain(s, what)?;
        let d = self.deformation(s, what)?;
        let mut r = SplatRenderer::new(CpuSplat);
        self.problem
            .views
            .iter()
            .map(|v| {
                r.render(
                    &self.problem.scene,
                    Some(&d),
                    &v.camera,
                    &self.problem.settings,
                )
                .map(|img| img.rgb)
                .map_err(FitError::from)
            })
            .collect()
    }

    /// An exploded simulation: a particle outside the grid's interior or non-finite.
    fn check_domain<T: Real>(&self, s: &HostState<T>, what: &str) -> Result<(), FitError> {
        let setup = &self.sim.setup;
        let inv_dx = 1.0 / setup.dx;
        let hi = setup.n as f64 - 1.5;
        if let Some(i) = s.x.iter().position(|p| {
            !p.iter().all(|c| {
                let g = c.f64() * inv_dx;
                g.is_finite() && (0.5..hi).contains(&g)
            })
        }) {
            return Err(FitError::Exploded(format!("{what}: particle {i}")));
        }
        Ok(())
    }

    fn deformation<T: Real>(&self, s: &HostState<T>, what: &str) -> Result<Deformation, FitError> {
        let x: Vec<[f32; 3]> = s.x.iter().map(|p| p.map(|c| c.f64() as f32)).collect();
        let f: Vec<[[f32; 3]; 3]> =
            s.f.iter()
                .map(|m| {
                    let g = |i: usize| m[i].f64() as f32;
                    [[g(0), g(1), g(2)], [g(3), g(4), g(5)], [g(6), g(7), g(8)]]
                })
                .collect();
        Ok(self
            .problem
            .link
            .deformation(&self.problem.scene, &x, Some(&f), what)?)
    }

    /// Adds the gradient of `sum(d_rgb * render(s))` over every view to `adj`.
    fn render_vjp_into<T: Real>(
        &self,
        s: &HostState<T>,
        d_rgb: &[Vec<f32>],
        adj: &mut HostState<T>,
    ) -> Result<(), FitError> {
        let d = self.deformation(s, "reverse sweep")?;
        let mut r = SplatRenderer::new(CpuSplat);
        let link = &self.problem.link;
        let rot = link.rotation;
        for (v, g) in self.problem.views.iter().zip(d_rgb) {
            if g.iter().all(|&x| x == 0.0) {
                continue;
            }
            let gr = r.render_vjp(
                &self.problem.scene,
                Some(&d),
                &v.camera,
                &self.problem.settings,
                g,
            )?;
            // x_world = R^T ((x_sim - shift) / scale + centre): dL/dx_sim = R dL/dx_world / scale.
            // F_world = R^T F_sim R: dL/dF_sim = R dL/dF_world R^T.
            for (p, &gi) in link.simulated.iter().enumerate() {
                let gm = gr.means[gi as usize];
                for a in 0..3 {
                    let v: f64 = (0..3).map(|b| rot[a][b] * gm[b] as f64).sum::<f64>() / link.scale;
                    adj.x[p][a] += T::c(v);
                }
                let gf = gr.f[gi as usize];
                for a in 0..3 {
                    for b in 0..3 {
                        let mut v = 0.0;
                        for c in 0..3 {
                            for e in 0..3 {
                                v += rot[a][c] * gf[c][e] as f64 * rot[b][e];
                            }
                        }
                        adj.f[p][a * 3 + b] += T::c(v);
                    }
                }
            }
        }
        Ok(())
    }

    /// Assembles the rendered videos from the per-simulated-frame renders, moving frames out
    /// of `frames` (each is freed once no later video frame needs it), so the peak is one
    /// video per view plus a frame.
    fn assemble_take(
        &self,
        frames: &mut [Option<Vec<Vec<f32>>>],
    ) -> Result<Vec<Video<f32>>, FitError> {
        let views = &self.problem.views;
        let taps = &self.time.taps;
        // Last video frame that reads each simulated frame.
        let mut last_use = vec![usize::MAX; frames.len()];
        for (k, &(j0, j1, a)) in taps.iter().enumerate() {
            last_use[j0] = k;
            if a != 0.0 {
                last_use[j1] = k;
            }
        }
        let mut out = Vec::with_capacity(views.len());
        for v in 0..views.len() {
            let (h, w) = (views[v].video.height(), views[v].video.width());
            let last_view = v + 1 == views.len();
            let mut get = |j: usize, k: usize| -> Vec<f32> {
                let f = frames[j].as_mut().expect("rendered frame");
                if last_use[j] == k {
                    std::mem::take(&mut f[v])
                } else {
                    f[v].clone()
                }
            };
            let mut data = Vec::with_capacity(taps.len() * h * w * 3);
            for (k, &(j0, j1, a)) in taps.iter().enumerate() {
                let f0 = get(j0, k);
                if a == 0.0 {
                    data.extend_from_slice(&f0);
                } else {
                    let f1 = get(j1, k);
                    data.extend(f0.iter().zip(&f1).map(|(x, y)| x + a * (y - x)));
                }
            }
            if last_view {
                frames.iter_mut().for_each(|f| *f = None);
            }
            out.push(
                Video::new(taps.len(), h, w, data).map_err(|e| FitError::Input(e.to_string()))?,
            );
        }
        Ok(out)
    }

    /// `dL/d(rendered frame j)` of view `v` from the gradient of its video (`gv`, the
    /// video's layout), through the time map.
    fn frame_grad(&self, gv: &[f32], j: usize, out: &mut [f32]) -> bool {
        let fl = out.len();
        out.fill(0.0);
        let mut any = false;
        for (k, &(j0, j1, a)) in self.time.taps.iter().enumerate() {
            let w = if j0 == j && j1 == j {
                1.0
            } else if j0 == j {
                1.0 - a
            } else if j1 == j && a != 0.0 {
                a
            } else {
                continue;
            };
            any = true;
            for (o, &x) in out.iter_mut().zip(&gv[k * fl..(k + 1) * fl]) {
                *o += w * x;
            }
        }
        any
    }

    fn needed(&self) -> Vec<bool> {
        let mut need = vec![false; self.time.sim_frames + 1];
        for &(j0, j1, a) in &self.time.taps {
            need[j0] = true;
            if a != 0.0 {
                need[j1] = true;
            }
        }
        need
    }

    /// DMS of every view: the mean total and the terms; with `grads`, also the gradient of
    /// the mean with respect to each view's video (its layout).
    fn loss(
        &self,
        videos: &[Video<f32>],
        mut grads: Option<&mut Vec<Vec<f32>>>,
    ) -> Result<Evaluation, FitError> {
        let mut ev = Evaluation::default();
        let nv = self.dms.len() as f64;
        for (dms, video) in self.dms.iter().zip(videos) {
            let terms = match grads.as_deref_mut() {
                Some(gs) => {
                    let mut g = vec![0.0f32; video.data().len()];
                    let t = dms.terms_and_grad_into(video, &mut g)?;
                    g.iter_mut().for_each(|x| *x /= nv as f32);
                    gs.push(g);
                    t
                }
                None => dms.terms(video)?,
            };
            ev.total += terms.total / nv;
            ev.views.push(terms);
        }
        if !ev.total.is_finite() {
            return Err(FitError::NonFinite("the loss".into()));
        }
        Ok(ev)
    }

    /// Forward (and with `grad` the reverse sweep) in precision `T`. Returns the rendered
    /// videos only without `grad` (with it they are freed as soon as the loss is evaluated).
    #[allow(clippy::type_complexity)]
    fn run<T: Real>(
        &self,
        slots: &[PartParams],
        grad: bool,
    ) -> Result<(Evaluation, Option<Vec<PhysParams<f64>>>, Vec<Video<f32>>), FitError> {
        for (i, p) in slots.iter().enumerate() {
            p.validate(&format!("parameters of slot {i}"))?;
        }
        let phys: Vec<PhysParams<T>> = slots.iter().map(PhysParams::of).collect();
        let v0 = vec![[T::zero(); 3]; self.sim.len()];
        let init = self.sim.init(&phys, &v0);
        let stepper = ParallelHost::<T>::new(&self.sim);
        let spf = self.sim.setup.substeps_per_frame;
        let need = self.needed();
        let nframes = self.time.sim_frames;
        let substeps = nframes as u64 * spf as u64;
        let error: RefCell<Option<FitError>> = RefCell::new(None);
        let renders: RefCell<Vec<Option<Vec<Vec<f32>>>>> = RefCell::new(vec![None; nframes + 1]);
        renders.borrow_mut()[0] = Some(self.render_state(&init, "frame 0")?);
        let render_frame = |f: usize, s: &HostState<T>| {
            if need[f] && error.borrow().is_none() {
                match self.render_state(s, &format!("simulated frame {f}")) {
                    Ok(r) => renders.borrow_mut()[f] = Some(r),
                    Err(e) => first_err(&error, e),
                }
            }
        };
        if !grad {
            let mut s = init.clone();
            for j in 0..substeps {
                stepper.step(&mut s, &phys, j);
                if (j + 1) % spf as u64 == 0 {
                    render_frame(((j + 1) / spf as u64) as usize, &s);
                    if let Some(e) = error.borrow_mut().take() {
                        return Err(e);
                    }
                }
            }
            drop(s);
            let videos = self.assemble_take(&mut renders.borrow_mut())?;
            let ev = self.loss(&videos, None)?;
            return Ok((ev, None, videos));
        }
        // Reverse mode: the forward pass renders; the first reverse call assembles the
        // videos (freeing the renders), evaluates the loss and keeps only dL/dvideo.
        let video_grads: RefCell<Option<Vec<Vec<f32>>>> = RefCell::new(None);
        let eval_out: RefCell<Option<Evaluation>> = RefCell::new(None);
        let grad0 = vec![PhysParams::<T>::default(); self.sim.slots()];
        let mut frame_buf: Vec<f32> = Vec::new();
        let (_, adj0, mut g) = value_and_grad(
            &stepper,
            &init,
            &phys,
            substeps,
            spf,
            self.checkpointing,
            grad0,
            |f, s| {
                render_frame(f, s);
                0.0
            },
            |f, s, adj| {
                if error.borrow().is_some() {
                    return;
                }
                if video_grads.borrow().is_none() {
                    let r = self
                        .assemble_take(&mut renders.borrow_mut())
                        .and_then(|videos| {
                            let mut gs = Vec::with_capacity(videos.len());
                            let ev = self.loss(&videos, Some(&mut gs))?;
                            Ok((ev, gs))
                        });
                    match r {
                        Ok((ev, gs)) => {
                            *eval_out.borrow_mut() = Some(ev);
                            *video_grads.borrow_mut() = Some(gs);
                        }
                        Err(e) => return first_err(&error, e),
                    }
                }
                let gs = video_grads.borrow();
                let gs = gs.as_ref().expect("video gradients");
                let mut d_rgb = Vec::with_capacity(gs.len());
                for (v, gv) in gs.iter().enumerate() {
                    frame_buf.resize(self.problem.views[v].video.frame_len(), 0.0);
                    if self.frame_grad(gv, f, &mut frame_buf) {
                        d_rgb.push(frame_buf.clone());
                    } else {
                        d_rgb.push(Vec::new());
                    }
                }
                if let Err(e) = self.render_vjp_into(s, &d_rgb, adj) {
                    first_err(&error, e);
                }
            },
        );
        if let Some(e) = error.borrow_mut().take() {
            return Err(e);
        }
        self.sim.init_vjp(&adj0, &mut g);
        let ev = match eval_out.borrow_mut().take() {
            Some(ev) => ev,
            None => {
                let videos = self.assemble_take(&mut renders.borrow_mut())?;
                self.loss(&videos, None)?
            }
        };
        let g64: Vec<PhysParams<f64>> = g
            .iter()
            .map(|p| PhysParams {
                youngs_modulus: p.youngs_modulus.f64(),
                poisson_ratio: p.poisson_ratio.f64(),
                yield_stress: p.yield_stress.f64(),
                plastic_viscosity: p.plastic_viscosity.f64(),
                friction_angle_deg: p.friction_angle_deg.f64(),
                density: p.density.f64(),
            })
            .collect();
        if g64.iter().any(|p| {
            ![
                p.youngs_modulus,
                p.poisson_ratio,
                p.yield_stress,
                p.plastic_viscosity,
                p.friction_angle_deg,
                p.density,
            ]
            .iter()
            .all(|x| x.is_finite())
        }) {
            return Err(FitError::NonFinite("the parameter gradient".into()));
        }
        Ok((ev, Some(g64), Vec::new()))
    }
}
