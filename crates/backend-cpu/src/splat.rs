//! The parallel CPU renderer: [`r4d_splat::SplatKernels`] for [`CpuBackend`] (host `Vec`s,
//! rayon, the backend's thread pool; the images are f32 in either scalar type). It calls
//! the same per-Gaussian ([`r4d_splat::project`]) and per-pixel ([`r4d_splat::raster`])
//! functions as the reference and adds only scheduling:
//!
//! * `project` / `project_vjp`: parallel over Gaussians.
//! * `bin_tiles`: parallel depth sort (stable order: f32 depth, then index), then a counting
//!   pass and a fill pass that keep each tile's list front to back.
//! * `rasterize`: parallel over the rows of tiles that cover the composited rows
//!   (`CameraConsts::rows`); each job writes its own slices of the images; a tile's Gaussians
//!   are gathered into contiguous arrays once for its pixels, and each row of a tile is
//!   composited at once (`r4d_splat::span`: the power of every Gaussian evaluated for the 16
//!   pixels together, vectorised, with AVX2 where present; bitwise the pixel-by-pixel
//!   results).
//! * `rasterize_vjp`: each row of a tile is composited again at once keeping each pixel's
//!   trace (or, with the forward's tape, each pixel walked back); rows of tiles are dealt
//!   round-robin to four workers, each with its own
//!   per-Gaussian accumulator (36 bytes per Gaussian); the accumulators are added to the
//!   caller's gradient in a fixed order, so the result does not depend on scheduling.

use crate::CpuBackend;
use r4d_mpm::math::Real;
use r4d_splat::kernels::{ImageBufs, SceneBufs, SceneGradBufs, TileBufs};
use r4d_splat::project::{self as pj, GaussianIn, Projected, ProjectedGrad};
use r4d_splat::raster::{self, Contribution, PixelOut, TileSplats};
use r4d_splat::span::{composite_span_f32, SPAN};
use r4d_splat::{CameraConsts, SplatKernels};
use rayon::prelude::*;

/// Accumulators of the rasterizer's backward pass (see `rasterize_vjp`): fixed, so that the
/// result does not depend on the number of threads.
const VJP_ACCUMULATORS: usize = 4;
use std::convert::Infallible;

fn gaussian<T: Real>(s: &SceneBufs<CpuBackend<T>>, i: usize) -> GaussianIn<f32> {
    GaussianIn {
        mean: s.means[i],
        log_scale: s.log_scales[i],
        quat: s.quats[i],
        opacity_logit: s.opacity_logits[i],
        f: s.f.as_ref().map(|f| f[i]),
    }
}

fn sh_len<T: Real>(s: &SceneBufs<CpuBackend<T>>) -> usize {
    r4d_splat::gaussians::sh_coeffs(s.sh_degree) * 3
}

impl<T: Real> SplatKernels for CpuBackend<T> {
    fn project(
        &self,
        scene: &SceneBufs<Self>,
        cam: &CameraConsts,
    ) -> Result<Vec<Projected<f32>>, Infallible> {
        self.run(|| {
            let cp = cam.params();
            let k = sh_len(scene);
            Ok((0..scene.n)
                .into_par_iter()
                .with_min_len(256)
                .map(|i| {
                    pj::project(
                        &gaussian(scene, i),
                        &scene.sh[i * k..(i + 1) * k],
                        scene.sh_degree,
                        &cp,
                    )
                    .unwrap_or_default()
                })
                .collect())
        })
    }

    fn bin_tiles(
        &self,
        proj: &Vec<Projected<f32>>,
        cam: &CameraConsts,
    ) -> Result<TileBufs<Self>, Infallible> {
        self.run(|| {
            let mut order: Vec<u32> = (0..proj.len() as u32)
                .into_par_iter()
                .filter(|&i| proj[i as usize].radii != [0, 0])
                .collect();
            order.par_sort_unstable_by(|&a, &b| {
                proj[a as usize]
                    .depth
                    .total_cmp(&proj[b as usize].depth)
                    .then(a.cmp(&b))
            });
            let b = raster::bin_tiles(proj, &order, cam.size[0], cam.size[1]);
            Ok(TileBufs {
                intersections: b.ids.len(),
                offsets: b.offsets,
                ids: b.ids,
            })
        })
    }

