//! Per-particle and per-node functions of a substep: B-spline stencil, particle boundary
//! conditions, the particle stress stage, scatter (P2G), grid node update and gather (G2P).
//!
//! These are the one source of truth for the substep math. [`crate::reference`] calls them in
//! plain loops; the CPU backend calls the same functions and adds only scheduling (particle
//! ordering, parallel slabs, active blocks). A GPU backend's shaders mirror them and are tested
//! against the reference.
//!
//! Grid layout: node `(i, j, k)` sits at `(i dx, j dx, k dx)` and is stored at index
//! `(i n + j) n + k` as `[momentum or velocity (3), mass]`.

use crate::boundary::{BC_BOUNDING_BOX, BC_CUBOID, BC_SURFACE, PBC_IMPULSE, PBC_VELOCITY};
use crate::constitutive::stress_update;
use crate::kernels::{
    GridBc, Health, ParticleBc, StepConsts, FORCE_MLS, HEALTH_NAN, HEALTH_OUT_OF_DOMAIN,
    HEALTH_SPEED, OUT_OF_DOMAIN_CLAMP,
};
use crate::material::PartConsts;
use crate::math::Mat3;

/// Quadratic B-spline stencil of a particle: base node and per-axis weights.
#[derive(Clone, Copy, Debug)]
pub struct Stencil {
    /// Lowest node index per axis (`int(x / dx - 0.5)`).
    pub base: [i32; 3],
    /// Fractional position `x / dx - base`, in [0.5, 1.5).
    pub fx: [f32; 3],
    /// Weights of nodes `base + 0..3` per axis.
    pub w: [[f32; 3]; 3],
    /// Derivatives of the weights with respect to `x / dx`.
    pub dw: [[f32; 3]; 3],
}

/// The stencil of a particle at `x` (PhysGaussian's convention: truncation toward zero).
#[inline(always)]
pub fn stencil(x: [f32; 3], inv_dx: f32) -> Stencil {
    let mut s = Stencil {
        base: [0; 3],
        fx: [0.0; 3],
        w: [[0.0; 3]; 3],
        dw: [[0.0; 3]; 3],
    };
    for a in 0..3 {
        let g = x[a] * inv_dx;
        let b = (g - 0.5) as i32;
        let f = g - b as f32;
        s.base[a] = b;
        s.fx[a] = f;
        s.w[a] = [
            0.5 * (1.5 - f) * (1.5 - f),
            0.75 - (f - 1.0) * (f - 1.0),
            0.5 * (f - 0.5) * (f - 0.5),
        ];
        s.dw[a] = [f - 1.5, -2.0 * (f - 1.0), f - 0.5];
    }
    s
}

/// True when the whole 27-node stencil of `x` lies on the grid (`x / dx` in
/// `[0.5, n - 1.5)` on every axis) and `x` is finite.
#[inline(always)]
pub fn in_domain(x: [f32; 3], inv_dx: f32, n: usize) -> bool {
    let hi = n as f32 - 1.5;
    x.iter().all(|&xa| {
        let g = xa * inv_dx;
        g.is_finite() && (0.5..hi).contains(&g)
    })
}

/// Whether a time window `[start, end)` contains `t` (compared in f32, as PhysGaussian does).
#[inline(always)]
fn active(start: f32, end: f32, t: f32) -> bool {
    start <= t && t < end
}

/// Applies the particle boundary conditions (in order) to one particle's velocity.
#[inline]
pub fn particle_bcs(x0: [f32; 3], v: &mut [f32; 3], mass: f32, bcs: &[ParticleBc], c: &StepConsts) {
    for bc in bcs {
        if !active(bc.start, bc.end, c.time) {
            continue;
        }
        let inside = (0..3).all(|a| (x0[a] - bc.point[a]).abs() < bc.size[a]);
        if !inside {
            continue;
        }
        match bc.kind {
            PBC_IMPULSE => {
                for a in 0..3 {
                    v[a] += bc.vector[a] / mass * c.dt;
                }
            }
            PBC_VELOCITY => *v = bc.vector,
            _ => {}
        }
    }
}

