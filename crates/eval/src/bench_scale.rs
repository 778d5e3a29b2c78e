//! One full fit iteration at the paper's scale (`r4d bench-scale`): forward simulation with
//! checkpointing, rendering, DMS, and the backward pass through both, with per-stage time and
//! peak memory, next to the paper's figures.
//!
//! # The scene
//! A jelly block of two parts (lower and upper half) standing on a floor in a 64^3 grid:
//! `cells^3` cells with 8 particles each (23^3 cells: 97 336 particles, the paper's ~100k),
//! its base clamped and its top pushed sideways by a 0.01-s force so it wobbles; every
//! particle is a Gaussian (SH degree 3), and static floor and back-wall Gaussians bring the
//! total to `gaussians` (300 000). One 1920x1080 camera sees the block from the front, the
//! block covering well over a quarter of the frame ([`BenchScene::coverage`] measures it).
//! 16 frames of 400 substeps of 1e-4 s.
//!
//! The reference video is rendered from the simulation at other parameters (`truth`) or is
//! the rest frame repeated (`rest`, cheaper: no extra simulation), stored as 8-bit frames,
//! like a video read from PNG files. The measured iteration is
//! [`Objective::value_and_grad`] itself: nothing is special-cased.

use r4d_loss::bands::{ReferenceVideo, Video8};
use r4d_loss::{DmsConfig, Video};
use r4d_mpm::adjoint::checkpoint::{memory_plan, Checkpointing};
use r4d_mpm::{PartParams, ParticleSet, SimConfig};
use r4d_optim::video::{Objective, StageProfile, VideoProblem, View};
use r4d_optim::{Compute, FitError, Precision};
use r4d_splat::{Camera, Gaussians, RenderSettings, SimLink};
use serde::Serialize;
use std::path::Path;
use std::sync::Arc;
use std::time::Instant;

/// Size of the benchmark.
#[derive(Clone, Debug, PartialEq)]
pub struct BenchScale {
    /// Cells per side of the block (8 particles per cell).
    pub cells: usize,
    /// Total Gaussians (the block's particles plus static background).
    pub gaussians: usize,
    /// Simulated frames (the video has one more: the rest frame).
    pub frames: usize,
    /// Substeps per frame.
    pub substeps: usize,
    /// Image width.
    pub width: u32,
    /// Image height.
    pub height: u32,
    /// Checkpointing of the reverse sweep.
    pub checkpointing: Checkpointing,
    /// Rows per loss band.
    pub band_rows: usize,
    /// Reference from a simulation at other parameters (`true`) or the rest frame.
    pub reference_from_simulation: bool,
    /// Keep simulated frames on the device from the simulation to the rasterizer where the
    /// backend can ([`Objective::device_frames`]; `false` reads them back to the host).
    pub device_frames: bool,
}

/// The largest benchmark a user can ask for: sizes past these are refused before anything
/// is built (each is well above the paper's scale: 23 cells, 300 000 Gaussians, 16 x 400
/// substeps, 1920 x 1080).
pub const LIMITS: BenchLimits = BenchLimits {
    max_gaussians: 20_000_000,
    max_frames: 1_000,
    max_substeps: 100_000,
    max_total_substeps: 10_000_000,
    max_bytes: 256 << 30,
};

/// Bytes one Gaussian takes in the estimate of [`BenchScale::estimated_bytes`]: its
/// parameters (SH degree 3), its projection and tile lists, and their gradients.
pub const GAUSSIAN_BYTES: u64 = 1024;

/// Bytes one pixel of one video frame takes in the estimate: the rendered frame (3 x f32),
/// its gradient (3 x f32) and the 8-bit reference (3 bytes).
pub const VIDEO_PIXEL_BYTES: u64 = 27;

/// See [`LIMITS`].
#[derive(Clone, Copy, Debug)]
pub struct BenchLimits {
    /// Gaussians in all.
    pub max_gaussians: usize,
    /// Simulated frames.
    pub max_frames: usize,
    /// Substeps per frame.
    pub max_substeps: usize,
    /// Frames x substeps.
    pub max_total_substeps: usize,
    /// The estimated memory of the run ([`BenchScale::estimated_bytes`]); the machine's
    /// available memory bounds it too.
    pub max_bytes: u64,
}

