//! A video-fitting problem (scene, particles, parts, cameras, reference videos) and its
//! objective: simulate, render every view, evaluate the DMS loss, and differentiate all of it
//! back to the parameters of every part.
//!
//! # Time
//! Video frame `k` is at `t = k / fps`; simulation frame `j` (after `j x substeps_per_frame`
//! substeps, frame 0 the rest state) at `t = j x frame_dt`. When the two grids differ the
//! rendered video is resampled linearly in time between the two nearest simulated frames
//! ([`TimeMap`]), and the gradient is split back with the same weights.

use crate::compute::{Compute, Precision};
use crate::FitError;
use crate::{HeapProbe, HeapSpan};
use r4d_loss::bands::ReferenceVideo;
use r4d_loss::ssim::ms_ssim;
use r4d_loss::{BandedLoss, DmsConfig, DmsTerms, MsSsimConfig, Video, VideoLoss};
use r4d_mpm::adjoint::checkpoint::{value_and_grad, Checkpointing, Differentiable};
use r4d_mpm::adjoint::host::{HostSim, PhysParams};
use r4d_mpm::kernels::AnyBuf;
use r4d_mpm::simulation::AnyState;
use r4d_mpm::DynSimulation;
use r4d_mpm::{PartParams, ParticleSet, SimConfig};
use r4d_splat::{
    Camera, Deformation, Gaussians, PreparedFrame, RenderSettings, Renderer, SceneHandle, SimLink,
};
use serde::Serialize;
use std::cell::RefCell;
use std::ops::Range;
use std::sync::{Arc, Mutex};
use std::time::Instant;

/// One camera and the reference video seen from it.
#[derive(Clone, Debug)]
pub struct View {
    /// Label for messages (file name).
    pub name: String,
    /// The camera.
    pub camera: Camera,
    /// The reference video `(T, H, W, 3)`, same size as the camera (8-bit sources are kept
    /// as bytes: `ReferenceVideo::from(video)` picks the compact form).
    pub video: ReferenceVideo,
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
    /// Where the simulation (forward and reverse) and the rendering run (the loss runs on
    /// the host): any backend ([`Compute`]; [`crate::compute::ReferenceCompute`] without a
    /// backend crate, the `resonance4d` facade's `compute::cpu()` / `compute::wgpu()`).
    pub compute: Arc<dyn Compute>,
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
                    // Saturating: a frame rate so low that the frame index overflows is
                    // refused by the objective's limit, not wrapped.
                    (j as usize, (j as usize).saturating_add(1), (s - j) as f32)
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
        self.settings
            .validate("render settings")
            .map_err(FitError::Input)?;
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
    /// Sum over views of the DMS total (one view: its DMS).
    pub total: f64,
    /// Terms per view.
    pub views: Vec<DmsTerms>,
}

/// Where the time and memory of the last evaluation went ([`Objective::profile`]). Peaks are
/// the process's live heap bytes at the highest point of each stage, read from the counting
/// allocator the caller supplies ([`Objective::heap`]; 0 without one); on a GPU, the
/// device's own accounting of its buffers ([`Compute::device_peak_bytes`]).
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct StageProfile {
    /// Forward simulation (with checkpointing), reading the frames back excluded.
    pub forward_s: f64,
    /// Rendering every band of every frame and view.
    pub render_s: f64,
    /// The DMS loss (value and, with a gradient, its gradient), band by band.
    pub loss_s: f64,
    /// The renderer's VJP, band by band.
    pub render_vjp_s: f64,
    /// Reverse sweep of the simulation (its recomputation included).
    pub backward_s: f64,
    /// Heap peak during the forward simulation.
    pub forward_peak_bytes: usize,
    /// Heap peak while rendering, evaluating and differentiating the loss.
    pub loss_peak_bytes: usize,
    /// Heap peak during the reverse sweep.
    pub backward_peak_bytes: usize,
    /// Device peak (simulation and rendering on the GPU), when one is used.
    pub device_peak_bytes: Option<u64>,
    /// Bytes copied from the host to the device during the evaluation (on a GPU).
    pub host_to_device_bytes: Option<u64>,
    /// Bytes copied from the device to the host during the evaluation (on a GPU).
    pub device_to_host_bytes: Option<u64>,
    /// Row bands per view.
    pub bands: usize,
}

/// The most simulated frames one evaluation may need (video frames mapped onto the
/// simulation's frame grid); more is refused by [`Objective::new`] before any work.
pub const MAX_SIMULATED_FRAMES: usize = 100_000;

/// The most substeps one evaluation may run ([`MAX_SIMULATED_FRAMES`]'s companion).
pub const MAX_SUBSTEPS: u64 = 10_000_000;

/// Prepared frames a view keeps for all its bands on a host backend by default
/// ([`Objective::frame_cache_bytes`]): at the paper's scale (300 000 Gaussians at 1080p,
/// about 37 MB a frame) 3 of 17 frames, which keeps the iteration under 1 GB of heap.
pub const DEFAULT_FRAME_CACHE_BYTES: usize = 128 << 20;

/// The heap the initialisation's candidates may hold together: as many are evaluated at once
/// as [`Objective::score_bytes`] fits in this (at least one, at most the pool's threads).
pub const INIT_MEMORY_BUDGET_BYTES: u64 = 1 << 30;

/// Row bands of the loss by default ([`Objective::set_band_rows`]).
pub const DEFAULT_BAND_ROWS: usize = 128;