/// The particle stage of P2G: return mapping and Kirchhoff stress.
///
/// Updates `f` from F_trial to F_elastic and `plastic` in place, and returns the matrix that the
/// scatter multiplies by the weight gradient (classic form: `-dt V0 tau / dx`, so that
/// `S (dw/d(x/dx))` is the node force times dt) or by `w dpos` (MLS form:
/// `-dt V0 (4 / dx^2) tau`).
#[inline(always)]
pub fn particle_stress(
    f: &mut [f32; 9],
    plastic: &mut [f32; 2],
    c_affine: &[f32; 9],
    vol0: f32,
    pc: &PartConsts,
    c: &StepConsts,
) -> [f32; 9] {
    let grad_v = Mat3::from_array(*c_affine);
    let (fe, tau) = stress_update(Mat3::from_array(*f), pc, plastic, &grad_v, c.dt);
    *f = fe.to_array();
    let tau = tau.sym();
    let k = if c.force_form == FORCE_MLS {
        -c.dt * vol0 * 4.0 * c.inv_dx * c.inv_dx
    } else {
        -c.dt * vol0 * c.inv_dx
    };
    tau.scaled(k).to_array()
}

/// The APIC matrix used by the scatter, after RPIC damping.
#[inline(always)]
pub fn damped_affine(cm: &[f32; 9], r: f32) -> [f32; 9] {
    if r < -0.001 {
        return [0.0; 9];
    }
    if r == 0.0 {
        return *cm;
    }
    let m = Mat3::from_array(*cm);
    (m.scaled(1.0 - r) + (m - m.transpose()).scaled(0.5 * r)).to_array()
}

/// Scatters one particle's mass, APIC momentum and stress force into `nodes`, a slab of the
/// grid that starts at node layer `x_lo` (index `((i - x_lo) n + j) n + k`).
///
/// `s` is the particle stage's stress term, `cm` the (damped) APIC matrix.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
pub fn scatter(
    nodes: &mut [[f32; 4]],
    x_lo: usize,
    n: usize,
    st: &Stencil,
    v: [f32; 3],
    cm: &[f32; 9],
    mass: f32,
    s: &[f32; 9],
    c: &StepConsts,
) {
    let dx = c.dx;
    // Momentum of node offsets (i, j, k): w (m v + m C dpos) + stress term.
    let mut mc = [0.0f32; 9];
    for e in 0..9 {
        mc[e] = mass * cm[e];
    }
    let mls = c.force_form == FORCE_MLS;
    if mls {
        // tau * w * dpos folds into the affine matrix.
        for e in 0..9 {
            mc[e] += s[e];
        }
    }
    let mv = [mass * v[0], mass * v[1], mass * v[2]];
    let dp: [[f32; 3]; 3] =
        std::array::from_fn(|a| std::array::from_fn(|o| (o as f32 - st.fx[a]) * dx));
    let (w0, w1, w2) = (st.w[0], st.w[1], st.w[2]);
    let (d0, d1, d2) = (st.dw[0], st.dw[1], st.dw[2]);
    let bz = st.base[2] as usize;
    for i in 0..3 {
        // a_i = m v + mC[:,0] dpx_i
        let ai = [
            mv[0] + mc[0] * dp[0][i],
            mv[1] + mc[3] * dp[0][i],
            mv[2] + mc[6] * dp[0][i],
        ];
        let row_i = (st.base[0] as usize + i - x_lo) * n;
        for j in 0..3 {
            let wij = w0[i] * w1[j];
            let aij = [
                ai[0] + mc[1] * dp[1][j],
                ai[1] + mc[4] * dp[1][j],
                ai[2] + mc[7] * dp[1][j],
            ];
            // Per (i, j): A = w_ij a_ij, B = w_ij mC[:,2], P/Q from the stress (classic form).
            let mut a = [wij * aij[0], wij * aij[1], wij * aij[2]];
            let b = [wij * mc[2], wij * mc[5], wij * mc[8]];
            let mut q = [0.0f32; 3];
            if !mls {
                let gx = d0[i] * w1[j];
                let gy = w0[i] * d1[j];
                a[0] += s[0] * gx + s[1] * gy;
                a[1] += s[3] * gx + s[4] * gy;
                a[2] += s[6] * gx + s[7] * gy;
                q = [s[2] * wij, s[5] * wij, s[8] * wij];
            }
            let m_ij = wij * mass;
            let base = (row_i + st.base[1] as usize + j) * n + bz;
            let cell = &mut nodes[base..base + 3];
            for (k, node) in cell.iter_mut().enumerate() {
                let wk = w2[k];
                let wdk = w2[k] * dp[2][k];
                let dk = d2[k];
                node[0] += wk * a[0] + wdk * b[0] + dk * q[0];
                node[1] += wk * a[1] + wdk * b[1] + dk * q[1];
                node[2] += wk * a[2] + wdk * b[2] + dk * q[2];
                node[3] += wk * m_ij;
            }
        }
    }
}

