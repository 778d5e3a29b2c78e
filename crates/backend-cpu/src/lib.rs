//! # r4d-backend-cpu: the fast CPU backend (rayon)
//!
//! One backend, [`CpuBackend`], in f32 or f64: the family's base trait
//! ([`r4d_backend::Backend`], host `Vec`s), the simulator's kernels ([`r4d_mpm::MpmKernels`]
//! and the reverse sweep's) and the renderer's ([`r4d_splat::SplatKernels`], in [`splat`]). It calls the same per-particle and
//! per-node functions as [`r4d_mpm::reference`] (the math lives once, in `r4d_mpm::transfer`
//! and `r4d_mpm::constitutive`) and adds only scheduling and memory layout:
//!
//! * **Deterministic parallel P2G without atomics.** Each substep the particles are ordered by
//!   the x index of their stencil base (a stable counting sort). Node layers are stored
//!   x-major, so the particles whose base lies in a slab of [`SLAB`] layers write only to a
//!   contiguous range of `SLAB + 2` layers. Even slabs are scattered in parallel, then odd
//!   slabs: same-colour slabs never share a node, so each thread owns a disjoint `&mut` range
//!   of the grid (safe Rust, no atomics). The summation order of every node is fixed by the
//!   scheme, so results are bitwise identical for any thread count.
//! * **Active blocks only.** The grid tracks which blocks of 4^3 nodes were touched; clearing
//!   and the grid update visit only those.
//! * [`Par::Seq`] runs the same code on one thread (tests use it to check determinism).
//!
//! Memory: buffers are plain `Vec`s; host memory is measured by the benches' counting
//! allocator, so [`Backend::memory_usage`] reports zero here.

use r4d_mpm::kernels::{
    blocks_per_axis, Backend, Grid, GridBc, MemoryUsage, MpmKernels, ParticleBc, Particles,
    StepConsts, BLOCK, HEALTH_OUT_OF_DOMAIN,
};
use r4d_mpm::math::{svd3_many, Mat3, Real, Svd3};
use r4d_mpm::params::MAT_CONSTS;
use r4d_mpm::transfer::{
    damped_affine, g2p_finish, gather, grid_node_update, in_domain, k, out_of_domain_coordinate,
    particle_bcs, particle_stress_svd, record, scatter, stencil,
};
use r4d_mpm::PartConsts;
use rayon::prelude::*;
use std::convert::Infallible;
use std::marker::PhantomData;
use std::sync::Arc;

pub mod adjoint;
pub mod slabs;
pub mod splat;

pub use slabs::SLAB;

/// Particles per work item of the particle stress stage: their SVDs are computed side by side
/// ([`r4d_mpm::math::svd3_many`]).
const STRESS_CHUNK: usize = 8 * r4d_mpm::math::SVD_BATCH;

/// Particles per work item of G2P.
const G2P_CHUNK: usize = 256;

/// Parallelism of the CPU backend.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Par {
    /// One thread.
    Seq,
    /// Rayon's global pool (all cores).
    #[default]
    Rayon,
    /// A dedicated pool of this many threads.
    Threads(usize),
}

/// The CPU backend, in scalar type `T` (`f32` by default; `f64` for the fits' reverse sweeps
/// and finite-difference checks).
#[derive(Clone, Debug)]
pub struct CpuBackend<T = f32> {
    pool: Option<Arc<rayon::ThreadPool>>,
    par: Par,
    /// The reverse G2P's per-particle results in slab order, kept between substeps (a
    /// buffer of this size allocated every substep costs its page faults each time).
    g2p_bar: Arc<std::sync::Mutex<Vec<r4d_mpm::adjoint::transfer_vjp::G2pBar<T>>>>,
    _t: PhantomData<T>,
}

impl Default for CpuBackend<f32> {
    fn default() -> Self {
        Self::new(Par::Rayon)
    }
}

