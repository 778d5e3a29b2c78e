//! Vector-Jacobian products of the transfer stages of a substep ([`crate::transfer`]):
//! particle boundary conditions, RPIC damping, P2G scatter, the grid node update with every
//! boundary condition, and G2P (gather, advection, F update).
//!
//! Each function takes the forward inputs (recomputed from a checkpoint by the caller) and the
//! adjoints of the forward outputs, and *accumulates* (`+=`) into the adjoints of the inputs.
//! Written for clarity over speed (plain loops over the 27 stencil nodes), generic over
//! [`Real`] so they are checked against f64 finite differences; the fast backends mirror them.
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

/// Grid index of the stencil node at offset `off` (full grid of `n` nodes per axis).
#[inline(always)]
fn node_index<T>(st: &Stencil<T>, off: [usize; 3], n: usize) -> usize {
    ((st.base[0] as usize + off[0]) * n + st.base[1] as usize + off[1]) * n
        + st.base[2] as usize
        + off[2]
}

/// Stencil weight of node offset `o` and its derivatives with respect to `fx` on each axis.
#[inline(always)]
fn weight_and_grad<T: Real>(st: &Stencil<T>, o: [usize; 3]) -> (T, [T; 3]) {
    let w = st.w[0][o[0]] * st.w[1][o[1]] * st.w[2][o[2]];
    let dw = [
        st.dw[0][o[0]] * st.w[1][o[1]] * st.w[2][o[2]],
        st.w[0][o[0]] * st.dw[1][o[1]] * st.w[2][o[2]],
        st.w[0][o[0]] * st.w[1][o[1]] * st.dw[2][o[2]],
    ];
    (w, dw)
}

