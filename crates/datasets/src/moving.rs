//! The moving-part rules: which Gaussians or particles a `moving_part_points.ply` selects.
//!
//! * PhysFlow (`find_far_points` in `utils/decode_param.py`): a Gaussian farther than
//!   `threshold` (`0.5 / n_grid`; `1.0 / n_grid` for scenes whose path contains "playdoh") from
//!   every moving-part point, in the **world** frame, is not simulated (it stays in the scene as
//!   static background). "Farther" is strict: `min distance > threshold`.
//! * PhysDreamer (`apply_grid_bc_w_freeze_pts`): in the normalised simulation box, a particle
//!   farther than `0.5 / n_grid` from every moving-part point is *frozen*: the grid node at
//!   the lower corner of its cell (`floor(x / dx)`) gets zero velocity in every substep.
//!   [`freeze_boxes`] turns those nodes into axis-aligned boxes of nodes, applied as zero-velocity
//!   cuboid conditions, which clamp exactly the same nodes.

use kiddo::{ImmutableKdTree, SquaredEuclidean};

/// For each query point, whether it lies within `threshold` of some reference point
/// (`min distance <= threshold`). Empty references select nothing.
pub fn within(queries: &[[f64; 3]], refs: &[[f64; 3]], threshold: f64) -> Vec<bool> {
    if refs.is_empty() {
        return vec![false; queries.len()];
    }
    let tree: ImmutableKdTree<f64, 3> = ImmutableKdTree::new_from_slice(refs);
    let t2 = threshold * threshold;
    // A radius-bounded search prunes far queries at once (an unbounded nearest-neighbour
    // search from a point far from the moving part visits much of the tree); the radius is
    // padded so the `<=` test below decides ties.
    let one = std::num::NonZero::new(1).expect("1 > 0");
    queries
        .iter()
        .map(|q| {
            tree.nearest_n_within::<SquaredEuclidean>(q, t2 * (1.0 + 1e-9), one, true)
                .first()
                .is_some_and(|n| n.distance <= t2)
        })
        .collect()
}

/// Merges grid nodes `(i, j, k)` into disjoint axis-aligned boxes of nodes, `[lo, hi]`
/// inclusive, covering exactly the given set: runs along k, merged along j where the runs
/// match, then along i where the rectangles match. Work is proportional to the number of
/// nodes (only occupied rows are visited).
pub fn freeze_boxes(nodes: &[[u32; 3]]) -> Vec<([u32; 3], [u32; 3])> {
    use std::collections::{BTreeMap, BTreeSet};
    type Rect = (u32, u32, u32, u32); // (j0, j1, k0, k1)
    let set: BTreeSet<[u32; 3]> = nodes.iter().copied().collect();
    // Runs along k per (i, j).
    let mut runs: BTreeMap<(u32, u32), Vec<(u32, u32)>> = BTreeMap::new();
    let mut iter = set.iter().peekable();
    while let Some(&[i, j, k0]) = iter.next() {
        let mut k1 = k0;
        while let Some(&&[i2, j2, k2]) = iter.peek() {
            if i2 == i && j2 == j && Some(k2) == k1.checked_add(1) {
                k1 = k2;
                iter.next();
            } else {
                break;
            }
        }
        runs.entry((i, j)).or_default().push((k0, k1));
    }
    // Rectangles in (j, k) per i: equal runs of consecutive j merge.
    let mut rects: BTreeMap<u32, Vec<Rect>> = BTreeMap::new();
    let mut open: Vec<Rect> = Vec::new();
    let mut cur_i = None;
    for (&(i, j), row) in &runs {
        if cur_i != Some(i) {
            if let Some(ci) = cur_i {
                rects.entry(ci).or_default().append(&mut open);
            }
            cur_i = Some(i);
        }
        let mut next_open = Vec::new();
        for &(k0, k1) in row {
            match open
                .iter()
                .position(|r| Some(j) == r.1.checked_add(1) && r.2 == k0 && r.3 == k1)
            {
                Some(p) => {
                    let r = open.swap_remove(p);
                    next_open.push((r.0, j, k0, k1));
                }
                None => next_open.push((j, j, k0, k1)),
            }
        }
        rects.entry(i).or_default().append(&mut open);
        open = next_open;
    }
    if let Some(ci) = cur_i {
        rects.entry(ci).or_default().append(&mut open);
    }
    // Boxes: equal rectangles of consecutive i merge.
    let mut boxes = Vec::new();
    let mut open: Vec<(u32, Rect, u32)> = Vec::new(); // (i0, rect, i1)
    for (&i, here) in &rects {
        let mut next_open = Vec::new();
        for &r in here {
            match open
                .iter()
                .position(|o| o.1 == r && Some(i) == o.2.checked_add(1))
            {
                Some(p) => {
                    let mut o = open.swap_remove(p);
                    o.2 = i;
                    next_open.push(o);
                }
                None => next_open.push((i, r, i)),
            }
        }
        for (i0, r, i1) in open.drain(..) {
            boxes.push(([i0, r.0, r.2], [i1, r.1, r.3]));
        }
        open = next_open;
    }
    for (i0, r, i1) in open {
        boxes.push(([i0, r.0, r.2], [i1, r.1, r.3]));
    }
    boxes
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn within_is_inclusive_at_the_threshold() {
        let refs = [[0.0, 0.0, 0.0]];
        let q = [[0.5, 0.0, 0.0], [0.5000001, 0.0, 0.0], [0.0, 0.3, 0.4]];
        assert_eq!(within(&q, &refs, 0.5), vec![true, false, true]);
        assert_eq!(within(&q, &[], 0.5), vec![false; 3]);
    }

    #[test]
    fn boxes_cover_exactly_the_nodes() {
        let mut rng = 0x1234_5678u64;
        let mut next = || {
            rng = rng
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (rng >> 33) as u32
        };
        let mut nodes = Vec::new();
        // A solid block plus random nodes.
        for i in 2..5 {
            for j in 1..6 {
                for k in 3..8 {
                    nodes.push([i, j, k]);
                }
            }
        }
        for _ in 0..60 {
            nodes.push([next() % 9, next() % 9, next() % 9]);
        }
        let boxes = freeze_boxes(&nodes);
        let set: std::collections::BTreeSet<[u32; 3]> = nodes.iter().copied().collect();
        let mut covered = std::collections::BTreeSet::new();
        for (lo, hi) in &boxes {
            for i in lo[0]..=hi[0] {
                for j in lo[1]..=hi[1] {
                    for k in lo[2]..=hi[2] {
                        assert!(
                            covered.insert([i, j, k]),
                            "boxes overlap at {:?}",
                            [i, j, k]
                        );
                    }
                }
            }
        }
        assert_eq!(covered, set);
        assert!(
            boxes.len() < set.len() / 2,
            "{} boxes for {} nodes",
            boxes.len(),
            set.len()
        );
    }
}
