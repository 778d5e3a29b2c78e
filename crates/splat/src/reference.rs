//! The single-threaded reference renderer, generic over `f32`/`f64`: every backend is tested
//! against it, and the f64 instance is what finite-difference checks differentiate. Stages
//! carry the kernel names: [`project`], [`bin_tiles`], [`rasterize`], [`rasterize_vjp`],
//! [`project_vjp`]; the per-Gaussian and per-pixel math lives in [`crate::project`] and
//! [`crate::raster`], shared with the fast backends.

use crate::camera::{Camera, RenderSettings};
use crate::gaussians::{sh_coeffs, Deformation, GaussianGrads, Gaussians};
use crate::project::{self as pj, CamParams, GaussianIn, Projected, ProjectedGrad};
use crate::raster::{self, Contribution, TileBins, TileSplats};
use crate::real::*;

/// A scene in the scalar type of the computation (see [`Gaussians`] and [`Deformation`]).
#[derive(Clone, Debug, Default)]
pub struct Scene<T> {
    /// SH degree.
    pub sh_degree: u32,
    /// Centres (deformed centres when `f` is given).
    pub means: Vec<V3<T>>,
    /// Log-scales.
    pub log_scales: Vec<V3<T>>,
    /// Quaternions.
    pub quats: Vec<[T; 4]>,
    /// Opacity logits.
    pub opacity_logits: Vec<T>,
    /// SH, `[n][k][c]`.
    pub sh: Vec<T>,
    /// Deformation gradients.
    pub f: Option<Vec<M3<T>>>,
}

impl<T: Real> Scene<T> {
    /// Converts Gaussians (and a deformation) to the scalar type `T`.
    pub fn new(g: &Gaussians, deform: Option<&Deformation>) -> Self {
        let v3 = |a: &[f32; 3]| a.map(|x| T::c(x as f64));
        Scene {
            sh_degree: g.sh_degree,
            means: match deform {
                Some(d) => d.means.iter().map(v3).collect(),
                None => g.means.iter().map(v3).collect(),
            },
            log_scales: g.log_scales.iter().map(v3).collect(),
            quats: g.quats.iter().map(|q| q.map(|x| T::c(x as f64))).collect(),
            opacity_logits: g.opacity_logits.iter().map(|&x| T::c(x as f64)).collect(),
            sh: g.sh.iter().map(|&x| T::c(x as f64)).collect(),
            f: deform.map(|d| {
                d.f.iter()
                    .map(|m| m.map(|r| r.map(|x| T::c(x as f64))))
                    .collect()
            }),
        }
    }

    /// Number of Gaussians.
    pub fn len(&self) -> usize {
        self.means.len()
    }

    /// True when empty.
    pub fn is_empty(&self) -> bool {
        self.means.is_empty()
    }

    /// Gaussian `i`'s inputs and SH slice.
    pub fn gaussian(&self, i: usize) -> (GaussianIn<T>, &[T]) {
        let k = sh_coeffs(self.sh_degree) * 3;
        (
            GaussianIn {
                mean: self.means[i],
                log_scale: self.log_scales[i],
                quat: self.quats[i],
                opacity_logit: self.opacity_logits[i],
                f: self.f.as_ref().map(|f| f[i]),
            },
            &self.sh[i * k..(i + 1) * k],
        )
    }
}

/// Rendered images, row 0 at the top.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Image<T> {
    /// Width.
    pub width: u32,
    /// Height.
    pub height: u32,
    /// Colour, `[H][W][3]`.
    pub rgb: Vec<T>,
    /// Accumulated opacity, `[H][W]`.
    pub alpha: Vec<T>,
    /// Expected depth, `[H][W]`.
    pub depth: Vec<T>,
    /// Final transmittance, `[H][W]` (the VJP's tape).
    pub t_final: Vec<T>,
    /// One past the last composited tile-list position, `[H][W]` (the VJP's tape).
    pub last: Vec<u32>,
}

/// Gradients of the raw scene parameters, in `T` (layouts as [`GaussianGrads`]), plus
/// dL/dSigma' per Gaussian.
#[derive(Clone, Debug, Default)]
pub struct SceneGrad<T> {
    /// dL/dmean.
    pub means: Vec<V3<T>>,
    /// dL/dlog_scale.
    pub log_scales: Vec<V3<T>>,
    /// dL/dquat.
    pub quats: Vec<[T; 4]>,
    /// dL/dopacity_logit.
    pub opacity_logits: Vec<T>,
    /// dL/dsh.
    pub sh: Vec<T>,
    /// dL/dF (empty without deformation).
    pub f: Vec<M3<T>>,
    /// dL/dSigma' (covariance after deformation).
    pub cov3d: Vec<M3<T>>,
}

