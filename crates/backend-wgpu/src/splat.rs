//! [`r4d_splat::SplatKernels`] on wgpu: the renderer and its backward pass in WGSL
//! (`r4d-shaders/wgsl/splat/`), mirroring the CPU backend stage by stage and the per-Gaussian /
//! per-pixel functions of `r4d_splat::project`, `r4d_splat::covariance`, `r4d_splat::sh` and
//! `r4d_splat::raster`. Every stage runs on the device; the host only records dispatches (and
//! reads back the 4-byte intersection count in `bin_tiles`).
//!
//! * `project`: one thread per Gaussian (`project.wgsl`); culled Gaussians get radii (0, 0).
//!   The per-Gaussian math (covariance, `F Sigma F^T`, the polar rotation of F, the SH basis,
//!   the projection up to the 2D covariance) is in `r4d-shaders/wgsl/lib/splat_project.wgsl`, shared
//!   with `project_vjp`.
//! * `bin_tiles`: `count_tiles` (tiles per Gaussian, `r4d_splat::raster::tile_rect` computed
//!   exactly), an exclusive scan (`scan_block` / `scan_add`, 1024 values per workgroup,
//!   recursive over the block sums), one 4-byte readback of the number of intersections,
//!   `emit_keys` (a (tile, depth, index) record per intersection, in ascending Gaussian
//!   index), a stable LSD radix sort with 4-bit digits (`radix_hist`, scan, `radix_scatter`):
//!   8 passes over the depth key (the f32 bits mapped to `total_cmp` order), then
//!   `ceil(log2(tiles) / 4)` passes over the tile id, so each tile's list is ordered by depth
//!   then index exactly as [`r4d_splat::raster::depth_order`] orders it; then `tile_ranges`
//!   writes the ids and the `tiles + 1` offsets. The result equals
//!   [`r4d_splat::raster::bin_tiles`] for the same projection, id for id.
//! * `rasterize`: one workgroup per 16x16 tile, one thread per pixel, the tile's Gaussians
//!   staged 256 at a time in workgroup memory (`rasterize.wgsl`).
//!
//! * `rasterize_vjp`: one workgroup per tile, one thread per pixel (`rasterize_vjp.wgsl`).
//!   The trait hands it no forward image, so each pixel first replays its compositing (as the
//!   CPU reference does) for its final transmittance and the position of its last composited
//!   Gaussian; then the tile's list is staged 128 Gaussians at a time from that position down
//!   and each pixel runs [`r4d_splat::raster::composite_pixel_vjp`]'s recursion back to front,
//!   recovering the transmittance in front of each Gaussian as `T / (1 - alpha)`. Pixels add
//!   their per-Gaussian gradients (mean2d, conic, opacity, colour) into workgroup memory
//!   first (a compare-exchange on the f32 bits), and each batch's nonzero sums go to the
//!   global `ProjectedGrad` array with one float atomic each: native `atomic<f32>` where the
//!   adapter has `SHADER_FLOAT32_ATOMIC`, else the compare-exchange variant
//!   (`splat_rasterize_vjp_cas`), so the sums are not bitwise reproducible run to run.
//! * `project_vjp`: one thread per Gaussian (`project_vjp.wgsl`),
//!   [`r4d_splat::project::project_vjp`] in f32 (including the polar-rotation VJP, which the
//!   reference solves in f64): it recomputes the forward quantities and writes dL/dmean,
//!   dL/dlog_scale, dL/dquat, dL/dopacity_logit and dL/dF into sections of one buffer (a kernel
//!   binds at most 8 storage buffers, WebGPU's default), plus the SH direction and the
//!   clamp-masked dL/dcolour, from which `project_vjp_sh.wgsl` writes dL/dsh; the sections are
//!   then copied into the separate gradient buffers on the device.