impl BenchScale {
    /// Checks every size against [`LIMITS`] and the camera limit
    /// ([`r4d_splat::camera::MAX_CAMERA_PIXELS`]); the error names the setting and its limit.
    pub fn validate(&self) -> Result<(), FitError> {
        let bad = |m: String| Err(FitError::Input(m));
        let l = LIMITS;
        if !(2..=48).contains(&self.cells) {
            return bad(format!(
                "cells = {}: between 2 and 48 (the grid is 64^3)",
                self.cells
            ));
        }
        // The block's particles are Gaussians too: fewer would silently mean the block alone.
        let block = 8 * self.cells.pow(3);
        if self.gaussians < block || self.gaussians > l.max_gaussians {
            return bad(format!(
                "gaussians = {}: at least the block's {block} particles (8 x cells^3), at most {}",
                self.gaussians, l.max_gaussians
            ));
        }
        if self.frames == 0 || self.frames > l.max_frames {
            return bad(format!("frames = {}: 1..={}", self.frames, l.max_frames));
        }
        if self.substeps == 0 || self.substeps > l.max_substeps {
            return bad(format!(
                "substeps = {}: 1..={}",
                self.substeps, l.max_substeps
            ));
        }
        if self.frames * self.substeps > l.max_total_substeps {
            return bad(format!(
                "frames x substeps = {}: at most {}",
                self.frames * self.substeps,
                l.max_total_substeps
            ));
        }
        let px = self.width as u64 * self.height as u64;
        if self.width < 16
            || self.height < 16
            || px > r4d_splat::camera::MAX_CAMERA_PIXELS
            || self.width > 1 << 15
            || self.height > 1 << 15
        {
            return bad(format!(
                "resolution {}x{}: at least 16x16, at most {} pixels",
                self.width,
                self.height,
                r4d_splat::camera::MAX_CAMERA_PIXELS
            ));
        }
        if self.band_rows == 0 {
            return bad("band_rows = 0: at least 1 (rounded up to 16)".into());
        }
        self.check_memory(r4d_mpm::budget::available_memory())
    }

    /// The estimated peak memory of a run whose sizes passed [`BenchScale::validate`]'s other
    /// checks (bytes, saturating): the simulation's checkpoints,
    /// grids and scratch ([`memory_plan`], f32), the Gaussians ([`GAUSSIAN_BYTES`] each) and
    /// the video frames ([`VIDEO_PIXEL_BYTES`] a pixel, the rest frame included).
    pub fn estimated_bytes(&self) -> u64 {
        let cells = self.cells as u64;
        let particles = cells.saturating_pow(3).saturating_mul(8);
        let total = (self.frames as u64).saturating_mul(self.substeps as u64);
        let sim = memory_plan(
            particles,
            N_GRID as u64,
            total,
            u32::try_from(self.substeps).unwrap_or(u32::MAX),
            self.checkpointing,
            4,
        )
        .peak_bytes;
        let video = (self.frames as u64 + 1)
            .saturating_mul(self.width as u64)
            .saturating_mul(self.height as u64)
            .saturating_mul(VIDEO_PIXEL_BYTES);
        sim.saturating_add((self.gaussians as u64).saturating_mul(GAUSSIAN_BYTES))
            .saturating_add(video)
    }

    /// Checks [`BenchScale::estimated_bytes`] against `LIMITS.max_bytes` and `available` (the
    /// machine's available memory, when known), naming the sizes to lower.
    pub fn check_memory(&self, available: Option<u64>) -> Result<(), FitError> {
        let need = self.estimated_bytes();
        let gib = |b: u64| b as f64 / (1u64 << 30) as f64;
        let limit = match available {
            Some(a) if a < LIMITS.max_bytes => (a, "the memory this machine has available"),
            _ => (LIMITS.max_bytes, "the benchmark's limit (LIMITS.max_bytes)"),
        };
        if need > limit.0 {
            return Err(FitError::Input(format!(
                "cells = {}, gaussians = {}, frames x substeps = {} x {}, resolution {}x{}, \
                 checkpointing {}: about {:.1} GiB, more than the {:.1} GiB of {}: lower the \
                 sizes or use a nested checkpointing",
                self.cells,
                self.gaussians,
                self.frames,
                self.substeps,
                self.width,
                self.height,
                checkpointing_name(self.checkpointing),
                gib(need),
                gib(limit.0),
                limit.1
            )));
        }
        Ok(())
    }
}

impl Default for BenchScale {
    /// The paper's scale.
    fn default() -> Self {
        BenchScale {
            cells: 23,
            gaussians: 300_000,
            frames: 16,
            substeps: 400,
            width: 1920,
            height: 1080,
            checkpointing: Checkpointing::Nested(20),
            band_rows: r4d_optim::video::problem::DEFAULT_BAND_ROWS,
            reference_from_simulation: true,
            device_frames: true,
        }
    }
}

/// The benchmark problem.
pub struct BenchScene {
    /// The problem (reference filled in by [`BenchScene::build`]).
    pub problem: VideoProblem,
    /// Parameters of the reference simulation.
    pub truth: Vec<PartParams>,
    /// Parameters the iteration is evaluated at.
    pub start: Vec<PartParams>,
    /// Fraction of the frame the block covers at rest (alpha > 0.5 of the block alone).
    pub coverage: f64,
    /// Seconds spent building the reference.
    pub reference_s: f64,
}

