//! One frame rendered in row bands from one projection. [`SplatRenderer::prepare_frame`]
//! uploads the scene, projects it for the whole image, depth-sorts and bins it once; each band
//! of rows is then only composited ([`SplatRenderer::render_rows`]), and each band's VJP only
//! walks its own pixels back ([`SplatRenderer::render_rows_vjp`]), adding into one per-frame
//! projection gradient that the projection's VJP turns into the scene gradient once
//! ([`SplatRenderer::frame_vjp`]).
//!
//! The rows of any band are the whole image's rows, bit for bit (the same tiles, the same
//! per-pixel arithmetic), and the bands' VJPs add up to the whole image's VJP up to the order
//! of the per-Gaussian sums. A [`PreparedFrame`] holds, on the backend, the projection (48
//! bytes per Gaussian), the tile lists (4 bytes per tile intersection) and, once a band's VJP
//! was added, the projection gradient (36 bytes per Gaussian); not the scene, which
//! [`SplatRenderer::frame_vjp`] takes again.

use crate::camera::{Camera, RenderSettings};
use crate::error::{Error, Result};
use crate::gaussians::{Deformation, GaussianGrads, Gaussians};
use crate::kernels::{CameraConsts, SceneBufs, SceneGradBufs, SplatKernels, TileBufs};
use crate::project::{Projected, ProjectedGrad};
use crate::renderer::{Image, SplatRenderer};
use std::any::Any;
use std::ops::Range;

/// A frame projected, sorted and binned once, for rendering and differentiating any rows of
/// its image ([`crate::Renderer::prepare_frame`]). It belongs to the backend that made it.
pub struct PreparedFrame {
    state: Box<dyn Any + Send + Sync>,
    width: u32,
    height: u32,
    gaussians: usize,
    sh_degree: u32,
    deformed: bool,
    bytes: usize,
}

impl std::fmt::Debug for PreparedFrame {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("PreparedFrame")
            .field("width", &self.width)
            .field("height", &self.height)
            .field("gaussians", &self.gaussians)
            .field("deformed", &self.deformed)
            .finish_non_exhaustive()
    }
}

impl PreparedFrame {
    /// Width and height of the whole image.
    pub fn size(&self) -> (u32, u32) {
        (self.width, self.height)
    }

    /// Number of Gaussians projected.
    pub fn gaussians(&self) -> usize {
        self.gaussians
    }

    /// Bytes the frame holds once its VJP has started: the projection and its gradient per
    /// Gaussian and the tile lists (on the backend's memory: the heap for host backends).
    pub fn bytes(&self) -> usize {
        self.bytes
    }

    /// The checked rows `rows` of the image.
    fn rows(&self, rows: &Range<u32>) -> Result<()> {
        if rows.start < rows.end && rows.end <= self.height {
            Ok(())
        } else {
            Err(Error::Mismatch(format!(
                "rows {rows:?} of a {}-row image",
                self.height
            )))
        }
    }
}

/// What a [`PreparedFrame`] holds on backend `B`.
struct FrameState<B: SplatKernels> {
    /// The whole image's camera.
    cc: CameraConsts,
    proj: B::Buf<Projected<f32>>,
    bins: TileBufs<B>,
    /// The sum of the bands' projection gradients (allocated by the first band's VJP).
    d_proj: Option<B::Buf<ProjectedGrad<f32>>>,
}

pub(crate) fn backend<E: std::error::Error + Send + Sync + 'static>(e: E) -> Error {
    Error::Backend(Box::new(e))
}

pub(crate) fn other_backend() -> Error {
    Error::Mismatch("the frame was prepared by a renderer of another backend".into())
}

/// The whole image of `cam` (itself unless it is cropped).
fn full_image(cam: &Camera) -> Camera {
    let (height, cy) = cam.full_frame_y();
    Camera {
        height,
        cy,
        crop: None,
        ..cam.clone()
    }
}

impl<B: SplatKernels> SplatRenderer<B> {
    /// Uploads `scene` (deformed by `deform` when given), projects it for the whole image of
    /// `cam` (a cropped camera's full image), depth-sorts and bins it, and records the
    /// statistics ([`SplatRenderer::stats`]).
    pub fn prepare_frame(
        &mut self,
        scene: &Gaussians,
        deform: Option<&Deformation>,
        cam: &Camera,
        settings: &RenderSettings,
    ) -> Result<PreparedFrame> {
        cam.validate("camera").map_err(Error::Mismatch)?;
        let bufs = self.upload(scene, deform)?;
        self.prepare_bufs(&bufs, cam, settings)
    }

    /// Projects, sorts and bins the uploaded scene `bufs` for the whole image of `cam`.
    pub(crate) fn prepare_bufs(
        &mut self,
        bufs: &SceneBufs<B>,
        cam: &Camera,
        settings: &RenderSettings,
    ) -> Result<PreparedFrame> {
        let full = full_image(cam);
        let cc = CameraConsts::new(&full, settings, bufs.sh_degree);
        let proj = self.backend.project(bufs, &cc).map_err(backend)?;
        let bins = self.backend.bin_tiles(&proj, &cc).map_err(backend)?;
        // The projection stays on the backend (no statistics read back).
        self.stats.intersections = bins.intersections;
        self.stats.visible = None;
        let tiles = cc.tiles[0] as usize * cc.tiles[1] as usize;
        let bytes = bufs.n
            * (std::mem::size_of::<Projected<f32>>() + std::mem::size_of::<ProjectedGrad<f32>>())
            + 4 * (bins.intersections + tiles + 1);
        Ok(PreparedFrame {
            state: Box::new(FrameState::<B> {
                cc,
                proj,
                bins,
                d_proj: None,
            }),
            width: full.width,
            height: full.height,
            gaussians: bufs.n,
            sh_degree: bufs.sh_degree,
            deformed: bufs.f.is_some(),
            bytes,
        })
    }