impl<T: Real> SceneGrad<T> {
    /// Converts to the f32 [`GaussianGrads`].
    pub fn to_f32(&self) -> GaussianGrads {
        let v3 = |a: &V3<T>| a.map(|x| x.f64() as f32);
        GaussianGrads {
            means: self.means.iter().map(v3).collect(),
            log_scales: self.log_scales.iter().map(v3).collect(),
            quats: self
                .quats
                .iter()
                .map(|q| q.map(|x| x.f64() as f32))
                .collect(),
            opacity_logits: self.opacity_logits.iter().map(|x| x.f64() as f32).collect(),
            sh: self.sh.iter().map(|x| x.f64() as f32).collect(),
            f: self
                .f
                .iter()
                .map(|m| m.map(|r| r.map(|x| x.f64() as f32)))
                .collect(),
        }
    }
}

/// Projects every Gaussian; culled ones get radii (0, 0).
pub fn project<T: Real>(scene: &Scene<T>, cam: &CamParams<T>) -> Vec<Projected<T>> {
    (0..scene.len())
        .map(|i| {
            let (g, sh) = scene.gaussian(i);
            pj::project(&g, sh, scene.sh_degree, cam).unwrap_or_default()
        })
        .collect()
}

/// Sorts by depth and bins into 16x16 tiles.
pub fn bin_tiles<T: Real>(proj: &[Projected<T>], cam: &CamParams<T>) -> TileBins {
    let order = raster::depth_order(proj);
    raster::bin_tiles(proj, &order, cam.width, cam.height)
}

/// The tile rows covering image rows `rows`.
fn tile_rows(rows: [u32; 2]) -> std::ops::Range<u32> {
    rows[0] / 16..rows[1].div_ceil(16)
}

/// Composites every pixel of rows `cam.rows` ([`CamParams::rows`]; the image holds those
/// rows only).
pub fn rasterize<T: Real>(
    proj: &[Projected<T>],
    bins: &TileBins,
    cam: &CamParams<T>,
    background: &[T; 3],
) -> Image<T> {
    let w = cam.width;
    let [r0, r1] = cam.rows;
    let h = r1 - r0;
    let mut img = Image {
        width: w,
        height: h,
        rgb: vec![T::zero(); (w * h * 3) as usize],
        alpha: vec![T::zero(); (w * h) as usize],
        depth: vec![T::zero(); (w * h) as usize],
        t_final: vec![T::zero(); (w * h) as usize],
        last: vec![0; (w * h) as usize],
    };
    let mut tile = TileSplats::default();
    for ty in tile_rows(cam.rows) {
        for tx in 0..bins.tiles_x {
            tile.gather(bins.tile((ty * bins.tiles_x + tx) as usize), proj);
            for j in (ty * 16).max(r0)..((ty + 1) * 16).min(r1) {
                for i in tx * 16..((tx + 1) * 16).min(w) {
                    let (px, t) = raster::composite_pixel(i, j, &tile, background, None);
                    let k = ((j - r0) * w + i) as usize;
                    img.rgb[3 * k..3 * k + 3].copy_from_slice(&px.rgb);
                    img.alpha[k] = px.alpha;
                    img.depth[k] = px.depth;
                    img.t_final[k] = t;
                    img.last[k] = px.last;
                }
            }
        }
    }
    img
}

/// VJP of [`rasterize`] for `dL/drgb` (`[rows][W][3]`, the rows of `cam.rows`):
/// per-Gaussian gradients of the projection. `tape` is the forward's per-pixel
/// `(t_final, last)` ([`Image::t_final`], [`Image::last`]): with it each pixel is walked back
/// to front ([`raster::trace_back`]), without it each pixel is composited once more keeping
/// its trace.
pub fn rasterize_vjp<T: Real>(
    proj: &[Projected<T>],
    bins: &TileBins,
    cam: &CamParams<T>,
    background: &[T; 3],
    tape: Option<(&[T], &[u32])>,
    d_rgb: &[T],
) -> Vec<ProjectedGrad<T>> {
    let mut out = vec![ProjectedGrad::default(); proj.len()];
    rasterize_vjp_into(proj, bins, cam, background, tape, d_rgb, &mut out);
    out
}