const N_GRID: usize = 64;
const DT: f64 = 1e-4;

fn sim_config(s: &BenchScale, parts: Vec<PartParams>) -> SimConfig {
    let text = format!(
        r#"
[domain]
grid_lim = 1.0
n_grid = {N_GRID}
[time]
substep_dt = {DT:e}
frame_dt = {frame_dt:e}
frames = {frames}
[solver]
gravity = [0.0, 0.0, -9.8]
[[parts]]
material = "jelly"
[[parts]]
material = "jelly"
[[boundary]]
type = "bounding_box"
[[boundary]]
type = "cuboid"
point = [0.5, 0.5, 0.09375]
size = [0.5, 0.5, 0.03]
velocity = [0.0, 0.0, 0.0]
[[boundary]]
type = "particle_impulse"
force = [0.02, 0.008, 0.0]
point = [0.5, 0.5, {top:e}]
size = [0.3, 0.3, {top_h:e}]
num_dt = 100
"#,
        frame_dt = s.substeps as f64 * DT,
        frames = s.frames,
        top = block_top(s) - 0.03,
        top_h = 0.03,
    );
    let mut c = SimConfig::parse(&text, Path::new("bench-scale.toml"))
        .expect("the bench-scale config parses");
    c.parts = parts;
    c
}

fn dx() -> f64 {
    1.0 / N_GRID as f64
}

/// Lower-left corner of the block (grid-aligned, centred in x and y, its base at 6 cells).
fn block_min(s: &BenchScale) -> [f64; 3] {
    let lo = ((N_GRID - s.cells) / 2) as f64 * dx();
    [lo, lo, 6.0 * dx()]
}

fn block_top(s: &BenchScale) -> f64 {
    block_min(s)[2] + s.cells as f64 * dx()
}

fn particles(s: &BenchScale) -> ParticleSet {
    let min = block_min(s);
    let lower = s.cells / 2 + s.cells % 2;
    let split = min[2] + lower as f64 * dx();
    let side = s.cells as f64 * dx();
    let shapes = [
        r4d_mpm::Shape::Box {
            min,
            max: [min[0] + side, min[1] + side, split],
            part: 0,
            per_cell: 2,
        },
        r4d_mpm::Shape::Box {
            min: [min[0], min[1], split],
            max: [min[0] + side, min[1] + side, min[2] + side],
            part: 1,
            per_cell: 2,
        },
    ];
    ParticleSet::from_shapes(&shapes, dx())
}

/// SplitMix64 in [0, 1).
struct Rng(u64);
impl Rng {
    fn next(&mut self) -> f32 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        ((z ^ (z >> 31)) >> 40) as f32 / (1u64 << 24) as f32
    }
}

/// The block's Gaussians (one per particle) then the static floor and back wall.
fn scene(s: &BenchScale, p: &ParticleSet) -> Gaussians {
    let mut g = Gaussians {
        sh_degree: 3,
        ..Default::default()
    };
    let mut rng = Rng(7);
    let dc = |c: f32| (c - 0.5) / 0.282_094_8;
    let mut push = |g: &mut Gaussians, m: [f32; 3], sc: [f32; 3], q: [f32; 4], c: [f32; 3]| {
        g.means.push(m);
        g.log_scales.push(sc.map(f32::ln));
        g.quats.push(q);
        g.opacity_logits.push(3.0);
        // DC colour, then small view-dependent terms (bands 1..3), channel-interleaved.
        g.sh.extend(c.map(dc));
        for _ in 0..15 * 3 {
            g.sh.push(0.04 * (rng.next() - 0.5));
        }
    };
    let sigma = (0.3 * dx()) as f32;
    let palettes = [
        [[0.20, 0.55, 0.25], [0.80, 0.85, 0.35]],
        [[0.85, 0.25, 0.35], [0.95, 0.75, 0.25]],
    ];
    for (x, &part) in p.x.iter().zip(&p.part) {
        let cell = x.map(|v| (v / (3.0 * dx() as f32)).floor() as i64);
        let odd = (cell[0] + cell[1] + cell[2]).rem_euclid(2) as usize;
        push(
            &mut g,
            *x,
            [sigma; 3],
            [1.0, 0.0, 0.0, 0.0],
            palettes[part as usize][odd],
        );
    }
    // Static background: floor (z = base) and back wall (y = 0.95), flat discs on square
    // lattices sized so the total is `gaussians`.
    let rest = s.gaussians.saturating_sub(p.x.len());
    let floor_n = rest / 2;
    let wall_n = rest - floor_n;
    let base = block_min(s)[2] as f32;
    let lattice = |n: usize, w: f32, h: f32| -> (usize, usize) {
        let cols = ((n as f32 * w / h).sqrt().ceil() as usize).max(1);
        (cols, n.div_ceil(cols))
    };
    let (fc, fr) = lattice(floor_n, 1.6, 1.0);
    let mut k = 0;
    'floor: for j in 0..fr {
        for i in 0..fc {
            if k == floor_n {
                break 'floor;
            }
            k += 1;
            let (x, y) = (
                -0.3 + 1.6 * (i as f32 + 0.5) / fc as f32,
                0.0 + 0.95 * (j as f32 + 0.5) / fr as f32,
            );
            let tile = ((x / 0.1).floor() + (y / 0.1).floor()) as i64 & 1;
            let c = if tile == 0 { 0.55 } else { 0.72 };
            let r = 1.2 * 1.6 / fc as f32;
            push(
                &mut g,
                [x, y, base],
                [r, r, 0.002],
                [1.0, 0.0, 0.0, 0.0],
                [c, c, c * 0.95],
            );
        }
    }
    let (wc, wr) = lattice(wall_n, 1.6, 0.9);
    let h = std::f32::consts::FRAC_1_SQRT_2;
    let mut k = 0;
    'wall: for j in 0..wr {
        for i in 0..wc {
            if k == wall_n {
                break 'wall;
            }
            k += 1;
            let (x, z) = (
                -0.3 + 1.6 * (i as f32 + 0.5) / wc as f32,
                base + 0.9 * (j as f32 + 0.5) / wr as f32,
            );
            let stripe = (((x + z) / 0.08).floor() as i64) & 1;
            let c = if stripe == 0 {
                [0.62, 0.72, 0.90]
            } else {
                [0.93, 0.80, 0.86]
            };
            let r = 1.2 * 1.6 / wc as f32;
            push(&mut g, [x, 0.95, z], [r, r, 0.002], [h, h, 0.0, 0.0], c);
        }
    }
    g
}