impl CpuBackend<f32> {
    /// An f32 backend with the given parallelism.
    pub fn new(par: Par) -> Self {
        Self::with_par(par)
    }
}

impl<T> CpuBackend<T> {
    /// A backend in scalar type `T` with the given parallelism.
    pub fn with_par(par: Par) -> Self {
        let threads = match par {
            Par::Seq => Some(1),
            Par::Threads(n) => Some(n.max(1)),
            Par::Rayon => None,
        };
        let pool = threads.map(|t| {
            Arc::new(
                rayon::ThreadPoolBuilder::new()
                    .num_threads(t)
                    .build()
                    .expect("thread pool creation"),
            )
        });
        CpuBackend {
            pool,
            par,
            g2p_bar: Default::default(),
            _t: PhantomData,
        }
    }
    /// The parallelism.
    pub fn par(&self) -> Par {
        self.par
    }
    fn run<R: Send>(&self, f: impl FnOnce() -> R + Send) -> R {
        match &self.pool {
            Some(p) => p.install(f),
            None => f(),
        }
    }
    /// Whether a kernel over `particles` particles runs on the calling thread: always with
    /// [`Par::Seq`], and below [`SEQUENTIAL_BELOW`] particles, where handing the work to the
    /// pool and waking its threads costs more than the work. The results do not depend on it
    /// (every kernel is deterministic for any thread count).
    fn sequential(&self, particles: usize) -> bool {
        self.par == Par::Seq || particles < SEQUENTIAL_BELOW
    }
    /// [`Self::sequential`] for a kernel over `nodes` grid nodes (a node's work is about
    /// [`NODES_PER_PARTICLE`] times cheaper than a particle's).
    fn sequential_nodes(&self, nodes: usize) -> bool {
        self.sequential(nodes / NODES_PER_PARTICLE)
    }
    /// Runs `f` on the calling thread when `seq`, else in the backend's pool.
    fn run_as<R: Send>(&self, seq: bool, f: impl FnOnce() -> R + Send) -> R {
        if seq {
            f()
        } else {
            self.run(f)
        }
    }
}

/// Kernels over fewer particles than this run on the calling thread ([`CpuBackend`]'s
/// small-problem path): the demo's test-size scenes have a few hundred particles, the plant
/// demo 1 836 (parallel).
pub const SEQUENTIAL_BELOW: usize = 1024;

/// Grid nodes counted as one particle's work by the small-problem rule.
pub const NODES_PER_PARTICLE: usize = 8;

/// Calls `f(node_index, node)` for each node of an active block (x-block slabs in parallel
/// unless `seq`).
pub(crate) fn for_active_blocks<T: Send>(
    seq: bool,
    nodes: &mut [[T; 4]],
    active: &[u32],
    n: usize,
    f: impl Fn([usize; 3], &mut [T; 4]) + Sync,
) {
    let nb = blocks_per_axis(n);
    let plane = BLOCK * n * n;
    let slab_fn = |(bx, slab): (usize, &mut [[T; 4]])| {
        let i0 = bx * BLOCK;
        let i1 = (i0 + BLOCK).min(n);
        for by in 0..nb {
            for bz in 0..nb {
                if active[(bx * nb + by) * nb + bz] == 0 {
                    continue;
                }
                let (j0, j1) = (by * BLOCK, (by * BLOCK + BLOCK).min(n));
                let (k0, k1) = (bz * BLOCK, (bz * BLOCK + BLOCK).min(n));
                for i in i0..i1 {
                    for j in j0..j1 {
                        let row = ((i - i0) * n + j) * n;
                        for (k, node) in slab[row + k0..row + k1].iter_mut().enumerate() {
                            f([i, j, k0 + k], node);
                        }
                    }
                }
            }
        }
    };
    if seq {
        nodes.chunks_mut(plane).enumerate().for_each(slab_fn);
    } else {
        nodes.par_chunks_mut(plane).enumerate().for_each(slab_fn);
    }
}