/// The differentiable objective over the first `frames` video frames.
///
/// # Memory
/// The forward pass keeps only the simulated frames' positions and deformation gradients
/// (`12` floats per particle per frame). The loss is then evaluated in row bands of every
/// view ([`BandedLoss`]; the paper's DMS by default, [`r4d_loss::bands::BandedDms`]): every
/// frame is projected, depth-sorted and binned once per view ([`Renderer::prepare_frame`]:
/// 48 bytes per Gaussian and 4 per tile intersection, plus 36 per Gaussian for its projection
/// gradient when differentiating), each band of every frame only composited, its loss and
/// gradient evaluated, and the gradient pulled back through the band's compositing at once
/// (the projection's VJP once per frame after the last band), so no whole rendered video,
/// video gradient or f32 reference is held; 8-bit references stay bytes. The bands' pixels
/// are the whole frame's, so the result equals the whole-frame loss up to the rounding of the
/// sums.
pub struct Objective<'a> {
    problem: &'a VideoProblem,
    sim: Arc<HostSim>,
    time: TimeMap,
    loss: Arc<dyn VideoLoss>,
    /// Rows per band (a multiple of 16).
    band_rows: usize,
    /// One parameter slot per particle (else per part).
    per_particle: bool,
    /// Checkpointing of the reverse sweep.
    pub checkpointing: Checkpointing,
    /// Simulation precision where the backend has a choice (the CPU; a GPU simulates in
    /// f32).
    pub precision: Precision,
    /// Where it simulates and renders (from [`VideoProblem::compute`]).
    pub compute: Arc<dyn Compute>,
    /// Most bytes of prepared frames (projections, tile lists, projection gradients) a view
    /// keeps for all its bands; frames beyond it are projected again for each band that
    /// needs them (slower, the same values). `None`: [`DEFAULT_FRAME_CACHE_BYTES`] on a
    /// host backend (the frames are heap), no limit on a device backend (device memory).
    pub frame_cache_bytes: Option<usize>,
    /// Keep simulated frames on the device from the simulation to the rasterizer where the
    /// backend can ([`Compute::frames_on_device`]; default `true`). `false` reads every frame
    /// back to the host and uploads its deformation (the same numbers up to the rounding of
    /// the link's transform; for comparing the bytes moved).
    pub device_frames: bool,
    /// Evaluations run so far ([`Objective::evaluations`]).
    evals: std::sync::atomic::AtomicUsize,
    profile: Mutex<StageProfile>,
    /// Measures the heap peaks of [`Objective::profile`] (`None`: peaks are 0). The caller
    /// supplies it (the `r4d` binary: its counting allocator); the objective never touches a
    /// global counter.
    pub heap: Option<Arc<dyn HeapProbe>>,
}

fn first_err(slot: &RefCell<Option<FitError>>, e: FitError) {
    let mut s = slot.borrow_mut();
    if s.is_none() {
        *s = Some(e);
    }
}

/// A stage's heap measurement ([`Objective::heap`]; `None`: not measured).
type Stage = Option<Box<dyn HeapSpan>>;

/// The stage's peak (absolute live bytes; 0 when not measured).
fn stage_end(span: Stage) -> usize {
    span.map_or(0, |s| s.peak())
}

/// The settings of an [`Objective`] by name ([`Objective::builder`]).
#[derive(Clone)]
pub struct ObjectiveBuilder<'a> {
    problem: &'a VideoProblem,
    frames: Option<usize>,
    loss: Arc<dyn VideoLoss>,
    per_particle: bool,
}

impl<'a> ObjectiveBuilder<'a> {
    /// Only the first `n` video frames (default: all).
    pub fn frames(mut self, n: usize) -> Self {
        self.frames = Some(n);
        self
    }

    /// The paper's DMS with these settings (default: [`DmsConfig::default`]).
    pub fn dms(mut self, dms: &DmsConfig) -> Self {
        self.loss = Arc::new(dms.clone());
        self
    }

    /// Any row-banded video loss instead of the DMS.
    pub fn loss(mut self, loss: Arc<dyn VideoLoss>) -> Self {
        self.loss = loss;
        self
    }

    /// One parameter set per particle ([`Granularity::Particle`](crate::space::Granularity::Particle)) or per part (the others;
    /// the object level is the fit's choice of free parameters, not the objective's).
    pub fn granularity(mut self, g: crate::space::Granularity) -> Self {
        self.per_particle = g == crate::space::Granularity::Particle;
        self
    }

    /// The objective ([`Objective::with_loss`]'s checks).
    pub fn build(self) -> Result<Objective<'a>, FitError> {
        Objective::with_loss(self.problem, self.frames, self.loss, self.per_particle)
    }
}

impl<'a> Objective<'a> {
    /// Starts measuring a stage's heap peak with [`Objective::heap`].
    fn stage_begin(&self) -> Stage {
        self.heap.as_ref().map(|h| h.start())
    }