/// The camera: in front of the block, slightly above, the block filling most of the height.
fn camera(s: &BenchScale) -> Camera {
    let top = block_top(s);
    let mid = 0.5 * (block_min(s)[2] + top);
    let mut c = Camera::look_at(
        s.width,
        s.height,
        50.0,
        [0.72, -0.12, top + 0.12],
        [0.5, 0.5, mid],
        [0.0, 0.0, 1.0],
    );
    c.name = "bench".into();
    c
}

impl BenchScene {
    /// Builds the scene and its reference video (on `compute`).
    pub fn build(s: &BenchScale, compute: Arc<dyn Compute>) -> Result<BenchScene, FitError> {
        s.validate()?;
        let truth = vec![
            PartParams {
                youngs_modulus_pa: 2e5,
                poisson_ratio: 0.3,
                density_kg_m3: 1000.0,
                ..Default::default()
            },
            PartParams {
                youngs_modulus_pa: 5e4,
                poisson_ratio: 0.3,
                density_kg_m3: 1200.0,
                ..Default::default()
            },
        ];
        let start = vec![
            PartParams {
                youngs_modulus_pa: 1e5,
                density_kg_m3: 800.0,
                ..truth[0]
            },
            PartParams {
                youngs_modulus_pa: 1e5,
                density_kg_m3: 800.0,
                ..truth[1]
            },
        ];
        let config = sim_config(s, truth.clone());
        let particles = particles(s);
        let scene = scene(s, &particles);
        let mut link = SimLink::identity(scene.len());
        link.simulated = (0..particles.x.len() as u32).collect();
        let cam = camera(s);
        let (h, w) = (s.height as usize, s.width as usize);
        let settings = RenderSettings {
            background: [0.93, 0.92, 0.86],
            ..Default::default()
        };
        let coverage = {
            // The block alone at a quarter of the resolution.
            let mut block = Gaussians {
                sh_degree: scene.sh_degree,
                ..Default::default()
            };
            let n = particles.x.len();
            block.means = scene.means[..n].to_vec();
            block.log_scales = scene.log_scales[..n].to_vec();
            block.quats = scene.quats[..n].to_vec();
            block.opacity_logits = scene.opacity_logits[..n].to_vec();
            block.sh = scene.sh[..n * 48].to_vec();
            let mut small = cam.clone();
            small.width = (s.width / 4).max(1);
            small.height = (s.height / 4).max(1);
            small.fx /= 4.0;
            small.fy /= 4.0;
            small.cx /= 4.0;
            small.cy /= 4.0;
            let img = compute.render(&block, None, &small, &settings)?;
            img.alpha.iter().filter(|&&a| a > 0.5).count() as f64 / img.alpha.len() as f64
        };
        let t0 = Instant::now();
        let placeholder = Video8::quantize(&Video::zeros(1, 1, 1));
        let mut problem = VideoProblem {
            config,
            particles,
            scene,
            link,
            settings,
            views: vec![View {
                name: "bench reference".into(),
                camera: cam.clone(),
                video: ReferenceVideo::U8(placeholder),
            }],
            fps: 1.0 / (s.substeps as f64 * DT),
            compute,
        };
        let reference = if s.reference_from_simulation {
            // Validation needs a video of the right size: a one-byte-per-value placeholder.
            problem.views[0].video =
                ReferenceVideo::U8(Video8::quantize(&Video::zeros(s.frames + 1, h, w)));
            let mut obj = Objective::new(&problem, None, &DmsConfig::default(), false)?;
            obj.precision = Precision::F32;
            let mut v = obj.render(&truth)?;
            Video8::quantize(&v.remove(0))
        } else {
            let img = (problem.compute).render(&problem.scene, None, &cam, &problem.settings)?;
            let frame = Video::new(1, h, w, img.rgb).map_err(FitError::from)?;
            let one = Video8::quantize(&frame);
            let data: Vec<f32> = (0..s.frames + 1)
                .flat_map(|_| one.data().iter().map(|&k| k as f32 / 255.0))
                .collect();
            Video8::from_exact(&Video::new(s.frames + 1, h, w, data).map_err(FitError::from)?)
                .expect("8-bit values")
        };
        problem.views[0].video = ReferenceVideo::U8(reference);
        problem.config.parts = start.clone();
        Ok(BenchScene {
            problem,
            truth,
            start,
            coverage,
            reference_s: t0.elapsed().as_secs_f64(),
        })
    }
}