/// [`rasterize_vjp`], adding into `out` (one entry per Gaussian), tile by tile in order.
pub fn rasterize_vjp_into<T: Real>(
    proj: &[Projected<T>],
    bins: &TileBins,
    cam: &CamParams<T>,
    background: &[T; 3],
    tape: Option<(&[T], &[u32])>,
    d_rgb: &[T],
    out: &mut [ProjectedGrad<T>],
) {
    let mut trace: Vec<Contribution<T>> = Vec::new();
    let w = cam.width;
    let [r0, r1] = cam.rows;
    let mut tile = TileSplats::default();
    for ty in tile_rows(cam.rows) {
        for tx in 0..bins.tiles_x {
            tile.gather(bins.tile((ty * bins.tiles_x + tx) as usize), proj);
            for j in (ty * 16).max(r0)..((ty + 1) * 16).min(r1) {
                for i in tx * 16..((tx + 1) * 16).min(w) {
                    let k = ((j - r0) * w + i) as usize;
                    let tf = match tape {
                        Some((t_final, last)) => {
                            raster::trace_back(i, j, &tile, t_final[k], last[k], &mut trace);
                            t_final[k]
                        }
                        None => {
                            trace.clear();
                            let c =
                                raster::composite_pixel(i, j, &tile, background, Some(&mut trace));
                            c.1
                        }
                    };
                    let d = [d_rgb[3 * k], d_rgb[3 * k + 1], d_rgb[3 * k + 2]];
                    raster::composite_pixel_vjp(&trace, tf, &tile, background, &d, |id, g| {
                        out[id as usize].add(g)
                    });
                }
            }
        }
    }
}

/// VJP of [`project`]: raw-parameter gradients from the projection gradients.
pub fn project_vjp<T: Real>(
    scene: &Scene<T>,
    cam: &CamParams<T>,
    proj: &[Projected<T>],
    d_proj: &[ProjectedGrad<T>],
) -> SceneGrad<T> {
    let n = scene.len();
    let k = sh_coeffs(scene.sh_degree) * 3;
    let mut out = SceneGrad {
        means: vec![[T::zero(); 3]; n],
        log_scales: vec![[T::zero(); 3]; n],
        quats: vec![[T::zero(); 4]; n],
        opacity_logits: vec![T::zero(); n],
        sh: vec![T::zero(); n * k],
        f: if scene.f.is_some() {
            vec![zero3(); n]
        } else {
            Vec::new()
        },
        cov3d: vec![zero3(); n],
    };
    for i in 0..n {
        if proj[i].radii == [0, 0] {
            continue;
        }
        let (g, sh) = scene.gaussian(i);
        let gg = pj::project_vjp(
            &g,
            sh,
            scene.sh_degree,
            cam,
            &d_proj[i],
            &mut out.sh[i * k..(i + 1) * k],
        );
        out.means[i] = gg.mean;
        out.log_scales[i] = gg.log_scale;
        out.quats[i] = gg.quat;
        out.opacity_logits[i] = gg.opacity_logit;
        out.cov3d[i] = gg.cov3d;
        if scene.f.is_some() {
            out.f[i] = gg.f;
        }
    }
    out
}

/// Forward render: projection, binning, compositing.
pub fn render<T: Real>(
    scene: &Scene<T>,
    cam: &Camera,
    settings: &RenderSettings,
) -> (Image<T>, Vec<Projected<T>>) {
    let cp = CamParams::new(cam, settings.mode);
    let bg = settings.background.map(|x| T::c(x as f64));
    let proj = project(scene, &cp);
    let bins = bin_tiles(&proj, &cp);
    (rasterize(&proj, &bins, &cp, &bg), proj)
}

/// Gradient of `sum(d_rgb * rgb)` with respect to the scene.
pub fn render_vjp<T: Real>(
    scene: &Scene<T>,
    cam: &Camera,
    settings: &RenderSettings,
    d_rgb: &[T],
) -> SceneGrad<T> {
    let cp = CamParams::new(cam, settings.mode);
    let bg = settings.background.map(|x| T::c(x as f64));
    let proj = project(scene, &cp);
    let bins = bin_tiles(&proj, &cp);
    let d_proj = rasterize_vjp(&proj, &bins, &cp, &bg, None, d_rgb);
    project_vjp(scene, &cp, &proj, &d_proj)
}

/// The reference as a [`crate::SplatKernels`] backend (f32, host vectors, one thread).
#[derive(Clone, Copy, Debug, Default)]
pub struct ReferenceSplat;

fn scene_of(s: &crate::kernels::SceneBufs<ReferenceSplat>) -> Scene<f32> {
    Scene {
        sh_degree: s.sh_degree,
        means: s.means.clone(),
        log_scales: s.log_scales.clone(),
        quats: s.quats.clone(),
        opacity_logits: s.opacity_logits.clone(),
        sh: s.sh.clone(),
        f: s.f.clone(),
    }
}

