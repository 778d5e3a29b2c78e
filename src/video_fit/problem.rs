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
use r4d_backend_wgpu::adjoint::{DeviceState, WgpuAdjoint};
use r4d_backend_wgpu::context::WgpuContext;
use r4d_loss::{Dms, DmsConfig, DmsTerms, Video};
use r4d_mpm::adjoint::checkpoint::{value_and_grad, Checkpointing, Differentiable};
use r4d_mpm::adjoint::host::{HostSim, HostState, PhysParams};
use r4d_mpm::math::Real;
use r4d_mpm::{PartParams, ParticleSet, SimConfig};
use r4d_splat::{Camera, Deformation, Gaussians, RenderSettings, Renderer, SimLink, SplatRenderer};
use serde::{Deserialize, Serialize};
use std::cell::RefCell;
use std::sync::Arc;

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
    /// Simulate (forward and reverse) on this GPU; `None`: on the CPU. Rendering and the loss
    /// stay on the CPU.
    pub gpu: Option<GpuHandle>,
}

/// A wgpu device to simulate on ([`VideoProblem::gpu`]).
#[derive(Clone)]
pub struct GpuHandle(pub Arc<WgpuContext>);

impl std::fmt::Debug for GpuHandle {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("GpuHandle(wgpu device)")
    }
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
    /// Simulation precision (CPU; the GPU simulates in f32).
    pub precision: Precision,
    /// Simulate on this GPU instead of the CPU (`None`: the CPU).
    pub gpu: Option<Arc<WgpuContext>>,
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
                Video::from_frames(
                    v.video.height(),
                    v.video.width(),
                    (0..frames).map(|t| v.video.frame(t).to_vec()),
                )
                .and_then(|r| Dms::new(r, dms.clone()))
                .map_err(|e| FitError::Input(format!("{}: reference video: {e}", v.name)))
            })
            .collect::<Result<Vec<_>, _>>()?;
        Ok(Objective {
            problem,
            sim,
            time,
            dms,
            checkpointing: Checkpointing::PerFrame,
            precision: Precision::F64,
            gpu: problem.gpu.as_ref().map(|h| h.0.clone()),
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
        self.dispatch(slots, false).map(|r| r.2)
    }

    /// Simulates and renders every view and evaluates the loss (no gradient).
    pub fn render_and_value(
        &self,
        slots: &[PartParams],
    ) -> Result<(Evaluation, Vec<Video<f32>>), FitError> {
        self.dispatch(slots, false).map(|r| (r.0, r.2))
    }

    /// The loss (no gradient).
    pub fn value(&self, slots: &[PartParams]) -> Result<Evaluation, FitError> {
        self.dispatch(slots, false).map(|r| r.0)
    }

    /// The loss and its gradient with respect to every slot's parameters.
    pub fn value_and_grad(
        &self,
        slots: &[PartParams],
    ) -> Result<(Evaluation, Vec<PhysParams<f64>>), FitError> {
        let r = self.dispatch(slots, true)?;
        Ok((r.0, r.1.expect("gradient requested")))
    }

    /// Runs on the chosen simulator: the CPU (`ParallelHost` in f32 or f64) or the GPU
    /// (`WgpuAdjoint`, f32).
    fn dispatch(&self, slots: &[PartParams], grad: bool) -> Result<RunOut, FitError> {
        for (i, p) in slots.iter().enumerate() {
            p.validate(&format!("parameters of slot {i}"))?;
        }
        if let Some(ctx) = &self.gpu {
            return self.run_gpu(ctx.clone(), slots, grad);
        }
        match self.precision {
            Precision::F32 => self.run_cpu::<f32>(slots, grad),
            Precision::F64 => self.run_cpu::<f64>(slots, grad),
        }
    }

    fn run_cpu<T: Real>(&self, slots: &[PartParams], grad: bool) -> Result<RunOut, FitError> {
        let phys: Vec<PhysParams<T>> = slots.iter().map(PhysParams::of).collect();
        let init = self.sim.init(&phys, &vec![[T::zero(); 3]; self.sim.len()]);
        let stepper = ParallelHost::<T>::new(&self.sim);
        let grad0 = vec![PhysParams::<T>::default(); self.sim.slots()];
        let read = |s: &HostState<T>| -> Result<Frame, FitError> {
            Ok(Frame {
                x: s.x.iter().map(|p| p.map(|c| c.f64() as f32)).collect(),
                f: s.f.iter().map(|m| m.map(|c| c.f64() as f32)).collect(),
            })
        };
        let add = |adj: &mut HostState<T>, d: &FrameGrad| -> Result<(), FitError> {
            for (a, g) in adj.x.iter_mut().zip(&d.x) {
                for q in 0..3 {
                    a[q] += T::c(g[q]);
                }
            }
            for (a, g) in adj.f.iter_mut().zip(&d.f) {
                for q in 0..9 {
                    a[q] += T::c(g[q]);
                }
            }
            Ok(())
        };
        let (ev, back, videos) = self.run_with(&stepper, &init, &phys, grad0, grad, &read, &add)?;
        let g = back.map(|(adj0, mut g)| {
            self.sim.init_vjp(&adj0, &mut g);
            g.iter().map(to_f64).collect::<Vec<_>>()
        });
        Ok((ev, check_grad(g)?, videos))
    }

    fn run_gpu(
        &self,
        ctx: Arc<WgpuContext>,
        slots: &[PartParams],
        grad: bool,
    ) -> Result<RunOut, FitError> {
        let gpu = |e: r4d_backend_wgpu::context::WgpuError| FitError::Gpu(e.to_string());
        let d = WgpuAdjoint::new(ctx, &self.sim).map_err(|e| FitError::Gpu(e.to_string()))?;
        let phys: Vec<PhysParams<f32>> = slots.iter().map(PhysParams::of).collect();
        let init = d
            .init(&phys, &vec![[0.0; 3]; self.sim.len()])
            .map_err(gpu)?;
        let grad0 = d.zero_grad().map_err(gpu)?;
        let read = |s: &DeviceState| -> Result<Frame, FitError> {
            let h = s.download().map_err(gpu)?;
            Ok(Frame { x: h.x, f: h.f })
        };
        let add = |adj: &mut DeviceState, g: &FrameGrad| -> Result<(), FitError> {
            let dx: Vec<[f32; 3]> = g.x.iter().map(|v| v.map(|c| c as f32)).collect();
            let df: Vec<[f32; 9]> = g.f.iter().map(|v| v.map(|c| c as f32)).collect();
            adj.add_to_x(&dx).map_err(gpu)?;
            adj.add_to_f(&df).map_err(gpu)
        };
        let (ev, back, videos) = self.run_with(&d, &init, &phys, grad0, grad, &read, &add)?;
        let g = match back {
            Some((adj0, g)) => {
                let mut host = d.grad_to_host(&g, &phys).map_err(gpu)?;
                let adj0 = adj0.download().map_err(gpu)?;
                self.sim.init_vjp(&adj0, &mut host);
                Some(host.iter().map(to_f64).collect::<Vec<_>>())
            }
            None => None,
        };
        Ok((ev, check_grad(g)?, videos))
    }

    /// Renders one simulated frame from every view.
    fn render_state(&self, s: &Frame, what: &str) -> Result<Vec<Vec<f32>>, FitError> {
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
    fn check_domain(&self, s: &Frame, what: &str) -> Result<(), FitError> {
        let setup = &self.sim.setup;
        let inv_dx = 1.0 / setup.dx;
        let hi = setup.n as f64 - 1.5;
        if let Some(i) = s.x.iter().position(|p| {
            !p.iter().all(|&c| {
                let g = c as f64 * inv_dx;
                g.is_finite() && (0.5..hi).contains(&g)
            })
        }) {
            return Err(FitError::Exploded(format!("{what}: particle {i}")));
        }
        Ok(())
    }

    fn deformation(&self, s: &Frame, what: &str) -> Result<Deformation, FitError> {
        let f: Vec<[[f32; 3]; 3]> =
            s.f.iter()
                .map(|m| [[m[0], m[1], m[2]], [m[3], m[4], m[5]], [m[6], m[7], m[8]]])
                .collect();
        Ok(self
            .problem
            .link
            .deformation(&self.problem.scene, &s.x, Some(&f), what)?)
    }

    /// The gradient of `sum(d_rgb * render(s))` over every view with respect to the
    /// particles' positions and deformation gradients (simulation space).
    fn render_vjp(&self, s: &Frame, d_rgb: &[Vec<f32>]) -> Result<FrameGrad, FitError> {
        let n = s.x.len();
        let mut out = FrameGrad {
            x: vec![[0.0; 3]; n],
            f: vec![[0.0; 9]; n],
        };
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
                    out.x[p][a] +=
                        (0..3).map(|b| rot[a][b] * gm[b] as f64).sum::<f64>() / link.scale;
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
                        out.f[p][a * 3 + b] += v;
                    }
                }
            }
        }
        Ok(out)
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

    /// Forward (and with `grad` the reverse sweep) on stepper `d`: `read` brings a state's
    /// positions and deformation gradients to the host for rendering, `add` adds a frame's
    /// rendering gradient to an adjoint state. Returns the rendered videos only without
    /// `grad` (with it they are freed as soon as the loss is evaluated), and with `grad` the
    /// initial state's adjoint and the parameter gradient.
    #[allow(clippy::too_many_arguments, clippy::type_complexity)]
    fn run_with<D: Differentiable>(
        &self,
        d: &D,
        init: &D::State,
        params: &D::Params,
        grad0: D::Grad,
        grad: bool,
        read: &dyn Fn(&D::State) -> Result<Frame, FitError>,
        add: &dyn Fn(&mut D::State, &FrameGrad) -> Result<(), FitError>,
    ) -> Result<(Evaluation, Option<(D::State, D::Grad)>, Vec<Video<f32>>), FitError> {
        let spf = self.sim.setup.substeps_per_frame;
        let need = self.needed();
        let nframes = self.time.sim_frames;
        let substeps = nframes as u64 * spf as u64;
        let error: RefCell<Option<FitError>> = RefCell::new(None);
        let renders: RefCell<Vec<Option<Vec<Vec<f32>>>>> = RefCell::new(vec![None; nframes + 1]);
        renders.borrow_mut()[0] = Some(self.render_state(&read(init)?, "frame 0")?);
        let render_frame = |f: usize, s: &D::State| {
            if need[f] && error.borrow().is_none() {
                let r =
                    read(s).and_then(|fr| self.render_state(&fr, &format!("simulated frame {f}")));
                match r {
                    Ok(r) => renders.borrow_mut()[f] = Some(r),
                    Err(e) => first_err(&error, e),
                }
            }
        };
        if !grad {
            let mut s = init.clone();
            for j in 0..substeps {
                d.step(&mut s, params, j);
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
        let mut frame_buf: Vec<f32> = Vec::new();
        let (_, adj0, g) = value_and_grad(
            d,
            init,
            params,
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
                let mut any = false;
                for (v, gv) in gs.iter().enumerate() {
                    frame_buf.resize(self.problem.views[v].video.frame_len(), 0.0);
                    if self.frame_grad(gv, f, &mut frame_buf) {
                        d_rgb.push(frame_buf.clone());
                        any = true;
                    } else {
                        d_rgb.push(Vec::new());
                    }
                }
                if !any {
                    return;
                }
                let r = read(s)
                    .and_then(|fr| self.render_vjp(&fr, &d_rgb))
                    .and_then(|fg| add(adj, &fg));
                if let Err(e) = r {
                    first_err(&error, e);
                }
            },
        );
        if let Some(e) = error.borrow_mut().take() {
            return Err(e);
        }
        let ev = match eval_out.borrow_mut().take() {
            Some(ev) => ev,
            None => {
                let videos = self.assemble_take(&mut renders.borrow_mut())?;
                self.loss(&videos, None)?
            }
        };
        Ok((ev, Some((adj0, g)), Vec::new()))
    }
}