use crate::context::{GpuBuffer, WgpuContext, WgpuError};
use bytemuck::{Pod, Zeroable};
use r4d_splat::kernels::{ImageBufs, SceneBufs, SceneGradBufs, TileBufs};
use r4d_splat::project::{Projected, ProjectedGrad};
use r4d_splat::{CameraConsts, SplatKernels};
use std::any::Any;
use std::sync::Arc;

/// Values per workgroup of the scan and radix kernels.
const BLOCK: usize = 1024;

/// One record of the intersection sort (`SplatTileKey` in `r4d-shaders/wgsl/lib/splat_structs.wgsl`):
/// tile id, order-preserving depth key, Gaussian index.
type TileKey = [u32; 3];

/// Sizes of the per-Gaussian kernels `project`, `project_vjp` and `project_vjp_sh`
/// (`SplatProjectParams` in `r4d-shaders/wgsl/lib/splat_structs.wgsl`).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Pod, Zeroable)]
pub struct SplatProjectParams {
    /// Number of Gaussians.
    pub n: u32,
    /// 1 when the scene is deformed (F given).
    pub has_f: u32,
    /// SH degree.
    pub sh_degree: u32,
    /// SH values per Gaussian (`K * 3`).
    pub sh_len: u32,
}

impl SplatProjectParams {
    fn of(scene: &SceneBufs<WgpuSplat>) -> Self {
        let k = r4d_splat::gaussians::sh_coeffs(scene.sh_degree) as u32;
        SplatProjectParams {
            n: scene.n as u32,
            has_f: scene.f.is_some() as u32,
            sh_degree: scene.sh_degree,
            sh_len: 3 * k,
        }
    }
}

/// The sections of `project_vjp.wgsl`'s output buffer (`PV_*` in
/// `r4d-shaders/wgsl/lib/splat_project.wgsl`), as (start in multiples of n, values per Gaussian):
/// dL/dmean, dL/dlog_scale, dL/dquat, dL/dopacity_logit; between the last two sections, the SH
/// direction and the masked dL/dcolour that `project_vjp_sh.wgsl` reads (3 + 3).
const SECTION_MEAN: (usize, usize) = (0, 3);
const SECTION_LOG_SCALE: (usize, usize) = (3, 3);
const SECTION_QUAT: (usize, usize) = (6, 4);
const SECTION_OPACITY: (usize, usize) = (10, 1);
/// dL/dF, present when the scene is deformed: it ends the buffer.
const SECTION_F: (usize, usize) = (17, 9);

/// The wgpu splatting backend.
pub struct WgpuSplat {
    ctx: Arc<WgpuContext>,
}

/// Buffers that must outlive the commands recorded with them.
#[derive(Default)]
struct Keep(Vec<Box<dyn Any>>);

impl Keep {
    fn add<T: 'static>(&mut self, b: GpuBuffer<T>) -> &GpuBuffer<T> {
        self.0.push(Box::new(b));
        self.0
            .last()
            .and_then(|b| b.downcast_ref::<GpuBuffer<T>>())
            .expect("just pushed")
    }
}

impl WgpuSplat {
    /// A backend on a device.
    pub fn new(ctx: Arc<WgpuContext>) -> Self {
        WgpuSplat { ctx }
    }

    /// The device.
    pub fn context(&self) -> &Arc<WgpuContext> {
        &self.ctx
    }

    /// A zero-filled buffer of `len` elements, allocated with at least one element so that it
    /// satisfies the minimum binding size of a runtime-sized array of `T`.
    fn zeros_bindable<T: Pod>(
        &self,
        label: &'static str,
        len: usize,
    ) -> Result<GpuBuffer<T>, WgpuError> {
        let mut b = self.ctx.zeros::<T>(label, len.max(1))?;
        b.len = len;
        Ok(b)
    }

