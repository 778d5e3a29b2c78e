//! [`r4d_splat::SplatKernels`] on wgpu: the forward renderer in WGSL (`shaders/splat/`),
//! mirroring the CPU backend stage by stage and the per-Gaussian / per-pixel functions of
//! `r4d_splat::project` and `r4d_splat::raster`:
//!
//! * `project`: one thread per Gaussian (`project.wgsl`); culled Gaussians get radii (0, 0).
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
//! The backward stages ([`SplatKernels::rasterize_vjp`], [`SplatKernels::project_vjp`]) are
//! not GPU kernels yet: they download their inputs, run the single-threaded reference
//! ([`r4d_splat::reference::rasterize_vjp`] / [`r4d_splat::reference::project_vjp`]) on the
//! host and upload the results.

use crate::context::{GpuBuffer, WgpuContext, WgpuError};
use bytemuck::Pod;
use r4d_splat::kernels::{ImageBufs, SceneBufs, SceneGradBufs, TileBufs};
use r4d_splat::project::{Projected, ProjectedGrad};
use r4d_splat::raster::TileBins;
use r4d_splat::reference::{self, Scene};
use r4d_splat::{CameraConsts, SplatKernels};
use std::any::Any;
use std::sync::Arc;

/// Values per workgroup of the scan and radix kernels.
const BLOCK: usize = 1024;
/// Threads per workgroup of the scan and radix kernels.
const WG: u32 = 256;

/// One record of the intersection sort (`SplatTileKey` in `shaders/lib/splat_structs.wgsl`):
/// tile id, order-preserving depth key, Gaussian index.
type TileKey = [u32; 3];

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
            "splat_scan_block",
            &[&params, data, &sums],
            blocks as u32 * WG,
            WG,
        )?;
        if blocks > 1 {
            self.scan(enc, &sums, blocks, keep)?;
            ctx.dispatch(enc, "splat_scan_add", &[&params, data, &sums], n as u32, WG)?;
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
            let threads = blocks as u32 * WG;
            ctx.dispatch(
                enc,
                "splat_radix_hist",
                &[&params, &src.buffer, &hist],
                threads,
                WG,
            )?;
            self.scan(enc, &hist, 16 * blocks, keep)?;
            ctx.dispatch(
                enc,
                "splat_radix_scatter",
                &[&params, &src.buffer, &hist, &dst.buffer],
                threads,
                WG,
            )?;
            std::mem::swap(&mut src, &mut dst);
        }
        Ok(src)
    }

    fn download_scene(&self, s: &SceneBufs<Self>) -> Result<Scene<f32>, WgpuError> {
        Ok(Scene {
            sh_degree: s.sh_degree,
            means: self.ctx.download(&s.means)?,
            log_scales: self.ctx.download(&s.log_scales)?,
            quats: self.ctx.download(&s.quats)?,
            opacity_logits: self.ctx.download(&s.opacity_logits)?,
            sh: self.ctx.download(&s.sh)?,
            f: match &s.f {
                Some(f) => Some(self.ctx.download(f)?),
                None => None,
            },
        })
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
        let k = r4d_splat::gaussians::sh_coeffs(scene.sh_degree) as u32;
        let cam_u = ctx.uniform("splat_camera", cam)?;
        let params = ctx.uniform(
            "splat_project_params",
            &[n as u32, scene.f.is_some() as u32, scene.sh_degree, 3 * k],
        )?;
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
            "splat_project",
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
            64,
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
            "splat_count_tiles",
            &[&cam_u.buffer, &params.buffer, &proj.buffer, &counts.buffer],
            n as u32,
            WG,
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
            "splat_emit_keys",
            &[
                &cam_u.buffer,
                &params.buffer,
                &proj.buffer,
                &counts.buffer,
                &keys_a.buffer,
            ],
            n as u32,
            WG,
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
            "splat_tile_ranges",
            &[
                &range_params.buffer,
                &sorted.buffer,
                &offsets.buffer,
                &ids.buffer,
            ],
            m as u32,
            WG,
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
        // A runtime-sized array binding needs at least one element.
        let dummy;
        let proj_buf = if proj.bytes() < std::mem::size_of::<Projected<f32>>() as u64 {
            dummy = ctx.zeros::<Projected<f32>>("splat_no_projected", 1)?;
            &dummy.buffer
        } else {
            &proj.buffer
        };
        let pipeline = ctx.pipeline("splat_rasterize")?;
        let entries: Vec<wgpu::BindGroupEntry> = [
            &cam_u.buffer,
            proj_buf,
            &bins.offsets.buffer,
            &bins.ids.buffer,
            &img.rgb.buffer,
            &img.alpha.buffer,
            &img.depth.buffer,
        ]
        .iter()
        .enumerate()
        .map(|(i, b)| wgpu::BindGroupEntry {
            binding: i as u32,
            resource: b.as_entire_binding(),
        })
        .collect();
        let bind = ctx.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("splat_rasterize"),
            layout: &pipeline.get_bind_group_layout(0),
            entries: &entries,
        });
        let mut enc = ctx.encoder();
        {
            let mut pass = enc.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some("splat_rasterize"),
                timestamp_writes: None,
            });
            pass.set_pipeline(&pipeline);
            pass.set_bind_group(0, &bind, &[]);
            pass.dispatch_workgroups(tx, ty, 1);
        }
        ctx.submit(enc);
        Ok(img)
    }

    /// Not a GPU kernel yet: downloads its inputs, runs
    /// [`r4d_splat::reference::rasterize_vjp`] on the host and uploads the result.
    fn rasterize_vjp(
        &self,
        proj: &GpuBuffer<Projected<f32>>,
        bins: &TileBufs<Self>,
        cam: &CameraConsts,
        d_rgb: &GpuBuffer<f32>,
    ) -> Result<GpuBuffer<ProjectedGrad<f32>>, WgpuError> {
        let proj = self.ctx.download(proj)?;
        let tb = TileBins {
            tiles_x: cam.tiles[0],
            tiles_y: cam.tiles[1],
            offsets: self.ctx.download(&bins.offsets)?,
            ids: self.ctx.download(&bins.ids)?,
        };
        let d = self.ctx.download(d_rgb)?;
        let g = reference::rasterize_vjp(&proj, &tb, &cam.params(), &cam.bg(), &d);
        self.ctx.upload("splat_d_projected", &g)
    }

    /// Not a GPU kernel yet: downloads its inputs, runs
    /// [`r4d_splat::reference::project_vjp`] on the host and uploads the results.
    fn project_vjp(
        &self,
        scene: &SceneBufs<Self>,
        cam: &CameraConsts,
        proj: &GpuBuffer<Projected<f32>>,
        d_proj: &GpuBuffer<ProjectedGrad<f32>>,
    ) -> Result<SceneGradBufs<Self>, WgpuError> {
        let s = self.download_scene(scene)?;
        let proj = self.ctx.download(proj)?;
        let d = self.ctx.download(d_proj)?;
        let g = reference::project_vjp(&s, &cam.params(), &proj, &d);
        let ctx = &self.ctx;
        Ok(SceneGradBufs {
            means: ctx.upload("splat_d_means", &g.means)?,
            log_scales: ctx.upload("splat_d_log_scales", &g.log_scales)?,
            quats: ctx.upload("splat_d_quats", &g.quats)?,
            opacity_logits: ctx.upload("splat_d_opacity_logits", &g.opacity_logits)?,
            sh: ctx.upload("splat_d_sh", &g.sh)?,
            f: match scene.f {
                Some(_) => Some(ctx.upload("splat_d_f", &g.f)?),
                None => None,
            },
        })
    }
}
