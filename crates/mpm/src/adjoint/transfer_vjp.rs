//! Vector-Jacobian products of the transfer stages of a substep ([`crate::transfer`]):
//! particle boundary conditions, RPIC damping, P2G scatter, the grid node update with every
//! boundary condition, and G2P (gather, advection, F update).
//!
//! Each function takes the forward inputs (recomputed from a checkpoint by the caller) and the
//! adjoints of the forward outputs, and *accumulates* (`+=`) into the adjoints of the inputs.
//! Generic over [`Real`] so they are checked against f64 finite differences; the host
//! backends call them, the GPU backends mirror them. The P2G and G2P adjoints sum over the 27
//! stencil nodes axis by axis (the weights are products of one factor per axis); their
//! node-by-node derivation is the test oracle.
//!
//! Non-smooth points (a boundary condition switching on a velocity sign, the truncation of the
//! stencil base, the out-of-domain clamp) are differentiated piecewise: the derivative of the
//! branch the forward pass took.

use crate::boundary::{BC_BOUNDING_BOX, BC_CUBOID, BC_SURFACE, PBC_IMPULSE, PBC_VELOCITY};
use crate::kernels::{GridBc, ParticleBc, StepConsts, FORCE_MLS};
use crate::math::{Mat3, Real};
use crate::transfer::{
    behind_surface, cuboid_resets, inside_cuboid, k, particle_bc_applies, Stencil,
};

/// Second derivatives of the quadratic B-spline weights with respect to `x / dx`.
const DDW: [f64; 3] = [1.0, -2.0, 1.0];

/// Adjoint of [`crate::transfer::particle_bcs`]: given the adjoint `v_bar` of the velocity after
/// the conditions, turns it into the adjoint of the velocity before them (in place) and adds
/// the adjoint of the particle mass to `mass_bar`.
pub fn particle_bcs_vjp<T: Real>(
    x0: [f32; 3],
    mass: T,
    bcs: &[ParticleBc],
    c: &StepConsts,
    v_bar: &mut [T; 3],
    mass_bar: &mut T,
) {
    for bc in bcs.iter().rev() {
        if !particle_bc_applies(bc, x0, c) {
            continue;
        }
        match bc.kind {
            PBC_IMPULSE => {
                // v += f / m dt  =>  m_bar -= (f . v_bar) dt / m^2
                let fv: T = (0..3).fold(T::zero(), |s, a| s + k::<T>(bc.vector[a]) * v_bar[a]);
                *mass_bar -= fv * k(c.dt) / (mass * mass);
            }
            PBC_VELOCITY => *v_bar = [T::zero(); 3],
            _ => {}
        }
    }
}

/// Adjoint of [`crate::transfer::damped_affine`]: the adjoint of C from that of the damped matrix.
pub fn damped_affine_vjp<T: Real>(a_bar: &[T; 9], r: f32) -> [T; 9] {
    if r < -0.001 {
        return [T::zero(); 9];
    }
    if r == 0.0 {
        return *a_bar;
    }
    // The map is linear: A = (1 - r) C + r/2 (C - C^T); its transpose has the same form.
    crate::transfer::damped_affine(a_bar, r)
}

/// `acc += k v` on four lanes (one node's entries; the compiler vectorises it).
#[inline(always)]
fn fma4<T: Real>(acc: &mut [T; 4], k: T, v: &[T; 4]) {
    for l in 0..4 {
        acc[l] += k * v[l];
    }
}

/// The offsets of the stencil nodes from the particle in cells: `d[a][o] = o - fx[a]`.
#[inline(always)]
fn offsets<T: Real>(st: &Stencil<T>) -> [[T; 3]; 3] {
    std::array::from_fn(|a| std::array::from_fn(|o| T::c(o as f64) - st.fx[a]))
}