    /// Records an in-place exclusive prefix sum of the first `n` values of `data`.
    fn scan(
        &self,
        enc: &mut wgpu::CommandEncoder,
        data: &wgpu::Buffer,
        n: usize,
        keep: &mut Keep,
    ) -> Result<(), WgpuError> {
        if n == 0 {
            return Ok(());
        }
        let ctx = &self.ctx;
        let blocks = n.div_ceil(BLOCK);
        let params = keep.add(ctx.uniform("splat_scan_params", &[n as u32, blocks as u32, 0, 0])?);
        let params = params.buffer.clone();
        let sums = keep.add(ctx.zeros::<u32>("splat_scan_sums", blocks)?);
        let sums = sums.buffer.clone();
        ctx.dispatch(
            enc,
            &r4d_shaders::splat::SCAN_BLOCK,
            &[&params, data, &sums],
            blocks as u32 * r4d_shaders::splat::SCAN_BLOCK.threads_per_group(),
        )?;
        if blocks > 1 {
            self.scan(enc, &sums, blocks, keep)?;
            ctx.dispatch(
                enc,
                &r4d_shaders::splat::SCAN_ADD,
                &[&params, data, &sums],
                n as u32,
            )?;
        }
        Ok(())
    }

    /// Records a stable radix sort of `m` records (4-bit digits: `depth_passes` over the
    /// depth key, then `tile_passes` over the tile id); returns the buffer holding the result.
    fn radix_sort<'a>(
        &self,
        enc: &mut wgpu::CommandEncoder,
        a: &'a GpuBuffer<TileKey>,
        b: &'a GpuBuffer<TileKey>,
        m: usize,
        tile_passes: u32,
        keep: &mut Keep,
    ) -> Result<&'a GpuBuffer<TileKey>, WgpuError> {
        let ctx = &self.ctx;
        let blocks = m.div_ceil(BLOCK);
        let hist = keep.add(ctx.zeros::<u32>("splat_radix_hist", 16 * blocks)?);
        let hist = hist.buffer.clone();
        let (mut src, mut dst) = (a, b);
        let passes = (0..8u32)
            .map(|p| (0u32, 4 * p))
            .chain((0..tile_passes).map(|p| (1u32, 4 * p)));
        for (key_sel, shift) in passes {
            let params = keep.add(ctx.uniform(
                "splat_radix_params",
                &[m as u32, shift, key_sel, blocks as u32],
            )?);
            let params = params.buffer.clone();
            let threads = blocks as u32 * r4d_shaders::splat::RADIX_HIST.threads_per_group();
            ctx.dispatch(
                enc,
                &r4d_shaders::splat::RADIX_HIST,
                &[&params, &src.buffer, &hist],
                threads,
            )?;
            self.scan(enc, &hist, 16 * blocks, keep)?;
            ctx.dispatch(
                enc,
                &r4d_shaders::splat::RADIX_SCATTER,
                &[&params, &src.buffer, &hist, &dst.buffer],
                threads,
            )?;
            std::mem::swap(&mut src, &mut dst);
        }
        Ok(src)
    }

    /// Records `kernel` over the image's 16x16 tiles (one workgroup each) with `buffers` bound
    /// at bindings 0, 1, ... of group 0.
    fn dispatch_tiles(
        &self,
        enc: &mut wgpu::CommandEncoder,
        kernel: &'static r4d_shaders::Kernel,
        buffers: &[&wgpu::Buffer],
        tiles: [u32; 2],
    ) -> Result<(), WgpuError> {
        self.ctx
            .dispatch_groups(enc, kernel, buffers, [tiles[0], tiles[1], 1])
    }

    /// The buffer of a projection, or a one-record dummy when it is empty (a runtime-sized
    /// array binding needs at least one element).
    fn bindable_projection<'a>(
        &self,
        proj: &'a GpuBuffer<Projected<f32>>,
        dummy: &'a mut Option<GpuBuffer<Projected<f32>>>,
    ) -> Result<&'a wgpu::Buffer, WgpuError> {
        if proj.bytes() < std::mem::size_of::<Projected<f32>>() as u64 {
            let d = dummy.insert(self.ctx.zeros::<Projected<f32>>("splat_no_projected", 1)?);
            Ok(&d.buffer)
        } else {
            Ok(&proj.buffer)
        }
    }
}

