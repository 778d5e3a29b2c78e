//! Where a fit runs: the [`Compute`] trait a backend implements once (its MPM kernels and its
//! renderer), so that every job of this crate — the video objective, the trajectory fit, a
//! forward simulation for evaluation — runs on it without naming it.
//!
//! A job is generic over the kernels ([`MpmJob::run_on`]); a backend runs it on its own
//! kernels in [`Compute::run_mpm`]:
//!
//! ```
//! use r4d_mpm::reference::ReferenceBackend;
//! use r4d_optim::compute::{Compute, JobOut, MpmJob};
//! use r4d_optim::{FitError, Precision};
//! use r4d_splat::{reference::ReferenceSplat, Renderer, SplatRenderer};
//!
//! /// The single-threaded reference kernels (the gradient oracle).
//! #[derive(Debug)]
//! struct Oracle;
//!
//! impl Compute for Oracle {
//!     fn name(&self) -> &str {
//!         "reference"
//!     }
//!     fn run_mpm(&self, precision: Precision, job: MpmJob<'_>) -> Result<JobOut, FitError> {
//!         match precision {
//!             Precision::F32 => job.run_on(ReferenceBackend::<f32>::in_scalar()),
//!             Precision::F64 => job.run_on(ReferenceBackend::<f64>::in_scalar()),
//!         }
//!     }
//!     fn with_renderer(
//!         &self,
//!         f: &mut dyn FnMut(&mut dyn Renderer) -> Result<(), FitError>,
//!     ) -> Result<(), FitError> {
//!         f(&mut SplatRenderer::new(ReferenceSplat))
//!     }
//! }
//! # let _ = Oracle;
//! ```
//! ([`ReferenceCompute`] is that implementation.)

use crate::record::{FitState, IterRecord};
use crate::trajectory::{self, FitOptions, Fitted};
use crate::video::problem::{Mode, Objective, RunOut};
use crate::FitError;
use r4d_mpm::adjoint::checkpoint::Differentiable;
use r4d_mpm::adjoint::engine::{KernelAdjoint, MpmAdjointKernels};
use r4d_mpm::adjoint::host::{HostSim, PhysParams};
use r4d_mpm::math::Real;
use r4d_mpm::{PartParams, ParticleSet, SimConfig};
use r4d_splat::{Camera, Deformation, Gaussians, Image, RenderSettings, Renderer};
use serde::{Deserialize, Serialize};

/// Floating-point type of the simulation and its reverse sweep, where the backend has a
/// choice (the CPU backends; a GPU simulates in f32).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Precision {
    /// Single precision (faster; gradients agree with f64 to a few 1e-3 relative).
    F32,
    /// Double precision (default).
    #[default]
    F64,
}

/// A compute backend for the fits: its MPM kernels and its renderer.
///
/// Implement [`Compute::run_mpm`] by handing the job your kernels
/// ([`MpmJob::run_on`]); [`Compute::with_renderer`] by calling `f` with your renderer.
pub trait Compute: Send + Sync + std::fmt::Debug {
    /// A short name for messages and reports (`"cpu"`, `"wgpu"`, ...).
    fn name(&self) -> &str;
    /// Runs `job` on this backend's MPM kernels, in `precision` where the backend has a
    /// choice.
    fn run_mpm(&self, precision: Precision, job: MpmJob<'_>) -> Result<JobOut, FitError>;
    /// Calls `f` with this backend's renderer.
    fn with_renderer(
        &self,
        f: &mut dyn FnMut(&mut dyn Renderer) -> Result<(), FitError>,
    ) -> Result<(), FitError>;
    /// Renders `scene` (deformed by `deform` when given) from `cam` with this backend's
    /// renderer.
    fn render(
        &self,
        scene: &Gaussians,
        deform: Option<&Deformation>,
        cam: &Camera,
        settings: &RenderSettings,
    ) -> Result<Image, FitError> {
        let mut img = None;
        self.with_renderer(&mut |r| {
            img = Some(r.render(scene, deform, cam, settings)?);
            Ok(())
        })?;
        img.ok_or_else(|| {
            FitError::backend_msg(self.name(), "with_renderer did not call the renderer")
        })
    }
    /// Starts a new device-memory peak ([`Compute::device_peak_bytes`]).
    fn reset_device_peak(&self) {}
    /// Turns per-kernel GPU timing on or off (`--profile`); returns whether this backend
    /// measures it (GPU timestamp queries: the Vulkan backend; `false` elsewhere).
    fn set_profiling(&self, _on: bool) -> Result<bool, FitError> {
        Ok(false)
    }
    /// GPU time per kernel since profiling was turned on, slowest first (empty where it is
    /// not measured).
    fn kernel_times(&self) -> Result<Vec<r4d_mpm::KernelTime>, FitError> {
        Ok(Vec::new())
    }
    /// The device's peak of allocated bytes since [`Compute::reset_device_peak`]; `None` for
    /// host backends (their memory is the process heap).
    fn device_peak_bytes(&self) -> Option<u64> {
        None
    }
}

/// The single-threaded reference kernels of `r4d-mpm` and `r4d-splat` (the gradient oracle;
/// slow, for checking and for builds with no backend crate).
#[derive(Clone, Copy, Debug, Default)]
pub struct ReferenceCompute;

impl Compute for ReferenceCompute {
    fn name(&self) -> &str {
        "reference"
    }