    /// The objective of `problem` with named settings: the paper's DMS on every video frame
    /// and part-level parameters unless [`ObjectiveBuilder`] says otherwise.
    ///
    /// ```no_run
    /// # fn f(problem: &r4d_optim::video::VideoProblem) -> Result<(), r4d_optim::FitError> {
    /// use r4d_optim::video::{Granularity, Objective};
    /// let obj = Objective::builder(problem).frames(8).granularity(Granularity::Particle).build()?;
    /// # Ok(()) }
    /// ```
    pub fn builder(problem: &'a VideoProblem) -> ObjectiveBuilder<'a> {
        ObjectiveBuilder {
            problem,
            frames: None,
            loss: Arc::new(DmsConfig::default()),
            per_particle: false,
        }
    }

    /// The objective of `problem` on its first `frames` video frames (all when `None`), with
    /// per-particle parameter slots when `per_particle`, on the DMS loss `dms` (the paper's).
    /// [`Objective::builder`] names these settings.
    pub fn new(
        problem: &'a VideoProblem,
        frames: Option<usize>,
        dms: &DmsConfig,
        per_particle: bool,
    ) -> Result<Self, FitError> {
        Self::with_loss(problem, frames, Arc::new(dms.clone()), per_particle)
    }

    /// As [`Objective::new`], on any video loss that splits by row bands ([`VideoLoss`]
    /// makes each view's [`BandedLoss`]; a [`DmsConfig`] makes the DMS).
    pub fn with_loss(
        problem: &'a VideoProblem,
        frames: Option<usize>,
        loss: Arc<dyn VideoLoss>,
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
        let substeps = (time.sim_frames as u64).saturating_mul(t.substeps() as u64);
        if time.sim_frames > MAX_SIMULATED_FRAMES || substeps > MAX_SUBSTEPS {
            return Err(FitError::Input(format!(
                "{frames} video frames at {} fps span {} simulated frames of {frame_dt} s ({substeps} substeps); the limits are {MAX_SIMULATED_FRAMES} frames and {MAX_SUBSTEPS} substeps (check the frame rate and the simulation's time step)",
                problem.fps, time.sim_frames
            )));
        }
        let mut obj = Objective {
            problem,
            sim: Arc::new(sim),
            time,
            loss,
            band_rows: DEFAULT_BAND_ROWS,
            per_particle,
            checkpointing: Checkpointing::PerFrame,
            precision: Precision::F64,
            compute: problem.compute.clone(),
            frame_cache_bytes: None,
            device_frames: true,
            evals: std::sync::atomic::AtomicUsize::new(0),
            profile: Mutex::new(StageProfile::default()),
            heap: None,
        };
        obj.set_band_rows(DEFAULT_BAND_ROWS)?;
        Ok(obj)
    }

    /// Evaluates the loss in bands of about `rows` rows (rounded up to a multiple of the
    /// 16-px patch and tile size). Smaller bands hold less memory (the rendered band video,
    /// its gradient and the loss's buffers) and composite the same pixels; the value does not
    /// change (up to rounding).
    pub fn set_band_rows(&mut self, rows: usize) -> Result<(), FitError> {
        self.band_rows = rows.max(1).div_ceil(16) * 16;
        // Each view's loss is made once here to refuse a bad reference or configuration
        // before any simulation; the evaluations make their own (the loss borrows the
        // reference for the evaluation only).
        for v in &self.problem.views {
            self.view_loss(v)?;
        }
        Ok(())
    }

    /// The loss of view `v` ([`Objective::with_loss`]'s [`VideoLoss`]) on the evaluated
    /// frames in bands of [`Objective::set_band_rows`] rows.
    fn view_loss<'v>(&self, v: &'v View) -> Result<Box<dyn BandedLoss + 'v>, FitError> {
        self.loss
            .banded(&v.video, self.time.taps.len(), self.band_rows)
            .map_err(|e| FitError::Input(format!("{}: reference video: {e}", v.name)))
    }

    /// The host simulator (its `slot` gives each particle's parameter slot).
    pub fn sim(&self) -> &HostSim {
        &self.sim
    }

    /// Time and memory of the stages of the last evaluation.
    pub fn profile(&self) -> StageProfile {
        self.profile.lock().map(|p| p.clone()).unwrap_or_default()
    }

    /// The part of every parameter slot.
    pub fn slot_parts(&self) -> Vec<u32> {
        if self.per_particle {
            self.sim.part.clone()
        } else {
            (0..self.problem.config.parts.len() as u32).collect()
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
        self.dispatch(slots, Mode::RenderOnly).map(|r| r.2)
    }

    /// Simulates and renders every view and evaluates the loss (no gradient).
    pub fn render_and_value(
        &self,
        slots: &[PartParams],
    ) -> Result<(Evaluation, Vec<Video<f32>>), FitError> {
        self.dispatch(slots, Mode::Render).map(|r| (r.0, r.2))
    }

    /// The initialisation's score: MS-SSIM of every view's rendered video against its
    /// reference, mean over frames, then over views (equal to [`ms_ssim_score`] of
    /// [`Objective::render`]'s videos). Each video frame is rendered and compared as soon as
    /// the simulation has produced it, so no whole video is held: the memory is the
    /// simulation's and one frame's, whatever the number of frames.
    ///
    /// [`ms_ssim_score`]: crate::video::fit::ms_ssim_score
    pub fn ms_ssim(&self, slots: &[PartParams]) -> Result<f64, FitError> {
        self.dispatch(slots, Mode::Score).map(|r| r.0.total)
    }

    /// A generous estimate of the host memory one [`Objective::ms_ssim`] call holds: the
    /// stored frames (48 bytes per particle and frame), the simulation's state and grids
    /// (256 bytes per particle, 64 per grid node), one frame's projection (64 bytes per
    /// Gaussian) and, for the largest view, its render, reference and MS-SSIM planes
    /// (34 bytes per pixel channel).
    pub fn score_bytes(&self) -> u64 {
        let n = self.sim.len() as u64;
        let frames = self.needed().iter().filter(|&&b| b).count() as u64;
        let nodes = (self.sim.setup.n as u64).pow(3);
        let pixels = self
            .problem
            .views
            .iter()
            .map(|v| (v.video.height() * v.video.width()) as u64)
            .max()
            .unwrap_or(0);
        frames * n * 48
            + n * 256
            + nodes * 64
            + self.problem.scene.len() as u64 * 64
            + pixels * 3 * 34
    }

    /// How many initialisation candidates may run at once: as many [`Objective::score_bytes`]
    /// as fit in [`INIT_MEMORY_BUDGET_BYTES`], at least one.
    pub fn init_concurrency(&self) -> usize {
        (INIT_MEMORY_BUDGET_BYTES / self.score_bytes().max(1)).max(1) as usize
    }

    /// The loss (no gradient).
    pub fn value(&self, slots: &[PartParams]) -> Result<Evaluation, FitError> {
        self.dispatch(slots, Mode::Value).map(|r| r.0)
    }

    /// The loss and its gradient with respect to every slot's parameters.
    pub fn value_and_grad(
        &self,
        slots: &[PartParams],
    ) -> Result<(Evaluation, Vec<PhysParams<f64>>), FitError> {
        let r = self.dispatch(slots, Mode::Grad)?;
        Ok((r.0, r.1.expect("gradient requested")))
    }

    /// Simulations this objective has run (every value, value and gradient, score and
    /// render, failed ones included): what a fit's evaluation budget counts.
    pub fn evaluations(&self) -> usize {
        self.evals.load(std::sync::atomic::Ordering::Relaxed)
    }

    /// Runs on the objective's backend ([`Objective::compute`]).
    fn dispatch(&self, slots: &[PartParams], mode: Mode) -> Result<RunOut, FitError> {
        for (i, p) in slots.iter().enumerate() {
            p.validate(&format!("parameters of slot {i}"))?;
        }
        self.evals
            .fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        self.compute.reset_device_peak();
        let before = self.compute.device_memory();
        let r = self.run_on(slots, mode);
        let after = self.compute.device_memory();
        if let Ok(mut p) = self.profile.lock() {
            p.device_peak_bytes = self.compute.device_peak_bytes();
            if let (Some(a), Some(b)) = (after, before) {
                p.host_to_device_bytes = Some(a.uploaded_bytes.saturating_sub(b.uploaded_bytes));
                p.device_to_host_bytes =
                    Some(a.downloaded_bytes.saturating_sub(b.downloaded_bytes));
            }
        }
        r
    }

    /// Runs on the objective's backend: the simulation and its reverse sweep on its
    /// [`Compute::simulation`]. On a host backend each frame's positions and deformation
    /// gradients are read for the renderer and the loss, and the loss's gradient is added to
    /// the adjoint state from the host; on a device backend ([`Objective::on_device`]) frames
    /// and their gradients stay there ([`DynSimulation::frame_buffers`],
    /// [`Renderer::prepare_frame_linked`], [`DynSimulation::add_buffers`]).
    fn run_on(&self, slots: &[PartParams], mode: Mode) -> Result<RunOut, FitError> {
        let d = self.compute.simulation(self.precision, self.sim.clone())?;
        let d: &dyn DynSimulation = &*d;
        let name = d.backend_name();
        let err = |e| FitError::sim(name, e);
        let phys = d.params(slots);
        let init = d
            .init(&phys, &vec![[0.0; 3]; self.sim.len()])
            .map_err(err)?;
        let grad0 = d.zero_grad().map_err(err)?;
        let on_device = self.on_device();
        // Positions to the host, converted before the deformation gradients are read back.
        let host_x = |s: &AnyState| -> Result<Vec<[f32; 3]>, FitError> {
            let x = d.positions_f64(s).map_err(err)?;
            Ok(x.iter().map(|p| p.map(|c| c as f32)).collect())
        };
        let read = |j: usize, s: &AnyState| -> Result<Frame, FitError> {
            let what = format!("simulated frame {j}");
            if on_device {
                // The frame stays on the device; the domain is checked from the substeps'
                // health record (a few bytes), and the positions are read back only for the
                // initial state or when the record holds a problem.
                let code = d.take_health_code().map_err(err)?;
                if j == 0 || code != 0 {
                    self.check_domain(&host_x(s)?, &what)?;
                }
                let (x, f) = d.frame_buffers(s).map_err(err)?;
                return Ok(Frame::Device { x, f });
            }
            let x = host_x(s)?;
            self.check_domain(&x, &what)?;
            let f = d.deformation_gradients_f64(s).map_err(err)?;
            let f = f.iter().map(|m| m.map(|c| c as f32)).collect();
            Ok(Frame::Host { x, f })
        };
        let add = |adj: &mut AnyState, g: &FrameGrad| -> Result<(), FitError> {
            match g {
                FrameGrad::Host { x, f } => {
                    let x: Vec<[f64; 3]> = x.iter().map(|p| p.map(f64::from)).collect();
                    let f: Vec<[f64; 9]> = f.iter().map(|m| m.map(f64::from)).collect();
                    d.add_to_x(adj, &x).map_err(err)?;
                    d.add_to_f(adj, &f).map_err(err)
                }
                FrameGrad::Device(parts) => {
                    for (x, f) in parts {
                        d.add_buffers(adj, x, f).map_err(err)?;
                    }
                    Ok(())
                }
            }
        };
        let (ev, back, videos) = self.run_with(name, d, &init, &phys, grad0, mode, &read, &add)?;
        let g = match back {
            Some((adj0, g)) => Some(d.gradient(&g, &adj0, &phys).map_err(err)?),
            None => None,
        };
        Ok((ev, check_grad(g)?, videos))
    }

    /// Runs `f` with the renderer of this objective's backend.
    /// The prepared-frame budget in force ([`Objective::frame_cache_bytes`]).
    fn frame_cache_budget(&self) -> usize {
        match (self.frame_cache_bytes, self.compute.device_peak_bytes()) {
            (Some(b), _) => b,
            (None, Some(_)) => usize::MAX,
            (None, None) => DEFAULT_FRAME_CACHE_BYTES,
        }
    }

    fn with_renderer<R>(
        &self,
        f: impl FnOnce(&mut dyn Renderer) -> Result<R, FitError>,
    ) -> Result<R, FitError> {
        let mut f = Some(f);
        let mut out = None;
        self.compute.with_renderer(&mut |r| {
            if let Some(f) = f.take() {
                out = Some(f(r)?);
            }
            Ok(())
        })?;
        out.ok_or_else(|| {
            FitError::backend_msg(
                self.compute.name(),
                "with_renderer did not call the renderer",
            )
        })
    }

    /// Whether frames stay on the backend's device between the simulation and the renderer:
    /// [`Objective::device_frames`] and a backend that can ([`Compute::frames_on_device`]).
    fn on_device(&self) -> bool {
        self.device_frames && self.compute.frames_on_device()
    }

    /// Renders one simulated frame from `cam` (a view's camera).
    fn render_frame(
        &self,
        handle: &mut Option<SceneHandle>,
        s: &Frame,
        cam: &Camera,
        what: &str,
    ) -> Result<Vec<f32>, FitError> {
        match s {
            Frame::Host { .. } => {
                let d = self.deformation(s, what)?;
                self.with_renderer(|r| {
                    r.render(&self.problem.scene, Some(&d), cam, &self.problem.settings)
                        .map(|img| img.rgb)
                        .map_err(FitError::from)
                })
            }
            Frame::Device { .. } => {
                let p = self.prepare_frame(handle, s, cam, what)?;
                let rows = 0..p.size().1;
                self.render_rows(&p, rows)
            }
        }
    }

    /// An exploded simulation: a particle (positions `x`) outside the grid's interior or
    /// non-finite.
    fn check_domain(&self, x: &[[f32; 3]], what: &str) -> Result<(), FitError> {
        let setup = &self.sim.setup;
        let inv_dx = 1.0 / setup.dx;
        let hi = setup.n as f64 - 1.5;
        if let Some(i) = x.iter().position(|p| {
            !p.iter().all(|&c| {
                let g = c as f64 * inv_dx;
                g.is_finite() && (0.5..hi).contains(&g)
            })
        }) {
            return Err(FitError::Exploded(format!("{what}: particle {i}")));
        }
        Ok(())
    }

    /// The deformation of the scene by a host frame.
    fn deformation(&self, s: &Frame, what: &str) -> Result<Deformation, FitError> {
        let Frame::Host { x, f } = s else {
            return Err(FitError::backend_msg(
                self.compute.name(),
                "a device frame has no host deformation",
            ));
        };
        let f: Vec<[[f32; 3]; 3]> = f
            .iter()
            .map(|m| [[m[0], m[1], m[2]], [m[3], m[4], m[5]], [m[6], m[7], m[8]]])
            .collect();
        Ok(self
            .problem
            .link
            .deformation(&self.problem.scene, x, Some(&f), what)?)
    }

    /// The scene kept on the renderer's device for one evaluation's frames
    /// ([`Renderer::upload_scene`]), made on first use; `None` on a host backend, whose
    /// frames read the scene in place.
    fn scene_on_device<'h>(
        &self,
        handle: &'h mut Option<SceneHandle>,
    ) -> Result<Option<&'h mut SceneHandle>, FitError> {
        if self.compute.device_memory().is_none() {
            return Ok(None);
        }
        if handle.is_none() {
            let link = &self.problem.link;
            let linked = self.on_device();
            let h = self.with_renderer(|r| {
                let mut h = r.upload_scene(&self.problem.scene)?;
                if linked {
                    r.link_scene(&mut h, link)?;
                }
                Ok(h)
            })?;
            *handle = Some(h);
        }
        Ok(handle.as_mut())
    }

    /// Projects, sorts and bins one simulated frame for the whole image of `cam`
    /// ([`Renderer::prepare_frame`]; on a device backend from the scene kept there,
    /// `handle`).
    fn prepare_frame(
        &self,
        handle: &mut Option<SceneHandle>,
        s: &Frame,
        cam: &Camera,
        what: &str,
    ) -> Result<PreparedFrame, FitError> {
        let settings = &self.problem.settings;
        if let Frame::Device { x, f } = s {
            let h = self.scene_on_device(handle)?.ok_or_else(|| {
                FitError::backend_msg(self.compute.name(), "a device frame without a device")
            })?;
            return self.with_renderer(|r| {
                r.prepare_frame_linked(h, x, f, cam, settings)
                    .map_err(FitError::from)
            });
        }
        let d = self.deformation(s, what)?;
        match self.scene_on_device(handle)? {
            Some(h) => self.with_renderer(|r| {
                r.prepare_frame_on(h, &d, cam, settings)
                    .map_err(FitError::from)
            }),
            None => self.with_renderer(|r| {
                r.prepare_frame(&self.problem.scene, Some(&d), cam, settings)
                    .map_err(FitError::from)
            }),
        }
    }

    /// Rows `rows` of a prepared frame's colour image.
    fn render_rows(&self, p: &PreparedFrame, rows: Range<u32>) -> Result<Vec<f32>, FitError> {
        self.with_renderer(|r| {
            r.render_rows(p, rows)
                .map(|img| img.rgb)
                .map_err(FitError::from)
        })
    }

    /// Adds the VJP of rows `rows` of a prepared frame for `d_rgb` to its projection
    /// gradient.
    fn render_rows_vjp(
        &self,
        p: &mut PreparedFrame,
        rows: Range<u32>,
        d_rgb: &[f32],
    ) -> Result<(), FitError> {
        self.with_renderer(|r| r.render_rows_vjp(p, rows, d_rgb).map_err(FitError::from))
    }

    /// Adds the gradient of the rows VJPs added to `p` (frame `s`'s) with respect to the
    /// particles' positions and deformation gradients (simulation space) to `out`.
    fn frame_vjp_into(
        &self,
        handle: &mut Option<SceneHandle>,
        s: &Frame,
        p: PreparedFrame,
        out: &mut FrameGrad,
    ) -> Result<(), FitError> {
        if let Frame::Device { x, f } = s {
            let h = self.scene_on_device(handle)?.ok_or_else(|| {
                FitError::backend_msg(self.compute.name(), "a device frame without a device")
            })?;
            let g =
                self.with_renderer(|r| r.frame_vjp_linked(p, h, x, f).map_err(FitError::from))?;
            return match out {
                FrameGrad::Device(parts) => {
                    parts.push(g);
                    Ok(())
                }
                FrameGrad::Host { .. } => Err(FitError::backend_msg(
                    self.compute.name(),
                    "a device frame's gradient into a host gradient",
                )),
            };
        }
        let FrameGrad::Host { x: out_x, f: out_f } = out else {
            return Err(FitError::backend_msg(
                self.compute.name(),
                "a host frame's gradient into a device gradient",
            ));
        };
        let d = self.deformation(s, "reverse sweep")?;
        let gr = match self.scene_on_device(handle)? {
            Some(h) => {
                self.with_renderer(|r| r.frame_vjp_motion_on(p, h, &d).map_err(FitError::from))?
            }
            None => self.with_renderer(|r| {
                r.frame_vjp_motion(p, &self.problem.scene, &d)
                    .map_err(FitError::from)
            })?,
        };
        drop(d);
        Ok(self.problem.link.deformation_vjp(&gr, out_x, out_f)?)
    }

    /// For each of `n` simulated frames, the last video frame (tap) that reads it
    /// (`usize::MAX` for none).
    fn last_uses(&self, n: usize) -> Vec<usize> {
        let mut last_use = vec![usize::MAX; n];
        for (k, &(j0, j1, a)) in self.time.taps.iter().enumerate() {
            last_use[j0] = k;
            if a != 0.0 {
                last_use[j1] = k;
            }
        }
        last_use
    }

    /// A video (or a band of one, `len` values per frame) from per-simulated-frame renders
    /// through the time map, moving frames out of `frames` (each freed once no later video
    /// frame needs it).
    fn assemble(&self, frames: &mut [Option<Vec<f32>>], len: usize) -> Vec<f32> {
        let taps = &self.time.taps;
        let last_use = self.last_uses(frames.len());
        let mut get = |j: usize, k: usize| -> Vec<f32> {
            if last_use[j] == k {
                frames[j].take().expect("rendered frame")
            } else {
                frames[j].clone().expect("rendered frame")
            }
        };
        let mut data = Vec::with_capacity(taps.len() * len);
        for (k, &(j0, j1, a)) in taps.iter().enumerate() {
            let f0 = get(j0, k);
            if a == 0.0 {
                data.extend_from_slice(&f0);
            } else {
                let f1 = get(j1, k);
                data.extend(f0.iter().zip(&f1).map(|(x, y)| x + a * (y - x)));
            }
        }
        data
    }

    /// `dL/d(rendered frame j)` from the gradient of a video (`gv`, the video's layout, frames
    /// of `out.len()` values), through the time map. False when frame `j` is not used.
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

    /// [`Mode::Score`]: per view, each video frame composed from its simulated frames' renders
    /// (through the time map) and compared with the reference frame by MS-SSIM; a render is
    /// dropped after the last video frame that uses it. The mean over frames, then over
    /// views, summed in the order [`crate::video::fit::ms_ssim_score`] sums them.
    fn score_frames(&self, frames: &[Option<Frame>]) -> Result<f64, FitError> {
        let taps = &self.time.taps;
        let last_use = self.last_uses(frames.len());
        let mut sum = 0.0;
        let mut handle: Option<SceneHandle> = None;
        for v in &self.problem.views {
            let (h, w) = (v.video.height(), v.video.width());
            let cfg = ms_ssim_config(&v.name, h, w)?;
            let mut renders: Vec<Option<Vec<f32>>> = (0..frames.len()).map(|_| None).collect();
            let mut per_frame = 0.0;
            for (k, &(j0, j1, a)) in taps.iter().enumerate() {
                let used: &[usize] = if a == 0.0 { &[j0] } else { &[j0, j1] };
                for &j in used {
                    if renders[j].is_none() {
                        let what = format!("simulated frame {j}");
                        let f = frames[j]
                            .as_ref()
                            .ok_or_else(|| FitError::Input(format!("{what} was not stored")))?;
                        renders[j] = Some(self.render_frame(&mut handle, f, &v.camera, &what)?);
                    }
                }
                let f0 = renders[j0].as_deref().expect("rendered above");
                let data: Vec<f32> = if a == 0.0 {
                    f0.to_vec()
                } else {
                    let f1 = renders[j1].as_deref().expect("rendered above");
                    f0.iter().zip(f1).map(|(x, y)| x + a * (y - x)).collect()
                };
                for &j in used {
                    if last_use[j] == k {
                        renders[j] = None;
                    }
                }
                let rendered =
                    Video::new(1, h, w, data).map_err(|e| FitError::Input(e.to_string()))?;
                let reference = Video::from_frames(h, w, std::iter::once(v.video.frame_f32(k)))?;
                per_frame += ms_ssim(&rendered, &reference, &cfg)?.per_frame[0];
            }
            sum += per_frame / taps.len() as f64;
        }
        Ok(sum / self.problem.views.len().max(1) as f64)
    }

    /// Renders every view at full size from the stored frames (forward-only runs).
    fn render_videos(&self, frames: &[Option<Frame>]) -> Result<Vec<Video<f32>>, FitError> {
        let mut out = Vec::new();
        let mut handle: Option<SceneHandle> = None;
        for v in &self.problem.views {
            let (h, w) = (v.video.height(), v.video.width());
            let mut renders: Vec<Option<Vec<f32>>> = frames
                .iter()
                .enumerate()
                .map(|(j, f)| {
                    f.as_ref()
                        .map(|f| {
                            let what = format!("simulated frame {j}");
                            self.render_frame(&mut handle, f, &v.camera, &what)
                        })
                        .transpose()
                })
                .collect::<Result<_, _>>()?;
            let data = self.assemble(&mut renders, h * w * 3);
            out.push(
                Video::new(self.time.taps.len(), h, w, data)
                    .map_err(|e| FitError::Input(e.to_string()))?,
            );
        }
        Ok(out)
    }

    /// The DMS of every view, band by band. Per view, every needed frame is projected, sorted
    /// and binned once ([`Renderer::prepare_frame`]); each band of every frame is then only
    /// composited ([`Renderer::render_rows`]; or cut out of `videos` when given), its terms
    /// evaluated and, with `grads`, its gradient pulled back through the time map and the
    /// band's compositing into the frame's projection gradient
    /// ([`Renderer::render_rows_vjp`]); after the last band the projection's VJP runs once per
    /// frame ([`Renderer::frame_vjp`]) into the per-frame gradients. Returns the sum over
    /// views.
    fn banded_loss(
        &self,
        frames: &[Option<Frame>],
        videos: Option<&[Video<f32>]>,
        mut grads: Option<&mut [Option<FrameGrad>]>,
        prof: &mut StageProfile,
    ) -> Result<Evaluation, FitError> {
        let mut ev = Evaluation::default();
        let nt = self.time.taps.len();
        let n = self.sim.len();
        prof.bands = 0;
        // The scene on the renderer's device for this evaluation's frames.
        let mut handle: Option<SceneHandle> = None;
        for (v, view) in self.problem.views.iter().enumerate() {
            let dms = self.view_loss(view)?;
            let band_rows = dms.band_rows();
            prof.bands = prof.bands.max(band_rows.len());
            let w = view.video.width();
            let mut terms = DmsTerms::default();
            let t0 = Instant::now();
            // Frames prepared once for every band, in order while they fit the budget (each
            // frame's size estimated by the one before it); the others are prepared again
            // for each band that needs them.
            let mut prepared: Vec<Option<PreparedFrame>> =
                (0..frames.len()).map(|_| None).collect();
            if videos.is_none() {
                let budget = self.frame_cache_budget();
                let (mut used, mut next) = (0usize, 0usize);
                for (j, f) in frames.iter().enumerate() {
                    let Some(f) = f else { continue };
                    if used.saturating_add(next) > budget {
                        break;
                    }
                    let what = format!("simulated frame {j}");
                    let p = self.prepare_frame(&mut handle, f, &view.camera, &what)?;
                    next = p.bytes();
                    used = used.saturating_add(next);
                    prepared[j] = Some(p);
                }
            }
            prof.render_s += t0.elapsed().as_secs_f64();
            // Frames whose projection gradient received a band's VJP.
            let mut pulled = vec![false; frames.len()];
            for (b, rows) in band_rows.into_iter().enumerate() {
                let len = rows.len() * w * 3;
                let rows32 = rows.start as u32..rows.end as u32;
                let t0 = Instant::now();
                let data = match videos {
                    Some(vs) => {
                        let mut d = Vec::with_capacity(nt * len);
                        for t in 0..nt {
                            d.extend_from_slice(
                                &vs[v].frame(t)[rows.start * w * 3..rows.end * w * 3],
                            );
                        }
                        d
                    }
                    None => {
                        let mut renders: Vec<Option<Vec<f32>>> = prepared
                            .iter()
                            .zip(frames)
                            .enumerate()
                            .map(|(j, (p, f))| match (p, f) {
                                (Some(p), _) => self.render_rows(p, rows32.clone()).map(Some),
                                (None, Some(f)) => {
                                    let what = format!("simulated frame {j}");
                                    let p =
                                        self.prepare_frame(&mut handle, f, &view.camera, &what)?;
                                    self.render_rows(&p, rows32.clone()).map(Some)
                                }
                                (None, None) => Ok(None),
                            })
                            .collect::<Result<_, _>>()?;
                        self.assemble(&mut renders, len)
                    }
                };
                let video = Video::new(nt, rows.len(), w, data)
                    .map_err(|e| FitError::Input(e.to_string()))?;
                let t1 = Instant::now();
                prof.render_s += (t1 - t0).as_secs_f64();
                match grads.as_deref_mut() {
                    None => {
                        let t = dms.band_terms(b, &video)?;
                        prof.loss_s += t1.elapsed().as_secs_f64();
                        terms.add(&t);
                    }
                    Some(_) => {
                        let mut g = vec![0.0f32; video.data().len()];
                        let t = dms.band_terms_and_grad_into(b, &video, &mut g)?;
                        drop(video);
                        terms.add(&t);
                        let t2 = Instant::now();
                        prof.loss_s += (t2 - t1).as_secs_f64();
                        let mut buf = vec![0.0f32; len];
                        for (j, p) in prepared.iter_mut().enumerate() {
                            let Some(f) = &frames[j] else { continue };
                            if !self.frame_grad(&g, j, &mut buf) || buf.iter().all(|&x| x == 0.0) {
                                continue;
                            }
                            match p {
                                Some(p) => {
                                    self.render_rows_vjp(p, rows32.clone(), &buf)?;
                                    pulled[j] = true;
                                }
                                None => {
                                    // Not kept: prepared again, this band's VJP pulled
                                    // through its projection at once.
                                    let what = format!("simulated frame {j}");
                                    let mut q =
                                        self.prepare_frame(&mut handle, f, &view.camera, &what)?;
                                    self.render_rows_vjp(&mut q, rows32.clone(), &buf)?;
                                    let gs = grads.as_deref_mut().expect("in the gradient branch");
                                    let acc = gs[j].get_or_insert_with(|| FrameGrad::zeros(f, n));
                                    self.frame_vjp_into(&mut handle, f, q, acc)?;
                                }
                            }
                        }
                        prof.render_vjp_s += t2.elapsed().as_secs_f64();
                    }
                }
            }
            if let Some(gs) = grads.as_deref_mut() {
                let t0 = Instant::now();
                for (j, p) in prepared.iter_mut().enumerate() {
                    let (Some(f), true) = (&frames[j], pulled[j]) else {
                        continue;
                    };
                    let p = p.take().expect("pulled frames are kept");
                    let acc = gs[j].get_or_insert_with(|| FrameGrad::zeros(f, n));
                    self.frame_vjp_into(&mut handle, f, p, acc)?;
                }
                prof.render_vjp_s += t0.elapsed().as_secs_f64();
            }
            ev.total += terms.total;
            ev.views.push(terms);
        }
        if !ev.total.is_finite() {
            return Err(FitError::NonFinite("the loss".into()));
        }
        Ok(ev)
    }

    /// Forward (and in [`Mode::Grad`] the reverse sweep) on stepper `d`: `read` brings a
    /// state's positions and deformation gradients to the host, `add` adds a frame's
    /// rendering gradient to an adjoint state. Returns the rendered videos in
    /// [`Mode::Render`], and in [`Mode::Grad`] the initial state's adjoint and the parameter
    /// gradient.
    #[allow(clippy::too_many_arguments, clippy::type_complexity)]
    fn run_with<D: Differentiable + ?Sized>(
        &self,
        name: &str,
        d: &D,
        init: &D::State,
        params: &D::Params,
        grad0: D::Grad,
        mode: Mode,
        read: &dyn Fn(usize, &D::State) -> Result<Frame, FitError>,
        add: &dyn Fn(&mut D::State, &FrameGrad) -> Result<(), FitError>,
    ) -> Result<(Evaluation, Option<(D::State, D::Grad)>, Vec<Video<f32>>), FitError> {
        let spf = self.sim.setup.substeps_per_frame;
        let need = self.needed();
        let nframes = self.time.sim_frames;
        let substeps = nframes as u64 * spf as u64;
        let error: RefCell<Option<FitError>> = RefCell::new(None);
        let prof = RefCell::new(StageProfile::default());
        let read_time = RefCell::new(0.0f64);
        let stored: RefCell<Vec<Option<Frame>>> =
            RefCell::new((0..=nframes).map(|_| None).collect());
        let store = |f: usize, s: &D::State| {
            if need[f] && error.borrow().is_none() {
                let t = Instant::now();
                let r = read(f, s);
                *read_time.borrow_mut() += t.elapsed().as_secs_f64();
                match r {
                    Ok(fr) => stored.borrow_mut()[f] = Some(fr),
                    Err(e) => first_err(&error, e),
                }
            }
        };
        let t_start = Instant::now();
        let saved = self.stage_begin();
        store(0, init);
        let sim_err = |e: D::Error| FitError::backend(name, e);
        if mode != Mode::Grad {
            let mut s = d.clone_state(init).map_err(sim_err)?;
            for j in 0..substeps {
                d.step(&mut s, params, j).map_err(sim_err)?;
                if (j + 1) % spf as u64 == 0 {
                    store(((j + 1) / spf as u64) as usize, &s);
                    if let Some(e) = error.borrow_mut().take() {
                        stage_end(saved);
                        return Err(e);
                    }
                }
            }
            drop(s);
            let mut p = prof.borrow_mut();
            p.forward_peak_bytes = stage_end(saved);
            p.forward_s = t_start.elapsed().as_secs_f64() - *read_time.borrow();
            let saved = self.stage_begin();
            let frames = std::mem::take(&mut *stored.borrow_mut());
            let r = if mode == Mode::Score {
                let t = Instant::now();
                let score = self.score_frames(&frames);
                p.render_s += t.elapsed().as_secs_f64();
                score.map(|total| {
                    let ev = Evaluation {
                        total,
                        views: Vec::new(),
                    };
                    (ev, None, Vec::new())
                })
            } else if mode != Mode::Value {
                let t = Instant::now();
                let videos = self.render_videos(&frames);
                p.render_s += t.elapsed().as_secs_f64();
                videos.and_then(|videos| {
                    let ev = if mode == Mode::Render {
                        self.banded_loss(&frames, Some(&videos), None, &mut p)?
                    } else {
                        Evaluation::default()
                    };
                    Ok((ev, None, videos))
                })
            } else {
                self.banded_loss(&frames, None, None, &mut p)
                    .map(|ev| (ev, None, Vec::new()))
            };
            p.loss_peak_bytes = stage_end(saved);
            self.save_profile(&p);
            return r;
        }
        // Reverse mode: the forward pass stores the frames; once the last frame is reached
        // (before the reverse sweep allocates its inner checkpoints) the loss is evaluated
        // band by band, each band's gradient pulled back to dL/dx, dL/dF of every frame, and
        // the reverse sweep adds them frame by frame.
        let frame_grads: RefCell<Option<Vec<Option<FrameGrad>>>> = RefCell::new(None);
        let eval_out: RefCell<Option<Evaluation>> = RefCell::new(None);
        let stage: RefCell<(Stage, Instant)> = RefCell::new((saved, t_start));
        let loss_stage = || {
            if frame_grads.borrow().is_some() || error.borrow().is_some() {
                return;
            }
            let mut p = prof.borrow_mut();
            let (saved, t0) = {
                let mut st = stage.borrow_mut();
                (st.0.take(), st.1)
            };
            p.forward_peak_bytes = stage_end(saved);
            p.forward_s = t0.elapsed().as_secs_f64() - *read_time.borrow();
            let saved = self.stage_begin();
            let frames = std::mem::take(&mut *stored.borrow_mut());
            let mut gs: Vec<Option<FrameGrad>> = (0..frames.len()).map(|_| None).collect();
            let r = self.banded_loss(&frames, None, Some(&mut gs), &mut p);
            drop(frames);
            p.loss_peak_bytes = stage_end(saved);
            *stage.borrow_mut() = (self.stage_begin(), Instant::now());
            match r {
                Ok(ev) => {
                    *eval_out.borrow_mut() = Some(ev);
                    *frame_grads.borrow_mut() = Some(gs);
                }
                Err(e) => first_err(&error, e),
            }
        };
        let (_, adj0, g) = value_and_grad(
            d,
            init,
            params,
            substeps,
            spf,
            self.checkpointing,
            grad0,
            |f, s| {
                store(f, s);
                if f == nframes {
                    loss_stage();
                }
                0.0
            },
            |f, _s, adj| {
                loss_stage();
                if error.borrow().is_some() {
                    return;
                }
                let g = frame_grads
                    .borrow_mut()
                    .as_mut()
                    .and_then(|gs| gs.get_mut(f).and_then(Option::take));
                if let Some(g) = g {
                    if let Err(e) = add(adj, &g) {
                        first_err(&error, e);
                    }
                }
            },
        )
        .map_err(sim_err)?;
        {
            let mut p = prof.borrow_mut();
            let (saved, t0) = {
                let mut st = stage.borrow_mut();
                (st.0.take(), st.1)
            };
            p.backward_peak_bytes = stage_end(saved);
            p.backward_s = t0.elapsed().as_secs_f64();
            self.save_profile(&p);
        }
        if let Some(e) = error.borrow_mut().take() {
            return Err(e);
        }
        let ev = match eval_out.borrow_mut().take() {
            Some(ev) => ev,
            None => {
                let frames = std::mem::take(&mut *stored.borrow_mut());
                self.banded_loss(&frames, None, None, &mut prof.borrow_mut())?
            }
        };
        Ok((ev, Some((adj0, g)), Vec::new()))
    }

    fn save_profile(&self, p: &StageProfile) {
        if let Ok(mut slot) = self.profile.lock() {
            let device = (
                slot.device_peak_bytes,
                slot.host_to_device_bytes,
                slot.device_to_host_bytes,
            );
            *slot = p.clone();
            (
                slot.device_peak_bytes,
                slot.host_to_device_bytes,
                slot.device_to_host_bytes,
            ) = device;
        }
    }
}