impl SplatKernels for WgpuSplat {
    type Buf<T: Pod + Send + Sync> = GpuBuffer<T>;
    type Error = WgpuError;

    fn upload<T: Pod + Send + Sync>(&self, data: &[T]) -> Result<GpuBuffer<T>, WgpuError> {
        self.ctx.upload("splat_upload", data)
    }

    fn download<T: Pod + Send + Sync>(&self, buf: &GpuBuffer<T>) -> Result<Vec<T>, WgpuError> {
        self.ctx.download(buf)
    }

    fn project(
        &self,
        scene: &SceneBufs<Self>,
        cam: &CameraConsts,
    ) -> Result<GpuBuffer<Projected<f32>>, WgpuError> {
        let ctx = &self.ctx;
        let n = scene.n;
        let out = self.zeros_bindable::<Projected<f32>>("splat_projected", n)?;
        if n == 0 {
            return Ok(out);
        }
        let cam_u = ctx.uniform("splat_camera", cam)?;
        let params = ctx.uniform("splat_project_params", &SplatProjectParams::of(scene))?;
        let no_f;
        let f = match &scene.f {
            Some(f) => &f.buffer,
            None => {
                no_f = ctx.zeros::<f32>("splat_no_f", 4)?;
                &no_f.buffer
            }
        };
        let mut enc = ctx.encoder();
        ctx.dispatch(
            &mut enc,
            &r4d_shaders::splat::PROJECT,
            &[
                &cam_u.buffer,
                &params.buffer,
                &scene.means.buffer,
                &scene.log_scales.buffer,
                &scene.quats.buffer,
                &scene.opacity_logits.buffer,
                &scene.sh.buffer,
                f,
                &out.buffer,
            ],
            n as u32,
        )?;
        ctx.submit(enc);
        Ok(out)
    }

    fn bin_tiles(
        &self,
        proj: &GpuBuffer<Projected<f32>>,
        cam: &CameraConsts,
    ) -> Result<TileBufs<Self>, WgpuError> {
        let ctx = &self.ctx;
        let n = proj.len;
        let tiles = (cam.tiles[0] * cam.tiles[1]) as usize;
        let offsets = ctx.zeros::<u32>("splat_tile_offsets", tiles + 1)?;
        let empty = |offsets: GpuBuffer<u32>| -> Result<TileBufs<Self>, WgpuError> {
            Ok(TileBufs {
                offsets,
                ids: ctx.zeros::<u32>("splat_tile_ids", 0)?,
                intersections: 0,
            })
        };
        if n == 0 || tiles == 0 {
            return empty(offsets);
        }
        let mut keep = Keep::default();
        let cam_u = ctx.uniform("splat_camera", cam)?;
        let params = ctx.uniform("splat_bin_params", &[n as u32, 0, 0, 0])?;
        // n + 1 counts: the last stays 0 and scans to the total.
        let counts = ctx.zeros::<u32>("splat_tile_counts", n + 1)?;
        let total = ctx.zeros::<u32>("splat_intersections", 1)?;
        let mut enc = ctx.encoder();
        ctx.dispatch(
            &mut enc,
            &r4d_shaders::splat::COUNT_TILES,
            &[&cam_u.buffer, &params.buffer, &proj.buffer, &counts.buffer],
            n as u32,
        )?;
        self.scan(&mut enc, &counts.buffer, n + 1, &mut keep)?;
        enc.copy_buffer_to_buffer(&counts.buffer, 4 * n as u64, &total.buffer, 0, 4);
        ctx.submit(enc);
        let m = ctx.download(&total)?[0] as usize;
        drop(keep);
        if m == 0 {
            return empty(offsets);
        }
        let mut keep = Keep::default();
        let keys_a = self.zeros_bindable::<TileKey>("splat_tile_keys", m)?;
        let keys_b = self.zeros_bindable::<TileKey>("splat_tile_keys", m)?;
        let ids = ctx.zeros::<u32>("splat_tile_ids", m)?;
        let mut enc = ctx.encoder();
        ctx.dispatch(
            &mut enc,
            &r4d_shaders::splat::EMIT_KEYS,
            &[
                &cam_u.buffer,
                &params.buffer,
                &proj.buffer,
                &counts.buffer,
                &keys_a.buffer,
            ],
            n as u32,
        )?;
        let tile_bits = u32::BITS - (tiles as u32 - 1).leading_zeros();
        let sorted = self.radix_sort(
            &mut enc,
            &keys_a,
            &keys_b,
            m,
            tile_bits.div_ceil(4),
            &mut keep,
        )?;
        let range_params = ctx.uniform("splat_range_params", &[m as u32, tiles as u32, 0, 0])?;
        ctx.dispatch(
            &mut enc,
            &r4d_shaders::splat::TILE_RANGES,
            &[
                &range_params.buffer,
                &sorted.buffer,
                &offsets.buffer,
                &ids.buffer,
            ],
            m as u32,
        )?;
        ctx.submit(enc);
        Ok(TileBufs {
            offsets,
            ids,
            intersections: m,
        })
    }