/// Adds one stencil column's `(i, j)` share to the classic form's weight-gradient moments:
/// `g[b] += sum_k g_b y` and the six distinct second moments
/// `h = [H00, H11, H22, H01, H02, H12]`, `H_ba = sum_k dg_b/dfx_a y`, where `r0`, `r2`, `r3`
/// are the column's sums of `w_k y`, `dw_k y` and `ddw_k y` over its three nodes.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn classic_moments<T: Real>(
    st: &Stencil<T>,
    i: usize,
    j: usize,
    r0: &[T; 4],
    r2: &[T; 4],
    r3: &[T; 4],
    g: &mut [[T; 4]; 3],
    h: &mut [[T; 4]; 6],
) {
    let (w0, w1, d0, d1) = (st.w[0], st.w[1], st.dw[0], st.dw[1]);
    let wij = w0[i] * w1[j];
    let (gx, gy) = (d0[i] * w1[j], w0[i] * d1[j]);
    fma4(&mut g[0], gx, r0);
    fma4(&mut g[1], gy, r0);
    fma4(&mut g[2], wij, r2);
    fma4(&mut h[0], T::c(DDW[i]) * w1[j], r0);
    fma4(&mut h[1], w0[i] * T::c(DDW[j]), r0);
    fma4(&mut h[2], wij, r3);
    fma4(&mut h[3], d0[i] * d1[j], r0);
    fma4(&mut h[4], gx, r2);
    fma4(&mut h[5], gy, r2);
}

/// `sum_b m[:, b] . H_ba` for each axis `a`, from the six second moments of
/// [`classic_moments`] (`H` is symmetric in `a, b`).
#[inline(always)]
fn hessian_term<T: Real>(m: &Mat3<T>, h: &[[T; 4]; 6]) -> [T; 3] {
    const IDX: [[usize; 3]; 3] = [[0, 3, 4], [3, 1, 5], [4, 5, 2]];
    std::array::from_fn(|a| {
        (0..3).fold(T::zero(), |acc, b| {
            let hv = &h[IDX[b][a]];
            acc + m.0[0][b] * hv[0] + m.0[1][b] * hv[1] + m.0[2][b] * hv[2]
        })
    })
}

/// Adjoints of one particle's scatter inputs, accumulated by [`scatter_vjp`].
#[derive(Clone, Copy, Debug, Default)]
pub struct ScatterBar<T> {
    /// Adjoint of the position (through the stencil).
    pub x: [T; 3],
    /// Adjoint of the velocity (after particle boundary conditions).
    pub v: [T; 3],
    /// Adjoint of the damped APIC matrix.
    pub a: [T; 9],
    /// Adjoint of the mass.
    pub mass: T,
    /// Adjoint of the stress term.
    pub s: [T; 9],
}

/// Adjoint of [`crate::transfer::scatter`] for one particle on the full grid (`x_lo = 0`):
/// `nodes_bar` holds the adjoints of the scattered `[momentum (3), mass]` of every node.
///
/// With `y` a node's adjoint, `d = offset - fx` its offset in cells and `w` its weight, every
/// input adjoint is a sum over the 27 nodes of `w y`, `w d y^T` or `dw s`, where
/// `s = y . [m v + dx mC d, m]` is the node's scattered momentum and mass dotted with their
/// adjoints per unit weight. The weights are products of one factor per axis, so the sums run
/// over the innermost axis first (three nodes contiguous in memory), then over the nine
/// columns, as the forward scatter does. The node-by-node derivation is kept as the test
/// oracle (`per_node_vjp`).
#[allow(clippy::too_many_arguments)]
pub fn scatter_vjp<T: Real>(
    nodes_bar: &[[T; 4]],
    n: usize,
    st: &Stencil<T>,
    v: [T; 3],
    a: &[T; 9],
    mass: T,
    s: &[T; 9],
    c: &StepConsts,
    out: &mut ScatterBar<T>,
) {
    if c.force_form == FORCE_MLS {
        scatter_vjp_form::<T, true>(nodes_bar, n, st, v, a, mass, s, c, out)
    } else {
        scatter_vjp_form::<T, false>(nodes_bar, n, st, v, a, mass, s, c, out)
    }
}

