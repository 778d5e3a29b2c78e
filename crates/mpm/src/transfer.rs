//! Per-particle and per-node functions of a substep: B-spline stencil, particle boundary
//! conditions, the particle stress stage, scatter (P2G), grid node update and gather (G2P).
//!
//! These are the one source of truth for the substep math. [`crate::reference`] calls them in
//! plain loops; the CPU backend calls the same functions and adds only scheduling (particle
//! ordering, parallel slabs, active blocks). A GPU backend's shaders mirror them and are tested
//! against the reference. Everything is generic over [`Real`]: `f32` for the simulation, `f64`
//! for finite-difference checks of the adjoints. Device constants ([`StepConsts`], boundary
//! conditions) stay `f32` and are converted with [`k`]; time windows and node positions are
//! compared in `f32`, as the kernels do.
//!
//! Grid layout: node `(i, j, k)` sits at `(i dx, j dx, k dx)` and is stored at index
//! `(i n + j) n + k` as `[momentum or velocity (3), mass]`.

use crate::boundary::{BC_BOUNDING_BOX, BC_CUBOID, BC_SURFACE, PBC_IMPULSE, PBC_VELOCITY};
use crate::constitutive::stress_update_with_svd;
use crate::kernels::{
    GridBc, Health, ParticleBc, StepConsts, FORCE_MLS, HEALTH_NAN, HEALTH_OUT_OF_DOMAIN,
    HEALTH_SPEED, OUT_OF_DOMAIN_CLAMP,
};
use crate::material::PartConsts;
use crate::math::{svd3, Mat3, Real, Svd3};
use crate::params::{material_of, MAT_CONSTS};

/// A device constant (stored as f32) in the kernel's scalar type.
#[inline(always)]
pub fn k<T: Real>(x: f32) -> T {
    T::c(x as f64)
}

/// Quadratic B-spline stencil of a particle: base node and per-axis weights.
#[derive(Clone, Copy, Debug)]
pub struct Stencil<T> {
    /// Lowest node index per axis (`int(x / dx - 0.5)`).
    pub base: [i32; 3],
    /// Fractional position `x / dx - base`, in [0.5, 1.5).
    pub fx: [T; 3],
    /// Weights of nodes `base + 0..3` per axis.
    pub w: [[T; 3]; 3],
    /// Derivatives of the weights with respect to `x / dx`.
    pub dw: [[T; 3]; 3],
}

/// The stencil of a particle at `x` (PhysGaussian's convention: truncation toward zero).
#[inline(always)]
pub fn stencil<T: Real>(x: [T; 3], inv_dx: T) -> Stencil<T> {
    let z = T::zero();
    let mut s = Stencil {
        base: [0; 3],
        fx: [z; 3],
        w: [[z; 3]; 3],
        dw: [[z; 3]; 3],
    };
    let (half, one, c15, c075, two) = (T::c(0.5), T::one(), T::c(1.5), T::c(0.75), T::c(2.0));
    for a in 0..3 {
        let g = x[a] * inv_dx;
        let b = (g - half).to_i32().unwrap_or(i32::MIN);
        let f = g - T::c(b as f64);
        s.base[a] = b;
        s.fx[a] = f;
        s.w[a] = [
            half * (c15 - f) * (c15 - f),
            c075 - (f - one) * (f - one),
            half * (f - half) * (f - half),
        ];
        s.dw[a] = [f - c15, -two * (f - one), f - half];
    }
    s
}

/// True when the whole 27-node stencil of `x` lies on the grid (`x / dx` in
/// `[0.5, n - 1.5)` on every axis) and `x` is finite.
#[inline(always)]
pub fn in_domain<T: Real>(x: [T; 3], inv_dx: T, n: usize) -> bool {
    let (lo, hi) = (T::c(0.5), T::c(n as f64 - 1.5));
    x.iter().all(|&xa| {
        let g = xa * inv_dx;
        g.is_finite() && g >= lo && g < hi
    })
}

/// The coordinate (m) of `x` that puts it outside the grid's interior: the first non-finite
/// one, else the one furthest outside `[0.5 dx, (n - 1.5) dx)`.
pub fn out_of_domain_coordinate<T: Real>(x: [T; 3], inv_dx: T, n: usize) -> f32 {
    let (lo, hi) = (0.5, n as f64 - 1.5);
    let mut worst = (f64::NEG_INFINITY, x[0]);
    for &xa in &x {
        let g = (xa * inv_dx).f64();
        if !g.is_finite() {
            return xa.f64() as f32;
        }
        let outside = (lo - g).max(g - hi);
        if outside > worst.0 {
            worst = (outside, xa);
        }
    }
    worst.1.f64() as f32
}