    fn rasterize(
        &self,
        proj: &Vec<Projected<f32>>,
        bins: &TileBufs<Self>,
        cam: &CameraConsts,
    ) -> Result<ImageBufs<Self>, Infallible> {
        self.run(|| {
            let w = cam.size[0] as usize;
            let [r0, r1] = [cam.rows[0] as usize, cam.rows[1] as usize];
            let n = w * (r1 - r0);
            let tiles_x = cam.tiles[0] as usize;
            let bg = cam.bg();
            let mut rgb = vec![0f32; n * 3];
            let mut alpha = vec![0f32; n];
            let mut depth = vec![0f32; n];
            let mut t_final = vec![0f32; n];
            let mut last = vec![0u32; n];
            // One job per row of tiles: the rows of the band it covers, each job writing its own
            // slices of the images.
            let mut jobs = Vec::new();
            let (mut rgb_r, mut alpha_r, mut depth_r, mut t_r, mut last_r) = (
                &mut rgb[..],
                &mut alpha[..],
                &mut depth[..],
                &mut t_final[..],
                &mut last[..],
            );
            for ty in r0 / 16..r1.div_ceil(16) {
                let rows = (ty * 16).max(r0)..((ty + 1) * 16).min(r1);
                let k = rows.len() * w;
                let (a, rest) = std::mem::take(&mut rgb_r).split_at_mut(3 * k);
                rgb_r = rest;
                let (b, rest) = std::mem::take(&mut alpha_r).split_at_mut(k);
                alpha_r = rest;
                let (c, rest) = std::mem::take(&mut depth_r).split_at_mut(k);
                depth_r = rest;
                let (d, rest) = std::mem::take(&mut t_r).split_at_mut(k);
                t_r = rest;
                let (e, rest) = std::mem::take(&mut last_r).split_at_mut(k);
                last_r = rest;
                jobs.push((ty, rows, a, b, c, d, e));
            }
            jobs.into_par_iter()
                .for_each(|(ty, rows, rgb, alpha, depth, t_final, last)| {
                    let mut tile = TileSplats::default();
                    let mut out = [(PixelOut::default(), 0.0); SPAN];
                    for tx in 0..tiles_x {
                        let t = ty * tiles_x + tx;
                        tile.gather(
                            &bins.ids[bins.offsets[t] as usize..bins.offsets[t + 1] as usize],
                            proj,
                        );
                        let i0 = tx * SPAN;
                        let lanes = SPAN.min(w - i0);
                        for (r, j) in rows.clone().enumerate() {
                            composite_span_f32(
                                i0 as u32,
                                j as u32,
                                &[true; SPAN][..lanes],
                                &tile,
                                &bg,
                                &mut out,
                                None,
                            );
                            for (l, (px, tf)) in out[..lanes].iter().enumerate() {
                                let k = r * w + i0 + l;
                                rgb[3 * k..3 * k + 3].copy_from_slice(&px.rgb);
                                alpha[k] = px.alpha;
                                depth[k] = px.depth;
                                t_final[k] = *tf;
                                last[k] = px.last;
                            }
                        }
                    }
                });
            Ok(ImageBufs {
                rgb,
                alpha,
                depth,
                t_final,
                last,
            })
        })
    }