/// The measurement of one iteration.
#[derive(Clone, Debug, Serialize)]
pub struct BenchReport {
    /// Simulated particles.
    pub particles: usize,
    /// Gaussians.
    pub gaussians: usize,
    /// Grid resolution.
    pub n_grid: usize,
    /// Frames.
    pub frames: usize,
    /// Substeps per frame.
    pub substeps_per_frame: usize,
    /// Image width.
    pub width: u32,
    /// Image height.
    pub height: u32,
    /// `cpu` or `wgpu`.
    pub backend: String,
    /// Checkpointing strategy.
    pub checkpointing: String,
    /// Rows per loss band, and bands per frame.
    pub band_rows: usize,
    /// Bands per frame.
    pub bands: usize,
    /// Fraction of the frame the block covers.
    pub object_coverage: f64,
    /// Loss of the iteration.
    pub loss: f64,
    /// Stage times and peaks.
    pub profile: StageProfile,
    /// Wall time of the iteration (s).
    pub total_s: f64,
    /// Peak heap bytes during the iteration (process total: inputs included).
    pub peak_bytes: usize,
    /// Heap bytes held before the iteration (scene, particles, reference, plans).
    pub held_bytes: usize,
    /// The reference video's bytes (8-bit).
    pub reference_bytes: usize,
    /// `memory_plan`'s prediction for the simulation's checkpoints and scratch (f32).
    pub memory_plan_bytes: u64,
    /// Seconds spent building the reference before the iteration.
    pub reference_s: f64,
    /// Whether the counting allocator measured the heap (false: peaks are 0).
    pub heap_measured: bool,
    /// The forward simulation against a rough compute bound of this machine's cores (`cpu`
    /// backend only).
    pub compute_bound: Option<ComputeBound>,
}

/// Runs one iteration (f32 simulation) and measures it.
/// Heap peaks come from `heap` (the `r4d` binary passes its counting allocator's
/// `CountingProbe`; `None`: 0).
pub fn run(
    s: &BenchScale,
    compute: Arc<dyn Compute>,
    heap: Option<Arc<dyn r4d_optim::HeapProbe>>,
) -> Result<(BenchScene, BenchReport), FitError> {
    let backend = compute.name().to_string();
    let scene = BenchScene::build(s, compute)?;
    let p = &scene.problem;
    let mut obj = Objective::new(p, None, &r4d_optim::video::FitConfig::default().loss, false)?;
    obj.precision = Precision::F32;
    obj.checkpointing = s.checkpointing;
    obj.set_band_rows(s.band_rows)?;
    obj.device_frames = s.device_frames;
    obj.heap = heap.clone();
    let span = heap.as_ref().map(|h| h.start());
    let t = Instant::now();
    let (ev, _grad) = obj.value_and_grad(&scene.start)?;
    let total_s = t.elapsed().as_secs_f64();
    let peak = span.as_ref().map_or(0, |s| s.peak());
    let profile = obj.profile();
    let n = p.particles.x.len();
    let plan = memory_plan(
        n as u64,
        N_GRID as u64,
        (s.frames * s.substeps) as u64,
        s.substeps as u32,
        s.checkpointing,
        4,
    );
    let report = BenchReport {
        particles: n,
        gaussians: p.scene.len(),
        n_grid: N_GRID,
        frames: s.frames,
        substeps_per_frame: s.substeps,
        width: s.width,
        height: s.height,
        backend,
        checkpointing: checkpointing_name(s.checkpointing),
        band_rows: s.band_rows,
        bands: profile.bands,
        object_coverage: scene.coverage,
        loss: ev.total,
        profile,
        total_s,
        peak_bytes: peak,
        held_bytes: span.as_ref().map_or(0, |s| s.base()),
        reference_bytes: p.views[0].video.bytes(),
        memory_plan_bytes: plan.peak_bytes,
        reference_s: scene.reference_s,
        heap_measured: peak > 0,
        compute_bound: None,
    };
    let report = BenchReport {
        compute_bound: (report.backend == "cpu").then(|| compute_bound(&report)),
        ..report
    };
    Ok((scene, report))
}