/// Whether a time window `[start, end)` contains `t` (compared in f32, as PhysGaussian does).
#[inline(always)]
fn active(start: f32, end: f32, t: f32) -> bool {
    start <= t && t < end
}

/// Whether a particle boundary condition acts on the particle with initial position `x0` in
/// this substep (selection by initial position, strict half extents, time window).
#[inline(always)]
pub fn particle_bc_applies(bc: &ParticleBc, x0: [f32; 3], c: &StepConsts) -> bool {
    active(bc.start, bc.end, c.time) && (0..3).all(|a| (x0[a] - bc.point[a]).abs() < bc.size[a])
}

/// Applies the particle boundary conditions (in order) to one particle's velocity.
#[inline]
pub fn particle_bcs<T: Real>(
    x0: [f32; 3],
    v: &mut [T; 3],
    mass: T,
    bcs: &[ParticleBc],
    c: &StepConsts,
) {
    for bc in bcs {
        if !particle_bc_applies(bc, x0, c) {
            continue;
        }
        match bc.kind {
            PBC_IMPULSE => {
                for a in 0..3 {
                    v[a] += k::<T>(bc.vector[a]) / mass * k(c.dt);
                }
            }
            PBC_VELOCITY => *v = bc.vector.map(k),
            _ => {}
        }
    }
}

/// The factor turning the Kirchhoff stress into the scatter's stress term: `-dt V0 / dx`
/// (classic form, multiplied by the weight gradient in units of `1 / dx`) or
/// `-dt V0 4 / dx^2` (MLS form, multiplied by `w dpos`).
#[inline(always)]
pub fn stress_scale<T: Real>(vol0: T, c: &StepConsts) -> T {
    let (dt, inv_dx) = (k::<T>(c.dt), k::<T>(c.inv_dx));
    if c.force_form == FORCE_MLS {
        -dt * vol0 * T::c(4.0) * inv_dx * inv_dx
    } else {
        -dt * vol0 * inv_dx
    }
}

/// The particle stage of P2G: return mapping and Kirchhoff stress.
///
/// Updates `f` from F_trial to F_elastic and `plastic` in place, and returns the stress term
/// of the scatter: the symmetrised Kirchhoff stress times [`stress_scale`].
#[inline(always)]
pub fn particle_stress<T: Real>(
    f: &mut [T; 9],
    plastic: &mut [T; 2],
    c_affine: &[T; 9],
    vol0: T,
    pc: &PartConsts,
    mat: &[T; MAT_CONSTS],
    c: &StepConsts,
) -> [T; 9] {
    let svd = svd3(Mat3::from_array(*f));
    particle_stress_svd(f, &svd, plastic, c_affine, vol0, pc, mat, c)
}

/// [`particle_stress`] given `svd`, the SVD of `f` (bitwise `svd3(f)`; the CPU backend computes
/// them in batches with [`crate::math::svd3_many`]).
#[allow(clippy::too_many_arguments)]
#[inline(always)]
pub fn particle_stress_svd<T: Real>(
    f: &mut [T; 9],
    svd: &Svd3<T>,
    plastic: &mut [T; 2],
    c_affine: &[T; 9],
    vol0: T,
    pc: &PartConsts,
    mat: &[T; MAT_CONSTS],
    c: &StepConsts,
) -> [T; 9] {
    let f_trial = Mat3::from_array(*f);
    let (fe, tau) = if pc.material == crate::Material::Fluid.kernel_id() {
        // The fluid's constants from the slot's table (the differentiable ones, in `T`).
        crate::constitutive::fluid(svd, material_of(mat), &Mat3::from_array(*c_affine))
    } else {
        stress_update_with_svd(f_trial, svd, pc, plastic, material_of(mat), k(c.dt))
    };
    *f = fe.to_array();
    tau.sym().scaled(stress_scale(vol0, c)).to_array()
}

