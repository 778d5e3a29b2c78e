//! [`crate::transfer::gather`] and [`crate::transfer::scatter`] of two `f32` particles at once
//! in 256-bit vectors (x86-64 AVX, detected at run time by the caller).
//!
//! Every node entry `[velocity or momentum (3), mass]` of the two particles sits in one 8-lane
//! vector (`[first particle (4), second particle (4)]`) and every weight is repeated over its
//! particle's four lanes, so each instruction advances both particles. The operations and
//! their order per lane are exactly those of the one-particle functions (no fused
//! multiply-add), and the scatter adds the first particle's node shares before the second's,
//! so every result is bitwise the one-particle result; the tests check it on random stencils in
//! both force forms, with shared nodes.

use crate::kernels::{StepConsts, FORCE_MLS};
use crate::transfer::{k, Gathered, Stencil};
use std::arch::x86_64::*;

/// Whether this processor runs [`gather_pair`] (AVX, detected at run time).
#[inline]
pub fn available() -> bool {
    std::is_x86_feature_detected!("avx")
}

/// [`crate::transfer::gather`] of the two particles of stencils `st` (both wholly inside the
/// grid `nodes` of `n^3` nodes), bitwise.
///
/// # Safety
/// The processor must support AVX ([`available`]).
///
/// # Panics
/// When a stencil reaches outside `nodes`.
#[target_feature(enable = "avx")]
pub unsafe fn gather_pair(
    nodes: &[[f32; 4]],
    n: usize,
    st: &[Stencil<f32>; 2],
    c: &StepConsts,
) -> [Gathered<f32>; 2] {
    if c.force_form == FORCE_MLS {
        gather_pair_form::<true>(nodes, n, st, c)
    } else {
        gather_pair_form::<false>(nodes, n, st, c)
    }
}

/// `a` in the first particle's lanes, `b` in the second's.
#[inline(always)]
unsafe fn pair(a: f32, b: f32) -> __m256 {
    _mm256_setr_m128(_mm_set1_ps(a), _mm_set1_ps(b))
}

/// `k x + y` (a product then a sum, rounded separately as in the scalar code).
#[inline(always)]
unsafe fn mul_add(k: __m256, x: __m256, y: __m256) -> __m256 {
    _mm256_add_ps(_mm256_mul_ps(k, x), y)
}

/// Index of the first node of a particle's stencil column `(i, j)`.
#[inline(always)]
fn column_start(s: &Stencil<f32>, n: usize, i: usize, j: usize) -> usize {
    ((s.base[0] as usize + i) * n + s.base[1] as usize + j) * n + s.base[2] as usize
}

