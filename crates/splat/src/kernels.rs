//! The kernel-level backend trait: one method per stage of the renderer and its VJP, over
//! the buffers of the family's base trait [`Backend`]. A new backend implements
//! [`SplatKernels`]; everything above it ([`crate::SplatRenderer`]) is written once.

use crate::camera::{Camera, RasterizeMode, RenderSettings};
use crate::project::{CamParams, Projected, ProjectedGrad};
use bytemuck::{Pod, Zeroable};
pub use r4d_backend::{AnyBuf, Backend, MemoryUsage};

// SAFETY: `repr(C)`, ten f32 and two u32: no padding, every bit pattern valid.
unsafe impl Zeroable for Projected<f32> {}
unsafe impl Pod for Projected<f32> {}
// SAFETY: `repr(C)`, nine f32: no padding, every bit pattern valid.
unsafe impl Zeroable for ProjectedGrad<f32> {}
unsafe impl Pod for ProjectedGrad<f32> {}

/// The camera and settings of one render, as the kernels see them (f32, shader-friendly).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct CameraConsts {
    /// World-to-camera rotation rows (4th entry unused).
    pub rot: [[f32; 4]; 3],
    /// Translation (4th entry unused).
    pub trans: [f32; 4],
    /// Camera centre (4th entry unused).
    pub campos: [f32; 4],
    /// Background colour (4th entry unused).
    pub background: [f32; 4],
    /// fx, fy, cx, cy (cy of the full image for a cropped camera).
    pub intrinsics: [f32; 4],
    /// Near and far planes.
    pub near_far: [f32; 2],
    /// Image width and height (the full image's for a cropped camera).
    pub size: [u32; 2],
    /// Tiles along x and y (of the full image).
    pub tiles: [u32; 2],
    /// 1 for antialiased mode.
    pub antialiased: u32,
    /// SH degree.
    pub sh_degree: u32,
    /// Frustum clamp `[x+, x-, y+, y-]` ([`CamParams::lims`]; the full image's for a crop).
    pub lims: [f32; 4],
    /// The rows `rasterize` and `rasterize_vjp` composite, `rows[0] .. rows[1]` of the
    /// `size[1]` rows ([`CamParams::rows`]); the images and dL/drgb hold those rows only.
    /// `rows[2..]` are unused (they pad the record to 16 bytes, as a uniform needs).
    pub rows: [u32; 4],
}

impl CameraConsts {
    /// From a camera, settings and the SH degree (a cropped camera: the full image's
    /// projection, its band's rows).
    pub fn new(cam: &Camera, s: &RenderSettings, sh_degree: u32) -> Self {
        let p = CamParams::<f32>::new(cam, s.mode);
        let t = crate::camera::consts::TILE;
        let (w, h) = (p.width, p.height);
        CameraConsts {
            rot: [0, 1, 2].map(|i| [p.rot[i][0], p.rot[i][1], p.rot[i][2], 0.0]),
            trans: [p.trans[0], p.trans[1], p.trans[2], 0.0],
            campos: [p.campos[0], p.campos[1], p.campos[2], 0.0],
            background: [s.background[0], s.background[1], s.background[2], 0.0],
            intrinsics: [p.fx, p.fy, p.cx, p.cy],
            near_far: [p.near, p.far],
            size: [w, h],
            tiles: [w.div_ceil(t), h.div_ceil(t)],
            antialiased: (s.mode == RasterizeMode::Antialiased) as u32,
            sh_degree,
            lims: p.lims,
            rows: [p.rows[0], p.rows[1], 0, 0],
        }
    }

    /// The same camera compositing rows `rows` of its full image.
    pub fn with_rows(&self, rows: std::ops::Range<u32>) -> Self {
        CameraConsts {
            rows: [rows.start, rows.end, 0, 0],
            ..*self
        }
    }

    /// Number of rows composited.
    pub fn band_height(&self) -> u32 {
        self.rows[1].saturating_sub(self.rows[0])
    }