/// The APIC matrix used by the scatter, after RPIC damping.
#[inline(always)]
pub fn damped_affine<T: Real>(cm: &[T; 9], r: f32) -> [T; 9] {
    if r < -0.001 {
        return [T::zero(); 9];
    }
    if r == 0.0 {
        return *cm;
    }
    let m = Mat3::from_array(*cm);
    let r = k::<T>(r);
    (m.scaled(T::one() - r) + (m - m.transpose()).scaled(T::c(0.5) * r)).to_array()
}

/// Scatters one particle's mass, APIC momentum and stress force into `nodes`, a slab of the
/// grid that starts at node layer `x_lo` (index `((i - x_lo) n + j) n + k`).
///
/// `s` is the particle stage's stress term, `cm` the (damped) APIC matrix.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
pub fn scatter<T: Real>(
    nodes: &mut [[T; 4]],
    x_lo: usize,
    n: usize,
    st: &Stencil<T>,
    v: [T; 3],
    cm: &[T; 9],
    mass: T,
    s: &[T; 9],
    c: &StepConsts,
) {
    if c.force_form == FORCE_MLS {
        scatter_form::<T, true>(nodes, x_lo, n, st, v, cm, mass, s, c)
    } else {
        scatter_form::<T, false>(nodes, x_lo, n, st, v, cm, mass, s, c)
    }
}

/// [`scatter`] for one force form (`MLS`: the stress folds into the affine matrix; classic:
/// it enters through the weight gradients).
///
/// A node's share is `w0_i w1_j w2_k (P + Q0 d0_i + Q1 d1_j + Q2 d2_k)` with `P = [m v, m]`,
/// `Qa` the column `a` of `m C` (plus the stress term in the MLS form) and `d` the offsets in
/// metres; the classic form adds the stress columns times the weight gradients. The weights are
/// products of one factor per axis, so the factors are applied axis by axis: once per `i`, once
/// per column `(i, j)`, and per node only the last axis. Every quantity is a 4-lane
/// `[momentum (3), mass]` vector so that the compiler vectorises it.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn scatter_form<T: Real, const MLS: bool>(
    nodes: &mut [[T; 4]],
    x_lo: usize,
    n: usize,
    st: &Stencil<T>,
    v: [T; 3],
    cm: &[T; 9],
    mass: T,
    s: &[T; 9],
    c: &StepConsts,
) {
    let z = T::zero();
    let dx = k::<T>(c.dx);
    let mut mc = [z; 9];
    for e in 0..9 {
        mc[e] = mass * cm[e];
    }
    if MLS {
        // tau * w * dpos folds into the affine matrix.
        for e in 0..9 {
            mc[e] += s[e];
        }
    }
    let col = |m: &[T; 9], a: usize| [m[a], m[3 + a], m[6 + a], z];
    let p = [mass * v[0], mass * v[1], mass * v[2], mass];
    let q = [col(&mc, 0), col(&mc, 1), col(&mc, 2)];
    let sc = [col(s, 0), col(s, 1), col(s, 2)];
    let dp: [[T; 3]; 3] =
        std::array::from_fn(|a| std::array::from_fn(|o| (T::c(o as f64) - st.fx[a]) * dx));
    let (w0, w1, w2) = (st.w[0], st.w[1], st.w[2]);
    let (d0, d1, d2) = (st.dw[0], st.dw[1], st.dw[2]);
    let bz = st.base[2] as usize;
    for i in 0..3 {
        // Shares of the x layer i: A (all but the y and z terms), B (y), C (z) and, in the
        // classic form, E and F (the stress through the y and z weight gradients).
        let mut ai = scale4(w0[i], &axpy4(dp[0][i], &q[0], &p));
        let bi = scale4(w0[i], &q[1]);
        let ci = scale4(w0[i], &q[2]);
        let (mut ei, mut fi) = ([z; 4], [z; 4]);
        if !MLS {
            ai = axpy4(d0[i], &sc[0], &ai);
            ei = scale4(w0[i], &sc[1]);
            fi = scale4(w0[i], &sc[2]);
        }
        let row_i = (st.base[0] as usize + i - x_lo) * n;
        for j in 0..3 {
            let mut aij = scale4(w1[j], &axpy4(dp[1][j], &bi, &ai));
            let cij = scale4(w1[j], &ci);
            let mut dij = [z; 4];
            if !MLS {
                aij = axpy4(d1[j], &ei, &aij);
                dij = scale4(w1[j], &fi);
            }
            let base = (row_i + st.base[1] as usize + j) * n + bz;
            let cell = &mut nodes[base..base + 3];
            for (o, node) in cell.iter_mut().enumerate() {
                let (wk, wdk) = (w2[o], w2[o] * dp[2][o]);
                if MLS {
                    for l in 0..4 {
                        node[l] += wk * aij[l] + wdk * cij[l];
                    }
                } else {
                    let dk = d2[o];
                    for l in 0..4 {
                        node[l] += wk * aij[l] + wdk * cij[l] + dk * dij[l];
                    }
                }
            }
        }
    }
}