    fn rasterize(
        &self,
        proj: &GpuBuffer<Projected<f32>>,
        bins: &TileBufs<Self>,
        cam: &CameraConsts,
    ) -> Result<ImageBufs<Self>, WgpuError> {
        let ctx = &self.ctx;
        let [w, h] = cam.size.map(|v| v as usize);
        let img = ImageBufs {
            rgb: ctx.zeros::<f32>("splat_rgb", w * h * 3)?,
            alpha: ctx.zeros::<f32>("splat_alpha", w * h)?,
            depth: ctx.zeros::<f32>("splat_depth", w * h)?,
        };
        let [tx, ty] = cam.tiles;
        if w == 0 || h == 0 || tx == 0 || ty == 0 {
            return Ok(img);
        }
        let cam_u = ctx.uniform("splat_camera", cam)?;
        let mut dummy = None;
        let proj_buf = self.bindable_projection(proj, &mut dummy)?;
        let mut enc = ctx.encoder();
        self.dispatch_tiles(
            &mut enc,
            &r4d_shaders::splat::RASTERIZE,
            &[
                &cam_u.buffer,
                proj_buf,
                &bins.offsets.buffer,
                &bins.ids.buffer,
                &img.rgb.buffer,
                &img.alpha.buffer,
                &img.depth.buffer,
            ],
            cam.tiles,
        )?;
        ctx.submit(enc);
        Ok(img)
    }

    /// `rasterize_vjp.wgsl`: one workgroup per tile replays each pixel's compositing, walks it
    /// back to front and adds the per-Gaussian sums of each batch with float atomics.
    fn rasterize_vjp(
        &self,
        proj: &GpuBuffer<Projected<f32>>,
        bins: &TileBufs<Self>,
        cam: &CameraConsts,
        d_rgb: &GpuBuffer<f32>,
    ) -> Result<GpuBuffer<ProjectedGrad<f32>>, WgpuError> {
        let ctx = &self.ctx;
        let out = self.zeros_bindable::<ProjectedGrad<f32>>("splat_d_projected", proj.len)?;
        let [tx, ty] = cam.tiles;
        if proj.len == 0 || bins.intersections == 0 || tx == 0 || ty == 0 {
            return Ok(out);
        }
        let [w, h] = cam.size.map(|v| v as usize);
        assert_eq!(
            d_rgb.len,
            w * h * 3,
            "rasterize_vjp: dL/drgb must have 3 values per pixel"
        );
        let cam_u = ctx.uniform("splat_camera", cam)?;
        let mut enc = ctx.encoder();
        self.dispatch_tiles(
            &mut enc,
            &r4d_shaders::splat::RASTERIZE_VJP,
            &[
                &cam_u.buffer,
                &proj.buffer,
                &bins.offsets.buffer,
                &bins.ids.buffer,
                &d_rgb.buffer,
                &out.buffer,
            ],
            cam.tiles,
        )?;
        ctx.submit(enc);
        Ok(out)
    }

