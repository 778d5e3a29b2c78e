//! The user-facing [`Renderer`] trait and [`SplatRenderer`], its implementation for any
//! [`SplatKernels`] backend.

use crate::camera::{Camera, RenderSettings};
use crate::error::{Error, Result};
use crate::frame::PreparedFrame;
use crate::gaussians::{Deformation, GaussianGrads, Gaussians};
use crate::kernels::{
    AnyBuf, CameraConsts, ImageBufs, SceneBufs, SceneGradBufs, SplatKernels, TileBufs,
};
use crate::link::SimLink;
use crate::project::Projected;
use crate::scene_handle::SceneHandle;
use std::ops::Range;

/// A rendered image, row 0 at the top.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Image {
    /// Width.
    pub width: u32,
    /// Height.
    pub height: u32,
    /// Colour, `[H][W][3]`, background included.
    pub rgb: Vec<f32>,
    /// Accumulated opacity, `[H][W]`.
    pub alpha: Vec<f32>,
    /// Expected depth, `[H][W]` (0 where nothing was hit).
    pub depth: Vec<f32>,
}

/// Statistics of the last render.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct RenderStats {
    /// Gaussians that passed culling (counted by [`Renderer::render`] and its VJP; a prepared
    /// frame leaves the projection on the backend and records `None`).
    pub visible: Option<usize>,
    /// (tile, Gaussian) pairs.
    pub intersections: usize,
}

/// Renders Gaussians (optionally deformed) and differentiates the colour image.
pub trait Renderer {
    /// Renders `scene` (deformed by `deform` when given) from `cam`.
    fn render(
        &mut self,
        scene: &Gaussians,
        deform: Option<&Deformation>,
        cam: &Camera,
        settings: &RenderSettings,
    ) -> Result<Image>;

    /// The gradient of `sum(d_rgb * rgb)` with respect to the raw parameters of `scene`
    /// (positions: the deformed ones when `deform` is given; plus dL/dF).
    fn render_vjp(
        &mut self,
        scene: &Gaussians,
        deform: Option<&Deformation>,
        cam: &Camera,
        settings: &RenderSettings,
        d_rgb: &[f32],
    ) -> Result<GaussianGrads>;

    /// Projects, depth-sorts and bins `scene` (deformed by `deform` when given) once for the
    /// whole image of `cam` (the full image of a cropped camera), for rendering and
    /// differentiating any rows of it ([`Renderer::render_rows`],
    /// [`Renderer::render_rows_vjp`]; see [`crate::frame`]).
    fn prepare_frame(
        &mut self,
        scene: &Gaussians,
        deform: Option<&Deformation>,
        cam: &Camera,
        settings: &RenderSettings,
    ) -> Result<PreparedFrame>;

    /// Rows `rows` of a prepared frame's image: the whole image's rows, the same values as
    /// [`Renderer::render`] from the camera cropped to them ([`Camera::crop_rows`]).
    fn render_rows(&mut self, frame: &PreparedFrame, rows: Range<u32>) -> Result<Image>;

    /// Adds the VJP of rows `rows` for `d_rgb` (`rows.len() x W x 3` values) to the frame's
    /// projection gradient; [`Renderer::frame_vjp`] gives the scene gradient of the sum.
    fn render_rows_vjp(
        &mut self,
        frame: &mut PreparedFrame,
        rows: Range<u32>,
        d_rgb: &[f32],
    ) -> Result<()>;

    /// The gradient of the sum over the rows VJPs added to `frame` with respect to the raw
    /// parameters of its scene, as [`Renderer::render_vjp`] gives it; `scene` and `deform`
    /// must be the ones the frame was prepared from (only their sizes are checked).
    fn frame_vjp(
        &mut self,
        frame: PreparedFrame,
        scene: &Gaussians,
        deform: Option<&Deformation>,
    ) -> Result<GaussianGrads>;

    /// [`Renderer::frame_vjp`] for a caller that needs only the gradients of the deformation:
    /// `means` (the deformed positions) and `f` are filled, the other arrays left empty (a
    /// GPU backend reads back only those two).
    fn frame_vjp_motion(
        &mut self,
        frame: PreparedFrame,
        scene: &Gaussians,
        deform: &Deformation,
    ) -> Result<GaussianGrads> {
        let g = self.frame_vjp(frame, scene, Some(deform))?;
        Ok(GaussianGrads {
            means: g.means,
            f: g.f,
            ..Default::default()
        })
    }

