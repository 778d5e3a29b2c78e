//! Conflict-free parallel scatters: particles grouped by slabs of [`SLAB`] node layers along x
//! (a stable counting sort); a slab's particles write only to `SLAB + 2` contiguous layers of
//! the x-major grid, so even slabs run in parallel on disjoint `&mut` sub-slices, then odd
//! slabs. The summation order of every node is fixed by the scheme (deterministic for any
//! thread count).

use rayon::prelude::*;

/// Width (in node layers along x) of the slabs scattered in parallel; must be >= 2.
pub const SLAB: usize = 2;

/// Number of slabs for `n` node layers.
pub fn slab_count(n: usize) -> usize {
    n.div_ceil(SLAB)
}

/// Node layers `[lo, hi)` written by slab `s`.
fn slab_layers(s: usize, n: usize) -> (usize, usize) {
    (s * SLAB, (s * SLAB + SLAB + 2).min(n))
}

/// Stable counting sort of particles by the slab of their stencil's base x layer
/// (`base_x[i] = None`: the particle is left out). `order` (one entry per particle) receives
/// the ids, `starts` (`slab_count(n) + 1` entries) the slab boundaries in `order`.
pub fn sort_by_slab(base_x: &[Option<u32>], n: usize, order: &mut [u32], starts: &mut [u32]) {
    let ns = slab_count(n);
    starts.fill(0);
    for b in base_x.iter().flatten() {
        starts[*b as usize / SLAB + 1] += 1;
    }
    for s in 0..ns {
        starts[s + 1] += starts[s];
    }
    let mut fill: Vec<u32> = starts[..ns].to_vec();
    for (i, b) in base_x.iter().enumerate() {
        if let Some(b) = b {
            let s = *b as usize / SLAB;
            order[fill[s] as usize] = i as u32;
            fill[s] += 1;
        }
    }
}

/// Runs `f(x_lo, ids, slab_nodes)` for every non-empty slab, even slabs in parallel, then odd
/// ones (all on the calling thread when `seq`). `nodes` is the x-major grid with `layer`
/// entries per x layer; `slab_nodes` starts at layer `x_lo`. Returns the results in slab order.
pub fn scatter_by_slab<T: Send, R: Send>(
    seq: bool,
    nodes: &mut [T],
    layer: usize,
    n: usize,
    order: &[u32],
    starts: &[u32],
    f: impl Fn(usize, &[u32], &mut [T]) -> R + Sync,
) -> Vec<R> {
    let ns = slab_count(n);
    let mut out = Vec::new();
    for colour in 0..2 {
        let mut tasks: Vec<(usize, &[u32], &mut [T])> = Vec::new();
        let mut rest: &mut [T] = &mut *nodes;
        let mut rest_lo = 0usize;
        for s in (colour..ns).step_by(2) {
            let ids = &order[starts[s] as usize..starts[s + 1] as usize];
            let (lo, hi) = slab_layers(s, n);
            let tail = std::mem::take(&mut rest);
            let (_, tail) = tail.split_at_mut((lo - rest_lo) * layer);
            let (mine, tail) = tail.split_at_mut((hi - lo) * layer);
            rest = tail;
            rest_lo = hi;
            if !ids.is_empty() {
                tasks.push((lo, ids, mine));
            }
        }
        let results: Vec<R> = if seq {
            tasks
                .into_iter()
                .map(|(lo, ids, slab)| f(lo, ids, slab))
                .collect()
        } else {
            tasks
                .into_par_iter()
                .map(|(lo, ids, slab)| f(lo, ids, slab))
                .collect()
        };
        out.extend(results);
    }
    out
}