    /// Rows `rows` of the prepared frame's image: the whole image's rows, the same values as
    /// rendering the camera cropped to them ([`Camera::crop_rows`]).
    pub fn render_rows(&mut self, frame: &PreparedFrame, rows: Range<u32>) -> Result<Image> {
        frame.rows(&rows)?;
        let st: &FrameState<B> = frame.state.downcast_ref().ok_or_else(other_backend)?;
        let b = &self.backend;
        let img = b
            .rasterize(&st.proj, &st.bins, &st.cc.with_rows(rows.clone()))
            .map_err(backend)?;
        drop((img.t_final, img.last));
        Ok(Image {
            width: frame.width,
            height: rows.len() as u32,
            rgb: b.download_owned(img.rgb).map_err(backend)?,
            alpha: b.download_owned(img.alpha).map_err(backend)?,
            depth: b.download_owned(img.depth).map_err(backend)?,
        })
    }

    /// Adds the VJP of rows `rows` for `d_rgb` (`rows.len() x W x 3` values) to the frame's
    /// projection gradient (each pixel composited again for its trace, as
    /// [`crate::Renderer::render_vjp`] does).
    pub fn render_rows_vjp(
        &mut self,
        frame: &mut PreparedFrame,
        rows: Range<u32>,
        d_rgb: &[f32],
    ) -> Result<()> {
        frame.rows(&rows)?;
        let want = frame.width as usize * rows.len() * 3;
        if d_rgb.len() != want {
            return Err(Error::Mismatch(format!(
                "dL/drgb has {} values, rows {rows:?} of a {}-pixel-wide image need {want}",
                d_rgb.len(),
                frame.width
            )));
        }
        let n = frame.gaussians;
        let st: &mut FrameState<B> = frame.state.downcast_mut().ok_or_else(other_backend)?;
        let b = &self.backend;
        let d = b.upload(d_rgb).map_err(backend)?;
        let acc = match &mut st.d_proj {
            Some(acc) => acc,
            slot => slot.insert(b.zeros(n).map_err(backend)?),
        };
        b.rasterize_vjp(&st.proj, &st.bins, &st.cc.with_rows(rows), None, &d, acc)
            .map_err(backend)
    }

    /// The gradient of the sum of the rows VJPs added to `frame` with respect to the raw
    /// parameters of its scene (zero when none was added), as [`crate::Renderer::render_vjp`]
    /// gives it. `scene` and `deform` must be the ones the frame was prepared from (their
    /// sizes are checked).
    pub fn frame_vjp(
        &mut self,
        frame: PreparedFrame,
        scene: &Gaussians,
        deform: Option<&Deformation>,
    ) -> Result<GaussianGrads> {
        let g = self.frame_vjp_bufs(frame, scene, deform)?;
        self.download_grads(g)
    }

    /// [`SplatRenderer::frame_vjp`] reading back only the gradients of the deformed positions
    /// and of F ([`crate::Renderer::frame_vjp_motion`]).
    pub fn frame_vjp_motion(
        &mut self,
        frame: PreparedFrame,
        scene: &Gaussians,
        deform: &Deformation,
    ) -> Result<GaussianGrads> {
        let g = self.frame_vjp_bufs(frame, scene, Some(deform))?;
        self.download_motion_grads(g)
    }

    fn frame_vjp_bufs(
        &mut self,
        frame: PreparedFrame,
        scene: &Gaussians,
        deform: Option<&Deformation>,
    ) -> Result<SceneGradBufs<B>> {
        let bufs = self.upload(scene, deform)?;
        self.frame_vjp_of(frame, &bufs)
    }

    /// The scene gradient of `frame`, prepared from the uploaded scene `bufs`.
    pub(crate) fn frame_vjp_of(
        &mut self,
        frame: PreparedFrame,
        bufs: &SceneBufs<B>,
    ) -> Result<SceneGradBufs<B>> {
        if bufs.n != frame.gaussians
            || bufs.sh_degree != frame.sh_degree
            || bufs.f.is_some() != frame.deformed
        {
            return Err(Error::Mismatch(format!(
                "the frame was prepared from {} Gaussians of SH degree {}{}, not {} of degree {}{}",
                frame.gaussians,
                frame.sh_degree,
                if frame.deformed { ", deformed" } else { "" },
                bufs.n,
                bufs.sh_degree,
                if bufs.f.is_some() { ", deformed" } else { "" },
            )));
        }
        let st: Box<FrameState<B>> = frame.state.downcast().map_err(|_| other_backend())?;
        let FrameState {
            cc,
            proj,
            bins,
            d_proj,
        } = *st;
        drop(bins);
        let b = &self.backend;
        let d_proj = match d_proj {
            Some(d) => d,
            None => b.zeros(frame.gaussians).map_err(backend)?,
        };
        let g = b.project_vjp(bufs, &cc, &proj, &d_proj).map_err(backend)?;
        drop((proj, d_proj));
        Ok(g)
    }
}