    fn run_mpm(&self, precision: Precision, job: MpmJob<'_>) -> Result<JobOut, FitError> {
        use r4d_mpm::reference::ReferenceBackend;
        match precision {
            Precision::F32 => job.run_on(ReferenceBackend::<f32>::in_scalar()),
            Precision::F64 => job.run_on(ReferenceBackend::<f64>::in_scalar()),
        }
    }

    fn with_renderer(
        &self,
        f: &mut dyn FnMut(&mut dyn Renderer) -> Result<(), FitError>,
    ) -> Result<(), FitError> {
        f(&mut r4d_splat::SplatRenderer::new(
            r4d_splat::reference::ReferenceSplat,
        ))
    }
}

/// Work for a backend's MPM kernels, generic over them ([`MpmJob::run_on`]).
pub struct MpmJob<'a>(Job<'a>);

/// What a job returned (read by the job's owner).
pub struct JobOut(Out);

enum Job<'a> {
    /// The video objective's forward (and reverse) pass.
    Video {
        obj: &'a Objective<'a>,
        slots: &'a [PartParams],
        mode: Mode,
    },
    /// A forward simulation reporting every frame's positions (simulation space, f64).
    Forward(ForwardJob<'a>),
    /// The trajectory fit.
    Trajectory(Box<TrajectoryJob<'a>>),
}

enum Out {
    Video(RunOut),
    Forward,
    Trajectory(Fitted),
}

/// Receives frame `j`'s positions of a forward simulation ([`simulate_frames`]).
pub type FrameSink<'a> = dyn FnMut(usize, &[[f64; 3]]) -> Result<(), FitError> + 'a;

/// A forward simulation of `frames` frames: `on_frame(j, x)` for `j = 0..=frames`.
pub(crate) struct ForwardJob<'a> {
    pub sim: &'a HostSim,
    pub slots: &'a [PartParams],
    pub frames: usize,
    pub on_frame: &'a mut FrameSink<'a>,
}

/// The arguments of [`trajectory::fit_trajectory_resumable`].
pub(crate) struct TrajectoryJob<'a> {
    pub config: &'a SimConfig,
    pub scene: &'a ParticleSet,
    pub targets: &'a [Vec<[f32; 3]>],
    pub opts: &'a FitOptions,
    pub resume: Option<FitState>,
    pub on_iter: &'a mut dyn FnMut(&IterRecord),
    pub on_checkpoint: &'a mut dyn FnMut(&FitState),
}

impl<'a> MpmJob<'a> {
    pub(crate) fn video(obj: &'a Objective<'a>, slots: &'a [PartParams], mode: Mode) -> Self {
        MpmJob(Job::Video { obj, slots, mode })
    }

    pub(crate) fn forward(job: ForwardJob<'a>) -> Self {
        MpmJob(Job::Forward(job))
    }

    pub(crate) fn trajectory(job: TrajectoryJob<'a>) -> Self {
        MpmJob(Job::Trajectory(Box::new(job)))
    }

