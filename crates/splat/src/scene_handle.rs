//! A scene kept on a renderer's backend for many frames ([`SceneHandle`]): what a deformation
//! leaves unchanged (scales, rotations, opacities, colours) is uploaded once
//! ([`crate::Renderer::upload_scene`]); each frame then moves only the deformed centres and
//! deformation gradients to the backend ([`crate::Renderer::prepare_frame_on`]) and brings
//! back only their gradients ([`crate::Renderer::frame_vjp_motion_on`]). With a simulation link
//! attached ([`crate::Renderer::link_scene`]) nothing of a frame crosses at all: the simulated
//! Gaussians are moved on the backend from the simulation's own particle buffers
//! ([`crate::Renderer::prepare_frame_linked`], the kernel [`SplatKernels::deform`]) and the
//! gradient comes back as particle buffers there ([`crate::Renderer::frame_vjp_linked`]).

use crate::error::{Error, Result};
use crate::frame::{backend, other_backend, PreparedFrame};
use crate::gaussians::{Deformation, GaussianGrads, Gaussians};
use crate::kernels::{AnyBuf, LinkBufs, SceneBufs, SplatKernels};
use crate::link::SimLink;
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

    fn device<B: SplatKernels>(&mut self) -> Result<&mut DeviceScene<B>> {
        self.state.downcast_mut().ok_or_else(other_backend)
    }
}

/// What a [`SceneHandle`] of a [`SplatRenderer`] holds: the scene's buffers and, once
/// [`SplatRenderer::link_scene`] attached a link, the link and the deformed scene it writes.
struct DeviceScene<B: SplatKernels> {
    bufs: SceneBufs<B>,
    linked: Option<Linked<B>>,
}

/// A link on the backend with the centres and deformation gradients of the scene it moves:
/// static Gaussians keep their centres and `F = I` for good, the kernel overwrites only the
/// simulated ones.
struct Linked<B: SplatKernels> {
    link: LinkBufs<B>,
    means: B::Buf<[f32; 3]>,
    f: Option<B::Buf<[[f32; 3]; 3]>>,
}

/// The buffer `a` as this backend's buffer of `T`, else a typed error naming what it is.
fn linked_buf<'a, B: SplatKernels, T: bytemuck::Pod + Send + Sync>(
    a: &'a AnyBuf,
    want: usize,
    what: &str,
) -> Result<&'a B::Buf<T>> {
    if a.len() != want {
        return Err(Error::Mismatch(format!(
            "{what}: {} particles, the link expects {want}",
            a.len()
        )));
    }
    a.get::<B, T>().ok_or_else(|| {
        Error::Mismatch(format!(
            "{what}: a buffer of backend {} (or of another scalar type), not of this renderer's",
            a.backend()
        ))
    })
}

impl<B: SplatKernels> SplatRenderer<B> {
    /// Uploads `scene` once for many frames ([`crate::Renderer::upload_scene`]).
    pub fn upload_scene(&mut self, scene: &Gaussians) -> Result<SceneHandle> {
        let bufs = self.upload(scene, None)?;
        Ok(SceneHandle {
            gaussians: bufs.n,
            state: Box::new(DeviceScene { bufs, linked: None }),
        })
    }