    fn rasterize_vjp(
        &self,
        proj: &Vec<Projected<f32>>,
        bins: &TileBufs<Self>,
        cam: &CameraConsts,
        tape: Option<&ImageBufs<Self>>,
        d_rgb: &Vec<f32>,
        d_proj: &mut Vec<ProjectedGrad<f32>>,
    ) -> Result<(), Infallible> {
        self.run(|| {
            let w = cam.size[0] as usize;
            let [r0, r1] = [cam.rows[0] as usize, cam.rows[1] as usize];
            let tiles_x = cam.tiles[0] as usize;
            let (ty0, ty1) = (r0 / 16, r1.div_ceil(16));
            let bg = cam.bg();
            // A fixed number of accumulators (tile rows interleaved over them, added to `d_proj`
            // in order): the gradients are bitwise the same whatever the thread count (1 thread
            // runs the four in turn). Memory: four copies of the per-Gaussian gradients (36 B
            // each).
            let workers = VJP_ACCUMULATORS;
            let parts: Vec<Vec<ProjectedGrad<f32>>> = (0..workers)
                .into_par_iter()
                .map(|wk| {
                    let mut acc = vec![ProjectedGrad::<f32>::default(); proj.len()];
                    let mut traces: [Vec<Contribution<f32>>; SPAN] =
                        std::array::from_fn(|_| Vec::new());
                    let mut out = [(PixelOut::default(), 0.0); SPAN];
                    let mut tile = TileSplats::default();
                    for ty in (ty0 + wk..ty1).step_by(workers) {
                        for tx in 0..tiles_x {
                            let t = ty * tiles_x + tx;
                            tile.gather(
                                &bins.ids[bins.offsets[t] as usize..bins.offsets[t + 1] as usize],
                                proj,
                            );
                            let i0 = tx * SPAN;
                            let lanes = SPAN.min(w - i0);
                            for j in (ty * 16).max(r0)..((ty + 1) * 16).min(r1) {
                                let row = (j - r0) * w + i0;
                                let d = |l: usize| {
                                    let k = 3 * (row + l);
                                    [d_rgb[k], d_rgb[k + 1], d_rgb[k + 2]]
                                };
                                // Pixels with dL/drgb = 0 take no part.
                                let mut live = [false; SPAN];
                                for (l, on) in live[..lanes].iter_mut().enumerate() {
                                    *on = d(l) != [0.0; 3];
                                }
                                if !live.contains(&true) {
                                    continue;
                                }
                                match tape {
                                    Some(img) => {
                                        for l in (0..lanes).filter(|&l| live[l]) {
                                            let p = row + l;
                                            let tf = img.t_final[p];
                                            raster::trace_back(
                                                (i0 + l) as u32,
                                                j as u32,
                                                &tile,
                                                tf,
                                                img.last[p],
                                                &mut traces[l],
                                            );
                                            out[l].1 = tf;
                                        }
                                    }
                                    None => composite_span_f32(
                                        i0 as u32,
                                        j as u32,
                                        &live[..lanes],
                                        &tile,
                                        &bg,
                                        &mut out,
                                        Some(&mut traces),
                                    ),
                                }
                                for l in (0..lanes).filter(|&l| live[l]) {
                                    raster::composite_pixel_vjp(
                                        &traces[l],
                                        out[l].1,
                                        &tile,
                                        &bg,
                                        &d(l),
                                        |id, g| acc[id as usize].add(g),
                                    );
                                }
                            }
                        }
                    }
                    acc
                })
                .collect();
            d_proj
                .par_iter_mut()
                .enumerate()
                .with_min_len(4096)
                .for_each(|(i, a)| {
                    for p in &parts {
                        a.add(&p[i]);
                    }
                });
            Ok(())
        })
    }

    fn deform(
        &self,
        link: &r4d_splat::kernels::LinkBufs<Self>,
        x: &Vec<[f32; 3]>,
        f_sim: &Vec<[f32; 9]>,
        means: &mut Vec<[f32; 3]>,
        f: &mut Vec<[[f32; 3]; 3]>,
    ) -> Result<(), std::convert::Infallible> {
        r4d_splat::link::deform_host(&link.consts, &link.simulated, x, f_sim, means, f);
        Ok(())
    }

    fn deform_vjp(
        &self,
        link: &r4d_splat::kernels::LinkBufs<Self>,
        d_means: &Vec<[f32; 3]>,
        d_f: &Vec<[[f32; 3]; 3]>,
        dx: &mut Vec<[f32; 3]>,
        df_sim: &mut Vec<[f32; 9]>,
    ) -> Result<(), std::convert::Infallible> {
        r4d_splat::link::deform_vjp_host(&link.consts, &link.simulated, d_means, d_f, dx, df_sim);
        Ok(())
    }

    fn project_vjp(
        &self,
        scene: &SceneBufs<Self>,
        cam: &CameraConsts,
        proj: &Vec<Projected<f32>>,
        d_proj: &Vec<ProjectedGrad<f32>>,
    ) -> Result<SceneGradBufs<Self>, Infallible> {
        self.run(|| {
            let cp = cam.params();
            let k = sh_len(scene);
            let mut d_sh = vec![0f32; scene.n * k];
            let per: Vec<pj::GaussianGrad<f32>> = d_sh
                .par_chunks_mut(k.max(1))
                .enumerate()
                .with_min_len(256)
                .map(|(i, dsh)| {
                    if proj[i].radii == [0, 0] {
                        return pj::GaussianGrad::default();
                    }
                    pj::project_vjp(
                        &gaussian(scene, i),
                        &scene.sh[i * k..(i + 1) * k],
                        scene.sh_degree,
                        &cp,
                        &d_proj[i],
                        dsh,
                    )
                })
                .collect();
            Ok(SceneGradBufs {
                means: per.iter().map(|g| g.mean).collect(),
                log_scales: per.iter().map(|g| g.log_scale).collect(),
                quats: per.iter().map(|g| g.quat).collect(),
                opacity_logits: per.iter().map(|g| g.opacity_logit).collect(),
                sh: d_sh,
                f: scene.f.as_ref().map(|_| per.iter().map(|g| g.f).collect()),
            })
        })
    }
}