/// [`scatter_vjp`] for one force form (`MLS`: the stress is part of the affine matrix;
/// classic: it enters through the weight gradients, whose first and second moments are
/// summed too).
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn scatter_vjp_form<T: Real, const MLS: bool>(
    nodes_bar: &[[T; 4]],
    n: usize,
    st: &Stencil<T>,
    v: [T; 3],
    a: &[T; 9],
    mass: T,
    s: &[T; 9],
    c: &StepConsts,
    out: &mut ScatterBar<T>,
) {
    let z = T::zero();
    let dx = k::<T>(c.dx);
    let inv_dx = k::<T>(c.inv_dx);
    let am = Mat3::from_array(*a);
    let sm = Mat3::from_array(*s);
    // The affine matrix of the momentum: m A (+ S in MLS form).
    let mc = if MLS {
        am.scaled(mass) + sm
    } else {
        am.scaled(mass)
    };
    let m = mc.0;
    let d = offsets(st);
    let (w0, w1, w2) = (st.w[0], st.w[1], st.w[2]);
    let (d0, d1, d2) = (st.dw[0], st.dw[1], st.dw[2]);
    // The innermost axis's share of [m v + dx mC d, m]: dx mC[:, 2] d_z.
    let zk: [[T; 4]; 3] = std::array::from_fn(|o| {
        let t = dx * d[2][o];
        [m[0][2] * t, m[1][2] * t, m[2][2] * t, z]
    });
    let mut s0 = [z; 4]; // sum w y
    let mut t1 = [[z; 4]; 3]; // t1[b] = sum w d_b y
    let mut fb = [z; 3]; // fb[a] = sum dw_a s
    let mut g = [[z; 4]; 3]; // classic: g[b] = sum g_b y
    let mut h = [[z; 4]; 6]; // classic: second moments
    let bz = st.base[2] as usize;
    for i in 0..3 {
        for j in 0..3 {
            let base = ((st.base[0] as usize + i) * n + st.base[1] as usize + j) * n + bz;
            let cell = &nodes_bar[base..base + 3];
            let zij = [
                mass * v[0] + dx * (m[0][0] * d[0][i] + m[0][1] * d[1][j]),
                mass * v[1] + dx * (m[1][0] * d[0][i] + m[1][1] * d[1][j]),
                mass * v[2] + dx * (m[2][0] * d[0][i] + m[2][1] * d[1][j]),
                mass,
            ];
            let (mut r0, mut r1, mut r2, mut r3) = ([z; 4], [z; 4], [z; 4], [z; 4]);
            let (mut sw, mut sdw) = (z, z);
            for (o, y) in cell.iter().enumerate() {
                let sn = (0..4).fold(z, |acc, l| acc + y[l] * (zij[l] + zk[o][l]));
                fma4(&mut r0, w2[o], y);
                fma4(&mut r1, w2[o] * d[2][o], y);
                sw += w2[o] * sn;
                sdw += d2[o] * sn;
                if !MLS {
                    fma4(&mut r2, d2[o], y);
                    fma4(&mut r3, T::c(DDW[o]), y);
                }
            }
            let wij = w0[i] * w1[j];
            fma4(&mut s0, wij, &r0);
            fma4(&mut t1[0], wij * d[0][i], &r0);
            fma4(&mut t1[1], wij * d[1][j], &r0);
            fma4(&mut t1[2], wij, &r1);
            fb[0] += d0[i] * w1[j] * sw;
            fb[1] += w0[i] * d1[j] * sw;
            fb[2] += wij * sdw;
            if !MLS {
                classic_moments(st, i, j, &r0, &r2, &r3, &mut g, &mut h);
            }
        }
    }
    // The adjoint of mC: sum w y dpos^T = dx sum w y d^T.
    let mc_bar = Mat3(std::array::from_fn(|q| {
        std::array::from_fn(|b| dx * t1[b][q])
    }));
    let ys = [s0[0], s0[1], s0[2]];
    for q in 0..3 {
        out.v[q] += mass * ys[q];
    }
    // mass: sum w (v . y + (A dpos) . y + m_bar) = v . ys + <A, mc_bar> + sum w m_bar.
    let a_mc = (0..3).fold(z, |acc, q| {
        acc + am.0[q][0] * mc_bar.0[q][0]
            + am.0[q][1] * mc_bar.0[q][1]
            + am.0[q][2] * mc_bar.0[q][2]
    });
    out.mass += v[0] * ys[0] + v[1] * ys[1] + v[2] * ys[2] + a_mc + s0[3];
    // position: through the weights (fb) and through dpos (-dx mC^T sum w y).
    let mty = mc.transpose().mul_vec(ys);
    let mut f_bar: [T; 3] = std::array::from_fn(|ax| fb[ax] - dx * mty[ax]);
    let s_bar = if MLS {
        mc_bar
    } else {
        let ht = hessian_term(&sm, &h);
        for ax in 0..3 {
            f_bar[ax] += ht[ax];
        }
        Mat3(std::array::from_fn(|q| std::array::from_fn(|b| g[b][q])))
    };
    let a_bar = mc_bar.scaled(mass).to_array();
    let s_bar = s_bar.to_array();
    for e in 0..9 {
        out.a[e] += a_bar[e];
        out.s[e] += s_bar[e];
    }
    for ax in 0..3 {
        out.x[ax] += f_bar[ax] * inv_dx;
    }
}