/// What a run computes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Mode {
    /// Render the videos only.
    RenderOnly,
    /// MS-SSIM against the references, frame by frame (no video kept).
    Score,
    /// Render the videos and evaluate the loss.
    Render,
    /// The loss only.
    Value,
    /// The loss and the parameter gradient.
    Grad,
}

/// The MS-SSIM settings for frames of `h x w` of view `name`: the standard 11-tap window, or
/// the smaller-window fallback for frames under 161 px ([`MsSsimConfig::largest_window`]).
pub(crate) fn ms_ssim_config(name: &str, h: usize, w: usize) -> Result<MsSsimConfig, FitError> {
    let side = h.min(w);
    if side > 160 {
        return Ok(MsSsimConfig::default());
    }
    MsSsimConfig::largest_window(side).ok_or_else(|| {
        FitError::Input(format!(
            "{name}: frames of {w}x{h} are too small for MS-SSIM (need more than 32 px a side)"
        ))
    })
}

/// What a run returns: the loss, the parameter gradient (when asked) and the rendered videos
/// (forward-only runs).
pub(crate) type RunOut = (Evaluation, Option<Vec<PhysParams<f64>>>, Vec<Video<f32>>);

/// A simulated frame: positions and row-major deformation gradients, on the host or left on
/// the backend's device (copies of the state's buffers the renderer reads there).
enum Frame {
    Host { x: Vec<[f32; 3]>, f: Vec<[f32; 9]> },
    Device { x: AnyBuf, f: AnyBuf },
}