    /// Attaches `link` to a scene this renderer uploaded ([`crate::Renderer::link_scene`]):
    /// its simulated Gaussians then follow particle buffers that never leave the backend
    /// ([`SplatRenderer::prepare_frame_linked`]).
    pub fn link_scene(&mut self, scene: &mut SceneHandle, link: &SimLink) -> Result<()> {
        link.validate("link")?;
        if link.scene_gaussians != scene.gaussians {
            return Err(Error::Mismatch(format!(
                "link: for {} Gaussians, the scene has {}",
                link.scene_gaussians, scene.gaussians
            )));
        }
        let b = &self.backend;
        let dev = scene.device::<B>()?;
        let n = dev.bufs.n;
        let mut means = b.zeros::<[f32; 3]>(n).map_err(backend)?;
        b.copy(&dev.bufs.means, &mut means).map_err(backend)?;
        let eye = [[1.0f32, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
        let f = b.upload(&vec![eye; n]).map_err(backend)?;
        dev.linked = Some(Linked {
            link: LinkBufs {
                consts: link.consts(),
                simulated: b.upload(&link.simulated).map_err(backend)?,
            },
            means,
            f: Some(f),
        });
        Ok(())
    }

    /// Runs `f` on the handle's buffers with the simulated Gaussians moved to particle
    /// buffers `x` (`[f32; 3]`) and `f_sim` (`[f32; 9]`, row-major) of this backend.
    fn with_linked<R>(
        &mut self,
        scene: &mut SceneHandle,
        x: &AnyBuf,
        f_sim: &AnyBuf,
        f: impl FnOnce(&mut Self, &SceneBufs<B>, &LinkBufs<B>) -> Result<R>,
    ) -> Result<R> {
        let dev = scene.device::<B>()?;
        let Some(l) = dev.linked.as_mut() else {
            return Err(Error::Mismatch(
                "the scene has no simulation link (link_scene first)".into(),
            ));
        };
        let want = l.link.consts.particles as usize;
        let xb = linked_buf::<B, [f32; 3]>(x, want, "positions")?;
        let fb = linked_buf::<B, [f32; 9]>(f_sim, want, "deformation gradients")?;
        let Some(mut fw) = l.f.take() else {
            return Err(Error::Mismatch(
                "the scene's linked buffers were lost by an earlier failure".into(),
            ));
        };
        let r = self
            .backend
            .deform(&l.link, xb, fb, &mut l.means, &mut fw)
            .map_err(backend);
        if let Err(e) = r {
            l.f = Some(fw);
            return Err(e);
        }
        std::mem::swap(&mut dev.bufs.means, &mut l.means);
        dev.bufs.f = Some(fw);
        let r = f(self, &dev.bufs, &l.link);
        std::mem::swap(&mut dev.bufs.means, &mut l.means);
        l.f = dev.bufs.f.take();
        r
    }

    /// [`SplatRenderer::prepare_frame`] of the uploaded scene with its simulated Gaussians
    /// at the particles `x`, `f_sim` ([`crate::Renderer::prepare_frame_linked`]).
    pub fn prepare_frame_linked(
        &mut self,
        scene: &mut SceneHandle,
        x: &AnyBuf,
        f_sim: &AnyBuf,
        cam: &Camera,
        settings: &RenderSettings,
    ) -> Result<PreparedFrame> {
        cam.validate("camera").map_err(Error::Mismatch)?;
        self.with_linked(scene, x, f_sim, |r, bufs, _| {
            r.prepare_bufs(bufs, cam, settings)
        })
    }

    /// The gradient of the rows VJPs added to a frame prepared by
    /// [`SplatRenderer::prepare_frame_linked`] (from the same handle and particles) with
    /// respect to the particles' positions and row-major deformation gradients, as buffers
    /// of this backend (`[f32; 3]`, `[f32; 9]` per particle; filling particles get 0).
    pub fn frame_vjp_linked(
        &mut self,
        frame: PreparedFrame,
        scene: &mut SceneHandle,
        x: &AnyBuf,
        f_sim: &AnyBuf,
    ) -> Result<(AnyBuf, AnyBuf)> {
        self.with_linked(scene, x, f_sim, |r, bufs, link| {
            let g = r.frame_vjp_of(frame, bufs)?;
            let b = &r.backend;
            let n = link.consts.particles as usize;
            let mut dx = b.zeros::<[f32; 3]>(n).map_err(backend)?;
            let mut df = b.zeros::<[f32; 9]>(n).map_err(backend)?;
            let d_f = g.f.as_ref().ok_or_else(|| {
                Error::Mismatch("the backend's scene gradient has no dL/dF".into())
            })?;
            b.deform_vjp(link, &g.means, d_f, &mut dx, &mut df)
                .map_err(backend)?;
            Ok((AnyBuf::new(b, dx, n), AnyBuf::new(b, df, n)))
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
        let bufs = &mut scene.device::<B>()?.bufs;
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