impl<T: Real> Backend for CpuBackend<T> {
    r4d_backend::host_vec_backend!();

    fn name(&self) -> &'static str {
        "cpu"
    }
    fn memory_usage(&self) -> MemoryUsage {
        MemoryUsage::default()
    }
}

impl<T: Real> MpmKernels for CpuBackend<T> {
    type Scalar = T;
    r4d_mpm::host_vec_accumulate!();

    fn particle_bcs(
        &self,
        p: &mut Particles<Self>,
        bcs: &Vec<ParticleBc>,
        c: &StepConsts,
    ) -> Result<(), Infallible> {
        let bcs = &bcs[..c.n_particle_bcs as usize];
        let (x0, mass) = (&p.x0, &p.mass);
        let body = |(i, v): (usize, &mut [T; 3])| particle_bcs(x0[i], v, mass[i], bcs, c);
        if self.sequential(p.count) {
            p.v.iter_mut().enumerate().for_each(body);
        } else {
            self.run(|| p.v.par_iter_mut().enumerate().for_each(body));
        }
        Ok(())
    }

    fn p2g(
        &self,
        p: &mut Particles<Self>,
        parts: &Vec<PartConsts>,
        mats: &Vec<[T; MAT_CONSTS]>,
        g: &mut Grid<Self>,
        c: &StepConsts,
    ) -> Result<(), Infallible> {
        let n = g.n;
        let np = p.count;
        let inv_dx = k::<T>(c.inv_dx);
        let n_slabs = slabs::slab_count(n);
        if g.scratch.len() != 2 * np + n_slabs + 1 {
            g.scratch = vec![0; 2 * np + n_slabs + 1];
        }
        let seq = self.sequential(np);
        self.run_as(seq, || {
            // 1. Clear the blocks touched last substep (every other node is zero).
            for_active_blocks(seq, &mut g.nodes, &g.active, n, |_, node| {
                *node = [T::zero(); 4]
            });

            // 2. Particle stage: return mapping + stress; key = stencil base cell.
            let (keys, rest) = g.scratch.split_at_mut(np);
            let (order, starts) = rest.split_at_mut(np);
            // In chunks whose SVDs are computed side by side (bitwise `svd3` of each F).
            let (x, cm, vol0, part) = (&p.x, &p.c, &p.vol0, &p.part);
            type Chunk<'a, T> = (
                usize,
                (
                    ((&'a mut [[T; 9]], &'a mut [[T; 2]]), &'a mut [[T; 9]]),
                    &'a mut [u32],
                ),
            );
            let stage = |(ci, (((f, pl), s), key)): Chunk<'_, T>| {
                let len = f.len();
                let mut fm = [Mat3::<T>::default(); STRESS_CHUNK];
                for (m, fi) in fm.iter_mut().zip(f.iter()) {
                    *m = Mat3::from_array(*fi);
                }
                let mut svd = [Svd3::<T>::default(); STRESS_CHUNK];
                svd3_many(&fm[..len], &mut svd[..len]);
                for j in 0..len {
                    let i = ci * STRESS_CHUNK + j;
                    let slot = part[i] as usize;
                    s[j] = particle_stress_svd(
                        &mut f[j],
                        &svd[j],
                        &mut pl[j],
                        &cm[i],
                        vol0[i],
                        &parts[slot],
                        &mats[slot],
                        c,
                    );
                    key[j] = if in_domain(x[i], inv_dx, n) {
                        let b = stencil(x[i], inv_dx).base;
                        ((b[0] as usize * n + b[1] as usize) * n + b[2] as usize) as u32
                    } else {
                        u32::MAX
                    };
                }
            };
            if seq {
                p.f.chunks_mut(STRESS_CHUNK)
                    .zip(p.plastic.chunks_mut(STRESS_CHUNK))
                    .zip(p.stress.chunks_mut(STRESS_CHUNK))
                    .zip(keys.chunks_mut(STRESS_CHUNK))
                    .enumerate()
                    .for_each(stage);
            } else {
                p.f.par_chunks_mut(STRESS_CHUNK)
                    .zip(p.plastic.par_chunks_mut(STRESS_CHUNK))
                    .zip(p.stress.par_chunks_mut(STRESS_CHUNK))
                    .zip(keys.par_chunks_mut(STRESS_CHUNK))
                    .enumerate()
                    .for_each(stage);
            }

            // 3. Sort the particles by slab; mark the active blocks.
            slabs::sort_by_slab(keys, n, order, starts);
            slabs::mark_active_blocks(seq, keys, order, starts, n, &mut g.active);

            // 4. Scatter: even slabs in parallel, then odd slabs.
            let (v, mass, stress) = (&p.v, &p.mass, &p.stress);
            slabs::scatter_by_slab(
                seq,
                &mut g.nodes,
                n * n,
                n,
                order,
                starts,
                &mut [] as &mut [()],
                |lo, ids, nodes, _| {
                    ScatterRun {
                        x,
                        v,
                        cm,
                        mass,
                        stress,
                        c,
                    }
                    .run(nodes, lo, n, ids)
                },
            );
        });
        Ok(())
    }

    fn grid_update(
        &self,
        g: &mut Grid<Self>,
        bcs: &Vec<GridBc>,
        c: &StepConsts,
    ) -> Result<(), Infallible> {
        let bcs = &bcs[..c.n_grid_bcs as usize];
        let n = g.n;
        let active_nodes = g.active.iter().filter(|&&a| a != 0).count() * BLOCK.pow(3);
        let seq = self.sequential_nodes(active_nodes);
        self.run_as(seq, || {
            for_active_blocks(seq, &mut g.nodes, &g.active, n, |ijk, node| {
                grid_node_update(ijk, node, bcs, c)
            })
        });
        Ok(())
    }

    fn g2p(
        &self,
        p: &mut Particles<Self>,
        g: &mut Grid<Self>,
        c: &StepConsts,
    ) -> Result<(), Infallible> {
        let n = g.n;
        let nodes = &g.nodes;
        let chunk = |(ci, (((x, v), cm), f)): ChunkItem<'_, T>| -> Problem {
            G2pChunk {
                first: ci * G2P_CHUNK,
                x,
                v,
                cm,
                f,
                nodes,
                n,
                c,
            }
            .run()
        };
        type ChunkItem<'a, T> = (
            usize,
            (
                ((&'a mut [[T; 3]], &'a mut [[T; 3]]), &'a mut [[T; 9]]),
                &'a mut [[T; 9]],
            ),
        );
        let worst = if self.sequential(p.count) {
            p.x.chunks_mut(G2P_CHUNK)
                .zip(p.v.chunks_mut(G2P_CHUNK))
                .zip(p.c.chunks_mut(G2P_CHUNK))
                .zip(p.f.chunks_mut(G2P_CHUNK))
                .enumerate()
                .map(chunk)
                .fold(None, earliest)
        } else {
            self.run(|| {
                p.x.par_chunks_mut(G2P_CHUNK)
                    .zip(p.v.par_chunks_mut(G2P_CHUNK))
                    .zip(p.c.par_chunks_mut(G2P_CHUNK))
                    .zip(p.f.par_chunks_mut(G2P_CHUNK))
                    .enumerate()
                    .map(chunk)
                    .reduce(|| None, earliest)
            })
        };
        if let Some((code, i, val)) = worst {
            record(&mut g.health[0], code, c.substep, i, val);
        }
        Ok(())
    }
}