/// `k x` on four lanes.
#[inline(always)]
fn scale4<T: Real>(k: T, x: &[T; 4]) -> [T; 4] {
    std::array::from_fn(|l| k * x[l])
}

/// `k x + y` on four lanes.
#[inline(always)]
fn axpy4<T: Real>(k: T, x: &[T; 4], y: &[T; 4]) -> [T; 4] {
    std::array::from_fn(|l| k * x[l] + y[l])
}

/// Updates one grid node: momentum to velocity plus gravity, damping, then the boundary
/// conditions in order. `ijk` is the node index.
#[inline]
pub fn grid_node_update<T: Real>(
    ijk: [usize; 3],
    node: &mut [T; 4],
    bcs: &[GridBc],
    c: &StepConsts,
) {
    let m = node[3];
    let dt = k::<T>(c.dt);
    let mut v = if m > T::c(1e-15) {
        let inv = T::one() / m;
        [
            node[0] * inv + dt * k(c.gravity[0]),
            node[1] * inv + dt * k(c.gravity[1]),
            node[2] * inv + dt * k(c.gravity[2]),
        ]
    } else {
        [T::zero(); 3]
    };
    if c.grid_v_damping < 1.0 {
        let d = k::<T>(c.grid_v_damping);
        for x in v.iter_mut() {
            *x *= d;
        }
    }
    apply_grid_bcs(ijk, &mut v, bcs, c);
    node[0] = v[0];
    node[1] = v[1];
    node[2] = v[2];
}

/// The node position `ijk dx` in f32, as the kernels compare it.
#[inline(always)]
pub fn node_pos(ijk: [usize; 3], c: &StepConsts) -> [f32; 3] {
    [
        ijk[0] as f32 * c.dx,
        ijk[1] as f32 * c.dx,
        ijk[2] as f32 * c.dx,
    ]
}

/// Whether the node `ijk` lies strictly behind an active collider plane.
#[inline(always)]
pub fn behind_surface(bc: &GridBc, ijk: [usize; 3], c: &StepConsts) -> bool {
    let pos = node_pos(ijk, c);
    let d: f32 = (0..3).map(|a| (pos[a] - bc.point[a]) * bc.axis[a]).sum();
    active(bc.start, bc.end, c.time) && d < 0.0
}

/// Whether a (moving) cuboid prescribes the velocity of node `ijk` in this substep.
#[inline(always)]
pub fn inside_cuboid(bc: &GridBc, ijk: [usize; 3], c: &StepConsts) -> bool {
    let pos = node_pos(ijk, c);
    let shift = c.time - bc.start;
    active(bc.start, bc.end, c.time)
        && (0..3).all(|a| (pos[a] - (bc.point[a] + bc.velocity[a] * shift)).abs() < bc.axis[a])
}

/// Whether a cuboid with PhysGaussian's `reset` zeroes the whole grid in this substep.
#[inline(always)]
pub fn cuboid_resets(bc: &GridBc, c: &StepConsts) -> bool {
    !active(bc.start, bc.end, c.time) && bc.layers == 1 && c.time < bc.end + 15.0 * c.dt
}