    /// Runs the job on kernels `b`.
    pub fn run_on<B: MpmAdjointKernels>(self, b: B) -> Result<JobOut, FitError> {
        match self.0 {
            Job::Video { obj, slots, mode } => obj.run_on(b, slots, mode).map(Out::Video),
            Job::Forward(j) => forward(b, j).map(|_| Out::Forward),
            Job::Trajectory(j) => trajectory::fit_trajectory_resumable(
                b,
                j.config,
                j.scene,
                j.targets,
                j.opts,
                j.resume,
                j.on_iter,
                j.on_checkpoint,
            )
            .map(Out::Trajectory),
        }
        .map(JobOut)
    }
}

impl JobOut {
    pub(crate) fn into_video(self) -> Result<RunOut, FitError> {
        match self.0 {
            Out::Video(r) => Ok(r),
            _ => Err(wrong_out()),
        }
    }

    pub(crate) fn into_forward(self) -> Result<(), FitError> {
        match self.0 {
            Out::Forward => Ok(()),
            _ => Err(wrong_out()),
        }
    }

    pub(crate) fn into_trajectory(self) -> Result<Fitted, FitError> {
        match self.0 {
            Out::Trajectory(f) => Ok(f),
            _ => Err(wrong_out()),
        }
    }
}

/// A backend that returned another job's output.
fn wrong_out() -> FitError {
    FitError::Input("the backend returned the output of another job (a Compute that does not run the job it is given)".into())
}

fn forward<B: MpmAdjointKernels>(b: B, j: ForwardJob<'_>) -> Result<(), FitError> {
    let name = b.name();
    let err = |e: B::Error| FitError::backend(name, e);
    let phys: Vec<PhysParams<B::Scalar>> = j.slots.iter().map(PhysParams::of).collect();
    let stepper = KernelAdjoint::new(b, j.sim).map_err(err)?;
    let zero = B::Scalar::c(0.0);
    let mut s = stepper
        .init(&phys, &vec![[zero; 3]; j.sim.len()])
        .map_err(err)?;
    let spf = j.sim.setup.substeps_per_frame as u64;
    let read = |s: &r4d_mpm::adjoint::engine::StateBufs<B>| -> Result<Vec<[f64; 3]>, FitError> {
        let x = stepper.backend().download(&s.x).map_err(err)?;
        Ok(x.iter().map(|p| p.map(|c| c.f64())).collect())
    };
    (j.on_frame)(0, &read(&s)?)?;
    let mut k = 0u64;
    for f in 1..=j.frames {
        for _ in 0..spf {
            stepper.step(&mut s, &phys, k).map_err(err)?;
            k += 1;
        }
        (j.on_frame)(f, &read(&s)?)?;
    }
    Ok(())
}

/// [`trajectory::fit_trajectory_resumable`] on `compute`'s kernels (in f64 where the backend
/// has a choice).
#[allow(clippy::too_many_arguments)]
pub fn fit_trajectory_on(
    compute: &dyn Compute,
    config: &SimConfig,
    scene: &ParticleSet,
    targets: &[Vec<[f32; 3]>],
    opts: &FitOptions,
    resume: Option<FitState>,
    on_iter: &mut dyn FnMut(&IterRecord),
    on_checkpoint: &mut dyn FnMut(&FitState),
) -> Result<Fitted, FitError> {
    let job = TrajectoryJob {
        config,
        scene,
        targets,
        opts,
        resume,
        on_iter,
        on_checkpoint,
    };
    compute
        .run_mpm(Precision::F64, MpmJob::trajectory(job))?
        .into_trajectory()
}

/// Simulates `frames` frames of `sim` with the parameters `slots` (one per parameter slot) on
/// `compute`'s kernels, the same substeps as every fit: `on_frame(j, x)` gets frame `j`'s
/// positions (simulation space) for `j = 0..=frames`; an error it returns stops the run.
pub fn simulate_frames(
    compute: &dyn Compute,
    precision: Precision,
    sim: &HostSim,
    slots: &[PartParams],
    frames: usize,
    on_frame: &mut FrameSink<'_>,
) -> Result<(), FitError> {
    if slots.len() != sim.slots() {
        return Err(FitError::Input(format!(
            "{} parameter sets for a simulation with {} parameter slots",
            slots.len(),
            sim.slots()
        )));
    }
    let job = ForwardJob {
        sim,
        slots,
        frames,
        on_frame,
    };
    compute
        .run_mpm(precision, MpmJob::forward(job))?
        .into_forward()
}