/// A health problem of G2P: code, particle, value.
type Problem = Option<(u32, u32, f32)>;

/// The earlier problem: the one of the lower particle index.
fn earliest(a: Problem, b: Problem) -> Problem {
    match (a, b) {
        (Some(a), Some(b)) => Some(if a.1 <= b.1 { a } else { b }),
        (a, None) => a,
        (None, b) => b,
    }
}

/// G2P of a run of particles (the first has index `first`).
struct G2pChunk<'a, T> {
    first: usize,
    x: &'a mut [[T; 3]],
    v: &'a mut [[T; 3]],
    cm: &'a mut [[T; 9]],
    f: &'a mut [[T; 9]],
    nodes: &'a [[T; 4]],
    n: usize,
    c: &'a StepConsts,
}

impl<T: Real> G2pChunk<'_, T> {
    /// Runs G2P on the chunk's particles; returns its earliest health problem. In `f32` on a
    /// processor with AVX (detected at run time), two particles' gathers share each
    /// instruction ([`r4d_mpm::transfer_avx`]); the results are bitwise the same either way.
    fn run(mut self) -> Problem {
        #[cfg(target_arch = "x86_64")]
        if std::any::TypeId::of::<T>() == std::any::TypeId::of::<f32>()
            && r4d_mpm::transfer_avx::available()
        {
            // SAFETY: the processor supports AVX (checked just above).
            return unsafe { self.run_pairs_avx() };
        }
        let mut worst = None;
        for j in 0..self.x.len() {
            worst = earliest(worst, self.one(j));
        }
        worst
    }

    /// G2P of particle `j` of the chunk on its own.
    #[inline(always)]
    fn one(&mut self, j: usize) -> Problem {
        let (n, c) = (self.n, self.c);
        let inv_dx = k::<T>(c.inv_dx);
        let i = (self.first + j) as u32;
        let x = &mut self.x[j];
        if !in_domain(*x, inv_dx, n) {
            let value = out_of_domain_coordinate(*x, inv_dx, n);
            return Some((HEALTH_OUT_OF_DOMAIN, i, value));
        }
        let st = stencil(*x, inv_dx);
        let gathered = gather(self.nodes, n, &st, c);
        let (code, value) = g2p_finish(
            &gathered,
            x,
            &mut self.v[j],
            &mut self.cm[j],
            &mut self.f[j],
            c,
        );
        (code != 0).then_some((code, i, value))
    }

    /// [`Self::run`] two particles at a time where both are inside the grid (`T` = `f32`).
    ///
    /// # Safety
    /// The processor must support AVX.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx")]
    unsafe fn run_pairs_avx(mut self) -> Problem {
        use r4d_mpm::transfer::{Gathered, Stencil};
        let (n, c) = (self.n, self.c);
        let inv_dx = k::<T>(c.inv_dx);
        // `T` is `f32` here, so these conversions are exact.
        let nodes: &[[f32; 4]] = bytemuck::cast_slice(self.nodes);
        let to_f32 = |x: [T; 3]| x.map(|e| e.f64() as f32);
        let back = |g: &Gathered<f32>| Gathered::<T> {
            v: g.v.map(|e| T::c(e as f64)),
            c: g.c.map(|e| T::c(e as f64)),
            grad_v: g.grad_v.map(|e| T::c(e as f64)),
        };
        let mut worst = None;
        let len = self.x.len();
        let mut j = 0;
        while j < len {
            if j + 1 < len && in_domain(self.x[j], inv_dx, n) && in_domain(self.x[j + 1], inv_dx, n)
            {
                let inv = k::<f32>(c.inv_dx);
                let st: [Stencil<f32>; 2] = [
                    stencil(to_f32(self.x[j]), inv),
                    stencil(to_f32(self.x[j + 1]), inv),
                ];
                let gathered = r4d_mpm::transfer_avx::gather_pair(nodes, n, &st, c);
                for (p, g) in gathered.iter().enumerate() {
                    let q = j + p;
                    let (code, value) = g2p_finish(
                        &back(g),
                        &mut self.x[q],
                        &mut self.v[q],
                        &mut self.cm[q],
                        &mut self.f[q],
                        c,
                    );
                    if code != 0 {
                        worst = earliest(worst, Some((code, (self.first + q) as u32, value)));
                    }
                }
                j += 2;
            } else {
                worst = earliest(worst, self.one(j));
                j += 1;
            }
        }
        worst
    }
}

