//! The paper's evaluation protocol on fitted parameters (`r4d eval`).
//!
//! * **Videos** (Table 2): every view's reference video is converted from the fit's frame rate
//!   to the evaluation rate (30 fps by default, "all rendered videos are exported at 30 FPS
//!   during evaluation") by the nearest frame in time ([`r4d_video::resample_indices`]); the
//!   fitted parameters are simulated and rendered at that rate (video frame `k` at `k / fps`,
//!   linear in time between simulated frames, as in the fit); the rendered frames are rounded
//!   to 8 bits, as an exported video is; then PSNR, SSIM, MS-SSIM and LPIPS per view
//!   ([`video_metrics`], the numbers `r4d metrics` prints for the same frames), and their
//!   means over views.
//! * **Trajectories** (Table 3), where the dataset has ground-truth point clouds (PhysFlow's
//!   `pcd/<k>.ply` = frame `k - 1`, in world coordinates): the fitted parameters are simulated
//!   with the fit's own simulator (`Simulation` on the problem's backend, f64 where it has
//!   the choice); ground-truth frame `j` is at
//!   `j / fps_fit` (the video's frame rate; the positions are linear in time between simulated
//!   frames when the grids differ); every particle is mapped to world coordinates by the
//!   simulation link; then Chamfer distance (`cd_sq_sum`), HD95 (`hd95_max_of_directed`) and
//!   F-score at `tau` = 0.04 ([`r4d_loss::trajectory`]'s defaults, those of `r4d
//!   metrics-trajectory`), means over frames, frame 0 included.

use crate::report::video_metrics;
use r4d_loss::bands::{ReferenceVideo, Video8};
use r4d_loss::lpips::Lpips;
use r4d_loss::trajectory::{trajectory_metrics, TrajectoryMetrics, DEFAULT_TAU};
use r4d_loss::Video;
use r4d_mpm::adjoint::host::HostSim;
use r4d_mpm::PartParams;
use r4d_optim::compute::simulate_frames;
use r4d_optim::video::{FitConfig, Objective, VideoProblem, View};
use r4d_optim::FitError;
use r4d_optim::Precision;
use std::path::PathBuf;

/// The evaluation frame rate of the paper.
pub const EVAL_FPS: f64 = 30.0;

/// What [`evaluate_videos`] found.
#[derive(Clone, Debug)]
pub struct VideoEval {
    /// Per view: the metrics object of [`video_metrics`] plus `view`.
    pub views: Vec<serde_json::Value>,
    /// Per view: the rendered frames at the evaluation rate, 8-bit.
    pub rendered: Vec<Video<f32>>,
    /// Per view: the reference frames at the evaluation rate.
    pub references: Vec<Video<f32>>,
    /// Frames per view at the evaluation rate.
    pub frames: usize,
}

/// The frames `idx` of a reference video, in its own storage.
fn select_frames(v: &ReferenceVideo, idx: &[usize]) -> Result<ReferenceVideo, FitError> {
    let (h, w) = (v.height(), v.width());
    Ok(match v {
        ReferenceVideo::F32(v) => {
            ReferenceVideo::F32(Video::from_frames(h, w, idx.iter().map(|&i| v.frame(i)))?)
        }
        ReferenceVideo::U8(v8) => {
            let fl = h * w * 3;
            let mut data = Vec::with_capacity(idx.len() * fl);
            for &i in idx {
                data.extend_from_slice(&v8.data()[i * fl..(i + 1) * fl]);
            }
            ReferenceVideo::U8(Video8::new(idx.len(), h, w, data)?)
        }
    })
}

/// `problem` with every reference video converted to `fps` (nearest frame in time).
pub fn at_frame_rate(problem: &VideoProblem, fps: f64) -> Result<VideoProblem, FitError> {
    if !(fps.is_finite() && fps > 0.0 && fps <= r4d_video::MAX_FPS) {
        return Err(FitError::Input(format!(
            "evaluation frame rate {fps} must be in (0, {}]",
            r4d_video::MAX_FPS
        )));
    }
    let mut views = Vec::with_capacity(problem.views.len());
    for v in &problem.views {
        let idx =
            r4d_video::resample_indices(v.video.frames(), problem.fps, fps).ok_or_else(|| {
                FitError::Input(format!(
                    "{}: {} frames at {} fps converted to {fps} fps exceed {} frames",
                    v.name,
                    v.video.frames(),
                    problem.fps,
                    r4d_video::MAX_FRAMES
                ))
            })?;
        views.push(View {
            name: v.name.clone(),
            camera: v.camera.clone(),
            video: select_frames(&v.video, &idx)?,
        });
    }
    Ok(VideoProblem {
        views,
        fps,
        ..problem.clone()
    })
}