impl r4d_backend::Backend for ReferenceSplat {
    r4d_backend::host_vec_backend!();
    fn name(&self) -> &'static str {
        "reference"
    }
    fn memory_usage(&self) -> r4d_backend::MemoryUsage {
        r4d_backend::MemoryUsage::default()
    }
}

impl crate::SplatKernels for ReferenceSplat {
    fn project(
        &self,
        scene: &crate::kernels::SceneBufs<Self>,
        cam: &crate::CameraConsts,
    ) -> Result<Vec<Projected<f32>>, Self::Error> {
        Ok(project(&scene_of(scene), &cam.params()))
    }
    fn bin_tiles(
        &self,
        proj: &Vec<Projected<f32>>,
        cam: &crate::CameraConsts,
    ) -> Result<crate::kernels::TileBufs<Self>, Self::Error> {
        let b = bin_tiles(proj, &cam.params());
        Ok(crate::kernels::TileBufs {
            intersections: b.ids.len(),
            offsets: b.offsets,
            ids: b.ids,
        })
    }
    fn rasterize(
        &self,
        proj: &Vec<Projected<f32>>,
        bins: &crate::kernels::TileBufs<Self>,
        cam: &crate::CameraConsts,
    ) -> Result<crate::kernels::ImageBufs<Self>, Self::Error> {
        let tb = TileBins {
            tiles_x: cam.tiles[0],
            tiles_y: cam.tiles[1],
            offsets: bins.offsets.clone(),
            ids: bins.ids.clone(),
        };
        let img = rasterize(proj, &tb, &cam.params(), &cam.bg());
        Ok(crate::kernels::ImageBufs {
            rgb: img.rgb,
            alpha: img.alpha,
            depth: img.depth,
            t_final: img.t_final,
            last: img.last,
        })
    }
    fn rasterize_vjp(
        &self,
        proj: &Vec<Projected<f32>>,
        bins: &crate::kernels::TileBufs<Self>,
        cam: &crate::CameraConsts,
        tape: Option<&crate::kernels::ImageBufs<Self>>,
        d_rgb: &Vec<f32>,
        d_proj: &mut Vec<ProjectedGrad<f32>>,
    ) -> Result<(), Self::Error> {
        let tb = TileBins {
            tiles_x: cam.tiles[0],
            tiles_y: cam.tiles[1],
            offsets: bins.offsets.clone(),
            ids: bins.ids.clone(),
        };
        rasterize_vjp_into(
            proj,
            &tb,
            &cam.params(),
            &cam.bg(),
            tape.map(|i| (&i.t_final[..], &i.last[..])),
            d_rgb,
            d_proj,
        );
        Ok(())
    }
    fn deform(
        &self,
        link: &crate::kernels::LinkBufs<Self>,
        x: &Vec<[f32; 3]>,
        f_sim: &Vec<[f32; 9]>,
        means: &mut Vec<[f32; 3]>,
        f: &mut Vec<[[f32; 3]; 3]>,
    ) -> Result<(), std::convert::Infallible> {
        crate::link::deform_host(&link.consts, &link.simulated, x, f_sim, means, f);
        Ok(())
    }

    fn deform_vjp(
        &self,
        link: &crate::kernels::LinkBufs<Self>,
        d_means: &Vec<[f32; 3]>,
        d_f: &Vec<[[f32; 3]; 3]>,
        dx: &mut Vec<[f32; 3]>,
        df_sim: &mut Vec<[f32; 9]>,
    ) -> Result<(), std::convert::Infallible> {
        crate::link::deform_vjp_host(&link.consts, &link.simulated, d_means, d_f, dx, df_sim);
        Ok(())
    }

    fn project_vjp(
        &self,
        scene: &crate::kernels::SceneBufs<Self>,
        cam: &crate::CameraConsts,
        proj: &Vec<Projected<f32>>,
        d_proj: &Vec<ProjectedGrad<f32>>,
    ) -> Result<crate::kernels::SceneGradBufs<Self>, Self::Error> {
        let g = project_vjp(&scene_of(scene), &cam.params(), proj, d_proj);
        Ok(crate::kernels::SceneGradBufs {
            means: g.means,
            log_scales: g.log_scales,
            quats: g.quats,
            opacity_logits: g.opacity_logits,
            sh: g.sh,
            f: scene.f.as_ref().map(|_| g.f),
        })
    }
}