    /// The camera as the shared per-Gaussian math takes it.
    pub fn params(&self) -> CamParams<f32> {
        CamParams {
            rot: [0, 1, 2].map(|i| [self.rot[i][0], self.rot[i][1], self.rot[i][2]]),
            trans: [self.trans[0], self.trans[1], self.trans[2]],
            campos: [self.campos[0], self.campos[1], self.campos[2]],
            fx: self.intrinsics[0],
            fy: self.intrinsics[1],
            cx: self.intrinsics[2],
            cy: self.intrinsics[3],
            width: self.size[0],
            height: self.size[1],
            near: self.near_far[0],
            far: self.near_far[1],
            antialiased: self.antialiased != 0,
            lims: self.lims,
            rows: [self.rows[0], self.rows[1]],
        }
    }

    /// Background as an array.
    pub fn bg(&self) -> [f32; 3] {
        [self.background[0], self.background[1], self.background[2]]
    }
}

/// The simulation link as the kernels see it ([`crate::SimLink`] in f32, shader-friendly):
/// particle `s < simulated` moves Gaussian `simulated[s]` ([`LinkBufs::simulated`]) to
/// `A x + t` with deformation gradient `R^T F R` (see [`crate::link::link_point`]).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct LinkConsts {
    /// Simulation to world, rows `[A_i0, A_i1, A_i2, t_i]` (`A = R^T / scale`,
    /// `t = R^T (centre - shift / scale)`).
    pub to_world: [[f32; 4]; 3],
    /// The world-to-simulation rotation `R`, rows (4th entry unused).
    pub rot: [[f32; 4]; 3],
    /// `1 / scale`.
    pub inv_scale: f32,
    /// Simulated Gaussians (particles `0 .. simulated` move one each).
    pub simulated: u32,
    /// Particles in a simulated frame (simulated plus filling).
    pub particles: u32,
    /// Padding (a uniform is a multiple of 16 bytes).
    pub _pad: u32,
}

/// A simulation link in backend buffers.
pub struct LinkBufs<B: SplatKernels> {
    /// The transform.
    pub consts: LinkConsts,
    /// Scene index of the Gaussian particle `s` moves, `consts.simulated` entries.
    pub simulated: B::Buf<u32>,
}

/// A scene in backend buffers.
pub struct SceneBufs<B: SplatKernels> {
    /// Number of Gaussians.
    pub n: usize,
    /// SH degree.
    pub sh_degree: u32,
    /// Centres (deformed centres when `f` is given).
    pub means: B::Buf<[f32; 3]>,
    /// Log-scales.
    pub log_scales: B::Buf<[f32; 3]>,
    /// Quaternions.
    pub quats: B::Buf<[f32; 4]>,
    /// Opacity logits.
    pub opacity_logits: B::Buf<f32>,
    /// SH `[n][k][c]`.
    pub sh: B::Buf<f32>,
    /// Deformation gradients.
    pub f: Option<B::Buf<[[f32; 3]; 3]>>,
}

/// Tile lists in backend buffers (see [`crate::raster::TileBins`]).
pub struct TileBufs<B: SplatKernels> {
    /// Offsets, `tiles + 1` entries.
    pub offsets: B::Buf<u32>,
    /// Gaussian ids, front to back per tile.
    pub ids: B::Buf<u32>,
    /// Number of (tile, Gaussian) pairs.
    pub intersections: usize,
}

/// Rendered images in backend buffers, with what the VJP reads back (the forward's tape).
pub struct ImageBufs<B: SplatKernels> {
    /// `[H][W][3]`.
    pub rgb: B::Buf<f32>,
    /// `[H][W]`.
    pub alpha: B::Buf<f32>,
    /// `[H][W]`.
    pub depth: B::Buf<f32>,
    /// Final transmittance per pixel, `[H][W]` (kept exactly: `1 - alpha` loses digits when
    /// it is small).
    pub t_final: B::Buf<f32>,
    /// Per pixel, one past the tile-list position of the last Gaussian composited
    /// ([`crate::raster::PixelOut::last`]), `[H][W]`.
    pub last: B::Buf<u32>,
}