/// The particles of one P2G scatter.
struct ScatterRun<'a, T> {
    x: &'a [[T; 3]],
    v: &'a [[T; 3]],
    cm: &'a [[T; 9]],
    mass: &'a [T],
    stress: &'a [[T; 9]],
    c: &'a StepConsts,
}

impl<T: Real> ScatterRun<'_, T> {
    /// Scatters particles `ids` (in order) into `nodes`, a slab starting at layer `lo`. In
    /// `f32` on a processor with AVX (detected at run time) two particles' node shares are
    /// computed side by side ([`r4d_mpm::transfer_avx::scatter_pair`]); every node receives
    /// bitwise the same sums either way.
    fn run(&self, nodes: &mut [[T; 4]], lo: usize, n: usize, ids: &[u32]) {
        #[cfg(target_arch = "x86_64")]
        if std::any::TypeId::of::<T>() == std::any::TypeId::of::<f32>()
            && r4d_mpm::transfer_avx::available()
        {
            // SAFETY: the processor supports AVX (checked just above).
            return unsafe { self.run_pairs_avx(nodes, lo, n, ids) };
        }
        for &i in ids {
            self.one(nodes, lo, n, i as usize);
        }
    }

    /// Scatters particle `i` on its own.
    #[inline(always)]
    fn one(&self, nodes: &mut [[T; 4]], lo: usize, n: usize, i: usize) {
        let c = self.c;
        let st = stencil(self.x[i], k::<T>(c.inv_dx));
        let a = damped_affine(&self.cm[i], c.rpic_damping);
        scatter(
            nodes,
            lo,
            n,
            &st,
            self.v[i],
            &a,
            self.mass[i],
            &self.stress[i],
            c,
        );
    }

    /// [`Self::run`] two particles at a time (`T` = `f32`).
    ///
    /// # Safety
    /// The processor must support AVX.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx")]
    unsafe fn run_pairs_avx(&self, nodes: &mut [[T; 4]], lo: usize, n: usize, ids: &[u32]) {
        let c = self.c;
        let inv = k::<f32>(c.inv_dx);
        // `T` is `f32` here: these views and conversions are exact.
        let nodes32: &mut [[f32; 4]] = bytemuck::cast_slice_mut(nodes);
        let nine = |a: &[T; 9]| -> [f32; 9] { a.map(|e| e.f64() as f32) };
        let three = |a: &[T; 3]| -> [f32; 3] { a.map(|e| e.f64() as f32) };
        let mass: &[f32] = bytemuck::cast_slice(self.mass);
        let mut pairs = ids.chunks_exact(2);
        for ab in &mut pairs {
            let (a, b) = (ab[0] as usize, ab[1] as usize);
            let st = [
                stencil(three(&self.x[a]), inv),
                stencil(three(&self.x[b]), inv),
            ];
            let ca = nine(&damped_affine(&self.cm[a], c.rpic_damping));
            let cb = nine(&damped_affine(&self.cm[b], c.rpic_damping));
            let (sa, sb) = (nine(&self.stress[a]), nine(&self.stress[b]));
            r4d_mpm::transfer_avx::scatter_pair(
                nodes32,
                lo,
                n,
                &st,
                [three(&self.v[a]), three(&self.v[b])],
                [&ca, &cb],
                [mass[a], mass[b]],
                [&sa, &sb],
                c,
            );
        }
        if let [i] = pairs.remainder() {
            self.one(bytemuck::cast_slice_mut(nodes32), lo, n, *i as usize);
        }
    }
}