#[inline(always)]
unsafe fn gather_pair_form<const MLS: bool>(
    nodes: &[[f32; 4]],
    n: usize,
    st: &[Stencil<f32>; 2],
    c: &StepConsts,
) -> [Gathered<f32>; 2] {
    // Every node read below lies between a stencil's first and last node: check those once.
    for s in st {
        assert!(
            s.base.iter().all(|&b| b >= 0) && column_start(s, n, 2, 2) + 2 < nodes.len(),
            "gather_pair: a stencil reaches outside the grid"
        );
    }
    let ptr = nodes.as_ptr() as *const f32;
    let z = _mm256_setzero_ps();
    // Per axis and node offset: the weights, their derivatives and the node offsets from the
    // particle (in cells), one particle per half.
    let (mut w, mut d, mut dp) = ([[z; 3]; 3], [[z; 3]; 3], [[z; 3]; 3]);
    for a in 0..3 {
        for o in 0..3 {
            w[a][o] = pair(st[0].w[a][o], st[1].w[a][o]);
            dp[a][o] = pair(o as f32 - st[0].fx[a], o as f32 - st[1].fx[a]);
            if !MLS {
                d[a][o] = pair(st[0].dw[a][o], st[1].dw[a][o]);
            }
        }
    }
    let mut v = z;
    let mut m = [z; 3];
    let mut g = [z; 3];
    for i in 0..3 {
        // Layer sums: t[0] = sum w1 w2 v, t[1] = sum w1 d1 w2 v, t[2] = sum w1 w2 d2 v and,
        // in the classic form, t[3] = sum dw1 w2 v, t[4] = sum w1 dw2 v.
        let mut t = [z; 5];
        for j in 0..3 {
            let (a, b) = (column_start(&st[0], n, i, j), column_start(&st[1], n, i, j));
            // SAFETY: `a + 2` and `b + 2` are at most the checked last nodes.
            let node = |o: usize| _mm256_loadu2_m128(ptr.add(4 * (b + o)), ptr.add(4 * (a + o)));
            let cell = [node(0), node(1), node(2)];
            let p0 = _mm256_mul_ps(w[2][0], cell[0]);
            let p1 = _mm256_mul_ps(w[2][1], cell[1]);
            let p2 = _mm256_mul_ps(w[2][2], cell[2]);
            let s0 = _mm256_add_ps(_mm256_add_ps(p0, p1), p2);
            let s1 = _mm256_add_ps(
                _mm256_add_ps(_mm256_mul_ps(dp[2][0], p0), _mm256_mul_ps(dp[2][1], p1)),
                _mm256_mul_ps(dp[2][2], p2),
            );
            let q = _mm256_mul_ps(w[1][j], s0);
            t[0] = _mm256_add_ps(t[0], q);
            t[1] = mul_add(dp[1][j], q, t[1]);
            t[2] = mul_add(w[1][j], s1, t[2]);
            if !MLS {
                let s2 = _mm256_add_ps(
                    _mm256_add_ps(
                        _mm256_mul_ps(d[2][0], cell[0]),
                        _mm256_mul_ps(d[2][1], cell[1]),
                    ),
                    _mm256_mul_ps(d[2][2], cell[2]),
                );
                t[3] = mul_add(d[1][j], s0, t[3]);
                t[4] = mul_add(w[1][j], s2, t[4]);
            }
        }
        let r = _mm256_mul_ps(w[0][i], t[0]);
        v = _mm256_add_ps(v, r);
        m[0] = mul_add(dp[0][i], r, m[0]);
        m[1] = mul_add(w[0][i], t[1], m[1]);
        m[2] = mul_add(w[0][i], t[2], m[2]);
        if !MLS {
            g[0] = mul_add(d[0][i], t[0], g[0]);
            g[1] = mul_add(w[0][i], t[3], g[1]);
            g[2] = mul_add(w[0][i], t[4], g[2]);
        }
    }
    let lanes = |x: __m256| -> [f32; 8] {
        let mut r = [0.0; 8];
        _mm256_storeu_ps(r.as_mut_ptr(), x);
        r
    };
    let (v, m, g) = (lanes(v), m.map(&lanes), g.map(&lanes));
    let inv_dx = k::<f32>(c.inv_dx);
    let kc = 4.0f32 * inv_dx;
    std::array::from_fn(|p| {
        let b = 4 * p;
        let cm: [f32; 9] = std::array::from_fn(|e| m[e % 3][b + e / 3] * kc);
        let gv = if MLS {
            cm
        } else {
            std::array::from_fn(|e| g[e % 3][b + e / 3] * inv_dx)
        };
        Gathered {
            v: [v[b], v[b + 1], v[b + 2]],
            c: cm,
            grad_v: gv,
        }
    })
}