/// The adjoint of a node's scattered `[momentum, mass]` from the adjoint `node_bar` G2P left
/// on the updated node (its velocity part): [`grid_node_update_vjp`], or zero where the
/// velocity adjoint is zero (no particle gathered from the node). Every backend's
/// `grid_update_vjp` applies this per node.
#[inline]
pub fn grid_node_vjp<T: Real>(
    ijk: [usize; 3],
    node_in: [T; 4],
    node_bar: [T; 4],
    bcs: &[GridBc],
    c: &StepConsts,
) -> [T; 4] {
    let vb = [node_bar[0], node_bar[1], node_bar[2]];
    if vb.iter().any(|x| *x != T::zero()) {
        grid_node_update_vjp(ijk, node_in, bcs, c, vb)
    } else {
        [T::zero(); 4]
    }
}

/// Adjoint of [`crate::transfer::grid_node_update`]: `v_bar` is the adjoint of the node's
/// final velocity, `node_in` the node's scattered `[momentum, mass]` (forward input). Returns
/// the adjoint of `[momentum, mass]`.
pub fn grid_node_update_vjp<T: Real>(
    ijk: [usize; 3],
    node_in: [T; 4],
    bcs: &[GridBc],
    c: &StepConsts,
    v_bar: [T; 3],
) -> [T; 4] {
    let m = node_in[3];
    if m <= T::c(1e-15) {
        return [T::zero(); 4];
    }
    let dt = k::<T>(c.dt);
    let inv = T::one() / m;
    let u: [T; 3] = std::array::from_fn(|a| node_in[a] * inv);
    let mut v: [T; 3] = std::array::from_fn(|a| u[a] + dt * k(c.gravity[a]));
    let damp = c.grid_v_damping < 1.0;
    if damp {
        let d = k::<T>(c.grid_v_damping);
        v = [v[0] * d, v[1] * d, v[2] * d];
    }
    let mut bar = apply_grid_bcs_vjp(ijk, v, bcs, c, v_bar);
    if damp {
        let d = k::<T>(c.grid_v_damping);
        bar = [bar[0] * d, bar[1] * d, bar[2] * d];
    }
    // u = mom / m: mom_bar = bar / m, m_bar = -(bar . u) / m.
    let dot = (0..3).fold(T::zero(), |s, a| s + bar[a] * u[a]);
    [bar[0] * inv, bar[1] * inv, bar[2] * inv, -dot * inv]
}