    /// Uploads `scene` to this renderer's backend once, for many frames of it
    /// ([`Renderer::prepare_frame_on`]); the default keeps a host copy.
    fn upload_scene(&mut self, scene: &Gaussians) -> Result<SceneHandle> {
        Ok(SceneHandle::host(scene))
    }

    /// [`Renderer::prepare_frame`] of an uploaded scene deformed by `deform`: only the
    /// deformed centres and deformation gradients move to the backend.
    fn prepare_frame_on(
        &mut self,
        scene: &mut SceneHandle,
        deform: &Deformation,
        cam: &Camera,
        settings: &RenderSettings,
    ) -> Result<PreparedFrame> {
        let g = scene.host_scene()?.clone();
        self.prepare_frame(&g, Some(deform), cam, settings)
    }

    /// [`Renderer::frame_vjp_motion`] of a frame prepared by [`Renderer::prepare_frame_on`]
    /// from the same handle and deformation.
    fn frame_vjp_motion_on(
        &mut self,
        frame: PreparedFrame,
        scene: &mut SceneHandle,
        deform: &Deformation,
    ) -> Result<GaussianGrads> {
        let g = scene.host_scene()?.clone();
        self.frame_vjp_motion(frame, &g, deform)
    }

    /// Attaches a simulation link to a scene this renderer uploaded, so that its frames can
    /// come from particle buffers on the backend ([`Renderer::prepare_frame_linked`]). A
    /// renderer without device buffers refuses.
    fn link_scene(&mut self, scene: &mut SceneHandle, link: &SimLink) -> Result<()> {
        let _ = (scene, link);
        Err(no_device_scene())
    }

    /// [`Renderer::prepare_frame`] of a linked scene ([`Renderer::link_scene`]) with its
    /// simulated Gaussians at particle positions `x` (`[f32; 3]`) and deformation gradients
    /// `f_sim` (`[f32; 9]`, row-major, simulation space): buffers of this renderer's backend
    /// (a simulation's [`AnyBuf`]s), so nothing crosses to the host.
    fn prepare_frame_linked(
        &mut self,
        scene: &mut SceneHandle,
        x: &AnyBuf,
        f_sim: &AnyBuf,
        cam: &Camera,
        settings: &RenderSettings,
    ) -> Result<PreparedFrame> {
        let _ = (scene, x, f_sim, cam, settings);
        Err(no_device_scene())
    }

    /// The gradient of the rows VJPs added to a frame prepared by
    /// [`Renderer::prepare_frame_linked`] (same handle and particles) with respect to the
    /// particles' positions and deformation gradients, as buffers of the backend (`[f32; 3]`
    /// and row-major `[f32; 9]` per particle).
    fn frame_vjp_linked(
        &mut self,
        frame: PreparedFrame,
        scene: &mut SceneHandle,
        x: &AnyBuf,
        f_sim: &AnyBuf,
    ) -> Result<(AnyBuf, AnyBuf)> {
        let _ = (frame, scene, x, f_sim);
        Err(no_device_scene())
    }
}

/// What the [`Renderer`] trait's linked-frame methods answer for a renderer without device
/// buffers.
fn no_device_scene() -> Error {
    Error::Mismatch("this renderer keeps no scene on a device to link".into())
}

/// [`Renderer`] over any kernel backend.
pub struct SplatRenderer<B: SplatKernels> {
    /// The backend.
    pub backend: B,
    /// Statistics of the last render.
    pub stats: RenderStats,
}

impl<B: SplatKernels> SplatRenderer<B> {
    /// Wraps a backend.
    pub fn new(backend: B) -> Self {
        SplatRenderer {
            backend,
            stats: RenderStats::default(),
        }
    }