/// [`crate::transfer::scatter`] of two `f32` particles (stencils `st`, velocities `v`, damped
/// APIC matrices `cm`, masses `mass`, stress terms `s`) into `nodes`, a slab of the grid that
/// starts at node layer `x_lo`: both particles' node shares are computed side by side, then
/// added to the nodes, the first particle's before the second's, so every node receives
/// bitwise the sums of two one-particle scatters in order.
///
/// # Safety
/// The processor must support AVX ([`available`]).
///
/// # Panics
/// When a stencil reaches outside the slab.
#[allow(clippy::too_many_arguments)]
#[target_feature(enable = "avx")]
pub unsafe fn scatter_pair(
    nodes: &mut [[f32; 4]],
    x_lo: usize,
    n: usize,
    st: &[Stencil<f32>; 2],
    v: [[f32; 3]; 2],
    cm: [&[f32; 9]; 2],
    mass: [f32; 2],
    s: [&[f32; 9]; 2],
    c: &StepConsts,
) {
    if c.force_form == FORCE_MLS {
        scatter_pair_form::<true>(nodes, x_lo, n, st, v, cm, mass, s, c)
    } else {
        scatter_pair_form::<false>(nodes, x_lo, n, st, v, cm, mass, s, c)
    }
}

/// Index in a slab starting at layer `x_lo` of the first node of a stencil column `(i, j)`.
#[inline(always)]
fn slab_column_start(s: &Stencil<f32>, x_lo: usize, n: usize, i: usize, j: usize) -> usize {
    ((s.base[0] as usize + i - x_lo) * n + s.base[1] as usize + j) * n + s.base[2] as usize
}