/// Adjoint of [`crate::transfer::apply_grid_bcs`]: `v_in` is the velocity before the
/// conditions, `v_bar` the adjoint after them; returns the adjoint before them.
pub fn apply_grid_bcs_vjp<T: Real>(
    ijk: [usize; 3],
    v_in: [T; 3],
    bcs: &[GridBc],
    c: &StepConsts,
    v_bar: [T; 3],
) -> [T; 3] {
    let n = c.n_grid as usize;
    let z = T::zero();
    let mut bar = v_bar;
    for (i, bc) in bcs.iter().enumerate().rev() {
        // The velocity before condition i: replay the ones before it (few conditions, no
        // allocation in this per-node hot loop).
        let mut vb = v_in;
        crate::transfer::apply_grid_bcs(ijk, &mut vb, &bcs[..i], c);
        let on = c.time >= bc.start && c.time < bc.end;
        match bc.kind {
            BC_BOUNDING_BOX if on => {
                let l = bc.layers as usize;
                if bc.mode == 0 {
                    if (0..3).any(|a| ijk[a] < l || ijk[a] >= n - l) {
                        bar = [z; 3];
                    }
                } else {
                    for a in 0..3 {
                        if (ijk[a] < l && vb[a] < z) || (ijk[a] >= n - l && vb[a] > z) {
                            bar[a] = z;
                        }
                    }
                }
            }
            BC_CUBOID if inside_cuboid(bc, ijk, c) || cuboid_resets(bc, c) => {
                bar = [z; 3];
            }
            BC_SURFACE if behind_surface(bc, ijk, c) => {
                let nrm: [T; 3] = bc.axis.map(k);
                let vn = (0..3).fold(z, |s, a| s + vb[a] * nrm[a]);
                match bc.mode {
                    0 => bar = [z; 3],
                    1 => {
                        let bn = (0..3).fold(z, |s, a| s + bar[a] * nrm[a]);
                        bar = std::array::from_fn(|a| bar[a] - bn * nrm[a]);
                    }
                    _ => {
                        if vn < z {
                            let w: [T; 3] = std::array::from_fn(|a| vb[a] - vn * nrm[a]);
                            let vt = (w[0] * w[0] + w[1] * w[1] + w[2] * w[2]).sqrt();
                            let mu = k::<T>(bc.friction);
                            let (w_bar, vn_bar) = if vt > T::c(1e-20) {
                                if vt + vn * mu > z {
                                    let f = (vt + vn * mu) / vt;
                                    let wb = (0..3).fold(z, |s, a| s + w[a] * bar[a]);
                                    let df_dvt = -vn * mu / (vt * vt);
                                    let w_bar: [T; 3] = std::array::from_fn(|a| {
                                        f * bar[a] + wb * df_dvt * w[a] / vt
                                    });
                                    (w_bar, wb * mu / vt)
                                } else {
                                    ([z; 3], z)
                                }
                            } else {
                                (bar, z)
                            };
                            // w = v - (v . n) n, vn = v . n
                            let nw = (0..3).fold(z, |s, a| s + nrm[a] * w_bar[a]);
                            bar = std::array::from_fn(|a| w_bar[a] + nrm[a] * (vn_bar - nw));
                        }
                    }
                }
            }
            _ => {}
        }
    }
    bar
}

/// Adjoints of one particle's G2P inputs, from [`g2p_vjp`].
#[derive(Clone, Copy, Debug, Default)]
pub struct G2pBar<T> {
    /// Adjoint of the position at the start of the substep.
    pub x: [T; 3],
    /// Adjoint of F_elastic.
    pub f_elastic: [T; 9],
}