/// Applies the grid boundary conditions, in order, to a node velocity.
#[inline]
pub fn apply_grid_bcs<T: Real>(ijk: [usize; 3], v: &mut [T; 3], bcs: &[GridBc], c: &StepConsts) {
    let n = c.n_grid as usize;
    let z = T::zero();
    for bc in bcs {
        match bc.kind {
            BC_BOUNDING_BOX if active(bc.start, bc.end, c.time) => {
                let l = bc.layers as usize;
                if bc.mode == 0 {
                    if (0..3).any(|a| ijk[a] < l || ijk[a] >= n - l) {
                        *v = [z; 3];
                    }
                } else {
                    for a in 0..3 {
                        if (ijk[a] < l && v[a] < z) || (ijk[a] >= n - l && v[a] > z) {
                            v[a] = z;
                        }
                    }
                }
            }
            BC_CUBOID => {
                if inside_cuboid(bc, ijk, c) {
                    *v = bc.velocity.map(k);
                } else if cuboid_resets(bc, c) {
                    *v = [z; 3];
                }
            }
            BC_SURFACE if behind_surface(bc, ijk, c) => {
                let nrm: [T; 3] = bc.axis.map(k);
                let vn = v[0] * nrm[0] + v[1] * nrm[1] + v[2] * nrm[2];
                match bc.mode {
                    0 => *v = [z; 3],
                    1 => {
                        for a in 0..3 {
                            v[a] -= vn * nrm[a];
                        }
                    }
                    _ => {
                        if vn < z {
                            for a in 0..3 {
                                v[a] -= vn * nrm[a];
                            }
                            let vt = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
                            if vt > T::c(1e-20) {
                                let f = (vt + vn * k(bc.friction)).max(z) / vt;
                                for x in v.iter_mut() {
                                    *x *= f;
                                }
                            }
                        }
                    }
                }
            }
            _ => {}
        }
    }
}

/// What G2P gathers for one particle.
#[derive(Clone, Copy, Debug)]
pub struct Gathered<T> {
    /// Interpolated velocity.
    pub v: [T; 3],
    /// APIC matrix `C = (4 / dx^2) sum w v dpos^T`.
    pub c: [T; 9],
    /// Velocity gradient `sum v grad_w^T` (classic form) or C (MLS form).
    pub grad_v: [T; 9],
}

/// Gathers velocity, APIC matrix and velocity gradient from the grid (full grid, x_lo = 0).
#[inline(always)]
pub fn gather<T: Real>(nodes: &[[T; 4]], n: usize, st: &Stencil<T>, c: &StepConsts) -> Gathered<T> {
    if c.force_form == FORCE_MLS {
        gather_form::<T, true>(nodes, n, st, c)
    } else {
        gather_form::<T, false>(nodes, n, st, c)
    }
}

/// [`gather`] for one force form (`MLS`: the velocity gradient is C, so the weight-gradient
/// sums are skipped).
///
/// The weights are products of one factor per axis, so the sums run axis by axis: over the
/// three nodes of a column (`k`, contiguous in memory), then over the columns of an x layer
/// (`j`), then over the layers (`i`); the first moments `sum w d v` (d = o - f, the offset of
/// the node in cells) that make up C reuse the products `w v` of the velocity sum. (They are
/// summed with the offsets from the particle, not about a node and shifted afterwards: for a
/// nearly uniform velocity that shift would cancel most of the digits of C.) Sums run over
/// all four entries of a node (the fourth, the mass, is dropped at the end) so that the
/// compiler vectorises them.
#[inline(always)]
fn gather_form<T: Real, const MLS: bool>(
    nodes: &[[T; 4]],
    n: usize,
    st: &Stencil<T>,
    c: &StepConsts,
) -> Gathered<T> {
    let (w0, w1, w2) = (st.w[0], st.w[1], st.w[2]);
    let (d0, d1, d2) = (st.dw[0], st.dw[1], st.dw[2]);
    let z = T::zero();
    let dp: [[T; 3]; 3] =
        std::array::from_fn(|a| std::array::from_fn(|o| T::c(o as f64) - st.fx[a]));
    let bz = st.base[2] as usize;
    // Layer sums: t[0] = sum w1 w2 v, t[1] = sum w1 d1 w2 v, t[2] = sum w1 w2 d2 v and, in
    // the classic form, t[3] = sum dw1 w2 v, t[4] = sum w1 dw2 v.
    let mut v = [z; 4];
    let mut m = [[z; 4]; 3];
    let mut g = [[z; 4]; 3];
    for i in 0..3 {
        let mut t = [[z; 4]; 5];
        for j in 0..3 {
            let base = ((st.base[0] as usize + i) * n + st.base[1] as usize + j) * n + bz;
            let cell: &[[T; 4]; 3] = nodes[base..base + 3].try_into().expect("three nodes");
            let p0 = scale4(w2[0], &cell[0]);
            let p1 = scale4(w2[1], &cell[1]);
            let p2 = scale4(w2[2], &cell[2]);
            // Column sums: s0 = sum w2 v, s1 = sum w2 d2 v (and s2 = sum dw2 v).
            let s0: [T; 4] = std::array::from_fn(|l| p0[l] + p1[l] + p2[l]);
            let s1: [T; 4] =
                std::array::from_fn(|l| dp[2][0] * p0[l] + dp[2][1] * p1[l] + dp[2][2] * p2[l]);
            let q = scale4(w1[j], &s0);
            for l in 0..4 {
                t[0][l] += q[l];
            }
            t[1] = axpy4(dp[1][j], &q, &t[1]);
            t[2] = axpy4(w1[j], &s1, &t[2]);
            if !MLS {
                let s2: [T; 4] = std::array::from_fn(|l| {
                    d2[0] * cell[0][l] + d2[1] * cell[1][l] + d2[2] * cell[2][l]
                });
                t[3] = axpy4(d1[j], &s0, &t[3]);
                t[4] = axpy4(w1[j], &s2, &t[4]);
            }
        }
        let r = scale4(w0[i], &t[0]);
        for l in 0..4 {
            v[l] += r[l];
        }
        m[0] = axpy4(dp[0][i], &r, &m[0]);
        m[1] = axpy4(w0[i], &t[1], &m[1]);
        m[2] = axpy4(w0[i], &t[2], &m[2]);
        if !MLS {
            g[0] = axpy4(d0[i], &t[0], &g[0]);
            g[1] = axpy4(w0[i], &t[3], &g[1]);
            g[2] = axpy4(w0[i], &t[4], &g[2]);
        }
    }
    let inv_dx = k::<T>(c.inv_dx);
    let kc = T::c(4.0) * inv_dx;
    let cm: [T; 9] = std::array::from_fn(|e| m[e % 3][e / 3] * kc);
    let gv = if MLS {
        cm
    } else {
        std::array::from_fn(|e| g[e % 3][e / 3] * inv_dx)
    };
    Gathered {
        v: [v[0], v[1], v[2]],
        c: cm,
        grad_v: gv,
    }
}