    pub(crate) fn upload(
        &self,
        g: &Gaussians,
        deform: Option<&Deformation>,
    ) -> Result<SceneBufs<B>> {
        g.validate("scene")?;
        if let Some(d) = deform {
            d.validate(g.len(), "deformation")?;
        }
        let be = |e: B::Error| Error::Backend(Box::new(e));
        let b = &self.backend;
        Ok(SceneBufs {
            n: g.len(),
            sh_degree: g.sh_degree,
            means: b
                .upload(deform.map_or(&g.means, |d| &d.means))
                .map_err(be)?,
            log_scales: b.upload(&g.log_scales).map_err(be)?,
            quats: b.upload(&g.quats).map_err(be)?,
            opacity_logits: b.upload(&g.opacity_logits).map_err(be)?,
            sh: b.upload(&g.sh).map_err(be)?,
            f: match deform {
                Some(d) => Some(b.upload(&d.f).map_err(be)?),
                None => None,
            },
        })
    }
}

/// What a render keeps for its VJP, in backend buffers: the uploaded scene, the projection,
/// the tile lists and the per-pixel tape (final transmittance, last composited position).
/// [`SplatRenderer::render_taped`] returns it, [`SplatRenderer::render_vjp_taped`] consumes
/// it: the VJP then neither projects, bins nor composites again. It holds the scene on the
/// backend (about 60 bytes per Gaussian plus the SH) and 8 bytes per pixel besides the image:
/// keep one only while its gradient is still to come.
pub struct RenderTape<B: SplatKernels> {
    bufs: SceneBufs<B>,
    cc: CameraConsts,
    proj: B::Buf<Projected<f32>>,
    bins: TileBufs<B>,
    img: ImageBufs<B>,
    width: u32,
    height: u32,
}

impl<B: SplatKernels> RenderTape<B> {
    /// Image width and height.
    pub fn size(&self) -> (u32, u32) {
        (self.width, self.height)
    }
}

impl<B: SplatKernels> SplatRenderer<B> {
    /// Uploads, projects, bins and composites: the forward pass with its tape.
    fn forward(
        &mut self,
        scene: &Gaussians,
        deform: Option<&Deformation>,
        cam: &Camera,
        settings: &RenderSettings,
    ) -> Result<RenderTape<B>> {
        cam.validate("camera").map_err(Error::Mismatch)?;
        let bufs = self.upload(scene, deform)?;
        let be = |e: B::Error| Error::Backend(Box::new(e));
        let cc = CameraConsts::new(cam, settings, scene.sh_degree);
        let b = &self.backend;
        let proj = b.project(&bufs, &cc).map_err(be)?;
        let bins = b.bin_tiles(&proj, &cc).map_err(be)?;
        let img = b.rasterize(&proj, &bins, &cc).map_err(be)?;
        Ok(RenderTape {
            bufs,
            cc,
            proj,
            bins,
            img,
            width: cam.width,
            height: cam.height,
        })
    }

    /// Records the statistics of a render (reads the projection back).
    fn record_stats(&mut self, tape: &RenderTape<B>) -> Result<()> {
        self.record(&tape.proj, &tape.bins)
    }

    /// Records the statistics of a projection and its tile lists (reads the projection
    /// back).
    pub(crate) fn record(
        &mut self,
        proj: &B::Buf<Projected<f32>>,
        bins: &TileBufs<B>,
    ) -> Result<()> {
        let be = |e: B::Error| Error::Backend(Box::new(e));
        self.stats.intersections = bins.intersections;
        self.stats.visible = Some(
            self.backend
                .download(proj)
                .map_err(be)?
                .iter()
                .filter(|p| p.radii != [0, 0])
                .count(),
        );
        Ok(())
    }

    /// Renders as [`Renderer::render`] and keeps what the VJP needs
    /// ([`SplatRenderer::render_vjp_taped`]).
    pub fn render_taped(
        &mut self,
        scene: &Gaussians,
        deform: Option<&Deformation>,
        cam: &Camera,
        settings: &RenderSettings,
    ) -> Result<(Image, RenderTape<B>)> {
        let tape = self.forward(scene, deform, cam, settings)?;
        self.record_stats(&tape)?;
        let be = |e: B::Error| Error::Backend(Box::new(e));
        let b = &self.backend;
        let out = Image {
            width: tape.width,
            height: tape.height,
            rgb: b.download(&tape.img.rgb).map_err(be)?,
            alpha: b.download(&tape.img.alpha).map_err(be)?,
            depth: b.download(&tape.img.depth).map_err(be)?,
        };
        Ok((out, tape))
    }