/// Adjoint of [`crate::transfer::gather`] + [`crate::transfer::g2p_finish`] for one particle:
/// given the adjoints of the new `x, v, C, F`, accumulates the adjoints of the grid node
/// velocities into `nodes_bar[..][0..3]` (a slab of the grid starting at node layer `x_lo`,
/// as in [`crate::transfer::scatter`]) and returns those of the old position and F_elastic.
///
/// One pass over the 27 nodes, axis by axis as in [`scatter_vjp`]: each node's adjoint is
/// `w u` (plus the weight-gradient term in the classic form) with
/// `u = v_bar + dt x_bar + 4/dx Cbar d`, the position adjoint sums `dw_a (v . u)`, and the
/// velocity gradient of the F update is summed again in the same pass (it is needed only for
/// the adjoint of F_elastic).
#[allow(clippy::too_many_arguments)]
pub fn g2p_vjp<T: Real>(
    nodes: &[[T; 4]],
    n: usize,
    x: [T; 3],
    f_elastic: &[T; 9],
    c: &StepConsts,
    x_bar: [T; 3],
    v_bar: [T; 3],
    c_bar: &[T; 9],
    f_bar: &[T; 9],
    nodes_bar: &mut [[T; 4]],
    x_lo: usize,
) -> G2pBar<T> {
    if c.force_form == FORCE_MLS {
        g2p_vjp_form::<T, true>(
            nodes, n, x, f_elastic, c, x_bar, v_bar, c_bar, f_bar, nodes_bar, x_lo,
        )
    } else {
        g2p_vjp_form::<T, false>(
            nodes, n, x, f_elastic, c, x_bar, v_bar, c_bar, f_bar, nodes_bar, x_lo,
        )
    }
}

