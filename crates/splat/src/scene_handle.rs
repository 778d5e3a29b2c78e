//! A scene kept on a renderer's backend for many frames ([`SceneHandle`]): what a deformation
//! leaves unchanged (scales, rotations, opacities, colours) is uploaded once
//! ([`crate::Renderer::upload_scene`]); each frame then moves only the deformed centres and
//! deformation gradients to the backend ([`crate::Renderer::prepare_frame_on`]) and brings
//! back only their gradients ([`crate::Renderer::frame_vjp_motion_on`]).

use crate::error::{Error, Result};
use crate::frame::{backend, other_backend, PreparedFrame};
use crate::gaussians::{Deformation, GaussianGrads, Gaussians};
use crate::kernels::{SceneBufs, SplatKernels};
use crate::renderer::SplatRenderer;
use crate::{Camera, RenderSettings};
use std::any::Any;

/// A scene uploaded once to a renderer's backend (or, for a renderer without its own, held as
/// a host copy): opaque, used only with renderers of the backend that made it.
pub struct SceneHandle {
    state: Box<dyn Any + Send + Sync>,
    gaussians: usize,
}

impl std::fmt::Debug for SceneHandle {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SceneHandle")
            .field("gaussians", &self.gaussians)
            .finish_non_exhaustive()
    }
}

impl SceneHandle {
    /// A host copy of `scene` (what a renderer without device buffers keeps).
    pub fn host(scene: &Gaussians) -> SceneHandle {
        SceneHandle {
            gaussians: scene.len(),
            state: Box::new(scene.clone()),
        }
    }

    /// The host copy of a handle made by [`SceneHandle::host`].
    pub fn host_scene(&self) -> Result<&Gaussians> {
        self.state.downcast_ref().ok_or_else(|| {
            Error::Mismatch("the scene was uploaded by a renderer of another backend".into())
        })
    }

    /// Number of Gaussians.
    pub fn gaussians(&self) -> usize {
        self.gaussians
    }

    fn bufs<B: SplatKernels>(&mut self) -> Result<&mut SceneBufs<B>> {
        self.state.downcast_mut().ok_or_else(other_backend)
    }
}

impl<B: SplatKernels> SplatRenderer<B> {
    /// Uploads `scene` once for many frames ([`crate::Renderer::upload_scene`]).
    pub fn upload_scene(&mut self, scene: &Gaussians) -> Result<SceneHandle> {
        let bufs = self.upload(scene, None)?;
        Ok(SceneHandle {
            gaussians: bufs.n,
            state: Box::new(bufs),
        })
    }

    /// Runs `f` on the handle's buffers with the centres and deformation gradients of
    /// `deform` in place of the undeformed centres (put back afterwards).
    fn with_deformed<R>(
        &mut self,
        scene: &mut SceneHandle,
        deform: &Deformation,
        f: impl FnOnce(&mut Self, &SceneBufs<B>) -> Result<R>,
    ) -> Result<R> {
        deform.validate(scene.gaussians, "deformation")?;
        let means = self.backend.upload(&deform.means).map_err(backend)?;
        let fb = self.backend.upload(&deform.f).map_err(backend)?;
        let bufs = scene.bufs::<B>()?;
        let rest = std::mem::replace(&mut bufs.means, means);
        bufs.f = Some(fb);
        let r = f(self, bufs);
        bufs.means = rest;
        bufs.f = None;
        r
    }

    /// [`SplatRenderer::prepare_frame`] of the uploaded scene deformed by `deform`.
    pub fn prepare_frame_on(
        &mut self,
        scene: &mut SceneHandle,
        deform: &Deformation,
        cam: &Camera,
        settings: &RenderSettings,
    ) -> Result<PreparedFrame> {
        cam.validate("camera").map_err(Error::Mismatch)?;
        self.with_deformed(scene, deform, |r, bufs| r.prepare_bufs(bufs, cam, settings))
    }

    /// [`SplatRenderer::frame_vjp_motion`] of a frame prepared by
    /// [`SplatRenderer::prepare_frame_on`] from the same handle and deformation.
    pub fn frame_vjp_motion_on(
        &mut self,
        frame: PreparedFrame,
        scene: &mut SceneHandle,
        deform: &Deformation,
    ) -> Result<GaussianGrads> {
        let g = self.with_deformed(scene, deform, |r, bufs| r.frame_vjp_of(frame, bufs))?;
        self.download_motion_grads(g)
    }
}