/// The measurement of the simulation-driven initialisation at the benchmark's scale
/// ([`run_init`]).
#[derive(Clone, Debug, Serialize)]
pub struct InitBenchReport {
    /// Simulated particles.
    pub particles: usize,
    /// Gaussians.
    pub gaussians: usize,
    /// Video frames each candidate simulates and compares.
    pub frames: usize,
    /// Substeps per frame.
    pub substeps_per_frame: usize,
    /// Image width.
    pub width: u32,
    /// Image height.
    pub height: u32,
    /// `cpu`, `wgpu` or `vulkan`.
    pub backend: String,
    /// Latin hypercube candidates evaluated.
    pub candidates: usize,
    /// Candidates whose simulation or score failed (recorded and skipped, as in a fit).
    pub failed: usize,
    /// At most this many candidates ran at once (the memory budget over the estimate).
    pub concurrent: usize,
    /// Threads available to the process (the candidates and their simulations share them).
    pub threads: usize,
    /// [`Objective::score_bytes`]: the estimated heap of one candidate.
    pub candidate_bytes_estimate: u64,
    /// The best candidate's MS-SSIM.
    pub best_score: f64,
    /// Wall time of the whole initialisation (s).
    pub total_s: f64,
    /// `total_s / candidates`.
    pub per_candidate_s: f64,
    /// Peak heap bytes during the initialisation (process total: inputs included).
    pub peak_bytes: usize,
    /// Heap bytes held before it (scene, particles, reference).
    pub held_bytes: usize,
    /// Whether the counting allocator measured the heap (false: peaks are 0).
    pub heap_measured: bool,
}

/// Young's modulus bounds of [`run_init`]'s candidates (Pa): around the scene's parameters
/// (1e5 start, 5e4 and 2e5 truth) and stable at its substep.
pub const INIT_E_BOUNDS: [f64; 2] = [2e4, 5e5];

/// Runs the video fit's initialisation ([`r4d_optim::video::fit::initialize`], f32 simulation,
/// both parts' Young's moduli free in [`INIT_E_BOUNDS`]) with `candidates` Latin hypercube
/// candidates over the benchmark's scene and frames, and measures it. `on_candidate` sees
/// each candidate as it finishes (progress).
pub fn run_init(
    s: &BenchScale,
    compute: Arc<dyn Compute>,
    heap: Option<Arc<dyn r4d_optim::HeapProbe>>,
    candidates: usize,
    on_candidate: &mut dyn FnMut(&r4d_optim::Candidate),
) -> Result<(BenchScene, InitBenchReport), FitError> {
    struct Progress<'a>(&'a mut dyn FnMut(&r4d_optim::Candidate));
    impl r4d_optim::video::FitHooks for Progress<'_> {
        fn on_event(&mut self, e: &r4d_optim::video::FitEvent<'_>) {
            if let r4d_optim::video::FitEvent::Candidate(c) = e {
                (self.0)(c)
            }
        }
    }
    if candidates == 0 {
        return Err(FitError::Input(
            "init candidates = 0: must be at least 1".into(),
        ));
    }
    let backend = compute.name().to_string();
    let scene = BenchScene::build(s, compute)?;
    let p = &scene.problem;
    // Both parts' Young's moduli free over a range where every candidate is stable at the
    // benchmark's substep (the CFL bound at 5e5 Pa and 1000 kg/m^3 is 3e-4 s), so each one
    // runs all its frames, as the paper's candidates do.
    let parts = (0..2)
        .map(|id| r4d_optim::video::config::PartFit {
            id,
            free: None,
            bounds: [("E".to_string(), INIT_E_BOUNDS)].into_iter().collect(),
        })
        .collect();
    let cfg = r4d_optim::video::FitConfig {
        strategy: r4d_optim::video::Strategy::Fixed,
        precision: Precision::F32,
        free: Some(vec!["E".to_string()]),
        parts,
        init: r4d_optim::video::InitConfig {
            candidates,
            frames: s.frames,
            ..Default::default()
        },
        ..Default::default()
    };
    let obj = Objective::new(p, Some(s.frames), &cfg.loss, false)?;
    let (estimate, concurrent) = (obj.score_bytes(), obj.init_concurrency());
    drop(obj);
    let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
    let span = heap.as_ref().map(|h| h.start());
    let t = Instant::now();
    let (_, outcome) = r4d_optim::video::fit::initialize(p, &cfg, &mut Progress(on_candidate))?;
    let total_s = t.elapsed().as_secs_f64();
    let peak = span.as_ref().map_or(0, |s| s.peak());
    let best_score = outcome
        .ranking
        .first()
        .and_then(|&i| outcome.candidates[i].score)
        .unwrap_or(f64::NAN);
    let report = InitBenchReport {
        particles: p.particles.x.len(),
        gaussians: p.scene.len(),
        frames: s.frames,
        substeps_per_frame: s.substeps,
        width: s.width,
        height: s.height,
        backend,
        candidates,
        failed: outcome.failed().count(),
        concurrent: concurrent.min(threads).min(candidates),
        threads,
        candidate_bytes_estimate: estimate,
        best_score,
        total_s,
        per_candidate_s: total_s / candidates as f64,
        peak_bytes: peak,
        held_bytes: span.as_ref().map_or(0, |s| s.base()),
        heap_measured: peak > 0,
    };
    Ok((scene, report))
}

