//! The user-facing [`Renderer`] trait and [`SplatRenderer`], its implementation for any
//! [`SplatKernels`] backend.

use crate::camera::{Camera, RenderSettings};
use crate::error::{Error, Result};
use crate::gaussians::{Deformation, GaussianGrads, Gaussians};
use crate::kernels::{CameraConsts, SceneBufs, SplatKernels};

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
    /// Gaussians that passed culling.
    pub visible: usize,
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

    fn upload(&self, g: &Gaussians, deform: Option<&Deformation>) -> Result<SceneBufs<B>> {
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

impl<B: SplatKernels> Renderer for SplatRenderer<B> {
    fn render(
        &mut self,
        scene: &Gaussians,
        deform: Option<&Deformation>,
        cam: &Camera,
        settings: &RenderSettings,
    ) -> Result<Image> {
        cam.validate("camera").map_err(Error::Mismatch)?;
        let bufs = self.upload(scene, deform)?;
        let be = |e: B::Error| Error::Backend(Box::new(e));
        let cc = CameraConsts::new(cam, settings, scene.sh_degree);
        let b = &self.backend;
        let proj = b.project(&bufs, &cc).map_err(be)?;
        let bins = b.bin_tiles(&proj, &cc).map_err(be)?;
        let img = b.rasterize(&proj, &bins, &cc).map_err(be)?;
        let out = Image {
            width: cam.width,
            height: cam.height,
            rgb: b.download_owned(img.rgb).map_err(be)?,
            alpha: b.download_owned(img.alpha).map_err(be)?,
            depth: b.download_owned(img.depth).map_err(be)?,
        };
        self.stats.intersections = bins.intersections;
        self.stats.visible = b
            .download(&proj)
            .map_err(be)?
            .iter()
            .filter(|p| p.radii != [0, 0])
            .count();
        Ok(out)
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
        let bufs = self.upload(scene, deform)?;
        let be = |e: B::Error| Error::Backend(Box::new(e));
        let cc = CameraConsts::new(cam, settings, scene.sh_degree);
        let b = &self.backend;
        let proj = b.project(&bufs, &cc).map_err(be)?;
        let bins = b.bin_tiles(&proj, &cc).map_err(be)?;
        let d = b.upload(d_rgb).map_err(be)?;
        let d_proj = b.rasterize_vjp(&proj, &bins, &cc, &d).map_err(be)?;
        let g = b.project_vjp(&bufs, &cc, &proj, &d_proj).map_err(be)?;
        // The scene's buffers and the intermediates are freed before the gradients come back.
        drop((bufs, proj, bins, d, d_proj));
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
