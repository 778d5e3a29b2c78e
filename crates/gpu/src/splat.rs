//! [`r4d_splat::SplatKernels`] for every GPU engine: the renderer and its backward pass in WGSL
//! (`r4d-shaders/wgsl/splat/`), mirroring the CPU backend stage by stage and the per-Gaussian /
//! per-pixel functions of `r4d_splat::project`, `r4d_splat::covariance`, `r4d_splat::sh` and
//! `r4d_splat::raster`. Every stage is a recording ([`crate::Recording`]) of `r4d-shaders`' kernels that
//! the engine executes; the host reads back only the 4-byte intersection count in
//! `bin_tiles` (between its two recordings).
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
//! * `rasterize`: one workgroup per 16x16 tile of the rows of tiles covering the composited
//!   rows (`CameraConsts::rows`), one thread per pixel, the tile's Gaussians staged 256 at a
//!   time in workgroup memory (`rasterize.wgsl`).
//!
//! * `rasterize_vjp`: one workgroup per tile, one thread per pixel (`rasterize_vjp.wgsl`).
//!   Each pixel reads the forward's tape (`ImageBufs::t_final`, `ImageBufs::last`: its final
//!   transmittance and one past the position of its last composited Gaussian); then the
//!   tile's list is staged 128 Gaussians at a time from that position down
//!   and each pixel runs [`r4d_splat::raster::composite_pixel_vjp`]'s recursion back to front,
//!   recovering the transmittance in front of each Gaussian as `T / (1 - alpha)`. Pixels add
//!   their per-Gaussian gradients (mean2d, conic, opacity, colour) into workgroup memory
//!   first (a compare-exchange on the f32 bits), and each batch's nonzero sums are added to
//!   the caller's `ProjectedGrad` array with one float atomic each: native `atomic<f32>` where the
//!   adapter has `SHADER_FLOAT32_ATOMIC`, else the compare-exchange variant
//!   (`splat_rasterize_vjp_cas`), so the sums are not bitwise reproducible run to run.
//! * `project_vjp`: one thread per Gaussian (`project_vjp.wgsl`),
//!   [`r4d_splat::project::project_vjp`] in f32 (including the polar-rotation VJP, which the
//!   reference solves in f64): it recomputes the forward quantities and writes dL/dmean,
//!   dL/dlog_scale, dL/dquat, dL/dopacity_logit and dL/dF into sections of one buffer (a kernel
//!   binds at most 8 storage buffers, WebGPU's default), plus the SH direction and the
//!   clamp-masked dL/dcolour, from which `project_vjp_sh.wgsl` writes dL/dsh; the sections are
//!   then copied into the separate gradient buffers on the device.

use crate::backend::Gpu;
use crate::engine::{GpuBuf, GpuEngine};
use crate::recording::{Recording, Resource};
use bytemuck::{Pod, Zeroable};
use r4d_shaders::splat as k;
use r4d_splat::kernels::{ImageBufs, LinkBufs, SceneBufs, SceneGradBufs, TileBufs};
use r4d_splat::project::{Projected, ProjectedGrad};
use r4d_splat::{CameraConsts, SplatKernels};

/// Values per workgroup of the scan and radix kernels (4 per thread).
const BLOCK: usize = 1024;

/// One record of the intersection sort (`SplatTileKey` in `wgsl/lib/splat_structs.wgsl`):
/// tile id, order-preserving depth key, Gaussian index.
type TileKey = [u32; 3];