/// What a run returns: the loss, the parameter gradient (when asked) and the rendered videos
/// (forward-only runs).
type RunOut = (Evaluation, Option<Vec<PhysParams<f64>>>, Vec<Video<f32>>);

/// A simulated frame on the host: positions and row-major deformation gradients.
struct Frame {
    x: Vec<[f32; 3]>,
    f: Vec<[f32; 9]>,
}

/// A frame's rendering gradient with respect to positions and deformation gradients.
struct FrameGrad {
    x: Vec<[f64; 3]>,
    f: Vec<[f64; 9]>,
}

fn to_f64<T: Real>(p: &PhysParams<T>) -> PhysParams<f64> {
    PhysParams {
        youngs_modulus: p.youngs_modulus.f64(),
        poisson_ratio: p.poisson_ratio.f64(),
        yield_stress: p.yield_stress.f64(),
        plastic_viscosity: p.plastic_viscosity.f64(),
        friction_angle_deg: p.friction_angle_deg.f64(),
        density: p.density.f64(),
    }
}

/// A non-finite parameter gradient is an error.
fn check_grad(g: Option<Vec<PhysParams<f64>>>) -> Result<Option<Vec<PhysParams<f64>>>, FitError> {
    if let Some(g) = &g {
        if g.iter().any(|p| {
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
    }
    Ok(g)
}