/// Scene gradients in backend buffers.
pub struct SceneGradBufs<B: SplatKernels> {
    /// dL/dmean.
    pub means: B::Buf<[f32; 3]>,
    /// dL/dlog_scale.
    pub log_scales: B::Buf<[f32; 3]>,
    /// dL/dquat.
    pub quats: B::Buf<[f32; 4]>,
    /// dL/dopacity_logit.
    pub opacity_logits: B::Buf<f32>,
    /// dL/dsh.
    pub sh: B::Buf<f32>,
    /// dL/dF.
    pub f: Option<B::Buf<[[f32; 3]; 3]>>,
}

/// The stages of the renderer on one backend.
pub trait SplatKernels: Backend {
    /// Projects every Gaussian (culled ones get radii (0, 0)).
    fn project(
        &self,
        scene: &SceneBufs<Self>,
        cam: &CameraConsts,
    ) -> Result<Self::Buf<Projected<f32>>, Self::Error>;
    /// Depth-sorts the visible Gaussians and bins them into 16x16 tiles.
    fn bin_tiles(
        &self,
        proj: &Self::Buf<Projected<f32>>,
        cam: &CameraConsts,
    ) -> Result<TileBufs<Self>, Self::Error>;
    /// Composites every pixel of rows `cam.rows` (images of those rows only).
    fn rasterize(
        &self,
        proj: &Self::Buf<Projected<f32>>,
        bins: &TileBufs<Self>,
        cam: &CameraConsts,
    ) -> Result<ImageBufs<Self>, Self::Error>;
    /// VJP of [`SplatKernels::rasterize`] for `dL/drgb` (rows `cam.rows`), **added** to
    /// `d_proj` (one entry per Gaussian), so that the VJPs of several bands of rows of one
    /// projection sum into one gradient. With the forward's image (`tape`: its `t_final` and
    /// `last`) each pixel is walked back to front without being composited again; without it
    /// the backend composites what it needs itself (the CPU backends one pass per pixel
    /// keeping the trace, a GPU backend its `rasterize`).
    fn rasterize_vjp(
        &self,
        proj: &Self::Buf<Projected<f32>>,
        bins: &TileBufs<Self>,
        cam: &CameraConsts,
        tape: Option<&ImageBufs<Self>>,
        d_rgb: &Self::Buf<f32>,
        d_proj: &mut Self::Buf<ProjectedGrad<f32>>,
    ) -> Result<(), Self::Error>;
    /// Moves the simulated Gaussians to a simulated frame through the link: for particle
    /// `s < link.consts.simulated`, `means[simulated[s]] = link_point(x[s])` and
    /// `f[simulated[s]] = link_f(f_sim[s])` ([`crate::link::link_point`],
    /// [`crate::link::link_f`]; `f_sim` row-major, simulation space); every other entry is
    /// left as it is.
    fn deform(
        &self,
        link: &LinkBufs<Self>,
        x: &Self::Buf<[f32; 3]>,
        f_sim: &Self::Buf<[f32; 9]>,
        means: &mut Self::Buf<[f32; 3]>,
        f: &mut Self::Buf<[[f32; 3]; 3]>,
    ) -> Result<(), Self::Error>;
    /// VJP of [`SplatKernels::deform`]: **adds** to `dx` and `df_sim` (one entry per
    /// particle; filling particles untouched) the gradient of a loss whose gradient with
    /// respect to the moved Gaussians is `d_means`, `d_f` ([`crate::link::link_point_vjp`],
    /// [`crate::link::link_f_vjp`]).
    fn deform_vjp(
        &self,
        link: &LinkBufs<Self>,
        d_means: &Self::Buf<[f32; 3]>,
        d_f: &Self::Buf<[[f32; 3]; 3]>,
        dx: &mut Self::Buf<[f32; 3]>,
        df_sim: &mut Self::Buf<[f32; 9]>,
    ) -> Result<(), Self::Error>;
    /// VJP of [`SplatKernels::project`].
    fn project_vjp(
        &self,
        scene: &SceneBufs<Self>,
        cam: &CameraConsts,
        proj: &Self::Buf<Projected<f32>>,
        d_proj: &Self::Buf<ProjectedGrad<f32>>,
    ) -> Result<SceneGradBufs<Self>, Self::Error>;
}