/// [`InitBenchReport`] as text.
pub fn init_table(r: &InitBenchReport) -> String {
    let mib = |b: f64| b / (1024.0 * 1024.0);
    let mut s = format!(
        "initialisation: {} Latin hypercube candidates x {} frames x {} substeps, {} particles, {} Gaussians, {}x{}, backend {}\n",
        r.candidates, r.frames, r.substeps_per_frame, r.particles, r.gaussians, r.width, r.height, r.backend
    );
    s += &format!(
        "  at most {} at once on {} threads (estimate {:.1} MiB each, budget {:.0} MiB); {} failed; best MS-SSIM {:.4}\n",
        r.concurrent,
        r.threads,
        mib(r.candidate_bytes_estimate as f64),
        mib(r4d_optim::video::INIT_MEMORY_BUDGET_BYTES as f64),
        r.failed,
        r.best_score
    );
    s += &format!(
        "  whole initialisation {:.1} s ({:.1} min), {:.1} s per candidate; peak heap {:.1} MiB (held before: {:.1} MiB)\n",
        r.total_s,
        r.total_s / 60.0,
        r.per_candidate_s,
        mib(r.peak_bytes as f64),
        mib(r.held_bytes as f64)
    );
    if !r.heap_measured {
        s += "  (the counting allocator is not installed: heap peaks read 0)\n";
    }
    s
}

/// `nested:20` etc.
pub fn checkpointing_name(c: Checkpointing) -> String {
    match c {
        Checkpointing::StoreAll => "store_all".into(),
        Checkpointing::PerFrame => "per_frame".into(),
        Checkpointing::EveryN(n) => format!("every_n:{n}"),
        Checkpointing::Nested(n) => format!("nested:{n}"),
    }
}

/// Peak GPU memory the paper reports per method (GB, mean over the four PhysDreamer scenes).
pub const PAPER_PEAK_GB: [(&str, f64); 4] = [
    ("Resonance4D (paper, CUDA)", 21.77),
    ("DreamPhysics", 33.42),
    ("Physics3D", 33.06),
    ("PhysFlow", 38.52),
];

/// The report as a text table.
pub fn table(r: &BenchReport) -> String {
    let mib = |b: f64| b / (1024.0 * 1024.0);
    let p = &r.profile;
    let mut s = String::new();
    s += &format!(
        "one fit iteration: {} particles, {} Gaussians, n_grid {}, {} frames x {} substeps, {}x{}, backend {}, checkpointing {}, loss in {} bands of {} rows; the block covers {:.0}% of the frame\n\n",
        r.particles, r.gaussians, r.n_grid, r.frames, r.substeps_per_frame, r.width, r.height,
        r.backend, r.checkpointing, r.bands, r.band_rows, 100.0 * r.object_coverage
    );
    s += "stage                               time (s)   peak heap (MiB)\n";
    let rows = [
        (
            "forward simulation (checkpointed)",
            p.forward_s,
            Some(p.forward_peak_bytes),
        ),
        ("render (band by band)", p.render_s, None),
        ("DMS value + gradient", p.loss_s, None),
        ("render VJP", p.render_vjp_s, None),
        (
            "  render + DMS + VJP together",
            p.render_s + p.loss_s + p.render_vjp_s,
            Some(p.loss_peak_bytes),
        ),
        (
            "reverse sweep (simulation)",
            p.backward_s,
            Some(p.backward_peak_bytes),
        ),
        ("whole iteration", r.total_s, Some(r.peak_bytes)),
    ];
    for (name, t, m) in rows {
        s += &format!(
            "{name:<34} {t:>9.1}   {}\n",
            m.map_or("".into(), |b| format!("{:>10.1}", mib(b as f64)))
        );
    }
    if let Some(d) = p.device_peak_bytes {
        s += &format!(
            "peak device memory (backend's own accounting): {:.1} MiB\n",
            mib(d as f64)
        );
    }
    if let (Some(up), Some(down)) = (p.host_to_device_bytes, p.device_to_host_bytes) {
        s += &format!(
            "moved between host and device: {:.1} MiB up, {:.1} MiB down\n",
            mib(up as f64),
            mib(down as f64)
        );
    }
    s += &format!(
        "\nheld before the iteration: {:.1} MiB (scene, particles, 8-bit reference {:.1} MiB)\nmemory_plan (simulation checkpoints + scratch, f32): {:.1} MiB\n",
        mib(r.held_bytes as f64),
        mib(r.reference_bytes as f64),
        mib(r.memory_plan_bytes as f64)
    );
    if !r.heap_measured {
        s += "(the counting allocator is not installed: heap peaks read 0)\n";
    }
    s += "\npeak memory of one fit iteration        GB      vs ours\n";
    let ours = r.peak_bytes as f64 / 1e9;
    s += &format!(
        "{:<36} {:>6.2}\n",
        format!("resonance4d ({}, this run)", r.backend),
        ours
    );
    for (name, gb) in PAPER_PEAK_GB {
        s += &format!("{name:<36} {gb:>6.2}   {:>6.1}x\n", gb / ours.max(1e-12));
    }
    s
}