    /// The gradient of `sum(d_rgb * rgb)` for the render that made `tape` (as
    /// [`Renderer::render_vjp`], without projecting, binning or compositing again).
    pub fn render_vjp_taped(
        &mut self,
        tape: RenderTape<B>,
        d_rgb: &[f32],
    ) -> Result<GaussianGrads> {
        let want = tape.width as usize * tape.height as usize * 3;
        if d_rgb.len() != want {
            return Err(Error::Mismatch(format!(
                "dL/drgb has {} values, the {}x{} image needs {want}",
                d_rgb.len(),
                tape.width,
                tape.height
            )));
        }
        let RenderTape {
            bufs,
            cc,
            proj,
            bins,
            img,
            ..
        } = tape;
        self.backward(bufs, cc, proj, bins, Some(img), d_rgb)
    }

    /// The reverse stages from the forward's buffers (`img`: its per-pixel tape, when kept).
    fn backward(
        &mut self,
        bufs: SceneBufs<B>,
        cc: CameraConsts,
        proj: B::Buf<Projected<f32>>,
        bins: TileBufs<B>,
        img: Option<ImageBufs<B>>,
        d_rgb: &[f32],
    ) -> Result<GaussianGrads> {
        let be = |e: B::Error| Error::Backend(Box::new(e));
        let b = &self.backend;
        let d = b.upload(d_rgb).map_err(be)?;
        let mut d_proj = b.zeros(bufs.n).map_err(be)?;
        b.rasterize_vjp(&proj, &bins, &cc, img.as_ref(), &d, &mut d_proj)
            .map_err(be)?;
        drop((img, bins, d));
        let g = b.project_vjp(&bufs, &cc, &proj, &d_proj).map_err(be)?;
        // The scene's buffers and the intermediates are freed before the gradients come back.
        drop((bufs, proj, d_proj));
        self.download_grads(g)
    }

    /// Brings the position and deformation-gradient gradients back to the host; the others
    /// are freed on the backend.
    pub(crate) fn download_motion_grads(&self, g: SceneGradBufs<B>) -> Result<GaussianGrads> {
        let be = |e: B::Error| Error::Backend(Box::new(e));
        let b = &self.backend;
        Ok(GaussianGrads {
            means: b.download_owned(g.means).map_err(be)?,
            f: match g.f {
                Some(f) => b.download_owned(f).map_err(be)?,
                None => Vec::new(),
            },
            ..Default::default()
        })
    }

    /// Brings scene gradients back to the host, freeing each buffer as it comes.
    pub(crate) fn download_grads(&self, g: SceneGradBufs<B>) -> Result<GaussianGrads> {
        let be = |e: B::Error| Error::Backend(Box::new(e));
        let b = &self.backend;
        Ok(GaussianGrads {
            means: b.download_owned(g.means).map_err(be)?,
            log_scales: b.download_owned(g.log_scales).map_err(be)?,
            quats: b.download_owned(g.quats).map_err(be)?,
            opacity_logits: b.download_owned(g.opacity_logits).map_err(be)?,
            sh: b.download_owned(g.sh).map_err(be)?,
            f: match g.f {
                Some(f) => b.download_owned(f).map_err(be)?,
                None => Vec::new(),
            },
        })
    }
}

impl<B: SplatKernels> Renderer for SplatRenderer<B> {
    fn render(
        &mut self,
        scene: &Gaussians,
        deform: Option<&Deformation>,
        cam: &Camera,
        settings: &RenderSettings,
    ) -> Result<Image> {
        let tape = self.forward(scene, deform, cam, settings)?;
        self.record_stats(&tape)?;
        let be = |e: B::Error| Error::Backend(Box::new(e));
        let b = &self.backend;
        Ok(Image {
            width: tape.width,
            height: tape.height,
            rgb: b.download_owned(tape.img.rgb).map_err(be)?,
            alpha: b.download_owned(tape.img.alpha).map_err(be)?,
            depth: b.download_owned(tape.img.depth).map_err(be)?,
        })
    }