/// Updates one grid node: momentum to velocity plus gravity, damping, then the boundary
/// conditions in order. `ijk` is the node index.
#[inline]
pub fn grid_node_update(ijk: [usize; 3], node: &mut [f32; 4], bcs: &[GridBc], c: &StepConsts) {
    let m = node[3];
    let mut v = if m > 1e-15 {
        let inv = 1.0 / m;
        [
            node[0] * inv + c.dt * c.gravity[0],
            node[1] * inv + c.dt * c.gravity[1],
            node[2] * inv + c.dt * c.gravity[2],
        ]
    } else {
        [0.0; 3]
    };
    if c.grid_v_damping < 1.0 {
        for x in v.iter_mut() {
            *x *= c.grid_v_damping;
        }
    }
    let n = c.n_grid as usize;
    let pos = [
        ijk[0] as f32 * c.dx,
        ijk[1] as f32 * c.dx,
        ijk[2] as f32 * c.dx,
    ];
    for bc in bcs {
        let on = active(bc.start, bc.end, c.time);
        match bc.kind {
            BC_BOUNDING_BOX if on => {
                let l = bc.layers as usize;
                if bc.mode == 0 {
                    if (0..3).any(|a| ijk[a] < l || ijk[a] >= n - l) {
                        v = [0.0; 3];
                    }
                } else {
                    for a in 0..3 {
                        if ijk[a] < l && v[a] < 0.0 {
                            v[a] = 0.0;
                        }
                        if ijk[a] >= n - l && v[a] > 0.0 {
                            v[a] = 0.0;
                        }
                    }
                }
            }
            BC_CUBOID => {
                if on {
                    let shift = c.time - bc.start;
                    let inside = (0..3).all(|a| {
                        (pos[a] - (bc.point[a] + bc.velocity[a] * shift)).abs() < bc.axis[a]
                    });
                    if inside {
                        v = bc.velocity;
                    }
                } else if bc.layers == 1 && c.time < bc.end + 15.0 * c.dt {
                    v = [0.0; 3];
                }
            }
            BC_SURFACE if on => {
                let nrm = bc.axis;
                let d: f32 = (0..3).map(|a| (pos[a] - bc.point[a]) * nrm[a]).sum();
                if d < 0.0 {
                    let vn: f32 = (0..3).map(|a| v[a] * nrm[a]).sum();
                    match bc.mode {
                        0 => v = [0.0; 3],
                        1 => {
                            for a in 0..3 {
                                v[a] -= vn * nrm[a];
                            }
                        }
                        _ => {
                            if vn < 0.0 {
                                for a in 0..3 {
                                    v[a] -= vn * nrm[a];
                                }
                                let vt = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
                                if vt > 1e-20 {
                                    let k = (vt + vn * bc.friction).max(0.0) / vt;
                                    for x in v.iter_mut() {
                                        *x *= k;
                                    }
                                }
                            }
                        }
                    }
                }
            }
            _ => {}
        }
    }
    node[0] = v[0];
    node[1] = v[1];
    node[2] = v[2];
}

/// What G2P gathers for one particle.
#[derive(Clone, Copy, Debug)]
pub struct Gathered {
    /// Interpolated velocity.
    pub v: [f32; 3],
    /// APIC matrix `C = (4 / dx^2) sum w v dpos^T`.
    pub c: [f32; 9],
    /// Velocity gradient `sum v grad_w^T` (classic form) or C (MLS form).
    pub grad_v: [f32; 9],
}