#[allow(clippy::too_many_arguments)]
#[inline(always)]
unsafe fn scatter_pair_form<const MLS: bool>(
    nodes: &mut [[f32; 4]],
    x_lo: usize,
    n: usize,
    st: &[Stencil<f32>; 2],
    v: [[f32; 3]; 2],
    cm: [&[f32; 9]; 2],
    mass: [f32; 2],
    s: [&[f32; 9]; 2],
    c: &StepConsts,
) {
    for t in st {
        assert!(
            t.base.iter().all(|&b| b >= 0)
                && t.base[0] as usize >= x_lo
                && slab_column_start(t, x_lo, n, 2, 2) + 2 < nodes.len(),
            "scatter_pair: a stencil reaches outside the slab"
        );
    }
    let dx = k::<f32>(c.dx);
    // The particle terms of `transfer::scatter`: P = [m v, m], Q_a = column a of m C (plus the
    // stress term in the MLS form), S_a = column a of the stress term.
    let terms = |p: usize| {
        let mut mc = [0.0f32; 9];
        for e in 0..9 {
            mc[e] = mass[p] * cm[p][e];
        }
        if MLS {
            for e in 0..9 {
                mc[e] += s[p][e];
            }
        }
        let col = |m: &[f32; 9], a: usize| [m[a], m[3 + a], m[6 + a], 0.0];
        let pv = [
            mass[p] * v[p][0],
            mass[p] * v[p][1],
            mass[p] * v[p][2],
            mass[p],
        ];
        (
            pv,
            [col(&mc, 0), col(&mc, 1), col(&mc, 2)],
            [col(s[p], 0), col(s[p], 1), col(s[p], 2)],
        )
    };
    let (ta, tb) = (terms(0), terms(1));
    let join = |a: &[f32; 4], b: &[f32; 4]| {
        _mm256_setr_m128(_mm_loadu_ps(a.as_ptr()), _mm_loadu_ps(b.as_ptr()))
    };
    let p = join(&ta.0, &tb.0);
    let q: [__m256; 3] = std::array::from_fn(|a| join(&ta.1[a], &tb.1[a]));
    let sc: [__m256; 3] = std::array::from_fn(|a| join(&ta.2[a], &tb.2[a]));
    let z = _mm256_setzero_ps();
    let (mut w, mut d, mut dp) = ([[z; 3]; 3], [[z; 3]; 3], [[z; 3]; 3]);
    for a in 0..3 {
        for o in 0..3 {
            w[a][o] = pair(st[0].w[a][o], st[1].w[a][o]);
            dp[a][o] = pair((o as f32 - st[0].fx[a]) * dx, (o as f32 - st[1].fx[a]) * dx);
            if !MLS {
                d[a][o] = pair(st[0].dw[a][o], st[1].dw[a][o]);
            }
        }
    }
    // The 27 node shares of both particles, in stencil order.
    let mut share = [z; 27];
    for i in 0..3 {
        let mut ai = _mm256_mul_ps(w[0][i], mul_add(dp[0][i], q[0], p));
        let bi = _mm256_mul_ps(w[0][i], q[1]);
        let ci = _mm256_mul_ps(w[0][i], q[2]);
        let (mut ei, mut fi) = (z, z);
        if !MLS {
            ai = mul_add(d[0][i], sc[0], ai);
            ei = _mm256_mul_ps(w[0][i], sc[1]);
            fi = _mm256_mul_ps(w[0][i], sc[2]);
        }
        for j in 0..3 {
            let mut aij = _mm256_mul_ps(w[1][j], mul_add(dp[1][j], bi, ai));
            let cij = _mm256_mul_ps(w[1][j], ci);
            let mut dij = z;
            if !MLS {
                aij = mul_add(d[1][j], ei, aij);
                dij = _mm256_mul_ps(w[1][j], fi);
            }
            for o in 0..3 {
                let wk = w[2][o];
                let wdk = _mm256_mul_ps(w[2][o], dp[2][o]);
                let mut add = _mm256_add_ps(_mm256_mul_ps(wk, aij), _mm256_mul_ps(wdk, cij));
                if !MLS {
                    add = _mm256_add_ps(add, _mm256_mul_ps(d[2][o], dij));
                }
                share[(i * 3 + j) * 3 + o] = add;
            }
        }
    }
    let ptr = nodes.as_mut_ptr() as *mut f32;
    for (half, t) in st.iter().enumerate() {
        for i in 0..3 {
            for j in 0..3 {
                let first = slab_column_start(t, x_lo, n, i, j);
                for o in 0..3 {
                    let sh = share[(i * 3 + j) * 3 + o];
                    let part = if half == 0 {
                        _mm256_castps256_ps128(sh)
                    } else {
                        _mm256_extractf128_ps::<1>(sh)
                    };
                    // SAFETY: at most the checked last node of the stencil.
                    let node = ptr.add(4 * (first + o));
                    _mm_storeu_ps(node, _mm_add_ps(_mm_loadu_ps(node), part));
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::kernels::FORCE_CLASSIC;
    use crate::transfer::{gather, scatter, stencil};

    /// A small deterministic generator of values in [0, 1).
    struct Lcg(u64);
    impl Lcg {
        fn next(&mut self) -> f32 {
            self.0 = self
                .0
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (self.0 >> 40) as f32 / (1u64 << 24) as f32
        }
    }

    fn consts(n: usize, force: u32) -> StepConsts {
        StepConsts {
            gravity: [0.0, 0.0, -9.8],
            dt: 1e-4,
            dx: 1.0 / n as f32,
            inv_dx: n as f32,
            n_grid: n as u32,
            substep: 0,
            time: 0.0,
            rpic_damping: 0.0,
            grid_v_damping: 1.0,
            force_form: force,
            n_grid_bcs: 0,
            n_particle_bcs: 0,
            out_of_domain: 0,
            max_speed: 1e9,
        }
    }

    #[test]
    fn pair_scatters_are_bitwise_two_one_particle_scatters() {
        if !available() {
            eprintln!("skipped: no AVX");
            return;
        }
        const N: usize = 10;
        let mut r = Lcg(11);
        for force in [FORCE_MLS, FORCE_CLASSIC] {
            let c = consts(N, force);
            for round in 0..500 {
                // A slab of layers x_lo..N; the second particle near the first (shared nodes)
                // in half of the rounds.
                let x_lo = round % 3;
                let len = (N - x_lo) * N * N;
                let start: Vec<[f32; 4]> = (0..len)
                    .map(|_| std::array::from_fn(|_| r.next() - 0.5))
                    .collect();
                let lo = (x_lo as f32 + 0.5) / N as f32;
                let span = (N as f32 - 2.0 - x_lo as f32) / N as f32;
                let xa: [f32; 3] = std::array::from_fn(
                    |a| if a == 0 { lo } else { 0.5 / N as f32 } + r.next() * span,
                );
                let xb: [f32; 3] = if round % 2 == 0 {
                    std::array::from_fn(|a| {
                        let lo_a = if a == 0 { lo } else { 0.5 / N as f32 };
                        (xa[a] + (r.next() - 0.5) * 1.5 / N as f32).clamp(lo_a, lo_a + span * 0.999)
                    })
                } else {
                    std::array::from_fn(
                        |a| if a == 0 { lo } else { 0.5 / N as f32 } + r.next() * span,
                    )
                };
                let st = [stencil(xa, c.inv_dx), stencil(xb, c.inv_dx)];
                let mut big =
                    |s: f32| s * 10f32.powi((r.next() * 6.0) as i32 - 3) * (r.next() - 0.5);
                let v = [
                    [big(1.0), big(1.0), big(1.0)],
                    [big(1.0), big(1.0), big(1.0)],
                ];
                let cm: [[f32; 9]; 2] = std::array::from_fn(|_| std::array::from_fn(|_| big(1.0)));
                let s: [[f32; 9]; 2] = std::array::from_fn(|_| std::array::from_fn(|_| big(1e-3)));
                let mass = [r.next() + 0.1, r.next() + 0.1];
                let mut one = start.clone();
                for p in 0..2 {
                    scatter(&mut one, x_lo, N, &st[p], v[p], &cm[p], mass[p], &s[p], &c);
                }
                let mut two = start.clone();
                // SAFETY: AVX is available (checked above).
                unsafe {
                    scatter_pair(
                        &mut two,
                        x_lo,
                        N,
                        &st,
                        v,
                        [&cm[0], &cm[1]],
                        mass,
                        [&s[0], &s[1]],
                        &c,
                    )
                };
                let bits =
                    |g: &[[f32; 4]]| g.iter().flatten().map(|e| e.to_bits()).collect::<Vec<_>>();
                assert!(
                    bits(&one) == bits(&two),
                    "force form {force}, round {round}"
                );
            }
        }
    }

    #[test]
    fn pairs_are_bitwise_the_one_particle_gather() {
        if !available() {
            eprintln!("skipped: no AVX");
            return;
        }
        const N: usize = 12;
        let mut r = Lcg(7);
        // Velocities of mixed magnitudes and signs, so that roundings differ between orders.
        let nodes: Vec<[f32; 4]> = (0..N * N * N)
            .map(|_| {
                let s = 10f32.powi((r.next() * 6.0) as i32 - 3);
                [
                    s * (r.next() - 0.5),
                    s * (r.next() - 0.5),
                    r.next() - 0.5,
                    r.next(),
                ]
            })
            .collect();
        for force in [FORCE_MLS, FORCE_CLASSIC] {
            let c = consts(N, force);
            for _ in 0..2000 {
                // Positions whose stencils lie inside the grid ([0.5, N - 1.5) cells).
                let mut x =
                    || std::array::from_fn(|_| (0.5 + r.next() * (N as f32 - 2.0)) / N as f32);
                let st = [stencil(x(), c.inv_dx), stencil(x(), c.inv_dx)];
                // SAFETY: AVX is available (checked above).
                let pair = unsafe { gather_pair(&nodes, N, &st, &c) };
                for (s, p) in st.iter().zip(&pair) {
                    let one = gather(&nodes, N, s, &c);
                    let bits = |g: &Gathered<f32>| {
                        g.v.iter()
                            .chain(&g.c)
                            .chain(&g.grad_v)
                            .map(|e| e.to_bits())
                            .collect::<Vec<_>>()
                    };
                    assert_eq!(bits(p), bits(&one), "force form {force}, stencil {s:?}");
                }
            }
        }
    }
}