/// [`g2p_vjp`] for one force form (`MLS`: the velocity gradient is C).
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn g2p_vjp_form<T: Real, const MLS: bool>(
    nodes: &[[T; 4]],
    n: usize,
    x: [T; 3],
    f_elastic: &[T; 9],
    c: &StepConsts,
    x_bar: [T; 3],
    v_bar: [T; 3],
    c_bar: &[T; 9],
    f_bar: &[T; 9],
    nodes_bar: &mut [[T; 4]],
    x_lo: usize,
) -> G2pBar<T> {
    let z = T::zero();
    let lo = x_lo * n * n;
    let dt = k::<T>(c.dt);
    let inv_dx = k::<T>(c.inv_dx);
    let kc = T::c(4.0) * inv_dx;
    let st = crate::transfer::stencil(x, inv_dx);
    let fe = Mat3::from_array(*f_elastic);
    let fb = Mat3::from_array(*f_bar);
    // The adjoint of the velocity gradient: F = (I + dt grad_v) F_elastic.
    let g_bar = (fb * fe.transpose()).scaled(dt);
    let cm_bar = if MLS {
        Mat3::from_array(*c_bar) + g_bar
    } else {
        Mat3::from_array(*c_bar)
    };
    let cb = cm_bar.0;
    // Classic form: node adjoint inv_dx g_bar g.
    let gb = g_bar.scaled(inv_dx).0;
    let vp_bar: [T; 3] = std::array::from_fn(|a| v_bar[a] + dt * x_bar[a]);
    let d = offsets(&st);
    let (w0, w1, w2) = (st.w[0], st.w[1], st.w[2]);
    let (d0, d1, d2) = (st.dw[0], st.dw[1], st.dw[2]);
    // The innermost axis's share of u: kc Cbar[:, 2] d_z.
    let uk: [[T; 4]; 3] = std::array::from_fn(|o| {
        let t = kc * d[2][o];
        [cb[0][2] * t, cb[1][2] * t, cb[2][2] * t, z]
    });
    let mut rv = [z; 4]; // sum w v_i
    let mut cw = [[z; 4]; 3]; // cw[b] = sum w d_b v_i
    let mut fp = [z; 3]; // fp[a] = sum dw_a (v_i . u)
    let mut g = [[z; 4]; 3]; // classic: g[b] = sum g_b v_i
    let mut h = [[z; 4]; 6]; // classic: second moments
    let bz = st.base[2] as usize;
    for i in 0..3 {
        for j in 0..3 {
            let wij = w0[i] * w1[j];
            let uij = [
                vp_bar[0] + kc * (cb[0][0] * d[0][i] + cb[0][1] * d[1][j]),
                vp_bar[1] + kc * (cb[1][0] * d[0][i] + cb[1][1] * d[1][j]),
                vp_bar[2] + kc * (cb[2][0] * d[0][i] + cb[2][1] * d[1][j]),
                z,
            ];
            // Node adjoint: w_k (wij uij [+ gx gb[:,0] + gy gb[:,1]]) + wij w_k uk
            // [+ dw_k wij gb[:,2]].
            let mut aij = [wij * uij[0], wij * uij[1], wij * uij[2], z];
            let mut hij = [z; 4];
            if !MLS {
                let (gx, gy) = (d0[i] * w1[j], w0[i] * d1[j]);
                for q in 0..3 {
                    aij[q] += gx * gb[q][0] + gy * gb[q][1];
                    hij[q] = wij * gb[q][2];
                }
            }
            let base = ((st.base[0] as usize + i) * n + st.base[1] as usize + j) * n + bz;
            let cell = &nodes[base..base + 3];
            let cell_bar = &mut nodes_bar[base - lo..base - lo + 3];
            let (mut r0, mut r1, mut r2, mut r3) = ([z; 4], [z; 4], [z; 4], [z; 4]);
            let (mut sw, mut sdw) = (z, z);
            for (o, (vi, nb)) in cell.iter().zip(cell_bar.iter_mut()).enumerate() {
                let wk = wij * w2[o];
                for l in 0..4 {
                    nb[l] += w2[o] * aij[l] + wk * uk[o][l];
                }
                if !MLS {
                    fma4(nb, d2[o], &hij);
                }
                let sn = (0..3).fold(z, |acc, q| acc + vi[q] * (uij[q] + uk[o][q]));
                sw += w2[o] * sn;
                sdw += d2[o] * sn;
                fma4(&mut r0, w2[o], vi);
                fma4(&mut r1, w2[o] * d[2][o], vi);
                if !MLS {
                    fma4(&mut r2, d2[o], vi);
                    fma4(&mut r3, T::c(DDW[o]), vi);
                }
            }
            fma4(&mut rv, wij, &r0);
            fma4(&mut cw[0], wij * d[0][i], &r0);
            fma4(&mut cw[1], wij * d[1][j], &r0);
            fma4(&mut cw[2], wij, &r1);
            fp[0] += d0[i] * w1[j] * sw;
            fp[1] += w0[i] * d1[j] * sw;
            fp[2] += wij * sdw;
            if !MLS {
                classic_moments(&st, i, j, &r0, &r2, &r3, &mut g, &mut h);
            }
        }
    }
    // The velocity gradient of the forward F update: C = kc sum w v d^T (MLS) or
    // inv_dx sum v g^T (classic).
    let grad_v = if MLS {
        Mat3(std::array::from_fn(|q| {
            std::array::from_fn(|b| kc * cw[b][q])
        }))
    } else {
        Mat3(std::array::from_fn(|q| {
            std::array::from_fn(|b| inv_dx * g[b][q])
        }))
    };
    let mut l = grad_v.scaled(dt);
    for a in 0..3 {
        l.0[a][a] += T::one();
    }
    let fe_bar = l.transpose() * fb;
    // Position: through the weights (fp) and through d (-kc Cbar^T sum w v_i).
    let ctv = cm_bar.transpose().mul_vec([rv[0], rv[1], rv[2]]);
    let mut f_pos_bar: [T; 3] = std::array::from_fn(|a| fp[a] - kc * ctv[a]);
    if !MLS {
        let ht = hessian_term(&g_bar, &h);
        for a in 0..3 {
            f_pos_bar[a] += inv_dx * ht[a];
        }
    }
    G2pBar {
        x: std::array::from_fn(|a| x_bar[a] + f_pos_bar[a] * inv_dx),
        f_elastic: fe_bar.to_array(),
    }
}