/// Gathers velocity, APIC matrix and velocity gradient from the grid (full grid, x_lo = 0).
#[inline(always)]
pub fn gather(nodes: &[[f32; 4]], n: usize, st: &Stencil, c: &StepConsts) -> Gathered {
    let (w0, w1, w2) = (st.w[0], st.w[1], st.w[2]);
    let (d0, d1, d2) = (st.dw[0], st.dw[1], st.dw[2]);
    let dp: [[f32; 3]; 3] = std::array::from_fn(|a| std::array::from_fn(|o| o as f32 - st.fx[a]));
    let mut v = [0.0f32; 3];
    let mut cm = [0.0f32; 9];
    let mut gv = [0.0f32; 9];
    let bz = st.base[2] as usize;
    for i in 0..3 {
        for j in 0..3 {
            let base = ((st.base[0] as usize + i) * n + st.base[1] as usize + j) * n + bz;
            let cell = &nodes[base..base + 3];
            // Sums over k: s0 = sum w_k v, s1 = sum w_k dpz_k v, s2 = sum dw_k v.
            let mut s0 = [0.0f32; 3];
            let mut s1 = [0.0f32; 3];
            let mut s2 = [0.0f32; 3];
            for (k, node) in cell.iter().enumerate() {
                for a in 0..3 {
                    s0[a] += w2[k] * node[a];
                    s1[a] += w2[k] * dp[2][k] * node[a];
                    s2[a] += d2[k] * node[a];
                }
            }
            let wij = w0[i] * w1[j];
            let gx = d0[i] * w1[j];
            let gy = w0[i] * d1[j];
            for a in 0..3 {
                v[a] += wij * s0[a];
                cm[3 * a] += wij * dp[0][i] * s0[a];
                cm[3 * a + 1] += wij * dp[1][j] * s0[a];
                cm[3 * a + 2] += wij * s1[a];
                gv[3 * a] += gx * s0[a];
                gv[3 * a + 1] += gy * s0[a];
                gv[3 * a + 2] += wij * s2[a];
            }
        }
    }
    let kc = 4.0 * c.inv_dx;
    for e in cm.iter_mut() {
        *e *= kc;
    }
    if c.force_form == FORCE_MLS {
        gv = cm;
    } else {
        for e in gv.iter_mut() {
            *e *= c.inv_dx;
        }
    }
    Gathered {
        v,
        c: cm,
        grad_v: gv,
    }
}

/// Finishes G2P for one particle: stores v and C, advects x, updates F to
/// `(I + dt grad_v) F_elastic`, applies the out-of-domain policy and returns the health code
/// (0 when healthy) and the offending value.
#[inline(always)]
pub fn g2p_finish(
    g: &Gathered,
    x: &mut [f32; 3],
    v: &mut [f32; 3],
    cm: &mut [f32; 9],
    f: &mut [f32; 9],
    c: &StepConsts,
) -> (u32, f32) {
    *v = g.v;
    *cm = g.c;
    for a in 0..3 {
        x[a] += c.dt * g.v[a];
    }
    let fe = Mat3::from_array(*f);
    let mut l = Mat3::from_array(g.grad_v).scaled(c.dt);
    for a in 0..3 {
        l.0[a][a] += 1.0;
    }
    *f = (l * fe).to_array();
    let speed2 = v[0] * v[0] + v[1] * v[1] + v[2] * v[2];
    if !(speed2.is_finite() && x.iter().all(|e| e.is_finite()) && f.iter().all(|e| e.is_finite())) {
        return (HEALTH_NAN, f32::NAN);
    }
    if speed2 > c.max_speed * c.max_speed {
        return (HEALTH_SPEED, speed2.sqrt());
    }
    let n = c.n_grid as usize;
    if !in_domain(*x, c.inv_dx, n) {
        if c.out_of_domain == OUT_OF_DOMAIN_CLAMP {
            let lo = 0.5 * c.dx * 1.0001;
            let hi = (n as f32 - 1.5) * c.dx * 0.9999;
            for e in x.iter_mut() {
                *e = e.clamp(lo, hi);
            }
        } else {
            let worst = x
                .iter()
                .cloned()
                .fold(0.0f32, |m, e| if e.abs() > m.abs() { e } else { m });
            return (HEALTH_OUT_OF_DOMAIN, worst);
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