/// Finishes G2P for one particle: stores v and C, advects x, updates F to
/// `(I + dt grad_v) F_elastic`, applies the out-of-domain policy and returns the health code
/// (0 when healthy) and the offending value.
#[inline(always)]
pub fn g2p_finish<T: Real>(
    g: &Gathered<T>,
    x: &mut [T; 3],
    v: &mut [T; 3],
    cm: &mut [T; 9],
    f: &mut [T; 9],
    c: &StepConsts,
) -> (u32, f32) {
    let dt = k::<T>(c.dt);
    *v = g.v;
    *cm = g.c;
    for a in 0..3 {
        x[a] += dt * g.v[a];
    }
    let fe = Mat3::from_array(*f);
    let mut l = Mat3::from_array(g.grad_v).scaled(dt);
    for a in 0..3 {
        l.0[a][a] += T::one();
    }
    *f = (l * fe).to_array();
    let speed2 = v[0] * v[0] + v[1] * v[1] + v[2] * v[2];
    if !(speed2.is_finite() && x.iter().all(|e| e.is_finite()) && f.iter().all(|e| e.is_finite())) {
        return (HEALTH_NAN, f32::NAN);
    }
    let max_speed = k::<T>(c.max_speed);
    if speed2 > max_speed * max_speed {
        return (HEALTH_SPEED, speed2.sqrt().f64() as f32);
    }
    let n = c.n_grid as usize;
    if !in_domain(*x, k(c.inv_dx), n) {
        if c.out_of_domain == OUT_OF_DOMAIN_CLAMP {
            let lo = T::c(0.5 * c.dx as f64 * 1.0001);
            let hi = T::c((n as f64 - 1.5) * c.dx as f64 * 0.9999);
            for e in x.iter_mut() {
                *e = e.max(lo).min(hi);
            }
        } else {
            return (
                HEALTH_OUT_OF_DOMAIN,
                out_of_domain_coordinate(*x, k(c.inv_dx), n),
            );
        }
    }
    (0, 0.0)
}

/// Merges a problem into a health record, keeping the earliest substep, then the lowest
/// particle index.
#[inline]
pub fn record(h: &mut Health, code: u32, substep: u32, particle: u32, value: f32) {
    if code == 0 {
        return;
    }
    let earlier =
        h.code == 0 || substep < h.substep || (substep == h.substep && particle < h.particle);
    if earlier {
        *h = Health {
            code,
            substep,
            particle,
            value_bits: value.to_bits(),
        };
    }
}