/// A frame's rendering gradient with respect to positions and deformation gradients: summed
/// on the host, or on the device as the list of its parts (one per view, and per band where
/// a frame was not kept), each added to the adjoint state there.
enum FrameGrad {
    Host { x: Vec<[f32; 3]>, f: Vec<[f32; 9]> },
    Device(Vec<(AnyBuf, AnyBuf)>),
}

impl FrameGrad {
    /// A zero gradient for `n` particles, where frame `s` lives.
    fn zeros(s: &Frame, n: usize) -> FrameGrad {
        match s {
            Frame::Host { .. } => FrameGrad::Host {
                x: vec![[0.0; 3]; n],
                f: vec![[0.0; 9]; n],
            },
            Frame::Device { .. } => FrameGrad::Device(Vec::new()),
        }
    }
}

/// A non-finite parameter gradient is an error.
fn check_grad(g: Option<Vec<PhysParams<f64>>>) -> Result<Option<Vec<PhysParams<f64>>>, FitError> {
    if let Some(g) = &g {
        for (slot, p) in g.iter().enumerate() {
            for k in crate::ParamKind::ALL {
                let v = crate::space::grad_of(p, k);
                if !v.is_finite() {
                    return Err(FitError::NonFinite(format!(
                        "the gradient of slot {slot}'s {} ({v})",
                        k.name()
                    )));
                }
            }
        }
    }
    Ok(g)
}