/// Estimated floating-point operations of one particle-substep of the forward MPM (f32, MLS,
/// fixed corotated): the 3x3 SVD and stress (~700), the 27-node scatter (~600) and gather
/// (~500) with their weights, the F update and the grid update's share (~200).
pub const FLOPS_PER_PARTICLE_SUBSTEP: f64 = 2000.0;

/// Single-precision operations per cycle per core the bound assumes: one 8-lane AVX2
/// multiply or add per cycle (no fused multiply-add; the kernels keep their rounding).
pub const FLOPS_PER_CYCLE: f64 = 8.0;

/// How close the forward simulation came to a rough compute bound.
#[derive(Clone, Debug, Serialize)]
pub struct ComputeBound {
    /// Particle-substeps per second of the checkpointed forward pass (frame read-backs
    /// included).
    pub particle_substeps_per_s: f64,
    /// Cores the bound counts (the parallelism available to the process).
    pub cores: usize,
    /// Clock the bound assumes (GHz; from `/proc/cpuinfo` when it can be read, else 3.0).
    pub clock_ghz: f64,
    /// The bound: `cores * clock * FLOPS_PER_CYCLE / FLOPS_PER_PARTICLE_SUBSTEP`.
    pub bound_per_s: f64,
    /// `particle_substeps_per_s / bound_per_s`.
    pub fraction: f64,
}

/// The mean clock of this machine's cores from `/proc/cpuinfo` (GHz), when it can be read.
fn clock_ghz() -> Option<f64> {
    let text = std::fs::read_to_string("/proc/cpuinfo").ok()?;
    let mhz: Vec<f64> = text
        .lines()
        .filter(|l| l.starts_with("cpu MHz"))
        .filter_map(|l| l.split(':').nth(1)?.trim().parse().ok())
        .filter(|v: &f64| v.is_finite() && *v > 100.0 && *v < 10_000.0)
        .collect();
    (!mhz.is_empty()).then(|| mhz.iter().sum::<f64>() / mhz.len() as f64 / 1000.0)
}

/// The forward simulation's throughput against the compute bound of this machine's cores
/// (meaningful for the `cpu` backend).
pub fn compute_bound(r: &BenchReport) -> ComputeBound {
    let work = (r.particles * r.frames * r.substeps_per_frame) as f64;
    let rate = work / r.profile.forward_s.max(1e-12);
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    let clock = clock_ghz().unwrap_or(3.0);
    let bound = cores as f64 * clock * 1e9 * FLOPS_PER_CYCLE / FLOPS_PER_PARTICLE_SUBSTEP;
    ComputeBound {
        particle_substeps_per_s: rate,
        cores,
        clock_ghz: clock,
        bound_per_s: bound,
        fraction: rate / bound,
    }
}

/// [`compute_bound`] as one line of text.
pub fn compute_bound_line(b: &ComputeBound) -> String {
    format!(
        "forward simulation: {:.3e} particle-substeps/s = {:.0}% of a rough compute bound of {:.3e}/s \
         ({} cores x {:.2} GHz x {FLOPS_PER_CYCLE} flop/cycle / {FLOPS_PER_PARTICLE_SUBSTEP} flop per particle-substep)",
        b.particle_substeps_per_s,
        100.0 * b.fraction,
        b.bound_per_s,
        b.cores,
        b.clock_ghz
    )
}
