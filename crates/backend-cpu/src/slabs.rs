//! Conflict-free parallel scatters: particles grouped by slabs of [`SLAB`] node layers along x
//! (a stable counting sort); a slab's particles write only to `SLAB + 2` contiguous layers of
//! the x-major grid, so even slabs run in parallel on disjoint `&mut` sub-slices, then odd
//! slabs. The summation order of every node is fixed by the scheme (deterministic for any
//! thread count).

use r4d_mpm::kernels::{blocks_per_axis, BLOCK};
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

/// Stable counting sort of particles by the slab of their stencil's base x layer. `keys[i]`
/// is particle `i`'s base node index `(x n + y) n + z` on the `n^3` grid, `u32::MAX` for a
/// particle left out. `order` (one entry per particle) receives the ids, `starts`
/// (`slab_count(n) + 1` entries) the slab boundaries in `order`.
pub fn sort_by_slab(keys: &[u32], n: usize, order: &mut [u32], starts: &mut [u32]) {
    let ns = slab_count(n);
    let layer = (n * n) as u32;
    starts.fill(0);
    for &k in keys.iter().filter(|&&k| k != u32::MAX) {
        starts[(k / layer) as usize / SLAB + 1] += 1;
    }
    for s in 0..ns {
        starts[s + 1] += starts[s];
    }
    // `starts[s]` is slab s's fill position until the pass below, which leaves it at slab s's
    // end, i.e. at the start of slab s + 1; shifting back restores the starts.
    for (i, &k) in keys.iter().enumerate() {
        if k != u32::MAX {
            let s = (k / layer) as usize / SLAB;
            order[starts[s] as usize] = i as u32;
            starts[s] += 1;
        }
    }
    for s in (1..=ns).rev() {
        starts[s] = starts[s - 1];
    }
    starts[0] = 0;
}

/// One slab's work: its first node layer, its particles, its nodes and its outputs.
type SlabTask<'a, T, O> = (usize, &'a [u32], &'a mut [T], &'a mut [O]);

/// Runs `f(x_lo, ids, slab_nodes, slab_out)` for every non-empty slab, even slabs in
/// parallel, then odd ones (all on the calling thread when `seq`). `nodes` is the x-major
/// grid with `layer` entries per x layer; `slab_nodes` starts at layer `x_lo`. `out` is empty
/// (no per-particle results: every `slab_out` is empty) or has one entry per sorted particle
/// (`starts`' last entry), in `order`'s order: `slab_out[j]` belongs to `ids[j]`.
#[allow(clippy::too_many_arguments)]
pub fn scatter_by_slab<T: Send, O: Send>(
    seq: bool,
    nodes: &mut [T],
    layer: usize,
    n: usize,
    order: &[u32],
    starts: &[u32],
    out: &mut [O],
    f: impl Fn(usize, &[u32], &mut [T], &mut [O]) + Sync,
) {
    let ns = slab_count(n);
    let with_out = !out.is_empty();
    assert!(
        !with_out || out.len() == starts[ns] as usize,
        "scatter_by_slab: one output per sorted particle"
    );
    // Each colour hands out disjoint pieces of `nodes` and `out`; the second colour needs
    // the whole of both again, so split them per colour from reborrows.
    for colour in 0..2 {
        let mut tasks: Vec<SlabTask<'_, T, O>> = Vec::new();
        let mut rest: &mut [T] = &mut *nodes;
        let mut rest_lo = 0usize;
        let mut rest_out: &mut [O] = &mut *out;
        let mut out_lo = 0usize;
        for s in (colour..ns).step_by(2) {
            let (a, b) = (starts[s] as usize, starts[s + 1] as usize);
            let ids = &order[a..b];
            let (lo, hi) = slab_layers(s, n);
            let tail = std::mem::take(&mut rest);
            let (_, tail) = tail.split_at_mut((lo - rest_lo) * layer);
            let (mine, tail) = tail.split_at_mut((hi - lo) * layer);
            rest = tail;
            rest_lo = hi;
            let mine_out = if with_out {
                let tail = std::mem::take(&mut rest_out);
                let (_, tail) = tail.split_at_mut(a - out_lo);
                let (m, tail) = tail.split_at_mut(b - a);
                rest_out = tail;
                out_lo = b;
                m
            } else {
                &mut []
            };
            if !ids.is_empty() {
                tasks.push((lo, ids, mine, mine_out));
            }
        }
        if seq {
            tasks
                .into_iter()
                .for_each(|(lo, ids, slab, o)| f(lo, ids, slab, o));
        } else {
            tasks
                .into_par_iter()
                .for_each(|(lo, ids, slab, o)| f(lo, ids, slab, o));
        }
    }
}