/// Sizes of the per-Gaussian kernels `project`, `project_vjp` and `project_vjp_sh`
/// (`SplatProjectParams` in `wgsl/lib/splat_structs.wgsl`).
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
    fn of<E: GpuEngine>(scene: &SceneBufs<Gpu<E>>) -> Self {
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
/// `wgsl/lib/splat_project.wgsl`), as (start in multiples of n, values per Gaussian):
/// dL/dmean, dL/dlog_scale, dL/dquat, dL/dopacity_logit; between the last two sections, the SH
/// direction and the masked dL/dcolour that `project_vjp_sh.wgsl` reads (3 + 3).
const SECTION_MEAN: (usize, usize) = (0, 3);
const SECTION_LOG_SCALE: (usize, usize) = (3, 3);
const SECTION_QUAT: (usize, usize) = (6, 4);
const SECTION_OPACITY: (usize, usize) = (10, 1);
/// dL/dF, present when the scene is deformed: it ends the buffer.
const SECTION_F: (usize, usize) = (17, 9);

impl<E: GpuEngine> Gpu<E> {
    /// A zero-filled buffer of `len` elements, allocated with at least one element so that it
    /// satisfies the minimum binding size of a runtime-sized array of `T`.
    fn zeros_bindable<T: Pod>(
        &self,
        label: &'static str,
        len: usize,
    ) -> Result<GpuBuf<E, T>, E::Error> {
        GpuBuf::zeros_with_capacity(&self.engine, label, len, len.max(1))
    }

    /// One thread per simulated particle of `link` running `kernel` (`link_deform` or its
    /// VJP) over the link's constants and indices and four buffers, two read, two written.
    fn link_pass(
        &self,
        kernel: &'static r4d_shaders::Kernel,
        link: &LinkBufs<Self>,
        bufs: [&E::Raw; 4],
    ) -> Result<(), E::Error> {
        let n = link.consts.simulated;
        if n == 0 {
            return Ok(());
        }
        let mut r = Recording::new();
        let mut bind = vec![r.uniform(&link.consts), r.buf(&link.simulated.raw)];
        bind.extend(bufs.map(|b| r.buf(b)));
        r.dispatch(kernel, n, &bind);
        self.engine.execute(r)
    }

    fn zeros_labelled<T: Pod>(
        &self,
        label: &'static str,
        len: usize,
    ) -> Result<GpuBuf<E, T>, E::Error> {
        GpuBuf::zeros(&self.engine, label, len)
    }
}

/// Records an in-place exclusive prefix sum of the first `n` u32 of `data`.
fn scan<R>(r: &mut Recording<'_, R>, data: Resource, n: usize) {
    if n == 0 {
        return;
    }
    let blocks = n.div_ceil(BLOCK);
    let params = r.uniform(&[n as u32, blocks as u32, 0, 0]);
    let sums = r.scratch(4 * blocks as u64);
    let threads = blocks as u32 * k::SCAN_BLOCK.threads_per_group();
    r.dispatch(&k::SCAN_BLOCK, threads, &[params, data, sums]);
    if blocks > 1 {
        scan(r, sums, blocks);
        r.dispatch(&k::SCAN_ADD, n as u32, &[params, data, sums]);
    }
}

/// Records a stable radix sort of `m` records (4-bit digits: 8 passes over the depth key,
/// then `tile_passes` over the tile id), ping-ponging between `a` and `b`; returns the one
/// holding the result.
fn radix_sort<R>(
    r: &mut Recording<'_, R>,
    a: Resource,
    b: Resource,
    m: usize,
    tile_passes: u32,
) -> Resource {
    let blocks = m.div_ceil(BLOCK);
    let hist = r.scratch(4 * 16 * blocks as u64);
    let (mut src, mut dst) = (a, b);
    let passes = (0..8u32)
        .map(|p| (0u32, 4 * p))
        .chain((0..tile_passes).map(|p| (1u32, 4 * p)));
    for (key_sel, shift) in passes {
        let params = r.uniform(&[m as u32, shift, key_sel, blocks as u32]);
        let threads = blocks as u32 * k::RADIX_HIST.threads_per_group();
        r.dispatch(&k::RADIX_HIST, threads, &[params, src, hist]);
        scan(r, hist, 16 * blocks);
        r.dispatch(&k::RADIX_SCATTER, threads, &[params, src, hist, dst]);
        std::mem::swap(&mut src, &mut dst);
    }
    src
}

/// The rows of tiles covering the composited rows (`CameraConsts::rows`): the y extent of the
/// `rasterize` and `rasterize_vjp` dispatches.
fn tile_rows(cam: &CameraConsts) -> u32 {
    let t = r4d_splat::camera::consts::TILE;
    if cam.rows[1] <= cam.rows[0] {
        return 0;
    }
    cam.rows[1].div_ceil(t) - cam.rows[0] / t
}

impl<E: GpuEngine> SplatKernels for Gpu<E> {
    fn project(
        &self,
        scene: &SceneBufs<Self>,
        cam: &CameraConsts,
    ) -> Result<GpuBuf<E, Projected<f32>>, E::Error> {
        let n = scene.n;
        let out = self.zeros_bindable::<Projected<f32>>("splat_projected", n)?;
        if n == 0 {
            return Ok(out);
        }
        let mut r = Recording::new();
        let f = match &scene.f {
            Some(f) => r.buf(&f.raw),
            None => r.scratch(16),
        };
        let bind = [
            r.uniform(cam),
            r.uniform(&SplatProjectParams::of(scene)),
            r.buf(&scene.means.raw),
            r.buf(&scene.log_scales.raw),
            r.buf(&scene.quats.raw),
            r.buf(&scene.opacity_logits.raw),
            r.buf(&scene.sh.raw),
            f,
            r.buf(&out.raw),
        ];
        r.dispatch(&k::PROJECT, n as u32, &bind);
        self.engine.execute(r)?;
        Ok(out)
    }

    fn bin_tiles(
        &self,
        proj: &GpuBuf<E, Projected<f32>>,
        cam: &CameraConsts,
    ) -> Result<TileBufs<Self>, E::Error> {
        let n = proj.len;
        let tiles = (cam.tiles[0] * cam.tiles[1]) as usize;
        let offsets = self.zeros_labelled::<u32>("splat_tile_offsets", tiles + 1)?;
        let empty = |offsets: GpuBuf<E, u32>| -> Result<TileBufs<Self>, E::Error> {
            Ok(TileBufs {
                offsets,
                ids: self.zeros_labelled::<u32>("splat_tile_ids", 0)?,
                intersections: 0,
            })
        };
        if n == 0 || tiles == 0 {
            return empty(offsets);
        }
        // n + 1 counts: the last stays 0 and scans to the total.
        let counts = self.zeros_labelled::<u32>("splat_tile_counts", n + 1)?;
        let total = self.zeros_labelled::<u32>("splat_intersections", 1)?;
        let params = [n as u32, 0, 0, 0];
        {
            let mut r = Recording::new();
            let (cam_u, params_u) = (r.uniform(cam), r.uniform(&params));
            let (p, c, t) = (r.buf(&proj.raw), r.buf(&counts.raw), r.buf(&total.raw));
            r.dispatch(&k::COUNT_TILES, n as u32, &[cam_u, params_u, p, c]);
            scan(&mut r, c, n + 1);
            r.copy_range(c, 4 * n as u64, t, 0, 4);
            self.engine.execute(r)?;
        }
        let m = total.download(&self.engine)?[0] as usize;
        if m == 0 {
            return empty(offsets);
        }
        let keys_a = self.zeros_bindable::<TileKey>("splat_tile_keys", m)?;
        let keys_b = self.zeros_bindable::<TileKey>("splat_tile_keys", m)?;
        let ids = self.zeros_labelled::<u32>("splat_tile_ids", m)?;
        let mut r = Recording::new();
        let (cam_u, params_u) = (r.uniform(cam), r.uniform(&params));
        let (a, b) = (r.buf(&keys_a.raw), r.buf(&keys_b.raw));
        let emit = [cam_u, params_u, r.buf(&proj.raw), r.buf(&counts.raw), a];
        r.dispatch(&k::EMIT_KEYS, n as u32, &emit);
        let tile_bits = u32::BITS - (tiles as u32 - 1).leading_zeros();
        let sorted = radix_sort(&mut r, a, b, m, tile_bits.div_ceil(4));
        let ranges = [
            r.uniform(&[m as u32, tiles as u32, 0, 0]),
            sorted,
            r.buf(&offsets.raw),
            r.buf(&ids.raw),
        ];
        r.dispatch(&k::TILE_RANGES, m as u32, &ranges);
        self.engine.execute(r)?;
        Ok(TileBufs {
            offsets,
            ids,
            intersections: m,
        })
    }

    fn rasterize(
        &self,
        proj: &GpuBuf<E, Projected<f32>>,
        bins: &TileBufs<Self>,
        cam: &CameraConsts,
    ) -> Result<ImageBufs<Self>, E::Error> {
        let w = cam.size[0] as usize;
        let h = cam.band_height() as usize;
        let img = ImageBufs {
            rgb: self.zeros_labelled::<f32>("splat_rgb", w * h * 3)?,
            alpha: self.zeros_labelled::<f32>("splat_alpha", w * h)?,
            depth: self.zeros_labelled::<f32>("splat_depth", w * h)?,
            t_final: self.zeros_labelled::<f32>("splat_t_final", w * h)?,
            last: self.zeros_labelled::<u32>("splat_last", w * h)?,
        };
        let tx = cam.tiles[0];
        let ty = tile_rows(cam);
        if w == 0 || h == 0 || tx == 0 || ty == 0 {
            return Ok(img);
        }
        let mut r = Recording::new();
        // An empty projection binds a one-record dummy (a runtime-sized array needs one).
        let p = if proj.bytes() < std::mem::size_of::<Projected<f32>>() as u64 {
            r.scratch(std::mem::size_of::<Projected<f32>>() as u64)
        } else {
            r.buf(&proj.raw)
        };
        let bind = [
            r.uniform(cam),
            p,
            r.buf(&bins.offsets.raw),
            r.buf(&bins.ids.raw),
            r.buf(&img.rgb.raw),
            r.buf(&img.alpha.raw),
            r.buf(&img.depth.raw),
            r.buf(&img.t_final.raw),
            r.buf(&img.last.raw),
        ];
        r.dispatch_groups(&k::RASTERIZE, [tx, ty, 1], &bind);
        self.engine.execute(r)?;
        Ok(img)
    }

    /// `rasterize_vjp.wgsl`: one workgroup per tile reads each pixel's tape (final T, last
    /// position), walks it back to front and adds the per-Gaussian sums of each batch to
    /// `d_proj` with float atomics.
    fn rasterize_vjp(
        &self,
        proj: &GpuBuf<E, Projected<f32>>,
        bins: &TileBufs<Self>,
        cam: &CameraConsts,
        tape: Option<&ImageBufs<Self>>,
        d_rgb: &GpuBuf<E, f32>,
        d_proj: &mut GpuBuf<E, ProjectedGrad<f32>>,
    ) -> Result<(), E::Error> {
        assert_eq!(
            d_proj.len, proj.len,
            "rasterize_vjp: one projection gradient per Gaussian"
        );
        let tx = cam.tiles[0];
        let ty = tile_rows(cam);
        if proj.len == 0 || bins.intersections == 0 || tx == 0 || ty == 0 {
            return Ok(());
        }
        let w = cam.size[0] as usize;
        let h = cam.band_height() as usize;
        assert_eq!(
            d_rgb.len,
            w * h * 3,
            "rasterize_vjp: dL/drgb must have 3 values per pixel"
        );
        // Without the forward's tape, the forward writes one (the kernel does not composite).
        let own;
        let img = match tape {
            Some(t) => t,
            None => {
                own = self.rasterize(proj, bins, cam)?;
                &own
            }
        };
        let mut r = Recording::new();
        let bind = [
            r.uniform(cam),
            r.buf(&proj.raw),
            r.buf(&bins.offsets.raw),
            r.buf(&bins.ids.raw),
            r.buf(&img.t_final.raw),
            r.buf(&img.last.raw),
            r.buf(&d_rgb.raw),
            r.buf(&d_proj.raw),
        ];
        r.dispatch_groups(&k::RASTERIZE_VJP, [tx, ty, 1], &bind);
        self.engine.execute(r)?;
        Ok(())
    }

    /// `project_vjp.wgsl` (one thread per Gaussian, into one sectioned buffer), then
    /// `project_vjp_sh.wgsl` (dL/dsh) and copies of the sections into the gradient buffers.
    fn deform(
        &self,
        link: &LinkBufs<Self>,
        x: &GpuBuf<E, [f32; 3]>,
        f_sim: &GpuBuf<E, [f32; 9]>,
        means: &mut GpuBuf<E, [f32; 3]>,
        f: &mut GpuBuf<E, [[f32; 3]; 3]>,
    ) -> Result<(), E::Error> {
        self.link_pass(
            &k::LINK_DEFORM,
            link,
            [&x.raw, &f_sim.raw, &means.raw, &f.raw],
        )
    }

    fn deform_vjp(
        &self,
        link: &LinkBufs<Self>,
        d_means: &GpuBuf<E, [f32; 3]>,
        d_f: &GpuBuf<E, [[f32; 3]; 3]>,
        dx: &mut GpuBuf<E, [f32; 3]>,
        df_sim: &mut GpuBuf<E, [f32; 9]>,
    ) -> Result<(), E::Error> {
        let bufs = [&d_means.raw, &d_f.raw, &dx.raw, &df_sim.raw];
        self.link_pass(&k::LINK_DEFORM_VJP, link, bufs)
    }

    fn project_vjp(
        &self,
        scene: &SceneBufs<Self>,
        cam: &CameraConsts,
        proj: &GpuBuf<E, Projected<f32>>,
        d_proj: &GpuBuf<E, ProjectedGrad<f32>>,
    ) -> Result<SceneGradBufs<Self>, E::Error> {
        let n = scene.n;
        assert!(
            proj.len == n && d_proj.len == n,
            "project_vjp: {n} Gaussians but {} projections and {} projection gradients",
            proj.len,
            d_proj.len
        );
        let params = SplatProjectParams::of(scene);
        let out = SceneGradBufs {
            means: self.zeros_labelled::<[f32; 3]>("splat_d_means", n)?,
            log_scales: self.zeros_labelled::<[f32; 3]>("splat_d_log_scales", n)?,
            quats: self.zeros_labelled::<[f32; 4]>("splat_d_quats", n)?,
            opacity_logits: self.zeros_labelled::<f32>("splat_d_opacity_logits", n)?,
            sh: self.zeros_bindable::<f32>("splat_d_sh", n * params.sh_len as usize)?,
            f: match scene.f {
                Some(_) => Some(self.zeros_labelled::<[[f32; 3]; 3]>("splat_d_f", n)?),
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
        let packed = self.zeros_labelled::<f32>("splat_project_vjp_sections", n * width)?;
        let mut r = Recording::new();
        let f = match &scene.f {
            Some(f) => r.buf(&f.raw),
            None => r.scratch(16),
        };
        let params_u = r.uniform(&params);
        let pk = r.buf(&packed.raw);
        let bind = [
            r.uniform(cam),
            params_u,
            r.buf(&scene.means.raw),
            r.buf(&scene.log_scales.raw),
            r.buf(&scene.quats.raw),
            r.buf(&scene.opacity_logits.raw),
            r.buf(&scene.sh.raw),
            f,
            r.buf(&d_proj.raw),
            pk,
        ];
        r.dispatch(&k::PROJECT_VJP, n as u32, &bind);
        let sh = r.buf(&out.sh.raw);
        r.dispatch(&k::PROJECT_VJP_SH, n as u32, &[params_u, pk, sh]);
        let mut sections = vec![
            (SECTION_MEAN, r.buf(&out.means.raw)),
            (SECTION_LOG_SCALE, r.buf(&out.log_scales.raw)),
            (SECTION_QUAT, r.buf(&out.quats.raw)),
            (SECTION_OPACITY, r.buf(&out.opacity_logits.raw)),
        ];
        if let Some(df) = &out.f {
            sections.push((SECTION_F, r.buf(&df.raw)));
        }
        for ((start, width), dst) in sections {
            r.copy_range(pk, 4 * (start * n) as u64, dst, 0, 4 * (width * n) as u64);
        }
        self.engine.execute(r)?;
        Ok(out)
    }
}