/// The classic-form weight gradient `g_b = dN_b/d(x_b/dx)` of node offset `o`, and
/// `dg[b][a] = d g_b / d fx_a`.
#[inline(always)]
fn grad_and_hessian<T: Real>(st: &Stencil<T>, o: [usize; 3]) -> ([T; 3], [[T; 3]; 3]) {
    let h = |b: usize, c: usize, a: Option<usize>| -> T {
        // Factor of axis c in g_b, differentiated once more along `a` when a == Some(c).
        let first = b == c;
        let second = a == Some(c);
        match (first, second) {
            (false, false) => st.w[c][o[c]],
            (true, false) | (false, true) => st.dw[c][o[c]],
            (true, true) => T::c(DDW[o[c]]),
        }
    };
    let g = std::array::from_fn(|b| h(b, 0, None) * h(b, 1, None) * h(b, 2, None));
    let dg = std::array::from_fn(|b| {
        std::array::from_fn(|a| h(b, 0, Some(a)) * h(b, 1, Some(a)) * h(b, 2, Some(a)))
    });
    (g, dg)
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
    let dx = k::<T>(c.dx);
    let inv_dx = k::<T>(c.inv_dx);
    let mls = c.force_form == FORCE_MLS;
    let am = Mat3::from_array(*a);
    let sm = Mat3::from_array(*s);
    // The affine matrix of the momentum: m A (+ S in MLS form).
    let mc = if mls {
        am.scaled(mass) + sm
    } else {
        am.scaled(mass)
    };
    let mut mc_bar = Mat3::<T>::zero();
    let mut s_bar = Mat3::<T>::zero();
    let mut f_bar = [T::zero(); 3];
    for i in 0..3 {
        for j in 0..3 {
            for o in 0..3 {
                let off = [i, j, o];
                let idx = node_index(st, off, n);
                let nb = nodes_bar[idx];
                let mom_bar = [nb[0], nb[1], nb[2]];
                let m_bar = nb[3];
                let (w, dw) = weight_and_grad(st, off);
                let dpos: [T; 3] = std::array::from_fn(|q| (T::c(off[q] as f64) - st.fx[q]) * dx);
                let aff = mc.mul_vec(dpos);
                let p: [T; 3] = std::array::from_fn(|q| mass * v[q] + aff[q]);
                let p_dot = (0..3).fold(T::zero(), |acc, q| acc + p[q] * mom_bar[q]);
                // mass, velocity
                for q in 0..3 {
                    out.v[q] += w * mass * mom_bar[q];
                }
                let va_dot = (0..3).fold(T::zero(), |acc, q| acc + v[q] * mom_bar[q]);
                let a_dpos = am.mul_vec(dpos);
                let ad_dot = (0..3).fold(T::zero(), |acc, q| acc + a_dpos[q] * mom_bar[q]);
                out.mass += w * (va_dot + ad_dot) + w * m_bar;
                // affine matrix
                mc_bar = mc_bar + Mat3::outer(mom_bar, dpos).scaled(w);
                // position through w and dpos
                for ax in 0..3 {
                    f_bar[ax] += dw[ax] * (p_dot + mass * m_bar);
                    let col = mc.col(ax);
                    let cd = (0..3).fold(T::zero(), |acc, q| acc + col[q] * mom_bar[q]);
                    f_bar[ax] -= w * cd * dx;
                }
                if !mls {
                    let (g, dg) = grad_and_hessian(st, off);
                    s_bar = s_bar + Mat3::outer(mom_bar, g);
                    for ax in 0..3 {
                        let dg_a = [dg[0][ax], dg[1][ax], dg[2][ax]];
                        let sg = sm.mul_vec(dg_a);
                        f_bar[ax] += (0..3).fold(T::zero(), |acc, q| acc + sg[q] * mom_bar[q]);
                    }
                }
            }
        }
    }
    let a_bar = mc_bar.scaled(mass);
    if mls {
        s_bar = s_bar + mc_bar;
    }
    for e in 0..9 {
        out.a[e] += a_bar.to_array()[e];
        out.s[e] += s_bar.to_array()[e];
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
    let lo = x_lo * n * n;
    let dt = k::<T>(c.dt);
    let inv_dx = k::<T>(c.inv_dx);
    let st = crate::transfer::stencil(x, inv_dx);
    let g = crate::transfer::gather(nodes, n, &st, c);
    let fe = Mat3::from_array(*f_elastic);
    let mut l = Mat3::from_array(g.grad_v).scaled(dt);
    for a in 0..3 {
        l.0[a][a] += T::one();
    }
    let fb = Mat3::from_array(*f_bar);
    let fe_bar = l.transpose() * fb;
    let g_bar = (fb * fe.transpose()).scaled(dt);
    let mls = c.force_form == FORCE_MLS;
    let cm_bar = if mls {
        Mat3::from_array(*c_bar) + g_bar
    } else {
        Mat3::from_array(*c_bar)
    };
    let vp_bar: [T; 3] = std::array::from_fn(|a| v_bar[a] + dt * x_bar[a]);
    let kc = T::c(4.0) * inv_dx;
    let mut f_pos_bar = [T::zero(); 3];
    for i in 0..3 {
        for j in 0..3 {
            for o in 0..3 {
                let off = [i, j, o];
                let idx = node_index(&st, off, n);
                let vi = [nodes[idx][0], nodes[idx][1], nodes[idx][2]];
                let (w, dw) = weight_and_grad(&st, off);
                let d: [T; 3] = std::array::from_fn(|q| T::c(off[q] as f64) - st.fx[q]);
                // C = kc sum w v d^T: node adjoint kc w Cbar d; position through w and d.
                let cd = cm_bar.mul_vec(d);
                let vcd = (0..3).fold(T::zero(), |s, q| s + vi[q] * cd[q]);
                let vvp = (0..3).fold(T::zero(), |s, q| s + vi[q] * vp_bar[q]);
                for q in 0..3 {
                    nodes_bar[idx - lo][q] += w * vp_bar[q] + kc * w * cd[q];
                }
                for ax in 0..3 {
                    let col = cm_bar.col(ax);
                    let vcol = (0..3).fold(T::zero(), |s, q| s + vi[q] * col[q]);
                    f_pos_bar[ax] += dw[ax] * (vvp + kc * vcd) - kc * w * vcol;
                }
                if !mls {
                    // grad_v = inv_dx sum v g^T.
                    let (gg, dg) = grad_and_hessian(&st, off);
                    let gb = g_bar.mul_vec(gg);
                    for q in 0..3 {
                        nodes_bar[idx - lo][q] += inv_dx * gb[q];
                    }
                    for ax in 0..3 {
                        let dga = [dg[0][ax], dg[1][ax], dg[2][ax]];
                        let gbd = g_bar.mul_vec(dga);
                        f_pos_bar[ax] += inv_dx * (0..3).fold(T::zero(), |s, q| s + vi[q] * gbd[q]);
                    }
                }
            }
        }
    }
    G2pBar {
        x: std::array::from_fn(|a| x_bar[a] + f_pos_bar[a] * inv_dx),
        f_elastic: fe_bar.to_array(),
    }
}