    fn render_vjp(
        &mut self,
        scene: &Gaussians,
        deform: Option<&Deformation>,
        cam: &Camera,
        settings: &RenderSettings,
        d_rgb: &[f32],
    ) -> Result<GaussianGrads> {
        cam.validate("camera").map_err(Error::Mismatch)?;
        let want = cam.width as usize * cam.height as usize * 3;
        if d_rgb.len() != want {
            return Err(Error::Mismatch(format!(
                "dL/drgb has {} values, the {}x{} image needs {want}",
                d_rgb.len(),
                cam.width,
                cam.height
            )));
        }
        // No image is needed: the backend composites what the VJP needs itself.
        let bufs = self.upload(scene, deform)?;
        let be = |e: B::Error| Error::Backend(Box::new(e));
        let cc = CameraConsts::new(cam, settings, scene.sh_degree);
        let proj = self.backend.project(&bufs, &cc).map_err(be)?;
        let bins = self.backend.bin_tiles(&proj, &cc).map_err(be)?;
        self.backward(bufs, cc, proj, bins, None, d_rgb)
    }

    fn prepare_frame(
        &mut self,
        scene: &Gaussians,
        deform: Option<&Deformation>,
        cam: &Camera,
        settings: &RenderSettings,
    ) -> Result<PreparedFrame> {
        SplatRenderer::prepare_frame(self, scene, deform, cam, settings)
    }

    fn render_rows(&mut self, frame: &PreparedFrame, rows: Range<u32>) -> Result<Image> {
        SplatRenderer::render_rows(self, frame, rows)
    }

    fn render_rows_vjp(
        &mut self,
        frame: &mut PreparedFrame,
        rows: Range<u32>,
        d_rgb: &[f32],
    ) -> Result<()> {
        SplatRenderer::render_rows_vjp(self, frame, rows, d_rgb)
    }

    fn frame_vjp(
        &mut self,
        frame: PreparedFrame,
        scene: &Gaussians,
        deform: Option<&Deformation>,
    ) -> Result<GaussianGrads> {
        SplatRenderer::frame_vjp(self, frame, scene, deform)
    }

    fn frame_vjp_motion(
        &mut self,
        frame: PreparedFrame,
        scene: &Gaussians,
        deform: &Deformation,
    ) -> Result<GaussianGrads> {
        SplatRenderer::frame_vjp_motion(self, frame, scene, deform)
    }

    fn upload_scene(&mut self, scene: &Gaussians) -> Result<SceneHandle> {
        SplatRenderer::upload_scene(self, scene)
    }

    fn prepare_frame_on(
        &mut self,
        scene: &mut SceneHandle,
        deform: &Deformation,
        cam: &Camera,
        settings: &RenderSettings,
    ) -> Result<PreparedFrame> {
        SplatRenderer::prepare_frame_on(self, scene, deform, cam, settings)
    }

    fn frame_vjp_motion_on(
        &mut self,
        frame: PreparedFrame,
        scene: &mut SceneHandle,
        deform: &Deformation,
    ) -> Result<GaussianGrads> {
        SplatRenderer::frame_vjp_motion_on(self, frame, scene, deform)
    }

    fn link_scene(&mut self, scene: &mut SceneHandle, link: &SimLink) -> Result<()> {
        SplatRenderer::link_scene(self, scene, link)
    }

    fn prepare_frame_linked(
        &mut self,
        scene: &mut SceneHandle,
        x: &AnyBuf,
        f_sim: &AnyBuf,
        cam: &Camera,
        settings: &RenderSettings,
    ) -> Result<PreparedFrame> {
        SplatRenderer::prepare_frame_linked(self, scene, x, f_sim, cam, settings)
    }

    fn frame_vjp_linked(
        &mut self,
        frame: PreparedFrame,
        scene: &mut SceneHandle,
        x: &AnyBuf,
        f_sim: &AnyBuf,
    ) -> Result<(AnyBuf, AnyBuf)> {
        SplatRenderer::frame_vjp_linked(self, frame, scene, x, f_sim)
    }
}