    /// `project_vjp.wgsl` (one thread per Gaussian, into one sectioned buffer), then
    /// `project_vjp_sh.wgsl` (dL/dsh) and copies of the sections into the gradient buffers.
    fn project_vjp(
        &self,
        scene: &SceneBufs<Self>,
        cam: &CameraConsts,
        proj: &GpuBuffer<Projected<f32>>,
        d_proj: &GpuBuffer<ProjectedGrad<f32>>,
    ) -> Result<SceneGradBufs<Self>, WgpuError> {
        let ctx = &self.ctx;
        let n = scene.n;
        assert!(
            proj.len == n && d_proj.len == n,
            "project_vjp: {n} Gaussians but {} projections and {} projection gradients",
            proj.len,
            d_proj.len
        );
        let params = SplatProjectParams::of(scene);
        let out = SceneGradBufs {
            means: ctx.zeros::<[f32; 3]>("splat_d_means", n)?,
            log_scales: ctx.zeros::<[f32; 3]>("splat_d_log_scales", n)?,
            quats: ctx.zeros::<[f32; 4]>("splat_d_quats", n)?,
            opacity_logits: ctx.zeros::<f32>("splat_d_opacity_logits", n)?,
            sh: self.zeros_bindable::<f32>("splat_d_sh", n * params.sh_len as usize)?,
            f: match scene.f {
                Some(_) => Some(ctx.zeros::<[[f32; 3]; 3]>("splat_d_f", n)?),
                None => None,
            },
        };
        if n == 0 {
            return Ok(out);
        }
        let width = match scene.f {
            Some(_) => SECTION_F.0 + SECTION_F.1,
            None => SECTION_F.0,
        };
        let packed = ctx.zeros::<f32>("splat_project_vjp_sections", n * width)?;
        let cam_u = ctx.uniform("splat_camera", cam)?;
        let params_u = ctx.uniform("splat_project_params", &params)?;
        let no_f;
        let f = match &scene.f {
            Some(f) => &f.buffer,
            None => {
                no_f = ctx.zeros::<f32>("splat_no_f", 4)?;
                &no_f.buffer
            }
        };
        let mut enc = ctx.encoder();
        ctx.dispatch(
            &mut enc,
            &r4d_shaders::splat::PROJECT_VJP,
            &[
                &cam_u.buffer,
                &params_u.buffer,
                &scene.means.buffer,
                &scene.log_scales.buffer,
                &scene.quats.buffer,
                &scene.opacity_logits.buffer,
                &scene.sh.buffer,
                f,
                &d_proj.buffer,
                &packed.buffer,
            ],
            n as u32,
        )?;
        ctx.dispatch(
            &mut enc,
            &r4d_shaders::splat::PROJECT_VJP_SH,
            &[&params_u.buffer, &packed.buffer, &out.sh.buffer],
            n as u32,
        )?;
        let mut copy = |(start, width): (usize, usize), dst: &wgpu::Buffer| {
            let (off, len) = (4 * (start * n) as u64, 4 * (width * n) as u64);
            enc.copy_buffer_to_buffer(&packed.buffer, off, dst, 0, len);
        };
        copy(SECTION_MEAN, &out.means.buffer);
        copy(SECTION_LOG_SCALE, &out.log_scales.buffer);
        copy(SECTION_QUAT, &out.quats.buffer);
        copy(SECTION_OPACITY, &out.opacity_logits.buffer);
        if let Some(df) = &out.f {
            copy(SECTION_F, &df.buffer);
        }
        ctx.submit(enc);
        Ok(out)
    }
}