/// Flags the blocks of [`BLOCK`]^3 nodes that the stencils of the particles touch
/// (`active[(ix nb + iy) nb + iz]`, 1 or 0), one x row of blocks per task (in parallel unless
/// `seq`): a row reads the particles of the slabs whose stencils can reach it (`order` and
/// `starts` from [`sort_by_slab`] of `keys`) and writes only its own flags.
pub fn mark_active_blocks(
    seq: bool,
    keys: &[u32],
    order: &[u32],
    starts: &[u32],
    n: usize,
    active: &mut [u32],
) {
    let nb = blocks_per_axis(n);
    let row = |(ix, flags): (usize, &mut [u32])| {
        flags.fill(0);
        // Stencil bases bx with bx / BLOCK <= ix <= (bx + 2) / BLOCK.
        let (x0, x1) = (
            (ix * BLOCK).saturating_sub(2),
            (ix * BLOCK + BLOCK - 1).min(n - 1),
        );
        let (s0, s1) = (x0 / SLAB, (x1 / SLAB).min(starts.len() - 2));
        let ids = &order[starts[s0] as usize..starts[s1 + 1] as usize];
        for &i in ids {
            let k = keys[i as usize] as usize;
            let (bx, by, bz) = (k / (n * n), (k / n) % n, k % n);
            if bx < x0 || bx > x1 {
                continue;
            }
            for iy in by / BLOCK..=(by + 2) / BLOCK {
                for iz in bz / BLOCK..=(bz + 2) / BLOCK {
                    flags[iy * nb + iz] = 1;
                }
            }
        }
    };
    if seq {
        active.chunks_mut(nb * nb).enumerate().for_each(row);
    } else {
        active.par_chunks_mut(nb * nb).enumerate().for_each(row);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn active_blocks_are_those_the_stencils_touch() {
        // Few particles on large grids, so that most blocks stay inactive and a missed or
        // extra flag shows.
        for (n, count, seed) in [
            (9, 3, 1u32),
            (16, 6, 2),
            (21, 10, 3),
            (33, 12, 4),
            (64, 40, 5),
        ] {
            let nb = blocks_per_axis(n);
            // Stencil bases inside the grid (0..=n-3 per axis), some particles left out.
            let m = (n - 2) as u32;
            let keys: Vec<u32> = (0..count)
                .map(|i| {
                    let h = (i + 1000 * seed).wrapping_mul(2654435761);
                    if h % 17 == 0 {
                        return u32::MAX;
                    }
                    let (x, y, z) = ((h >> 3) % m, (h >> 11) % m, (h >> 19) % m);
                    (x * n as u32 + y) * n as u32 + z
                })
                .collect();
            let mut order = vec![0; keys.len()];
            let mut starts = vec![0; slab_count(n) + 1];
            sort_by_slab(&keys, n, &mut order, &mut starts);
            let mut want = vec![0u32; nb * nb * nb];
            for &k in keys.iter().filter(|&&k| k != u32::MAX) {
                let k = k as usize;
                let (bx, by, bz) = (k / (n * n), (k / n) % n, k % n);
                for ix in bx / BLOCK..=(bx + 2) / BLOCK {
                    for iy in by / BLOCK..=(by + 2) / BLOCK {
                        for iz in bz / BLOCK..=(bz + 2) / BLOCK {
                            want[(ix * nb + iy) * nb + iz] = 1;
                        }
                    }
                }
            }
            for seq in [true, false] {
                let mut active = vec![7u32; nb * nb * nb];
                mark_active_blocks(seq, &keys, &order, &starts, n, &mut active);
                assert_eq!(active, want, "n = {n}, seq = {seq}");
            }
        }
    }

    #[test]
    fn sort_by_slab_is_a_stable_sort_by_slab_leaving_out_the_marked() {
        let n = 9;
        let layer = (n * n) as u32;
        let mut keys: Vec<u32> = (0..200u32)
            .map(|i| (i.wrapping_mul(2654435761) >> 7) % (n as u32 * layer))
            .collect();
        keys[3] = u32::MAX;
        keys[150] = u32::MAX;
        let mut order = vec![0; keys.len()];
        let mut starts = vec![7; slab_count(n) + 1];
        sort_by_slab(&keys, n, &mut order, &mut starts);
        let mut want: Vec<u32> = (0..keys.len() as u32)
            .filter(|&i| keys[i as usize] != u32::MAX)
            .collect();
        want.sort_by_key(|&i| keys[i as usize] / layer / SLAB as u32);
        assert_eq!(starts[0], 0);
        assert_eq!(*starts.last().unwrap() as usize, want.len());
        assert_eq!(&order[..want.len()], &want[..]);
        for s in 0..slab_count(n) {
            for &i in &order[starts[s] as usize..starts[s + 1] as usize] {
                assert_eq!((keys[i as usize] / layer) as usize / SLAB, s);
            }
        }
    }
}
