//! The transfer VJPs written node by node, as first derived: the test oracle of the separable
//! [`super::transfer_vjp::scatter_vjp`] and [`super::transfer_vjp::g2p_vjp`] (the same sums,
//! regrouped axis by axis), which must agree with these to rounding.

use super::transfer_vjp::{G2pBar, ScatterBar};
use crate::kernels::{StepConsts, FORCE_MLS};
use crate::math::{Mat3, Real};
use crate::transfer::{k, Stencil};

/// Second derivatives of the quadratic B-spline weights with respect to `x / dx`.
const DDW: [f64; 3] = [1.0, -2.0, 1.0];

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

/// Adjoint of [`crate::transfer::scatter`] for one particle on the full grid (`x_lo = 0`):
/// `nodes_bar` holds the adjoints of the scattered `[momentum (3), mass]` of every node.
#[allow(clippy::too_many_arguments)]
pub fn scatter_vjp_per_node<T: Real>(
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

/// Adjoint of [`crate::transfer::gather`] + [`crate::transfer::g2p_finish`] for one particle:
/// given the adjoints of the new `x, v, C, F`, accumulates the adjoints of the grid node
/// velocities into `nodes_bar[..][0..3]` (a slab of the grid starting at node layer `x_lo`,
/// as in [`crate::transfer::scatter`]) and returns those of the old position and F_elastic.
#[allow(clippy::too_many_arguments)]
pub fn g2p_vjp_per_node<T: Real>(
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
