// Helpers of the reverse sweep: WGSL mirror of the private helpers of
// `r4d_mpm::adjoint::transfer_vjp` (weight gradients and their derivatives along the stencil).
#import lib/transfer.wgsl

// Factor of axis `ax` in the classic-form weight gradient component `b` of node offset `o`,
// differentiated once more along `d` when d == ax (`d = 3u`: not at all). Second derivatives
// of the quadratic B-spline are 1, -2, 1.
fn vjp_hfac(st: Stencil, b: u32, ax: u32, d: u32, o: u32) -> f32 {
    let first = b == ax;
    let second = d == ax;
    if first && second {
        return select(-2.0, 1.0, o != 1u);
    }
    if first || second {
        return st.dw[ax][o];
    }
    return st.w[ax][o];
}

// `dg[b][d]` of the node offset `off`: derivative of the weight gradient component b along d.
fn vjp_weight_hessian(st: Stencil, off: vec3<u32>) -> mat3x3<f32> {
    // Column d holds (dg[0][d], dg[1][d], dg[2][d]).
    var h: mat3x3<f32>;
    for (var d = 0u; d < 3u; d++) {
        for (var b = 0u; b < 3u; b++) {
            h[d][b] = vjp_hfac(st, b, 0u, d, off.x) * vjp_hfac(st, b, 1u, d, off.y) * vjp_hfac(st, b, 2u, d, off.z);
        }
    }
    return h;
}

fn vjp_weight(st: Stencil, off: vec3<u32>) -> f32 {
    return st.w[0][off.x] * st.w[1][off.y] * st.w[2][off.z];
}

fn vjp_weight_grad(st: Stencil, off: vec3<u32>) -> vec3<f32> {
    return vec3<f32>(
        st.dw[0][off.x] * st.w[1][off.y] * st.w[2][off.z],
        st.w[0][off.x] * st.dw[1][off.y] * st.w[2][off.z],
        st.w[0][off.x] * st.w[1][off.y] * st.dw[2][off.z],
    );
}

fn vjp_node(st: Stencil, off: vec3<u32>, n: u32) -> u32 {
    return (u32(st.base.x + i32(off.x)) * n + u32(st.base.y + i32(off.y))) * n + u32(st.base.z + i32(off.z));
}

// Per-particle scratch of the reverse sweep (`sbar`, SBAR_STRIDE floats per particle):
// x (0..3), v (3..6), damped C (6..15, rows), mass (15), stress term (16..25, rows),
// adjoints of mu (25), lambda (26), plastic viscosity (27), Drucker-Prager alpha (28), the
// in-domain flag (29: 1 or 0), the adjoint of the hardening coefficient (30), padding.
const SBAR_STRIDE: u32 = 32u;
const SBAR_PARAMS: u32 = 25u;
const SBAR_FLAG: u32 = 29u;
const SBAR_HARDENING: u32 = 30u;

// Per-particle constants (`info`, 8 floats): x0 (0..3), vol0 (3), mass (4), slot bits (5).
const INFO_STRIDE: u32 = 8u;