/// Simulates `slots` (per part, or per particle when `per_particle`), renders every view at
/// `fps` and measures it against its reference converted to `fps` (see the module docs).
pub fn evaluate_videos(
    problem: &VideoProblem,
    cfg: &FitConfig,
    slots: &[PartParams],
    per_particle: bool,
    fps: f64,
    lpips: &[Lpips],
) -> Result<VideoEval, FitError> {
    let p = at_frame_rate(problem, fps)?;
    let mut obj = Objective::new(&p, None, &cfg.loss, per_particle)?;
    obj.precision = cfg.precision;
    let videos = obj.render(slots)?;
    let (mut views, mut rendered, mut references) = (Vec::new(), Vec::new(), Vec::new());
    for (k, (v, fitted)) in p.views.iter().zip(videos).enumerate() {
        let fitted = ReferenceVideo::U8(Video8::quantize(&fitted)).to_f32();
        let reference = Video::from_frames(
            v.video.height(),
            v.video.width(),
            (0..fitted.frames()).map(|t| v.video.frame_f32(t)),
        )?;
        let mut m = video_metrics(&reference, &fitted, lpips)?;
        m["view"] = serde_json::json!(k);
        views.push(m);
        rendered.push(fitted);
        references.push(reference);
    }
    let frames = rendered.first().map_or(0, |v| v.frames());
    Ok(VideoEval {
        views,
        rendered,
        references,
        frames,
    })
}

/// The most simulated frames [`evaluate_trajectory`] runs (a frame rate and frame duration
/// that disagree by orders of magnitude are refused, not simulated for hours).
pub const MAX_TRAJECTORY_FRAMES: usize = 100_000;

/// What [`evaluate_trajectory`] found.
#[derive(Clone, Debug)]
pub struct TrajectoryEval {
    /// Every metric variant, per frame and averaged.
    pub metrics: TrajectoryMetrics,
    /// The simulated particles per ground-truth frame, world coordinates.
    pub simulated: Vec<Vec<[f64; 3]>>,
}

/// Simulates `slots` and compares the particles with the ground-truth point clouds `gt`
/// (frame `j` of them at `j / problem.fps`; see the module docs).
pub fn evaluate_trajectory(
    problem: &VideoProblem,
    slots: &[PartParams],
    per_particle: bool,
    gt: &[PathBuf],
) -> Result<TrajectoryEval, FitError> {
    if gt.is_empty() {
        return Err(FitError::Input(
            "no ground-truth point clouds (pcd/1.ply, 2.ply, ...) for trajectory metrics".into(),
        ));
    }
    let reference: Vec<Vec<[f64; 3]>> = gt
        .iter()
        .map(|f| r4d_datasets::read_points(f).map_err(|e| FitError::Input(e.to_string())))
        .collect::<Result<_, _>>()?;
    let mut sim = HostSim::new(&problem.config, &problem.particles)?;
    if per_particle {
        sim = sim.per_particle();
    }
    let t = &problem.config.time;
    let frame_dt = t.substeps() as f64 * t.substep_dt;
    // Ground-truth frame j on the simulation's frame grid.
    let at: Vec<f64> = (0..gt.len())
        .map(|j| j as f64 / (problem.fps * frame_dt))
        .collect();
    let last_f = at.iter().fold(0.0f64, |a, &b| a.max(b)).ceil();
    if last_f > MAX_TRAJECTORY_FRAMES as f64 {
        return Err(FitError::Input(format!(
            "{} ground-truth frames at {} fps span {last_f} simulated frames of {frame_dt} s; the limit is {MAX_TRAJECTORY_FRAMES}",
            gt.len(),
            problem.fps
        )));
    }
    let last = last_f as usize;
    // World coordinates, rounded to f32 as the exported PLY frames hold them (so
    // `r4d metrics-trajectory` on those files gives the same numbers).
    let world = |x: &[[f64; 3]]| -> Vec<[f64; 3]> {
        x.iter()
            .map(|&p| problem.link.to_world(p).map(|c| c as f32 as f64))
            .collect()
    };
    let mut frames: Vec<Vec<[f64; 3]>> = Vec::with_capacity(last + 1);
    simulate_frames(
        &*problem.compute,
        Precision::F64,
        &sim,
        slots,
        last,
        &mut |j, x| {
            if x.iter().flatten().any(|c| !c.is_finite()) {
                return Err(FitError::Input(format!(
                    "the simulation with the fitted parameters diverged by frame {j}"
                )));
            }
            frames.push(world(x));
            Ok(())
        },
    )?;
    let simulated: Vec<Vec<[f64; 3]>> = at
        .iter()
        .map(|&a| {
            let (j0, w) = (a.floor() as usize, a - a.floor());
            if w < 1e-6 {
                frames[j0].clone()
            } else {
                frames[j0]
                    .iter()
                    .zip(&frames[(j0 + 1).min(last)])
                    .map(|(p, q)| std::array::from_fn(|c| (p[c] + w * (q[c] - p[c])) as f32 as f64))
                    .collect()
            }
        })
        .collect();
    let metrics = trajectory_metrics(&simulated, &reference, &[DEFAULT_TAU])
        .map_err(|e| FitError::Input(format!("trajectory metrics: {e}")))?;
    Ok(TrajectoryEval { metrics, simulated })
}
